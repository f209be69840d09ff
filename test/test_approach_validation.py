"""Approach sequences read by scene-fold banks (``speed_sign_train validate --approach``).

Real all the way: rendered signs pasted in GTSDB-format scenes, the detector, real bank
training, bank files written and read, approach bags written with rosbags and run through
the pipeline with tracking (:func:`speed_sign_detector.tools.eval_bag.evaluate_bag`).
"""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

import pytest
from test_recognition_scene_training import (  # noqa: F401 (module fixtures)
    SCENES,
    RecordedSceneTraining,
    crop_folder,
    scene_folder,
)
from test_recognition_training import (
    SMALL,
    TRAINING,
    _train_command,
    write_small_params,
)

from speed_sign_detector.approach_sequences import ApproachConfig
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.recognition.trained_bank import TrainedBank
from speed_sign_detector.tools.approach_validation import (
    ApproachFolds,
    approached_figures,
    sum_approach_figures,
)
from speed_sign_detector.tools.bag_grading import DRIVE_COUNT_KEYS
from speed_sign_detector.tools.train import main as train_main
from speed_sign_detector.training.scene_examples import DetectedScene, scene_folds
from speed_sign_detector.training.scene_validation import cross_validate_scenes

#: Short sequences at 320x240 from the 480x320 scenes: the signs (30-36 px) start at
#: 11-14 px radius and end within the small banks' 24 px. The gap outlasts the tracker.
SMALL_APPROACH = ApproachConfig(frames_per_sequence=8, gap_frames=12, width_px=320,
                                height_px=240, growth_min=1.5, growth_max=1.9)
#: Fewer, shorter trainings than :data:`TRAINING` (training is most of the time here).
QUICK_TRAINING = dataclasses.replace(TRAINING, augmented_copies=0, rendered_per_kind=1,
                                     epochs=2, members=1, composites_per_value=2,
                                     design_per_kind=0)
#: The limit signs of :data:`SCENES`, one approach sequence each.
LIMIT_SIGNS = sum(kind.isdigit() for _, signs in SCENES for kind, *_ in signs)


