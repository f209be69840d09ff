"""Correlation evidence at several sign positions of one image, measured together.

The classifier's method (see :mod:`.classifier`) per position: the detection filters of
the sizes near the position's radius find the sign's size and centre; the classification
filters of that size (upright, of every class; then the rotated ones of the leading
classes) and of its neighbouring sizes (the leaders' filters) score the classes.

Every step runs for all positions at once: the correlations of every position with the
filters of one size share one product, one batched inverse FFT and one search for their
peaks (:func:`~.correlation.correlation_peaks`, which transforms only the rows of the
planes that the peak search reads). The answers are those of one position at a time.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import cv2
import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.recognition.correlation import (
    correlation_peaks,
    disc_window,
    keep_inside,
    scene_spectra,
    transposed_spectra,
)
from speed_sign_detector.recognition.filter_banks import SizeBank
from speed_sign_detector.recognition.sign_polarity import (
    Polarity,
    is_partly_unlit,
    painted_polarity,
    sign_polarity,
)


#: A candidate whose polarity is unsure (:attr:`.Polarity.UNSURE`: it may be an electronic
#: sign lit on a dark face, a single or dotted digit, a small sign's blurred ring of lamps)
#: and whose painted reading stays below ``psr_threshold`` is read inverted too; the
#: inverted reading stands where its leading class scores at least this PSR. gtsrb-dev
#: look-alikes (blue, no-entry and no-vehicles signs) read inverted score 12 at most (at
#: 8, 176 of 3,920 would have been read inverted and 3 of them as 40); rendered LED
#: signs read right score 11 to 20.
INVERTED_READING_MIN_PSR = 12.0


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
        inverted: the sign looked lit on a dark face (an electronic sign,
            :func:`.sign_polarity.is_lit_on_dark`) and was correlated inverted; whatever
            reads it further (the second opinion) must read ``255 - image`` too.
        partly_unlit: a sign read inverted (lit on a dark face) with rows of its lamps
            dark: pulsed lamps caught by a rolling shutter between pulses
            (:func:`.sign_polarity.is_partly_unlit`). What is left of its digits may
            spell another value, so it is not read.
    """

    ranked: tuple[tuple[str, float], ...]
    x_px: float
    y_px: float
    radius_px: float
    rotation_deg: float
    detection_psr: float
    inverted: bool = False
    partly_unlit: bool = False


@dataclass(frozen=True)
class NoSignFound:
    """No detection filter found a sign at a position, or the position or size is
    unusable.

    Attributes:
        detection_psr: PSR of the best detection filter (dimensionless), 0 when none was
            correlated.
    """

    detection_psr: float = 0.0


#: One filter's match: (PSR, centre x, centre y in ROI pixels, radius px, roll deg).
_Match = tuple[float, float, float, float, float]


@dataclass
class _Position:
    """The state of one position through the steps of :class:`EvidenceSearch`."""

    x_px: float
    y_px: float
    radius_px: float
    scale: float  # ROI pixels per frame pixel
    radius_scaled: float  # the sign's expected radius, ROI pixels
    indices: list[int]  # bank indices of the detection filters searched
    largest: int  # ROI side, pixels (largest FFT size of those banks)
    raw: np.ndarray  # (largest, largest) uint8 ROI, as correlated
    lit: np.ndarray  # the same ROI as the image shows it (before any inversion)
    enhanced: np.ndarray  # the same after CLAHE (or ``raw``)
    inverted: bool  # the ROI is the image inverted (a sign lit on a dark face)
    # read painted, but it may be lit on a dark face (:attr:`.Polarity.UNSURE`)
    polarity_unsure: bool = False
    # by bank index: (best detection PSR of the size, peak row, peak column); the peak in
    # plane pixels, unwrapped around the expected peak (it may lie before index 0)
    detections: dict[int, tuple[float, int, int]] = field(default_factory=dict)
    bank_index: int = -1  # the best detection filter's size
    detection_psr: float = 0.0
    centre_y: float = 0.0  # the detected sign centre, ROI pixels (continuous)
    centre_x: float = 0.0
    # by bank index: the masked classification window's spectrum (in the layout of
    # :func:`~.correlation.transposed_spectra`), its top and left
    spectra: dict[int, tuple[np.ndarray, int, int]] = field(default_factory=dict)
    # every classification filter's match, by class name
    found: dict[str, list[_Match]] = field(default_factory=dict)
    leaders: set[str] = field(default_factory=set)


