"""Running the installed command-line tools in tests, and interrupting them mid-run.

:func:`interrupt_at_fifo` makes "Ctrl-C in the middle of a run" deterministic without
timing: one input file of the run is a named pipe. The tool blocks reading it after it
has finished the items before it; the test then sends SIGINT, waits until the tool says
it was interrupted, and only then writes the file's bytes into the pipe. The tool
finishes that item and must stop there.
"""
from __future__ import annotations

import errno
import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

#: Longest a tool may take to reach the pipe or to finish, seconds (a hang, not a timing).
DEADLINE_S = 180.0


def tool(name: str) -> list[str]:
    """Command line of an installed tool (the venv's entry point, else one on PATH)."""
    script = Path(sys.executable).with_name(name)
    if script.exists():
        return [str(script)]
    found = shutil.which(name)
    assert found, f'{name} is not installed (pip install -e . makes the entry points)'
    return [found]


def run_tool(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run an installed tool to its end; stdout and stderr captured as text."""
    return subprocess.run([*tool(name), *args], capture_output=True, text=True,
                          timeout=DEADLINE_S, check=False)


def last_json(stdout: str) -> dict[str, Any]:
    """The JSON object on the last line of a tool's stdout."""
    lines = stdout.strip().splitlines()
    assert lines, 'no output on stdout'
    return json.loads(lines[-1])


#: How long to wait for the tool's 'interrupted' message before feeding the pipe, s.
SIGNAL_WAIT_S = 5.0


def _open_writer_when_read(fifo: Path, process: subprocess.Popen[str]) -> int:
    """Open ``fifo`` for writing once the tool has opened it for reading."""
    deadline = time.monotonic() + DEADLINE_S
    while True:
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as err:
            if err.errno != errno.ENXIO:
                raise
        assert process.poll() is None, f'the tool ended before reading {fifo}'
        assert time.monotonic() < deadline, f'the tool never read {fifo}'
        time.sleep(0.05)


def interrupt_at_fifo(command: list[str], fifo: Path, payload: bytes
                      ) -> tuple[int, str, str]:
    """Run ``command``, send SIGINT while it reads the named pipe ``fifo``, then feed it.

    Returns:
        (exit status, stdout, stderr) of the tool.
    """
    os.mkfifo(fifo)
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    stderr_lines: queue.Queue[str | None] = queue.Queue()

    def collect() -> None:
        assert process.stderr is not None
        for line in process.stderr:
            stderr_lines.put(line)
        stderr_lines.put(None)

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()
    seen: list[str] = []
    try:
        writer = _open_writer_when_read(fifo, process)
        process.send_signal(signal.SIGINT)
        # The kernel may hand the signal to any of the tool's threads (OpenCV's, BLAS's);
        # then Python runs the handler only once the main thread's blocking read of the
        # pipe returns. Either way the handler has run before the read returns to the
        # tool's loop, so after a short wait for the message the payload is fed anyway.
        deadline = time.monotonic() + SIGNAL_WAIT_S
        while not any('interrupted' in line for line in seen):
            try:
                line = stderr_lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            assert line is not None, 'the tool ended without saying it was interrupted:\n' + \
                ''.join(seen)
            seen.append(line)
        os.set_blocking(writer, True)
        os.write(writer, payload)
        os.close(writer)
        process.wait(timeout=DEADLINE_S)   # stdout (one JSON line) fits the pipe's buffer
        assert process.stdout is not None
        stdout = process.stdout.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    reader.join(timeout=DEADLINE_S)
    while not stderr_lines.empty():
        line = stderr_lines.get_nowait()
        if line is not None:
            seen.append(line)
    return process.returncode, stdout, ''.join(seen)
