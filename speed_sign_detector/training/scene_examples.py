"""Second-opinion training examples cut from annotated real scenes (GTSDB format).

Crops show the second opinion what signs look like, but not what the detector finds on
a real road that is *not* a sign (wheels, windows, foliage, lamps), nor how a sign of
5-10 px radius looks in a whole frame. Scenes teach both. For each image of a scene folder
(``images/`` and ``gt.txt``, :mod:`speed_sign_detector.scene_truth`):

1. the detector proposes its candidates, as at run time;
2. the rendered-only classifier locates a sign at each, with the run-time positions
   (the candidate radius times ``candidate_radius_scale``, and for large candidates
   also the larger-size retry's; :func:`classification_positions`);
3. every located sign becomes an example: the label of the annotated sign it lies on
   (:data:`~speed_sign_detector.labelled_crops.GTSRB_CLASS_NAMES`, other
   annotated classes ``'other_sign'``), or :data:`SCENE_BACKGROUND_LABEL` where it lies
   on none. A located size far from the annotated one is left out (neither sign nor
   background). Degraded, jittered copies follow each example, as for crops.

The second opinion answers "not a sign" where it reads :data:`SCENE_BACKGROUND_LABEL`
(a label no correlation filter ranks, so the answer is withheld).

Validation splits scenes in contiguous blocks of their sorted names (:func:`scene_folds`):
neighbouring frames of one drive, which may show the same physical sign, stay together.
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.errors import InvalidFrameError, TrainingDataError, TruthFileError
from speed_sign_detector.image_files import UnreadableImageError, read_gray_image
from speed_sign_detector.labelled_crops import GTSRB_CLASS_NAMES
from speed_sign_detector.recognition.classifier import Classifier, CorrelationEvidence
from speed_sign_detector.recognition.sign_features import (
    FEATURE_SIZE,
    aligned_patches,
    sign_features,
)
from speed_sign_detector.scene_truth import SceneSign, read_gtsdb_truth, scene_image_files
from speed_sign_detector.training.degradation import degraded, jittered

__all__ = ['MAX_RADIUS_ERROR', 'SCENE_BACKGROUND_LABEL', 'DetectedScene', 'SceneExamples',
           'classification_positions', 'detect_scenes', 'read_scene_examples',
           'read_scene_gray', 'scene_examples_of_image', 'scene_folds', 'scene_label']

_LOG = logging.getLogger(__name__)

#: The second opinion's label for a located "sign" that lies on no annotated sign.
SCENE_BACKGROUND_LABEL = 'no_sign'
#: A located sign whose radius differs from the annotated sign's by more than this share
#: of it is left out of training (a ring, the digits or a neighbour, not the sign).
MAX_RADIUS_ERROR = 0.35
#: Called with (done, total) as scenes are processed.
ProgressCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class SceneExamples:
    """Labelled second-opinion feature rows cut from scenes.

    Attributes:
        scenes: (N,) the scene of each row, ``'FOLDER/FILE'``.
        labels: (N,) the label of each row.
        features: (N, FEATURE_SIZE) float32 second-opinion features
            (:func:`~speed_sign_detector.recognition.sign_features.sign_features`).
        unreadable: scene images that could not be used, ``'path: reason'``.
    """

    scenes: tuple[str, ...]
    labels: tuple[str, ...]
    features: np.ndarray
    unreadable: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not (len(self.scenes) == len(self.labels) == len(self.features)) \
                or self.features.ndim != 2 or self.features.shape[1] != FEATURE_SIZE:
            raise ValueError(f'scene examples need one scene and label per (N, {FEATURE_SIZE})'
                             f' feature row; got {len(self.scenes)} scenes, '
                             f'{len(self.labels)} labels, features {self.features.shape}')

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, keep_scenes: set[str]) -> SceneExamples:
        """The rows of the scenes in ``keep_scenes``."""
        rows = [i for i, scene in enumerate(self.scenes) if scene in keep_scenes]
        return SceneExamples(tuple(self.scenes[i] for i in rows),
                             tuple(self.labels[i] for i in rows), self.features[rows],
                             self.unreadable)

    def counts(self) -> dict[str, int]:
        """Rows per label (copies included)."""
        return dict(sorted(Counter(self.labels).items()))


def scene_label(signs: Sequence[SceneSign], x_px: float, y_px: float, radius_px: float
                ) -> str | None:
    """The training label of a sign located at (x, y) with ``radius_px``.

    Returns:
        The label of the nearest annotated sign whose centre lies within
        ``max(3, 0.35 r)`` px, :data:`SCENE_BACKGROUND_LABEL` where there is none, or
        ``None`` where the located size is off by more than :data:`MAX_RADIUS_ERROR`.
    """
    near = [(math.hypot(sign.centre_px[0] - x_px, sign.centre_px[1] - y_px), sign)
            for sign in signs]
    near = [(distance, sign) for distance, sign in near
            if distance <= max(3.0, 0.35 * sign.radius_px)]
    if not near:
        return SCENE_BACKGROUND_LABEL
    sign = min(near, key=lambda pair: pair[0])[1]
    if abs(radius_px - sign.radius_px) > MAX_RADIUS_ERROR * sign.radius_px:
        return None
    return GTSRB_CLASS_NAMES.get(sign.class_id, 'other_sign')


def classification_positions(candidates: Sequence[Candidate], classifier: Classifier
                             ) -> list[tuple[float, float, float]]:
    """The (x, y, radius) positions, pixels, at which :meth:`Classifier.classify` may
    correlate the candidates: each at its scaled radius, and the large ones also at the
    larger-size retry's radius."""
    return (classifier.candidate_positions(candidates)
            + classifier.candidate_positions(
                [c for c in candidates if classifier.may_retry_larger(c)], retry=True))


