#!/usr/bin/env python3
"""``speed_sign_eval bag`` at each camera size: speed on synthetic drives, signs
recognized on approach sequences made of real pixels.

The README's commands, run as a user runs them, for each camera size (640x480, 1280x720,
1920x1080 by default):

drive
    ``speed_sign_synth D --truth D.csv --duration 4 --seed 5 --compressed --width W
    --height H``, then ``speed_sign_eval bag D --truth D.csv --json``: frames per second,
    latency p50 / p95 (ms), the median time of each stage (ms), recall and wrong limits.
    A synthetic drive has exact answers: its recall says that the speed was not bought
    with misses, it is not an accuracy claim.
approach
    ``speed_sign_synth approach GTSDB A --truth A.csv --max-sequences 40 --compressed
    --width W --height H``, then the same ``eval bag``: the limit signs recognized and the
    wrong limits on real pixels resampled to each camera size. The shipped bank learned
    from these scenes, so compare the sizes with each other, not the shares with held-out
    figures (those come from ``make validate``).

Every bag is made first; the evaluations then run one after another, each in its own
process, so that they do not compete with the bag making or each other. The timed loop of
``eval bag`` leaves out its start-up (bank loading, GL context). ``run_all.py`` runs this as
its ``camera_sizes`` stage. Usage::

    python bench/bench_camera_sizes.py [--sizes 640x480,1280x720,1920x1080]
        [--duration 4] [--max-sequences 40] [--gtsdb DIR] [--work DIR] [--json]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench_inputs import DATA_DIR, MissingExecutableError, installed_executable

#: Camera sizes measured by default, (width, height) in pixels.
CAMERA_SIZES: tuple[tuple[int, int], ...] = ((640, 480), (1280, 720), (1920, 1080))
#: Issue 33's targets for ``eval bag`` on the synthetic drives, frames per second by size.
DRIVE_FPS_TARGETS: dict[str, float] = {'640x480': 50.0, '1280x720': 35.0,
                                       '1920x1080': 25.0}
#: The fields of ``eval bag``'s JSON summary kept for each drive and approach bag.
SUMMARY_KEYS = ('frames', 'fps', 'latency_ms_p50', 'latency_ms_p95', 'stage_ms_p50',
                'backend', 'backend_choice', 'classifier', 'signs', 'recognized', 'recall',
                'wrong_limits', 'truncated', 'error')


class CameraSizeBenchError(RuntimeError):
    """A tool of this benchmark failed (the message holds its command and stderr)."""


@dataclass(frozen=True)
class CameraSizeSettings:
    """What ``measure_camera_sizes`` runs.

    Attributes:
        work_dir: folder for the bags and truth files (created where absent; it must not
            hold bags of the same names: ``speed_sign_synth`` refuses to overwrite one).
        sizes: camera sizes, (width, height) in pixels, in report order.
        gtsdb_dir: GTSDB-format scene folder for the approach sequences; None = none made.
        drive_seconds: length of each synthetic drive, seconds (30 frames/s).
        drive_seed: the synthetic drive's seed (the same world at every size).
        approach_sequences: approach sequences per size (0 = no approach bags).
    """

    work_dir: Path
    sizes: tuple[tuple[int, int], ...] = CAMERA_SIZES
    gtsdb_dir: Path | None = DATA_DIR / 'gtsdb-dev'
    drive_seconds: float = 4.0
    drive_seed: int = 5
    approach_sequences: int = 40


def size_name(width: int, height: int) -> str:
    """``'1280x720'``."""
    return f'{width}x{height}'


def run_tool(name: str, arguments: Sequence[str]) -> str:
    """Run installed executable ``name`` with ``arguments``; its stdout.

    Raises:
        CameraSizeBenchError: it is not installed, could not start or exited non-zero
            (the message holds the command and the end of its stderr).
    """
    command = [name, *arguments]
    try:
        completed = subprocess.run([installed_executable(name), *arguments],
                                   capture_output=True, text=True, check=False)
    except (OSError, MissingExecutableError) as err:
        raise CameraSizeBenchError(f'{" ".join(command)}: could not start: {err}') from err
    if completed.returncode != 0:
        tail = completed.stderr.strip()[-800:]
        raise CameraSizeBenchError(f'{" ".join(command)} exited with {completed.returncode}: '
                                   f'{tail}')
    return completed.stdout


@dataclass(frozen=True)
class BagToMake:
    """One bag of the benchmark: the ``speed_sign_synth`` arguments that make it."""

    kind: str                   #: 'drive' or 'approach'
    bag: Path                   #: the bag ``speed_sign_synth`` writes
    truth: Path                 #: its truth CSV
    arguments: tuple[str, ...]  #: ``speed_sign_synth``'s arguments

    def command_line(self, work_dir: Path) -> str:
        """The command as a reader types it (paths relative to the work folder)."""
        return _relative(['speed_sign_synth', *self.arguments], work_dir)


def bags_of_size(settings: CameraSizeSettings, width: int, height: int) -> list[BagToMake]:
    """The synthetic drive of that camera size and, unless
    ``settings.approach_sequences`` is 0, its approach sequences."""
    name = size_name(width, height)
    size = ('--compressed', '--width', str(width), '--height', str(height), '--quiet')
    drive_bag, drive_truth = settings.work_dir / f'drive_{name}', \
        settings.work_dir / f'drive_{name}.csv'
    bags = [BagToMake('drive', drive_bag, drive_truth, (
        str(drive_bag), '--truth', str(drive_truth), '--duration',
        f'{settings.drive_seconds:g}', '--seed', str(settings.drive_seed), *size))]
    if settings.approach_sequences > 0 and settings.gtsdb_dir is not None:
        bag, truth = settings.work_dir / f'approach_{name}', \
            settings.work_dir / f'approach_{name}.csv'
        bags.append(BagToMake('approach', bag, truth, (
            'approach', str(settings.gtsdb_dir), str(bag), '--truth', str(truth),
            '--max-sequences', str(settings.approach_sequences), *size)))
    return bags


def evaluate(bag: Path, truth: Path) -> dict[str, Any]:
    """``speed_sign_eval bag BAG --truth TRUTH --json`` in its own process: the
    :data:`SUMMARY_KEYS` of its summary and its ``command``.

    Raises:
        CameraSizeBenchError: it failed or printed no JSON summary.
    """
    arguments = ['bag', str(bag), '--truth', str(truth), '--json']
    lines = run_tool('speed_sign_eval', arguments).strip().splitlines()
    try:
        summary = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError) as err:
        raise CameraSizeBenchError(f'speed_sign_eval {" ".join(arguments)} printed no JSON '
                                   f'summary') from err
    kept = {key: summary.get(key) for key in SUMMARY_KEYS}
    kept['command'] = _relative(['speed_sign_eval', *arguments], bag.parent)
    return kept


def _relative(command: Sequence[str], work_dir: Path) -> str:
    """``command`` as one line as a reader types it in the project's folder: the work
    folder left out of its paths, the data folder as ``../shared/data``, ``--quiet``
    dropped."""
    return ' '.join(word.replace(f'{work_dir}/', '').replace(str(DATA_DIR), '../shared/data')
                    for word in command if word != '--quiet')


def measure_camera_sizes(settings: CameraSizeSettings) -> dict[str, Any]:
    """Make every size's bags, then evaluate them one after another.

    Returns:
        ``{'sizes': {name: {'width', 'height', 'drive': summary, 'approach': summary or
        {'skipped': reason}}}, 'drive_fps_targets', 'approach_sequences', 'drive_seconds'}``
        where each summary holds :data:`SUMMARY_KEYS` of ``eval bag``'s JSON and the
        command (fps in frames per second, latencies and stage times in ms).

    Raises:
        CameraSizeBenchError: a tool failed.
    """
    settings.work_dir.mkdir(parents=True, exist_ok=True)
    approach_skipped = None
    if settings.approach_sequences <= 0:
        approach_skipped = 'approach_sequences = 0'
    elif settings.gtsdb_dir is None or not (settings.gtsdb_dir / 'gt.txt').is_file():
        approach_skipped = f'no GTSDB-format scene folder at {settings.gtsdb_dir}'
        settings = dataclasses.replace(settings, gtsdb_dir=None)
    bags = {size: bags_of_size(settings, *size) for size in settings.sizes}
    for size_bags in bags.values():
        for bag in size_bags:
            run_tool('speed_sign_synth', bag.arguments)
    sizes: dict[str, Any] = {}
    for (width, height), size_bags in bags.items():
        row: dict[str, Any] = {'width': width, 'height': height, 'drive': None,
                               'approach': {'skipped': approach_skipped}}
        for bag in size_bags:
            row[bag.kind] = evaluate(bag.bag, bag.truth)
            row[bag.kind]['made_by'] = bag.command_line(settings.work_dir)
        name = size_name(width, height)
        sizes[name] = row
        drive, approach = row['drive'], row['approach']
        print(f'{name}: drive {drive["fps"]:.1f} fps, recall {drive["recall"]}, wrong '
              f'{drive["wrong_limits"]}; approach '
              + (f'not run ({approach_skipped})' if 'skipped' in approach else
                 f'{approach["recognized"]} of {approach["signs"]} recognized, wrong '
                 f'{approach["wrong_limits"]}'), file=sys.stderr, flush=True)
    return {'sizes': sizes, 'drive_fps_targets': DRIVE_FPS_TARGETS,
            'drive_seconds': settings.drive_seconds, 'drive_seed': settings.drive_seed,
            'approach_sequences': settings.approach_sequences}


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``'640x480,1280x720'`` -> ((640, 480), (1280, 720)).

    Raises:
        ValueError: a size is not WIDTHxHEIGHT with positive integers.
    """
    sizes = []
    for item in text.split(','):
        try:
            width, height = (int(part) for part in item.lower().split('x'))
        except ValueError as err:
            raise ValueError(f'camera size {item!r} is not WIDTHxHEIGHT') from err
        if width <= 0 or height <= 0:
            raise ValueError(f'camera size {item!r} must be positive')
        sizes.append((width, height))
    return tuple(sizes)


