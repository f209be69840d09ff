"""Sign rendering: EU/German regulatory signs drawn by code, no image files.

Every sign is drawn at high resolution (a canvas several times the requested
diameter) with OpenCV filled shapes and round-capped polylines, then reduced with
area interpolation, so small renderings are properly anti-aliased.

Geometry follows the German StVO signs (VZ 274 speed limit, VZ 278 end of limit,
VZ 276 no overtaking, VZ 250 no vehicles, VZ 262/264/265 weight/width/height limits):
a white disc with a thin white rim, a red ring about a tenth of the diameter wide, and
digits in a DIN 1451 Mittelschrift-like lettering (narrow, uniform stroke, rounded
bowls), narrower (Engschrift-like) for three-digit values. The digit glyphs are stroke
centre lines defined here (:data:`GLYPH_STROKES`), not a font file.

Units: "unit" coordinates are relative to the sign radius (centre 0, radius 1, y down).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

#: Speed-limit values that have a rendering, km/h: every value EU speed-limit signs show
#: (140 is the motorway limit in Poland and Bulgaria).
LIMIT_VALUES_KMH: tuple[int, ...] = (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130,
                                     140)
#: Generic detection templates of the DAGM 2010 paper (two- and three-digit shapes).
GENERIC_KINDS: tuple[str, ...] = ('00', '100')
#: End-of-limit signs (VZ 278), one per limit value.
END_OF_LIMIT_KINDS: tuple[str, ...] = tuple(f'end_of_limit_{v}' for v in LIMIT_VALUES_KMH)
#: Circular look-alikes that must not be read as a limit.
LOOKALIKE_KINDS: tuple[str, ...] = ('no_overtaking', 'no_entry', 'weight_limit', 'width_limit',
                                    'height_limit', 'end_of_restrictions')
#: Every kind :func:`render_sign` can draw.
SIGN_KINDS: tuple[str, ...] = (tuple(str(v) for v in LIMIT_VALUES_KMH) + ('00',)
                               + END_OF_LIMIT_KINDS + LOOKALIKE_KINDS)

# Colours (BGR), close to retro-reflective sign foils seen by a camera.
WHITE_BGR = (235, 235, 235)
RED_BGR = (40, 30, 200)
BLACK_BGR = (25, 25, 25)
GRAY_BGR = (120, 120, 120)


@dataclass(frozen=True)
class SignGeometry:
    """Proportions (relative to the outer radius, 1.0) and colours of a round sign.

    Attributes:
        ring_outer: outer radius of the red ring (inside the thin white rim).
        ring_inner: inner radius of the red ring (edge of the white field).
        digit_height_2: outer height of the digits of a two-digit value.
        digit_height_3: outer height of the digits of a three-digit value.
        digit_width: outer width of a digit glyph relative to its height (two digits).
        digit_width_3: same for three-digit values (narrower lettering).
        stroke: stroke width relative to digit height.
        gap: space between digits relative to digit height.
        arched_six: draw the 6 with an arched top whose end turns down towards the bowl
            (a lettering seen on older signs, which a plain renderer would read as an 8)
            instead of the straight diagonal stem.
        white_bgr, red_bgr, black_bgr, gray_bgr: colours of the sign foils (BGR).
    """

    ring_outer: float = 0.97
    ring_inner: float = 0.66
    digit_height_2: float = 0.74
    digit_height_3: float = 0.68
    digit_width: float = 0.56
    digit_width_3: float = 0.47
    stroke: float = 0.11
    gap: float = 0.12
    arched_six: bool = False
    white_bgr: tuple[int, int, int] = WHITE_BGR
    red_bgr: tuple[int, int, int] = RED_BGR
    black_bgr: tuple[int, int, int] = BLACK_BGR
    gray_bgr: tuple[int, int, int] = GRAY_BGR


#: Proportions and colours of the colour renderings. The proportions were checked
#: against real crops (GTSRB): mean normalised cross-correlation of the rendering with
#: the real signs, maximised over the ring radii, digit size, stroke and spacing.
GEOMETRY = SignGeometry()
#: The same signs as the classifier's gray templates see them: in the gray frames of
#: colour cameras the red ring is about as dark as the digits (measured on real crops).
GRAY_TEMPLATE_GEOMETRY = SignGeometry(red_bgr=(50, 50, 50))
#: The colour renderings with the older lettering's arched 6 (:attr:`SignGeometry.arched_six`).
ARCHED_SIX_GEOMETRY = SignGeometry(arched_six=True)

Polyline = np.ndarray  # (n, 2) float64 points, x right, y down


def _arc(cx: float, cy: float, rx: float, ry: float, start_deg: float, end_deg: float,
         steps: int = 48) -> np.ndarray:
    """Points of an elliptic arc (angles counter-clockwise as seen, 90 = top)."""
    angles = np.radians(np.linspace(start_deg, end_deg, steps))
    return np.stack([cx + rx * np.cos(angles), cy - ry * np.sin(angles)], axis=1)


def _bezier(p0: Sequence[float], p1: Sequence[float], p2: Sequence[float],
            steps: int = 32) -> np.ndarray:
    """Points of a quadratic Bezier curve."""
    t = np.linspace(0.0, 1.0, steps)[:, None]
    a, b, c = (np.asarray(p, dtype=np.float64) for p in (p0, p1, p2))
    return (1 - t) ** 2 * a + 2 * (1 - t) * t * b + t ** 2 * c


def _pts(*points: tuple[float, float]) -> np.ndarray:
    return np.asarray(points, dtype=np.float64)


def _glyph(char: str, w: float, arched_six: bool = False) -> tuple[list[np.ndarray], float]:
    """Stroke centre lines of one glyph in a box [0, advance] x [0, 1] (y down).

    ``w`` is the centre-line width of a regular digit (height 1); ``arched_six`` draws the
    6's top as an arch (:attr:`SignGeometry.arched_six`). Returns the polylines and the
    glyph's advance width (centre-line width).
    """
    r = w / 2.0
    if char == '0':
        loop = np.concatenate([_arc(r, r, r, r, 0, 180), _arc(r, 1 - r, r, r, 180, 360)])
        return [np.concatenate([loop, loop[:1]])], w
    if char == '1':
        adv = 0.62 * w
        return [_pts((0.0, 0.30), (adv, 0.0), (adv, 1.0))], adv
    if char == '2':
        top = _arc(r, r, r, r, 165, -35)
        return [np.concatenate([top, _pts((0.0, 1.0), (w, 1.0))])], w
    if char == '3':
        upper = _arc(r, 0.25, 0.92 * r, 0.25, 155, -90)
        lower = _arc(r, 0.74, r, 0.26, 90, -155)
        return [np.concatenate([upper, lower])], w
    if char == '4':
        return [_pts((0.78 * w, 1.0), (0.78 * w, 0.0), (0.0, 0.68), (w, 0.68))], w
    if char == '5':
        bowl = _arc(r, 0.67, r, 0.33, 125, -150)
        return [np.concatenate([_pts((0.92 * w, 0.0), (0.10 * w, 0.0), (0.04 * w, 0.45)),
                                bowl])], w
    if char == '6':
        bowl = _arc(r, 0.67, r, 0.33, 0, 360, 64)
        if arched_six:  # up the left side, over the top, the end turned down on the right
            stem = np.concatenate([_pts((0.0, 0.67)), _arc(r, r, r, r, 180, -18)])
        else:
            stem = _bezier((0.85 * w, 0.0), (0.02 * w, 0.22), (0.0, 0.67))
        return [bowl, stem], w
    if char == '9':
        strokes, adv = _glyph('6', w)
        return [np.stack([adv - s[:, 0], 1.0 - s[:, 1]], axis=1) for s in strokes], adv
    if char == '7':
        return [_pts((0.0, 0.0), (w, 0.0), (0.25 * w, 1.0))], w
    if char == '8':
        upper = _arc(r, 0.24, 0.86 * r, 0.24, 0, 360, 64)
        lower = _arc(r, 0.73, r, 0.27, 0, 360, 64)
        return [upper, lower], w
    if char == 't':
        adv = 0.6 * w
        stem = np.concatenate([_pts((0.3 * adv, 0.15)),
                               _arc(0.3 * adv + 0.35 * adv, 0.85, 0.35 * adv, 0.15, 180, 300)])
        return [stem, _pts((0.0, 0.38), (adv, 0.38))], adv
    if char == 'm':
        adv = 1.3 * w
        half = adv / 2
        left = np.concatenate([_pts((0.0, 1.0), (0.0, 0.55)),
                               _arc(half / 2, 0.55, half / 2, 0.2, 180, 0), _pts((half, 1.0))])
        right = np.concatenate([_pts((half, 0.55)), _arc(half * 1.5, 0.55, half / 2, 0.2, 180, 0),
                                _pts((adv, 1.0))])
        return [_pts((0.0, 0.38), (0.0, 1.0)), left, right], adv
    if char == ',':
        return [_pts((0.05, 0.92), (0.0, 1.08))], 0.05
    raise ValueError(f'no glyph for character {char!r}')


def _text_strokes(text: str, height: float, digit_width: float, stroke: float,
                  gap: float, arched_six: bool = False) -> tuple[list[np.ndarray], float]:
    """Polylines of a text centred at (0, 0) in units where the glyph outer height is
    ``height``; returns the polylines and the stroke width in the same units."""
    stroke_w = stroke * height
    centre_h = height - stroke_w
    w = (digit_width * height - stroke_w) / centre_h
    lines: list[np.ndarray] = []
    x = 0.0
    for index, char in enumerate(text):
        strokes, adv = _glyph(char, w, arched_six)
        lines.extend(s + np.array([x, 0.0]) for s in strokes)
        x += adv + (gap * height + stroke_w) / centre_h
        if index == len(text) - 1:
            x -= (gap * height + stroke_w) / centre_h
    offset = np.array([x / 2.0, 0.5])
    return [(line - offset) * centre_h for line in lines], stroke_w


class _Canvas:
    """A square high-resolution BGR canvas with unit-to-pixel mapping."""

    def __init__(self, size_px: int) -> None:
        self.size_px = size_px
        self.bgr = np.zeros((size_px, size_px, 3), np.uint8)
        self.alpha = np.zeros((size_px, size_px), np.uint8)
        self.scale = size_px / 2.0
        self.shift = 4  # sub-pixel bits of cv2 drawing

    def _px(self, points: np.ndarray) -> np.ndarray:
        fixed = (points * self.scale + self.scale) * (1 << self.shift)
        return np.round(fixed).astype(np.int32)

    def disc(self, radius: float, colour: tuple[int, int, int], alpha: bool = False) -> None:
        centre = (int(self.scale * (1 << self.shift)),) * 2
        rad = int(round(radius * self.scale * (1 << self.shift)))
        cv2.circle(self.bgr, centre, rad, colour, -1, cv2.LINE_AA, self.shift)
        if alpha:
            cv2.circle(self.alpha, centre, rad, 255, -1, cv2.LINE_AA, self.shift)

    def polylines(self, lines: Sequence[np.ndarray], width: float,
                  colour: tuple[int, int, int]) -> None:
        thickness = max(1, int(round(width * self.scale)))
        for line in lines:
            cv2.polylines(self.bgr, [self._px(line)], False, colour, thickness, cv2.LINE_AA,
                          self.shift)

    def polygon(self, points: np.ndarray, colour: tuple[int, int, int]) -> None:
        cv2.fillPoly(self.bgr, [self._px(points)], colour, cv2.LINE_AA, self.shift)

    def clip_to_disc(self, radius: float, background: tuple[int, int, int]) -> None:
        mask = np.zeros_like(self.alpha)
        centre = (int(self.scale * (1 << self.shift)),) * 2
        cv2.circle(mask, centre, int(round(radius * self.scale * (1 << self.shift))), 255, -1,
                   cv2.LINE_AA, self.shift)
        weight = (mask.astype(np.float32) / 255.0)[..., None]
        blended = self.bgr * weight + np.array(background, np.float32) * (1.0 - weight)
        self.bgr = blended.astype(np.uint8)


def _draw_ring_sign(canvas: _Canvas, geometry: SignGeometry) -> None:
    canvas.disc(1.0, geometry.white_bgr, alpha=True)
    canvas.disc(geometry.ring_outer, geometry.red_bgr)
    canvas.disc(geometry.ring_inner, geometry.white_bgr)


def _draw_number(canvas: _Canvas, text: str, geometry: SignGeometry,
                 colour: tuple[int, int, int]) -> None:
    three = len(text) >= 3
    height = geometry.digit_height_3 if three else geometry.digit_height_2
    width = geometry.digit_width_3 if three else geometry.digit_width
    lines, stroke_w = _text_strokes(text, height, width, geometry.stroke, geometry.gap,
                                    geometry.arched_six)
    canvas.polylines(lines, stroke_w, colour)


def _draw_end_bar(canvas: _Canvas, geometry: SignGeometry, stripes: int = 5,
                  band_width: float = 0.34) -> None:
    """VZ 278/282 diagonal band of thin black stripes, upper right to lower left."""
    direction = np.array([-1.0, 1.0]) / math.sqrt(2.0)  # along the band (y down)
    normal = np.array([1.0, 1.0]) / math.sqrt(2.0)
    stripe_w = band_width / (2 * stripes - 1)
    for index in range(stripes):
        offset = -band_width / 2 + stripe_w / 2 + 2 * index * stripe_w
        centre = normal * offset
        line = np.stack([centre - direction, centre + direction])
        canvas.polylines([line], stripe_w, geometry.black_bgr)


def _draw_end_of_limit(canvas: _Canvas, text: str | None, geometry: SignGeometry) -> None:
    canvas.disc(1.0, geometry.black_bgr, alpha=True)
    canvas.disc(0.975, geometry.white_bgr)
    if text is not None:
        _draw_number(canvas, text, geometry, geometry.gray_bgr)
    _draw_end_bar(canvas, geometry)
    canvas.clip_to_disc(0.975, geometry.white_bgr)


def _car_outline(cx: float, cy: float, width: float) -> np.ndarray:
    """Car seen from behind (VZ 276 symbol), a closed polygon in unit coordinates."""
    h = width * 1.05
    pts = [(-0.5, 0.72), (-0.5, 0.28), (-0.36, 0.22), (-0.28, -0.08), (0.28, -0.08),
           (0.36, 0.22), (0.5, 0.28), (0.5, 0.72), (0.36, 0.72), (0.36, 0.88), (0.18, 0.88),
           (0.18, 0.72), (-0.18, 0.72), (-0.18, 0.88), (-0.36, 0.88), (-0.36, 0.72)]
    arr = np.asarray(pts, dtype=np.float64)
    return np.stack([cx + arr[:, 0] * width, cy + (arr[:, 1] - 0.4) * h], axis=1)


def _arrowhead(tip: tuple[float, float], direction: tuple[float, float],
               size: float) -> np.ndarray:
    """Filled triangle (3, 2) with its tip at ``tip`` pointing along ``direction``."""
    d = np.asarray(direction, dtype=np.float64)
    n = np.array([-d[1], d[0]])
    t = np.asarray(tip, dtype=np.float64)
    base = t - d * size
    return np.stack([t, base + n * size * 0.6, base - n * size * 0.6])


def _draw_lookalike(canvas: _Canvas, kind: str, geometry: SignGeometry) -> None:
    if kind == 'end_of_restrictions':
        _draw_end_of_limit(canvas, None, geometry)
        return
    _draw_ring_sign(canvas, geometry)
    if kind == 'no_entry':
        return
    if kind == 'no_overtaking':
        canvas.polygon(_car_outline(-0.3, 0.05, 0.5), geometry.red_bgr)
        canvas.polygon(_car_outline(0.3, 0.05, 0.5), geometry.black_bgr)
        return
    small = {'height': 0.46, 'digit_width': 0.52, 'stroke': 0.15, 'gap': 0.08}
    if kind == 'weight_limit':
        lines, stroke_w = _text_strokes('7,5t', **small)
        canvas.polylines(lines, stroke_w, geometry.black_bgr)
        return
    if kind == 'width_limit':
        lines, stroke_w = _text_strokes('2m', **small)
        canvas.polylines(lines, stroke_w, geometry.black_bgr)
        for sign in (-1.0, 1.0):
            canvas.polygon(_arrowhead((sign * 0.42, 0.0), (sign * -1.0, 0.0), 0.2),
                           geometry.black_bgr)
        return
    if kind == 'height_limit':
        lines, stroke_w = _text_strokes('3,8m', **small)
        canvas.polylines(lines, stroke_w, geometry.black_bgr)
        for sign in (-1.0, 1.0):
            canvas.polygon(_arrowhead((0.0, sign * 0.42), (0.0, sign * -1.0), 0.2),
                           geometry.black_bgr)
        return
    raise ValueError(f'unknown look-alike kind {kind!r}')


def _supersample(diameter_px: int) -> int:
    """Canvas oversampling factor: at least 4, canvas at least ~512 px."""
    return max(4, math.ceil(512 / diameter_px))


def render_sign(kind: str, diameter_px: int,
                geometry: SignGeometry = GEOMETRY) -> tuple[np.ndarray, np.ndarray]:
    """Render one sign on a transparent background.

    Args:
        kind: one of :data:`SIGN_KINDS` (also ``'100'``, the generic three-digit template).
        diameter_px: the sign's outer diameter D in pixels (>= 4).
        geometry: sign proportions (defaults to the German StVO ones).

    Returns:
        ``(bgr, alpha)``: ``bgr`` (D, D, 3) uint8 colour, ``alpha`` (D, D) float32 in
        [0, 1] (1 inside the disc, anti-aliased at its edge, 0 outside).

    Raises:
        ValueError: for an unknown kind or a diameter below 4 pixels.
    """
    if kind not in SIGN_KINDS and kind not in GENERIC_KINDS:
        raise ValueError(f'unknown sign kind {kind!r}; known kinds: {", ".join(SIGN_KINDS)}')
    diameter_px = int(diameter_px)
    if diameter_px < 4:
        raise ValueError(f'diameter_px must be at least 4, got {diameter_px}')
    big_bgr, big_alpha = render_sign_highres(kind, diameter_px * _supersample(diameter_px),
                                             geometry)
    bgr = cv2.resize(big_bgr, (diameter_px, diameter_px), interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(big_alpha, (diameter_px, diameter_px), interpolation=cv2.INTER_AREA)
    return bgr, alpha


def render_sign_highres(kind: str, size_px: int,
                        geometry: SignGeometry = GEOMETRY) -> tuple[np.ndarray, np.ndarray]:
    """Draw a sign directly at ``size_px`` (no reduction; aliasing at small sizes).

    Returns ``(bgr (S, S, 3) uint8, alpha (S, S) float32)`` like :func:`render_sign`;
    the alpha of the colour pixels outside the disc is 0 and their colour is black.
    """
    canvas = _Canvas(size_px)
    if kind.startswith('end_of_limit_'):
        _draw_end_of_limit(canvas, kind.removeprefix('end_of_limit_'), geometry)
    elif kind in LOOKALIKE_KINDS:
        _draw_lookalike(canvas, kind, geometry)
    elif kind in GENERIC_KINDS or kind.isdigit():
        _draw_ring_sign(canvas, geometry)
        _draw_number(canvas, kind, geometry, geometry.black_bgr)
    else:
        raise ValueError(f'unknown sign kind {kind!r}')
    alpha = canvas.alpha.astype(np.float32) / 255.0
    bgr = (canvas.bgr.astype(np.float32) * alpha[..., None]).round().astype(np.uint8)
    return bgr, alpha


def gray_template(kind: str, diameter_px: int, canvas_px: int | None = None, *,
                  background: float = 128.0, yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                  roll_deg: float = 0.0, geometry: SignGeometry = GEOMETRY) -> np.ndarray:
    """A grayscale template of a sign on a uniform gray background (DAGM 2010).

    The sign is rendered at high resolution, rotated out of plane (``yaw_deg`` about the
    vertical axis, ``pitch_deg`` about the horizontal axis, seen by a camera at ~6
    diameters so the foreshortening is slightly perspective) and in plane (``roll_deg``,
    counter-clockwise), composited on ``background`` and reduced with area interpolation.

    Args:
        kind: a sign kind (see :func:`render_sign`).
        diameter_px: sign diameter in output pixels (>= 4).
        canvas_px: side of the square output (default: ``diameter_px``); the sign is centred.
        background: gray level of the background, 0..255.

    Returns:
        (canvas_px, canvas_px) float32 gray levels 0..255.
    """
    return gray_views(kind, diameter_px, canvas_px, ((yaw_deg, pitch_deg, roll_deg),),
                      background=background, geometry=geometry)[0]


def render_master(kind: str, size_px: int = 512,
                  geometry: SignGeometry = GEOMETRY) -> np.ndarray:
    """A high-resolution gray rendering for :func:`views_from_master`.

    Returns:
        (size_px, size_px, 2) float32: channel 0 the gray level 0..255 premultiplied by
        alpha, channel 1 the alpha 0..1.
    """
    bgr, alpha = render_sign_highres(kind, int(size_px), geometry)
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    return np.dstack([gray, alpha])


def views_from_master(master: np.ndarray, diameter_px: float, canvas_px: int,
                      views: Sequence[tuple[float, float, float]], *,
                      background: float = 128.0, supersample: int = 2) -> np.ndarray:
    """Views of a sign rendered by :func:`render_master`, as gray templates.

    The master is reduced with area interpolation to ``supersample`` times the target
    diameter, warped per view (linear interpolation) and reduced again by area.

    Args:
        master: (S, S, 2) float32 from :func:`render_master`.
        diameter_px: sign diameter in output pixels (may be fractional, >= 4).
        canvas_px: side of the square outputs; the sign is centred.
        views: ``(yaw_deg, pitch_deg, roll_deg)`` per output (see :func:`gray_template`).
        background: gray level of the background, 0..255.
        supersample: oversampling of the warp (>= 1).

    Returns:
        (V, canvas_px, canvas_px) float32 gray levels 0..255.
    """
    return views_from_masters([master], diameter_px, canvas_px, views,
                              background=background, supersample=supersample)[0]


def views_from_masters(masters: Sequence[np.ndarray], diameter_px: float, canvas_px: int,
                       views: Sequence[tuple[float, float, float]], *,
                       background: float = 128.0, supersample: int = 2) -> np.ndarray:
    """:func:`views_from_master` of several signs at once (same result per sign).

    The reduced masters are stacked as channels of one image, so each view is one warp
    (the interpolation coordinates are computed once for all signs).

    Args:
        masters: K arrays (S, S, 2) float32 from :func:`render_master` (same S).
        diameter_px: sign diameter in output pixels (may be fractional, >= 4).
        canvas_px: side of the square outputs; the sign is centred.
        views: ``(yaw_deg, pitch_deg, roll_deg)`` per output (see :func:`gray_template`).
        background: gray level of the background, 0..255.
        supersample: oversampling of the warp (>= 1).

    Returns:
        (K, V, canvas_px, canvas_px) float32 gray levels 0..255.
    """
    if diameter_px < 4:
        raise ValueError(f'diameter_px must be at least 4, got {diameter_px}')
    canvas_px = int(canvas_px)
    if canvas_px < 1:
        raise ValueError(f'canvas_px must be positive, got {canvas_px}')
    if len(masters) == 0:
        raise ValueError('masters must hold at least one rendering')
    shapes = {np.shape(master) for master in masters}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3 or next(iter(shapes))[2] != 2:
        raise ValueError(f'masters must all have the same shape (S, S, 2), got {shapes}')
    factor = max(1, int(supersample))
    big_d = int(math.ceil(diameter_px * factor))
    big_canvas = canvas_px * factor
    # area reduction per master (cv2.resize takes at most 4 channels), then one
    # (big_d, big_d, 2K) stack: channels 2k, 2k + 1 are master k's gray and alpha
    reduced = [cv2.resize(np.asarray(master, np.float32), (big_d, big_d),
                          interpolation=cv2.INTER_AREA) for master in masters]
    if len(reduced) == 2:
        # OpenCV warps 4-channel images on another code path (interpolation rounding
        # differs from the 2-channel one by up to a few gray levels): pad to 6 channels
        reduced.append(np.zeros_like(reduced[0]))
    stacked = np.dstack(reduced)
    out = np.empty((len(masters), len(views), canvas_px, canvas_px), np.float32)
    scale = diameter_px * factor / big_d
    for index, (yaw, pitch, roll) in enumerate(views):
        homography = _view_homography(big_d, big_canvas, yaw, pitch, roll, scale=scale)
        warped = cv2.warpPerspective(stacked, homography, (big_canvas, big_canvas),
                                     flags=cv2.INTER_LINEAR, borderValue=(0.0, 0.0))
        warped = warped.reshape(big_canvas, big_canvas, len(reduced), 2)[:, :, :len(masters)]
        composite = warped[..., 0] + (1.0 - warped[..., 1]) * np.float32(background)
        if factor == 1:
            out[:, index] = composite.transpose(2, 0, 1)
            continue
        for sign in range(len(masters)):
            out[sign, index] = cv2.resize(np.ascontiguousarray(composite[..., sign]),
                                          (canvas_px, canvas_px),
                                          interpolation=cv2.INTER_AREA)
    return out


def gray_views(kind: str, diameter_px: float, canvas_px: int | None,
               views: Sequence[tuple[float, float, float]], *, background: float = 128.0,
               supersample: int = 4, geometry: SignGeometry = GEOMETRY) -> np.ndarray:
    """Several views of one sign as gray templates, rendering the sign only once.

    Args:
        kind: a sign kind (see :func:`render_sign`).
        diameter_px: sign diameter in output pixels (may be fractional, >= 4).
        canvas_px: side of the square outputs (default: ``ceil(diameter_px)``).
        views: ``(yaw_deg, pitch_deg, roll_deg)`` per output (see :func:`gray_template`).
        background: gray level of the background, 0..255.
        supersample: oversampling of the warp before the area reduction (>= 1).

    Returns:
        (V, canvas_px, canvas_px) float32 gray levels 0..255.
    """
    if diameter_px < 4:
        raise ValueError(f'diameter_px must be at least 4, got {diameter_px}')
    canvas_px = int(canvas_px if canvas_px is not None else math.ceil(diameter_px))
    master_px = max(512, int(math.ceil(diameter_px * max(1, supersample))) * 2)
    return views_from_master(render_master(kind, master_px, geometry), diameter_px, canvas_px,
                             views, background=background, supersample=supersample)


def _view_homography(sign_px: int, canvas_px: int, yaw_deg: float, pitch_deg: float,
                     roll_deg: float, distance_diameters: float = 6.0,
                     scale: float = 1.0) -> np.ndarray:
    """Homography mapping the sign image (sign_px square) into a canvas of canvas_px,
    centred, after 3-D rotation (yaw about y, pitch about x, then roll in the image plane)
    and a pinhole projection at ``distance_diameters`` sign diameters; ``scale``
    multiplies the projected size (fractional output diameters)."""
    half = sign_px / 2.0
    yaw, pitch, roll = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    rot_y = np.array([[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0],
                      [-math.sin(yaw), 0, math.cos(yaw)]])
    rot_x = np.array([[1, 0, 0], [0, math.cos(pitch), -math.sin(pitch)],
                      [0, math.sin(pitch), math.cos(pitch)]])
    rotation = rot_x @ rot_y
    distance = distance_diameters * sign_px
    focal = distance * scale  # scale 1 keeps the unrotated sign at its size
    src = np.array([[0, 0], [sign_px, 0], [sign_px, sign_px], [0, sign_px]], np.float64)
    dst = []
    cos_r, sin_r = math.cos(roll), math.sin(roll)
    for x, y in src:
        point = rotation @ np.array([x - half, y - half, 0.0])
        u = focal * point[0] / (distance + point[2])
        v = focal * point[1] / (distance + point[2])
        # counter-clockwise in the image (y down): rotate by -roll in maths convention
        ur = cos_r * u + sin_r * v
        vr = -sin_r * u + cos_r * v
        dst.append((ur + canvas_px / 2.0, vr + canvas_px / 2.0))
    return cv2.getPerspectiveTransform(src.astype(np.float32), np.asarray(dst, np.float32))
