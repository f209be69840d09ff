"""Frame validation, image pyramid and 3x3 Sobel edge extraction (IVS 2011, III-A).

This is the numpy reference of the preprocessing; ``voting_gl`` runs the same maths in
compute shaders. Conventions shared by both backends:

- Pixel ``(row i, column j)`` has its centre at ``(x, y) = (j, i)``.
- Pyramid level ``k + 1`` is the 2x2 box average of level ``k`` cropped to even size
  (``floor(w / 2) x floor(h / 2)``), kept in float32 (no rounding), so both backends
  see identical gray values. A level-``k`` pixel ``(x, y)`` covers full-resolution
  pixels ``2^k x .. 2^k x + 2^k - 1``; its centre is at ``2^k x + (2^k - 1) / 2``.
- Gradients are the 3x3 Sobel (``gx = [[-1,0,1],[-2,0,2],[-1,0,1]]``), evaluated on
  interior pixels only (the one-pixel border never holds an edge). ``(gx, gy)`` points
  from dark to bright.
- An edge pixel has magnitude ``>= threshold`` and, with non-maximum suppression, is a
  local maximum of the magnitude along its gradient direction (quantised to 0, 45, 90,
  135 degrees): ``m > m(p - d)`` and ``m >= m(p + d)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.errors import InvalidFrameError


@dataclass(frozen=True)
class EdgeList:
    """Edge pixels of one pyramid level.

    Attributes:
        x_px, y_px: (E,) float32 pixel coordinates at this level.
        gx, gy: (E,) float32 Sobel gradient components (dark -> bright).
        level: pyramid level (0 = full resolution).
        width_px, height_px: size of this level, in its own pixels.
    """

    x_px: np.ndarray
    y_px: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    level: int
    width_px: int
    height_px: int

    @property
    def count(self) -> int:
        """Number of edge pixels."""
        return int(self.x_px.shape[0])


def validate_frame(gray: np.ndarray, min_size_px: int) -> np.ndarray:
    """Check a grayscale frame and return it as a C-contiguous (H, W) uint8 array.

    Float input is accepted when it holds finite gray levels in [0, 255] (rounded).

    Raises:
        InvalidFrameError: not an ndarray, empty, not 2-D, unsupported dtype, NaN or
            infinite values, values out of range, or smaller than ``min_size_px`` on a side.
    """
    if not isinstance(gray, np.ndarray):
        raise InvalidFrameError(f'frame must be a numpy array, got {type(gray).__name__}')
    if gray.ndim != 2:
        raise InvalidFrameError(f'frame must be 2-D grayscale (H, W), got shape {gray.shape}')
    if gray.size == 0:
        raise InvalidFrameError(f'frame is empty (shape {gray.shape})')
    if gray.dtype == np.uint8:
        frame = gray
    elif np.issubdtype(gray.dtype, np.floating):
        if not np.all(np.isfinite(gray)):
            raise InvalidFrameError('frame holds NaN or infinite values')
        if gray.min() < 0.0 or gray.max() > 255.0:
            raise InvalidFrameError(f'float frame values must lie in [0, 255], got '
                                    f'[{gray.min()}, {gray.max()}]')
        frame = np.rint(gray).astype(np.uint8)
    else:
        raise InvalidFrameError(f'frame dtype must be uint8 (or float gray levels), '
                                f'got {gray.dtype}')
    height, width = frame.shape
    if height < min_size_px or width < min_size_px:
        raise InvalidFrameError(f'frame {width}x{height} is smaller than the voting window '
                                f'({min_size_px} px on each side)')
    return np.ascontiguousarray(frame)


def gray_lookup(contrast: str, log_offset_gray: float) -> np.ndarray:
    """(256,) float32 table: gray level -> value the gradients are taken on.

    ``'linear'``: the gray level itself. ``'log'``: ``255 ln((I + c) / c) / ln((255 + c) / c)``
    (same 0..255 range; a step between two gray levels then depends on their ratio).
    """
    levels = np.arange(256, dtype=np.float64)
    if contrast == 'linear':
        return levels.astype(np.float32)
    offset = float(log_offset_gray)
    return (255.0 * np.log((levels + offset) / offset)
            / math.log((255.0 + offset) / offset)).astype(np.float32)


def build_pyramid(gray: np.ndarray, levels: int, lookup: np.ndarray) -> list[np.ndarray]:
    """Float32 box-filter pyramid: ``levels`` images, level 0 = ``lookup[gray]``."""
    pyramid = [lookup[gray]]
    for _ in range(1, levels):
        previous = pyramid[-1]
        height, width = previous.shape[0] // 2, previous.shape[1] // 2
        cropped = previous[:2 * height, :2 * width]
        pyramid.append(np.float32(0.25) * (
            (cropped[0::2, 0::2] + cropped[0::2, 1::2])
            + (cropped[1::2, 0::2] + cropped[1::2, 1::2])))
    return pyramid


def sobel(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3x3 Sobel of a float32 (H, W) image; returns ``(gx, gy)``, zero on the border."""
    gx = np.zeros_like(image)
    gy = np.zeros_like(image)
    top, mid, bot = image[:-2], image[1:-1], image[2:]
    gx[1:-1, 1:-1] = ((top[:, 2:] - top[:, :-2]) + np.float32(2.0) * (mid[:, 2:] - mid[:, :-2])
                      + (bot[:, 2:] - bot[:, :-2]))
    left, centre, right = image[:, :-2], image[:, 1:-1], image[:, 2:]
    gy[1:-1, 1:-1] = ((left[2:] - left[:-2]) + np.float32(2.0) * (centre[2:] - centre[:-2])
                      + (right[2:] - right[:-2]))
    return gx, gy


