"""The node in-process with real rclpy: topics, QoS, bad input, parameters.

A helper node in the same (private) context publishes synthetic approach sequences (a
rendered sign growing on a textured background) and listens to every output. One
executor thread spins both nodes; the node under test processes on its own worker
thread with the real pipeline (GL on llvmpipe here, numpy where there is no GL).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from process_helpers import CLASSIFIER_WORKER, child_processes
from ros_spin import module_domain, ros_domain_environment, spinning
from scene_helpers import approach_frames, textured_background
from sensor_msgs.msg import CompressedImage, Image, PointCloud2
from std_msgs.msg import Header, UInt16

from speed_sign_detector.classifier_placement import (
    choose_classifier_placement,
    usable_cpu_count,
)
from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.config_parameters import node_option_specs, parameter_specs
from speed_sign_detector.ros.messages import image_message, pointcloud_to_array
from speed_sign_detector.ros.node import (
    NODE_NAME,
    SpeedSignDetectorNode,
    default_parameter_file,
)

DOMAIN_ID = module_domain('test_node')
WAIT_S = 60.0
WIDTH, HEIGHT = 320, 240
pytestmark = pytest.mark.ros

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Probe(Node):
    """Publishes frames and records everything the node under test publishes."""

    def __init__(self, image_topic: str = 'image', **kwargs: Any) -> None:
        super().__init__('speed_sign_probe', **kwargs)
        self.lock = threading.Lock()
        self.candidates: list[PointCloud2] = []
        self.limits: list[int] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.debug_images: list[Image] = []
        self.image_pub = self.create_publisher(Image, image_topic, qos_profile_sensor_data)
        self.compressed_pub = self.create_publisher(CompressedImage, f'{image_topic}/compressed',
                                                    qos_profile_sensor_data)
        self.create_subscription(PointCloud2, 'candidates', self._keep(self.candidates), 50)
        self.create_subscription(UInt16, 'speed_limit',
                                 self._keep(self.limits, lambda msg: msg.data), LATCHED)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._keep(self.diagnostics),
                                 10)
        self.parameters_client = self.create_client(SetParameters,
                                                    '/speed_sign_detector/set_parameters')
        self.stamp_ns = 1_700_000_000_000_000_000

    def _keep(self, store: list, convert: Callable[[Any], Any] = lambda msg: msg
              ) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            with self.lock:
                store.append(convert(msg))
        return callback

    def subscribe_debug_images(self) -> None:
        self.create_subscription(Image, 'debug_image', self._keep(self.debug_images), 5)

    def next_header_stamp(self, msg: Any) -> int:
        """Stamp ``msg`` 1/30 s after the previous frame (message time); returns ns."""
        self.stamp_ns += 33_333_333
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.stamp_ns, 1_000_000_000)
        msg.header.frame_id = 'camera'
        return self.stamp_ns


def wait_for(condition: Callable[[], Any], what: str, timeout_s: float = WAIT_S) -> Any:
    """Poll until ``condition()`` is truthy; fail naming ``what`` after the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.01)
    pytest.fail(f'timed out after {timeout_s:.0f} s waiting for {what}')


def stamp_ns(msg: Any) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture(scope='module', params=[True, False], ids=['overlapped', 'serial'])
def ros(request: pytest.FixtureRequest) -> Iterator[tuple[SpeedSignDetectorNode, Probe]]:
    """The node (recognition overlapping detection, or all on the worker) and a probe."""
    with ros_domain_environment(DOMAIN_ID):
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=DOMAIN_ID)
        # filter banks are built once and cached across test runs (pytest's cache folder)
        bank_cache = request.config.cache.mkdir('speed_sign_classifier_banks')
        node = SpeedSignDetectorNode(context=context, parameter_overrides=[
            Parameter('classifier.cache_dir', value=str(bank_cache)),
            Parameter('overlap_stages', value=request.param)])
        probe = Probe(context=context)
        with spinning(context, node, probe):
            wait_for(lambda: probe.image_pub.get_subscription_count() > 0
                     and probe.compressed_pub.get_subscription_count() > 0
                     and node.count_subscribers('candidates') > 0, 'discovery')
            yield node, probe