class _RecordingApproachFolds(ApproachFolds):
    """Also records which bank each fold was measured with."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.banks: list[TrainedBank] = []

    def measure_fold(self, fold: int, bank: TrainedBank,
                     scenes: Sequence[DetectedScene]) -> None:
        self.banks.append(bank)
        super().measure_fold(fold, bank, scenes)


def test_each_folds_approach_sequences_are_read_by_the_bank_that_never_saw_them(
        crop_folder: Path, scene_folder: Path, tmp_path: Path) -> None:
    recorded = RecordedSceneTraining(crop_folder, scene_folder, QUICK_TRAINING)
    scenes, trained_on, trained = recorded.scenes, recorded.trained_on, recorded.trained

    work = tmp_path / 'work'
    work.mkdir()
    measure = _RecordingApproachFolds(PipelineConfig(backend='cpu', classifier=SMALL),
                                      SMALL_APPROACH, work_dir=work)
    report = cross_validate_scenes(scenes, recorded.examples, 2, recorded.train, SMALL,
                                   [measure])
    fold_of = scene_folds([scene.key for scene in scenes], 2)
    approach = report['approach']
    assert approach['folds'] == 2 and len(approach['per_fold']) == 2
    # each fold was read by the bank trained for it, which saw none of its scenes
    assert [id(bank) for bank in measure.banks] == [id(bank) for bank in trained]
    approached: list[str] = []
    for fold, row in enumerate(approach['per_fold']):
        assert row['fold'] == fold and row['scene_files']
        assert all(fold_of[key] == fold for key in row['scene_files'])
        assert not set(row['scene_files']) & trained_on[fold]
        assert row['sequences'] == sum(
            kind.isdigit() for name, signs in SCENES for kind, *_ in signs
            if f'{scene_folder}/{name}' in row['scene_files'])
        assert 0 <= row['recognized'] <= row['signs'] and row['signs'] >= row['sequences']
        # one approached sign per sequence, each with its truth track
        assert row['approached_signs'] == row['sequences']
        assert 0 <= row['approached_recognized'] <= row['approached_signs']
        assert row['backend'] == 'cpu' and row['classifier']   # as eval bag reports them
        approached += row['scene_files']
    assert sorted(approached) == sorted(scene.key for scene in scenes)  # each scene once
    # the folds add up
    assert approach['sequences'] == LIMIT_SIGNS
    for key in (*DRIVE_COUNT_KEYS, 'frames', 'approached_signs', 'approached_recognized'):
        assert approach[key] == sum(row[key] for row in approach['per_fold']), key
    assert approach['frames'] == LIMIT_SIGNS * (SMALL_APPROACH.frames_per_sequence
                                                + SMALL_APPROACH.gap_frames)
    assert 0 <= approach['recognized'] <= approach['signs']
    assert 2 * approach['recognized'] >= approach['signs'], approach   # most were read
    assert approach['recall'] == approach['recognized'] / approach['signs']
    assert approach['approached_recall'] == (approach['approached_recognized']
                                             / approach['approached_signs'])
    judged_s = approach['judged_s']
    assert judged_s > 0 and 0.0 <= approach['time_in_correct_limit'] <= 1.0
    assert approach['time_in_correct_limit'] == pytest.approx(sum(
        row['time_in_correct_limit'] * row['judged_s'] for row in approach['per_fold']
        if row['time_in_correct_limit'] is not None) / judged_s)
    assert approach['settings']['width_px'] == 320 and 'scenes' not in approach['settings']
    assert approach['unreadable'] == []
    assert list(work.iterdir()) == []   # the temporary banks and bags are gone
    # the single-frame figures are those of the folds as before
    assert report['frames'] == len(SCENES) and len(report['fold_recall']) == 2


def test_approach_figures_weight_the_time_in_the_correct_limit_by_judged_seconds() -> None:
    counts = dict.fromkeys(DRIVE_COUNT_KEYS, 0)
    first = {**counts, 'signs': 3, 'recognized': 2, 'frames': 40, 'drive_time_s': 4.0,
             'time_in_correct_limit': 1.0, 'time_in_correct_limit_strict': 0.5,
             'judged_s': 3.0}
    second = {**counts, 'signs': 1, 'recognized': 1, 'wrong_limits': 1, 'frames': 20,
              'drive_time_s': 2.0, 'time_in_correct_limit': 0.0,
              'time_in_correct_limit_strict': 0.0, 'judged_s': 1.0}
    unjudged = {**counts, 'frames': 5, 'drive_time_s': 0.5, 'time_in_correct_limit': None,
                'time_in_correct_limit_strict': None, 'judged_s': 0.0}
    total = sum_approach_figures([first, second, unjudged], 4)
    assert (total['sequences'], total['frames'], total['signs'], total['recognized'],
            total['wrong_limits']) == (4, 65, 4, 3, 1)
    assert total['recall'] == 0.75 and total['drive_time_s'] == 6.5
    assert total['time_in_correct_limit'] == 0.75
    assert total['time_in_correct_limit_strict'] == 0.375 and total['judged_s'] == 4.0
    assert sum_approach_figures([unjudged], 0)['time_in_correct_limit'] is None
    assert total['approached_signs'] == 0 and total['approached_recall'] is None


def test_the_approached_sign_of_each_sequence_is_counted_apart_from_the_others() -> None:
    """A scene's other signs have truth tracks of their own; the approached one is the
    sign the sequence closes in on (:attr:`ApproachStream.approached_track_ids`)."""
    summary = {'per_sign': [
        {'track_id': 1, 'recognized': True}, {'track_id': 2, 'recognized': False},
        {'track_id': 3, 'recognized': False}, {'track_id': 4, 'recognized': True}]}
    assert approached_figures(summary, [1, 3]) == {'approached_signs': 2,
                                                   'approached_recognized': 1}
    assert approached_figures(summary, [9]) == {'approached_signs': 0,
                                                'approached_recognized': 0}


@pytest.mark.parametrize('argv, message', [
    (['--approach'], '--approach needs --scenes'),
    (['--scenes-only'], '--scenes-only needs --scenes'),
    (['--boxes'], '--boxes needs --scenes'),
    (['--scenes', 'S', '--approach', '--leave-one-value-out'], 'does not go with'),
    (['--scenes', 'S', '--scenes-only', '--no-second-opinion'], 'needs the second opinion'),
])
def test_approach_and_scenes_only_refuse_what_they_cannot_do(
        argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert train_main(['validate', 'CROPS', *argv]) == 2
    assert message in capsys.readouterr().err


def test_validate_command_measures_approach_sequences_by_scene_fold_only(
        tmp_path: Path, crop_folder: Path, scene_folder: Path) -> None:
    env = dict(os.environ, PYTHONWARNINGS='ignore', TMPDIR=str(tmp_path))
    done = subprocess.run(_train_command() + [
        'validate', str(crop_folder), '--scenes', str(scene_folder), '--scenes-only',
        '--approach', '--folds', '2', '--config', str(write_small_params(tmp_path)),
        '--backend', 'cpu', '--augmented-copies', '0', '--rendered-per-kind', '1',
        '--scene-copies', '1', '--epochs', '2', '--members', '1',
        '--composites-per-value', '2', '--design-per-kind', '0', '--json', '-q'],
        capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    report = json.loads(lines[-1])
    assert 'variants' not in report   # no folds by track
    assert report['folds'] == 2 and report['scene_folders'] == [str(scene_folder)]
    scenes = report['scenes']
    assert scenes['frames'] == len(SCENES)
    approach = scenes['approach']
    assert approach['folds'] == 2 and approach['sequences'] == LIMIT_SIGNS
    assert approach['settings']['width_px'] == 640   # the default sequences
    assert 0 <= approach['recognized'] <= approach['signs']
    assert any(line.startswith('approach sequences, 2 folds by scene') for line in lines)
    assert sorted(path.name for path in tmp_path.iterdir()) == ['params.yaml']
