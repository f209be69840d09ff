"""Sign rendering: every kind renders, shapes/types/alpha are right, proportions hold."""
from __future__ import annotations

import numpy as np
import pytest

from speed_sign_detector.recognition.templates import (
    ARCHED_SIX_GEOMETRY,
    GRAY_TEMPLATE_GEOMETRY,
    SIGN_KINDS,
    gray_template,
    gray_views,
    render_master,
    render_sign,
    views_from_master,
    views_from_masters,
)

REQUIRED_KINDS = ([str(v) for v in (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130)]
                  + ['00', 'end_of_limit_80', 'no_overtaking', 'no_entry', 'weight_limit',
                     'width_limit', 'height_limit'])


def test_sign_kinds_cover_the_contract() -> None:
    missing = [kind for kind in REQUIRED_KINDS if kind not in SIGN_KINDS]
    assert not missing, f'kinds missing from SIGN_KINDS: {missing}'
    assert len(set(SIGN_KINDS)) == len(SIGN_KINDS)


@pytest.mark.parametrize('kind', SIGN_KINDS)
def test_every_kind_renders_with_disc_alpha(kind: str) -> None:
    bgr, alpha = render_sign(kind, 48)
    assert bgr.shape == (48, 48, 3) and bgr.dtype == np.uint8
    assert alpha.shape == (48, 48) and alpha.dtype == np.float32
    assert alpha[24, 24] == pytest.approx(1.0)
    assert alpha[0, 0] == pytest.approx(0.0)
    # the disc covers pi/4 of the square
    assert alpha.mean() == pytest.approx(np.pi / 4, abs=0.02)
    assert bgr[alpha == 0].max() == 0, 'colour outside the disc must be black (premultiplied)'


def test_speed_limit_has_red_ring_white_field_black_digits() -> None:
    bgr, _ = render_sign('50', 200)
    g, r = bgr[..., 1].astype(int), bgr[..., 2].astype(int)
    ring_x = 100 + 82  # 0.82 R right of the centre
    assert r[100, ring_x] > 150 and g[100, ring_x] < 80, 'red ring expected'
    field = bgr[42:56, 95:105]  # above the digits, inside the ring
    assert field.mean() > 200, 'white field expected above the digits'
    digits = bgr[70:130, 55:145].mean(axis=2)
    assert (digits < 60).mean() > 0.1, 'black digits expected in the middle'


def test_arched_six_closes_the_top_of_the_6_as_an_8_is_closed() -> None:
    """The older lettering's 6 (``arched_six``) is drawn where the plain 6 is open and
    the 8 is not, and nothing but a 6 changes."""
    plain = render_sign('60', 200)[0].mean(axis=2)
    arched = render_sign('60', 200, ARCHED_SIX_GEOMETRY)[0].mean(axis=2)
    eight = render_sign('80', 200)[0].mean(axis=2)
    added = (arched < 80) & (plain > 180)  # the arch, where the plain 6 is white
    assert added.sum() > 300, 'the arched 6 should add a stroke to the plain one'
    rows, columns = np.nonzero(added)
    assert rows.mean() < 100 and columns.mean() < 100, 'the arch is on the top of the first digit'
    assert (eight[added] < 128).mean() > 0.5, 'most of the arch lies on the 8\'s upper loop'
    for kind in ('80', '100', '30'):
        np.testing.assert_array_equal(render_sign(kind, 64, ARCHED_SIX_GEOMETRY)[0],
                                      render_sign(kind, 64)[0])


def test_end_of_limit_has_no_red() -> None:
    bgr, alpha = render_sign('end_of_limit_80', 120)
    b, g, r = (bgr[..., i].astype(int) for i in range(3))
    redness = (r - np.maximum(g, b))[alpha > 0.99]
    assert redness.max() < 10


def test_render_is_deterministic_and_small_sizes_are_antialiased() -> None:
    first, _ = render_sign('120', 16)
    second, _ = render_sign('120', 16)
    np.testing.assert_array_equal(first, second)
    levels = np.unique(first)
    assert levels.size > 20, 'area reduction should give intermediate gray levels'


@pytest.mark.parametrize('bad', [('70', 3), ('not_a_sign', 32)])
def test_bad_arguments_raise_value_error(bad: tuple[str, int]) -> None:
    with pytest.raises(ValueError):
        render_sign(*bad)


def test_gray_template_background_and_views() -> None:
    template = gray_template('30', 40, 52, background=128.0)
    assert template.shape == (52, 52) and template.dtype == np.float32
    assert template[0, 0] == pytest.approx(128.0)
    views = gray_views('30', 40, 52, [(0, 0, 0), (30, 0, 0), (0, 10, 6)])
    assert views.shape == (3, 52, 52)
    # yaw 30 deg narrows the sign horizontally: fewer non-background columns
    def width(image: np.ndarray) -> int:
        return int((np.abs(image - 128.0) > 20).any(axis=0).sum())
    assert width(views[1]) < width(views[0]) - 2


def test_master_views_match_gray_views() -> None:
    master = render_master('80', 512, GRAY_TEMPLATE_GEOMETRY)
    from_master = views_from_master(master, 30.0, 40, [(0, 0, 0)], supersample=4)
    direct = gray_views('80', 30.0, 40, [(0, 0, 0)], geometry=GRAY_TEMPLATE_GEOMETRY)
    assert np.abs(from_master - direct).mean() < 3.0


@pytest.mark.parametrize('count', [2, 3])
def test_batched_master_views_equal_single_ones(count: int) -> None:
    """One warp over stacked masters gives each master's own views (2 masters included:
    OpenCV warps 4-channel images on another code path)."""
    kinds = ['30', 'end_of_limit_80', 'no_overtaking'][:count]
    masters = [render_master(kind, 256, GRAY_TEMPLATE_GEOMETRY) for kind in kinds]
    views = [(0.0, 0.0, 0.0), (20.0, -10.0, 6.0), (-30.0, 10.0, -6.0)]
    batched = views_from_masters(masters, 33.5, 45, views, supersample=1)
    assert batched.shape == (count, len(views), 45, 45)
    for master, from_batch in zip(masters, batched):
        single = views_from_master(master, 33.5, 45, views, supersample=1)
        np.testing.assert_allclose(from_batch, single, rtol=0, atol=1e-4)


def test_batched_master_views_reject_mixed_masters() -> None:
    with pytest.raises(ValueError):
        views_from_masters([np.zeros((64, 64, 2), np.float32),
                            np.zeros((32, 32, 2), np.float32)], 20.0, 30, [(0, 0, 0)])
    with pytest.raises(ValueError):
        views_from_masters([], 20.0, 30, [(0, 0, 0)])
