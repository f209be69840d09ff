"""What ``speed_sign_monitor`` prints, fed by a real /diagnostics and speed_limit publisher.

The publisher here plays the node: a latched speed_limit and a status like the node's
every 0.4 s. The monitor (the installed executable, stdout a pipe) must print one line
per report, not one per poll, and on SIGTERM the final state, which reads as an idle
node (its stream ended), not as a failure.
"""
from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import UInt16
from test_node_cli import tool

DOMAIN_ID = 98
REPORTS = 6
pytestmark = pytest.mark.ros


@pytest.fixture()
def fake_node() -> Iterator[Node]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    node = rclpy.create_node('speed_sign_detector', context=context)
    yield node
    node.destroy_node()
    rclpy.shutdown(context=context)


def status(index: int) -> DiagnosticArray:
    """The node's status after its stream ended: fps 0, last image ``index`` s ago."""
    values = {'frames_received': '450', 'frames_processed': '440', 'frames_dropped': '10',
              'frames_lost_in_transport': '3', 'processing_fps': '0.00',
              'latency_p50_ms': '4.0', 'latency_p95_ms': '9.0',
              'processing_latency_p50_ms': '60.0', 'processing_latency_p95_ms': '90.0',
              'seconds_since_last_image': f'{1.0 + index:.1f}', 'backend': 'gl'}
    return DiagnosticArray(status=[DiagnosticStatus(
        level=DiagnosticStatus.OK, name='speed_sign_detector: pipeline', message='running',
        values=[KeyValue(key=key, value=value) for key, value in values.items()])])


def test_one_line_per_report_and_an_idle_final_state(fake_node: Node) -> None:
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    fake_node.create_publisher(UInt16, 'speed_limit', latched).publish(UInt16(data=80))
    diagnostics = fake_node.create_publisher(DiagnosticArray, '/diagnostics', 10)
    monitor = subprocess.Popen([tool('speed_sign_monitor'), '--timeout', '30'],
                               env=dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID),
                                        PYTHONUNBUFFERED='1'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while diagnostics.get_subscription_count() == 0:
            assert time.monotonic() < deadline, 'the monitor did not subscribe'
            time.sleep(0.05)
        time.sleep(1.0)  # the latched limit reaches it
        for index in range(REPORTS):
            diagnostics.publish(status(index))
            time.sleep(0.4)
        time.sleep(0.5)
    finally:
        monitor.send_signal(signal.SIGTERM)
        output, errors = monitor.communicate(timeout=30)
    assert monitor.returncode == 0, errors
    lines = output.strip().splitlines()
    *reports, final = lines
    report_lines = [line for line in reports if 'processed 440' in line]
    assert len(report_lines) == REPORTS, output       # one per report, none repeated
    assert len(set(report_lines)) == REPORTS, output
    assert final.startswith('final state: limit 80 km/h'), output
    assert 'idle, last image 6 s ago' in final and 'fps 0.0' not in final
    assert 'transport (stamp to receipt) p50 4 p95 9 ms' in final
    assert 'lost in transport 3' in final and final.endswith('gl OK')
