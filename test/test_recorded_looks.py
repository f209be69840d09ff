"""Recorded looks decided again (:mod:`speed_sign_detector.training.recorded_looks`, and
``bench/redecide_rules.py replay``): the same answers as reading the crops, and rule changes
taking effect on the record as they do on the crops."""
from __future__ import annotations

import dataclasses
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.recognition import second_opinion
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.sign_designs import design_crop
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.training.recorded_looks import (
    record_frame,
    record_looks,
    redecide,
    redecide_frame,
)
from test_bench_smoke import bench_module


@pytest.fixture(scope='module')
def crops() -> list[tuple[str, np.ndarray]]:
    """Rendered camera crops of several values and designs (small ones, whose first look
    is often "no sign", among them), and clutter."""
    rng = np.random.default_rng(5)
    found = [(kind, design_crop(kind, design, int(rng.integers(15, 45)), rng))
             for kind in ('30', '60', '80', '100', '130') for design in ('painted', 'led')
             for _ in range(3)]
    found.append(('no_sign', rng.integers(0, 255, (40, 40), dtype=np.uint8)))
    return found


@pytest.fixture(scope='module')
def classifier() -> Classifier:
    return Classifier(ClassifierConfig())


def test_recorded_looks_are_decided_as_the_crops_are(classifier: Classifier, crops) -> None:
    records = [record_looks(classifier, crop) for _, crop in crops]
    answers = [classifier.classify_crop(crop).label for _, crop in crops]
    assert [redecide(classifier, looks).label for looks in records] == answers
    assert sum(answer == kind for answer, (kind, _) in zip(answers, crops)) >= len(crops) // 2
    assert any(looks.padded is not None or looks.held is not None for looks in records)
    # the filters alone decide as the crops' reading without the second opinion does
    alone = [classifier.decide_crop(crop, looks.first, use_second_opinion=False).label
             for looks, (_, crop) in zip(records, crops)]
    assert [redecide(classifier, looks, use_second_opinion=False).label
            for looks in records] == alone


def test_a_rule_changed_after_recording_decides_the_record(classifier: Classifier, crops,
                                                           monkeypatch) -> None:
    records = [record_looks(classifier, crop) for _, crop in crops]
    before = [redecide(classifier, looks).label for looks in records]
    assert any(label.isdigit() for label in before)
    # a configuration change: no PSR is enough for the second opinion
    strict = Classifier(dataclasses.replace(classifier.config,
                                            second_opinion_psr_threshold=1000.0),
                        classifier.trained_bank)
    assert {redecide(strict, looks).label for looks in records} == {'no_sign'}
    # a rule constant of second_opinion.py: every answer needs an impossible lead
    monkeypatch.setattr(second_opinion, 'COMPOSITE_ONLY_ANSWER_LEAD', 3.0)
    monkeypatch.setattr(second_opinion, 'COMPOSITE_ONLY_OVERRULE_LEAD', 3.0)
    after = [redecide(classifier, looks).label for looks in records]
    assert after == [classifier.classify_crop(crop).label for _, crop in crops]


def _write_folds_record(classifier: Classifier, crops, path: Path) -> list[dict]:
    """A record of one fold holding the looks at ``crops``; returns its rows."""
    rows = []
    for kind, crop in crops:
        looks = record_looks(classifier, crop)
        rows.append({'label': kind, 'class_id': 0, 'width': crop.shape[1], 'looks': looks,
                     'answer': classifier.decide_crop(crop, looks.first).label})
    with open(path, 'wb') as file:
        pickle.dump({'mode': 'folds', 'runs': {'fold 0': {'bank': classifier.trained_bank,
                                                         'rows': rows}}}, file)
    return rows


def test_recorded_frames_are_decided_as_the_frames_are(classifier: Classifier,
                                                       monkeypatch) -> None:
    bench_classifier = bench_module('bench_classifier')
    frames = []
    for seed in range(3):
        gray, candidates = bench_classifier.synthetic_frame(seed)
        # the inner ring's radius, as the detector reports on large signs: "no sign" at
        # first, then read by the larger-size retry
        halved = [Candidate(c.x_px, c.y_px, c.radius_px * 0.55, c.score)
                  for c in candidates if c.radius_px >= 18]
        frames.append((gray, list(candidates) + halved))
    records = [record_frame(classifier, gray, candidates) for gray, candidates in frames]
    answers = [classifier.classify(gray, candidates) for gray, candidates in frames]
    assert [redecide_frame(classifier, looks) for looks in records] == answers
    labels = [answer.label for frame in answers for answer in frame]
    assert sum(label.isdigit() for label in labels) >= 6
    assert any(look is not None for looks in records for look in looks.retry)
    # a rule changed after recording decides as the frames are then read
    monkeypatch.setattr(second_opinion, 'COMPOSITE_ONLY_ANSWER_LEAD', 3.0)
    monkeypatch.setattr(second_opinion, 'UNSEEN_RUNNER_UP_PSR', 50.0)
    strict = [classifier.classify(gray, candidates) for gray, candidates in frames]
    assert strict != answers
    assert [redecide_frame(classifier, looks) for looks in records] == strict


