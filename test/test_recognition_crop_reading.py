"""Reading crops: the positions a framing implies, the crops' detection gate, and the framed
retry after "no sign"."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from speed_sign_detector.config import ClassifierConfig, ConfigError
from speed_sign_detector.config_parameters import from_parameters
from speed_sign_detector.labelled_crops import LabelledCrop
from speed_sign_detector.recognition.candidate_evidence import CorrelationEvidence
from speed_sign_detector.recognition.classification import LABEL_NO_SIGN, Classification
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.crop_framing import auto_framings, crop_sign_radius
from speed_sign_detector.recognition.crop_reading import (
    crop_positions,
    decide_crop,
    framed_search_config,
)
from speed_sign_detector.recognition.second_opinion import SecondOpinion
from speed_sign_detector.recognition.sign_designs import design_crop
from speed_sign_detector.recognition.sign_reading import SignReading
from speed_sign_detector.training.bank_training import locate_signs

#: gtsrb-dev crops (class folder 00003 = 60 km/h, 00007 = 100 km/h) where the free search
#: settles 8-9 px off the centre of a 56 px crop (on a filter that reads no class clearly)
#: and the search held to the framing reads the limit.
OFF_CENTRE_CROPS = {'00003/00012_00024.png': '60', '00007/00012_00024.png': '100'}
#: gtsrb-dev crops (00001 = 30 km/h, backlit; 00008 = 120 km/h) whose ring the detection
#: filters find with a PSR of 3.3-3.8: under the frames' gate (4), over the crops' (2.5).
WEAK_RING_CROPS = {'00001/00051_00003.png': '30', '00008/00037_00015.png': '120'}


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
    assert crop_positions(shape, 'tight', 5.0) == [
        (25.0, 20.0, crop_sign_radius(shape, 'tight'))]
    assert crop_positions(shape, 'auto', 5.0) == [
        (25.0, 20.0, crop_sign_radius(shape, 'margin')),
        (25.0, 20.0, crop_sign_radius(shape, 'tight'))]


def test_auto_framing_of_a_crop_too_small_for_gtsrb_margins() -> None:
    # GTSRB's 5 px margins leave a 19 px crop a sign of radius 4.5 px, under the least
    # radius read (5 px): 'auto' compares a margin in proportion and none instead
    assert crop_sign_radius((19, 19), 'margin') == 4.5
    assert auto_framings((19, 19), 5.0) == ('padded', 'tight')
    assert auto_framings((20, 20), 5.0) == ('margin', 'tight')
    assert auto_framings((19, 19), 4.5) == ('margin', 'tight')
    assert [radius for _, _, radius in crop_positions((19, 19), 'auto', 5.0)] == [
        crop_sign_radius((19, 19), 'padded'), 9.5]
    # an explicit framing stands whatever the size
    assert crop_positions((19, 19), 'margin', 5.0) == [(9.5, 9.5, 4.5)]


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
    ({'classifier.crop_detection_psr_threshold': -1.0}, 'below its minimum'),
])
def test_invalid_retry_settings_are_rejected(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_parameters(values)


@pytest.mark.slow
@pytest.mark.parametrize('name', sorted(OFF_CENTRE_CROPS))
def test_the_held_search_stays_on_the_framed_sign(shared_data_dir: Path,
                                                  classifier: Classifier, name: str) -> None:
    crop = _crop(shared_data_dir, name)
    (x_px, y_px, radius_px), = crop_positions(crop.shape, 'margin', 5.0)
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


@pytest.mark.slow
@pytest.mark.parametrize('name', sorted(WEAK_RING_CROPS))
def test_a_crop_whose_ring_is_found_weakly_is_read(shared_data_dir: Path,
                                                   classifier: Classifier, name: str) -> None:
    crop = _crop(shared_data_dir, name)
    config = classifier.config
    assert classifier.crop_detection_gate == config.crop_detection_psr_threshold
    evidence = classifier.crop_evidence(crop)
    assert isinstance(evidence, CorrelationEvidence)
    assert config.crop_detection_psr_threshold <= evidence.detection_psr \
        < config.detection_psr_threshold
    answer = classifier.decide_crop(crop, evidence)
    assert answer.label == WEAK_RING_CROPS[name]
    # with the frames' gate the classification filters never run: "no sign"
    frames_gate = Classifier(dataclasses.replace(
        config, crop_detection_psr_threshold=config.detection_psr_threshold))
    assert not isinstance(frames_gate.crop_evidence(crop), CorrelationEvidence)
    assert frames_gate.classify_crop(crop).label == 'no_sign'
    # a weak ring needs a clear reading: under psr_threshold the first look's answer is
    # withheld (the second looks are off here: 'margin' framing, no framed retry)
    unclear = Classifier(dataclasses.replace(config, psr_threshold=answer.psr + 1.0,
                                             crop_framed_retry=False))
    assert unclear.decide(crop, evidence, crop=True).label == WEAK_RING_CROPS[name]
    assert unclear.decide_crop(crop, evidence, framing='margin').label == 'no_sign'


@pytest.mark.slow
def test_training_locates_signs_with_the_frames_gate(shared_data_dir: Path,
                                                     classifier: Classifier) -> None:
    names = sorted(WEAK_RING_CROPS)
    images = [_crop(shared_data_dir, name) for name in names]
    crops = [LabelledCrop(shared_data_dir / 'gtsrb-dev' / name,
                          (0, 0, image.shape[1] - 1, image.shape[0] - 1), 1, name[:11])
             for name, image in zip(names, images)]
    located = locate_signs(classifier, crops, images)
    # read (the evidence validation uses), but not a training example
    assert all(isinstance(evidence, CorrelationEvidence) for evidence in located.evidence)
    assert np.isnan(located.signs).all()


@pytest.mark.slow
def test_the_renderings_alone_keep_the_frames_gate(shared_data_dir: Path,
                                                   config: ClassifierConfig) -> None:
    rendered = Classifier(dataclasses.replace(config, bank_file='none'))
    assert rendered.crop_detection_gate == config.detection_psr_threshold
    for name in sorted(WEAK_RING_CROPS):
        assert not isinstance(rendered.crop_evidence(_crop(shared_data_dir, name)),
                              CorrelationEvidence)


def test_crops_read_rendered_only_leaders_with_their_own_floor(
        classifier: Classifier, monkeypatch: pytest.MonkeyPatch) -> None:
    """A crop's decision hands the second opinion ``crop_rendered_only_min_score``; a
    frame's candidate keeps the form's floor (``None``), which keeps clutter out."""
    floors: list[float | None] = []
    choose = SecondOpinion.choose

    def spy(self: SecondOpinion, *args: object, **kwargs: object) -> str | None:
        floors.append(kwargs.get('rendered_only_floor', args[6] if len(args) > 6 else None))
        return choose(self, *args, **kwargs)

    monkeypatch.setattr(SecondOpinion, 'choose', spy)
    crop = design_crop('40', 'painted', 44, np.random.default_rng(3))
    evidence = classifier.crop_evidence(crop)
    assert isinstance(evidence, CorrelationEvidence)
    classifier.decide(crop, evidence, crop=True)
    classifier.decide(crop, evidence, crop=False)
    assert floors == [classifier.config.crop_rendered_only_min_score, None]


def test_frames_answer_a_value_without_crops_only_on_a_clear_peak(
        classifier: Classifier, config: ClassifierConfig) -> None:
    """In a frame, a limit the bank has no real crops of (130: composites of real digits)
    needs ``frame_value_without_crops_min_psr``; a crop does not, nor does a value with
    real crops (30)."""
    bank = classifier.trained_bank
    assert bank.second_opinion is not None
    assert '130' not in bank.second_opinion.labels_with_crops
    assert '30' in bank.second_opinion.labels_with_crops
    lenient = Classifier(dataclasses.replace(config, frame_value_without_crops_min_psr=0.0),
                         bank)
    rng = np.random.default_rng(5)
    for value in ('130', '30'):
        crop = design_crop(value, 'painted', 48, rng)
        evidence = classifier.crop_evidence(crop)
        assert isinstance(evidence, CorrelationEvidence)
        peak = evidence.ranked[0][1]
        strict = Classifier(dataclasses.replace(
            config, frame_value_without_crops_min_psr=peak + 1.0), bank)
        assert lenient.decide(crop, evidence).label == value
        assert strict.decide(crop, evidence, crop=True).label == value
        expected = LABEL_NO_SIGN if value == '130' else value
        assert strict.decide(crop, evidence).label == expected


def test_frames_overrule_the_correlation_only_on_a_clear_peak(
        classifier: Classifier, config: ClassifierConfig, monkeypatch) -> None:
    """In a frame, the second opinion answers a limit other than the correlation's leader
    only where the leader's PSR is at least ``frame_overrule_min_psr`` (a weak peak is
    often clutter it reads a limit in); it may still agree with a weak leader, and a crop
    (which frames a sign) is overruled on any peak. A model all but certain (a lead of
    ``second_opinion_certain_lead``) overrules a leader under ``psr_threshold`` in a frame
    too (:meth:`.SecondOpinion.certain_choice`)."""
    opinion = classifier.trained_bank.second_opinion
    assert opinion is not None and config.frame_overrule_min_psr == 8.0
    assert config.second_opinion_certain_lead > 1.9
    scores = np.full(len(opinion.labels), -1.0, np.float32)
    scores[opinion.labels.index('30')] = 0.9  # the model is sure, short of certain: a 30
    monkeypatch.setattr(classifier, 'sign_reading',
                        lambda gray, evidence: SignReading(scores, None))
    gray = np.full((100, 100), 128, np.uint8)

    def evidence(leader: str, psr: float) -> CorrelationEvidence:
        runner_up = '30' if leader != '30' else '70'
        return CorrelationEvidence(((leader, psr), (runner_up, psr - 0.2), ('20', psr - 2.0),
                                    ('50', psr - 2.5)), 50.0, 50.0, 20.0, 0.0, 9.0)

    weak = evidence('70', 7.0)
    assert classifier.decide(gray, weak).label == LABEL_NO_SIGN
    assert classifier.decide(gray, weak, crop=True).label == '30'
    assert classifier.decide(gray, evidence('70', 8.5)).label == '30'
    assert classifier.decide(gray, evidence('30', 7.0)).label == '30'
    lenient = Classifier(dataclasses.replace(config, frame_overrule_min_psr=0.0),
                         classifier.trained_bank)
    monkeypatch.setattr(lenient, 'sign_reading', lambda gray, evidence: SignReading(scores, None))
    assert lenient.decide(gray, weak).label == '30'
    scores[opinion.labels.index('30')] = 1.0  # all but certain
    assert classifier.decide(gray, weak).label == '30'


def test_on_a_lit_face_a_limit_needs_a_clear_lead_over_every_other_limit(
        classifier: Classifier, config: ClassifierConfig, monkeypatch) -> None:
    """On a sign whose face glows in dark surroundings (``SignReading.lit_face``), a limit
    the model agrees on is answered only with a PSR lead of ``lit_face_min_margin`` over
    every other limit the correlation ranks (a non-limit between them does not count);
    without the glow the same evidence is answered, in a frame and as a crop."""
    opinion = classifier.trained_bank.second_opinion
    assert opinion is not None and config.lit_face_min_margin == 0.75
    scores = np.full(len(opinion.labels), -1.0, np.float32)
    scores[opinion.labels.index('60')] = 0.9   # the model is sure of the leader, 60
    lit = [True]
    monkeypatch.setattr(classifier, 'sign_reading',
                        lambda gray, evidence: SignReading(scores, None, lit_face=lit[0]))
    gray = np.full((100, 100), 128, np.uint8)

    def evidence(lead: float) -> CorrelationEvidence:
        return CorrelationEvidence((('60', 12.0), ('weight_limit', 11.9), ('80', 12.0 - lead),
                                    ('50', 9.0)), 50.0, 50.0, 20.0, 0.0, 9.0)

    for crop in (False, True):
        lit[0] = True
        assert classifier.decide(gray, evidence(0.5), crop=crop).label == LABEL_NO_SIGN
        assert classifier.decide(gray, evidence(1.0), crop=crop).label == '60'
        lit[0] = False
        assert classifier.decide(gray, evidence(0.5), crop=crop).label == '60'
    lit[0] = True
    lenient = Classifier(dataclasses.replace(config, lit_face_min_margin=0.0),
                         classifier.trained_bank)
    monkeypatch.setattr(lenient, 'sign_reading',
                        lambda gray, evidence: SignReading(scores, None, lit_face=True))
    assert lenient.decide(gray, evidence(0.5)).label == '60'


def test_frames_have_their_own_floor_of_the_correlation_psr(
        classifier: Classifier, config: ClassifierConfig, monkeypatch) -> None:
    """With a second opinion, a frame's candidate is answered down to
    ``frame_second_opinion_psr_threshold`` and a crop down to
    ``second_opinion_psr_threshold``: a peak between the two is read in the one and
    withheld in the other; below both it is withheld in either."""
    opinion = classifier.trained_bank.second_opinion
    assert opinion is not None
    frame_floor = config.frame_second_opinion_psr_threshold
    crop_floor = config.second_opinion_psr_threshold
    assert frame_floor < crop_floor < config.psr_threshold
    scores = np.full(len(opinion.labels), -1.0, np.float32)
    scores[opinion.labels.index('30')] = 1.0  # the model is sure: a 30
    monkeypatch.setattr(classifier, 'sign_reading',
                        lambda gray, evidence: SignReading(scores, None))
    gray = np.full((100, 100), 128, np.uint8)

    def evidence(psr: float) -> CorrelationEvidence:
        return CorrelationEvidence((('30', psr), ('70', psr - 2.0), ('20', psr - 2.5),
                                    ('50', psr - 3.0)), 50.0, 50.0, 20.0, 0.0, 9.0)

    between = evidence((frame_floor + crop_floor) / 2)
    assert classifier.decide(gray, between).label == '30'
    assert classifier.decide(gray, between, crop=True).label == LABEL_NO_SIGN
    below = evidence(frame_floor - 0.1)
    assert classifier.decide(gray, below).label == LABEL_NO_SIGN
    assert classifier.decide(gray, below, crop=True).label == LABEL_NO_SIGN
    above = evidence(crop_floor + 0.1)
    assert classifier.decide(gray, above, crop=True).label == '30'


class _TwoLooks:
    """A :class:`~.crop_reading.CropReader` whose first look and framed look answer as
    given (their evidence is the answer itself)."""

    def __init__(self, framed: Classification) -> None:
        self.config = ClassifierConfig()
        self.framed = framed
        self.framed_looks = 0

    @property
    def crop_detection_gate(self) -> float:
        return self.config.crop_detection_psr_threshold

    def evidence_for_candidates(self, gray, positions, detection_psr_threshold=None,
                                held_to_framing=False):
        assert held_to_framing, 'only the framed look is asked for'
        self.framed_looks += 1
        return [self.framed]

    def decide(self, gray, evidence, use_second_opinion=True, crop=False):
        return evidence

    def second_look_stands(self, answer: Classification) -> bool:
        return answer.label != LABEL_NO_SIGN


def _answer(label: str, psr: float) -> Classification:
    return Classification(label, int(label) if label.isdigit() else None, psr, 20.0, 0.0,
                          2.0, 30.0, 30.0)


def test_a_limit_the_framed_look_reads_otherwise_is_withheld() -> None:
    """A limit the first look reads is checked by the framed look: another limit read at
    least as clearly there withholds the crop (a 130 whose free search read the inner
    30); a weaker other limit, the same limit or no sign leaves the answer."""
    crop = np.zeros((60, 60), np.uint8)
    first = _answer('30', 15.5)
    for framed, expected in ((_answer('130', 18.3), LABEL_NO_SIGN),
                             (_answer('130', 15.5), LABEL_NO_SIGN),
                             (_answer('130', 12.0), '30'),
                             (_answer('30', 18.0), '30'),
                             (_answer(LABEL_NO_SIGN, 0.0), '30'),
                             (_answer('other_sign', 19.0), '30')):
        reader = _TwoLooks(framed)
        assert decide_crop(reader, crop, first, 'margin').label == expected, framed
        assert reader.framed_looks == 1
    # without the framed retry there is no framed look to check with
    reader = _TwoLooks(_answer('130', 18.3))
    reader.config = dataclasses.replace(reader.config, crop_framed_retry=False)
    assert decide_crop(reader, crop, first, 'margin').label == '30'
    assert reader.framed_looks == 0
    # an answer that is no limit is not checked
    reader = _TwoLooks(_answer('130', 18.3))
    assert decide_crop(reader, crop, _answer('other_sign', 12.0), 'margin').label \
        == 'other_sign'
    assert reader.framed_looks == 0
