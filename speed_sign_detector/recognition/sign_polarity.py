"""Which way round a sign is lit: a painted sign (dark digits on a light face) or an
electronic one (lit digits and ring on a dark face, :mod:`.sign_designs`).

The classifier's templates are painted signs. An electronic sign has the opposite polarity,
so the classifier reads it inverted where :func:`is_lit_on_dark` says so. The test compares
three gray levels of a small window around the candidate (cheap next to the correlation):

- the face: the median of the caps above and below the digits (inside the ring, beyond
  the digits' half height, :data:`FACE_CAPS`), which no value's digits reach;
- the digits: the mean of the box the digits fill (:data:`DIGIT_BOX`);
- the ring: the mean of the ring annulus (:data:`RING_RADII`).

A sign is lit on dark where its ring is brighter than its face by :data:`MIN_CONTRAST` gray
levels, its digit box by :data:`MIN_DIGIT_CONTRAST`, and its face is dark next to its digits
(:data:`MAX_FACE_TO_DIGITS`: not a blue sign's face beside its white arrows). A painted
sign fails it whatever its lighting (its face is brighter than its red ring and its
digits); so does an electronic sign of the rarer
dark-on-lit polarity, which the classifier reads as it reads a painted one, and flat
clutter.

A looser test (:func:`may_be_lit_on_dark`) marks the polarity of a sign that fails the
strict one as unsure (:attr:`Polarity.UNSURE`, :func:`sign_polarity`): a single or dotted
digit, whose digit box is mostly dark face, and a small sign whose ring of lamps blurs into
its face. The classifier reads such a sign inverted too where its painted reading is weak.

:func:`is_lit_face` tells the rarer electronic polarity (dark digits on a lit face) from
a sign in daylight: a glowing face in the dark housing of a gantry display. The classifier
reads such a sign painted; its second opinion only trusts it less (:mod:`.second_opinion`).

:func:`painted_polarity` turns a window of a sign lit on a dark face into the painted
templates' polarity, damping the bloom of its lamps on the way (:data:`BLOOM_GAMMA`).

:func:`is_partly_unlit` tells an electronic sign lit on a dark face caught with some of
its rows dark: its lamps are pulsed (PWM), and a rolling-shutter camera with a short
exposure exposes some rows between the pulses, so horizontal bands of the sign are dark.
The digits that remain may spell another value (a 20 without its base reads as 70), so
the classifier does not read such a sign.
"""
from __future__ import annotations

import enum
import functools

import cv2
import numpy as np

__all__ = ['BLOOM_GAMMA', 'BLOOM_LEVELS_PERCENTILES', 'DIGIT_BOX', 'FACE_CAPS',
           'LIT_FACE_MAX_SURROUND_RATIO', 'LIT_FACE_MIN_LEVEL', 'LIT_FACE_PERCENTILE',
           'LIT_FACE_SURROUND_RADII',
           'MAX_FACE_TO_DIGITS', 'MIN_CONTRAST', 'MIN_DIGIT_CONTRAST', 'RING_RADII',
           'UNLIT_ROW_DISC', 'UNLIT_ROW_HALF_HEIGHT', 'UNLIT_ROW_MIN_SHARE',
           'UNSURE_MAX_FACE_TO_LAMPS', 'UNSURE_MIN_LAMP_CONTRAST', 'UNSURE_MIN_RING_CONTRAST',
           'WINDOW_PX',
           'Polarity', 'is_lit_face', 'is_lit_on_dark', 'is_partly_unlit', 'may_be_lit_on_dark',
           'painted_polarity',
           'polarity_measures', 'sign_polarity']

