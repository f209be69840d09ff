"""FFT correlation, kth-law nonlinearity and peak-to-sidelobe ratio (DAGM 2010, section 3).

Conventions: images are real float32 arrays placed at the top-left of an FFT array of
shape ``fft_shape = (Ny, Nx)``; spectra are the half spectra of :func:`numpy.fft.rfft2`,
shape ``(..., Ny, Nx // 2 + 1)`` complex64 (scene spectra are computed with
:func:`cv2.dft`: the same to float32 rounding). The correlation plane ``c[ty, tx]`` of a
scene with a filter is the filter's match with its top-left corner at scene pixel
``(ty, tx)`` (circular).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np


def kth_law(spectrum: np.ndarray, k: float, fast: bool = False) -> np.ndarray:
    """Raise spectrum magnitudes to the power ``k``, keeping the phase.

    Args:
        spectrum: complex array of any shape.
        k: exponent in [0, 1] (1 = unchanged, 0 = phase only).
        fast: for k = 0.5, scale by 1 / sqrt in float64 (4 times faster than the float32
            power; equal to it but for ~0.06% of the values, 1 float32 ulp apart there).
            Filter synthesis keeps the power, so that built banks equal cached ones.

    Returns:
        complex64 array of the same shape (zero where the input is zero).
    """
    spectrum = np.asarray(spectrum)
    if k == 1.0:
        return spectrum.astype(np.complex64, copy=False)
    magnitude = np.abs(spectrum).astype(np.float32, copy=False)
    if fast and k == 0.5:
        with np.errstate(divide='ignore'):
            root = np.sqrt(magnitude.astype(np.float64))
            scale = np.divide(1.0, root, out=root).astype(np.float32)
        scale[magnitude <= 1e-12] = 0.0
    else:
        scale = np.zeros_like(magnitude)
        np.power(magnitude, np.float32(k - 1.0), out=scale, where=magnitude > 1e-12)
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
    # roi.mean() without its Python wrapper (the same float32 sum and division)
    centred = roi - np.float32(np.add.reduce(roi, axis=None) / roi.size)
    if centred.shape != tuple(fft_shape):
        padded = np.zeros(fft_shape, np.float32)
        padded[:centred.shape[0], :centred.shape[1]] = centred
        centred = padded
    # OpenCV's real FFT is 2 to 4 times faster than numpy's at these sizes; it returns
    # the full spectrum as (Ny, Nx, 2) float32 (real, imaginary) pairs
    full = cv2.dft(centred, flags=cv2.DFT_COMPLEX_OUTPUT)
    half = full[:, :fft_shape[1] // 2 + 1].view(np.complex64)[..., 0]
    return kth_law(half, k, fast=True)


def correlate(scene: np.ndarray, conj_filters: np.ndarray, fft_shape: tuple[int, int]
              ) -> np.ndarray:
    """Correlation planes of one scene spectrum with a stack of filters.

    Args:
        scene: (Ny, Nx // 2 + 1) complex64 scene spectrum (kth-law already applied).
        conj_filters: (F, Ny, Nx // 2 + 1) complex64 CONJUGATED filter spectra
            (``np.conj(H)``, stored so at bank build time).
        fft_shape: (Ny, Nx).

    Returns:
        (F, Ny, Nx) float32 correlation planes (one batched inverse FFT).
    """
    product = conj_filters * scene[None]
    # irfft2 by its two passes, the first in place (saves a complex array per call)
    np.fft.ifft(product, axis=-2, out=product)
    return np.fft.irfft(product, n=fft_shape[1], axis=-1).astype(np.float32, copy=False)


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
    layout = _psr_layout((int(centre_yx[0]), int(centre_yx[1])), (ny, nx), search_half,
                         sidelobe_half, exclude_half)
    # every sidelobe square lies in one block, centre +/- (search_half + sidelobe_half):
    # copy that block once, then read each plane's square from a strided view of it
    block_side = layout.block_side
    block = planes.reshape(count, -1).take(layout.block_indices, axis=1).reshape(
        count, block_side, block_side)
    search_side = 2 * search_half + 1
    window = block[:, sidelobe_half:sidelobe_half + search_side,
                   sidelobe_half:sidelobe_half + search_side].reshape(count, -1)
    best = window.argmax(axis=1)
    peak_value = window.max(axis=1)
    best_y, best_x = np.divmod(best, search_side)
    lobe_side = 2 * sidelobe_half + 1
    squares = np.ndarray((count, search_side, search_side, lobe_side, lobe_side), block.dtype,
                         block, 0, block.strides + block.strides[1:])
    region = squares[np.arange(count), best_y, best_x].reshape(count, -1).astype(np.float64)
    # mean and standard deviation from the sums in one pass, in float64 (numpy's std
    # takes two; the PSR agrees to float32 rounding); the weights drop the centre
    mean = region @ layout.sidelobe_weights / layout.sidelobe_count
    np.square(region, out=region)
    variance = region @ layout.sidelobe_weights / layout.sidelobe_count - mean * mean
    std = np.sqrt(np.maximum(variance, 0.0))
    psr = (peak_value - mean) / np.maximum(std, np.float32(1e-12))
    return PeakStats(peak_value, layout.search_rows[best_y], layout.search_cols[best_x],
                     psr.astype(np.float32))


@dataclass(frozen=True)
class _PsrLayout:
    """Index arrays and weights of :func:`peak_psr` for one plane shape, centre and set of
    half sizes (read-only, cached by :func:`_psr_layout`).

    Attributes:
        block_side: side of the block that holds every sidelobe square,
            ``2 * (search_half + sidelobe_half) + 1``.
        block_indices: (block_side ** 2,) flat plane indices of the block, row by row
            (circular).
        search_rows, search_cols: (2 * search_half + 1,) plane rows / columns of the peak
            search square.
        sidelobe_weights: ((2 * sidelobe_half + 1) ** 2,) float64, row by row: 1, and 0
            in the excluded central square.
        sidelobe_count: number of sidelobe pixels (the weights' sum).
    """

    block_side: int
    block_indices: np.ndarray
    search_rows: np.ndarray
    search_cols: np.ndarray
    sidelobe_weights: np.ndarray
    sidelobe_count: float


@functools.lru_cache(maxsize=256)  # ~65 layouts (~3 MB) on GTSRB crops and frames
def _psr_layout(centre_yx: tuple[int, int], shape: tuple[int, int], search_half: int,
                sidelobe_half: int, exclude_half: int) -> _PsrLayout:
    """The :class:`_PsrLayout` of planes of ``shape`` (Ny, Nx) around ``centre_yx``."""
    reach = search_half + sidelobe_half
    rows = (centre_yx[0] + np.arange(-reach, reach + 1)) % shape[0]
    cols = (centre_yx[1] + np.arange(-reach, reach + 1)) % shape[1]
    weights = np.ones((2 * sidelobe_half + 1, 2 * sidelobe_half + 1))
    inner = slice(sidelobe_half - exclude_half, sidelobe_half + exclude_half + 1)
    weights[inner, inner] = 0.0
    search = slice(sidelobe_half, sidelobe_half + 2 * search_half + 1)
    layout = _PsrLayout(2 * reach + 1, (rows[:, None] * shape[1] + cols[None, :]).reshape(-1),
                        rows[search], cols[search], weights.reshape(-1),
                        float(weights.sum()))
    for array in (layout.block_indices, layout.search_rows, layout.search_cols,
                  layout.sidelobe_weights):
        array.flags.writeable = False
    return layout


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
