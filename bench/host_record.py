"""The host a benchmark ran on, as results.json records it under ``'machine'``.

Imports only the standard library and OpenCV: ``record_json.py`` describes the host of
the commands it runs without loading the pipeline (``run_all`` limits the BLAS threads
as it loads, which a command it ran would inherit).
"""
from __future__ import annotations

import contextlib
import os
import platform
from pathlib import Path

import cv2

__all__ = ['cpu_model', 'load_average', 'machine_record']


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo on Linux), else what ``platform`` says."""
    with contextlib.suppress(OSError):
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.lower().startswith(('model name', 'hardware')) and ':' in line:
                return line.split(':', 1)[1].strip()
    return platform.processor() or platform.machine()


def load_average() -> list[float] | None:
    """The load average over 1, 5 and 15 minutes, or None where the OS has none."""
    return list(os.getloadavg()) if hasattr(os, 'getloadavg') else None


def machine_record() -> dict[str, object]:
    """CPU model and count, platform, Python and OpenCV versions, load average now."""
    return {'cpus': os.cpu_count(), 'cpu_model': cpu_model(), 'platform': platform.platform(),
            'processor': platform.processor() or platform.machine(),
            'python': platform.python_version(), 'opencv': cv2.__version__,
            'load_average_at_start': load_average()}
