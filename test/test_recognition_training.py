"""Training a bank from labelled crops, the bank file, crop framing, the cache, the CLI.

The crop folders are generated here (rendered signs on textured backgrounds, GTSRB
file names and labels.csv), so the answers are known and no real data is needed.
"""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scene_helpers import textured_background

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import BankFileError, TrainingDataError
from speed_sign_detector.labelled_crops import read_crop_folder, track_folds
from speed_sign_detector.recognition.bank_file import load_bank_file, save_bank_file
from speed_sign_detector.recognition.classifier import (
    Classifier,
    CorrelationEvidence,
    crop_sign_radius,
)
from speed_sign_detector.recognition.crop_framing import (
    auto_framings,
    padded_fallback_radius,
)
from speed_sign_detector.recognition.filter_banks import bank_radii, build_banks
from speed_sign_detector.recognition.second_opinion import SecondOpinion
from speed_sign_detector.recognition.sign_features import FEATURE_SIZE
from speed_sign_detector.recognition.templates import LIMIT_VALUES_KMH, render_sign
from speed_sign_detector.recognition.trained_bank import (
    TRAINED_BANK_FORMAT,
    TRAINED_BANK_VERSION,
    TrainedBank,
    load_trained_bank,
    save_trained_bank,
)
from speed_sign_detector.recognition.sign_designs import design_training_crops
from speed_sign_detector.training.bank_training import (
    TrainingConfig,
    locate_rendered,
    rendered_classifier,
    rendered_training_crops,
    train_bank,
)
from speed_sign_detector.training.track_validation import cross_validate

#: Small banks (radius 16-24 px) keep the module fast.
SMALL = ClassifierConfig(max_radius_px=24.0, cache_dir='', bank_file='none')
#: GTSRB class id -> rendered kind.
KINDS = {1: '30', 2: '50', 5: '80', 17: 'no_entry'}
TRAINING = TrainingConfig(augmented_copies=1, examples_per_class=2, rendered_per_kind=3,
                          composites_per_value=4, design_per_kind=1)


def crop_of(kind: str, sign_px: int, margin_px: int, seed: int, blur_px: float = 0.0
            ) -> np.ndarray:
    """A gray crop: one rendered sign ``sign_px`` wide with ``margin_px`` around it."""
    side = sign_px + 2 * margin_px
    background = cv2.cvtColor(textured_background(seed, side, side), cv2.COLOR_BGR2GRAY)
    bgr, alpha = render_sign(kind, sign_px)
    sign = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    frame = background.astype(np.float32)
    window = frame[margin_px:margin_px + sign_px, margin_px:margin_px + sign_px]
    window[:] = sign + (1.0 - alpha) * window
    if blur_px:
        frame = cv2.GaussianBlur(frame, (0, 0), blur_px)
    return np.clip(frame, 0, 255).astype(np.uint8)


def write_crop_folder(folder: Path, tracks_per_class: int = 3, per_track: int = 3,
                      seed: int = 0) -> Path:
    """A GTSRB-format folder: CLASS/TRACK_INDEX.png and labels.csv (10% margin)."""
    rows = ['Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId']
    for class_id, kind in KINDS.items():
        for track in range(tracks_per_class):
            for index in range(per_track):
                sign = 30 + 4 * index + 2 * track
                margin = max(5, sign // 10)
                crop = crop_of(kind, sign, margin, seed + 97 * class_id + 13 * track + index,
                               blur_px=0.4 * (index % 2))
                name = f'{class_id:05d}/{track:05d}_{index:05d}.png'
                (folder / f'{class_id:05d}').mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(folder / name), crop)
                side = crop.shape[0]
                rows.append(f'{name};{side};{side};{margin};{margin};{margin + sign - 1};'
                            f'{margin + sign - 1};{class_id}')
    (folder / 'labels.csv').write_text('\n'.join(rows) + '\n')
    return folder


@pytest.fixture(scope='module')
def crop_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_crop_folder(tmp_path_factory.mktemp('crops'))


@pytest.fixture(scope='module')
def trained(crop_folder: Path) -> TrainedBank:
    return train_bank([crop_folder], SMALL, TRAINING)


