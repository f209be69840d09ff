"""The installed ``speed_sign_detector`` executable: usage, start-up errors, parameters
given as integers, a clean stop while publishing; the monitor without rclpy.

Every test runs the console scripts as separate processes; the node's peers are real
rclpy clients in this module's own ROS domain.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from ros_spin import module_domain, spinning
from scene_helpers import approach_frames
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header

from speed_sign_detector.bag_io import BagReader
from speed_sign_detector.config_parameters import load_yaml, to_parameters
from speed_sign_detector.ros.messages import image_message, pointcloud_to_array
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.synth import write_drive

DOMAIN_ID = module_domain('test_node_cli')
WAIT_S = 120.0
CAMERA_TOPIC = '/cli_cam/image_raw'
pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: A user's parameter file: integers where floats are declared, floats, nested and
#: dotted keys, a node option; fewer candidates per frame than the default (7), which
#: shows in the outputs.
USER_YAML = """\
speed_sign_detector:
  ros__parameters:
    no_image_warning_s: 30
    detector:
      min_radius_px: 4
      max_radius_px: 50
      gradient_threshold: 55.5
      max_candidates: 2
    tracker.window_s: 2
    classifier:
      psr_threshold: 7
"""
#: The float parameters USER_YAML sets with integers, and their values.
INTEGERS_FOR_FLOATS = {'detector.min_radius_px': 4.0, 'detector.max_radius_px': 50.0,
                       'tracker.window_s': 2.0, 'classifier.psr_threshold': 7.0,
                       'no_image_warning_s': 30.0}


def tool(name: str) -> str:
    """An installed console script (next to this interpreter, else on PATH)."""
    search = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get('PATH', '')])
    found = shutil.which(name, path=search)
    assert found, f'{name} is not installed: run `pip install -e .` first'
    return found


def environment(**extra: str) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID), PYTHONUNBUFFERED='1', **extra)


def run(*command: str, env: dict[str, str] | None = None,
        timeout: float = WAIT_S) -> subprocess.CompletedProcess:
    return subprocess.run(command, env=env or environment(), capture_output=True, text=True,
                          timeout=timeout, check=False)


def test_help_prints_the_usage_and_exits_0() -> None:
    result = run(tool('speed_sign_detector'), '--help', timeout=60)
    assert result.returncode == 0, result.stderr
    for expected in ('--ros-args', '--lifecycle', '--params-file', 'image/compressed',
                     'speed_limit', '/diagnostics', 'speed_sign_detector.yaml',
                     'fastdds_large_images.xml'):
        assert expected in result.stdout, expected
    assert result.stderr == ''


def test_an_unknown_option_is_refused() -> None:
    result = run(tool('speed_sign_detector'), '--frobnicate', timeout=60)
    assert result.returncode == 2
    assert 'unrecognized arguments: --frobnicate' in result.stderr
    assert 'Traceback' not in result.stderr


def test_a_missing_parameter_file_is_one_line_and_a_failure(tmp_path: Path) -> None:
    missing = tmp_path / 'nope.yaml'
    result = run(tool('speed_sign_detector'), '--ros-args', '--params-file', str(missing),
                 timeout=60)
    assert result.returncode != 0
    assert result.stderr.strip() == (f'speed_sign_detector: error: parameter file {missing} '
                                     f'does not exist')


@pytest.mark.parametrize('program', ['speed_sign_detector', 'speed_sign_monitor'])
def test_without_rclpy_the_tools_say_what_to_install(tmp_path: Path, program: str) -> None:
    """A module on PYTHONPATH named rclpy that fails to import as a missing one would."""
    shim = tmp_path / 'rclpy'
    shim.mkdir()
    (shim / '__init__.py').write_text(
        "raise ModuleNotFoundError(\"No module named 'rclpy'\", name='rclpy')\n")
    result = run(tool(program), '--once', env=environment(PYTHONPATH=str(tmp_path)),
                 timeout=60) if program == 'speed_sign_monitor' else run(
        tool(program), env=environment(PYTHONPATH=str(tmp_path)), timeout=60)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "'rclpy'" in lines[0] and 'pip install ros-jazzy-rclpy' in lines[0]
    assert '/opt/ros/jazzy/setup.bash' in lines[0]


class Peer(Node):
    """Publishes camera frames, counts candidates, talks to the node's parameter services."""

    def __init__(self, **kwargs: object) -> None:
        super().__init__('cli_test_peer', **kwargs)
        self.image_pub = self.create_publisher(Image, CAMERA_TOPIC, qos_profile_sensor_data)
        self.candidates = 0
        self.create_subscription(PointCloud2, 'candidates', self._on_candidates, 10)
        # a debug_image subscriber: the node draws and publishes more per frame
        self.create_subscription(Image, 'debug_image', lambda msg: None, 1)
        self.get_client = self.create_client(GetParameters,
                                             '/speed_sign_detector/get_parameters')
        self.set_client = self.create_client(SetParameters,
                                             '/speed_sign_detector/set_parameters')

    def _on_candidates(self, msg: PointCloud2) -> None:
        self.candidates += 1

    def call(self, client: object, request: object) -> object:
        deadline = time.monotonic() + WAIT_S
        while not client.service_is_ready():
            assert time.monotonic() < deadline, 'parameter service not available'
            time.sleep(0.05)
        future = client.call_async(request)
        while not future.done():
            assert time.monotonic() < deadline, 'no parameter service response'
            time.sleep(0.02)
        return future.result()


