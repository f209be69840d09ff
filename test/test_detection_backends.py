"""The GL backend computes the numpy reference's maths (up to rasterization rules)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_detection_synthetic import ring_frame

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.detection.voting_gl import resolve_vote_method
from speed_sign_detector.detection.voting_numpy import compute_edges

CONFIGS = {
    'default': DetectorConfig(),
    'both_flat_linear': DetectorConfig(polarity='both', vote_profile='flat',
                                       contrast='linear', edge_support=2,
                                       vote_pixels_per_radius=0.0),
    # a wide second band: its scatter votes are not packed (two integers per pixel)
    'two_bands': DetectorConfig(radius_bands=2),
}



def synthetic_scene() -> np.ndarray:
    frame = ring_frame(320, 240, (80.0, 70.0), 9.0)
    for centre, radius in (((200.0, 90.0), 20.0), ((150.0, 180.0), 6.0)):
        other = ring_frame(320, 240, centre, radius)
        frame = np.where(other != 110, other, frame)
    rng = np.random.default_rng(5)
    return np.clip(frame + rng.normal(0.0, 6.0, frame.shape), 0, 255).astype(np.uint8)


def assert_backends_agree(gray: np.ndarray, config: DetectorConfig) -> None:
    with Detector(config, backend='gl') as gl, Detector(config, backend='numpy') as ref:
        assert gl.vote_method == config.vote_method
        gl_votes, ref_votes = gl.vote_images(gray), ref.vote_images(gray)
        assert len(gl_votes) == len(ref_votes) == len(ref.bands)
        for band, gl_image, ref_image in zip(ref.bands, gl_votes, ref_votes):
            assert gl_image.shape == ref_image.shape
            for channel in range(ref_image.shape[2]):
                a, b = gl_image[..., channel].ravel(), ref_image[..., channel].ravel()
                correlation = float(np.corrcoef(a, b)[0, 1])
                assert correlation > 0.999, (band, channel, correlation)
                assert abs(a.sum() - b.sum()) <= 0.005 * b.sum(), (band, channel)
        gl_edges = gl._gl.edge_counts()
        ref_edges = [edges.count for edges in compute_edges(gray, config)]
        for gl_count, ref_count in zip(gl_edges, ref_edges):
            assert abs(gl_count - ref_count) <= max(2, 0.002 * ref_count)
        assert_same_candidates(gl.detect(gray), ref.detect(gray))


def assert_same_candidates(gl: tuple[Candidate, ...], ref: tuple[Candidate, ...]) -> None:
    assert gl and ref
    matched = 0
    for candidate in ref:
        twins = [other for other in gl if other.band == candidate.band
                 and math.hypot(other.x_px - candidate.x_px, other.y_px - candidate.y_px) <= 1.0]
        if twins:
            matched += 1
            assert abs(twins[0].score - candidate.score) <= 0.02 * candidate.score
            assert abs(twins[0].radius_px - candidate.radius_px) <= 0.05 * candidate.radius_px
    # near-ties at the bottom of the list may swap; the leaders must be the same
    assert matched >= len(ref) - 1
    for first_gl, first_ref in zip(gl[:3], ref[:3]):
        assert math.hypot(first_gl.x_px - first_ref.x_px, first_gl.y_px - first_ref.y_px) <= 1.0


VOTE_METHODS = ('raster', 'scatter')


def with_method(config: DetectorConfig, vote_method: str) -> DetectorConfig:
    return dataclasses.replace(config, vote_method=vote_method)


@pytest.mark.parametrize('vote_method', VOTE_METHODS)
@pytest.mark.parametrize('name', sorted(CONFIGS))
def test_backends_agree_on_synthetic_scene(name: str, vote_method: str) -> None:
    assert_backends_agree(synthetic_scene(), with_method(CONFIGS[name], vote_method))


@pytest.mark.parametrize('vote_method', VOTE_METHODS)
def test_backends_agree_on_real_scene(gtsdb_scene: np.ndarray, vote_method: str) -> None:
    assert_backends_agree(gtsdb_scene, with_method(CONFIGS['default'], vote_method))


@pytest.mark.parametrize('vote_method', VOTE_METHODS)
def test_backends_agree_at_640x480(gtsdb_scene: np.ndarray, vote_method: str) -> None:
    assert_backends_agree(np.ascontiguousarray(gtsdb_scene[:, 88:728]),
                          with_method(CONFIGS['default'], vote_method))


def test_scatter_votes_are_reproducible(gtsdb_scene: np.ndarray) -> None:
    """Integer sums do not depend on the (atomic, unordered) edge list order."""
    config = with_method(CONFIGS['default'], 'scatter')
    with Detector(config, backend='gl') as gl:
        first = gl.vote_images(gtsdb_scene)
        second = gl.vote_images(gtsdb_scene[::-1, ::-1].copy())
        third = gl.vote_images(gtsdb_scene)
    for one, other in zip(first, third):
        np.testing.assert_array_equal(one, other)
    assert any(not np.array_equal(one, other) for one, other in zip(first, second))


def test_auto_vote_method_is_scatter_and_explicit_methods_stand() -> None:
    assert resolve_vote_method('auto') == 'scatter'
    assert resolve_vote_method('raster') == 'raster'
    assert resolve_vote_method('scatter') == 'scatter'