def scene_examples_of_image(gray: np.ndarray, signs: Sequence[SceneSign],
                            candidates: Sequence[Candidate], classifier: Classifier,
                            copies: int, rng: np.random.Generator
                            ) -> tuple[list[str], list[np.ndarray]]:
    """The labelled examples of one (H, W) uint8 scene.

    Returns:
        (labels, features): one label and one (1 + copies, FEATURE_SIZE) array per located
        sign: its features, then those of ``copies`` degraded, jittered copies.
    """
    labels: list[str] = []
    features: list[np.ndarray] = []
    positions = classification_positions(candidates, classifier)
    for evidence in classifier.evidence_for_candidates(gray, positions):
        if not isinstance(evidence, CorrelationEvidence):
            continue
        sign = np.asarray([evidence.x_px, evidence.y_px, evidence.radius_px])
        label = scene_label(signs, *sign)
        if label is None:
            continue
        patches = [aligned_patches(gray, sign[None])]
        # the copies are degraded from a window around the sign, not the whole frame
        reach = int(3 * evidence.radius_px) + 8
        left, top = max(0, int(sign[0]) - reach), max(0, int(sign[1]) - reach)
        window = gray[top:int(sign[1]) + reach, left:int(sign[0]) + reach]
        in_window = sign - np.asarray([left, top, 0.0])
        for _ in range(copies):
            patches.append(aligned_patches(degraded(window, rng), jittered(in_window, rng)[None]))
        labels.append(label)
        features.append(sign_features(np.concatenate(patches)))
    return labels, features


@dataclass(frozen=True)
class DetectedScene:
    """One scene image with its annotated signs and the detector's candidates.

    Attributes:
        key: ``'FOLDER/FILE'``, the scene's name in :class:`SceneExamples`.
        path: the image file.
        signs: the annotated signs.
        candidates: the detector's candidates, frame pixels.
    """

    key: str
    path: Path
    signs: tuple[SceneSign, ...]
    candidates: tuple[Candidate, ...]