def extract_edges(image: np.ndarray, level: int, threshold: float,
                  thin: bool, min_support: int = 0) -> EdgeList:
    """Edge pixels of one pyramid level (float32 (H, W) gray image).

    Args:
        image: the level's gray values.
        level: its pyramid level (recorded in the result).
        threshold: minimum Sobel magnitude.
        thin: apply non-maximum suppression along the gradient.
        min_support: keep an edge pixel only when at least this many of its 8 neighbours
            are edge pixels whose gradient direction is within SUPPORT_ANGLE_DEG of its
            own (a smooth contour such as a sign's ring, not isolated texture).
    """
    gx, gy = sobel(image)
    magnitude = np.sqrt(gx * gx + gy * gy)
    keep = magnitude >= np.float32(threshold)
    keep[0, :] = keep[-1, :] = False
    keep[:, 0] = keep[:, -1] = False
    if thin:
        keep &= _is_ridge(magnitude, gx, gy)
    if min_support > 0:
        keep &= _support(keep, gx, gy, magnitude) >= min_support
    rows, cols = np.nonzero(keep)
    return EdgeList(cols.astype(np.float32), rows.astype(np.float32),
                    gx[rows, cols], gy[rows, cols], level, image.shape[1], image.shape[0])


SUPPORT_ANGLE_DEG = 30.0
"""Largest direction difference of two neighbouring edge pixels that support each other."""


def _support(keep: np.ndarray, gx: np.ndarray, gy: np.ndarray,
             magnitude: np.ndarray) -> np.ndarray:
    """Number of 8-neighbours of each pixel that are edges with a similar direction."""
    height, width = keep.shape
    with np.errstate(divide='ignore', invalid='ignore'):
        unit_x = np.where(keep, gx / magnitude, 0.0).astype(np.float32)
        unit_y = np.where(keep, gy / magnitude, 0.0).astype(np.float32)
    pad_keep = np.pad(keep, 1)
    pad_x, pad_y = np.pad(unit_x, 1), np.pad(unit_y, 1)
    cosine = np.float32(math.cos(math.radians(SUPPORT_ANGLE_DEG)))
    count = np.zeros(keep.shape, np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx == 0 and dy == 0:
                continue
            window = (slice(1 + dy, 1 + dy + height), slice(1 + dx, 1 + dx + width))
            similar = (unit_x * pad_x[window] + unit_y * pad_y[window]) >= cosine
            count += pad_keep[window] & similar
    return count


def _is_ridge(magnitude: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """True where the magnitude is a maximum along the quantised gradient direction."""
    padded = np.pad(magnitude, 1)
    height, width = magnitude.shape
    # direction index: 0 = horizontal (dx=1,dy=0), 1 = 45 deg (1,1), 2 = vertical, 3 = (-1,1)
    ax, ay = np.abs(gx), np.abs(gy)
    tan_22 = np.float32(0.41421357)
    horizontal = ay <= tan_22 * ax
    vertical = ax <= tan_22 * ay
    same_sign = (gx * gy) > 0
    ridge = np.zeros(magnitude.shape, dtype=bool)
    for mask, (dx, dy) in ((horizontal, (1, 0)), (vertical & ~horizontal, (0, 1)),
                           (~horizontal & ~vertical & same_sign, (1, 1)),
                           (~horizontal & ~vertical & ~same_sign, (-1, 1))):
        ahead = padded[1 + dy:1 + dy + height, 1 + dx:1 + dx + width]
        behind = padded[1 - dy:1 - dy + height, 1 - dx:1 - dx + width]
        ridge |= mask & (magnitude > behind) & (magnitude >= ahead)
    return ridge
