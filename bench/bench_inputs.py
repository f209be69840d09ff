"""Inputs shared by the benchmark scripts, importable without rclpy.

``run_all.py --skip-node`` needs the node's parameter file and the synthetic frames but
not ROS, so that it also runs on a machine that has the GL stack and no rclpy (a lent
GPU machine, say); ``bench_node.py``, which needs rclpy, takes them from here too.
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy as np

from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive

PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: The data the benchmarks read (see ../shared/data/README).
DATA_DIR = PROJECT_ROOT.parent / 'shared' / 'data'
#: The node's parameter file: the settings every stage of the benchmark runs with.
PARAMS_FILE = PROJECT_ROOT / 'config' / 'speed_sign_detector.yaml'
#: Fast DDS profile for 640x480 and larger images over UDP (see the README).
DDS_PROFILE = PROJECT_ROOT / 'config' / 'fastdds_large_images.xml'


def drive_frames(width: int, height: int, count: int, seed: int = 0) -> list[np.ndarray]:
    """The first ``count`` BGR frames, each (height, width, 3) uint8, of a synthetic drive.

    The drive (signs, look-alikes, distractors, blur) runs at 30 frames/s.
    """
    drive = SyntheticDrive(DriveConfig(seed=seed, width_px=width, height_px=height,
                                       duration_s=count / 30.0 + 1.0, fps=30.0))
    return [drive.frame(index).bgr for index in range(count)]


class MissingExecutableError(Exception):
    """A console script of the package is not installed."""


def installed_executable(name: str) -> str:
    """The path of console script ``name`` (beside this interpreter, else on PATH).

    Raises:
        MissingExecutableError: when it is not installed.
    """
    found = shutil.which(name, path=os.pathsep.join(
        [str(Path(sys.executable).parent), os.environ.get('PATH', '')]))
    if found is None:
        raise MissingExecutableError(f'{name} is not installed (pip install -e .)')
    return found
