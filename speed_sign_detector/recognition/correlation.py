"""FFT correlation, kth-law nonlinearity and peak-to-sidelobe ratio (DAGM 2010, section 3).

Conventions: images are real float32 arrays placed at the top-left of an FFT array of
shape ``fft_shape = (Ny, Nx)``; spectra are the half spectra of :func:`numpy.fft.rfft2`,
shape ``(..., Ny, Nx // 2 + 1)`` complex64 (scene spectra are computed with
:func:`cv2.dft`: the same to float32 rounding). The correlation plane ``c[ty, tx]`` of a
scene with a filter is the filter's match with its top-left corner at scene pixel
``(ty, tx)`` (circular).

The classifier correlates through :func:`correlation_peaks`, which reads products in the
transposed layout ``(..., Nx // 2 + 1, Ny)`` (:func:`transposed_spectra`: the first pass
of the inverse FFT then runs along contiguous memory) and transforms only the plane rows
that the peak search reads; its peaks and PSRs are bitwise those of :func:`peak_psr` on
:func:`inverse_planes`' planes (the same one-dimensional transforms of the same numbers).
On the classifier's frames these steps took 27 % (inverse FFTs), 14 % (peaks) and 8 %
(scene DFTs) of its time, 2-core development machine, 2026-11-27.
"""
from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np


def kth_law(spectrum: np.ndarray, k: float, fast: bool = False,
            out: np.ndarray | None = None) -> np.ndarray:
    """Raise spectrum magnitudes to the power ``k``, keeping the phase.

    Args:
        spectrum: complex array of any shape.
        k: exponent in [0, 1] (1 = unchanged, 0 = phase only).
        fast: for k = 0.5, scale by 1 / sqrt in float64 (4 times faster than the float32
            power; equal to it but for ~0.06% of the values, 1 float32 ulp apart there).
            Filter synthesis keeps the power, so that built banks equal cached ones.
        out: complex64 array of the same shape (any memory layout, e.g. a transposed
            view) to write the result to; by default a new one.

    Returns:
        complex64 array of the same shape (zero where the input is zero): ``out`` when
        given.
    """
    spectrum = np.asarray(spectrum)
    if k == 1.0:
        if out is None:
            return spectrum.astype(np.complex64, copy=False)
        out[...] = spectrum
        return out
    magnitude = np.abs(spectrum).astype(np.float32, copy=False)
    if fast and k == 0.5:
        with np.errstate(divide='ignore'):
            # the float64 root without a float64 copy of the magnitudes first
            root = np.sqrt(magnitude, dtype=np.float64)
            scale = np.divide(1.0, root, out=root).astype(np.float32)
        scale[magnitude <= 1e-12] = 0.0
    else:
        scale = np.zeros_like(magnitude)
        np.power(magnitude, np.float32(k - 1.0), out=scale, where=magnitude > 1e-12)
    if out is None:
        return (spectrum * scale).astype(np.complex64, copy=False)
    return np.multiply(spectrum, scale, out=out)


def scene_spectrum(roi: np.ndarray, fft_shape: tuple[int, int], k: float) -> np.ndarray:
    """kth-law half spectrum of a zero-mean ROI.

    Args:
        roi: (h, w) real array with h <= Ny and w <= Nx (placed top-left, zero padded).
        fft_shape: (Ny, Nx).
        k: kth-law exponent.

    Returns:
        (Ny, Nx // 2 + 1) complex64.
    """
    return kth_law(_half_spectrum(roi, fft_shape), k, fast=True)


