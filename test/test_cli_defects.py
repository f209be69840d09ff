"""The user-facing defects of issue 34, each checked on the installed executables.

Every check runs a console script as its own process and reads its exit status and
messages: a misspelt node parameter is warned about with the closest name; a misspelt
or mistyped config key names the parameter as written; numeric options out of range are
usage errors naming the option; ``speed_sign_synth --help`` gives both modes; a start-up
gap is not reported as transport loss; a text file given as a bank is "not a bank file";
the monitor shows ``-`` for latencies the node has not measured yet.

The node processes run in this module's own ROS domains (:data:`IDLE_DOMAIN_ID`,
:data:`REPLAY_DOMAIN_ID`), detection only on the numpy backend (light on CPU).
"""
from __future__ import annotations

import dataclasses
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_helpers import DEADLINE_S, run_tool, tool

from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.synthetic_bag import write_drive

#: ROS domain of the node that never gets a frame (parameters, monitor before frames).
IDLE_DOMAIN_ID = 89
#: ROS domain of the node fed by speed_sign_replay (start-up gap).
REPLAY_DOMAIN_ID = 90
#: The tiny drive: frames, rate and size.
DRIVE = DriveConfig(seed=5, duration_s=2.0, fps=10.0, width_px=160, height_px=120,
                    focal_px=190.0)
#: How much earlier than the second frame the first one is stamped, in frame periods: a
#: first frame sent before the subscription matched (delivered late), the frames in
#: between never received. Less than the estimator's pause (1 s).
START_GAP_PERIODS = 8
#: Node parameters of both nodes: detection only, numpy voting (no GL context needed).
LIGHT_NODE_YAML = """\
speed_sign_detector:
  ros__parameters:
    classify: false
    backend: numpy
    tracker:
      windw_s: 2.0
"""


# ------------------------------------------------------------------------ helpers

class ToolProcess:
    """An installed tool running in the background; its stdout and stderr lines are
    collected by threads, and can be waited for (with a deadline, never a sleep)."""

    def __init__(self, command: list[str], env: dict[str, str]) -> None:
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, env=env)
        self.lines: dict[str, list[str]] = {'stdout': [], 'stderr': []}
        self._new: queue.Queue[None] = queue.Queue()
        self._readers = [threading.Thread(target=self._collect, args=(name,), daemon=True)
                         for name in self.lines]
        for reader in self._readers:
            reader.start()

    def _collect(self, name: str) -> None:
        stream = getattr(self.process, name)
        for line in stream:
            self.lines[name].append(line.rstrip('\n'))
            self._new.put(None)
        self._new.put(None)

    def wait_for_line(self, stream: str, wanted: Callable[[str], bool],
                      what: str) -> str:
        """The first line of ``stream`` satisfying ``wanted``; fails after
        :data:`DEADLINE_S` or when the process ends without one."""
        deadline = time.monotonic() + DEADLINE_S
        while True:
            ended = not any(reader.is_alive() for reader in self._readers)
            found = next((line for line in list(self.lines[stream]) if wanted(line)), None)
            if found is not None:
                return found
            assert not ended, (f'the process ended (status {self.process.poll()}) before '
                               f'{what}:\n' + '\n'.join(self.lines['stderr'][-20:]))
            assert time.monotonic() < deadline, f'no {what} within {DEADLINE_S:.0f} s:\n' \
                + '\n'.join(self.lines[stream][-20:])
            try:
                self._new.get(timeout=0.5)
            except queue.Empty:
                pass

    def stop(self) -> int:
        """SIGINT, then wait for the exit; returns the exit status."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=DEADLINE_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        for reader in self._readers:
            reader.join(timeout=DEADLINE_S)
        return self.process.returncode


def ros_environment(domain_id: int) -> dict[str, str]:
    """The environment of a ROS tool in ``domain_id`` (logs unbuffered, uncoloured)."""
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1',
                RCUTILS_COLORIZED_OUTPUT='0')


@pytest.fixture(scope='module')
def tiny_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s, 10 Hz, 160x120 compressed drive whose first frame is stamped
    :data:`START_GAP_PERIODS` periods before the second (and written at that time)."""
    frames = list(SyntheticDrive(DRIVE))
    period_ns = frames[1].stamp_ns - frames[0].stamp_ns
    early = dataclasses.replace(frames[0], stamp_ns=frames[1].stamp_ns
                                - (START_GAP_PERIODS + 1) * period_ns)
    path = tmp_path_factory.mktemp('tiny') / 'drive'
    write_drive([early, *frames[1:]], path, 'mcap', compressed=True)
    return path


