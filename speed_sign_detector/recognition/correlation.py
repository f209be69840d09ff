"""FFT correlation, kth-law nonlinearity and peak-to-sidelobe ratio (DAGM 2010, section 3).

Conventions: images are real float32 arrays placed at the top-left of an FFT array of
shape ``fft_shape = (Ny, Nx)``; spectra are the half spectra of :func:`numpy.fft.rfft2`,
shape ``(..., Ny, Nx // 2 + 1)`` complex64 (scene spectra come from :func:`cv2.dft`, the
same to float32 rounding). The correlation plane ``c[ty, tx]`` of a
scene with a filter is the filter's match with its top-left corner at scene pixel
``(ty, tx)`` (circular).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np


def kth_law(spectrum: np.ndarray, k: float) -> np.ndarray:
    """Raise spectrum magnitudes to the power ``k``, keeping the phase.

    Args:
        spectrum: complex array of any shape.
        k: exponent in [0, 1] (1 = unchanged, 0 = phase only).

    Returns:
        complex64 array of the same shape (zero where the input is zero).
    """
    spectrum = np.asarray(spectrum)
    if k == 1.0:
        return spectrum.astype(np.complex64, copy=False)
    magnitude = np.abs(spectrum).astype(np.float32, copy=False)
    with np.errstate(divide='ignore'):
        # 1 / sqrt is about 5 times faster than power(-0.5) and agrees to float32 rounding
        scale = (np.reciprocal(np.sqrt(magnitude)) if k == 0.5
                 else np.power(magnitude, np.float32(k - 1.0)))
    scale[magnitude <= 1e-12] = 0.0
    return (spectrum * scale).astype(np.complex64, copy=False)


def scene_spectrum(roi: np.ndarray, fft_shape: tuple[int, int], k: float) -> np.ndarray:
    """kth-law half spectrum of a zero-mean ROI.

    Args:
        roi: (h, w) real array with h <= Ny and w <= Nx (placed top-left, zero padded).
        fft_shape: (Ny, Nx).
        k: kth-law exponent.

    Returns:
        (Ny, Nx // 2 + 1) complex64.
    """
    roi = np.asarray(roi, dtype=np.float32)
    centred = roi - np.float32(roi.mean())
    if centred.shape != tuple(fft_shape):
        padded = np.zeros(fft_shape, np.float32)
        padded[:centred.shape[0], :centred.shape[1]] = centred
        centred = padded
    # OpenCV's real FFT is 2 to 4 times faster than numpy's at these sizes; it returns
    # the full spectrum as (Ny, Nx, 2) float32 (real, imaginary) pairs
    full = cv2.dft(centred, flags=cv2.DFT_COMPLEX_OUTPUT)
    half = full[:, :fft_shape[1] // 2 + 1].view(np.complex64)[..., 0]
    return kth_law(half, k)


def correlate(scene: np.ndarray, conj_filters: np.ndarray, fft_shape: tuple[int, int]
              ) -> np.ndarray:
    """Correlation planes of one scene spectrum with a stack of filters.

    Args:
        scene: (Ny, Nx // 2 + 1) complex64 scene spectrum (kth-law already applied).
        conj_filters: (F, Ny, Nx // 2 + 1) complex64 CONJUGATED filter spectra
            (``np.conj(H)``, stored so at bank build time).
        fft_shape: (Ny, Nx).

    Returns:
        (F, Ny, Nx) float32 correlation planes (one inverse FFT call for the batch).
    """
    product = conj_filters * scene[None]
    return np.fft.irfft2(product, s=fft_shape).astype(np.float32, copy=False)


@dataclass(frozen=True)
class PeakStats:
    """Peaks of a stack of correlation planes.

    Attributes:
        value: (F,) peak heights.
        y, x: (F,) peak positions (plane indices).
        psr: (F,) peak-to-sidelobe ratios.
    """

    value: np.ndarray
    y: np.ndarray
    x: np.ndarray
    psr: np.ndarray


def peak_psr(planes: np.ndarray, centre_yx: tuple[int, int], search_half: int,
             sidelobe_half: int, exclude_half: int) -> PeakStats:
    """Find each plane's peak near a point and its peak-to-sidelobe ratio.

    The peak is the maximum inside the square ``centre +/- search_half`` (circular
    indices). PSR = (peak - mean) / std over the square ``peak +/- sidelobe_half``
    without the central square ``peak +/- exclude_half``.

    Args:
        planes: (F, Ny, Nx) float32 correlation planes.
        centre_yx: where the peak is expected.
        search_half, sidelobe_half, exclude_half: half sizes in pixels
            (``exclude_half < sidelobe_half``).

    Returns:
        :class:`PeakStats` with arrays of shape (F,).
    """
    count, ny, nx = planes.shape
    if exclude_half >= sidelobe_half:
        raise ValueError('exclude_half must be smaller than sidelobe_half')
    cy, cx = int(centre_yx[0]), int(centre_yx[1])
    # every sidelobe square lies in one block, centre +/- (search_half + sidelobe_half):
    # copy that block once (by cached flat indices), then read each plane's square from
    # a strided view of it, with no index arithmetic per call
    reach = search_half + sidelobe_half
    block_side = 2 * reach + 1
    block = planes.reshape(count, -1).take(_square_indices((cy, cx), reach, (ny, nx)),
                                           axis=1).reshape(count, block_side, block_side)
    search_side = 2 * search_half + 1
    window = block[:, sidelobe_half:sidelobe_half + search_side,
                   sidelobe_half:sidelobe_half + search_side].reshape(count, -1)
    best = np.argmax(window, axis=1)
    peak_value = window.max(axis=1)
    best_y, best_x = np.divmod(best, search_side)
    # each plane's sidelobe square, read from a strided view of the block's squares
    lobe_side = 2 * sidelobe_half + 1
    squares = np.lib.stride_tricks.as_strided(
        block, (count, search_side, search_side, lobe_side, lobe_side),
        block.strides + block.strides[1:], writeable=False)
    region = squares[np.arange(count), best_y, best_x].reshape(count, -1).astype(np.float64)
    # mean and standard deviation from the sums in one pass, in float64 (numpy's std
    # takes two; the PSR agrees to float32 rounding); the weights drop the centre
    weights = _sidelobe_weights(sidelobe_half, exclude_half)
    count_kept = weights.sum()
    mean = region @ weights / count_kept
    np.square(region, out=region)
    variance = region @ weights / count_kept - mean * mean
    std = np.sqrt(np.maximum(variance, 0.0))
    psr = (peak_value - mean) / np.maximum(std, np.float32(1e-12))
    peak_y = (cy - search_half + best_y) % ny
    peak_x = (cx - search_half + best_x) % nx
    return PeakStats(peak_value, peak_y, peak_x, psr.astype(np.float32))


@functools.lru_cache(maxsize=1024)
def _square_indices(centre_yx: tuple[int, int], reach: int, shape: tuple[int, int]
                    ) -> np.ndarray:
    """Flat indices into an (Ny, Nx) array of the square ``centre +/- reach`` (circular),
    row by row: ((2 * reach + 1) ** 2,), read-only, cached."""
    span = np.arange(-reach, reach + 1)
    rows = (centre_yx[0] + span) % shape[0]
    cols = (centre_yx[1] + span) % shape[1]
    indices = (rows[:, None] * shape[1] + cols[None, :]).reshape(-1)
    indices.flags.writeable = False
    return indices


@functools.lru_cache(maxsize=256)
def _sidelobe_weights(sidelobe_half: int, exclude_half: int) -> np.ndarray:
    """((2 * sidelobe_half + 1) ** 2,) float64 weights of a sidelobe square, row by row:
    1, and 0 inside the central (2 * exclude_half + 1) ** 2 square; read-only, cached."""
    weights = np.ones((2 * sidelobe_half + 1, 2 * sidelobe_half + 1))
    inner = slice(sidelobe_half - exclude_half, sidelobe_half + exclude_half + 1)
    weights[inner, inner] = 0.0
    weights = weights.reshape(-1)
    weights.flags.writeable = False
    return weights


def disc_window(shape: tuple[int, int], centre_yx: tuple[float, float],
                radius_px: float) -> np.ndarray:
    """A disc of ones with a one-pixel linear edge, zeros outside.

    Args:
        shape: (h, w) of the window.
        centre_yx: disc centre in pixel coordinates (pixel (i, j) has centre (i + 0.5,
            j + 0.5)).
        radius_px: disc radius in pixels.

    Returns:
        (h, w) float32 weights in [0, 1].
    """
    rows = np.arange(shape[0], dtype=np.float32)[:, None] + np.float32(0.5 - centre_yx[0])
    cols = np.arange(shape[1], dtype=np.float32)[None, :] + np.float32(0.5 - centre_yx[1])
    distance = np.sqrt(rows * rows + cols * cols)
    return np.clip(np.float32(radius_px + 0.5) - distance, 0.0, 1.0)


def keep_inside(image: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Replace what lies outside a window by the window's weighted mean.

    Args:
        image: (h, w) real image.
        window: (h, w) weights in [0, 1] (e.g. :func:`disc_window`).

    Returns:
        (h, w) float32: ``image`` inside, its mean there outside, blended at the edge.
    """
    image = np.asarray(image, dtype=np.float32)
    total = float(window.sum())
    mean = float((image * window).sum()) / total if total > 0 else float(image.mean())
    return image * window + np.float32(mean) * (1.0 - window)