def test_training_gives_a_bank_that_reads_those_signs(trained: TrainedBank) -> None:
    classifier = Classifier(SMALL, trained)
    for class_id, kind in KINDS.items():
        crop = crop_of(kind, 34, 5, seed=1000 + class_id)  # not a training crop
        answer = classifier.classify_crop(crop).label
        assert answer == (kind if kind.isdigit() else answer), (kind, answer)
        if not kind.isdigit():
            assert not answer.isdigit(), f'look-alike {kind} read as {answer}'
    assert trained.second_opinion is not None
    # the real classes, and from the renderings every limit the package draws
    assert {'30', '50', '80', 'other_sign', 'end_of_limit'} <= set(trained.second_opinion.labels)
    assert {str(v) for v in LIMIT_VALUES_KMH} <= set(trained.second_opinion.labels)
    # it chooses only among the labels it saw real pixels of: the crops' classes, and the
    # values whose digits all occur in them (5, from the 5 of the 50)
    assert set(trained.second_opinion.real_labels) == {'30', '50', '80', '5', 'other_sign'}
    assert set(trained.class_examples) == {'30', '50', '80'}
    # composite filters trained from the crops (and the renderings of the other labels)
    assert trained.real_filters is not None
    assert set(trained.real_filters.labels) == set(trained.second_opinion.labels)
    assert trained.real_filters.weight == TRAINING.real_filter_weight > 0
    assert trained.provenance['counts_per_class'] == {'30': 9, '50': 9, '80': 9,
                                                      'other_sign': 9}


def test_values_made_of_real_digits_count_as_learned_from_real_pixels(
        trained: TrainedBank) -> None:
    """The crops show 30, 50 and 80: a 5 km/h composite has only real digits (the 5 of the
    50), so the second opinion may choose it; 20, 40 or 130 need a digit no crop shows, so
    they stay rendered classes, which it never chooses over the correlation."""
    opinion = trained.second_opinion
    assert opinion is not None
    assert {'30', '50', '80', '5'} <= set(opinion.real_labels)
    assert not {'20', '40', '130', '140'} & set(opinion.real_labels)
    assert {'20', '40', '130', '140'} <= set(opinion.labels)  # known from renderings


def test_bank_file_round_trips(tmp_path: Path, trained: TrainedBank) -> None:
    path = tmp_path / 'bank.npz'
    save_trained_bank(path, trained)
    loaded = load_trained_bank(path)
    assert loaded.second_opinion is not None and trained.second_opinion is not None
    assert loaded.second_opinion.labels == trained.second_opinion.labels
    np.testing.assert_allclose(loaded.second_opinion.weights, trained.second_opinion.weights,
                               rtol=2e-3, atol=1e-4)  # weights stored as float16
    assert loaded.candidates == trained.candidates and loaded.min_lead == trained.min_lead
    assert loaded.provenance['counts_per_class'] == trained.provenance['counts_per_class']
    assert loaded.provenance['package_version']
    assert loaded.real_filters is not None and trained.real_filters is not None
    assert loaded.real_filters.labels == trained.real_filters.labels
    np.testing.assert_array_equal(loaded.real_filters.spectra, trained.real_filters.spectra)
    crop = crop_of('50', 36, 5, seed=77)
    config = dataclasses.replace(SMALL, bank_file=str(path))
    assert Classifier(config).classify_crop(crop).label == '50'