@dataclass(frozen=True)
class TransposedFilters:
    """The filter spectra of one size bank in the layout the correlation reads
    (:func:`~.correlation.transposed_spectra`; the same values as the bank's).

    Attributes:
        detection: (Fd, N // 2 + 1, N) complex64 conjugated detection filter spectra.
        classification: (Fc, M // 2 + 1, M) complex64 conjugated classification ones.
    """

    detection: np.ndarray
    classification: np.ndarray

    @classmethod
    def of(cls, bank: SizeBank) -> TransposedFilters:
        """The transposed filters of ``bank``."""
        return cls(transposed_spectra(bank.detection), transposed_spectra(bank.classification))

    @property
    def nbytes(self) -> int:
        """Memory of the spectra, bytes."""
        return int(self.detection.nbytes + self.classification.nbytes)


class EvidenceSearch:
    """Correlates positions of an image with the filter banks of a classifier."""

    def __init__(self, config: ClassifierConfig, banks: Sequence[SizeBank],
                 filters: Sequence[TransposedFilters] | None = None) -> None:
        """Index the banks.

        Args:
            config: the classifier's settings.
            banks: the filter banks, by increasing radius.
            filters: their :class:`TransposedFilters` (made here when not given; searches
                over the same banks can share them: :attr:`filters`).
        """
        self.config = config
        self.banks = tuple(banks)
        self.filters = tuple(filters) if filters is not None else tuple(
            TransposedFilters.of(bank) for bank in self.banks)
        if len(self.filters) != len(self.banks):
            raise ValueError(f'{len(self.filters)} transposed filter sets for '
                             f'{len(self.banks)} banks')
        self.radii = np.asarray([bank.radius_px for bank in self.banks])
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

    def evidence(self, gray: np.ndarray, positions: Sequence[tuple[float, float, float]],
                 detection_psr_threshold: float | None = None
                 ) -> list[CorrelationEvidence | NoSignFound]:
        """Correlate the signs near each position with every class.

        Args:
            gray: (H, W) uint8 image.
            positions: (x, y, radius) of each expected sign: centre and radius in image
                pixels.
            detection_psr_threshold: least detection PSR for the classification filters
                to run (default: ``config.detection_psr_threshold``).

        Returns:
            Per position, in order: the ranked class scores with the sign's measured
            centre and size, or :class:`NoSignFound`.
        """
        threshold = (self.config.detection_psr_threshold if detection_psr_threshold is None
                     else detection_psr_threshold)
        prepared = [self._prepare(gray, x_px, y_px, radius_px)
                    for x_px, y_px, radius_px in positions]
        found = self._search(prepared, threshold)
        # a sign whose polarity is unsure and that reads as nothing clear painted is read
        # inverted too; a clear inverted reading stands
        unsure = [index for index, (position, evidence) in enumerate(zip(prepared, found))
                  if isinstance(position, _Position) and position.polarity_unsure
                  and not self._clear(evidence)]
        if unsure:
            inverted = self._search([self._inverted(prepared[index]) for index in unsure],
                                    threshold)
            for index, evidence in zip(unsure, inverted):
                if _top_score(evidence) >= INVERTED_READING_MIN_PSR:
                    found[index] = evidence
        return found

    def _search(self, prepared: Sequence[_Position | NoSignFound], threshold: float
                ) -> list[CorrelationEvidence | NoSignFound]:
        """Detect and classify the prepared positions (:meth:`evidence`'s steps)."""
        searched = [p for p in prepared if isinstance(p, _Position)]
        self._detect(searched)
        located = [p for p in searched if p.detection_psr >= threshold]
        self._classify(located)
        return [p if isinstance(p, NoSignFound) else self._result(p, threshold)
                for p in prepared]

    def _clear(self, evidence: CorrelationEvidence | NoSignFound) -> bool:
        """True for evidence whose leading class scores at least ``psr_threshold``."""
        return _top_score(evidence) >= self.config.psr_threshold

    # -- steps ------------------------------------------------------------------------

    def _prepare(self, gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                 ) -> _Position | NoSignFound:
        """The ROI and detection sizes of a position, or :class:`NoSignFound` when the
        position or size is unusable."""
        config = self.config
        if not (math.isfinite(x_px) and math.isfinite(y_px) and math.isfinite(radius_px)):
            return NoSignFound()
        if radius_px < config.min_sign_radius_px or radius_px <= 0:
            return NoSignFound()
        # signs smaller than the smallest filters are magnified to their size, signs
        # larger than the largest reduced
        scale = max(1.0, float(self.radii[0]) * config.magnify_margin / radius_px)
        largest_radius = float(self.radii[-1])
        if radius_px > largest_radius / config.magnify_margin:
            scale = largest_radius / config.magnify_margin / radius_px
        radius_scaled = radius_px * scale
        low = radius_scaled / config.size_search_ratio
        high = radius_scaled * config.size_search_ratio
        indices = [i for i, r in enumerate(self.radii) if low <= r <= high]
        if not indices:
            return NoSignFound()
        largest = max(self.banks[i].fft_size for i in indices)
        raw, scale = _roi(gray, x_px, y_px, largest, scale)
        # an electronic sign (lit on a dark face) is read inverted: the polarity of the
        # painted templates, its lamps' bloom damped (the test on the ROI, centred on the
        # position)
        polarity = sign_polarity(raw, largest / 2.0, largest / 2.0, radius_px * scale)
        inverted = polarity is Polarity.LIT_ON_DARK
        lit = raw
        if inverted:
            raw = painted_polarity(raw)
        return _Position(x_px, y_px, radius_px, scale, radius_scaled, indices, largest, raw,
                         lit, self._enhance(raw), inverted, polarity is Polarity.UNSURE)

    def _inverted(self, position: _Position) -> _Position:
        """A fresh, unsearched copy of a position read painted, its ROI inverted
        (:func:`.sign_polarity.painted_polarity`)."""
        raw = painted_polarity(position.lit)
        return _Position(position.x_px, position.y_px, position.radius_px, position.scale,
                         position.radius_scaled, position.indices, position.largest, raw,
                         position.lit, self._enhance(raw), True)

    def _enhance(self, raw: np.ndarray) -> np.ndarray:
        """The ROI after CLAHE (``raw`` itself without CLAHE)."""
        return self._clahe.apply(raw) if self._clahe is not None else raw

    def _detect(self, positions: Sequence[_Position]) -> None:
        """Every position's best detection filter (size) and its peak; sets
        ``bank_index``, ``detection_psr`` and the centre."""
        # by bank index: the positions searched at that size and their ROIs
        jobs: dict[int, list[tuple[_Position, np.ndarray]]] = {}
        for position in positions:
            for index in position.indices:
                size = self.banks[index].fft_size
                offset = (position.largest - size) // 2
                jobs.setdefault(index, []).append(
                    (position, position.enhanced[offset:offset + size, offset:offset + size]))
        for index, group in jobs.items():
            bank = self.banks[index]
            size = bank.fft_size
            detection = self.filters[index].detection
            filters = detection.shape[0]
            spectra = scene_spectra([sub for _, sub in group], (size, size),
                                    self.config.kth_law, transposed=True)
            # (positions x filters) products conj(H) * S
            product = (detection * spectra[:, None]).reshape((-1,) + detection.shape[1:])
            centre = (size - bank.canvas_px) // 2
            searches = np.repeat([max(1, int(math.ceil(self.config.position_search *
                                                         position.radius_scaled)))
                                  for position, _ in group], filters)
            stats = correlation_peaks(product, (size, size), (centre, centre), searches,
                                      *self._lobes(bank.radius_px))
            psr = stats.psr.reshape(-1, filters)
            tops = psr.argmax(axis=1)
            for slot, (position, _) in enumerate(group):
                plane = slot * filters + int(tops[slot])
                # the plane index is circular, and the search square around the expected
                # peak reaches across index 0 (a sign up or left of the position by more
                # than that peak's few pixels): a signed shift from the expected peak
                position.detections[index] = (
                    float(psr[slot, tops[slot]]),
                    centre + _signed_shift(int(stats.y[plane]) - centre, size),
                    centre + _signed_shift(int(stats.x[plane]) - centre, size))
        for position in positions:
            best_index = -1
            best_psr = 0.0
            for index in position.indices:  # the first of equal PSRs wins
                if best_index < 0 or position.detections[index][0] > best_psr:
                    best_index, best_psr = index, position.detections[index][0]
            bank = self.banks[best_index]
            _, peak_y, peak_x = position.detections[best_index]
            offset = (position.largest - bank.fft_size) // 2
            position.bank_index = best_index
            position.detection_psr = best_psr
            # sign centre in ROI pixel coordinates (continuous)
            position.centre_y = peak_y + offset + bank.canvas_px / 2.0
            position.centre_x = peak_x + offset + bank.canvas_px / 2.0

    def _classify(self, positions: Sequence[_Position]) -> None:
        """Every classification filter's match, coarse to fine: at the detected size the
        upright filters of every class, then the rotated ones of the leading classes; at
        the neighbouring sizes all filters of those leaders. Fills ``found``."""
        config = self.config
        self._correlate_classes([(p, p.bank_index, self._upright_filters[p.bank_index])
                                 for p in positions])
        refinements: list[tuple[_Position, int, np.ndarray]] = []
        for position in positions:
            found = position.found
            ranked = sorted(found, key=lambda n: -max(e[0] for e in found[n]))
            position.leaders = set(ranked[:config.class_neighbour_classes])
            detected = position.bank_index
            low = max(0, detected - config.class_size_neighbours)
            high = min(len(self.banks) - 1, detected + config.class_size_neighbours)
            for index in [detected] + [i for i in range(low, high + 1) if i != detected]:
                class_filters = self._class_filters[index]
                chosen = np.asarray(sorted(f for n in position.leaders
                                           for f in class_filters.get(n, ())), dtype=np.intp)
                if index == detected:  # the detected size: the leaders' rotated filters
                    chosen = chosen[self.banks[index].class_rolls_deg[chosen] != 0.0]
                refinements.append((position, index, chosen))
        self._correlate_classes(refinements)

    def _correlate_classes(self, jobs: Sequence[tuple[_Position, int, np.ndarray]]) -> None:
        """Correlate each (position, bank index, classification filter indices) job and
        add the matches to the position's ``found``, in job order."""
        config = self.config
        by_bank: dict[int, list[int]] = {}
        for job_number, (position, index, chosen) in enumerate(jobs):
            if chosen.size:
                by_bank.setdefault(index, []).append(job_number)
        matches: dict[int, list[tuple[str, _Match]]] = {}
        for index, job_numbers in by_bank.items():
            bank = self.banks[index]
            size = bank.class_size
            group = [jobs[j] for j in job_numbers]
            self._class_spectra([position for position, _, _ in group], index)
            spectra = [position.spectra[index] for position, _, _ in group]
            counts = [chosen.size for _, _, chosen in group]
            classification = self.filters[index].classification
            if all(chosen is group[0][2] for _, _, chosen in group):
                # the same filters for every position: (positions x filters) products
                scenes = np.stack([spectrum for spectrum, _, _ in spectra])[:, None]
                product = (_rows(classification, group[0][2]) * scenes).reshape(
                    (-1,) + classification.shape[1:])
            else:
                product = classification[np.concatenate([c for _, _, c in group])]
                start = 0
                for count, (spectrum, _, _) in zip(counts, spectra):
                    product[start:start + count] *= spectrum
                    start += count
            tops = np.repeat([top for _, top, _ in spectra], counts)
            lefts = np.repeat([left for _, _, left in spectra], counts)
            # the template's centre is at size / 2: the peak lies near the offset of the
            # detected centre from the window's centre
            expected = np.repeat(
                [(int(round(position.centre_y - top - size / 2.0)),
                  int(round(position.centre_x - left - size / 2.0)))
                 for (position, _, _), (_, top, left) in zip(group, spectra)], counts, axis=0)
            search = max(1, int(round(config.class_position_search * bank.radius_px)))
            stats = correlation_peaks(product, (size, size), expected, search,
                                      *self._lobes(bank.radius_px))
            # circular -> signed shifts, then the sign's centre in ROI pixels
            centre_xs = (_signed_shift(stats.x, size) + lefts + size / 2.0).tolist()
            centre_ys = (_signed_shift(stats.y, size) + tops + size / 2.0).tolist()
            psrs = stats.psr.tolist()
            plane = 0
            for job_number, (_, _, chosen) in zip(job_numbers, group):
                job_matches = []
                for filter_index, roll in zip(chosen.tolist(),
                                              bank.class_rolls_deg[chosen].tolist()):
                    job_matches.append((bank.class_names[filter_index], (
                        psrs[plane], centre_xs[plane], centre_ys[plane], bank.radius_px,
                        roll)))
                    plane += 1
                matches[job_number] = job_matches
        for job_number, (position, _, _) in enumerate(jobs):
            for name, match in matches.get(job_number, ()):
                position.found.setdefault(name, []).append(match)

    def _class_spectra(self, positions: Sequence[_Position], index: int) -> None:
        """Each position's spectrum of the classification window of size ``index``
        around its detected centre, the sign's inner field kept, with the window's top
        and left in ROI pixels (``spectra[index]``; computed once)."""
        config = self.config
        bank = self.banks[index]
        size = bank.class_size
        missing = [position for position in positions if index not in position.spectra]
        if not missing:
            return
        fields = []
        corners = []
        for position in missing:
            scene = position.enhanced if config.clahe_for_classification else position.raw
            top = int(math.floor(position.centre_y - size / 2.0 + 0.5))
            left = int(math.floor(position.centre_x - size / 2.0 + 0.5))
            inner = _disc(size, position.centre_y - top, position.centre_x - left,
                          config.class_field_radius * bank.radius_px)
            fields.append(keep_inside(_window(scene, top, left, size), inner))
            corners.append((top, left))
        spectra = scene_spectra(fields, (size, size), config.kth_law, transposed=True)
        for position, spectrum, (top, left) in zip(missing, spectra, corners):
            position.spectra[index] = (spectrum, top, left)

    def _result(self, position: _Position, detection_psr_threshold: float
                ) -> CorrelationEvidence | NoSignFound:
        """The evidence of a position after :meth:`_classify` (or :class:`NoSignFound`
        when its detection PSR is below ``detection_psr_threshold``, the one that kept it
        from classification)."""
        if position.detection_psr < detection_psr_threshold:
            return NoSignFound(position.detection_psr)
        if not position.found:
            return NoSignFound()
        found = position.found
        # a class scores the mean of its few best filters (sizes x rotations): steadier
        # than the single best one
        top = self.config.class_score_top
        scores = {name: _mean(sorted(p[0] for p in entries)[-top:])
                  for name, entries in found.items()}
        ranked = tuple(sorted(scores.items(), key=lambda item: -item[1]))
        _, roi_x, roi_y, size_radius, roll = max(found[ranked[0][0]])
        scale = position.scale
        half = position.largest / 2.0
        partly_unlit = position.inverted and is_partly_unlit(position.lit, roi_x, roi_y,
                                                             size_radius)
        return CorrelationEvidence(ranked, position.x_px + (roi_x - half) / scale,
                                   position.y_px + (roi_y - half) / scale,
                                   size_radius / scale, roll, position.detection_psr,
                                   position.inverted, partly_unlit)

    def _lobes(self, radius_px: float) -> tuple[int, int]:
        """PSR window half sizes (sidelobe square, excluded centre) for a sign radius."""
        sidelobe = max(5, int(round(self.config.sidelobe_window * radius_px)))
        exclude = max(1, int(round(self.config.sidelobe_exclude * radius_px)))
        return sidelobe, min(exclude, sidelobe - 1)


