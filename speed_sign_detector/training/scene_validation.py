"""Validation on annotated scenes, k folds by scene.

Each fold's bank is trained by the caller's ``train`` on every crop and on the examples
of the other folds' scenes only (:func:`.scene_examples.scene_folds`: contiguous blocks of
the sorted names); it then classifies the detector's candidates of its own fold's scenes,
which it never saw, one frame at a time as ``speed_sign_eval scenes`` does. The figures
are those of ``speed_sign_eval scenes``: recognition recall over the speed-limit signs and
false limits per frame.

More measurements of each fold's bank on its own fold's scenes join through
:class:`SceneFoldMeasure` (the approach sequences of
:mod:`speed_sign_detector.tools.approach_validation`, which runs the whole pipeline: a
tool, so that this package imports no tool). :func:`validate_by_scene` runs the scene
folds alone, without the k folds by track.
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

from speed_sign_detector.config import ClassifierConfig, DetectorConfig
from speed_sign_detector.errors import TrainingDataError
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.trained_bank import TrainedBank
from speed_sign_detector.scene_truth import count_false_limits, is_recognized
from speed_sign_detector.training.bank_training import (
    ProgressCallback,
    TrainingConfig,
    locate_rendered,
    locate_signs,
    read_crops,
    rendered_classifier,
    scene_examples_of,
    train_from_located,
)
from speed_sign_detector.training.scene_examples import (
    DetectedScene,
    SceneExamples,
    read_scene_gray,
    scene_folds,
)

__all__ = ['SceneFoldMeasure', 'cross_validate_scenes', 'validate_by_scene']

_LOG = logging.getLogger(__name__)


class SceneFoldMeasure(Protocol):
    """A further measurement of each scene fold's bank on that fold's own scenes.

    :func:`cross_validate_scenes` calls :meth:`measure_fold` once per fold, in fold
    order, right after the fold's bank is trained, then puts :meth:`summary` into its
    report under :attr:`key`.
    """

    #: The key of the summary in the scene report (``'approach'``).
    key: str

    def measure_fold(self, fold: int, bank: TrainedBank, scenes: Sequence[DetectedScene]
                     ) -> None:
        """Measure ``bank`` (trained without the fold's scenes) on the fold's scenes.

        Args:
            fold: the fold's index, 0-based.
            bank: the fold's bank: every crop and the other folds' scenes.
            scenes: the fold's scenes (their image files and annotated signs), sorted by
                image file.
        """

    def summary(self) -> dict[str, Any]:
        """The figures over every fold measured (JSON-ready)."""


def cross_validate_scenes(scenes: Sequence[DetectedScene], examples: SceneExamples,
                          folds: int, train: Callable[[SceneExamples], TrainedBank],
                          classifier_config: ClassifierConfig = ClassifierConfig(),  # noqa: B008
                          measures: Sequence[SceneFoldMeasure] = (),
                          ) -> dict[str, Any]:
    """k-fold validation by scene (see the module docstring).

    Args:
        scenes: the detected scenes (:func:`.scene_examples.detect_scenes`).
        examples: their training examples (:func:`.scene_examples.read_scene_examples`).
        folds: number of folds (>= 2, at most one per scene).
        train: trains a bank on every crop and the given scene examples.
        classifier_config: the classifier that uses each fold's bank.
        measures: further measurements of each fold's bank on its fold's scenes.

    Returns:
        ``{'folds', 'frames', 'signs', 'recognized', 'recognition_recall',
        'false_limits', 'false_limits_per_frame', 'fold_recall': [...],
        'fold_false_limits_per_frame': [...]}`` and each measure's summary under its
        key.

    Raises:
        TrainingDataError: fewer scenes than folds.
    """
    try:
        fold_of = scene_folds([scene.key for scene in scenes], folds)
    except ValueError as err:
        raise TrainingDataError(f'cannot validate by scene: {err}') from err
    totals = {'frames': 0, 'signs': 0, 'recognized': 0, 'false_limits': 0}
    fold_recall: list[float] = []
    fold_false: list[float] = []
    for fold in range(folds):
        kept = examples.subset({key for key, scene_fold in fold_of.items() if scene_fold != fold})
        bank = train(kept)
        classifier = Classifier(classifier_config, bank)
        frames = signs = recognized = false_limits = 0
        for scene in scenes:
            if fold_of[scene.key] != fold:
                continue
            gray = read_scene_gray(scene.path)
            if gray is None:
                continue
            answers = classifier.classify(gray, scene.candidates)
            frames += 1
            false_limits += count_false_limits(scene.signs, scene.candidates, answers)
            limit_signs = [sign for sign in scene.signs if sign.limit_kmh]
            signs += len(limit_signs)
            recognized += sum(is_recognized(sign, scene.candidates, answers)
                              for sign in limit_signs)
        _LOG.info('scene fold %d: %d/%d recognized, %d false limits in %d frames', fold,
                  recognized, signs, false_limits, frames)
        fold_recall.append(recognized / signs if signs else 0.0)
        fold_false.append(false_limits / frames if frames else 0.0)
        for key, value in (('frames', frames), ('signs', signs), ('recognized', recognized),
                           ('false_limits', false_limits)):
            totals[key] += value
        fold_scenes = sorted((scene for scene in scenes if fold_of[scene.key] == fold),
                             key=lambda scene: scene.path)
        for measure in measures:
            measure.measure_fold(fold, bank, fold_scenes)
    extra = {measure.key: measure.summary() for measure in measures}
    return {'folds': folds, **totals,
            'recognition_recall': totals['recognized'] / totals['signs']
            if totals['signs'] else 0.0,
            'false_limits_per_frame': totals['false_limits'] / totals['frames']
            if totals['frames'] else 0.0,
            'fold_recall': fold_recall, 'fold_false_limits_per_frame': fold_false, **extra}


def validate_by_scene(folders: Sequence[Path], scene_folders: Sequence[Path], folds: int = 5,
                      classifier_config: ClassifierConfig = ClassifierConfig(),  # noqa: B008
                      config: TrainingConfig = TrainingConfig(),  # noqa: B008 (frozen)
                      progress: ProgressCallback | None = None,
                      detector_config: DetectorConfig = DetectorConfig(),  # noqa: B008
                      backend: str = 'auto', measures: Sequence[SceneFoldMeasure] = ()
                      ) -> dict[str, Any]:
    """The k folds by scene alone: what :func:`.track_validation.cross_validate` reports
    under ``'scenes'``, without its k folds by track (which take most of its time).

    Each fold's bank is trained as there: on every crop, the renderings and the other
    folds' scene examples.

    Args:
        folders: labelled crop folders (GTSRB ``labels.csv`` format).
        scene_folders: annotated scene folders (GTSDB format), at least one.
        folds: number of scene folds (>= 2, at most one per scene).
        classifier_config: the classifier's parameters.
        config: how each bank is trained.
        progress: called with (done, total) as the crops are located.
        detector_config, backend: the detector that finds the scenes' candidates.
        measures: further measurements of each fold's bank (:class:`SceneFoldMeasure`).

    Returns:
        ``{'folds', 'crops', 'unreadable', 'data_folders', 'scene_folders', 'training',
        'scenes'}``, keyed as in :func:`.track_validation.cross_validate`'s report.

    Raises:
        TrainingDataError: for unusable folders, no scene folder, no second opinion
            (``config.second_opinion`` false), or fewer scenes than folds.
    """
    if not scene_folders:
        raise TrainingDataError('validation by scene needs at least one scene folder')
    crops, images, unreadable = read_crops(folders)
    rendered = rendered_classifier(classifier_config)
    located = locate_signs(rendered, crops, images, progress)
    rendered_crops = locate_rendered(rendered, config)
    detected, scenes = scene_examples_of(scene_folders, rendered, detector_config, config,
                                       backend)
    if scenes is None:  # without a second opinion the scenes teach nothing
        raise TrainingDataError('validation by scene trains the second opinion on the other '
                                'folds\' scenes: drop --no-second-opinion')
    report: dict[str, Any] = {
        'folds': folds, 'crops': len(crops), 'data_folders': [str(f) for f in folders],
        'scene_folders': [str(f) for f in scene_folders],
        'training': dataclasses.asdict(config),
        'scenes': cross_validate_scenes(
            detected, scenes, folds, lambda kept: train_from_located(
                located, config, rendered=rendered_crops, scenes=kept), classifier_config,
            measures)}
    report['unreadable'] = list(unreadable) + list(scenes.unreadable)
    return report
