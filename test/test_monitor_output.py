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
import threading
import time
from collections.abc import Callable, Iterator

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import UInt16
from ros_spin import module_domain
from test_node_cli import tool

DOMAIN_ID = module_domain('test_monitor_output')
WAIT_S = 60.0
#: The simulated node's diagnostics period, seconds.
REPORT_PERIOD_S = 0.4
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


class OutputLines:
    """The lines a process prints on stdout, read as they come on a thread."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self._thread.start()

    def _read(self, process: subprocess.Popen) -> None:
        for line in process.stdout:
            with self._lock:
                self.lines.append(line.rstrip('\n'))

    def matching(self, keep: Callable[[str], bool]) -> list[str]:
        with self._lock:
            return [line for line in self.lines if keep(line)]

    def wait_for(self, keep: Callable[[str], bool], count: int, what: str,
                 process: subprocess.Popen) -> None:
        """Until ``count`` lines satisfy ``keep``; fails naming ``what`` after WAIT_S or
        when the process ended."""
        deadline = time.monotonic() + WAIT_S
        while len(self.matching(keep)) < count:
            assert process.poll() is None, f'the monitor ended before {what}: {self.lines}'
            assert time.monotonic() < deadline, f'no {what} within {WAIT_S:.0f} s: {self.lines}'
            time.sleep(0.02)

    def close(self) -> list[str]:
        """Every line, once the process closed its stdout."""
        self._thread.join(timeout=WAIT_S)
        with self._lock:
            return list(self.lines)


def is_report(line: str) -> bool:
    return 'processed 440' in line


def test_one_line_per_report_and_an_idle_final_state(fake_node: Node) -> None:
    """Each report is published once the monitor has printed the one before (so the
    count is exact over a reliable topic), then a report period passes, in which a
    monitor printing once per poll would print the same line again."""
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    fake_node.create_publisher(UInt16, 'speed_limit', latched).publish(UInt16(data=80))
    diagnostics = fake_node.create_publisher(DiagnosticArray, '/diagnostics', 10)
    monitor = subprocess.Popen([tool('speed_sign_monitor'), '--timeout', '30'],
                               env=dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID),
                                        PYTHONUNBUFFERED='1'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    output = OutputLines(monitor)
    try:
        deadline = time.monotonic() + WAIT_S
        while diagnostics.get_subscription_count() == 0:
            assert time.monotonic() < deadline, 'the monitor did not subscribe'
            time.sleep(0.05)
        # the latched limit reaches it: a line of its own
        output.wait_for(lambda line: line.startswith('limit 80 km/h'), 1, 'the limit',
                        monitor)
        for index in range(REPORTS):
            diagnostics.publish(status(index))
            output.wait_for(is_report, index + 1, f'the line of report {index + 1}', monitor)
            time.sleep(REPORT_PERIOD_S)  # the node's reporting period, the span checked
    finally:
        monitor.send_signal(signal.SIGTERM)
        monitor.wait(timeout=WAIT_S)
    lines = output.close()
    errors = monitor.stderr.read()
    assert monitor.returncode == 0, errors
    *reports, final = lines
    report_lines = [line for line in reports if is_report(line)]
    assert len(report_lines) == REPORTS, lines       # one per report, none repeated
    assert len(set(report_lines)) == REPORTS, lines
    assert final.startswith('final state: limit 80 km/h'), lines
    assert 'idle, last image 6 s ago' in final and 'fps 0.0' not in final
    assert 'transport (stamp to receipt) p50 4 p95 9 ms' in final
    assert 'lost in transport 3' in final and final.endswith('gl OK')
