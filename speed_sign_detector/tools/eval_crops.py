"""``speed_sign_eval crops DIR``: classification accuracy on GTSRB-format crops.

``DIR/labels.csv`` (``;``-separated, header
``Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId``) lists the crops, with
GTSRB class ids. Each crop is read as grayscale and given to
:meth:`Classifier.classify_crop`, framed as ``--framing`` or else
``classifier.crop_framing`` says (``auto``: a GTSRB margin, a tight box or, in a crop
under 20 px, a margin in proportion). Two groups of classes are evaluated:

- the limit classes 0=20, 1=30, 2=50, 3=60, 4=70, 5=80, 7=100, 8=120 km/h, and 6 = end
  of 80: an answer is right when it is the true limit, or, for class 6, any answer that
  is not a speed limit. ``wrong_limit`` counts answers that name a different limit (the
  dangerous error); ``no_sign`` / ``other_sign`` / ``end_of_limit`` answers on a limit
  sign are misses. Reported overall and per class.
- the round look-alikes of :data:`GTSRB_LOOKALIKE_NAMES` (no passing, no entry, end of
  all limits, the blue mandatory signs, ...; ``../shared/data/gtsrb-lookalikes-dev``):
  every answer that names a speed limit is a false limit. Reported as the share "read
  as a limit", overall and per class.

Rows of other classes are skipped (counted in ``skipped``). A crop file that cannot be
read is skipped and listed with its reason in ``unreadable``; the rest is evaluated and
the exit status is 1. Ctrl-C stops after the crop in hand: the metrics of the crops
done are reported with ``partial`` true, exit status 130.

JSON (``--json``, the last stdout line) keys: ``crops`` (limit-class crops evaluated),
``accuracy``, ``wrong_limit_rate``, ``per_class``, ``per_class_wrong_limit``,
``per_class_count``, ``confusion``, ``accuracy_by_size_px``, ``count_by_size_px``,
``mean_psr_right``, ``mean_psr_wrong``; ``lookalike_crops``, ``read_as_limit_rate``,
``per_lookalike_read_as_limit``, ``per_lookalike_count``, ``lookalike_confusion``;
``skipped``, ``unreadable`` (list of ``{file, reason}``), ``crops_planned``,
``crops_done``, ``partial``; ``ms_per_crop``, ``bank_build_s``, ``bank_mb``;
``framing`` (``--framing``, else ``classifier.crop_framing``). Rates
over an empty group are null.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.errors import TrainingDataError, TruthFileError
from speed_sign_detector.image_files import (
    UnreadableImage,
    UnreadableImageError,
    read_gray_image,
)
from speed_sign_detector.labelled_crops import (
    GTSRB_END_OF_80,
    GTSRB_LIMITS_KMH,
    GTSRB_LOOKALIKE_NAMES,
    LABELS_HEADER,
    read_label_rows,
)
from speed_sign_detector.recognition.classifier import Classification, Classifier
from speed_sign_detector.recognition.crop_framing import CROP_FRAMINGS
from speed_sign_detector.tools.cli_types import non_negative_integer, positive_integer
from speed_sign_detector.tools.run_control import (
    EXIT_INTERRUPTED,
    ItemProgress,
    StopRequest,
    stop_on_interrupt,
)

_LOG = logging.getLogger(__name__)

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

    @property
    def is_lookalike(self) -> bool:
        """True for a look-alike class (:data:`GTSRB_LOOKALIKE_NAMES`)."""
        return self.class_id in GTSRB_LOOKALIKE_NAMES


@dataclass(frozen=True)
class CropOutcome:
    """The classifier's answer on one crop, and how long it took (seconds)."""

    label: CropLabel
    classification: Classification
    seconds: float


