"""The one way through: a grayscale frame in, a :class:`FrameResult` out.

The node, the bag tools, the evaluation and the benchmarks all run frames through
:class:`Pipeline`: detection (radial-symmetry voting), recognition (FFT correlation
with MACE filter banks) and temporal integration (tracking table, active limit).
:class:`~speed_sign_detector.overlapped_pipeline.OverlappedPipeline` runs the same
halves on several threads, so that frame N+1 is detected while frame N is recognized
(the node's way). No ROS imports here.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np

from speed_sign_detector.blas_threads import limit_blas_threads
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import DETECTION_STAGES, Detector
from speed_sign_detector.recognition.classifier import Classification, Classifier
from speed_sign_detector.recognition.classifier_process import (
    ClassifierProcess,
    start_classifier_processes,
)
from speed_sign_detector.tracking import Tracker, TrackState

LOGGER = logging.getLogger(__name__)

#: The stages of :attr:`FrameResult.timings_ms` that follow one another (each frame's
#: times of these add up to at most its ``total``): image conversion (by the caller),
#: the detector's :data:`~speed_sign_detector.detection.detector.DETECTION_STAGES`,
#: classification (``classify``) and tracking (``track``).
STAGE_TIMINGS: tuple[str, ...] = ('conversion', *DETECTION_STAGES, 'classify', 'track')


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
        timings_ms: stage durations in milliseconds: each of :data:`STAGE_TIMINGS`
            (``conversion``: what the caller said converting the message took, 0 when
            it gave none; ``scaling``, ``gradients``, ``voting``, ``candidates``: parts of
            the detection; ``classify``; ``track``), ``detect`` (the whole detection:
            its parts and the frame's validation), and ``total`` (conversion, detection,
            classification and tracking).
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
        gray: the (H, W) uint8 frame, at full resolution.
        stamp_s: message time of the frame, seconds.
        candidates: the detector's candidates, best first, in full-resolution pixels.
        detect_ms: time the detection took, milliseconds.
        detect_stages_ms: its parts (:data:`~speed_sign_detector.detection.detector.
            DETECTION_STAGES`), milliseconds.
        conversion_ms: time the caller took to convert the image message, milliseconds.
    """

    gray: np.ndarray
    stamp_s: float
    candidates: tuple[Candidate, ...]
    detect_ms: float
    detect_stages_ms: Mapping[str, float] = field(default_factory=dict)
    conversion_ms: float = 0.0


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
    order), and so may its two steps: :meth:`classify` of different workers at the same
    time, :meth:`track` one frame at a time in order. That is what
    :class:`~speed_sign_detector.overlapped_pipeline.OverlappedPipeline` does.

    The detector searches each frame at its working resolution (``detector.
    detection_width_px``, ``detector.roi_*_fraction``); the classifier reads the
    candidates from the full-resolution frame. A pipeline that classifies in this
    process limits numpy's BLAS to one thread for the whole process (see
    :func:`~speed_sign_detector.blas_threads.limit_blas_threads`).

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
        _limit_blas_for(self._classifiers)
        LOGGER.info('pipeline ready: backend %s (%s), %s voting%s', self.backend_name,
                    self.renderer, self.vote_method,
                    f', fell back because {self.fallback_reason}' if self.fallback_reason
                    else '')

    @property
    def backend_name(self) -> str:
        """Detector backend in use: ``'gl'``, ``'cpu'`` or ``'numpy'`` (with ``auto`` on a
        software renderer it may change after the first frames: see
        :attr:`backend_choice`)."""
        return self._live_detector().backend_name

    @property
    def backend_choice(self) -> str:
        """How the detector backend was chosen, in one line (``auto``: with the times of
        GL and CPU on the first frames, once they are known)."""
        return self._live_detector().backend_choice

    @property
    def renderer(self) -> str:
        """The GL renderer string, or a description of the numpy reference."""
        return self._live_detector().renderer

    @property
    def vote_method(self) -> str:
        """How votes are added: ``'raster'`` or ``'scatter'`` (GL), ``'stencil'`` (CPU),
        ``'numpy'``."""
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

    def process(self, gray: np.ndarray, stamp_s: float, conversion_ms: float = 0.0
                ) -> FrameResult:
        """Run one frame through detection, recognition and tracking.

        Args:
            gray: frame, shape (H, W), dtype uint8.
            stamp_s: message time of the frame in seconds (drives track expiry).
            conversion_ms: time the caller took to make ``gray`` from its message, in
                milliseconds (reported in the timings).

        Raises:
            ValueError: for an unusable frame (empty, wrong dtype or shape, too small).
        """
        return self.recognize(self.detect(gray, stamp_s, conversion_ms))

    def detect(self, gray: np.ndarray, stamp_s: float, conversion_ms: float = 0.0
               ) -> DetectedFrame:
        """The first half of :meth:`process`: the candidates of one frame.

        Runs on the thread that created the pipeline (the detector's GL context).

        Raises:
            ValueError: for an unusable frame (empty, wrong dtype or shape, too small).
        """
        detector = self._live_detector()
        started = time.perf_counter()
        candidates, stages_ms = detector.detect_with_stage_times(gray)
        return DetectedFrame(gray, stamp_s, candidates, (time.perf_counter() - started) * 1e3,
                             stages_ms, conversion_ms)

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
        track_ms = (time.perf_counter() - started) * 1e3
        return FrameResult(
            stamp_s=frame.stamp_s,
            width_px=int(frame.gray.shape[1]),
            height_px=int(frame.gray.shape[0]),
            detections=tuple(Detection(candidate, classification)
                             for candidate, classification in pairs),
            tracks=update.tracks,
            active_limit_kmh=update.active_limit_kmh,
            recognized_limit_kmh=update.recognized_limit_kmh,
            timings_ms={'conversion': frame.conversion_ms,
                        **{stage: frame.detect_stages_ms.get(stage, 0.0)
                           for stage in DETECTION_STAGES},
                        'detect': frame.detect_ms,
                        'classify': classified.classify_ms,
                        'track': track_ms,
                        'total': frame.conversion_ms + frame.detect_ms
                        + classified.classify_ms + track_ms},
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
            _limit_blas_for(classifiers)
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
    ``classifier_workers`` in worker processes of their own (0, auto, counts as 1 here:
    the node sizes it to the host before, with :mod:`~speed_sign_detector.
    classifier_placement`)."""
    if not config.classify:
        return ()
    if config.classifier_process:
        return start_classifier_processes(config.classifier,
                                          max(1, config.classifier_workers))
    return (Classifier(config.classifier),)


def _limit_blas_for(classifiers: tuple[Classifier | ClassifierProcess, ...]) -> None:
    """One BLAS thread for a classifier in this process (its small matrix products;
    worker processes are started with one already)."""
    if any(isinstance(item, Classifier) for item in classifiers):
        limit_blas_threads(1)


def _close_classifiers(classifiers: tuple[Classifier | ClassifierProcess, ...]) -> None:
    """Stop the classifiers' worker processes, where they have them."""
    for classifier in classifiers:
        if isinstance(classifier, ClassifierProcess):
            classifier.close()
