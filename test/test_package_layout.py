"""`colcon build` of the package gives the layout `ros2 run` and `ros2 launch` rely on."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
EXECUTABLES = ('speed_sign_detector', 'speed_sign_eval', 'speed_sign_synth',
               'speed_sign_replay', 'speed_sign_monitor')
SKIPPED_WHEN_COPYING = shutil.ignore_patterns('.git', '.venv', 'build', 'install', 'log',
                                              'out', '__pycache__', '*.egg-info', '.pytest_cache')


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A colcon workspace holding a copy of this package, built; returns install/."""
    colcon = Path(sys.executable).parent / 'colcon'
    if not colcon.exists():
        found = shutil.which('colcon')
        assert found, ('colcon is not installed: `pip install .[test]` brings colcon-core '
                       'and colcon-ros')
        colcon = Path(found)
    workspace = tmp_path_factory.mktemp('colcon_ws')
    shutil.copytree(PROJECT_ROOT, workspace / 'src' / 'speed_sign_detector',
                    ignore=SKIPPED_WHEN_COPYING)
    completed = subprocess.run([str(colcon), 'build'], cwd=workspace, capture_output=True,
                               text=True, timeout=300, check=False)
    assert completed.returncode == 0, \
        f'colcon build failed:\n{completed.stdout}\n{completed.stderr}'
    return workspace / 'install'


def test_executables_land_where_ros2_run_looks(colcon_install: Path) -> None:
    lib = colcon_install / 'speed_sign_detector' / 'lib' / 'speed_sign_detector'
    for name in EXECUTABLES:
        assert (lib / name).is_file(), f'{name} missing from {lib}'
        assert os.access(lib / name, os.X_OK), f'{name} is not executable'


def test_ament_index_marker_config_and_launch_are_installed(colcon_install: Path) -> None:
    share = colcon_install / 'speed_sign_detector' / 'share'
    index = share / 'ament_index' / 'resource_index' / 'packages'
    assert (index / 'speed_sign_detector').is_file()
    package_share = share / 'speed_sign_detector'
    assert (package_share / 'package.xml').is_file()
    assert (package_share / 'config' / 'speed_sign_detector.yaml').is_file()
    assert list((package_share / 'launch').glob('*.launch.py')), 'no launch file installed'


def test_installed_executable_runs(colcon_install: Path) -> None:
    """The colcon-installed speed_sign_eval starts (imports resolve from install/)."""
    prefix = colcon_install / 'speed_sign_detector'
    site_packages = next(prefix.glob('lib/python3*/site-packages'))
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(site_packages), os.environ.get('PYTHONPATH', '')]))
    completed = subprocess.run(
        [sys.executable, str(prefix / 'lib' / 'speed_sign_detector' / 'speed_sign_eval'),
         '--help'],
        capture_output=True, text=True, env=environment, timeout=120, check=False)
    assert completed.returncode == 0, completed.stderr
    assert 'scenes' in completed.stdout
