"""The CPU detector path (OpenCV edges, stencil voting) computes the numpy reference's
maths, and ``backend: auto`` chooses between it and GL by timing both."""
from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest
from test_detection_backends import CONFIGS, assert_same_candidates, synthetic_scene

from speed_sign_detector.config import DetectorConfig, PipelineConfig
from speed_sign_detector.detection.backend_trial import (
    TIMED_FRAMES,
    WARMUP_FRAMES,
    BackendTrial,
)
from speed_sign_detector.detection.candidates import (
    block_maxima,
    score_normaliser,
    select_candidates,
)
from speed_sign_detector.detection.candidates_cpu import (
    packed_block_maxima,
    select_packed_candidates,
)
from speed_sign_detector.detection.detector import CPU_RENDERER, Detector
from speed_sign_detector.detection.gradients_cpu import compute_edges_fast
from speed_sign_detector.detection.voting_cpu import (
    CPUVoter,
    build_stencils,
    fixed_point_units,
)
from speed_sign_detector.detection.voting_numpy import (
    RadiusBand,
    compute_edges,
    plan_bands,
    vote_images,
    vote_signs,
)
from speed_sign_detector.errors import ConfigError

CPU_CONFIGS = {
    **CONFIGS,
    'bright_inside_dark_side': DetectorConfig(polarity='bright_inside',
                                              dark_side_min_radius_px=10.0),
    'deep_pyramid': DetectorConfig(max_radius_px=80.0, max_pyramid_level=3,
                                   vote_pixels_per_radius=1.0),
}



def assert_same_edges(gray: np.ndarray, config: DetectorConfig) -> None:
    """The fast edge lists hold the reference's pixels (a last-bit rounding may decide
    one in a thousand the other way) in the same order, with the same gradients."""
    for fast, ref in zip(compute_edges_fast(gray, config), compute_edges(gray, config),
                         strict=True):
        assert ref.count > 0
        fast_pixels = set(zip(fast.x_px.tolist(), fast.y_px.tolist()))
        ref_pixels = set(zip(ref.x_px.tolist(), ref.y_px.tolist()))
        assert len(fast_pixels ^ ref_pixels) <= max(2, 0.001 * ref.count)
        assert np.all(np.diff(fast.y_px * fast.width_px + fast.x_px) > 0)  # row order
        if fast.count == ref.count and np.array_equal(fast.x_px, ref.x_px):
            np.testing.assert_allclose(fast.gx, ref.gx, atol=1e-3)
            np.testing.assert_allclose(fast.gy, ref.gy, atol=1e-3)


def assert_same_votes(gray: np.ndarray, config: DetectorConfig) -> None:
    """Each band's two channels match the reference's, and the strongest pixel is in the
    same place. With the default settings: correlation above 0.9997, totals within 0.25 %;
    with others, as the GL backend's test asks: 0.999 and 0.5 % (the flat profile's
    full-weight trapezoid sides, and a band whose smallest radius spans under 2 vote
    pixels, turn with the quantised direction)."""
    defaults = dataclasses.replace(config, detection_width_px=960) == DetectorConfig()
    least_correlation, total_tolerance = (0.9997, 2.5e-3) if defaults else (0.999, 5e-3)
    edges = compute_edges(gray, config)
    fast_votes = CPUVoter(config).vote_images(edges, (gray.shape[1], gray.shape[0]))
    for band, fast, ref in zip(plan_bands(config), fast_votes, vote_images(gray, config),
                               strict=True):
        assert fast.shape == ref.shape and fast.dtype == np.float32
        for channel in range(ref.shape[2]):
            a, b = fast[..., channel].ravel(), ref[..., channel].ravel()
            assert b.sum() > 0.0
            correlation = float(np.corrcoef(a, b)[0, 1])
            assert correlation > least_correlation, (band, channel, correlation)
            assert abs(a.sum() - b.sum()) <= total_tolerance * b.sum(), (band, channel)
        assert np.argmax(fast[..., 0]) == np.argmax(ref[..., 0]), band


@pytest.mark.parametrize('name', sorted(CPU_CONFIGS))
def test_cpu_path_matches_the_reference_on_a_synthetic_scene(name: str) -> None:
    gray = synthetic_scene()
    assert_same_edges(gray, CPU_CONFIGS[name])
    assert_same_votes(gray, CPU_CONFIGS[name])


def test_cpu_path_matches_the_reference_on_a_real_scene(gtsdb_scene: np.ndarray) -> None:
    assert_same_edges(gtsdb_scene, DetectorConfig())
    assert_same_votes(gtsdb_scene, DetectorConfig())
    assert_same_votes(np.ascontiguousarray(gtsdb_scene[:, 88:728]), DetectorConfig())