def read_labels(folder: Path, include_lookalikes: bool = False
                ) -> tuple[list[CropLabel], int]:
    """Rows of ``folder/labels.csv`` with a class this evaluation knows.

    Args:
        folder: the data folder holding ``labels.csv``.
        include_lookalikes: also keep the look-alike classes (skipped otherwise).

    Returns:
        (labels, skipped): the usable rows and the number of rows of other classes.

    Raises:
        TruthFileError: when the file is missing, empty, malformed, or lists no crop of
            a class this evaluation knows.
    """
    path = folder / 'labels.csv'
    try:
        rows = read_label_rows(folder)
    except TrainingDataError as err:
        raise TruthFileError(str(err)) from err
    labels: list[CropLabel] = []
    skipped = 0
    for row in rows:
        class_id = row.class_id
        label = CropLabel(folder / row.filename, *row.roi, class_id)
        if (class_id in GTSRB_LIMITS_KMH or class_id == GTSRB_END_OF_80
                or (include_lookalikes and label.is_lookalike)):
            labels.append(label)
        else:
            skipped += 1
    if not labels:
        known = 'the classes 0-8' + (' or a look-alike class (' + ', '.join(
            str(class_id) for class_id in GTSRB_LOOKALIKE_NAMES) + ')'
            if include_lookalikes else '')
        raise TruthFileError(f'{path} lists no crop of {known}')
    return labels, skipped


def truth_name(class_id: int) -> str:
    """The answer expected for a limit class (the value, or ``end_of_limit``), or the
    name of a look-alike class."""
    if class_id in GTSRB_LIMITS_KMH:
        return str(GTSRB_LIMITS_KMH[class_id])
    if class_id == GTSRB_END_OF_80:
        return 'end_of_limit'
    return GTSRB_LOOKALIKE_NAMES[class_id]


def size_bin(width_px: int) -> str:
    """Name of the size bin of a sign ``width_px`` wide, e.g. ``'20-25'``."""
    low = 0
    for high in SIZE_BINS_PX:
        if width_px < high:
            return f'{low}-{high}' if high < 10_000 else f'{low}+'
        low = high
    return f'{low}+'


def is_right(outcome: CropOutcome) -> bool:
    """A limit-class crop answered right: its limit, or for end of 80 no limit at all."""
    if outcome.label.class_id == GTSRB_END_OF_80:
        return not outcome.classification.is_limit
    return outcome.classification.label == truth_name(outcome.label.class_id)


def _rate(count: int, total: int) -> float | None:
    return count / total if total else None


def limit_class_metrics(outcomes: list[CropOutcome]) -> dict[str, Any]:
    """Accuracy, wrong-limit rates, confusion and size bins of the limit-class crops."""
    confusion: dict[str, Counter[str]] = defaultdict(Counter)
    right_by_class: Counter[str] = Counter()
    count_by_class: Counter[str] = Counter()
    wrong_limit_by_class: Counter[str] = Counter()
    right_by_size: Counter[str] = Counter()
    count_by_size: Counter[str] = Counter()
    psr_right: list[float] = []
    psr_wrong: list[float] = []
    for outcome in outcomes:
        truth, result = truth_name(outcome.label.class_id), outcome.classification
        right = is_right(outcome)
        confusion[truth][result.label] += 1
        count_by_class[truth] += 1
        right_by_class[truth] += right
        wrong_limit_by_class[truth] += result.is_limit and result.label != truth
        bin_name = size_bin(outcome.label.roi_x2 - outcome.label.roi_x1 + 1)
        count_by_size[bin_name] += 1
        right_by_size[bin_name] += right
        (psr_right if right else psr_wrong).append(result.psr)
    order = [truth_name(c) for c in sorted(set(GTSRB_LIMITS_KMH) | {GTSRB_END_OF_80})]
    classes = [name for name in order if count_by_class[name]]
    bins = [b for b in (size_bin(h - 1) for h in SIZE_BINS_PX) if count_by_size[b]]
    total = len(outcomes)
    return {
        'crops': total,
        'accuracy': _rate(sum(right_by_class.values()), total),
        'wrong_limit_rate': _rate(sum(wrong_limit_by_class.values()), total),
        'per_class': {name: right_by_class[name] / count_by_class[name] for name in classes},
        'per_class_wrong_limit': {name: wrong_limit_by_class[name] / count_by_class[name]
                                  for name in classes},
        'per_class_count': {name: count_by_class[name] for name in classes},
        'confusion': {name: dict(confusion[name].most_common()) for name in classes},
        'accuracy_by_size_px': {b: right_by_size[b] / count_by_size[b] for b in bins},
        'count_by_size_px': {b: count_by_size[b] for b in bins},
        'mean_psr_right': float(np.mean(psr_right)) if psr_right else None,
        'mean_psr_wrong': float(np.mean(psr_wrong)) if psr_wrong else None,
    }


