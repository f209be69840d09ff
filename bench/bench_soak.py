"""Soak benchmark of the node: hours at 30 Hz on a looping drive, memory and every frame.

Starts the installed ``speed_sign_detector`` executable as its own process (as
``bench_node.py`` does, with its helpers) and feeds it, from this process, the image topic
of a synthetic drive (made with ``speed_sign_synth``, 1280x720 JPEG by default) at a
steady 30 Hz, over and over for ``--minutes``. The stored messages are published as they
are (serialized bytes, no re-encoding), with their recorded header stamps: at each loop
the stamps jump back, as from a looped bag or a restarted camera, and the node must reset
its tracks without restarting. Publishing follows a ROS timer on a fixed grid (a tick
missed under load is skipped, not caught up in a burst), so the rate achieved is measured
and reported, never assumed.

Recorded:
    rss_mib: the node process's resident memory (/proc) every ``--rss-interval`` s; the
        figure after the first minute (``reference_s``), at the end, and the growth
        between them in % (target: at most 5 % over an hour), also to ``--rss-csv``.
    frames: published (by this process), answered (``candidates`` messages matched to the
        frame by header stamp and loop), node_dropped (the node's own count: replaced
        while waiting, or unreadable), lost_in_transport (published but never received by
        the node: published - the node's ``frames_received``), the node's own estimate of
        it from stamp gaps, and unaccounted (published - answered - node_dropped -
        lost_in_transport; target 0: every frame answered or counted as dropped).
    errors: ERROR/FATAL lines and Python tracebacks in the node's log output, and
        /diagnostics statuses at ERROR level; the node alive at the end as the same
        process (PID and start time unchanged), its counters never reset, the loops
        done and the stamp jumps it logged ('image stamps jumped back').
    host: CPU model and cores (``run_all``'s machine record), GL renderer and backend
        (the node's diagnostics), the load average at the start and the end.

Usage:
    python bench/bench_soak.py [--minutes 60] [--width 1280 --height 720]
        [--loop-seconds 20] [--bag DRIVE] [--rss-csv rss.csv] [--node-log node.log] [--json]

Progress goes to stderr once a minute; with ``--json`` the last stdout line is one JSON
object. Exit status 0 when the soak ran (the targets are judged in the JSON:
``meets_*``), 1 when it could not start.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, PointCloud2

from bench_inputs import MissingExecutableError, installed_executable
from bench_node import (
    BenchClient,
    NodeBenchError,
    add_node_arguments,
    node_and_client,
    resident_mb,
)
from speed_sign_detector.bag_io import COMPRESSED_IMAGE_MSGTYPE, BagReader, header_stamp_ns
from speed_sign_detector.errors import BagError, ImageConversionError
from speed_sign_detector.image_conversion import message_to_gray

#: Acceptance: the node's RSS at the end at most this much above the first minute's, %.
TARGET_RSS_GROWTH_PERCENT = 5.0
#: The RSS reference is taken this long after the start (or halfway, in shorter runs), s.
RSS_REFERENCE_S = 60.0
#: After the last frame, how long its answer may take, seconds.
ANSWER_WAIT_S = 3.0
#: After that, how long to wait for a diagnostics report with the final counts, seconds.
FINAL_DIAGNOSTICS_WAIT_S = 5.0
#: A publish later than this many frame periods after the previous one counts as late.
LATE_PUBLISH_PERIODS = 1.5
#: The node's console log format (fixed, so that the severity opens every line).
NODE_LOG_FORMAT = '[{severity}] [{time}] [{name}]: {message}'
#: How the node logs a jump back of the image stamps (detector_node_base).
STAMP_JUMP_LOG = 'image stamps jumped back'
#: Diagnostic status levels (diagnostic_msgs/DiagnosticStatus).
WARN_LEVEL, ERROR_LEVEL = 1, 2
#: Lines of each kind of error kept in the JSON (the count covers them all).
ERRORS_KEPT = 10


class SoakError(Exception):
    """The soak could not be set up (drive, bag); the message says why."""


# ------------------------------------------------------------------------ the drive
class LoopingDrive:
    """The image messages of a ROS 2 bag, over and over, as stored.

    Each call of :meth:`next_message` returns the next message; after the last one the
    bag starts again (a new loop: the header stamps jump back). ``width_px`` and
    ``height_px`` are the first frame's.
    """

    def __init__(self, path: Path) -> None:
        try:
            self.bag = BagReader(path)
            topic = self.bag.image_topic()
        except BagError as err:
            raise SoakError(str(err)) from err
        if not self.bag.is_ros2:
            raise SoakError(f'{path}: a ROS 1 bag; the soak publishes stored CDR bytes, '
                            f'so it needs a ROS 2 bag (MCAP or sqlite3)')
        self.topic = topic.name
        self.compressed = topic.msgtype == COMPRESSED_IMAGE_MSGTYPE
        self.frames_per_loop = topic.count
        self.loop = 0
        self._messages = self.bag.messages(self.topic)
        try:
            first = next(self.bag.messages(self.topic))
            self.height_px, self.width_px = message_to_gray(first.message).shape
        except (BagError, ImageConversionError, StopIteration) as err:
            raise SoakError(f'{path}: cannot read the first image: {err}') from err

    def next_message(self) -> tuple[int, int, bytes]:
        """(loop index from 0, header stamp in ns, serialized message)."""
        item = next(self._messages, None)
        if item is None:
            self.loop += 1
            self._messages = self.bag.messages(self.topic)
            item = next(self._messages)
        return self.loop, header_stamp_ns(item.message, item.log_time_ns), item.raw


def make_drive(out: Path, args: argparse.Namespace) -> Path:
    """Write the synthetic drive of ``args`` (size, length, seed, JPEG or raw) to the bag
    ``out`` with the installed ``speed_sign_synth``; returns ``out``."""
    try:
        executable = installed_executable('speed_sign_synth')
    except MissingExecutableError as err:
        raise SoakError(str(err)) from err
    command = [executable, str(out),
               '--duration', f'{args.loop_seconds:g}', '--seed', str(args.seed),
               '--width', str(args.width), '--height', str(args.height), '-q',
               *([] if args.raw else ['--compressed'])]
    try:
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    except subprocess.CalledProcessError as err:
        raise SoakError(f'speed_sign_synth exited with {err.returncode}: '
                        f'{" ".join(command)}') from err
    return out


# ----------------------------------------------------------------------- the client
class SoakClient(BenchClient):
    """``bench_node``'s client publishing a :class:`LoopingDrive` and matching each answer
    to its frame by stamp and loop; also counts diagnostics by level."""

    def __init__(self, drive: LoopingDrive) -> None:
        super().__init__([])
        if drive.compressed:
            self.destroy_publisher(self.publisher)
            self.publisher = self.create_publisher(CompressedImage, 'image/compressed',
                                                   qos_profile_sensor_data)
        self.drive = drive
        self.sent: dict[int, tuple[int, float]] = {}   # stamp ns -> (loop, publish time)
        self.answered_loop: dict[int, int] = {}         # stamp ns -> last loop answered
        self.published = 0
        self.answered = 0
        self.duplicate_answers = 0
        self.unmatched_answers = 0
        self.period_s = 0.0
        self.last_publish_s: float | None = None
        self.publish_gap_max_ms = 0.0
        self.late_publishes = 0
        self.diagnostics_at = 0.0
        self.counter_resets = 0
        self.status_counts = {'warn': 0, 'error': 0}
        self.error_statuses: list[str] = []
        self.publish_error = ''

    def start(self, rate_hz: float) -> None:
        self.period_s = 1.0 / rate_hz
        super().start(rate_hz)

    def _publish(self) -> None:
        try:
            loop, stamp_ns, data = self.drive.next_message()
        except (BagError, StopIteration) as err:   # a damaged or empty bag: stop publishing
            self.publish_error = f'{type(err).__name__}: {err}'
            self.stop()
            return
        now = time.perf_counter()
        with self.lock:
            self.sent[stamp_ns] = (loop, now)
            self.published += 1
            if self.last_publish_s is not None:
                gap_s = now - self.last_publish_s
                self.publish_gap_max_ms = max(self.publish_gap_max_ms, gap_s * 1e3)
                self.late_publishes += gap_s > LATE_PUBLISH_PERIODS * self.period_s
            self.last_publish_s = now
        self.publisher.publish(data)

    def _on_candidates(self, msg: PointCloud2) -> None:
        received = time.perf_counter()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            sent = self.sent.get(stamp)
            if sent is None:
                self.unmatched_answers += 1
                return
            loop, published_at = sent
            if self.answered_loop.get(stamp) == loop:
                self.duplicate_answers += 1
                return
            self.answered_loop[stamp] = loop
            self.answered += 1
            self.latencies_ms.append((received - published_at) * 1e3)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            level = status.level[0] if isinstance(status.level, bytes) else int(status.level)
            if level >= ERROR_LEVEL:
                self.status_counts['error'] += 1
                if len(self.error_statuses) < ERRORS_KEPT:
                    self.error_statuses.append(f'{status.name}: {status.message}')
            elif level == WARN_LEVEL:
                self.status_counts['warn'] += 1
        before = int(self.diagnostics.get('frames_received', 0))
        super()._on_diagnostics(msg)
        if int(self.diagnostics.get('frames_received', 0)) < before:
            self.counter_resets += 1
        self.diagnostics_at = time.monotonic()

    def node_count(self, key: str) -> int:
        """A counter of the node's latest diagnostics (0 before the first)."""
        return int(self.diagnostics.get(key, 0))


