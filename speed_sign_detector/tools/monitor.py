"""``speed_sign_monitor``: watch a running detector node.

Example::

    speed_sign_monitor                  # live status line, Ctrl-C to stop
    speed_sign_monitor --once --json    # one snapshot as JSON, for scripts

Subscribes to ``speed_limit`` (std_msgs/UInt16, reliable + transient local, so the
current value arrives at once), ``candidates`` (sensor_msgs/PointCloud2) and
``/diagnostics`` (the node's status: the one whose values hold ``frames_processed``,
or the one named by ``--status``). The status line shows the active limit, candidates
per frame, the node's processing rate and latency, and dropped frames.

On a terminal the line is refreshed in place; otherwise (and with ``--json``) one line
is printed per diagnostics report of the node (or change of limit), and Ctrl-C prints
the last state as ``final state: ...``. "transport (stamp to receipt)" is the time from
the image's header stamp to its arrival at the node: transport only, processing is
shown apart. A node whose stream ended shows as idle.

``--once`` waits until all three topics were heard and a diagnostics report counts
processed frames, or the limit and two diagnostics reports of a node whose stream has
ended (or ``--timeout`` passes), prints one snapshot
and exits. Exit status 1 with a message when nothing at all was published
within ``--timeout`` seconds (is the node running, in the same ROS_DOMAIN_ID?).
ROS arguments (``--ros-args -r speed_limit:=/car/speed_limit``) are accepted.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any

from speed_sign_detector import __version__
from speed_sign_detector.ros.messages import pointcloud_to_array
from speed_sign_detector.tools.cli_types import positive_number

#: Diagnostics values copied into the snapshot (key in the node's status -> snapshot field).
DIAGNOSTIC_FIELDS: dict[str, str] = {
    'processing_fps': 'fps',
    'latency_p50_ms': 'latency_p50_ms',
    'latency_p95_ms': 'latency_p95_ms',
    'processing_latency_p50_ms': 'processing_latency_p50_ms',
    'processing_latency_p95_ms': 'processing_latency_p95_ms',
    'frames_received': 'frames_received',
    'frames_processed': 'frames_processed',
    'frames_dropped': 'frames_dropped',
    'frames_rejected_bad_input': 'frames_rejected',
    'frames_lost_in_transport': 'frames_lost_in_transport',
    'frames_lost_in_transport_share': 'frames_lost_in_transport_share',
    'seconds_since_last_image': 'seconds_since_last_image',
    'backend': 'backend',
}
#: A node that processed no frame since its last report and got no image for this many
#: seconds is shown as idle (its stream ended) rather than at "fps 0.0".
IDLE_AFTER_S = 1.5


@dataclass
class MonitorSnapshot:
    """What the monitor knows now (None = not heard yet).

    Attributes:
        active_limit_kmh: last value on ``speed_limit`` (0 = none known).
        candidates_per_frame: points in the last ``candidates`` message.
        candidates_per_frame_mean: mean over the last 30 ``candidates`` messages.
        candidate_limits_kmh: limits the classifier gave the last frame's candidates.
        candidates_hz: rate of ``candidates`` messages over the last 30, Hz.
        fps, latency_p50_ms, latency_p95_ms, processing_latency_p50_ms,
        processing_latency_p95_ms, frames_received, frames_processed, frames_dropped,
        frames_rejected, frames_lost_in_transport, frames_lost_in_transport_share,
        seconds_since_last_image, backend: from the node's ``/diagnostics`` status
        (``latency_*`` is the stamp latency: receipt time minus header stamp, i.e. the
        time in transport, processing not included).
        status_level, status_message, status_name: that status' level, message, name.
        messages: messages heard per topic.
        age_s: seconds since the last message of any topic.
    """

    active_limit_kmh: int | None = None
    candidates_per_frame: int | None = None
    candidates_per_frame_mean: float | None = None
    candidate_limits_kmh: list[int] | None = None
    candidates_hz: float | None = None
    fps: float | None = None
    latency_p50_ms: float | None = None
    latency_p95_ms: float | None = None
    processing_latency_p50_ms: float | None = None
    processing_latency_p95_ms: float | None = None
    frames_received: int | None = None
    frames_processed: int | None = None
    frames_dropped: int | None = None
    frames_rejected: int | None = None
    frames_lost_in_transport: int | None = None
    frames_lost_in_transport_share: float | None = None
    seconds_since_last_image: float | None = None
    backend: str | None = None
    status_level: str | None = None
    status_message: str | None = None
    status_name: str | None = None
    messages: dict[str, int] = field(default_factory=lambda: {
        'speed_limit': 0, 'candidates': 0, 'diagnostics': 0})
    age_s: float | None = None

    def status_line(self) -> str:
        """One line for a terminal."""
        def show(value: Any, fmt: str = '{}') -> str:
            unknown = value is None or (isinstance(value, float) and math.isnan(value))
            return '-' if unknown else fmt.format(value)

        limit = ('none' if self.active_limit_kmh == 0 else
                 show(self.active_limit_kmh, '{} km/h'))
        if isinstance(self.latency_p50_ms, (int, float)) and self.latency_p50_ms > 60_000:
            transport = 'old stamps'   # a replayed bag without --restamp
        else:
            transport = (f'p50 {show(self.latency_p50_ms, "{:.0f}")} p95 '
                         f'{show(self.latency_p95_ms, "{:.0f}")} ms')
        if self.is_idle():
            rate = f'idle, last image {self.seconds_since_last_image:.0f} s ago'
        else:
            rate = f'fps {show(self.fps, "{:.1f}")}'
        return (f'limit {limit} | candidates {show(self.candidates_per_frame)}'
                f' (mean {show(self.candidates_per_frame_mean, "{:.1f}")}) | {rate} | '
                f'processing p50 {show(self.processing_latency_p50_ms, "{:.0f}")} p95 '
                f'{show(self.processing_latency_p95_ms, "{:.0f}")} ms | transport (stamp '
                f'to receipt) {transport} | processed {show(self.frames_processed)} '
                f'dropped {show(self.frames_dropped)} lost in transport '
                f'{show(self.frames_lost_in_transport)} | {show(self.backend)} '
                f'{show(self.status_level)}')

    def is_idle(self) -> bool:
        """True when the node processed frames before but none lately (stream ended)."""
        return (isinstance(self.seconds_since_last_image, (int, float))
                and self.seconds_since_last_image >= IDLE_AFTER_S
                and self.fps is not None and self.fps == 0
                and bool(self.frames_processed))


class _Monitor:
    """Subscriptions and the snapshot they fill."""

    def __init__(self, node: Any, status_name: str | None) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import (
            DurabilityPolicy,
            QoSProfile,
            ReliabilityPolicy,
            qos_profile_sensor_data,
        )
        from sensor_msgs.msg import PointCloud2
        from std_msgs.msg import UInt16

        self.snapshot = MonitorSnapshot()
        self._status_name = status_name
        self._cloud_times: deque[float] = deque(maxlen=30)
        self._cloud_sizes: deque[int] = deque(maxlen=30)
        self._last_message: float | None = None
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.subscriptions = [
            node.create_subscription(UInt16, 'speed_limit', self._on_limit, latched),
            node.create_subscription(PointCloud2, 'candidates', self._on_candidates,
                                     qos_profile_sensor_data),
            node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                     10),
        ]

    def heard_any(self) -> bool:
        return any(self.snapshot.messages.values())

    def heard_all(self) -> bool:
        return all(self.snapshot.messages.values())

    def refresh_age(self) -> None:
        if self._last_message is not None:
            self.snapshot.age_s = round(time.monotonic() - self._last_message, 3)

    def _heard(self, topic: str) -> None:
        self.snapshot.messages[topic] += 1
        self._last_message = time.monotonic()

    def _on_limit(self, msg: Any) -> None:
        self.snapshot.active_limit_kmh = int(msg.data)
        self._heard('speed_limit')

    def _on_candidates(self, msg: Any) -> None:
        points = pointcloud_to_array(msg)
        snapshot = self.snapshot
        snapshot.candidates_per_frame = int(points.size)
        if points.dtype.names and 'limit_kmh' in points.dtype.names:
            snapshot.candidate_limits_kmh = [int(v) for v in points['limit_kmh'] if v > 0]
        self._cloud_times.append(time.monotonic())
        self._cloud_sizes.append(int(points.size))
        snapshot.candidates_per_frame_mean = round(
            sum(self._cloud_sizes) / len(self._cloud_sizes), 2)
        if len(self._cloud_times) > 1:
            span = self._cloud_times[-1] - self._cloud_times[0]
            snapshot.candidates_hz = round((len(self._cloud_times) - 1) / span, 2) \
                if span > 0 else None
        self._heard('candidates')

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            values = {item.key: item.value for item in status.values}
            if self._status_name is not None:
                if status.name != self._status_name:
                    continue
            elif 'frames_processed' not in values:
                continue
            snapshot = self.snapshot
            for key, name in DIAGNOSTIC_FIELDS.items():
                if key in values:
                    setattr(snapshot, name, _parse(values[key]))
            level = status.level
            level_value = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
            snapshot.status_level = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}.get(
                level_value, str(level_value))
            snapshot.status_message = str(status.message)
            snapshot.status_name = str(status.name)
            self._heard('diagnostics')
            return


def _parse(text: str) -> Any:
    """Diagnostic values are strings: ints and floats are returned as numbers, and
    ``nan`` (the node's "no value yet", e.g. a latency before the first frame) as None,
    shown ``-`` like a field not heard yet (and ``null`` in JSON)."""
    for kind in (int, float):
        try:
            value = kind(text)
        except ValueError:
            continue
        return None if isinstance(value, float) and math.isnan(value) else value
    return text


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments of ``speed_sign_monitor``."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_monitor',
        description='Show the state of a running speed_sign_detector node.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('--once', action='store_true',
                        help='print one snapshot (after hearing every topic, or at the '
                        'timeout) and exit')
    parser.add_argument('--json', action='store_true', help='print snapshots as JSON')
    parser.add_argument('--timeout', type=positive_number, default=10.0,
                        help='give up when nothing is published for this many seconds '
                        '(default 10)')
    parser.add_argument('--status', help='name of the /diagnostics status to show (default: '
                        'the one with frames_processed)')
    parser.add_argument('--interval', type=positive_number, default=0.5,
                        help='seconds between refreshes of the status line on a terminal '
                        '(default 0.5)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_monitor``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        import diagnostic_msgs.msg  # noqa: F401 - checked here, used by _Monitor
        import rclpy
        import sensor_msgs.msg  # noqa: F401
        import std_msgs.msg  # noqa: F401
        from rclpy.executors import ExternalShutdownException
        from rclpy.utilities import remove_ros_args
    except ImportError as err:
        from speed_sign_detector.ros.entry_point import missing_ros_message
        print(missing_ros_message('speed_sign_monitor', err), file=sys.stderr)
        return 1
    args = build_parser().parse_args(remove_ros_args(['speed_sign_monitor', *argv])[1:])
    rclpy.init(args=['speed_sign_monitor', *argv])
    node = rclpy.create_node('speed_sign_monitor')
    monitor: _Monitor | None = None
    try:
        monitor = _Monitor(node, args.status)
        return _run(node, monitor, args)
    except (KeyboardInterrupt, ExternalShutdownException):
        if monitor is None or not monitor.heard_any():
            return 130
        _print_snapshot(monitor.snapshot, args, prefix='\nfinal state: ' if
                        sys.stdout.isatty() and not args.json else 'final state: ')
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _print_snapshot(snapshot: MonitorSnapshot, args: argparse.Namespace,
                    prefix: str = '') -> None:
    if args.json:
        print(json.dumps(asdict(snapshot)), flush=True)
    else:
        print(prefix + snapshot.status_line(), flush=True)


def _once_complete(monitor: _Monitor) -> bool:
    """--once: every topic heard and a diagnostics report that counts the frames behind
    the candidates (an earlier report may predate the first frame), or the node's stream
    has ended (limit and two diagnostics reports heard, which say it processed frames
    but is idle now: no candidates will come)."""
    snapshot = monitor.snapshot
    serving = monitor.heard_all() and (snapshot.frames_processed or 0) > 0
    return serving or (snapshot.messages['speed_limit'] > 0
                       and snapshot.messages['diagnostics'] >= 2
                       and snapshot.is_idle())


def _run(node: Any, monitor: _Monitor, args: argparse.Namespace) -> int:
    """Spin until --once is satisfied or nothing is heard for --timeout. On a terminal
    the status line is refreshed in place every --interval; otherwise (and with --json)
    a line is printed for each new diagnostics report or limit, not more often."""
    import rclpy

    started = time.monotonic()
    terminal = sys.stdout.isatty() and not args.json
    next_print = started + args.interval
    printed_state: tuple[int, int | None] | None = None
    while True:
        rclpy.spin_once(node, timeout_sec=0.05)
        now = time.monotonic()
        monitor.refresh_age()
        silent_s = (monitor.snapshot.age_s if monitor.heard_any() else now - started)
        if args.once:
            if _once_complete(monitor) or (now - started >= args.timeout):
                break
            continue
        if silent_s is not None and silent_s >= args.timeout:
            if terminal:
                print()
            break
        if terminal:
            if now >= next_print:
                next_print = now + args.interval
                print(f'\r{monitor.snapshot.status_line():<120}', end='', flush=True)
            continue
        state = (monitor.snapshot.messages['diagnostics'], monitor.snapshot.active_limit_kmh)
        if monitor.heard_any() and state != printed_state:
            printed_state = state
            _print_snapshot(monitor.snapshot, args)
    if not monitor.heard_any():
        print(f'speed_sign_monitor: error: nothing published on speed_limit, candidates or '
              f'/diagnostics within {args.timeout:g} s; is speed_sign_detector running with '
              f'the same ROS_DOMAIN_ID (here {_domain_id()}) and namespace?', file=sys.stderr)
        return 1
    if args.once:
        _print_snapshot(monitor.snapshot, args)
        return 0
    print(f'speed_sign_monitor: error: nothing published for {args.timeout:g} s; the node '
          f'stopped or its topics were remapped', file=sys.stderr)
    return 1


def _domain_id() -> str:
    import os

    return os.environ.get('ROS_DOMAIN_ID', '0')


if __name__ == '__main__':
    sys.exit(main())
