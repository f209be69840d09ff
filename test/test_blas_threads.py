"""The executables that run the pipeline ask for one BLAS thread before numpy loads, and a
pipeline that classifies in its process limits the loaded BLAS to one thread at run time
(threadpoolctl), unless the user chose a thread count."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from speed_sign_detector.blas_threads import (
    BLAS_THREAD_VARIABLES,
    FALLBACK_THREAD_VARIABLES,
    use_one_blas_thread,
)

EVERY_THREAD_VARIABLE = BLAS_THREAD_VARIABLES + FALLBACK_THREAD_VARIABLES


def test_unset_variables_are_set_and_the_users_choice_stands(monkeypatch) -> None:
    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv('MKL_NUM_THREADS', '4')
    assert use_one_blas_thread() == {'OPENBLAS_NUM_THREADS': '1'}
    assert os.environ['OPENBLAS_NUM_THREADS'] == '1'
    assert os.environ['MKL_NUM_THREADS'] == '4'
    assert use_one_blas_thread() == {}


def _environment_after(code: str, **preset: str) -> dict:
    environment = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    environment.update(preset)
    probe = (f'{code}\nimport json, os, sys\n'
             'print(json.dumps({"numpy_before": NUMPY_BEFORE, '
             '"values": {n: os.environ.get(n) for n in ("OPENBLAS_NUM_THREADS", '
             '"MKL_NUM_THREADS")}}))')
    done = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                          env=environment, timeout=120, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_eval_sets_one_thread_before_numpy_loads() -> None:
    # the variable is in place when the subcommand modules import numpy
    code = ('import builtins, os\n'
            'NUMPY_BEFORE = None\n'
            'real_import = builtins.__import__\n'
            'def spy(name, *args, **kwargs):\n'
            '    global NUMPY_BEFORE\n'
            '    if name == "numpy" and NUMPY_BEFORE is None:\n'
            '        NUMPY_BEFORE = os.environ.get("OPENBLAS_NUM_THREADS")\n'
            '    return real_import(name, *args, **kwargs)\n'
            'builtins.__import__ = spy\n'
            'import speed_sign_detector.tools.eval\n')
    result = _environment_after(code)
    assert result['numpy_before'] == '1'
    assert result['values'] == {'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}
    # a value the user chose stands
    result = _environment_after(code, OPENBLAS_NUM_THREADS='2')
    assert result['numpy_before'] == '2' and result['values']['OPENBLAS_NUM_THREADS'] == '2'


def test_node_entry_point_loads_no_numpy_before_it_sets_one_thread() -> None:
    code = ('import sys\n'
            'import speed_sign_detector.ros.entry_point as entry\n'
            'NUMPY_BEFORE = "loaded" if "numpy" in sys.modules else "not loaded"\n'
            'try:\n'
            '    entry.main(["--help"])\n'
            'except SystemExit:\n'
            '    pass\n')
    result = _environment_after(code)
    assert result['numpy_before'] == 'not loaded'
    assert result['values']['OPENBLAS_NUM_THREADS'] == '1'


#: Run in a fresh interpreter: the BLAS pools (threadpoolctl) after numpy loads, and after
#: a pipeline is built with the config given as JSON in argv[1].
POOLS_PROBE = """
import json, sys
import numpy
from threadpoolctl import threadpool_info

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.pipeline import Pipeline

def blas_threads():
    return [pool['num_threads'] for pool in threadpool_info() if pool['user_api'] == 'blas']

before = blas_threads()
settings = json.loads(sys.argv[1])
with Pipeline(PipelineConfig(backend='numpy', **settings)):
    during = blas_threads()
print(json.dumps({'before': before, 'during': during, 'after': blas_threads()}))
"""


def blas_pools(settings: dict, **preset: str) -> dict[str, list[int]]:
    """The BLAS pools' thread counts of a fresh interpreter before, while and after a
    pipeline with ``settings`` is open, with only the ``preset`` thread variables set."""
    environment = {name: value for name, value in os.environ.items()
                   if name not in EVERY_THREAD_VARIABLE}
    environment.update(preset)
    done = subprocess.run([sys.executable, '-c', POOLS_PROBE, json.dumps(settings)],
                          capture_output=True, text=True, env=environment, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_classifying_pipeline_limits_the_blas_to_one_thread() -> None:
    """With no thread variable set, numpy's BLAS starts one thread per core (2 here); a
    pipeline that classifies in its process limits every BLAS pool to 1 thread, for the
    rest of the process."""
    pools = blas_pools({})
    cores = os.cpu_count() or 1
    assert pools['before'], 'numpy loaded no BLAS that threadpoolctl sees'
    assert cores == 1 or max(pools['before']) > 1, pools  # the probe can see a limit
    assert pools['during'] == [1] * len(pools['before'])
    assert pools['after'] == pools['during']


def test_no_limit_without_a_classifier_in_the_process() -> None:
    """Detection alone (no matrix products) leaves the BLAS as it was."""
    pools = blas_pools({'classify': False})
    assert pools['during'] == pools['before']


@pytest.mark.parametrize('variable', ['OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'])
def test_the_users_thread_count_stands(variable: str) -> None:
    """A thread count the user set (even more threads) is left as the BLAS read it."""
    pools = blas_pools({}, **{variable: '2'})
    assert pools['during'] == pools['before'] == [min(2, os.cpu_count() or 1)] * len(
        pools['before'])
