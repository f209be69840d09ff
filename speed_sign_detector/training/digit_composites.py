"""Training examples of any speed-limit value made from the digits of real signs.

A value with no real crops (130 km/h in GTSRB, say) would be known to the second opinion
from renderings only, and a model that has seen real 120 signs and rendered 130 signs
reads a real 130 as 120: the renderings do not look like real pixels. This module makes
examples that do. Each one is a real located crop of one value (the *background*: its
ring, face, lighting, blur and noise) whose digits are replaced by the digits of the new
value, cut from other real crops (a real "3" from a 30 sign put between the real "1"
and "0" of a 120 sign makes a 130):

1. :func:`digit_boxes` lays out the digits of a value as the renderer draws them
   (:func:`~speed_sign_detector.recognition.templates.render_sign`): one box per digit,
   in units of the sign's radius around its centre. Three-digit values have narrower,
   lower digits; a digit moved from a two-digit sign into a three-digit one is squeezed
   box to box, as real lettering is.
2. A digit is carried as *ink*: ``(face - pixel) / (face - ink)`` of its source crop,
   clipped to [0, 1], so that a digit from a bright sign lands on a dark one without a
   seam. The background's own digits where the new value differs are erased first
   (their ink taken away, leaving the face's own shading), then the new ink is laid
   over at the background's ink level.
3. Digit sources, in order: a real digit of the same character (a "9" is also a real
   "6" turned by 180 degrees, as DIN 1451 draws them); else the renderer's glyph at the
   background's size, lightly blurred, in the background's real context. A value whose
   digits occur in no real crop (a "4" for 40 and 140 in GTSRB) is therefore still
   learned from real rings, faces and lighting.

Composites are made for every value asked, also those with real crops, so that the
traces of compositing (an inpainted patch, a slightly misplaced digit) say nothing about
the label. Everything comes from the crops passed in, so a fold's composites use only
that fold's training crops.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from speed_sign_detector.recognition.templates import GEOMETRY, render_sign

__all__ = ['CompositeSet', 'DigitBox', 'digit_boxes', 'digit_composites', 'ink_levels']

#: Diameter of the rendering that lays out a value's digits, pixels.
_LAYOUT_DIAMETER_PX = 512
#: Margin added around each digit's box (radius units): the blur of a real digit spills
#: a little beyond its strokes.
_BOX_MARGIN_X = 0.035
_BOX_MARGIN_Y = 0.06
#: Inner field (radius units) where a sign's face and ink levels are measured, and
#: beyond which nothing is erased (the ring starts at 0.66).
_FIELD_RADIUS = 0.6
#: Least contrast between face and ink, gray levels, for a crop to lend or take digits.
_MIN_CONTRAST = 25.0
#: A real source digit's radius within this factor of the background's is preferred.
_SIZE_RATIO = 1.6
#: Digits that a real digit turned by 180 degrees draws (DIN 1451: 9 is a turned 6).
_TURNED_DIGITS: dict[str, str] = {'9': '6', '6': '9'}


@dataclass(frozen=True)
class DigitBox:
    """Where one digit of a value sits on a sign, in units of the sign's outer radius.

    Attributes:
        character: the digit, ``'0'`` to ``'9'``.
        left, top, right, bottom: the box around the digit's strokes (x right, y down,
            the sign's centre at 0, its rim at radius 1), with a small margin.
    """

    character: str
    left: float
    top: float
    right: float
    bottom: float


@functools.lru_cache(maxsize=64)
def _layout_rendering(value: str) -> tuple[np.ndarray, np.ndarray]:
    """(gray (D, D) float32, alpha (D, D) float32) of ``value`` rendered at
    :data:`_LAYOUT_DIAMETER_PX`, shared by the digit layout and the rendered ink."""
    bgr, alpha = render_sign(value, _LAYOUT_DIAMETER_PX)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32), alpha


@functools.lru_cache(maxsize=64)
def digit_boxes(value: str) -> tuple[DigitBox, ...]:
    """The boxes of ``value``'s digits, left to right, as the renderer lays them out.

    Args:
        value: a speed limit in km/h as digits, e.g. ``'130'``.

    Returns:
        One :class:`DigitBox` per character of ``value``.

    Raises:
        ValueError: for a value that is not 1 to 3 digits.
    """
    if not value.isdigit() or not 1 <= len(value) <= 3:
        raise ValueError(f'a speed-limit value is 1 to 3 digits, got {value!r}')
    gray, alpha = _layout_rendering(value)
    half = _LAYOUT_DIAMETER_PX / 2.0
    rows, columns = np.mgrid[0:_LAYOUT_DIAMETER_PX, 0:_LAYOUT_DIAMETER_PX]
    inside = np.hypot(columns + 0.5 - half, rows + 0.5 - half) < GEOMETRY.ring_inner * half
    ink = ((gray < 90.0) & inside & (alpha > 0.5)).astype(np.uint8)
    count, _, stats, _ = cv2.connectedComponentsWithStats(ink, connectivity=8)
    spans = sorted([int(stats[i, cv2.CC_STAT_LEFT]), int(stats[i, cv2.CC_STAT_TOP]),
                    int(stats[i, cv2.CC_STAT_LEFT] + stats[i, cv2.CC_STAT_WIDTH]),
                    int(stats[i, cv2.CC_STAT_TOP] + stats[i, cv2.CC_STAT_HEIGHT])]
                   for i in range(1, count) if stats[i, cv2.CC_STAT_AREA] > 20)
    merged: list[list[int]] = []
    for span in spans:  # a glyph drawn in several strokes: columns that overlap are one
        if merged and span[0] <= merged[-1][2]:
            last = merged[-1]
            merged[-1] = [min(last[0], span[0]), min(last[1], span[1]),
                          max(last[2], span[2]), max(last[3], span[3])]
        else:
            merged.append(span)
    if len(merged) != len(value):
        raise ValueError(f'the rendering of {value!r} shows {len(merged)} glyphs')
    return tuple(DigitBox(character, left / half - 1.0 - _BOX_MARGIN_X,
                          top / half - 1.0 - _BOX_MARGIN_Y,
                          right / half - 1.0 + _BOX_MARGIN_X,
                          bottom / half - 1.0 + _BOX_MARGIN_Y)
                 for character, (left, top, right, bottom) in zip(value, merged))


def ink_levels(image: np.ndarray, sign: np.ndarray) -> tuple[float, float]:
    """The face and ink gray levels of a located sign.

    Args:
        image: (h, w) uint8 gray crop.
        sign: (3,) float (x, y, radius) of the sign in crop pixels (pixel centres at +0.5).

    Returns:
        (face, ink): high and low percentiles of the pixels of the sign's inner field.
    """
    x_px, y_px, radius_px = (float(v) for v in sign)
    rows, columns = np.indices(image.shape)
    field = np.hypot(columns + 0.5 - x_px, rows + 0.5 - y_px) < _FIELD_RADIUS * radius_px
    values = image[field].astype(np.float32)
    if values.size < 4:
        return float(image.max()), float(image.min())
    return float(np.percentile(values, 85)), float(np.percentile(values, 3))


def _box_transform(source_box: DigitBox, source_sign: np.ndarray, target_box: DigitBox,
                   target_sign: np.ndarray, turned: bool) -> np.ndarray:
    """(2, 3) affine map from target crop pixels to source crop pixels that carries the
    target box onto the source box (turned by 180 degrees when ``turned``)."""

    def corners(box: DigitBox, sign: np.ndarray) -> np.ndarray:
        x_px, y_px, radius_px = (float(v) for v in sign)
        return np.array([[x_px + box.left * radius_px, y_px + box.top * radius_px],
                         [x_px + box.right * radius_px, y_px + box.top * radius_px],
                         [x_px + box.left * radius_px, y_px + box.bottom * radius_px]])

    target = corners(target_box, target_sign)
    source = corners(source_box, source_sign)
    if turned:  # the source's bottom right is the target's top left
        x_px, y_px, radius_px = (float(v) for v in source_sign)
        source = np.array([[x_px + source_box.right * radius_px,
                            y_px + source_box.bottom * radius_px],
                           [x_px + source_box.left * radius_px,
                            y_px + source_box.bottom * radius_px],
                           [x_px + source_box.right * radius_px,
                            y_px + source_box.top * radius_px]])
    # pixel centres at +0.5: OpenCV's maps index pixel centres at integers
    return cv2.getAffineTransform((target - 0.5).astype(np.float32),
                                  (source - 0.5).astype(np.float32))


def _box_mask(shape: tuple[int, int], box: DigitBox, sign: np.ndarray) -> np.ndarray:
    """(h, w) float32 weight of ``box`` placed on ``sign``: 1 inside, feathered by a pixel,
    and 0 beyond the inner field."""
    x_px, y_px, radius_px = (float(v) for v in sign)
    rows, columns = np.indices(shape, dtype=np.float32)
    u = (columns + 0.5 - x_px) / radius_px
    v = (rows + 0.5 - y_px) / radius_px
    feather = 1.0 / max(radius_px, 1.0)
    inside_x = np.clip(np.minimum(u - box.left, box.right - u) / feather + 0.5, 0.0, 1.0)
    inside_y = np.clip(np.minimum(v - box.top, box.bottom - v) / feather + 0.5, 0.0, 1.0)
    field = np.clip((0.64 - np.hypot(u, v)) / feather + 0.5, 0.0, 1.0)
    return (inside_x * inside_y * field).astype(np.float32)


@dataclass(frozen=True)
class _Donor:
    """A real digit that can be lent: crop index, its position in its value, turned."""

    crop: int
    box: DigitBox
    turned: bool


@dataclass(frozen=True)
class CompositeSet:
    """Composite crops and where they came from.

    Attributes:
        images: the composites, each (h, w) uint8, the size of its background crop.
        signs: (N, 3) float64 (x, y, radius) of each composite's sign (its background's).
        labels: (N,) the value each composite shows, km/h as a string.
        backgrounds: (N,) index of each composite's background crop in the input.
        rendered_digits: (N,) how many of each composite's digits are renderings (0 when
            every digit is real).
    """

    images: tuple[np.ndarray, ...]
    signs: np.ndarray
    labels: tuple[str, ...]
    backgrounds: np.ndarray
    rendered_digits: np.ndarray

    def __len__(self) -> int:
        return len(self.images)


@functools.lru_cache(maxsize=64)
def _rendered_value_ink(value: str) -> np.ndarray:
    """(D, D) float32 ink (0 face, 1 digit) of ``value``'s digits rendered at
    :data:`_LAYOUT_DIAMETER_PX`, nothing outside the inner field."""
    gray, _ = _layout_rendering(value)
    white = float(np.mean(GEOMETRY.white_bgr))
    black = float(np.mean(GEOMETRY.black_bgr))
    half = _LAYOUT_DIAMETER_PX / 2.0
    rows, columns = np.mgrid[0:_LAYOUT_DIAMETER_PX, 0:_LAYOUT_DIAMETER_PX]
    inside = np.hypot(columns + 0.5 - half, rows + 0.5 - half) < _FIELD_RADIUS * 1.05 * half
    return np.where(inside, np.clip((white - gray) / (white - black), 0.0, 1.0),
                    0.0).astype(np.float32)


def _rendered_ink(value: str, slot: int, target_sign: np.ndarray, shape: tuple[int, int],
                  rng: np.random.Generator) -> np.ndarray:
    """(h, w) float32 ink of digit ``slot`` of ``value`` as the renderer draws it on the
    target sign (at its size and place), smoothed as a camera of that resolution and a
    little more."""
    x_px, y_px, radius_px = (float(v) for v in target_sign)
    # reduced first (by area) to 4 rendering pixels per target pixel
    side = int(min(_LAYOUT_DIAMETER_PX, max(32, round(8.0 * radius_px))))
    ink = cv2.resize(_rendered_value_ink(value), (side, side), interpolation=cv2.INTER_AREA)
    half = side / 2.0
    scale = radius_px / half  # target pixels per rendering pixel
    # a camera pixel integrates about 1/scale rendering pixels; then a lens blur
    sigma = math.hypot(0.45 / scale, float(rng.uniform(0.3, 0.9)) / scale)
    smooth = cv2.GaussianBlur(ink, (0, 0), sigma)
    to_target = np.float32([[scale, 0.0, x_px - 0.5 - scale * (half - 0.5)],
                            [0.0, scale, y_px - 0.5 - scale * (half - 0.5)]])
    placed = cv2.warpAffine(smooth, to_target, (shape[1], shape[0]), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return placed * _box_mask(shape, digit_boxes(value)[slot], target_sign)


def _lent_ink(donor_image: np.ndarray, donor_sign: np.ndarray, donor: _Donor,
              target_box: DigitBox, target_sign: np.ndarray,
              shape: tuple[int, int]) -> np.ndarray:
    """(h, w) float32 ink of a real donor digit carried into ``target_box``."""
    face, ink_level = ink_levels(donor_image, donor_sign)
    ink = np.clip((face - donor_image.astype(np.float32)) / max(face - ink_level, 1.0),
                  0.0, 1.0)
    scale = float(target_sign[2]) / float(donor_sign[2])
    if scale < 0.7:  # the donor is much larger: smooth before reducing
        ink = cv2.GaussianBlur(ink, (0, 0), 0.45 / scale)
    to_source = _box_transform(donor.box, donor_sign, target_box, target_sign, donor.turned)
    carried = cv2.warpAffine(ink, to_source, (shape[1], shape[0]),
                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return carried * _box_mask(shape, target_box, target_sign)


def _erased(image: np.ndarray, sign: np.ndarray, boxes: Sequence[DigitBox],
            face: float, ink_level: float) -> np.ndarray:
    """(h, w) float32 ``image`` with the ink inside ``boxes`` taken away: a pixel that is
    ``face - ink * (face - ink_level)`` becomes ``face`` (the digit's blur goes with it)."""
    contrast = max(face - ink_level, 1.0)
    pixels = image.astype(np.float32)
    ink = np.clip((face - pixels) / contrast, 0.0, 1.0)
    region = np.zeros(image.shape, np.float32)
    for box in boxes:
        region = np.maximum(region, _box_mask(image.shape, box, sign))
    return pixels + region * ink * contrast


def digit_composites(images: Sequence[np.ndarray], signs: np.ndarray,
                     labels: Sequence[str], values: Sequence[str], per_value: int,
                     rng: np.random.Generator) -> CompositeSet:
    """``per_value`` composite crops of each of ``values`` from the located real crops.

    Args:
        images: (h, w) uint8 gray crops.
        signs: (N, 3) float (x, y, radius) of each crop's sign; rows with NaN are unused.
        labels: (N,) each crop's label; only speed limits (digit labels) lend a
            background or digits.
        values: the values to make, km/h as strings (e.g. ``'130'``).
        per_value: composites of each value (>= 0).
        rng: random choices of backgrounds, donors and blur.

    Returns:
        The composites (empty where no crop can serve as a background).
    """
    if per_value < 0:
        raise ValueError(f'per_value must be >= 0, got {per_value}')
    signs = np.asarray(signs, np.float64).reshape(-1, 3)
    usable: list[int] = []
    levels: dict[int, tuple[float, float]] = {}
    for index, label in enumerate(labels):
        if not label.isdigit() or not np.all(np.isfinite(signs[index])):
            continue
        face, ink_level = ink_levels(images[index], signs[index])
        if face - ink_level >= _MIN_CONTRAST:
            usable.append(index)
            levels[index] = (face, ink_level)
    donors: dict[str, list[_Donor]] = {}
    for index in usable:
        for box in digit_boxes(labels[index]):
            donors.setdefault(box.character, []).append(_Donor(index, box, False))
            turned = _TURNED_DIGITS.get(box.character)
            if turned is not None:
                donors.setdefault(turned, []).append(_Donor(index, box, True))
    out_images: list[np.ndarray] = []
    out_signs: list[np.ndarray] = []
    out_labels: list[str] = []
    out_backgrounds: list[int] = []
    out_rendered: list[int] = []
    for value in values:
        wanted = digit_boxes(value)
        backgrounds = [i for i in usable if labels[i] != value
                       and len(labels[i]) == len(value)] or \
            [i for i in usable if labels[i] != value]
        if not backgrounds:
            continue
        for background in rng.choice(backgrounds, size=per_value):
            background = int(background)
            image, sign = images[background], signs[background]
            face, ink_level = levels[background]
            own = digit_boxes(labels[background])
            same_layout = len(own) == len(wanted)
            changed = [slot for slot, box in enumerate(wanted)
                       if not same_layout or own[slot].character != box.character]
            erase = [own[slot] for slot in changed] if same_layout else list(own)
            canvas = _erased(image, sign, erase, face, ink_level)
            new_ink = np.zeros(image.shape, np.float32)
            rendered = 0
            for slot in changed:
                ink = None
                candidates = donors.get(wanted[slot].character, [])
                if candidates:
                    close = [d for d in candidates if 1.0 / _SIZE_RATIO
                             <= signs[d.crop][2] / sign[2] <= _SIZE_RATIO] or candidates
                    donor = close[int(rng.integers(len(close)))]
                    ink = _lent_ink(images[donor.crop], signs[donor.crop], donor,
                                    wanted[slot], sign, image.shape)
                if ink is None:
                    ink = _rendered_ink(value, slot, sign, image.shape, rng)
                    rendered += 1
                new_ink = np.maximum(new_ink, ink)
            composite = canvas * (1.0 - new_ink) + ink_level * new_ink
            out_images.append(np.clip(np.round(composite), 0, 255).astype(np.uint8))
            out_signs.append(np.asarray(sign, np.float64))
            out_labels.append(value)
            out_backgrounds.append(background)
            out_rendered.append(rendered)
    return CompositeSet(tuple(out_images),
                        np.asarray(out_signs, np.float64).reshape(-1, 3),
                        tuple(out_labels), np.asarray(out_backgrounds, np.int64),
                        np.asarray(out_rendered, np.int64))
