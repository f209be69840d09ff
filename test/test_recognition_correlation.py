"""kth-law, MACE synthesis, FFT correlation and PSR on rendered templates."""
from __future__ import annotations

import numpy as np
import pytest

from speed_sign_detector.recognition.correlation import (
    correlate,
    correlation_peaks,
    disc_window,
    inverse_planes,
    keep_inside,
    kth_law,
    peak_psr,
    scene_spectra,
    scene_spectrum,
    transposed_spectra,
)
from speed_sign_detector.recognition.mace import (
    mace_filter,
    mace_filters,
    training_spectra,
)
from speed_sign_detector.recognition.templates import GRAY_TEMPLATE_GEOMETRY, gray_views

FFT = (64, 64)
VIEWS = [(yaw, pitch, 0.0) for yaw in (0, 10, -10, 20, -20, 30, -30) for pitch in (0, 10, -10)]


def _views(kind: str) -> np.ndarray:
    return gray_views(kind, 40.0, 52, VIEWS, geometry=GRAY_TEMPLATE_GEOMETRY, supersample=1)


def _scene(kind: str, shift: tuple[int, int], yaw: float = 0.0) -> np.ndarray:
    """64 x 64 gray scene with the sign's 52 px canvas at ``shift`` (top-left)."""
    scene = np.full(FFT, 128.0, np.float32)
    image = gray_views(kind, 40.0, 52, [(yaw, 0.0, 0.0)], geometry=GRAY_TEMPLATE_GEOMETRY)[0]
    scene[shift[0]:shift[0] + 52, shift[1]:shift[1] + 52] = image
    return scene


@pytest.fixture(scope='module')
def filter_50() -> np.ndarray:
    return mace_filter(training_spectra(_views('50'), FFT, 0.3), FFT, noise_tradeoff=0.5)


def test_kth_law_keeps_phase_and_compresses_magnitude() -> None:
    rng = np.random.default_rng(1)
    spectrum = (rng.normal(size=100) + 1j * rng.normal(size=100)) * 50
    spectrum[0] = 0
    out = kth_law(spectrum, 0.2)
    nonzero = np.abs(spectrum) > 0
    np.testing.assert_allclose(np.angle(out[nonzero]), np.angle(spectrum[nonzero]), atol=1e-4)
    np.testing.assert_allclose(np.abs(out[nonzero]), np.abs(spectrum[nonzero]) ** 0.2,
                               rtol=1e-4)
    assert out[0] == 0


def test_mace_meets_its_constraints() -> None:
    """Every training image correlates to ~1 at the origin (k = 1, pure MACE)."""
    images = _views('80')
    spectra = training_spectra(images, FFT, 1.0)
    filt = mace_filter(spectra, FFT, noise_tradeoff=0.0, ridge=1e-6)
    origins = [correlate(spectra[i], filt.conj()[None], FFT)[0, 0, 0] for i in range(len(images))]
    np.testing.assert_allclose(origins, 1.0, atol=1e-2)


def test_psr_sharp_on_match_at_the_right_place(filter_50: np.ndarray) -> None:
    scene = _scene('50', (5, 7), yaw=15.0)
    planes = correlate(scene_spectrum(scene, FFT, 0.3), filter_50.conj()[None], FFT)
    stats = peak_psr(planes, (6, 6), 4, 12, 2)
    assert (int(stats.y[0]), int(stats.x[0])) == (5, 7)
    assert stats.psr[0] > 15.0


def test_psr_lower_on_other_signs_and_noise(filter_50: np.ndarray) -> None:
    rng = np.random.default_rng(7)
    psr = {}
    for name, scene in (('50', _scene('50', (6, 6))), ('80', _scene('80', (6, 6))),
                        ('no_overtaking', _scene('no_overtaking', (6, 6))),
                        ('noise', rng.normal(128, 30, FFT).astype(np.float32))):
        planes = correlate(scene_spectrum(scene, FFT, 0.3), filter_50.conj()[None], FFT)
        psr[name] = float(peak_psr(planes, (6, 6), 4, 12, 2).psr[0])
    assert psr['50'] > 1.5 * max(psr['80'], psr['no_overtaking']), psr
    assert psr['noise'] < 0.5 * psr['50'], psr


def test_batched_correlation_equals_one_by_one(filter_50: np.ndarray) -> None:
    other = mace_filter(training_spectra(_views('30'), FFT, 0.3), FFT, noise_tradeoff=0.5)
    bank = np.conj(np.stack([filter_50, other]))
    spectrum = scene_spectrum(_scene('30', (6, 6)), FFT, 0.3)
    batched = correlate(spectrum, bank, FFT)
    for index in range(2):
        single = correlate(spectrum, bank[index:index + 1], FFT)[0]
        np.testing.assert_allclose(batched[index], single, atol=1e-5)



