"""The one way through: a grayscale frame in, a :class:`FrameResult` out.

The node, the bag tools, the evaluation and the benchmarks all run frames through
:class:`Pipeline`: detection (radial-symmetry voting), recognition (FFT correlation
with MACE filter banks) and temporal integration (tracking table, active limit).
:class:`OverlappedPipeline` runs the same two halves on two threads, so that frame
N+1 is detected while frame N is recognized (the node's way). No ROS imports here.
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

import numpy as np

from speed_sign_detector.blas_threads import blas_thread_advice
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.recognition.classifier import Classification, Classifier
from speed_sign_detector.recognition.classifier_process import (
    ClassifierProcess,
    start_classifier_processes,
)
from speed_sign_detector.tracking import Tracker, TrackState

LOGGER = logging.getLogger(__name__)


@dataclass(frozen=True)
class Detection:
    """A candidate with what the classifier said of it (None when classification is off)."""

    candidate: Candidate
    classification: Classification | None


@dataclass(frozen=True)
class FrameResult:
    """Everything the pipeline found in one frame.

    Attributes:
        stamp_s: message time of the frame, seconds.
        width_px, height_px: frame size.
        detections: this frame's candidates, best first, with their classification.
        tracks: the tracking table after this frame.
        active_limit_kmh: the limit in force after this frame, 0 when none is known.
        recognized_limit_kmh: a limit newly recognized in this frame, 0 when none.
        timings_ms: stage durations in milliseconds: ``detect``, ``classify``,
            ``track``, ``total``.
        tracks_reset: True when the frame's time jumped back (a restarted source) and
            the tracker started afresh.
    """

    stamp_s: float
    width_px: int
    height_px: int
    detections: tuple[Detection, ...]
    tracks: tuple[TrackState, ...]
    active_limit_kmh: int
    recognized_limit_kmh: int
    timings_ms: Mapping[str, float]
    tracks_reset: bool = False


@dataclass(frozen=True)
class DetectedFrame:
    """A frame after detection, waiting for recognition and tracking.

    Attributes:
        gray: the (H, W) uint8 frame.
        stamp_s: message time of the frame, seconds.
        candidates: the detector's candidates, best first.
        detect_ms: time the detection took, milliseconds.
    """

    gray: np.ndarray
    stamp_s: float
    candidates: tuple[Candidate, ...]
    detect_ms: float


@dataclass(frozen=True)
class ClassifiedFrame:
    """A frame after classification, waiting for tracking.

    Attributes:
        frame: the detected frame.
        classifications: what the classifier said of each candidate, in order (None
            each when classification is off).
        classify_ms: time the classification took, milliseconds.
    """

    frame: DetectedFrame
    classifications: tuple[Classification | None, ...]
    classify_ms: float


class Pipeline:
    """Detector, classifier and tracker behind one ``process`` call.

    The detector may hold an OpenGL context: create, close and :meth:`detect` on one
    thread. :meth:`recognize` may run on another thread (one at a time, frames in
    order), which is what :class:`OverlappedPipeline` does; its two steps too, with
    several classifier workers: :meth:`classify` of different workers at the same time,
    :meth:`track` one frame at a time in order.

    Example:
        >>> import numpy as np
        >>> with Pipeline(PipelineConfig(backend='numpy', classify=False)) as pipeline:
        ...     result = pipeline.process(np.zeros((120, 160), np.uint8), stamp_s=0.0)
        >>> result.active_limit_kmh
        0
    """

    def __init__(self, config: PipelineConfig | None = None) -> None:
        self.config = config or PipelineConfig()
        self._detector: Detector | None = Detector(self.config.detector,
                                                   backend=self.config.backend)
        self._classifiers = _build_classifiers(self.config)
        self._tracker = Tracker(self.config.tracker)
        in_process = any(isinstance(item, Classifier) for item in self._classifiers)
        advice = blas_thread_advice() if in_process else None
        if advice is not None:
            LOGGER.warning(advice)
        LOGGER.info('pipeline ready: backend %s (%s), %s voting%s', self.backend_name,
                    self.renderer, self.vote_method,
                    f', fell back because {self.fallback_reason}' if self.fallback_reason
                    else '')

    @property
    def backend_name(self) -> str:
        """Voting backend in use: ``'gl'`` or ``'numpy'``."""
        return self._live_detector().backend_name

    @property
    def renderer(self) -> str:
        """The GL renderer string, or a description of the numpy reference."""
        return self._live_detector().renderer

    @property
    def vote_method(self) -> str:
        """How votes are added: ``'raster'`` or ``'scatter'`` (GL), ``'numpy'``."""
        return self._live_detector().vote_method

    @property
    def classifier_workers(self) -> int:
        """How many frames :meth:`classify` can work on at the same time (one per
        ``worker`` index), at least 1."""
        return max(1, len(self._classifiers))

    @property
    def classifier_location(self) -> str:
        """Where the classifier runs: ``'off'``, ``'in this process'`` or ``'N worker
        process(es)'``."""
        if not self._classifiers:
            return 'off'
        if isinstance(self._classifiers[0], ClassifierProcess):
            count = len(self._classifiers)
            return f'{count} worker process{"es" if count > 1 else ""}'
        return 'in this process'

    @property
    def fallback_reason(self) -> str | None:
        """Why the GL backend is not used although it was allowed, else None."""
        return self._live_detector().fallback_reason

    def process(self, gray: np.ndarray, stamp_s: float) -> FrameResult:
        """Run one frame through detection, recognition and tracking.

        Args:
            gray: frame, shape (H, W), dtype uint8.
            stamp_s: message time of the frame in seconds (drives track expiry).

        Raises:
            ValueError: for an unusable frame (empty, wrong dtype or shape, too small).
        """
        return self.recognize(self.detect(gray, stamp_s))

    def detect(self, gray: np.ndarray, stamp_s: float) -> DetectedFrame:
        """The first half of :meth:`process`: the candidates of one frame.

        Runs on the thread that created the pipeline (the detector's GL context).

        Raises:
            ValueError: for an unusable frame (empty, wrong dtype or shape, too small).
        """
        detector = self._live_detector()
        started = time.perf_counter()
        candidates = detector.detect(gray)
        return DetectedFrame(gray, stamp_s, candidates, (time.perf_counter() - started) * 1e3)

    def recognize(self, frame: DetectedFrame) -> FrameResult:
        """The second half of :meth:`process`: classification and tracking.

        Frames must come in the order they were detected (the tracker integrates them).
        """
        return self.track(self.classify(frame))

    def classify(self, frame: DetectedFrame, worker: int = 0) -> ClassifiedFrame:
        """Classification alone, the first step of :meth:`recognize`.

        Args:
            frame: a detected frame.
            worker: which classifier reads it, in ``[0, classifier_workers)``: calls with
                different workers may run at the same time on different threads (each
                worker one frame at a time), in any order.

        Raises:
            IndexError: for a worker outside that range.
        """
        if not 0 <= worker < self.classifier_workers:
            raise IndexError(f'worker {worker} is outside [0, {self.classifier_workers})')
        started = time.perf_counter()
        candidates = frame.candidates
        if self._classifiers and candidates:
            classifications: tuple[Classification | None, ...] = \
                self._classifiers[worker].classify(frame.gray, candidates)
        else:
            classifications = (None,) * len(candidates)
        return ClassifiedFrame(frame, classifications, (time.perf_counter() - started) * 1e3)

    def track(self, classified: ClassifiedFrame) -> FrameResult:
        """Tracking, the second step of :meth:`recognize`: frames in the order they were
        detected, one at a time."""
        frame = classified.frame
        started = time.perf_counter()
        pairs = list(zip(frame.candidates, classified.classifications))
        update = self._tracker.update(frame.stamp_s, pairs)
        tracked = time.perf_counter()
        return FrameResult(
            stamp_s=frame.stamp_s,
            width_px=int(frame.gray.shape[1]),
            height_px=int(frame.gray.shape[0]),
            detections=tuple(Detection(candidate, classification)
                             for candidate, classification in pairs),
            tracks=update.tracks,
            active_limit_kmh=update.active_limit_kmh,
            recognized_limit_kmh=update.recognized_limit_kmh,
            timings_ms={'detect': frame.detect_ms,
                        'classify': classified.classify_ms,
                        'track': (tracked - started) * 1e3,
                        'total': frame.detect_ms + classified.classify_ms
                        + (tracked - started) * 1e3},
            tracks_reset=update.tracks_reset)

    def reconfigure(self, config: PipelineConfig) -> None:
        """Apply a new config, rebuilding only the stages whose settings changed.

        The tracker keeps its tracks and active limit when only its weights change.
        """
        if config.detector != self.config.detector or config.backend != self.config.backend:
            detector = Detector(config.detector, backend=config.backend)
            self._live_detector().close()
            self._detector = detector
        if config.classify != self.config.classify \
                or config.classifier_process != self.config.classifier_process \
                or config.classifier_workers != self.config.classifier_workers or (
                config.classify and config.classifier != self.config.classifier):
            classifiers = _build_classifiers(config)
            _close_classifiers(self._classifiers)
            self._classifiers = classifiers
        if config.tracker != self.config.tracker:
            self._tracker.config = config.tracker
        self.config = config

    def reset(self) -> None:
        """Forget tracks and the active limit (a new drive or a restarted bag)."""
        self._tracker.reset()

    def close(self) -> None:
        """Release the detector's GL context (and stop the classifier's process, if it
        has one); the pipeline cannot process afterwards."""
        if self._detector is not None:
            self._detector.close()
            self._detector = None
        _close_classifiers(self._classifiers)
        self._classifiers = ()

    def _live_detector(self) -> Detector:
        if self._detector is None:
            raise RuntimeError('this Pipeline was closed; create a new one')
        return self._detector

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def _build_classifiers(config: PipelineConfig
                       ) -> tuple[Classifier, ...] | tuple[ClassifierProcess, ...]:
    """The classifiers ``config`` asks for: none, one in this process, or
    ``classifier_workers`` in worker processes of their own."""
    if not config.classify:
        return ()
    if config.classifier_process:
        return start_classifier_processes(config.classifier, config.classifier_workers)
    return (Classifier(config.classifier),)


