"""One BLAS thread for the package's programs that run the pipeline.

The pipeline runs its own threads (the node overlaps detection with recognition) and its
matrix products are small: the second opinion's networks multiply a few signs' 2,020
features by 256-unit layers. A multi-threaded BLAS (the OpenBLAS that numpy's wheels
bundle) spreads each such product over every core and then keeps its threads spinning
after the call (OpenBLAS's thread timeout), which takes a core from the detector.
Measured on 2 cores on 2026-11-24 with the network bank: the classifier's CPU time per
candidate 5.1 ms with BLAS threads against 2.8 ms with one (the same wall time), and the
node at 30 Hz 20.5 fps against 29-30 fps.

Two ways, both leaving a user's own choice alone (any of :data:`BLAS_THREAD_VARIABLES`
and :data:`FALLBACK_THREAD_VARIABLES` set in the environment by someone else):

* :func:`limit_blas_threads` limits the BLAS libraries already loaded at run time, with
  threadpoolctl: :class:`~speed_sign_detector.pipeline.Pipeline` calls it when it
  builds a classifier in its own process, so a program that embeds the pipeline needs
  no environment variable. The limit holds for the whole process (a BLAS has one
  thread count) and stays after the pipeline is closed.
* :func:`use_one_blas_thread` sets the variables before numpy loads, so that the BLAS
  never starts its extra threads: the node's executable and ``speed_sign_eval`` call it
  first, and the classifier's worker processes inherit it. ``speed_sign_train`` keeps
  every thread: training the networks is large matrix work.

This module imports nothing but the standard library (threadpoolctl only when
:func:`limit_blas_threads` runs).
"""
from __future__ import annotations

import logging
import os
from typing import Literal

__all__ = ['BLAS_THREAD_VARIABLES', 'FALLBACK_THREAD_VARIABLES', 'BlasLimit',
           'limit_blas_threads', 'use_one_blas_thread']

LOGGER = logging.getLogger(__name__)

#: The variables the common BLAS builds read their thread count from.
BLAS_THREAD_VARIABLES: tuple[str, ...] = ('OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')
#: Variables a BLAS also takes its thread count from when its own is not set (OpenBLAS:
#: ``GOTO_NUM_THREADS``, then ``OMP_NUM_THREADS``; MKL: ``OMP_NUM_THREADS``).
FALLBACK_THREAD_VARIABLES: tuple[str, ...] = ('GOTO_NUM_THREADS', 'OMP_NUM_THREADS')
_EVERY_THREAD_VARIABLE = BLAS_THREAD_VARIABLES + FALLBACK_THREAD_VARIABLES
#: The variables :func:`use_one_blas_thread` set (not a user's choice).
_SET_HERE: dict[str, str] = {}


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
    _SET_HERE.update(changed)
    return changed


def users_thread_choice() -> dict[str, str]:
    """The thread variables set in the environment by someone other than
    :func:`use_one_blas_thread` (the user's choice), with their values."""
    return {name: os.environ[name] for name in _EVERY_THREAD_VARIABLE
            if name in os.environ and _SET_HERE.get(name) != os.environ[name]}


#: What :func:`limit_blas_threads` did: ``'limited'`` (some pools had more threads),
#: ``'already'`` (none had), ``'user'`` (the user's variables stand),
#: ``'unavailable'`` (threadpoolctl is not installed).
BlasLimit = Literal['limited', 'already', 'user', 'unavailable']


def limit_blas_threads(threads: int = 1) -> BlasLimit:
    """Limit every loaded BLAS library of this process to ``threads`` threads, at run
    time (threadpoolctl), unless the user set a thread variable (see the module).

    Load numpy first: only libraries already loaded are seen.

    Args:
        threads: the most threads a BLAS may use, at least 1.

    Returns:
        What was done, one of the :data:`BlasLimit` words; logged at info level (a
        warning naming the fix when threadpoolctl is missing).

    Raises:
        ValueError: for ``threads`` below 1.
    """
    if threads < 1:
        raise ValueError(f'threads must be at least 1, got {threads}')
    chosen = users_thread_choice()
    if chosen:
        LOGGER.info('BLAS threads left as set: %s',
                    ', '.join(f'{name}={value}' for name, value in chosen.items()))
        return 'user'
    try:
        from threadpoolctl import threadpool_info, threadpool_limits
    except ImportError:
        LOGGER.warning('threadpoolctl is not installed, so numpy\'s BLAS may run one thread '
                       'per core and take cores from the detector; pip install '
                       '"threadpoolctl>=3" (or set OPENBLAS_NUM_THREADS=1)')
        return 'unavailable'
    wide = [pool for pool in threadpool_info()
            if pool['user_api'] == 'blas' and pool['num_threads'] > threads]
    if not wide:
        return 'already'
    threadpool_limits(limits=threads, user_api='blas')
    LOGGER.info('BLAS limited to %d thread(s): %s', threads,
                ', '.join(f'{pool["internal_api"]} had {pool["num_threads"]}'
                          for pool in wide))
    return 'limited'
