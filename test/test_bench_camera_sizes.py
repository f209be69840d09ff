"""bench/bench_camera_sizes.py: ``speed_sign_eval bag`` at each camera size, its failures.

The stage's real run (the installed tools on a tiny drive and an approach bag) is in
test_bench_smoke.py; here the ways it fails or leaves a part out, and the sizes option.
"""
from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest
from test_bench_smoke import bench_module


@pytest.fixture(scope='module')
def camera_sizes() -> ModuleType:
    return bench_module('bench_camera_sizes')


def test_a_failing_tool_names_its_command_and_reason(camera_sizes: ModuleType,
                                                     tmp_path: Path) -> None:
    settings = camera_sizes.CameraSizeSettings(work_dir=tmp_path / 'work', sizes=((320, 240),),
                                               drive_seconds=-1.0, approach_sequences=0)
    with pytest.raises(camera_sizes.CameraSizeBenchError) as raised:
        camera_sizes.measure_camera_sizes(settings)
    message = str(raised.value)
    assert message.startswith('speed_sign_synth ') and '--duration -1' in message
    assert 'exited with 2' in message and 'duration' in message.split('exited with 2')[1]


def test_without_a_scene_folder_the_approach_is_left_out_with_the_reason(
        camera_sizes: ModuleType, tmp_path: Path) -> None:
    settings = camera_sizes.CameraSizeSettings(work_dir=tmp_path / 'work', sizes=((320, 240),),
                                               gtsdb_dir=tmp_path / 'no_scenes',
                                               drive_seconds=0.5)
    figures = camera_sizes.measure_camera_sizes(settings)
    row = figures['sizes']['320x240']
    assert row['drive']['frames'] == 15
    assert row['approach'] == {'skipped': f'no GTSDB-format scene folder at '
                                          f'{tmp_path / "no_scenes"}'}


def test_sizes_option(camera_sizes: ModuleType) -> None:
    assert camera_sizes.parse_sizes('640x480,1920X1080') == ((640, 480), (1920, 1080))
    for wrong in ('640', '640x', 'ax480', '0x480'):
        with pytest.raises(ValueError, match='camera size'):
            camera_sizes.parse_sizes(wrong)
