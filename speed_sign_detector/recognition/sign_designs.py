"""Sign designs beyond the painted white-faced sign: electronic (LED) signs and
yellow-faced signs, rendered by code like :mod:`.templates` draws the painted ones.

Designs (:data:`SIGN_DESIGNS`):

- ``'painted'``: the white-faced retro-reflective sign of :mod:`.templates`.
- ``'yellow'``: a yellow face and a thicker red ring (Finland, older Swedish signs).
- ``'led'``: an electronic sign on a motorway gantry: white digits and a red ring lit on
  a black face (the opposite polarity of a painted sign), solid strokes.
- ``'led_amber'``: the same with amber digits.
- ``'led_dot_matrix'``: the same made of separate round lamps (a dot matrix).
- ``'led_dark_on_lit'``: the rarer polarity: dark digits and a red ring on a lit white
  face (the polarity of a painted sign, with the glow of a lit one).

Every LED design takes an :class:`LedLook`: how much the lit parts bloom (the glow of a
camera at night), an exposure gain above 1 that over-exposes them (saturated digits
whose glow fills their counters), and dark bands: an LED sign's lamps are pulsed (PWM),
and a rolling-shutter camera with a short exposure catches some rows between the pulses
(:func:`random_look` with ``banded``).

Sizes and coordinates are as in :mod:`.templates`: the sign's outer diameter in pixels,
drawn at high resolution and reduced with area interpolation.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.recognition.templates import (
    GEOMETRY,
    SIGN_KINDS,
    SignGeometry,
    render_sign,
    render_sign_highres,
)

__all__ = ['LED_DESIGNS', 'SIGN_DESIGNS', 'YELLOW_GEOMETRY', 'DesignError', 'LedLook',
           'design_crop', 'design_gray', 'design_label', 'design_training_crops',
           'lit_on_dark_design', 'random_look', 'render_design']

#: Every design :func:`render_design` draws.
SIGN_DESIGNS: tuple[str, ...] = ('painted', 'yellow', 'led', 'led_amber', 'led_dot_matrix',
                                 'led_dark_on_lit')
#: The electronic designs.
LED_DESIGNS: tuple[str, ...] = ('led', 'led_amber', 'led_dot_matrix', 'led_dark_on_lit')

#: Yellow-faced signs: a yellow foil (BGR) and a red ring about 0.37 of the radius wide
#: (0.31 on the German sign), the digits a little smaller to keep their clearance.
YELLOW_GEOMETRY = SignGeometry(ring_inner=0.60, digit_height_2=0.68, digit_height_3=0.62,
                               white_bgr=(30, 200, 240))

# Colours (BGR) of lit and unlit LED sign parts as a camera sees them.
LED_FACE_BGR = (18, 18, 18)
LED_RED_BGR = (50, 50, 255)
LED_WHITE_BGR = (245, 245, 245)
LED_AMBER_BGR = (20, 175, 255)
LED_LIT_FACE_BGR = (240, 240, 240)
#: LED signs draw bolder strokes than the painted lettering (lamp rows of 2-3 lamps) and
#: a narrower ring (a few rows of red lamps inside the black housing's rim).
_LED_STROKE = 0.15
_LED_RING_OUTER = 0.95
_LED_RING_INNER = 0.76
#: Lamp pitch of the dot matrix, relative to the sign radius (about 36 lamps across).
_DOT_PITCH = 0.055
#: Lamp radius relative to the pitch.
_DOT_RADIUS = 0.36


class DesignError(SpeedSignError, ValueError):
    """A design or look that :func:`render_design` cannot draw."""


@dataclass(frozen=True)
class LedLook:
    """How a camera sees an LED sign.

    Attributes:
        glow: strength of the bloom around lit parts (0 none; 1 about as bright again,
            spread over ``glow_radius``).
        glow_radius: the bloom's Gaussian sigma relative to the sign radius.
        exposure: gain on the lit parts (1 as drawn; above 1 over-exposed, clipped at 255).
        band_period: the period of the dark bands (rows exposed between the lamps'
            pulses), a fraction of the sign's diameter; 0: the sign lit whole.
        band_lit_share: the share of each period that is lit (0 < share <= 1).
        band_phase: where the first period starts, a fraction of it (from the sign's top).
    """

    glow: float = 0.4
    glow_radius: float = 0.05
    exposure: float = 1.0
    band_period: float = 0.0
    band_lit_share: float = 1.0
    band_phase: float = 0.0

    def __post_init__(self) -> None:
        if not (self.glow >= 0.0 and self.glow_radius > 0.0 and self.exposure > 0.0):
            raise DesignError(f'LedLook needs glow >= 0, glow_radius > 0 and exposure > 0, '
                              f'got {self.glow}, {self.glow_radius}, {self.exposure}')
        if not (self.band_period >= 0.0 and 0.0 < self.band_lit_share <= 1.0
                and math.isfinite(self.band_phase)):
            raise DesignError(f'LedLook needs band_period >= 0, 0 < band_lit_share <= 1 and a '
                              f'finite band_phase, got {self.band_period}, '
                              f'{self.band_lit_share}, {self.band_phase}')


def lit_on_dark_design(design: str) -> bool:
    """True for the designs whose face is darker than their digits and ring (the opposite
    polarity of a painted sign)."""
    return design in ('led', 'led_amber', 'led_dot_matrix')


def design_label(kind: str) -> str:
    """The label a sign of ``kind`` must be read as, whatever its design: the limit's value,
    ``'end_of_limit'`` for end-of-limit signs and the end of all restrictions (VZ 282,
    which ends the limit too), ``'other_sign'`` for the other look-alikes."""
    if kind.isdigit():
        return kind
    if kind.startswith('end_of_limit') or kind == 'end_of_restrictions':
        return 'end_of_limit'
    return 'other_sign'


def _led_geometry(design: str) -> SignGeometry:
    digits = LED_AMBER_BGR if design == 'led_amber' else LED_WHITE_BGR
    if design == 'led_dark_on_lit':
        return SignGeometry(ring_outer=_LED_RING_OUTER, ring_inner=_LED_RING_INNER,
                            stroke=_LED_STROKE, white_bgr=LED_LIT_FACE_BGR,
                            red_bgr=LED_RED_BGR, black_bgr=LED_FACE_BGR)
    return SignGeometry(ring_outer=_LED_RING_OUTER, ring_inner=_LED_RING_INNER,
                        stroke=_LED_STROKE, white_bgr=LED_FACE_BGR, red_bgr=LED_RED_BGR,
                        black_bgr=digits)


def _dot_matrix(lit: np.ndarray, size_px: int) -> np.ndarray:
    """The lit parts (S, S, 3) float32 as round lamps on a square grid: a lamp is on where
    the drawing is lit at its centre, with the colour there."""
    pitch = _DOT_PITCH * size_px / 2.0
    count = int(math.ceil(size_px / pitch))
    offset = (size_px - (count - 1) * pitch) / 2.0
    centres = offset + pitch * np.arange(count)
    index = np.clip(np.round(centres).astype(int), 0, size_px - 1)
    colours = lit[index[:, None], index[None, :]]  # (count, count, 3)
    out = np.zeros_like(lit)
    radius = max(1, int(round(_DOT_RADIUS * pitch)))
    for row, centre_y in enumerate(centres):
        for column, centre_x in enumerate(centres):
            colour = colours[row, column]
            if float(colour.max()) > 8.0:
                cv2.circle(out, (int(round(centre_x)), int(round(centre_y))), radius,
                           tuple(float(c) for c in colour), -1, cv2.LINE_AA)
    return out


def _lit_rows(size_px: int, look: LedLook) -> np.ndarray:
    """(S, 1, 1) float32 share of each row of an ``size_px`` drawing that is lit: 1, or 0
    in the dark bands of ``look`` (edges softened over a hundredth of the diameter)."""
    if look.band_period <= 0.0 or look.band_lit_share >= 1.0:
        return np.ones((size_px, 1, 1), np.float32)
    phase = (np.arange(size_px, dtype=np.float32) + 0.5) / (look.band_period * size_px)
    lit = (((phase + look.band_phase) % 1.0) < look.band_lit_share).astype(np.float32)
    soft = cv2.GaussianBlur(lit[:, None], (1, 0), 0.01 * size_px)
    return soft.reshape(size_px, 1, 1)


def _render_led_highres(kind: str, size_px: int, design: str, look: LedLook
                        ) -> tuple[np.ndarray, np.ndarray]:
    """An LED sign drawn at ``size_px``: (bgr (S, S, 3) uint8 premultiplied, alpha)."""
    bgr, alpha = render_sign_highres(kind, size_px, _led_geometry(design))
    face = np.asarray(LED_FACE_BGR, np.float32)
    drawing = bgr.astype(np.float32)
    lit = np.maximum(drawing - face * alpha[..., None], 0.0)
    if design == 'led_dot_matrix':
        lit = _dot_matrix(lit, size_px)
    lit = lit * _lit_rows(size_px, look)
    sigma = look.glow_radius * size_px / 2.0
    bloom = cv2.GaussianBlur(lit, (0, 0), sigma) if look.glow > 0 else 0.0
    # lit parts premultiplied already; the bloom kept inside the disc
    image = face * alpha[..., None] + look.exposure * (lit + look.glow * bloom
                                                      * alpha[..., None])
    image = np.clip(image, 0.0, 255.0)
    return image.round().astype(np.uint8), alpha


def render_design(kind: str, diameter_px: int, design: str = 'painted',
                  look: LedLook = LedLook()) -> tuple[np.ndarray, np.ndarray]:
    """Render one sign of a design on a transparent background.

    Args:
        kind: a kind of :data:`.templates.SIGN_KINDS` (limits, end-of-limit signs,
            look-alikes).
        diameter_px: the sign's outer diameter D in pixels (>= 4).
        design: one of :data:`SIGN_DESIGNS`.
        look: the glow and exposure of the LED designs (ignored by the others).

    Returns:
        ``(bgr, alpha)`` as :func:`.templates.render_sign`: (D, D, 3) uint8 colour
        premultiplied by ``alpha``, (D, D) float32 in [0, 1].

    Raises:
        DesignError: for an unknown design or kind, or a diameter below 4 pixels.
    """
    if design not in SIGN_DESIGNS:
        raise DesignError(f'unknown sign design {design!r}; known designs: '
                          f'{", ".join(SIGN_DESIGNS)}')
    if kind not in SIGN_KINDS:
        raise DesignError(f'unknown sign kind {kind!r}; known kinds: {", ".join(SIGN_KINDS)}')
    diameter_px = int(diameter_px)
    if diameter_px < 4:
        raise DesignError(f'diameter_px must be at least 4, got {diameter_px}')
    if design == 'painted':
        return render_sign(kind, diameter_px, GEOMETRY)
    if design == 'yellow':
        return render_sign(kind, diameter_px, YELLOW_GEOMETRY)
    size_px = diameter_px * max(4, math.ceil(512 / diameter_px))
    big_bgr, big_alpha = _render_led_highres(kind, size_px, design, look)
    bgr = cv2.resize(big_bgr, (diameter_px, diameter_px), interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(big_alpha, (diameter_px, diameter_px), interpolation=cv2.INTER_AREA)
    return bgr, alpha


def design_gray(kind: str, diameter_px: int, design: str, background: np.ndarray,
                look: LedLook = LedLook()) -> np.ndarray:
    """A sign of ``design`` composited centred on a gray ``background``.

    Args:
        kind, diameter_px, design, look: as :func:`render_design`.
        background: (H, W) uint8 or float gray image at least ``diameter_px`` on a side.

    Returns:
        (H, W) float32 gray levels 0..255 (BT.601 luma of the colour rendering).
    """
    bgr, alpha = render_design(kind, diameter_px, design, look)
    out = np.asarray(background, np.float32).copy()
    height, width = out.shape
    if min(height, width) < diameter_px:
        raise DesignError(f'background {width}x{height} is smaller than the sign '
                          f'({diameter_px} px)')
    top, left = (height - diameter_px) // 2, (width - diameter_px) // 2
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    region = out[top:top + diameter_px, left:left + diameter_px]
    out[top:top + diameter_px, left:left + diameter_px] = gray + (1.0 - alpha) * region
    return out


def _background(side: int, design: str, rng: np.random.Generator) -> np.ndarray:
    """(side, side) float32 gray surroundings of a sign: a smooth textured scene (sky,
    foliage, buildings) for a painted or yellow sign; for an electronic one the black
    housing of a gantry display around the disc."""
    mean = float(rng.uniform(50.0, 210.0))
    noise = rng.normal(0.0, 1.0, (side, side)).astype(np.float32)
    texture = cv2.GaussianBlur(noise, (0, 0), float(rng.uniform(1.0, 4.0)))
    texture *= float(rng.uniform(5.0, 40.0)) / (float(texture.std()) + 1e-6)
    scene = mean + texture
    if design in LED_DESIGNS:
        scene[:] = float(rng.uniform(10.0, 45.0)) + 0.2 * texture
    return scene


def _camera(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A float gray image as a camera delivers it: blur, noise and JPEG (uint8)."""
    out = cv2.GaussianBlur(image, (0, 0), float(rng.uniform(0.3, 1.2)))
    out = np.clip(out + rng.normal(0.0, float(rng.uniform(1.0, 5.0)), out.shape), 0, 255)
    quality = int(rng.integers(30, 90))
    ok, encoded = cv2.imencode('.jpg', out.astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise DesignError('JPEG encoding of a rendered crop failed')
    return cv2.imdecode(encoded, cv2.IMREAD_GRAYSCALE)


def random_look(design: str, rng: np.random.Generator, banded: bool = False) -> LedLook:
    """An LED look drawn at random: a glow from none to strong, an exposure from right to
    about twice too long (ignored by the painted designs); ``banded``: dark bands too, a
    period of 0.3-2 diameters of which 40-85 % is lit, at a random phase."""
    del design  # the same range for every LED design
    look = LedLook(glow=float(rng.uniform(0.0, 1.0)), glow_radius=float(rng.uniform(0.03, 0.08)),
                   exposure=float(rng.uniform(0.8, 2.0)))
    if not banded:
        return look
    return dataclasses.replace(look, band_period=float(rng.uniform(0.3, 2.0)),
                               band_lit_share=float(rng.uniform(0.4, 0.85)),
                               band_phase=float(rng.uniform(0.0, 1.0)))


def design_crop(kind: str, design: str, diameter_px: int, rng: np.random.Generator,
                banded: bool = False) -> np.ndarray:
    """A camera's crop of one sign of ``design`` (GTSRB framing: a margin of 10% of the
    diameter, at least 5 px), on random surroundings, with a random LED look (with dark
    bands where ``banded``: :func:`random_look`), blur, noise and JPEG compression.

    Returns:
        (S, S) uint8 gray crop, S = ``diameter_px`` + 2 margins.
    """
    margin = max(5, int(round(0.1 * diameter_px)))
    side = int(diameter_px) + 2 * margin
    scene = design_gray(kind, int(diameter_px), design, _background(side, design, rng),
                        random_look(design, rng, banded))
    return _camera(scene, rng)


def design_training_crops(per_kind: int, rng: np.random.Generator
                          ) -> tuple[list[np.ndarray], list[str]]:
    """Crops of the designs a painted-sign training set lacks, as the classifier's second
    opinion sees them, ``per_kind`` of each kind and design, diameters 16-60 px:

    - every limit on an LED sign (white, amber, dot matrix; inverted, as the classifier
      reads a sign lit on a dark face) and on a dark-on-lit LED sign;
    - every limit on a yellow-faced sign;
    - the end of all restrictions (VZ 282), labelled ``'end_of_limit'``
      (:func:`design_label`).

    Returns:
        (gray uint8 crops, labels).
    """
    crops: list[np.ndarray] = []
    labels: list[str] = []
    limits = [kind for kind in SIGN_KINDS if kind.isdigit() and kind != '00']
    jobs = [(kind, design) for kind in limits for design in LED_DESIGNS + ('yellow',)]
    jobs.append(('end_of_restrictions', 'painted'))
    for kind, design in jobs:
        for _ in range(per_kind):
            crop = design_crop(kind, design, int(rng.integers(16, 61)), rng)
            crops.append(255 - crop if lit_on_dark_design(design) else crop)
            labels.append(design_label(kind))
    return crops, labels
