"""The ROS 2 node: camera images in, candidates / speed limit / debug image / diagnostics out.

Threads:
    * The executor thread runs the subscription callbacks, which only store the newest
      message (a message replaced before it was processed counts as dropped), the
      diagnostics timer and the parameter callback. It never waits for processing.
    * One worker thread owns the :class:`~speed_sign_detector.pipeline.Pipeline` (and so
      the OpenGL context, created, used and released on that thread): it converts the
      newest frame and detects its candidates.
    * With ``overlap_stages`` (the default), a recognition thread classifies and tracks
      each detected frame while the worker detects the next one, and publishes the
      results (:class:`~speed_sign_detector.pipeline.OverlappedPipeline`); without it
      the worker does that too.

Topics (relative, remappable): in ``image`` (sensor_msgs/Image) and ``image/compressed``
(sensor_msgs/CompressedImage), both with sensor-data QoS (best effort, volatile, keep
last 5; overridable with ``qos_overrides./<topic>.subscription.*`` parameters); out
``candidates`` (sensor_msgs/PointCloud2), ``speed_limit`` (std_msgs/UInt16, reliable +
transient local, on change), ``debug_image`` (sensor_msgs/Image bgr8, only while
subscribed) and ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).

Run: ``ros2 run speed_sign_detector speed_sign_detector --ros-args --params-file
config/speed_sign_detector.yaml -r image:=/camera/image_raw``.
"""
from __future__ import annotations

import dataclasses
import json
import textwrap
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CompressedImage, Image, PointCloud2, PointField
from std_msgs.msg import Header, UInt16

from speed_sign_detector.config import (
    NodeOptions,
    ParameterSpec,
    PipelineConfig,
    from_parameters,
    node_option_specs,
    parameter_specs,
)
from speed_sign_detector.errors import ConfigError, ImageConversionError, SpeedSignError
from speed_sign_detector.image_conversion import message_to_gray
from speed_sign_detector.pipeline import FrameResult, OverlappedPipeline, Pipeline
from speed_sign_detector.ros.messages import (
    DiagnosticsSnapshot,
    candidates_message,
    debug_image_message,
    diagnostics_message,
    speed_limit_message,
)

NODE_NAME = 'speed_sign_detector'
#: Latency samples kept for the percentiles in the diagnostics.
LATENCY_WINDOW = 300


#: Parameters that cannot change while the node runs.
READ_ONLY_PARAMETERS = frozenset({'diagnostics_period_s', 'overlap_stages'})


def parameter_descriptor(spec: ParameterSpec, read_only: bool = False) -> ParameterDescriptor:
    """ROS parameter descriptor of a spec: description, range or choices, read-only flag."""
    description = spec.description
    if spec.choices:
        description += f' One of: {", ".join(spec.choices)}.'
    descriptor = ParameterDescriptor(name=spec.name, description=description,
                                     read_only=read_only)
    if spec.choices:
        descriptor.additional_constraints = f'one of: {", ".join(spec.choices)}'
    has_range = spec.low is not None or spec.high is not None
    if isinstance(spec.default, bool) or not has_range:
        return descriptor
    if isinstance(spec.default, int):
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.low) if spec.low is not None else -2**63,
            to_value=int(spec.high) if spec.high is not None else 2**63 - 1, step=1)]
    elif isinstance(spec.default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low) if spec.low is not None else -np.finfo(float).max,
            to_value=float(spec.high) if spec.high is not None else np.finfo(float).max,
            step=0.0)]
    return descriptor


