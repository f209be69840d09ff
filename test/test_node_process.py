"""The installed ``speed_sign_detector`` executable as a separate process, over DDS.

Started as ``ros2 run`` would start it: the console script from the environment's bin
folder, with the package's parameter file and topic remappings on the command line.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from rcl_interfaces.msg import Log
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_spin import module_domain, ros_domain_environment, spinning
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from test_node import (
    Probe,
    approach_frames,
    assert_sign_in_most_frames,
    latest_status,
    send_and_wait,
    sign_candidate,
    wait_for,
)

from speed_sign_detector.classifier_placement import (
    choose_classifier_placement,
    usable_cpu_count,
)
from speed_sign_detector.ros.messages import image_message

DOMAIN_ID = module_domain('test_node_process')
PARAMS_FILE = Path(__file__).resolve().parents[1] / 'config' / 'speed_sign_detector.yaml'
CAMERA_TOPIC = '/test_cam/image_raw'
STOP_TIMEOUT_S = 30.0

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def executable() -> str:
    """The installed console script (next to this interpreter, else on PATH)."""
    search = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get('PATH', '')])
    found = shutil.which('speed_sign_detector', path=search)
    if found is None:
        pytest.fail('the speed_sign_detector executable is not installed: run '
                    '`pip install -e .` (or colcon build) first')
    return found


def start_node(bank_cache: Path, *extra: str) -> subprocess.Popen:
    command = [executable(), '--ros-args', '--params-file', str(PARAMS_FILE),
               '-p', f'classifier.cache_dir:={bank_cache}',
               '-r', f'image:={CAMERA_TOPIC}',
               '-r', f'image/compressed:={CAMERA_TOPIC}/compressed', *extra]
    environment = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID), PYTHONUNBUFFERED='1')
    return subprocess.Popen(command, env=environment, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def stop(process: subprocess.Popen, signal_number: int) -> tuple[int, str]:
    """Send a signal, wait for the exit; returns (exit status, everything it printed)."""
    if process.poll() is None:
        process.send_signal(signal_number)
    try:
        output, _ = process.communicate(timeout=STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
        pytest.fail(f'the node did not stop within {STOP_TIMEOUT_S:.0f} s of signal '
                    f'{signal_number}; output:\n{output}')
    return process.returncode, output


@pytest.fixture(scope='module')
def bank_cache(request: pytest.FixtureRequest) -> Path:
    return request.config.cache.mkdir('speed_sign_classifier_banks')


@pytest.fixture(scope='module')
def probe() -> Iterator[Probe]:
    with ros_domain_environment(DOMAIN_ID):
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=DOMAIN_ID)
        probe = Probe(image_topic=CAMERA_TOPIC, context=context)
        with spinning(context, probe):
            yield probe


def wait_until_serving(probe: Probe, process: subprocess.Popen) -> None:
    """Until the node's latched speed_limit arrives (it is published once it is ready)."""
    def ready() -> bool:
        if process.poll() is not None:
            pytest.fail(f'the node exited with {process.returncode}:\n'
                        f'{process.communicate()[0]}')
        return bool(probe.limits) and probe.image_pub.get_subscription_count() > 0
    wait_for(ready, 'the node process to come up', timeout_s=180.0)


def test_installed_node_talks_over_dds_and_stops_on_sigterm(probe: Probe,
                                                            bank_cache: Path) -> None:
    process = start_node(bank_cache)
    try:
        wait_until_serving(probe, process)
        assert probe.limits[0] == 0
        found = []
        for frame, x, y, radius in approach_frames('80', 16, seed=2):
            cloud = send_and_wait(probe, image_message(frame, Header(), image_class=Image),
                                  probe.image_pub)
            found.append(sign_candidate(cloud, x, y, radius))
        assert_sign_in_most_frames(found)
        wait_for(lambda: probe.limits[-1] == 80, 'speed_limit 80 from the process')
        values = latest_status(probe, lambda v: int(v['frames_processed']) >= 16)
        assert values['backend'] in ('gl', 'cpu', 'numpy')
    finally:
        status, output = stop(process, signal.SIGTERM)
    assert status == 0, output
    assert 'Traceback' not in output, output
    assert CAMERA_TOPIC in output  # the startup log names the remapped topic
    # and where the classifier runs: sized to this host (classifier_workers 0, the default)
    placement = choose_classifier_placement(usable_cpu_count(), 0, False)
    assert placement.describe() in output, output


def test_qos_override_and_clean_stop_on_ctrl_c(probe: Probe, bank_cache: Path) -> None:
    """A reliable-only image subscription (QoS override) meets the probe's best-effort
    publisher: the node says the QoS is incompatible; Ctrl-C stops it cleanly."""
    probe.limits.clear()
    node_warnings: list[str] = []
    # /rosout publishers are transient-local: a subscriber of the same durability also
    # gets a warning logged before the two matched (the event may fire first under load)
    rosout = probe.create_subscription(
        Log, '/rosout', lambda msg: node_warnings.append(msg.msg)
        if msg.name == 'speed_sign_detector' and msg.level >= Log.WARN else None,
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL))
    process = start_node(
        bank_cache, '-p', f'qos_overrides.{CAMERA_TOPIC}.subscription.reliability:=reliable')

    def node_subscription() -> list:
        return [info for info in probe.get_subscriptions_info_by_topic(CAMERA_TOPIC)
                if info.node_name == 'speed_sign_detector']
    try:
        wait_for(lambda: probe.limits, 'the node process to come up', timeout_s=180.0)
        [info] = wait_for(node_subscription, 'the node on the camera topic')
        assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        assert probe.image_pub.get_subscription_count() == 0  # not matched
        # the incompatible-QoS event reaches the node's executor, which warns
        wait_for(lambda: [text for text in list(node_warnings) if 'incompatible' in text],
                 'the node to warn of the incompatible QoS on /rosout')
    finally:
        status, output = stop(process, signal.SIGINT)
        probe.destroy_subscription(rosout)
    assert status == 0, output
    assert 'Traceback' not in output, output
    assert 'incompatible' in output, output


def test_invalid_parameters_stop_the_start_with_the_reason(bank_cache: Path) -> None:
    process = start_node(bank_cache, '-p', 'detector.min_radius_px:=60.0')
    output, _ = process.communicate(timeout=120)
    assert process.returncode == 1, output
    assert 'max_radius_px' in output
    assert 'Traceback' not in output, output
