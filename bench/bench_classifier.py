#!/usr/bin/env python3
"""Classifier-stage benchmark: speed, bank memory, and a plain NCC baseline.

Prints (stderr, and with ``--json`` one JSON object as the last stdout line):

Both the trained bank (the package's default, or ``--bank-file``) and the rendered
templates alone (``bank_file: none``) are measured in the same run, and any bank named by
``--compare-bank`` (the previous default, say):

- filter-bank build time (``cache_dir`` "", so really built) and memory of the
  spectra; peak resident memory growth of the process while building;
- time per candidate and per 640x480 frame holding 7 rendered signs (7 candidates),
  median of ``--frames`` frames, in this process (no other load is controlled for);
- with ``--data``: on GTSRB-format crops, the accuracy of (a) the classifier and (b) a
  plain ``cv2.matchTemplate`` normalised cross-correlation baseline with the SAME
  rendered gray templates (best template over scales 0.85..1.15 and +-3 px shifts), and
  the mean NCC of each class's rendered template with its real crops (how well the
  rendering resembles real signs; crop ROI resized to the template, best of +-3 px).

Usage::

    python bench/bench_classifier.py [--frames 20] [--data ../shared/data/gtsrb-dev]
        [--every 4] [--threads 2] [--compare-bank prev.npz] [--json]
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import sys
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()  # as the node does, before numpy loads its BLAS: the node's figures

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from speed_sign_detector.config import ClassifierConfig  # noqa: E402
from speed_sign_detector.detection.candidates import Candidate  # noqa: E402
from speed_sign_detector.recognition.classifier import CLASS_TEMPLATES, Classifier  # noqa: E402
from speed_sign_detector.recognition.templates import (  # noqa: E402
    GRAY_TEMPLATE_GEOMETRY,
    gray_views,
    render_sign,
)
from speed_sign_detector.tools.eval_crops import (  # noqa: E402
    GTSRB_END_OF_80,
    GTSRB_LIMITS_KMH,
    read_labels,
    size_bin,
    truth_name,
)

FRAME_SHAPE = (480, 640)
FRAME_KINDS = ('30', '50', '80', '100', '120', 'no_overtaking', 'end_of_limit_60')


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def synthetic_frame(seed: int) -> tuple[np.ndarray, list[Candidate]]:
    """640x480 gray frame with 7 signs, and their candidates (centre error ~1 px, radius
    0.65..0.95 of the true one, as the radial-symmetry detector reports on GTSDB). Radii
    are log-uniform in 6..37 px, the range of GTSDB signs."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(40, 200, (FRAME_SHAPE[0] // 20, FRAME_SHAPE[1] // 20))
    frame = cv2.resize(coarse.astype(np.float32), FRAME_SHAPE[::-1],
                       interpolation=cv2.INTER_CUBIC)
    candidates = []
    for index, kind in enumerate(FRAME_KINDS):
        radius = float(np.exp(rng.uniform(np.log(6.0), np.log(37.0))))
        size = int(round(2 * radius))
        bgr, alpha = render_sign(kind, size)
        sign = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        x0 = 10 + index * 88 + int(rng.integers(0, 88 - min(size, 80) + 1))
        y0 = int(rng.integers(10, FRAME_SHAPE[0] - size - 10))
        x0 = min(x0, FRAME_SHAPE[1] - size - 1)
        patch = frame[y0:y0 + size, x0:x0 + size]
        frame[y0:y0 + size, x0:x0 + size] = sign + (1.0 - alpha) * patch
        candidates.append(Candidate(x0 + radius + rng.normal(0, 1), y0 + radius +
                                    rng.normal(0, 1), radius * rng.uniform(0.65, 0.95), 1.0))
    frame += rng.normal(0, 4, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8), candidates


