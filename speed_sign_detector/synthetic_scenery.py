"""The scenery of the synthetic drives (:mod:`speed_sign_detector.synthetic`): the road's
geometry, the ground and far-scene textures, the lighting of day, dusk and night, and the
raster primitives the frames are drawn with (float32 BGR images, pixels).
"""
from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

ROAD_LEFT_M, ROAD_RIGHT_M, LANE_WIDTH_M = -5.4, 1.8, 3.6
GROUND_RESOLUTION_M = 0.05        # ground texture: metres per texel
GROUND_HALF_WIDTH_M = 30.0        # ground texture spans X in [-30, 30] m
GROUND_PERIOD_M = 60.0            # ... and repeats every 60 m along Z
FOG_DISTANCE_M = 90.0             # ground fades into the far scene over this distance
FAR_AZIMUTH_RAD = 1.2             # far scene texture spans azimuth [-1.2, 1.2] rad
FAR_TAN_LOW, FAR_TAN_HIGH = -0.06, 0.7   # ... and tan(elevation) in this range
FAR_SIZE = (700, 2400)            # far scene texture rows, columns


@lru_cache(maxsize=4096)
def sign_image(kind: str, diameter_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Rendered sign (premultiplied BGR float32 (D,D,3), alpha float32 (D,D)), cached."""
    from speed_sign_detector.recognition.templates import render_sign

    bgr, alpha = render_sign(kind, diameter_px)
    return bgr.astype(np.float32), alpha.astype(np.float32)


# ---------------------------------------------------------------------- textures
def periodic_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float
                   ) -> np.ndarray:
    """Smooth noise, zero mean, unit-ish std, periodic in both axes (float32)."""
    noise = rng.standard_normal(shape).astype(np.float32)
    pad = int(3 * sigma_px) + 1
    padded = np.pad(noise, pad, mode='wrap')
    blurred = cv2.GaussianBlur(padded, (0, 0), sigma_px)[pad:-pad, pad:-pad]
    return blurred / max(float(blurred.std()), 1e-6)


def ground_texture(rng: np.random.Generator) -> np.ndarray:
    """Road and verges seen from above: (rows along Z, columns along X, 3) float32 BGR."""
    rows = int(round(GROUND_PERIOD_M / GROUND_RESOLUTION_M))
    cols = int(round(2 * GROUND_HALF_WIDTH_M / GROUND_RESOLUTION_M))
    x_m = (np.arange(cols, dtype=np.float32) + 0.5) * GROUND_RESOLUTION_M - GROUND_HALF_WIDTH_M
    z_m = (np.arange(rows, dtype=np.float32) + 0.5) * GROUND_RESOLUTION_M
    fine = periodic_noise(rng, (rows, cols), 0.7)
    coarse = periodic_noise(rng, (rows, cols), 12.0)
    texture = np.empty((rows, cols, 3), np.float32)
    # Grass verges.
    grass = np.array([55.0, 105.0, 80.0], np.float32)
    texture[:] = grass * (1.0 + 0.18 * coarse[..., None] + 0.12 * fine[..., None])
    # Gravel shoulders.
    shoulder = ((x_m > ROAD_RIGHT_M) & (x_m < ROAD_RIGHT_M + 0.8)) | (
        (x_m < ROAD_LEFT_M) & (x_m > ROAD_LEFT_M - 0.6))
    texture[:, shoulder] = (np.array([110.0, 120.0, 125.0], np.float32)
                            * (1.0 + 0.15 * fine[:, shoulder, None]))
    # Asphalt with patches and cracks.
    road = (x_m >= ROAD_LEFT_M) & (x_m <= ROAD_RIGHT_M)
    asphalt = 95.0 + 9.0 * coarse[:, road] + 7.0 * fine[:, road]
    texture[:, road] = asphalt[..., None] * np.array([1.0, 0.98, 0.96], np.float32)
    # Markings: solid edge lines, dashed centre line (3 m dash every 12 m).
    paint = np.array([210.0, 212.0, 215.0], np.float32)
    for centre_m in (ROAD_RIGHT_M - 0.1, ROAD_LEFT_M + 0.1):
        texture[:, np.abs(x_m - centre_m) < 0.075] = paint
    dash_rows = np.mod(z_m, 12.0) < 3.0
    centre_cols = np.abs(x_m - (ROAD_RIGHT_M - LANE_WIDTH_M)) < 0.075
    texture[np.ix_(dash_rows, centre_cols)] = paint
    return np.clip(texture * (1.0 + 0.04 * fine[..., None]), 0, 255).astype(np.float32)


def far_texture(rng: np.random.Generator) -> np.ndarray:
    """Sky, clouds and the far treeline/buildings: (rows = tan elevation high->low,
    columns = azimuth, 3) float32 BGR."""
    rows, cols = FAR_SIZE
    tan_e = FAR_TAN_HIGH - (np.arange(rows, dtype=np.float32) + 0.5) / rows * (
        FAR_TAN_HIGH - FAR_TAN_LOW)
    sky_t = np.clip(tan_e / 0.5, 0.0, 1.0)[:, None, None]
    horizon_colour = np.array([225.0, 210.0, 195.0], np.float32)
    zenith_colour = np.array([205.0, 150.0, 95.0], np.float32)
    texture = np.broadcast_to(horizon_colour * (1 - sky_t) + zenith_colour * sky_t,
                              (rows, cols, 3)).copy()
    clouds = periodic_noise(rng, (rows, cols), 25.0)
    cloud_weight = np.clip(clouds - 0.6, 0.0, 1.0)[..., None] * 0.8
    texture = texture * (1 - cloud_weight) + 240.0 * cloud_weight
    # Skyline: smooth treeline with blocks of buildings.
    profile = periodic_noise(rng, (1, cols), 15.0)[0]
    skyline = 0.015 + 0.012 * (profile - profile.min())
    block = 0
    while block < cols:
        width = int(rng.integers(40, 160))
        if rng.uniform() < 0.25:
            skyline[block:block + width] = np.maximum(skyline[block:block + width],
                                                      rng.uniform(0.03, 0.07))
        block += width
    fine = periodic_noise(rng, (rows, cols), 1.5)
    below = tan_e[:, None] < skyline[None, :]
    treeline = np.array([60.0, 80.0, 65.0], np.float32) * (1.0 + 0.2 * fine[..., None])
    texture[below] = treeline[below]
    return np.ascontiguousarray(texture, dtype=np.float32)


def headlight_pool(width: int, height: int) -> np.ndarray:
    """Relative illumination of the headlights, (H, W) float32 in [0, 1]."""
    cols, rows = np.meshgrid(np.linspace(-1.0, 1.0, width, dtype=np.float32),
                             np.linspace(0.0, 1.0, height, dtype=np.float32))
    pool = np.exp(-(cols / 0.55) ** 2) * np.clip((rows - 0.45) / 0.25, 0.0, 1.0)
    return pool.astype(np.float32)


# ---------------------------------------------------------------------- lighting
def background_gain(darkness: float) -> float:
    """Overall brightness of the scene: 1 by day, ~0.55 at dusk, ~0.12 at night."""
    if darkness <= 0.5:
        return 1.0 - 0.9 * darkness
    return 0.55 - 0.86 * (darkness - 0.5)


def apply_lighting(image: np.ndarray, darkness: float, headlight: np.ndarray) -> np.ndarray:
    """Scene brightness, dusk tint, night headlights and raised black level."""
    dusk = 1.0 - abs(darkness - 0.5) * 2.0
    night = float(np.clip((darkness - 0.5) * 2.0, 0.0, 1.0))
    tint = np.array([1.0 - 0.25 * dusk + 0.05 * night, 1.0 - 0.08 * dusk,
                     1.0 + 0.06 * dusk - 0.05 * night], np.float32)
    gain = background_gain(darkness) + night * 0.45 * headlight
    lit = image * gain[..., None] * tint
    return lit + 10.0 * night


def line_kernel(dx_px: float, dy_px: float) -> np.ndarray | None:
    """Normalised kernel of a straight motion path, None when shorter than a pixel."""
    length = math.hypot(dx_px, dy_px)
    if length < 1.0:
        return None
    size = 2 * int(math.ceil(length / 2.0)) + 1
    kernel = np.zeros((size, size), np.float32)
    centre = size // 2
    steps = max(2, int(math.ceil(length * 4)))
    for t in np.linspace(-0.5, 0.5, steps):
        x, y = centre + t * dx_px, centre + t * dy_px
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - x0, y - y0
        for xi, yi, w in ((x0, y0, (1 - fx) * (1 - fy)), (x0 + 1, y0, fx * (1 - fy)),
                          (x0, y0 + 1, (1 - fx) * fy), (x0 + 1, y0 + 1, fx * fy)):
            if 0 <= xi < size and 0 <= yi < size:
                kernel[yi, xi] += w
    return kernel / kernel.sum()


# ---------------------------------------------------------------------- primitives
def fill_rect(image: np.ndarray, x1: float, y1: float, x2: float, y2: float,
              colour: tuple[float, ...]) -> None:
    height, width = image.shape[:2]
    left, right = max(0, int(round(x1))), min(width, int(round(x2)))
    top, bottom = max(0, int(round(y1))), min(height, int(round(y2)))
    if right <= left:
        right = min(width, left + 1)
    if right > left and bottom > top:
        image[top:bottom, left:right] = colour


def fill_ellipse(image: np.ndarray, x: float, y: float, rx: float, ry: float,
                 colour: tuple[float, ...]) -> None:
    """Anti-aliased filled ellipse (sub-pixel centre and radii) on a float image."""
    if rx < 0.3 or ry < 0.3:
        return
    height, width = image.shape[:2]
    left, right = max(0, int(x - rx - 1)), min(width, int(x + rx + 2))
    top, bottom = max(0, int(y - ry - 1)), min(height, int(y + ry + 2))
    if right <= left or bottom <= top:
        return
    cols = np.arange(left, right, dtype=np.float32) + 0.5 - x
    rows = np.arange(top, bottom, dtype=np.float32) + 0.5 - y
    distance = np.sqrt((cols[None, :] / rx) ** 2 + (rows[:, None] / ry) ** 2)
    coverage = np.clip((1.0 - distance) * min(rx, ry) + 0.5, 0.0, 1.0)[..., None]
    region = image[top:bottom, left:right]
    region[:] = region * (1.0 - coverage) + np.asarray(colour, np.float32) * coverage


def add_glow(image: np.ndarray, x: float, y: float, radius: float, strength: float,
             colour: tuple[float, float, float] = (0.8, 0.95, 1.0)) -> None:
    """Emissive light: a bright disc with a soft halo, added to the image."""
    reach = radius * 4.0 + 3.0
    height, width = image.shape[:2]
    left, right = max(0, int(x - reach)), min(width, int(x + reach + 1))
    top, bottom = max(0, int(y - reach)), min(height, int(y + reach + 1))
    if right <= left or bottom <= top:
        return
    cols = np.arange(left, right, dtype=np.float32) + 0.5 - x
    rows = np.arange(top, bottom, dtype=np.float32) + 0.5 - y
    distance = np.sqrt(cols[None, :] ** 2 + rows[:, None] ** 2)
    core = np.clip(radius + 0.5 - distance, 0.0, 1.0)
    halo = np.exp(-(distance / max(radius * 1.5, 1.0)) ** 2) * 0.5
    glow = (core + halo)[..., None] * strength * np.asarray(colour, np.float32)
    image[top:bottom, left:right] += glow


def composite(image: np.ndarray, left: int, top: int, premultiplied: np.ndarray,
              alpha: np.ndarray) -> None:
    """Alpha-blend a premultiplied patch at (left, top), clipped to the image."""
    height, width = image.shape[:2]
    size_v, size_u = alpha.shape
    x1, y1 = max(0, left), max(0, top)
    x2, y2 = min(width, left + size_u), min(height, top + size_v)
    if x2 <= x1 or y2 <= y1:
        return
    patch_alpha = alpha[y1 - top:y2 - top, x1 - left:x2 - left, None]
    patch = premultiplied[y1 - top:y2 - top, x1 - left:x2 - left]
    region = image[y1:y2, x1:x2]
    region[:] = region * (1.0 - patch_alpha) + patch