def send_and_wait(probe: Probe, msg: Any, publisher: Any) -> PointCloud2:
    """Publish one frame and wait for the candidates with its stamp (lockstep)."""
    sent = probe.next_header_stamp(msg)

    def answered() -> PointCloud2 | None:
        with probe.lock:
            return next((c for c in probe.candidates if stamp_ns(c) == sent), None)
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:  # best effort: resend if the sample was lost
        publisher.publish(msg)
        try:
            return wait_for(answered, f'candidates stamped {sent}', timeout_s=5.0)
        except pytest.fail.Exception:
            continue
    pytest.fail(f'no candidates for the frame stamped {sent}')


def frame_counters(node: SpeedSignDetectorNode) -> dict[str, int]:
    """The node's frame counters now: received, processed, dropped_stale, rejected."""
    stats = node._stats
    with stats.lock:
        return {'received': stats.received, 'processed': stats.processed,
                'dropped_stale': stats.dropped_stale, 'rejected': stats.rejected}


def settled_counters(node: SpeedSignDetectorNode) -> dict[str, int]:
    """Wait until every frame the node received is processed, dropped or rejected
    (none waiting or in flight); returns the counters then."""
    def settled() -> dict[str, int] | None:
        counters = frame_counters(node)
        done = counters['processed'] + counters['dropped_stale'] + counters['rejected']
        return counters if done == counters['received'] else None
    return wait_for(settled, 'every received frame to be processed, dropped or rejected')


def publish_until(probe: Probe, msg: Any, publisher: Any, condition: Callable[[], Any],
                  what: str, new_stamp: bool = True) -> int:
    """Publish ``msg`` (with a new header stamp each time when ``new_stamp``) until
    ``condition()`` holds, waiting 5 s between sends (best effort may lose a sample);
    fail naming ``what`` after WAIT_S. Returns the number of sends."""
    deadline = time.monotonic() + WAIT_S
    sends = 0
    while time.monotonic() < deadline:
        if new_stamp:
            probe.next_header_stamp(msg)
        publisher.publish(msg)
        sends += 1
        try:
            wait_for(condition, what, timeout_s=5.0)
            return sends
        except pytest.fail.Exception:
            continue
    pytest.fail(f'timed out after {WAIT_S:.0f} s waiting for {what}')


def latest_status(probe: Probe, key_filter: Callable[[dict[str, Any]], bool]
                  ) -> dict[str, Any]:
    """Wait for a /diagnostics status of the node satisfying ``key_filter``: its values,
    plus ``_message``, ``_hardware_id`` and ``_level``."""
    def found() -> dict[str, Any] | None:
        with probe.lock:
            arrays = list(probe.diagnostics)
        for array in reversed(arrays):
            for status in array.status:
                if status.name == 'speed_sign_detector: pipeline':
                    values = {kv.key: kv.value for kv in status.values}
                    values['_message'] = status.message
                    values['_hardware_id'] = status.hardware_id
                    values['_level'] = status.level
                    if key_filter(values):
                        return values
        return None
    return wait_for(found, 'a matching /diagnostics status')


def sign_candidate(cloud: PointCloud2, x: float, y: float, radius: float
                   ) -> np.ndarray | None:
    """The candidate on the sign (centre within half a radius, size within 50 %), or None."""
    points = pointcloud_to_array(cloud)
    assert points.dtype.names == ('u', 'v', 'radius', 'score', 'limit_kmh', 'psr',
                                  'rotation_deg')
    assert cloud.header.frame_id == 'camera'
    on_sign = points[(np.hypot(points['u'] - x, points['v'] - y) < 0.5 * radius)
                     & (np.abs(points['radius'] - radius) < 0.5 * radius)]
    return on_sign[0] if on_sign.size else None


def assert_sign_in_most_frames(found: list[np.ndarray | None]) -> list[np.ndarray]:
    """The sign must be a candidate in at least 3 of 4 frames (detector recall is measured
    by the detector's own tests; here the candidates must carry it through the node)."""
    hits = [point for point in found if point is not None]
    assert len(hits) >= 0.75 * len(found), f'sign among the candidates in {len(hits)} of ' \
        f'{len(found)} frames'
    return hits


