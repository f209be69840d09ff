"""``speed_sign_eval crops DIR``: classification accuracy on GTSRB-format crops.

``DIR/labels.csv`` (``;``-separated, header
``Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId``) lists the crops, with
GTSRB class ids: 0=20, 1=30, 2=50, 3=60, 4=70, 5=80, 6=end of 80, 7=100, 8=120 km/h.
Rows of other classes are skipped (counted in ``skipped``). Each crop is read as
grayscale and given to :meth:`Classifier.classify_crop`.

An answer is right when it is the true limit, or, for class 6 (end of 80), any answer
that is not a speed limit. ``wrong_limit`` counts answers that name a different limit
(the dangerous error); ``no_sign`` / ``other_sign`` / ``end_of_limit`` answers on a limit
sign are misses.
"""
from __future__ import annotations

import argparse
import csv
import json
import logging
import sys
import time
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.config import ClassifierConfig, load_yaml
from speed_sign_detector.errors import TruthFileError
from speed_sign_detector.recognition.classifier import Classifier

_LOG = logging.getLogger(__name__)

#: GTSRB class id -> speed limit in km/h (class 6, end of 80, has none).
GTSRB_LIMITS_KMH: dict[int, int] = {0: 20, 1: 30, 2: 50, 3: 60, 4: 70, 5: 80, 7: 100, 8: 120}
GTSRB_END_OF_80 = 6
#: Upper bounds (exclusive) of the sign-size bins, pixels of the ROI width.
SIZE_BINS_PX: tuple[int, ...] = (20, 25, 30, 40, 50, 70, 10_000)


@dataclass(frozen=True)
class CropLabel:
    """One row of labels.csv: the file, its sign box (inclusive corners) and class."""

    path: Path
    roi_x1: int
    roi_y1: int
    roi_x2: int
    roi_y2: int
    class_id: int


def read_labels(folder: Path) -> tuple[list[CropLabel], int]:
    """Rows of ``folder/labels.csv`` with a class this evaluation knows.

    Returns:
        (labels, skipped): the usable rows and the number of rows of other classes.

    Raises:
        TruthFileError: when the file is missing or malformed.
    """
    path = folder / 'labels.csv'
    try:
        with path.open(newline='') as handle:
            rows = list(csv.DictReader(handle, delimiter=';'))
    except OSError as err:
        raise TruthFileError(f'cannot read {path}: {err}') from err
    labels: list[CropLabel] = []
    skipped = 0
    for number, row in enumerate(rows, start=2):
        try:
            class_id = int(row['ClassId'])
            label = CropLabel(folder / row['Filename'], int(row['Roi.X1']), int(row['Roi.Y1']),
                              int(row['Roi.X2']), int(row['Roi.Y2']), class_id)
        except (KeyError, TypeError, ValueError) as err:
            raise TruthFileError(f'{path}:{number}: malformed row {row!r} ({err}); expected '
                                 'Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId'
                                 ) from err
        if class_id in GTSRB_LIMITS_KMH or class_id == GTSRB_END_OF_80:
            labels.append(label)
        else:
            skipped += 1
    if not labels:
        raise TruthFileError(f'{path} lists no crop of the classes 0-8')
    return labels, skipped


def truth_name(class_id: int) -> str:
    """The answer expected for a class: the limit value, or ``end_of_limit``."""
    return str(GTSRB_LIMITS_KMH[class_id]) if class_id in GTSRB_LIMITS_KMH else 'end_of_limit'


def size_bin(width_px: int) -> str:
    """Name of the size bin of a sign ``width_px`` wide, e.g. ``'20-25'``."""
    low = 0
    for high in SIZE_BINS_PX:
        if width_px < high:
            return f'{low}-{high}' if high < 10_000 else f'{low}+'
        low = high
    return f'{low}+'