def _close_classifiers(classifiers: tuple[Classifier | ClassifierProcess, ...]) -> None:
    """Stop the classifiers' worker processes, where they have them."""
    for classifier in classifiers:
        if isinstance(classifier, ClassifierProcess):
            classifier.close()


ResultCallback = Callable[[FrameResult, Any], None]
"""``on_result(result, context)``: a frame's result and the context it was submitted with."""
ErrorCallback = Callable[[Exception, Any], None]
"""``on_error(error, context)``: recognition of a frame raised ``error``."""


class OverlappedPipeline:
    """Detection of frame N+1 overlapping the recognition of frame N, on two threads (or
    more, with several classifier workers).

    :meth:`submit` detects on the calling thread (the one that owns the pipeline and
    its GL context), then hands the frame to a helper thread, which recognizes and
    tracks it and calls ``on_result(result, context)`` there, frames in the order they
    were submitted. On a multi-core machine the two halves run at the same time, so
    frames go through at the pace of the slower half instead of the sum of both (the GL
    detector releases the GIL while the driver works). A result comes one recognition
    later than with :meth:`Pipeline.process`.

    With ``classifier_workers`` N above 1 (worker processes, see
    :class:`~speed_sign_detector.config.PipelineConfig`) there are N helpers, helper i
    classifying with worker i: up to N frames are classified at the same time, and each
    is tracked and reported in its turn, so results still come in the order submitted
    and the tracker sees the frames in that order. The helpers follow the pipeline's
    worker count as :meth:`Pipeline.reconfigure` changes it (at the next :meth:`submit`).

    At most one detected frame waits for a helper: :meth:`submit` first waits until
    the previous one has been taken, so a caller that keeps only the newest frame (the
    node) never detects a frame that would then wait. With ``overlap=False``
    :meth:`submit` runs :meth:`Pipeline.process` and calls ``on_result`` itself.

    Args:
        pipeline: the pipeline; created on the calling thread.
        on_result: called with each frame's result and the submitted ``context``.
        on_error: called when recognition of a frame raises (the helper keeps going).
        overlap: False runs everything on the calling thread.

    Call :meth:`drain` before :meth:`Pipeline.reconfigure` or :meth:`Pipeline.reset`,
    and :meth:`close` before closing the pipeline.
    """

    def __init__(self, pipeline: Pipeline, on_result: ResultCallback,
                 on_error: ErrorCallback, overlap: bool = True) -> None:
        self.pipeline = pipeline
        self.overlap = overlap
        self._on_result = on_result
        self._on_error = on_error
        self._condition = threading.Condition()
        # the frame waiting for a helper: (sequence number, frame, context)
        self._waiting: tuple[int, DetectedFrame, Any] | None = None
        self._submitted = 0  # sequence numbers handed out
        self._next_to_report = 0  # the sequence number whose result goes out next
        self._in_flight = 0  # frames taken by helpers and not yet reported
        self._closed = False
        self._helpers: dict[int, threading.Thread] = {}  # by classifier worker
        if overlap:
            self._start_helpers()

    def wait_until_ready(self) -> None:
        """Block until :meth:`submit` can detect at once (no frame waits for a helper)."""
        with self._condition:
            while self._waiting is not None and not self._closed:
                self._condition.wait()

    def submit(self, gray: np.ndarray, stamp_s: float, context: Any = None) -> None:
        """Detect a frame here, then recognize it on a helper (see the class).

        Errors of the detection (and, with ``overlap=False``, of the recognition and of
        ``on_result``) propagate from here; with overlap, the recognition's go to
        ``on_error``.

        Raises:
            ValueError: for an unusable frame (nothing is handed to the helper).
            RuntimeError: after :meth:`close`.
        """
        if self._closed:
            raise RuntimeError('this OverlappedPipeline was closed')
        if not self.overlap:
            self._on_result(self.pipeline.process(gray, stamp_s), context)
            return
        self._start_helpers()
        self.wait_until_ready()
        detected = self.pipeline.detect(gray, stamp_s)
        with self._condition:
            if self._closed:
                raise RuntimeError('this OverlappedPipeline was closed')
            self._waiting = (self._submitted, detected, context)
            self._submitted += 1
            self._condition.notify_all()

    def drain(self) -> None:
        """Block until every submitted frame has been recognized and reported."""
        with self._condition:
            while (self._waiting is not None or self._in_flight) and any(
                    helper.is_alive() for helper in self._helpers.values()):
                self._condition.wait()

    def close(self) -> None:
        """Finish the submitted frames and stop the helpers (idempotent)."""
        self.drain()
        with self._condition:
            self._closed = True
            self._condition.notify_all()
        for helper in self._helpers.values():
            helper.join()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _start_helpers(self) -> None:
        """A helper for each classifier worker of the pipeline that has none running
        (helpers beyond the workers' count stop by themselves)."""
        for worker in range(self.pipeline.classifier_workers):
            helper = self._helpers.get(worker)
            if helper is None or not helper.is_alive():
                helper = threading.Thread(
                    target=self._run_helper, args=(worker,), daemon=True,
                    name='recognition' if worker == 0 else f'recognition-{worker}')
                self._helpers[worker] = helper
                helper.start()

    def _run_helper(self, worker: int) -> None:
        while True:
            with self._condition:
                while self._waiting is None and not self._closed \
                        and worker < self.pipeline.classifier_workers:
                    self._condition.wait()
                if self._waiting is None or worker >= self.pipeline.classifier_workers:
                    return
                (sequence, detected, context), self._waiting = self._waiting, None
                self._in_flight += 1
                self._condition.notify_all()
            classified: ClassifiedFrame | Exception
            try:
                classified = self.pipeline.classify(detected, worker)
            except Exception as err:  # noqa: BLE001 - reported in its turn, on_error
                classified = err
            with self._condition:
                while self._next_to_report != sequence:
                    self._condition.wait()
            try:
                self._report(classified, context)
            finally:
                with self._condition:
                    self._next_to_report += 1
                    self._in_flight -= 1
                    self._condition.notify_all()

    def _report(self, classified: ClassifiedFrame | Exception, context: Any) -> None:
        """Track a classified frame and call ``on_result``, or ``on_error`` with what
        its classification or tracking raised (in the frame's turn)."""
        try:
            if isinstance(classified, Exception):
                self._on_error(classified, context)
                return
            try:
                result = self.pipeline.track(classified)
            except Exception as err:  # noqa: BLE001 - one bad frame must not stop it
                self._on_error(err, context)
            else:
                self._on_result(result, context)
        except Exception:  # noqa: BLE001 - a failing callback must not stop it either
            LOGGER.exception('result callback failed')