def run_approach(probe: Probe, kind: str, *, compressed: bool, seed: int
                 ) -> list[np.ndarray]:
    """Send an approach sequence frame by frame; returns the candidates found on the sign."""
    found = []
    for frame, x, y, radius in approach_frames(kind, 16, seed):
        if compressed:
            jpeg = cv2.imencode('.jpg', frame, [cv2.IMWRITE_JPEG_QUALITY, 90])[1]
            msg = CompressedImage(format='jpeg', data=jpeg.tobytes())
            cloud = send_and_wait(probe, msg, probe.compressed_pub)
        else:
            msg = image_message(frame, Header(), image_class=Image)
            cloud = send_and_wait(probe, msg, probe.image_pub)
        found.append(sign_candidate(cloud, x, y, radius))
    return assert_sign_in_most_frames(found)


def test_raw_approach_is_detected_and_its_limit_published(ros: tuple) -> None:
    node, probe = ros
    wait_for(lambda: probe.limits, 'the initial speed_limit')
    nearest = run_approach(probe, '50', compressed=False, seed=1)
    assert any(point['limit_kmh'] == 50 for point in nearest)
    wait_for(lambda: probe.limits and probe.limits[-1] == 50, 'speed_limit 50')
    with probe.lock:
        assert probe.limits[0] == 0  # the value published at start: none known


def test_compressed_approach_and_late_subscriber(ros: tuple) -> None:
    node, probe = ros
    nearest = run_approach(probe, '80', compressed=True, seed=2)
    assert any(point['limit_kmh'] == 80 for point in nearest)
    wait_for(lambda: probe.limits and probe.limits[-1] == 80, 'speed_limit 80')
    late: list[int] = []
    subscription = probe.create_subscription(UInt16, 'speed_limit',
                                             lambda msg: late.append(msg.data), LATCHED)
    try:
        assert wait_for(lambda: late, 'the latched speed_limit') == [80]
    finally:
        probe.destroy_subscription(subscription)


def test_diagnostics_report_counts_latency_and_backend(ros: tuple) -> None:
    node, probe = ros
    send_and_wait(probe, image_message(textured_background(7), Header(), image_class=Image),
                  probe.image_pub)
    values = latest_status(probe, lambda v: int(v['frames_processed']) >= 1
                           and v['latency_p50_ms'] != 'nan')
    assert values['backend'] in ('gl', 'cpu', 'numpy')
    assert values['gl_renderer']
    assert values['vote_method'] in ('raster', 'scatter', 'stencil', 'numpy')
    # auto on llvmpipe times gl and cpu on the first frames, then names the one it kept
    assert values['backend_choice'].startswith('auto: ')
    assert values['_hardware_id'].startswith(values['backend'])
    for key in ('processing_fps', 'latency_p50_ms', 'latency_p95_ms',
                'processing_latency_p50_ms', 'processing_latency_p95_ms'):
        float(values[key])
    assert int(values['frames_received']) >= int(values['frames_processed'])
    assert int(values['frames_dropped']) == (int(values['frames_dropped_stale'])
                                             + int(values['frames_rejected_bad_input']))


def test_debug_image_is_drawn_for_a_subscriber(ros: tuple) -> None:
    node, probe = ros
    probe.subscribe_debug_images()
    wait_for(lambda: node.count_subscribers('debug_image') > 0, 'debug_image subscriber')
    frame = textured_background(5)
    msg = image_message(frame, Header(), image_class=Image)
    send_and_wait(probe, msg, probe.image_pub)
    debug = wait_for(lambda: probe.debug_images, 'a debug image')[-1]
    assert (debug.encoding, debug.width, debug.height) == ('bgr8', WIDTH, HEIGHT)
    assert stamp_ns(debug) == stamp_ns(msg)
    pixels = np.frombuffer(bytes(debug.data), np.uint8).reshape(HEIGHT, WIDTH, 3)
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    drawn = np.any(pixels != gray[..., None], axis=2)
    assert 0 < drawn.mean() < 0.5  # annotations on top of the gray frame


