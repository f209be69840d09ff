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
    centred = images - images.mean(axis=(1, 2), keepdims=True)
    norms = np.sqrt((centred ** 2).sum(axis=(1, 2), keepdims=True))
    centred /= np.maximum(norms, np.float32(1e-6))
    return kth_law(np.fft.rfft2(centred, s=fft_shape), k)


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
    if not 0.0 <= noise_tradeoff <= 1.0:
        raise ValueError(f'noise_tradeoff must be in [0, 1], got {noise_tradeoff}')
    count = spectra.shape[0]
    flat = spectra.reshape(count, -1).astype(np.complex64, copy=False)
    power = (flat.real ** 2 + flat.imag ** 2).mean(axis=0)
    power = (1.0 - noise_tradeoff) * power + noise_tradeoff * power.mean()
    power = np.maximum(power, np.float32(1e-12) * max(float(power.max()), 1e-30))
    # weights of the half spectrum: interior columns stand for two full-spectrum bins
    weights = np.full(spectra.shape[1:], 2.0, np.float32)
    weights[:, 0] = 1.0
    if fft_shape[1] % 2 == 0:
        weights[:, -1] = 1.0
    # X^H D^-1 X is real for real images: Re(conj(a) b) = ar br + ai bi. Real float32
    # products (not a complex GEMM, which is slow with threaded BLAS on busy cores).
    root = np.sqrt(weights.reshape(-1) / power).astype(np.float32)
    stacked = np.concatenate([flat.real * root, flat.imag * root], axis=1)
    gram = np.einsum('ik,jk->ij', stacked, stacked).astype(np.float64)
    gram += np.eye(count) * ridge * np.trace(gram) / count
    coefficients = np.linalg.solve(gram, np.ones(count)).astype(np.float32)
    # times Ny * Nx: the inverse FFT divides by it, so a training image peaks at 1
    filter_flat = (coefficients @ flat) * np.float32(fft_shape[0] * fft_shape[1]) / power
    return filter_flat.reshape(spectra.shape[1:]).astype(np.complex64)
