"""The CPU edge extraction, with its reused buffers, gives bitwise the edge lists of the
earlier allocating version (kept here as the reference) on real and synthetic frames, and
its workspace never leaks one frame, thread or size into another."""
from __future__ import annotations

import dataclasses
import math
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_detection_backends import synthetic_scene

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.gradients import (
    SUPPORT_ANGLE_DEG,
    EdgeList,
    gray_lookup,
)
from speed_sign_detector.detection.gradients_cpu import (
    MAX_WORKSPACE_SHAPES,
    EdgeWorkspace,
    compute_edges_fast,
    thread_workspace,
)
from speed_sign_detector.detection.voting_numpy import plan_bands, pyramid_levels

EDGE_CONFIGS = {
    'default': DetectorConfig(),
    'linear_support_2': DetectorConfig(contrast='linear', edge_support=2),
    'no_thinning': DetectorConfig(thin_edges=False),
    'no_support': DetectorConfig(edge_support=0),
    'threshold_0_unthinned': DetectorConfig(gradient_threshold=0.0, thin_edges=False),
    'deep_pyramid': DetectorConfig(max_radius_px=80.0, max_pyramid_level=3,
                                   vote_pixels_per_radius=1.0),
}
GTSDB_SCENES = ('00001.jpg', '00040.jpg', '00120.jpg', '00233.jpg', '00371.jpg')


# --- the reference: the allocating version this module had before its workspace ---------

def _reference_edges(gray: np.ndarray, config: DetectorConfig) -> list[EdgeList]:
    lookup = gray_lookup(config.contrast, config.log_offset_gray)
    pyramid = [cv2.LUT(gray, lookup)]
    for _ in range(1, pyramid_levels(plan_bands(config))):
        previous = pyramid[-1]
        height, width = previous.shape[0] // 2, previous.shape[1] // 2
        pyramid.append(cv2.resize(previous[:2 * height, :2 * width], (width, height),
                                  interpolation=cv2.INTER_AREA))
    return [_reference_level(image, level, config.gradient_threshold, config.thin_edges,
                             config.edge_support)
            for level, image in enumerate(pyramid)]


def _reference_level(image: np.ndarray, level: int, threshold: float, thin: bool,
                     min_support: int) -> EdgeList:
    height, width = image.shape
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    magnitude = cv2.magnitude(gx, gy)
    for array in (gx, gy, magnitude):
        array[0, :] = array[-1, :] = 0.0
        array[:, 0] = array[:, -1] = 0.0
    keep = magnitude >= np.float32(threshold)
    keep[0, :] = keep[-1, :] = False
    keep[:, 0] = keep[:, -1] = False
    flat_gx, flat_gy, flat_magnitude = gx.ravel(), gy.ravel(), magnitude.ravel()
    pixels = np.flatnonzero(keep)
    if thin and pixels.size:
        px, py, centre = flat_gx[pixels], flat_gy[pixels], flat_magnitude[pixels]
        ax, ay = np.abs(px), np.abs(py)
        tan_22 = np.float32(0.41421357)
        step = np.where(ay <= tan_22 * ax, 1, np.where(
            ax <= tan_22 * ay, width, np.where(px * py > 0, width + 1, width - 1)))
        pixels = pixels[(centre > flat_magnitude[pixels - step])
                        & (centre >= flat_magnitude[pixels + step])]
    if min_support > 0 and pixels.size:
        unit_x = np.zeros(flat_magnitude.shape, np.float32)
        unit_y = np.zeros(flat_magnitude.shape, np.float32)
        with np.errstate(divide='ignore', invalid='ignore'):
            unit_x[pixels] = flat_gx[pixels] / flat_magnitude[pixels]
            unit_y[pixels] = flat_gy[pixels] / flat_magnitude[pixels]
        own_x, own_y = unit_x[pixels], unit_y[pixels]
        cosine = np.float32(math.cos(math.radians(SUPPORT_ANGLE_DEG)))
        count = np.zeros(pixels.shape, np.int32)
        for offset in (-width - 1, -width, -width + 1, -1, 1, width - 1, width, width + 1):
            neighbours = pixels + offset
            count += (own_x * unit_x[neighbours] + own_y * unit_y[neighbours]) >= cosine
        pixels = pixels[count >= min_support]
    rows, cols = np.divmod(pixels, width)
    return EdgeList(cols.astype(np.float32), rows.astype(np.float32), flat_gx[pixels],
                    flat_gy[pixels], level, width, height)


# --- helpers --------------------------------------------------------------------------

def assert_bitwise_equal(fast: list[EdgeList], reference: list[EdgeList]) -> None:
    """Same levels, sizes, and x, y, gx, gy arrays to the bit (dtype included)."""
    assert len(fast) == len(reference)
    for got, want in zip(fast, reference, strict=True):
        assert (got.level, got.width_px, got.height_px) == (
            want.level, want.width_px, want.height_px)
        for field in ('x_px', 'y_px', 'gx', 'gy'):
            got_array, want_array = getattr(got, field), getattr(want, field)
            assert got_array.dtype == want_array.dtype == np.float32, field
            assert got_array.shape == want_array.shape, (got.level, field)
            assert got_array.tobytes() == want_array.tobytes(), (got.level, field)


