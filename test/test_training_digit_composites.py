"""Composite training crops of any limit value from the digits of other signs.

The crops here are renderings on textured backgrounds with a known sign position, so
what a composite should show is known exactly: a 130 made from a 120's background and a
30's "3" must look like a rendered 130, not like the 120 it was made from.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from test_recognition_training import crop_of

from speed_sign_detector.recognition.templates import GEOMETRY, LIMIT_VALUES_KMH
from speed_sign_detector.training.digit_composites import (
    digit_boxes,
    digit_composites,
    ink_levels,
)

SIGN_PX = 40
MARGIN_PX = 6


def _located(values: list[str], per_value: int = 3) -> tuple[list[np.ndarray], np.ndarray,
                                                             list[str]]:
    """Rendered crops of ``values`` with their signs' (x, y, radius)."""
    images, signs, labels = [], [], []
    for value in values:
        for index in range(per_value):
            images.append(crop_of(value, SIGN_PX, MARGIN_PX, seed=31 * index + int(value)))
            centre = MARGIN_PX + SIGN_PX / 2.0
            signs.append((centre, centre, SIGN_PX / 2.0))
            labels.append(value)
    return images, np.asarray(signs), labels


def _field_correlation(first: np.ndarray, second: np.ndarray) -> float:
    """Normalised cross-correlation of two crops over the sign's inner field."""
    side = first.shape[0]
    rows, columns = np.indices(first.shape)
    centre = MARGIN_PX + SIGN_PX / 2.0
    field = np.hypot(columns + 0.5 - centre, rows + 0.5 - centre) \
        < GEOMETRY.ring_inner * SIGN_PX / 2.0
    assert second.shape == (side, side)
    a = first[field].astype(np.float64) - first[field].mean()
    b = second[field].astype(np.float64) - second[field].mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


@pytest.mark.parametrize('value', [str(v) for v in LIMIT_VALUES_KMH])
def test_digit_boxes_follow_the_rendered_layout(value: str) -> None:
    boxes = digit_boxes(value)
    assert ''.join(box.character for box in boxes) == value
    for box in boxes:
        assert box.left < box.right and box.top < box.bottom
        assert np.hypot(max(abs(box.left), abs(box.right)), 0.0) < GEOMETRY.ring_inner
    for left, right in zip(boxes, boxes[1:]):
        assert left.right - right.left < 0.1  # neighbours meet at most in their margins


def test_three_digit_values_have_narrower_lower_digits() -> None:
    two, three = digit_boxes('30')[0], digit_boxes('130')[1]
    assert three.right - three.left < two.right - two.left
    assert three.bottom - three.top < two.bottom - two.top


def test_digit_boxes_refuse_what_is_not_a_limit_value() -> None:
    for value in ('', '1300', 'end', '3a'):
        with pytest.raises(ValueError, match='1 to 3 digits'):
            digit_boxes(value)


def test_a_composite_shows_the_new_value_not_its_background() -> None:
    images, signs, labels = _located(['120', '30'])
    made = digit_composites(images, signs, labels, ['130'], 6, np.random.default_rng(0))
    assert len(made) == 6 and set(made.labels) == {'130'}
    assert np.all(made.rendered_digits == 0)  # 1, 3 and 0 all have real donors here
    for image, background in zip(made.images, made.backgrounds):
        assert labels[background] == '120'  # a three-digit background for a three-digit value
        truth = crop_of('130', SIGN_PX, MARGIN_PX, seed=int(background))
        was = images[background]
        assert _field_correlation(image, truth) > _field_correlation(image, was)
        assert _field_correlation(image, truth) > 0.8


def test_a_turned_six_is_a_nine_and_a_missing_digit_is_rendered() -> None:
    images, signs, labels = _located(['60', '30'])
    rng = np.random.default_rng(1)
    nines = digit_composites(images, signs, labels, ['90'], 4, rng)
    assert np.all(nines.rendered_digits == 0)
    fours = digit_composites(images, signs, labels, ['40'], 4, rng)
    assert np.all(fours.rendered_digits == 1)  # no real 4 among 60 and 30
    for made in (nines, fours):
        for image, background in zip(made.images, made.backgrounds):
            truth = crop_of(made.labels[0], SIGN_PX, MARGIN_PX, seed=0)
            assert _field_correlation(image, truth) > _field_correlation(
                image, images[background])


def test_composites_come_only_from_the_crops_given() -> None:
    images, signs, labels = _located(['120'])
    # a 120 cannot be made from 120s alone: no background of another value
    assert len(digit_composites(images, signs, labels, ['120'], 5,
                                np.random.default_rng(2))) == 0
    # unlocated crops and crops that are not limits lend nothing
    signs[:] = np.nan
    assert len(digit_composites(images, signs, labels, ['130'], 5,
                                np.random.default_rng(2))) == 0
    other = digit_composites(images, np.asarray([(26.0, 26.0, 20.0)] * 3), ['other_sign'] * 3,
                             ['130'], 5, np.random.default_rng(2))
    assert len(other) == 0
    with pytest.raises(ValueError, match='per_value'):
        digit_composites(images, signs, labels, ['130'], -1, np.random.default_rng(2))


def test_ink_levels_measure_face_and_digits() -> None:
    images, signs, _ = _located(['50'], per_value=1)
    face, ink = ink_levels(images[0], signs[0])
    white = cv2.cvtColor(np.uint8([[GEOMETRY.white_bgr]]), cv2.COLOR_BGR2GRAY)[0, 0]
    black = cv2.cvtColor(np.uint8([[GEOMETRY.black_bgr]]), cv2.COLOR_BGR2GRAY)[0, 0]
    assert abs(face - float(white)) < 12 and abs(ink - float(black)) < 25
