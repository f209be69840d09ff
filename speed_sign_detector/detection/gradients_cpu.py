"""Edge extraction on the CPU, fast: OpenCV filters and sparse neighbour tests.

The same maths as :func:`speed_sign_detector.detection.gradients.extract_edges` (the
reference, whose conventions this module follows), arranged for speed on a CPU:

- the contrast table, the pyramid's 2x2 box averages, the 3x3 Sobel and the magnitude are
  OpenCV calls (vectorised, on every core);
- the non-maximum suppression along the gradient and the neighbour-support test look at
  the pixels that can still be edges only (those above the threshold, then the ridge
  pixels), by flat index, instead of at every pixel for every direction.

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


def extract_edges_fast(image: np.ndarray, level: int, threshold: float, thin: bool,
                       min_support: int = 0) -> EdgeList:
    """Edge pixels of one pyramid level (float32 (H, W) gray image), row-ordered as the
    reference's :func:`gradients.extract_edges` lists them."""
    height, width = image.shape
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    magnitude = cv2.magnitude(gx, gy)
    for array in (gx, gy, magnitude):  # the reference has no gradient on the border
        array[0, :] = array[-1, :] = 0.0
        array[:, 0] = array[:, -1] = 0.0
    keep = magnitude >= np.float32(threshold)
    keep[0, :] = keep[-1, :] = False
    keep[:, 0] = keep[:, -1] = False
    flat_gx, flat_gy, flat_magnitude = gx.ravel(), gy.ravel(), magnitude.ravel()
    pixels = np.flatnonzero(keep)
    if thin and pixels.size:
        pixels = pixels[_is_ridge(pixels, flat_magnitude, flat_gx, flat_gy, width)]
    if min_support > 0 and pixels.size:
        pixels = pixels[_support(pixels, flat_magnitude, flat_gx, flat_gy, width)
                        >= min_support]
    rows, cols = np.divmod(pixels, width)
    return EdgeList(cols.astype(np.float32), rows.astype(np.float32), flat_gx[pixels],
                    flat_gy[pixels], level, width, height)


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