# ------------------------------------------------------------------- the node's side
class NodeLog:
    """The node's console output, read as it grows: errors, warnings, stamp jumps."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._offset = 0
        self.errors: list[str] = []
        self.error_count = 0
        self.warning_count = 0
        self.traceback_count = 0
        self.stamp_jumps = 0

    def scan(self) -> None:
        """Read the lines written since the last scan (complete lines only)."""
        with self.path.open('rb') as file:
            file.seek(self._offset)
            chunk = file.read()
        end = chunk.rfind(b'\n') + 1
        self._offset += end
        for line in chunk[:end].decode('utf-8', 'replace').splitlines():
            error = re.match(r'\[(ERROR|FATAL)\]', line) is not None
            traceback = line.startswith('Traceback (most recent call last)')
            self.error_count += error
            self.traceback_count += traceback
            self.warning_count += line.startswith('[WARN]')
            self.stamp_jumps += STAMP_JUMP_LOG in line
            if (error or traceback) and len(self.errors) < ERRORS_KEPT:
                self.errors.append(line.strip())


def process_start_ticks(pid: int) -> int | None:
    """When process ``pid`` started (clock ticks after boot, /proc/PID/stat field 22):
    with the PID, it names one process; None when there is no such process."""
    try:
        return int(Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def process_cpu_s(pid: int) -> float:
    """CPU time (user + system) process ``pid`` used so far, seconds; NaN when gone."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return float('nan')
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


