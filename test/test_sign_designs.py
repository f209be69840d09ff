"""Sign designs (LED, yellow-faced), every EU value, and end signs: the renderings have
the properties their names claim, and the label tables agree."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from speed_sign_detector.recognition.classification import LABEL_END_OF_LIMIT, label_of_class
from speed_sign_detector.recognition.filter_banks import CLASS_TEMPLATES, SPEED_LIMITS_KMH
from speed_sign_detector.recognition.sign_designs import (
    LED_DESIGNS,
    SIGN_DESIGNS,
    DesignError,
    LedLook,
    design_crop,
    design_label,
    design_training_crops,
    lit_on_dark_design,
    random_look,
    render_design,
)
from speed_sign_detector.recognition.templates import (
    END_OF_LIMIT_KINDS,
    GEOMETRY,
    LIMIT_VALUES_KMH,
    SIGN_KINDS,
)
from speed_sign_detector.synthetic import DRIVE_EXCLUDED_KINDS, sign_kinds

EU_VALUES_KMH = (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130, 140)
DIAMETER = 120


def _gray(design: str, kind: str = '80', look: LedLook = LedLook()) -> np.ndarray:
    bgr, _ = render_design(kind, DIAMETER, design, look)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)


def _unit_grid() -> tuple[np.ndarray, np.ndarray]:
    """(y, x) of each pixel's centre in units of the sign radius (centre 0)."""
    half = DIAMETER / 2.0
    rows, cols = np.mgrid[:DIAMETER, :DIAMETER]
    return (rows + 0.5 - half) / half, (cols + 0.5 - half) / half


def _face_and_digits(gray: np.ndarray, ring_inner: float) -> tuple[float, float]:
    """Median of the face above and below the digits, and the level of the digits (the
    gray level farthest from the face in the digit box)."""
    y, x = _unit_grid()
    caps = (np.hypot(y, x) < ring_inner - 0.05) & (np.abs(y) > 0.45)
    face = float(np.median(gray[caps]))
    box = gray[(np.abs(y) < 0.25) & (np.abs(x) < 0.4)]
    digits = float(box.max()) if abs(box.max() - face) > abs(box.min() - face) \
        else float(box.min())
    return face, digits


def test_every_eu_value_is_drawn_and_read() -> None:
    assert set(EU_VALUES_KMH) <= set(LIMIT_VALUES_KMH)
    assert tuple(SPEED_LIMITS_KMH) == tuple(LIMIT_VALUES_KMH)
    for value in LIMIT_VALUES_KMH:
        assert str(value) in SIGN_KINDS and str(value) in CLASS_TEMPLATES
        assert f'end_of_limit_{value}' in END_OF_LIMIT_KINDS


def test_drives_keep_their_published_kinds() -> None:
    limits, lookalikes = sign_kinds()
    assert not DRIVE_EXCLUDED_KINDS & (set(limits) | set(lookalikes))
    assert set(limits) | set(lookalikes) | DRIVE_EXCLUDED_KINDS >= {
        kind for kind in SIGN_KINDS if kind != '00'}


@pytest.mark.parametrize('design', ['led', 'led_amber', 'led_dot_matrix'])
def test_led_face_is_darker_than_its_digits_and_ring(design: str) -> None:
    for look in (LedLook(glow=0.0), LedLook(glow=1.0, exposure=1.8)):
        gray = _gray(design, '80', look)
        face, digits = _face_and_digits(gray, 0.76)
        y, x = _unit_grid()
        ring = float(gray[(np.hypot(y, x) > 0.8) & (np.hypot(y, x) < 0.92)].mean())
        assert digits > face + 100, (design, look, face, digits)
        assert ring > face + 30, (design, look, face, ring)


@pytest.mark.parametrize('design', ['painted', 'yellow', 'led_dark_on_lit'])
def test_painted_polarity_designs_have_dark_digits_on_a_light_face(design: str) -> None:
    face, digits = _face_and_digits(_gray(design), 0.6)
    assert face > digits + 100, (design, face, digits)
    assert lit_on_dark_design(design) is False


def test_dot_matrix_is_made_of_separate_lamps() -> None:
    solid = _gray('led', '80', LedLook(glow=0.0)) > 100
    dotted = _gray('led_dot_matrix', '80', LedLook(glow=0.0)) > 100
    count_solid, _ = cv2.connectedComponents(solid.astype(np.uint8))
    count_dotted, _ = cv2.connectedComponents(dotted.astype(np.uint8))
    assert count_dotted > 10 * count_solid


