"""Frames lost before the node: a real publisher skips stamps of a regular 30 Hz sequence.

The node (in-process, real rclpy, detection only) must report in /diagnostics exactly the
frames the publisher skipped, 0 for the regular part, turn its status to WARN, and log
a warning naming the cause and the Fast DDS profile (read back from /rosout).
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from ros_spin import spinning
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from test_node import Probe, wait_for

from speed_sign_detector.ros.messages import image_message
from speed_sign_detector.ros.node import SpeedSignDetectorNode

DOMAIN_ID = 94
NODE_NAME = 'transport_loss_test_node'
PERIOD_NS = 33_333_333
START_NS = 1_750_000_000_000_000_000
#: Frames 0..39 regular; of 40..119 these are never published (12 frames).
SKIPPED = frozenset({45, 52, 53, 60, 71, 72, 73, 88, 95, 101, 102, 110})
pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def ros(request: pytest.FixtureRequest) -> Iterator[tuple[SpeedSignDetectorNode, Probe, list]]:
    os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    # a name of its own: /rosout is read back, and other test modules of this process
    # ran nodes named speed_sign_detector
    node = SpeedSignDetectorNode(NODE_NAME, context=context, parameter_overrides=[
        Parameter('classify', value=False),
        Parameter('diagnostics_period_s', value=0.3)])
    probe = Probe(context=context)
    logs: list[str] = []
    probe.create_subscription(Log, '/rosout', lambda msg: logs.append(msg.msg), 100)
    with spinning(context, node, probe):
        wait_for(lambda: probe.image_pub.get_subscription_count() > 0, 'discovery')
        yield node, probe, logs


def latest_status(probe: Probe, key_filter: Callable[[dict[str, Any]], bool]
                  ) -> dict[str, Any]:
    """Wait for a status of the node satisfying ``key_filter``: its values, plus
    ``_message`` and ``_level``."""
    def found() -> dict[str, Any] | None:
        with probe.lock:
            arrays = list(probe.diagnostics)
        for array in reversed(arrays):
            for status in array.status:
                if status.name == f'{NODE_NAME}: pipeline':
                    values = {kv.key: kv.value for kv in status.values}
                    values.update(_message=status.message, _level=status.level)
                    if key_filter(values):
                        return values
        return None
    return wait_for(found, 'a matching /diagnostics status')


def publish_frames(probe: Probe, indices: range) -> int:
    """Publish frames ``indices`` (minus SKIPPED) stamped index x 1/30 s, at 30 Hz."""
    frame = np.full((96, 128), 90, np.uint8)
    published = 0
    for index in indices:
        if index in SKIPPED:
            continue
        message = image_message(frame, Header(frame_id='camera'), image_class=Image)
        message.header.stamp.sec, message.header.stamp.nanosec = divmod(
            START_NS + index * PERIOD_NS, 1_000_000_000)
        probe.image_pub.publish(message)
        published += 1
        time.sleep(PERIOD_NS * 1e-9)
    return published


def test_a_regular_stream_reports_no_loss_and_skipped_stamps_are_counted(ros: tuple) -> None:
    node, probe, logs = ros
    received = publish_frames(probe, range(0, 40))
    values = latest_status(probe, lambda v: int(v['frames_received']) == received)
    assert values['frames_lost_in_transport'] == '0'
    assert float(values['source_frame_period_ms']) == pytest.approx(33.3, abs=0.2)

    received += publish_frames(probe, range(40, 126))
    values = latest_status(probe, lambda v: int(v['frames_received']) == received)
    assert int(values['frames_lost_in_transport']) == len(SKIPPED)
    assert float(values['frames_lost_in_transport_share']) == pytest.approx(
        len(SKIPPED) / 126, abs=0.001)

    warned = latest_status(probe, lambda v: v['_level'] == DiagnosticStatus.WARN
                           and 'lost in transport' in v['_message'])
    assert int(warned['frames_lost_in_transport']) > 0
    warning = wait_for(lambda: [text for text in list(logs)
                                if 'lost before they reach this node' in text],
                       'the transport-loss warning on /rosout')[0]
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' in warning
    assert 'fastdds_large_images.xml' in warning and 'camera driver' in warning
