"""Edge extraction on the CPU, fast: OpenCV filters, sparse neighbour tests, reused buffers.

The same maths as :func:`speed_sign_detector.detection.gradients.extract_edges` (the
reference, whose conventions this module follows), arranged for speed on a CPU:

- the contrast table, the pyramid's 2x2 box averages, the 3x3 Sobel and the magnitude are
  OpenCV calls (vectorised, on every core);
- the non-maximum suppression along the gradient and the neighbour-support test look at
  the pixels that can still be edges only (those above the threshold, then the ridge
  pixels), by flat index, instead of at every pixel for every direction; the gradients
  of those pixels are gathered once and narrowed down with them;
- the full-frame images (pyramid levels, Sobel components, magnitude, threshold mask,
  unit vectors) live in an :class:`EdgeWorkspace` and are written in place frame after
  frame: fresh full-frame arrays cost about 1,500 page faults per 640x480 frame (none
  with the workspace). With the narrowed gathers, a frame's edges take about half the
  time the allocating version took (default config, 2-core host, interleaved medians:
  6.7 against 13.7 ms at 640x480, 12.5 against 27.5 ms at 960x540).

Float rounding may differ from the reference in the last bit (OpenCV sums in another
order), so a pixel whose magnitude equals the threshold or its neighbour's to the last
bit may be decided the other way; ``test_voting_cpu.py`` checks the edge lists agree, and
``test_gradients_cpu.py`` that they are bitwise the ones the earlier, allocating version
of this module gave.
"""
from __future__ import annotations

import math
import threading

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

MAX_WORKSPACE_SHAPES = 8
"""Level sizes a workspace keeps buffers for; a new size beyond them drops all of them."""


class _LevelBuffers:
    """Full-frame scratch images of one (H, W) pyramid level, written in place.

    ``image``, ``gx``, ``gy``, ``magnitude``: (H, W) float32; ``keep``: (H, W) bool;
    ``unit_pairs``: (H * W,) int64, each the bits of a float32 (x, y) unit vector, zero
    except while :func:`_support` runs.
    """

    def __init__(self, height: int, width: int) -> None:
        self.image = np.empty((height, width), np.float32)
        self.gx = np.empty((height, width), np.float32)
        self.gy = np.empty((height, width), np.float32)
        self.magnitude = np.empty((height, width), np.float32)
        self.keep = np.empty((height, width), bool)
        self.unit_pairs = np.zeros(height * width, np.int64)


class EdgeWorkspace:
    """Scratch images reused by :func:`compute_edges_fast` from one frame to the next.

    One workspace serves one thread at a time (calls that share it must not overlap).
    It holds 25 bytes per pixel of every level size it has seen: about 10 MB for a
    640x480 frame's three levels, 17 MB at 960x540.
    The edge lists returned never point into it. Without an explicit workspace the
    functions use one per calling thread, so two detectors on two threads never share
    buffers, and two on the same thread take turns with them.
    """

    def __init__(self) -> None:
        self._levels: dict[tuple[int, int], _LevelBuffers] = {}

    def level(self, height: int, width: int) -> _LevelBuffers:
        """The buffers of an (H, W) level, allocated on first use of that size."""
        buffers = self._levels.get((height, width))
        if buffers is None:
            if len(self._levels) >= MAX_WORKSPACE_SHAPES:
                self._levels.clear()   # frame size changing: no unbounded growth
            buffers = self._levels[(height, width)] = _LevelBuffers(height, width)
        return buffers


_THREAD_STATE = threading.local()


def thread_workspace() -> EdgeWorkspace:
    """The calling thread's own :class:`EdgeWorkspace` (created on first use)."""
    workspace = getattr(_THREAD_STATE, 'workspace', None)
    if workspace is None:
        workspace = _THREAD_STATE.workspace = EdgeWorkspace()
    return workspace