def test_peak_psr_per_plane_centres_equal_one_plane_at_a_time() -> None:
    planes = np.random.default_rng(3).standard_normal((5, 32, 40)).astype(np.float32)
    centres = np.array([[6, 6], [6, 6], [0, 39], [31, 2], [16, 20]])
    searches = np.array([4, 2, 3, 1, 4])
    together = peak_psr(planes, centres, searches, 7, 2)
    for index in range(5):
        alone = peak_psr(planes[index:index + 1], tuple(centres[index]), int(searches[index]),
                         7, 2)
        for name in ('value', 'y', 'x', 'psr'):
            assert getattr(together, name)[index] == getattr(alone, name)[0], name

@pytest.mark.parametrize('shape', [(64, 64), (54, 54), (45, 45), (20, 20)])
def test_correlation_peaks_equal_peak_psr_of_the_planes(filter_50: np.ndarray,
                                                        shape: tuple[int, int]) -> None:
    """The classifier's peaks from the transposed products (the rows of the peak blocks
    only) are bitwise those of peak_psr on the full planes, for one centre shared by
    every plane and for a centre per plane (wrapping around index 0), with per-plane
    search sizes, and for blocks wider than a small plane (20 px)."""
    rng = np.random.default_rng(11)
    filters = np.conj(np.fft.rfft2(rng.standard_normal((3,) + shape), s=shape)).astype(
        np.complex64)
    scenes = scene_spectra([_scene('50', (5, 7))[:shape[0], :shape[1]],
                            rng.normal(128, 30, shape).astype(np.float32)], shape, 0.5)
    planes = inverse_planes(filters * scenes[:, None], shape).reshape((-1,) + shape)
    product = (transposed_spectra(filters) * transposed_spectra(scenes)[:, None]).reshape(
        (-1, shape[1] // 2 + 1, shape[0]))
    count = planes.shape[0]
    per_plane = np.stack([rng.integers(0, shape[0], count), rng.integers(0, shape[1], count)],
                         axis=1)
    for centre, search in (((6, 6), 3), ((0, shape[1] - 1), np.arange(count) % 4 + 1),
                           (per_plane, 2), (per_plane, np.arange(count) % 3 + 1)):
        expected = peak_psr(planes, centre, search, 9, 2)
        found = correlation_peaks(product.copy(), shape, centre, search, 9, 2)
        for name in ('value', 'y', 'x', 'psr'):
            np.testing.assert_array_equal(getattr(found, name), getattr(expected, name), name)


def test_peak_psr_rejects_bad_windows() -> None:
    with pytest.raises(ValueError):
        peak_psr(np.zeros((1, 16, 16), np.float32), (8, 8), 2, 3, 3)


def test_disc_window_and_keep_inside() -> None:
    window = disc_window((21, 21), (10.5, 10.5), 5.0)
    assert window[10, 10] == 1.0 and window[0, 0] == 0.0
    assert window.sum() == pytest.approx(np.pi * 25, rel=0.05)
    image = np.arange(21 * 21, dtype=np.float32).reshape(21, 21)
    kept = keep_inside(image, window)
    assert kept[10, 10] == image[10, 10]
    inside_mean = (image * window).sum() / window.sum()
    assert kept[0, 0] == pytest.approx(inside_mean)


def test_training_spectra_rejects_empty_stack() -> None:
    with pytest.raises(ValueError):
        training_spectra(np.zeros((0, 8, 8), np.float32), (8, 8), 0.5)


def test_batched_mace_filters_equal_single_ones() -> None:
    """Filters synthesized together equal those synthesized one by one."""
    stacks = np.stack([training_spectra(_views(kind), FFT, 0.5) for kind in ('30', '80')])
    together = mace_filters(stacks, FFT, noise_tradeoff=0.9)
    assert together.shape == (2, FFT[0], FFT[1] // 2 + 1) and together.dtype == np.complex64
    for spectra, batched in zip(stacks, together):
        single = mace_filter(spectra, FFT, noise_tradeoff=0.9)
        assert np.abs(batched - single).max() <= 1e-5 * np.abs(single).max()


def test_training_spectra_do_not_depend_on_the_stack() -> None:
    """Each image's spectrum is the same in a large stack (chunked FFTs) as alone."""
    images = np.concatenate([_views('30'), _views('80')])  # 42 images: two chunks
    stacked = training_spectra(images, FFT, 0.5)
    for index in (0, 33, 41):
        np.testing.assert_array_equal(stacked[index],
                                      training_spectra(images[index:index + 1], FFT, 0.5)[0])
