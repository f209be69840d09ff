"""End-to-end benchmark of the node through DDS: fps, latency, drops, resident memory.

Starts the installed ``speed_sign_detector`` executable as its own process (as ``ros2
run`` would), publishes 640x480 bgr8 frames of a synthetic drive (signs, look-alikes,
distractors, blur) from this process at fixed rates (30 Hz, then faster) and matches
each ``candidates`` message to its frame by the header stamp.

Figures per rate:
    output_fps: candidates messages received per second (the node's throughput).
    latency_p50_ms / latency_p95_ms: publish of a frame -> receipt of its candidates.
    dropped: frames published but never answered (the node drops stale frames on purpose
        when it cannot keep up; the node's own count is ``node_frames_dropped``).
    node_received / node_frames_dropped / node_lost_in_transport: the node's own counts
        (the middleware reports some, not all, samples lost on the way).
    pipeline_total_p50_ms: the pipeline's own processing time per frame (median).
    pipeline_stage_p50_ms: the same per stage (detect, classify, track).
    rss_mb: resident memory of the node process, peak over the run (from /proc).

Usage:
    python bench/bench_node.py [--rates 30 60] [--seconds 10] [--json]

Progress goes to stderr; with ``--json`` the last stdout line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, TypeVar

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header, UInt16

from bench_inputs import (
    DDS_PROFILE,
    PARAMS_FILE,
    MissingExecutableError,
    drive_frames,
    installed_executable,
)
from speed_sign_detector.ros.messages import image_message
TARGET_FPS = 30.0
TARGET_RSS_MB = 400.0
#: Longest wait for the node to subscribe and publish its first speed limit, seconds.
NODE_START_TIMEOUT_S = 300.0
#: Longest wait for the node to exit after SIGINT before it is killed, seconds.
NODE_STOP_TIMEOUT_S = 30.0


class NodeBenchError(Exception):
    """The node could not be started or did not come up; the message says why."""


@dataclass(frozen=True)
class RateResult:
    """Figures of one publishing rate (see the module docstring)."""

    publish_hz: float
    seconds: float
    published: int
    answered: int
    dropped: int
    output_fps: float
    latency_p50_ms: float
    latency_p95_ms: float
    node_frames_dropped: int
    node_latency_p95_ms: float
    node_received: int
    node_lost_in_transport: int
    pipeline_total_p50_ms: float
    pipeline_stage_p50_ms: dict[str, float]
    rss_mb: float


def resident_mb(pid: int) -> float:
    """Resident set size of a process in MiB (VmRSS from /proc)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return float('nan')


class BenchClient(Node):
    """Publishes frames on a timer and times the node's answers."""

    def __init__(self, frames: list[np.ndarray]) -> None:
        super().__init__('speed_sign_bench')
        self.messages = [image_message(frame, Header(frame_id='camera'), image_class=Image)
                         for frame in frames]
        self.lock = threading.Lock()
        self.sent_at: dict[int, float] = {}
        self.latencies_ms: list[float] = []
        self.limits: list[int] = []
        self.diagnostics: dict[str, str] = {}
        self.publisher = self.create_publisher(Image, 'image', qos_profile_sensor_data)
        self.create_subscription(PointCloud2, 'candidates', self._on_candidates, 100)
        self.create_subscription(UInt16, 'speed_limit', lambda msg: self.limits.append(msg.data),
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.timer = None
        self.count = 0
        self.stamp_ns = time.time_ns()

    def start(self, rate_hz: float) -> None:
        with self.lock:
            self.sent_at.clear()
            self.latencies_ms.clear()
        self.count = 0
        self.timer = self.create_timer(1.0 / rate_hz, self._publish)

    def stop(self) -> None:
        if self.timer is not None:
            self.destroy_timer(self.timer)
            self.timer = None

    def _publish(self) -> None:
        msg = self.messages[self.count % len(self.messages)]
        self.stamp_ns = max(self.stamp_ns + 1, time.time_ns())
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.stamp_ns, 1_000_000_000)
        with self.lock:
            self.sent_at[self.stamp_ns] = time.perf_counter()
        self.publisher.publish(msg)
        self.count += 1

    def _on_candidates(self, msg: PointCloud2) -> None:
        received = time.perf_counter()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            sent = self.sent_at.get(stamp)
            if sent is not None:
                self.latencies_ms.append((received - sent) * 1e3)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith(': pipeline'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}


