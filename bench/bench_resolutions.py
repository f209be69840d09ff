#!/usr/bin/env python3
"""Detection at full resolution against detection at a working resolution, same frames.

Renders a synthetic drive at each camera size (the same world and field of view: the
focal length grows with the width, so a sign is twice as many pixels wide at 1280 as at
640) and runs the pipeline on the same frames with each ``detector.detection_width_px``
(0 = full resolution). Reports per setting: the median time of each stage
(:data:`speed_sign_detector.pipeline.STAGE_TIMINGS`), the detector's recall of the
speed-limit signs in view (a candidate within half a radius of the centre whose size the
classifier's size search reaches), the share of them read right, and wrong reads; both
for every limit sign in view and for those a 640 px wide camera also lists (at least
5 px radius there: the far signs only a larger camera sees are left out). The host's
CPU and GL renderer are recorded with the figures. Times are only comparable within one
run on an otherwise idle host.

Usage::

    python bench/bench_resolutions.py [--frames 6] [--widths 0,640,800,960] [--json]
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()

from speed_sign_detector.config import (  # noqa: E402
    ClassifierConfig,
    DetectorConfig,
    PipelineConfig,
)
from speed_sign_detector.pipeline import STAGE_TIMINGS, FrameResult, Pipeline  # noqa: E402
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive  # noqa: E402
from speed_sign_detector.truth import TruthRow  # noqa: E402

SIZES: tuple[tuple[int, int], ...] = ((640, 480), (1280, 720), (1920, 1080))
#: Focal length of the 640-wide drive, pixels (the synthetic drive's default).
FOCAL_AT_640_PX = 760.0


def host_cpu() -> str:
    """The CPU model from /proc/cpuinfo (else the platform's word for it)."""
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def drive_frames(width: int, height: int, count: int, seed: int
                 ) -> list[tuple[np.ndarray, tuple[TruthRow, ...], float]]:
    """``count`` frames spread over the drive that show a speed-limit sign: (gray,
    truth, stamp_s)."""
    drive = SyntheticDrive(DriveConfig(seed=seed, duration_s=12.0, fps=30, width_px=width,
                                       height_px=height,
                                       focal_px=FOCAL_AT_640_PX * width / 640))
    chosen = []
    step = max(1, drive.frame_count // (4 * count))
    for index in range(0, drive.frame_count, step):
        frame = drive.frame(index)
        if any(row.limit_kmh for row in frame.truth):
            chosen.append((cv2.cvtColor(frame.bgr, cv2.COLOR_BGR2GRAY), frame.truth,
                           frame.stamp_s))
    spacing = max(1, len(chosen) // count)
    return chosen[::spacing][:count]


def score_frame(result: FrameResult, truth: Sequence[TruthRow], min_radius_px: float = 0.0
                ) -> tuple[int, int, int, int]:
    """(limit signs in view of at least ``min_radius_px`` outer radius, found by the
    detector, read right, wrong limit reads)."""
    classifier = ClassifierConfig()
    signs = [row for row in truth if row.limit_kmh and 0.25 * (
        (row.x2_px - row.x1_px) + (row.y2_px - row.y1_px)) >= min_radius_px]
    found = read = 0
    for row in signs:
        x, y = row.centre_px
        radius = 0.25 * ((row.x2_px - row.x1_px) + (row.y2_px - row.y1_px))
        near = [d for d in result.detections
                if math.hypot(d.candidate.x_px - x, d.candidate.y_px - y) < 0.5 * radius]
        sized = [d for d in near if radius / classifier.size_search_ratio
                 <= d.candidate.radius_px * classifier.candidate_radius_scale
                 <= radius * classifier.size_search_ratio]
        found += bool(sized)
        if any(d.classification is not None and d.classification.label == row.kind
               for d in near):
            read += 1
    wrong = sum(1 for d in result.detections
                if d.classification is not None and d.classification.label.isdigit()
                and not any(d.classification.label == row.kind and math.hypot(
                    d.candidate.x_px - row.centre_px[0], d.candidate.y_px - row.centre_px[1])
                    < 0.5 * (row.x2_px - row.x1_px) for row in truth))
    return len(signs), found, read, wrong


def run(frames_per_size: int, widths: Sequence[int], seed: int) -> dict[str, object]:
    rows = []
    renderer = ''
    for width, height in SIZES:
        frames = drive_frames(width, height, frames_per_size, seed)
        settings = [w for w in widths if w == 0 or w < width] or [0]
        for detection_width in settings:
            config = PipelineConfig(detector=DetectorConfig(detection_width_px=detection_width))
            with Pipeline(config) as pipeline:
                renderer = pipeline.renderer
                pipeline.process(frames[0][0], frames[0][2])  # warm-up: GL sizes, FFT plans
                pipeline.reset()
                times: dict[str, list[float]] = {}
                counts = [0, 0, 0, 0]
                # the signs a 640 px wide camera also lists (at least 5 px radius there)
                visible_at_640 = [0, 0, 0, 0]
                for gray, truth, stamp_s in frames:
                    result = pipeline.process(gray, stamp_s)
                    for key, value in result.timings_ms.items():
                        times.setdefault(key, []).append(value)
                    for slot, value in enumerate(score_frame(result, truth)):
                        counts[slot] += value
                    for slot, value in enumerate(score_frame(result, truth,
                                                             5.0 * width / 640)):
                        visible_at_640[slot] += value
            signs, found, read, wrong = counts
            signs_640, found_640, read_640, _ = visible_at_640
            row = {'size': f'{width}x{height}', 'detection_width_px': detection_width,
                   'frames': len(frames), 'limit_signs': signs,
                   'detector_recall': found / signs if signs else None,
                   'read_share': read / signs if signs else None, 'wrong_reads': wrong,
                   'limit_signs_640_visible': signs_640,
                   'detector_recall_640_visible': found_640 / signs_640 if signs_640 else None,
                   'read_share_640_visible': read_640 / signs_640 if signs_640 else None,
                   'stage_ms_p50': {key: statistics.median(values)
                                    for key, values in times.items()}}
            rows.append(row)
            print(f'{row["size"]:>9} width {detection_width:>4}: detect '
                  f'{row["stage_ms_p50"]["detect"]:6.1f} ms, classify '
                  f'{row["stage_ms_p50"]["classify"]:5.1f} ms; recall {found}/{signs}, read '
                  f'{read}/{signs}, wrong {wrong} (signs a 640 camera lists: found '
                  f'{found_640}/{signs_640}, read {read_640}/{signs_640}); '
                  + ' '.join(f'{key} {row["stage_ms_p50"][key]:.1f}' for key in STAGE_TIMINGS),
                  file=sys.stderr, flush=True)
    return {'host_cpu': host_cpu(), 'gl_renderer': renderer,
            'date': time.strftime('%Y-%m-%d'), 'seed': seed, 'rows': rows}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=6, help='frames per size (default 6)')
    parser.add_argument('--widths', default='0,640,800,960',
                        help='detection widths to compare, 0 = full resolution')
    parser.add_argument('--seed', type=int, default=5, help='drive seed (default 5)')
    parser.add_argument('--json', action='store_true', help='print the figures as JSON')
    args = parser.parse_args(argv)
    if args.frames < 1:
        parser.error('--frames must be at least 1')
    try:
        widths = [int(item) for item in args.widths.split(',')]
    except ValueError:
        parser.error(f'--widths must be integers separated by commas, got {args.widths!r}')
    figures = run(args.frames, widths, args.seed)
    print(f'host: {figures["host_cpu"]}; GL: {figures["gl_renderer"]}', file=sys.stderr)
    if args.json:
        print(json.dumps(figures))
    return 0


if __name__ == '__main__':
    sys.exit(main())