@pytest.fixture(scope='module')
def peer() -> Iterator[Peer]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    node = Peer(context=context)
    with spinning(context, node):
        yield node


@pytest.fixture(scope='module')
def user_yaml(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('params') / 'user.yaml'
    path.write_text(USER_YAML)
    return path


@pytest.fixture(scope='module')
def node_process(user_yaml: Path, pytestconfig: pytest.Config,
                 tmp_path_factory: pytest.TempPathFactory
                 ) -> Iterator[tuple[subprocess.Popen, Path]]:
    """The installed node started with the user's YAML; yields (process, its log)."""
    bank_cache = pytestconfig.cache.mkdir('speed_sign_classifier_banks')
    log_path = tmp_path_factory.mktemp('node') / 'node.log'
    log = log_path.open('w')
    process = subprocess.Popen(
        [tool('speed_sign_detector'), '--ros-args', '--params-file', str(user_yaml),
         '-p', f'classifier.cache_dir:={bank_cache}', '-p', 'diagnostics_period_s:=1',
         '-r', f'image:={CAMERA_TOPIC}'], env=environment(), stdout=log,
        stderr=subprocess.STDOUT)
    yield process, log_path
    if process.poll() is None:
        process.kill()
        process.wait()
    log.close()


def get_parameters(peer: Peer, names: list[str]) -> dict[str, object]:
    response = peer.call(peer.get_client, GetParameters.Request(names=names))
    values = {}
    for name, value in zip(names, response.values):
        values[name] = {ParameterType.PARAMETER_DOUBLE: value.double_value,
                        ParameterType.PARAMETER_INTEGER: value.integer_value,
                        ParameterType.PARAMETER_STRING: value.string_value,
                        ParameterType.PARAMETER_BOOL: value.bool_value}[value.type]
    return values


def test_integers_for_floats_start_the_node_like_the_offline_tools(
        node_process: tuple[subprocess.Popen, Path], peer: Peer, user_yaml: Path) -> None:
    process, log_path = node_process
    values = get_parameters(peer, [*INTEGERS_FOR_FLOATS, 'detector.gradient_threshold',
                                   'diagnostics_period_s'])
    assert process.poll() is None, log_path.read_text()
    for name, expected in INTEGERS_FOR_FLOATS.items():
        assert values[name] == expected and isinstance(values[name], float), name
    assert values['detector.gradient_threshold'] == 55.5
    assert values['diagnostics_period_s'] == 1  # read-only: kept as given, used as 1.0
    # the node and the offline tools read the same file to the same pipeline config
    offline = to_parameters(load_yaml(user_yaml))
    offline['classifier.cache_dir'] = get_parameters(
        peer, ['classifier.cache_dir'])['classifier.cache_dir']  # set on the command line
    node_values = get_parameters(peer, list(offline))
    assert node_values == offline


def test_ros2_param_set_accepts_an_integer_for_a_float(
        node_process: tuple[subprocess.Popen, Path], peer: Peer) -> None:
    def set_value(name: str, value: ParameterValue) -> object:
        [result] = peer.call(peer.set_client, SetParameters.Request(
            parameters=[ParameterMsg(name=name, value=value)])).results
        return result
    integer = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=9)
    result = set_value('detector.gradient_threshold', integer)
    assert result.successful, result.reason
    assert get_parameters(peer, ['detector.gradient_threshold']) == {
        'detector.gradient_threshold': 9.0}
    text = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value='nine')
    refused = set_value('detector.gradient_threshold', text)
    assert not refused.successful and 'float' in refused.reason
    out_of_range = set_value('detector.min_radius_px', ParameterValue(
        type=ParameterType.PARAMETER_INTEGER, integer_value=1))
    assert not out_of_range.successful and 'out of range' in out_of_range.reason


