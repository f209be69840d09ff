"""Composite correlation filters trained from real crops, at the sign's canonical patch.

The rendered filters (:mod:`.filter_banks`) find the sign's size and centre and rank the
classes; their digits are drawn, not photographed. These filters are synthesized from
the training crops themselves: each located sign resampled to the canonical patch of
:mod:`.sign_features` (its disc fills 48x48 pixels), its inner field (where the digits
are, a disc of ``inner_radius_px``) normalised to zero mean and unit energy, and each
label's examples (the real crops, their degraded copies, and renderings of the values
with no real examples) combined into one optimal trade-off (OT-MACH) filter
(:mod:`speed_sign_detector.training.filter_fitting` builds them)::

    H(u, v) = M(u, v) / (D(u, v) + S(u, v) + noise * mean(D))

with M the examples' mean spectrum, D their average power spectrum and S their average
similarity (the power of each example's difference from the mean) -- Mahalanobis,
Vijaya Kumar et al., "Unconstrained correlation filters" (1994), and Refregier's
optimal trade-off. Averaging keeps the filter stable with thousands of examples, where
a MACE filter, which passes every training image exactly, would not be.

At run time the patch the second opinion reads is correlated with every label's filter
and the PSR of the peak near the centre scores the label (:meth:`RealFilters.psr`). The
score joins the rendered filters' PSR (:func:`fused_label_order`): the labels the second
opinion may choose among are the leaders of that sum, so the real filters decide which
classes the correlation ranks, and the second opinion still never adds a class they did
not rank.
"""
from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.recognition.classification import label_of_class
from speed_sign_detector.recognition.sign_features import PATCH_PX

__all__ = ['REAL_FILTER_FFT_PX', 'RealFilters', 'fused_label_order', 'patch_spectra']

#: Side of the correlation plane, pixels (the 48-pixel patch zero-padded).
REAL_FILTER_FFT_PX = 64
#: The correlation peak is sought within this many pixels of the centre (the patch is
#: already centred on the sign by the rendered filters).
PEAK_REACH_PX = 3