#: Side of the square window the levels are taken on, pixels (the sign is resampled to
#: fill it: its outer radius is half the side).
WINDOW_PX = 24
#: The face's caps: inside this radius, beyond this half height (fractions of the sign
#: radius; the digits' half height is 0.37 at most, the ring's inner edge 0.60 or more).
FACE_CAPS = (0.62, 0.42)
#: The digits' box: half width and half height, fractions of the sign radius.
DIGIT_BOX = (0.45, 0.28)
#: The ring annulus, fractions of the sign radius (the red ring of a painted sign spans
#: 0.66-0.97, the lamps of an electronic one about 0.76-0.95).
RING_RADII = (0.74, 0.95)
#: Least contrast of the ring over the face, gray levels.
MIN_CONTRAST = 15.0
#: Least contrast of the digit box over the face, gray levels.
MIN_DIGIT_CONTRAST = 30.0
#: Largest ratio of the face's level to the digit box's: an LED face is black (in rendered
#: camera crops 0.18 of the digits' level in the median, 0.41 at the 95th percentile); the
#: blue mandatory signs (white arrows on blue) that pass the contrast tests show 0.66 in the
#: median (gtsrb-lookalikes-dev: 595 of 4,000 pass the contrasts, 20 this ratio too).
MAX_FACE_TO_DIGITS = 0.4
#: :func:`may_be_lit_on_dark`: least contrast of the digit box's lamps (the mean of its
#: brighter half, which a single narrow or dotted digit fills as a wide one does) over
#: the face, gray levels.
UNSURE_MIN_LAMP_CONTRAST = 20.0
#: :func:`may_be_lit_on_dark`: largest ratio of the face's level to the lamps'.
UNSURE_MAX_FACE_TO_LAMPS = 0.5
#: :func:`may_be_lit_on_dark`: least contrast of the ring over the face, gray levels (a
#: small sign's thin ring of lamps blurs into its face).
UNSURE_MIN_RING_CONTRAST = 5.0

#: :func:`is_lit_face`: the least gray level of the face's caps nearly everywhere (their
#: :data:`LIT_FACE_PERCENTILE`): a lit face glows near white all over (rendered dark-on-lit
#: signs: 216 at the 5th percentile), where a painted sign's face in daylight, or one lit
#: bright on part of its face, is not (gtsrb-dev 70s read right that a test on the caps'
#: median took: 112 to 197).
LIT_FACE_MIN_LEVEL = 200.0
#: :func:`is_lit_face`: the percentile of the face's caps compared with
#: :data:`LIT_FACE_MIN_LEVEL`.
LIT_FACE_PERCENTILE = 10.0
#: :func:`is_lit_face`: the largest ratio of the surround's level (the median of
#: :data:`LIT_FACE_SURROUND_RADII`) to the face's. Rendered dark-on-lit signs show 0.11 in
#: the median, 0.17 at the 95th percentile. With :data:`LIT_FACE_MIN_LEVEL`: 441 of 450
#: rendered dark-on-lit signs pass, no sign of the other rendered designs, 45 of 4,400
#: gtsrb-dev limit crops and 6 of 4,000 look-alikes (a bright face before dark trees).
LIT_FACE_MAX_SURROUND_RATIO = 0.2
#: :func:`is_lit_face`: the surround, from just outside the sign to the window's edge,
#: fractions of the sign radius (a crop's margin is about 0.1 of the radius or more).
LIT_FACE_SURROUND_RADII = (1.04, 1.25)

#: :func:`is_partly_unlit`: the rows tested, within this half height of the sign's centre
#: (fractions of its radius): the ring of lamps crosses every one of them.
UNLIT_ROW_HALF_HEIGHT = 0.85
#: :func:`is_partly_unlit`: each row's brightest pixel is taken within this radius of the
#: centre (fractions of the sign radius: the ring's outer edge, with a little of the glow).
UNLIT_ROW_DISC = 0.97
#: :func:`is_partly_unlit`: the least contrast over the face of the brighter of two
#: neighbouring rows' brightest pixels, as a share of the median row's. Rendered LED
#: signs of ``make validate-designs`` (white, amber, dot matrix; 30 of each value, seed 1)
#: read inverted and right: the 1st percentile 0.76 at the first look; the 2 of 1,248
#: under 0.5 (located at a radius far off) are read right by the crop's second look. Its
#: LED signs with rows dark in bands (``led_banded``: a period of 0.3-2 diameters, 40-85 %
#: of it lit): the 4 of 450 read inverted and as another limit without the test are all
#: taken; of another 450 (seed 5), the 8 such, with shares of 0.01-0.42.
UNLIT_ROW_MIN_SHARE = 0.5

#: :func:`painted_polarity`: the power applied to the lit levels (0 at the window's dark
#: level, 1 at its brightest) before they are inverted. A camera sees a lit sign's lamps
#: bloom, most of all over-exposed at night: the glow fills the counters of the digits,
#: and the correlation, whose templates are painted strokes, then finds a 40 in a 60 (the
#: 6's bowl filled) about as well as the 60. A power above 1 darkens the glow's mid levels
#: more than the lamps' cores. On rendered LED signs (white, amber, dot matrix, 30 of each
#: value, 15-60 px, glow and exposure at random; 1,350 signs) 1.5 read 12 more right and 8
#: fewer wrong than a plain inversion (9 and 5 with the second opinion's rule for signs
#: read inverted); 2 cost right answers, and 3 lost the thin 1 of 130 and 140 (read 30, 40).
BLOOM_GAMMA = 1.5
#: :func:`painted_polarity`: the percentiles of the window's levels taken as its dark
#: level (the face and housing) and its brightest (the lamps' cores).
BLOOM_LEVELS_PERCENTILES = (10.0, 99.5)


