"""Leave one value out: a bank that never saw a value's real crops reads them.

On generated crops (renderings on textured backgrounds, GTSRB layout) whose answers are
known: every held-out value's bank is trained without any of its crops and without the
measured fold's tracks, and the command reports each value's crops as read.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from test_recognition_training import (
    KINDS,
    SMALL,
    _train_command,
    write_crop_folder,
    write_small_params,
)

from speed_sign_detector.labelled_crops import read_crop_folder, track_folds
from speed_sign_detector.training import bank_training, value_holdout
from speed_sign_detector.training.bank_training import TrainingConfig
from speed_sign_detector.training.value_holdout import leave_one_value_out, value_answers

TINY = TrainingConfig(augmented_copies=0, rendered_per_kind=1, arched_six_per_kind=0,
                      composites_per_value=2, design_per_kind=0, epochs=2, members=1,
                      hidden_units=16)
VALUES = sorted({kind for kind in KINDS.values() if kind.isdigit()}, key=int)


@pytest.fixture(scope='module')
def crop_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_crop_folder(tmp_path_factory.mktemp('crops'), tracks_per_class=3,
                             per_track=2)


def test_value_answers_tell_right_wrong_and_withheld() -> None:
    row = value_answers('130', ['130', '120', 'no_sign', '130', 'end_of_limit', 'other_sign'])
    assert (row['right'], row['wrong_limit'], row['withheld']) == (2, 1, 3)
    assert row['accuracy'] == pytest.approx(2 / 6)
    assert row['answers']['130'] == 2


def test_no_bank_sees_its_held_out_value_or_the_measured_fold(
        crop_folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    trained_on: list[list[tuple[str, str]]] = []
    original = bank_training.train_from_located

    def recording(located, config, *args, **kwargs):  # type: ignore[no-untyped-def]
        trained_on.append([(crop.label, crop.track) for crop in located.crops])
        return original(located, config, *args, **kwargs)

    monkeypatch.setattr(value_holdout, 'train_from_located', recording)
    report = leave_one_value_out([crop_folder], 3, SMALL, TINY)
    crops = read_crop_folder(crop_folder)
    folds = track_folds(crops, 3, TINY.seed)
    fold_of_track = {crop.track: int(fold) for crop, fold in zip(crops, folds)}
    assert list(report['values']) == VALUES and len(trained_on) == len(VALUES)
    for (value, row), seen in zip(report['values'].items(), trained_on):
        assert value not in {label for label, _ in seen}
        assert row['fold'] not in {fold_of_track[track] for _, track in seen}
        assert row['training_crops'] == len(seen)
        held = row['held_out']
        assert held['crops'] == sum(crop.label == value for crop in crops)
        assert held['right'] + held['wrong_limit'] + held['withheld'] == held['crops']
        others = [crop for crop, fold in zip(crops, folds)
                  if fold == row['fold'] and crop.label != value]
        assert row['others']['crops'] + row['others']['lookalikes'] == len(others)


def test_the_command_reports_each_value_and_refuses_unknown_ones(crop_folder: Path,
                                                                 tmp_path: Path) -> None:
    params = write_small_params(tmp_path)
    common = ['validate', str(crop_folder), '--config', str(params), '--folds', '3',
              '--leave-one-value-out', '--augmented-copies', '0', '--rendered-per-kind', '1',
              '--arched-six-per-kind', '0', '--composites-per-value', '2',
              '--design-per-kind', '0',
              '--epochs', '2',
              '--members', '1', '--hidden-units', '16', '-q']
    done = subprocess.run([*_train_command(), *common, '--values', VALUES[0], '--json'],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert list(report['values']) == [VALUES[0]]
    assert report['mean_accuracy'] == report['values'][VALUES[0]]['held_out']['accuracy']
    assert f'{VALUES[0]:>6}' in done.stdout
    refused = subprocess.run([*_train_command(), *common, '--values', '130'],
                             capture_output=True, text=True, timeout=600)
    assert refused.returncode == 1
    assert 'no real crops of 130 km/h' in refused.stderr
    unpaired = subprocess.run([*_train_command(), 'validate', str(crop_folder), '--values',
                               '30'], capture_output=True, text=True, timeout=600)
    assert unpaired.returncode == 2 and '--leave-one-value-out' in unpaired.stderr
    assert np.isfinite(report['worst_accuracy'])
