"""Features of a located sign for the second opinion: gradient orientations and pixels.

The correlation filters measure the sign's centre and radius; the sign is resampled
from the frame to a canonical patch (:func:`aligned_patches`) and described by
(:func:`sign_features`):

- histograms of gradient orientation (unsigned, 9 bins, 4x4-pixel cells, blocks of 2x2
  cells normalised with L2-Hys, as in Dalal & Triggs' HOG) of the sign's inner field,
  where the digits are;
- the inner field's pixels at 16x16, normalised to zero mean and unit variance.

Both are cheap (about 0.1 ms per sign) and numpy only.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ['FEATURE_SIZE', 'PATCH_PX', 'aligned_patches', 'sign_features']

#: Side of the canonical patch, pixels; it spans the sign's diameter (radius 24 px).
PATCH_PX = 48
#: The inner field described: the central INNER_PX x INNER_PX of the patch (+-2/3 radius).
INNER_PX = 32
#: Orientation histogram: cell side (pixels) and bins over 180 degrees.
CELL_PX = 4
ORIENTATION_BINS = 9
#: Side of the normalised pixel block, pixels.
PIXELS_PX = 16
_CELLS = INNER_PX // CELL_PX
#: Length of one feature vector.
FEATURE_SIZE = (_CELLS - 1) ** 2 * 4 * ORIENTATION_BINS + PIXELS_PX ** 2


def aligned_patches(gray: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """Resample each sign to a canonical (PATCH_PX, PATCH_PX) patch.

    Args:
        gray: (H, W) uint8 image.
        signs: (N, 3) float rows of (x, y, radius) in image pixels (pixel centres at +0.5,
            as :class:`~speed_sign_detector.recognition.classifier.CorrelationEvidence`).

    Returns:
        (N, PATCH_PX, PATCH_PX) float32 patches; the sign's disc fills the patch (its
        radius becomes PATCH_PX / 2). Outside the image the border is replicated.
    """
    signs = np.asarray(signs, dtype=np.float64).reshape(-1, 3)
    patches = np.empty((len(signs), PATCH_PX, PATCH_PX), np.float32)
    half = PATCH_PX / 2.0
    height, width = gray.shape
    for index, (x_px, y_px, radius_px) in enumerate(signs):
        scale = half / max(float(radius_px), 1e-3)
        # a window of the image just around the sign (smoothed there only, when reduced)
        reach = int(math.ceil(float(radius_px) * 1.1)) + 3
        left = min(max(int(math.floor(x_px)) - reach, 0), max(width - 1, 0))
        top = min(max(int(math.floor(y_px)) - reach, 0), max(height - 1, 0))
        window = gray[top:min(top + 2 * reach + 1, height), left:min(left + 2 * reach + 1, width)]
        if scale < 1.0:  # reduce: smooth first so the resampling does not alias
            window = cv2.GaussianBlur(window, (0, 0), 0.5 / scale)
        # pixel centre convention: image point (x, y) maps to patch point (half, half)
        matrix = np.float32([[scale, 0.0, half - 0.5 - (x_px - left - 0.5) * scale],
                             [0.0, scale, half - 0.5 - (y_px - top - 0.5) * scale]])
        patches[index] = cv2.warpAffine(window, matrix, (PATCH_PX, PATCH_PX),
                                        flags=cv2.INTER_LINEAR,
                                        borderMode=cv2.BORDER_REPLICATE)
    return patches


def _orientation_histograms(images: np.ndarray) -> np.ndarray:
    """HOG-style block-normalised orientation histograms.

    Args:
        images: (N, INNER_PX, INNER_PX) float32.

    Returns:
        (N, (cells-1)^2 * 4 * bins) float32.
    """
    count = len(images)
    gx = np.empty_like(images)
    gy = np.empty_like(images)
    for index, image in enumerate(images):
        gx[index] = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
        gy[index] = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    magnitude = np.sqrt(gx * gx + gy * gy)
    position = np.mod(np.arctan2(gy, gx), np.pi) * (ORIENTATION_BINS / np.pi)
    low = np.floor(position)
    upper_share = (position - low).astype(np.float32)
    low = low.astype(np.int64) % ORIENTATION_BINS
    high = (low + 1) % ORIENTATION_BINS
    # cell index of every pixel, then one bincount for all images, cells and bins
    cell_row = np.arange(INNER_PX) // CELL_PX
    cell_of_pixel = (cell_row[:, None] * _CELLS + cell_row[None, :])[None]  # (1, h, w)
    base = (np.arange(count)[:, None, None] * _CELLS * _CELLS + cell_of_pixel) \
        * ORIENTATION_BINS
    length = count * _CELLS * _CELLS * ORIENTATION_BINS
    cells = (np.bincount((base + low).ravel(), (magnitude * (1.0 - upper_share)).ravel(),
                         length)
             + np.bincount((base + high).ravel(), (magnitude * upper_share).ravel(), length))
    cells = cells.reshape(count, _CELLS, _CELLS, ORIENTATION_BINS).astype(np.float32)
    blocks = np.concatenate([cells[:, :-1, :-1], cells[:, 1:, :-1], cells[:, :-1, 1:],
                             cells[:, 1:, 1:]], axis=-1)
    # L2-Hys: normalise, clip at 0.2, normalise again
    blocks = np.minimum(blocks / np.sqrt((blocks * blocks).sum(-1, keepdims=True) + 1e-3), 0.2)
    blocks = blocks / np.sqrt((blocks * blocks).sum(-1, keepdims=True) + 1e-3)
    return blocks.reshape(count, -1)


def sign_features(patches: np.ndarray) -> np.ndarray:
    """Feature vectors of canonical patches.

    Args:
        patches: (N, PATCH_PX, PATCH_PX) patches from :func:`aligned_patches`.

    Returns:
        (N, FEATURE_SIZE) float32: orientation histograms, then normalised pixels.
    """
    patches = np.asarray(patches, dtype=np.float32)
    if patches.ndim != 3 or patches.shape[1:] != (PATCH_PX, PATCH_PX):
        raise ValueError(f'patches must have shape (N, {PATCH_PX}, {PATCH_PX}), '
                         f'got {patches.shape}')
    border = (PATCH_PX - INNER_PX) // 2
    inner = np.ascontiguousarray(patches[:, border:border + INNER_PX,
                                         border:border + INNER_PX])
    pixels = np.stack([cv2.resize(image, (PIXELS_PX, PIXELS_PX), interpolation=cv2.INTER_AREA)
                       for image in inner]).reshape(len(inner), -1) if len(inner) else \
        np.zeros((0, PIXELS_PX * PIXELS_PX), np.float32)
    pixels = pixels - pixels.mean(axis=1, keepdims=True)
    pixels /= pixels.std(axis=1, keepdims=True) + 1e-3
    return np.hstack([_orientation_histograms(inner), pixels]).astype(np.float32)
