"""The host a benchmark ran on, as results.json records it under ``'machine'``.

Imports only the standard library, OpenCV and the package's
:mod:`~speed_sign_detector.training.training_host` (numpy and OpenCV): ``record_json.py``
describes the host of the commands it runs without loading the pipeline (``run_all``
limits the BLAS threads as it loads, which a command it ran would inherit).
"""
from __future__ import annotations

import os
import platform

import cv2

from speed_sign_detector.training.training_host import blas_libraries, cpu_model

__all__ = ['cpu_model', 'load_average', 'machine_record']


def load_average() -> list[float] | None:
    """The load average over 1, 5 and 15 minutes, or None where the OS has none."""
    return list(os.getloadavg()) if hasattr(os, 'getloadavg') else None


def machine_record() -> dict[str, object]:
    """CPU model and count, platform, Python and OpenCV versions, the BLAS libraries
    loaded and their kernels (:func:`.blas_libraries`: another kernel rounds training
    otherwise), load average now."""
    return {'cpus': os.cpu_count(), 'cpu_model': cpu_model(), 'platform': platform.platform(),
            'processor': platform.processor() or platform.machine(),
            'python': platform.python_version(), 'opencv': cv2.__version__,
            'blas': blas_libraries(), 'load_average_at_start': load_average()}
