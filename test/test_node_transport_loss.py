"""Frames lost before the node: a real publisher skips stamps of a regular 30 Hz sequence.

The node (in-process, real rclpy, detection only) must report in /diagnostics the frames
the publisher skipped, none for the regular part, turn its status to WARN, and log a
warning naming the cause and the Fast DDS profile (read back from /rosout). The stream is
best effort: the counts are bounded by what was published and what reached the node
(recorded as the node's subscription callback runs), not taken as exact.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from ros_spin import module_domain, ros_domain_environment, spinning
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from test_node import Probe, wait_for

from speed_sign_detector.ros.messages import image_message
from speed_sign_detector.ros.node import SpeedSignDetectorNode

DOMAIN_ID = module_domain('test_node_transport_loss')
NODE_NAME = 'transport_loss_test_node'
PERIOD_NS = 33_333_333
START_NS = 1_750_000_000_000_000_000
#: Frames 0..39 regular; of 40..119 these are never published (12 frames).
SKIPPED = frozenset({45, 52, 53, 60, 71, 72, 73, 88, 95, 101, 102, 110})
#: Longest the last frame of a run is sent again until it reaches the node, seconds.
WAIT_FOR_LAST_S = 60.0
pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def ros(request: pytest.FixtureRequest
        ) -> Iterator[tuple[SpeedSignDetectorNode, Probe, list, list]]:
    """The node, the probe, the /rosout texts, and the frame indices that reached the
    node's image subscription (in arrival order)."""
    with ros_domain_environment(DOMAIN_ID):
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=DOMAIN_ID)
        # a name of its own: /rosout is read back, and other test modules of this process
        # ran nodes named speed_sign_detector
        node = SpeedSignDetectorNode(NODE_NAME, context=context, parameter_overrides=[
            Parameter('classify', value=False),
            Parameter('diagnostics_period_s', value=0.3)])
        arrived: list[int] = []
        on_image = node._image_sub.callback

        def note_arrival(msg: Image) -> None:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            arrived.append(round((stamp - START_NS) / PERIOD_NS))
            on_image(msg)

        node._image_sub.callback = note_arrival
        probe = Probe(context=context)
        logs: list[str] = []
        probe.create_subscription(Log, '/rosout', lambda msg: logs.append(msg.msg), 100)
        with spinning(context, node, probe):
            wait_for(lambda: probe.image_pub.get_subscription_count() > 0, 'discovery')
            yield node, probe, logs, arrived


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


def frame_message(index: int) -> Image:
    """A small gray frame stamped index x 1/30 s after START_NS."""
    message = image_message(np.full((96, 128), 90, np.uint8), Header(frame_id='camera'),
                            image_class=Image)
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(
        START_NS + index * PERIOD_NS, 1_000_000_000)
    return message


def publish_frames(probe: Probe, indices: range, arrived: list[int]) -> list[int]:
    """Publish frames ``indices`` (minus SKIPPED) at the camera's rate (30 Hz); the last
    one is sent again should it not reach the node within 5 s (so the stream's end is
    known). Returns the indices published."""
    published = [index for index in indices if index not in SKIPPED]
    for index in published:
        probe.image_pub.publish(frame_message(index))
        time.sleep(PERIOD_NS * 1e-9)  # the source's frame period, not a wait for the node
    deadline = time.monotonic() + WAIT_FOR_LAST_S
    while True:
        try:
            wait_for(lambda: published[-1] in arrived, f'frame {published[-1]} at the node',
                     timeout_s=5.0)
            return published
        except pytest.fail.Exception:
            if time.monotonic() > deadline:
                raise
            probe.image_pub.publish(frame_message(published[-1]))


def missing_between(arrived: list[int], published: list[int]) -> int:
    """Published frames that did not reach the node, between its first and last arrival."""
    seen = set(arrived)
    return sum(1 for index in published
               if index not in seen and min(seen) < index < max(seen))


def test_a_regular_stream_reports_no_loss_and_skipped_stamps_are_counted(ros: tuple) -> None:
    node, probe, logs, arrived = ros
    published = publish_frames(probe, range(0, 40), arrived)
    values = latest_status(probe, lambda v: int(v['frames_received']) == len(arrived))
    assert len(arrived) <= len(published) + 1  # the last one may come twice
    # nothing skipped: only frames best effort lost on the way may count
    assert int(values['frames_lost_in_transport']) <= missing_between(arrived, published)
    assert float(values['source_frame_period_ms']) == pytest.approx(33.3, abs=0.2)

    published += publish_frames(probe, range(40, 126), arrived)
    values = latest_status(probe, lambda v: int(v['frames_received']) == len(arrived))
    lost = int(values['frames_lost_in_transport'])
    assert len(SKIPPED) <= lost <= len(SKIPPED) + missing_between(arrived, published)
    assert float(values['frames_lost_in_transport_share']) == pytest.approx(
        lost / (len(arrived) + lost), abs=0.001)

    warned = latest_status(probe, lambda v: v['_level'] == DiagnosticStatus.WARN
                           and 'lost in transport' in v['_message'])
    assert int(warned['frames_lost_in_transport']) > 0
    warning = wait_for(lambda: [text for text in list(logs)
                                if 'lost before they reach this node' in text],
                       'the transport-loss warning on /rosout')[0]
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' in warning
    assert 'fastdds_large_images.xml' in warning and 'camera driver' in warning