def _flip_byte(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize('damage', ['truncated', 'empty', 'byte flipped', 'missing'])
def test_corrupt_bank_file_is_a_clear_error(tmp_path: Path, trained: TrainedBank,
                                            damage: str) -> None:
    path = tmp_path / 'bank.npz'
    save_trained_bank(path, trained)
    size = path.stat().st_size
    if damage == 'truncated':
        path.write_bytes(path.read_bytes()[:size // 2])
    elif damage == 'empty':
        path.write_bytes(b'')
    elif damage == 'byte flipped':
        _flip_byte(path, size // 3)
    else:
        path.unlink()
    with pytest.raises(BankFileError, match=str(path.name)):
        load_trained_bank(path)
    with pytest.raises(BankFileError):
        Classifier(dataclasses.replace(SMALL, bank_file=str(path)))


def test_bank_of_another_version_or_format_is_refused(tmp_path: Path) -> None:
    path = tmp_path / 'bank.npz'
    save_bank_file(path, {'x': np.zeros(3)}, {}, TRAINED_BANK_FORMAT, TRAINED_BANK_VERSION + 1)
    with pytest.raises(BankFileError, match=f'version {TRAINED_BANK_VERSION + 1}.*reads version'):
        load_trained_bank(path)
    save_bank_file(path, {'x': np.zeros(3)}, {}, 'something.else', 1)
    with pytest.raises(BankFileError, match="'something.else'"):
        load_trained_bank(path)
    with pytest.raises(ValueError, match='object'):
        save_bank_file(path, {'x': np.asarray([{}], dtype=object)}, {}, 'f', 1)
    arrays, meta = load_bank_file(path, 'something.else', (1,))  # the refused save left it
    assert meta['format_version'] == 1 and set(arrays) == {'x'}


@pytest.mark.parametrize('damage', ['truncated', 'empty', 'byte flipped'])
def test_corrupt_filter_bank_cache_is_rebuilt(tmp_path: Path, damage: str) -> None:
    config = dataclasses.replace(SMALL, max_radius_px=17.0, cache_dir=str(tmp_path))
    first = build_banks(config)
    (cache,) = tmp_path.glob('filter_banks_*.npz')
    size = cache.stat().st_size
    if damage == 'truncated':
        cache.write_bytes(cache.read_bytes()[:size // 2])
    elif damage == 'empty':
        cache.write_bytes(b'')
    else:
        _flip_byte(cache, size // 2)
    rebuilt = build_banks(config)
    assert len(rebuilt) == len(bank_radii(config))
    np.testing.assert_array_equal(rebuilt[0].classification, first[0].classification)
    load_bank_file(cache, 'speed_sign_detector.filter_bank_cache', (6,))  # rewritten whole


@pytest.mark.parametrize('framing', ['auto', 'margin', 'tight'])
def test_tight_and_margin_crops(trained: TrainedBank, framing: str) -> None:
    classifier = Classifier(SMALL, trained)
    margin_crop = crop_of('80', 36, 6, seed=5)
    tight_crop = np.ascontiguousarray(margin_crop[6:-6, 6:-6])
    for crop, kind in ((margin_crop, 'margin'), (tight_crop, 'tight')):
        answer = classifier.classify_crop(crop, framing)
        if framing in ('auto', kind):
            assert answer.label == '80', (framing, kind, answer)
            assert abs(answer.radius_px - 18.0) < 3.0
    assert crop_sign_radius((48, 48), 'tight') == 24.0
    assert crop_sign_radius((48, 48), 'margin') == 19.0
    with pytest.raises(ValueError, match='unknown crop framing'):
        classifier.classify_crop(tight_crop, 'loose')


@pytest.mark.parametrize('kind', ['30', '50', '80', '120'])
def test_small_crop_padded_in_proportion_is_read_by_auto(kind: str) -> None:
    # a 13 px sign with 2 px around it (a 17 px crop, padded in proportion as some tools
    # cut boxes): GTSRB's least margin of 5 px makes 'margin' expect a 3.5 px radius (too
    # small to read), and 'tight' 8.5 px; 'auto' compares 'padded' (7.1 px) and 'tight'
    crop = crop_of(kind, 13, 2, seed=1)
    classifier = Classifier(SMALL)
    assert classifier.classify_crop(crop, 'margin').label == 'no_sign'
    assert classifier.classify_crop(crop, 'tight').label == 'no_sign'
    assert auto_framings(crop.shape, SMALL.min_sign_radius_px) == ('padded', 'tight')
    padded = classifier.classify_crop(crop, 'padded')
    assert padded.label == kind
    evidence = classifier.crop_evidence(crop, 'auto')
    assert classifier.decide(crop, evidence, crop=True) == padded  # the first look reads it
    assert classifier.classify_crop(crop, 'auto') == padded
    assert abs(padded.radius_px - 6.5) < 1.5
    # the filters alone, as cross-validation asks them, read it too
    assert classifier.decide_crop(crop, evidence, use_second_opinion=False).label == kind
    assert crop_sign_radius(crop.shape, 'padded') == pytest.approx(17 / 1.2 / 2)
    assert padded_fallback_radius(crop.shape) == pytest.approx(17 / 1.2 / 2)
    # from about 60 px GTSRB's margin is 10 % too: no fallback to try
    assert padded_fallback_radius((72, 72)) is None
    assert crop_sign_radius((72, 72), 'padded') == crop_sign_radius((72, 72), 'margin')


@pytest.mark.parametrize('kind', ['50', '80'])
def test_padded_fallback_needs_a_clear_peak(kind: str) -> None:
    # an 18 px sign with 2 px around it (a 22 px crop): 'margin' (6 px) reads no sign;
    # 'auto' answered so looks once more at the 'padded' radius (9.2 px), and that second
    # look stands only with a PSR of at least larger_size_retry_min_psr
    crop = crop_of(kind, 18, 2, seed=1)
    no_retry = dataclasses.replace(SMALL, crop_framed_retry=False)
    classifier = Classifier(no_retry)
    assert auto_framings(crop.shape, SMALL.min_sign_radius_px) == ('margin', 'tight')
    margin = classifier.crop_evidence(crop, 'margin')
    assert classifier.decide(crop, margin, crop=True).label == 'no_sign'
    padded = classifier.classify_crop(crop, 'padded')
    assert padded.label == kind
    assert padded.psr >= SMALL.larger_size_retry_min_psr
    assert classifier.decide_crop(crop, margin, 'auto') == padded
    stricter = Classifier(dataclasses.replace(no_retry,
                                              larger_size_retry_min_psr=padded.psr + 0.1))
    assert stricter.decide_crop(crop, margin, 'auto').label == 'no_sign'


@pytest.mark.parametrize('kind', ['30', '80', '120'])
def test_box_inside_the_sign_edge_is_read_as_a_crop_but_not_as_a_frame(kind: str) -> None:
    # annotation boxes often sit a pixel or two inside the ring (GTSRB ROIs do): the crop
    # border is the sign's box, not a frame border cutting the sign off
    margin_crop = crop_of(kind, 36, 6, seed=5)
    box = np.ascontiguousarray(margin_crop[8:-8, 8:-8])  # 2 px inside the sign's edge
    classifier = Classifier(SMALL)
    for framing in ('tight', 'auto'):
        assert classifier.classify_crop(box, framing).label == kind, framing
    # the same pixels as a camera frame: the sign reaches beyond the border, and the
    # frame rule (max_cut_fraction) withholds it
    centre = box.shape[1] / 2.0
    radius = crop_sign_radius(box.shape, 'tight') / SMALL.candidate_radius_scale
    (in_frame,) = classifier.classify(box, [Candidate(centre, centre, radius, 1.0)])
    assert in_frame.label == 'no_sign'
    assert in_frame.radius_px > 18.0  # measured beyond the border


def test_folds_never_split_a_track(crop_folder: Path) -> None:
    crops = read_crop_folder(crop_folder)
    folds = track_folds(crops, 3)
    for track in {crop.track for crop in crops}:
        assert len({int(f) for c, f in zip(crops, folds) if c.track == track}) == 1
    assert set(folds.tolist()) == {0, 1, 2}


def test_cross_validation_reports_every_variant(crop_folder: Path) -> None:
    report = cross_validate([crop_folder], 3, SMALL, TRAINING)
    assert report['crops'] == 36 and report['folds'] == 3
    assert set(report['variants']) == {'rendered', 'trained_filters',
                                       'second_opinion_rendered_ranking',
                                       'trained_filters_second_opinion'}
    for variant, summary in report['variants'].items():
        assert set(summary['per_class']) == {'30', '50', '80'}, variant
        assert summary['lookalikes'] == 9
        assert 0.0 <= summary['accuracy'] <= 1.0
        assert len(report['fold_accuracy'][variant]) == 3
    assert report['variants']['trained_filters_second_opinion']['accuracy'] >= 0.8


def test_empty_or_unlabelled_folders_are_clear_errors(tmp_path: Path) -> None:
    (tmp_path / 'labels.csv').write_text('')
    with pytest.raises(TrainingDataError, match='is empty'):
        train_bank([tmp_path], SMALL, TRAINING)
    with pytest.raises(TrainingDataError, match='cannot read'):
        train_bank([tmp_path / 'nowhere'], SMALL, TRAINING)


def _train_command() -> list[str]:
    script = Path(sys.executable).with_name('speed_sign_train')
    if script.exists():
        return [str(script)]
    return [sys.executable, '-c', 'import sys; from speed_sign_detector.tools.train import '
            'main; sys.exit(main())']


def write_small_params(folder: Path) -> Path:
    """A node parameter file with the small filter banks of :data:`SMALL`."""
    config = folder / 'params.yaml'
    config.write_text('speed_sign_detector:\n  ros__parameters:\n    classifier:\n'
                      '      max_radius_px: 24\n      cache_dir: ""\n')
    return config


def test_train_command_builds_a_bank_and_reports_bad_input(tmp_path: Path,
                                                           crop_folder: Path) -> None:
    out = tmp_path / 'my_bank.npz'
    config = write_small_params(tmp_path)
    env = dict(os.environ, PYTHONWARNINGS='ignore')
    done = subprocess.run(_train_command() + [
        'build', str(out), str(crop_folder), '--config', str(config), '--augmented-copies', '0',
        '--examples-per-class', '1', '--rendered-per-kind', '1', '--real-filter-weight', '0.5',
        '--composites-per-value', '2', '--design-per-kind', '0',
        '--json', '-q'], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary['crops'] == 36 and out.is_file() and summary['bytes'] == out.stat().st_size
    built = load_trained_bank(out)
    provenance = built.provenance
    assert provenance['data_folders'] == [str(crop_folder)]
    assert provenance['classifier']['max_radius_px'] == 24.0
    assert provenance['training']['real_filter_weight'] == 0.5
    # where it was trained: the host and the BLAS kernels, also in the JSON summary
    assert provenance['host']['cpu_model'] and provenance['host']['blas']
    assert summary['host'] == provenance['host']
    assert f'trained on {provenance["host"]["cpu_model"]}' in done.stdout
    assert built.real_filters is not None and built.real_filters.weight == 0.5
    refused = subprocess.run(_train_command() + [
        'build', str(tmp_path / 'y.npz'), str(crop_folder), '--real-filter-weight', '-1'],
        capture_output=True, text=True, timeout=300, env=env)
    assert refused.returncode == 2 and 'argument --real-filter-weight' in refused.stderr
    assert 'Traceback' not in refused.stderr and not (tmp_path / 'y.npz').exists()
    empty = tmp_path / 'empty'
    empty.mkdir()
    (empty / 'labels.csv').write_text('')
    failed = subprocess.run(_train_command() + ['build', str(tmp_path / 'x.npz'), str(empty)],
                            capture_output=True, text=True, timeout=300, env=env)
    assert failed.returncode == 1
    assert 'is empty' in failed.stderr and 'Traceback' not in failed.stderr
    assert not (tmp_path / 'x.npz').exists()


def test_linear_second_opinion_still_trains_and_reads_those_signs(crop_folder: Path) -> None:
    linear = train_bank([crop_folder], SMALL, dataclasses.replace(TRAINING, model='linear',
                                                                  min_lead=0.2))
    assert linear.second_opinion is not None and linear.second_opinion.form == 'linear'
    assert linear.provenance['training']['model'] == 'linear'
    classifier = Classifier(SMALL, linear)
    crops = read_crop_folder(crop_folder)
    answers = [classifier.classify_crop(cv2.imread(str(c.path), cv2.IMREAD_GRAYSCALE)).label
               for c in crops]
    limits = [(c.label, a) for c, a in zip(crops, answers) if c.label.isdigit()]
    assert sum(truth == answer for truth, answer in limits) >= 0.8 * len(limits)
    assert not any(answer.isdigit() and answer != truth for truth, answer in limits)


def test_train_command_refuses_invalid_settings(tmp_path: Path, crop_folder: Path) -> None:
    out = tmp_path / 'bank.npz'
    env = dict(os.environ, PYTHONWARNINGS='ignore')
    for option in (['--members', '0'], ['--hidden-units', '0'], ['--candidates', '0'],
                   ['--arched-six-per-kind', '-1']):
        done = subprocess.run(_train_command() + ['build', str(out), str(crop_folder), '-q']
                              + option, capture_output=True, text=True, timeout=120, env=env)
        assert done.returncode == 2, option  # a usage error, named by its option
        assert f'argument {option[0]}: must be' in done.stderr, done.stderr
        assert 'Traceback' not in done.stderr
        assert not out.exists()


def test_arched_six_renderings_follow_the_other_renderings() -> None:
    """``arched_six_per_kind`` adds 60s in the older lettering after the usual renderings,
    which stay as they were (a bank trained without them is unchanged)."""
    plain_crops, plain_labels = rendered_training_crops(1, np.random.default_rng(5))
    crops, labels = rendered_training_crops(1, np.random.default_rng(5), arched_six_per_kind=3)
    assert labels == plain_labels + ['60'] * 3
    for crop, plain in zip(crops, plain_crops):
        np.testing.assert_array_equal(crop, plain)
    assert all(crop.ndim == 2 and crop.shape[0] >= 26 for crop in crops[-3:])


def test_design_renderings_join_the_rendered_training_crops() -> None:
    """LED and yellow-faced signs of every limit, and the end of all restrictions (read as
    an end of limit), join the second opinion's rendered crops, after the usual ones."""
    classifier = rendered_classifier(SMALL)
    plain = locate_rendered(classifier, dataclasses.replace(TRAINING, design_per_kind=0))
    with_designs = locate_rendered(classifier, TRAINING)
    assert plain is not None and with_designs is not None
    design_images, design_labels = design_training_crops(
        TRAINING.design_per_kind, np.random.default_rng(TRAINING.seed + 3))
    labels = [crop.label for crop in with_designs.crops]
    assert labels == [crop.label for crop in plain.crops] + design_labels
    assert set(design_labels) == {str(v) for v in LIMIT_VALUES_KMH} | {'end_of_limit'}
    for image, design_image in zip(with_designs.images[len(plain.crops):], design_images):
        np.testing.assert_array_equal(image, design_image)
    # 'end_of_restrictions' renderings are ends of limits, never 'other_sign'
    crops, kinds = rendered_training_crops(1, np.random.default_rng(0))
    assert 'other_sign' in kinds and kinds.count('end_of_limit') >= 2


def test_weak_correlation_peaks_need_a_clear_second_opinion() -> None:
    """Between the lower threshold (a frame's frame_second_opinion_psr_threshold; a
    crop's second_opinion_psr_threshold) and psr_threshold an answer needs the second
    opinion's larger lead; below the lower threshold, and without a second opinion below
    psr_threshold, the answer is withheld."""
    config = dataclasses.replace(SMALL, psr_threshold=8.0, second_opinion_psr_threshold=7.0,
                                 frame_second_opinion_psr_threshold=7.0,
                                 second_opinion_low_psr_lead=0.5)
    labels = ('30', '80', 'other_sign')
    size = len(labels)

    def classifier_reading(scores: list[float]) -> Classifier:
        # zero weights: the model scores every sign with its bias
        opinion = SecondOpinion(labels, np.zeros(FEATURE_SIZE, np.float32),
                                np.ones(FEATURE_SIZE, np.float32),
                                np.zeros((FEATURE_SIZE, size), np.float32),
                                np.asarray(scores, np.float32), labels)
        return Classifier(config, TrainedBank(opinion, candidates=2, min_lead=0.2))

    gray = crop_of('30', 40, 6, seed=5)

    def answer(classifier: Classifier, psr: float, use_second_opinion: bool = True) -> str:
        evidence = CorrelationEvidence((('30', psr), ('80', psr - 1.0)), 26.0, 26.0, 20.0,
                                       0.0, 10.0)
        return classifier.decide(gray, evidence, use_second_opinion).label

    leads_by_0_3 = classifier_reading([0.3, 0.0, -1.0])
    leads_by_0_6 = classifier_reading([0.6, 0.0, -1.0])
    assert answer(leads_by_0_3, 9.0) == '30'        # a clear peak: the bank's min_lead
    assert answer(leads_by_0_3, 7.5) == 'no_sign'   # a weak peak: 0.3 is not enough
    assert answer(leads_by_0_6, 7.5) == '30'
    assert answer(leads_by_0_6, 6.5) == 'no_sign'   # below second_opinion_psr_threshold
    assert answer(leads_by_0_6, 7.5, use_second_opinion=False) == 'no_sign'
    assert answer(leads_by_0_6, 9.0, use_second_opinion=False) == '30'