def test_the_bench_replays_a_record_and_applies_settings(classifier: Classifier, crops,
                                                         tmp_path: Path, capsys) -> None:
    redecide_rules = bench_module('redecide_rules')
    path = tmp_path / 'looks.pkl'
    rows = _write_folds_record(classifier, crops, path)
    assert redecide_rules.main(['replay', str(path), '--json']) == 0
    figures = eval_json(capsys.readouterr().out)[str(path)]
    assert figures['answers_changed'] == 0
    right = sum(row['answer'] == row['label'] for row in rows)
    assert 0 < right < len(rows)
    assert figures['accuracy_mean'] == pytest.approx(right / len(rows))
    assert redecide_rules.main(['replay', str(path), '--json', '--set',
                                'classifier.second_opinion_psr_threshold=1000']) == 0
    strict = eval_json(capsys.readouterr().out)[str(path)]
    clutter = sum(row['label'] == 'no_sign' for row in rows)  # right: withheld
    assert strict['accuracy_mean'] == pytest.approx(clutter / len(rows))
    assert strict['answers_changed'] == sum(row['answer'] != 'no_sign' for row in rows)
    with pytest.raises(SystemExit):
        redecide_rules.main(['replay', str(path), '--set', 'NO_SUCH_RULE=1'])


def test_the_bench_replays_a_record_with_its_scores_jittered(classifier: Classifier, crops,
                                                           tmp_path: Path, capsys) -> None:
    """``replay --jitter SIGMA`` moves the recorded second-opinion scores before deciding:
    a billionth changes no answer of the record, noise as wide as the scores' range
    changes many, and the record on disk is left as it was."""
    redecide_rules = bench_module('redecide_rules')
    path = tmp_path / 'looks.pkl'
    rows = _write_folds_record(classifier, crops, path)
    written = path.read_bytes()
    assert redecide_rules.main(['replay', str(path), '--json', '--jitter', '1e-9']) == 0
    assert eval_json(capsys.readouterr().out)[str(path)]['answers_changed'] == 0
    assert redecide_rules.main(['replay', str(path), '--json', '--jitter', '2']) == 0
    noisy = eval_json(capsys.readouterr().out)[str(path)]
    answered = sum(row['answer'] != 'no_sign' for row in rows)
    assert answered > 0 and noisy['answers_changed'] > 0
    assert path.read_bytes() == written
    for bad in ('-1e-4', 'nan', 'inf'):
        with pytest.raises(SystemExit):
            redecide_rules.main(['replay', str(path), '--jitter', bad])
        assert '--jitter' in capsys.readouterr().err


def test_the_bench_counts_what_each_rule_costs_and_saves(classifier: Classifier, crops,
                                                         tmp_path: Path, capsys) -> None:
    redecide_rules = bench_module('redecide_rules')
    path = tmp_path / 'looks.pkl'
    rows = _write_folds_record(classifier, crops, path)
    # a "rule" whose cost is known: with it on, every crop is withheld
    costs = redecide_rules.rule_costs(path, {
        'withhold all': 'classifier.second_opinion_psr_threshold=1000'})
    limits = [row for row in rows if row['label'].isdigit()]
    assert limits and len(limits) < len(rows)
    right = sum(row['answer'] == row['label'] for row in limits)
    wrong = sum(row['answer'].isdigit() and row['answer'] != row['label'] for row in limits)
    clutter = [row for row in rows if not row['label'].isdigit()]
    assert costs['rules']['withhold all'] == {
        'limits and ends': {'right': -right, 'another_limit': -wrong},
        'look-alikes': {'right': sum(row['answer'].isdigit() for row in clutter),
                        'another_limit': -sum(row['answer'].isdigit() for row in clutter)}}
    # every rule of RULES_OFF is measured, and the constants are as they were after it
    before = second_opinion.UNSEEN_RUNNER_UP_PSR
    assert redecide_rules.main(['costs', str(path), '--json']) == 0
    output = capsys.readouterr().out
    measured = eval_json(output)[str(path)]['rules']
    assert set(measured) == set(redecide_rules.RULES_OFF)
    assert second_opinion.UNSEEN_RUNNER_UP_PSR == before
    assert all(set(groups) <= {'limits and ends', 'look-alikes'}
               for groups in measured.values())
    assert 'with each rule off' in output
    assert redecide_rules.main(['costs', str(tmp_path / 'missing.pkl')]) == 1