@pytest.mark.parametrize('backend', ['cpu', 'gl'])
def test_cpu_and_gl_backends_find_the_reference_candidates(backend: str) -> None:
    gray = synthetic_scene()
    with Detector(DetectorConfig(), backend=backend) as detector, \
            Detector(DetectorConfig(), backend='numpy') as reference:
        assert_same_candidates(detector.detect(gray), reference.detect(gray))
        if backend == 'cpu':
            assert detector.vote_method == 'stencil' and detector.renderer == CPU_RENDERER


def test_stencils_follow_the_band_geometry() -> None:
    """A band voting on a 2x coarser image keeps 2 x 2 phases of stencils; every
    stencil's votes lie between r0 and the trapezoid's far corner."""
    bands = plan_bands(DetectorConfig())
    coarser = next(band for band in bands if band.shrink == 0.5)
    stencils = build_stencils(coarser, tent=True)
    assert stencils.phases == 2
    assert stencils.offset_x.shape == stencils.packed_votes.shape
    assert stencils.packed_votes.shape[0] == 4 * 1024
    voted = stencils.packed_votes > 0.0
    distance = np.hypot(stencils.offset_x, stencils.offset_y)[voted]
    r0, r1 = coarser.level_radii
    assert distance.min() >= r0 * coarser.shrink - 2.0
    assert distance.max() <= r1 * coarser.shrink * 1.09 + 2.0


@pytest.mark.parametrize('radii', [(2.0, 3.0), (3.5, 6.4), (5.4, 10.0), (2.0, 200.0)])
def test_packed_votes_fit_a_float64_mantissa(radii: tuple[float, float]) -> None:
    """Weight and count fields together stay below 2^53 at the largest per-pixel sums."""
    band = RadiusBand(0, 0, 0, *radii)
    weight_one, count_one, count_scale = fixed_point_units(band)
    assert count_scale >= 2 ** 10 and weight_one == count_one >= 2 ** 10
    from speed_sign_detector.detection.vote_fixed_point import votes_per_pixel_bound
    votes = votes_per_pixel_bound(*radii)
    largest = votes * (weight_one * 2.0 / radii[0] + 0.5) * count_scale + count_scale
    assert largest < 2.0 ** 53 or weight_one == 2 ** 10


def test_backend_trial_keeps_the_faster_and_alternates_the_order() -> None:
    trial = BackendTrial('llvmpipe (test)')
    orders = []
    decision = None
    for frame in range(WARMUP_FRAMES + TIMED_FRAMES):
        orders.append(trial.order())
        # the warm-up frame is slow for cpu and must not count
        decision = trial.record({'gl': 30.0 + frame, 'cpu': 500.0 if frame == 0 else 20.0})
        if frame < WARMUP_FRAMES + TIMED_FRAMES - 1:
            assert decision is None
    assert orders[0] == ('gl', 'cpu') and orders[1] == ('cpu', 'gl')
    assert decision is not None and decision.backend == 'cpu'
    assert decision.median_ms == {'gl': 33.0, 'cpu': 20.0}
    line = decision.describe()
    assert 'cpu, 20.0 ms' in line and 'gl 33.0 ms' in line and 'llvmpipe (test)' in line
    tie = BackendTrial('x', warmup_frames=0, timed_frames=1)
    assert tie.record({'gl': 5.0, 'cpu': 5.0}).backend == 'gl'
    with pytest.raises(ValueError, match='needs a time for each'):
        BackendTrial('x').record({'gl': 1.0})


def test_auto_on_llvmpipe_times_both_and_says_which_it_kept(
        caplog: pytest.LogCaptureFixture) -> None:
    gray = synthetic_scene()
    with caplog.at_level(logging.INFO, logger='speed_sign_detector.detection.detector'), \
            Detector(DetectorConfig(), backend='auto') as detector:
        if 'llvmpipe' not in detector.renderer:
            pytest.skip(f'not a software renderer: {detector.renderer}')
        assert detector.backend_choice.startswith('auto: timing gl and cpu')
        with Detector(DetectorConfig(), backend='numpy') as reference:
            expected = reference.detect(gray)
        for _ in range(WARMUP_FRAMES + TIMED_FRAMES):
            assert_same_candidates(detector.detect(gray), expected)
        decision = detector.trial_decision
        assert decision is not None and decision.backend == detector.backend_name
        assert detector.backend_name in ('gl', 'cpu')
        assert detector.backend_choice == decision.describe()
        assert detector.renderer == decision.renderer   # the host's renderer stays named
        assert set(decision.median_ms) == {'gl', 'cpu'}
        assert all(value > 0.0 for value in decision.median_ms.values())
        assert_same_candidates(detector.detect(gray), expected)   # on the kept path
        assert detector.vote_images(gray)[0].shape[:2] == gray.shape
    assert f'detector backend chosen: auto: {detector.backend_name}' in caplog.text


