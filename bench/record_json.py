#!/usr/bin/env python3
"""Run a command that prints one JSON object last, and save that object with its run.

``make validate`` runs the long recognition measures through this, so that the JSON files
``make bench`` later renders into bench/RESULTS.md (``long_runs_markdown.py``) say which
command made them, on which host, and how long it took::

    python bench/record_json.py OUT.json -- COMMAND [ARG ...]

COMMAND's stdout is passed through, all but its last non-empty line, which must be one
JSON object (``speed_sign_train validate ... --json``, ``bench_sign_designs.py --json``);
stderr is left alone. OUT.json gets that object with ``'recorded_run'`` added:
``{'command': [...] (the program by its name, not its path), 'machine': host_record's
record (load average at the start), 'load_average_at_end', 'elapsed_s',
'exit_status'}``. Exit status: COMMAND's; 1 when it printed no JSON object (OUT.json is
then not written), 130 when interrupted.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from host_record import load_average, machine_record

__all__ = ['RecordError', 'last_json_object', 'main', 'record_command']


class RecordError(Exception):
    """The command printed no JSON object on its last line."""


def last_json_object(text: str) -> dict[str, Any]:
    """The JSON object on the last non-empty line of ``text``.

    Raises:
        RecordError: no line, or the last line is not a JSON object.
    """
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise RecordError('no output')
    try:
        value = json.loads(lines[-1])
    except json.JSONDecodeError as err:
        raise RecordError(f'the last line is not JSON ({err}): {lines[-1][:120]!r}') from err
    if not isinstance(value, dict):
        raise RecordError(f'the last line is JSON but not an object: {lines[-1][:120]!r}')
    return value


def shown_command(command: list[str]) -> list[str]:
    """``command`` with its program by name (``.venv/bin/python`` -> ``python``)."""
    program = Path(command[0]).name
    if program.startswith('python'):
        program = 'python'
    return [program, *command[1:]]


def record_command(command: list[str], out: Path) -> int:
    """Run ``command``, echo its stdout but the last line, write OUT (see the module
    docstring); returns the command's exit status.

    Raises:
        RecordError: the command printed no JSON object last.
        OSError: the command cannot be started, or ``out`` cannot be written.
    """
    machine = machine_record()
    started = time.perf_counter()
    held = ''   # the latest non-empty line, printed once a later one shows it is not last
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as process:
        assert process.stdout is not None
        for line in process.stdout:
            if not line.strip():
                continue
            if held:
                sys.stdout.write(held)
                sys.stdout.flush()
            held = line
        status = process.wait()
    report = last_json_object(held)
    report['recorded_run'] = {'command': shown_command(command), 'machine': machine,
                              'load_average_at_end': load_average(),
                              'elapsed_s': round(time.perf_counter() - started, 1),
                              'exit_status': status}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, sort_keys=True) + '\n')
    return status


def main(argv: list[str] | None = None) -> int:
    """Parse ``OUT.json -- COMMAND ...`` and run it (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('out', type=Path, help='the JSON file to write')
    parser.add_argument('command', nargs=argparse.REMAINDER,
                        help='-- then the command and its arguments')
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ['--'] else args.command
    if not command:
        parser.error('give the command after --')
    try:
        status = record_command(command, args.out)
    except KeyboardInterrupt:
        return 130
    except (RecordError, OSError) as err:
        print(f'record_json: {" ".join(command)}: {err}', file=sys.stderr)
        return 1
    print(f'wrote {args.out}', file=sys.stderr)
    return status


if __name__ == '__main__':
    sys.exit(main())