def test_bad_frames_are_counted_and_the_node_keeps_running(ros: tuple) -> None:
    node, probe = ros
    before = latest_status(probe, lambda v: True)
    rejected_before = int(before['frames_rejected_bad_input'])
    good = image_message(textured_background(3), Header(), image_class=Image)
    unknown = image_message(textured_background(3), Header(), image_class=Image)
    unknown.encoding = 'hsv8'
    truncated = image_message(textured_background(3), Header(), image_class=Image)
    truncated.data = truncated.data[:1000]
    bad_jpeg = CompressedImage(format='jpeg', data=b'\xff\xd8\xff\xe0 this is no jpeg')
    for bad, publisher in ((unknown, probe.image_pub), (truncated, probe.image_pub),
                           (bad_jpeg, probe.compressed_pub)):
        # each is taken alone (not replaced by the next one): the next is sent once the
        # worker has rejected this one
        rejected = frame_counters(node)['rejected']
        publish_until(probe, bad, publisher,
                      lambda: frame_counters(node)['rejected'] > rejected,  # noqa: B023
                      f'the node to reject the {bad.__class__.__name__} '
                      f'{getattr(bad, "encoding", "jpeg")!r}')
    send_and_wait(probe, good, probe.image_pub)
    values = latest_status(
        probe, lambda v: int(v['frames_rejected_bad_input']) >= rejected_before + 3)
    assert 'dropped' in values['last_error']
    assert int(values['frames_dropped']) >= int(values['frames_rejected_bad_input'])


def test_silence_turns_the_status_to_warn(ros: tuple) -> None:
    node, probe = ros
    [result] = call_set_parameters(probe, parameter('no_image_warning_s', 0.5))
    assert result.successful, result.reason
    try:
        values = latest_status(probe, lambda v: v['_message'].startswith('no image'))
        assert float(values['seconds_since_last_image']) >= 0.5
        assert values['_level'] == DiagnosticStatus.WARN
    finally:
        call_set_parameters(probe, parameter('no_image_warning_s', 5.0))


BURST_FRAMES = 30


def test_burst_keeps_only_the_newest_frame(ros: tuple, monkeypatch: pytest.MonkeyPatch
                                           ) -> None:
    """A burst arrives while the worker is held on one frame: once free, the worker
    processes the newest frame of the burst and no other; every older one that reached the
    node is dropped as stale and never published."""
    node, probe = ros
    held = threading.Event()
    release = threading.Event()
    process = node._process

    def process_holding_the_first(stages: Any, frame: Any) -> None:
        if not held.is_set():
            held.set()
            release.wait(WAIT_S)
        process(stages, frame)

    arrived: list[int] = []  # stamps of the images that reached the node, in order
    on_image = node._image_sub.callback

    def note_arrival(msg: Image) -> None:
        arrived.append(stamp_ns(msg))
        on_image(msg)

    frame = textured_background(4)
    holder = image_message(frame, Header(), image_class=Image)
    burst = [image_message(frame, Header(), image_class=Image) for _ in range(BURST_FRAMES)]
    stamps = [probe.next_header_stamp(msg) for msg in burst]
    newest = stamps[-1]
    before = settled_counters(node)
    monkeypatch.setattr(node._image_sub, 'callback', note_arrival)
    monkeypatch.setattr(node, '_process', process_holding_the_first)
    try:
        publish_until(probe, holder, probe.image_pub, held.is_set,
                      'the worker to take a frame')
        for msg in burst[:-1]:
            probe.image_pub.publish(msg)
        # the burst's newest frame reaches the node (sent again if it was lost)
        publish_until(probe, burst[-1], probe.image_pub, lambda: newest in arrived,
                      'the newest frame of the burst to reach the node', new_stamp=False)
    finally:
        release.set()
    wait_for(lambda: any(stamp_ns(c) == newest for c in list(probe.candidates)),
             'the candidates of the newest frame of the burst')
    after = settled_counters(node)
    with probe.lock:
        published = [stamp_ns(cloud) for cloud in probe.candidates
                     if stamp_ns(cloud) in stamps]
    assert published == [newest], 'frames of the burst published (their places in it): ' \
        f'{[stamps.index(stamp) for stamp in published]}, expected only the newest ' \
        f'({BURST_FRAMES - 1})'
    older = {stamp for stamp in arrived if stamp in stamps and stamp != newest}
    assert older, 'no older frame of the burst reached the node (nothing to drop)'
    # every arrival counted; the held frame and the burst's newest processed; every
    # other arrival replaced while it waited, none rejected
    received = after['received'] - before['received']
    assert received == len(arrived)
    assert after['processed'] - before['processed'] == 2
    assert after['rejected'] == before['rejected']
    assert after['dropped_stale'] - before['dropped_stale'] == received - 2


