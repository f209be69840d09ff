"""The host record a bank's provenance carries (training/training_host.py)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from speed_sign_detector.training.training_host import (
    blas_libraries,
    describe_host,
    training_host,
)


def test_the_host_record_names_the_cpu_the_libraries_and_the_blas_kernels() -> None:
    host = training_host()
    assert host['cpu_model'] and host['cpus'] >= 1
    assert host['numpy'] == np.__version__ and host['opencv'] == cv2.__version__
    # numpy is loaded, and its wheel bundles a BLAS that threadpoolctl sees
    assert host['blas'] == blas_libraries() and host['blas']
    assert all(library['internal_api'] and library['version'] for library in host['blas'])
    line = describe_host(host)
    assert host['cpu_model'] in line and f'numpy {np.__version__}' in line
    assert all(str(library['version']) in line for library in host['blas'])


def test_the_host_record_is_the_same_from_call_to_call() -> None:
    # nothing that changes run to run: a bank rebuilt on the same host is the same file
    assert training_host() == training_host()


def test_the_variables_that_choose_the_blas_kernel_are_recorded_where_set(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv('OPENBLAS_CORETYPE', raising=False)
    monkeypatch.setenv('OPENBLAS_NUM_THREADS', '1')
    assert 'OPENBLAS_CORETYPE' not in training_host()['environment']
    monkeypatch.setenv('OPENBLAS_CORETYPE', 'Haswell')
    host = training_host()
    assert host['environment']['OPENBLAS_CORETYPE'] == 'Haswell'
    assert host['environment']['OPENBLAS_NUM_THREADS'] == '1'
    assert describe_host(host).endswith('OPENBLAS_CORETYPE=Haswell, OPENBLAS_NUM_THREADS=1')


def test_a_record_without_blas_or_cpu_is_still_described() -> None:
    assert describe_host({}) == 'unknown CPU, BLAS unknown'
    host = {'cpu_model': 'Some CPU', 'cpus': 4, 'numpy': '2.0.0',
            'blas': [{'internal_api': 'mkl', 'version': '2024.1'}]}
    assert describe_host(host) == 'Some CPU (4 CPUs), numpy 2.0.0, mkl 2024.1'
