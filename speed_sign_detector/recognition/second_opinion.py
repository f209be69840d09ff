"""The second opinion: a linear model on sign features that chooses among the classes the
correlation filters ranked highest, or withholds the answer.

It never adds a class: it picks one of the correlation's ``candidates`` leading labels,
and only when it agrees that this label is the best of the labels it has real examples
of, with a lead of at least ``min_lead`` (and of ``overrule_lead`` to answer a limit
other than the correlation's leading limit). Its real labels are those it learned from
real pixels: real crops, or composites of real digits (a 130 made of the real digits of
120 and 30 signs). A class it has no real examples of (a limit whose digits it has seen
only rendered, such as the 4 of 40 and 140 km/h) is never its choice: when the
correlation filters rank such a class first, their answer stands only where the model
scores that class highest too, at least :data:`RENDERED_ONLY_MIN_SCORE` (the linear
form) or :data:`NETWORK_RENDERED_ONLY_MIN_SCORE` (the network form); otherwise the
answer is withheld, never turned into another limit. Nor does it turn a limit the
correlation read first into an end of limit (which would drop the limit in force): it
withholds the answer instead.

The model takes standardised :mod:`.sign_features` and has one of two forms, both with
scores from about -1 to +1 per class, comparable across classes:

- linear: ridge regression onto +-1 class indicators (one-vs-rest), solved in closed
  form with numpy;
- network: an ensemble of small one-hidden-layer networks whose score of a class is the
  mean of ``2 p - 1`` over its members.

Bank building fits both forms (:mod:`speed_sign_detector.training.opinion_fitting`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ['NETWORK_RENDERED_ONLY_MIN_SCORE', 'RENDERED_ONLY_MIN_SCORE', 'SecondOpinion']

#: The label of end-of-limit signs (as :data:`.classifier.LABEL_END_OF_LIMIT`).
END_OF_LIMIT_LABEL = 'end_of_limit'

#: Least score of the model for a class it learned from renderings only, for the
#: correlation's answer of that class to stand. Scores aim at +1 for the class and -1
#: else; on gtsdb-dev the 4 of 10 false limits that were such classes (5 and 10 km/h on
#: small clutter) scored -0.33 to -0.5, a clean rendered 130 km/h sign -0.05.
RENDERED_ONLY_MIN_SCORE = -0.25
#: The same floor for the network form, whose scores are 2 p - 1 (here p >= 0.65). On
#: gtsdb-dev single frames, 5 of the network's 6 false limits of such classes (5, 10
#: and 40 km/h on clutter) scored -0.01 to 0.24 (with the linear floor the network read
#: 10 false limits, 4 more than the linear model).
NETWORK_RENDERED_ONLY_MIN_SCORE = 0.3


@dataclass(frozen=True)
class SecondOpinion:
    """A trained model over sign features: linear, or an ensemble of small networks.

    Attributes:
        labels: (C,) the labels it scores: limits as km/h strings, ``'end_of_limit'``,
            ``'other_sign'``.
        feature_mean: (D,) float32 mean of the training features.
        feature_scale: (D,) float32 standard deviation of the training features.
        weights: linear form: (D, C) float32 ridge weights on the standardised features;
            network form: (M, H, C) output weights of the M members' H hidden units.
        bias: (C,) float32 (linear form) or (M, C) (network form).
        real_labels: the labels it was trained on real examples of (the others were
            learned from renderings only).
        hidden_weights: network form only: (M, D, H) float32 hidden-layer weights.
        hidden_bias: network form only: (M, H) float32.
    """

    labels: tuple[str, ...]
    feature_mean: np.ndarray
    feature_scale: np.ndarray
    weights: np.ndarray
    bias: np.ndarray
    real_labels: tuple[str, ...]
    hidden_weights: np.ndarray | None = None
    hidden_bias: np.ndarray | None = None

    def __post_init__(self) -> None:
        dimension, classes = self.feature_mean.size, len(self.labels)
        if self.hidden_weights is None:
            expected = {'weights': ((dimension, classes), self.weights.shape),
                        'bias': ((classes,), self.bias.shape)}
        else:
            members, hidden = self.hidden_weights.shape[0], self.hidden_weights.shape[-1]
            expected = {'hidden_weights': ((members, dimension, hidden),
                                           self.hidden_weights.shape),
                        'hidden_bias': ((members, hidden), np.shape(self.hidden_bias)),
                        'weights': ((members, hidden, classes), self.weights.shape),
                        'bias': ((members, classes), self.bias.shape)}
        for name, (wanted, got) in expected.items():
            if tuple(got) != wanted:
                raise ValueError(f'{name} of shape {tuple(got)} does not fit {dimension} '
                                 f'features and {classes} labels (expected {wanted})')

    @property
    def form(self) -> str:
        """``'linear'`` or ``'network'``."""
        return 'linear' if self.hidden_weights is None else 'network'

    def scores(self, features: np.ndarray) -> np.ndarray:
        """(N, C) scores of (N, D) feature vectors (about +1 for the class, -1 else)."""
        standardised = (np.asarray(features, np.float32) - self.feature_mean) \
            / self.feature_scale
        if self.hidden_weights is None:
            return standardised @ self.weights + self.bias
        total = np.zeros((len(standardised), len(self.labels)), np.float32)
        for hidden_weights, hidden_bias, weights, bias in zip(
                self.hidden_weights, self.hidden_bias, self.weights, self.bias):
            hidden = np.maximum(standardised @ hidden_weights + hidden_bias, 0.0)
            logits = hidden @ weights + bias
            logits -= logits.max(axis=1, keepdims=True)
            probabilities = np.exp(logits)
            total += 2.0 * probabilities / probabilities.sum(axis=1, keepdims=True) - 1.0
        return total / len(self.weights)

    def choose(self, scores: np.ndarray, ranked_labels: Sequence[str], candidates: int,
               min_lead: float, overrule_lead: float = 0.0) -> str | None:
        """The label to answer for one sign, or ``None`` to withhold.

        Args:
            scores: (C,) this model's scores of the sign.
            ranked_labels: the correlation filters' labels, best first (repeats allowed).
            candidates: how many of the leading distinct labels the model may choose from.
            min_lead: least lead of the chosen label over the model's next best label.
            overrule_lead: least lead for the model to answer a limit other than the limit
                the correlation ranked first (a weaker lead withholds the answer: a value
                the two disagree on is not published).

        Returns:
            One of ``ranked_labels`` or ``None``.
        """
        distinct: list[str] = []
        for label in ranked_labels:
            if label not in distinct:
                distinct.append(label)
        if not distinct:
            return None
        order = np.argsort(-scores)
        if distinct[0] not in self.real_labels:
            # no real examples of the correlation's winner: it stands where the model,
            # which learned it from renderings, reads it too, and not as "rather not this
            # class" (its one-vs-rest target is +1 for the class, -1 else)
            best = int(order[0])
            floor = RENDERED_ONLY_MIN_SCORE if self.form == 'linear' else \
                NETWORK_RENDERED_ONLY_MIN_SCORE
            if self.labels[best] == distinct[0] and float(scores[best]) >= floor:
                return distinct[0]
            if distinct[0].isdigit():
                # a model that never saw this value's real pixels rejects them on weak
                # grounds: it does not turn the value into another (it would pull a 130
                # to the 120 it knows); the answer is withheld
                return None
        real = [int(i) for i in order if self.labels[int(i)] in self.real_labels]
        model_best = self.labels[real[0]]
        lead = float(scores[real[0]] - scores[real[1]]) if len(real) > 1 else np.inf
        allowed = [label for label in distinct[:candidates] if label in self.real_labels]
        if model_best not in allowed or lead < min_lead:
            return None
        if model_best != distinct[0] and model_best.isdigit() and distinct[0].isdigit() \
                and lead < overrule_lead:
            return None
        if model_best == END_OF_LIMIT_LABEL and distinct[0].isdigit():
            # an end of limit drops the limit in force: the model confirms one the
            # correlation read, but does not turn a limit the correlation read into one
            return None
        return model_best