def lookalike_metrics(outcomes: list[CropOutcome]) -> dict[str, Any]:
    """The share of look-alike crops read as a speed limit, overall and per class."""
    count_by_class: Counter[str] = Counter()
    as_limit_by_class: Counter[str] = Counter()
    confusion: dict[str, Counter[str]] = defaultdict(Counter)
    for outcome in outcomes:
        name = truth_name(outcome.label.class_id)
        count_by_class[name] += 1
        as_limit_by_class[name] += outcome.classification.is_limit
        confusion[name][outcome.classification.label] += 1
    classes = [name for _, name in sorted(GTSRB_LOOKALIKE_NAMES.items())
               if count_by_class[name]]
    return {
        'lookalike_crops': len(outcomes),
        'read_as_limit_rate': _rate(sum(as_limit_by_class.values()), len(outcomes)),
        'per_lookalike_read_as_limit': {name: as_limit_by_class[name] / count_by_class[name]
                                        for name in classes},
        'per_lookalike_count': {name: count_by_class[name] for name in classes},
        'lookalike_confusion': {name: dict(confusion[name].most_common())
                                for name in classes},
    }


def evaluate(folder: Path, classifier: Classifier, limit: int = 0, every: int = 1,
             stop: StopRequest | None = None, progress: bool = False) -> dict[str, Any]:
    """Classify the crops listed in ``folder/labels.csv``; returns the metrics dict.

    Args:
        folder: the data folder.
        classifier: the classifier to measure.
        limit: evaluate at most this many crops (0 = all).
        every: evaluate every Nth listed crop.
        stop: when its ``requested`` turns True, the run ends after the crop in hand
            and the metrics cover the crops done (``partial`` true).
        progress: show progress on stderr.

    Raises:
        TruthFileError: labels.csv is missing, empty or malformed.
    """
    labels, skipped = read_labels(folder, include_lookalikes=True)
    labels = labels[::max(1, every)]
    if limit > 0:
        labels = labels[:limit]
    outcomes: list[CropOutcome] = []
    unreadable: list[UnreadableImage] = []
    bar = ItemProgress(len(labels), 'crops', 'crop', enabled=progress)
    done = 0
    for label in labels:
        if stop is not None and stop.requested:
            break
        try:
            crop = read_gray_image(label.path)
        except UnreadableImageError as err:
            unreadable.append(UnreadableImage(_relative_name(label.path, folder), str(err)))
        else:
            start = time.perf_counter()
            result = classifier.classify_crop(crop)
            outcomes.append(CropOutcome(label, result, time.perf_counter() - start))
        done += 1
        bar.update()
    bar.close()
    limit_outcomes = [outcome for outcome in outcomes if not outcome.label.is_lookalike]
    metrics = limit_class_metrics(limit_outcomes)
    metrics.update(lookalike_metrics([outcome for outcome in outcomes
                                      if outcome.label.is_lookalike]))
    metrics.update({
        'skipped': skipped,
        'unreadable': [asdict(item) for item in unreadable],
        'crops_planned': len(labels),
        'crops_done': done,
        'partial': done < len(labels),
        'ms_per_crop': _rate(1000.0 * sum(outcome.seconds for outcome in outcomes),
                             len(outcomes)),
        'bank_build_s': classifier.build_time_s,
        'bank_mb': classifier.bank_nbytes / 1e6,
        'framing': classifier.config.crop_framing,
    })
    return metrics


def _relative_name(path: Path, folder: Path) -> str:
    try:
        return path.relative_to(folder).as_posix()
    except ValueError:
        return str(path)


def _fraction(value: float | None) -> str:
    return '-' if value is None else f'{value:.3f}'


