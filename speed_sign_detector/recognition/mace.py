"""kth-law nonlinear MACE composite filter synthesis (DAGM 2010, section 3).

A MACE (minimum average correlation energy) synthetic discriminant function filter
``h = D^-1 X (X^H D^-1 X)^-1 u`` gives correlation 1 at the origin for each of its
training images (columns of X, as spectra) while minimising the average energy of the
correlation planes (D: the diagonal average power spectrum). The kth-law variant first
raises every training spectrum's magnitude to the power k (phase kept); the scene
spectrum gets the same nonlinearity before correlation
(:func:`speed_sign_detector.recognition.correlation.scene_spectrum`).

A noise trade-off ``alpha`` (optimal trade-off SDF) replaces D with
``(1 - alpha) D + alpha mean(D)``: 0 is pure MACE, larger values tolerate blur and
noise better at the cost of peak sharpness.
"""
from __future__ import annotations

import numpy as np

from speed_sign_detector.recognition.correlation import kth_law

#: Images per FFT call in :func:`training_spectra`.
_FFT_CHUNK = 32


def training_spectra(images: np.ndarray, fft_shape: tuple[int, int], k: float) -> np.ndarray:
    """kth-law half spectra of zero-mean, unit-energy training images.

    Args:
        images: (N, h, w) real training images (h <= Ny, w <= Nx), placed top-left.
        fft_shape: (Ny, Nx) FFT size.
        k: kth-law exponent.

    Returns:
        (N, Ny, Nx // 2 + 1) complex64.
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim != 3 or images.shape[0] == 0:
        raise ValueError(f'images must have shape (N, h, w) with N >= 1, got {images.shape}')
    spectra = np.empty((images.shape[0], fft_shape[0], fft_shape[1] // 2 + 1), np.complex64)
    # in chunks: one FFT call over a large stack is about twice as slow (cache misses of
    # the column transforms); each image's spectrum is the same either way
    for start in range(0, images.shape[0], _FFT_CHUNK):
        chunk = images[start:start + _FFT_CHUNK]
        centred = chunk - chunk.mean(axis=(1, 2), keepdims=True)
        norms = np.sqrt((centred ** 2).sum(axis=(1, 2), keepdims=True))
        centred /= np.maximum(norms, np.float32(1e-6))
        spectra[start:start + _FFT_CHUNK] = kth_law(np.fft.rfft2(centred, s=fft_shape), k)
    return spectra


def mace_filter(spectra: np.ndarray, fft_shape: tuple[int, int], noise_tradeoff: float = 0.0,
                ridge: float = 1e-3) -> np.ndarray:
    """Synthesize one MACE filter from training spectra.

    Args:
        spectra: (N, Ny, Nx // 2 + 1) complex training spectra (kth-law applied).
        fft_shape: (Ny, Nx), the full FFT size the half spectra came from.
        noise_tradeoff: alpha in [0, 1] (see module docstring).
        ridge: relative Tikhonov regularisation of the N x N correlation matrix, for
            nearly identical training views.

    Returns:
        (Ny, Nx // 2 + 1) complex64 filter spectrum H; correlate as
        ``irfft2(S * conj(H))``. Each training image, placed like the filter, then
        correlates to 1 at the origin (up to the ridge).
    """
    spectra = np.asarray(spectra)
    if spectra.ndim != 3 or spectra.shape[0] == 0:
        raise ValueError(f'spectra must have shape (N, Ny, Nx // 2 + 1) with N >= 1, '
                         f'got {spectra.shape}')
    return mace_filters(spectra[None], fft_shape, noise_tradeoff, ridge)[0]


def mace_filters(spectra: np.ndarray, fft_shape: tuple[int, int], noise_tradeoff: float = 0.0,
                 ridge: float = 1e-3) -> np.ndarray:
    """Synthesize F MACE filters of N training spectra each at once (:func:`mace_filter`
    per filter, vectorized over filters and frequencies).

    Args:
        spectra: (F, N, Ny, Nx // 2 + 1) complex training spectra (kth-law applied).
        fft_shape: (Ny, Nx), the full FFT size the half spectra came from.
        noise_tradeoff: alpha in [0, 1] (see module docstring).
        ridge: relative Tikhonov regularisation of each N x N correlation matrix.

    Returns:
        (F, Ny, Nx // 2 + 1) complex64 filter spectra.
    """
    if not 0.0 <= noise_tradeoff <= 1.0:
        raise ValueError(f'noise_tradeoff must be in [0, 1], got {noise_tradeoff}')
    spectra = np.asarray(spectra)
    if spectra.ndim != 4 or spectra.shape[0] == 0 or spectra.shape[1] == 0:
        raise ValueError(f'spectra must have shape (F, N, Ny, Nx // 2 + 1) with F, N >= 1, '
                         f'got {spectra.shape}')
    filters, count = spectra.shape[:2]
    bins = spectra.shape[2] * spectra.shape[3]
    # interleaved real and imaginary parts: (F, N, 2 P) float32, no copy of complex64 input
    pairs = np.ascontiguousarray(spectra, dtype=np.complex64).reshape(
        filters, count, bins).view(np.float32)
    squares = pairs * pairs
    power = (squares[..., 0::2] + squares[..., 1::2]).mean(axis=1)  # (F, P)
    power = (1.0 - noise_tradeoff) * power + noise_tradeoff * power.mean(axis=1, keepdims=True)
    floor = np.float32(1e-12) * np.maximum(power.max(axis=1, keepdims=True), np.float32(1e-30))
    power = np.maximum(power, floor)
    # weights of the half spectrum: interior columns stand for two full-spectrum bins
    weights = np.full(spectra.shape[2:], 2.0, np.float32)
    weights[:, 0] = 1.0
    if fft_shape[1] % 2 == 0:
        weights[:, -1] = 1.0
    # X^H D^-1 X is real for real images: Re(conj(a) b) = ar br + ai bi, real float32
    # products of the weighted real and imaginary parts side by side (not a complex GEMM,
    # slow with threaded BLAS on busy cores)
    root = np.sqrt(weights.reshape(-1) / power)[:, None, :]  # (F, 1, P)
    scaled = np.concatenate([pairs[..., 0::2] * root, pairs[..., 1::2] * root], axis=2)
    # one 2-D product per filter: the same summation order as for a single filter (the
    # solve below amplifies rounding differences of the nearly singular Gram matrices)
    gram = np.stack([np.einsum('ik,jk->ij', one, one) for one in scaled]).astype(np.float64)
    trace = np.trace(gram, axis1=1, axis2=2)
    gram += np.eye(count) * (ridge * trace / count)[:, None, None]
    coefficients = np.linalg.solve(gram, np.ones((filters, count, 1))).astype(np.float32)
    # times Ny * Nx: the inverse FFT divides by it, so a training image peaks at 1
    combined = np.matmul(coefficients.transpose(0, 2, 1), pairs)[:, 0, :]  # (F, 2 P)
    combined *= np.repeat(np.float32(fft_shape[0] * fft_shape[1]) / power, 2, axis=1)
    return combined.view(np.complex64).reshape((filters,) + spectra.shape[2:])