def test_yellow_face_and_thicker_ring() -> None:
    yellow, _ = render_design('80', DIAMETER, 'yellow')
    painted, _ = render_design('80', DIAMETER, 'painted')
    y, x = _unit_grid()
    face = (np.hypot(y, x) < 0.5) & (np.abs(y) > 0.42)
    blue, green, red = (float(np.median(yellow[..., c][face])) for c in range(3))
    assert red > 150 and green > 150 and blue < 0.5 * min(red, green), (blue, green, red)

    def ring_width(bgr: np.ndarray) -> float:  # red pixels along the vertical radius
        column = bgr[:DIAMETER // 2, DIAMETER // 2].astype(int)
        red_px = (column[:, 2] > 120) & (column[:, 2] > column[:, 1] + 60)
        return float(red_px.sum())

    assert ring_width(yellow) > 1.1 * ring_width(painted)


@pytest.mark.parametrize('kind', ['end_of_limit_80', 'end_of_limit_120', 'end_of_limit_140'])
def test_end_of_limit_signs_show_gray_digits_beside_the_band(kind: str) -> None:
    gray = _gray('painted', kind)
    y, x = _unit_grid()
    off_band = (np.abs(x + y) / math.sqrt(2.0) > 0.25) & (np.hypot(y, x) < 0.8)
    face = float(np.median(gray[off_band]))
    digit_like = (np.abs(gray - GEOMETRY.gray_bgr[0]) < 30) & off_band
    assert face > 200 and digit_like.sum() > 0.02 * off_band.sum()


def test_end_of_all_restrictions_has_no_digits_and_ends_the_limit() -> None:
    gray = _gray('painted', 'end_of_restrictions')
    y, x = _unit_grid()
    off_band = (np.abs(x + y) / math.sqrt(2.0) > 0.25) & (np.hypot(y, x) < 0.9)
    assert float(gray[off_band].min()) > 200  # face only: no digit, no stripe
    assert design_label('end_of_restrictions') == LABEL_END_OF_LIMIT
    assert label_of_class('end_of_restrictions') == LABEL_END_OF_LIMIT
    assert label_of_class('no_overtaking') != LABEL_END_OF_LIMIT


def test_unknown_design_or_kind_is_refused() -> None:
    with pytest.raises(DesignError, match='design'):
        render_design('80', 40, 'neon')
    with pytest.raises(DesignError, match='kind'):
        render_design('85', 40, 'led')
    with pytest.raises(DesignError, match='diameter'):
        render_design('80', 3, 'led')


def test_dark_bands_darken_whole_rows_of_an_led_sign() -> None:
    """LedLook's bands (lamps pulsed, a rolling shutter between the pulses): the rows of a
    band are dark across the sign, the others as the sign lit whole; random_look draws
    them only where asked; a band look that cannot be drawn is refused."""
    whole, _ = render_design('80', 60, 'led')
    banded, _ = render_design('80', 60, 'led', LedLook(band_period=1.0, band_lit_share=0.5,
                                                        band_phase=0.5))
    whole_rows = whole.max(axis=(1, 2)).astype(int)
    banded_rows = banded.max(axis=(1, 2)).astype(int)
    # band phase 0.5 of a period of one diameter, half of it lit: the top half dark
    assert banded_rows[3:27].max() <= 40 < whole_rows[3:27].min()
    assert np.abs(banded_rows[33:57] - whole_rows[33:57]).max() <= 2
    rng = np.random.default_rng(0)
    assert random_look('led', rng).band_period == 0.0
    banded_look = random_look('led', rng, banded=True)
    assert 0.3 <= banded_look.band_period <= 2.0 and 0.4 <= banded_look.band_lit_share <= 0.85
    for bad in ({'band_period': -1.0}, {'band_lit_share': 0.0}, {'band_lit_share': 1.5},
                {'band_phase': float('nan')}):
        with pytest.raises(DesignError, match='band'):
            LedLook(**bad)


def test_design_crops_and_training_crops() -> None:
    rng = np.random.default_rng(3)
    for design in SIGN_DESIGNS:
        crop = design_crop('50', design, 30, rng)
        assert crop.dtype == np.uint8 and crop.shape == (40, 40)
    crops, labels = design_training_crops(1, np.random.default_rng(4))
    limits = [str(v) for v in LIMIT_VALUES_KMH]
    assert len(crops) == len(labels) == len(limits) * (len(LED_DESIGNS) + 1) + 1
    assert set(labels) == set(limits) | {LABEL_END_OF_LIMIT}