@pytest.fixture(scope='module')
def light_parameters(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The node parameter file :data:`LIGHT_NODE_YAML` (one key misspelt)."""
    path = tmp_path_factory.mktemp('params') / 'light.yaml'
    path.write_text(LIGHT_NODE_YAML)
    return path


@pytest.fixture(scope='module')
def idle_node(light_parameters: Path) -> Iterator[ToolProcess]:
    """The node with a misspelt parameter in its file and one given with -p; no camera."""
    node = ToolProcess([*tool('speed_sign_detector'), '--ros-args', '--params-file',
                        str(light_parameters), '-p', 'detector.min_raduis_px:=6.0'],
                       ros_environment(IDLE_DOMAIN_ID))
    try:
        node.wait_for_line('stderr', lambda line: 'listening on' in line,
                           'the node subscribing to its images')
        yield node
    finally:
        node.stop()


# ------------------------------------------------ 1. misspelt node parameters

def test_misspelt_node_parameters_are_warned_with_the_closest_name(
        idle_node: ToolProcess) -> None:
    # the parameters are checked when declared, before the node subscribes: by the
    # 'listening on' line the fixture waited for, the warnings have been logged
    start_up = list(idle_node.lines['stderr'])
    for given, closest in (('detector.min_raduis_px', 'detector.min_radius_px'),
                           ('tracker.windw_s', 'tracker.window_s')):
        warnings = [line for line in start_up if f'unknown parameter {given}' in line]
        assert len(warnings) == 1, '\n'.join(start_up)
        assert '[WARN]' in warnings[0]
        assert f'did you mean {closest}?' in warnings[0]
    assert idle_node.process.poll() is None, 'the node must keep running'
    # the correctly spelt parameters of the same file are not warned about
    assert not [line for line in idle_node.lines['stderr']
                if 'unknown parameter classify' in line or 'unknown parameter backend' in line]


# ------------------------------------- 2, 9. config keys and values named as written

@pytest.mark.parametrize(('yaml_text', 'expected', 'absent'), [
    ('detector:\n  min_raduis_px: 6\n',
     'unknown parameter detector.min_raduis_px (did you mean detector.min_radius_px?)',
     'detector.max_radius_px'),
    ('detector:\n  min_radius_px: "six"\n',
     "detector.min_radius_px must be float, got 'six'", 'DetectorConfig'),
])
def test_eval_bag_config_errors_are_short_and_name_the_parameter(
        tmp_path: Path, tiny_bag: Path, yaml_text: str, expected: str, absent: str) -> None:
    config = tmp_path / 'typo.yaml'
    config.write_text(yaml_text)
    result = run_tool('speed_sign_eval', 'bag', str(tiny_bag), '--config', str(config))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert expected in lines[0]
    assert absent not in lines[0]
    assert len(lines[0]) < 200, lines[0]


# --------------------------------------------- 3, 4. numeric options out of range

#: (command line, the option it gets wrong); DIR and OUT stand for a scratch folder and
#: an output path in it.
RANGE_CASES: list[tuple[tuple[str, ...], str]] = [
    (('speed_sign_eval', 'scenes', 'DIR', '--limit', '-3'), '--limit'),
    (('speed_sign_eval', 'scenes', 'DIR', '--max-candidates', '0'), '--max-candidates'),
    (('speed_sign_eval', 'crops', 'DIR', '--every', '0'), '--every'),
    (('speed_sign_eval', 'crops', 'DIR', '--limit', '-1'), '--limit'),
    (('speed_sign_eval', 'bag', 'DIR', '--grace', '-1'), '--grace'),
    (('speed_sign_eval', 'fleet', 'DIR', '--out', 'OUT', '--gpus-per-worker', '-1'),
     '--gpus-per-worker'),
    (('speed_sign_eval', 'fleet', 'DIR', '--out', 'OUT', '--gpus-per-worker', '1.5'),
     '--gpus-per-worker'),
    (('speed_sign_eval', 'fleet', 'DIR', '--out', 'OUT', '--workers', '0'), '--workers'),
    (('speed_sign_eval', 'fleet', 'DIR', '--out', 'OUT', '--retries', '-1'), '--retries'),
    (('speed_sign_synth', 'OUT', '--duration', '-5'), '--duration'),
    (('speed_sign_synth', 'approach', 'DIR', 'OUT', '--max-sequences', '-1'),
     '--max-sequences'),
    (('speed_sign_synth', 'approach', 'DIR', 'OUT', '--frames', '1'), '--frames'),
    (('speed_sign_replay', 'DIR', '--rate', '0'), '--rate'),
    (('speed_sign_replay', 'DIR', '--depth', '0'), '--depth'),
    (('speed_sign_replay', 'DIR', '--wait', '-1'), '--wait'),
    (('speed_sign_monitor', '--timeout', '0'), '--timeout'),
    (('speed_sign_monitor', '--interval', '-0.5'), '--interval'),
    (('speed_sign_train', 'build', 'OUT', 'DIR', '--epochs', '0'), '--epochs'),
    (('speed_sign_train', 'validate', 'DIR', '--folds', '1'), '--folds'),
    (('speed_sign_train', 'validate', 'DIR', '--real-filter-noise', '-2'),
     '--real-filter-noise'),
]


@pytest.mark.parametrize(('command', 'option'), RANGE_CASES,
                         ids=[f'{command[0]}-{option}' for command, option in RANGE_CASES])
def test_numbers_out_of_range_are_usage_errors_naming_the_option(
        tmp_path: Path, command: tuple[str, ...], option: str) -> None:
    places = {'DIR': str(tmp_path), 'OUT': str(tmp_path / 'out')}
    result = run_tool(*(places.get(argument, argument) for argument in command))
    assert result.returncode == 2, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert 'error:' in last and option in last, last
    field_name = option.lstrip('-').replace('-', '_')
    if '_' in field_name:
        assert field_name not in last, last   # the option, not the config field
    assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'out').exists()


# ------------------------------------------- 5. both synth modes; no import circle

def test_synth_help_gives_both_modes_and_the_output_path() -> None:
    result = run_tool('speed_sign_synth', '--help')
    assert result.returncode == 0
    text = ' '.join(result.stdout.split())
    assert 'speed_sign_synth [options] OUT' in text
    assert 'speed_sign_synth approach SCENES OUT [options]' in text
    assert 'OUT is the output path' in text
    assert 'OUT output path: the bag to create' in text
    assert 'speed_sign_synth approach --help' in text


def test_synth_approach_does_not_import_synth() -> None:
    """The two modes' modules no longer import each other (the shared part is
    tools.synthetic_bag): loading the approach mode leaves the drive mode unloaded."""
    probe = ('import sys, speed_sign_detector.tools.synth_approach; '
             'print("speed_sign_detector.tools.synth" in sys.modules)')
    result = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                            timeout=DEADLINE_S, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == 'False'


# ----------------------------------------- 6. a start-up gap is not transport loss

def test_a_start_up_gap_is_not_reported_as_transport_loss(
        tiny_bag: Path, light_parameters: Path) -> None:
    """The replay's first frame is stamped 8 periods before the second (as a first frame
    sent before the subscription matched, delivered late): the node receives every frame
    and reports none lost, no WARN, no loss warning.

    The node subscribes reliably here (a QoS override), so that the replay's wait for
    the first frame's acknowledgement makes sure that frame arrives: with the default
    best-effort subscription it may be dropped while the two sides match, and the gap
    would not be seen."""
    env = ros_environment(REPLAY_DOMAIN_ID)
    topic = '/cli_defects_camera/image/compressed'
    node = ToolProcess([*tool('speed_sign_detector'), '--ros-args', '--params-file',
                        str(light_parameters), '-r', f'image/compressed:={topic}',
                        '-p', f'qos_overrides.{topic}.subscription.reliability:=reliable',
                        '-p', 'qos_overrides./image.subscription.reliability:=reliable'],
                       env)   # (the log line describes the raw topic's subscription)
    monitor = None
    try:
        listening = node.wait_for_line('stderr', lambda line: 'listening on' in line,
                                       'the node ready')
        assert '(reliable' in listening, listening
        monitor = ToolProcess([*tool('speed_sign_monitor'), '--json', '--timeout', '120'],
                              env)
        replay = run_tool_in(env, 'speed_sign_replay', str(tiny_bag), '--publish-as', topic,
                             '--wait', '120', '-q')
        assert replay.returncode == 0, replay.stderr
        sent = SyntheticDrive(DRIVE).frame_count

        def all_received(line: str) -> bool:
            return json.loads(line).get('frames_received') == sent
        final = json.loads(monitor.wait_for_line('stdout', all_received,
                                                 f'a report of all {sent} frames received'))
    finally:
        if monitor is not None:
            monitor.stop()
        node.stop()
    assert final['frames_lost_in_transport'] == 0, final
    snapshots = [json.loads(line) for line in monitor.lines['stdout'] if line.startswith('{')]
    assert not [s for s in snapshots if 'lost in transport' in (s['status_message'] or '')]
    assert not [line for line in node.lines['stderr']
                if 'lost before they reach this node' in line]


def run_tool_in(env: dict[str, str], name: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run an installed tool to its end in ``env``."""
    return subprocess.run([*tool(name), *args], capture_output=True, text=True, env=env,
                          timeout=DEADLINE_S, check=False)


