"""OverlappedPipeline: detection of frame N+1 on the calling thread while frame N is
recognized on a helper thread gives the same results as Pipeline.process, in order; with
several classifier worker processes, frames classified at the same time are still
tracked and reported in order."""
from __future__ import annotations

import ctypes
import dataclasses
import sys
import threading
import time
from collections.abc import Callable, Iterable

import cv2
import numpy as np
import pytest
from scene_helpers import approach_frames, textured_background

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.overlapped_pipeline import OverlappedPipeline
from speed_sign_detector.pipeline import (
    ClassifiedFrame,
    DetectedFrame,
    FrameResult,
    Pipeline,
)

FRAME_PERIOD_S = 1 / 30


@pytest.fixture(scope='module')
def pipeline() -> Iterable[Pipeline]:
    with Pipeline(PipelineConfig(backend='gl')) as built:
        yield built


@pytest.fixture(scope='module')
def approach() -> list[np.ndarray]:
    """A 60 km/h sign growing over 20 gray frames on a textured background."""
    background = textured_background(21, 640, 480)
    return [cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            for frame, *_ in approach_frames('60', 20, 21, background)]


def comparable(result: FrameResult) -> tuple:
    """Everything of a result except its timings and track ids (which keep counting
    across Pipeline.reset)."""
    tracks = tuple(dataclasses.replace(track, track_id=0) for track in result.tracks)
    return (result.stamp_s, result.width_px, result.height_px, result.detections,
            tracks, result.active_limit_kmh, result.recognized_limit_kmh,
            result.tracks_reset)


@pytest.mark.parametrize('overlap', [True, False])
def test_same_results_in_order_as_process(pipeline: Pipeline, approach: list[np.ndarray],
                                          overlap: bool) -> None:
    pipeline.reset()
    serial = [pipeline.process(gray, index * FRAME_PERIOD_S)
              for index, gray in enumerate(approach)]
    pipeline.reset()
    received: list[tuple[FrameResult, int, str]] = []

    def on_result(result: FrameResult, context: int) -> None:
        received.append((result, context, threading.current_thread().name))

    def on_error(error: Exception, context: int) -> None:
        raise AssertionError(f'frame {context}: {error}')

    with OverlappedPipeline(pipeline, on_result, on_error, overlap=overlap) as stages:
        for index, gray in enumerate(approach):
            stages.submit(gray, index * FRAME_PERIOD_S, context=index)
    assert [context for _, context, _ in received] == list(range(len(approach)))
    assert [comparable(result) for result, _, _ in received] == [
        comparable(result) for result in serial]
    assert [result.recognized_limit_kmh for result in serial if result.recognized_limit_kmh
            ] == [60]
    helper_threads = {thread for _, _, thread in received}
    if overlap:
        assert helper_threads == {'recognition'}
    else:
        assert helper_threads == {threading.current_thread().name}