def default_parameter_file() -> str:
    """Text of ``config/speed_sign_detector.yaml``: every parameter at its default.

    Regenerate the file after adding a config field::

        python -c "from speed_sign_detector.ros.node import default_parameter_file as f; \\
            print(f(), end='')" > config/speed_sign_detector.yaml
    """
    lines = [
        '# Parameters of the speed_sign_detector node, with their defaults (generated by',
        '# speed_sign_detector.ros.node.default_parameter_file). Load with:',
        '#   ros2 run speed_sign_detector speed_sign_detector --ros-args --params-file <file>',
        '# (the launch file passes the installed copy). ROS parameters are typed: write',
        '# floating-point values with a decimal point. Every value can be changed at run time',
        '# with `ros2 param set` except the read-only ones; invalid values are rejected with',
        '# the reason.',
        f'{NODE_NAME}:',
        '  ros__parameters:',
    ]
    section = ''
    for spec in node_option_specs() + parameter_specs():
        owner, _, name = spec.name.rpartition('.')
        if owner and owner != section:
            lines.append(f'    {owner}:')
            section = owner
        indent = '      ' if owner else '    '
        notes = [f'one of {", ".join(spec.choices)}'] if spec.choices else []
        if spec.low is not None or spec.high is not None:
            notes.append(f'range [{spec.low}, {spec.high}]')
        if spec.name in READ_ONLY_PARAMETERS:
            notes.append('read-only')
        text = spec.description + (f' ({"; ".join(notes)})' if notes else '')
        lines += [f'{indent}# {line}' for line in textwrap.wrap(text, 92 - len(indent))]
        lines.append(f'{indent}{name}: {_yaml_scalar(spec.default)}')
    return '\n'.join(lines) + '\n'


def _yaml_scalar(value: Any) -> str:
    """A YAML scalar that ROS reads back with the value's type (floats keep a '.')."""
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    if isinstance(value, float):
        mantissa, _, exponent = repr(value).partition('e')
        mantissa += '' if '.' in mantissa else '.0'
        return mantissa + (f'e{exponent}' if exponent else '')
    return json.dumps(value)


@dataclass(frozen=True)
class ReceivedFrame:
    """A message waiting for the worker.

    Attributes:
        message: the sensor_msgs/Image or CompressedImage.
        topic: the resolved topic it came on.
        received_ns: node clock (ROS time) at receipt, nanoseconds.
        received_monotonic_s: ``time.monotonic()`` at receipt, seconds.
    """

    message: Any
    topic: str
    received_ns: int
    received_monotonic_s: float


class LogThrottle:
    """Log at most once per period; count what was held back and say so in the next log."""

    def __init__(self) -> None:
        self._last_s = -float('inf')
        self._suppressed = 0
        self._lock = threading.Lock()

    def admit(self, period_s: float) -> int | None:
        """Return the number of suppressed messages if one may be logged now, else None."""
        now = time.monotonic()
        with self._lock:
            if now - self._last_s < period_s:
                self._suppressed += 1
                return None
            suppressed, self._suppressed, self._last_s = self._suppressed, 0, now
            return suppressed