def eval_json(output: str) -> dict:
    """The JSON object on the last line of a script's output."""
    return json.loads(output.strip().splitlines()[-1])


def test_the_bench_records_the_runs_it_replays(tmp_path: Path, capsys) -> None:
    """``record`` on generated crops (a tiny recipe): the folds by track and one value left
    out, each replayed with the answers the recording banks gave."""
    from test_recognition_training import SMALL, write_crop_folder
    from test_training_value_holdout import TINY
    redecide_rules = bench_module('redecide_rules')
    folder = write_crop_folder(tmp_path / 'crops', tracks_per_class=5, per_track=2)
    folds, values = tmp_path / 'folds.pkl', tmp_path / 'values.pkl'
    redecide_rules.record('folds', folds, [folder], [], None, TINY, SMALL)
    redecide_rules.record('values', values, [folder], [], ['30'], TINY, SMALL)
    with open(folds, 'rb') as file:
        recorded = pickle.load(file)
    assert list(recorded['runs']) == [f'fold {fold}' for fold in range(5)]
    measured = sum(len(run['rows']) for run in recorded['runs'].values())
    crops = len((folder / 'labels.csv').read_text().splitlines()) - 1
    assert measured == crops  # every crop measured once, by the fold that never saw it
    assert redecide_rules.main(['replay', str(folds), str(values), '--json']) == 0
    results = eval_json(capsys.readouterr().out)
    assert results[str(folds)]['answers_changed'] == 0
    assert results[str(values)]['answers_changed'] == 0
    held = results[str(values)]['runs']['value 30']
    assert held['crops'] == 10 and held['right'] + held['wrong_limit'] + held['withheld'] == 10


def test_the_bench_records_the_scene_folds_it_replays(tmp_path: Path, capsys) -> None:
    """``record scenes`` on generated crops and scenes (a tiny recipe, 2 folds): replayed,
    the figures of the scene folds' validation with the same banks."""
    from scene_helpers import write_gtsdb_scenes
    from test_recognition_scene_training import HEIGHT, SCENES, WIDTH
    from test_recognition_training import SMALL, write_crop_folder
    from test_training_value_holdout import TINY

    from speed_sign_detector.config import DetectorConfig
    from speed_sign_detector.training.bank_training import (
        locate_rendered,
        locate_signs,
        read_crops,
        rendered_classifier,
        scene_examples_of,
        train_from_located,
    )
    from speed_sign_detector.training.scene_validation import cross_validate_scenes
    redecide_rules = bench_module('redecide_rules')
    crops = write_crop_folder(tmp_path / 'crops', tracks_per_class=2, per_track=2)
    scenes = write_gtsdb_scenes(tmp_path / 'scenes', SCENES, WIDTH, HEIGHT)
    path = tmp_path / 'scenes.pkl'
    redecide_rules.record_scenes(path, [crops], [scenes], TINY, SMALL, folds=2)
    assert redecide_rules.main(['replay', str(path), '--json']) == 0
    replayed = eval_json(capsys.readouterr().out)[str(path)]
    assert replayed['answers_changed'] == 0
    # the same banks (the recipe is seeded) in the scene folds' validation itself
    rendered = rendered_classifier(SMALL)
    located = locate_signs(rendered, *read_crops([crops])[:2])
    rendered_crops = locate_rendered(rendered, TINY)
    detected, examples = scene_examples_of([scenes], rendered, DetectorConfig(), TINY, 'auto')
    report = cross_validate_scenes(detected, examples, 2, lambda kept: train_from_located(
        located, TINY, rendered=rendered_crops, scenes=kept), SMALL)
    assert report['signs'] == replayed['signs'] == 5 and report['frames'] == 4
    for key in ('recognized', 'false_limits', 'frames'):
        assert replayed[key] == report[key], key
    assert replayed['recognized'] > 0
    costs = redecide_rules.rule_costs(path, {  # frames have their own floor
        'withhold all': 'classifier.frame_second_opinion_psr_threshold=1000'})
    assert costs['rules']['withhold all'] == {'limit signs': {
        'right': -report['recognized'], 'another_limit': -report['false_limits']}}


