"""Non-maximum suppression of the block maxima (``candidates.select_candidates``), exactly:
hand-made maxima, every backend's selection step."""
from __future__ import annotations

import numpy as np
import pytest

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import (
    ENCLOSED_CENTRE_FRACTION,
    BlockMaxima,
    Candidate,
    best_first,
    block_maxima,
    is_same_sign,
    select_candidates,
)
from speed_sign_detector.detection.voting_numpy import CHANNELS, plan_bands


def maxima(*blocks: tuple[float, float, float, float]) -> BlockMaxima:
    """One row of blocks, each (score, x, y, radius)."""
    score, x_px, y_px, radius_px = (np.asarray([[block[i] for block in blocks]], np.float32)
                                    for i in range(4))
    return BlockMaxima(score, x_px, y_px, radius_px, np.zeros_like(score, np.int32))


def test_best_first_is_a_prefix_of_the_stable_order() -> None:
    """The partial order the selection visits is the stable sort's prefix, ties (equal
    scores, -inf) included, and at least as long as asked for."""
    generator = np.random.default_rng(3)
    scores = np.round(generator.normal(size=500), 1).astype(np.float32)  # many ties
    scores[::7] = -np.inf
    full = np.argsort(-scores, kind='stable')
    for count in (0, 1, 5, 64, 499, 500, 2000):
        order = best_first(scores, count)
        assert order.size >= min(count, scores.size)
        np.testing.assert_array_equal(order, full[:order.size])
    # the selection over a frame's maxima visits them in that order whatever it sorts first
    found = maxima(*[(float(score), 20.0 * index, 0.0, 5.0)
                     for index, score in enumerate(scores)])
    expected = [(20.0 * int(index), 0.0, 5.0) for index in full[:40]
                if scores[index] > 0.0]
    assert centres(select_candidates(found, 40, 0.0, 1.0, 2.0)) == expected


def test_selection_visits_more_maxima_where_suppression_leaves_too_few() -> None:
    """Where the best maxima are mostly one sign's (suppressed), the selection visits four
    times as many again and again, and selects what a plain pass over every maximum in
    the stable order selects (written out here, independently)."""
    generator = np.random.default_rng(11)
    count = 2000
    # 1,600 maxima crowd around 8 signs (suppressed by the best of each), then 400 apart
    crowded = generator.integers(0, 8, 1600)
    x_px = np.concatenate([100.0 * crowded + generator.uniform(-3, 3, 1600),
                           1000.0 + 30.0 * np.arange(400)])
    score = np.concatenate([generator.uniform(0.5, 1.0, 1600),
                            generator.uniform(0.01, 0.5, 400)]).astype(np.float32)
    found = maxima(*[(float(score[i]), float(x_px[i]), 0.0, 5.0) for i in range(count)])
    plain: list[Candidate] = []
    for index in np.argsort(-score, kind='stable'):
        candidate = Candidate(float(found.x_px[0, index]), 0.0, 5.0, float(score[index]), 0)
        if len(plain) < 40 and not any(is_same_sign(candidate, other, 1.0, 2.0)
                                       for other in plain):
            plain.append(candidate)
    selected = select_candidates(found, 40, 0.0, 1.0, 2.0)
    assert len(selected) == 40 and list(selected) == plain
    assert len({round(c.x_px, -2) for c in selected if c.x_px < 900}) == 8


def test_every_band_keeps_its_block_maximum() -> None:
    """A band that loses a block to a smaller band's better score keeps its own maximum
    there (slot ``band`` of the block), and the selection sees both."""
    bands = plan_bands(DetectorConfig())
    height, width = 64, 64
    votes = [np.zeros((height // band.target_scale, width // band.target_scale, CHANNELS),
                      np.float32) for band in bands]
    # in block (1, 2) (pixels 8-15, 16-23): a loop of radius 5 in band 0 at (20, 9),
    # weaker votes of a ring of radius 16 in band 2 at (17.5, 9.5) (its level's pixel (4, 2))
    votes[0][9, 20] = (2.0, 10.0)
    votes[2][2, 4] = (1.0, 8.0)   # count / weight x the band's scale 2: radius 16
    normalisers = [0.5] * len(bands)
    found = block_maxima(votes, bands, (height, width), 8, normalisers)
    assert found.score.shape == (8, 8, len(bands))
    np.testing.assert_array_equal(found.band[1, 2], [band.index for band in bands])
    assert found.score[1, 2, 0] == pytest.approx(1.0)
    assert found.radius_px[1, 2, 0] == pytest.approx(5.0)
    assert found.score[1, 2, 2] == pytest.approx(0.5)
    assert found.radius_px[1, 2, 2] == pytest.approx(16.0)
    assert (found.x_px[1, 2, 2], found.y_px[1, 2, 2]) == pytest.approx((17.5, 9.5))
    assert np.count_nonzero(found.score > 0.0) == 2
    assert [candidate.band for candidate in select_candidates(found, 7, 0.0, 1.0, 2.0)] \
        == [0, 2]


def centres(candidates: tuple[Candidate, ...]) -> list[tuple[float, float, float]]:
    return [(c.x_px, c.y_px, c.radius_px) for c in candidates]


def test_ring_around_a_better_small_circle_is_kept() -> None:
    # a digit's loop (radius 5, the best score) 4 px from the centre of the sign's ring
    # (radius 17), and a second loop beside it
    found = maxima((0.9, 100.0, 104.0, 5.0), (0.8, 100.0, 100.0, 17.0),
                   (0.7, 109.0, 104.0, 5.0))
    # kept, the ring suppresses the second loop as its own sign
    assert centres(select_candidates(found, 7, 0.0, 1.0, 2.0)) == [
        (100.0, 104.0, 5.0), (100.0, 100.0, 17.0)]
    # suppressed as the first loop's sign, the ring leaves the loops alone
    assert centres(select_candidates(found, 7, 0.0, 1.0, 0.0)) == [
        (100.0, 104.0, 5.0), (109.0, 104.0, 5.0)]


@pytest.mark.parametrize('ring', [
    (100.0, 100.0, 9.0),    # not twice the loop's radius: the same sign
    (100.0, 113.0, 20.0),   # the loop beyond 0.6 of its radius from its centre
])
def test_other_neighbours_stay_suppressed(ring: tuple[float, float, float]) -> None:
    found = maxima((0.9, 100.0, 100.0, 5.0), (0.8, *ring))
    assert centres(select_candidates(found, 7, 0.0, 1.0, 2.0)) == [(100.0, 100.0, 5.0)]


def test_same_sign_rule() -> None:
    loop = Candidate(100.0, 100.0, 5.0, 0.9)
    ring = Candidate(100.0, 100.0 + ENCLOSED_CENTRE_FRACTION * 20.0 - 0.01, 20.0, 0.8)
    assert not is_same_sign(ring, loop, 1.0, 2.0)
    assert is_same_sign(ring, loop, 1.0, 0.0)
    assert is_same_sign(Candidate(100.0, 100.0 + ENCLOSED_CENTRE_FRACTION * 20.0, 20.0, 0.8),
                        loop, 1.0, 2.0)
    far = Candidate(130.0, 100.0, 20.0, 0.8)   # 30 px off: another sign in any case
    assert not is_same_sign(far, loop, 1.0, 0.0)


def test_default_keeps_enclosing_rings() -> None:
    assert DetectorConfig().enclosing_ring_ratio == 2.0
