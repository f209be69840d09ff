"""``speed_sign_train``: build a filter bank from labelled crops, or validate the recipe.

- ``build OUT.npz DIR [DIR ...]``: train on every crop of the folders (GTSRB
  ``labels.csv`` format; classes 0-8 are limits and end of 80, the look-alike classes
  9, 10, 15-17, 32-42 are negatives) and write one bank file with its provenance. Load it
  with the parameter ``classifier.bank_file``.
- ``validate DIR [DIR ...]``: k-fold validation split by track (a physical sign is never
  on both sides): per-class accuracy, wrong-limit and withheld rates, look-alikes read
  as a limit, for the rendered-only classifier, the trained filters, and the trained
  filters with the second opinion, side by side. With ``--leave-one-value-out``: for each
  limit value with real crops, a bank trained without any of them reads them (how a
  value with no real crops, such as 130 km/h, is read; :mod:`..training.value_holdout`).

Both take ``--scenes SCENE_DIR`` (repeatable): annotated scene folders (GTSDB format:
``images/`` and ``gt.txt``) whose detector candidates teach the second opinion real
signs in whole frames and real background (``no_sign``). ``validate`` then also reports
k folds by scene: each fold's bank never saw that fold's scenes. ``--approach`` also
reads approach sequences made from each fold's scenes through the whole pipeline, with
that fold's bank (:mod:`.approach_validation`), ``--boxes`` reads the annotated boxes of
each fold's scenes as crops with that fold's bank (:mod:`..training.scene_box_validation`),
and ``--scenes-only`` runs the folds by scene without the folds by track.

With ``--json`` the last line on stdout is ONE JSON object; progress goes to stderr.
Exit status: 0 on success, 1 when training failed (the reason on stderr), 2 for bad
usage, 130 when interrupted.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
from pathlib import Path
from typing import Any

from speed_sign_detector import __version__
from speed_sign_detector.config import ClassifierConfig, DetectorConfig, PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.recognition.trained_bank import save_trained_bank
from speed_sign_detector.tools.approach_validation import ApproachFolds, format_approach_line
from speed_sign_detector.tools.cli_types import (
    integer_in_range,
    non_negative_integer,
    non_negative_number,
    positive_integer,
)
from speed_sign_detector.tools.progress import progress_bar
from speed_sign_detector.tools.run_control import run_subcommand
from speed_sign_detector.training.bank_training import (
    MIN_LEAD_OF_MODEL,
    SECOND_OPINION_MODELS,
    TrainingConfig,
    train_bank,
)
from speed_sign_detector.training.scene_box_validation import (
    BOXES_KEY,
    SceneBoxFolds,
    format_boxes_line,
)
from speed_sign_detector.training.scene_validation import SceneFoldMeasure, validate_by_scene
from speed_sign_detector.training.track_validation import VARIANTS, cross_validate
from speed_sign_detector.training.training_host import describe_host
from speed_sign_detector.training.value_holdout import leave_one_value_out

_DEFAULTS = TrainingConfig()
#: Column titles of :func:`cross_validate`'s variants.
_VARIANT_TITLES = {'rendered': 'renderings only',
                   'trained_filters': 'trained, no second opinion',
                   'second_opinion_rendered_ranking': 'opinion, rendered ranking',
                   'trained_filters_second_opinion': 'trained bank (+ real filters)'}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``speed_sign_train``."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_train', description='Train the classifier\'s filter bank on labelled '
        'real crops (GTSRB labels.csv format), or validate training by k-fold split by track.',
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='command', required=True)
    common = argparse.ArgumentParser(add_help=False,
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    common.add_argument('--config', type=Path, help='YAML parameter file (the node\'s format); '
                        'its classifier settings shape the filters')
    common.add_argument('--model', choices=SECOND_OPINION_MODELS, default=_DEFAULTS.model,
                        help='the second opinion: an ensemble of small networks, or a ridge '
                        'model (linear)')
    common.add_argument('--ridge', type=non_negative_number, default=_DEFAULTS.ridge,
                        help='regularisation of the linear second opinion')
    common.add_argument('--hidden-units', type=positive_integer, default=_DEFAULTS.hidden_units,
                        help='hidden units of each network of the second opinion')
    common.add_argument('--epochs', type=positive_integer, default=_DEFAULTS.epochs,
                        help='training passes of each network')
    common.add_argument('--members', type=positive_integer, default=_DEFAULTS.members,
                        help='networks in the second opinion\'s ensemble')
    common.add_argument('--candidates', type=positive_integer, default=_DEFAULTS.candidates,
                        help='the second opinion chooses among this many leading labels of '
                        'the correlation filters')
    common.add_argument('--min-lead', type=non_negative_number, default=None,
                        help='least lead of the second opinion\'s answer over its next best '
                        'label; less withholds the answer (default: '
                        + ', '.join(f'{lead} for {model}'
                                    for model, lead in MIN_LEAD_OF_MODEL.items())
                        + ')%(default).0s')  # (the formatter adds no "default: None")
    common.add_argument('--augmented-copies', type=non_negative_integer,
                        default=_DEFAULTS.augmented_copies,
                        help='degraded copies (blur, JPEG, contrast, scale) of each crop')
    common.add_argument('--examples-per-class', type=non_negative_integer,
                        default=_DEFAULTS.examples_per_class,
                        help='mean real images per class in the composite filters (0: none)')
    common.add_argument('--rendered-per-kind', type=non_negative_integer,
                        default=_DEFAULTS.rendered_per_kind,
                        help='rendered, degraded crops of every sign kind the package draws '
                        'added to the second opinion\'s training (values without real '
                        'examples: 5, 10, 40, 90, 110, 130 km/h)')
    common.add_argument('--arched-six-per-kind', type=non_negative_integer,
                        default=_DEFAULTS.arched_six_per_kind,
                        help='more rendered crops of each limit with a 6 (60 km/h), drawn '
                        'with the older lettering\'s arched 6, which real crops rarely '
                        'show and the rest of the classifier reads as 8')
    common.add_argument('--composites-per-value', type=non_negative_integer,
                        default=_DEFAULTS.composites_per_value,
                        help='composite crops of every limit value (5 to 140 km/h) made from '
                        'the real crops\' digits, so that values without real crops are '
                        'learned from real pixels too (0: renderings only)')
    common.add_argument('--design-per-kind', type=non_negative_integer,
                        default=_DEFAULTS.design_per_kind,
                        help='rendered crops of every limit on LED and yellow-faced signs, '
                        'and of the end of all restrictions, for the second opinion')
    common.add_argument('--scenes', type=Path, action='append', default=[],
                        metavar='SCENE_DIR', help='annotated scene folder (GTSDB format: '
                        'images/ and gt.txt) to learn real signs and background from; '
                        'repeatable')
    common.add_argument('--scene-copies', type=non_negative_integer,
                        default=_DEFAULTS.scene_copies,
                        help='degraded copies of each example cut from the scenes')
    common.add_argument('--real-filter-weight', type=non_negative_number,
                        default=_DEFAULTS.real_filter_weight,
                        help='weight of the composite filters trained from the real crops in '
                             'ranking the labels the second opinion chooses among, against '
                             'the rendered filters\' 1 (0: no real filters)')
    common.add_argument('--real-filter-noise', type=non_negative_number,
                        default=_DEFAULTS.real_filter_noise,
                        help='the real filters\' white-noise weight (OT-MACH trade-off), '
                             'relative to the examples\' mean power')
    common.add_argument('--backend', choices=('auto', 'gl', 'cpu', 'numpy'), default='auto',
                        help='detector backend that finds the candidates in the scenes')
    common.add_argument('--no-second-opinion', action='store_true',
                        help='train the composite filters only')
    common.add_argument('--seed', type=int, default=_DEFAULTS.seed)
    common.add_argument('--json', action='store_true',
                        help='print one JSON object as the last line of stdout')
    common.add_argument('-q', '--quiet', action='store_true', help='no progress bar')

    build = subparsers.add_parser('build', parents=[common], help='train a bank file',
                                  formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    build.add_argument('out', type=Path, help='the bank file to write (.npz)')
    build.add_argument('folders', type=Path, nargs='+', help='labelled crop folders')
    build.set_defaults(run=_run_build)

    validate = subparsers.add_parser('validate', parents=[common],
                                     help='k-fold validation split by track',
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    validate.add_argument('folders', type=Path, nargs='+', help='labelled crop folders')
    validate.add_argument('--folds', type=integer_in_range(minimum=2), default=5,
                          help='number of folds (>= 2)')
    validate.add_argument('--leave-one-value-out', action='store_true',
                          help='instead of the k folds: for each limit value V with real '
                          'crops, train a bank without any real crop of V and read all of '
                          'V\'s crops (and one track fold of the others): how a value '
                          'without real examples, such as 130 km/h, is read')
    validate.add_argument('--values', nargs='+', metavar='KMH',
                          help='with --leave-one-value-out: the values to hold out '
                          '(default: every value with real crops)')
    validate.add_argument('--scenes-only', action='store_true',
                          help='with --scenes: only the k folds by scene (the k folds by '
                          'track, most of the time, are skipped)')
    validate.add_argument('--approach', action='store_true',
                          help='with --scenes: each scene fold\'s bank, written to a bank '
                          'file, also reads approach sequences made from its own fold\'s '
                          'scenes (speed_sign_synth approach, 640x480) through the whole '
                          'pipeline with tracking (speed_sign_eval bag\'s figures, summed '
                          'over the folds; temporary bags of about 0.9 MB a frame in '
                          '$TMPDIR)')
    validate.add_argument('--boxes', action='store_true',
                          help='with --scenes: each scene fold\'s bank also reads the '
                          'annotated boxes of its own fold\'s scenes as crops, tight and '
                          'padded by 10 %% (read right, another limit, round look-alikes '
                          'read as a limit; another camera\'s crops, held out)')
    validate.set_defaults(run=_run_validate)
    return parser


def _configs(args: argparse.Namespace
             ) -> tuple[ClassifierConfig, TrainingConfig, DetectorConfig]:
    pipeline = load_yaml(args.config) if args.config else PipelineConfig()
    classifier = pipeline.classifier
    min_lead = MIN_LEAD_OF_MODEL[args.model] if args.min_lead is None else args.min_lead
    try:
        training = TrainingConfig(model=args.model, ridge=args.ridge,
                                  hidden_units=args.hidden_units, epochs=args.epochs,
                                  members=args.members, candidates=args.candidates,
                                  min_lead=min_lead, augmented_copies=args.augmented_copies,
                                  examples_per_class=args.examples_per_class,
                                  rendered_per_kind=args.rendered_per_kind,
                                  arched_six_per_kind=args.arched_six_per_kind,
                                  composites_per_value=args.composites_per_value,
                                  design_per_kind=args.design_per_kind,
                                  scene_copies=args.scene_copies,
                                  second_opinion=not args.no_second_opinion,
                                  real_filter_weight=args.real_filter_weight,
                                  real_filter_noise=args.real_filter_noise, seed=args.seed)
    except ValueError as err:
        raise SpeedSignError(f'invalid training setting: {err}') from err
    return classifier, training, pipeline.detector


def _bar(args: argparse.Namespace, description: str) -> Any:
    bar = progress_bar(None, description, 'crop', enabled=not args.quiet)

    def update(done: int, total: int) -> None:
        bar.total = total
        bar.update(done - bar.n)
    update.close = bar.close  # type: ignore[attr-defined]
    return update


def _run_build(args: argparse.Namespace) -> int:
    classifier_config, training, detector_config = _configs(args)
    progress = _bar(args, 'locating signs')
    try:
        bank = train_bank(args.folders, classifier_config, training, progress, args.scenes,
                          detector_config, args.backend)
    finally:
        progress.close()
    try:
        save_trained_bank(args.out, bank)
    except OSError as err:
        raise SpeedSignError(f'cannot write {args.out}: {err}') from err
    size = args.out.stat().st_size
    record = bank.provenance
    summary = {'bank_file': str(args.out), 'bytes': size, 'crops': record['crops'],
               'located': record['located'], 'counts_per_class': record['counts_per_class'],
               'scene_examples': record['scene_examples'], 'unreadable': record['unreadable'],
               'host': record.get('host')}
    print(f'wrote {args.out} ({size / 1e6:.2f} MB) from {record["crops"]} crops '
          f'({record["located"]} located): ' + ', '.join(
              f'{label} {count}' for label, count in record['counts_per_class'].items()))
    if record['scene_examples']:
        print('scene examples (with copies): ' + ', '.join(
            f'{label} {count}' for label, count in record['scene_examples'].items()))
    if record.get('host'):
        print(f'trained on {describe_host(record["host"])}')
    for line in record['unreadable']:
        print(f'skipped unreadable crop: {line}')
    if args.json:
        print(json.dumps(summary, sort_keys=True))
    return 1 if record['unreadable'] else 0


def _percent(value: float | None) -> str:
    return '-' if value is None else f'{100.0 * value:5.1f}%'


def _run_value_holdout(args: argparse.Namespace) -> int:
    classifier_config, training, detector_config = _configs(args)
    progress = _bar(args, 'holding out values')
    try:
        report = leave_one_value_out(args.folders, args.folds, classifier_config, training,
                                     progress, args.scenes, detector_config, args.backend,
                                     args.values)
    except ValueError as err:
        raise SpeedSignError(str(err)) from err
    finally:
        progress.close()
    print(f'leave one value out, {report["crops"]} crops: each value read by a bank '
          'trained without any of its real crops')
    print(f'{"value":>6} {"crops":>6} {"right":>7} {"wrong limit":>12} {"withheld":>9}   '
          f'{"others: right":>13} {"wrong limit":>12} {"look-alikes as limit":>21}')
    for value, row in report['values'].items():
        held, others = row['held_out'], row['others']
        print(f'{value:>6} {held["crops"]:>6} {_percent(held["accuracy"]):>7} '
              f'{_percent(held["wrong_limit_rate"]):>12} {_percent(held["withheld_rate"]):>9}   '
              f'{_percent(others["accuracy"]):>13} {_percent(others["wrong_limit_rate"]):>12} '
              f'{_percent(others["lookalikes_read_as_limit_rate"]):>21}')
    print(f'held-out values: mean right {report["mean_accuracy"]:.4f}, worst right '
          f'{report["worst_accuracy"]:.4f}, worst wrong limit '
          f'{_percent(report["worst_wrong_limit_rate"]).strip()}')
    if args.json:
        print(json.dumps(report, sort_keys=True))
    return 1 if report['unreadable'] else 0


def _usage_error(args: argparse.Namespace) -> str | None:
    """What is wrong with the combination of ``validate``'s options, or None."""
    if args.values and not args.leave_one_value_out:
        return '--values needs --leave-one-value-out'
    for option, given in (('--scenes-only', args.scenes_only), ('--approach', args.approach),
                          ('--boxes', args.boxes)):
        if not given:
            continue
        if args.leave_one_value_out:
            return f'{option} does not go with --leave-one-value-out'
        if not args.scenes:
            return f'{option} needs --scenes SCENE_DIR'
        if args.no_second_opinion:
            return (f'{option} needs the second opinion (the folds by scene train it on the '
                    'other folds\' scenes): drop --no-second-opinion')
    return None