# ----------------------------------------------------------------------- the soak
@dataclass(frozen=True)
class RssSample:
    """One memory sample: seconds since the soak started, the node's RSS in MiB, and the
    frames published and answered by then."""

    elapsed_s: float
    rss_mib: float
    published: int
    answered: int
    node_dropped: int
    loop: int


def rss_summary(samples: list[RssSample], soak_s: float) -> dict[str, Any]:
    """RSS after the first minute (halfway in runs under two minutes), at the end, the
    growth between them in %, the peak, and the slope over the second half (MiB/min)."""
    valid = [sample for sample in samples if np.isfinite(sample.rss_mib)]
    if not valid:
        return {'samples': 0}
    reference_s = min(RSS_REFERENCE_S, soak_s / 2)
    reference = next((s for s in valid if s.elapsed_s >= reference_s), valid[-1])
    end = valid[-1]
    late = [s for s in valid if s.elapsed_s >= soak_s / 2]
    slope = (float(np.polyfit([s.elapsed_s / 60 for s in late], [s.rss_mib for s in late],
                              1)[0]) if len(late) >= 3 else float('nan'))
    return {'samples': len(valid), 'reference_s': round(reference.elapsed_s, 1),
            'at_reference': round(reference.rss_mib, 2), 'start': round(valid[0].rss_mib, 2),
            'end': round(end.rss_mib, 2), 'max': round(max(s.rss_mib for s in valid), 2),
            'growth_percent': round(100 * (end.rss_mib / reference.rss_mib - 1), 2),
            'slope_mib_per_min_second_half': round(slope, 3)}