def _window_grid(window_px: int, half_side_radii: float = 1.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dy, dx, distance) of each pixel of a (window_px, window_px) window from its
    centre, in sign radii, for a window whose half side is ``half_side_radii`` radii."""
    centre = (window_px - 1) / 2.0
    rows, cols = np.mgrid[:window_px, :window_px]
    half = window_px / 2.0 / half_side_radii  # pixels per sign radius
    dy, dx = (rows - centre) / half, (cols - centre) / half
    return dy, dx, np.hypot(dy, dx)


def _caps(dy: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """Flat indices of the face's caps (:data:`FACE_CAPS`) of :func:`_window_grid`'s grid."""
    return np.flatnonzero((distance <= FACE_CAPS[0]) & (np.abs(dy) >= FACE_CAPS[1]))


@functools.lru_cache(maxsize=4)
def _masks(window_px: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat indices of the face's caps, the digit box and the ring annulus in a window
    whose sign radius is half its side."""
    dy, dx, distance = _window_grid(window_px)
    caps = _caps(dy, distance)
    box = np.flatnonzero((np.abs(dx) <= DIGIT_BOX[0]) & (np.abs(dy) <= DIGIT_BOX[1]))
    ring = np.flatnonzero((distance >= RING_RADII[0]) & (distance <= RING_RADII[1]))
    return caps, box, ring


def _usable(x_px: float, y_px: float, radius_px: float) -> bool:
    """True for a finite centre and a finite positive radius (pixels)."""
    return bool(radius_px > 0 and np.isfinite(radius_px) and np.isfinite(x_px)
                and np.isfinite(y_px))


def _window(gray: np.ndarray, x_px: float, y_px: float, radius_px: float) -> np.ndarray:
    """(WINDOW_PX, WINDOW_PX) float32 window whose sign radius is half its side, border
    pixels replicated outside the image."""
    scale = (WINDOW_PX / 2.0) / radius_px
    centre = (WINDOW_PX - 1) / 2.0
    matrix = np.float32([[scale, 0.0, centre - x_px * scale],
                         [0.0, scale, centre - y_px * scale]])
    flags = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    if scale < 1.0:  # reduce by area: take the window at full size, then resize
        side = int(np.ceil(2.0 * radius_px)) + 1
        top, left = int(round(y_px - side / 2.0)), int(round(x_px - side / 2.0))
        height, width = gray.shape
        if top >= 0 and left >= 0 and top + side <= height and left + side <= width:
            patch = gray[top:top + side, left:left + side]  # inside: the same pixels
        else:
            rows = np.clip(np.arange(top, top + side), 0, height - 1)
            cols = np.clip(np.arange(left, left + side), 0, width - 1)
            patch = np.ascontiguousarray(gray[rows[:, None], cols[None, :]])
        return cv2.resize(patch, (WINDOW_PX, WINDOW_PX), interpolation=flags).astype(np.float32)
    return cv2.warpAffine(gray, matrix, (WINDOW_PX, WINDOW_PX), flags=flags,
                          borderMode=cv2.BORDER_REPLICATE).astype(np.float32)


def polarity_measures(gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                      ) -> tuple[float, float, float]:
    """The gray levels the test compares, for a sign centred at (x, y) of ``radius_px``.

    Args:
        gray: (H, W) uint8 image.
        x_px, y_px: the sign's centre, pixels.
        radius_px: its outer radius, pixels (> 0).

    Returns:
        ``(face, digits, ring)``: the median of the face's caps, the mean of the digit box
        and the mean of the ring annulus, gray levels 0..255.
    """
    return _levels(_window(gray, float(x_px), float(y_px), float(radius_px)).ravel())[:3]


def _levels(window: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """``(face, digits, ring, digit box pixels)`` of a flattened (WINDOW_PX ** 2,) window
    (:func:`polarity_measures`)."""
    caps, box, ring = _masks(WINDOW_PX)
    digit_box = window[box]
    return (_median(window[caps]), float(digit_box.mean()), float(window[ring].mean()),
            digit_box)


def _median(values: np.ndarray) -> float:
    """``numpy.median`` of a small float32 vector without NaNs, the same float (for an
    even count the mean of the two middle values, summed in float32), at a tenth of its
    cost (the classifier takes one per candidate)."""
    ordered = np.sort(values)
    middle = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[middle])
    return float((ordered[middle - 1] + ordered[middle]) / ordered.dtype.type(2))


