"""A trained bank: what training on labelled real crops adds to the rendered filters.

It holds the second opinion (:mod:`.second_opinion`), the rule that decides with it,
the composite filters trained from real crops that rank the labels it chooses among
(:mod:`.real_filters`), and the mean real examples of each class that join the
renderings in the classification filters (:mod:`.filter_banks`). It is saved as one
file with its provenance (:mod:`.bank_file`): data folders, counts per class,
parameters, package version.

The package ships one, built by ``speed_sign_train build`` from the project's real data
(:data:`DEFAULT_BANK_FILE`); ``classifier.bank_file`` names another, or ``none`` for the
renderings alone.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector.errors import BankFileError
from speed_sign_detector.recognition.bank_file import load_bank_file, save_bank_file
from speed_sign_detector.recognition.real_filters import RealFilters
from speed_sign_detector.recognition.second_opinion import SecondOpinion

__all__ = ['DEFAULT_BANK_FILE', 'NO_BANK_FILE', 'TRAINED_BANK_FORMAT', 'TrainedBank',
           'load_trained_bank', 'resolve_bank_file', 'save_trained_bank']

TRAINED_BANK_FORMAT = 'speed_sign_detector.trained_bank'
TRAINED_BANK_VERSION = 4
#: Versions this package reads: 2 (linear second opinion only), 3 (linear or network)
#: and 4 (with real filters).
READABLE_BANK_VERSIONS = (2, 3, TRAINED_BANK_VERSION)
#: The bank shipped with the package.
DEFAULT_BANK_FILE = Path(__file__).resolve().parent / 'data' / 'default_bank.npz'
#: ``classifier.bank_file`` value for the rendered templates alone (no trained bank).
NO_BANK_FILE = 'none'


@dataclass(frozen=True)
class TrainedBank:
    """The trained parts of the classifier.

    Attributes:
        second_opinion: the linear model, or ``None``.
        candidates: the second opinion chooses among this many leading correlation labels.
        min_lead: its least score lead over its next best label.
        class_examples: label -> (M, P, P) float32 mean real examples (canonical patches
            of :mod:`.sign_features`) joining that class's composite filters; may be empty.
        provenance: data folders, counts per class, parameters, package version.
        real_filters: composite filters trained from real crops, whose PSR joins the
            rendered filters' in ranking the labels the second opinion chooses among; or
            ``None`` (the rendered filters rank alone).
    """

    second_opinion: SecondOpinion | None
    candidates: int = 2
    min_lead: float = 0.2
    class_examples: dict[str, np.ndarray] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    real_filters: RealFilters | None = None


def resolve_bank_file(setting: str) -> Path | None:
    """The file a ``classifier.bank_file`` value names: ``''`` the shipped default,
    ``'none'`` no file (renderings only), else the path (``~`` expanded)."""
    if setting.strip().lower() == NO_BANK_FILE:
        return None
    if not setting.strip():
        return DEFAULT_BANK_FILE
    return Path(setting).expanduser()


def save_trained_bank(path: Path, bank: TrainedBank) -> None:
    """Write ``bank`` to ``path`` with its provenance (atomically)."""
    arrays: dict[str, np.ndarray] = {}
    if bank.second_opinion is not None:
        opinion = bank.second_opinion
        arrays.update(opinion_labels=np.asarray(opinion.labels),
                      opinion_real_labels=np.asarray(opinion.real_labels),
                      opinion_crop_labels=np.asarray(opinion.labels_with_crops),
                      feature_mean=opinion.feature_mean,
                      feature_scale=opinion.feature_scale,
                      weights=opinion.weights.astype(np.float16), bias=opinion.bias)
        if opinion.hidden_weights is not None:
            arrays.update(hidden_weights=opinion.hidden_weights.astype(np.float16),
                          hidden_bias=opinion.hidden_bias)
    for label, examples in bank.class_examples.items():
        arrays[f'examples_{label}'] = np.asarray(examples, np.float16)
    decision: dict[str, Any] = {'candidates': bank.candidates, 'min_lead': bank.min_lead}
    if bank.real_filters is not None:
        filters = bank.real_filters
        arrays.update(real_filter_labels=np.asarray(filters.labels),
                      real_filter_spectra=filters.spectra.astype(np.complex64))
        decision.update(real_filter_weight=filters.weight,
                        real_filter_inner_radius_px=filters.inner_radius_px)
    meta = dict(bank.provenance, decision=decision)
    save_bank_file(path, arrays, meta, TRAINED_BANK_FORMAT, TRAINED_BANK_VERSION)


def load_trained_bank(path: Path) -> TrainedBank:
    """Read a trained bank.

    Raises:
        BankFileError: for a missing, corrupt or incompatible file (the reason named).
    """
    arrays, meta = load_bank_file(path, TRAINED_BANK_FORMAT, READABLE_BANK_VERSIONS)
    try:
        opinion = None
        if 'weights' in arrays:
            opinion = SecondOpinion(tuple(str(n) for n in arrays['opinion_labels']),
                                    arrays['feature_mean'].astype(np.float32),
                                    arrays['feature_scale'].astype(np.float32),
                                    arrays['weights'].astype(np.float32),
                                    arrays['bias'].astype(np.float32),
                                    tuple(str(n) for n in arrays['opinion_real_labels']),
                                    *((arrays['hidden_weights'].astype(np.float32),
                                       arrays['hidden_bias'].astype(np.float32))
                                      if 'hidden_weights' in arrays else (None, None)),
                                    crop_labels=tuple(
                                        str(n) for n in arrays['opinion_crop_labels'])
                                    if 'opinion_crop_labels' in arrays else None)
        examples = {name[len('examples_'):]: array.astype(np.float32)
                    for name, array in arrays.items() if name.startswith('examples_')}
        decision = meta['decision']
        real_filters = None
        if 'real_filter_spectra' in arrays:
            real_filters = RealFilters(
                tuple(str(n) for n in arrays['real_filter_labels']),
                arrays['real_filter_spectra'].astype(np.complex64),
                float(decision['real_filter_inner_radius_px']),
                float(decision['real_filter_weight']))
        return TrainedBank(opinion, int(decision['candidates']), float(decision['min_lead']),
                           examples, {k: v for k, v in meta.items() if k != 'decision'},
                           real_filters)
    except (KeyError, ValueError, TypeError) as err:
        raise BankFileError(f'{path} is not a complete trained bank ({err})') from err
