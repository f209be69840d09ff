#!/usr/bin/env python3
"""Detection next to a busy classifier: in a thread of this process, or in its own.

The node detects on one thread while another classifies (``overlap_stages``). Both are
Python code making many calls into numpy, OpenCV and OpenGL, so on two threads of one
interpreter they also wait for each other's turn with the GIL. This measures, on the same
640x480 frame with 7 candidates (``bench_classifier.synthetic_frame``), ms per frame of:

- detection alone, and classification alone (in this process);
- detection while a thread of this process classifies without pause;
- detection while a thread keeps a :class:`ClassifierProcess` (``classifier_process:
  true``) classifying without pause: the thread mostly waits on a socket.

It prints the figures (stderr) and, with ``--json``, one JSON object as the last stdout
line. The figures depend on the cores free: no threshold is checked here.

Usage::

    python bench/bench_stage_contention.py [--seconds 4] [--backend gl] [--json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()  # as the node does, before numpy loads its BLAS

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

from bench_classifier import synthetic_frame  # noqa: E402

from speed_sign_detector.config import ClassifierConfig, DetectorConfig  # noqa: E402
from speed_sign_detector.detection.detector import Detector  # noqa: E402
from speed_sign_detector.recognition.classifier import Classifier  # noqa: E402
from speed_sign_detector.recognition.classifier_process import (  # noqa: E402
    ClassifierProcess,
)


def _ms_per_call(call: Callable[[], Any], seconds: float) -> float:
    """Mean ms per call of ``call`` repeated for ``seconds`` (after one warm-up call)."""
    call()
    started = time.perf_counter()
    count = 0
    while time.perf_counter() - started < seconds or count == 0:
        call()
        count += 1
    return (time.perf_counter() - started) / count * 1e3


def _detect_beside(classify: Callable[[], Any], detect: Callable[[], Any], seconds: float
                   ) -> tuple[float, float]:
    """(detection ms, median classification ms) while a thread runs ``classify`` in a
    loop for as long as detection is timed."""
    stop = threading.Event()
    classify_ms: list[float] = []

    def loop() -> None:
        while not stop.is_set():
            started = time.perf_counter()
            classify()
            classify_ms.append((time.perf_counter() - started) * 1e3)

    helper = threading.Thread(target=loop, name='busy_classifier', daemon=True)
    helper.start()
    try:
        detect_ms = _ms_per_call(detect, seconds)
        while not classify_ms and helper.is_alive():  # at least one classification
            time.sleep(0.001)
    finally:
        stop.set()
        helper.join()
    return detect_ms, statistics.median(classify_ms) if classify_ms else float('nan')


def bench_contention(classifier_config: ClassifierConfig, backend: str, seconds: float
                     ) -> dict[str, Any]:
    """The figures of the module docstring (ms per frame)."""
    gray, candidates = synthetic_frame(0)
    with Detector(DetectorConfig(), backend=backend) as detector:
        def detect() -> Any:
            return detector.detect(gray)

        classifier = Classifier(classifier_config)
        figures: dict[str, Any] = {
            'backend': detector.backend_name, 'renderer': detector.renderer,
            'detect_ms_alone': _ms_per_call(detect, seconds),
            'classify_ms_alone': _ms_per_call(lambda: classifier.classify(gray, candidates),
                                              seconds)}
        figures['detect_ms_beside_thread'], figures['classify_ms_beside_thread'] = \
            _detect_beside(lambda: classifier.classify(gray, candidates), detect, seconds)
        with ClassifierProcess(classifier_config) as worker:
            worker.classify(gray, candidates)
            figures['detect_ms_beside_process'], figures['classify_ms_beside_process'] = \
                _detect_beside(lambda: worker.classify(gray, candidates), detect, seconds)
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=4.0,
                        help='seconds each figure is timed for')
    parser.add_argument('--backend', default='auto', choices=('auto', 'gl', 'numpy'))
    parser.add_argument('--bank-cache', default='', help='classifier filter-bank cache folder')
    parser.add_argument('--json', action='store_true', help='print one JSON object last')
    args = parser.parse_args(argv)
    figures = bench_contention(ClassifierConfig(cache_dir=args.bank_cache), args.backend,
                               args.seconds)
    print(f"detector: {figures['backend']} ({figures['renderer']})", file=sys.stderr)
    print(f"alone:                   detect {figures['detect_ms_alone']:6.1f} ms, "
          f"classify {figures['classify_ms_alone']:6.1f} ms", file=sys.stderr)
    for where in ('thread', 'process'):
        print(f'classifier in a {where + ":":8s} detect '
              f"{figures[f'detect_ms_beside_{where}']:6.1f} ms, classify "
              f"{figures[f'classify_ms_beside_{where}']:6.1f} ms", file=sys.stderr)
    if args.json:
        print(json.dumps(figures))
    return 0


if __name__ == '__main__':
    sys.exit(main())
