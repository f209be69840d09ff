"""Detection at a working resolution, recognition at full resolution, a region of interest.

Frames wider than ``detector.detection_width_px`` are scaled down (cv2.INTER_AREA) for
the detector; the candidates come back in full-resolution pixels and the classifier
reads them there. Runs the real GL backend (llvmpipe here) and the numpy reference.
"""
from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest
from scene_helpers import paste, textured_background

from speed_sign_detector.config import ClassifierConfig, DetectorConfig, PipelineConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector, working_frame
from speed_sign_detector.errors import ConfigError, InvalidFrameError
from speed_sign_detector.pipeline import Pipeline
from speed_sign_detector.recognition.templates import render_sign

FULL_HD = (1920, 1080)


def scene(width: int, height: int, signs: list[tuple[str, int, int, int]], seed: int = 5
          ) -> tuple[np.ndarray, list[tuple[float, float, float]]]:
    """Rendered signs ``(kind, diameter px, left, top)`` pasted on road-like clutter.

    Returns the gray frame and each sign's (centre x, centre y, outer radius) in pixels
    (pixel (i, j) has its centre at x = j, y = i)."""
    frame = textured_background(seed, width, height)
    truth = []
    for kind, diameter, left, top in signs:
        bgr, alpha = render_sign(kind, diameter)
        paste(frame, bgr, alpha, left, top)
        truth.append((left + diameter / 2 - 0.5, top + diameter / 2 - 0.5, diameter / 2))
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), truth


def centre_tolerance_px(detector: Detector, candidate: Candidate, scale: float) -> float:
    """How far a candidate's centre may lie from the truth, full-resolution pixels.

    The band that found it votes into an image of ``2 ** target_level`` working pixels
    per vote pixel; the sub-pixel fit puts the centre within half a vote pixel (at least
    the 1 px the detector's own tests allow at full resolution), and each working pixel
    is ``scale`` full-resolution pixels."""
    vote_pixel = 2 ** detector.bands[candidate.band].target_level
    return scale * max(1.0, vote_pixel / 2)


def radius_within_size_search(radius_px: float, outer_radius_px: float) -> bool:
    """True when the classifier's size search reaches the sign from this candidate
    radius: it correlates at radius x candidate_radius_scale, with filters within
    size_search_ratio of that."""
    defaults = ClassifierConfig()
    searched = radius_px * defaults.candidate_radius_scale
    ratio = defaults.size_search_ratio
    return outer_radius_px / ratio <= searched <= outer_radius_px * ratio


def nearest(candidates: tuple[Candidate, ...], x: float, y: float) -> Candidate:
    return min(candidates, key=lambda c: math.hypot(c.x_px - x, c.y_px - y))


@pytest.fixture(scope='module', params=['gl', 'numpy'])
def backend(request: pytest.FixtureRequest) -> str:
    return request.param


def test_full_hd_signs_are_found_at_full_resolution_coordinates(backend: str) -> None:
    """A sign of radius 80 px (twice the detector's largest radius) and one of 20 px at
    1920x1080: both found at their full-resolution centre and size."""
    gray, truth = scene(*FULL_HD, [('50', 160, 1320, 320), ('80', 40, 680, 280)])
    config = DetectorConfig()
    scale = FULL_HD[0] / config.detection_width_px
    assert scale == 2.0  # the default working width halves a full-HD frame
    with Detector(config, backend=backend) as detector:
        candidates = detector.detect(gray)
        for x, y, outer_radius in truth:
            best = nearest(candidates, x, y)
            error = math.hypot(best.x_px - x, best.y_px - y)
            assert error <= centre_tolerance_px(detector, best, scale), (best, (x, y))
            assert radius_within_size_search(best.radius_px, outer_radius), (best,
                                                                             outer_radius)


def test_mapping_back_is_exact(backend: str) -> None:
    """Detecting a frame at the working resolution gives the candidates of the scaled
    region itself, mapped by x = (x' + 0.5) s - 0.5, y = top + (y' + 0.5) s - 0.5,
    r = r' s (the same pixels voted: exact)."""
    gray, _ = scene(*FULL_HD, [('50', 150, 1300, 500), ('30', 60, 400, 600)])
    config = DetectorConfig(detection_width_px=960, roi_top_fraction=0.25)
    top = round(0.25 * FULL_HD[1])
    band = gray[top:]
    scaled = cv2.resize(band, (960, round(band.shape[0] * 960 / FULL_HD[0])),
                        interpolation=cv2.INTER_AREA)
    scale_x = FULL_HD[0] / scaled.shape[1]
    scale_y = band.shape[0] / scaled.shape[0]
    with Detector(config, backend=backend) as working, \
            Detector(dataclasses.replace(config, detection_width_px=0, roi_top_fraction=0.0),
                     backend=backend) as plain:
        found = working.detect(gray)
        reference = plain.detect(scaled)
    assert len(found) == len(reference) > 0
    for mapped, original in zip(found, reference):
        assert mapped.x_px == pytest.approx((original.x_px + 0.5) * scale_x - 0.5, abs=1e-3)
        assert mapped.y_px == pytest.approx(top + (original.y_px + 0.5) * scale_y - 0.5,
                                            abs=1e-3)
        assert mapped.radius_px == pytest.approx(original.radius_px * (scale_x + scale_y) / 2,
                                                 rel=1e-5)
        assert (mapped.score, mapped.band) == (original.score, original.band)