def format_summary(metrics: dict[str, Any]) -> str:
    """The human-readable summary of :func:`evaluate`'s metrics."""
    lines = []
    if metrics['crops']:
        ms_per_crop = metrics['ms_per_crop']
        lines.append(f"limit-class crops {metrics['crops']}  accuracy "
                     f"{_fraction(metrics['accuracy'])}  wrong limit "
                     f"{_fraction(metrics['wrong_limit_rate'])}"
                     + (f'  {ms_per_crop:.2f} ms/crop' if ms_per_crop is not None else ''))
        for name, value in metrics['per_class'].items():
            lines.append(f'  {name:>13}: {value:.3f} right, '
                         f'{metrics["per_class_wrong_limit"][name]:.3f} wrong limit '
                         f'({metrics["per_class_count"][name]} crops)')
        lines.append('  by size: ' + ', '.join(
            f'{k} px {v:.3f}' for k, v in metrics['accuracy_by_size_px'].items()))
    if metrics['lookalike_crops']:
        lines.append(f"look-alike crops {metrics['lookalike_crops']}  read as a limit "
                     f"{_fraction(metrics['read_as_limit_rate'])}")
        for name, value in metrics['per_lookalike_read_as_limit'].items():
            lines.append(f'  {name:>27}: {value:.3f} read as a limit '
                         f'({metrics["per_lookalike_count"][name]} crops)')
    if metrics['skipped']:
        lines.append(f"skipped {metrics['skipped']} rows of other classes")
    if metrics['unreadable']:
        lines.append(f"UNREADABLE {len(metrics['unreadable'])} files (skipped):")
        lines.extend(f"  {item['file']}: {item['reason']}" for item in metrics['unreadable'])
    if metrics['partial']:
        lines.append(f"PARTIAL: interrupted after {metrics['crops_done']} of "
                     f"{metrics['crops_planned']} crops")
    return '\n'.join(lines)


def run(args: argparse.Namespace) -> int:
    """Entry of the subcommand; returns the exit status."""
    folder = Path(args.folder)
    if not folder.is_dir():
        raise TruthFileError(f'{folder} is not a folder (expected one holding labels.csv)')
    read_labels(folder, include_lookalikes=True)   # a bad labels.csv fails before the banks
    config = load_yaml(args.config).classifier if args.config else ClassifierConfig()
    if args.framing is not None:
        config = replace(config, crop_framing=args.framing)
    classifier = Classifier(config)
    _LOG.info('filter banks: %d sizes, %.1f MB, built in %.2f s', len(classifier.banks),
              classifier.bank_nbytes / 1e6, classifier.build_time_s)
    with stop_on_interrupt('speed_sign_eval crops') as stop:
        metrics = evaluate(folder, classifier, limit=args.limit, every=args.every,
                           stop=stop, progress=not args.quiet)
    if args.json:
        print(json.dumps(metrics))
    else:
        print(format_summary(metrics))
    if metrics['unreadable']:
        print(f"speed_sign_eval crops: {len(metrics['unreadable'])} crop file(s) could not be "
              f"read and were skipped (listed under 'unreadable')", file=sys.stderr)
    if metrics['partial']:
        return EXIT_INTERRUPTED
    return 1 if metrics['unreadable'] else 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``crops`` subcommand."""
    parser = subparsers.add_parser(
        'crops', help='classification accuracy on GTSRB-format crops (DIR/labels.csv)',
        description='Classify every crop listed in DIR/labels.csv (GTSRB format: '
        f'{LABELS_HEADER}). Limit classes 0-8: accuracy and wrong-limit rate, overall and '
        'per class. Round look-alikes (classes 9, 10, 15, 16, 17, 32-42): the share read '
        'as a speed limit. Crops may frame the sign with a margin (as GTSRB does) or '
        'tightly (the box is the sign): --framing or classifier.crop_framing (auto by '
        'default) says which. Unreadable crop files are skipped, listed, and make the exit '
        'status 1; Ctrl-C reports the crops done, marked partial (exit status 130).')
    parser.add_argument('folder', metavar='DIR', help='folder holding labels.csv and the crops')
    parser.add_argument('--config', help='ROS 2 parameter YAML file of the node (its '
                        'classifier section is used)')
    parser.add_argument('--framing', choices=CROP_FRAMINGS, default=None,
                        help='how the crops frame their sign (overrides '
                        'classifier.crop_framing; default: the config\'s, auto): margin '
                        '(GTSRB: 10%% of the sign, at least 5 px), tight (the box is the '
                        'sign), padded (10%%, no least margin), auto (any)')
    parser.add_argument('--json', action='store_true', help='print one JSON object as the '
                        'last line on stdout (instead of the summary)')
    parser.add_argument('--limit', type=non_negative_integer, default=0,
                        help='evaluate at most N crops (default 0 = all)')
    parser.add_argument('--every', type=positive_integer, default=1,
                        help='evaluate every Nth listed crop (default 1 = all)')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress on stderr')
    parser.set_defaults(run=run)
