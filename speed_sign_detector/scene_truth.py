"""Ground truth of GTSDB-format scene folders: the signs of each image and how a
detector's candidate is matched to them.

A scene folder holds ``images/`` and a GTSDB ``gt.txt`` (``file;x1;y1;x2;y2;classId`` per
sign, box corners in pixels, class ids as in GTSRB). A candidate lies on a sign when its
centre is within ``max(3 px, 0.35 r)`` of the box centre, ``r = (w + h) / 4``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import TruthFileError
from speed_sign_detector.recognition.classifier import Classification

__all__ = ['SCENE_IMAGE_SUFFIXES', 'SPEED_LIMIT_CLASSES', 'SceneSign', 'count_false_limits',
           'is_found', 'is_recognized', 'matching_candidate', 'read_gtsdb_truth',
           'scene_image_files']

#: GTSDB class id -> speed limit in km/h (class 6, end of 80, is not a limit).
SPEED_LIMIT_CLASSES: dict[int, int] = {0: 20, 1: 30, 2: 50, 3: 60, 4: 70, 5: 80, 7: 100,
                                       8: 120}


@dataclass(frozen=True)
class SceneSign:
    """One sign of a GTSDB scene.

    Attributes:
        file: image file name (relative to ``images/``).
        x1_px, y1_px, x2_px, y2_px: its box, pixels.
        class_id: GTSDB class id.
    """

    file: str
    x1_px: float
    y1_px: float
    x2_px: float
    y2_px: float
    class_id: int

    @property
    def centre_px(self) -> tuple[float, float]:
        """Box centre (x, y), pixels."""
        return 0.5 * (self.x1_px + self.x2_px), 0.5 * (self.y1_px + self.y2_px)

    @property
    def radius_px(self) -> float:
        """``(w + h) / 4``, pixels."""
        return 0.25 * ((self.x2_px - self.x1_px) + (self.y2_px - self.y1_px))

    @property
    def limit_kmh(self) -> int:
        """Speed limit of the sign, km/h; 0 when it is not a speed-limit sign."""
        return SPEED_LIMIT_CLASSES.get(self.class_id, 0)


def read_gtsdb_truth(path: Path) -> dict[str, list[SceneSign]]:
    """Read a GTSDB ``gt.txt``: signs per image file.

    Raises:
        TruthFileError: missing file or a malformed line (named with its number).
    """
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as err:
        raise TruthFileError(f'cannot read GTSDB truth file {path}: {err}') from err
    signs: dict[str, list[SceneSign]] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.strip().split(';')
        if len(fields) != 6:
            raise TruthFileError(f'{path}:{number}: expected file;x1;y1;x2;y2;classId, '
                                 f'got {line!r}')
        try:
            x1, y1, x2, y2 = (float(value) for value in fields[1:5])
            class_id = int(fields[5])
        except ValueError as err:
            raise TruthFileError(f'{path}:{number}: not a number in {line!r}') from err
        if x2 <= x1 or y2 <= y1:
            raise TruthFileError(f'{path}:{number}: empty box in {line!r}')
        signs.setdefault(fields[0], []).append(SceneSign(fields[0], x1, y1, x2, y2, class_id))
    return signs


def matching_candidate(sign: SceneSign, candidates: Sequence[Candidate]) -> Candidate | None:
    """The best candidate whose centre lies within ``max(3, 0.35 r)`` px of the sign's centre."""
    x, y = sign.centre_px
    tolerance = max(3.0, 0.35 * sign.radius_px)
    return next((c for c in candidates if math.hypot(c.x_px - x, c.y_px - y) <= tolerance),
                None)


def count_false_limits(signs: Sequence[SceneSign], candidates: Sequence[Candidate],
                       classifications: Sequence[Classification]) -> int:
    """Candidates read as a limit that lie on no speed-limit sign of that value."""
    false_limits = 0
    for candidate, classification in zip(candidates, classifications):
        if classification.limit_kmh is None:
            continue
        on_signs = [sign for sign in signs if matching_candidate(sign, [candidate])]
        if not any(sign.limit_kmh == classification.limit_kmh for sign in on_signs):
            false_limits += 1
    return false_limits


def is_recognized(sign: SceneSign, candidates: Sequence[Candidate],
                  classifications: Sequence[Classification]) -> bool:
    """True when a candidate on the limit ``sign`` is classified as its limit."""
    return any(classification.limit_kmh == sign.limit_kmh
               and matching_candidate(sign, [candidate]) is not None
               for candidate, classification in zip(candidates, classifications))


def is_found(sign: SceneSign, candidates: Sequence[Candidate]) -> bool:
    """True when a candidate centre lies within ``max(3, 0.35 r)`` px of the sign's centre."""
    return matching_candidate(sign, candidates) is not None


#: Image file suffixes of a scene folder's ``images/``.
SCENE_IMAGE_SUFFIXES: tuple[str, ...] = ('.jpg', '.jpeg', '.png', '.ppm')


def scene_image_files(directory: Path) -> list[str]:
    """The sorted image file names of ``directory/images``.

    Raises:
        TruthFileError: when there is no ``images/`` folder.
    """
    image_dir = directory / 'images'
    if not image_dir.is_dir():
        raise TruthFileError(f'{directory} has no images/ folder')
    return sorted(path.name for path in image_dir.iterdir()
                  if path.suffix.lower() in SCENE_IMAGE_SUFFIXES)