def bench_speed(classifier: Classifier, frames: int) -> dict[str, float]:
    """Median wall-clock ms per frame of 7 candidates and per candidate, and the
    process CPU time (less sensitive to other processes on a shared machine).

    The frames are classified twice: the first pass (``ms_per_frame_first_pass``) also
    fills the classifier's caches of index layouts per sign size and position, which a
    running node fills in its first seconds; the figures are from the second pass (the
    steady state)."""
    scenes = [synthetic_frame(seed) for seed in range(frames)]
    first_pass = []
    for gray, candidates in scenes:
        start = time.perf_counter()
        classifier.classify(gray, candidates)
        first_pass.append((time.perf_counter() - start) * 1000.0)
    per_frame = []
    cpu_ms = 0.0
    for gray, candidates in scenes:
        start, cpu_start = time.perf_counter(), time.process_time()
        classifier.classify(gray, candidates)
        cpu_ms += (time.process_time() - cpu_start) * 1000.0
        per_frame.append((time.perf_counter() - start) * 1000.0)
    median = statistics.median(per_frame)
    return {'ms_per_frame_7_candidates': median, 'ms_per_candidate': median / 7.0,
            'ms_per_frame_best': min(per_frame),
            'ms_per_frame_first_pass': statistics.median(first_pass),
            'cpu_ms_per_candidate': cpu_ms / (7.0 * frames)}


def bench_threads(config: ClassifierConfig, frames: int, threads: int) -> dict[str, float]:
    """How much of the classifier runs in parallel: ``threads`` classifiers (one each:
    a classifier is used by one thread at a time) classify the same synthetic frames
    at once, against one of them alone; both timed after each classifier's warm-up pass
    (which fills its caches, as :func:`bench_speed`'s first pass does).

    Returns:
        ``ms_per_frame_alone`` (one thread, median), ``ms_per_frame_together`` (median
        over every thread's frames) and ``throughput_ratio``: frames per second with the
        threads together over frames per second alone. ``threads`` means that no part of
        the classifier holds the GIL (given that many free cores); 1 means that all of it
        does. The node runs recognition beside its executor and detection threads, so
        what holds the GIL here slows recognition there.
    """
    scenes = [synthetic_frame(seed) for seed in range(frames)]
    classifiers = [Classifier(config) for _ in range(threads)]
    timings: list[list[float]] = [[] for _ in range(threads)]

    def classify_all(index: int) -> None:
        for gray, candidates in scenes:
            start = time.perf_counter()
            classifiers[index].classify(gray, candidates)
            timings[index].append((time.perf_counter() - start) * 1000.0)

    for index in range(threads):  # warm-up: index layouts and FFT plans of every thread
        classify_all(index)
    timings = [[] for _ in range(threads)]
    classify_all(0)  # one thread alone, warm (the first pass above filled the caches)
    alone = timings[0]
    timings = [[] for _ in range(threads)]
    workers = [threading.Thread(target=classify_all, args=(index,)) for index in range(threads)]
    start = time.perf_counter()
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    wall_s = time.perf_counter() - start
    alone_ms = statistics.median(alone)
    return {'threads': threads, 'ms_per_frame_alone': alone_ms,
            'ms_per_frame_together': statistics.median(sum(timings, [])),
            'throughput_ratio': threads * frames / wall_s / (1000.0 / alone_ms)}


def _crop_window(crop: np.ndarray, box: tuple[int, int, int, int], size: int, pad: int
                 ) -> np.ndarray:
    """The sign box of a crop resized to ``size`` with ``pad`` px of context, float32."""
    x1, y1, x2, y2 = box
    sx, sy = size / (x2 - x1 + 1), size / (y2 - y1 + 1)
    matrix = np.float32([[sx, 0, pad - x1 * sx], [0, sy, pad - y1 * sy]])
    return cv2.warpAffine(crop, matrix, (size + 2 * pad, size + 2 * pad),
                          flags=cv2.INTER_AREA if sx < 1 else cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE).astype(np.float32)


def _bin_low(name: str) -> int:
    """Lower bound (px) of a size-bin name such as '20-25' or '70+'."""
    return int(name.split('-')[0].rstrip('+'))


