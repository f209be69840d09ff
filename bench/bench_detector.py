#!/usr/bin/env python3
"""Detector-stage benchmark: GL, CPU and numpy voting vs cv2.HoughCircles and radsym.

Every method sees the same grayscale GTSDB frames in the same run, at 640x480 (the
central 640 columns of the 816x480 scenes, so sign sizes are unchanged) and 816x480.
For each size it prints, per method, the median and best time per frame (methods are
interleaved frame by frame, so machine load hits them alike), the candidate recall with
the top N candidates on the recall frames (hit: centre within max(3, 0.35 r) px of the
box centre, as ``speed_sign_eval scenes``), and the ratio of the fastest peer's time to
the GL detector's and to the CPU detector's (``backend: cpu``, the vectorised CPU path;
``backend: auto`` on a software GL renderer keeps the faster of the two).

Usage::

    python bench/bench_detector.py --data ../shared/data/gtsdb-dev \
        [--timing-frames 6] [--repeats 3] [--recall-frames 0] [--json]

``--recall-frames 0`` uses every frame that holds a speed-limit sign.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.scene_truth import SceneSign, read_gtsdb_truth

Centres = list[tuple[float, float]]
Method = Callable[[np.ndarray], Centres]

TOP_N = 7
MIN_RADIUS_PX, MAX_RADIUS_PX = 4, 40


# Peer settings: the best top-7 recall of a small grid on every 4th gtsdb-dev scene with a
# speed-limit sign (HOUGH_GRADIENT: param1 60..150 x param2 14..50, with/without blur;
# ALT: param1 100..300 x param2 0.3..0.85, dp 1 / 1.5; radsym: 6 or 11 radii, gradient
# threshold 0..80, polarity bright/dark/both, smoothing 0.5 / 1).


def hough_gradient(gray: np.ndarray) -> Centres:
    """cv2.HoughCircles, HOUGH_GRADIENT, tuned on gtsdb-dev for top-7 recall."""
    circles = cv2.HoughCircles(cv2.GaussianBlur(gray, (5, 5), 1.0), cv2.HOUGH_GRADIENT,
                               dp=1, minDist=8, param1=150, param2=40,
                               minRadius=MIN_RADIUS_PX, maxRadius=MAX_RADIUS_PX)
    return [] if circles is None else [(float(c[0]), float(c[1])) for c in circles[0][:TOP_N]]


def hough_gradient_alt(gray: np.ndarray) -> Centres:
    """cv2.HoughCircles, HOUGH_GRADIENT_ALT, tuned on gtsdb-dev for top-7 recall."""
    circles = cv2.HoughCircles(gray, cv2.HOUGH_GRADIENT_ALT, dp=1.5, minDist=8,
                               param1=200, param2=0.8, minRadius=MIN_RADIUS_PX,
                               maxRadius=MAX_RADIUS_PX)
    return [] if circles is None else [(float(c[0]), float(c[1])) for c in circles[0][:TOP_N]]


def _radsym_method(kind: str) -> Method:
    import radsym

    radii = [4, 5, 6, 8, 10, 13, 16, 20, 25, 31, 38]
    # smoothing_factor (radsym default 0.5) matters most: on the 26 gtsdb-dev scenes (37
    # signs) that are every 6th of those outside run_all.py's 60 evaluation scenes, FRST
    # recall@7 is 0.81 with these settings vs 0.19 with threshold 20, smoothing 1, NMS 8;
    # RSD 0.59 vs 0.19 with smoothing 0.5 (grid: smoothing 0.01..1, threshold 0..40,
    # polarity, NMS radius 4/8; see bench/RESULTS.md).
    if kind == 'rsd':
        config = radsym.RsdConfig(radii=radii, gradient_threshold=0.0, polarity='both',
                                  smoothing_factor=0.02)
        response_of = radsym.rsd_response
    else:
        config = radsym.FrstConfig(radii=radii, gradient_threshold=0.0, polarity='both',
                                   smoothing_factor=0.05)
        response_of = radsym.frst_response
    nms = radsym.NmsConfig(radius=4, threshold=0.0, max_detections=TOP_N)

    def run(gray: np.ndarray) -> Centres:
        response = response_of(radsym.sobel_gradient(gray), config)
        proposals = radsym.extract_proposals(response, nms, polarity='both')
        return [(float(p.position[0]), float(p.position[1])) for p in proposals[:TOP_N]]

    run.__doc__ = f'radsym {kind.upper()} response + NMS, radii {radii}, both polarities'
    return run


_FLOOR_SHADER = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0) uniform usampler2D frame;
layout(std430, binding = 0) writeonly buffer Blocks { vec4 blocks[]; };
uniform ivec2 size;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y || p.x % 8 != 0 || p.y % 8 != 0) return;
    blocks[2 * ((p.y / 8) * ((size.x + 7) / 8) + p.x / 8)] = vec4(texelFetch(frame, p, 0).r);
}
"""


