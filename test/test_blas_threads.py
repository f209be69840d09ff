"""The executables that run the pipeline ask for one BLAS thread before numpy loads, and a
pipeline built in a process that set none warns."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from speed_sign_detector.blas_threads import (
    BLAS_THREAD_VARIABLES,
    FALLBACK_THREAD_VARIABLES,
    blas_thread_advice,
    use_one_blas_thread,
)
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.pipeline import Pipeline

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


def test_advice_only_where_no_thread_variable_is_set(monkeypatch) -> None:
    for name in EVERY_THREAD_VARIABLE:
        monkeypatch.delenv(name, raising=False)
    advice = blas_thread_advice(cpu_count=4)
    assert advice is not None
    assert 'runs 4 threads' in advice and 'OPENBLAS_NUM_THREADS=1' in advice
    assert blas_thread_advice(cpu_count=1) is None  # one core: nothing to take
    for name in EVERY_THREAD_VARIABLE:
        monkeypatch.setenv(name, '2')  # any choice of the user's, even more threads
        assert blas_thread_advice(cpu_count=4) is None
        monkeypatch.delenv(name)


@pytest.mark.parametrize('preset', [None, 'OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'])
def test_pipeline_warns_when_no_thread_variable_is_set(monkeypatch, caplog, preset) -> None:
    for name in EVERY_THREAD_VARIABLE:
        monkeypatch.delenv(name, raising=False)
    if preset is not None:
        monkeypatch.setenv(preset, '1')
    monkeypatch.setattr(os, 'cpu_count', lambda: 2)  # the same on a one-core machine
    with caplog.at_level('WARNING', logger='speed_sign_detector.pipeline'):
        with Pipeline(PipelineConfig(backend='numpy')):
            pass
        with Pipeline(PipelineConfig(backend='numpy', classify=False)):
            pass  # no classifier, no matrix products: never a warning
    warnings = [record.getMessage() for record in caplog.records
                if record.name == 'speed_sign_detector.pipeline'
                and record.levelname == 'WARNING']
    if preset is None:
        assert len(warnings) == 1 and 'OPENBLAS_NUM_THREADS=1' in warnings[0]
    else:
        assert warnings == []