def _run_validate(args: argparse.Namespace) -> int:
    problem = _usage_error(args)
    if problem is not None:
        print(f'speed_sign_train validate: error: {problem}', file=sys.stderr)
        return 2
    if args.leave_one_value_out:
        return _run_value_holdout(args)
    classifier_config, training, detector_config = _configs(args)
    pipeline_config = load_yaml(args.config) if args.config else PipelineConfig()
    measures: list[SceneFoldMeasure] = [SceneBoxFolds(classifier_config)] if args.boxes else []
    if args.approach:
        measures.append(ApproachFolds(dataclasses.replace(pipeline_config,
                                                          backend=args.backend)))
    progress = _bar(args, 'locating crops' if args.scenes_only else 'validating')
    try:
        if args.scenes_only:
            report = validate_by_scene(args.folders, args.scenes, args.folds,
                                       classifier_config, training, progress, detector_config,
                                       args.backend, measures)
        else:
            report = cross_validate(args.folders, args.folds, classifier_config, training,
                                    progress, args.scenes, detector_config, args.backend,
                                    measures)
    finally:
        progress.close()
    if not args.scenes_only:
        _print_track_folds(args.folds, report)
    if 'scenes' in report:
        scenes = report['scenes']
        print(f'{args.folds}-fold validation split by scene ({scenes["frames"]} frames, trained '
              f'second opinion): {scenes["recognized"]}/{scenes["signs"]} limit signs '
              f'recognized ({scenes["recognition_recall"]:.3f}), {scenes["false_limits"]} '
              f'false limits ({scenes["false_limits_per_frame"]:.4f} per frame)')
        if BOXES_KEY in scenes:
            print(format_boxes_line(scenes[BOXES_KEY], args.folds))
        if 'approach' in scenes:
            print(format_approach_line(scenes['approach'], args.folds))
    if args.json:
        print(json.dumps(report, sort_keys=True))
    return 1 if report['unreadable'] else 0


