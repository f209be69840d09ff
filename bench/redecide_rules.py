#!/usr/bin/env python3
"""Try decision-rule changes in seconds: record the looks of the validation runs once, then
decide them again with the rules as the code has them now.

``record`` trains the banks of the 5 folds by track (with ``--scenes``, as
``make validate-folds`` does) or of leave one value out (as ``make
validate-value-holdout``, without scenes), and records every look at every crop each bank measures
(:mod:`speed_sign_detector.training.recorded_looks`) into one pickle file (about 50 MB for
the folds, 85 MB for leave one value out; 12-20 min each on 2 cores); ``record designs``
renders the signs of ``make validate-designs`` (``bench/bench_sign_designs.py``, 30 of
each value and design, seed 1) and records the shipped bank's looks at them (3 min);
``record scenes`` trains the banks of the 5 folds by scene (every crop and the other
folds' scenes, as the scene folds of ``make validate-folds``) and records each bank's
looks at the detector's candidates of its own fold's frames. ``replay`` decides
the recorded looks again and prints the figures of the run: the folds' accuracy, crops
read as another limit per class and look-alikes read as a limit; per held-out value its
crops read right and as another limit; per rendered design its signs read right and
wrong (a limit not theirs); the scenes' limit signs recognized and false limits per
frame. ``--set NAME=VALUE`` changes a constant of
``recognition/second_opinion.py`` (``UNSEEN_RUNNER_UP_PSR=1.0``) or a classifier
parameter (``classifier.min_margin=2``) for that replay. With the rules unchanged the
replay gives the recorded answers (it checks this and says so); ``--jitter SIGMA`` first
moves every recorded second-opinion score by normal noise of that size, and the answers
that then differ are those on a rule's edge (another host's rounding may decide them).
``costs`` decides each record again once per withholding rule with that rule turned off
(:data:`RULES_OFF`) and counts what the rule costs and what it saves: crops it withholds
that would be read right without it, and crops it keeps from being read as another limit
(per record: the folds' limit crops and look-alikes; the held-out values' crops and the
other values' crops of their folds; the rendered designs; the scenes' limit signs
recognized and false limits).

The pickle holds the banks and numpy arrays: read only files you made. ``record`` writes
it after each run (a run that fails keeps the runs before it); ``replay`` reports a file
that is missing, empty, truncated or not a record, decides the others, and exits 1.

Usage::

    python bench/redecide_rules.py record folds out/looks_folds.pkl \\
        ../shared/data/gtsrb-dev ../shared/data/gtsrb-lookalikes-dev \\
        --scenes ../shared/data/gtsdb-dev
    python bench/redecide_rules.py record values out/looks_values.pkl \\
        ../shared/data/gtsrb-dev ../shared/data/gtsrb-lookalikes-dev
    python bench/redecide_rules.py record designs out/looks_designs.pkl
    python bench/redecide_rules.py record scenes out/looks_scenes.pkl \\
        ../shared/data/gtsrb-dev ../shared/data/gtsrb-lookalikes-dev \\
        --scenes ../shared/data/gtsdb-dev
    python bench/redecide_rules.py replay out/looks_folds.pkl out/looks_values.pkl \\
        [--set UNSEEN_RUNNER_UP_PSR=1.0] [--jitter 1e-4] [--json]
    python bench/redecide_rules.py costs out/looks_folds.pkl out/looks_values.pkl [--json]
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import pickle
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()  # reproducible training, as make bank

import numpy as np  # noqa: E402
from bench_sign_designs import BENCH_DESIGNS, design_signs  # noqa: E402 (bench/, beside)

from speed_sign_detector.config import ClassifierConfig, DetectorConfig  # noqa: E402
from speed_sign_detector.errors import TrainingDataError  # noqa: E402
from speed_sign_detector.labelled_crops import track_folds  # noqa: E402
from speed_sign_detector.recognition import second_opinion  # noqa: E402
from speed_sign_detector.recognition.classifier import Classifier  # noqa: E402
from speed_sign_detector.training.bank_training import (  # noqa: E402
    TrainingConfig,
    locate_rendered,
    locate_signs,
    read_crops,
    rendered_classifier,
    scene_examples_of,
    train_from_located,
)
from speed_sign_detector.scene_truth import count_false_limits, is_recognized  # noqa: E402
from speed_sign_detector.training.recorded_looks import (  # noqa: E402
    record_frame,
    record_looks,
    redecide,
    redecide_frame,
)
from speed_sign_detector.training.scene_examples import read_scene_gray, scene_folds  # noqa: E402
from speed_sign_detector.training.track_validation import summarise  # noqa: E402
from speed_sign_detector.training.value_holdout import value_answers  # noqa: E402

FOLDS = 5
#: What ``record`` records.
MODES = ('folds', 'values', 'designs', 'scenes')
#: ``costs``: each rule that withholds an answer, and the ``--set`` that turns it off
#: (the constants of ``recognition/second_opinion.py`` and the classifier's parameters).
RULES_OFF: dict[str, str] = {
    'runner-up without real pixels (UNSEEN_RUNNER_UP_PSR)': 'UNSEEN_RUNNER_UP_PSR=-inf',
    'composite-only answer lead (COMPOSITE_ONLY_ANSWER_LEAD)': 'COMPOSITE_ONLY_ANSWER_LEAD=0',
    'composite-only overrule lead (COMPOSITE_ONLY_OVERRULE_LEAD)':
        'COMPOSITE_ONLY_OVERRULE_LEAD=0',
    'lit-on-dark overrule lead (LIT_ON_DARK_OVERRULE_LEAD)': 'LIT_ON_DARK_OVERRULE_LEAD=0',
    'three-digit composite runner-up (COMPOSITE_ONLY_RUNNER_UP_PSR)':
        'COMPOSITE_ONLY_RUNNER_UP_PSR=-inf',
    'candidate PSR gap (CANDIDATE_PSR_GAP)': 'CANDIDATE_PSR_GAP=inf',
    'overrule lead (classifier.second_opinion_overrule_lead)':
        'classifier.second_opinion_overrule_lead=0',
    'filters\' margin (classifier.min_margin)': 'classifier.min_margin=0',
    'lit-face lead (classifier.lit_face_min_margin)': 'classifier.lit_face_min_margin=0',
}


def record(mode: str, out: Path, folders: list[Path], scenes: list[Path],
           values: list[str] | None, config: TrainingConfig = TrainingConfig(),
           classifier_config: ClassifierConfig = ClassifierConfig()) -> None:
    """Train the runs' banks (``mode`` ``'folds'`` or ``'values'``) by the recipe
    ``config`` and write their recorded looks to ``out``."""
    crops, images, unreadable = read_crops(folders)
    for path in unreadable:
        print(f'unreadable: {path}', file=sys.stderr)
    fold_of = track_folds(crops, FOLDS, config.seed)
    rendered = rendered_classifier(classifier_config)
    located = locate_signs(rendered, crops, images)
    rendered_crops = locate_rendered(rendered, config)
    _, scene_examples = scene_examples_of(scenes, rendered, DetectorConfig(), config, 'auto')
    labels = np.asarray([crop.label for crop in crops])
    runs: list[tuple[str, np.ndarray, np.ndarray]] = []
    if mode == 'folds':
        runs = [(f'fold {fold}', fold_of != fold, np.flatnonzero(fold_of == fold))
                for fold in range(FOLDS)]
    else:
        limits = sorted({label for label in labels if label.isdigit()}, key=int)
        for value in values or limits:
            if value not in limits:
                raise SystemExit(f'no real crops of {value} km/h in {folders}')
            fold = limits.index(value) % FOLDS  # as value_holdout.hold_out_values
            runs.append((f'value {value}', (fold_of != fold) & (labels != value),
                         np.concatenate([np.flatnonzero(labels == value),
                                         np.flatnonzero((fold_of == fold) & (labels != value))])))
    recorded: dict[str, Any] = {'mode': mode, 'runs': {}}
    for name, train, measured in runs:
        bank = train_from_located(located.subset(train), config, rendered=rendered_crops,
                                  scenes=scene_examples if mode == 'folds' else None)
        trained = Classifier(classifier_config, bank)
        rows = []
        for index in measured:
            looks = record_looks(trained, images[index])
            rows.append({'label': crops[index].label, 'class_id': crops[index].class_id,
                         'width': crops[index].roi[2] - crops[index].roi[0] + 1,
                         'looks': looks,
                         'answer': trained.decide_crop(images[index], looks.first).label})
        recorded['runs'][name] = {'bank': bank, 'rows': rows}
        _write_record(out, recorded)  # after each run: what was recorded is kept
        print(f'{name}: {len(rows)} crops recorded in {out}', file=sys.stderr)


def record_scenes(out: Path, folders: list[Path], scenes: list[Path],
                  config: TrainingConfig = TrainingConfig(),
                  classifier_config: ClassifierConfig = ClassifierConfig(),
                  folds: int = FOLDS) -> None:
    """Train the banks of the ``folds`` folds by scene (every crop and the other folds'
    scenes, as the scene folds of ``make validate-folds``) and record each bank's looks at
    the detector's candidates of its own fold's frames (:func:`.record_frame`) into
    ``out``."""
    crops, images, unreadable = read_crops(folders)
    for path in unreadable:
        print(f'unreadable: {path}', file=sys.stderr)
    rendered = rendered_classifier(classifier_config)
    located = locate_signs(rendered, crops, images)
    rendered_crops = locate_rendered(rendered, config)
    detected, scene_examples = scene_examples_of(scenes, rendered, DetectorConfig(), config,
                                                 'auto')
    if scene_examples is None:
        raise TrainingDataError('scenes mode trains the second opinion on the scenes')
    try:
        fold_of = scene_folds([scene.key for scene in detected], folds)
    except ValueError as err:
        raise TrainingDataError(f'cannot record the scene folds: {err}') from err
    recorded: dict[str, Any] = {'mode': 'scenes', 'runs': {}}
    for fold in range(folds):
        kept = scene_examples.subset({key for key, scene_fold in fold_of.items()
                                      if scene_fold != fold})
        bank = train_from_located(located, config, rendered=rendered_crops, scenes=kept)
        trained = Classifier(classifier_config, bank)
        rows = []
        for scene in detected:
            gray = read_scene_gray(scene.path) if fold_of[scene.key] == fold else None
            if gray is None:
                continue
            rows.append({'key': scene.key, 'signs': scene.signs,
                         'candidates': scene.candidates,
                         'looks': record_frame(trained, gray, scene.candidates),
                         'answer': tuple(answer.label for answer in
                                         trained.classify(gray, scene.candidates))})
        recorded['runs'][f'scene fold {fold}'] = {'bank': bank, 'rows': rows}
        _write_record(out, recorded)
        print(f'scene fold {fold}: {len(rows)} frames recorded in {out}', file=sys.stderr)


def _frame_counts(row: dict[str, Any], answers: Any) -> tuple[int, int, int]:
    """(limit signs, recognized, false limits) of one recorded frame given its answers
    (:class:`Classification` objects)."""
    limits = [sign for sign in row['signs'] if sign.limit_kmh]
    return (len(limits), sum(is_recognized(sign, row['candidates'], answers) for sign in limits),
            count_false_limits(row['signs'], row['candidates'], answers))


def record_designs(out: Path, per_value: int = 30, seed: int = 1,
                   classifier_config: ClassifierConfig = ClassifierConfig()) -> None:
    """Record the shipped bank's looks at the rendered signs of ``make validate-designs``
    (``per_value`` of each value and design, ``seed``) into ``out``."""
    classifier = Classifier(classifier_config)
    rows = []
    for design, kind, truth, diameter, crop in design_signs(
            BENCH_DESIGNS, per_value, 15, 60, np.random.default_rng(seed)):
        looks = record_looks(classifier, crop)
        rows.append({'label': truth, 'design': design, 'kind': kind, 'width': diameter,
                     'looks': looks,
                     'answer': classifier.decide_crop(crop, looks.first).label})
    _write_record(out, {'mode': 'designs',
                        'runs': {'designs': {'bank': classifier.trained_bank, 'rows': rows}}})
    print(f'designs: {len(rows)} signs recorded in {out}', file=sys.stderr)


def _write_record(out: Path, recorded: dict[str, Any]) -> None:
    """Write ``recorded`` to ``out`` whole or not at all (through a file beside it)."""
    partial = out.with_name(out.name + '.partial')
    with open(partial, 'wb') as file:
        pickle.dump(recorded, file)
    partial.replace(out)


class RecordError(Exception):
    """A file that is not a record written by ``record``."""


def _read_record(path: Path) -> dict[str, Any]:
    """The record in ``path``; :class:`RecordError` for a missing, empty, truncated or
    foreign file."""
    try:
        with open(path, 'rb') as file:
            recorded = pickle.load(file)
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError,
            ValueError) as err:
        raise RecordError(f'{path}: not readable as a record ({type(err).__name__}: '
                          f'{err})') from err
    if not (isinstance(recorded, dict) and recorded.get('mode') in MODES
            and isinstance(recorded.get('runs'), dict)):
        raise RecordError(f'{path}: not a record of redecide_rules.py record')
    return recorded


def replay(path: Path, classifier_config: ClassifierConfig, jitter: float = 0.0
           ) -> dict[str, Any]:
    """The figures of one recorded run decided again (:class:`RecordError` for a file
    that is not a record); ``jitter`` > 0: with every recorded second-opinion score moved
    by normal noise of that standard deviation first (:func:`jittered`)."""
    recorded = _read_record(path)
    if jitter > 0:
        jittered(recorded, jitter)
    changed = 0
    figures: dict[str, Any] = {'mode': recorded['mode'], 'runs': {}}
    everything: list[tuple[str, str, int, int]] = []
    decided = decide_again(recorded, classifier_config)
    totals = np.zeros(4, int)  # scenes: frames, limit signs, recognized, false limits
    for name, run in recorded['runs'].items():
        answers = decided[name]
        if recorded['mode'] == 'scenes':
            changed += sum(answer != label for frame, row in zip(answers, run['rows'])
                           for answer, label in zip((a.label for a in frame), row['answer']))
            counts = np.asarray([[1, *_frame_counts(row, frame)]
                                 for row, frame in zip(run['rows'], answers)]).sum(axis=0)
            totals += counts
            figures['runs'][name] = {'recall': counts[2] / max(counts[1], 1),
                                     'false_limits_per_frame': counts[3] / max(counts[0], 1)}
            continue
        changed += sum(answer != row['answer'] for answer, row in zip(answers, run['rows']))
        if recorded['mode'] == 'designs':
            figures['runs'] = design_figures(run['rows'], answers)
            continue
        rows = [(row['label'], answer, row['class_id'], row['width'])
                for row, answer in zip(run['rows'], answers)]
        if recorded['mode'] == 'folds':
            everything += rows
            figures['runs'][name] = summarise(*map(list, zip(*rows)))['accuracy']
        else:
            value = name.split()[-1]
            figures['runs'][name] = value_answers(value, [a for t, a, _, _ in rows
                                                          if t == value])
    if recorded['mode'] == 'folds':
        summary = summarise(*map(list, zip(*everything)))
        figures['accuracy_mean'] = float(np.mean(list(figures['runs'].values())))
        figures['wrong_limit_rate'] = {label: row['wrong_limit_rate'] for label, row
                                       in summary['per_class'].items() if label.isdigit()}
        figures['lookalikes_read_as_limit'] = round(
            (summary['lookalikes_read_as_limit_rate'] or 0.0) * summary['lookalikes'])
    if recorded['mode'] == 'scenes':
        frames, signs, recognized, false_limits = (int(value) for value in totals)
        figures.update({'frames': frames, 'signs': signs, 'recognized': recognized,
                        'false_limits': false_limits,
                        'recognition_recall': recognized / max(signs, 1),
                        'false_limits_per_frame': false_limits / max(frames, 1)})
    figures['answers_changed'] = changed
    return figures


def jittered(recorded: dict[str, Any], sigma: float, seed: int = 0) -> None:
    """Move every second-opinion score of ``recorded`` (each reading's ``opinion_scores``,
    -1 to +1) by normal noise of standard deviation ``sigma`` (fixed ``seed``), in place:
    the answers that change are those on a rule's edge, which another host's rounding of
    the same training may decide otherwise (a held-out 60 scored -0.99901 against a
    dismissal at -0.999)."""
    rng = np.random.default_rng(seed)

    def moved(reading: Any) -> Any:
        if reading is None:
            return None
        scores = np.asarray(reading.opinion_scores)
        noisy = np.clip(scores + rng.normal(0.0, sigma, scores.shape), -1.0, 1.0)
        return dataclasses.replace(reading, opinion_scores=noisy.astype(scores.dtype))

    for run in recorded['runs'].values():
        for row in run['rows']:
            looks = row['looks']
            if recorded['mode'] == 'scenes':
                row['looks'] = dataclasses.replace(
                    looks, first_readings=tuple(map(moved, looks.first_readings)),
                    retry_readings=tuple(map(moved, looks.retry_readings)))
            else:
                row['looks'] = dataclasses.replace(
                    looks, readings=tuple(map(moved, looks.readings)))


def decide_again(recorded: dict[str, Any], classifier_config: ClassifierConfig
                 ) -> dict[str, list[Any]]:
    """Each run's answers (labels, in the order of its rows; for scenes, each frame's
    :class:`Classification` tuple) decided again by the rules as they are now and
    ``classifier_config``."""
    decided: dict[str, list[Any]] = {}
    for name, run in recorded['runs'].items():
        classifier = Classifier(classifier_config, run['bank'])
        if recorded['mode'] == 'scenes':  # each frame's answers, Classification objects
            decided[name] = [redecide_frame(classifier, row['looks']) for row in run['rows']]
        else:
            decided[name] = [redecide(classifier, row['looks']).label for row in run['rows']]
    return decided


def _is_right(truth: str, answer: str) -> bool:
    """A limit read as its value; an end of limit, a look-alike or clutter read as no limit."""
    return answer == truth if truth.isdigit() else not answer.isdigit()


def _is_another_limit(truth: str, answer: str) -> bool:
    return answer.isdigit() and answer != truth


def rule_costs(path: Path, rules: dict[str, str] | None = None) -> dict[str, Any]:
    """What each rule of ``rules`` (name -> the ``--set`` that turns it off; default
    :data:`RULES_OFF`) costs and saves on the record in ``path``: the record decided
    with the rules as they are, then with each rule off in turn.

    Returns:
        ``{'mode', 'rules': {name: {group: {'right': n, 'another_limit': n}}}}``: per
        group of rows, how many more would be read right and how many more read as
        another limit with the rule off (negative: fewer). Groups: ``'limits and ends'``
        and ``'look-alikes'`` (folds); ``'held-out value'`` and ``'other values'``
        (values); each design (designs); ``'limit signs'`` (scenes: ``right`` counts
        the signs recognized, ``another_limit`` the false limits).
    """
    recorded = _read_record(path)
    base = decide_again(recorded, ClassifierConfig())
    mode = recorded['mode']
    costs: dict[str, Any] = {}
    for rule, setting in (RULES_OFF if rules is None else rules).items():
        with settings_applied([setting]) as classifier_config:
            answers = decide_again(recorded, classifier_config)
        groups: dict[str, Counter[str]] = {}
        for name, run in recorded['runs'].items():
            if mode == 'scenes':  # limit signs recognized, false limits
                counts = groups.setdefault('limit signs', Counter())
                for row, before, after in zip(run['rows'], base[name], answers[name]):
                    _, right_before, false_before = _frame_counts(row, before)
                    _, right_after, false_after = _frame_counts(row, after)
                    counts['right'] += right_after - right_before
                    counts['another_limit'] += false_after - false_before
                continue
            for row, before, after in zip(run['rows'], base[name], answers[name]):
                group = _cost_group(mode, name, row)
                counts = groups.setdefault(group, Counter())
                counts['right'] += _is_right(row['label'], after) - _is_right(row['label'],
                                                                              before)
                counts['another_limit'] += (_is_another_limit(row['label'], after)
                                            - _is_another_limit(row['label'], before))
        costs[rule] = {group: {'right': counts['right'],
                               'another_limit': counts['another_limit']}
                       for group, counts in sorted(groups.items())}
    return {'mode': mode, 'rules': costs}


def _cost_group(mode: str, run: str, row: dict[str, Any]) -> str:
    if mode == 'designs':
        return row['design']
    if mode == 'values':
        return 'held-out value' if row['label'] == run.split()[-1] else 'other values'
    return 'limits and ends' if row['label'].isdigit() or row['label'] == 'end_of_limit' \
        else 'look-alikes'


def print_costs(path: Path, costs: dict[str, Any]) -> None:
    print(f'{path}: with each rule off, crops read right / read as another limit, more (+) '
          'or fewer (-)')
    for rule, groups in costs['rules'].items():
        changed = [f'{group} {counts["right"]:+d} / {counts["another_limit"]:+d}'
                   for group, counts in groups.items() if any(counts.values())]
        print(f'  {rule}: ' + ('; '.join(changed) if changed else 'no change'))


def design_figures(rows: list[dict[str, Any]], answers: list[str]
                   ) -> dict[str, dict[str, Any]]:
    """Per design: signs, read right, wrong (a limit not the truth) and the wrong answers
    (as ``bench_sign_designs.py`` reports them)."""
    figures: dict[str, dict[str, Any]] = {}
    for row, answer in zip(rows, answers):
        design = figures.setdefault(row['design'], {'signs': 0, 'right': 0, 'wrong': 0,
                                                     'wrong_answers': []})
        design['signs'] += 1
        if answer == row['label']:
            design['right'] += 1
        elif answer.isdigit():
            design['wrong'] += 1
            design['wrong_answers'].append(f'{row["kind"]} as {answer} ({row["width"]} px)')
    return figures


def print_figures(path: Path, figures: dict[str, Any]) -> None:
    print(f'{path} ({figures["answers_changed"]} answers differ from the recorded ones)')
    if figures['mode'] == 'designs':
        wrong = sum(design['wrong'] for design in figures['runs'].values())
        print(f'  {wrong} wrong in all')
        for name, design in figures['runs'].items():
            print(f'  {name}: right {design["right"] / design["signs"]:.3f}, wrong '
                  f'{design["wrong"]}' + (f' ({", ".join(design["wrong_answers"])})'
                                          if design['wrong_answers'] else ''))
        return
    if figures['mode'] == 'scenes':
        print(f'  limit signs recognized {figures["recognized"]} of {figures["signs"]} '
              f'({figures["recognition_recall"]:.3f}), false limits {figures["false_limits"]} '
              f'in {figures["frames"]} frames ({figures["false_limits_per_frame"]:.4f} per '
              'frame)')
        return
    if figures['mode'] == 'folds':
        worst = max(figures['wrong_limit_rate'].items(), key=lambda item: item[1])
        print(f'  accuracy {figures["accuracy_mean"]:.4f} (folds: '
              + ', '.join(f'{a:.3f}' for a in figures['runs'].values())
              + f'); worst class read as another limit {worst[0]} {100 * worst[1]:.2f} %; '
              f'look-alikes read as a limit {figures["lookalikes_read_as_limit"]}')
        return
    for name, held in figures['runs'].items():
        print(f'  {name}: right {held["accuracy"]:.3f}, another limit '
              f'{100 * held["wrong_limit_rate"]:.2f} %')


@contextlib.contextmanager
def settings_applied(settings: list[str]) -> Iterator[ClassifierConfig]:
    """:func:`apply_settings` for the ``with`` block, the constants of
    ``second_opinion.py`` restored after it."""
    saved = {name: value for name, value in vars(second_opinion).items()
             if name.isupper() and isinstance(value, (int, float))}
    try:
        yield apply_settings(settings)
    finally:
        for name, value in saved.items():
            setattr(second_opinion, name, value)


def apply_settings(settings: list[str]) -> ClassifierConfig:
    """Apply ``--set`` values; returns the classifier config to decide with."""
    classifier_config = ClassifierConfig()
    for setting in settings:
        name, _, text = setting.partition('=')
        if name.startswith('classifier.'):
            field = name.removeprefix('classifier.')
            kind = type(getattr(classifier_config, field, None))
            if kind not in (int, float, bool):
                raise SystemExit(f'--set {setting}: not a numeric classifier parameter')
            classifier_config = dataclasses.replace(classifier_config, **{field: kind(text)})
        elif isinstance(getattr(second_opinion, name, None), (int, float)):
            setattr(second_opinion, name, float(text))
        else:
            raise SystemExit(f'--set {setting}: no such constant in second_opinion.py')
    return classifier_config


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    recording = commands.add_parser('record', help='train the banks and record the looks')
    recording.add_argument('mode', choices=MODES)
    recording.add_argument('out', type=Path)
    recording.add_argument('folders', type=Path, nargs='*',
                           help='the crop folders (folds and values modes)')
    recording.add_argument('--scenes', type=Path, action='append', default=[])
    recording.add_argument('--values', nargs='+', help='values to hold out (values mode)')
    recording.add_argument('--seed', type=int, default=1,
                           help='designs mode: the seed of the rendered signs (default 1, as '
                                'make validate-designs)')
    replaying = commands.add_parser('replay', help='decide recorded looks again')
    replaying.add_argument('records', type=Path, nargs='+')
    replaying.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    replaying.add_argument('--json', action='store_true')
    replaying.add_argument('--jitter', type=float, default=0.0, metavar='SIGMA',
                           help='move every recorded second-opinion score by normal noise '
                                'of this standard deviation before deciding (fixed seed): '
                                'the answers that then differ sit on a rule\'s edge')
    costing = commands.add_parser('costs', help='what each withholding rule costs and saves')
    costing.add_argument('records', type=Path, nargs='+')
    costing.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    if args.command == 'replay' and not (math.isfinite(args.jitter) and args.jitter >= 0):
        parser.error(f'--jitter {args.jitter}: a standard deviation, 0 or more')
    if args.command == 'record':
        if args.mode == 'values' and args.scenes:
            parser.error('values mode trains without scenes, as make validate-value-holdout')
        if args.mode == 'designs':
            if args.folders or args.scenes or args.values:
                parser.error('designs mode renders its signs: no folders, scenes or values')
            record_designs(args.out, seed=args.seed)
            return 0
        if not args.folders:
            parser.error(f'{args.mode} mode needs the crop folders')
        if args.mode == 'scenes' and not args.scenes:
            parser.error('scenes mode needs --scenes')
        try:
            if args.mode == 'scenes':
                record_scenes(args.out, args.folders, args.scenes)
            else:
                record(args.mode, args.out, args.folders, args.scenes, args.values)
        except TrainingDataError as err:
            print(f'redecide_rules.py record: {err}', file=sys.stderr)
            return 1
        return 0
    classifier_config = apply_settings(args.set) if args.command == 'replay' else None
    results: dict[str, Any] = {}
    failed = 0
    for path in args.records:
        try:
            if classifier_config is None:
                results[str(path)] = rule_costs(path)
            else:
                results[str(path)] = replay(path, classifier_config, args.jitter)
        except RecordError as err:
            print(f'redecide_rules.py {args.command}: {err}', file=sys.stderr)
            failed += 1
            continue
        if classifier_config is None:
            print_costs(path, results[str(path)])
        else:
            print_figures(path, results[str(path)])
    if args.json:
        print(json.dumps(results))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