def test_backend_values_are_checked() -> None:
    with pytest.raises(ConfigError, match="backend = 'cuda' is not one of auto, gl, cpu, numpy"):
        PipelineConfig(backend='cuda')
    with pytest.raises(ConfigError, match='unknown detector backend'):
        Detector(DetectorConfig(), backend='vulkan')
    assert dataclasses.replace(PipelineConfig(), backend='cpu').backend == 'cpu'


@pytest.mark.parametrize('name', ['default', 'two_bands', 'deep_pyramid'])
def test_packed_block_maxima_equal_the_reference_reduction(name: str) -> None:
    """From the packed sums, the block maxima are those :func:`block_maxima` finds in the
    unpacked vote images, bit for bit (a frame size no block size divides included)."""
    config = CPU_CONFIGS[name]
    voter = CPUVoter(config)
    bands = plan_bands(config)
    normalisers = [score_normaliser(len(vote_signs(config, band))) for band in bands]
    for gray in (synthetic_scene(), synthetic_scene()[:237, :301]):
        edges = compute_edges_fast(gray, config)
        packed = voter.packed_votes(edges, (gray.shape[1], gray.shape[0]))
        votes = [stencils.unpack(sums) for stencils, sums in zip(voter.stencils, packed)]
        expected = block_maxima(votes, bands, gray.shape, config.block_size_px, normalisers)
        found = packed_block_maxima(packed, voter.stencils, gray.shape,
                                    config.block_size_px, normalisers)
        assert np.count_nonzero(expected.score > 0.0) > 10
        for field in ('score', 'x_px', 'y_px', 'radius_px', 'band'):
            np.testing.assert_array_equal(getattr(found, field), getattr(expected, field),
                                          err_msg=field)


@pytest.mark.parametrize('max_candidates', [1, 7, 40])
def test_packed_selection_equals_the_reference_selection(max_candidates: int) -> None:
    """Locating only the blocks the top-N selection visits (more when suppression leaves
    too few) selects what the full block maxima give."""
    config = DetectorConfig(max_candidates=max_candidates)
    voter = CPUVoter(config)
    normalisers = [score_normaliser(len(vote_signs(config, band))) for band in voter.bands]
    gray = synthetic_scene()
    packed = voter.packed_votes(compute_edges_fast(gray, config), (320, 240))
    full = packed_block_maxima(packed, voter.stencils, gray.shape, 8, normalisers)
    for suppression in (1.0, 6.0):   # 6 voting radii: most blocks are suppressed
        for ring_ratio in (config.enclosing_ring_ratio, 0.0):
            expected = select_candidates(full, max_candidates, 0.0, suppression, ring_ratio)
            assert select_packed_candidates(packed, voter.stencils, gray.shape, 8,
                                            normalisers, max_candidates, 0.0, suppression,
                                            ring_ratio) == expected


def test_voting_on_two_threads_equals_one_thread() -> None:
    """The bands split between two threads give the same packed sums (exact integers)."""
    config = DetectorConfig()
    gray = synthetic_scene()
    edges = compute_edges_fast(gray, config)
    alone, helped = CPUVoter(config, threads=1), CPUVoter(config, threads=2)
    try:
        for one, two in zip(alone.packed_votes(edges, (320, 240)),
                            helped.packed_votes(edges, (320, 240)), strict=True):
            np.testing.assert_array_equal(one, two)
    finally:
        helped.close()
        helped.close()   # idempotent
    assert helped.packed_votes(edges, (320, 240))[0].shape == (240, 320)   # on one thread


def test_auto_keeps_gl_on_a_hardware_renderer_without_a_trial(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """On a renderer that is not a CPU one, auto neither builds the CPU path nor times it."""
    from speed_sign_detector.detection import detector as detector_module

    monkeypatch.setattr(detector_module, 'is_software_renderer', lambda renderer: False)
    with Detector(DetectorConfig(), backend='auto') as detector:
        assert detector.backend_name == 'gl'
        assert detector.backend_choice.startswith('auto: gl on a hardware renderer')
        for _ in range(WARMUP_FRAMES + TIMED_FRAMES + 1):
            assert detector.detect(synthetic_scene())
        assert detector.backend_name == 'gl' and detector.trial_decision is None
        assert detector._cpu is None
