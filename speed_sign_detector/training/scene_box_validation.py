"""Annotated scene boxes read as crops by scene-fold banks: another camera's crops, held out.

``speed_sign_train validate ... --scenes SCENE_DIR --boxes`` measures each scene fold's bank
(:func:`.scene_validation.cross_validate_scenes`: every crop and the other folds' scenes)
also on the annotated boxes of its own fold's scenes, cut out as crops and read with
:meth:`~speed_sign_detector.recognition.classifier.Classifier.classify_crop` (the
classifier's ``crop_framing``), as ``speed_sign_eval crops`` reads a crop folder. GTSDB
scenes come from another camera than the GTSRB crops the banks mostly learned from, and
no bank reads a scene it trained on: the nearest dev-data stand-in for crops of another
camera.

Each box is cut two ways (:data:`BOX_CUTS`):

- ``tight``: the annotated box, as a detector or a labelling tool gives it;
- ``padded``: the box grown by :data:`PADDING_SHARE` of its width and height on every
  side (clamped to the image), as tools that pad boxes in proportion cut them.

Per cut: the limit signs read right, read as another limit (the dangerous error, with
the confusions named) and withheld; the round signs that are not limits (GTSRB's
look-alike classes and the end of 80) read as a limit.
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.labelled_crops import GTSRB_END_OF_80, GTSRB_LOOKALIKE_NAMES
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.trained_bank import TrainedBank
from speed_sign_detector.scene_truth import SceneSign
from speed_sign_detector.training.scene_examples import DetectedScene, read_scene_gray

__all__ = ['BOXES_KEY', 'BOX_CUTS', 'PADDING_SHARE', 'SceneBoxFolds', 'box_crop',
           'format_boxes_line']

_LOG = logging.getLogger(__name__)

#: The key of the box figures in the scene folds' report.
BOXES_KEY = 'boxes'
#: How each box is cut (see the module docstring).
BOX_CUTS = ('tight', 'padded')
#: The padded cut's margin on every side, a share of the box's width (height).
PADDING_SHARE = 0.1
#: GTSDB classes (the same ids as GTSRB's) of round signs that are not limits.
NOT_LIMIT_ROUND_CLASSES = frozenset(GTSRB_LOOKALIKE_NAMES) | {GTSRB_END_OF_80}
#: The smallest crop side read, pixels (smaller boxes are skipped and counted).
MIN_CROP_PX = 4


def box_crop(gray: np.ndarray, sign: SceneSign, cut: str) -> np.ndarray | None:
    """The (h, w) uint8 crop of ``sign``'s box in an (H, W) uint8 scene, cut as ``cut``
    (``'tight'`` or ``'padded'``, clamped to the image); ``None`` when it is narrower or
    lower than :data:`MIN_CROP_PX` pixels.

    Raises:
        ValueError: an unknown cut.
    """
    if cut not in BOX_CUTS:
        raise ValueError(f'unknown box cut {cut!r} (one of {", ".join(BOX_CUTS)})')
    margin = PADDING_SHARE if cut == 'padded' else 0.0
    width, height = sign.x2_px - sign.x1_px, sign.y2_px - sign.y1_px
    left = max(0, math.floor(sign.x1_px - margin * width))
    top = max(0, math.floor(sign.y1_px - margin * height))
    right = min(gray.shape[1], math.ceil(sign.x2_px + margin * width) + 1)
    bottom = min(gray.shape[0], math.ceil(sign.y2_px + margin * height) + 1)
    if right - left < MIN_CROP_PX or bottom - top < MIN_CROP_PX:
        return None
    return np.ascontiguousarray(gray[top:bottom, left:right])


class SceneBoxFolds:
    """Reads each scene fold's annotated boxes with that fold's bank (module docstring).

    A :class:`~speed_sign_detector.training.scene_validation.SceneFoldMeasure`: the scene
    folds call :meth:`measure_fold` once per fold; :meth:`summary` sums the folds.

    Args:
        classifier_config: the classifier that uses each fold's bank (its
            ``crop_framing`` frames the crops).
    """

    key = BOXES_KEY

    def __init__(self, classifier_config: ClassifierConfig = ClassifierConfig()  # noqa: B008
                 ) -> None:
        self.classifier_config = classifier_config
        self.per_fold: list[dict[str, Any]] = []

    def measure_fold(self, fold: int, bank: TrainedBank, scenes: Sequence[DetectedScene]
                     ) -> None:
        """Read the annotated boxes of ``scenes`` with ``bank``, trained without them."""
        classifier = Classifier(self.classifier_config, bank)
        counts = {cut: Counter() for cut in BOX_CUTS}
        confusions = {cut: Counter() for cut in BOX_CUTS}
        unreadable: list[str] = []
        for scene in scenes:
            if not scene.signs:
                continue
            gray = read_scene_gray(scene.path)
            if gray is None:
                unreadable.append(f'{scene.path}: not a readable image')
                continue
            for sign in scene.signs:
                kind = _kind(sign)
                if kind is None:
                    continue
                for cut in BOX_CUTS:
                    crop = box_crop(gray, sign, cut)
                    if crop is None:
                        counts[cut]['too_small'] += 1
                        continue
                    answer = classifier.classify_crop(crop).label
                    _count(counts[cut], confusions[cut], sign, kind, answer)
        figures = {'fold': fold, 'unreadable': unreadable,
                   **{cut: _figures(counts[cut], confusions[cut]) for cut in BOX_CUTS}}
        self.per_fold.append(figures)
        _LOG.info('scene fold %d boxes: tight %d/%d right, %d another limit; padded %d/%d '
                  'right, %d another limit', fold, figures['tight']['right'],
                  figures['tight']['limit_signs'], figures['tight']['wrong_limits'],
                  figures['padded']['right'], figures['padded']['limit_signs'],
                  figures['padded']['wrong_limits'])

    def summary(self) -> dict[str, Any]:
        """The figures of every fold measured, summed per cut (see :func:`_figures`),
        with ``'per_fold'``, ``'unreadable'`` and the ``'padding_share'``."""
        summed: dict[str, Any] = {'folds': len(self.per_fold), 'padding_share': PADDING_SHARE,
                                  'unreadable': [line for row in self.per_fold
                                                 for line in row['unreadable']]}
        for cut in BOX_CUTS:
            counts: Counter[str] = Counter()
            confusions: Counter[str] = Counter()
            for row in self.per_fold:
                counts.update({key: row[cut][key] for key in _COUNT_KEYS})
                confusions.update(row[cut]['another_limit'])
            summed[cut] = _figures(counts, confusions)
        summed['per_fold'] = self.per_fold
        return summed


_COUNT_KEYS = ('limit_signs', 'right', 'wrong_limits', 'withheld', 'lookalikes',
               'lookalikes_read_as_limit', 'too_small')


def _kind(sign: SceneSign) -> str | None:
    """``'limit'``, ``'not_limit'`` (a round sign that is not a limit) or None (the other
    signs, not measured)."""
    if sign.limit_kmh:
        return 'limit'
    if sign.class_id in NOT_LIMIT_ROUND_CLASSES:
        return 'not_limit'
    return None


def _count(counts: Counter[str], confusions: Counter[str], sign: SceneSign, kind: str,
           answer: str) -> None:
    if kind == 'limit':
        counts['limit_signs'] += 1
        if answer == str(sign.limit_kmh):
            counts['right'] += 1
        elif answer.isdigit():
            counts['wrong_limits'] += 1
            confusions[f'{sign.limit_kmh} as {answer}'] += 1
        else:
            counts['withheld'] += 1
    else:
        counts['lookalikes'] += 1
        counts['lookalikes_read_as_limit'] += answer.isdigit()


def _figures(counts: Counter[str], confusions: Counter[str]) -> dict[str, Any]:
    """Counts of one cut (:data:`_COUNT_KEYS`) with ``accuracy``, ``wrong_limit_rate``
    and ``lookalikes_read_as_limit_rate`` (None over nothing) and ``another_limit``
    (``'80 as 60'`` -> count)."""
    figures: dict[str, Any] = {key: int(counts[key]) for key in _COUNT_KEYS}
    limits, lookalikes = figures['limit_signs'], figures['lookalikes']
    figures['accuracy'] = figures['right'] / limits if limits else None
    figures['wrong_limit_rate'] = figures['wrong_limits'] / limits if limits else None
    figures['lookalikes_read_as_limit_rate'] = (
        figures['lookalikes_read_as_limit'] / lookalikes if lookalikes else None)
    figures['another_limit'] = dict(sorted(confusions.items()))
    return figures


def format_boxes_line(figures: dict[str, Any], folds: int) -> str:
    """One line of the box figures (``speed_sign_train validate`` prints it)."""
    parts = []
    for cut in BOX_CUTS:
        row = figures[cut]
        parts.append(f'{cut} {row["right"]}/{row["limit_signs"]} right, {row["wrong_limits"]} '
                     f'another limit, {row["lookalikes_read_as_limit"]} of '
                     f'{row["lookalikes"]} look-alikes read as a limit')
    return (f'scene boxes read as crops, {folds} folds by scene (each by the bank of its '
            f'scenes\' fold): ' + '; '.join(parts))
