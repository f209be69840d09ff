"""The long runs in bench/RESULTS.md: recognition per value, leave one value out, designs, soak.

``make bench`` (minutes) cannot run them: 5-fold validation by track (about 40 min on 2
cores), leave one value out (about 45 min), the rendered sign designs (minutes) and the
soak (an hour). ``make validate`` and ``make soak`` write their JSON files; ``run_all.py``
and ``report.py`` take them as ``--validation``, ``--value-holdout``, ``--designs`` and
``--soak`` (:func:`add_arguments`), merge them into results.json under the keys of
:data:`LONG_RUNS` (:func:`load_long_runs`), and ``results_markdown.py`` renders a section
for each one given (:func:`long_run_lines`) and a row of the summary
(:func:`summary_rows`). None given, none rendered.

A file is either what ``bench/record_json.py`` wrote (the command's JSON object with
``'recorded_run'``: the command, host and time) or a command's stdout saved as it is (its
last line the JSON object); the second kind names the command the Makefile runs and no
host, as it records neither. Every section states the targets of issue 32 beside its
figures, with '**no**' where a figure misses one.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from markdown_tables import number, percent, table
from record_json import RecordError, last_json_object

__all__ = ['LONG_RUNS', 'LongRun', 'add_arguments', 'load_long_runs', 'long_run_lines',
           'read_long_run', 'summary_rows']


@dataclass(frozen=True)
class LongRun:
    """One long run: where its figures go in results.json and how they are made."""

    key: str           #: its key in results.json
    option: str        #: the option of run_all.py and report.py that names its JSON file
    title: str         #: its section's heading in RESULTS.md
    make_target: str   #: the make target that writes its JSON file
    command: str       #: the command that target runs (its JSON file's own command wins)


LONG_RUNS: tuple[LongRun, ...] = (
    LongRun('recognition_folds', '--validation', 'Recognition per value: 5 folds by track',
            'make validate', 'speed_sign_train validate ../shared/data/gtsrb-dev '
            '../shared/data/gtsrb-lookalikes-dev --scenes ../shared/data/gtsdb-dev --approach '
            '--boxes --json'),
    LongRun('value_holdout', '--value-holdout', 'Leave one value out', 'make validate',
            'speed_sign_train validate ../shared/data/gtsrb-dev '
            '../shared/data/gtsrb-lookalikes-dev --leave-one-value-out --json'),
    LongRun('sign_designs', '--designs', 'Rendered designs', 'make validate',
            'python bench/bench_sign_designs.py --per-value 30 --seed 1 --json'),
    LongRun('soak', '--soak', 'Soak', 'make soak',
            'python bench/bench_soak.py --minutes 60 --width 1280 --height 720 --json'),
)

#: The variant of ``speed_sign_train validate`` that is the shipped bank's recipe.
SHIPPED_VARIANT = 'trained_filters_second_opinion'
#: Issue 32's targets: 5 folds by track.
FOLD_ACCURACY_TARGET = 0.97
CLASS_ANOTHER_LIMIT_BUDGET = 0.005
LOOKALIKE_AS_LIMIT_TARGET = 0.001
SCENE_RECALL_TARGET = 0.90
SCENE_FALSE_LIMITS_PER_FRAME_TARGET = 0.01
#: Approach sequences of the scene folds (``--approach``): limit signs recognized, and no
#: wrong limit.
APPROACH_RECOGNIZED_TARGET = 0.94
#: Leave one value out: each value, and the mean.
HOLDOUT_RIGHT_TARGET = 0.85
HOLDOUT_ANOTHER_LIMIT_TARGET = 0.01
HOLDOUT_MEAN_RIGHT_TARGET = 0.90
#: Rendered designs: each design.
DESIGN_RIGHT_TARGET = 0.9
#: Rendered designs whose target is 0 wrong only: signs a reader should withhold (an LED
#: sign with rows dark between its lamps' pulses), not read.
WITHHELD_DESIGNS: frozenset[str] = frozenset({'led_banded'})
#: Soak, where its JSON states none: RSS growth, %.
SOAK_RSS_GROWTH_TARGET_PERCENT = 5.0
#: The designs of ``bench_sign_designs.py`` in words.
DESIGN_LABELS: dict[str, str] = {
    'painted': 'painted, white face', 'yellow': 'yellow face', 'led': 'LED, white',
    'led_amber': 'LED, amber', 'led_dot_matrix': 'LED, dot matrix',
    'led_dark_on_lit': 'LED, dark on lit', 'end_of_limit': 'end of limit',
    'end_of_all': 'end of all restrictions', 'led_banded': 'LED, white, rows dark in bands'}

Section = Mapping[str, Any]


# ------------------------------------------------------------------------------- inputs
def _existing_file(text: str) -> Path:
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f'no file {path}')
    return path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add one option per long run (``--validation PATH`` ...) to ``parser``."""
    for run in LONG_RUNS:
        parser.add_argument(run.option, type=_existing_file, metavar='PATH',
                            dest=run.key, help=f'JSON of an earlier run ({run.make_target}: '
                            f'`{run.command}`) to merge into results.json and render as '
                            f'"{run.title}"')


