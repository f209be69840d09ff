"""Classifier on rendered signs under perspective, blur, noise, contrast loss and
rotation; rejection of look-alikes and blank/noise patches; bad inputs."""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classifier import (
    LABEL_NO_SIGN,
    LONGER_PARTNERS,
    PARTNER_PSR_GAP,
    Classification,
    Classifier,
    ClassifierInputError,
    bank_radii,
    build_banks,
)
from speed_sign_detector.recognition.templates import render_sign

#: Banks up to radius 30 px only, to keep the module fast (the default goes to 48).
TEST_CONFIG = ClassifierConfig(max_radius_px=30.0, cache_dir='')


@pytest.fixture(scope='module')
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp('filter_banks')


@pytest.fixture(scope='module')
def classifier(cache_dir: Path) -> Classifier:
    return Classifier(dataclasses.replace(TEST_CONFIG, cache_dir=str(cache_dir)))


def _background(shape: tuple[int, int], seed: int) -> np.ndarray:
    """Smooth textured gray background (sky/trees-like), uint8."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(40, 200, (shape[0] // 16 + 2, shape[1] // 16 + 2)).astype(np.float32)
    smooth = cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
    return np.clip(smooth + rng.normal(0, 6, shape), 0, 255).astype(np.uint8)


def make_scene(kind: str, radius_px: float, *, yaw_deg: float = 0.0, roll_deg: float = 0.0,
               blur_px: float = 0.0, noise: float = 0.0, contrast: float = 1.0,
               seed: int = 0, shape: tuple[int, int] = (120, 160),
               centre: tuple[float, float] = (80.0, 60.0)) -> np.ndarray:
    """A gray frame with one rendered sign at ``centre`` (x, y), distorted."""
    diameter = int(round(2 * radius_px * 4))
    bgr, alpha = render_sign(kind, diameter)
    gray_sign = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    # perspective (yaw) + in-plane rotation + scale down by 4, in one homography
    half = diameter / 2.0
    yaw = math.radians(yaw_deg)
    corners = np.float32([[0, 0], [diameter, 0], [diameter, diameter], [0, diameter]])
    distance = 6.0 * diameter
    projected = []
    for x, y in corners - half:
        z = x * math.sin(yaw)
        u = distance * x * math.cos(yaw) / (distance + z)
        v = distance * y / (distance + z)
        c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
        projected.append((c * u + s * v, -s * u + c * v))
    target = np.float32(projected) / 4.0 + np.float32(centre)
    homography = cv2.getPerspectiveTransform(corners, target)
    size = (shape[1], shape[0])
    warped_sign = cv2.warpPerspective(gray_sign, homography, size, flags=cv2.INTER_AREA)
    warped_alpha = cv2.warpPerspective(alpha, homography, size, flags=cv2.INTER_AREA)
    frame = _background(shape, seed).astype(np.float32)
    frame = warped_sign + (1.0 - warped_alpha) * frame
    if blur_px > 0:
        frame = cv2.GaussianBlur(frame, (0, 0), blur_px)
    frame = 128.0 + (frame - 128.0) * contrast
    if noise > 0:
        frame += np.random.default_rng(seed + 1).normal(0, noise, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8)


def _candidate(radius_px: float, error_px: float = 0.0) -> Candidate:
    """A candidate like the radial-symmetry detector gives: ~0.75 of the outer radius
    (undone by ClassifierConfig.candidate_radius_scale)."""
    return Candidate(80.0 + error_px, 60.0 - error_px, radius_px * 0.78, 1.0)


DISTORTIONS = {
    'clean': {},
    'yaw 25 deg': {'yaw_deg': 25.0},
    'blur 1.2 px': {'blur_px': 1.2},
    'noise 10': {'noise': 10.0},
    'contrast 35%': {'contrast': 0.35},
    'roll +6 deg': {'roll_deg': 6.0},
    'roll -6 deg': {'roll_deg': -6.0},
    'all at once': {'yaw_deg': -20.0, 'blur_px': 0.8, 'noise': 6.0, 'contrast': 0.5,
                    'roll_deg': 4.0},
}


@pytest.mark.parametrize('distortion', sorted(DISTORTIONS))
def test_rendered_limits_read_under_distortion(classifier: Classifier, distortion: str) -> None:
    """Never a wrong limit; at most one of the eight withheld.

    The one withheld answer allowed: the second opinion learned 5, 10, 40, 90, 110 and
    130 km/h from renderings only, so a rendering looks a little like those classes to
    it. Retrained on a few more scene examples (session 8), it read a rendered 100 under
    1.2 px of blur as "rather 130" (100 at -0.45, 130 at +0.45; -0.03 and +0.03 with the
    bank before) and withheld the answer, as its rule says; on real 100 km/h crops the
    same recipe reads 0.963 (0.960 before; 5 folds by track), 0.4 % as another limit.
    """
    wrong, withheld = [], []
    for index, value in enumerate((20, 30, 50, 60, 70, 80, 100, 120)):
        radius = 14.0 + 2.0 * (index % 4)
        frame = make_scene(str(value), radius, seed=index, **DISTORTIONS[distortion])
        result = classifier.classify(frame, [_candidate(radius, error_px=1.5)])[0]
        if result.limit_kmh is None:
            withheld.append((value, result.label, round(result.psr, 1)))
        elif result.limit_kmh != value:
            wrong.append((value, result.label, round(result.psr, 1)))
    assert not wrong, f'{distortion}: misread {wrong}'
    assert len(withheld) <= 1, f'{distortion}: withheld {withheld}'


def test_every_limit_value_reads_clean(classifier: Classifier) -> None:
    misread = []
    for value in (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130):
        result = classifier.classify(make_scene(str(value), 16.0, seed=value),
                                     [_candidate(16.0)])[0]
        if result.limit_kmh != value:
            misread.append((value, result.label))
    assert not misread


def test_result_fields_locate_and_size_the_sign(classifier: Classifier) -> None:
    frame = make_scene('70', 18.0, roll_deg=6.0, seed=3)
    result = classifier.classify(frame, [Candidate(82.0, 58.0, 13.0, 1.0)])[0]
    assert result.label == '70' and result.limit_kmh == 70 and result.is_limit
    assert abs(result.x_px - 80.0) <= 2.0 and abs(result.y_px - 60.0) <= 2.0
    assert result.radius_px == pytest.approx(18.0, rel=0.2)
    assert result.rotation_deg == pytest.approx(6.0)
    assert result.margin > 0 and result.psr > classifier.config.psr_threshold


def test_small_and_large_signs_are_rescaled(classifier: Classifier) -> None:
    small = make_scene('50', 9.0, seed=11)
    large = make_scene('50', 40.0, seed=12, shape=(200, 240), centre=(120.0, 100.0))
    assert classifier.classify(small, [_candidate(9.0)])[0].limit_kmh == 50
    result = classifier.classify(large, [Candidate(120.0, 100.0, 31.0, 1.0)])[0]
    assert result.limit_kmh == 50
    assert result.radius_px == pytest.approx(40.0, rel=0.2)



@pytest.mark.parametrize('direction', [(-1.0, 0.0), (0.0, -1.0), (1.0, 0.0), (0.0, 1.0),
                                       (-0.7, -0.7)])
@pytest.mark.parametrize('radius_px', [9.0, 16.0, 26.0])
def test_sign_off_the_candidate_centre_is_found_on_every_side(
        classifier: Classifier, direction: tuple[float, float], radius_px: float) -> None:
    # the detection filters search +-position_search radii around the candidate; a
    # sign up or left of it was once placed a whole FFT size away (the correlation
    # plane's circular index was not unwrapped) and went unread
    offset = 0.3 * radius_px
    frame = make_scene('50', radius_px, seed=5, shape=(160, 200), centre=(100.0, 80.0))
    candidate = Candidate(100.0 - direction[0] * offset, 80.0 - direction[1] * offset,
                          radius_px * 0.78, 1.0)
    result = classifier.classify(frame, [candidate])[0]
    assert result.limit_kmh == 50, (direction, radius_px, result)
    assert abs(result.x_px - 100.0) <= 1.5 and abs(result.y_px - 80.0) <= 1.5, result


def test_tight_crop_cut_off_centre_is_read(classifier: Classifier) -> None:
    # a tight box a few pixels off the sign, as another tool may cut it: the sign
    # up-left of the box centre and cut on one side by the box border
    frame = make_scene('30', 16.0, seed=9, shape=(160, 200), centre=(100.0, 80.0))
    for shift_x, shift_y in ((5, 0), (0, 5), (4, 4), (-5, 0), (0, -5)):
        crop = frame[80 - 16 + shift_y:80 + 16 + shift_y, 100 - 16 + shift_x:100 + 16 + shift_x]
        result = classifier.classify_crop(np.ascontiguousarray(crop), framing='tight')
        assert result.limit_kmh == 30, (shift_x, shift_y, result)


@pytest.mark.parametrize('kind', ['30', '50', '80'])
@pytest.mark.parametrize(('radius_px', 'candidate_radius_px'), [(30.0, 14.0), (24.0, 11.0)])
def test_large_sign_found_by_its_inner_ring_is_read_at_a_larger_size(
        classifier: Classifier, kind: str, radius_px: float, candidate_radius_px: float
) -> None:
    # the radial-symmetry detector often gives a large sign the radius of its inner ring
    # or digits, about half the outer one: beyond the size search, so "no sign" at first
    frame = make_scene(kind, radius_px, seed=12, shape=(200, 240), centre=(120.0, 100.0))
    candidate = Candidate(120.0, 100.0, candidate_radius_px, 1.0)
    without_retry = Classifier(dataclasses.replace(classifier.config,
                                                   larger_size_retry_factor=1.0))
    assert without_retry.classify(frame, [candidate])[0].label == 'no_sign'
    (answer,) = classifier.classify(frame, [candidate])
    assert answer.label == kind
    assert answer.radius_px == pytest.approx(radius_px, rel=0.1)
    # below the least radius of the retry, or no retries allowed: not tried again; a
    # retried answer below the retry's least PSR, or a detection below its least
    # detection PSR: withheld
    for setting in ({'larger_size_retry_min_radius_px': candidate_radius_px + 1.0},
                    {'larger_size_retry_max_candidates': 0},
                    {'larger_size_retry_min_psr': answer.psr + 0.1},
                    {'larger_size_retry_min_detection_psr': 1000.0}):
        config = dataclasses.replace(classifier.config, **setting)
        assert Classifier(config).classify(frame, [candidate])[0].label == 'no_sign', setting


@pytest.mark.parametrize('kind', ['no_overtaking', 'no_entry', 'weight_limit', 'width_limit',
                                  'height_limit', 'end_of_limit_80', 'end_of_limit_60',
                                  'end_of_restrictions'])
def test_lookalikes_are_not_read_as_limits(classifier: Classifier, kind: str) -> None:
    for seed, radius in enumerate((13.0, 17.0, 22.0)):
        frame = make_scene(kind, radius, seed=seed, blur_px=0.6)
        result = classifier.classify(frame, [_candidate(radius)])[0]
        assert not result.is_limit, f'{kind} at radius {radius} read as {result.label}'


def test_blank_and_noise_patches_are_rejected(classifier: Classifier) -> None:
    rng = np.random.default_rng(5)
    patches = {
        'uniform': np.full((120, 160), 128, np.uint8),
        'noise': rng.integers(0, 256, (120, 160), dtype=np.uint8),
        'texture': _background((120, 160), 9),
    }
    for name, frame in patches.items():
        results = classifier.classify(frame, [_candidate(r) for r in (10.0, 16.0, 24.0)])
        limits = [r.label for r in results if r.is_limit]
        assert not limits, f'{name} patch read as {limits}'


def test_one_result_per_candidate_in_order(classifier: Classifier) -> None:
    frame = make_scene('30', 15.0, seed=2)
    candidates = [_candidate(15.0), Candidate(10.0, 10.0, 8.0, 0.5),
                  Candidate(-30.0, 500.0, 12.0, 0.1), Candidate(80.0, 60.0, 1.0, 0.1)]
    results = classifier.classify(frame, candidates)
    assert len(results) == 4
    assert results[0].limit_kmh == 30
    assert all(isinstance(r, Classification) for r in results)
    assert results[3].label == LABEL_NO_SIGN  # radius below min_sign_radius_px
    assert classifier.classify(frame, []) == ()



def test_candidates_correlated_together_answer_as_one_by_one(classifier: Classifier) -> None:
    # evidence_for_candidates shares products, inverse FFTs and peak searches between
    # the positions; each answer must be exactly that of the position alone
    frame = make_scene('50', 15.0, seed=3)
    frame[:, 120:] = make_scene('80', 22.0, seed=5)[:, 120:]
    positions = [(80.0, 60.0, 15.0), (80.5, 59.0, 12.0), (10.0, 10.0, 8.0),
                 (math.nan, 60.0, 15.0), (80.0, 60.0, 2.0), (80.0, 60.0, 60.0),
                 (-30.0, 500.0, 12.0), (80.0, 60.0, 15.0)]
    together = classifier.evidence_for_candidates(frame, positions)
    assert len(together) == len(positions)
    assert not isinstance(together[0], Classification)  # a sign found there
    for position, found in zip(positions, together):
        alone = classifier.evidence_at(frame, *position)
        assert repr(found) == repr(alone)
    # classify: the second opinion's features of all its signs in one call, same answers
    candidates = [Candidate(x, y, r, 1.0) for x, y, r in positions]
    scale = classifier.config.candidate_radius_scale
    assert classifier.trained_bank.second_opinion is not None
    assert classifier.classify(frame, candidates) == tuple(
        classifier.decide(frame, classifier.evidence_at(frame, x, y, r * scale))
        for x, y, r in positions)

@pytest.mark.parametrize('bad', [np.zeros((0, 0), np.uint8), np.zeros((20, 20, 3), np.uint8),
                                 np.zeros((20, 20), np.float32), [[1, 2], [3, 4]]])
def test_bad_images_raise_clear_errors(classifier: Classifier, bad: object) -> None:
    with pytest.raises(ClassifierInputError) as info:
        classifier.classify_crop(bad)  # type: ignore[arg-type]
    assert isinstance(info.value, ValueError)
    with pytest.raises(ClassifierInputError):
        classifier.classify(bad, [_candidate(10.0)])  # type: ignore[arg-type]


@pytest.mark.parametrize('shape', [(1, 1), (3, 4), (6, 6), (9, 30)])
def test_tiny_crops_answer_no_sign(classifier: Classifier, shape: tuple[int, int]) -> None:
    crop = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    assert classifier.classify_crop(crop).label == LABEL_NO_SIGN


def test_non_finite_candidates_answer_no_sign(classifier: Classifier) -> None:
    frame = make_scene('30', 15.0)
    for candidate in (Candidate(math.nan, 60.0, 15.0, 1.0), Candidate(80.0, 60.0, math.inf, 1.0)):
        assert classifier.classify(frame, [candidate])[0].label == LABEL_NO_SIGN


def test_classify_crop_on_a_gtsrb_like_crop(classifier: Classifier) -> None:
    frame = make_scene('80', 15.0, seed=4, blur_px=0.7)
    crop = frame[60 - 20:60 + 20, 80 - 20:80 + 20]  # sign 30 px, margin 5 px
    result = classifier.classify_crop(np.ascontiguousarray(crop))
    assert result.limit_kmh == 80
    assert abs(result.x_px - 20.0) <= 2.0


def test_banks_are_deterministic_and_cached(cache_dir: Path, classifier: Classifier) -> None:
    config = dataclasses.replace(TEST_CONFIG, cache_dir=str(cache_dir))
    cached = build_banks(config)  # read from the cache the fixture wrote
    assert len(list(cache_dir.glob('filter_banks_*.npz'))) == 1
    fresh = build_banks(dataclasses.replace(TEST_CONFIG, max_radius_px=18.0, cache_dir=""))
    assert len(cached) == len(bank_radii(config)) == len(classifier.banks)
    np.testing.assert_array_equal(cached[0].classification, classifier.banks[0].classification)
    np.testing.assert_allclose(fresh[0].classification, cached[0].classification, rtol=1e-4,
                               atol=1e-3 * float(np.abs(cached[0].classification).max()))
    # the memory counted is that of every bank's detection and classification spectra
    assert classifier.bank_nbytes == sum(bank.detection.nbytes + bank.classification.nbytes
                                         for bank in classifier.banks)
    # the time reported is a part of the construction (here from the cache)
    start = time.perf_counter()
    from_cache = Classifier(config)
    constructed_s = time.perf_counter() - start
    assert 0.0 < from_cache.build_time_s <= constructed_s


def test_unwritable_cache_is_not_fatal(tmp_path: Path) -> None:
    blocker = tmp_path / 'file'
    blocker.write_text('not a folder')
    config = dataclasses.replace(TEST_CONFIG, max_radius_px=17.0, cache_dir=str(blocker / "x"))
    assert len(build_banks(config)) == len(bank_radii(config))


@pytest.mark.parametrize('centre', [(150.0, 60.0), (80.0, 5.0), (3.0, 110.0)])
def test_sign_cut_by_the_frame_border_is_not_read(classifier: Classifier,
                                                  centre: tuple[float, float]) -> None:
    """A near sign leaving the frame shows only part of its digits: answer no sign."""
    radius = 22.0
    cut = make_scene('80', radius, centre=centre)
    answer = classifier.classify(cut, [Candidate(centre[0], centre[1], radius / 1.33, 1.0)])[0]
    assert answer.label == LABEL_NO_SIGN
    inside = make_scene('80', radius, centre=(80.0, 60.0))
    answer = classifier.classify(inside, [Candidate(80.0, 60.0, radius / 1.33, 1.0)])[0]
    assert answer.label == '80'


def test_longer_partners_are_the_limits_a_lost_outer_digit_turns_into_others() -> None:
    assert LONGER_PARTNERS == {'5': ('50',), '10': ('100', '110'), '20': ('120',),
                               '30': ('130',), '40': ('140',)}


@pytest.mark.parametrize(('short', 'longer'), [('30', '130'), ('10', '100'), ('10', '110'),
                                                ('40', '140'), ('5', '50')])
def test_a_limit_is_withheld_where_its_longer_partner_scores_nearly_as_high(
        classifier: Classifier, short: str, longer: str) -> None:
    """A 130 whose 1 the filters lose reads as 30, with 130 close behind: withheld. With
    130 far behind, or for the longer limit itself, the answer stands; a limit without a
    longer partner is not affected."""
    gray = np.full((96, 96), 128, np.uint8)

    def answer(*ranked: tuple[str, float]) -> str:
        evidence = CorrelationEvidence(tuple(ranked), 48.0, 48.0, 20.0, 0.0, 10.0)
        return classifier.decide(gray, evidence, use_second_opinion=False, crop=True).label

    near, far = 12.0 - PARTNER_PSR_GAP + 0.5, 12.0 - PARTNER_PSR_GAP - 0.5
    assert answer((short, 12.0), (longer, near), ('80', 6.0)) == LABEL_NO_SIGN
    assert answer((short, 12.0), ('80', 6.0), (longer, far)) == short
    assert answer((longer, 12.0), (short, 11.5)) == longer
    assert answer(('80', 12.0), ('130', 11.5), ('60', 6.0)) == '80'
