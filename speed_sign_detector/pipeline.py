"""The one way through: a grayscale frame in, a :class:`FrameResult` out.

The node, the bag tools, the evaluation and the benchmarks all run frames through
:class:`Pipeline`: detection (radial-symmetry voting), recognition (FFT correlation
with MACE filter banks) and temporal integration (tracking table, active limit).
No ROS imports here.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from types import TracebackType

import numpy as np

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.recognition.classifier import Classification, Classifier
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


class Pipeline:
    """Detector, classifier and tracker behind one ``process`` call.

    The detector may hold an OpenGL context: create, use and close a Pipeline on one
    thread.

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
        self._classifier: Classifier | None = (Classifier(self.config.classifier)
                                               if self.config.classify else None)
        self._tracker = Tracker(self.config.tracker)
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
        detector = self._live_detector()
        started = time.perf_counter()
        candidates = detector.detect(gray)
        detected = time.perf_counter()
        if self._classifier is not None and candidates:
            classifications: tuple[Classification | None, ...] = self._classifier.classify(
                gray, candidates)
        else:
            classifications = (None,) * len(candidates)
        classified = time.perf_counter()
        pairs = list(zip(candidates, classifications))
        update = self._tracker.update(stamp_s, pairs)
        tracked = time.perf_counter()
        return FrameResult(
            stamp_s=stamp_s,
            width_px=int(gray.shape[1]),
            height_px=int(gray.shape[0]),
            detections=tuple(Detection(candidate, classification)
                             for candidate, classification in pairs),
            tracks=update.tracks,
            active_limit_kmh=update.active_limit_kmh,
            recognized_limit_kmh=update.recognized_limit_kmh,
            timings_ms={'detect': (detected - started) * 1e3,
                        'classify': (classified - detected) * 1e3,
                        'track': (tracked - classified) * 1e3,
                        'total': (tracked - started) * 1e3},
            tracks_reset=update.tracks_reset)

    def reconfigure(self, config: PipelineConfig) -> None:
        """Apply a new config, rebuilding only the stages whose settings changed.

        The tracker keeps its tracks and active limit when only its weights change.
        """
        if config.detector != self.config.detector or config.backend != self.config.backend:
            detector = Detector(config.detector, backend=config.backend)
            self._live_detector().close()
            self._detector = detector
        if config.classify != self.config.classify or (
                config.classify and config.classifier != self.config.classifier):
            self._classifier = Classifier(config.classifier) if config.classify else None
        if config.tracker != self.config.tracker:
            self._tracker.config = config.tracker
        self.config = config

    def reset(self) -> None:
        """Forget tracks and the active limit (a new drive or a restarted bag)."""
        self._tracker.reset()

    def close(self) -> None:
        """Release the detector's GL context; the pipeline cannot process afterwards."""
        if self._detector is not None:
            self._detector.close()
            self._detector = None

    def _live_detector(self) -> Detector:
        if self._detector is None:
            raise RuntimeError('this Pipeline was closed; create a new one')
        return self._detector

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()