def run_rate(client: BenchClient, pid: int, rate_hz: float, seconds: float) -> RateResult:
    """Publish at ``rate_hz`` for ``seconds`` and collect the figures."""
    dropped_before = int(client.diagnostics.get('frames_dropped', 0))
    received_before = int(client.diagnostics.get('frames_received', 0))
    lost_before = int(client.diagnostics.get('frames_lost_in_transport', 0))
    client.start(rate_hz)
    rss = 0.0
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        time.sleep(0.25)
        rss = max(rss, resident_mb(pid))
    client.stop()
    time.sleep(1.0)  # answers still in flight
    time.sleep(1.2)  # one more diagnostics period
    with client.lock:
        latencies = np.array(client.latencies_ms)
        published = len(client.sent_at)
    answered = int(latencies.size)
    return RateResult(
        publish_hz=rate_hz, seconds=seconds, published=published, answered=answered,
        dropped=published - answered, output_fps=answered / seconds,
        latency_p50_ms=float(np.percentile(latencies, 50)) if answered else float('nan'),
        latency_p95_ms=float(np.percentile(latencies, 95)) if answered else float('nan'),
        node_frames_dropped=int(client.diagnostics.get('frames_dropped', 0)) - dropped_before,
        node_latency_p95_ms=float(client.diagnostics.get('processing_latency_p95_ms', 'nan')),
        node_received=int(client.diagnostics.get('frames_received', 0)) - received_before,
        node_lost_in_transport=int(client.diagnostics.get('frames_lost_in_transport', 0))
        - lost_before,
        pipeline_total_p50_ms=float(client.diagnostics.get('pipeline_total_p50_ms', 'nan')),
        pipeline_stage_p50_ms={key[len('pipeline_'):-len('_p50_ms')]: float(value)
                               for key, value in client.diagnostics.items()
                               if key.startswith('pipeline_') and key.endswith('_p50_ms')},
        rss_mb=rss)


def add_node_arguments(parser: argparse.ArgumentParser, domain_id: int) -> None:
    """The options saying how the node is started: ``--domain-id``, ``--bank-cache``,
    ``--node-arg``, ``--dds-profile``, and ``--json``."""
    parser.add_argument('--domain-id', type=int, default=domain_id)
    parser.add_argument('--bank-cache', default=str(Path(tempfile.gettempdir())
                                                    / 'speed_sign_detector_banks'),
                        help='classifier filter-bank cache folder')
    parser.add_argument('--node-arg', action='append', default=[],
                        help='extra --ros-args argument for the node (e.g. -p backend:=numpy)')
    parser.add_argument('--dds-profile', default=str(DDS_PROFILE),
                        help='Fast DDS profile for both processes unless '
                        'FASTRTPS_DEFAULT_PROFILES_FILE is set ("" = Fast DDS defaults, '
                        'which lose large best-effort frames)')
    parser.add_argument('--json', action='store_true', help='print one JSON object last')


ClientType = TypeVar('ClientType', bound=BenchClient)


