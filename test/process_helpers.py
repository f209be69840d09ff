"""Child processes of the test process, read from /proc (Linux)."""
from __future__ import annotations

import os
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
