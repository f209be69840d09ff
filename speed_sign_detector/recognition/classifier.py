"""Classifier: decides the value of a sign at a candidate, or rejects it.

The result type :class:`Classification` is the contract with the tracker and node.

Method (DAGM 2010, section 4): a square ROI around the candidate is contrast-enhanced
with CLAHE and correlated in the frequency domain with kth-law MACE filter banks built
from rendered templates (:mod:`.templates`, :mod:`.mace`). Detection filters (generic
"00" and "100" signs) of the sizes near the candidate radius find and size the sign;
the classification filters of that size (and its neighbours) then decide the value by
the largest peak-to-sidelobe ratio (PSR). Every filter combines the out-of-plane views
of one template; the in-plane rotations are separate filters.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import ClassifierError
from speed_sign_detector.recognition.correlation import correlate, peak_psr, scene_spectrum
from speed_sign_detector.recognition.mace import mace_filter, training_spectra
from speed_sign_detector.recognition.templates import (GRAY_TEMPLATE_GEOMETRY, render_master,
                                                       views_from_master)

#: Speed limits the classifier can read, in km/h.
SPEED_LIMITS_KMH: tuple[int, ...] = (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130)
#: Labels that are not a speed limit.
LABEL_END_OF_LIMIT = 'end_of_limit'
LABEL_OTHER_SIGN = 'other_sign'
LABEL_NO_SIGN = 'no_sign'

_LOG = logging.getLogger(__name__)

#: Side of the high-resolution renderings the filter views are reduced from, pixels.
MASTER_PX = 512
#: Bump when the bank construction changes, so cached banks are rebuilt.
BANK_VERSION = 1
#: Out-of-plane views combined in each composite filter: yaw (about the vertical axis)
#: and pitch (about the horizontal axis), degrees (DAGM 2010 base configuration).
YAW_VIEWS_DEG: tuple[float, ...] = (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0)
PITCH_VIEWS_DEG: tuple[float, ...] = (0.0, 10.0, -10.0)
#: In-plane rotations: one filter each (counter-clockwise degrees).
ROLLS_DEG: tuple[float, ...] = (-6.0, 0.0, 6.0)
#: Templates of the detection filters (two- and three-digit generic signs).
DETECTION_KINDS: tuple[str, ...] = ('00', '100')
#: Classification filters: label -> the template kinds combined in its filter(s).
#: End-of-limit and look-alike templates are there so that such signs win as rejects.
CLASS_TEMPLATES: dict[str, tuple[str, ...]] = {
    **{str(v): (str(v),) for v in SPEED_LIMITS_KMH},
    'end_of_limit': ('end_of_limit_30', 'end_of_limit_60', 'end_of_limit_80',
                     'end_of_limit_100', 'end_of_limit_120'),
    'no_entry': ('no_entry',),
    'no_overtaking': ('no_overtaking',),
    'weight_limit': ('weight_limit',),
    'width_limit': ('width_limit',),
    'height_limit': ('height_limit',),
    'end_of_restrictions': ('end_of_restrictions',),
}
#: Views (indices into the yaw x pitch grid) of each kind in multi-template filters:
#: yaw 0, +-20 deg at pitch 0.
_MULTI_KIND_VIEWS: list[int] = [YAW_VIEWS_DEG.index(y) * len(PITCH_VIEWS_DEG)
                                for y in (0.0, 20.0, -20.0)]


def _label_of(class_name: str) -> str:
    if class_name.isdigit():
        return class_name
    if class_name == 'end_of_limit':
        return LABEL_END_OF_LIMIT
    return LABEL_OTHER_SIGN


@dataclass(frozen=True)
class SizeBank:
    """The filters of one sign size.

    Attributes:
        radius_px: sign radius of the templates, pixels.
        canvas_px: side of the square template canvas (sign centred), pixels.
        fft_size: side of the square FFT (and ROI), pixels.
        detection: (Fd, N, N//2+1) complex64 detection filter spectra.
        classification: (Fc, N, N//2+1) complex64 classification filter spectra.
        class_names: (Fc,) class name of each classification filter
            (a key of :data:`CLASS_TEMPLATES`).
        class_rolls_deg: (Fc,) in-plane rotation of each classification filter.
    """

    radius_px: float
    canvas_px: int
    fft_size: int
    detection: np.ndarray
    classification: np.ndarray
    class_names: tuple[str, ...]
    class_rolls_deg: np.ndarray

    @property
    def nbytes(self) -> int:
        """Memory of the filter spectra, bytes."""
        return int(self.detection.nbytes + self.classification.nbytes)


def bank_radii(config: ClassifierConfig) -> tuple[float, ...]:
    """Template radii of the banks: geometric from min to max radius, pixels."""
    count = max(1, math.ceil(math.log(config.max_radius_px / config.min_radius_px)
                             / math.log(config.radius_step) - 1e-9)) + 1
    ratio = (config.max_radius_px / config.min_radius_px) ** (1.0 / (count - 1))
    return tuple(config.min_radius_px * ratio ** i for i in range(count))


def _fast_size(n: int) -> int:
    """Smallest 2^a 3^b 5^c >= n (cheap FFT size)."""
    return int(cv2.getOptimalDFTSize(int(n)))


def _geometry_of_size(radius_px: float, config: ClassifierConfig) -> tuple[int, int]:
    """Template canvas side and FFT side (pixels) of one sign size."""
    canvas = int(math.ceil(2.0 * radius_px * (1.0 + 2.0 * config.canvas_margin)))
    slack = int(math.ceil(config.position_search * radius_px))
    return canvas, _fast_size(canvas + slack)


def _class_views() -> list[tuple[float, float, float]]:
    return [(yaw, pitch, roll) for roll in ROLLS_DEG for yaw in YAW_VIEWS_DEG
            for pitch in PITCH_VIEWS_DEG]


def build_size_bank(radius_px: float, config: ClassifierConfig,
                    masters: dict[str, np.ndarray]) -> SizeBank:
    """Synthesize the detection and classification filters of one sign size.

    Args:
        radius_px: sign radius of the templates, pixels.
        config: classifier configuration.
        masters: high-resolution renderings by kind (:func:`.templates.render_master`).
    """
    canvas, fft_size = _geometry_of_size(radius_px, config)
    shape = (fft_size, fft_size)
    per_roll = len(YAW_VIEWS_DEG) * len(PITCH_VIEWS_DEG)
    views: dict[str, np.ndarray] = {}  # kind -> (rolls, per_roll, h, w)

    def kind_views(kind: str) -> np.ndarray:
        if kind not in views:
            images = views_from_master(masters[kind], 2.0 * radius_px, canvas, _class_views(),
                                       supersample=2 if radius_px < 16.0 else 1)
            views[kind] = images.reshape(len(ROLLS_DEG), per_roll, canvas, canvas)
        return views[kind]

    roll_zero = ROLLS_DEG.index(0.0)
    detection = np.stack([mace_filter(training_spectra(kind_views(kind)[roll_zero], shape,
                                                       config.kth_law), shape,
                                      config.noise_tradeoff) for kind in DETECTION_KINDS])
    spectra: list[np.ndarray] = []
    names: list[str] = []
    rolls: list[float] = []
    for name, kinds in CLASS_TEMPLATES.items():
        for roll_index, roll in enumerate(ROLLS_DEG):
            if len(kinds) == 1:
                images = kind_views(kinds[0])[roll_index]
            else:  # several templates in one filter: frontal and +-20 deg yaw views
                images = np.concatenate([kind_views(kind)[roll_index][_MULTI_KIND_VIEWS]
                                         for kind in kinds])
            spectra.append(mace_filter(training_spectra(images, shape, config.kth_law), shape,
                                       config.noise_tradeoff))
            names.append(name)
            rolls.append(roll)
    return SizeBank(radius_px, canvas, fft_size, detection, np.stack(spectra), tuple(names),
                    np.asarray(rolls, np.float32))


def _bank_key(config: ClassifierConfig) -> str:
    relevant = {name: getattr(config, name) for name in (
        'kth_law', 'noise_tradeoff', 'min_radius_px', 'max_radius_px', 'radius_step',
        'canvas_margin', 'position_search')}
    relevant.update(version=BANK_VERSION, geometry=dataclasses.asdict(GRAY_TEMPLATE_GEOMETRY),
                    yaws=YAW_VIEWS_DEG, pitches=PITCH_VIEWS_DEG, rolls=ROLLS_DEG,
                    classes=CLASS_TEMPLATES, detection=DETECTION_KINDS)
    text = json.dumps(relevant, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_banks(config: ClassifierConfig) -> tuple[SizeBank, ...]:
    """All size banks for ``config``, from the cache folder when one is configured.

    Raises:
        ClassifierError: when the banks cannot be built or the cache cannot be written.
    """
    cache_file = None
    if config.cache_dir:
        cache_file = Path(config.cache_dir).expanduser() / f'filter_banks_{_bank_key(config)}.npz'
        if cache_file.is_file():
            try:
                return _load_banks(cache_file)
            except (OSError, ValueError, KeyError) as err:
                _LOG.warning('ignoring unreadable filter bank cache %s: %s', cache_file, err)
    try:
        kinds = set(DETECTION_KINDS).union(*CLASS_TEMPLATES.values())
        masters = {kind: render_master(kind, MASTER_PX, GRAY_TEMPLATE_GEOMETRY) for kind in sorted(kinds)}
        banks = tuple(build_size_bank(radius, config, masters) for radius in bank_radii(config))
    except (ValueError, np.linalg.LinAlgError, cv2.error) as err:
        raise ClassifierError(f'cannot build the filter banks: {err}') from err
    if cache_file is not None:
        try:
            _save_banks(cache_file, banks)
        except OSError as err:
            raise ClassifierError(f'cannot write the filter bank cache {cache_file}: {err}; '
                                  'set classifier.cache_dir to a writable folder or to ""'
                                  ) from err
    return banks


def _save_banks(path: Path, banks: Sequence[SizeBank]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {'count': np.asarray(len(banks))}
    for index, bank in enumerate(banks):
        arrays[f'{index}_meta'] = np.asarray([bank.radius_px, bank.canvas_px, bank.fft_size])
        arrays[f'{index}_detection'] = bank.detection
        arrays[f'{index}_classification'] = bank.classification
        arrays[f'{index}_names'] = np.asarray(bank.class_names)
        arrays[f'{index}_rolls'] = bank.class_rolls_deg
    temporary = path.with_suffix('.tmp.npz')
    np.savez(temporary, **arrays)
    temporary.replace(path)


def _load_banks(path: Path) -> tuple[SizeBank, ...]:
    with np.load(path) as data:
        banks = []
        for index in range(int(data['count'])):
            radius, canvas, fft_size = data[f'{index}_meta']
            banks.append(SizeBank(float(radius), int(canvas), int(fft_size),
                                  data[f'{index}_detection'], data[f'{index}_classification'],
                                  tuple(str(n) for n in data[f'{index}_names']),
                                  data[f'{index}_rolls']))
    return tuple(banks)


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

    def __init__(self, config: ClassifierConfig = ClassifierConfig()) -> None:
        self.config = config
        start = time.perf_counter()
        self.banks: tuple[SizeBank, ...] = build_banks(config)
        self.build_time_s = time.perf_counter() - start
        self._radii = np.asarray([bank.radius_px for bank in self.banks])
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
            ClassifierError: for a frame that is not a non-empty 2-D uint8 array
                (a ``ValueError``).
        """
        gray = _check_gray(gray, 'gray')
        return tuple(self._classify_at(gray, c.x_px, c.y_px, c.radius_px) for c in candidates)

    def classify_crop(self, crop: np.ndarray) -> Classification:
        """Classify a crop holding one centred sign (e.g. a GTSRB image, ~10% margin).

        Args:
            crop: (h, w) uint8 gray crop.

        Returns:
            The classification; ``x_px``/``y_px`` are crop pixels. A crop too small for
            the smallest filter is answered ``'no_sign'``.

        Raises:
            ClassifierError: for an empty or non-2-D / non-uint8 array (a ``ValueError``).
        """
        crop = _check_gray(crop, 'crop')
        height, width = crop.shape
        radius = min(height, width) / 2.0 / 1.12
        return self._classify_at(crop, width / 2.0, height / 2.0, radius)

    # -- internals ---------------------------------------------------------------------

    def _roi(self, gray: np.ndarray, x_px: float, y_px: float, size: int) -> np.ndarray:
        """size x size window centred on (x, y), border replicated, CLAHE applied."""
        top = int(round(y_px - size / 2.0))
        left = int(round(x_px - size / 2.0))
        rows = np.clip(np.arange(top, top + size), 0, gray.shape[0] - 1)
        cols = np.clip(np.arange(left, left + size), 0, gray.shape[1] - 1)
        roi = gray[rows[:, None], cols[None, :]]
        if self._clahe is not None:
            roi = self._clahe.apply(roi)
        return roi

    def _no_sign(self, x_px: float, y_px: float, radius_px: float, psr: float = 0.0
                 ) -> Classification:
        return Classification(LABEL_NO_SIGN, None, psr, radius_px, 0.0, 0.0, x_px, y_px)

    def _classify_at(self, gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                     ) -> Classification:
        config = self.config
        if not (math.isfinite(x_px) and math.isfinite(y_px) and math.isfinite(radius_px)):
            return self._no_sign(float(x_px), float(y_px), float(radius_px))
        sign_px = min(gray.shape) / 1.0
        if radius_px * 2.0 > sign_px * 1.5 or sign_px < 2.0 * self._radii[0] / 1.25:
            return self._no_sign(x_px, y_px, radius_px)
        low, high = radius_px / config.size_search_ratio, radius_px * config.size_search_ratio
        indices = [i for i, r in enumerate(self._radii) if low <= r <= high]
        if not indices:
            return self._no_sign(x_px, y_px, radius_px)
        largest = max(self.banks[i].fft_size for i in indices)
        roi = self._roi(gray, x_px, y_px, largest)
        spectra: dict[int, np.ndarray] = {}

        def spectrum(index: int) -> np.ndarray:
            if index not in spectra:
                size = self.banks[index].fft_size
                offset = (largest - size) // 2
                sub = roi[offset:offset + size, offset:offset + size]
                spectra[index] = scene_spectrum(sub, (size, size), config.kth_law)
            return spectra[index]

        best: _Scored | None = None
        for index in indices:
            bank = self.banks[index]
            stats = self._peaks(bank, correlate(spectrum(index), bank.detection,
                                                (bank.fft_size,) * 2),
                                int(math.ceil(config.position_search * radius_px)))
            top = int(np.argmax(stats.psr))
            if best is None or stats.psr[top] > best.psr:
                best = _Scored(index, float(stats.psr[top]), int(stats.y[top]), int(stats.x[top]))
        assert best is not None
        # classification: sizes around the detected one, peak near the detected position
        class_psr: dict[str, float] = {}
        class_where: dict[str, tuple[float, float, float, float]] = {}
        lo = max(0, best.bank_index - config.class_size_neighbours)
        hi = min(len(self.banks) - 1, best.bank_index + config.class_size_neighbours)
        det_bank = self.banks[best.bank_index]
        det_offset = (largest - det_bank.fft_size) // 2
        centre_y = best.peak_y + det_offset + det_bank.canvas_px / 2.0
        centre_x = best.peak_x + det_offset + det_bank.canvas_px / 2.0
        for index in range(lo, hi + 1):
            bank = self.banks[index]
            offset = (largest - bank.fft_size) // 2
            expect_y = int(round(centre_y - offset - bank.canvas_px / 2.0))
            expect_x = int(round(centre_x - offset - bank.canvas_px / 2.0))
            planes = correlate(spectrum(index), bank.classification, (bank.fft_size,) * 2)
            stats = peak_psr(planes, (expect_y, expect_x), max(1, int(round(bank.radius_px * 0.1))),
                             *self._lobes(bank.radius_px))
            for f, name in enumerate(bank.class_names):
                value = float(stats.psr[f])
                if value > class_psr.get(name, -np.inf):
                    class_psr[name] = value
                    roi_y = stats.y[f] + offset + bank.canvas_px / 2.0
                    roi_x = stats.x[f] + offset + bank.canvas_px / 2.0
                    class_where[name] = (float(roi_x), float(roi_y), bank.radius_px,
                                         float(bank.class_rolls_deg[f]))
        ranked = sorted(class_psr.items(), key=lambda item: -item[1])
        winner, winner_psr = ranked[0]
        label = _label_of(winner)
        runner_up = next((p for n, p in ranked[1:] if _label_of(n) != label), -np.inf)
        margin = winner_psr - runner_up if math.isfinite(runner_up) else winner_psr
        roi_x, roi_y, size_radius, roll = class_where[winner]
        frame_x = x_px - largest / 2.0 + roi_x
        frame_y = y_px - largest / 2.0 + roi_y
        if winner_psr < config.psr_threshold or (label.isdigit() and margin < config.min_margin):
            return Classification(LABEL_NO_SIGN, None, winner_psr, size_radius, roll, margin,
                                  frame_x, frame_y)
        return Classification(label, int(label) if label.isdigit() else None, winner_psr,
                              size_radius, roll, margin, frame_x, frame_y)

    def _lobes(self, radius_px: float) -> tuple[int, int]:
        sidelobe = max(4, int(math.ceil(0.5 * radius_px)))
        exclude = max(1, int(round(0.12 * radius_px)))
        return sidelobe, exclude

    def _peaks(self, bank: SizeBank, planes: np.ndarray, search: int):
        offset_centre = (bank.fft_size - bank.canvas_px) // 2
        return peak_psr(planes, (offset_centre, offset_centre), max(1, search),
                        *self._lobes(bank.radius_px))


def _check_gray(image: np.ndarray, name: str) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ClassifierError(f'{name} must be a numpy array, got {type(image).__name__}')
    if image.ndim != 2 or image.size == 0:
        raise ClassifierError(f'{name} must be a non-empty 2-D (H, W) array, got shape '
                              f'{image.shape}')
    if image.dtype != np.uint8:
        raise ClassifierError(f'{name} must be uint8, got {image.dtype}')
    return np.ascontiguousarray(image)


@dataclass(frozen=True)
class Classification:
    """What the classifier says about one candidate or crop.

    Attributes:
        label: the limit as a string of its km/h value (``'30'``), or one of
            ``'end_of_limit'``, ``'other_sign'``, ``'no_sign'``.
        limit_kmh: the speed limit in km/h, or ``None`` when the label is not a limit.
        psr: peak-to-sidelobe ratio of the winning filter (dimensionless).
        radius_px: the sign's radius as the detection filters sized it, in pixels.
        rotation_deg: in-plane rotation of the winning filter, degrees (counter-clockwise).
        margin: PSR of the winner minus PSR of the best different label.
        x_px, y_px: the sign's centre as the correlation peak placed it, frame pixels.
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