def _roi(gray: np.ndarray, x_px: float, y_px: float, size: int, scale: float = 1.0
         ) -> tuple[np.ndarray, float]:
    """(size, size) uint8 window centred on (x, y), resampled by ``scale``; outside the
    image the border pixels are replicated.

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


def _rows(array: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """``array[indices]``: a strided view where the indices step evenly (every class's
    upright filter is every third), else a copy."""
    if indices.size > 1:
        step = int(indices[1] - indices[0])
        if step > 0 and np.array_equal(np.diff(indices), np.full(indices.size - 1, step)):
            return array[int(indices[0]):int(indices[-1]) + 1:step]
    return array[indices]


@functools.lru_cache(maxsize=256)  # the centre is whole or half a pixel: few windows
def _disc(size: int, centre_y: float, centre_x: float, radius_px: float) -> np.ndarray:
    """(size, size) :func:`~.correlation.disc_window` (read-only, cached)."""
    disc = disc_window((size, size), (centre_y, centre_x), radius_px)
    disc.flags.writeable = False
    return disc


def _window(image: np.ndarray, top: int, left: int, size: int) -> np.ndarray:
    """(size, size) window of ``image`` at (top, left); outside the image its border is
    replicated. A view when the window lies inside."""
    height, width = image.shape
    if top >= 0 and left >= 0 and top + size <= height and left + size <= width:
        return image[top:top + size, left:left + size]
    rows = np.clip(np.arange(top, top + size), 0, height - 1)
    cols = np.clip(np.arange(left, left + size), 0, width - 1)
    return image[rows[:, None], cols[None, :]]


IndexT = TypeVar('IndexT', int, np.ndarray)


def _signed_shift(shift: IndexT, period: int) -> IndexT:
    """A circular shift of a correlation plane of side ``period`` (an int, or an integer
    array of them) as the signed shift in ``[-period // 2, period - period // 2)``."""
    return (shift + period // 2) % period - period // 2


def _top_score(evidence: CorrelationEvidence | NoSignFound) -> float:
    """The leading class's score of ``evidence``, ``-inf`` for :class:`NoSignFound`."""
    return evidence.ranked[0][1] if isinstance(evidence, CorrelationEvidence) else -math.inf


def _mean(values: Sequence[float]) -> float:
    """Mean of a few floats: the same float as ``numpy.mean`` (which adds fewer than 8
    values in order) without the cost of making an array."""
    return sum(values) / len(values) if len(values) < 8 else float(np.mean(values))