def build_pyramid_fast(gray: np.ndarray, levels: int, lookup: np.ndarray,
                       workspace: EdgeWorkspace | None = None) -> list[np.ndarray]:
    """Float32 box-filter pyramid of an (H, W) uint8 frame: ``levels`` images, level 0
    ``lookup[gray]`` (as :func:`gradients.build_pyramid`). With a workspace the images
    are its buffers, overwritten by its next use."""
    if workspace is None:
        pyramid = [cv2.LUT(gray, lookup)]
    else:
        pyramid = [cv2.LUT(gray, lookup, dst=workspace.level(*gray.shape).image)]
    for _ in range(1, levels):
        previous = pyramid[-1]
        height, width = previous.shape[0] // 2, previous.shape[1] // 2
        target = None if workspace is None else workspace.level(height, width).image
        pyramid.append(cv2.resize(previous[:2 * height, :2 * width], (width, height),
                                  dst=target, interpolation=cv2.INTER_AREA))
    return pyramid


def extract_edges_fast(image: np.ndarray, level: int, threshold: float, thin: bool,
                       min_support: int = 0, workspace: EdgeWorkspace | None = None
                       ) -> EdgeList:
    """Edge pixels of one pyramid level (float32 (H, W) gray image), row-ordered as the
    reference's :func:`gradients.extract_edges` lists them. ``workspace`` defaults to
    the calling thread's (:func:`thread_workspace`)."""
    height, width = image.shape
    buffers = (thread_workspace() if workspace is None else workspace).level(height, width)
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, dst=buffers.gx, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, dst=buffers.gy, ksize=3)
    magnitude = cv2.magnitude(gx, gy, magnitude=buffers.magnitude)
    for array in (gx, gy, magnitude):  # the reference has no gradient on the border
        array[0, :] = array[-1, :] = 0.0
        array[:, 0] = array[:, -1] = 0.0
    keep = np.greater_equal(magnitude, np.float32(threshold), out=buffers.keep)
    keep[0, :] = keep[-1, :] = False
    keep[:, 0] = keep[:, -1] = False
    flat_magnitude = magnitude.ravel()
    pixels = np.flatnonzero(keep)
    # the gradients of the candidate pixels, narrowed down with them
    pixel_gx, pixel_gy = gx.ravel().take(pixels), gy.ravel().take(pixels)
    pixel_magnitude = flat_magnitude.take(pixels)
    if thin and pixels.size:
        ridge = _is_ridge(pixels, pixel_gx, pixel_gy, pixel_magnitude, flat_magnitude,
                          width)
        pixels, pixel_gx, pixel_gy, pixel_magnitude = _select(
            ridge, pixels, pixel_gx, pixel_gy, pixel_magnitude)
    if min_support > 0 and pixels.size:
        supported = _support(pixels, pixel_gx, pixel_gy, pixel_magnitude, buffers,
                             width) >= min_support
        pixels, pixel_gx, pixel_gy = _select(supported, pixels, pixel_gx, pixel_gy)
    rows, cols = np.divmod(pixels, width)
    return EdgeList(cols.astype(np.float32), rows.astype(np.float32), pixel_gx, pixel_gy,
                    level, width, height)


def compute_edges_fast(gray: np.ndarray, config: DetectorConfig,
                       workspace: EdgeWorkspace | None = None) -> list[EdgeList]:
    """Edge lists of every pyramid level the config needs (index = level), as
    :func:`voting_numpy.compute_edges` gives them. ``workspace`` defaults to the calling
    thread's (:func:`thread_workspace`)."""
    if workspace is None:
        workspace = thread_workspace()
    pyramid = build_pyramid_fast(gray, pyramid_levels(plan_bands(config)),
                                 gray_lookup(config.contrast, config.log_offset_gray),
                                 workspace)
    return [extract_edges_fast(image, level, config.gradient_threshold, config.thin_edges,
                               config.edge_support, workspace)
            for level, image in enumerate(pyramid)]