def run_soak(client: SoakClient, node_pid: int, args: argparse.Namespace, log: NodeLog,
             csv_writer: Callable[[RssSample], None]) -> tuple[list[RssSample], float]:
    """Publish at ``args.rate`` for ``args.minutes``, sampling the node's RSS; returns the
    samples and the seconds the soak lasted. Stops early when the node dies."""
    samples: list[RssSample] = []
    interval_s, duration_s = args.rss_interval, args.minutes * 60.0
    started = time.monotonic()
    next_sample, next_progress = started, started + args.progress_interval
    client.start(args.rate)
    while True:
        now = time.monotonic()
        alive = process_start_ticks(node_pid) is not None
        if now >= next_sample or now - started >= duration_s or not alive:
            with client.lock:
                published, answered = client.published, client.answered
            sample = RssSample(now - started, resident_mb(node_pid) if alive else float('nan'),
                               published, answered, client.node_count('frames_dropped'),
                               client.drive.loop)
            samples.append(sample)
            csv_writer(sample)
            next_sample += interval_s
        if now >= next_progress:
            log.scan()
            reference = rss_summary(samples, now - started).get('at_reference', float('nan'))
            print(f'{(now - started) / 60:5.1f} min: published {sample.published} '
                  f'({sample.published / (now - started):.1f} Hz), answered {sample.answered}, '
                  f'node dropped {sample.node_dropped}, loop {sample.loop + 1}, RSS '
                  f'{sample.rss_mib:.0f} MiB (first minute {reference:.0f}), log errors '
                  f'{log.error_count + log.traceback_count}, error statuses '
                  f'{client.status_counts["error"]}', file=sys.stderr)
            next_progress += args.progress_interval
        if not alive:
            print('the node died during the soak', file=sys.stderr)
            break
        if client.publish_error:
            print(f'publishing stopped: {client.publish_error}', file=sys.stderr)
            break
        if now - started >= duration_s:
            break
        time.sleep(max(0.0, min(next_sample, next_progress, started + duration_s)
                       - time.monotonic()))
    client.stop()
    return samples, time.monotonic() - started


def settle(client: SoakClient) -> None:
    """Wait for the answers in flight, then for a diagnostics report sent after them."""
    time.sleep(ANSWER_WAIT_S)
    asked = time.monotonic()
    deadline = asked + FINAL_DIAGNOSTICS_WAIT_S
    while client.diagnostics_at <= asked and time.monotonic() < deadline:
        time.sleep(0.1)


def frame_figures(client: SoakClient) -> dict[str, int]:
    """Every published frame's fate (see the module docstring)."""
    received = client.node_count('frames_received')
    with client.lock:
        published, answered = client.published, client.answered
        duplicates, unmatched = client.duplicate_answers, client.unmatched_answers
    dropped = client.node_count('frames_dropped')
    lost = published - received
    return {'published': published, 'answered': answered, 'node_received': received,
            'node_processed': client.node_count('frames_processed'), 'node_dropped': dropped,
            'node_dropped_stale': client.node_count('frames_dropped_stale'),
            'node_rejected_bad_input': client.node_count('frames_rejected_bad_input'),
            'lost_in_transport': lost,
            'node_lost_in_transport_estimate': client.node_count('frames_lost_in_transport'),
            'lost_reported_by_middleware':
                client.node_count('frames_lost_reported_by_middleware'),
            'unaccounted': published - answered - dropped - lost,
            'duplicate_answers': duplicates, 'unmatched_answers': unmatched}


def machine_record() -> dict[str, Any]:
    """The host as ``run_all`` records it (CPU model, cores, platform, load average)."""
    import run_all

    return run_all._machine()


