#!/usr/bin/env python3
"""cProfile of the stages that run_all.py finds slower than a peer.

Profiles, on the frames/crops run_all.py uses, the detector (``--backend gl`` or
``numpy``) at one frame size, and ``Classifier.classify_crop`` on GTSRB crops, and prints
the functions with the most own time (``tottime``) and cumulative time, and for the GL
backend the time of each GL stage (``GLVoter.profile_stages``). With the GL backend on
llvmpipe the GL calls (dispatches, barriers, ``finish``) are where the CPU threads of
the driver run; on a real GPU they would mostly wait for it.

Usage::

    python bench/profile_stages.py detector [--backend gl] [--size 816x480] [--frames 8]
    python bench/profile_stages.py classifier [--crops 200]
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import bench_classifier  # noqa: F401  (run_all_stages imports it too)
import run_all_stages

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.tools.eval_crops import read_labels
from speed_sign_detector.scene_truth import read_gtsdb_truth


def _print(profile: cProfile.Profile, lines: int) -> None:
    stats = pstats.Stats(profile, stream=sys.stdout).strip_dirs()
    stats.sort_stats('tottime').print_stats(lines)
    stats.sort_stats('cumulative').print_stats(lines)


def _profiled(call: Callable[[Any], object], items: Sequence[Any]) -> cProfile.Profile:
    """A cProfile of ``call(item)`` for every item."""
    profile = cProfile.Profile()
    profile.enable()
    for item in items:
        call(item)
    profile.disable()
    return profile


def profile_detector(backend: str, size_name: str, frames: int, lines: int) -> None:
    """Profile ``Detector.detect`` on ``frames`` of run_all's GTSDB frames."""
    size = next(s for s in run_all_stages.DETECTOR_SIZES if s[0] == size_name)
    folder = run_all_stages.DATA_DIR / 'gtsdb-dev'
    truth = read_gtsdb_truth(folder / 'gt.txt')
    files = run_all_stages._spaced(sorted(n for n, signs in truth.items()
                                          if any(s.limit_kmh for s in signs)), frames)
    images = [run_all_stages._frame_at(
        cv2.imread(str(folder / 'images' / name), cv2.IMREAD_GRAYSCALE),
        truth[name], size[1], size[2], size[3])[0] for name in files]
    with Detector(DetectorConfig(), backend=backend) as detector:
        detector.detect(images[0])  # warm-up outside the profile
        profile = _profiled(detector.detect, images)
        print(f'{backend} ({detector.renderer}) on {len(images)} frames at {size_name}')
        if detector._gl is not None:  # GL stage times (a GPU sync after each stage)
            detector._gl.profile_stages(True)
            for image in images:
                detector.detect(image)
            stage_ms = detector._gl.stage_ms or {}
            print(f'GL stages, {detector.vote_method} voting, ms per frame: ' + ', '.join(
                f'{name} {total / len(images):.2f}' for name, total in stage_ms.items()))
    _print(profile, lines)


def profile_classifier(crops: int, lines: int, params: Path | None) -> None:
    """Profile ``Classifier.classify_crop`` on ``crops`` GTSRB crops (evenly spaced)."""
    settings = run_all_stages.BenchSettings(out_dir=Path('.'), pipeline_params=params)
    classifier = Classifier(run_all_stages.pipeline_config(settings).classifier)
    labels, _ = read_labels(run_all_stages.DATA_DIR / 'gtsrb-dev')
    labels = labels[::max(1, len(labels) // crops)][:crops]
    images = [cv2.imread(str(label.path), cv2.IMREAD_GRAYSCALE) for label in labels]
    classifier.classify_crop(images[0])
    profile = _profiled(classifier.classify_crop, images)
    print(f'classify_crop on {len(images)} crops')
    _print(profile, lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('stage', choices=('detector', 'classifier'))
    parser.add_argument('--backend', choices=('gl', 'numpy'), default='gl')
    parser.add_argument('--size', default='816x480',
                        choices=[size[0] for size in run_all_stages.DETECTOR_SIZES])
    parser.add_argument('--frames', type=int, default=8)
    parser.add_argument('--crops', type=int, default=200)
    parser.add_argument('--lines', type=int, default=18)
    parser.add_argument('--params', default=str(run_all_stages.bench_inputs.PARAMS_FILE),
                        help="classifier parameter file, as run_all.py --params")
    args = parser.parse_args(argv)
    if args.stage == 'detector':
        profile_detector(args.backend, args.size, args.frames, args.lines)
    else:
        profile_classifier(args.crops, args.lines,
                           None if args.params == 'defaults' else Path(args.params))
    return 0


if __name__ == '__main__':
    sys.exit(main())