def scene_spectra(rois: Sequence[np.ndarray], fft_shape: tuple[int, int], k: float,
                  transposed: bool = False) -> np.ndarray:
    """:func:`scene_spectrum` of several ROIs for one FFT size, stacked (the same values).

    Args:
        rois: S (h, w) real arrays with h <= Ny and w <= Nx.
        fft_shape: (Ny, Nx).
        k: kth-law exponent.
        transposed: return them in the layout of :func:`transposed_spectra` (written so
            by the kth law: no copy).

    Returns:
        (S, Ny, Nx // 2 + 1) complex64, or (S, Nx // 2 + 1, Ny) with ``transposed``.
    """
    spectra = np.stack([_half_spectrum(roi, fft_shape) for roi in rois])
    if not transposed:
        return kth_law(spectra, k, fast=True)
    out = np.empty((len(spectra), spectra.shape[2], spectra.shape[1]), np.complex64)
    kth_law(spectra, k, fast=True, out=np.swapaxes(out, -1, -2))
    return out


def _half_spectrum(roi: np.ndarray, fft_shape: tuple[int, int]) -> np.ndarray:
    """(Ny, Nx // 2 + 1) complex64 half spectrum of a zero-mean ROI (a view of the full
    one); see :func:`scene_spectrum`."""
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
    return full[:, :fft_shape[1] // 2 + 1].view(np.complex64)[..., 0]


def correlate(scene: np.ndarray, conj_filters: np.ndarray, fft_shape: tuple[int, int]
              ) -> np.ndarray:
    """Correlation planes of scene spectra with filters, in one batched inverse FFT.

    Args:
        scene: (..., Ny, Nx // 2 + 1) complex64 scene spectra (kth-law already applied):
            one scene (Ny, Nx // 2 + 1) for every filter, or a stack that broadcasts
            with ``conj_filters`` over the leading axes (e.g. (S, 1, ...) scenes with
            (F, ...) filters give (S, F) planes; (P, ...) with (P, ...) pairs them).
        conj_filters: (..., Ny, Nx // 2 + 1) complex64 CONJUGATED filter spectra
            (``np.conj(H)``, stored so at bank build time), e.g. (F, Ny, Nx // 2 + 1).
        fft_shape: (Ny, Nx).

    Returns:
        (..., Ny, Nx) float32 correlation planes, the leading axes broadcast from both
        inputs ((F, Ny, Nx) for one scene and F filters).
    """
    return inverse_planes(conj_filters * scene, fft_shape)


def inverse_planes(product: np.ndarray, fft_shape: tuple[int, int]) -> np.ndarray:
    """Correlation planes from the products of filter and scene spectra (what
    :func:`correlate` does after the product; ``product`` is overwritten).

    Args:
        product: (..., Ny, Nx // 2 + 1) complex64 products ``conj(H) * S``.
        fft_shape: (Ny, Nx).

    Returns:
        (..., Ny, Nx) float32 planes.
    """
    # irfft2 by its two passes, the first in place (saves a complex array per call)
    np.fft.ifft(product, axis=-2, out=product)
    return np.fft.irfft(product, n=fft_shape[1], axis=-1).astype(np.float32, copy=False)


def transposed_spectra(spectra: np.ndarray) -> np.ndarray:
    """Half spectra in the layout of :func:`correlation_peaks`: frequency columns first.

    Args:
        spectra: (..., Ny, Nx // 2 + 1) complex half spectra (:func:`numpy.fft.rfft2`
            layout).

    Returns:
        (..., Nx // 2 + 1, Ny) C-contiguous complex64 copy (the same values).
    """
    return np.ascontiguousarray(np.swapaxes(np.asarray(spectra, np.complex64), -1, -2))


@dataclass(frozen=True)
class PeakStats:
    """Peaks of a stack of correlation planes.

    Attributes:
        value: (F,) peak heights.
        y, x: (F,) peak positions: plane indices in ``[0, Ny)`` and ``[0, Nx)``, circular
            (a peak ``k`` pixels before index 0 reads ``N - k``; callers that expect a
            shift of either sign unwrap it).
        psr: (F,) peak-to-sidelobe ratios.
    """

    value: np.ndarray
    y: np.ndarray
    x: np.ndarray
    psr: np.ndarray


@dataclass(frozen=True)
class _PeakBlocks:
    """Where :func:`peak_psr` reads each plane: the rows and columns of the square block
    ``centre +/- (search_widest + sidelobe_half)`` (circular), which holds every sidelobe
    square a peak in the search square can have.

    Attributes:
        rows, cols: (B,) plane rows / columns shared by every plane, or (F, B) per plane.
        searches: (1,) or (F,) peak search half sizes.
        search_widest: the largest of them.
        flat: (B * B,) flat plane indices of the block, row by row, for one shared
            centre (cached); ``None`` for per-plane centres.
    """

    rows: np.ndarray
    cols: np.ndarray
    searches: np.ndarray
    search_widest: int
    flat: np.ndarray | None


def _peak_blocks(count: int, shape: tuple[int, int], centre_yx: tuple[int, int] | np.ndarray,
                 search_half: int | np.ndarray, sidelobe_half: int, exclude_half: int
                 ) -> _PeakBlocks:
    """The :class:`_PeakBlocks` of ``count`` planes of ``shape`` (Ny, Nx); the arguments
    as :func:`peak_psr` takes them."""
    if exclude_half >= sidelobe_half:
        raise ValueError('exclude_half must be smaller than sidelobe_half')
    ny, nx = shape
    centres = np.asarray(centre_yx).reshape(-1, 2)
    searches = np.asarray(search_half).reshape(-1)
    if len(centres) > 1 and (centres == centres[0]).all():
        centres = centres[:1]
    if len(searches) > 1 and (searches == searches[0]).all():
        searches = searches[:1]
    search_widest = int(searches.max())
    if len(centres) == 1:
        layout = _psr_layout((int(centres[0, 0]), int(centres[0, 1])), (ny, nx),
                             search_widest, sidelobe_half)
        return _PeakBlocks(layout.block_rows, layout.block_cols, searches, search_widest,
                           layout.block_indices)
    # per-plane centres: each plane's block around its own centre
    offsets = np.arange(-(search_widest + sidelobe_half), search_widest + sidelobe_half + 1)
    centres = np.broadcast_to(centres, (count, 2))
    return _PeakBlocks((centres[:, :1] + offsets) % ny, (centres[:, 1:] + offsets) % nx,
                       searches, search_widest, None)


def peak_psr(planes: np.ndarray, centre_yx: tuple[int, int] | np.ndarray,
             search_half: int | np.ndarray, sidelobe_half: int, exclude_half: int
             ) -> PeakStats:
    """Find each plane's peak near a point and its peak-to-sidelobe ratio.

    The peak is the maximum inside the square ``centre +/- search_half`` (circular
    indices; the first one row by row on a tie). PSR = (peak - mean) / std over the square
    ``peak +/- sidelobe_half`` without the central square ``peak +/- exclude_half``.

    Args:
        planes: (F, Ny, Nx) float32 correlation planes.
        centre_yx: where the peak is expected: (y, x) for every plane, or (F, 2) integer
            (y, x) rows, one per plane.
        search_half: peak search half size in pixels, for every plane or (F,) integers.
        sidelobe_half, exclude_half: half sizes in pixels (``exclude_half <
            sidelobe_half``).

    Returns:
        :class:`PeakStats` with arrays of shape (F,).
    """
    count, ny, nx = planes.shape
    blocks = _peak_blocks(count, (ny, nx), centre_yx, search_half, sidelobe_half,
                          exclude_half)
    side = blocks.rows.shape[-1]
    if blocks.flat is not None:
        # copy the block once, then read each plane's square from a strided view of it
        block = planes.reshape(count, -1).take(blocks.flat, axis=1)
    else:
        flat = (blocks.rows[:, :, None] * nx + blocks.cols[:, None, :]).reshape(count, -1)
        block = np.take_along_axis(planes.reshape(count, -1), flat, axis=1)
    return _block_peaks(block.reshape(count, side, side), blocks, sidelobe_half,
                        exclude_half)


def correlation_peaks(product: np.ndarray, fft_shape: tuple[int, int],
                      centre_yx: tuple[int, int] | np.ndarray, search_half: int | np.ndarray,
                      sidelobe_half: int, exclude_half: int) -> PeakStats:
    """:func:`peak_psr` of the correlation planes of spectrum products, without forming
    the planes: the same numbers, for the work of the rows the peak search reads.

    The inverse FFT runs its first pass (over the rows' frequencies) on every column
    frequency, then the second (real) pass only on the rows of each plane's block; the
    values are those :func:`inverse_planes` gives there (the same one-dimensional
    transforms of the same numbers).

    Args:
        product: (F, Nx // 2 + 1, Ny) complex64 products ``conj(H) * S`` in the layout of
            :func:`transposed_spectra` (overwritten).
        fft_shape: (Ny, Nx).
        centre_yx, search_half, sidelobe_half, exclude_half: as :func:`peak_psr`.

    Returns:
        :class:`PeakStats` with arrays of shape (F,).
    """
    count = product.shape[0]
    blocks = _peak_blocks(count, fft_shape, centre_yx, search_half, sidelobe_half,
                          exclude_half)
    np.fft.ifft(product, axis=-1, out=product)
    rows, cols = blocks.rows, blocks.cols
    if rows.ndim == 1:
        lines = product.transpose(0, 2, 1)[:, rows]
    else:
        lines = product[np.arange(count)[:, None], :, rows]
    # (F, B, Nx) float32 rows of the planes, then their block's columns
    planes = np.fft.irfft(lines, n=fft_shape[1], axis=-1)
    return _block_peaks(_circular_columns(planes, cols), blocks, sidelobe_half, exclude_half)


def _circular_columns(planes: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``planes[p, i, cols[p, j]]`` for columns that run on circularly from their first,
    ``cols[p, j] = (cols[p, 0] + j) % Nx``, as at most two slices per distinct first column
    (a fancy index reads element by element).

    Args:
        planes: (F, B, Nx) array.
        cols: (C,) columns of every plane, or (F, C) per plane.

    Returns:
        (F, B, C) C-contiguous array.
    """
    count, height, width = planes.shape
    side = cols.shape[-1]
    if side > width:  # the block is wider than the plane: columns repeat
        if cols.ndim == 1:
            return planes.take(cols, axis=2)
        return planes[np.arange(count)[:, None, None], np.arange(height)[None, :, None],
                      cols[:, None, :]]
    out = np.empty((count, height, side), planes.dtype)
    firsts = cols[..., 0]
    for first in (np.unique(firsts) if cols.ndim > 1 else (int(firsts),)):
        first = int(first)
        head = min(side, width - first)
        if cols.ndim == 1:
            out[:, :, :head] = planes[:, :, first:first + head]
            out[:, :, head:] = planes[:, :, :side - head]
        else:
            chosen = np.flatnonzero(firsts == first)
            out[chosen, :, :head] = planes[chosen, :, first:first + head]
            out[chosen, :, head:] = planes[chosen, :, :side - head]
    return out


def _block_peaks(block: np.ndarray, blocks: _PeakBlocks, sidelobe_half: int,
                 exclude_half: int) -> PeakStats:
    """The peaks and PSRs of :func:`peak_psr` from each plane's block, (F, B, B) float32
    (the plane's values at ``blocks.rows`` x ``blocks.cols``)."""
    count = block.shape[0]
    searches, search_widest = blocks.searches, blocks.search_widest
    search_side = 2 * search_widest + 1
    window = block[:, sidelobe_half:sidelobe_half + search_side,
                   sidelobe_half:sidelobe_half + search_side].reshape(count, -1)
    if len(searches) > 1:
        # a plane's narrower search square: the rest of the widest one cannot win (row by
        # row order within the narrower square is kept, so ties resolve alike)
        outside = np.abs(np.arange(search_side) - search_widest)[None, :] > searches[:, None]
        window = window.reshape(count, search_side, search_side)  # a copy already
        window[outside[:, :, None] | outside[:, None, :]] = -np.inf
        window = window.reshape(count, -1)
    best = window.argmax(axis=1)
    peak_value = window[np.arange(count), best]  # the maximum (read, not sought again)
    best_y, best_x = np.divmod(best, search_side)
    lobe_side = 2 * sidelobe_half + 1
    squares = np.ndarray((count, search_side, search_side, lobe_side, lobe_side), block.dtype,
                         block, 0, block.strides + block.strides[1:])
    region = squares[np.arange(count), best_y, best_x].reshape(count, -1).astype(np.float64)
    weights, sidelobe_count = _sidelobe_weights(sidelobe_half, exclude_half)
    # mean and standard deviation from the sums in one pass, in float64 (numpy's std
    # takes two; the PSR agrees to float32 rounding); the weights drop the centre
    mean = region @ weights / sidelobe_count
    np.square(region, out=region)
    variance = region @ weights / sidelobe_count - mean * mean
    std = np.sqrt(np.maximum(variance, 0.0))
    psr = (peak_value - mean) / np.maximum(std, np.float32(1e-12))
    rows, cols = blocks.rows, blocks.cols
    if rows.ndim == 1:
        peak_y, peak_x = rows[sidelobe_half + best_y], cols[sidelobe_half + best_x]
    else:
        every = np.arange(count)
        peak_y = rows[every, sidelobe_half + best_y]
        peak_x = cols[every, sidelobe_half + best_x]
    return PeakStats(peak_value, peak_y, peak_x, psr.astype(np.float32))


@functools.lru_cache(maxsize=64)
def _sidelobe_weights(sidelobe_half: int, exclude_half: int) -> tuple[np.ndarray, float]:
    """((2 * sidelobe_half + 1) ** 2,) float64 weights, row by row: 1, and 0 in the
    excluded central square; and their sum (read-only, cached)."""
    weights = np.ones((2 * sidelobe_half + 1, 2 * sidelobe_half + 1))
    inner = slice(sidelobe_half - exclude_half, sidelobe_half + exclude_half + 1)
    weights[inner, inner] = 0.0
    weights = weights.reshape(-1)
    weights.flags.writeable = False
    return weights, float(weights.sum())


@dataclass(frozen=True)
class _PsrLayout:
    """Index arrays of :func:`peak_psr` for one plane shape, centre and set of half sizes
    (read-only, cached by :func:`_psr_layout`).

    Attributes:
        block_side: side of the block that holds every sidelobe square,
            ``2 * (search_half + sidelobe_half) + 1``.
        block_indices: (block_side ** 2,) flat plane indices of the block, row by row
            (circular).
        block_rows, block_cols: (block_side,) plane rows / columns of the block.
    """

    block_side: int
    block_indices: np.ndarray
    block_rows: np.ndarray
    block_cols: np.ndarray


@functools.lru_cache(maxsize=256)  # ~65 layouts (~3 MB) on GTSRB crops and frames
def _psr_layout(centre_yx: tuple[int, int], shape: tuple[int, int], search_half: int,
                sidelobe_half: int) -> _PsrLayout:
    """The :class:`_PsrLayout` of planes of ``shape`` (Ny, Nx) around ``centre_yx``."""
    reach = search_half + sidelobe_half
    rows = (centre_yx[0] + np.arange(-reach, reach + 1)) % shape[0]
    cols = (centre_yx[1] + np.arange(-reach, reach + 1)) % shape[1]
    layout = _PsrLayout(2 * reach + 1, (rows[:, None] * shape[1] + cols[None, :]).reshape(-1),
                        rows, cols)
    for array in (layout.block_indices, layout.block_rows, layout.block_cols):
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
