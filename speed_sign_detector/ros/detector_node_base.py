"""What the plain and the managed (lifecycle) node share: pipeline worker, topics, diagnostics.

:class:`DetectorNodeBase` is a mixin for an rclpy ``Node`` or ``LifecycleNode``; the two
node classes (:mod:`~speed_sign_detector.ros.node`,
:mod:`~speed_sign_detector.ros.lifecycle_node`) only decide *when* its parts start and
stop: the plain node starts everything in its constructor, the managed one in its
transitions.

Threads:
    * The executor thread runs the subscription callbacks, which only store the newest
      message (a message replaced before it was processed counts as dropped) and feed
      its header stamp to the transport-loss estimate; the diagnostics timer; the
      parameter callback. It never waits for processing.
    * One worker thread owns the :class:`~speed_sign_detector.pipeline.Pipeline` (and so
      the OpenGL context, created, used and released on that thread): it converts the
      newest frame and detects its candidates.
    * With ``overlap_stages`` (the default), a recognition thread classifies and tracks
      each detected frame while the worker detects the next one, and publishes the
      results (:class:`~speed_sign_detector.overlapped_pipeline.OverlappedPipeline`;
      with ``classifier_workers`` N, N recognition threads classify and take turns to
      track and publish, frames in order; 0, the default, sizes N to the host:
      :mod:`~speed_sign_detector.classifier_placement`); without it the worker does that
      too.

Worker threads are stopped (:meth:`DetectorNodeBase.stop_pipeline`) before the node is
destroyed and before the ROS context shuts down, so no thread publishes through a dead
context.
"""
from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
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

from speed_sign_detector.classifier_placement import ClassifierPlacement, place_classifier
from speed_sign_detector.config import NodeOptions, PipelineConfig
from speed_sign_detector.config_parameters import (
    from_parameters,
    node_option_specs,
    parameter_specs,
)
from speed_sign_detector.detection.detector import cpu_detector_advice
from speed_sign_detector.errors import ConfigError, ImageConversionError, SpeedSignError
from speed_sign_detector.image_conversion import message_to_gray
from speed_sign_detector.overlapped_pipeline import OverlappedPipeline
from speed_sign_detector.pipeline import FrameResult, Pipeline
from speed_sign_detector.ros.frame_statistics import (
    LATENCY_WINDOW,
    FrameStatistics,
    LogThrottle,
    ReceivedFrame,
    describe_qos,
    percentiles_ms,
)
from speed_sign_detector.ros.input_warnings import no_image_warning, transport_loss_warning
from speed_sign_detector.ros.messages import (
    DiagnosticsSnapshot,
    candidates_message,
    debug_image_message,
    diagnostics_message,
    speed_limit_message,
)
from speed_sign_detector.ros.parameters import (
    declare_node_parameters,
    parameter_values,
    unknown_parameter_overrides,
)

#: QoS of the image subscriptions (sensor data: best effort, volatile, keep last 5).
IMAGE_QOS = qos_profile_sensor_data
#: Seconds between two transport-loss warnings in the log.
TRANSPORT_LOSS_LOG_PERIOD_S = 10.0
#: Seconds the deactivation waits for frames in flight to be published.
DRAIN_TIMEOUT_S = 30.0


