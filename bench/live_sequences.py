"""The installed node over real DDS: how many truth signs it recognizes, how many frames
DDS loses on the way, with and without the shipped Fast DDS profile.

Usage::

    python bench/live_sequences.py BAG --truth TRUTH.csv [--runs profile,default]
        [--reliable] [--params-file FILE] [--json]

For each run (``profile``: ``FASTRTPS_DEFAULT_PROFILES_FILE`` set to
``config/fastdds_large_images.xml`` for both the replay and the node, as the README's
deployment steps say; ``default``: Fast DDS defaults), in a ROS domain of its own:

1. start the installed ``speed_sign_detector`` with its image topic remapped to the
   bag's, and wait until it serves (its latched ``speed_limit`` arrives);
2. replay the bag with ``speed_sign_replay`` at its recorded rate, best effort like a
   camera driver (``--reliable`` for reliable), with the recorded header stamps;
3. listen to ``candidates``, ``speed_limit`` and ``/diagnostics`` here, then stop the
   node with SIGTERM;
4. grade as ``speed_sign_eval bag --truth`` does (:func:`score_drive` over the truth
   tracks of :mod:`speed_sign_detector.truth`): a recognition is a change of the
   published limit, at the stamp of the candidates message just before it, at the
   position of the candidate carrying that value. Unlike the offline tool, a sign that
   repeats the limit already active changes nothing on ``speed_limit`` and so cannot
   be seen as recognized here.

Prints one line per run (recognized / signs, wrong limits, frames the node received and
processed, ``frames_lost_in_transport`` from its last diagnostics report) on stderr and,
with ``--json``, one JSON object with every run as the last line of stdout. Exit status
1 when a run could not be made (the node did not start, the replay failed).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import UInt16

from speed_sign_detector.bag_io import COMPRESSED_IMAGE_MSGTYPE, BagReader, header_stamp_ns
from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.ros.messages import pointcloud_to_array
from speed_sign_detector.tools.bag_grading import DEFAULT_GRACE_S, LimitEvent, score_drive
from speed_sign_detector.truth import group_tracks, read_truth

PROJECT_ROOT = Path(__file__).resolve().parents[1]
PROFILE = PROJECT_ROOT / 'config' / 'fastdds_large_images.xml'
RUNS = ('profile', 'default')
#: ROS domain of the first run (each run takes the next one).
FIRST_DOMAIN_ID = 71
START_TIMEOUT_S = 180.0
SETTLE_S = 3.0


class LiveRunError(SpeedSignError):
    """A run could not be made (node or replay failed)."""


@dataclass
class RunResult:
    """One run's figures (see the module docstring)."""

    run: str
    profile_file: str | None
    signs: int | None = None
    recognized: int | None = None
    wrong_limits: int | None = None
    frames_in_bag: int = 0
    frames_received: int | None = None
    frames_processed: int | None = None
    frames_lost_in_transport: int | None = None
    frames_lost_in_transport_share: float | None = None
    limit_changes: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None


class Listener:
    """Collects the node's outputs in a context of its own."""

    def __init__(self, domain_id: int) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('live_sequences_listener', context=self.context)
        self.lock = threading.Lock()
        self.last_cloud: tuple[float, Any] | None = None
        self.events: list[LimitEvent] = []
        self.limits: list[int] = []
        self.status: dict[str, str] | None = None
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(PointCloud2, 'candidates', self._on_cloud, 50)
        self.node.create_subscription(UInt16, 'speed_limit', self._on_limit, latched)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_status, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_cloud(self, msg: PointCloud2) -> None:
        stamp_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self.lock:
            self.last_cloud = (stamp_s, pointcloud_to_array(msg))

    def _on_limit(self, msg: UInt16) -> None:
        limit = int(msg.data)
        with self.lock:
            first = not self.limits
            self.limits.append(limit)
            if first or self.last_cloud is None:
                return  # the value published at start-up
            stamp_s, points = self.last_cloud
            carrying = points[points['limit_kmh'] == limit] if limit else points[:0]
            if carrying.size:
                best = carrying[carrying['psr'].argmax()]
                x_px, y_px = float(best['u']), float(best['v'])
            else:
                x_px = y_px = math.nan
            self.events.append(LimitEvent(stamp_s, limit, x_px, y_px))

    def _on_status(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {item.key: item.value for item in status.values}
            if 'frames_lost_in_transport' in values:
                with self.lock:
                    self.status = values

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
        self.thread.join(timeout=10)


def installed(name: str) -> str:
    """An installed console script (beside this interpreter, else on PATH)."""
    search = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get('PATH', '')])
    found = shutil.which(name, path=search)
    if found is None:
        raise LiveRunError(f'{name} is not installed (pip install -e . or colcon build)')
    return found


