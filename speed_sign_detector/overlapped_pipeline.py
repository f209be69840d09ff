"""Detection, classification and tracking of a stream of frames on several threads.

:class:`OverlappedPipeline` runs the halves of :class:`~speed_sign_detector.pipeline.
Pipeline` on threads of their own: detection on the caller's (the GL context's) thread,
classification on a helper per classifier worker, tracking and the results in the order
the frames came. The node and ``speed_sign_eval bag`` run frames this way. No ROS imports
here.
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Any, Self

import numpy as np

from speed_sign_detector.pipeline import ClassifiedFrame, DetectedFrame, FrameResult, Pipeline

LOGGER = logging.getLogger(__name__)


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
        # the sequence number whose result goes out next: the frames from it to
        # _submitted are waiting or being classified
        self._next_to_report = 0
        self._closed = False
        self._helpers: dict[int, threading.Thread] = {}  # by classifier worker
        if overlap:
            self._start_helpers()

    def wait_until_ready(self) -> None:
        """Block until :meth:`submit` can detect at once (no frame waits for a helper)."""
        with self._condition:
            while self._waiting is not None and not self._closed:
                self._condition.wait()

    def submit(self, gray: np.ndarray, stamp_s: float, context: Any = None,
               conversion_ms: float = 0.0) -> None:
        """Detect a frame here, then recognize it on a helper (see the class).

        ``conversion_ms`` is the time the caller took to make ``gray`` from its message
        (milliseconds, reported in the result's timings).

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
            self._on_result(self.pipeline.process(gray, stamp_s, conversion_ms), context)
            return
        self._start_helpers()
        self.wait_until_ready()
        detected = self.pipeline.detect(gray, stamp_s, conversion_ms)
        with self._condition:
            if self._closed:
                raise RuntimeError('this OverlappedPipeline was closed')
            self._waiting = (self._submitted, detected, context)
            self._submitted += 1
            self._condition.notify_all()

    def drain(self) -> None:
        """Block until every submitted frame has been recognized and reported."""
        with self._condition:
            while self._next_to_report < self._submitted and any(
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
