"""What a trained bank reads of located signs, beyond the rendered filters' evidence.

Each sign the rendered filters located (:class:`~.candidate_evidence.CorrelationEvidence`)
is resampled once to its canonical patch (:func:`~.sign_features.aligned_patches`); from
that patch the second opinion scores every label (:mod:`.second_opinion`) and the filters
trained from real crops (:mod:`.real_filters`) re-rank the labels the second opinion may
choose among.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.real_filters import fused_label_order
from speed_sign_detector.recognition.sign_features import aligned_patches, sign_features
from speed_sign_detector.recognition.sign_polarity import is_lit_face
from speed_sign_detector.recognition.trained_bank import TrainedBank

__all__ = ['SignReading', 'read_signs']


@dataclass(frozen=True)
class SignReading:
    """The trained bank's reading of one located sign.

    Attributes:
        opinion_scores: (C,) the second opinion's score of each of its labels.
        ranking: the labels, best first, by the rendered and the real filters together;
            ``None`` without real filters (the rendered filters' ranking stands).
        lit_face: the sign has a glowing face in dark surroundings
            (:func:`.sign_polarity.is_lit_face`, at the located centre and radius).
    """

    opinion_scores: np.ndarray
    ranking: list[str] | None
    lit_face: bool = False


def read_signs(bank: TrainedBank, gray: np.ndarray, found: Sequence[CorrelationEvidence]
               ) -> list[SignReading]:
    """Read each located sign of ``gray`` with ``bank``'s second opinion (which it must
    have) and real filters (where it has them), all signs in one call.

    Args:
        bank: the trained bank.
        gray: (H, W) uint8 image the evidence was measured on.
        found: the rendered filters' evidence of each sign (centre and radius in pixels).

    Returns:
        One :class:`SignReading` per sign, in order.

    Raises:
        ValueError: when the bank has no second opinion.
    """
    if bank.second_opinion is None:
        raise ValueError('reading signs needs a trained bank with a second opinion')
    if not found:
        return []
    patches = aligned_patches(gray, np.asarray([[evidence.x_px, evidence.y_px,
                                                 evidence.radius_px] for evidence in found]))
    scores = bank.second_opinion.scores(sign_features(patches))
    lit = [is_lit_face(gray, evidence.x_px, evidence.y_px, evidence.radius_px)
           for evidence in found]
    if bank.real_filters is None:
        return [SignReading(row, None, lit_face) for row, lit_face in zip(scores, lit)]
    return [SignReading(row, fused_label_order(evidence.ranked, bank.real_filters, psr),
                        lit_face)
            for row, evidence, psr, lit_face in zip(scores, found,
                                                    bank.real_filters.psr(patches), lit,
                                                    strict=True)]
