"""Validation that keeps physical signs apart: k folds by GTSRB track.

Each fold's bank is trained on the other folds (:func:`.bank_training.train_from_located`)
and every crop is answered by the bank that never saw its track; per-class accuracy,
wrong-limit and withheld rates, and the look-alikes read as a limit, for the
rendered-only classifier, the trained filters alone, the second opinion choosing among
the rendered filters' leaders, and the whole trained bank (the real filters' ranking
too), side by side; with scenes also k folds by scene (:mod:`.scene_validation`).
"""
from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector.config import ClassifierConfig, DetectorConfig
from speed_sign_detector.labelled_crops import track_folds
from speed_sign_detector.recognition.classifier import Classifier
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
from speed_sign_detector.training.scene_validation import SceneFoldMeasure, cross_validate_scenes

__all__ = ['VARIANTS', 'answer_is_limit', 'cross_validate', 'summarise']


#: The variants :func:`cross_validate` compares: the rendered filters alone; the trained
#: bank without its second opinion; its second opinion choosing among the rendered
#: filters' leaders (without the real filters' ranking); the whole trained bank.
VARIANTS: tuple[str, ...] = ('rendered', 'trained_filters', 'second_opinion_rendered_ranking',
                             'trained_filters_second_opinion')


def answer_is_limit(label: str) -> bool:
    """True when an answer names a speed limit."""
    return label.isdigit()


def summarise(truths: Sequence[str], answers: Sequence[str], class_ids: Sequence[int],
              widths_px: Sequence[int]) -> dict[str, Any]:
    """Accuracy, wrong-limit and withheld rates per class, and look-alikes read as limit.

    A limit crop is right when answered its value; an end-of-limit crop when the answer
    is not a limit; a look-alike when the answer is not a limit. A wrong limit is a limit
    answer other than the truth.
    """
    per_class: dict[str, dict[str, Any]] = {}
    for truth in sorted(set(truths) - {'other_sign'}, key=lambda t: (not t.isdigit(), t.zfill(3))):
        picked = [a for t, a in zip(truths, answers) if t == truth]
        if truth.isdigit():
            right = sum(a == truth for a in picked)
        else:
            right = sum(not answer_is_limit(a) for a in picked)
        wrong = sum(answer_is_limit(a) and a != truth for a in picked)
        withheld = sum(a == 'no_sign' for a in picked)
        per_class[truth] = {'crops': len(picked), 'accuracy': right / len(picked),
                            'wrong_limit_rate': wrong / len(picked),
                            'withheld_rate': withheld / len(picked),
                            'answers': dict(Counter(picked).most_common())}
    limit_rows = [(t, a) for t, a in zip(truths, answers) if t != 'other_sign']
    right_all = sum((a == t) if t.isdigit() else not answer_is_limit(a) for t, a in limit_rows)
    wrong_all = sum(answer_is_limit(a) and a != t for t, a in limit_rows)
    small = [(t, a) for (t, a), w in zip(zip(truths, answers), widths_px)
             if t != 'other_sign' and w < 20]
    lookalike: dict[str, dict[str, Any]] = {}
    for class_id in sorted({c for c, t in zip(class_ids, truths) if t == 'other_sign'}):
        picked = [a for c, a in zip(class_ids, answers) if c == class_id]
        lookalike[str(class_id)] = {'crops': len(picked), 'read_as_limit_rate': sum(
            answer_is_limit(a) for a in picked) / len(picked)}
    lookalike_answers = [a for t, a in zip(truths, answers) if t == 'other_sign']
    return {
        'crops': len(limit_rows),
        'accuracy': right_all / max(1, len(limit_rows)),
        'wrong_limit_rate': wrong_all / max(1, len(limit_rows)),
        'accuracy_under_20px': (sum((a == t) if t.isdigit() else not answer_is_limit(a)
                                    for t, a in small) / len(small)) if small else None,
        'crops_under_20px': len(small),
        'per_class': per_class,
        'lookalikes': len(lookalike_answers),
        'lookalikes_read_as_limit_rate': (sum(answer_is_limit(a) for a in lookalike_answers)
                                          / len(lookalike_answers)) if lookalike_answers
        else None,
        'lookalike_classes': lookalike,
    }