@contextmanager
def node_and_client(args: argparse.Namespace, make_client: Callable[[], ClientType],
                    node_output: IO[str] | None = None,
                    node_environment: Mapping[str, str] | None = None
                    ) -> Iterator[tuple[subprocess.Popen, ClientType]]:
    """The installed node as its own process and a client spinning on a thread beside it.

    Starts ``speed_sign_detector`` (the package's parameter file, the bank cache and
    ``args.node_arg``; ROS domain ``args.domain_id``), then ``make_client()`` in this
    process, and waits until the node subscribes to the client's publisher and has
    published its first speed limit. On leaving, the node gets SIGINT (killed after
    :data:`NODE_STOP_TIMEOUT_S`), then the client's executor, node and context stop.

    Args:
        args: parsed options of :func:`add_node_arguments`.
        make_client: builds the client (called after ``rclpy.init``).
        node_output: where the node's stdout and stderr go (default: stdout discarded,
            stderr to this process's stderr).
        node_environment: variables added to the node's environment.

    Raises:
        NodeBenchError: the node is not installed, exited, or did not come up within
            :data:`NODE_START_TIMEOUT_S`.
    """
    if args.dds_profile and 'FASTRTPS_DEFAULT_PROFILES_FILE' not in os.environ:
        os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = args.dds_profile
    environment = dict(os.environ, **(node_environment or {}),
                       ROS_DOMAIN_ID=str(args.domain_id))
    try:
        executable = installed_executable('speed_sign_detector')
    except MissingExecutableError as err:
        raise NodeBenchError(str(err)) from err
    command = [executable, '--ros-args', '--params-file',
               str(PARAMS_FILE), '-p', f'classifier.cache_dir:={args.bank_cache}',
               *args.node_arg]
    node_process = subprocess.Popen(
        command, env=environment,
        stdout=subprocess.DEVNULL if node_output is None else node_output,
        stderr=sys.stderr if node_output is None else subprocess.STDOUT)
    os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    rclpy.init(args=[])
    client = make_client()
    executor = SingleThreadedExecutor()
    executor.add_node(client)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        started = time.monotonic()
        while not client.limits or client.publisher.get_subscription_count() == 0:
            if node_process.poll() is not None:
                raise NodeBenchError(f'node exited with {node_process.returncode}')
            if time.monotonic() - started > NODE_START_TIMEOUT_S:
                raise NodeBenchError(f'node did not come up within '
                                     f'{NODE_START_TIMEOUT_S:.0f} s')
            time.sleep(0.1)
        print(f'node up after {time.monotonic() - started:.1f} s; idle RSS '
              f'{resident_mb(node_process.pid):.0f} MiB', file=sys.stderr)
        yield node_process, client
    finally:
        node_process.send_signal(signal.SIGINT)
        try:
            node_process.wait(timeout=NODE_STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            node_process.kill()
            node_process.wait()
        executor.shutdown()
        spinner.join(timeout=10)   # a spinning thread left at exit aborts the process
        client.destroy_node()
        rclpy.try_shutdown()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rates', type=float, nargs='+', default=[30.0, 60.0],
                        help='publishing rates in Hz, run in order')
    parser.add_argument('--seconds', type=float, default=10.0, help='duration per rate')
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--frames', type=int, default=120,
                        help='distinct synthetic-drive frames, published in a loop')
    add_node_arguments(parser, domain_id=97)
    args = parser.parse_args(argv)
    results: list[RateResult] = []
    try:
        with node_and_client(args, lambda: BenchClient(
                drive_frames(args.width, args.height, args.frames))) as (node_process, client):
            run_rate(client, node_process.pid, 30.0, 2.0)  # warm-up
            for rate in args.rates:
                result = run_rate(client, node_process.pid, rate, args.seconds)
                results.append(result)
                print(f'{rate:5.0f} Hz: {result.output_fps:5.1f} fps out, latency p50 '
                      f'{result.latency_p50_ms:6.1f} ms p95 {result.latency_p95_ms:6.1f} ms, '
                      f'{result.dropped}/{result.published} unanswered (node received '
                      f'{result.node_received}, dropped {result.node_frames_dropped}, saw '
                      f'{result.node_lost_in_transport} lost in transport), '
                      f'pipeline p50 {result.pipeline_total_p50_ms:.0f} ms ('
                      + ', '.join(f'{stage} {value:.0f}' for stage, value
                                  in result.pipeline_stage_p50_ms.items() if stage != 'total')
                      + '), '
                      f'RSS {result.rss_mb:.0f} MiB', file=sys.stderr)
    except NodeBenchError as err:
        print(err, file=sys.stderr)
        return 1
    summary = {
        'width': args.width, 'height': args.height,
        'backend': client.diagnostics.get('backend', ''),
        'renderer': client.diagnostics.get('gl_renderer', ''),
        'backend_choice': client.diagnostics.get('backend_choice', ''),
        'rates': [asdict(result) for result in results],
        'targets': {'fps': TARGET_FPS, 'rss_mb': TARGET_RSS_MB},
        'meets_fps_target': bool(results) and results[0].output_fps >= 0.95 * TARGET_FPS
        and results[0].publish_hz >= TARGET_FPS,
        'meets_rss_target': bool(results) and max(r.rss_mb for r in results) < TARGET_RSS_MB,
    }
    if args.json:
        print(json.dumps(summary))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
