"""One BLAS thread for the package's programs that run the pipeline.

The pipeline runs its own threads (the node overlaps detection with recognition) and its
matrix products are small: the second opinion's networks multiply a few signs' 2,020
features by 256-unit layers. A multi-threaded BLAS (the OpenBLAS that numpy's wheels
bundle) spreads each such product over every core and then keeps its threads spinning
after the call (OpenBLAS's thread timeout), which takes a core from the detector.
Measured on 2 cores on 2026-11-24 with the network bank: the classifier's CPU time per
candidate 5.1 ms with BLAS threads against 2.8 ms with one (the same wall time), and the
node at 30 Hz 20.5 fps against 29-30 fps.

A BLAS reads its thread count once, when numpy first loads it, so
:func:`use_one_blas_thread` must run before numpy is imported: the node's executable and
``speed_sign_eval`` call it first. A program that embeds the pipeline sets
``OPENBLAS_NUM_THREADS=1`` itself; :func:`blas_thread_advice` is the warning the pipeline
logs where it finds none of the thread variables set. ``speed_sign_train`` keeps every
thread: training the networks is large matrix work.

This module imports nothing but :mod:`os`.
"""
from __future__ import annotations

import os

__all__ = ['BLAS_THREAD_VARIABLES', 'blas_thread_advice', 'use_one_blas_thread']

#: The variables the common BLAS builds read their thread count from.
BLAS_THREAD_VARIABLES: tuple[str, ...] = ('OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')
#: Variables a BLAS also takes its thread count from when its own is not set (OpenBLAS:
#: ``GOTO_NUM_THREADS``, then ``OMP_NUM_THREADS``; MKL: ``OMP_NUM_THREADS``).
FALLBACK_THREAD_VARIABLES: tuple[str, ...] = ('GOTO_NUM_THREADS', 'OMP_NUM_THREADS')
_EVERY_THREAD_VARIABLE = BLAS_THREAD_VARIABLES + FALLBACK_THREAD_VARIABLES


def use_one_blas_thread() -> dict[str, str]:
    """Set each of :data:`BLAS_THREAD_VARIABLES` to ``'1'`` unless the environment
    already sets it (the user's choice stands).

    Returns:
        The variables and values this call set (empty when all were set already).
    """
    changed: dict[str, str] = {}
    for name in BLAS_THREAD_VARIABLES:
        if name not in os.environ:
            os.environ[name] = '1'
            changed[name] = '1'
    return changed


def blas_thread_advice(cpu_count: int | None = None) -> str | None:
    """A warning for a process that runs the classifier beside the detector with a BLAS
    that likely runs one thread per core (a program that loaded numpy without setting
    the thread variables).

    Args:
        cpu_count: cores of the machine (default :func:`os.cpu_count`).

    Returns:
        None when one core, or when any of :data:`BLAS_THREAD_VARIABLES` and
        :data:`FALLBACK_THREAD_VARIABLES` is set (the user chose); else one line naming
        the cost and the fix.
    """
    cores = os.cpu_count() if cpu_count is None else cpu_count
    if (cores or 1) <= 1 or any(name in os.environ for name in _EVERY_THREAD_VARIABLE):
        return None
    return (f'none of {", ".join(_EVERY_THREAD_VARIABLE)} is '
            f'set, so numpy\'s BLAS likely runs {cores} threads, which keep spinning after '
            f'the classifier\'s small matrix products and take cores from the detector '
            f'(on 2 cores the GL detector took 94-99 ms per 816x480 frame so, 73-74 ms '
            f'with one BLAS thread). Set OPENBLAS_NUM_THREADS=1 in the environment (or in '
            f'os.environ before numpy is first imported; README, "One BLAS thread")')