class FrameStatistics:
    """Counters and latency samples, written by both threads (guarded by a lock)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.received = 0
        self.processed = 0
        self.dropped_stale = 0
        self.rejected = 0
        self.lost_in_transport: dict[str, int] = {}
        self.last_error = ''
        self.last_received_monotonic_s: float | None = None
        self.stamp_latency_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.processing_latency_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.stage_ms: dict[str, deque[float]] = {}
        self.active_limit_kmh = 0

    @property
    def dropped(self) -> int:
        """Frames received but not processed: replaced while waiting, or rejected."""
        return self.dropped_stale + self.rejected


def _percentiles_ms(samples: deque[float]) -> tuple[float, float]:
    if not samples:
        return float('nan'), float('nan')
    p50, p95 = np.percentile(np.fromiter(samples, float), (50, 95))
    return float(p50), float(p95)


def _describe_qos(qos: QoSProfile, *, with_history: bool = True) -> str:
    text = f'{qos.reliability.name.lower()}, {qos.durability.name.lower()}'
    return text + (f', {qos.history.name.lower()} {qos.depth}' if with_history else '')


class SpeedSignDetectorNode(Node):
    """Detects and reads speed-limit signs in the images of one camera.

    Parameters: every field of :class:`PipelineConfig` as ``section.field`` (see
    ``config/speed_sign_detector.yaml``) plus :class:`NodeOptions`. Changes are validated
    (an invalid value or combination is rejected with the reason) and applied by the
    worker before its next frame.

    Raises (from the constructor):
        ConfigError: for invalid initial parameters.
        SpeedSignError: when the pipeline cannot be built (e.g. backend 'gl' without GL).
    """

    def __init__(self, node_name: str = NODE_NAME, **node_kwargs: Any) -> None:
        super().__init__(node_name, **node_kwargs)
        self._pipeline_specs = parameter_specs()
        self._pipeline_names = frozenset(spec.name for spec in self._pipeline_specs)
        for spec in self._pipeline_specs + node_option_specs():
            self.declare_parameter(spec.name, spec.default,
                                   parameter_descriptor(spec, spec.name in READ_ONLY_PARAMETERS))
        try:
            self._pipeline_config: PipelineConfig = from_parameters(
                {name: self.get_parameter(name).value for name in self._pipeline_names})
            self._options = NodeOptions(**{spec.name: self.get_parameter(spec.name).value
                                           for spec in node_option_specs()})
        except ConfigError:
            super().destroy_node()
            raise
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._stats = FrameStatistics()
        self._error_throttle = LogThrottle()
        self._no_image_throttle = LogThrottle()
        self._started_monotonic_s = time.monotonic()  # reset once the pipeline is ready
        self._condition = threading.Condition()
        self._pending_frame: ReceivedFrame | None = None
        self._pending_config: PipelineConfig | None = None
        self._stopping = False
        self._backend = 'starting'
        self._renderer = ''
        self._vote_method = ''
        self._fallback_reason: str | None = None
        self._last_tick = (time.monotonic(), 0)
        self._published_limit_kmh: int | None = None

        self._candidates_pub = self.create_publisher(PointCloud2, 'candidates', 10)
        self._speed_limit_pub = self.create_publisher(UInt16, 'speed_limit', QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST))
        self._debug_pub = self.create_publisher(Image, 'debug_image', 1)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)

        self._worker_ready = threading.Event()
        self._worker_error: BaseException | None = None
        self._worker = threading.Thread(target=self._run_worker, name='speed_sign_pipeline',
                                        daemon=True)
        self.get_logger().info('building the pipeline (GL context, classifier filter banks)')
        self._worker.start()
        self._worker_ready.wait()
        if self._worker_error is not None:
            super().destroy_node()
            if isinstance(self._worker_error, SpeedSignError):
                raise self._worker_error
            raise SpeedSignError(f'cannot build the pipeline: {self._worker_error}') \
                from self._worker_error
        self._publish_speed_limit(0)
        self._started_monotonic_s = time.monotonic()

        self._image_sub = self.create_subscription(
            Image, 'image', self._on_image, qos_profile_sensor_data,
            event_callbacks=self._image_events('image'),
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._compressed_sub = self.create_subscription(
            CompressedImage, 'image/compressed', self._on_image, qos_profile_sensor_data,
            event_callbacks=self._image_events('image/compressed'),
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._diagnostics_timer = self.create_timer(self._options.diagnostics_period_s,
                                                    self._on_diagnostics_timer)
        self.get_logger().info(
            f'listening on {self._image_sub.topic_name} and {self._compressed_sub.topic_name} '
            f'({_describe_qos(self._image_sub.qos_profile)}); voting backend {self._backend} '
            f'({self._renderer}, {self._vote_method} voting)'
            + (f', GL not used because {self._fallback_reason}' if self._fallback_reason
               else ''))

    # ----------------------------------------------------------------- executor thread

    def _on_image(self, message: Image | CompressedImage) -> None:
        """Keep only the newest message; a replaced one counts as dropped."""
        topic = (self._image_sub.topic_name if isinstance(message, Image)
                 else self._compressed_sub.topic_name)
        frame = ReceivedFrame(message, topic, self.get_clock().now().nanoseconds,
                              time.monotonic())
        with self._stats.lock:
            self._stats.received += 1
            self._stats.last_received_monotonic_s = frame.received_monotonic_s
        with self._condition:
            if self._pending_frame is not None:
                with self._stats.lock:
                    self._stats.dropped_stale += 1
            self._pending_frame = frame
            self._condition.notify()

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a change as a whole; hand a valid pipeline config to the worker."""
        pipeline_changes = {p.name: p.value for p in parameters
                            if p.name in self._pipeline_names}
        node_changes = {p.name: p.value for p in parameters
                        if p.name not in self._pipeline_names
                        and p.name in NodeOptions.__dataclass_fields__}
        try:
            config = (from_parameters(pipeline_changes, base=self._pipeline_config)
                      if pipeline_changes else None)
            options = (dataclasses.replace(self._options, **node_changes)
                       if node_changes else None)
        except (ConfigError, TypeError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        if config is not None:
            self._pipeline_config = config
            with self._condition:
                self._pending_config = config
                self._condition.notify()
        if options is not None:
            self._options = options
        return SetParametersResult(successful=True)

    def _image_events(self, topic: str) -> SubscriptionEventCallbacks:
        def on_message_lost(event: Any) -> None:
            """The middleware saw images that never arrived (best effort under load)."""
            with self._stats.lock:
                self._stats.lost_in_transport[topic] = int(event.total_count)
        return SubscriptionEventCallbacks(incompatible_qos=self._on_incompatible_qos,
                                          message_lost=on_message_lost)

    def _on_incompatible_qos(self, event: Any) -> None:
        self.get_logger().warn(
            f'a publisher of an image topic has QoS incompatible with this subscriber '
            f'({_describe_qos(self._image_sub.qos_profile)}); last incompatible policy: '
            f'{getattr(event.last_policy_kind, "name", event.last_policy_kind)}. Publish '
            f'with compatible QoS or override it with the qos_overrides parameters.')

    def _on_diagnostics_timer(self) -> None:
        self._warn_if_no_images()
        header = Header(stamp=self.get_clock().now().to_msg())
        self._diagnostics_pub.publish(diagnostics_message(
            self.diagnostics_snapshot(), header, array_class=DiagnosticArray,
            status_class=DiagnosticStatus, key_value_class=KeyValue))

    def diagnostics_snapshot(self) -> DiagnosticsSnapshot:
        """The node's health now: counters, fps since the last call, latencies, backend."""
        now = time.monotonic()
        stats = self._stats
        with stats.lock:
            processed, received, dropped = stats.processed, stats.received, stats.dropped
            dropped_stale, rejected, last_error = (stats.dropped_stale, stats.rejected,
                                                   stats.last_error)
            lost_in_transport = sum(stats.lost_in_transport.values())
            stamp_p50, stamp_p95 = _percentiles_ms(stats.stamp_latency_ms)
            proc_p50, proc_p95 = _percentiles_ms(stats.processing_latency_ms)
            last_received = stats.last_received_monotonic_s
            stage_p50 = {stage: _percentiles_ms(samples)[0]
                         for stage, samples in stats.stage_ms.items()}
            active_limit = stats.active_limit_kmh
        last_tick_s, last_processed = self._last_tick
        fps = (processed - last_processed) / max(now - last_tick_s, 1e-6)
        self._last_tick = (now, processed)
        silent_s = now - (last_received if last_received is not None
                          else self._started_monotonic_s)
        if silent_s > self._options.no_image_warning_s:
            level, message = 'WARN', f'no image for {silent_s:.0f} s'
        elif last_error:
            level, message = 'OK', f'running; last bad input: {last_error}'
        else:
            level, message = 'OK', 'running'
        return DiagnosticsSnapshot(
            name=f'{self.get_name()}: pipeline',
            hardware_id=f'{self._backend}: {self._renderer}',
            level=level, message=message,
            values={
                'frames_received': str(received),
                'frames_processed': str(processed),
                'frames_dropped': str(dropped),
                'frames_dropped_stale': str(dropped_stale),
                'frames_rejected_bad_input': str(rejected),
                'frames_lost_in_transport': str(lost_in_transport),
                'processing_fps': f'{fps:.2f}',
                'latency_p50_ms': f'{stamp_p50:.1f}',
                'latency_p95_ms': f'{stamp_p95:.1f}',
                'processing_latency_p50_ms': f'{proc_p50:.1f}',
                'processing_latency_p95_ms': f'{proc_p95:.1f}',
                **{f'pipeline_{stage}_p50_ms': f'{value:.1f}'
                   for stage, value in stage_p50.items()},
                'seconds_since_last_image': f'{silent_s:.1f}',
                'active_limit_kmh': str(active_limit),
                'backend': self._backend,
                'gl_renderer': self._renderer,
                'vote_method': self._vote_method,
                'gl_fallback_reason': self._fallback_reason or '',
                'last_error': last_error,
            })

    def _warn_if_no_images(self) -> None:
        with self._stats.lock:
            last = self._stats.last_received_monotonic_s
        silent_s = time.monotonic() - (last if last is not None
                                       else self._started_monotonic_s)
        if silent_s < self._options.no_image_warning_s:
            return
        if self._no_image_throttle.admit(self._options.no_image_warning_s) is None:
            return
        publishers = []
        for subscription in (self._image_sub, self._compressed_sub):
            infos = self.get_publishers_info_by_topic(subscription.topic_name)
            publishers.append(
                f'{subscription.topic_name}: {len(infos)} publisher(s)'
                + ''.join(f' [{info.node_name}: '
                          f'{_describe_qos(info.qos_profile, with_history=False)}]'
                          for info in infos))
        self.get_logger().warn(
            f'no image received for {silent_s:.0f} s on {self._image_sub.topic_name} '
            f'(sensor_msgs/Image) or {self._compressed_sub.topic_name} '
            f'(sensor_msgs/CompressedImage). This node subscribes with QoS '
            f'{_describe_qos(self._image_sub.qos_profile)} (sensor data); a publisher must '
            f'offer compatible QoS, and the topic must be remapped to the camera '
            f'(e.g. -r image:=/camera/image_raw). Seen: {"; ".join(publishers)}')

    # ------------------------------------------------------------------ worker thread

    def _run_worker(self) -> None:
        """Own the pipeline: build it, process the newest frame until stopped, close it."""
        try:
            pipeline = Pipeline(self._pipeline_config)
            self._note_backend(pipeline)
            stages = OverlappedPipeline(pipeline, self._finish_frame, self._recognition_failed,
                                        overlap=self._options.overlap_stages)
        except Exception as err:  # noqa: BLE001 - reported to the constructor
            self._worker_error = err
            self._worker_ready.set()
            return
        self._worker_ready.set()
        try:
            while True:
                # take a frame only when it can be detected at once: one that waited here
                # would be stale, while newer ones replace it in the pending slot
                stages.wait_until_ready()
                with self._condition:
                    while (not self._stopping and self._pending_frame is None
                           and self._pending_config is None):
                        self._condition.wait()
                    if self._stopping:
                        return
                    frame, self._pending_frame = self._pending_frame, None
                    config, self._pending_config = self._pending_config, None
                if config is not None:
                    stages.drain()
                    self._reconfigure(pipeline, config)
                if frame is not None:
                    self._process(stages, frame)
        finally:
            stages.close()
            pipeline.close()

    def _reconfigure(self, pipeline: Pipeline, config: PipelineConfig) -> None:
        try:
            pipeline.reconfigure(config)
        except Exception as err:  # noqa: BLE001 - the node keeps its previous stages
            self._record_error(f'cannot apply the new parameters: {err}')
            return
        self._note_backend(pipeline)
        self.get_logger().info(f'parameters applied (backend {self._backend}, '
                               f'{self._vote_method} voting)')

    def _note_backend(self, pipeline: Pipeline) -> None:
        """Keep what the diagnostics report of the pipeline's detector."""
        self._backend, self._renderer = pipeline.backend_name, pipeline.renderer
        self._vote_method = pipeline.vote_method
        self._fallback_reason = pipeline.fallback_reason

    def _process(self, stages: OverlappedPipeline, frame: ReceivedFrame) -> None:
        """Convert and detect one frame (a bad one is counted and logged); its recognition
        and publication follow in :meth:`_finish_frame`."""
        header = frame.message.header
        stamp_ns = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
        stamp_s = stamp_ns * 1e-9 if stamp_ns > 0 else frame.received_ns * 1e-9
        try:
            gray = message_to_gray(frame.message)
            stages.submit(gray, stamp_s, context=(frame, gray, stamp_ns))
        except (ImageConversionError, ValueError) as err:
            self._reject(frame, str(err))
        except Exception as err:  # noqa: BLE001 - one bad frame must not stop the node
            self._reject(frame, f'{type(err).__name__}: {err}')

    def _finish_frame(self, result: FrameResult,
                      context: tuple[ReceivedFrame, np.ndarray, int]) -> None:
        """Publish a frame's results and count it (recognition thread, or the worker)."""
        frame, gray, stamp_ns = context
        if result.tracks_reset:
            self.get_logger().info('image stamps jumped back (a restarted source): '
                                   'tracks and the active limit were reset')
        self._publish(gray, result, frame.message.header)
        done = time.monotonic()
        with self._stats.lock:
            self._stats.processed += 1
            self._stats.active_limit_kmh = result.active_limit_kmh
            self._stats.processing_latency_ms.append((done - frame.received_monotonic_s) * 1e3)
            for stage, duration_ms in result.timings_ms.items():
                self._stats.stage_ms.setdefault(
                    stage, deque(maxlen=LATENCY_WINDOW)).append(duration_ms)
            if stamp_ns > 0:
                self._stats.stamp_latency_ms.append((frame.received_ns - stamp_ns) * 1e-6)

    def _recognition_failed(self, error: Exception,
                            context: tuple[ReceivedFrame, np.ndarray, int]) -> None:
        frame, _, _ = context
        self._reject(frame, f'{type(error).__name__}: {error}')

    def _publish(self, gray: np.ndarray, result: FrameResult, header: Header) -> None:
        self._candidates_pub.publish(candidates_message(
            result, header, pointcloud_class=PointCloud2, pointfield_class=PointField))
        if result.active_limit_kmh != self._published_limit_kmh:
            if result.recognized_limit_kmh:
                self.get_logger().info(f'speed limit {result.active_limit_kmh} km/h')
            self._publish_speed_limit(result.active_limit_kmh)
        if self._options.publish_debug_image and self._debug_pub.get_subscription_count() > 0:
            self._debug_pub.publish(debug_image_message(gray, result, header,
                                                        image_class=Image))

    def _publish_speed_limit(self, limit_kmh: int) -> None:
        self._speed_limit_pub.publish(speed_limit_message(limit_kmh, uint16_class=UInt16))
        self._published_limit_kmh = limit_kmh

    def _reject(self, frame: ReceivedFrame, problem: str) -> None:
        with self._stats.lock:
            self._stats.rejected += 1
        self._record_error(f'frame on {frame.topic} dropped: {problem}')

    def _record_error(self, text: str) -> None:
        with self._stats.lock:
            self._stats.last_error = text
        suppressed = self._error_throttle.admit(self._options.error_log_period_s)
        if suppressed is not None:
            self.get_logger().error(text + (f' ({suppressed} similar errors not logged)'
                                            if suppressed else ''))

    # ---------------------------------------------------------------------- lifecycle

    def destroy_node(self) -> None:
        """Stop the worker (which closes the pipeline on its own thread), then the node."""
        with self._condition:
            self._stopping = True
            self._condition.notify()
        if self._worker.is_alive():
            self._worker.join()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C or SIGTERM; returns the process exit status."""
    rclpy.init(args=args)
    node: SpeedSignDetectorNode | None = None
    try:
        node = SpeedSignDetectorNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SpeedSignError, ParameterException) as err:
        rclpy.logging.get_logger(NODE_NAME).fatal(f'cannot start: {err}')
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
