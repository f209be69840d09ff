"""The live loop with real processes and real rclpy: replay -> node -> monitor.

``speed_sign_replay`` publishes a synthetic bag, the node (``speed_sign_detector``)
processes it, ``speed_sign_monitor --once --json`` reports the node's outputs. A
subscriber in this process checks what the replay publishes (ROS 1 bags are converted
to ROS 2 messages). Every process runs in this module's own ROS_DOMAIN_ID.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from cli_helpers import tool
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from ros_spin import module_domain, ros_domain_environment, spinning
from sensor_msgs.msg import CompressedImage, Image

from speed_sign_detector.bag_io import BagReader
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.monitor import MonitorSnapshot
from speed_sign_detector.tools.replay import to_rclpy
from speed_sign_detector.tools.synth import write_drive
from speed_sign_detector.truth import group_tracks

DOMAIN_ID = module_domain('test_replay_monitor')
#: A domain where nothing runs.
QUIET_DOMAIN_ID = module_domain('test_replay_monitor', 1)
WAIT_S = 90
FRAMES = 12
CONFIG = DriveConfig(seed=2, duration_s=FRAMES / 6, fps=6, width_px=320, height_px=240,
                     focal_px=380.0)
TOPIC = '/camera/image_raw'


@pytest.fixture(scope='module')
def env() -> Iterator[dict[str, str]]:
    """The environment of the processes (this module's domain), also set in this process
    for the module and restored after it."""
    with ros_domain_environment(DOMAIN_ID):
        yield dict(os.environ, PYTHONUNBUFFERED='1')


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('bags')
    frames = list(SyntheticDrive(CONFIG))
    paths = {'mcap': folder / 'drive_mcap', 'ros1': folder / 'drive.bag',
             'mcap_jpeg': folder / 'drive_mcap_jpeg', 'ros1_jpeg': folder / 'drive_jpeg.bag'}
    for name, path in paths.items():
        write_drive(frames, path, name.split('_')[0], compressed=name.endswith('jpeg'),
                    topic=TOPIC)
    return paths


@pytest.mark.parametrize('encoding', ['', '_jpeg'], ids=['raw', 'jpeg'])
def test_ros1_messages_convert_to_the_same_ros2_messages(bags: dict[str, Path],
                                                         encoding: str) -> None:
    message_class = CompressedImage if encoding else Image
    with BagReader(bags[f'mcap{encoding}']) as ros2_bag, \
            BagReader(bags[f'ros1{encoding}']) as ros1_bag:
        ros2_items = list(ros2_bag.messages(TOPIC))
        ros1_items = list(ros1_bag.messages(TOPIC))
    assert len(ros1_items) == len(ros2_items) == FRAMES
    for ros1_item, ros2_item in zip(ros1_items, ros2_items):
        converted = to_rclpy(ros1_item, message_class)
        original = deserialize_message(ros2_item.raw, message_class)
        assert converted == original


def test_monitor_without_a_node_exits_with_a_clear_message(env: dict[str, str]) -> None:
    quiet_env = dict(env, ROS_DOMAIN_ID=str(QUIET_DOMAIN_ID))
    result = subprocess.run([*tool('speed_sign_monitor'), '--once', '--json', '--timeout', '2'],
                            env=quiet_env, capture_output=True, text=True, timeout=WAIT_S)
    assert result.returncode == 1
    assert 'nothing published' in result.stderr and str(QUIET_DOMAIN_ID) in result.stderr
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
    with spinning(context, node):
        yield received, node


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
                                  tmp_path: Path, pytestconfig: pytest.Config) -> None:
    """The replay loops the drive with fresh stamps (so the node keeps its limit across
    passes); the monitor reports the drive's speed limit once the node has read it; the
    node stops cleanly on SIGTERM and the replay on Ctrl-C."""
    frames = list(SyntheticDrive(CONFIG))
    drive_limits = {track.limit_kmh for track in group_tracks(
        row for frame in frames for row in frame.truth) if track.is_limit}
    assert drive_limits, 'the drive shows no speed-limit sign'
    bank_cache = pytestconfig.cache.mkdir('speed_sign_filter_banks')
    node_log = (tmp_path / 'node.log').open('w')
    node = subprocess.Popen([*tool('speed_sign_detector'), '--ros-args', '-r',
                             f'image:={TOPIC}', '-p', 'diagnostics_period_s:=0.5',
                             '-p', f'classifier.cache_dir:={bank_cache}'],
                            env=env, stdout=node_log, stderr=subprocess.STDOUT)
    snapshots: list[dict] = []
    try:
        replay = subprocess.Popen([*tool('speed_sign_replay'), str(bags['mcap']), '--loop',
                                   '--restamp', '--wait', '60', '--quiet'], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + WAIT_S
            while not snapshots or snapshots[-1]['active_limit_kmh'] not in drive_limits:
                assert time.monotonic() < deadline, (
                    f'the monitor never reported a limit of the drive {sorted(drive_limits)}'
                    f': {snapshots[-1:]}')
                assert node.poll() is None and replay.poll() is None, 'a process ended'
                monitor = subprocess.run([*tool('speed_sign_monitor'), '--once', '--json',
                                          '--timeout', '60'], env=env, capture_output=True,
                                         text=True, timeout=WAIT_S)
                assert monitor.returncode == 0, monitor.stderr
                snapshots.append(json.loads(monitor.stdout.strip().splitlines()[-1]))
        finally:
            replay.send_signal(signal.SIGINT)
            replay_status = replay.wait(timeout=30)
            replay_errors = replay.stderr.read()
    finally:
        node.terminate()
        node_status = node.wait(timeout=30)
        node_log.close()
    log = (tmp_path / 'node.log').read_text()
    assert node_status == 0, log
    assert replay_status == 130, replay_errors  # Ctrl-C
    assert 'Traceback' not in log + replay_errors
    snapshot = snapshots[-1]
    assert snapshot['messages']['speed_limit'] >= 1
    assert snapshot['messages']['candidates'] >= 1, log
    assert snapshot['messages']['diagnostics'] >= 1, log
    assert isinstance(snapshot['candidates_per_frame'], int)
    assert snapshot['frames_processed'] >= 1
    assert snapshot['backend'] in ('gl', 'cpu', 'numpy')
    assert snapshot['status_level'] in ('OK', 'WARN')


def test_status_line_shows_what_is_known() -> None:
    empty = MonitorSnapshot().status_line()
    assert empty.startswith('limit - | candidates - ')
    line = MonitorSnapshot(active_limit_kmh=50, candidates_per_frame=3,
                           candidates_per_frame_mean=2.5, fps=14.2,
                           processing_latency_p50_ms=40.0, processing_latency_p95_ms=61.0,
                           latency_p50_ms=55.0, latency_p95_ms=80.0, frames_processed=100,
                           frames_dropped=4, frames_lost_in_transport=7,
                           seconds_since_last_image=0.1, backend='gl',
                           status_level='OK').status_line()
    assert line == ('limit 50 km/h | candidates 3 (mean 2.5) | fps 14.2 | processing p50 40 '
                    'p95 61 ms | transport (stamp to receipt) p50 55 p95 80 ms | processed '
                    '100 dropped 4 lost in transport 7 | gl OK')
    replayed = MonitorSnapshot(active_limit_kmh=0, latency_p50_ms=9e10).status_line()
    assert 'limit none' in replayed and 'transport (stamp to receipt) old stamps' in replayed
    ended = MonitorSnapshot(active_limit_kmh=80, fps=0.0, frames_processed=450,
                            seconds_since_last_image=3.4, status_level='OK').status_line()
    assert 'idle, last image 3 s ago' in ended and 'fps' not in ended
