"""Classifier: decides the value of a sign at a candidate, or rejects it.

The result type :class:`Classification` is the contract with the tracker and node.

Method (DAGM 2010, section 4), per candidate:

1. A square ROI around the candidate (magnified when the sign is smaller than the
   smallest filters) is contrast-enhanced with CLAHE (optional) and correlated in the
   frequency domain with the detection filters (generic "00" and "100" signs) of the
   sizes near the candidate radius: the filter with the largest peak-to-sidelobe ratio
   (PSR) gives the sign's size and centre. A sign lit on a dark face (an electronic
   sign, :mod:`.sign_polarity`) is read inverted, in the painted templates' polarity,
   and so is its patch for the second opinion; one with rows of its lamps dark (caught
   between their pulses by a rolling shutter) is not read.
2. The classification filters of that size and its neighbours decide the value by the
   largest PSR. They see only the sign's inner field (the digits): the scene is masked
   with a disc at the detected centre and the templates with the same disc, because
   the ring and the surroundings are common to all classes and otherwise dominate the
   correlation (measured on real crops: 0.55 -> 0.9 accuracy).
3. Below ``psr_threshold``, or for a limit ahead of another label by less than
   ``min_margin``, the answer is "no sign" (a wrong limit is worse than none). With a
   trained bank its second opinion decides among the leading classes (or withholds);
   it may then answer down to ``second_opinion_psr_threshold`` (a frame's candidates:
   ``frame_second_opinion_psr_threshold``) when it leads clearly.
   A limit whose digits begin or end a longer limit's (:data:`LONGER_PARTNERS`: 30 of
   130) is withheld where the correlation scores that longer limit nearly as high
   (:data:`PARTNER_PSR_GAP`): the longer sign with its outer digit lost.

Every filter is a kth-law MACE composite (optimal trade-off with noise) of the
out-of-plane views of one template (yaw 0, +-10, +-20, +-30 deg x pitch 0, +-10 deg);
each in-plane rotation (-6, 0, +6 deg) has its own filter. Filters are synthesized from
the package's own renderings (:mod:`.templates`, :mod:`.mace`) at start-up, or read
from a cache keyed by every parameter that shapes them.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence

import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import BankFileError, ClassifierInputError
from speed_sign_detector.recognition.candidate_evidence import (
    CorrelationEvidence,
    EvidenceSearch,
    NoSignFound,
)
from speed_sign_detector.recognition.classification import (  # noqa: F401 (re-exported)
    LABEL_END_OF_LIMIT,
    LABEL_NO_SIGN,
    LABEL_OTHER_SIGN,
    Classification,
    label_of_class,
)
from speed_sign_detector.recognition.crop_framing import (  # noqa: F401 (re-exported)
    AUTO_FRAMINGS,
    CROP_FRAMINGS,
    crop_sign_radius,
    padded_fallback_radius,
)
from speed_sign_detector.recognition.crop_reading import (
    clearest,
    crop_positions,
    decide_crop,
    framed_search_config,
)
from speed_sign_detector.recognition.filter_banks import (  # noqa: F401 (re-exported)
    CLASS_TEMPLATES,
    SPEED_LIMITS_KMH,
    SizeBank,
    bank_radii,
    build_banks,
)
from speed_sign_detector.recognition.second_opinion import SecondOpinion
from speed_sign_detector.recognition.sign_features import FEATURE_SIZE
from speed_sign_detector.recognition.sign_reading import SignReading, read_signs
from speed_sign_detector.recognition.templates import LIMIT_VALUES_KMH
from speed_sign_detector.recognition.trained_bank import (
    TrainedBank,
    load_trained_bank,
    resolve_bank_file,
)

_LOG = logging.getLogger(__name__)


def _longer_partners() -> dict[str, tuple[str, ...]]:
    """Each limit whose digits begin or end a longer limit's, with those longer limits."""
    values = [str(value) for value in LIMIT_VALUES_KMH]
    partners = {short: tuple(longer for longer in values if len(longer) > len(short)
                             and (longer.startswith(short) or longer.endswith(short)))
                for short in values}
    return {short: longer for short, longer in partners.items() if longer}


