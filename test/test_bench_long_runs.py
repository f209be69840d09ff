"""The long runs in bench/RESULTS.md: bench/long_runs_markdown.py on fixture JSON files.

The 5-fold and leave-one-value-out fixtures are made by the package's own summaries
(``track_validation.summarise``, ``value_holdout.value_answers``) from chosen answers, so
they have the shape ``speed_sign_train validate --json`` prints; the designs and soak
fixtures follow ``bench_sign_designs.py`` and ``bench_soak.py``. The tests check that each
section holds its per-value rows and flags a figure that misses its target, states its
command and host, is absent when its file is not given, and that the files reach the
report through ``report.py`` and ``make bench`` (``make -n``), and through
``record_json.py``, which ``make validate`` runs.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from test_bench_results import fake_results, row_starting, sections, table_rows
from test_bench_smoke import bench_module

from speed_sign_detector.training.track_validation import summarise
from speed_sign_detector.training.value_holdout import value_answers

PROJECT_ROOT = Path(__file__).resolve().parents[1]
HOLDOUT_HEADING = 'Leave one value out'
FOLDS_HEADING = 'Recognition per value: 5 folds by track'


@pytest.fixture(scope='module')
def long_runs() -> ModuleType:
    return bench_module('long_runs_markdown')


@pytest.fixture(scope='module')
def markdown() -> ModuleType:
    return bench_module('results_markdown')


def _answers(truth: str, right: int, wrong: dict[str, int], withheld: int) -> list[str]:
    return [truth] * right + [answer for answer, count in wrong.items()
                              for _ in range(count)] + ['no_sign'] * withheld


def _recorded(command: list[str]) -> dict[str, Any]:
    return {'command': command, 'elapsed_s': 2400.0, 'exit_status': 0,
            'load_average_at_end': [2.0, 2.1, 2.2],
            'machine': {'cpus': 2, 'cpu_model': 'Fixture EPYC 7000', 'platform': 'Linux-x',
                        'python': '3.12.3', 'opencv': '4.11.0',
                        'load_average_at_start': [1.5, 1.6, 1.7]}}


def folds_json() -> dict[str, Any]:
    """5 folds: 20 clean, 100 read as 10 in 2 of 300 (0.67 %: over the budget), 120 read
    as 100 once in 400 (0.25 %), an end class, 2 look-alike classes, and scenes."""
    truths: list[str] = []
    answers: list[str] = []
    for truth, right, wrong, withheld in (('100', 290, {'10': 2}, 8), ('120', 391, {'100': 1}, 8),
                                          ('20', 200, {}, 0), ('end_of_limit', 150, {}, 0)):
        answers += _answers(truth, right, wrong, withheld)
        truths += [truth] * (right + sum(wrong.values()) + withheld)
    class_ids = [{'20': 0, '100': 5, '120': 6, 'end_of_limit': 8}[t] for t in truths]
    truths += ['other_sign'] * 2000
    answers += ['other_sign'] * 1999 + ['30']
    class_ids += [9] * 1000 + [10] * 1000
    summary = summarise(truths, answers, class_ids, [30] * len(truths))
    return {'folds': 5, 'crops': len(truths), 'unreadable': [],
            'data_folders': ['../shared/data/gtsrb-dev', '../shared/data/gtsrb-lookalikes-dev'],
            'variants': {'rendered': {**summary, 'accuracy': 0.912},
                         'trained_filters_second_opinion': summary},
            'accuracy_mean': {'trained_filters_second_opinion': 0.9741},
            'accuracy_std': {'trained_filters_second_opinion': 0.0062},
            'scenes': {'folds': 5, 'frames': 466, 'signs': 284, 'recognized': 258,
                       'recognition_recall': 258 / 284, 'false_limits': 7,
                       'false_limits_per_frame': 7 / 466},
            'recorded_run': _recorded(['speed_sign_train', 'validate', '../shared/data/gtsrb-dev',
                                       '../shared/data/gtsrb-lookalikes-dev', '--scenes',
                                       '../shared/data/gtsdb-dev', '--approach', '--boxes',
                                       '--json'])}


def holdout_json() -> dict[str, Any]:
    """30 held out: 0.9 right, none wrong (meets); 60: 0.8 right (misses); 120: 0.9 right
    but 1.5 % as 100 (misses)."""
    values = {}
    for value, right, wrong, withheld in (('30', 540, {}, 60), ('60', 480, {'80': 3}, 117),
                                          ('120', 360, {'100': 6}, 34)):
        held = value_answers(value, _answers(value, right, wrong, withheld))
        others = summarise(['20', '50'], ['20', '50'], [0, 2], [30, 30])
        values[value] = {'fold': 0, 'training_crops': 3000, 'held_out': held, 'others': others}
    accuracies = [row['held_out']['accuracy'] for row in values.values()]
    return {'crops': 4400, 'folds': 5, 'values': values, 'data_folders': ['gtsrb-dev'],
            'mean_accuracy': sum(accuracies) / 3, 'worst_accuracy': min(accuracies),
            'worst_wrong_limit_rate': 0.015, 'unreadable': []}


def designs_json() -> dict[str, Any]:
    """Painted: all right; LED dot matrix: 130 read as 120 once (a wrong number)."""
    def design(per_value: dict[str, dict[str, int]], wrong_answers: dict[str, int]
               ) -> dict[str, Any]:
        totals = {key: sum(row.get(key, 0) for row in per_value.values())
                  for key in ('right', 'wrong', 'withheld')}
        signs = sum(totals.values())
        return {'signs': signs, **totals, 'right_rate': round(totals['right'] / signs, 3),
                'per_value': per_value, 'wrong_answers': wrong_answers}
    return {'designs': {
        'painted': design({'30': {'right': 6}, '130': {'right': 6}}, {}),
        'led_dot_matrix': design({'30': {'right': 5, 'withheld': 1},
                                  '130': {'right': 4, 'wrong': 1, 'withheld': 1}},
                                 {'130 as 120 (17 px)': 1}),
        'end_of_limit': design({'end_of_limit_30': {'right': 6},
                                'end_of_limit_130': {'right': 6}}, {}),
        'end_of_all': design({'end_of_restrictions': {'right': 90}}, {}),
        'led_banded': design({'30': {'right': 1, 'withheld': 5},
                              '130': {'withheld': 6}}, {})},
        'seed': 1, 'per_value': 6, 'diameter_px': [15, 60], 'bank_file': 'shipped',
        'elapsed_s': 180.0}


def soak_json() -> dict[str, Any]:
    """An hour at 30 Hz: RSS 400 -> 424 MiB (6 %: over 5 %), 2 frames unaccounted."""
    return {
        'bench': 'soak', 'minutes_requested': 60.0, 'seconds': 3600.4, 'width': 1280,
        'height': 720, 'drive': {'bag': 'synthetic (made for the run)', 'seed': 1,
                                 'frames_per_loop': 600,
                                 'message': 'sensor_msgs/CompressedImage'},
        'publish_hz_target': 30.0, 'publish_hz_achieved': 29.98, 'loops': 180,
        'stamp_jumps_published': 179, 'stamp_jumps_logged_by_node': 179,
        'frames': {'published': 107940, 'answered': 100000, 'node_dropped': 7900,
                   'lost_in_transport': 38, 'unaccounted': 2},
        'latency_ms': {'p50': 61.5, 'p95': 90.5, 'max': 300.5}, 'node_cpu_percent': 150.5,
        'rss_mib': {'samples': 360, 'reference_s': 60.0, 'at_reference': 400.0, 'end': 424.0,
                    'max': 425.0, 'growth_percent': 6.0},
        'errors': {'log_error_lines': 0, 'log_tracebacks': 0, 'diagnostics_error_statuses': 0},
        'node': {'same_process_at_end': True, 'counter_resets': 0},
        'backend': 'gl', 'renderer': 'llvmpipe (LLVM 19.1.1, 256 bits)',
        'machine': {'cpus': 2, 'cpu_model': 'Fixture EPYC 7000',
                    'load_average_at_start': [1.0, 1.0, 1.0]},
        'host': 'Fixture EPYC 7000, 2 cores; GL renderer llvmpipe',
        'load_average_at_end': [2.5, 2.5, 2.5], 'targets': {'rss_growth_percent': 5.0},
        'meets_rss_target': False, 'meets_error_target': True,
        'meets_accounting_target': False, 'meets_restart_target': True}


def with_long_runs(**figures: dict[str, Any]) -> dict[str, Any]:
    results = fake_results()
    results.update(figures)
    return results


def test_no_long_run_sections_when_none_is_given(markdown: ModuleType,
                                                 long_runs: ModuleType) -> None:
    text = markdown.render_results_markdown(fake_results())
    for run in long_runs.LONG_RUNS:
        assert f'## {run.title}' not in text
    summary = [row[0] for row in table_rows(sections(text)['Summary'])]
    assert not [row for row in summary if row.startswith(('recognition,', 'leave one',
                                                          'rendered designs', 'soak'))]
    assert long_runs.long_run_lines({}) == [] and long_runs.summary_rows({}) == []


def test_folds_per_class_rows_flag_the_budget(markdown: ModuleType) -> None:
    figures = folds_json()
    text = markdown.render_results_markdown(with_long_runs(recognition_folds=figures))
    part = sections(text)[FOLDS_HEADING]
    rows = table_rows(part.split('\n### ')[0])
    classes = [row[0] for row in rows[1:]]
    assert classes == ['20', '100', '120', 'end_of_limit', 'all']   # by value, not as text
    hundred = row_starting(rows, '100')
    assert hundred[1:5] == ['300', '0.967', '0.67 % (2)', '2.7 %']
    assert hundred[5] == '10 (2)' and hundred[6] == '**no**'
    assert row_starting(rows, '120')[4:7] == ['2.0 %', '100 (1)', 'yes']
    assert row_starting(rows, '20')[3] == '0.00 % (0)'
    targets = table_rows(part.split('### Targets')[1])
    assert row_starting(targets, 'accuracy, mean of the folds >= 0.97')[1:] == [
        '0.974 ± 0.006', 'yes']
    assert row_starting(targets, 'no class read as another limit over 0.5 %')[1:] == [
        'worst: 100, 0.67 %', '**no**']
    assert row_starting(targets, 'look-alikes read as a limit <= 0.1 %')[1:] == [
        '0.050 % (1 of 2000)', 'yes']
    scene_rows = [row for row in targets if row[0].startswith('scenes')]
    assert [row[2] for row in scene_rows] == ['yes', '**no**']   # 0.908 >= 0.9; 0.015 > 0.01
    assert 'Command: `speed_sign_train validate ../shared/data/gtsrb-dev' in part
    assert '(`make validate`), 40 min' in part   # the very command make validate runs
    assert 'Host: Fixture EPYC 7000, 2 cores' in part and '1.5, 1.6, 1.7 at the start' in part
    summary = table_rows(sections(text)['Summary'])
    row = next(row for row in summary if row[0].startswith('recognition, 5 folds'))
    assert '0.974' in row[1] and '100: 0.67 %' in row[1]


def test_the_scene_folds_approach_sequences_against_their_targets(
        markdown: ModuleType) -> None:
    """``validate --approach``: the approach rows flag 0.94 recognized and 0 wrong limits;
    a file without them has no such rows."""
    figures = folds_json()
    figures['scenes']['approach'] = {'folds': 5, 'sequences': 239, 'signs': 309,
                                     'recognized': 250, 'recall': 250 / 309,
                                     'approached_signs': 239, 'approached_recognized': 226,
                                     'approached_recall': 226 / 239, 'wrong_limits': 1}
    text = markdown.render_results_markdown(with_long_runs(recognition_folds=figures))
    targets = table_rows(sections(text)[FOLDS_HEADING].split('### Targets')[1])
    recognized = row_starting(targets, 'approach sequences, 5 folds by scene (each read by a '
                              'bank that never saw its scene): approached signs recognized '
                              '>= 0.94')
    assert recognized[1:] == ['0.946 (226 of 239); all limit signs in view 0.809 (250 of 309)',
                              'yes']
    assert row_starting(targets, 'approach sequences: wrong limits 0')[1:] == ['1', '**no**']
    summary = table_rows(sections(text)['Summary'])
    row = next(row for row in summary if row[0].startswith('recognition, 5 folds'))
    assert 'approach sequences 0.946 recognized, 1 wrong limits' in row[1]
    plain = markdown.render_results_markdown(with_long_runs(recognition_folds=folds_json()))
    assert 'approach sequences' not in plain and 'gtsdb-dev boxes' not in plain


def test_the_scene_folds_boxes_are_listed_per_cut(markdown: ModuleType) -> None:
    figures = folds_json()
    cut = {'limit_signs': 284, 'right': 270, 'wrong_limits': 1, 'withheld': 13,
           'accuracy': 270 / 284, 'lookalikes': 256, 'lookalikes_read_as_limit': 0}
    figures['scenes']['boxes'] = {'folds': 5, 'tight': cut,
                                  'padded': {**cut, 'right': 263, 'accuracy': 263 / 284}}
    part = sections(markdown.render_results_markdown(
        with_long_runs(recognition_folds=figures)))[FOLDS_HEADING]
    assert ("gtsdb-dev boxes read as crops by the scene folds' banks, tight: 0.951 read "
            "right (270 of 284), 1 another limit, 0 of 256 look-alikes read as a limit") in part
    assert "padded: 0.926 read right (263 of 284)" in part


def test_holdout_per_value_rows_and_mean(markdown: ModuleType) -> None:
    text = markdown.render_results_markdown(with_long_runs(value_holdout=holdout_json()))
    part = sections(text)[HOLDOUT_HEADING]
    rows = table_rows(part)
    assert [row[0] for row in rows[1:]] == ['30', '60', '120', 'mean']
    assert row_starting(rows, '30')[1:7] == ['600', '0.900', '0.00 % (0)', '10.0 % (60)', '-',
                                             'yes']
    sixty = row_starting(rows, '60')
    assert sixty[2] == '0.800' and sixty[5] == '80 (3)'
    assert sixty[6] == '**no**: right 0.80 < 0.85'   # 0.5 % another limit is within 1 %
    hundred_twenty = row_starting(rows, '120')
    assert hundred_twenty[3] == '1.50 % (6)'
    assert hundred_twenty[6] == '**no**: another limit 1.5 % > 1 %'
    mean = row_starting(rows, 'mean')
    assert mean[2] == '0.867' and mean[6].startswith('**no**')
    # no recorded run: the command make validate runs is named, the host is not
    assert '--leave-one-value-out --json' in part and 'Host: not recorded.' in part


def test_a_note_says_which_run_each_figure_comes_from(markdown: ModuleType) -> None:
    """Figures merged from two runs carry a note, printed under the command."""
    merged = {**holdout_json(), 'note': 'Values 30 and 60 come from an earlier full run.',
              'recorded_run': _recorded(['speed_sign_train', 'validate', 'gtsrb-dev',
                                         '--leave-one-value-out', '--values', '120',
                                         '--json'])}
    part = sections(markdown.render_results_markdown(
        with_long_runs(value_holdout=merged)))[HOLDOUT_HEADING]
    lines = part.splitlines()
    command = next(i for i, line in enumerate(lines) if line.startswith('Command:'))
    assert '--values 120' in lines[command]
    assert lines[command + 1] == 'Values 30 and 60 come from an earlier full run.'
    assert lines[command + 2].startswith('Host:')


def test_designs_rows_and_the_wrong_number(markdown: ModuleType, long_runs: ModuleType
                                           ) -> None:
    text = markdown.render_results_markdown(with_long_runs(sign_designs=designs_json()))
    part = sections(text)['Rendered designs']
    rows = table_rows(part.split('\n### ')[0])
    assert row_starting(rows, 'painted, white face')[1:] == ['12', '1.000', '0', '0', 'yes']
    assert row_starting(rows, 'LED, dot matrix')[1:] == ['12', '0.750', '1', '2', '**no**']
    assert row_starting(rows, 'end of all restrictions')[-1] == 'yes'
    # rows dark between the lamps' pulses: withheld is right, the target is 0 wrong
    assert row_starting(rows, 'LED, white, rows dark in bands')[1:] == [
        '12', '0.083', '0', '11', 'yes']
    per_value = table_rows(part.split('### Read right per value')[1])
    assert per_value[0] == ['value', 'painted, white face', 'LED, dot matrix', 'end of limit',
                            'LED, white, rows dark in bands']
    assert row_starting(per_value, '130')[1:] == ['6/6', '4/6, **1 wrong**', '6/6', '0/6']
    assert '130 as 120 (17 px) x1' in part
    assert 'bench_sign_designs.py --per-value 30 --seed 1 --json' in part
    # the summary's worst design is one that should be read, not the banded one
    summary = long_runs.summary_rows({'sign_designs': designs_json()})
    assert summary[0][1] == 'LED, dot matrix 0.750; 1 wrong'


def test_soak_rows_against_the_targets(markdown: ModuleType) -> None:
    text = markdown.render_results_markdown(with_long_runs(soak=soak_json()))
    part = sections(text)['Soak']
    rows = table_rows(part)
    assert row_starting(rows, 'RSS growth after the first minute')[1:] == [
        '6.00 %', '<= 5 %', '**no**']
    assert row_starting(rows, 'RSS after 60 s / at the end / peak, MiB')[1] == \
        '400.0 / 424.0 / 425.0'
    assert row_starting(rows, 'frames unaccounted (neither answered nor counted as dropped '
                              'or lost)')[1:] == ['2', '0', '**no**']
    assert row_starting(rows, 'loops / stamp jumps the node logged')[1] == '180 / 179'
    assert 'bench_soak.py --minutes 60 --width 1280 --height 720 --json' in part
    assert 'Host: Fixture EPYC 7000, 2 cores; GL renderer llvmpipe' in part


def test_a_file_without_figures_says_so(tmp_path: Path, markdown: ModuleType,
                                        long_runs: ModuleType) -> None:
    empty = tmp_path / 'soak.json'
    empty.write_text('')   # what `make soak` leaves when the soak could not start
    saved = tmp_path / 'folds.txt'   # the command's whole stdout: a table, then the JSON
    saved.write_text('5-fold validation split by track\n' + json.dumps(folds_json()) + '\n')
    wrong_shape = tmp_path / 'designs.json'
    wrong_shape.write_text(json.dumps(holdout_json()))
    results = with_long_runs(soak=long_runs.read_long_run(empty),
                             recognition_folds=long_runs.read_long_run(saved),
                             sign_designs=long_runs.read_long_run(wrong_shape))
    parts = sections(markdown.render_results_markdown(results))
    assert 'Failed: cannot read' in parts['Soak']
    assert table_rows(parts[FOLDS_HEADING])
    assert 'does not hold the figures' in parts['Rendered designs']


def test_record_json_keeps_the_command_and_host(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    record = bench_module('record_json')
    out = tmp_path / 'validation' / 'designs.json'
    script = "import json; print('a table line'); print(json.dumps({'designs': {}}))"
    assert record.main([str(out), '--', sys.executable, '-c', script]) == 0
    saved = json.loads(out.read_text())
    assert saved['designs'] == {}
    run = saved['recorded_run']
    assert run['command'] == ['python', '-c', script] and run['exit_status'] == 0
    assert run['machine']['cpus'] >= 1 and run['machine']['cpu_model']
    assert capsys.readouterr().out == 'a table line\n'   # the JSON line is not echoed
    assert record.main([str(tmp_path / 'none.json'), '--', sys.executable, '-c',
                        "print('no json')"]) == 1
    assert not (tmp_path / 'none.json').exists()


def test_report_merges_the_files_into_results_json(tmp_path: Path,
                                                   markdown: ModuleType) -> None:
    pytest.importorskip('matplotlib', reason='matplotlib (setup.py extra "bench") not installed')
    report = bench_module('report')
    saved = tmp_path / 'results.json'
    saved.write_text(json.dumps(fake_results()))
    files = {'folds.json': folds_json(), 'value_holdout.json': holdout_json(),
             'designs.json': designs_json(), 'soak.json': soak_json()}
    for name, figures in files.items():
        (tmp_path / name).write_text(json.dumps(figures))
    written = tmp_path / 'RESULTS.md'
    assert report.main([str(saved), '--out', str(tmp_path / 'plots'), '--results-md',
                        str(written), '--validation', str(tmp_path / 'folds.json'),
                        '--value-holdout', str(tmp_path / 'value_holdout.json'),
                        '--designs', str(tmp_path / 'designs.json'),
                        '--soak', str(tmp_path / 'soak.json')]) == 0
    merged = json.loads(saved.read_text())
    assert merged['value_holdout']['source_file'] == str(tmp_path / 'value_holdout.json')
    assert merged['soak']['frames']['unaccounted'] == 2
    text = written.read_text()
    assert text == markdown.render_results_markdown(merged)
    assert (f"the long runs' files merged into it afterwards by `python bench/report.py "
            f"{saved} --out") in text.split('\n## ')[0]   # in the note before the summary
    headings = list(sections(text))
    assert headings.index('Node through DDS') < headings.index(FOLDS_HEADING) \
        < headings.index(HOLDOUT_HEADING) < headings.index('Rendered designs') \
        < headings.index('Soak')


@pytest.mark.skipif(shutil.which('make') is None, reason='make is not installed')
def test_make_validate_runs_the_commands_the_report_names(tmp_path: Path,
                                                          long_runs: ModuleType) -> None:
    dry_run = subprocess.run(['make', '-n', 'validate', f'OUT={tmp_path}', 'DATA=../shared/data'],
                             cwd=PROJECT_ROOT, capture_output=True, text=True, check=True).stdout
    recorded = {}
    for line in re.sub(r'\s*\\\n\s*', ' ', dry_run).splitlines():
        if 'record_json.py' in line:
            out, command = line.split('record_json.py ', 1)[1].split(' -- ', 1)
            program, *arguments = command.split()
            recorded[Path(out).name] = ' '.join([Path(program).name.replace('python3', 'python'),
                                                 *arguments])
    commands = {run.key: run.command for run in long_runs.LONG_RUNS}
    assert recorded == {'folds.json': commands['recognition_folds'],
                        'value_holdout.json': commands['value_holdout'],
                        'designs.json': commands['sign_designs']}


@pytest.mark.skipif(shutil.which('make') is None, reason='make is not installed')
def test_make_bench_passes_the_files_that_exist(tmp_path: Path) -> None:
    (tmp_path / 'validation').mkdir()
    (tmp_path / 'validation' / 'value_holdout.json').write_text('{}')

    def run_all_line() -> str:
        dry_run = subprocess.run(['make', '-n', 'bench', f'OUT={tmp_path}'], cwd=PROJECT_ROOT,
                                 capture_output=True, text=True, check=True).stdout
        return re.sub(r'\s*\\\n\s*', ' ', dry_run.split('bench/run_all.py', 1)[1])

    line = run_all_line()
    assert f"--value-holdout {tmp_path / 'validation' / 'value_holdout.json'}" in line
    assert '--validation' not in line and '--soak' not in line and '--designs' not in line
    (tmp_path / 'soak').mkdir()
    (tmp_path / 'soak' / 'soak.json').write_text('{}')
    assert f"--soak {tmp_path / 'soak' / 'soak.json'}" in run_all_line()
