"""Edge extraction on the CPU, fast: OpenCV filters and sparse neighbour tests.

The same maths as :func:`speed_sign_detector.detection.gradients.extract_edges` (the
reference, whose conventions this module follows), arranged for speed on a CPU:

- the contrast table, the pyramid's 2x2 box averages and the 3x3 Sobel are OpenCV calls
  (vectorised, on every core), the magnitude is numpy's (rounded as the reference's);
- the non-maximum suppression along the gradient and the neighbour-support test look at
  the pixels that can still be edges only (those above the threshold, then the ridge
  pixels), by flat index, instead of at every pixel for every direction;
- a level is taken in strips of :data:`STRIP_ROWS` rows (with a halo), so that the
  gradient images the sparse tests read are still in the CPU caches.

Float rounding may differ from the reference in the last bit (OpenCV sums in another
order), so a pixel whose magnitude equals the threshold or its neighbour's to the last
bit may be decided the other way; ``test_voting_cpu.py`` checks the edge lists agree.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.gradients import (
    SUPPORT_ANGLE_DEG,
    EdgeList,
    gray_lookup,
)
from speed_sign_detector.detection.voting_numpy import plan_bands, pyramid_levels

_TAN_22 = np.float32(0.41421357)
_COS_SUPPORT = np.float32(math.cos(math.radians(SUPPORT_ANGLE_DEG)))


def build_pyramid_fast(gray: np.ndarray, levels: int, lookup: np.ndarray
                       ) -> list[np.ndarray]:
    """Float32 box-filter pyramid of an (H, W) uint8 frame: ``levels`` images, level 0
    ``lookup[gray]`` (as :func:`gradients.build_pyramid`)."""
    pyramid = [cv2.LUT(gray, lookup)]
    for _ in range(1, levels):
        previous = pyramid[-1]
        height, width = previous.shape[0] // 2, previous.shape[1] // 2
        pyramid.append(cv2.resize(previous[:2 * height, :2 * width], (width, height),
                                  interpolation=cv2.INTER_AREA))
    return pyramid


STRIP_ROWS = 64
"""Rows of a level extracted at a time: the strip's gradient images (with their halo)
stay in the CPU caches between the Sobel pass and the neighbour tests (on 2 loaded cores,
a 640x480 level took 8 ms of CPU time in strips of 64 rows against 12 ms whole, frames
interleaved)."""
_HALO_ROWS = 3
"""Rows above and below a strip whose Sobel must be right: the support test reads the
ridge test of the rows next to the strip, which reads the magnitude one row further,
which needs the image one row further still."""


def extract_edges_fast(image: np.ndarray, level: int, threshold: float, thin: bool,
                       min_support: int = 0) -> EdgeList:
    """Edge pixels of one pyramid level (float32 (H, W) gray image), row-ordered as the
    reference's :func:`gradients.extract_edges` lists them.

    The level is taken in strips of :data:`STRIP_ROWS` rows, each with
    :data:`_HALO_ROWS` rows of the image above and below: every value a strip's tests
    read is computed from the same 3x3 neighbourhood as on the whole level, so the edges
    are those of the whole level.
    """
    height, width = image.shape
    pixels, gx, gy = [], [], []
    for top in range(0, height, STRIP_ROWS):
        bottom = min(height, top + STRIP_ROWS)
        first = max(0, top - _HALO_ROWS)
        strip_pixels, strip_gx, strip_gy = _strip_edges(
            image[first:min(height, bottom + _HALO_ROWS)], top - first, bottom - first,
            threshold, thin, min_support)
        pixels.append(strip_pixels + first * width)
        gx.append(strip_gx)
        gy.append(strip_gy)
    rows, cols = np.divmod(np.concatenate(pixels), width)
    return EdgeList(cols.astype(np.float32), rows.astype(np.float32), np.concatenate(gx),
                    np.concatenate(gy), level, width, height)


def _strip_edges(image: np.ndarray, top: int, bottom: int, threshold: float, thin: bool,
                 min_support: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge pixels in rows ``top`` to ``bottom`` (exclusive) of a strip of a level
    (float32 (h, W), the strip's rows and its halo): their flat indices in the strip,
    row-ordered, and their ``gx``, ``gy``.

    The strip's first and last rows are the level's border rows or halo rows no test
    reads (the reference has no gradient on the border, so both are zeroed).
    """
    height, width = image.shape
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    # as the reference rounds it (cv2.magnitude's last bit depends on where the row
    # starts in its vector lanes, so strips would round some pixels otherwise)
    magnitude = gx * gx
    magnitude += gy * gy
    np.sqrt(magnitude, out=magnitude)
    for array in (gx, gy, magnitude):  # the reference has no gradient on the border
        array[0, :] = array[-1, :] = 0.0
        array[:, 0] = array[:, -1] = 0.0
    # the rows whose ridge test the support test of rows top..bottom reads
    tested_top, tested_bottom = max(1, top - 1), min(height - 1, bottom + 1)
    keep = magnitude[tested_top:tested_bottom] >= np.float32(threshold)
    keep[:, 0] = keep[:, -1] = False
    flat_gx, flat_gy, flat_magnitude = gx.ravel(), gy.ravel(), magnitude.ravel()
    pixels = np.flatnonzero(keep) + tested_top * width
    if thin and pixels.size:
        pixels = pixels[_is_ridge(pixels, flat_magnitude, flat_gx, flat_gy, width)]
    if min_support > 0 and pixels.size:
        pixels = pixels[_support(pixels, flat_magnitude, flat_gx, flat_gy, width)
                        >= min_support]
    pixels = pixels[(pixels >= top * width) & (pixels < bottom * width)]
    return pixels, flat_gx[pixels], flat_gy[pixels]


