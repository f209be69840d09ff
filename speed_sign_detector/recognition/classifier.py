"""Classifier: decides the value of a sign at a candidate, or rejects it.

The result type :class:`Classification` is the contract with the tracker and node.

Method (DAGM 2010, section 4), per candidate:

1. A square ROI around the candidate (magnified when the sign is smaller than the
   smallest filters) is contrast-enhanced with CLAHE (optional) and correlated in the
   frequency domain with the detection filters (generic "00" and "100" signs) of the
   sizes near the candidate radius: the filter with the largest peak-to-sidelobe ratio
   (PSR) gives the sign's size and centre.
2. The classification filters of that size and its neighbours decide the value by the
   largest PSR. They see only the sign's inner field (the digits): the scene is masked
   with a disc at the detected centre and the templates with the same disc, because
   the ring and the surroundings are common to all classes and otherwise dominate the
   correlation (measured on real crops: 0.55 -> 0.9 accuracy).
3. Below ``psr_threshold``, or for a limit ahead of another label by less than
   ``min_margin``, the answer is "no sign" (a wrong limit is worse than none). With a
   trained bank its second opinion decides among the leading classes (or withholds);
   it may then answer down to ``second_opinion_psr_threshold`` when it leads clearly.

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
from dataclasses import dataclass

import cv2
import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import BankFileError, ClassifierInputError
from speed_sign_detector.recognition.correlation import (
    correlate,
    disc_window,
    keep_inside,
    peak_psr,
    scene_spectrum,
)
from speed_sign_detector.recognition.filter_banks import (  # noqa: F401 (re-exported)
    CLASS_TEMPLATES,
    SPEED_LIMITS_KMH,
    SizeBank,
    bank_radii,
    build_banks,
)
from speed_sign_detector.recognition.sign_features import (
    FEATURE_SIZE,
    aligned_patches,
    sign_features,
)
from speed_sign_detector.recognition.trained_bank import (
    TrainedBank,
    load_trained_bank,
    resolve_bank_file,
)

#: Labels that are not a speed limit.
LABEL_END_OF_LIMIT = 'end_of_limit'
LABEL_OTHER_SIGN = 'other_sign'
LABEL_NO_SIGN = 'no_sign'


@dataclass(frozen=True)
class Classification:
    """What the classifier says about one candidate or crop.

    Attributes:
        label: the limit as a string of its km/h value (``'30'``), or one of
            ``'end_of_limit'``, ``'other_sign'``, ``'no_sign'``.
        limit_kmh: the speed limit in km/h, or ``None`` when the label is not a limit.
        psr: peak-to-sidelobe ratio of the winning class (dimensionless): the mean of
            its ``class_score_top`` best filters (sizes x in-plane rotations).
        radius_px: the sign's radius (size of the winning class's best filter), pixels.
        rotation_deg: in-plane rotation of the winning class's best filter, degrees
            (counter-clockwise).
        margin: PSR of the winner minus PSR of the best class with a different label.
        x_px, y_px: the sign's centre as the best filter's correlation peak placed it,
            frame pixels (crop pixels for :meth:`Classifier.classify_crop`).
    """

    label: str
    limit_kmh: int | None
    psr: float
    radius_px: float
    rotation_deg: float
    margin: float
    x_px: float
    y_px: float

    @property
    def is_limit(self) -> bool:
        """True when the answer is a speed limit."""
        return self.limit_kmh is not None

_LOG = logging.getLogger(__name__)


def _label_of(class_name: str) -> str:
    if class_name.isdigit():
        return class_name
    if class_name == 'end_of_limit':
        return LABEL_END_OF_LIMIT
    return LABEL_OTHER_SIGN



@dataclass(frozen=True)
class CorrelationEvidence:
    """What the correlation filters measured at one sign position.

    Attributes:
        ranked: (class name, score) of every class correlated, best first; the score is
            the mean PSR of the class's ``class_score_top`` best filters.
        x_px, y_px: the sign's centre from the winning class's best filter, frame pixels.
        radius_px: the sign's radius (that filter's size), frame pixels.
        rotation_deg: in-plane rotation of that filter, degrees counter-clockwise.
        detection_psr: PSR of the best detection filter (dimensionless).
    """

    ranked: tuple[tuple[str, float], ...]
    x_px: float
    y_px: float
    radius_px: float
    rotation_deg: float
    detection_psr: float


@dataclass(frozen=True)
class _Scored:
    """Best detection result of one candidate."""

    bank_index: int
    psr: float
    peak_y: int
    peak_x: int


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
        self._radii = np.asarray([bank.radius_px for bank in self.banks])
        # per size: the upright classification filters, and the filters of each class
        self._upright_filters = [np.flatnonzero(bank.class_rolls_deg == 0.0)
                                 for bank in self.banks]
        self._class_filters: list[dict[str, list[int]]] = []
        for bank in self.banks:
            by_class: dict[str, list[int]] = {}
            for filter_index, name in enumerate(bank.class_names):
                by_class.setdefault(name, []).append(filter_index)
            self._class_filters.append(by_class)
        tiles = (config.clahe_tiles, config.clahe_tiles)
        self._clahe = (cv2.createCLAHE(clipLimit=config.clahe_clip_limit, tileGridSize=tiles)
                       if config.clahe_clip_limit > 0 else None)
        _LOG.debug('classifier banks: %d sizes, %.1f MB, %.2f s', len(self.banks),
                   self.bank_nbytes / 1e6, self.build_time_s)

    @property
    def bank_nbytes(self) -> int:
        """Memory of all filter spectra, bytes."""
        return sum(bank.nbytes for bank in self.banks)

    @property
    def min_radius_px(self) -> float:
        """Smallest sign radius the banks cover, pixels."""
        return float(self._radii[0])

    def classify(self, gray: np.ndarray, candidates: Sequence[Candidate]
                 ) -> tuple[Classification, ...]:
        """Classify each candidate of a frame.

        Args:
            gray: (H, W) uint8 frame.
            candidates: candidate centres and radii in frame pixels.

        Returns:
            One :class:`Classification` per candidate, in the same order.

        Raises:
            ClassifierInputError: (a ``ValueError``) for a frame that is not a non-empty
                2-D uint8 array.
        """
        gray = _check_gray(gray, 'gray')
        scale = self.config.candidate_radius_scale
        return tuple(self._classify_at(gray, c.x_px, c.y_px, c.radius_px * scale)
                     for c in candidates)

    def classify_crop(self, crop: np.ndarray, framing: str | None = None) -> Classification:
        """Classify a crop holding one centred sign.

        Args:
            crop: (h, w) uint8 gray crop.
            framing: how the crop frames the sign (default ``config.crop_framing``):
                ``'margin'`` as GTSRB crops do (a margin of 10% of the sign's size but at
                least 5 pixels on each side), ``'tight'`` (the box is the sign), or
                ``'auto'`` (either: the size search spans both). The detection filters
                then find the exact size and position.

        Returns:
            The classification; ``x_px``/``y_px`` are crop pixels. A crop too small for
            any sign (radius below ``min_sign_radius_px``) is answered ``'no_sign'``.

        Raises:
            ClassifierInputError: for an empty or non-2-D / non-uint8 array, or an
                unknown framing.
        """
        crop = _check_gray(crop, 'crop')
        return self.decide(crop, self.crop_evidence(crop, framing))

    def crop_evidence(self, crop: np.ndarray, framing: str | None = None
                      ) -> CorrelationEvidence | Classification:
        """:meth:`evidence_at` for a crop framed as :meth:`classify_crop` takes it; for
        ``'auto'`` framing both framings are tried and the one whose detection filter
        finds the sign more clearly (higher PSR) wins."""
        crop = _check_gray(crop, 'crop')
        height, width = crop.shape
        framing = framing or self.config.crop_framing
        framings = ('margin', 'tight') if framing == 'auto' else (framing,)
        best: CorrelationEvidence | Classification | None = None
        for name in framings:
            found = self.evidence_at(crop, width / 2.0, height / 2.0,
                                     crop_sign_radius(crop.shape, name))
            if best is None or _detection_psr(found) > _detection_psr(best):
                best = found
        assert best is not None
        return best

    def decide(self, gray: np.ndarray, evidence: CorrelationEvidence | Classification,
               use_second_opinion: bool = True) -> Classification:
        """The answer for :meth:`evidence_at`'s result (as :meth:`classify` gives it);
        ``use_second_opinion=False`` decides by the correlation filters alone."""
        if isinstance(evidence, Classification):
            return evidence
        return self._decide(gray, evidence, use_second_opinion)

    # -- internals ---------------------------------------------------------------------

    @staticmethod
    def _roi(gray: np.ndarray, x_px: float, y_px: float, size: int,
             scale: float = 1.0) -> tuple[np.ndarray, float]:
        """(size, size) uint8 window centred on (x, y), resampled by ``scale``; outside
        the frame the border pixels are replicated.

        Returns the window and the scale actually applied (a reduction rounds the source
        window to whole pixels).
        """
        if scale > 1.0:  # magnify, bilinear
            matrix = np.float32([[scale, 0.0, size / 2.0 - x_px * scale],
                                 [0.0, scale, size / 2.0 - y_px * scale]])
            return cv2.warpAffine(gray, matrix, (size, size), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE), scale
        source = size if scale == 1.0 else int(round(size / scale))
        top = int(round(y_px - source / 2.0))
        left = int(round(x_px - source / 2.0))
        window = np.ascontiguousarray(_window(gray, top, left, source))
        if source == size:
            return window, 1.0
        return cv2.resize(window, (size, size), interpolation=cv2.INTER_AREA), size / source

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
        config = self.config
        if not (math.isfinite(x_px) and math.isfinite(y_px) and math.isfinite(radius_px)):
            return self._no_sign(float(x_px), float(y_px), float(radius_px))
        if radius_px < config.min_sign_radius_px or radius_px <= 0:
            return self._no_sign(x_px, y_px, radius_px)
        # signs smaller than the smallest filters are magnified to their size, signs
        # larger than the largest reduced
        scale = max(1.0, self.min_radius_px * config.magnify_margin / radius_px)
        largest_radius = float(self._radii[-1])
        if radius_px > largest_radius / config.magnify_margin:
            scale = largest_radius / config.magnify_margin / radius_px
        radius_scaled = radius_px * scale
        low = radius_scaled / config.size_search_ratio
        high = radius_scaled * config.size_search_ratio
        indices = [i for i, r in enumerate(self._radii) if low <= r <= high]
        if not indices:
            return self._no_sign(x_px, y_px, radius_px)
        largest = max(self.banks[i].fft_size for i in indices)
        raw, scale = self._roi(gray, x_px, y_px, largest, scale)
        enhanced = self._clahe.apply(raw) if self._clahe is not None else raw
        best = self._detect(enhanced, indices, largest, radius_scaled)
        if best.psr < config.detection_psr_threshold:
            return self._no_sign(x_px, y_px, radius_px, best.psr)
        det_bank = self.banks[best.bank_index]
        det_offset = (largest - det_bank.fft_size) // 2
        # sign centre in ROI pixel coordinates (continuous)
        centre_y = best.peak_y + det_offset + det_bank.canvas_px / 2.0
        centre_x = best.peak_x + det_offset + det_bank.canvas_px / 2.0
        scene = enhanced if config.clahe_for_classification else raw
        # every classification filter's PSR, by class name: (psr, x, y, radius, roll)
        found: dict[str, list[tuple[float, float, float, float, float]]] = {}
        # coarse to fine: at the detected size the upright filters of every class, then
        # the rotated ones of the leading classes; at the neighbouring sizes all filters
        # of those leaders
        lo = max(0, best.bank_index - config.class_size_neighbours)
        hi = min(len(self.banks) - 1, best.bank_index + config.class_size_neighbours)
        upright = self._upright_filters[best.bank_index]
        passes: list[tuple[int, np.ndarray | None]] = [(best.bank_index, upright),
                                                       (best.bank_index, None)]
        passes += [(i, None) for i in range(lo, hi + 1) if i != best.bank_index]
        spectra: dict[int, tuple[np.ndarray, int, int]] = {}
        leaders: set[str] | None = None
        for pass_number, (index, chosen) in enumerate(passes):
            bank = self.banks[index]
            size = bank.class_size
            if chosen is None:
                assert leaders is not None
                class_filters = self._class_filters[index]
                chosen = np.asarray(sorted(f for n in leaders for f in class_filters.get(n, ())),
                                    dtype=np.intp)
                if pass_number == 1:  # the detected size: the leaders' rotated filters
                    chosen = chosen[bank.class_rolls_deg[chosen] != 0.0]
            if chosen.size == 0:
                continue
            if index not in spectra:
                # window of the classification size around the detected centre
                top = int(math.floor(centre_y - size / 2.0 + 0.5))
                left = int(math.floor(centre_x - size / 2.0 + 0.5))
                sub = _window(scene, top, left, size)
                field = disc_window((size, size), (centre_y - top, centre_x - left),
                                    config.class_field_radius * bank.radius_px)
                spectra[index] = (scene_spectrum(keep_inside(sub, field), (size, size),
                                                 config.kth_law), top, left)
            spectrum, top, left = spectra[index]
            planes = correlate(spectrum, bank.classification[chosen], (size, size))
            # the template's centre is at size / 2: the peak lies near the offset of the
            # detected centre from the window's centre
            expect_y = int(round(centre_y - top - size / 2.0))
            expect_x = int(round(centre_x - left - size / 2.0))
            search = max(1, int(round(config.class_position_search * bank.radius_px)))
            stats = peak_psr(planes, (expect_y, expect_x), search, *self._lobes(bank.radius_px))
            # circular -> signed shifts, then the sign's centre in ROI pixels
            centre_xs = ((stats.x + size // 2) % size - size // 2 + left + size / 2.0).tolist()
            centre_ys = ((stats.y + size // 2) % size - size // 2 + top + size / 2.0).tolist()
            rolls = bank.class_rolls_deg[chosen].tolist()
            for f, (filter_index, psr) in enumerate(zip(chosen.tolist(), stats.psr.tolist())):
                found.setdefault(bank.class_names[filter_index], []).append((
                    psr, centre_xs[f], centre_ys[f], bank.radius_px, rolls[f]))
            if pass_number == 0:
                ranked = sorted(found, key=lambda n: -max(e[0] for e in found[n]))
                leaders = set(ranked[:config.class_neighbour_classes])
        if not found:
            return self._no_sign(x_px, y_px, radius_px)
        # a class scores the mean of its few best filters (sizes x rotations): steadier
        # than the single best one
        top = config.class_score_top
        scores = {name: _mean(sorted(p[0] for p in entries)[-top:])
                  for name, entries in found.items()}
        ranked = tuple(sorted(scores.items(), key=lambda item: -item[1]))
        _, roi_x, roi_y, size_radius, roll = max(found[ranked[0][0]])
        return CorrelationEvidence(ranked, x_px + (roi_x - largest / 2.0) / scale,
                                   y_px + (roi_y - largest / 2.0) / scale, size_radius / scale,
                                   roll, best.psr)

    def _classify_at(self, gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                     ) -> Classification:
        return self.decide(gray, self.evidence_at(gray, x_px, y_px, radius_px))

    def _decide(self, gray: np.ndarray, evidence: CorrelationEvidence,
                use_second_opinion: bool = True) -> Classification:
        """The answer from the correlation evidence: the leading class (or the second
        opinion's choice among the leading classes), or "no sign" when the PSR or the lead
        is too small, the second opinion withholds it, or the sign is cut by the frame
        border."""
        config = self.config
        labels = [_label_of(name) for name, _ in evidence.ranked]
        label = labels[0]
        frame_x, frame_y, size_radius = evidence.x_px, evidence.y_px, evidence.radius_px
        roll = evidence.rotation_deg
        height, width = gray.shape
        cut_px = max(-frame_x, -frame_y, frame_x - (width - 1),
                     frame_y - (height - 1)) + size_radius
        opinion = self.trained_bank.second_opinion if use_second_opinion else None
        top_psr = evidence.ranked[0][1]
        withhold = (top_psr < (config.psr_threshold if opinion is None
                               else config.second_opinion_psr_threshold)
                    or cut_px > config.max_cut_fraction * size_radius)
        if opinion is not None and not withhold:
            scores = opinion.scores(sign_features(aligned_patches(
                gray, np.asarray([[frame_x, frame_y, size_radius]]))))[0]
            # a weak correlation peak needs a clearer second opinion
            min_lead = self.trained_bank.min_lead if top_psr >= config.psr_threshold else \
                max(self.trained_bank.min_lead, config.second_opinion_low_psr_lead)
            choice = opinion.choose(scores, labels, self.trained_bank.candidates, min_lead)
            withhold = choice is None
            label = choice if choice is not None else label
        psr = next(p for (_, p), name in zip(evidence.ranked, labels) if name == label)
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

    def _detect(self, roi: np.ndarray, indices: Sequence[int], largest: int,
                radius_px: float) -> _Scored:
        """Best detection filter (size) and its peak, among the banks ``indices``."""
        best: _Scored | None = None
        for index in indices:
            bank = self.banks[index]
            size = bank.fft_size
            offset = (largest - size) // 2
            sub = roi[offset:offset + size, offset:offset + size]
            planes = correlate(scene_spectrum(sub, (size, size), self.config.kth_law),
                               bank.detection, (size, size))
            centre = (size - bank.canvas_px) // 2
            search = max(1, int(math.ceil(self.config.position_search * radius_px)))
            stats = peak_psr(planes, (centre, centre), search, *self._lobes(bank.radius_px))
            top = int(np.argmax(stats.psr))
            if best is None or stats.psr[top] > best.psr:
                best = _Scored(index, float(stats.psr[top]), int(stats.y[top]),
                               int(stats.x[top]))
        assert best is not None  # indices is never empty
        return best

    def _lobes(self, radius_px: float) -> tuple[int, int]:
        """PSR window half sizes (sidelobe square, excluded centre) for a sign radius."""
        sidelobe = max(5, int(round(self.config.sidelobe_window * radius_px)))
        exclude = max(1, int(round(self.config.sidelobe_exclude * radius_px)))
        return sidelobe, min(exclude, sidelobe - 1)


def _window(image: np.ndarray, top: int, left: int, size: int) -> np.ndarray:
    """(size, size) window of ``image`` at (top, left); outside the image its border is
    replicated. A view when the window lies inside."""
    height, width = image.shape
    if top >= 0 and left >= 0 and top + size <= height and left + size <= width:
        return image[top:top + size, left:left + size]
    rows = np.clip(np.arange(top, top + size), 0, height - 1)
    cols = np.clip(np.arange(left, left + size), 0, width - 1)
    return image[rows[:, None], cols[None, :]]


def _mean(values: Sequence[float]) -> float:
    """Mean of a few floats: the same float as ``numpy.mean`` (which adds fewer than 8
    values in order) without the cost of making an array."""
    return sum(values) / len(values) if len(values) < 8 else float(np.mean(values))


def _detection_psr(found: CorrelationEvidence | Classification) -> float:
    return found.detection_psr if isinstance(found, CorrelationEvidence) else found.psr


#: Crop framings :meth:`Classifier.classify_crop` accepts.
CROP_FRAMINGS: tuple[str, ...] = ('auto', 'margin', 'tight')


def crop_sign_radius(shape: tuple[int, ...], framing: str) -> float:
    """The sign radius to search around for a crop of ``shape`` (h, w), pixels.

    ``'margin'``: GTSRB framing, a margin of 10% of the sign's size but at least 5 pixels
    each side; ``'tight'``: the sign fills the box. (``'auto'`` tries both:
    :meth:`Classifier.crop_evidence`.)
    """
    if framing not in CROP_FRAMINGS or framing == 'auto':
        raise ClassifierInputError(f'unknown crop framing {framing!r}; expected one of '
                                   f'{", ".join(CROP_FRAMINGS)}')
    side = float(min(shape[0], shape[1]))
    if framing == 'tight':
        return side / 2.0
    return (min(side / 1.2, side - 10.0) if side > 10.0 else side / 1.2) / 2.0


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