def cross_validate(folders: Sequence[Path], folds: int = 5,
                   classifier_config: ClassifierConfig = ClassifierConfig(),
                   config: TrainingConfig = TrainingConfig(),
                   progress: ProgressCallback | None = None,
                   scene_folders: Sequence[Path] = (),
                   detector_config: DetectorConfig = DetectorConfig(),  # noqa: B008 (frozen)
                   backend: str = 'auto',
                   scene_measures: Sequence[SceneFoldMeasure] = ()) -> dict[str, Any]:
    """k-fold validation split by track (see the module docstring). With
    ``scene_folders`` every crop fold's bank also learns from all scenes, and the scenes
    are validated too, k folds by scene (:func:`.scene_validation.cross_validate_scenes`:
    each fold's bank learns from every crop and the other folds' scenes; it is also
    measured by ``scene_measures``, whose summaries join ``'scenes'``).

    Returns:
        ``{'folds': k, 'variants': {variant: summary over all crops}, 'fold_accuracy':
        {variant: [per-fold accuracy]}, 'accuracy_mean'/'accuracy_std': {variant: ...}}``,
        and with scenes ``'scenes'``: the scene folds' figures.

    Raises:
        TrainingDataError: for unusable folders.
    """
    crops, images, unreadable = read_crops(folders)
    fold_of = track_folds(crops, folds, config.seed)
    total_steps = len(crops) * (1 + folds)
    done = 0

    def step(_: int, __: int) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total_steps)

    rendered = rendered_classifier(classifier_config)
    located = locate_signs(rendered, crops, images, step)
    rendered_crops = locate_rendered(rendered, config)
    detected, scenes = scene_examples_of(scene_folders, rendered, detector_config, config,
                                       backend)
    answers: dict[str, list[str]] = {variant: [''] * len(crops) for variant in VARIANTS}
    for index, image in enumerate(images):
        answers['rendered'][index] = rendered.decide_crop(image,
                                                          located.evidence[index]).label
    for fold in range(folds):
        train = fold_of != fold
        bank = train_from_located(located.subset(train), config, rendered=rendered_crops,
                                  scenes=scenes)
        trained = Classifier(classifier_config, bank)
        rendered_ranking = Classifier(classifier_config,
                                      dataclasses.replace(bank, real_filters=None))
        for index in np.flatnonzero(~train):
            # without real examples in its composite filters the trained classifier
            # correlates with the rendered filters: their evidence stands
            evidence = located.evidence[index] if not bank.class_examples else \
                trained.crop_evidence(images[index])
            answers['trained_filters'][index] = trained.decide_crop(
                images[index], evidence, use_second_opinion=False).label
            answers['trained_filters_second_opinion'][index] = trained.decide_crop(
                images[index], evidence).label
            answers['second_opinion_rendered_ranking'][index] = rendered_ranking.decide_crop(
                images[index], evidence).label
            step(0, 0)
        done += int(train.sum())  # the steps of this fold's training crops
    truths = [crop.label for crop in crops]
    class_ids = [crop.class_id for crop in crops]
    widths = [crop.roi[2] - crop.roi[0] + 1 for crop in crops]
    report: dict[str, Any] = {'folds': folds, 'crops': len(crops), 'unreadable': unreadable,
                              'data_folders': [str(f) for f in folders],
                              'training': dataclasses.asdict(config), 'variants': {},
                              'fold_accuracy': {}, 'accuracy_mean': {}, 'accuracy_std': {}}
    for variant in VARIANTS:
        report['variants'][variant] = summarise(truths, answers[variant], class_ids, widths)
        per_fold = []
        for fold in range(folds):
            members = [i for i in range(len(crops)) if fold_of[i] == fold]
            per_fold.append(summarise([truths[i] for i in members],
                                      [answers[variant][i] for i in members],
                                      [class_ids[i] for i in members],
                                      [widths[i] for i in members])['accuracy'])
        report['fold_accuracy'][variant] = per_fold
        report['accuracy_mean'][variant] = float(np.mean(per_fold))
        report['accuracy_std'][variant] = float(np.std(per_fold))
    if scenes is not None:
        report['scene_folders'] = [str(f) for f in scene_folders]
        report['scenes'] = cross_validate_scenes(
            detected, scenes, folds, lambda kept: train_from_located(
                located, config, rendered=rendered_crops, scenes=kept), classifier_config,
            scene_measures)
        report['unreadable'] += list(scenes.unreadable)
    return report

