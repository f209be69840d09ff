"""Fitting the composite correlation filters of real crops (OT-MACH, one per label).

The filters, and how the reader scores a sign with them at run time:
:mod:`speed_sign_detector.recognition.real_filters`.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from speed_sign_detector.recognition.real_filters import (
    REAL_FILTER_FFT_PX,
    RealFilters,
    patch_spectra,
)

__all__ = ['train_real_filters']


def train_real_filters(patches: np.ndarray, labels: Sequence[str], noise: float = 10.0,
                       inner_radius_px: float = 16.0, weight: float = 0.25) -> RealFilters:
    """One OT-MACH filter per label from its examples' canonical patches.

    Args:
        patches: (N, 48, 48) canonical patches of located signs.
        labels: (N,) their labels.
        noise: weight of white noise in the trade-off, relative to the mean power
            (larger: closer to the plain mean of the examples, more tolerant).
        inner_radius_px: radius of the disc of the patch the filters see, pixels.
        weight: see :class:`RealFilters`.

    Raises:
        ValueError: when ``patches`` and ``labels`` differ in length or are empty.
    """
    labels = list(labels)
    if len(labels) != len(patches) or not labels:
        raise ValueError(f'need as many labels as patches (at least one), got '
                         f'{len(labels)} labels for {len(patches)} patches')
    if noise < 0.0:
        raise ValueError(f'noise must be >= 0, got {noise}')
    names = tuple(sorted(set(labels)))
    label_array = np.asarray(labels)
    filters = np.empty((len(names), REAL_FILTER_FFT_PX, REAL_FILTER_FFT_PX // 2 + 1),
                       np.complex64)
    for index, name in enumerate(names):  # one label's spectra at a time (memory)
        examples = patch_spectra(np.asarray(patches[label_array == name], np.float32),
                                  inner_radius_px)
        mean = examples.mean(axis=0)
        power = (np.abs(examples) ** 2).mean(axis=0)
        similarity = (np.abs(examples - mean) ** 2).mean(axis=0)
        filters[index] = np.conj(mean / (power + similarity + noise * power.mean()))
    return RealFilters(names, filters, float(inner_radius_px), float(weight))