class DetectorNodeBase:
    """Mixin holding the detector's state and parts; see the module docstring.

    The host class must be an rclpy ``Node`` (or ``LifecycleNode``) and call
    :meth:`init_detector` in its constructor.
    """

    # ------------------------------------------------------------------- construction

    def init_detector(self) -> None:
        """Declare the parameters, read them, set up the (idle) state.

        Raises:
            ConfigError: for invalid initial parameters.
        """
        self._worker: threading.Thread | None = None  # before anything that may fail
        self._pipeline_specs = parameter_specs()
        self._pipeline_names = frozenset(spec.name for spec in self._pipeline_specs)
        declare_node_parameters(self)
        for warning in unknown_parameter_overrides(self):
            self.get_logger().warning(warning)
        self._pipeline_config, self._options = self.read_parameters()
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._stats = FrameStatistics()
        self._error_throttle = LogThrottle()
        self._no_image_throttle = LogThrottle()
        self._transport_loss_throttle = LogThrottle()
        self._started_monotonic_s = time.monotonic()
        self._condition = threading.Condition()
        self._pending_frame: ReceivedFrame | None = None
        self._pending_config: PipelineConfig | None = None
        self._drain_requests: list[threading.Event] = []
        self._stopping = False
        self._backend = 'not started'
        self._renderer = ''
        self._vote_method = ''
        self._fallback_reason: str | None = None
        self._backend_choice = ''
        self._classifier_location = 'off'
        self._classifier_placement: ClassifierPlacement | None = None
        self._last_tick = (time.monotonic(), 0)
        self._published_limit_kmh: int | None = None
        self._worker_error: BaseException | None = None
        self._candidates_pub: Any = None
        self._speed_limit_pub: Any = None
        self._debug_pub: Any = None
        self._diagnostics_pub: Any = None
        self._image_sub: Any = None
        self._compressed_sub: Any = None
        self._diagnostics_timer: Any = None

    def read_parameters(self) -> tuple[PipelineConfig, NodeOptions]:
        """The pipeline config and node options of the current parameter values.

        Raises:
            ConfigError: naming the invalid value.
        """
        pipeline = from_parameters(parameter_values(self, self._pipeline_specs))
        try:
            options = NodeOptions(**parameter_values(self, node_option_specs()))
        except TypeError as err:
            raise ConfigError(f'invalid node option: {err}') from err
        return pipeline, options

    # ---------------------------------------------------------- parts started/stopped

    def start_pipeline(self) -> None:
        """Build the pipeline on a new worker thread (GL context, filter banks); returns
        once it is ready.

        Raises:
            SpeedSignError: when the pipeline cannot be built (the reason in the message).
        """
        if self._worker is not None:
            return
        self._stopping = False
        self._worker_error = None
        with self._condition:
            # the new pipeline is built from _pipeline_config, which holds every change
            # accepted so far: none is left to apply to it
            self._pending_config = None
        ready = threading.Event()
        self._worker = threading.Thread(target=self._run_worker, args=(ready,),
                                        name='speed_sign_pipeline', daemon=True)
        self.get_logger().info('building the pipeline (GL context, classifier filter banks)')
        self._worker.start()
        ready.wait()
        if self._worker_error is not None:
            error, self._worker_error = self._worker_error, None
            self._worker.join()
            self._worker = None
            if isinstance(error, SpeedSignError):
                raise error
            raise SpeedSignError(f'cannot build the pipeline: {error}') from error

    def stop_pipeline(self) -> None:
        """Stop the worker and recognition threads (the worker closes the pipeline and
        its GL context on its own thread). Idempotent."""
        worker = getattr(self, '_worker', None)
        if worker is None:
            return
        with self._condition:
            self._stopping = True
            self._pending_frame = None
            self._condition.notify_all()
        if worker is not threading.current_thread():
            worker.join()
        self._worker = None

    @property
    def pipeline_running(self) -> bool:
        """True while the worker thread holds a built pipeline (and its GL context)."""
        worker = getattr(self, '_worker', None)
        return worker is not None and worker.is_alive()

    def create_outputs(self, create_publisher: Callable[..., Any]) -> None:
        """Create the output publishers with ``create_publisher`` (plain or lifecycle)."""
        self._candidates_pub = create_publisher(PointCloud2, 'candidates', 10)
        self._speed_limit_pub = create_publisher(UInt16, 'speed_limit', QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST))
        self._debug_pub = create_publisher(Image, 'debug_image', 1)
        self._diagnostics_pub = create_publisher(DiagnosticArray, '/diagnostics', 10)

    def destroy_outputs(self, destroy_publisher: Callable[[Any], Any]) -> None:
        """Destroy the output publishers (idempotent)."""
        for name in ('_candidates_pub', '_speed_limit_pub', '_debug_pub', '_diagnostics_pub'):
            publisher = getattr(self, name)
            if publisher is not None:
                destroy_publisher(publisher)
                setattr(self, name, None)

    def subscribe_images(self) -> None:
        """Subscribe to ``image`` and ``image/compressed`` and start the diagnostics."""
        if self._image_sub is None:
            self._image_sub = self.create_subscription(
                Image, 'image', self._on_image, IMAGE_QOS,
                event_callbacks=self._image_events('image'),
                qos_overriding_options=QoSOverridingOptions.with_default_policies())
            self._compressed_sub = self.create_subscription(
                CompressedImage, 'image/compressed', self._on_image, IMAGE_QOS,
                event_callbacks=self._image_events('image/compressed'),
                qos_overriding_options=QoSOverridingOptions.with_default_policies())
        if self._diagnostics_timer is None:
            self._diagnostics_timer = self.create_timer(self._options.diagnostics_period_s,
                                                        self._on_diagnostics_timer)
        self._started_monotonic_s = time.monotonic()
        self.get_logger().info(
            f'listening on {self._image_sub.topic_name} and {self._compressed_sub.topic_name} '
            f'({describe_qos(self._image_sub.qos_profile)}); voting backend {self._backend} '
            f'({self._renderer}, {self._vote_method} voting; {self._backend_choice})'
            + (f', GL not used because {self._fallback_reason}' if self._fallback_reason
               else ''))
        advice = cpu_detector_advice(self._backend, self._renderer,
                                     self._pipeline_config.detector)
        if advice is not None:
            self.get_logger().warning(advice)

    def unsubscribe_images(self) -> None:
        """Stop the subscriptions and the diagnostics timer (idempotent)."""
        for name in ('_image_sub', '_compressed_sub'):
            subscription = getattr(self, name)
            if subscription is not None:
                self.destroy_subscription(subscription)
                setattr(self, name, None)
        if self._diagnostics_timer is not None:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = None

    def finish_frames_in_flight(self) -> bool:
        """Drop the waiting frame and wait until the frames being processed are published.

        Returns False if they were not done within :data:`DRAIN_TIMEOUT_S`.
        """
        if self._worker is None:
            return True
        done = threading.Event()
        with self._condition:
            self._pending_frame = None
            self._drain_requests.append(done)
            self._condition.notify_all()
        return done.wait(DRAIN_TIMEOUT_S)

    def publish_speed_limit(self, limit_kmh: int) -> None:
        """Publish the active limit (latched) and remember it."""
        self._speed_limit_pub.publish(speed_limit_message(limit_kmh, uint16_class=UInt16))
        self._published_limit_kmh = limit_kmh

    # ----------------------------------------------------------------- executor thread

    def _on_image(self, message: Image | CompressedImage) -> None:
        """Keep only the newest message; a replaced one counts as dropped."""
        subscription = self._image_sub if isinstance(message, Image) else self._compressed_sub
        topic = subscription.topic_name if subscription is not None else '?'
        frame = ReceivedFrame(message, topic, self.get_clock().now().nanoseconds,
                              time.monotonic())
        stamp = message.header.stamp
        with self._stats.lock:
            self._stats.received += 1
            self._stats.last_received_monotonic_s = frame.received_monotonic_s
            self._stats.transport_loss.add(topic, stamp.sec * 1_000_000_000 + stamp.nanosec)
        with self._condition:
            if self._pending_frame is not None:
                with self._stats.lock:
                    self._stats.dropped_stale += 1
            self._pending_frame = frame
            self._condition.notify_all()

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
                self._condition.notify_all()
        if options is not None:
            self._options = options
        return SetParametersResult(successful=True)

    def _image_events(self, topic: str) -> SubscriptionEventCallbacks:
        def on_message_lost(event: Any) -> None:
            """The middleware saw images that never arrived (not every loss is seen)."""
            with self._stats.lock:
                self._stats.lost_reported_by_middleware[topic] = int(event.total_count)
        return SubscriptionEventCallbacks(incompatible_qos=self._on_incompatible_qos,
                                          message_lost=on_message_lost)

    def _on_incompatible_qos(self, event: Any) -> None:
        self.get_logger().warn(
            f'a publisher of an image topic has QoS incompatible with this subscriber '
            f'({describe_qos(self._image_sub.qos_profile if self._image_sub else IMAGE_QOS)}'
            f'); last incompatible policy: '
            f'{getattr(event.last_policy_kind, "name", event.last_policy_kind)}. Publish '
            f'with compatible QoS or override it with the qos_overrides parameters.')

    def _on_diagnostics_timer(self) -> None:
        self._warn_if_no_images()
        snapshot = self.diagnostics_snapshot()
        if self._diagnostics_pub is not None:
            header = Header(stamp=self.get_clock().now().to_msg())
            self._diagnostics_pub.publish(diagnostics_message(
                snapshot, header, array_class=DiagnosticArray,
                status_class=DiagnosticStatus, key_value_class=KeyValue))

    def diagnostics_snapshot(self) -> DiagnosticsSnapshot:
        """The node's health now: counters, fps and transport loss since the last call,
        latencies, backend."""
        now = time.monotonic()
        stats = self._stats
        with stats.lock:
            processed, received, dropped = stats.processed, stats.received, stats.dropped
            dropped_stale, rejected, last_error = (stats.dropped_stale, stats.rejected,
                                                   stats.last_error)
            transport_total = stats.transport_loss.totals()
            transport_recent = stats.transport_loss.since_last_call(transport_total)
            middleware_lost = sum(stats.lost_reported_by_middleware.values())
            stamp_p50, stamp_p95 = percentiles_ms(stats.stamp_latency_ms)
            proc_p50, proc_p95 = percentiles_ms(stats.processing_latency_ms)
            last_received = stats.last_received_monotonic_s
            stage_p50 = {stage: percentiles_ms(samples)[0]
                         for stage, samples in stats.stage_ms.items()}
            active_limit = stats.active_limit_kmh
        last_tick_s, last_processed = self._last_tick
        fps = (processed - last_processed) / max(now - last_tick_s, 1e-6)
        self._last_tick = (now, processed)
        silent_s = now - (last_received if last_received is not None
                          else self._started_monotonic_s)
        losing = (transport_recent.frames_lost > 0 and transport_recent.lost_share
                  > self._options.transport_loss_warning_share)
        if silent_s > self._options.no_image_warning_s:
            level, message = 'WARN', f'no image for {silent_s:.0f} s' + (
                f' (the source stopped after {received} frames)' if received else '')
        elif losing:
            level, message = 'WARN', (
                f'frames lost in transport: {transport_recent.frames_lost} of '
                f'{transport_recent.frames_received + transport_recent.frames_lost} '
                f'({100 * transport_recent.lost_share:.0f} %) since the last report')
            self._warn_transport_loss(transport_recent.lost_share, transport_total)
        elif last_error:
            level, message = 'OK', f'running; last bad input: {last_error}'
        else:
            level, message = 'OK', 'running'
        period = transport_total.frame_period_s
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
                'frames_lost_in_transport': str(transport_total.frames_lost),
                'frames_lost_in_transport_share': f'{transport_total.lost_share:.3f}',
                'frames_lost_reported_by_middleware': str(middleware_lost),
                'source_frame_period_ms': f'{period * 1e3:.1f}' if period else 'nan',
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
                'backend_choice': self._backend_choice,
                'classifier': self._classifier_location,
                'last_error': last_error,
            })

    def _warn_transport_loss(self, recent_share: float, total: Any) -> None:
        if self._transport_loss_throttle.admit(TRANSPORT_LOSS_LOG_PERIOD_S) is None:
            return
        with self._stats.lock:
            lossy = [topic for topic, lost in
                     self._stats.transport_loss.lost_by_topic().items() if lost]
        self.get_logger().warn(transport_loss_warning(
            lossy, recent_share, total.frames_lost, total.frames_received,
            total.frame_period_s))

    def _warn_if_no_images(self) -> None:
        if self._image_sub is None:
            return
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
                          f'{describe_qos(info.qos_profile, with_history=False)}]'
                          for info in infos))
        self.get_logger().warn(no_image_warning(
            silent_s, self._image_sub.topic_name, self._compressed_sub.topic_name,
            describe_qos(self._image_sub.qos_profile), publishers))

    # ------------------------------------------------------------------ worker thread

    def _run_worker(self, ready: threading.Event) -> None:
        """Own the pipeline: build it, process the newest frame until stopped, close it."""
        try:
            config, placement = place_classifier(self._pipeline_config,
                                                 self._options.overlap_stages)
            pipeline = Pipeline(config)
            self._note_classifier_placement(placement)
            self._note_backend(pipeline)
            stages = OverlappedPipeline(pipeline, self._finish_frame, self._recognition_failed,
                                        overlap=self._options.overlap_stages)
        except Exception as err:  # noqa: BLE001 - reported by start_pipeline
            self._worker_error = err
            ready.set()
            return
        ready.set()
        try:
            while True:
                # take a frame only when it can be detected at once: one that waited here
                # would be stale, while newer ones replace it in the pending slot
                stages.wait_until_ready()
                with self._condition:
                    while (not self._stopping and self._pending_frame is None
                           and self._pending_config is None and not self._drain_requests):
                        self._condition.wait()
                    if self._stopping:
                        return
                    frame, self._pending_frame = self._pending_frame, None
                    config, self._pending_config = self._pending_config, None
                    drains, self._drain_requests = self._drain_requests, []
                if drains:
                    stages.drain()
                    for done in drains:
                        done.set()
                if config is not None:
                    stages.drain()
                    self._reconfigure(pipeline, config)
                if frame is not None:
                    self._process(stages, frame)
                    if pipeline.backend_choice != self._backend_choice:  # auto decided
                        self._note_backend(pipeline)
                        self.get_logger().info(f'detector backend {self._backend_choice}')
        finally:
            stages.close()
            pipeline.close()
            with self._condition:
                for done in self._drain_requests:
                    done.set()
                self._drain_requests = []

    def _reconfigure(self, pipeline: Pipeline, config: PipelineConfig) -> None:
        placed, placement = place_classifier(config, self._options.overlap_stages)
        try:
            pipeline.reconfigure(placed)
        except Exception as err:  # noqa: BLE001 - the node keeps its previous stages
            self._record_error(f'cannot apply the new parameters: {err}')
            return
        self._note_classifier_placement(placement)
        self._note_backend(pipeline)
        self.get_logger().info(f'parameters applied (backend {self._backend}, '
                               f'{self._vote_method} voting)')

    def _note_backend(self, pipeline: Pipeline) -> None:
        """Keep what the diagnostics report of the pipeline's detector."""
        self._backend, self._renderer = pipeline.backend_name, pipeline.renderer
        self._vote_method = pipeline.vote_method
        self._fallback_reason = pipeline.fallback_reason
        self._backend_choice = pipeline.backend_choice
        location, placement = pipeline.classifier_location, self._classifier_placement
        self._classifier_location = (f'{location} ({placement.reason})'
                                     if placement is not None and location != 'off'
                                     else location)

    def _note_classifier_placement(self, placement: ClassifierPlacement) -> None:
        """Keep where the classifier runs; log it at start and when it changes."""
        if placement != self._classifier_placement:
            self.get_logger().info(placement.describe() + (
                '' if placement.automatic else f'; {placement.cpus} usable CPUs'))
        self._classifier_placement = placement

    def _process(self, stages: OverlappedPipeline, frame: ReceivedFrame) -> None:
        """Convert and detect one frame (a bad one is counted and logged); its recognition
        and publication follow in :meth:`_finish_frame`."""
        header = frame.message.header
        stamp_ns = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
        stamp_s = stamp_ns * 1e-9 if stamp_ns > 0 else frame.received_ns * 1e-9
        try:
            started = time.perf_counter()
            gray = message_to_gray(frame.message)
            stages.submit(gray, stamp_s, context=(frame, gray, stamp_ns),
                          conversion_ms=(time.perf_counter() - started) * 1e3)
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
        if self._candidates_pub is None:
            return
        self._candidates_pub.publish(candidates_message(
            result, header, pointcloud_class=PointCloud2, pointfield_class=PointField))
        if result.active_limit_kmh != self._published_limit_kmh:
            if result.recognized_limit_kmh:
                self.get_logger().info(f'speed limit {result.active_limit_kmh} km/h')
            self.publish_speed_limit(result.active_limit_kmh)
        if self._options.publish_debug_image and self._debug_pub.get_subscription_count() > 0:
            self._debug_pub.publish(debug_image_message(gray, result, header,
                                                        image_class=Image))

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