def gl_floor_ms(width: int, height: int, repeats: int = 100) -> float:
    """Median ms of the least any GL detector does per frame on this renderer.

    Uploads a (height, width) uint8 frame, runs one trivial compute pass over it and
    reads back a block list as large as the detector's (32 bytes per 8x8 block): no
    gradients, no votes. A GL detector cannot be faster than this on the same renderer.
    """
    import moderngl

    ctx = moderngl.create_standalone_context(backend='egl', require=430)
    try:
        frame = ctx.texture((width, height), 1, dtype='u1')
        blocks = ctx.buffer(reserve=32 * (-(-width // 8)) * (-(-height // 8)))
        shader = ctx.compute_shader(_FLOOR_SHADER)
        shader['size'] = (width, height)
        pixels = np.random.default_rng(0).integers(0, 256, (height, width), np.uint8)
        times = []
        for index in range(repeats + 1):
            start = time.perf_counter()
            frame.write(pixels.tobytes())
            frame.use(0)
            blocks.bind_to_storage_buffer(0)
            shader.run(-(-width // 8), -(-height // 8))
            ctx.memory_barrier()
            blocks.read()
            if index:  # the first run compiles the shader
                times.append(1e3 * (time.perf_counter() - start))
        return statistics.median(times)
    finally:
        ctx.release()


def _detector_method(detector: Detector) -> Method:
    def run(gray: np.ndarray) -> Centres:
        return [(c.x_px, c.y_px) for c in detector.detect(gray)]
    return run


def _found(sign: SceneSign, centres: Centres, x_offset: float) -> bool:
    x, y = sign.centre_px
    tolerance = max(3.0, 0.35 * sign.radius_px)
    return any(math.hypot(cx + x_offset - x, cy - y) <= tolerance for cx, cy in centres)


def _crop(gray: np.ndarray, width: int) -> tuple[np.ndarray, int]:
    offset = (gray.shape[1] - width) // 2
    return np.ascontiguousarray(gray[:, offset:offset + width]), offset


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; prints a table (or one JSON object with --json)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--data', type=Path, default=Path(__file__).resolve().parents[1]
                        / '..' / 'shared' / 'data' / 'gtsdb-dev')
    parser.add_argument('--timing-frames', type=int, default=6)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--recall-frames', type=int, default=0,
                        help='frames with speed-limit signs used for recall (0 = all)')
    parser.add_argument('--skip-numpy-recall', action='store_true',
                        help='time the numpy reference but do not run it for recall')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)

    truth = read_gtsdb_truth(args.data / 'gt.txt')
    limit_files = sorted(name for name, signs in truth.items()
                         if any(sign.limit_kmh for sign in signs))
    recall_files = limit_files if args.recall_frames <= 0 else limit_files[:args.recall_frames]
    step = max(1, len(limit_files) // max(args.timing_frames, 1))
    timing_files = limit_files[::step][:args.timing_frames]
    frames = {name: cv2.imread(str(args.data / 'images' / name), cv2.IMREAD_GRAYSCALE)
              for name in sorted(set(recall_files) | set(timing_files))}

    gl = Detector(DetectorConfig(), backend='gl')
    cpu = Detector(DetectorConfig(), backend='cpu')
    numpy_detector = Detector(DetectorConfig(), backend='numpy')
    methods: dict[str, Method] = {
        'gl': _detector_method(gl),
        'cpu': _detector_method(cpu),
        'numpy': _detector_method(numpy_detector),
        'hough_gradient': hough_gradient,
        'hough_gradient_alt': hough_gradient_alt,
        'radsym_rsd': _radsym_method('rsd'),
        'radsym_frst': _radsym_method('frst'),
    }
    peers = ('hough_gradient', 'hough_gradient_alt', 'radsym_rsd', 'radsym_frst')
    report: dict[str, dict] = {'renderer': gl.renderer, 'sizes': {}}
    for width in (640, 816):
        times: dict[str, list[float]] = {name: [] for name in methods}
        for name in timing_files:
            gray, _ = _crop(frames[name], width)
            for method_name, method in methods.items():
                method(gray)  # warm-up (shaders, caches, per-size resources)
                for _ in range(args.repeats if method_name != 'numpy' else 1):
                    start = time.perf_counter()
                    method(gray)
                    times[method_name].append(1e3 * (time.perf_counter() - start))
        recall: dict[str, float | None] = {}
        for method_name, method in methods.items():
            if method_name == 'numpy' and args.skip_numpy_recall:
                recall[method_name] = None
                continue
            signs = found = 0
            for name in recall_files:
                gray, offset = _crop(frames[name], width)
                centres = method(gray)
                for sign in truth[name]:
                    x, _ = sign.centre_px
                    if not sign.limit_kmh or not offset <= x < offset + width:
                        continue
                    signs += 1
                    found += _found(sign, centres, offset)
            recall[method_name] = found / signs if signs else None
            print(f'{width}x480 {method_name}: recall {recall[method_name]}', file=sys.stderr)
        rows = {name: {'median_ms': statistics.median(values), 'best_ms': min(values),
                       'recall': recall[name]} for name, values in times.items()}
        fastest_peer = min(peers, key=lambda name: rows[name]['median_ms'])
        for name, row in rows.items():
            row['fastest_peer_over_this'] = rows[fastest_peer]['median_ms'] / row['median_ms']
        report['sizes'][f'{width}x480'] = {'methods': rows, 'fastest_peer': fastest_peer,
                                          'speedup_gl_vs_fastest_peer':
                                              rows[fastest_peer]['median_ms']
                                              / rows['gl']['median_ms'],
                                          'speedup_cpu_vs_fastest_peer':
                                              rows[fastest_peer]['median_ms']
                                              / rows['cpu']['median_ms'],
                                          'timing_frames': len(timing_files),
                                          'recall_frames': len(recall_files)}
    gl.close()
    cpu.close()
    numpy_detector.close()
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"GL renderer: {report['renderer']}")
    for size, item in report['sizes'].items():
        print(f"\n{size}: {item['timing_frames']} timing frames, {item['recall_frames']} "
              f"recall frames, top-{TOP_N} candidates")
        print(f"{'method':<22}{'median ms':>11}{'best ms':>10}{'recall':>9}"
              f"{'fastest peer / this':>22}")
        for name, row in item['methods'].items():
            recall_text = '-' if row['recall'] is None else f"{row['recall']:.3f}"
            print(f"{name:<22}{row['median_ms']:>11.1f}{row['best_ms']:>10.1f}"
                  f"{recall_text:>9}{row['fastest_peer_over_this']:>22.2f}")
        print(f"speed-up over the fastest peer ({item['fastest_peer']}): GL "
              f"{item['speedup_gl_vs_fastest_peer']:.2f}x, CPU "
              f"{item['speedup_cpu_vs_fastest_peer']:.2f}x")
    return 0


if __name__ == '__main__':
    sys.exit(main())
