"""Fitting the second opinion, with numpy alone: a ridge model in closed form
(:func:`fit_second_opinion`) or an ensemble of small neural networks
(:func:`fit_network_opinion`).

The network is an ensemble of ``members`` one-hidden-layer perceptrons over the
standardised sign features (:mod:`~speed_sign_detector.recognition.sign_features`):
``softmax(relu(x W1 + b1) W2 + b2)``, trained with softmax cross-entropy (class-balanced
sample weights), Adam and a cosine learning-rate schedule, each member from its own random
start and sample order. The ensemble's score of a class is the mean of ``2 p - 1`` over
its members (``p``: that member's probability of the class), so scores run from -1 to +1
as the linear model's do and
:meth:`~speed_sign_detector.recognition.second_opinion.SecondOpinion.choose` reads both
the same way; averaging members makes the probabilities less overconfident than any one
member's.

Measured on gtsrb-dev, 5 folds split by track (see the README's training section): the
same features and decision rule read 0.939 of the limit crops with the ridge model, 0.950
with one network; the shipped ensemble of three, choosing among three labels, 0.951 with
a smaller spread over the folds. Its run time is two small matrix products per sign and
member; its size, with float16 weights, about 1 MB per member of 256 units.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from speed_sign_detector.recognition.second_opinion import SecondOpinion

__all__ = ['fit_network_opinion', 'fit_second_opinion', 'ordered_labels']


def fit_network_opinion(features: np.ndarray, labels: Sequence[str], hidden_units: int = 256,
                        epochs: int = 12, members: int = 3, seed: int = 0,
                        weights: np.ndarray | None = None,
                        real_labels: Sequence[str] | None = None,
                        learning_rate: float = 1e-3, weight_decay: float = 1e-4,
                        batch_size: int = 256, min_steps: int = 300) -> SecondOpinion:
    """Train the ensemble.

    Args:
        features: (N, D) float feature vectors.
        labels: (N,) label of each.
        hidden_units: units of each member's hidden layer (>= 1).
        epochs: passes over the data per member (>= 1).
        members: networks in the ensemble (>= 1).
        seed: seeds every member's start and sample order.
        weights: optional (N,) sample weights (for example to balance classes); by
            default every label weighs the same in total.
        real_labels: the labels with real examples (default: every label).
        learning_rate: Adam's step size at the start of the cosine schedule.
        weight_decay: L2 penalty on the weight matrices (not on the biases).
        batch_size: samples per step.
        min_steps: least number of steps per member: a small training set gets more
            epochs than ``epochs`` (a few dozen crops would otherwise see a handful of
            steps and stay untrained).

    Returns:
        The trained :class:`~speed_sign_detector.recognition.second_opinion.SecondOpinion`
        (network form).

    Raises:
        ValueError: for features and labels that do not fit, fewer than two labels, or
            a setting out of range.
    """
    features = np.asarray(features, np.float32)
    if features.ndim != 2 or len(features) != len(labels) or len(features) == 0:
        raise ValueError(f'features must be (N, D) with one label per row, got '
                         f'{features.shape} for {len(labels)} labels')
    if hidden_units < 1 or epochs < 1 or members < 1 or batch_size < 1:
        raise ValueError(f'hidden_units, epochs, members and batch_size must be >= 1, got '
                         f'{hidden_units}, {epochs}, {members}, {batch_size}')
    names = ordered_labels(labels)
    if len(names) < 2:
        raise ValueError(f'need examples of at least two labels, got {names}')
    index = np.asarray([names.index(label) for label in labels])
    if weights is None:
        counts = np.bincount(index, minlength=len(names))
        weights = len(index) / (len(names) * counts[index])
    sample_weights = np.asarray(weights, np.float32)
    mean = features.mean(axis=0)
    scale = features.std(axis=0) + np.float32(1e-3)
    standardised = (features - mean) / scale
    trained = [_fit_member(standardised, index, len(names), sample_weights, hidden_units,
                           epochs, min_steps, np.random.default_rng([seed, member]),
                           learning_rate, weight_decay, batch_size) for member in range(members)]
    real = tuple(name for name in names if real_labels is None or name in real_labels)
    return SecondOpinion(names, mean, scale.astype(np.float32),
                         np.stack([member[2] for member in trained]),
                         np.stack([member[3] for member in trained]), real,
                         hidden_weights=np.stack([member[0] for member in trained]),
                         hidden_bias=np.stack([member[1] for member in trained]))


def _fit_member(standardised: np.ndarray, index: np.ndarray, classes: int,
                sample_weights: np.ndarray, hidden_units: int, epochs: int, min_steps: int,
                rng: np.random.Generator, learning_rate: float, weight_decay: float,
                batch_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One member: (W1 (D, H), b1 (H,), W2 (H, C), b2 (C,)), float32; ``epochs`` passes,
    or more to reach ``min_steps`` steps."""
    count, dimension = standardised.shape
    params = [
        (rng.standard_normal((dimension, hidden_units)) * np.sqrt(2.0 / dimension)
         ).astype(np.float32),
        np.zeros(hidden_units, np.float32),
        (rng.standard_normal((hidden_units, classes)) * np.sqrt(1.0 / hidden_units)
         ).astype(np.float32),
        np.zeros(classes, np.float32)]
    first_moment = [np.zeros_like(p) for p in params]
    second_moment = [np.zeros_like(p) for p in params]
    steps_per_epoch = -(-count // batch_size)
    epochs = max(epochs, -(-min_steps // steps_per_epoch))
    total_steps = epochs * steps_per_epoch
    step = 0
    for _ in range(epochs):
        order = rng.permutation(count)
        for start in range(0, count, batch_size):
            batch = order[start:start + batch_size]
            grads = _gradients(params, standardised[batch], index[batch],
                               sample_weights[batch])
            grads[0] += weight_decay * params[0]
            grads[2] += weight_decay * params[2]
            step += 1
            rate = learning_rate * 0.5 * (1.0 + np.cos(np.pi * step / total_steps))
            for param, grad, first, second in zip(params, grads, first_moment,
                                                  second_moment):
                first *= 0.9
                first += 0.1 * grad
                second *= 0.999
                second += 0.001 * grad * grad
                param -= (rate * (first / (1 - 0.9 ** step))
                          / (np.sqrt(second / (1 - 0.999 ** step)) + 1e-8)).astype(np.float32)
    return params[0], params[1], params[2], params[3]


def _gradients(params: list[np.ndarray], inputs: np.ndarray, index: np.ndarray,
               sample_weights: np.ndarray) -> list[np.ndarray]:
    """Gradients of the weighted mean cross-entropy of one batch."""
    hidden_weights, hidden_bias, weights, bias = params
    pre = inputs @ hidden_weights + hidden_bias
    hidden = np.maximum(pre, 0.0)
    logits = hidden @ weights + bias
    logits -= logits.max(axis=1, keepdims=True)
    probabilities = np.exp(logits)
    probabilities /= probabilities.sum(axis=1, keepdims=True)
    delta = probabilities
    delta[np.arange(len(index)), index] -= 1.0
    delta *= (sample_weights / sample_weights.sum())[:, None]
    back = delta @ weights.T
    back[pre <= 0.0] = 0.0
    return [inputs.T @ back, back.sum(axis=0), hidden.T @ delta, delta.sum(axis=0)]


def fit_second_opinion(features: np.ndarray, labels: Sequence[str], ridge: float,
                       weights: np.ndarray | None = None,
                       real_labels: Sequence[str] | None = None) -> SecondOpinion:
    """Fit the model in closed form.

    Args:
        features: (N, D) float feature vectors.
        labels: (N,) label of each.
        ridge: Tikhonov regularisation (> 0) on the standardised features.
        weights: optional (N,) sample weights (for example to balance classes).
        real_labels: the labels with real examples (default: every label).

    Returns:
        The fitted :class:`SecondOpinion`.
    """
    features = np.asarray(features, np.float32)
    if features.ndim != 2 or len(features) != len(labels) or len(features) == 0:
        raise ValueError(f'features must be (N, D) with one label per row, got '
                         f'{features.shape} for {len(labels)} labels')
    if ridge <= 0:
        raise ValueError(f'ridge must be > 0, got {ridge}')
    names = ordered_labels(labels)
    if len(names) < 2:
        raise ValueError(f'need examples of at least two labels, got {names}')
    index = np.asarray([names.index(label) for label in labels])
    sample = np.ones(len(features), np.float64) if weights is None else \
        np.asarray(weights, np.float64)
    mean = features.mean(axis=0)
    scale = features.std(axis=0) + np.float32(1e-3)
    standardised = ((features - mean) / scale).astype(np.float64)
    targets = -np.ones((len(features), len(names)))
    targets[np.arange(len(features)), index] = 1.0
    # weighted ridge with an unpenalised bias: centre by the weighted means
    total = sample.sum()
    x_mean = (sample[:, None] * standardised).sum(axis=0) / total
    y_mean = (sample[:, None] * targets).sum(axis=0) / total
    centred_x = (standardised - x_mean) * np.sqrt(sample)[:, None]
    centred_y = (targets - y_mean) * np.sqrt(sample)[:, None]
    count, dimension = centred_x.shape
    if dimension > count:  # dual form: N x N
        gram = centred_x @ centred_x.T
        solution = centred_x.T @ np.linalg.solve(gram + ridge * np.eye(count), centred_y)
    else:
        gram = centred_x.T @ centred_x
        solution = np.linalg.solve(gram + ridge * np.eye(dimension), centred_x.T @ centred_y)
    bias = y_mean - x_mean @ solution
    real = tuple(name for name in names if real_labels is None or name in real_labels)
    return SecondOpinion(names, mean.astype(np.float32), scale.astype(np.float32),
                         solution.astype(np.float32), bias.astype(np.float32), real)


def ordered_labels(labels: Sequence[str]) -> tuple[str, ...]:
    """The distinct labels in the models' order: limits by value, then the others by name."""
    return tuple(sorted(set(labels), key=lambda name: (
        not name.isdigit(), int(name) if name.isdigit() else 0, name)))