def test_full_hd_signs_are_read_from_full_resolution_pixels(bank_config_pipeline: Pipeline
                                                            ) -> None:
    """The classifier reads both signs right from the 1920x1080 pixels."""
    gray, truth = scene(*FULL_HD, [('50', 160, 1320, 320), ('80', 40, 680, 280)])
    result = bank_config_pipeline.process(gray, stamp_s=0.0)
    assert (result.width_px, result.height_px) == FULL_HD
    for (x, y, outer_radius), kind in zip(truth, ('50', '80')):
        detection = min(result.detections, key=lambda d: math.hypot(
            d.candidate.x_px - x, d.candidate.y_px - y))
        assert math.hypot(detection.candidate.x_px - x, detection.candidate.y_px - y) \
            < 0.25 * outer_radius
        assert detection.classification is not None
        assert detection.classification.label == kind, detection


@pytest.fixture(scope='module')
def bank_config_pipeline(pytestconfig: pytest.Config) -> Pipeline:
    """The default pipeline (GL where it can), its banks cached between runs."""
    cache_dir = pytestconfig.cache.mkdir('speed_sign_filter_banks')
    config = PipelineConfig(classifier=ClassifierConfig(cache_dir=str(cache_dir)))
    with Pipeline(config) as pipeline:
        yield pipeline


def test_signs_outside_the_region_of_interest_are_not_searched(backend: str) -> None:
    """A sign in the top fifth (the sky band) and one in the bottom fifth (the bonnet
    band): with the region of interest between them neither is a candidate, and no
    candidate lies outside the band; without it both are found."""
    width, height = 1280, 720
    gray, truth = scene(width, height, [('50', 70, 300, 20), ('60', 70, 900, 630),
                                        ('100', 70, 600, 320)])
    inside = DetectorConfig(roi_top_fraction=0.2, roi_bottom_fraction=0.8)
    with Detector(DetectorConfig(), backend=backend) as everywhere, \
            Detector(inside, backend=backend) as banded:
        all_candidates = everywhere.detect(gray)
        band_candidates = banded.detect(gray)
    for x, y, radius in truth:
        best = nearest(all_candidates, x, y)
        assert math.hypot(best.x_px - x, best.y_px - y) < 0.25 * radius
    top_row, bottom_row = round(0.2 * height), round(0.8 * height)
    assert band_candidates
    assert all(top_row - 0.5 <= c.y_px <= bottom_row - 0.5 for c in band_candidates)
    for x, y, radius in truth[:2]:
        assert all(math.hypot(c.x_px - x, c.y_px - y) > radius for c in band_candidates)
    x, y, radius = truth[2]
    best = nearest(band_candidates, x, y)
    assert math.hypot(best.x_px - x, best.y_px - y) < 0.25 * radius


@pytest.mark.parametrize('size', [(640, 480), (816, 480), (960, 540)])
def test_frames_up_to_the_working_width_are_detected_as_they_are(backend: str,
                                                                 size: tuple[int, int]
                                                                 ) -> None:
    """The defaults leave a 640x480 (or 816x480 GTSDB, 960x540) frame untouched: the
    same candidates as detection at full resolution, bit for bit."""
    gray, _ = scene(*size, [('50', 50, 100, 100), ('30', 24, size[0] - 120, 200)])
    working = working_frame(gray, DetectorConfig())
    assert (working.scale_x, working.scale_y, working.top_row) == (1.0, 1.0, 0)
    with Detector(DetectorConfig(), backend=backend) as default, \
            Detector(DetectorConfig(detection_width_px=0), backend=backend) as full:
        assert default.detect(gray) == full.detect(gray)


def test_region_of_interest_must_be_a_band() -> None:
    with pytest.raises(ConfigError, match='roi_bottom_fraction'):
        DetectorConfig(roi_top_fraction=0.6, roi_bottom_fraction=0.4)
    with pytest.raises(ConfigError, match='detection_width_px'):
        DetectorConfig(detection_width_px=-1)


def test_a_band_too_thin_to_search_names_the_parameters() -> None:
    gray = np.zeros((480, 640), np.uint8)
    with Detector(DetectorConfig(roi_top_fraction=0.45, roi_bottom_fraction=0.5),
                  backend='numpy') as detector:
        with pytest.raises(InvalidFrameError, match='roi_top_fraction') as caught:
            detector.detect(gray)
    assert 'voting window' in str(caught.value)
