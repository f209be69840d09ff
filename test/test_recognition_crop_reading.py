"""Reading crops: the positions a framing implies, and the framed retry after "no sign"."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from speed_sign_detector.config import ClassifierConfig, ConfigError, from_parameters
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.crop_framing import crop_sign_radius
from speed_sign_detector.recognition.crop_reading import crop_positions, framed_search_config

#: gtsrb-dev crops (class folder 00003 = 60 km/h, 00007 = 100 km/h) where the free search
#: settles 8-9 px off the centre of a 56 px crop (on a filter that reads no class clearly)
#: and the search held to the framing reads the limit.
OFF_CENTRE_CROPS = {'00003/00012_00024.png': '60', '00007/00012_00024.png': '100'}


@pytest.fixture(scope='module')
def config(pytestconfig: pytest.Config) -> ClassifierConfig:
    cache_dir = pytestconfig.cache.mkdir('speed_sign_filter_banks')
    return ClassifierConfig(cache_dir=str(cache_dir))


@pytest.fixture(scope='module')
def classifier(config: ClassifierConfig) -> Classifier:
    return Classifier(config)


@pytest.fixture(scope='module')
def without_retry(config: ClassifierConfig) -> Classifier:
    return Classifier(dataclasses.replace(config, crop_framed_retry=False))


def _crop(shared_data_dir: Path, name: str) -> np.ndarray:
    image = cv2.imread(str(shared_data_dir / 'gtsrb-dev' / name), cv2.IMREAD_GRAYSCALE)
    assert image is not None, name
    return image


def test_crop_positions_follow_the_framing() -> None:
    shape = (40, 50)
    assert crop_positions(shape, 'tight') == [(25.0, 20.0, crop_sign_radius(shape, 'tight'))]
    assert crop_positions(shape, 'auto') == [
        (25.0, 20.0, crop_sign_radius(shape, 'margin')),
        (25.0, 20.0, crop_sign_radius(shape, 'tight'))]


def test_the_framed_search_holds_size_and_position() -> None:
    config = ClassifierConfig(crop_retry_size_search_ratio=1.05, crop_retry_position_search=0.1)
    held = framed_search_config(config)
    assert (held.size_search_ratio, held.position_search) == (1.05, 0.1)
    assert dataclasses.replace(held, size_search_ratio=config.size_search_ratio,
                               position_search=config.position_search) == config


@pytest.mark.parametrize('values, message', [
    ({'classifier.crop_retry_size_search_ratio': 0.9}, 'below its minimum'),
    ({'classifier.crop_retry_position_search': -0.1}, 'below its minimum'),
    ({'classifier.crop_framed_retry': 'yes'}, 'must be bool'),
])
def test_invalid_retry_settings_are_rejected(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_parameters(values)


@pytest.mark.slow
@pytest.mark.parametrize('name', sorted(OFF_CENTRE_CROPS))
def test_the_held_search_stays_on_the_framed_sign(shared_data_dir: Path,
                                                  classifier: Classifier, name: str) -> None:
    crop = _crop(shared_data_dir, name)
    (x_px, y_px, radius_px), = crop_positions(crop.shape, 'margin')
    (free,) = classifier.evidence_for_candidates(crop, [(x_px, y_px, radius_px)])
    (held,) = classifier.evidence_for_candidates(crop, [(x_px, y_px, radius_px)],
                                                 held_to_framing=True)
    assert isinstance(free, CorrelationEvidence) and isinstance(held, CorrelationEvidence)
    assert math.hypot(free.x_px - x_px, free.y_px - y_px) > 0.25 * radius_px
    assert math.hypot(held.x_px - x_px, held.y_px - y_px) < 0.15 * radius_px
    assert held.ranked[0][0] == OFF_CENTRE_CROPS[name]


@pytest.mark.slow
@pytest.mark.parametrize('name', sorted(OFF_CENTRE_CROPS))
def test_a_crop_read_as_no_sign_is_read_by_the_framed_retry(
        shared_data_dir: Path, classifier: Classifier, without_retry: Classifier,
        name: str) -> None:
    crop = _crop(shared_data_dir, name)
    assert without_retry.classify_crop(crop).label == 'no_sign'
    answer = classifier.classify_crop(crop)
    assert answer.label == OFF_CENTRE_CROPS[name]
    assert answer.psr >= classifier.config.larger_size_retry_min_psr
    # the retry is a second look: its answer must be clear to replace "no sign"
    strict = Classifier(dataclasses.replace(classifier.config, larger_size_retry_min_psr=50.0))
    assert strict.classify_crop(crop).label == 'no_sign'