def host_line(machine: dict[str, Any], renderer: str) -> str:
    """The host in words, as bench/RESULTS.md names it (CPU, cores, GL renderer)."""
    import results_markdown

    return results_markdown.host_line({'machine': machine, 'node': {'renderer': renderer}})


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=60.0, help='soak length (default 60)')
    parser.add_argument('--rate', type=float, default=30.0, help='publishing rate, Hz')
    parser.add_argument('--width', type=int, default=1280, help='drive width, px')
    parser.add_argument('--height', type=int, default=720, help='drive height, px')
    parser.add_argument('--loop-seconds', type=float, default=20.0,
                        help='length of the synthetic drive made for the loop, s (default 20)')
    parser.add_argument('--seed', type=int, default=1, help='seed of the synthetic drive')
    parser.add_argument('--raw', action='store_true', help='make the drive raw bgr8 '
                        'sensor_msgs/Image (default: JPEG CompressedImage; raw 1280x720 is '
                        '2.8 MB a frame on disk)')
    parser.add_argument('--bag', type=Path, help='loop this ROS 2 bag\'s image topic instead '
                        'of making a drive (its size and format stand)')
    parser.add_argument('--rss-interval', type=float, default=10.0,
                        help='seconds between RSS samples (default 10)')
    parser.add_argument('--progress-interval', type=float, default=60.0,
                        help='seconds between progress lines on stderr (default 60)')
    parser.add_argument('--rss-csv', type=Path, help='write the RSS time series here')
    parser.add_argument('--node-log', type=Path, help='keep the node\'s console output here '
                        '(default: a temporary file)')
    add_node_arguments(parser, domain_id=77)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='speed_sign_soak_') as scratch:
        try:
            if args.bag is None:
                made = time.monotonic()
                bag_path = make_drive(Path(scratch) / 'drive', args)
                print(f'drive made in {time.monotonic() - made:.0f} s: {bag_path}',
                      file=sys.stderr)
            else:
                bag_path = args.bag
            drive = LoopingDrive(bag_path)
        except (SoakError, NodeBenchError) as err:
            print(f'bench_soak: {err}', file=sys.stderr)
            return 1
        log_path = args.node_log or Path(scratch) / 'node.log'
        log_path.parent.mkdir(parents=True, exist_ok=True)
        csv_file: IO[str] | None = None
        if args.rss_csv is not None:
            args.rss_csv.parent.mkdir(parents=True, exist_ok=True)
            csv_file = args.rss_csv.open('w', newline='')
        try:
            summary = soak_with_node(args, drive, bag_path, log_path, csv_file)
        except NodeBenchError as err:
            print(f'bench_soak: {err}; the node\'s output: {log_path}', file=sys.stderr)
            return 1
        finally:
            drive.bag.close()
            if csv_file is not None:
                csv_file.close()
    print(f'soak {summary["seconds"] / 60:.1f} min, {summary["loops"]} loops: RSS '
          f'{summary["rss_mib"].get("at_reference")} -> {summary["rss_mib"].get("end")} MiB '
          f'({summary["rss_mib"].get("growth_percent")} %); frames {summary["frames"]}; '
          f'errors {summary["errors"]["log_error_lines"]} logged, '
          f'{summary["errors"]["diagnostics_error_statuses"]} in diagnostics; node '
          + ('alive, the same process' if summary['node']['same_process_at_end']
             else 'RESTARTED OR DEAD'), file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    return 0


def soak_with_node(args: argparse.Namespace, drive: LoopingDrive, bag_path: Path,
                   log_path: Path, csv_file: IO[str] | None) -> dict[str, Any]:
    """Start the node, soak it, stop it; returns the JSON summary."""
    writer = csv.writer(csv_file) if csv_file is not None else None
    if writer is not None:
        writer.writerow(['elapsed_s', 'rss_mib', 'published', 'answered', 'node_dropped',
                         'loop'])

    def write_row(sample: RssSample) -> None:
        if writer is not None and csv_file is not None:
            writer.writerow([f'{sample.elapsed_s:.1f}', f'{sample.rss_mib:.2f}',
                             sample.published, sample.answered, sample.node_dropped,
                             sample.loop + 1])
            csv_file.flush()

    log = NodeLog(log_path)
    machine = machine_record()
    with log_path.open('w') as node_output, node_and_client(
            args, lambda: SoakClient(drive), node_output=node_output,
            node_environment={'RCUTILS_CONSOLE_OUTPUT_FORMAT': NODE_LOG_FORMAT,
                              'RCUTILS_COLORIZED_OUTPUT': '0', 'PYTHONUNBUFFERED': '1'}
    ) as (node_process, client):
        pid = node_process.pid
        started_ticks = process_start_ticks(pid)
        cpu_before, own_cpu_before = process_cpu_s(pid), time.process_time()
        samples, soak_s = run_soak(client, pid, args, log, write_row)
        node_cpu_s = process_cpu_s(pid) - cpu_before
        own_cpu_s = time.process_time() - own_cpu_before
        settle(client)
        same_process = process_start_ticks(pid) == started_ticks and node_process.poll() is None
        log.scan()
        run_errors = (log.error_count, log.traceback_count, list(log.errors))
    log.scan()   # what the node logged while stopping
    frames = frame_figures(client)
    with client.lock:
        latencies = np.array(client.latencies_ms)
    loops = client.drive.loop + 1
    rss = rss_summary(samples, soak_s)
    errors = {'log_error_lines': run_errors[0], 'log_tracebacks': run_errors[1],
              'log_warning_lines': log.warning_count, 'first_errors': run_errors[2],
              'log_errors_while_stopping': log.error_count + log.traceback_count
              - run_errors[0] - run_errors[1],
              'diagnostics_error_statuses': client.status_counts['error'],
              'diagnostics_warn_statuses': client.status_counts['warn'],
              'first_error_statuses': client.error_statuses}
    renderer = client.diagnostics.get('gl_renderer', '')
    return {
        'bench': 'soak', 'minutes_requested': args.minutes, 'seconds': round(soak_s, 1),
        'width': drive.width_px, 'height': drive.height_px,
        'drive': {'bag': str(bag_path) if args.bag else 'synthetic (made for the run)',
                  'seed': args.seed if args.bag is None else None,
                  'frames_per_loop': drive.frames_per_loop,
                  'message': 'sensor_msgs/CompressedImage' if drive.compressed
                  else 'sensor_msgs/Image'},
        'publish_hz_target': args.rate,
        'publish_hz_achieved': round(frames['published'] / soak_s, 2),
        'publish_gap_max_ms': round(client.publish_gap_max_ms, 1),
        'late_publishes': client.late_publishes, 'publish_error': client.publish_error,
        'loops': loops, 'stamp_jumps_published': loops - 1,
        'stamp_jumps_logged_by_node': log.stamp_jumps,
        'frames': frames,
        'latency_ms': {name: round(float(np.percentile(latencies, q)), 1) if latencies.size
                       else None for name, q in (('p50', 50), ('p95', 95), ('max', 100))},
        'pipeline_total_p50_ms': float(client.diagnostics.get('pipeline_total_p50_ms', 'nan')),
        'node_cpu_percent': round(100 * node_cpu_s / soak_s, 1),
        'bench_cpu_percent': round(100 * own_cpu_s / soak_s, 1),
        'rss_mib': {**rss, 'interval_s': args.rss_interval},
        'errors': errors,
        'node': {'pid': node_process.pid, 'same_process_at_end': same_process,
                 'counter_resets': client.counter_resets,
                 'exit_code_after_sigint': node_process.returncode},
        'backend': client.diagnostics.get('backend', ''), 'renderer': renderer,
        'machine': machine, 'host': host_line(machine, renderer),
        'load_average_at_end': list(os.getloadavg()),
        'targets': {'rss_growth_percent': TARGET_RSS_GROWTH_PERCENT, 'errors': 0,
                    'unaccounted_frames': 0},
        'meets_rss_target': bool(rss.get('growth_percent', float('inf'))
                                 <= TARGET_RSS_GROWTH_PERCENT),
        'meets_error_target': errors['log_error_lines'] + errors['log_tracebacks']
        + errors['diagnostics_error_statuses'] == 0,
        'meets_accounting_target': frames['unaccounted'] == 0
        and frames['node_lost_in_transport_estimate'] >= frames['lost_in_transport'],
        'meets_restart_target': same_process and client.counter_resets == 0
        and log.stamp_jumps >= loops - 1,
    }


if __name__ == '__main__':
    raise SystemExit(main())