#: Each limit whose digits begin or end a longer limit's, with those longer limits (5: 50;
#: 10: 100, 110; 20: 120; 30: 130; 40: 140): a sign of the longer value whose outer digit
#: the filters lose (small, blurred, cut by the window) reads as the shorter one.
LONGER_PARTNERS: dict[str, tuple[str, ...]] = _longer_partners()
#: A limit of :data:`LONGER_PARTNERS` is withheld where the correlation scores one of its
#: longer partners within this PSR of it (or above it). Leaving 120 out of training, its
#: held-out signs read as 20 had 120 within 0.0-2.9 PSR; 20s and 30s read right had it
#: that close in about 1 of 150 (5 folds by track).
PARTNER_PSR_GAP = 3.0


class Classifier:
    """Reads speed-limit signs at candidate positions with kth-law MACE filter banks.

    Building the banks (at construction) renders every template view and synthesizes
    the filters; see :attr:`build_time_s` and :attr:`bank_nbytes`.
    """

    def __init__(self, config: ClassifierConfig = ClassifierConfig(),
                 trained_bank: TrainedBank | None = None) -> None:
        """Build the filter banks.

        Args:
            config: the classifier's settings.
            trained_bank: the trained parts to use; by default the file named by
                ``config.bank_file`` (the shipped bank when empty, none for ``'none'``).

        Raises:
            BankFileError: when the bank file named cannot be read.
            ClassifierError: when the filter banks cannot be built.
        """
        self.config = config
        start = time.perf_counter()
        if trained_bank is None:
            path = resolve_bank_file(config.bank_file)
            trained_bank = load_trained_bank(path) if path is not None else TrainedBank(None)
        opinion = trained_bank.second_opinion
        if opinion is not None and opinion.feature_mean.size != FEATURE_SIZE:
            raise BankFileError(f'the trained bank\'s second opinion takes '
                                f'{opinion.feature_mean.size} features, this package computes '
                                f'{FEATURE_SIZE}: rebuild it with speed_sign_train build')
        self.trained_bank = trained_bank
        self.banks: tuple[SizeBank, ...] = build_banks(config, trained_bank.class_examples)
        self.build_time_s = time.perf_counter() - start
        self._evidence = EvidenceSearch(config, self.banks)
        # the same filters (one transposed copy for both searches)
        self._framed_evidence = EvidenceSearch(framed_search_config(config), self.banks,
                                               self._evidence.filters)
        _LOG.debug('classifier banks: %d sizes, %.1f MB, %.2f s', len(self.banks),
                   self.bank_nbytes / 1e6, self.build_time_s)

    @property
    def bank_nbytes(self) -> int:
        """Memory of the banks' filter spectra, bytes (the correlation reads a copy of
        them in another layout, :class:`~.candidate_evidence.TransposedFilters`: the
        classifier holds twice this)."""
        return sum(bank.nbytes for bank in self.banks)

    @property
    def min_radius_px(self) -> float:
        """Smallest sign radius the banks cover, pixels."""
        return float(self._evidence.radii[0])

    def classify(self, gray: np.ndarray, candidates: Sequence[Candidate]
                 ) -> tuple[Classification, ...]:
        """Classify each candidate of a frame.

        Args:
            gray: (H, W) uint8 frame.
            candidates: candidate centres and radii in frame pixels.

        Returns:
            One :class:`Classification` per candidate, in the same order. A candidate of
            at least ``larger_size_retry_min_radius_px`` answered "no sign" (at most
            ``larger_size_retry_max_candidates`` of them, the largest) is classified
            again at ``larger_size_retry_factor`` times its radius (classification
            filters only where a detection filter finds a sign there with a PSR of at
            least ``larger_size_retry_min_detection_psr``); that answer stands where it
            names a sign with a PSR of at least ``larger_size_retry_min_psr``.

        Raises:
            ClassifierInputError: (a ``ValueError``) for a frame that is not a non-empty
                2-D uint8 array.
        """
        gray = _check_gray(gray, 'gray')
        answers = list(self._classify_at(gray, self.candidate_positions(candidates)))
        # large signs whose candidate radius is the inner ring's or the digits': once
        # more at a larger size where the first answer was "no sign"
        retried = [index for index, (candidate, answer) in enumerate(zip(candidates, answers))
                   if answer.label == LABEL_NO_SIGN and self.may_retry_larger(candidate)]
        retried = sorted(retried, key=lambda i: -candidates[i].radius_px)[
            :self.config.larger_size_retry_max_candidates]
        if retried:
            second = self._classify_at(
                gray, self.candidate_positions([candidates[i] for i in retried], retry=True),
                max(self.config.detection_psr_threshold,
                    self.config.larger_size_retry_min_detection_psr))
            for index, answer in zip(retried, second):
                if self.second_look_stands(answer):
                    answers[index] = answer
        return tuple(answers)

    def sign_reading(self, gray: np.ndarray, evidence: CorrelationEvidence) -> SignReading:
        """The trained bank's reading (:func:`~.sign_reading.read_signs`) of the sign
        ``evidence`` located in the (H, W) uint8 ``gray``, inverted where the sign was read
        inverted; the bank must have a second opinion."""
        return read_signs(self.trained_bank, 255 - gray if evidence.inverted else gray,
                          [evidence])[0]

    def second_look_stands(self, answer: Classification) -> bool:
        """True when an answer from a second look (the larger-size retry of
        :meth:`classify`, a crop's padded and framed retries, :mod:`.crop_reading`)
        replaces "no sign": it names a sign with a PSR of at least ``larger_size_retry_min_psr`` (a
        second look needs clearer evidence: large round clutter matched a limit at PSR
        9-11, and at PSR 8 a dark GTSRB track of 60s was read as 80 at the padded size)."""
        return (answer.label != LABEL_NO_SIGN
                and answer.psr >= self.config.larger_size_retry_min_psr)

    def candidate_positions(self, candidates: Sequence[Candidate], retry: bool = False
                            ) -> list[tuple[float, float, float]]:
        """The (x, y, radius) positions, pixels, at which :meth:`classify` correlates
        candidates: each at its radius times ``candidate_radius_scale``, or with
        ``retry`` at the larger-size retry's radius (``larger_size_retry_factor`` times
        that)."""
        scale = self.config.candidate_radius_scale
        if retry:  # the products in the order classify has always formed them
            factor = self.config.larger_size_retry_factor
            return [(c.x_px, c.y_px, c.radius_px * scale * factor) for c in candidates]
        return [(c.x_px, c.y_px, c.radius_px * scale) for c in candidates]

    def may_retry_larger(self, candidate: Candidate) -> bool:
        """True when :meth:`classify` tries ``candidate`` once more at a larger size where
        it reads no sign (the retry is on and the candidate is large enough)."""
        return (self.config.larger_size_retry_factor > 1.0
                and candidate.radius_px >= self.config.larger_size_retry_min_radius_px)

    def _classify_at(self, gray: np.ndarray, positions: Sequence[tuple[float, float, float]],
                     detection_psr_threshold: float | None = None
                     ) -> tuple[Classification, ...]:
        """:meth:`classify` of signs at (x, y, radius) positions of a checked frame (the
        radius as the size search takes it), without the larger-size retry; see
        :meth:`evidence_for_candidates` for ``detection_psr_threshold``."""
        found = self.evidence_for_candidates(gray, positions, detection_psr_threshold)
        # the second opinion's scores of every sign it will be asked about, in one call
        # (one pass over its weights for all of them, not one per sign)
        opinion = self.trained_bank.second_opinion
        asked = [index for index, evidence in enumerate(found)
                 if isinstance(evidence, CorrelationEvidence)
                 and not self._withheld_by_filters(gray.shape, evidence, opinion)]
        readings: list[SignReading | None] = [None] * len(found)
        if opinion is not None and asked:
            # signs read inverted (lit on a dark face) are read so by the second opinion too
            for inverted in (False, True):
                group = [i for i in asked if found[i].inverted == inverted]
                if group:
                    image = 255 - gray if inverted else gray
                    for index, reading in zip(group, read_signs(self.trained_bank, image,
                                                                [found[i] for i in group])):
                        readings[index] = reading
        return tuple(evidence if isinstance(evidence, Classification)
                     else self._decide(gray, evidence, reading=reading)
                     for evidence, reading in zip(found, readings))

    def classify_crop(self, crop: np.ndarray, framing: str | None = None) -> Classification:
        """Classify a crop holding one centred sign.

        Args:
            crop: (h, w) uint8 gray crop.
            framing: how the crop frames the sign (default ``config.crop_framing``; see
                :mod:`.crop_framing`): ``'margin'`` as GTSRB crops do (a margin of 10% of
                the sign's size but at least 5 pixels on each side), ``'tight'`` (the box
                is the sign), ``'padded'`` (a 10% margin, no least margin), or
                ``'auto'`` (any: :meth:`crop_evidence`, then :meth:`decide_crop`). The
                detection filters then find the exact size and position.

        Returns:
            The classification; ``x_px``/``y_px`` are crop pixels. A crop too small for
            any sign (radius below ``min_sign_radius_px``) is answered ``'no_sign'``.

        Raises:
            ClassifierInputError: for an empty or non-2-D / non-uint8 array, or an
                unknown framing.
        """
        crop = _check_gray(crop, 'crop')
        return self.decide_crop(crop, self.crop_evidence(crop, framing), framing)

    def crop_evidence(self, crop: np.ndarray, framing: str | None = None,
                      detection_psr_threshold: float | None = None
                      ) -> CorrelationEvidence | Classification:
        """:meth:`evidence_at` for a crop framed as :meth:`classify_crop` takes it; for
        ``'auto'`` framing the ``'margin'`` and ``'tight'`` framings are tried (``'padded'``
        and ``'tight'`` in a crop under 20 px, :func:`.crop_framing.auto_framings`) and the
        one whose best classification filter matches more clearly (higher PSR) wins. (The
        detection filters' PSR is a worse judge: a filter larger than the sign of a margin
        crop often finds its ring more clearly, and the classification at that size
        suffers.) The detection gate is ``detection_psr_threshold`` (default
        :attr:`crop_detection_gate`)."""
        crop = _check_gray(crop, 'crop')
        gate = self.crop_detection_gate if detection_psr_threshold is None \
            else detection_psr_threshold
        return clearest(self.evidence_for_candidates(
            crop, crop_positions(crop.shape, framing or self.config.crop_framing,
                                 self.config.min_sign_radius_px), gate))

    @property
    def crop_detection_gate(self) -> float:
        """The least detection PSR at which a crop's classification filters run:
        ``crop_detection_psr_threshold`` with a trained second opinion, else the frames'
        ``detection_psr_threshold`` (see :mod:`.crop_reading`)."""
        if self.trained_bank.second_opinion is None:
            return self.config.detection_psr_threshold
        return self.config.crop_detection_psr_threshold

    def decide_crop(self, crop: np.ndarray, evidence: CorrelationEvidence | Classification,
                    framing: str | None = None, use_second_opinion: bool = True
                    ) -> Classification:
        """The answer for a crop from its :meth:`crop_evidence` (as :meth:`decide` with
        ``crop=True``). A crop answered "no sign" gets second looks
        (:func:`.crop_reading.decide_crop`): with ``'auto'`` framing a small crop at its
        ``'padded'`` radius (a 10% margin without GTSRB's least 5 pixels, as tools that pad
        boxes in proportion cut them), and with ``crop_framed_retry`` every crop with the
        search held to its framing's centre and size; such an answer stands where it names
        a sign with a PSR of at least ``larger_size_retry_min_psr``.

        Args:
            crop: (h, w) uint8 gray crop.
            evidence: :meth:`crop_evidence`'s result for it.
            framing: the framing ``evidence`` was found with (default
                ``config.crop_framing``).
            use_second_opinion: ``False`` decides by the correlation filters alone.
        """
        return decide_crop(self, crop, evidence, framing or self.config.crop_framing,
                           use_second_opinion)

    def decide(self, gray: np.ndarray, evidence: CorrelationEvidence | Classification,
               use_second_opinion: bool = True, crop: bool = False) -> Classification:
        """The answer for :meth:`evidence_at`'s result (as :meth:`classify` gives it);
        ``use_second_opinion=False`` decides by the correlation filters alone.
        ``crop=True``: ``gray`` is a crop framing one sign (:meth:`crop_evidence`'s
        input), whose border is the sign's box and not a frame border that cuts signs
        off: a sign reaching it (as in a tight crop) is read."""
        if isinstance(evidence, Classification):
            return evidence
        return self._decide(gray, evidence, use_second_opinion, crop=crop)

    # -- internals ---------------------------------------------------------------------

    def _no_sign(self, x_px: float, y_px: float, radius_px: float, psr: float = 0.0
                 ) -> Classification:
        return Classification(LABEL_NO_SIGN, None, psr, radius_px, 0.0, 0.0, x_px, y_px)

    def evidence_at(self, gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                    ) -> CorrelationEvidence | Classification:
        """Correlate the sign near (x, y) of about ``radius_px`` with every class.

        Returns:
            The ranked class scores with the sign's measured centre and size, or a
            "no sign" :class:`Classification` when no detection filter finds a sign there
            (or the position or size is unusable).
        """
        return self.evidence_for_candidates(gray, [(x_px, y_px, radius_px)])[0]

    def evidence_for_candidates(self, gray: np.ndarray,
                                positions: Sequence[tuple[float, float, float]],
                                detection_psr_threshold: float | None = None,
                                held_to_framing: bool = False
                                ) -> list[CorrelationEvidence | Classification]:
        """:meth:`evidence_at` for several signs of one image, correlated together (the
        same answers, faster).

        Args:
            gray: (H, W) uint8 image.
            positions: (x, y, radius) of each sign, pixels.
            detection_psr_threshold: least PSR of the best detection filter for the
                classification filters to run, "no sign" below (default
                ``config.detection_psr_threshold``; crops use
                :attr:`crop_detection_gate`).
            held_to_framing: search sizes and centres as a crop's framed retry does
                (``crop_retry_size_search_ratio``, ``crop_retry_position_search``).

        Returns:
            One result per position, in order.
        """
        found: list[CorrelationEvidence | Classification] = []
        search = self._framed_evidence if held_to_framing else self._evidence
        for (x_px, y_px, radius_px), evidence in zip(
                positions, search.evidence(gray, positions, detection_psr_threshold),
                strict=True):
            if isinstance(evidence, NoSignFound):
                evidence = self._no_sign(float(x_px), float(y_px), float(radius_px),
                                         evidence.detection_psr)
            found.append(evidence)
        return found

    def _withheld_by_filters(self, shape: tuple[int, ...] | None,
                             evidence: CorrelationEvidence, opinion: SecondOpinion | None
                             ) -> bool:
        """True when the correlation evidence alone withholds the answer (before any
        second opinion): its PSR is too small (with a second opinion:
        ``second_opinion_psr_threshold`` for a crop, ``frame_second_opinion_psr_threshold``
        for a frame's candidate), the sign was read inverted with rows of its lamps dark
        (``evidence.partly_unlit``), or the sign is cut by the border of the (H, W)
        ``shape`` frame (``None``: a crop, whose border cuts no sign)."""
        config = self.config
        if evidence.partly_unlit:
            return True  # what its dark rows leave of the digits may spell another value
        top_psr = evidence.ranked[0][1]
        if opinion is None:
            floor = config.psr_threshold
        else:
            floor = config.second_opinion_psr_threshold if shape is None \
                else config.frame_second_opinion_psr_threshold
        if top_psr < floor:
            return True
        if shape is None:
            return False
        frame_x, frame_y, size_radius = evidence.x_px, evidence.y_px, evidence.radius_px
        height, width = shape
        cut_px = max(-frame_x, -frame_y, frame_x - (width - 1),
                     frame_y - (height - 1)) + size_radius
        return cut_px > config.max_cut_fraction * size_radius

    def _decide(self, gray: np.ndarray, evidence: CorrelationEvidence,
                use_second_opinion: bool = True, reading: SignReading | None = None,
                crop: bool = False) -> Classification:
        """The answer from the correlation evidence: the leading class (or the second
        opinion's choice among the leading classes), or "no sign" when the PSR or the lead
        is too small, the second opinion withholds it, or the sign is cut by the frame
        border (not for a ``crop``). The second opinion chooses among the leading labels of
        the rendered and the real filters together where the bank has real filters.
        ``reading``: :func:`~.sign_reading.read_signs`'s answer for the sign when already
        computed."""
        config = self.config
        labels = [label_of_class(name) for name, _ in evidence.ranked]
        label = labels[0]
        frame_x, frame_y, size_radius = evidence.x_px, evidence.y_px, evidence.radius_px
        roll = evidence.rotation_deg
        opinion = self.trained_bank.second_opinion if use_second_opinion else None
        top_psr = evidence.ranked[0][1]
        withhold = self._withheld_by_filters(None if crop else gray.shape, evidence, opinion)
        if opinion is not None and not withhold:
            reading = reading or self.sign_reading(gray, evidence)
            # a weak correlation peak needs a clearer second opinion
            min_lead = self.trained_bank.min_lead if top_psr >= config.psr_threshold else \
                max(self.trained_bank.min_lead, config.second_opinion_low_psr_lead)
            correlation = [(name, psr) for name, (_, psr) in zip(labels, evidence.ranked)]
            choice = opinion.choose(reading.opinion_scores, reading.ranking or labels,
                                    self.trained_bank.candidates, min_lead,
                                    config.second_opinion_overrule_lead, correlation,
                                    config.crop_rendered_only_min_score if crop else None,
                                    lit_on_dark=evidence.inverted,
                                    lit_face=reading.lit_face)
            if (choice is not None and not crop and choice.isdigit()
                    and choice not in opinion.labels_with_crops
                    and top_psr < config.frame_value_without_crops_min_psr):
                choice = None  # in a frame, clutter reads as 5 or 40 on weak peaks
            if (choice is not None and not crop and choice.isdigit() and choice != label
                    and top_psr < config.frame_overrule_min_psr):
                choice = None  # in a frame, a weak peak is clutter the model reads a limit in
            if choice is None and not evidence.inverted:
                choice = opinion.certain_choice(reading.opinion_scores, correlation,
                                                config.second_opinion_certain_lead,
                                                config.psr_threshold)
            withhold = choice is None
            label = choice if choice is not None else label
        psr = next(p for (_, p), name in zip(evidence.ranked, labels) if name == label)
        partners = LONGER_PARTNERS.get(label, ())
        if any(name in partners and p > psr - PARTNER_PSR_GAP
               for (_, p), name in zip(evidence.ranked, labels)):
            withhold = True  # perhaps the longer limit with its outer digit lost
        if (reading is not None and reading.lit_face and label.isdigit()
                and psr - max((p for (_, p), name in zip(evidence.ranked, labels)
                               if name.isdigit() and name != label), default=-np.inf)
                < config.lit_face_min_margin):
            withhold = True  # the glow thins dark digits toward a close value
        runner_up = next((p for (_, p), name in zip(evidence.ranked, labels) if name != label),
                         -np.inf)
        margin = psr - runner_up if math.isfinite(runner_up) else psr
        if margin < config.min_margin and (opinion is None and label.isdigit()
                                           or label == LABEL_END_OF_LIMIT):
            # a limit on the filters alone, and always an end of limit (which drops the
            # limit in force), needs the filters' clear lead
            withhold = True
        if withhold:
            return Classification(LABEL_NO_SIGN, None, psr, size_radius, roll, margin,
                                  frame_x, frame_y)
        return Classification(label, int(label) if label.isdigit() else None, psr,
                              size_radius, roll, margin, frame_x, frame_y)


def _check_gray(image: np.ndarray, name: str) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ClassifierInputError(f'{name} must be a numpy array, got '
                                   f'{type(image).__name__}')
    if image.ndim != 2 or image.size == 0:
        raise ClassifierInputError(f'{name} must be a non-empty 2-D (H, W) array, got shape '
                              f'{image.shape}')
    if image.dtype != np.uint8:
        raise ClassifierInputError(f'{name} must be uint8, got {image.dtype}')
    return np.ascontiguousarray(image)
