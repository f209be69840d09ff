"""Every look the classifier takes at a crop, recorded once, and decided again later.

Reading a crop costs correlations (the first framing, then the padded radius and the
framed retry where the first look is "no sign") and the trained bank's reading of each
located sign (its real filters' ranking and the second opinion's scores). Deciding
between them, the rules of :mod:`~speed_sign_detector.recognition.second_opinion` and
:meth:`~speed_sign_detector.recognition.classifier.Classifier.decide`, costs next to
nothing. :func:`record_looks` keeps the costly part of every look, whether the answer needs
it or not; :func:`redecide` gives the answer :meth:`Classifier.decide_crop` would give with
the rules as they are when it is called (the same code decides: only the correlations and
readings come from the record). Bank validation (``bench/redecide_rules.py``) records
the crops of its runs once and tries rule changes on them in seconds instead of hours.

Training-side only: the node never imports this module.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classification import Classification
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.crop_reading import (
    decide_crop,
    framed_look,
    padded_look_radius,
)
from speed_sign_detector.recognition.sign_reading import SignReading

__all__ = ['RecordedLooks', 'record_looks', 'redecide']

Evidence = CorrelationEvidence | Classification


@dataclass(frozen=True)
class RecordedLooks:
    """The looks at one crop (see the module docstring).

    Attributes:
        shape: (h, w) of the crop, pixels.
        framing: the framing the first look was found with (``config.crop_framing``).
        first: the first look's evidence (:meth:`Classifier.crop_evidence`).
        padded: the padded-radius look's evidence, or ``None`` where the crop gets none.
        held: the framed retry's evidence, or ``None`` where the config has no retry.
        readings: the trained bank's reading of ``first``, ``padded`` and ``held`` (in
            that order), each ``None`` where that look found no sign or the bank has no
            second opinion.
    """

    shape: tuple[int, int]
    framing: str
    first: Evidence
    padded: Evidence | None
    held: Evidence | None
    readings: tuple[SignReading | None, SignReading | None, SignReading | None]


def record_looks(classifier: Classifier, crop: np.ndarray, first: Evidence | None = None
                 ) -> RecordedLooks:
    """Record every look :meth:`Classifier.decide_crop` may take at ``crop``.

    Args:
        classifier: the classifier (its bank and config) whose looks are recorded.
        crop: (h, w) uint8 gray crop.
        first: its :meth:`Classifier.crop_evidence` where already computed.
    """
    config = classifier.config
    height, width = crop.shape
    first = classifier.crop_evidence(crop) if first is None else first
    gate = classifier.crop_detection_gate
    radius = padded_look_radius(crop.shape, config.crop_framing, config.min_sign_radius_px)
    padded = None if radius is None else classifier.evidence_for_candidates(
        crop, [(width / 2.0, height / 2.0, radius)], gate)[0]
    held = framed_look(classifier, crop, config.crop_framing) if config.crop_framed_retry \
        else None
    bank = classifier.trained_bank
    readings = tuple(
        classifier.sign_reading(crop, look)
        if isinstance(look, CorrelationEvidence) and bank.second_opinion is not None
        else None for look in (first, padded, held))
    return RecordedLooks((height, width), config.crop_framing, first, padded, held,
                         readings)  # type: ignore[arg-type]


def redecide(classifier: Classifier, looks: RecordedLooks, use_second_opinion: bool = True
             ) -> Classification:
    """The answer :meth:`Classifier.decide_crop` gives for the recorded crop, decided by
    ``classifier``'s current rules and config on the recorded looks (``classifier`` must
    hold the bank the looks were recorded with)."""
    reader = _RecordedReader(classifier, looks)
    return decide_crop(reader, np.zeros(looks.shape, np.uint8), looks.first, looks.framing,
                       use_second_opinion)


class _RecordedReader:
    """A :class:`~.crop_reading.CropReader` whose second looks and bank readings come
    from a record; its decisions are the classifier's own."""

    def __init__(self, classifier: Classifier, looks: RecordedLooks) -> None:
        self._classifier = classifier
        self._looks = looks
        self.config: ClassifierConfig = classifier.config

    @property
    def crop_detection_gate(self) -> float:
        return self._classifier.crop_detection_gate

    def evidence_for_candidates(self, gray: np.ndarray,
                                positions: Sequence[tuple[float, float, float]],
                                detection_psr_threshold: float | None = None,
                                held_to_framing: bool = False) -> list[Evidence]:
        look = self._looks.held if held_to_framing else self._looks.padded
        if look is None:
            raise ValueError('the record holds no such look: it was recorded with another '
                             'crop_framing or crop_framed_retry')
        return [look]

    def decide(self, gray: np.ndarray, evidence: Evidence, use_second_opinion: bool = True,
               crop: bool = False) -> Classification:
        if isinstance(evidence, Classification):
            return evidence
        looks = (self._looks.first, self._looks.padded, self._looks.held)
        reading = next((recorded for look, recorded in zip(looks, self._looks.readings)
                        if look is evidence), None)
        if reading is None and use_second_opinion \
                and self._classifier.trained_bank.second_opinion is not None:
            raise ValueError('the record holds no bank reading of this look')
        return self._classifier._decide(gray, evidence, use_second_opinion, reading,
                                        crop=crop)

    def second_look_stands(self, answer: Classification) -> bool:
        return self._classifier.second_look_stands(answer)
