"""The detector's area scaling gives ``cv2.resize(..., INTER_AREA)``'s pixels, bit for bit."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.area_scaling import group_weights, scale_area
from speed_sign_detector.detection.detector import working_frame

# (height, width) -> (width, height): the camera sizes scaled to detection_width_px 960
# (4/3, 3/2, 8/5, 5/3, 8/3 on an axis), 640, a whole-number factor and sizes no small
# ratio divides (cv2.resize's own path)
SIZES = [((720, 1280), (960, 540)), ((1080, 1440), (960, 720)), ((864, 1536), (960, 540)),
         ((900, 1600), (960, 540)), ((1440, 2560), (960, 540)), ((600, 800), (640, 480)),
         ((720, 1280), (800, 450)), ((1080, 1920), (960, 540)), ((768, 1366), (960, 540)),
         ((101, 203), (150, 70))]


@pytest.mark.parametrize(('shape', 'size'), SIZES)
def test_area_scaling_equals_opencv_inter_area(shape: tuple[int, int],
                                               size: tuple[int, int]) -> None:
    rng = np.random.default_rng(3)
    stripes = np.broadcast_to((np.arange(shape[1]) % 2 * 255).astype(np.uint8), shape)
    for gray in (rng.integers(0, 256, shape, dtype=np.uint8),   # every rounding tie
                 np.ascontiguousarray(stripes), np.full(shape, 255, np.uint8)):
        expected = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
        found = scale_area(gray, size)
        assert found.dtype == np.uint8 and found.shape == expected.shape
        np.testing.assert_array_equal(found, expected)


def test_group_weights_cover_each_target_pixel_once() -> None:
    weights = group_weights(1280, 960)   # 4 source pixels -> 3 target pixels
    np.testing.assert_array_equal(weights, [[3, 1, 0, 0], [0, 2, 2, 0], [0, 0, 1, 3]])
    assert group_weights(1366, 960) is None   # 683/480: groups too large
    assert group_weights(960, 960) is None


def test_working_frame_of_a_region_of_interest_is_scaled_by_area() -> None:
    gray = np.random.default_rng(4).integers(0, 256, (720, 1280), dtype=np.uint8)
    config = DetectorConfig(roi_top_fraction=0.25, roi_bottom_fraction=0.75)
    working = working_frame(gray, config)
    np.testing.assert_array_equal(
        working.image, cv2.resize(gray[180:540], (960, 270), interpolation=cv2.INTER_AREA))
    assert working.scale_x == working.scale_y == 1280 / 960 and working.top_row == 180