def call_set_parameters(probe: Probe, *parameters: ParameterMsg) -> list[Any]:
    wait_for(lambda: probe.parameters_client.service_is_ready(), 'parameter service')
    future = probe.parameters_client.call_async(SetParameters.Request(parameters=parameters))
    wait_for(future.done, 'set_parameters response')
    return list(future.result().results)


def parameter(name: str, value: Any) -> ParameterMsg:
    if isinstance(value, bool):
        return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                            bool_value=value))
    if isinstance(value, int):
        return ParameterMsg(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_INTEGER, integer_value=value))
    if isinstance(value, float):
        return ParameterMsg(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=value))
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                        string_value=value))


def test_parameter_changes_apply_or_are_rejected_with_a_reason(ros: tuple) -> None:
    node, probe = ros
    [accepted] = call_set_parameters(probe, parameter('detector.max_candidates', 2))
    assert accepted.successful, accepted.reason
    assert node.get_parameter('detector.max_candidates').value == 2
    frame = textured_background(6)
    cloud = send_and_wait(probe, image_message(frame, Header(), image_class=Image),
                          probe.image_pub)
    assert cloud.width <= 2

    rejected = {
        'detector.min_radius_px': 60.0,        # above max_radius_px (40): cross-field rule
        'detector.max_candidates': 1000,       # outside the declared range
        'detector.polarity': 'sideways',       # not one of the choices
        'backend': 3,                          # wrong type
        'diagnostics_period_s': 2.0,           # read-only
    }
    for name, value in rejected.items():
        [result] = call_set_parameters(probe, parameter(name, value))
        assert not result.successful, name
        assert result.reason, name
    [cross] = call_set_parameters(probe, parameter('detector.min_radius_px', 60.0))
    assert 'max_radius_px' in cross.reason
    [choice] = call_set_parameters(probe, parameter('detector.polarity', 'sideways'))
    assert 'sideways' in choice.reason
    assert node.get_parameter('detector.min_radius_px').value == DetectorConfig().min_radius_px
    assert node.get_parameter('detector.max_candidates').value == 2
    [restored] = call_set_parameters(probe, parameter('detector.max_candidates', 7))
    assert restored.successful


def test_backend_switch_rebuilds_the_detector_on_the_worker(ros: tuple) -> None:
    node, probe = ros
    [result] = call_set_parameters(probe, parameter('backend', 'numpy'))
    assert result.successful, result.reason
    try:
        send_and_wait(probe, image_message(textured_background(8), Header(), image_class=Image),
                      probe.image_pub)
        values = latest_status(probe, lambda v: v['backend'] == 'numpy')
        assert values['gl_renderer'] == 'numpy reference'
        assert values['vote_method'] == 'numpy'
    finally:
        call_set_parameters(probe, parameter('backend', 'auto'))
    send_and_wait(probe, image_message(textured_background(9), Header(), image_class=Image),
                  probe.image_pub)


