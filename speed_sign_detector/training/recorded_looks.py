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
:func:`record_frame` and :func:`redecide_frame` do the same for the candidates of a frame
(:meth:`Classifier.classify`: each candidate's look and the larger-size retry's), for the
scene folds.

Training-side only: the node never imports this module.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classification import LABEL_NO_SIGN, Classification
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.crop_reading import (
    decide_crop,
    framed_look,
    padded_look_radius,
)
from speed_sign_detector.recognition.sign_reading import SignReading, read_signs

__all__ = ['RecordedFrame', 'RecordedLooks', 'record_frame', 'record_looks', 'redecide',
           'redecide_frame']

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


@dataclass(frozen=True)
class RecordedFrame:
    """The looks :meth:`Classifier.classify` may take at the candidates of one frame.

    Attributes:
        shape: (h, w) of the frame, pixels.
        radii: (N,) the candidates' radii, pixels (the larger-size retry takes the largest).
        first: each candidate's evidence at its radius.
        first_readings: the trained bank's reading of each, ``None`` where no sign was found
            there or the bank has no second opinion.
        retry: each candidate's evidence at the larger-size retry's radius, ``None`` for a
            candidate the config does not retry (taken for every candidate that may be
            retried, whatever its first answer: the rules decide which are).
        retry_readings: the bank's reading of each retry look, as ``first_readings``.
    """

    shape: tuple[int, int]
    radii: tuple[float, ...]
    first: tuple[Evidence, ...]
    first_readings: tuple[SignReading | None, ...]
    retry: tuple[Evidence | None, ...]
    retry_readings: tuple[SignReading | None, ...]


def record_frame(classifier: Classifier, gray: np.ndarray, candidates: Sequence[Candidate]
                 ) -> RecordedFrame:
    """Record every look :meth:`Classifier.classify` may take at ``candidates`` of the
    (H, W) uint8 frame ``gray``."""
    config = classifier.config
    first = classifier.evidence_for_candidates(gray, classifier.candidate_positions(candidates))
    retried = [index for index, candidate in enumerate(candidates)
               if classifier.may_retry_larger(candidate)]
    retry: list[Evidence | None] = [None] * len(candidates)
    if retried:
        second = classifier.evidence_for_candidates(
            gray, classifier.candidate_positions([candidates[i] for i in retried], retry=True),
            max(config.detection_psr_threshold, config.larger_size_retry_min_detection_psr))
        for index, evidence in zip(retried, second, strict=True):
            retry[index] = evidence
    return RecordedFrame(gray.shape[:2], tuple(float(c.radius_px) for c in candidates),
                         tuple(first), _readings(classifier, gray, first), tuple(retry),
                         _readings(classifier, gray, retry))


def _readings(classifier: Classifier, gray: np.ndarray, looks: Sequence[Evidence | None]
              ) -> tuple[SignReading | None, ...]:
    """The bank's reading of each located sign, read in the batches
    :meth:`Classifier.classify` reads them in (the same floats): the signs the filters do
    not withhold, upright and inverted apart; the others one by one."""
    bank = classifier.trained_bank
    if bank.second_opinion is None:
        return (None,) * len(looks)
    readings: list[SignReading | None] = [None] * len(looks)
    located = [index for index, look in enumerate(looks)
               if isinstance(look, CorrelationEvidence)]
    asked = [index for index in located if not classifier._withheld_by_filters(
        gray.shape, looks[index], bank.second_opinion)]
    for inverted in (False, True):
        group = [index for index in asked if looks[index].inverted == inverted]
        if group:
            for index, reading in zip(group, read_signs(
                    bank, 255 - gray if inverted else gray, [looks[i] for i in group])):
                readings[index] = reading
    for index in located:
        if index not in asked:
            readings[index] = classifier.sign_reading(gray, looks[index])
    return tuple(readings)


def redecide_frame(classifier: Classifier, looks: RecordedFrame) -> tuple[Classification, ...]:
    """The answers :meth:`Classifier.classify` gives for the recorded frame's candidates,
    decided by ``classifier``'s current rules and config (which must hold the bank the
    looks were recorded with, and the retry's radius and detection gate they were recorded
    with)."""
    shape_only = np.broadcast_to(np.uint8(0), looks.shape)  # the rules read its shape
    answers = [_decided(classifier, shape_only, look, reading)
               for look, reading in zip(looks.first, looks.first_readings, strict=True)]
    retried = [index for index, answer in enumerate(answers)
               if answer.label == LABEL_NO_SIGN and looks.retry[index] is not None]
    retried = sorted(retried, key=lambda i: -looks.radii[i])[
        :classifier.config.larger_size_retry_max_candidates]
    for index in retried:
        answer = _decided(classifier, shape_only, looks.retry[index],
                          looks.retry_readings[index])
        if classifier.second_look_stands(answer):
            answers[index] = answer
    return tuple(answers)


def _decided(classifier: Classifier, shape_only: np.ndarray, look: Evidence | None,
             reading: SignReading | None) -> Classification:
    if isinstance(look, Classification):
        return look
    if reading is None and classifier.trained_bank.second_opinion is not None:
        raise ValueError('the record holds no bank reading of this look')
    return classifier._decide(shape_only, look, reading=reading)


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