def test_the_bench_reports_unreadable_records_and_replays_the_rest(
        classifier: Classifier, crops, tmp_path: Path, capsys) -> None:
    """A missing, empty, truncated or foreign file is reported by name; the good record
    beside it is still replayed, and the exit status says something failed."""
    redecide_rules = bench_module('redecide_rules')
    kind, crop = crops[0]
    looks = record_looks(classifier, crop)
    good = tmp_path / 'good.pkl'
    redecide_rules._write_record(good, {'mode': 'folds', 'runs': {'fold 0': {
        'bank': classifier.trained_bank, 'rows': [
            {'label': kind, 'class_id': 0, 'width': crop.shape[1], 'looks': looks,
             'answer': classifier.decide_crop(crop, looks.first).label}]}}})
    assert not (tmp_path / 'good.pkl.partial').exists()
    empty, truncated, foreign = (tmp_path / name for name in ('empty', 'cut', 'foreign'))
    empty.write_bytes(b'')
    truncated.write_bytes(good.read_bytes()[:1000])
    with open(foreign, 'wb') as file:
        pickle.dump([1, 2, 3], file)
    missing = tmp_path / 'missing.pkl'
    paths = [empty, good, truncated, foreign, missing]
    assert redecide_rules.main(['replay', *map(str, paths), '--json']) == 1
    captured = capsys.readouterr()
    for bad in (empty, truncated, foreign, missing):
        assert str(bad) in captured.err
    assert 'not a record of redecide_rules.py record' in captured.err
    assert list(eval_json(captured.out)) == [str(good)]
    assert f'{good} (0 answers differ' in captured.out


def test_the_bench_says_why_it_cannot_record(tmp_path: Path, capsys) -> None:
    redecide_rules = bench_module('redecide_rules')
    empty_folder = tmp_path / 'no_crops'
    empty_folder.mkdir()
    out = tmp_path / 'looks.pkl'
    assert redecide_rules.main(['record', 'folds', str(out), str(empty_folder)]) == 1
    assert 'no_crops' in capsys.readouterr().err
    assert not out.exists()


def test_the_bench_records_and_replays_the_rendered_designs(tmp_path: Path, capsys) -> None:
    """``record designs`` (one sign of each value and design): the shipped bank's answers
    replayed, per design the signs of bench_sign_designs.py in its order."""
    redecide_rules = bench_module('redecide_rules')
    bench_designs = bench_module('bench_sign_designs')
    path = tmp_path / 'designs.pkl'
    redecide_rules.record_designs(path, per_value=1, seed=3)
    with open(path, 'rb') as file:
        recorded = pickle.load(file)
    rows = recorded['runs']['designs']['rows']
    expected = [(design, kind) for design in bench_designs.BENCH_DESIGNS
                for kind, _ in bench_designs.bench_cases(design)
                for _ in range(15 if len(bench_designs.bench_cases(design)) == 1 else 1)]
    assert [(row['design'], row['kind']) for row in rows] == expected
    assert redecide_rules.main(['replay', str(path), '--json']) == 0
    results = eval_json(capsys.readouterr().out)[str(path)]
    assert results['answers_changed'] == 0
    figures = results['runs']
    assert set(figures) == set(bench_designs.BENCH_DESIGNS)
    assert sum(design['signs'] for design in figures.values()) == len(rows)
    for design in figures.values():
        assert design['right'] + design['wrong'] <= design['signs']
        assert len(design['wrong_answers']) == design['wrong']
    # the folders belong to the folds and values modes only
    with pytest.raises(SystemExit):
        redecide_rules.main(['record', 'designs', str(path), str(tmp_path)])


def test_a_certain_second_opinion_only_answers_signs_otherwise_withheld(
        classifier: Classifier) -> None:
    """``second_opinion_certain_lead`` (:meth:`.SecondOpinion.certain_choice`): set above 2
    it never answers; set lower, every answer it changes was "no sign" and becomes a limit
    the bank has real crops of, the same on the crops as on their recorded looks."""
    rng = np.random.default_rng(5)
    small = [design_crop(kind, design, int(rng.integers(12, 30)), rng)
             for kind in ('30', '60', '80', '100', '120', '50')
             for design in ('painted', 'yellow') for _ in range(6)]
    records = [record_looks(classifier, crop) for crop in small]

    def answers(lead: float) -> list[str]:
        config = dataclasses.replace(classifier.config, second_opinion_certain_lead=lead)
        changed = Classifier(config, classifier.trained_bank)
        read = [changed.classify_crop(crop).label for crop in small]
        assert [redecide(changed, looks).label for looks in records] == read
        return read

    never, eager = answers(2.5), answers(0.0)
    shipped = answers(ClassifierConfig().second_opinion_certain_lead)
    with_crops = classifier.trained_bank.second_opinion.labels_with_crops
    changed = [(before, after) for before, after in zip(never, eager) if before != after]
    assert changed, 'a lead of 0 answers some crop of this set withheld otherwise'
    assert any(before != after for before, after in zip(never, shipped))
    for before, after in changed + list(zip(never, shipped)):
        assert before == after or (before == 'no_sign' and after in with_crops
                                   and after.isdigit())