def run_once(run: str, domain_id: int, bag: Path, topic: str, compressed: bool,
             args: argparse.Namespace, bag_stamps_s: list[float], tracks: Any,
             log_dir: Path) -> RunResult:
    """One run: node + replay + listener; see the module docstring."""
    environment = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
    environment.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    if run == 'profile':
        environment['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(PROFILE)
    result = RunResult(run, environment.get('FASTRTPS_DEFAULT_PROFILES_FILE'),
                       frames_in_bag=len(bag_stamps_s))
    remap = 'image/compressed' if compressed else 'image'
    command = [installed('speed_sign_detector'), '--ros-args', '-r', f'{remap}:={topic}']
    if args.params_file:
        command += ['--params-file', str(args.params_file)]
    node_log_path = log_dir / f'node_{run}.log'
    listener = Listener(domain_id)
    with node_log_path.open('w') as node_log:
        node = subprocess.Popen(command, env=environment, stdout=node_log,
                                stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not listener.limits:
            if node.poll() is not None or time.monotonic() > deadline:
                raise LiveRunError(f'the node did not start (see {node_log_path})')
            time.sleep(0.1)
        replay_command = [installed('speed_sign_replay'), str(bag), '--topic', topic,
                          '--wait', '30', '-q']
        if not args.reliable:
            replay_command.append('--best-effort')
        print(f'[{run}] replaying {bag} ({len(bag_stamps_s)} frames)', file=sys.stderr)
        replay = subprocess.run(replay_command, env=environment, capture_output=True,
                                text=True, check=False)
        if replay.returncode != 0:
            raise LiveRunError(f'speed_sign_replay failed: {replay.stderr.strip()}')
        time.sleep(SETTLE_S)  # the last frames are processed, diagnostics reported
    except LiveRunError as err:
        result.error = str(err)
    finally:
        if node.poll() is None:
            node.send_signal(signal.SIGTERM)
        try:
            node.wait(timeout=60)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
        listener.close()
    with listener.lock:
        events, status = list(listener.events), listener.status
        result.limit_changes = [asdict(event) for event in events]
    if status is not None:
        result.frames_received = int(status['frames_received'])
        result.frames_processed = int(status['frames_processed'])
        result.frames_lost_in_transport = int(status['frames_lost_in_transport'])
        result.frames_lost_in_transport_share = float(
            status.get('frames_lost_in_transport_share', 'nan'))
    if result.error is None:
        score = score_drive(tracks, events, bag_stamps_s, args.grace)
        result.signs, result.recognized = score.signs, score.recognized
        result.wrong_limits = score.wrong_limits
    return result


def describe(result: RunResult) -> str:
    """One line for a person."""
    if result.error:
        return f'[{result.run}] failed: {result.error}'
    return (f'[{result.run}] recognized {result.recognized} of {result.signs} signs, '
            f'{result.wrong_limits} wrong limits; node received {result.frames_received} '
            f'of {result.frames_in_bag} frames, processed {result.frames_processed}, '
            f'frames_lost_in_transport {result.frames_lost_in_transport} '
            f'(share {result.frames_lost_in_transport_share})')


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path, help='bag with the image topic (ROS 2 or 1)')
    parser.add_argument('--truth', type=Path, required=True, help='truth CSV')
    parser.add_argument('--topic', help='image topic (needed when the bag has several)')
    parser.add_argument('--runs', default=','.join(RUNS),
                        help=f'comma-separated runs out of {", ".join(RUNS)} (default all)')
    parser.add_argument('--reliable', action='store_true',
                        help='replay with reliable QoS (default best effort, as a camera)')
    parser.add_argument('--params-file', type=Path, help='parameter file for the node')
    parser.add_argument('--grace', type=float, default=DEFAULT_GRACE_S,
                        help='seconds after a sign left the view a recognition counts')
    parser.add_argument('--logs', type=Path, default=Path('out/live_sequences'),
                        help='folder for the node logs (default out/live_sequences)')
    parser.add_argument('--json', action='store_true',
                        help='print every run as one JSON object, last line of stdout')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the measurement; returns the exit status."""
    args = build_parser().parse_args(argv)
    runs = [run.strip() for run in args.runs.split(',') if run.strip()]
    unknown = sorted(set(runs) - set(RUNS))
    if unknown:
        print(f'live_sequences: error: unknown run(s) {", ".join(unknown)}', file=sys.stderr)
        return 2
    try:
        tracks = group_tracks(read_truth(args.truth))
        with BagReader(args.bag) as bag:
            image_topic = bag.image_topic(args.topic)
            stamps_s = [header_stamp_ns(item.message, item.log_time_ns) * 1e-9
                        for item in bag.messages(image_topic.name)]
    except SpeedSignError as err:
        print(f'live_sequences: error: {err}', file=sys.stderr)
        return 1
    args.logs.mkdir(parents=True, exist_ok=True)
    results = []
    for index, run in enumerate(runs):
        result = run_once(run, FIRST_DOMAIN_ID + index, args.bag, image_topic.name,
                          image_topic.msgtype == COMPRESSED_IMAGE_MSGTYPE, args, stamps_s,
                          tracks, args.logs)
        print(describe(result), file=sys.stderr)
        results.append(result)
    if args.json:
        print(json.dumps({'bag': str(args.bag), 'truth': str(args.truth),
                          'runs': [asdict(result) for result in results]}))
    return 1 if any(result.error for result in results) else 0


if __name__ == '__main__':
    sys.exit(main())
