"""The live loop with real processes and real rclpy: replay -> node -> monitor.

``speed_sign_replay`` publishes a synthetic bag, the node (``speed_sign_detector``)
processes it, ``speed_sign_monitor --once --json`` reports the node's outputs. A
subscriber in this process checks what the replay publishes (ROS 1 bags are converted
to ROS 2 messages). Every process runs in this module's own ROS_DOMAIN_ID.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

from speed_sign_detector.bag_io import BagReader
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.replay import to_rclpy
from speed_sign_detector.tools.synth import write_drive

DOMAIN_ID = 91
WAIT_S = 90
FRAMES = 12
CONFIG = DriveConfig(seed=2, duration_s=FRAMES / 6, fps=6, width_px=320, height_px=240,
                     focal_px=380.0)
TOPIC = '/camera/image_raw'


def tool(name: str) -> list[str]:
    """Command line of an installed tool (the venv's entry point, else python -c main)."""
    script = Path(sys.executable).with_name(name)
    if script.exists():
        return [str(script)]
    found = shutil.which(name)
    assert found, f'{name} is not installed (pip install -e . makes the entry points)'
    return [found]


@pytest.fixture(scope='module')
def env() -> dict[str, str]:
    environment = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID), PYTHONUNBUFFERED='1')
    os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
    return environment


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('bags')
    drive = SyntheticDrive(CONFIG)
    paths = {'mcap': folder / 'drive_mcap', 'ros1': folder / 'drive.bag'}
    for bag_format, path in paths.items():
        write_drive(drive, path, bag_format, topic=TOPIC)
    return paths


def test_ros1_messages_convert_to_the_same_ros2_messages(bags: dict[str, Path]) -> None:
    with BagReader(bags['mcap']) as ros2_bag, BagReader(bags['ros1']) as ros1_bag:
        ros2_items = list(ros2_bag.messages(TOPIC))
        ros1_items = list(ros1_bag.messages(TOPIC))
    assert len(ros1_items) == len(ros2_items) == FRAMES
    for ros1_item, ros2_item in zip(ros1_items, ros2_items):
        converted = to_rclpy(ros1_item, Image)
        original = deserialize_message(ros2_item.raw, Image)
        assert converted == original


def test_monitor_without_a_node_exits_with_a_clear_message(env: dict[str, str]) -> None:
    quiet_env = dict(env, ROS_DOMAIN_ID=str(DOMAIN_ID + 1))
    result = subprocess.run([*tool('speed_sign_monitor'), '--once', '--json', '--timeout', '2'],
                            env=quiet_env, capture_output=True, text=True, timeout=WAIT_S)
    assert result.returncode == 1
    assert 'nothing published' in result.stderr and str(DOMAIN_ID + 1) in result.stderr
    assert result.stdout == ''


def test_replay_missing_topic_is_an_error(bags: dict[str, Path], env: dict[str, str]) -> None:
    result = subprocess.run([*tool('speed_sign_replay'), str(bags['mcap']), '--topic', '/nope'],
                            env=env, capture_output=True, text=True, timeout=WAIT_S)
    assert result.returncode == 1
    assert "no topic '/nope'" in result.stderr and TOPIC in result.stderr


@pytest.fixture()
def listener() -> Iterator[tuple[list[Image], object]]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    node = rclpy.create_node('replay_listener', context=context)
    received: list[Image] = []
    node.create_subscription(Image, TOPIC, received.append,
                             QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield received, node
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)
    thread.join(timeout=5)


@pytest.mark.parametrize('bag_format', ['mcap', 'ros1'])
def test_replay_publishes_every_frame_with_recorded_stamps(
        bags: dict[str, Path], env: dict[str, str], listener: tuple[list[Image], object],
        bag_format: str) -> None:
    received, _ = listener
    result = subprocess.run([*tool('speed_sign_replay'), str(bags[bag_format]), '--rate', '4',
                             '--wait', '30'], env=env, capture_output=True, text=True,
                            timeout=WAIT_S)
    assert result.returncode == 0, result.stderr
    assert f'published {FRAMES} messages of {TOPIC}' in result.stderr
    deadline = time.monotonic() + 10
    while len(received) < FRAMES and time.monotonic() < deadline:
        time.sleep(0.05)
    stamps = [msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
              for msg in received]
    assert stamps == [CONFIG.stamp_ns(index) for index in range(FRAMES)]
    assert all(msg.width == 320 and msg.height == 240 and msg.encoding == 'bgr8'
               for msg in received)


def test_replay_node_monitor_loop(bags: dict[str, Path], env: dict[str, str],
                                  tmp_path: Path) -> None:
    node_log = (tmp_path / 'node.log').open('w')
    node = subprocess.Popen([*tool('speed_sign_detector'), '--ros-args', '-r',
                             f'image:={TOPIC}', '-p', 'diagnostics_period_s:=0.5'],
                            env=env, stdout=node_log, stderr=subprocess.STDOUT)
    try:
        replay = subprocess.Popen([*tool('speed_sign_replay'), str(bags['mcap']), '--loop',
                                   '--wait', '60', '--quiet'], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            monitor = subprocess.run([*tool('speed_sign_monitor'), '--once', '--json',
                                      '--timeout', '60'], env=env, capture_output=True,
                                     text=True, timeout=WAIT_S)
        finally:
            replay.terminate()
            replay.wait(timeout=30)
    finally:
        node.terminate()
        node.wait(timeout=30)
        node_log.close()
    log = (tmp_path / 'node.log').read_text()
    assert monitor.returncode == 0, monitor.stderr + log
    snapshot = json.loads(monitor.stdout.strip().splitlines()[-1])
    assert snapshot['messages']['speed_limit'] >= 1
    assert snapshot['messages']['candidates'] >= 1, log
    assert snapshot['messages']['diagnostics'] >= 1, log
    assert snapshot['active_limit_kmh'] in (0, *range(5, 135, 5))
    assert snapshot['candidates_per_frame'] >= 0
    assert snapshot['frames_processed'] >= 1
    assert snapshot['backend'] in ('gl', 'numpy')
    assert snapshot['status_level'] in ('OK', 'WARN')