class Polarity(enum.Enum):
    """How a sign is lit, as :func:`sign_polarity` tells it."""

    #: Dark digits on a light face (a painted sign, or an electronic one lit that way).
    PAINTED = 'painted'
    #: Lit on a dark face by the looser test only (:func:`may_be_lit_on_dark`).
    UNSURE = 'unsure'
    #: Lit digits and ring on a dark face (:func:`is_lit_on_dark`).
    LIT_ON_DARK = 'lit_on_dark'


def sign_polarity(gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                  ) -> Polarity:
    """The polarity of the sign at (x, y) of ``radius_px`` (outer radius, pixels) in the
    (H, W) uint8 ``gray`` image, both tests on one window: :attr:`Polarity.LIT_ON_DARK`
    where :func:`is_lit_on_dark` holds, else :attr:`Polarity.UNSURE` where
    :func:`may_be_lit_on_dark` does, else :attr:`Polarity.PAINTED` (also for an unusable
    position or radius)."""
    if not _usable(x_px, y_px, radius_px):
        return Polarity.PAINTED
    face, digits, ring, digit_box = _levels(
        _window(gray, float(x_px), float(y_px), float(radius_px)).ravel())
    if (ring >= face + MIN_CONTRAST and digits >= face + MIN_DIGIT_CONTRAST
            and face <= MAX_FACE_TO_DIGITS * digits):
        return Polarity.LIT_ON_DARK
    ordered = np.sort(digit_box)
    lamps = float(ordered[len(ordered) // 2:].mean())
    if (lamps >= face + UNSURE_MIN_LAMP_CONTRAST and face <= UNSURE_MAX_FACE_TO_LAMPS * lamps
            and ring >= face + UNSURE_MIN_RING_CONTRAST):
        return Polarity.UNSURE
    return Polarity.PAINTED


def is_lit_on_dark(gray: np.ndarray, x_px: float, y_px: float, radius_px: float) -> bool:
    """True when the sign at (x, y) of ``radius_px`` (outer radius, pixels) in the (H, W)
    uint8 ``gray`` image looks lit on a dark face: its ring brighter than its face by
    :data:`MIN_CONTRAST`, its digit box brighter by :data:`MIN_DIGIT_CONTRAST` and at most
    :data:`MAX_FACE_TO_DIGITS` of it (an electronic sign). False for a painted sign, for
    an unusable position or radius and for flat clutter."""
    return sign_polarity(gray, x_px, y_px, radius_px) is Polarity.LIT_ON_DARK


def may_be_lit_on_dark(gray: np.ndarray, x_px: float, y_px: float, radius_px: float
                       ) -> bool:
    """True when the sign at (x, y) of ``radius_px`` fails :func:`is_lit_on_dark` but may
    still be an electronic sign: the brighter half of its digit box (its lamps, whatever
    the digits' count and width) is brighter than its face by
    :data:`UNSURE_MIN_LAMP_CONTRAST` and at least twice as bright
    (:data:`UNSURE_MAX_FACE_TO_LAMPS`), and its ring brighter than its face by
    :data:`UNSURE_MIN_RING_CONTRAST`. A single dotted digit (an electronic 5) fills too
    little of the digit box for the strict test's mean, and a small sign's thin ring of
    lamps blurs into its face. Painted and blue signs pass too (on gtsrb-dev about 1 % of
    the limit crops and a fifth of the look-alikes): the classifier reads such a sign
    inverted only where its painted reading is weak and the inverted one clear
    (:mod:`.candidate_evidence`)."""
    return sign_polarity(gray, x_px, y_px, radius_px) is Polarity.UNSURE


@functools.lru_cache(maxsize=2)
def _lit_face_masks(window_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices of the face's caps and of the surround in a window whose half side is
    :data:`LIT_FACE_SURROUND_RADII` [1] sign radii."""
    dy, _, distance = _window_grid(window_px, LIT_FACE_SURROUND_RADII[1])
    return _caps(dy, distance), np.flatnonzero(distance >= LIT_FACE_SURROUND_RADII[0])


def is_lit_face(gray: np.ndarray, x_px: float, y_px: float, radius_px: float) -> bool:
    """True when the sign at (x, y) of ``radius_px`` (outer radius, pixels) in the (H, W)
    uint8 ``gray`` image has a glowing face in dark surroundings: its face's caps at least
    :data:`LIT_FACE_MIN_LEVEL` nearly everywhere (:data:`LIT_FACE_PERCENTILE`) and the
    surround (:data:`LIT_FACE_SURROUND_RADII`, border pixels replicated outside the
    image) at most :data:`LIT_FACE_MAX_SURROUND_RATIO` of the face. An electronic sign of
    the rarer polarity (dark digits on a lit face in a gantry's black housing) passes,
    and so does a painted sign lit bright before a dark background; a painted sign in
    daylight, an electronic sign lit on a dark face and an unusable position or radius do
    not."""
    if not _usable(x_px, y_px, radius_px):
        return False
    window = _window(gray, float(x_px), float(y_px),
                     float(radius_px) * LIT_FACE_SURROUND_RADII[1]).ravel()
    caps, surround = _lit_face_masks(WINDOW_PX)
    face = float(np.percentile(window[caps], LIT_FACE_PERCENTILE))
    return (face >= LIT_FACE_MIN_LEVEL
            and _median(window[surround]) <= LIT_FACE_MAX_SURROUND_RATIO * face)


@functools.lru_cache(maxsize=2)
def _row_masks(window_px: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a window whose sign radius is half its side: the tested rows (those within
    :data:`UNLIT_ROW_HALF_HEIGHT`), which of their pixels lie inside
    :data:`UNLIT_ROW_DISC` ((rows, window_px) bool), and the flat indices of the face's
    caps."""
    dy, _, distance = _window_grid(window_px)
    rows = np.flatnonzero(np.abs(dy[:, 0]) <= UNLIT_ROW_HALF_HEIGHT)
    return rows, distance[rows] <= UNLIT_ROW_DISC, _caps(dy, distance)


def is_partly_unlit(gray: np.ndarray, x_px: float, y_px: float, radius_px: float) -> bool:
    """True when the electronic sign lit on a dark face at (x, y) of ``radius_px`` (outer
    radius, pixels) in the (H, W) uint8 ``gray`` image (as the camera shows it, not
    inverted) has dark rows.

    Each row within :data:`UNLIT_ROW_HALF_HEIGHT` of the centre crosses the ring of lamps,
    so on a sign lit whole each pair of neighbouring rows has a lit pixel (a pair: a dot
    matrix's lamp rows have gaps); the sign has dark rows where the brightest pixel of some
    pair stands over the face by less than :data:`UNLIT_ROW_MIN_SHARE` of the median row's
    contrast (rows exposed between the lamps' pulses by a rolling shutter). Meant for a
    sign :func:`is_lit_on_dark` (or read inverted): a painted sign's face may be darker
    than its ring (in shadow, backlit) and its rows unlike. False for an unusable position
    or radius."""
    if not _usable(x_px, y_px, radius_px):
        return False
    window = _window(gray, float(x_px), float(y_px), float(radius_px))
    rows, inside, caps = _row_masks(WINDOW_PX)
    face = _median(window.ravel()[caps])
    contrast = np.where(inside, window[rows], -np.inf).max(axis=1) - face
    typical = float(np.median(contrast))
    pairs = np.maximum(contrast[:-1], contrast[1:])
    return typical > 0.0 and float(pairs.min()) < UNLIT_ROW_MIN_SHARE * typical


def painted_polarity(lit_window: np.ndarray) -> np.ndarray:
    """A window of a sign lit on a dark face in the painted templates' polarity (dark
    digits on a light face), the lamps' bloom damped.

    Args:
        lit_window: (H, W) uint8 gray window around the sign.

    Returns:
        (H, W) uint8: its levels mapped to 0..1 between the percentiles of
        :data:`BLOOM_LEVELS_PERCENTILES`, raised to :data:`BLOOM_GAMMA` and inverted
        (1 -> 0, the lamps' cores black; 0 -> 255). A flat window comes back inverted.
    """
    dark, bright = np.percentile(lit_window, BLOOM_LEVELS_PERCENTILES)
    if bright - dark < 1.0:
        return 255 - lit_window
    lit = (lit_window.astype(np.float32) - np.float32(dark)) / np.float32(bright - dark)
    np.clip(lit, 0.0, 1.0, out=lit)
    return (255.0 - 255.0 * lit ** np.float32(BLOOM_GAMMA) + 0.5).astype(np.uint8)