_SHIFTS = np.arange(-PEAK_REACH_PX, PEAK_REACH_PX + 1)
_FREQUENCIES = np.arange(REAL_FILTER_FFT_PX)
#: How often each rfft2 column stands in the full spectrum (the others are conjugates).
_COLUMN_COUNTS = np.r_[1.0, np.full(REAL_FILTER_FFT_PX // 2 - 1, 2.0), 1.0].astype(np.float32)
#: Inverse transform at the shifts near zero: rows (7, 64), columns (33, 7) weighted by
#: their counts (the real part of the sum is the plane's value).
_ROW_SHIFTS = np.exp(2j * np.pi * np.outer(_SHIFTS, _FREQUENCIES)
                     / REAL_FILTER_FFT_PX).astype(np.complex64)
_COLUMN_SHIFTS = (_COLUMN_COUNTS[:, None] * np.exp(
    2j * np.pi * np.outer(_FREQUENCIES[:REAL_FILTER_FFT_PX // 2 + 1], _SHIFTS)
    / REAL_FILTER_FFT_PX)).astype(np.complex64)


@dataclass(frozen=True)
class RealFilters:
    """One trained composite filter per label, and how its score joins the ranking.

    Attributes:
        labels: the labels (``'30'``, ``'end_of_limit'``, ``'other_sign'``, ...), (L,).
        spectra: (L, 64, 33) complex64 conjugated filter spectra (``rfft2`` layout).
        inner_radius_px: radius of the disc of the 48x48 patch the filters see, pixels.
        weight: the real filters' PSR is added to the rendered filters' PSR times this.
    """

    labels: tuple[str, ...]
    spectra: np.ndarray
    inner_radius_px: float
    weight: float

    def __post_init__(self) -> None:
        expected = (len(self.labels), REAL_FILTER_FFT_PX, REAL_FILTER_FFT_PX // 2 + 1)
        if self.spectra.shape != expected:
            raise ValueError(f'real filter spectra must have shape {expected}, got '
                             f'{self.spectra.shape}')
        if not 0.0 < self.inner_radius_px <= PATCH_PX / 2:
            raise ValueError(f'inner_radius_px must be in (0, {PATCH_PX / 2}], got '
                             f'{self.inner_radius_px}')
        if self.weight < 0.0:
            raise ValueError(f'weight must be >= 0, got {self.weight}')

    def psr(self, patches: np.ndarray) -> np.ndarray:
        """Each label's peak-to-sidelobe ratio on each patch.

        Args:
            patches: (N, 48, 48) canonical patches (:func:`~.sign_features.aligned_patches`).

        Returns:
            (N, L) float32 PSR (dimensionless): the plane's largest value within
            ``PEAK_REACH_PX`` of the centre, less the plane's mean, over its standard
            deviation.
        """
        spectra = patch_spectra(np.asarray(patches, np.float32), self.inner_radius_px)
        products = spectra[:, None] * self.spectra[None]  # (N, L, 64, 33)
        # no correlation plane is formed: its mean is the product's zero frequency, its energy
        # the product's (Parseval; rfft2 holds the columns 1-31 for two), and its values
        # near the centre a direct inverse transform at those 7x7 shifts only
        area = float(REAL_FILTER_FFT_PX ** 2)
        mean = products[..., 0, 0].real / area
        energy = (np.abs(products) ** 2 * _COLUMN_COUNTS).sum(axis=(2, 3)) / area
        spread = np.sqrt(np.maximum(energy / area - mean ** 2, 0.0)) + 1e-9
        peaks = (_ROW_SHIFTS @ products @ _COLUMN_SHIFTS).real.max(axis=(2, 3)) / area
        return ((peaks - mean) / spread).astype(np.float32)


def fused_label_order(ranked: Sequence[tuple[str, float]], filters: RealFilters,
                      psr: np.ndarray) -> list[str]:
    """The distinct labels, best first, by the rendered filters' PSR plus the real
    filters' PSR times ``filters.weight``.

    Args:
        ranked: the rendered filters' (class name, PSR) of every class correlated
            (:class:`~.candidate_evidence.CorrelationEvidence`); a label's PSR is the best
            of its classes.
        filters: the real filters.
        psr: (L,) :meth:`RealFilters.psr` of the sign.

    Returns:
        Every label of ``ranked`` once; a label without a real filter keeps its rendered
        PSR alone.
    """
    rendered: dict[str, float] = {}
    for class_name, score in ranked:
        label = label_of_class(class_name)
        rendered[label] = max(rendered.get(label, -np.inf), float(score))
    real = dict(zip(filters.labels, (float(value) for value in psr)))
    fused = {label: score + filters.weight * real.get(label, 0.0)
             for label, score in rendered.items()}
    return sorted(fused, key=lambda label: -fused[label])


@functools.lru_cache(maxsize=4)
def _inner_disc(inner_radius_px: float) -> np.ndarray:
    """(48, 48) float32 mask of the patch's inner disc (built once per radius: the
    classifier asks for it on every frame)."""
    centre = (PATCH_PX - 1) / 2.0
    rows, columns = np.mgrid[:PATCH_PX, :PATCH_PX]
    disc = (np.hypot(rows - centre, columns - centre) <= inner_radius_px).astype(np.float32)
    disc.setflags(write=False)
    return disc


def patch_spectra(patches: np.ndarray, inner_radius_px: float) -> np.ndarray:
    """(N, 64, 33) complex spectra of the patches' inner discs, each at zero mean and
    unit energy inside the disc."""
    disc = _inner_disc(float(inner_radius_px))
    inside = patches * disc
    mean = inside.sum(axis=(1, 2), keepdims=True) / disc.sum()
    centred = (patches - mean) * disc
    centred /= np.sqrt((centred ** 2).sum(axis=(1, 2), keepdims=True)) + 1e-3
    return np.fft.rfft2(centred, s=(REAL_FILTER_FFT_PX, REAL_FILTER_FFT_PX)).astype(
        np.complex64)