def test_recognition_errors_go_to_on_error_and_the_helper_keeps_going(
        pipeline: Pipeline, approach: list[np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    classify = pipeline.classify

    def failing_on_frame_3(frame: DetectedFrame, worker: int = 0) -> ClassifiedFrame:
        if frame.stamp_s == 3.0:
            raise RuntimeError('classifier broke')
        return classify(frame, worker)

    monkeypatch.setattr(pipeline, 'classify', failing_on_frame_3)
    pipeline.reset()
    results: list[int] = []
    errors: list[tuple[str, int]] = []
    with OverlappedPipeline(pipeline, lambda result, context: results.append(context),
                            lambda error, context: errors.append((str(error), context))
                            ) as stages:
        for index in range(6):
            stages.submit(approach[index], float(index), context=index)
    assert errors == [('classifier broke', 3)]
    assert results == [0, 1, 2, 4, 5]


def test_a_failing_result_callback_does_not_stop_the_helper(
        pipeline: Pipeline, approach: list[np.ndarray]) -> None:
    pipeline.reset()
    seen: list[int] = []

    def on_result(result: FrameResult, context: int) -> None:
        seen.append(context)
        if context == 0:
            raise RuntimeError('publisher gone')

    with OverlappedPipeline(pipeline, on_result, lambda error, context: None) as stages:
        for index in range(3):
            stages.submit(approach[index], float(index), context=index)
    assert seen == [0, 1, 2]


def test_bad_frames_raise_from_submit_and_nothing_is_queued(pipeline: Pipeline) -> None:
    results: list[object] = []
    with OverlappedPipeline(pipeline, lambda result, context: results.append(context),
                            lambda error, context: results.append(error)) as stages:
        with pytest.raises(ValueError):
            stages.submit(np.zeros((4, 4), np.uint8), 0.0, context='tiny')
        with pytest.raises(ValueError):
            stages.submit(np.zeros((480, 640, 3), np.uint8), 0.0, context='colour')
        stages.drain()
    assert results == []


def test_drain_waits_for_every_frame_and_submit_after_close_fails(
        pipeline: Pipeline, approach: list[np.ndarray]) -> None:
    pipeline.reset()
    results: list[int] = []
    stages = OverlappedPipeline(pipeline, lambda result, context: results.append(context),
                                lambda error, context: None)
    for index in range(4):
        stages.submit(approach[index], float(index), context=index)
    stages.drain()
    assert results == [0, 1, 2, 3]
    stages.close()
    stages.close()  # idempotent
    with pytest.raises(RuntimeError, match='closed'):
        stages.submit(approach[0], 10.0)


#: Longer than any test run: while it lasts, a thread waiting for the GIL never forces
#: the holder to drop it, so another thread runs only when the holder releases the GIL.
NO_FORCED_SWITCH_S = 3600.0


class _ProgressCounter:
    """A Python thread that counts steps, sleeping a little between them (which gives
    the GIL back at once): it takes a step only when it can get the GIL."""

    def __init__(self) -> None:
        self.steps = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._count, name='progress-counter')

    def _count(self) -> None:
        while not self._stop.is_set():
            self.steps += 1
            self._stop.wait(0.0002)

    def __enter__(self) -> _ProgressCounter:
        self._thread.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join()


def _holding_the_gil(function: ctypes._CFuncPtr) -> ctypes._CFuncPtr:
    """The same C function, called the way ctypes calls Python C API functions: with the
    GIL held for the whole call (the control for the test below)."""
    address = ctypes.cast(function, ctypes.c_void_p).value
    return ctypes.PYFUNCTYPE(None, *function.argtypes)(address)


def _steps_during_gl_calls(frames: list[np.ndarray], hold_gil: bool) -> tuple[int, int]:
    """Detect ``frames`` with a progress counter running on another thread.

    Returns:
        (steps the counter took while one of the detector's GL calls was in flight,
        number of those GL calls). Forced GIL switches are off for the run, so a step can
        fall inside a call only when the call itself lets other threads run.
    """
    with Detector(PipelineConfig().detector, backend='gl') as detector:
        calls = detector._gl._calls  # the GL calls that wait for llvmpipe's threads
        steps_inside = 0
        calls_made = 0
        switch_interval_s = sys.getswitchinterval()
        sys.setswitchinterval(NO_FORCED_SWITCH_S)  # before the counter first waits
        try:
            with _ProgressCounter() as counter:

                def watched(function: ctypes._CFuncPtr) -> Callable[..., None]:
                    def call(*arguments: int) -> None:
                        nonlocal steps_inside, calls_made
                        before = counter.steps
                        function(*arguments)
                        steps_inside += counter.steps - before
                        calls_made += 1
                    return call

                for name in ('_use_program', '_dispatch', '_dispatch_indirect',
                             '_bind_buffer', '_memory_barrier', 'finish'):
                    function = getattr(calls, name)
                    setattr(calls, name, watched(_holding_the_gil(function) if hold_gil
                                                 else function))
                for gray in frames:
                    detector.detect(gray)
        finally:
            sys.setswitchinterval(switch_interval_s)
    return steps_inside, calls_made


def test_gl_detection_lets_other_threads_run(approach: list[np.ndarray]) -> None:
    """The GL calls that wait for the driver release the GIL (what makes overlap work):
    a Python thread takes steps while the detector's GL calls are in flight. The control
    makes the same C calls holding the GIL, and the same count must then find no step
    inside any call (so the check can tell the two apart)."""
    steps_inside, calls_made = _steps_during_gl_calls(approach, hold_gil=False)
    control_steps_inside, control_calls_made = _steps_during_gl_calls(approach,
                                                                      hold_gil=True)
    assert calls_made == control_calls_made > len(approach)
    assert control_steps_inside == 0, 'the check cannot tell a call holding the GIL apart'
    assert steps_inside > 0, (f'no other thread ran during any of {calls_made} GL calls: '
                              'they hold the GIL')


def test_several_classifier_workers_classify_at_once_and_report_in_order(
        approach: list[np.ndarray]) -> None:
    """Two worker processes: every classification waits at a barrier for another one to
    run at the same time (it fails after 30 s otherwise), and the even frames take
    longer, so the odd ones finish first; the results still come in submission order
    and equal those of Pipeline.process, frame for frame."""
    config = PipelineConfig(backend='gl', classifier_process=True, classifier_workers=2)
    frames = approach[:12]
    with Pipeline(dataclasses.replace(config, classifier_process=False,
                                      classifier_workers=1)) as reference:
        serial = [reference.process(gray, index * FRAME_PERIOD_S)
                  for index, gray in enumerate(frames)]
    with Pipeline(config) as pipeline:
        classify = pipeline.classify
        together = threading.Barrier(2, timeout=30.0)
        workers_seen: set[tuple[str, int]] = set()

        def classify_alongside_another(frame: DetectedFrame, worker: int = 0
                                       ) -> ClassifiedFrame:
            together.wait()
            workers_seen.add((threading.current_thread().name, worker))
            classified = classify(frame, worker)
            if round(frame.stamp_s / FRAME_PERIOD_S) % 2 == 0:
                time.sleep(0.05)
            return classified

        pipeline.classify = classify_alongside_another  # type: ignore[method-assign]
        received: list[tuple[FrameResult, int]] = []

        def on_error(error: Exception, context: int) -> None:
            raise AssertionError(f'frame {context}: {error!r}')

        with OverlappedPipeline(pipeline, lambda result, context: received.append(
                (result, context)), on_error) as stages:
            for index, gray in enumerate(frames):
                stages.submit(gray, index * FRAME_PERIOD_S, context=index)
    assert [context for _, context in received] == list(range(len(frames)))
    assert [comparable(result) for result, _ in received] == [
        comparable(result) for result in serial]
    assert workers_seen == {('recognition', 0), ('recognition-1', 1)}
