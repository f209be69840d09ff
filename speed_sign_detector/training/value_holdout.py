"""Leave one value out: how a bank reads a speed-limit value it has no real crop of.

The held-out data the package is measured on holds values the development data lacks
(130 km/h, 140 km/h, ...). :func:`leave_one_value_out` measures that situation on data
whose answers are known: for each value V with real crops, a bank is trained with none
of V's real crops (V is then known only from renderings and from composites of other
values' digits, :mod:`.digit_composites`, as 130 is) and reads

- every real crop of V: right, read as another limit (wrong), or withheld;
- the crops of one track fold of the other values (that fold's tracks are left out of
  that bank's training too, so a physical sign is never on both sides): accuracy and
  wrong limits of the values it did see, and look-alikes read as a limit.

Annotated scenes (``scene_folders``), when given, join every bank's training without
their examples of V.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector.config import ClassifierConfig, DetectorConfig
from speed_sign_detector.labelled_crops import track_folds
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.training.bank_training import (
    LocatedCrops,
    ProgressCallback,
    TrainingConfig,
    locate_rendered,
    locate_signs,
    read_crops,
    rendered_classifier,
    scene_examples_of,
    train_from_located,
)
from speed_sign_detector.training.scene_examples import SceneExamples
from speed_sign_detector.training.track_validation import answer_is_limit, summarise

__all__ = ['hold_out_values', 'leave_one_value_out', 'value_answers']


def value_answers(truth: str, answers: Sequence[str]) -> dict[str, Any]:
    """How the crops of one limit value were answered.

    Returns:
        ``{'crops', 'right', 'wrong_limit', 'withheld', 'accuracy', 'wrong_limit_rate',
        'withheld_rate', 'answers'}``: right is the value itself, wrong any other limit,
        withheld every answer that is not a limit.
    """
    right = sum(answer == truth for answer in answers)
    wrong = sum(answer_is_limit(answer) and answer != truth for answer in answers)
    withheld = len(answers) - right - wrong
    count = max(1, len(answers))
    tally: dict[str, int] = {}
    for answer in answers:
        tally[answer] = tally.get(answer, 0) + 1
    return {'crops': len(answers), 'right': right, 'wrong_limit': wrong, 'withheld': withheld,
            'accuracy': right / count, 'wrong_limit_rate': wrong / count,
            'withheld_rate': withheld / count,
            'answers': dict(sorted(tally.items(), key=lambda item: -item[1]))}


def _without_value(scenes: SceneExamples | None, value: str) -> SceneExamples | None:
    """``scenes`` without their rows labelled ``value``."""
    if scenes is None:
        return None
    rows = [i for i, label in enumerate(scenes.labels) if label != value]
    return SceneExamples(tuple(scenes.scenes[i] for i in rows),
                         tuple(scenes.labels[i] for i in rows), scenes.features[rows],
                         scenes.unreadable)


def leave_one_value_out(folders: Sequence[Path], folds: int = 5,
                        classifier_config: ClassifierConfig = ClassifierConfig(),
                        config: TrainingConfig = TrainingConfig(),
                        progress: ProgressCallback | None = None,
                        scene_folders: Sequence[Path] = (),
                        detector_config: DetectorConfig = DetectorConfig(),  # noqa: B008
                        backend: str = 'auto',
                        values: Sequence[str] | None = None) -> dict[str, Any]:
    """Train one bank per held-out value and read its crops (see the module docstring).

    Args:
        folders: labelled crop folders (GTSRB ``labels.csv`` format).
        folds: track folds; value number i (in value order) is measured with the other
            values' crops of fold ``i % folds``.
        classifier_config: the classifier's parameters.
        config: how each bank is trained.
        progress: called with (done, total) as crops are located and read.
        scene_folders: annotated scenes that join every bank's training (without V).
        detector_config, backend: the detector that finds the scenes' candidates.
        values: the values to hold out (default: every limit with real crops).

    Returns:
        ``{'folds', 'crops', 'values': {V: {'held_out': value_answers of V's crops,
        'others': summarise() of the other values' fold crops}}, 'mean_accuracy',
        'worst_accuracy', 'worst_wrong_limit_rate', 'training', 'data_folders',
        'unreadable'}``.

    Raises:
        TrainingDataError: for unusable folders.
        ValueError: for a value in ``values`` without real crops, or ``folds`` < 2.
    """
    if folds < 2:
        raise ValueError(f'folds must be >= 2, got {folds}')
    crops, images, unreadable = read_crops(folders)
    labels = np.asarray([crop.label for crop in crops])
    present = sorted({label for label in labels if label.isdigit()}, key=int)
    chosen = list(present) if values is None else [str(value) for value in values]
    missing = [value for value in chosen if value not in present]
    if missing:
        raise ValueError(f'no real crops of {", ".join(missing)} km/h to hold out; values '
                         f'with crops: {", ".join(present)}')
    fold_of = track_folds(crops, folds, config.seed)
    total = len(crops) + sum(int(np.sum((labels == value) | (fold_of == i % folds)))
                             for i, value in enumerate(chosen))
    done = 0

    def step(_: int = 0, __: int = 0) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(done, total), total)

    rendered = rendered_classifier(classifier_config)
    located = locate_signs(rendered, crops, images, step)
    rendered_crops = locate_rendered(rendered, config)
    _, scenes = scene_examples_of(scene_folders, rendered, detector_config, config, backend)
    report = hold_out_values(located, fold_of, chosen, classifier_config, config,
                             rendered_crops, scenes, step)
    report.update(folds=folds, data_folders=[str(folder) for folder in folders],
                  scene_folders=[str(folder) for folder in scene_folders],
                  unreadable=list(unreadable) + list(scenes.unreadable if scenes else ()))
    return report


def hold_out_values(located: LocatedCrops, fold_of: np.ndarray, values: Sequence[str],
                    classifier_config: ClassifierConfig, config: TrainingConfig,
                    rendered_crops: LocatedCrops | None = None,
                    scenes: SceneExamples | None = None,
                    step: Callable[[], None] | None = None) -> dict[str, Any]:
    """The measurement of :func:`leave_one_value_out` on crops already located.

    Args:
        located: every crop, located by the rendered-only classifier.
        fold_of: (N,) the track fold of each crop.
        values: the values to hold out, each with real crops in ``located``.
        classifier_config, config: the classifier and the training recipe.
        rendered_crops, scenes: the located renderings and the scene examples that join
            every bank's training (the scenes without the held-out value).
        step: called once per crop read.

    Returns:
        ``{'crops', 'values', 'mean_accuracy', 'worst_accuracy', 'worst_wrong_limit_rate',
        'training'}`` (see :func:`leave_one_value_out`).
    """
    crops = located.crops
    images = located.images
    labels = np.asarray([crop.label for crop in crops])
    folds = int(fold_of.max()) + 1
    widths = [crop.roi[2] - crop.roi[0] + 1 for crop in crops]
    class_ids = [crop.class_id for crop in crops]
    per_value: dict[str, dict[str, Any]] = {}
    for position, value in enumerate(values):
        fold = position % folds
        train = (fold_of != fold) & (labels != value)
        bank = train_from_located(located.subset(train), config, rendered=rendered_crops,
                                  scenes=_without_value(scenes, value))
        trained = Classifier(classifier_config, bank)
        held_out = np.flatnonzero(labels == value)
        others = np.flatnonzero((fold_of == fold) & (labels != value))
        answers: dict[int, str] = {}
        for index in np.concatenate([held_out, others]):
            evidence = located.evidence[index] if not bank.class_examples else \
                trained.crop_evidence(images[index])
            answers[int(index)] = trained.decide_crop(images[index], evidence).label
            if step is not None:
                step()
        per_value[value] = {
            'fold': fold,
            'training_crops': int(train.sum()),
            'held_out': value_answers(value, [answers[int(i)] for i in held_out]),
            'others': summarise([str(labels[i]) for i in others],
                                [answers[int(i)] for i in others],
                                [class_ids[i] for i in others], [widths[i] for i in others]),
        }
    accuracies = [row['held_out']['accuracy'] for row in per_value.values()]
    wrong_rates = [row['held_out']['wrong_limit_rate'] for row in per_value.values()]
    return {'crops': len(crops), 'values': per_value,
            'mean_accuracy': float(np.mean(accuracies)) if accuracies else None,
            'worst_accuracy': float(np.min(accuracies)) if accuracies else None,
            'worst_wrong_limit_rate': float(np.max(wrong_rates)) if wrong_rates else None,
            'training': dataclasses.asdict(config)}