def read_long_run(path: Path) -> dict[str, Any]:
    """The JSON object on the last non-empty line of ``path``, with ``'source_file'``;
    ``{'error': why, 'source_file'}`` when there is none (an empty or cut-off file)."""
    try:
        figures = last_json_object(path.read_text())
    except (OSError, UnicodeDecodeError, RecordError) as err:
        return {'error': f'cannot read {path}: {err}', 'source_file': str(path)}
    figures['source_file'] = str(path)
    return figures


def load_long_runs(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """The long runs ``args`` names (options of :func:`add_arguments`), by results.json key."""
    return {run.key: read_long_run(getattr(args, run.key)) for run in LONG_RUNS
            if getattr(args, run.key, None) is not None}


# ------------------------------------------------------------------------------ helpers
def _met(ok: bool) -> str:
    return 'yes' if ok else '**no**'


def _value_order(name: str) -> tuple[bool, int, str]:
    """Limits by value first, then the other classes by name ('end_of_limit')."""
    return (not name.isdigit(), int(name) if name.isdigit() else 0, name)


def _count(rate: float | None, total: int) -> int:
    return round((rate or 0.0) * total)


def _wrong_limits(truth: str, answers: Mapping[str, int]) -> str:
    """The limits other than ``truth`` that crops were read as: '100 (7), 20 (1)'."""
    wrong = sorted(((answer, count) for answer, count in answers.items()
                    if answer.isdigit() and answer != truth), key=lambda item: -item[1])
    return ', '.join(f'{answer} ({count})' for answer, count in wrong) or '-'


def _machine_line(machine: Mapping[str, Any]) -> str:
    cpu = machine.get('cpu_model') or machine.get('processor') or 'unknown CPU'
    return (f"{cpu}, {machine.get('cpus', '?')} cores; {machine.get('platform', '?')}, "
            f"Python {machine.get('python', '?')}, OpenCV {machine.get('opencv', '?')}")


def _host(described: str, machine: Mapping[str, Any], run: Mapping[str, Any]) -> str:
    """'Host: ...; load average ... at the start, ... at the end.' (``machine`` holds the
    load at the start, ``run`` the load at the end)."""
    def text(load: Any) -> str:
        return ', '.join(f'{value:.1f}' for value in load) if load else '?'
    return (f"Host: {described}; load average (1, 5, 15 min) "
            f"{text(machine.get('load_average_at_start'))} at the start, "
            f"{text(run.get('load_average_at_end'))} at the end.")


def _duration(seconds: float) -> str:
    """'51 s', '40 min' or '1.5 h'."""
    if seconds < 120:
        return f'{seconds:.0f} s'
    return f'{seconds / 60:.0f} min' if seconds < 5400 else f'{seconds / 3600:.1f} h'


def _right_rate(design: Section) -> float | None:
    """The share of a design's signs read right, or None when it has none."""
    return design['right'] / design['signs'] if design['signs'] else None


def _error_count(errors: Section) -> int:
    """A soak's errors: logged error lines, tracebacks, ERROR statuses in /diagnostics."""
    return int(errors['log_error_lines'] + errors['log_tracebacks']
               + errors['diagnostics_error_statuses'])


def _soak_command(soak: Section) -> str:
    command = (f"python bench/bench_soak.py --minutes {soak['minutes_requested']:g} "
               f"--width {soak['width']} --height {soak['height']}")
    if soak.get('publish_hz_target', 30.0) != 30.0:
        command += f" --rate {soak['publish_hz_target']:g}"
    if not str(soak.get('drive', {}).get('bag', 'synthetic')).startswith('synthetic'):
        command += f" --bag {soak['drive']['bag']}"
    return command + ' --json'


def provenance_lines(run: LongRun, figures: Section) -> list[str]:
    """The command that made ``figures``, how long it took, the file's ``'note'`` (for
    figures merged from several runs: which figure comes from which), and the host."""
    recorded = figures.get('recorded_run')
    source = f"; figures from `{figures['source_file']}`" if figures.get('source_file') else ''
    if isinstance(recorded, Mapping):
        machine = recorded.get('machine') or {}
        took = f", {_duration(recorded['elapsed_s'])}" if 'elapsed_s' in recorded else ''
        command = ' '.join(recorded['command'])
        what_make_runs = f' (`{run.make_target}`)' if command == run.command else ''
        note = [str(figures['note'])] if figures.get('note') else []
        return [f'Command: `{command}`{what_make_runs}{took}'
                f"{source}.", *note,
                _host(_machine_line(machine), machine, recorded)]
    if run.key == 'soak' and 'host' in figures:
        machine = figures.get('machine') or {}
        command = _soak_command(figures)
        what_make_runs = f' (`{run.make_target}`)' if command == run.command else ''
        return [f'Command: `{command}`{what_make_runs}, '
                f"{_duration(figures['seconds'])}{source}.",
                _host(str(figures['host']), machine, figures)]
    return [f'Command: not recorded in the file (`{run.make_target}` records it; it runs '
            f'`{run.command}`){source}.', 'Host: not recorded.']


# --------------------------------------------------------------------- 5 folds by track
def _shipped_variant(folds: Section) -> Section:
    variants: Mapping[str, Any] = folds['variants']
    return variants[SHIPPED_VARIANT] if SHIPPED_VARIANT in variants \
        else variants[list(variants)[-1]]


def fold_lines(folds: Section) -> list[str]:
    """Per class: crops, read right, read as another limit (against the 0.5 % budget),
    withheld, the wrong limits read; then the targets (accuracy, look-alikes, scenes)."""
    shipped = _shipped_variant(folds)
    per_class: Mapping[str, Any] = shipped['per_class']
    lines = [f"{folds['folds']} folds split by track (a physical sign is never on both "
             f"sides): each crop of {', '.join(f'`{f}`' for f in folds.get('data_folders', []))}"
             f" read by the bank of the fold that never saw its track, trained as the "
             f"shipped bank is. {shipped['crops']} crops of limits and ends, "
             f"{shipped['lookalikes']} look-alikes. Read right: a limit as its value, an end "
             f"as no limit; read as another limit: a limit answer that is not the truth "
             f"(budget: at most {percent(CLASS_ANOTHER_LIMIT_BUDGET, 1)} of a class); "
             f"withheld: any answer that is no limit.", '']
    rows = []
    for name in sorted(per_class, key=_value_order):
        row = per_class[name]
        wrong = row['wrong_limit_rate']
        rows.append([name, str(row['crops']), number(row['accuracy'], 3),
                     f"{percent(wrong)} ({_count(wrong, row['crops'])})",
                     percent(max(0.0, 1.0 - row['accuracy'] - wrong), 1),
                     _wrong_limits(name, row.get('answers', {})),
                     _met(wrong <= CLASS_ANOTHER_LIMIT_BUDGET)])
    rows.append(['all', str(shipped['crops']), number(shipped['accuracy'], 3),
                 f"{percent(shipped['wrong_limit_rate'])} "
                 f"({_count(shipped['wrong_limit_rate'], shipped['crops'])})",
                 percent(max(0.0, 1.0 - shipped['accuracy'] - shipped['wrong_limit_rate']), 1),
                 '', ''])
    lines += table(['class', 'crops', 'read right', 'read as another limit', 'withheld',
                    'read as', f'within {percent(CLASS_ANOTHER_LIMIT_BUDGET, 1)}'], rows)
    worst = max(per_class, key=lambda name: per_class[name]['wrong_limit_rate'],
                default=None)
    variant = SHIPPED_VARIANT if SHIPPED_VARIANT in folds['variants'] \
        else list(folds['variants'])[-1]
    mean = folds.get('accuracy_mean', {}).get(variant)
    spread = folds.get('accuracy_std', {}).get(variant)
    lookalike_rate = shipped.get('lookalikes_read_as_limit_rate')
    targets = [
        [f'accuracy, mean of the folds >= {FOLD_ACCURACY_TARGET}',
         f'{number(mean, 3)} ± {number(spread, 3)}',
         _met(mean is not None and mean >= FOLD_ACCURACY_TARGET)]]
    if worst is not None:
        worst_rate = per_class[worst]['wrong_limit_rate']
        targets.append([f'no class read as another limit over '
                        f'{percent(CLASS_ANOTHER_LIMIT_BUDGET, 1)}',
                        f'worst: {worst}, {percent(worst_rate)}',
                        _met(worst_rate <= CLASS_ANOTHER_LIMIT_BUDGET)])
    if lookalike_rate is not None:
        lookalikes = shipped['lookalikes']
        targets.append([f'look-alikes read as a limit <= {percent(LOOKALIKE_AS_LIMIT_TARGET, 1)}',
                        f'{percent(lookalike_rate, 3)} ({_count(lookalike_rate, lookalikes)} '
                        f'of {lookalikes})',
                        _met(lookalike_rate <= LOOKALIKE_AS_LIMIT_TARGET)])
    scenes = folds.get('scenes')
    if isinstance(scenes, Mapping):
        targets += [
            [f"scenes, {scenes['folds']} folds by scene: limit signs recognized >= "
             f"{SCENE_RECALL_TARGET}",
             f"{number(scenes['recognition_recall'], 3)} ({scenes['recognized']} of "
             f"{scenes['signs']})", _met(scenes['recognition_recall'] >= SCENE_RECALL_TARGET)],
            [f'scenes: false limits per frame <= {SCENE_FALSE_LIMITS_PER_FRAME_TARGET}',
             f"{number(scenes['false_limits_per_frame'], 3)} ({scenes['false_limits']} in "
             f"{scenes['frames']} frames)",
             _met(scenes['false_limits_per_frame'] <= SCENE_FALSE_LIMITS_PER_FRAME_TARGET)]]
        targets += _approach_targets(scenes.get('approach'))
    lines += ['', '### Targets', ''] + table(['target', 'figure', 'met'], targets)
    others = [f"signs under 20 px wide: {number(shipped.get('accuracy_under_20px'), 3)} read "
              f"right ({shipped.get('crops_under_20px', 0)} crops)"]
    rendered = folds['variants'].get('rendered')
    if rendered is not None and variant != 'rendered':
        others.append(f"renderings only (no trained bank): {number(rendered['accuracy'], 3)} "
                      f"read right, {percent(rendered['wrong_limit_rate'])} read as another "
                      f"limit")
    boxes = scenes.get('boxes') if isinstance(scenes, Mapping) else None
    if isinstance(boxes, Mapping):
        others += [f"gtsdb-dev boxes read as crops by the scene folds' banks, {cut}: "
                   f"{number(boxes[cut]['accuracy'], 3)} read right "
                   f"({boxes[cut]['right']} of {boxes[cut]['limit_signs']}), "
                   f"{boxes[cut]['wrong_limits']} another limit, "
                   f"{boxes[cut]['lookalikes_read_as_limit']} of {boxes[cut]['lookalikes']} "
                   f"look-alikes read as a limit" for cut in ('tight', 'padded')]
    if folds.get('unreadable'):
        others.append(f"{len(folds['unreadable'])} unreadable files skipped")
    return lines + ['', 'Also: ' + '; '.join(others) + '.']


# --------------------------------------------------------------------- leave one value out
def _holdout_verdict(held: Section) -> str:
    misses = []
    if held['accuracy'] < HOLDOUT_RIGHT_TARGET:
        misses.append(f"right {number(held['accuracy'], 2)} < {HOLDOUT_RIGHT_TARGET}")
    if held['wrong_limit_rate'] > HOLDOUT_ANOTHER_LIMIT_TARGET:
        misses.append(f"another limit {percent(held['wrong_limit_rate'], 1)} > "
                      f"{percent(HOLDOUT_ANOTHER_LIMIT_TARGET, 0)}")
    return '**no**: ' + '; '.join(misses) if misses else 'yes'


def holdout_lines(holdout: Section) -> list[str]:
    """Per held-out value: right, another limit, withheld, what it was read as, the
    target; the others of its fold; then the mean against its target."""
    values: Mapping[str, Any] = holdout['values']
    lines = ['For each value V with real crops, a bank trained without any real crop of V '
             '(V known only from renderings and composites of other values\' digits, as '
             'values without real crops such as 130 are) reads every real crop of V, and '
             'the crops of one track fold of the other values (left out of its training '
             f"too). Data: {', '.join(f'`{f}`' for f in holdout.get('data_folders', []))}. "
             f'Targets: each value at least {HOLDOUT_RIGHT_TARGET} read right and at most '
             f'{percent(HOLDOUT_ANOTHER_LIMIT_TARGET, 0)} read as another limit; the mean '
             f'at least {HOLDOUT_MEAN_RIGHT_TARGET}.', '']
    rows = []
    for value in sorted(values, key=_value_order):
        held, others = values[value]['held_out'], values[value]['others']
        rows.append([value, str(held['crops']), number(held['accuracy'], 3),
                     f"{percent(held['wrong_limit_rate'])} ({held['wrong_limit']})",
                     f"{percent(held['withheld_rate'], 1)} ({held['withheld']})",
                     _wrong_limits(value, held.get('answers', {})), _holdout_verdict(held),
                     f"{number(others['accuracy'], 3)}, {percent(others['wrong_limit_rate'])}"])
    mean = holdout.get('mean_accuracy')
    rows.append(['mean', '', number(mean, 3), '', '', '',
                 f'{_met(mean is not None and mean >= HOLDOUT_MEAN_RIGHT_TARGET)} '
                 f'(>= {HOLDOUT_MEAN_RIGHT_TARGET})', ''])
    lines += table(['value', 'crops', 'read right', 'read as another limit', 'withheld',
                    'read as', f'>= {HOLDOUT_RIGHT_TARGET} right, <= '
                    f'{percent(HOLDOUT_ANOTHER_LIMIT_TARGET, 0)} another limit',
                    'other values of its fold: right, another limit'], rows)
    return lines


# ----------------------------------------------------------------------- rendered designs
def _design_value(kind: str) -> str | None:
    """The value a design bench's kind shows ('end_of_limit_80' -> '80'); None for the
    end of all restrictions."""
    value = kind.removeprefix('end_of_limit_')
    return value if value.isdigit() else None


def design_lines(designs: Section) -> list[str]:
    """Per design: right, wrong, withheld against the target; then right of each value on
    each design; then the wrong answers."""
    per_design: Mapping[str, Any] = designs['designs']
    low, high = designs.get('diameter_px', ['?', '?'])
    lines = [f"Every value drawn on each design, {designs.get('per_value', '?')} crops of "
             f"each value on each design (the end of all restrictions 15 times as many), {low} to "
             f"{high} px across, each a camera's crop (glow and over-exposure of LED signs, "
             f"blur, noise, JPEG), read by the {designs.get('bank_file', 'shipped')} bank; "
             f"seed {designs.get('seed', '?')}. Synthetic: ../shared/data holds no LED or "
             f"yellow-faced signs. Right: a limit read as its value, an end sign as an end; "
             f"wrong: any other limit. Target: at least {DESIGN_RIGHT_TARGET} right and 0 "
             f"wrong for each design; 0 wrong for "
             f"{', '.join(DESIGN_LABELS.get(name, name) for name in sorted(WITHHELD_DESIGNS))} "
             f"(rows exposed between the lamps' pulses by a rolling shutter: withheld, or "
             f"read right).", '']
    rows = []
    for name, row in per_design.items():
        rate = _right_rate(row)
        rows.append([DESIGN_LABELS.get(name, name), str(row['signs']), number(rate, 3),
                     str(row['wrong']), str(row['withheld']),
                     _met(row['wrong'] == 0 and (name in WITHHELD_DESIGNS or (
                         rate is not None and rate >= DESIGN_RIGHT_TARGET)))])
    lines += table(['design', 'signs', 'read right', 'wrong', 'withheld',
                    f'>= {DESIGN_RIGHT_TARGET} right, 0 wrong'], rows)
    columns = [name for name, row in per_design.items()
               if any(_design_value(kind) for kind in row['per_value'])]
    values = sorted({value for name in columns for kind in per_design[name]['per_value']
                     if (value := _design_value(kind))}, key=int)
    if columns:
        cells: list[list[str]] = []
        for value in values:
            cells.append([value])
            for name in columns:
                counts = per_design[name]['per_value'].get(
                    value if name != 'end_of_limit' else f'end_of_limit_{value}')
                if counts is None:
                    cells[-1].append('-')
                    continue
                signs = sum(counts.values())
                wrong = counts.get('wrong', 0)
                cells[-1].append(f"{counts.get('right', 0)}/{signs}"
                                 + (f', **{wrong} wrong**' if wrong else ''))
        lines += ['', '### Read right per value', '']
        lines += table(['value'] + [DESIGN_LABELS.get(name, name) for name in columns], cells)
    wrong_answers = [f"{DESIGN_LABELS.get(name, name)}: {text} x{count}"
                     for name, row in per_design.items()
                     for text, count in row.get('wrong_answers', {}).items()]
    if wrong_answers:
        lines += ['', 'Wrong answers: ' + '; '.join(wrong_answers) + '.']
    return lines


# ----------------------------------------------------------------------------------- soak
def soak_lines(soak: Section) -> list[str]:
    """Memory, every frame's fate, errors, loops: figures against the soak's targets."""
    rss, frames, errors = soak['rss_mib'], soak['frames'], soak['errors']
    node = soak.get('node', {})
    growth_target = soak.get('targets', {}).get('rss_growth_percent',
                                                SOAK_RSS_GROWTH_TARGET_PERCENT)
    growth = rss.get('growth_percent')
    drive = soak.get('drive', {})
    latency = soak.get('latency_ms', {})
    lines = [f"The installed node fed {soak['width']}x{soak['height']} "
             f"{drive.get('message', 'images')} at {soak['publish_hz_target']:g} Hz "
             f"(achieved {number(soak.get('publish_hz_achieved'), 2)} Hz) for "
             f"{soak['seconds'] / 60:.1f} min by a looping drive "
             f"({drive.get('frames_per_loop', '?')} frames, {drive.get('bag', '?')}): the "
             f"stamps jump back at each loop; backend {soak.get('backend') or '?'}, GL "
             f"renderer {soak.get('renderer') or '?'}.", '']
    rows = [
        [f"RSS after {number(rss.get('reference_s'), 0)} s / at the end / peak, MiB",
         f"{number(rss.get('at_reference'))} / {number(rss.get('end'))} / "
         f"{number(rss.get('max'))}", '', ''],
        ['RSS growth after the first minute', f'{number(growth, 2)} %',
         f'<= {growth_target:g} %',
         _met(soak.get('meets_rss_target', growth is not None and growth <= growth_target))],
        ['frames published / answered / dropped by the node / lost in transport',
         f"{frames['published']} / {frames['answered']} / {frames['node_dropped']} / "
         f"{frames['lost_in_transport']}", '', ''],
        ['frames unaccounted (neither answered nor counted as dropped or lost)',
         str(frames['unaccounted']), '0',
         _met(soak.get('meets_accounting_target', frames['unaccounted'] == 0))],
        ['errors: logged lines / tracebacks / ERROR statuses in /diagnostics',
         f"{errors['log_error_lines']} / {errors['log_tracebacks']} / "
         f"{errors['diagnostics_error_statuses']}", '0',
         _met(soak.get('meets_error_target', _error_count(errors) == 0))],
        ['loops / stamp jumps the node logged', f"{soak['loops']} / "
         f"{soak.get('stamp_jumps_logged_by_node', '?')}", '', ''],
        ['the same node process at the end, its counters never reset',
         'yes' if node.get('same_process_at_end') and not node.get('counter_resets')
         else 'no', 'yes', _met(bool(soak.get('meets_restart_target',
                                             node.get('same_process_at_end'))))],
        ['latency p50 / p95 / max, ms', f"{number(latency.get('p50'))} / "
         f"{number(latency.get('p95'))} / {number(latency.get('max'))}", '', ''],
        ['node CPU, % of one core', number(soak.get('node_cpu_percent')), '', '']]
    return lines + table(['figure', 'value', 'target', 'met'], rows, right_aligned_from=1)


# ------------------------------------------------------------------------------ sections
RENDERERS: dict[str, Callable[[Section], list[str]]] = {
    'recognition_folds': fold_lines, 'value_holdout': holdout_lines,
    'sign_designs': design_lines, 'soak': soak_lines}


def heading(run: LongRun, figures: Section) -> str:
    """The section's heading: its title, with the folds the run had where not 5."""
    folds = figures.get('folds')
    if run.key == 'recognition_folds' and isinstance(folds, int):
        return run.title.replace('5 folds', f'{folds} folds')
    return run.title


def long_run_lines(results: Mapping[str, Any]) -> list[str]:
    """A section for each long run in ``results`` (none when none is), each with its
    command and host; a file that could not be read, or does not hold the figures its
    section needs, says so in its section."""
    lines: list[str] = []
    for run in LONG_RUNS:
        figures = results.get(run.key)
        if not isinstance(figures, Mapping):
            continue
        lines += ['', f'## {heading(run, figures)}', '']
        if 'error' in figures:
            lines.append(f"Failed: {figures['error']}.")
            continue
        try:
            body = RENDERERS[run.key](figures)
            lines += provenance_lines(run, figures) + [''] + body
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            lines.append(f"The file {figures.get('source_file', '')} does not hold the "
                         f"figures of this section ({type(err).__name__}: {err}).")
    return lines


def _approach_targets(approach: Any) -> list[list[str]]:
    """The target rows of the scene folds' approach sequences (none without them): the
    approached sign of each sequence recognized (all limit signs in view beside it)."""
    if not isinstance(approach, Mapping) or approach.get('approached_recall') is None:
        return []
    return [[f"approach sequences, {approach['folds']} folds by scene (each read by a bank "
             f"that never saw its scene): approached signs recognized >= "
             f"{APPROACH_RECOGNIZED_TARGET}",
             f"{number(approach['approached_recall'], 3)} ({approach['approached_recognized']}"
             f" of {approach['approached_signs']}); all limit signs in view "
             f"{number(approach['recall'], 3)} ({approach['recognized']} of "
             f"{approach['signs']})",
             _met(approach['approached_recall'] >= APPROACH_RECOGNIZED_TARGET)],
            ['approach sequences: wrong limits 0', str(approach['wrong_limits']),
             _met(approach['wrong_limits'] == 0)]]


def _summary_row(run: LongRun, figures: Section) -> list[str]:
    if run.key == 'recognition_folds':
        shipped = _shipped_variant(figures)
        per_class = shipped['per_class']
        worst = max(per_class, key=lambda name: per_class[name]['wrong_limit_rate'])
        scenes = figures.get('scenes')
        scene_text = (f"; scenes {number(scenes['recognition_recall'], 3)} recognized, "
                      f"{number(scenes['false_limits_per_frame'], 3)} false limits per frame"
                      if isinstance(scenes, Mapping) else '')
        approach = scenes.get('approach') if isinstance(scenes, Mapping) else None
        if isinstance(approach, Mapping) and approach.get('approached_recall') is not None:
            scene_text += (f"; approach sequences {number(approach['approached_recall'], 3)}"
                           f" recognized, {approach['wrong_limits']} wrong limits")
        return [f"recognition, {figures['folds']} folds by track: accuracy; read as another "
                f"limit (worst class)",
                f"{number(figures['accuracy_mean'].get(SHIPPED_VARIANT, shipped['accuracy']), 3)};"
                f" {percent(shipped['wrong_limit_rate'])} ({worst}: "
                f"{percent(per_class[worst]['wrong_limit_rate'])}){scene_text}", '-']
    if run.key == 'value_holdout':
        values = figures['values']
        worst = min(values, key=lambda value: values[value]['held_out']['accuracy'])
        held = values[worst]['held_out']
        return ['leave one value out: mean read right; the worst value',
                f"{number(figures['mean_accuracy'], 3)}; {worst}: {number(held['accuracy'], 3)}"
                f" right, {percent(held['wrong_limit_rate'])} another limit", '-']
    if run.key == 'sign_designs':
        designs = figures['designs']
        worst = min((name for name in designs if name not in WITHHELD_DESIGNS),
                    key=lambda name: _right_rate(designs[name]) or 0.0)
        wrong = sum(row['wrong'] for row in designs.values())
        return ['rendered designs: read right (the worst design); wrong in all',
                f'{DESIGN_LABELS.get(worst, worst)} {number(_right_rate(designs[worst]), 3)}; '
                f'{wrong} wrong', '-']
    return [f"soak, {figures['seconds'] / 60:.0f} min at {figures['publish_hz_target']:g} Hz: "
            f"RSS growth; frames unaccounted; errors",
            f"{number(figures['rss_mib'].get('growth_percent'), 2)} %; "
            f"{figures['frames']['unaccounted']}; {_error_count(figures['errors'])}", '-']


def summary_rows(results: Mapping[str, Any]) -> list[list[str]]:
    """One row of the summary table ([benchmark, ours, peers]) per long run in ``results``."""
    rows: list[list[str]] = []
    for run in LONG_RUNS:
        figures = results.get(run.key)
        if not isinstance(figures, Mapping):
            continue
        if 'error' in figures:
            rows.append([run.title, f"failed: {figures['error']}", ''])
            continue
        try:
            rows.append(_summary_row(run, figures))
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            rows.append([run.title, f'unreadable figures ({type(err).__name__}: {err})', ''])
    return rows