def test_speed_sign_eval_reads_the_same_user_yaml(tmp_path: Path, user_yaml: Path) -> None:
    """The file's ``detector.max_candidates`` (2) bounds the candidates of every frame of
    the results bag, where the same drive without the file has more in some frame."""
    bag = tmp_path / 'drive'
    write_drive(SyntheticDrive(DriveConfig(seed=4, duration_s=1.0, fps=4, width_px=320,
                                           height_px=240, focal_px=380.0)), bag)
    candidates_per_frame: dict[str, list[int]] = {}
    for name, config in (('with the file', ['--config', str(user_yaml)]), ('without', [])):
        out = tmp_path / f'out {name}'
        result = run(tool('speed_sign_eval'), 'bag', str(bag), *config, '--backend', 'numpy',
                     '--out', str(out), '--json')
        assert result.returncode == 0, result.stderr
        summary = json.loads(result.stdout.strip().splitlines()[-1])
        assert summary['frames'] == 4
        with BagReader(out) as results:
            candidates_per_frame[name] = [pointcloud_to_array(item.message).size
                                          for item in results.messages('/candidates')]
    assert len(candidates_per_frame['with the file']) == 4
    assert max(candidates_per_frame['without']) > 2, candidates_per_frame
    assert max(candidates_per_frame['with the file']) == 2, candidates_per_frame


def test_sigterm_while_the_node_publishes_stops_it_cleanly(
        node_process: tuple[subprocess.Popen, Path], peer: Peer) -> None:
    """Frames stream in at 30 Hz; SIGTERM arrives while results are being published."""
    process, log_path = node_process
    frames = [image_message(frame, Header(frame_id='camera'), image_class=Image)
              for frame, *_ in approach_frames('60', 12, seed=5)]
    streaming = threading.Event()
    streaming.set()

    def stream() -> None:
        index = 0
        while streaming.is_set():
            message = frames[index % len(frames)]
            message.header.stamp = peer.get_clock().now().to_msg()
            peer.image_pub.publish(message)
            index += 1
            time.sleep(1 / 30)
    publisher = threading.Thread(target=stream, daemon=True)
    publisher.start()
    try:
        deadline = time.monotonic() + WAIT_S
        while peer.candidates < 10:
            assert process.poll() is None, log_path.read_text()
            assert time.monotonic() < deadline, 'no candidates from the node'
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)
        status = process.wait(timeout=60)
    finally:
        streaming.clear()
        publisher.join(timeout=5)
    output = log_path.read_text()
    assert status == 0, output
    for problem in ('Traceback', 'RCLError', 'context is invalid', 'Exception'):
        assert problem not in output, output
