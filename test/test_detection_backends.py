"""The GL backend computes the numpy reference's maths (up to rasterization rules)."""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_detection_synthetic import ring_frame

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.detection.voting_numpy import compute_edges

CONFIGS = {
    'default': DetectorConfig(),
    'both_flat_linear': DetectorConfig(polarity='both', vote_profile='flat',
                                       contrast='linear', edge_support=2,
                                       vote_pixels_per_radius=0.0),
}


@pytest.fixture(scope='module')
def scene(shared_data_dir: Path) -> np.ndarray:
    """A real GTSDB road scene (816x480 gray) with plenty of clutter."""
    path = shared_data_dir / 'gtsdb-dev' / 'images' / '00001.jpg'
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    assert gray is not None, f'cannot read {path}'
    return gray


def synthetic_scene() -> np.ndarray:
    frame = ring_frame(320, 240, (80.0, 70.0), 9.0)
    for centre, radius in (((200.0, 90.0), 20.0), ((150.0, 180.0), 6.0)):
        other = ring_frame(320, 240, centre, radius)
        frame = np.where(other != 110, other, frame)
    rng = np.random.default_rng(5)
    return np.clip(frame + rng.normal(0.0, 6.0, frame.shape), 0, 255).astype(np.uint8)


def assert_backends_agree(gray: np.ndarray, config: DetectorConfig) -> None:
    with Detector(config, backend='gl') as gl, Detector(config, backend='numpy') as ref:
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


@pytest.mark.parametrize('name', sorted(CONFIGS))
def test_backends_agree_on_synthetic_scene(name: str) -> None:
    assert_backends_agree(synthetic_scene(), CONFIGS[name])


def test_backends_agree_on_real_scene(scene: np.ndarray) -> None:
    assert_backends_agree(scene, CONFIGS['default'])


def test_backends_agree_at_640x480(scene: np.ndarray) -> None:
    assert_backends_agree(np.ascontiguousarray(scene[:, 88:728]), CONFIGS['default'])
