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
   ``min_margin``, the answer is "no sign" (a wrong limit is worse than none).

Every filter is a kth-law MACE composite (optimal trade-off with noise) of the
out-of-plane views of one template (yaw 0, +-10, +-20, +-30 deg x pitch 0, +-10 deg);
each in-plane rotation (-6, 0, +6 deg) has its own filter. Filters are synthesized from
the package's own renderings (:mod:`.templates`, :mod:`.mace`) at start-up, or read
from a cache keyed by every parameter that shapes them.
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
from speed_sign_detector.errors import ClassifierError, ClassifierInputError
from speed_sign_detector.recognition.correlation import (
    correlate,
    disc_window,
    keep_inside,
    peak_psr,
    scene_spectrum,
)
from speed_sign_detector.recognition.mace import mace_filters, training_spectra
from speed_sign_detector.recognition.templates import (
    GRAY_TEMPLATE_GEOMETRY,
    render_master,
    views_from_masters,
)

#: Speed limits the classifier can read, in km/h.
SPEED_LIMITS_KMH: tuple[int, ...] = (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130)
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

#: Side of the high-resolution renderings the filter views are reduced from, pixels.
MASTER_PX = 512
#: Bump when the bank construction changes, so cached banks are rebuilt.
BANK_VERSION = 5
#: Out-of-plane views combined in each composite filter: yaw (about the vertical axis)
#: and pitch (about the horizontal axis), degrees (DAGM 2010 base configuration).
YAW_VIEWS_DEG: tuple[float, ...] = (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0)
PITCH_VIEWS_DEG: tuple[float, ...] = (0.0, 10.0, -10.0)
#: In-plane rotations: one filter each (counter-clockwise degrees).
ROLLS_DEG: tuple[float, ...] = (-6.0, 0.0, 6.0)
#: Templates of the detection filters: two- and three-digit generic signs, and an
#: end-of-limit sign (no red ring: the generic ones mis-size it).
DETECTION_KINDS: tuple[str, ...] = ('00', '100', 'end_of_limit_80')
#: Classification filters: label -> the template kinds combined in its filter(s).
#: End-of-limit and look-alike templates are there so that such signs win as rejects.
#: "No vehicles" (an empty disc) has no filter: its empty field matches no filter and the
#: PSR threshold rejects it.
CLASS_TEMPLATES: dict[str, tuple[str, ...]] = {
    **{str(v): (str(v),) for v in SPEED_LIMITS_KMH},
    'end_of_limit': ('end_of_limit_30', 'end_of_limit_60', 'end_of_limit_80',
                     'end_of_limit_100', 'end_of_limit_120'),
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
        fft_size: side N of the square FFT (and ROI) of the detection filters, pixels.
        class_size: side M of the square FFT, ROI and template canvas of the
            classification filters (sign centred; they see only its inner field, so M
            is smaller than N), pixels.
        detection: (Fd, N, N//2+1) complex64 conjugated detection filter spectra.
        classification: (Fc, M, M//2+1) complex64 conjugated classification filter
            spectra.
        class_names: (Fc,) class name of each classification filter
            (a key of :data:`CLASS_TEMPLATES`).
        class_rolls_deg: (Fc,) in-plane rotation of each classification filter.
    """

    radius_px: float
    canvas_px: int
    fft_size: int
    class_size: int
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


def _geometry_of_size(radius_px: float, config: ClassifierConfig) -> tuple[int, int, int]:
    """Detection template canvas, detection FFT side and classification FFT side (pixels)
    of one sign size.

    The classification correlation only needs the shifts up to the peak search plus the
    PSR window; masked fields (radius f r) at larger shifts no longer overlap, so a side
    of r (2 f + search + window) keeps the circular correlation free of wrap-around there.
    """
    canvas = int(math.ceil(2.0 * radius_px * (1.0 + 2.0 * config.canvas_margin)))
    slack = int(math.ceil(config.position_search * radius_px))
    reach = 2.0 * config.class_field_radius + config.class_position_search \
        + config.sidelobe_window
    return canvas, _fast_size(canvas + slack), _fast_size(int(math.ceil(radius_px * reach)) + 2)


def _class_views() -> list[tuple[float, float, float]]:
    return [(yaw, pitch, roll) for roll in ROLLS_DEG for yaw in YAW_VIEWS_DEG
            for pitch in PITCH_VIEWS_DEG]


def _keep_inside_each(images: np.ndarray, window: np.ndarray) -> np.ndarray:
    """:func:`.correlation.keep_inside` of every image of a stack.

    Args:
        images: (..., h, w) real images.
        window: (h, w) weights in [0, 1].

    Returns:
        (..., h, w) float32.
    """
    images = np.asarray(images, dtype=np.float32)
    total = float(window.sum())
    if total <= 0:
        return np.stack([keep_inside(image, window) for image in images.reshape(
            (-1,) + window.shape)]).reshape(images.shape)
    means = (images * window).sum(axis=(-2, -1), keepdims=True) / np.float32(total)
    return images * window + means * (1.0 - window)


def build_size_bank(radius_px: float, config: ClassifierConfig,
                    masters: dict[str, np.ndarray]) -> SizeBank:
    """Synthesize the detection and classification filters of one sign size.

    Each kind's views are warped once (all kinds in one warp per view), the training
    spectra of all filters come from one :func:`.mace.training_spectra` call and the
    filters with the same number of training views are synthesized together
    (:func:`.mace.mace_filters`).

    Args:
        radius_px: sign radius of the templates, pixels.
        config: classifier configuration.
        masters: high-resolution renderings by kind (:func:`.templates.render_master`).
    """
    canvas, fft_size, class_size = _geometry_of_size(radius_px, config)
    shape = (fft_size, fft_size)
    per_roll = len(YAW_VIEWS_DEG) * len(PITCH_VIEWS_DEG)
    supersample = 2 if radius_px < 16.0 else 1
    detection_views = [(yaw, pitch, 0.0) for yaw in YAW_VIEWS_DEG for pitch in PITCH_VIEWS_DEG]
    images = views_from_masters([masters[kind] for kind in DETECTION_KINDS], 2.0 * radius_px,
                                canvas, detection_views, supersample=supersample)
    detection = mace_filters(
        training_spectra(images.reshape(-1, canvas, canvas), shape, config.kth_law).reshape(
            images.shape[:2] + (fft_size, fft_size // 2 + 1)), shape, config.noise_tradeoff)

    # classification templates: only the sign's inner field (digits), the rest set to
    # the field's mean, so the ring and the surroundings (common to all classes) do not
    # drown the digits
    class_kinds = sorted(set().union(*CLASS_TEMPLATES.values()))
    kind_index = {kind: index for index, kind in enumerate(class_kinds)}
    shape = (class_size, class_size)
    field = disc_window(shape, (class_size / 2.0, class_size / 2.0),
                        config.class_field_radius * radius_px)
    views = _keep_inside_each(views_from_masters([masters[kind] for kind in class_kinds],
                                               2.0 * radius_px, class_size, _class_views(),
                                               supersample=supersample), field)
    views = views.reshape(len(class_kinds), len(ROLLS_DEG), per_roll, class_size, class_size)
    # training images of every filter (name-major, roll-minor), grouped by view count
    filter_images: list[np.ndarray] = []
    names: list[str] = []
    rolls: list[float] = []
    for name, kinds in CLASS_TEMPLATES.items():
        for roll_index, roll in enumerate(ROLLS_DEG):
            if len(kinds) == 1:
                filter_images.append(views[kind_index[kinds[0]], roll_index])
            else:  # several templates in one filter: frontal and +-20 deg yaw views
                filter_images.append(np.concatenate(
                    [views[kind_index[kind], roll_index, _MULTI_KIND_VIEWS] for kind in kinds]))
            names.append(name)
            rolls.append(roll)
    spectra_all = training_spectra(np.concatenate(filter_images), shape, config.kth_law)
    classification = np.empty((len(filter_images), class_size, class_size // 2 + 1),
                              np.complex64)
    offsets = np.cumsum([0] + [len(images) for images in filter_images])
    counts = np.asarray([len(images) for images in filter_images])
    for count in np.unique(counts):
        members = np.flatnonzero(counts == count)
        group = np.stack([spectra_all[offsets[m]:offsets[m] + count] for m in members])
        classification[members] = mace_filters(group, shape, config.noise_tradeoff)
    return SizeBank(radius_px, canvas, fft_size, class_size, np.conj(detection),
                    np.conj(classification), tuple(names), np.asarray(rolls, np.float32))


def _bank_key(config: ClassifierConfig) -> str:
    relevant = {name: getattr(config, name) for name in (
        'kth_law', 'noise_tradeoff', 'min_radius_px', 'max_radius_px', 'radius_step',
        'canvas_margin', 'position_search', 'class_field_radius')}
    relevant.update(version=BANK_VERSION, geometry=dataclasses.asdict(GRAY_TEMPLATE_GEOMETRY),
                    yaws=YAW_VIEWS_DEG, pitches=PITCH_VIEWS_DEG, rolls=ROLLS_DEG,
                    classes=CLASS_TEMPLATES, detection=DETECTION_KINDS)
    text = json.dumps(relevant, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_banks(config: ClassifierConfig) -> tuple[SizeBank, ...]:
    """All size banks for ``config``, from the cache folder when one is configured.

    A cache that cannot be read is rebuilt; one that cannot be written is logged.

    Raises:
        ClassifierError: when the banks cannot be built.
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
        masters = {kind: render_master(kind, MASTER_PX, GRAY_TEMPLATE_GEOMETRY)
                   for kind in sorted(kinds)}
        banks = tuple(build_size_bank(radius, config, masters) for radius in bank_radii(config))
    except (ValueError, np.linalg.LinAlgError, cv2.error) as err:
        raise ClassifierError(f'cannot build the filter banks: {err}') from err
    if cache_file is not None:
        try:
            _save_banks(cache_file, banks)
        except OSError as err:  # the banks work without the cache: say so, go on
            _LOG.warning('cannot write the filter bank cache %s (%s); set '
                         'classifier.cache_dir to a writable folder or to "" to silence this',
                         cache_file, err)
    return banks


def _save_banks(path: Path, banks: Sequence[SizeBank]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {'count': np.asarray(len(banks))}
    for index, bank in enumerate(banks):
        arrays[f'{index}_meta'] = np.asarray([bank.radius_px, bank.canvas_px, bank.fft_size,
                                               bank.class_size])
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
            radius, canvas, fft_size, class_size = data[f'{index}_meta']
            banks.append(SizeBank(float(radius), int(canvas), int(fft_size), int(class_size),
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
            ClassifierInputError: (a ``ValueError``) for a frame that is not a non-empty
                2-D uint8 array.
        """
        gray = _check_gray(gray, 'gray')
        scale = self.config.candidate_radius_scale
        return tuple(self._classify_at(gray, c.x_px, c.y_px, c.radius_px * scale)
                     for c in candidates)

    def classify_crop(self, crop: np.ndarray) -> Classification:
        """Classify a crop holding one centred sign.

        The crop is taken to frame the sign like GTSRB crops do: a margin of 10% of the
        sign's size but at least 5 pixels on each side; the detection filters then find
        the exact size and position.

        Args:
            crop: (h, w) uint8 gray crop.

        Returns:
            The classification; ``x_px``/``y_px`` are crop pixels. A crop too small for
            any sign (radius below ``min_sign_radius_px``) is answered ``'no_sign'``.

        Raises:
            ClassifierInputError: for an empty or non-2-D / non-uint8 array.
        """
        crop = _check_gray(crop, 'crop')
        height, width = crop.shape
        side = float(min(height, width))
        sign_size = min(side / 1.2, side - 10.0) if side > 10.0 else side / 1.2
        return self._classify_at(crop, width / 2.0, height / 2.0, sign_size / 2.0)

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
        rows = np.clip(np.arange(top, top + source), 0, gray.shape[0] - 1)
        cols = np.clip(np.arange(left, left + source), 0, gray.shape[1] - 1)
        window = np.ascontiguousarray(gray[rows[:, None], cols[None, :]])
        if source == size:
            return window, 1.0
        return cv2.resize(window, (size, size), interpolation=cv2.INTER_AREA), size / source

    def _no_sign(self, x_px: float, y_px: float, radius_px: float, psr: float = 0.0
                 ) -> Classification:
        return Classification(LABEL_NO_SIGN, None, psr, radius_px, 0.0, 0.0, x_px, y_px)

    def _classify_at(self, gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                     ) -> Classification:
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
        detected_bank = self.banks[best.bank_index]
        upright = np.flatnonzero(detected_bank.class_rolls_deg == 0.0)
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
                chosen = np.flatnonzero([n in leaders for n in bank.class_names])
                if pass_number == 1:  # the detected size: the leaders' rotated filters
                    chosen = chosen[bank.class_rolls_deg[chosen] != 0.0]
            if chosen.size == 0:
                continue
            if index not in spectra:
                # window of the classification size around the detected centre
                top = int(math.floor(centre_y - size / 2.0 + 0.5))
                left = int(math.floor(centre_x - size / 2.0 + 0.5))
                rows = np.clip(np.arange(top, top + size), 0, largest - 1)
                cols = np.clip(np.arange(left, left + size), 0, largest - 1)
                sub = scene[rows[:, None], cols[None, :]]
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
            shift_y = (stats.y + size // 2) % size - size // 2  # circular -> signed
            shift_x = (stats.x + size // 2) % size - size // 2
            for f, filter_index in enumerate(chosen):
                found.setdefault(bank.class_names[filter_index], []).append((
                    float(stats.psr[f]), float(left + shift_x[f] + size / 2.0),
                    float(top + shift_y[f] + size / 2.0), bank.radius_px,
                    float(bank.class_rolls_deg[filter_index])))
            if pass_number == 0:
                ranked = sorted(found, key=lambda n: -max(e[0] for e in found[n]))
                leaders = set(ranked[:config.class_neighbour_classes])
        if not found:
            return self._no_sign(x_px, y_px, radius_px)
        # a class scores the mean of its few best filters (sizes x rotations): steadier
        # than the single best one
        top = config.class_score_top
        scores = {name: float(np.mean(sorted(p[0] for p in entries)[-top:]))
                  for name, entries in found.items()}
        ranked = sorted(scores.items(), key=lambda item: -item[1])
        winner, winner_psr = ranked[0]
        label = _label_of(winner)
        runner_up = next((p for n, p in ranked[1:] if _label_of(n) != label), -np.inf)
        margin = winner_psr - runner_up if math.isfinite(runner_up) else winner_psr
        _, roi_x, roi_y, size_radius, roll = max(found[winner])
        frame_x = x_px + (roi_x - largest / 2.0) / scale
        frame_y = y_px + (roi_y - largest / 2.0) / scale
        size_radius /= scale
        height, width = gray.shape
        cut_px = max(-frame_x, -frame_y, frame_x - (width - 1), frame_y - (height - 1)) + size_radius
        if (winner_psr < config.psr_threshold or (label.isdigit() and margin < config.min_margin)
                or cut_px > config.max_cut_fraction * size_radius):
            return Classification(LABEL_NO_SIGN, None, winner_psr, size_radius, roll, margin,
                                  frame_x, frame_y)
        return Classification(label, int(label) if label.isdigit() else None, winner_psr,
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
