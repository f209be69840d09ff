"""The CPU edge extraction taken in strips finds the edges of the whole level, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest
from test_detection_backends import synthetic_scene

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection import gradients_cpu
from speed_sign_detector.detection.gradients_cpu import compute_edges_fast

CONFIGS = [DetectorConfig(), DetectorConfig(thin_edges=False, edge_support=3),
           DetectorConfig(edge_support=0), DetectorConfig(contrast='linear', edge_support=2)]


def assert_strips_equal_whole(gray: np.ndarray, monkeypatch: pytest.MonkeyPatch) -> None:
    for config in CONFIGS:
        monkeypatch.setattr(gradients_cpu, 'STRIP_ROWS', 1 << 16)   # the whole level
        whole = compute_edges_fast(gray, config)
        assert whole[0].count > 0
        for strip_rows in (1, 7, 64):
            monkeypatch.setattr(gradients_cpu, 'STRIP_ROWS', strip_rows)
            for found, expected in zip(compute_edges_fast(gray, config), whole, strict=True):
                assert found.gx.dtype == expected.gx.dtype == np.float32
                for field in ('x_px', 'y_px', 'gx', 'gy'):
                    np.testing.assert_array_equal(getattr(found, field),
                                                  getattr(expected, field), err_msg=field)


def test_strips_find_the_edges_of_the_whole_level(monkeypatch: pytest.MonkeyPatch) -> None:
    gray = synthetic_scene()
    assert_strips_equal_whole(gray, monkeypatch)
    assert_strips_equal_whole(np.ascontiguousarray(gray[:131, :97]), monkeypatch)


def test_strips_find_the_edges_of_a_real_scene(gtsdb_scene: np.ndarray,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    assert_strips_equal_whole(gtsdb_scene, monkeypatch)