def _select(mask: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """The entries of each (N,) array where the (N,) bool ``mask`` is true (one index
    list, then a gather per array: faster than boolean indexing each)."""
    chosen = np.flatnonzero(mask)
    return [array.take(chosen) for array in arrays]


def _is_ridge(pixels: np.ndarray, pixel_gx: np.ndarray, pixel_gy: np.ndarray,
              centre: np.ndarray, magnitude: np.ndarray, width: int) -> np.ndarray:
    """For interior flat ``pixels`` (with their (N,) float32 gradients and magnitudes):
    is the magnitude a maximum along the quantised gradient direction (``m > m(p - d)``
    and ``m >= m(p + d)``), with ``magnitude`` the flat (H * W,) level?"""
    ax, ay = np.abs(pixel_gx), np.abs(pixel_gy)
    code = (ay <= _TAN_22 * ax).view(np.uint8) << 2            # horizontal
    code |= (ax <= _TAN_22 * ay).view(np.uint8) << 1            # vertical
    code |= (pixel_gx * pixel_gy > 0).view(np.uint8)            # same sign (diagonal)
    # flat step by code: 1 (horizontal, first), W (vertical), W + 1 or W - 1 (diagonal)
    step_table = np.array([width - 1, width + 1, width, width, 1, 1, 1, 1], np.intp)
    step = step_table.take(code)
    ridge = centre > magnitude.take(pixels - step)
    ridge &= centre >= magnitude.take(pixels + step)
    return ridge


def _support(pixels: np.ndarray, pixel_gx: np.ndarray, pixel_gy: np.ndarray,
             pixel_magnitude: np.ndarray, buffers: _LevelBuffers, width: int) -> np.ndarray:
    """Number of 8-neighbours of each of ``pixels`` (the ridge pixels, interior, sorted,
    with their (N,) float32 gradients and magnitudes) that are among them and whose
    gradient direction is within SUPPORT_ANGLE_DEG of its own; (N,) int32.

    The cosine ``u . v`` is computed as ``u_x v_x + u_y v_y`` in float32 from either side
    (the same bits, products and sums commute), so the left and right neighbours come from
    the sorted list's adjacent entries, and the other six from the workspace's unit
    vectors, one 8-byte (x, y) gather per offset."""
    count = np.zeros(pixels.shape, np.int32)
    own = np.empty((pixels.size, 2), np.float32)   # unit vectors, (x, y) per row
    with np.errstate(divide='ignore', invalid='ignore'):  # threshold 0: (0, 0) / 0
        np.divide(pixel_gx, pixel_magnitude, out=own[:, 0])
        np.divide(pixel_gy, pixel_magnitude, out=own[:, 1])
    product = np.empty_like(own)
    cosine = np.empty(pixels.size, np.float32)
    similar = np.empty(pixels.size, bool)
    # left and right: the next pixel in the sorted list, when it is the next in its row
    np.multiply(own[:-1], own[1:], out=product[:-1])
    np.add(product[:-1, 0], product[:-1, 1], out=cosine[:-1])
    np.greater_equal(cosine[:-1], _COS_SUPPORT, out=similar[:-1])
    similar[:-1] &= pixels[1:] == pixels[:-1] + 1
    count[:-1] += similar[:-1]
    count[1:] += similar[:-1]
    units = buffers.unit_pairs
    neighbour_units = np.empty_like(own)
    neighbours = np.empty_like(pixels)
    units[pixels] = own.view(np.int64).ravel()
    try:
        for offset in (-width - 1, -width, -width + 1, width - 1, width, width + 1):
            np.add(pixels, offset, out=neighbours)
            units.take(neighbours, out=neighbour_units.view(np.int64).ravel())
            # a non-edge neighbour has the unit vector (0, 0): its cosine 0 never counts
            np.multiply(own, neighbour_units, out=product)
            np.add(product[:, 0], product[:, 1], out=cosine)
            count += np.greater_equal(cosine, _COS_SUPPORT, out=similar)
    finally:   # the buffer is zero between calls
        units[pixels] = 0
    return count
