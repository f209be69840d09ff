"""Labelled sign crops in the GTSRB format, and splits that keep physical signs apart.

A crop folder holds ``labels.csv`` (``;``-separated, header
``Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId``) and the images it names.
GTSRB file names are ``CLASS/TRACK_INDEX.png``: the images of one track are the same
physical sign seen from an approaching car, so a fair split never puts one track on both
sides (:func:`track_folds`).
"""
from __future__ import annotations

import csv
import logging
import zlib
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from speed_sign_detector.errors import TrainingDataError

__all__ = ['GTSRB_CLASS_NAMES', 'GTSRB_END_OF_80', 'GTSRB_LIMITS_KMH', 'GTSRB_LOOKALIKE_NAMES',
           'LABELS_HEADER', 'LabelRow', 'LabelledCrop', 'read_crop_folder',
           'read_label_rows', 'track_folds']

_LOG = logging.getLogger(__name__)

#: GTSRB class id -> speed limit in km/h (class 6, end of 80, has none).
GTSRB_LIMITS_KMH: dict[int, int] = {0: 20, 1: 30, 2: 50, 3: 60, 4: 70, 5: 80, 7: 100, 8: 120}
#: GTSRB class id of the end-of-80 sign.
GTSRB_END_OF_80 = 6
#: GTSRB class id -> name of the round signs that are NOT speed limits (look-alikes).
GTSRB_LOOKALIKE_NAMES: dict[int, str] = {
    9: 'no_passing', 10: 'no_passing_over_3.5t', 15: 'no_vehicles',
    16: 'no_vehicles_over_3.5t', 17: 'no_entry', 32: 'end_of_all_limits',
    33: 'turn_right_ahead', 34: 'turn_left_ahead', 35: 'ahead_only', 36: 'ahead_or_right',
    37: 'ahead_or_left', 38: 'keep_right', 39: 'keep_left', 40: 'roundabout',
    41: 'end_of_no_passing', 42: 'end_of_no_passing_over_3.5t'}
#: GTSRB class id of the end of all speed and passing limits (VZ 282): it ends the limit
#: in force too, so it is read as an end of limit.
GTSRB_END_OF_ALL_LIMITS = 32
#: GTSRB class id -> the classifier's label for it: the limit in km/h as a string,
#: ``'end_of_limit'`` (the end of 80 and the end of all limits), or ``'other_sign'`` for
#: the other round look-alikes (negatives).
GTSRB_CLASS_NAMES: dict[int, str] = {
    **{class_id: str(limit) for class_id, limit in GTSRB_LIMITS_KMH.items()},
    **{class_id: 'other_sign' for class_id in GTSRB_LOOKALIKE_NAMES},
    GTSRB_END_OF_80: 'end_of_limit', GTSRB_END_OF_ALL_LIMITS: 'end_of_limit'}


@dataclass(frozen=True)
class LabelledCrop:
    """One row of ``labels.csv``.

    Attributes:
        path: the image file.
        roi: (x1, y1, x2, y2) inclusive corners of the sign's box inside the crop, pixels.
        class_id: GTSRB class id.
        track: the physical sign: folder and track number (``'00001/00012'``).
    """

    path: Path
    roi: tuple[int, int, int, int]
    class_id: int
    track: str

    @property
    def label(self) -> str:
        """The classifier's label for this crop's class (:data:`GTSRB_CLASS_NAMES`)."""
        return GTSRB_CLASS_NAMES[self.class_id]


def _track_of(filename: str) -> str:
    """``'00001/00012_00029.png'`` -> ``'00001/00012'`` (folder and track number)."""
    path = Path(filename)
    return f'{path.parent.as_posix()}/{path.stem.split("_")[0]}'


#: The header of ``labels.csv``.
LABELS_HEADER = 'Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId'


@dataclass(frozen=True)
class LabelRow:
    """One row of ``labels.csv``: the file name (relative to the folder), the sign's box
    (x1, y1, x2, y2, inclusive corners, pixels) and the GTSRB class id."""

    filename: str
    roi: tuple[int, int, int, int]
    class_id: int


def read_label_rows(folder: Path) -> list[LabelRow]:
    """Every row of ``folder/labels.csv``, whatever its class.

    Raises:
        TrainingDataError: when the file is missing, empty, has no rows, or a row is
            malformed (the row is named).
    """
    path = Path(folder) / 'labels.csv'
    try:
        with path.open(newline='') as handle:
            text = handle.read()
    except (OSError, UnicodeDecodeError) as err:
        raise TrainingDataError(f'cannot read {path}: {err}') from err
    if not text.strip():
        raise TrainingDataError(f'{path} is empty: expected the header {LABELS_HEADER} and '
                                'one row per crop')
    try:
        rows = list(csv.DictReader(text.splitlines(), delimiter=';'))
    except csv.Error as err:
        raise TrainingDataError(f'{path} is not a ;-separated table: {err}') from err
    if not rows:
        raise TrainingDataError(f'{path} has a header but no rows (one row per crop '
                                'expected)')
    parsed: list[LabelRow] = []
    for number, row in enumerate(rows, start=2):
        try:
            parsed.append(LabelRow(row['Filename'], (int(row['Roi.X1']), int(row['Roi.Y1']),
                                                     int(row['Roi.X2']), int(row['Roi.Y2'])),
                                   int(row['ClassId'])))
        except (KeyError, TypeError, ValueError) as err:
            raise TrainingDataError(f'{path}:{number}: malformed row {row!r} ({err}); '
                                    f'expected {LABELS_HEADER}') from err
    return parsed


def read_crop_folder(folder: Path) -> list[LabelledCrop]:
    """The crops of ``folder/labels.csv`` of the classes the package has a label for
    (:data:`GTSRB_CLASS_NAMES`). Rows of other classes are skipped and logged.

    Raises:
        TrainingDataError: when the file is missing, empty or malformed.
    """
    crops: list[LabelledCrop] = []
    skipped: Counter[int] = Counter()
    for row in read_label_rows(folder):
        if row.class_id not in GTSRB_CLASS_NAMES:
            skipped[row.class_id] += 1
            continue
        crops.append(LabelledCrop(Path(folder) / row.filename, row.roi, row.class_id,
                                  _track_of(row.filename)))
    if skipped:
        _LOG.info('%s: skipped %d crops of classes %s', folder, sum(skipped.values()),
                  ', '.join(str(class_id) for class_id in sorted(skipped)))
    return crops


def track_folds(crops: Sequence[LabelledCrop], folds: int, seed: int = 0) -> np.ndarray:
    """Fold index of every crop, such that all crops of a track share one fold.

    Tracks are spread over the folds class by class (each fold gets about the same share
    of every class), in an order fixed by ``seed`` and the track names alone.

    Args:
        crops: the labelled crops.
        folds: number of folds (>= 2).
        seed: changes the assignment.

    Returns:
        (len(crops),) int array of fold indices in ``[0, folds)``.
    """
    if folds < 2:
        raise ValueError(f'folds must be >= 2, got {folds}')
    tracks_by_class: dict[int, list[str]] = {}
    for crop in crops:
        tracks = tracks_by_class.setdefault(crop.class_id, [])
        if crop.track not in tracks:
            tracks.append(crop.track)
    fold_of_track: dict[str, int] = {}
    for class_id in sorted(tracks_by_class):
        tracks = sorted(tracks_by_class[class_id],
                        key=lambda name: zlib.crc32(f'{seed}:{name}'.encode()))
        for position, name in enumerate(tracks):
            fold_of_track[name] = position % folds
    return np.asarray([fold_of_track[crop.track] for crop in crops], dtype=np.int64)