def evaluate(folder: Path, classifier: Classifier, limit: int = 0, every: int = 1
             ) -> dict[str, object]:
    """Classify every crop listed in ``folder/labels.csv``; returns the metrics dict."""
    labels, skipped = read_labels(folder)
    labels = labels[::max(1, every)]
    if limit > 0:
        labels = labels[:limit]
    confusion: dict[str, Counter[str]] = defaultdict(Counter)
    right_by_class: Counter[str] = Counter()
    count_by_class: Counter[str] = Counter()
    wrong_limit_by_class: Counter[str] = Counter()
    right_by_size: Counter[str] = Counter()
    count_by_size: Counter[str] = Counter()
    psr_right: list[float] = []
    psr_wrong: list[float] = []
    elapsed = 0.0
    for index, label in enumerate(labels):
        crop = cv2.imread(str(label.path), cv2.IMREAD_GRAYSCALE)
        if crop is None:
            raise TruthFileError(f'cannot read crop image {label.path}')
        start = time.perf_counter()
        result = classifier.classify_crop(crop)
        elapsed += time.perf_counter() - start
        truth = truth_name(label.class_id)
        if label.class_id == GTSRB_END_OF_80:
            right = not result.is_limit
        else:
            right = result.label == truth
        wrong_limit = result.is_limit and result.label != truth
        confusion[truth][result.label] += 1
        count_by_class[truth] += 1
        right_by_class[truth] += right
        wrong_limit_by_class[truth] += wrong_limit
        bin_name = size_bin(label.roi_x2 - label.roi_x1 + 1)
        count_by_size[bin_name] += 1
        right_by_size[bin_name] += right
        (psr_right if right else psr_wrong).append(result.psr)
        if (index + 1) % 500 == 0:
            _LOG.info('%d / %d crops', index + 1, len(labels))
    total = len(labels)
    order = [truth_name(c) for c in sorted(set(GTSRB_LIMITS_KMH) | {GTSRB_END_OF_80})]
    classes = [name for name in order if count_by_class[name]]
    bins = [b for b in (size_bin(h - 1) for h in SIZE_BINS_PX) if count_by_size[b]]
    return {
        'crops': total,
        'skipped': skipped,
        'accuracy': sum(right_by_class.values()) / total,
        'wrong_limit_rate': sum(wrong_limit_by_class.values()) / total,
        'per_class': {name: right_by_class[name] / count_by_class[name] for name in classes},
        'per_class_wrong_limit': {name: wrong_limit_by_class[name] / count_by_class[name]
                                  for name in classes},
        'per_class_count': {name: count_by_class[name] for name in classes},
        'confusion': {name: dict(confusion[name].most_common()) for name in classes},
        'accuracy_by_size_px': {b: right_by_size[b] / count_by_size[b] for b in bins},
        'count_by_size_px': {b: count_by_size[b] for b in bins},
        'mean_psr_right': float(np.mean(psr_right)) if psr_right else None,
        'mean_psr_wrong': float(np.mean(psr_wrong)) if psr_wrong else None,
        'ms_per_crop': 1000.0 * elapsed / total,
        'bank_build_s': classifier.build_time_s,
        'bank_mb': classifier.bank_nbytes / 1e6,
    }


def _print_summary(metrics: dict[str, object]) -> None:
    out = sys.stderr
    print(f"crops {metrics['crops']}  accuracy {metrics['accuracy']:.3f}  wrong limit "
          f"{metrics['wrong_limit_rate']:.3f}  {metrics['ms_per_crop']:.2f} ms/crop", file=out)
    per_class = metrics['per_class']
    wrong = metrics['per_class_wrong_limit']
    assert isinstance(per_class, dict) and isinstance(wrong, dict)
    for name, value in per_class.items():
        print(f'  {name:>13}: {value:.3f} right, {wrong[name]:.3f} wrong limit', file=out)
    by_size = metrics['accuracy_by_size_px']
    assert isinstance(by_size, dict)
    print('  by size: ' + ', '.join(f'{k} px {v:.3f}' for k, v in by_size.items()), file=out)


def run(args: argparse.Namespace) -> int:
    """Entry of the subcommand; returns the exit status."""
    folder = Path(args.folder)
    if not folder.is_dir():
        raise TruthFileError(f'{folder} is not a folder (expected one holding labels.csv)')
    config = load_yaml(args.config).classifier if args.config else ClassifierConfig()
    classifier = Classifier(config)
    _LOG.info('filter banks: %d sizes, %.1f MB, built in %.2f s', len(classifier.banks),
              classifier.bank_nbytes / 1e6, classifier.build_time_s)
    metrics = evaluate(folder, classifier, limit=args.limit, every=args.every)
    _print_summary(metrics)
    if args.json:
        print(json.dumps(metrics))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``crops`` subcommand."""
    parser = subparsers.add_parser('crops', help='classification accuracy on GTSRB-format '
                                   'crops (DIR/labels.csv)')
    parser.add_argument('folder', metavar='DIR', help='folder holding labels.csv and the crops')
    parser.add_argument('--config', help='ROS 2 parameter YAML file (classifier section used)')
    parser.add_argument('--json', action='store_true', help='print one JSON object as the '
                        'last line on stdout')
    parser.add_argument('--limit', type=int, default=0, help='evaluate at most N crops')
    parser.add_argument('--every', type=int, default=1, help='evaluate every Nth crop')
    parser.set_defaults(run=run)
