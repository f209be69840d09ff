"""Child processes of the test process, read from /proc (Linux)."""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

#: What the command line of a classifier worker holds (``python -m ...``).
CLASSIFIER_WORKER = b'speed_sign_detector.recognition.classifier_process'


def child_processes(command_part: bytes) -> list[int]:
    """Process ids of this process's children whose command line holds
    ``command_part``."""
    found = []
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            command = (entry / 'cmdline').read_bytes()
            parent = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue  # gone meanwhile, or not readable
        if parent == os.getpid() and command_part in command:
            found.append(int(entry.name))
    return found


def process_state(pid: int) -> str | None:
    """The state letter of process ``pid`` from /proc (``R``, ``S``, ``T`` stopped, ``Z``
    zombie...), None when there is no such process."""
    try:
        return (Path('/proc') / str(pid) / 'stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def signal_mask(pid: int, field: str) -> int:
    """A signal set of process ``pid`` from /proc/PID/status (``SigIgn``, ``SigPnd``,
    ``ShdPnd``...): bit ``n - 1`` is signal ``n``."""
    for line in (Path('/proc') / str(pid) / 'status').read_text().splitlines():
        name, _, value = line.partition(':')
        if name == field:
            return int(value.strip(), 16)
    raise KeyError(f'no {field} in /proc/{pid}/status')


def wait_until(condition: Callable[[], object], what: str, timeout_s: float = 30.0) -> None:
    """Poll ``condition`` until it is truthy; AssertionError naming ``what`` after
    ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f'timed out after {timeout_s:g} s: {what}'
        time.sleep(0.01)
