"""Composite correlation filters trained from real crops (:mod:`.real_filters`), the ranking
they give with the rendered filters, how the bank file keeps them, and how the classifier
uses them (:mod:`.sign_reading`).

The examples are drawn here (digit-like strokes on noise, at known positions), so every
answer is known.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.errors import BankFileError
from speed_sign_detector.recognition.bank_file import load_bank_file, save_bank_file
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.real_filters import (
    REAL_FILTER_FFT_PX,
    RealFilters,
    fused_label_order,
    patch_spectra,
)
from speed_sign_detector.recognition.second_opinion import SecondOpinion
from speed_sign_detector.recognition.sign_features import FEATURE_SIZE, PATCH_PX
from speed_sign_detector.recognition.sign_reading import read_signs
from speed_sign_detector.recognition.trained_bank import (
    TRAINED_BANK_FORMAT,
    TrainedBank,
    load_trained_bank,
    save_trained_bank,
)
from speed_sign_detector.training.filter_fitting import train_real_filters

#: Each label's strokes: (x0, y0, x1, y1) in patch pixels, inside the inner disc.
STROKES = {'30': [(16, 14, 22, 34), (28, 14, 34, 34)],
           '80': [(18, 16, 30, 20), (18, 28, 30, 32)],
           'other_sign': [(12, 22, 36, 26)]}


def patch_of(label: str, rng: np.random.Generator, shift: tuple[int, int] = (0, 0)
             ) -> np.ndarray:
    """A (48, 48) float32 patch: the label's bright strokes on noise, moved by ``shift``
    (x, y) pixels."""
    patch = rng.normal(90.0, 12.0, (PATCH_PX, PATCH_PX)).astype(np.float32)
    for x0, y0, x1, y1 in STROKES[label]:
        cv2.rectangle(patch, (x0 + shift[0], y0 + shift[1]), (x1 + shift[0], y1 + shift[1]),
                      200.0, thickness=-1)
    return patch


@pytest.fixture(scope='module')
def filters() -> RealFilters:
    rng = np.random.default_rng(0)
    labels = [label for label in STROKES for _ in range(30)]
    patches = np.stack([patch_of(label, rng, tuple(rng.integers(-1, 2, 2))) for label in labels])
    return train_real_filters(patches, labels, noise=10.0, weight=0.5)


def test_each_label_scores_highest_on_its_own_examples(filters: RealFilters) -> None:
    rng = np.random.default_rng(1)
    assert filters.labels == ('30', '80', 'other_sign')
    assert filters.spectra.shape == (3, REAL_FILTER_FFT_PX, REAL_FILTER_FFT_PX // 2 + 1)
    for label in STROKES:
        for shift in [(0, 0), (2, -1), (-3, 3)]:  # the peak is sought near the centre
            psr = filters.psr(patch_of(label, rng, shift)[None])
            assert psr.shape == (1, 3) and psr.dtype == np.float32
            assert filters.labels[int(np.argmax(psr[0]))] == label, (label, shift, psr)
            assert psr[0].max() > 5.0


def test_psr_equals_that_of_the_whole_correlation_plane(filters: RealFilters) -> None:
    """The PSR is computed without forming the planes (Parseval, and a direct inverse
    transform near the centre); the reference forms each plane with an inverse FFT."""
    rng = np.random.default_rng(4)
    patches = np.stack([patch_of(label, rng, (1, -2)) for label in STROKES]
                       + [rng.uniform(0, 255, (PATCH_PX, PATCH_PX)).astype(np.float32)])
    spectra = patch_spectra(patches, filters.inner_radius_px)
    planes = np.fft.irfft2(spectra[:, None] * filters.spectra[None],
                           s=(REAL_FILTER_FFT_PX, REAL_FILTER_FFT_PX))
    planes = np.fft.fftshift(planes, axes=(2, 3))  # zero shift at the centre
    centre = REAL_FILTER_FFT_PX // 2
    near = planes[:, :, centre - 3:centre + 4, centre - 3:centre + 4]
    expected = (near.max(axis=(2, 3)) - planes.mean(axis=(2, 3))) / planes.std(axis=(2, 3))
    np.testing.assert_allclose(filters.psr(patches), expected, rtol=1e-4, atol=1e-4)


def test_psr_ignores_brightness_and_contrast(filters: RealFilters) -> None:
    patch = patch_of('80', np.random.default_rng(2))
    np.testing.assert_allclose(filters.psr(patch[None]), filters.psr(0.5 * patch[None] + 40.0),
                               rtol=1e-3, atol=1e-3)


def test_training_refuses_what_it_cannot_use() -> None:
    patches = np.zeros((2, PATCH_PX, PATCH_PX), np.float32)
    with pytest.raises(ValueError, match='as many labels as patches'):
        train_real_filters(patches, ['30'])
    with pytest.raises(ValueError, match='as many labels as patches'):
        train_real_filters(patches[:0], [])
    with pytest.raises(ValueError, match='noise must be >= 0'):
        train_real_filters(patches, ['30', '80'], noise=-1.0)
    with pytest.raises(ValueError, match='shape'):
        RealFilters(('30',), np.zeros((2, 64, 33), np.complex64), 16.0, 0.5)
    with pytest.raises(ValueError, match='weight must be >= 0'):
        RealFilters(('30',), np.zeros((1, 64, 33), np.complex64), 16.0, -0.5)


def test_fused_order_adds_the_weighted_real_psr(filters: RealFilters) -> None:
    # the rendered filters rank 80 before 30 (two classes of 80's label: the best counts)
    ranked = (('80', 12.0), ('30', 11.0), ('80', 11.5), ('no_overtaking', 7.0),
              ('120', 6.0))
    real_psr = np.asarray([10.0, 2.0, 0.0], np.float32)  # 30, 80, other_sign
    order = fused_label_order(ranked, filters, real_psr)
    # 30: 11 + 0.5 * 10 = 16; 80: 12 + 1 = 13; other_sign 7 + 0; 120 (no real filter) 6
    assert order == ['30', '80', 'other_sign', '120']
    unweighted = dataclasses.replace(filters, weight=0.0)
    assert fused_label_order(ranked, unweighted, real_psr) == ['80', '30', 'other_sign', '120']


def _opinion(labels: tuple[str, ...], favourite: str) -> SecondOpinion:
    """A linear second opinion that scores ``favourite`` 1 and every other label -1,
    whatever the features."""
    bias = np.where(np.asarray(labels) == favourite, 1.0, -1.0).astype(np.float32)
    return SecondOpinion(labels, np.zeros(FEATURE_SIZE, np.float32),
                         np.ones(FEATURE_SIZE, np.float32),
                         np.zeros((FEATURE_SIZE, len(labels)), np.float32), bias,
                         real_labels=labels)


def test_the_second_opinion_chooses_among_the_fused_leaders(filters: RealFilters) -> None:
    """The rendered filters rank 30 fourth: alone, the second opinion may not choose it; the
    real filters, which read the patch as 30, bring it among the three leaders."""
    rng = np.random.default_rng(3)
    patch = patch_of('30', rng)
    gray = np.clip(cv2.resize(patch, (96, 96)), 0, 255).astype(np.uint8)
    evidence = CorrelationEvidence((('80', 12.0), ('50', 11.5), ('other', 11.0), ('30', 9.0)),
                                   48.0, 48.0, 48.0, 0.0, 10.0)
    labels = ('30', '50', '80', 'other_sign')
    opinion = _opinion(labels, '30')
    config = ClassifierConfig(max_radius_px=24.0, cache_dir='', bank_file='none')
    plain = Classifier(config, TrainedBank(opinion, candidates=3, min_lead=0.5))
    fused = Classifier(config, TrainedBank(opinion, candidates=3, min_lead=0.5,
                                           real_filters=dataclasses.replace(filters,
                                                                            weight=1.0)))
    (reading,) = read_signs(fused.trained_bank, gray, [evidence])
    assert reading.ranking is not None and reading.ranking[0] == '30', reading.ranking
    assert read_signs(plain.trained_bank, gray, [evidence])[0].ranking is None
    assert plain.decide_crop(gray, evidence, framing='margin').label == 'no_sign'
    assert fused.decide_crop(gray, evidence, framing='margin').label == '30'
    assert read_signs(plain.trained_bank, gray, []) == []
    with pytest.raises(ValueError, match='second opinion'):
        read_signs(TrainedBank(None), gray, [evidence])


def test_bank_file_keeps_the_real_filters(tmp_path: Path, filters: RealFilters) -> None:
    path = tmp_path / 'bank.npz'
    opinion = _opinion(('30', '80', 'other_sign'), '30')
    save_trained_bank(path, TrainedBank(opinion, real_filters=filters))
    loaded = load_trained_bank(path).real_filters
    assert loaded is not None
    assert loaded.labels == filters.labels
    assert loaded.weight == filters.weight and loaded.inner_radius_px == filters.inner_radius_px
    np.testing.assert_array_equal(loaded.spectra, filters.spectra)
    # a bank without them loads without them
    save_trained_bank(path, TrainedBank(opinion))
    assert load_trained_bank(path).real_filters is None


def test_bank_with_damaged_real_filters_is_a_clear_error(tmp_path: Path,
                                                         filters: RealFilters) -> None:
    path = tmp_path / 'bank.npz'
    save_trained_bank(path, TrainedBank(_opinion(('30', '80'), '30'), real_filters=filters))
    arrays, meta = load_bank_file(path, TRAINED_BANK_FORMAT, (4,))
    meta = {key: value for key, value in meta.items() if key not in ('format',
                                                                      'format_version')}
    arrays['real_filter_spectra'] = arrays['real_filter_spectra'][:, :10]
    save_bank_file(path, arrays, meta, TRAINED_BANK_FORMAT, 4)
    with pytest.raises(BankFileError, match='not a complete trained bank.*shape'):
        load_trained_bank(path)
    del meta['decision']['real_filter_weight']
    arrays['real_filter_spectra'] = filters.spectra
    save_bank_file(path, arrays, meta, TRAINED_BANK_FORMAT, 4)
    with pytest.raises(BankFileError, match='real_filter_weight'):
        load_trained_bank(path)