def test_classifier_process_reads_signs_in_a_worker_process(ros: tuple) -> None:
    """``classifier_process`` set at run time: the classifier moves to a worker process,
    which reads the approach's limit; with ``classifier_workers`` 2, two workers read
    the next approach (a change that would leave two workers without processes is
    rejected with the reason); set back, the classifier returns to the node's process.
    ``classifier_workers`` 1 first, so that the counts do not depend on the host's size."""
    node, probe = ros
    [one, result] = call_set_parameters(probe, parameter('classifier_workers', 1),
                                        parameter('classifier_process', True))
    assert one.successful, one.reason
    assert result.successful, result.reason
    try:
        nearest = run_approach(probe, '70', compressed=False, seed=4)
        assert len(child_processes(CLASSIFIER_WORKER)) == 1
        latest_status(probe, lambda v: v['classifier']
                      == '1 worker process (classifier_workers 1)')
        assert any(point['limit_kmh'] == 70 for point in nearest)
        wait_for(lambda: probe.limits and probe.limits[-1] == 70, 'speed_limit 70')
        [result] = call_set_parameters(probe, parameter('classifier_workers', 2))
        assert result.successful, result.reason
        nearest = run_approach(probe, '50', compressed=False, seed=5)
        assert len(child_processes(CLASSIFIER_WORKER)) == 2
        latest_status(probe, lambda v: v['classifier']
                      == '2 worker processes (classifier_workers 2)')
        assert any(point['limit_kmh'] == 50 for point in nearest)
        wait_for(lambda: probe.limits and probe.limits[-1] == 50, 'speed_limit 50')
        [refused] = call_set_parameters(probe, parameter('classifier_process', False))
        assert not refused.successful
        assert 'classifier_workers (2) above 1 needs classifier_process' in refused.reason
    finally:
        [fewer] = call_set_parameters(probe, parameter('classifier_workers', 1))
        [restored] = call_set_parameters(probe, parameter('classifier_process', False))
    assert fewer.successful, fewer.reason
    assert restored.successful, restored.reason
    send_and_wait(probe, image_message(textured_background(10), Header(), image_class=Image),
                  probe.image_pub)  # the change applies between frames
    wait_for(lambda: not child_processes(CLASSIFIER_WORKER), 'the classifier worker to stop')

    def newest_classifier_location() -> str | None:
        with probe.lock:
            arrays = list(probe.diagnostics)
        return next((kv.value for array in reversed(arrays) for status in array.status
                     for kv in status.values if kv.key == 'classifier'), None)

    wait_for(lambda: newest_classifier_location() == 'in this process (classifier_workers 1)',
             'the diagnostics to say the classifier is back in the node process')
    [auto] = call_set_parameters(probe, parameter('classifier_workers', 0))  # the default
    assert auto.successful, auto.reason


def test_classifier_workers_default_to_the_host_size(ros: tuple) -> None:
    """``classifier_workers`` 0 (the default, auto) places the classifier as the CPUs
    this process may use allow, and /diagnostics says so: with the stages overlapped, in
    worker processes (one on this 2-core host), else in the node's process. A negative
    count is refused with a reason."""
    node, probe = ros
    assert node.get_parameter('classifier_workers').value == 0
    overlap = node.get_parameter('overlap_stages').value
    placement = choose_classifier_placement(usable_cpu_count(), 0, False, overlap)
    expected_location = (
        f'{placement.workers} worker process{"es" if placement.workers > 1 else ""}'
        if placement.in_worker_processes else 'in this process')
    expected = f'{expected_location} (auto for {usable_cpu_count()} CPUs' + (
        '' if overlap else ', stages not overlapped') + ')'
    if 2 <= usable_cpu_count() <= 5:
        assert expected.startswith(('1 worker process (auto for ' if overlap
                                    else 'in this process (auto for '))
    send_and_wait(probe, image_message(textured_background(11), Header(), image_class=Image),
                  probe.image_pub)
    latest_status(probe, lambda v: v['classifier'] == expected)
    workers = placement.workers if placement.in_worker_processes else 0
    wait_for(lambda: len(child_processes(CLASSIFIER_WORKER)) == workers,
             f'{workers} classifier worker processes')

    [refused] = call_set_parameters(probe, parameter('classifier_workers', -1))
    assert not refused.successful
    assert refused.reason == ('Parameter classifier_workers out of range. Min: 0, Max: 16, '
                              'value: -1'), refused.reason
    assert node.get_parameter('classifier_workers').value == 0



def test_parameter_file_lists_every_parameter_with_its_default() -> None:
    """config/speed_sign_detector.yaml holds exactly the declared parameters, at defaults."""
    path = Path(__file__).resolve().parents[1] / 'config' / 'speed_sign_detector.yaml'
    assert path.read_text() == default_parameter_file(), (
        f'{path} is out of date with the config classes; regenerate it with '
        f'default_parameter_file() (see its docstring)')
    document = yaml.safe_load(path.read_text())[NODE_NAME]['ros__parameters']

    def flatten(mapping: dict, prefix: str = '') -> dict[str, Any]:
        flat: dict[str, Any] = {}
        for key, value in mapping.items():
            flat.update(flatten(value, f'{prefix}{key}.') if isinstance(value, dict)
                        else {f'{prefix}{key}': value})
        return flat
    expected = {spec.name: spec.default for spec in parameter_specs() + node_option_specs()}
    assert flatten(document) == expected
    for name, value in flatten(document).items():  # ROS parameters are typed
        assert type(value) is type(expected[name]), name
