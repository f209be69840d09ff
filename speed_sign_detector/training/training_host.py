"""What a bank was trained on: the host, and the numeric libraries that did its arithmetic.

Training is reproducible on one machine, but not from one machine to another: the
OpenBLAS that numpy's wheels bundle picks its kernels for the CPU it finds (``Haswell``,
``SkylakeX``, ``Zen``; ``OPENBLAS_CORETYPE`` overrides it), and kernels that sum in
another order round differently. On a 2-core AMD EPYC host the shipped recipe (``make
bank``) built networks with other weights under the ``SkylakeX`` kernel than under
``Haswell``, from the same located crops, and the shipped bank, built on another host,
located 7,602 of the 8,400 crops where that host locates 7,606 (with today's code and
with the code that built the shipped bank alike). Whether a rebuilt bank
should equal another one depends on where each was built: :func:`training_host` is
recorded in every bank's provenance (``TrainedBank.provenance['host']``).

Training-side only: the node never imports this module.
"""
from __future__ import annotations

import contextlib
import os
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

__all__ = ['BLAS_KERNEL_VARIABLES', 'blas_libraries', 'cpu_model', 'describe_blas',
           'describe_host', 'training_host']

#: Environment variables that choose the BLAS's kernels or threads; recorded where set.
BLAS_KERNEL_VARIABLES: tuple[str, ...] = ('OPENBLAS_CORETYPE', 'OPENBLAS_NUM_THREADS',
                                          'MKL_NUM_THREADS', 'MKL_CBWR', 'OMP_NUM_THREADS')


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else what :mod:`platform`
    says."""
    with contextlib.suppress(OSError):
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.lower().startswith(('model name', 'hardware')) and ':' in line:
                return line.split(':', 1)[1].strip()
    return platform.processor() or platform.machine()


def blas_libraries() -> list[dict[str, Any]]:
    """The BLAS libraries loaded in this process (threadpoolctl), each as its API
    (``'openblas'``, ``'mkl'``), library name (numpy's and OpenCV's wheels each bundle
    an OpenBLAS), version, kernel architecture where the library names one and thread
    count; empty where threadpoolctl is not installed."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return []
    return [{key: info.get(key) for key in ('internal_api', 'prefix', 'version',
                                             'architecture', 'num_threads')}
            for info in threadpool_info() if info.get('user_api') == 'blas']


def training_host() -> dict[str, Any]:
    """The host and libraries of this process, for a bank's provenance: CPU model and
    count, machine, Python, numpy and OpenCV versions, the BLAS libraries
    (:func:`blas_libraries`) and the :data:`BLAS_KERNEL_VARIABLES` that are set. Nothing
    that changes from run to run on one host (no load, no time), so that a bank rebuilt on
    the same host is the same file."""
    return {'cpu_model': cpu_model(), 'cpus': os.cpu_count(), 'machine': platform.machine(),
            'python': platform.python_version(), 'numpy': np.__version__,
            'opencv': cv2.__version__, 'blas': blas_libraries(),
            'environment': {name: os.environ[name] for name in BLAS_KERNEL_VARIABLES
                            if name in os.environ}}


def describe_blas(libraries: Sequence[Mapping[str, Any]]) -> str:
    """The BLAS libraries of a :func:`blas_libraries` list in words
    (``'libscipy_openblas 0.3.31 SkylakeX kernel, libopenblas 0.3.15 Zen kernel'``), or
    ``'BLAS unknown'`` for none."""
    return ', '.join(f'{library.get("prefix") or library.get("internal_api")} '
                     f'{library.get("version")}'
                     + (f' {library["architecture"]} kernel' if library.get('architecture')
                        else '') for library in libraries) or 'BLAS unknown'


def describe_host(host: Mapping[str, Any]) -> str:
    """One line for a person: the CPU and the BLAS kernels of a :func:`training_host`
    record (``'AMD EPYC (2 CPUs), numpy 2.4.6, libscipy_openblas 0.3.31 SkylakeX kernel'``)."""
    chosen = ''.join(f', {name}={value}' for name, value
                     in sorted(host.get('environment', {}).items()))
    cpus = f' ({host["cpus"]} CPUs)' if host.get('cpus') else ''
    numpy_version = f'numpy {host["numpy"]}, ' if host.get('numpy') else ''
    return (f'{host.get("cpu_model") or "unknown CPU"}{cpus}, {numpy_version}'
            f'{describe_blas(host.get("blas", ()))}{chosen}')
