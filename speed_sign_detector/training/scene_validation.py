"""Validation on annotated scenes, k folds by scene.

Each fold's bank is trained by the caller's ``train`` on every crop and on the examples
of the other folds' scenes only (:func:`.scene_examples.scene_folds`: contiguous blocks of
the sorted names); it then classifies the detector's candidates of its own fold's scenes,
which it never saw, one frame at a time as ``speed_sign_eval scenes`` does. The figures
are those of ``speed_sign_eval scenes``: recognition recall over the speed-limit signs and
false limits per frame.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.errors import TrainingDataError
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.trained_bank import TrainedBank
from speed_sign_detector.scene_truth import count_false_limits, is_recognized
from speed_sign_detector.training.scene_examples import (
    DetectedScene,
    SceneExamples,
    read_scene_gray,
    scene_folds,
)

__all__ = ['cross_validate_scenes']

_LOG = logging.getLogger(__name__)


def cross_validate_scenes(scenes: Sequence[DetectedScene], examples: SceneExamples,
                          folds: int, train: Callable[[SceneExamples], TrainedBank],
                          classifier_config: ClassifierConfig = ClassifierConfig(),  # noqa: B008
                          ) -> dict[str, Any]:
    """k-fold validation by scene (see the module docstring).

    Args:
        scenes: the detected scenes (:func:`.scene_examples.detect_scenes`).
        examples: their training examples (:func:`.scene_examples.read_scene_examples`).
        folds: number of folds (>= 2, at most one per scene).
        train: trains a bank on every crop and the given scene examples.
        classifier_config: the classifier that uses each fold's bank.

    Returns:
        ``{'folds', 'frames', 'signs', 'recognized', 'recognition_recall',
        'false_limits', 'false_limits_per_frame', 'fold_recall': [...],
        'fold_false_limits_per_frame': [...]}``.

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
        classifier = Classifier(classifier_config, train(kept))
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
    return {'folds': folds, **totals,
            'recognition_recall': totals['recognized'] / totals['signs']
            if totals['signs'] else 0.0,
            'false_limits_per_frame': totals['false_limits'] / totals['frames']
            if totals['frames'] else 0.0,
            'fold_recall': fold_recall, 'fold_false_limits_per_frame': fold_false}
