"""The second opinion's network form: training, scores, the bank file, the decision.

Features with known answers are generated here (clusters in feature space, and rendered
signs through the real feature extractor), so no real data is needed.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from speed_sign_detector.errors import BankFileError
from speed_sign_detector.recognition.bank_file import load_bank_file, save_bank_file
from speed_sign_detector.recognition.second_opinion import SecondOpinion
from speed_sign_detector.recognition.sign_features import PATCH_PX, sign_features
from speed_sign_detector.recognition.templates import gray_template
from speed_sign_detector.recognition.trained_bank import (
    TRAINED_BANK_FORMAT,
    TrainedBank,
    load_trained_bank,
    save_trained_bank,
)
from speed_sign_detector.training.bank_training import TrainingConfig
from speed_sign_detector.training.opinion_fitting import fit_network_opinion, fit_second_opinion

LABELS = ('30', '80', 'other_sign')


def _clusters(count: int, dimension: int, seed: int) -> tuple[np.ndarray, list[str]]:
    """Three labels in feature space: '30' and '80' are the XOR of the signs of the first
    two coordinates (no linear model separates them), 'other_sign' is shifted along the
    third."""
    rng = np.random.default_rng(seed)
    features = rng.normal(0.0, 0.3, (count, dimension)).astype(np.float32)
    corner = rng.integers(0, 2, (count, 2)) * 2 - 1
    features[:, :2] += corner
    other = rng.random(count) < 1 / 3
    features[other, 2] += 2.0
    names = np.where(other, 'other_sign', np.where(corner[:, 0] == corner[:, 1], '30', '80'))
    return features, [str(n) for n in names]


def test_network_learns_what_a_linear_model_cannot() -> None:
    features, labels = _clusters(600, 12, seed=1)
    network = fit_network_opinion(features, labels, hidden_units=16, epochs=100, members=2,
                                  learning_rate=1e-2)
    linear = fit_second_opinion(features, labels, ridge=1.0)
    test_features, test_labels = _clusters(300, 12, seed=2)

    def accuracy(opinion: SecondOpinion) -> float:
        scores = opinion.scores(test_features)
        return float(np.mean([opinion.labels[i] == t
                              for i, t in zip(scores.argmax(axis=1), test_labels)]))

    assert network.form == 'network' and linear.form == 'linear'
    assert network.labels == LABELS
    assert accuracy(network) > 0.97
    assert accuracy(linear) < 0.8      # 30 against 80 is an XOR
    scores = network.scores(test_features)
    assert scores.shape == (300, 3) and scores.dtype == np.float32
    # mean of 2p - 1 over the members: within [-1, 1], and each row sums to 2 - C
    assert np.all(scores >= -1.0) and np.all(scores <= 1.0)
    np.testing.assert_allclose(scores.sum(axis=1), 2.0 - len(LABELS), atol=1e-4)


def test_network_reads_rendered_signs_from_their_features() -> None:
    rng = np.random.default_rng(3)
    patches, labels = [], []
    for kind in ('30', '80', 'no_entry'):
        for _ in range(40):
            patch = gray_template(kind, PATCH_PX, PATCH_PX,
                                  background=float(rng.uniform(60, 180)),
                                  yaw_deg=float(rng.uniform(-20, 20)),
                                  roll_deg=float(rng.uniform(-5, 5))).astype(np.float32)
            patches.append(patch + rng.normal(0, 6, patch.shape).astype(np.float32))
            labels.append('other_sign' if kind == 'no_entry' else kind)
    features = sign_features(np.stack(patches))
    train = np.arange(len(labels)) % 4 != 0
    opinion = fit_network_opinion(features[train], [l for l, t in zip(labels, train) if t],
                                  hidden_units=32, members=2)
    scores = opinion.scores(features[~train])
    read = [opinion.labels[i] for i in scores.argmax(axis=1)]
    truth = [l for l, t in zip(labels, train) if not t]
    assert read == truth
    # the decision rule reads the network's scores as it reads the linear model's
    for row, label in zip(scores, truth):
        ranked = [label] + [name for name in LABELS if name != label]
        assert opinion.choose(row, ranked, 2, 0.6) == label


def test_a_few_crops_still_get_trained() -> None:
    """A tiny training set gets at least ``min_steps`` steps, not one per epoch."""
    features, labels = _clusters(30, 6, seed=4)

    def training_accuracy(min_steps: int) -> float:
        opinion = fit_network_opinion(features, labels, hidden_units=16, epochs=1, members=1,
                                      min_steps=min_steps)
        read = [opinion.labels[i] for i in opinion.scores(features).argmax(axis=1)]
        return float(np.mean([r == t for r, t in zip(read, labels)]))

    assert training_accuracy(1) < 0.5      # one step: about chance (3 labels)
    assert training_accuracy(300) > 0.8


def test_network_rejects_bad_training_input() -> None:
    features, labels = _clusters(20, 4, seed=5)
    with pytest.raises(ValueError, match='one label per row'):
        fit_network_opinion(features, labels[:-1])
    with pytest.raises(ValueError, match='at least two labels'):
        fit_network_opinion(features, ['30'] * len(labels))
    with pytest.raises(ValueError, match='must be >= 1'):
        fit_network_opinion(features, labels, members=0)


def test_network_bank_round_trips_and_rejects_misshapen_arrays(tmp_path) -> None:
    features, labels = _clusters(200, 8, seed=6)
    opinion = fit_network_opinion(features, labels, hidden_units=8, epochs=5, members=2,
                                  real_labels=('30', '80'))
    path = tmp_path / 'bank.npz'
    save_trained_bank(path, TrainedBank(opinion, 3, 0.6, {}, {'note': 'test'}))
    loaded = load_trained_bank(path).second_opinion
    assert loaded is not None and loaded.form == 'network'
    assert loaded.real_labels == ('30', '80') and loaded.labels == LABELS
    # the file keeps the weight matrices in float16: the scores agree to that precision
    np.testing.assert_allclose(loaded.scores(features), opinion.scores(features), atol=2e-2)
    assert load_trained_bank(path).candidates == 3

    # a hidden layer that does not fit the output layer is a clear error, not a crash
    arrays, meta = load_bank_file(path, TRAINED_BANK_FORMAT, (meta_version(path),))
    arrays['hidden_bias'] = arrays['hidden_bias'][:, :-1]
    broken = tmp_path / 'broken.npz'
    save_bank_file(broken, arrays, {k: v for k, v in meta.items()
                                    if k not in ('format', 'format_version')},
                   TRAINED_BANK_FORMAT, meta['format_version'])
    with pytest.raises(BankFileError, match='not a complete trained bank.*hidden_bias'):
        load_trained_bank(broken)


def meta_version(path) -> int:
    """The format version written in a bank file."""
    _, meta = load_bank_file(path, TRAINED_BANK_FORMAT, tuple(range(1, 100)))
    return int(meta['format_version'])


def test_linear_banks_of_the_previous_version_still_load(tmp_path) -> None:
    features, labels = _clusters(100, 8, seed=7)
    opinion = fit_second_opinion(features, labels, ridge=1.0)
    arrays = {'opinion_labels': np.asarray(opinion.labels),
              'opinion_real_labels': np.asarray(opinion.real_labels),
              'feature_mean': opinion.feature_mean, 'feature_scale': opinion.feature_scale,
              'weights': opinion.weights.astype(np.float16), 'bias': opinion.bias}
    path = tmp_path / 'v2.npz'
    save_bank_file(path, arrays, {'decision': {'candidates': 2, 'min_lead': 0.2}},
                   TRAINED_BANK_FORMAT, 2)
    loaded = load_trained_bank(path)
    assert loaded.second_opinion.form == 'linear' and loaded.min_lead == 0.2
    np.testing.assert_allclose(loaded.second_opinion.scores(features),
                               opinion.scores(features), atol=2e-2)


def test_shipped_bank_is_small_and_records_its_provenance() -> None:
    from speed_sign_detector.recognition.trained_bank import DEFAULT_BANK_FILE
    assert DEFAULT_BANK_FILE.stat().st_size <= 10 * 1024 * 1024
    bank = load_trained_bank(DEFAULT_BANK_FILE)
    opinion = bank.second_opinion
    assert opinion is not None and opinion.form == 'network'
    record = bank.provenance
    assert record['training']['model'] == 'network'
    # built by `make bank` with today's training defaults (the arched 6 renderings included)
    assert record['training'] == dataclasses.asdict(TrainingConfig())
    assert record['training']['members'] == opinion.hidden_weights.shape[0]
    assert bank.candidates == record['training']['candidates']
    assert bank.min_lead == record['training']['min_lead']
    assert [folder.rsplit('/', 1)[-1] for folder in record['data_folders']] == [
        'gtsrb-dev', 'gtsrb-lookalikes-dev']
    assert record['counts_per_class']['other_sign'] > 0 and record['package_version']
    # real background and whole-frame signs from the annotated scenes of gtsdb-dev
    assert [folder.rsplit('/', 1)[-1] for folder in record['scene_folders']] == ['gtsdb-dev']
    assert record['scene_examples']['no_sign'] > 0 and 'no_sign' in opinion.real_labels
    # every EU limit is known; those whose digits all occur on real signs (130 from the
    # digits of 100, 120 and 30; 90 from a turned 6) are learned from real pixels, while
    # 40 and 140, whose 4 no real crop shows, rest on renderings
    assert {'5', '10', '90', '110', '130'} <= set(opinion.real_labels)
    assert {'40', '140'} == set(opinion.labels) - set(opinion.real_labels) - {'no_sign'}
