"""Filter banks: the kth-law MACE composite filters of every sign size.

A bank holds, per sign size (radius), the detection filters (generic signs that find the
sign's size and centre) and the classification filters (one per class and in-plane
rotation, seeing only the sign's inner field). Every filter is a kth-law MACE composite
(optimal trade-off with noise) of the out-of-plane views of its templates (yaw 0, +-10,
+-20, +-30 deg x pitch 0, +-10 deg), synthesized from the package's renderings
(:mod:`.templates`, :mod:`.mace`) and, when a trained bank file supplies them, from
real examples (:mod:`.bank_training`). Built banks are cached on disk, keyed by every
parameter that shapes them.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.errors import BankFileError, ClassifierError
from speed_sign_detector.recognition.bank_file import load_bank_file, save_bank_file
from speed_sign_detector.recognition.correlation import disc_window, keep_inside
from speed_sign_detector.recognition.mace import mace_filters, training_spectra
from speed_sign_detector.recognition.templates import (
    GRAY_TEMPLATE_GEOMETRY,
    LIMIT_VALUES_KMH,
    render_master,
    views_from_masters,
)

#: Speed limits the classifier can read, in km/h: every value the renderer draws.
SPEED_LIMITS_KMH: tuple[int, ...] = LIMIT_VALUES_KMH

_LOG = logging.getLogger(__name__)

#: Side of the high-resolution renderings the filter views are reduced from, pixels.
MASTER_PX = 512
#: Bump when the bank construction changes, so cached banks are rebuilt.
BANK_VERSION = 6
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


def _examples_at_size(examples: np.ndarray, radius_px: float, side: int, roll_deg: float
                      ) -> np.ndarray:
    """Canonical real examples (sign radius PATCH_PX / 2, :mod:`.sign_features`) resampled
    to a sign of ``radius_px`` centred on a (side, side) canvas, rotated by ``roll_deg``
    counter-clockwise; (M, side, side) float32."""
    half = examples.shape[-1] / 2.0
    matrix = cv2.getRotationMatrix2D((half, half), roll_deg, radius_px / half)
    matrix[:, 2] += side / 2.0 - half
    flags = cv2.INTER_AREA if radius_px < half else cv2.INTER_LINEAR
    return np.stack([cv2.warpAffine(np.asarray(example, np.float32), matrix, (side, side),
                                    flags=flags, borderMode=cv2.BORDER_REPLICATE)
                     for example in examples])


def build_size_bank(radius_px: float, config: ClassifierConfig,
                    masters: dict[str, np.ndarray],
                    class_examples: Mapping[str, np.ndarray] | None = None) -> SizeBank:
    """Synthesize the detection and classification filters of one sign size.

    Each kind's views are warped once (all kinds in one warp per view), the training
    spectra of all filters come from one :func:`.mace.training_spectra` call and the
    filters with the same number of training views are synthesized together
    (:func:`.mace.mace_filters`).

    Args:
        radius_px: sign radius of the templates, pixels.
        config: classifier configuration.
        masters: high-resolution renderings by kind (:func:`.templates.render_master`).
        class_examples: class name -> (M, P, P) canonical real examples (mean images of
            labelled crops, :mod:`.bank_training`) that join the renderings in that class's
            classification filters.
    """
    class_examples = class_examples or {}
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
            if name in class_examples and len(class_examples[name]):
                real = _keep_inside_each(_examples_at_size(class_examples[name], radius_px,
                                                           class_size, roll), field)
                filter_images[-1] = np.concatenate([filter_images[-1], real])
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


def _bank_key(config: ClassifierConfig, class_examples: Mapping[str, np.ndarray]) -> str:
    relevant = {name: getattr(config, name) for name in (
        'kth_law', 'noise_tradeoff', 'min_radius_px', 'max_radius_px', 'radius_step',
        'canvas_margin', 'position_search', 'class_field_radius')}
    relevant.update(version=BANK_VERSION, geometry=dataclasses.asdict(GRAY_TEMPLATE_GEOMETRY),
                    yaws=YAW_VIEWS_DEG, pitches=PITCH_VIEWS_DEG, rolls=ROLLS_DEG,
                    classes=CLASS_TEMPLATES, detection=DETECTION_KINDS,
                    examples={name: hashlib.sha256(np.ascontiguousarray(
                        examples, np.float32).tobytes()).hexdigest()
                        for name, examples in sorted(class_examples.items())})
    text = json.dumps(relevant, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_banks(config: ClassifierConfig,
                class_examples: Mapping[str, np.ndarray] | None = None
                ) -> tuple[SizeBank, ...]:
    """All size banks for ``config``, from the cache folder when one is configured.

    ``class_examples`` (class name -> (M, P, P) canonical real examples) join the
    renderings in the classification filters (:func:`build_size_bank`).

    A cache that cannot be read is rebuilt; one that cannot be written is logged.

    Raises:
        ClassifierError: when the banks cannot be built.
    """
    cache_file = None
    if config.cache_dir:
        key = _bank_key(config, class_examples or {})
        cache_file = Path(config.cache_dir).expanduser() / f'filter_banks_{key}.npz'
        if cache_file.is_file():
            try:
                return _load_banks(cache_file)
            except BankFileError as err:  # whatever is wrong with a cache: rebuild it
                _LOG.warning('rebuilding the filter bank cache: %s', err)
    try:
        kinds = set(DETECTION_KINDS).union(*CLASS_TEMPLATES.values())
        masters = {kind: render_master(kind, MASTER_PX, GRAY_TEMPLATE_GEOMETRY)
                   for kind in sorted(kinds)}
        banks = tuple(build_size_bank(radius, config, masters, class_examples)
                      for radius in bank_radii(config))
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


_CACHE_FORMAT = 'speed_sign_detector.filter_bank_cache'


def _save_banks(path: Path, banks: Sequence[SizeBank]) -> None:
    arrays: dict[str, np.ndarray] = {'count': np.asarray(len(banks))}
    for index, bank in enumerate(banks):
        arrays[f'{index}_meta'] = np.asarray([bank.radius_px, bank.canvas_px, bank.fft_size,
                                               bank.class_size])
        arrays[f'{index}_detection'] = bank.detection
        arrays[f'{index}_classification'] = bank.classification
        arrays[f'{index}_names'] = np.asarray(bank.class_names)
        arrays[f'{index}_rolls'] = bank.class_rolls_deg
    save_bank_file(path, arrays, {}, _CACHE_FORMAT, BANK_VERSION)


def _load_banks(path: Path) -> tuple[SizeBank, ...]:
    """The cached banks; :class:`BankFileError` for a file that is not a readable cache."""
    data, _ = load_bank_file(path, _CACHE_FORMAT, (BANK_VERSION,))
    try:
        banks = []
        for index in range(int(data['count'])):
            radius, canvas, fft_size, class_size = data[f'{index}_meta']
            banks.append(SizeBank(float(radius), int(canvas), int(fft_size), int(class_size),
                                  data[f'{index}_detection'], data[f'{index}_classification'],
                                  tuple(str(n) for n in data[f'{index}_names']),
                                  data[f'{index}_rolls']))
    except (KeyError, ValueError, TypeError) as err:
        raise BankFileError(f'{path} is not a complete filter bank cache ({err})') from err
    return tuple(banks)