def compute_edges_fast(gray: np.ndarray, config: DetectorConfig) -> list[EdgeList]:
    """Edge lists of every pyramid level the config needs (index = level), as
    :func:`voting_numpy.compute_edges` gives them."""
    pyramid = build_pyramid_fast(gray, pyramid_levels(plan_bands(config)),
                                 gray_lookup(config.contrast, config.log_offset_gray))
    return [extract_edges_fast(image, level, config.gradient_threshold, config.thin_edges,
                               config.edge_support)
            for level, image in enumerate(pyramid)]


def _is_ridge(pixels: np.ndarray, magnitude: np.ndarray, gx: np.ndarray, gy: np.ndarray,
              width: int) -> np.ndarray:
    """For interior flat ``pixels``: is the magnitude a maximum along the quantised
    gradient direction (``m > m(p - d)`` and ``m >= m(p + d)``)?"""
    px, py, centre = gx[pixels], gy[pixels], magnitude[pixels]
    ax, ay = np.abs(px), np.abs(py)
    horizontal = ay <= _TAN_22 * ax
    vertical = ax <= _TAN_22 * ay
    # flat step along the direction: 1 (horizontal), W (vertical), W + 1 or W - 1 (diagonal)
    step = np.where(horizontal, 1, np.where(vertical, width,
                                            np.where(px * py > 0, width + 1, width - 1)))
    return (centre > magnitude[pixels - step]) & (centre >= magnitude[pixels + step])


def _support(pixels: np.ndarray, magnitude: np.ndarray, gx: np.ndarray, gy: np.ndarray,
             width: int) -> np.ndarray:
    """Number of 8-neighbours of each of ``pixels`` (the ridge pixels, interior) that are
    among them and whose gradient direction is within SUPPORT_ANGLE_DEG of its own."""
    unit_x = np.zeros(magnitude.shape, np.float32)
    unit_y = np.zeros(magnitude.shape, np.float32)
    with np.errstate(divide='ignore', invalid='ignore'):  # threshold 0: (0, 0) / 0
        unit_x[pixels] = gx[pixels] / magnitude[pixels]
        unit_y[pixels] = gy[pixels] / magnitude[pixels]
    own_x, own_y = unit_x[pixels], unit_y[pixels]
    count = np.zeros(pixels.shape, np.int32)
    for offset in (-width - 1, -width, -width + 1, -1, 1, width - 1, width, width + 1):
        neighbours = pixels + offset
        # a non-edge neighbour has the unit vector (0, 0): its cosine 0 never counts
        count += (own_x * unit_x[neighbours] + own_y * unit_y[neighbours]) >= _COS_SUPPORT
    return count