def synthetic_drive_frame() -> np.ndarray:
    """A 641x481 (odd sizes: the pyramid crops) frame of rings, a gradient sky and noise."""
    scene = cv2.resize(synthetic_scene(), (641, 481), interpolation=cv2.INTER_LINEAR)
    rows = np.linspace(-40.0, 40.0, 481, dtype=np.float32)[:, None]
    rng = np.random.default_rng(11)
    noisy = scene.astype(np.float32) + rows + rng.normal(0.0, 4.0, scene.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)


def gtsdb_scene_frames(shared_data_dir: Path) -> list[np.ndarray]:
    folder = shared_data_dir / 'gtsdb-dev' / 'images'
    if not folder.is_dir():
        pytest.skip(f'gtsdb-dev scenes not available: {folder} does not exist')
    frames = []
    for name in GTSDB_SCENES:
        gray = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE)
        assert gray is not None, f'cannot read {folder / name}'
        frames.append(gray)
    return frames


def unit_buffers_are_zero(workspace: EdgeWorkspace) -> bool:
    return all(not buffers.unit_pairs.any() for buffers in workspace._levels.values())


# --- tests ----------------------------------------------------------------------------

@pytest.mark.parametrize('name', EDGE_CONFIGS)
def test_synthetic_frames_bitwise_equal(name: str) -> None:
    config = EDGE_CONFIGS[name]
    workspace = EdgeWorkspace()
    for gray in (synthetic_scene(), synthetic_drive_frame()):
        reference = _reference_edges(gray, config)
        assert sum(edges.count for edges in reference) > 100
        assert_bitwise_equal(compute_edges_fast(gray, config, workspace), reference)
        assert_bitwise_equal(compute_edges_fast(gray, config), reference)  # thread's
    assert unit_buffers_are_zero(workspace)


@pytest.mark.parametrize('name', ['default', 'linear_support_2', 'no_thinning'])
def test_gtsdb_scenes_bitwise_equal(shared_data_dir: Path, name: str) -> None:
    """Real road scenes at their 816x480 and at the 960x540 a 720p camera is detected at,
    one workspace across all (the sizes alternate, the buffers are reused)."""
    config = EDGE_CONFIGS[name]
    workspace = EdgeWorkspace()
    for gray in gtsdb_scene_frames(shared_data_dir):
        for frame in (gray, cv2.resize(gray, (960, 540), interpolation=cv2.INTER_AREA)):
            reference = _reference_edges(frame, config)
            assert reference[0].count > 1000
            assert_bitwise_equal(compute_edges_fast(frame, config, workspace), reference)
    assert unit_buffers_are_zero(workspace)


def test_results_do_not_alias_the_workspace() -> None:
    """An edge list stays as it was when the next frame reuses the buffers."""
    config = DetectorConfig()
    workspace = EdgeWorkspace()
    first, second = synthetic_drive_frame(), np.ascontiguousarray(synthetic_drive_frame()[::-1])
    kept = compute_edges_fast(first, config, workspace)
    compute_edges_fast(second, config, workspace)
    assert_bitwise_equal(kept, _reference_edges(first, config))


def test_threads_get_their_own_workspace() -> None:
    """Two threads extracting at once (two detectors) use separate buffers and both get
    the reference's edges."""
    config = DetectorConfig()
    frames = [synthetic_drive_frame(), np.ascontiguousarray(synthetic_drive_frame()[:, ::-1])]
    references = [_reference_edges(gray, config) for gray in frames]
    results: dict[int, list[list[EdgeList]]] = {}
    workspaces: dict[int, EdgeWorkspace] = {}
    start = threading.Barrier(2)

    def work(index: int) -> None:
        start.wait()
        workspaces[index] = thread_workspace()
        results[index] = [compute_edges_fast(frames[index], config) for _ in range(5)]

    threads = [threading.Thread(target=work, args=(index,)) for index in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert workspaces[0] is not workspaces[1]
    assert workspaces[0] is not thread_workspace()
    for index, reference in enumerate(references):
        for edges in results[index]:
            assert_bitwise_equal(edges, reference)


def test_workspace_keeps_a_bounded_number_of_sizes() -> None:
    """A stream of changing frame sizes neither grows the workspace without bound nor
    changes the edges."""
    config = dataclasses.replace(DetectorConfig(), edge_support=2)
    workspace = EdgeWorkspace()
    base = synthetic_drive_frame()
    for shrink in range(12):
        gray = np.ascontiguousarray(base[:481 - 7 * shrink, :641 - 5 * shrink])
        assert_bitwise_equal(compute_edges_fast(gray, config, workspace),
                             _reference_edges(gray, config))
        assert len(workspace._levels) <= MAX_WORKSPACE_SHAPES
    assert unit_buffers_are_zero(workspace)
