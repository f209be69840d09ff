"""Scene boxes read as crops by scene-fold banks (``speed_sign_train validate --boxes``).

Real all the way: rendered signs pasted in GTSDB-format scenes, the detector, real bank
training per fold, the boxes cut from the scene files and read by each fold's classifier.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from test_approach_validation import QUICK_TRAINING
from test_recognition_scene_training import (  # noqa: F401 (module fixtures)
    SCENES,
    RecordedSceneTraining,
    crop_folder,
    scene_folder,
)
from test_recognition_training import SMALL

from speed_sign_detector.recognition.trained_bank import TrainedBank
from speed_sign_detector.scene_truth import SceneSign
from speed_sign_detector.training.scene_box_validation import (
    BOX_CUTS,
    SceneBoxFolds,
    box_crop,
    format_boxes_line,
)
from speed_sign_detector.training.scene_examples import DetectedScene, scene_folds
from speed_sign_detector.training.scene_validation import cross_validate_scenes

LIMITS = sum(kind.isdigit() for _, signs in SCENES for kind, *_ in signs)
LOOKALIKES = sum(kind == 'no_entry' for _, signs in SCENES for kind, *_ in signs)


class _RecordingBoxFolds(SceneBoxFolds):
    """Also records which bank and which scenes each fold was measured with."""

    def __init__(self, *args: object) -> None:
        super().__init__(*args)  # type: ignore[arg-type]
        self.measured: list[tuple[TrainedBank, list[str]]] = []

    def measure_fold(self, fold: int, bank: TrainedBank,
                     scenes: Sequence[DetectedScene]) -> None:
        self.measured.append((bank, [scene.key for scene in scenes]))
        super().measure_fold(fold, bank, scenes)


def test_each_folds_boxes_are_read_by_the_bank_that_never_saw_them(
        crop_folder: Path, scene_folder: Path) -> None:
    recorded = RecordedSceneTraining(crop_folder, scene_folder, QUICK_TRAINING)
    scenes, trained_on, trained = recorded.scenes, recorded.trained_on, recorded.trained
    measure = _RecordingBoxFolds(SMALL)
    report = cross_validate_scenes(scenes, recorded.examples, 2, recorded.train, SMALL,
                                   [measure])
    fold_of = scene_folds([scene.key for scene in scenes], 2)
    boxes = report['boxes']
    assert boxes['folds'] == 2 and len(boxes['per_fold']) == 2
    for fold, (bank, images) in enumerate(measure.measured):
        assert bank is trained[fold]                        # the fold's own bank...
        assert images and all(fold_of[key] == fold for key in images)
        assert not set(images) & trained_on[fold]           # ...which never saw them
    for cut in BOX_CUTS:
        row = boxes[cut]
        assert row['limit_signs'] == LIMITS and row['lookalikes'] == LOOKALIKES
        assert row['right'] + row['wrong_limits'] + row['withheld'] == LIMITS
        assert row['limit_signs'] == sum(fold[cut]['limit_signs']
                                         for fold in boxes['per_fold'])
        assert 2 * row['right'] >= LIMITS, row              # clean rendered signs: most read
        assert row['accuracy'] == row['right'] / LIMITS
        assert sum(row['another_limit'].values()) == row['wrong_limits']
    line = format_boxes_line(boxes, 2)
    assert line.startswith('scene boxes read as crops, 2 folds by scene')
    assert f"tight {boxes['tight']['right']}/{LIMITS} right" in line


def test_box_cuts_are_the_box_and_the_box_padded_by_a_tenth_clamped_to_the_image() -> None:
    gray = np.arange(100 * 120, dtype=np.uint32).reshape(100, 120).astype(np.uint8)
    sign = SceneSign('x.jpg', 20.0, 30.0, 60.0, 70.0, 2)
    assert box_crop(gray, sign, 'tight').shape == (41, 41)
    assert box_crop(gray, sign, 'padded').shape == (49, 49)    # 4 px more on every side
    assert np.array_equal(box_crop(gray, sign, 'tight'), gray[30:71, 20:61])
    corner = SceneSign('x.jpg', 0.0, 0.0, 30.0, 20.0, 2)
    assert box_crop(gray, corner, 'padded').shape == (23, 34)  # clamped at the top left
    assert box_crop(gray, SceneSign('x.jpg', 5.0, 5.0, 7.0, 7.0, 2), 'tight') is None
    with pytest.raises(ValueError, match='unknown box cut'):
        box_crop(gray, sign, 'loose')