def _print_track_folds(folds: int, report: dict[str, Any]) -> None:
    """The table of :func:`cross_validate`'s folds by track, on stdout."""
    print(f'{folds}-fold validation split by track, {report["crops"]} crops')
    header = f'{"class":>13} ' + ' '.join(f'{_VARIANT_TITLES[v]:>30}' for v in VARIANTS)
    print(header)
    print(f'{"":>13} ' + ' '.join(f'{"right / wrong limit / none":>30}' for _ in VARIANTS))
    classes = list(report['variants'][VARIANTS[0]]['per_class'])
    for name in classes:
        cells = []
        for variant in VARIANTS:
            row = report['variants'][variant]['per_class'][name]
            cells.append(f'{_percent(row["accuracy"])} / {_percent(row["wrong_limit_rate"])}'
                         f' / {_percent(row["withheld_rate"])}')
        print(f'{name:>13} ' + ' '.join(f'{cell:>30}' for cell in cells))
    for key, title in (('accuracy', 'all limits'), ('wrong_limit_rate', 'wrong limit'),
                       ('accuracy_under_20px', 'under 20 px'),
                       ('lookalikes_read_as_limit_rate', 'look-alikes as limit')):
        print(f'{title:>20} ' + ' '.join(
            f'{_percent(report["variants"][v][key]):>30}' for v in VARIANTS))
    print(f'{"fold accuracy":>20} ' + ' '.join(
        f'{report["accuracy_mean"][v]:>21.4f} +- {report["accuracy_std"][v]:.4f}'
        for v in VARIANTS))


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_train``; returns the process exit status."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s',
                        stream=sys.stderr)
    return run_subcommand('speed_sign_train', args)


if __name__ == '__main__':
    sys.exit(main())