def bench_crops(classifier: Classifier, folder: Path, every: int) -> dict[str, object]:
    """Classifier vs NCC baseline accuracy, and rendering-vs-real NCC, on crops."""
    labels, _ = read_labels(folder)
    labels = labels[::max(1, every)]
    size = 32
    kinds = {name: kinds[0] if len(kinds) == 1 else 'end_of_limit_80'
             for name, kinds in CLASS_TEMPLATES.items()}
    templates = {name: gray_views(kind, size, size + 2, [(0, 0, 0)],
                                  geometry=GRAY_TEMPLATE_GEOMETRY)[0]
                 for name, kind in kinds.items()}
    render_ncc: dict[str, list[float]] = defaultdict(list)
    right = Counter()
    ncc_right = Counter()
    size_count: Counter[str] = Counter()
    size_right: Counter[str] = Counter()
    size_ncc_right: Counter[str] = Counter()
    count = Counter()
    ncc_ms = 0.0
    clf_ms = 0.0
    for label in labels:
        crop = cv2.imread(str(label.path), cv2.IMREAD_GRAYSCALE)
        truth = truth_name(label.class_id)
        box = (label.roi_x1, label.roi_y1, label.roi_x2, label.roi_y2)
        # rendering vs real: the class's own template on the crop's sign box
        window = _crop_window(crop, box, size, 4)
        own = templates[truth if truth != 'end_of_limit' else 'end_of_limit']
        render_ncc[truth].append(float(cv2.matchTemplate(window, own,
                                                         cv2.TM_CCOEFF_NORMED).max()))
        # NCC baseline: no box known, same framing guess as classify_crop, scale search
        start = time.perf_counter()
        height, width = crop.shape
        side = float(min(height, width))
        sign = min(side / 1.2, side - 10.0) if side > 10 else side / 1.2
        best_name, best_score = '', -2.0
        for scale in (0.85, 0.92, 1.0, 1.08, 1.15):
            factor = size / (sign * scale)
            resized = cv2.resize(crop, None, fx=factor, fy=factor,
                                 interpolation=cv2.INTER_AREA if factor < 1 else
                                 cv2.INTER_LINEAR).astype(np.float32)
            cy, cx = resized.shape[0] / 2.0, resized.shape[1] / 2.0
            half = (size + 2) // 2 + 3
            padded = cv2.copyMakeBorder(resized, half, half, half, half, cv2.BORDER_REPLICATE)
            top, left = int(round(cy)), int(round(cx))
            search = padded[top:top + 2 * half, left:left + 2 * half]
            for name, template in templates.items():
                score = float(cv2.matchTemplate(search, template, cv2.TM_CCOEFF_NORMED).max())
                if score > best_score:
                    best_name, best_score = name, score
        ncc_ms += time.perf_counter() - start
        start = time.perf_counter()
        answer = classifier.classify_crop(crop)
        clf_ms += time.perf_counter() - start
        is_end = label.class_id == GTSRB_END_OF_80
        count[truth] += 1
        bin_name = size_bin(label.roi_x2 - label.roi_x1 + 1)
        size_count[bin_name] += 1
        size_right[bin_name] += (not answer.is_limit) if is_end else answer.label == truth
        size_ncc_right[bin_name] += (not best_name.isdigit()) if is_end else best_name == truth
        right[truth] += (not answer.is_limit) if is_end else answer.label == truth
        ncc_right[truth] += (not best_name.isdigit()) if is_end else best_name == truth
    total = sum(count.values())
    order = [truth_name(c) for c in sorted(set(GTSRB_LIMITS_KMH) | {GTSRB_END_OF_80})]
    return {
        'crops': total,
        'classifier_accuracy': sum(right.values()) / total,
        'classifier_per_class': {k: right[k] / count[k] for k in order if count[k]},
        'classifier_ms_per_crop': 1000.0 * clf_ms / total,
        'ncc_baseline_accuracy': sum(ncc_right.values()) / total,
        'ncc_baseline_per_class': {k: ncc_right[k] / count[k] for k in order if count[k]},
        'ncc_baseline_ms_per_crop': 1000.0 * ncc_ms / total,
        # by sign width (ROI, px), bins of speed_sign_eval crops; dicts keep bin order
        'count_by_size_px': {b: size_count[b] for b in sorted(size_count, key=_bin_low)},
        'classifier_by_size_px': {b: size_right[b] / size_count[b]
                                  for b in sorted(size_count, key=_bin_low)},
        'ncc_baseline_by_size_px': {b: size_ncc_right[b] / size_count[b]
                                    for b in sorted(size_count, key=_bin_low)},
        'rendering_vs_real_mean_ncc': {k: float(np.mean(render_ncc[k])) for k in order
                                       if render_ncc[k]},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--frames', type=int, default=20, help='synthetic frames timed')
    parser.add_argument('--data', type=Path, help='GTSRB-format folder (labels.csv)')
    parser.add_argument('--every', type=int, default=4, help='use every Nth crop')
    parser.add_argument('--json', action='store_true', help='JSON object as last stdout line')
    parser.add_argument('--bank-file', default='', help='trained bank to time against the '
                        'rendered-only one ("" = the package\'s default bank)')
    parser.add_argument('--compare-bank', action='append', default=[], metavar='FILE',
                        help='another trained bank timed in the same run (for example the '
                             'previous default: git show REV:speed_sign_detector/recognition/'
                             'data/default_bank.npz > prev.npz); repeatable')
    parser.add_argument('--threads', type=int, default=0, help='also classify the frames in '
                        'this many threads at once with the trained bank, to see how much '
                        'of the classifier holds the GIL (0 = skip)')
    args = parser.parse_args(argv)

    result: dict[str, object] = {}
    # the trained bank (the package's default) against the renderings alone, same run
    compared = [(f'compared {path}', path) for path in args.compare_bank]
    for bank_name, bank_file in [('trained', args.bank_file), ('rendered', 'none'), *compared]:
        rss_before = _rss_mb()
        start = time.perf_counter()
        classifier = Classifier(ClassifierConfig(cache_dir='', bank_file=bank_file))
        build_s = time.perf_counter() - start
        figures: dict[str, object] = {
            'bank_build_s': build_s,
            'bank_sizes': len(classifier.banks),
            'bank_filters': sum(b.classification.shape[0] + b.detection.shape[0]
                                for b in classifier.banks),
            'bank_mb': classifier.bank_nbytes / 1e6,
            'rss_growth_mb': _rss_mb() - rss_before,
        }
        print(f"{bank_name} bank: {figures['bank_sizes']} sizes, {figures['bank_filters']} "
              f"filters, {figures['bank_mb']:.1f} MB, built in {build_s:.2f} s", file=sys.stderr)
        figures.update(bench_speed(classifier, args.frames))
        print(f"{bank_name} bank speed: {figures['ms_per_candidate']:.2f} ms/candidate, "
              f"{figures['ms_per_frame_7_candidates']:.1f} ms/frame (7 candidates; first "
              f"pass {figures['ms_per_frame_first_pass']:.1f}), CPU "
              f"{figures['cpu_ms_per_candidate']:.2f} ms/candidate", file=sys.stderr)
        if args.data:
            crops = bench_crops(classifier, args.data, args.every)
            figures.update(crops)
            print(f"{bank_name} bank, crops {crops['crops']}: classifier "
                  f"{crops['classifier_accuracy']:.3f}, NCC baseline "
                  f"{crops['ncc_baseline_accuracy']:.3f}; rendering vs real NCC "
                  f"{crops['rendering_vs_real_mean_ncc']}", file=sys.stderr)
        if bank_name == 'trained':
            result.update(figures)  # the default bank's figures at the top level
        elif bank_name == 'rendered':
            result['rendered_bank'] = figures
        else:
            result.setdefault('compared_banks', {})[bank_file] = figures
    if args.threads > 1:
        together = bench_threads(ClassifierConfig(cache_dir='', bank_file=args.bank_file),
                                 args.frames, args.threads)
        result['threads'] = together
        print(f"{args.threads} threads at once: {together['ms_per_frame_together']:.1f} "
              f"ms/frame each against {together['ms_per_frame_alone']:.1f} alone; throughput "
              f"{together['throughput_ratio']:.2f}x one thread's ({args.threads}x = nothing "
              f"holds the GIL, 1x = everything does)", file=sys.stderr)
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
