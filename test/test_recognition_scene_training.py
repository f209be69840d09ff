"""Training the second opinion on annotated scenes, and validation k folds by scene.

The scene folders are generated here (rendered signs pasted on clutter, GTSDB ``gt.txt``),
so every label is known; the detector runs for real (OpenGL through EGL, or numpy).
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scene_helpers import write_gtsdb_scenes
from test_recognition_training import (
    SMALL,
    TRAINING,
    _train_command,
    write_crop_folder,
    write_small_params,
)

from speed_sign_detector.errors import TrainingDataError
from speed_sign_detector.recognition.sign_features import FEATURE_SIZE
from speed_sign_detector.recognition.trained_bank import TrainedBank, load_trained_bank
from speed_sign_detector.scene_truth import SceneSign
from speed_sign_detector.training.bank_training import (
    TrainingConfig,
    locate_signs,
    read_crops,
    rendered_classifier,
    train_bank,
    train_from_located,
)
from speed_sign_detector.training.scene_examples import (
    SCENE_BACKGROUND_LABEL,
    SceneExamples,
    detect_scenes,
    read_scene_examples,
    scene_folds,
    scene_label,
)
from speed_sign_detector.training.scene_validation import cross_validate_scenes

WIDTH, HEIGHT = 480, 320
#: (file, [(kind, GTSDB class, diameter px, centre x, centre y)]); classes as in GTSRB:
#: 1 = 30, 2 = 50, 5 = 80, 17 = no entry.
SCENES = (
    ('00000.jpg', [('50', 2, 34, 330, 110), ('no_entry', 17, 30, 140, 170)]),
    ('00001.jpg', [('80', 5, 36, 250, 150)]),
    ('00002.jpg', [('30', 1, 32, 120, 100), ('80', 5, 30, 360, 220)]),
    ('00003.jpg', [('50', 2, 36, 200, 200)]),
)
COPIES = 1


@pytest.fixture(scope='module')
def scene_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_gtsdb_scenes(tmp_path_factory.mktemp('scenes'), SCENES, WIDTH, HEIGHT)


@pytest.fixture(scope='module')
def crop_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_crop_folder(tmp_path_factory.mktemp('crops'), tracks_per_class=2,
                             per_track=2)


def test_scene_label_names_the_annotated_sign_or_background() -> None:
    signs = [SceneSign('a.jpg', 100, 100, 140, 140, 1),    # 30, radius 20
             SceneSign('a.jpg', 200, 100, 240, 140, 6),    # end of 80
             SceneSign('a.jpg', 300, 100, 340, 140, 13)]   # yield: another sign
    assert scene_label(signs, 121, 119, 19.0) == '30'
    assert scene_label(signs, 220, 120, 22.0) == 'end_of_limit'
    assert scene_label(signs, 320, 120, 20.0) == 'other_sign'
    assert scene_label(signs, 50, 50, 20.0) == SCENE_BACKGROUND_LABEL
    assert scene_label(signs, 120, 120, 8.0) is None     # the digits, not the sign
    assert scene_label([], 120, 120, 8.0) == SCENE_BACKGROUND_LABEL


def test_scene_folds_keep_neighbouring_frames_together() -> None:
    names = [f'd/{index:05d}.jpg' for index in range(10)][::-1] + ['d/00003.jpg']
    folds = scene_folds(names, 3)
    assert sorted(folds) == sorted(set(names))
    ordered = [folds[name] for name in sorted(folds)]
    assert ordered == sorted(ordered) and set(ordered) == {0, 1, 2}
    with pytest.raises(ValueError, match='one scene per fold'):
        scene_folds(['d/a.jpg'], 2)
    with pytest.raises(ValueError, match='at least 2 folds'):
        scene_folds(names, 1)


def test_scene_examples_refuse_misshapen_rows() -> None:
    with pytest.raises(ValueError, match='one scene and label per'):
        SceneExamples(('a',), ('30', '50'), np.zeros((2, FEATURE_SIZE), np.float32))
    with pytest.raises(ValueError, match='one scene and label per'):
        SceneExamples(('a',), ('30',), np.zeros((1, 7), np.float32))


def test_scenes_teach_their_signs_and_background(scene_folder: Path, tmp_path: Path) -> None:
    broken = tmp_path / 'broken'
    write_gtsdb_scenes(broken, SCENES[:1], WIDTH, HEIGHT)
    (broken / 'images' / '00009.jpg').write_bytes(b'not a jpeg')
    scenes, unreadable = detect_scenes([scene_folder, broken])
    assert len(scenes) == len(SCENES) + 1
    assert len(unreadable) == 1 and '00009.jpg' in unreadable[0]
    examples = read_scene_examples(scenes, rendered_classifier(SMALL), COPIES, 0, unreadable)
    counts = examples.counts()
    # every limit sign of the scenes is located and labelled with its value ...
    assert {'30', '50', '80'} <= set(counts), counts
    # ... and the detector's candidates off the signs teach the background
    assert counts.get(SCENE_BACKGROUND_LABEL, 0) > 0, counts
    assert all(count % (1 + COPIES) == 0 for count in counts.values())
    assert examples.features.shape == (len(examples), FEATURE_SIZE)
    assert set(examples.scenes) <= {scene.key for scene in scenes}
    assert examples.unreadable == tuple(unreadable)
    kept = examples.subset({f'{scene_folder}/00001.jpg'})
    assert set(kept.scenes) == {f'{scene_folder}/00001.jpg'} and '80' in kept.labels


def test_missing_scene_truth_is_a_clear_error(tmp_path: Path) -> None:
    (tmp_path / 'images').mkdir()
    with pytest.raises(TrainingDataError, match='scene folder .*gt.txt'):
        detect_scenes([tmp_path])


def test_bank_trained_with_scenes_records_them_and_knows_background(
        crop_folder: Path, scene_folder: Path) -> None:
    bank = train_bank([crop_folder], SMALL, TRAINING, scene_folders=[scene_folder])
    record = bank.provenance
    assert record['scene_folders'] == [str(scene_folder)]
    assert record['scene_examples'].get(SCENE_BACKGROUND_LABEL, 0) > 0
    assert SCENE_BACKGROUND_LABEL in bank.second_opinion.real_labels


class RecordedSceneTraining:
    """The scenes of a folder detected, their examples, and a ``train`` for
    :func:`cross_validate_scenes` that really trains (on every crop of a crop folder and
    the scene examples it is given) and records what each bank saw.

    Attributes:
        scenes, examples: the detected scenes and their training examples.
        trained_on: per call of :meth:`train`, the scene keys its bank learned from.
        trained: per call, the bank.
    """

    def __init__(self, crop_folder: Path, scene_folder: Path,
                 training: TrainingConfig = TRAINING) -> None:
        classifier = rendered_classifier(SMALL)
        crops, images, _ = read_crops([crop_folder])
        self._located = locate_signs(classifier, crops, images)
        self._training = training
        self.scenes, _ = detect_scenes([scene_folder])
        self.examples = read_scene_examples(self.scenes, classifier, COPIES)
        self.trained_on: list[set[str]] = []
        self.trained: list[TrainedBank] = []

    def train(self, kept: SceneExamples) -> TrainedBank:
        self.trained_on.append(set(kept.scenes))
        self.trained.append(train_from_located(self._located, self._training, scenes=kept))
        return self.trained[-1]


def test_scene_cross_validation_answers_every_scene_with_a_bank_that_never_saw_it(
        crop_folder: Path, scene_folder: Path) -> None:
    recorded = RecordedSceneTraining(crop_folder, scene_folder)
    scenes, examples, train = recorded.scenes, recorded.examples, recorded.train
    trained_on = recorded.trained_on
    report = cross_validate_scenes(scenes, examples, 2, train, SMALL)
    folds = scene_folds([scene.key for scene in scenes], 2)
    assert report['frames'] == len(SCENES)
    assert report['signs'] == sum(1 for _, signs in SCENES for kind, *_ in signs
                                  if kind.isdigit())
    assert 0 <= report['recognized'] <= report['signs']
    assert len(report['fold_recall']) == 2
    for fold, seen in enumerate(trained_on):
        assert seen and all(folds[key] != fold for key in seen)
    with pytest.raises(TrainingDataError, match='cannot validate by scene'):
        cross_validate_scenes(scenes, examples, len(SCENES) + 1, train, SMALL)


def test_train_command_learns_from_scenes_and_reports_a_missing_folder(
        tmp_path: Path, crop_folder: Path, scene_folder: Path) -> None:
    out = tmp_path / 'bank.npz'
    config = write_small_params(tmp_path)
    env = dict(os.environ, PYTHONWARNINGS='ignore')
    done = subprocess.run(_train_command() + [
        'build', str(out), str(crop_folder), '--scenes', str(scene_folder), '--config',
        str(config), '--augmented-copies', '0', '--rendered-per-kind', '1',
        '--scene-copies', '1', '--epochs', '2', '--members', '1', '--composites-per-value', '2',
        '--design-per-kind', '0',
        '--json', '-q'],
        capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary['scene_examples'].get(SCENE_BACKGROUND_LABEL, 0) > 0
    assert load_trained_bank(out).provenance['scene_folders'] == [str(scene_folder)]
    failed = subprocess.run(_train_command() + [
        'build', str(tmp_path / 'x.npz'), str(crop_folder), '--scenes',
        str(tmp_path / 'nowhere'), '--config', str(config), '-q'],
        capture_output=True, text=True, timeout=300, env=env)
    assert failed.returncode == 1
    assert 'scene folder' in failed.stderr and 'Traceback' not in failed.stderr
    assert not (tmp_path / 'x.npz').exists()