def main(argv: Sequence[str] | None = None) -> int:
    """Measure, print each size's line on stderr and, with ``--json``, the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', default=','.join(size_name(*size) for size in CAMERA_SIZES),
                        help='camera sizes, WIDTHxHEIGHT separated by commas')
    parser.add_argument('--duration', type=float, default=4.0,
                        help='seconds of each synthetic drive (default 4)')
    parser.add_argument('--max-sequences', type=int, default=40,
                        help='approach sequences per size (0 = none; default 40)')
    parser.add_argument('--gtsdb', type=Path, default=DATA_DIR / 'gtsdb-dev',
                        help='GTSDB-format scene folder of the approach sequences')
    parser.add_argument('--work', type=Path,
                        help='folder for the bags (default: a temporary folder, removed)')
    parser.add_argument('--json', action='store_true', help='print the figures as JSON')
    args = parser.parse_args(argv)
    try:
        sizes = parse_sizes(args.sizes)
    except ValueError as err:
        parser.error(str(err))
    if args.duration <= 0:
        parser.error('--duration must be positive')
    with tempfile.TemporaryDirectory(prefix='speed_sign_camera_sizes_') as scratch:
        settings = CameraSizeSettings(work_dir=args.work or Path(scratch), sizes=sizes,
                                      gtsdb_dir=args.gtsdb, drive_seconds=args.duration,
                                      approach_sequences=args.max_sequences)
        try:
            figures = measure_camera_sizes(settings)
        except CameraSizeBenchError as err:
            print(f'bench_camera_sizes: {err}', file=sys.stderr)
            return 1
    if args.json:
        print(json.dumps(figures))
    return 0


if __name__ == '__main__':
    sys.exit(main())