# --------------------------------------------------- 7. a text file as the bank

def test_a_text_file_as_bank_file_is_not_a_bank_file(tmp_path: Path) -> None:
    crops = tmp_path / 'crops'
    (crops / '00001').mkdir(parents=True)
    crop = np.full((40, 40, 3), 128, np.uint8)
    cv2.circle(crop, (20, 20), 16, (40, 40, 200), 4)
    cv2.imwrite(str(crops / '00001' / '00000_00000.png'), crop)
    (crops / 'labels.csv').write_text('Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;'
                                      'ClassId\n00001/00000_00000.png;40;40;4;4;36;36;1\n')
    notes = tmp_path / 'notes.txt'
    notes.write_text('remember to buy milk\n')
    config = tmp_path / 'bank.yaml'
    config.write_text(f'classifier:\n  bank_file: "{notes}"\n')
    result = run_tool('speed_sign_eval', 'crops', str(crops), '--config', str(config), '-q')
    assert result.returncode == 1
    assert f'{notes} is not a bank file' in result.stderr
    for advice in ('allow_pickle', 'unsafely', 'pickle'):
        assert advice not in result.stderr


# --------------------------------------------- 8. the monitor before the first frame

def test_monitor_before_the_first_frame_shows_dashes_not_nan(idle_node: ToolProcess) -> None:
    env = ros_environment(IDLE_DOMAIN_ID)
    for json_output in (False, True):
        monitor = ToolProcess([*tool('speed_sign_monitor'), '--timeout', '120',
                               *(['--json'] if json_output else [])], env)
        try:
            # a snapshot with the node's diagnostics in it (frames_processed 0), not one
            # printed on hearing the latched limit alone (every field still unknown)
            line = monitor.wait_for_line(
                'stdout', (lambda text: text.startswith('{')
                           and json.loads(text).get('frames_processed') == 0)
                if json_output else (lambda text: 'processed 0 ' in text),
                'a snapshot of the node\'s diagnostics before any frame')
        finally:
            monitor.stop()
        if json_output:
            snapshot = json.loads(line)
            assert snapshot['processing_latency_p50_ms'] is None
            assert snapshot['processing_latency_p95_ms'] is None
        else:
            assert 'processing p50 - p95 - ms' in line, line
            assert 'nan' not in line, line
            assert 'processed 0 ' in line, line