def read_scene_gray(path: Path) -> np.ndarray | None:
    """The (H, W) uint8 gray image, or ``None`` where it cannot be read (decoded from the
    file's bytes, as the evaluation tools do: OpenCV prints no warning of its own)."""
    try:
        return read_gray_image(path)
    except UnreadableImageError:
        return None


def detect_scenes(folders: Sequence[Path],
                  detector_config: DetectorConfig = DetectorConfig(),  # noqa: B008 (frozen)
                  backend: str = 'auto', progress: ProgressCallback | None = None
                  ) -> tuple[list[DetectedScene], list[str]]:
    """Run the detector on every scene of the GTSDB-format ``folders``.

    Returns:
        (scenes, unreadable): the detected scenes, and the images that could not be used
        (``'path: reason'``, skipped).

    Raises:
        TrainingDataError: a folder without a readable ``gt.txt`` or ``images/``.
    """
    work: list[tuple[Path, str, tuple[SceneSign, ...]]] = []
    for folder in folders:
        folder = Path(folder)
        try:
            truth = read_gtsdb_truth(folder / 'gt.txt')
            files = scene_image_files(folder)
        except TruthFileError as err:
            raise TrainingDataError(f'scene folder {folder}: {err}') from err
        work += [(folder, name, tuple(truth.get(name, ()))) for name in files]
    scenes: list[DetectedScene] = []
    unreadable: list[str] = []
    with Detector(detector_config, backend=backend) as detector:
        for done, (folder, name, signs) in enumerate(work, start=1):
            path = folder / 'images' / name
            gray = read_scene_gray(path)
            try:
                if gray is None:
                    raise InvalidFrameError('not a readable image')
                candidates = tuple(detector.detect(gray))
            except InvalidFrameError as err:  # e.g. smaller than the voting window
                unreadable.append(f'{path}: {err}')
                _LOG.warning('skipped scene image %s: %s', path, err)
            else:
                scenes.append(DetectedScene(f'{folder}/{name}', path, signs, candidates))
            if progress is not None:
                progress(done, len(work))
    return scenes, unreadable


def read_scene_examples(scenes: Sequence[DetectedScene], classifier: Classifier,
                        copies: int = 2, seed: int = 0, unreadable: Sequence[str] = ()
                        ) -> SceneExamples:
    """The examples of detected ``scenes`` (see the module docstring).

    Args:
        scenes: from :func:`detect_scenes`.
        classifier: the rendered-only classifier that locates the signs.
        copies: degraded, jittered copies of each example.
        seed: seeds the copies.
        unreadable: images already skipped, recorded with the examples.
    """
    rng = np.random.default_rng(seed)
    keys: list[str] = []
    labels: list[str] = []
    rows: list[np.ndarray] = []
    skipped = list(unreadable)
    for scene in scenes:
        gray = read_scene_gray(scene.path)
        if gray is None:
            skipped.append(f'{scene.path}: not a readable image')
            continue
        found, features = scene_examples_of_image(gray, scene.signs, scene.candidates,
                                                  classifier, copies, rng)
        for label, block in zip(found, features):
            keys += [scene.key] * len(block)
            labels += [label] * len(block)
            rows.append(block)
    matrix = np.concatenate(rows).astype(np.float32) if rows else \
        np.zeros((0, FEATURE_SIZE), np.float32)
    return SceneExamples(tuple(keys), tuple(labels), matrix, tuple(skipped))


def scene_folds(scenes: Sequence[str], folds: int) -> dict[str, int]:
    """Fold of each distinct scene: contiguous blocks of the sorted names (neighbouring
    frames of a drive stay on one side).

    Raises:
        ValueError: for fewer than two folds, or fewer scenes than folds.
    """
    names = sorted(set(scenes))
    if folds < 2 or len(names) < folds:
        raise ValueError(f'need at least 2 folds and one scene per fold; got {folds} folds '
                         f'for {len(names)} scenes')
    return {name: (index * folds) // len(names) for index, name in enumerate(names)}
