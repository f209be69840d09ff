"""The packed integer format of the scatter votes: its geometric bound holds."""
from __future__ import annotations

import math

import numpy as np
import pytest

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.gradients import EdgeList
from speed_sign_detector.detection.vote_fixed_point import (
    MIN_COUNT_ONE,
    MIN_WEIGHT_ONE,
    UNPACKED_ONE,
    vote_fixed_point,
    votes_per_pixel_bound,
)
from speed_sign_detector.detection.voting_numpy import RadiusBand, plan_bands, vote_band

DEFAULT_BANDS = plan_bands(DetectorConfig())


def converging_edges(band: RadiusBand, target: tuple[int, int],
                     frame_size: tuple[int, int]) -> EdgeList:
    """Every edge-level pixel of the frame, its gradient pointing at one vote pixel.

    The worst case for that pixel's sums: every edge pixel within reach votes for it with
    a full profile.
    """
    width, height = frame_size[0] >> band.level, frame_size[1] >> band.level
    # the vote pixel's centre in edge-level coordinates (vote x = (edge x + 0.5) s - 0.5)
    centre_x = (target[0] + 0.5) / band.shrink - 0.5
    centre_y = (target[1] + 0.5) / band.shrink - 0.5
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    gx, gy = centre_x - x.ravel(), centre_y - y.ravel()
    keep = np.hypot(gx, gy) > 0.0
    return EdgeList(x.ravel()[keep], y.ravel()[keep], gx[keep], gy[keep], band.level,
                    width, height)


@pytest.mark.parametrize('band', DEFAULT_BANDS, ids=lambda band: f'band{band.index}')
def test_bound_holds_for_edges_converging_on_a_pixel(band: RadiusBand) -> None:
    frame_size = (256, 256)
    target = (96 >> band.target_level, 96 >> band.target_level)
    votes = vote_band(converging_edges(band, target, frame_size), band, (1.0, -1.0),
                      frame_size)
    weight, count = votes[target[1], target[0]]
    bound = votes_per_pixel_bound(*band.level_radii)
    assert count <= bound
    # not vacuous: the edges between the band's radii all vote at full profile
    assert count >= 0.5 * bound
    assert count >= math.pi * (band.level_radii[1] ** 2 - band.level_radii[0] ** 2) * 0.9
    assert weight <= bound * 2.0 / band.level_radii[0]
    # and no other pixel gets more than the bound either
    assert votes[..., 1].max() <= bound


@pytest.mark.parametrize('config', [
    DetectorConfig(),
    DetectorConfig(vote_pixels_per_radius=0.0),
    DetectorConfig(radius_bands=2),
    DetectorConfig(radius_bands=1, vote_pixels_per_radius=0.0),
    DetectorConfig(min_radius_px=2.0, max_radius_px=64.0, radius_bands=6),
], ids=['default', 'edge_level_votes', 'two_bands', 'one_band', 'six_bands'])
def test_packed_fields_cannot_overflow(config: DetectorConfig) -> None:
    for band in plan_bands(config):
        bands = (band,)
        fixed_point = vote_fixed_point(bands)
        votes = votes_per_pixel_bound(*band.level_radii)
        if not fixed_point.packed:
            assert fixed_point.weight_one == fixed_point.count_one == UNPACKED_ONE
            continue
        assert fixed_point.count_one >= MIN_COUNT_ONE
        assert fixed_point.weight_one >= MIN_WEIGHT_ONE
        assert votes * fixed_point.count_one <= fixed_point.count_mask
        most_weight = votes * (fixed_point.weight_one * 2.0 / band.level_radii[0] + 0.5)
        assert most_weight < 2 ** (32 - fixed_point.count_bits)


def test_default_bands_pack_and_wide_bands_do_not() -> None:
    assert all(vote_fixed_point((band,)).packed for band in DEFAULT_BANDS)
    # one band from 3.5 to 40 px on the full-resolution edges: up to ~6,000 votes a pixel
    wide = plan_bands(DetectorConfig(radius_bands=1, vote_pixels_per_radius=0.0))
    assert not vote_fixed_point(wide).packed
