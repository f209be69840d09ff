"""Shared fixtures: the real data folder, and a per-module ROS domain."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: ../shared/data relative to the project root (see that folder's README).
SHARED_DATA_DIR = PROJECT_ROOT.parent / 'shared' / 'data'


@pytest.fixture(scope='session')
def shared_data_dir() -> Path:
    """The real-data folder; tests needing it skip with the reason when it is absent."""
    if not SHARED_DATA_DIR.is_dir():
        pytest.skip(f'real data not available: {SHARED_DATA_DIR} does not exist '
                    '(it lives beside the project checkout, see README "Data")')
    return SHARED_DATA_DIR


@pytest.fixture(scope='session')
def gtsdb_scene(shared_data_dir: Path) -> np.ndarray:
    """A real GTSDB road scene (816x480 gray) with plenty of clutter."""
    path = shared_data_dir / 'gtsdb-dev' / 'images' / '00001.jpg'
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    assert gray is not None, f'cannot read {path}'
    return gray


@pytest.fixture(scope='module')
def bank_config(pytestconfig: pytest.Config, tmp_path_factory: pytest.TempPathFactory
                ) -> Path:
    """A node parameter file caching the classifier's filter banks between runs."""
    cache_dir = pytestconfig.cache.mkdir('speed_sign_filter_banks')
    path = tmp_path_factory.mktemp('config') / 'params.yaml'
    path.write_text(f'classifier:\n  cache_dir: "{cache_dir}"\n')
    return path
