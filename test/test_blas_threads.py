"""The executables that run the pipeline ask for one BLAS thread before numpy loads."""
from __future__ import annotations

import json
import os
import subprocess
import sys

from speed_sign_detector.blas_threads import BLAS_THREAD_VARIABLES, use_one_blas_thread


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
