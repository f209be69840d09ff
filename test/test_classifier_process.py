"""The classifier in a worker process: the same answers as in this process, errors
reported (a refused frame, a bad bank file, a killed worker), and the pipeline's
``classifier_process`` setting start, swap and stop real worker processes."""
from __future__ import annotations

import dataclasses
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from process_helpers import (
    CLASSIFIER_WORKER,
    child_processes,
    process_state,
    signal_mask,
    wait_until,
)

from speed_sign_detector.config import ClassifierConfig, ConfigError, PipelineConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.errors import (
    BankFileError,
    ClassifierInputError,
    ClassifierProcessError,
)
from speed_sign_detector.pipeline import Pipeline
from speed_sign_detector.recognition.classifier import Classifier
from speed_sign_detector.recognition.classifier_process import (
    ClassifierProcess,
    start_classifier_processes,
)
from speed_sign_detector.recognition.templates import render_sign

#: Banks up to radius 30 px only, to keep the module fast (the default goes to 48).
SMALL_BANKS = ClassifierConfig(max_radius_px=30.0, cache_dir='')
#: (kind, centre x, centre y, outer radius) of the signs of the test frame.
SIGNS = (('30', 50.0, 60.0, 22.0), ('80', 130.0, 55.0, 20.0), ('no_overtaking', 210.0, 62.0,
                                                                 21.0))


def _frame() -> tuple[np.ndarray, list[Candidate]]:
    """A (120, 260) gray frame with three rendered signs on a textured background, and
    a candidate on each (at about 0.78 of the outer radius, as the detector reports)
    plus one on the empty background."""
    rng = np.random.default_rng(3)
    coarse = rng.uniform(60, 190, (10, 19)).astype(np.float32)
    frame = cv2.resize(coarse, (260, 120), interpolation=cv2.INTER_CUBIC)
    candidates = []
    for kind, x_px, y_px, radius_px in SIGNS:
        diameter = int(round(2 * radius_px))
        bgr, alpha = render_sign(kind, diameter)
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        left, top = int(round(x_px - diameter / 2)), int(round(y_px - diameter / 2))
        window = frame[top:top + diameter, left:left + diameter]
        window[:] = alpha * gray + (1 - alpha) * window
        candidates.append(Candidate(x_px, y_px, radius_px * 0.78, 1.0))
    candidates.append(Candidate(240.0, 20.0, 12.0, 0.5))
    return np.clip(frame, 0, 255).astype(np.uint8), candidates


@pytest.fixture(scope='module')
def config(tmp_path_factory: pytest.TempPathFactory) -> ClassifierConfig:
    return dataclasses.replace(SMALL_BANKS,
                               cache_dir=str(tmp_path_factory.mktemp('filter_banks')))


@pytest.fixture(scope='module')
def in_process(config: ClassifierConfig) -> Classifier:
    return Classifier(config)  # also fills the bank cache the workers read


@pytest.fixture()
def worker(config: ClassifierConfig, in_process: Classifier) -> Iterator[ClassifierProcess]:
    with ClassifierProcess(config) as process:
        yield process


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_worker_answers_as_the_classifier_in_this_process(
        worker: ClassifierProcess, in_process: Classifier) -> None:
    gray, candidates = _frame()
    answers = worker.classify(gray, candidates)
    assert worker.pid is not None and worker.pid != os.getpid()
    assert answers == in_process.classify(gray, candidates)
    assert [answer.label for answer in answers[:2]] == ['30', '80']
    assert answers[2].limit_kmh is None  # the look-alike is no limit


def test_refused_frame_raises_the_classifiers_error_and_the_worker_goes_on(
        worker: ClassifierProcess, in_process: Classifier) -> None:
    gray, candidates = _frame()
    pid = worker.pid
    with pytest.raises(ClassifierInputError, match='uint8'):
        worker.classify(gray.astype(np.float32), candidates)
    with pytest.raises(ClassifierInputError, match='non-empty'):
        worker.classify(np.zeros((0, 0), np.uint8), candidates)
    assert worker.classify(gray, candidates) == in_process.classify(gray, candidates)
    assert worker.pid == pid


def test_killed_worker_is_reported_then_replaced(worker: ClassifierProcess,
                                                 in_process: Classifier) -> None:
    gray, candidates = _frame()
    first = worker.pid
    assert first is not None
    os.kill(first, signal.SIGKILL)
    with pytest.raises(ClassifierProcessError, match='exit code -9'):
        worker.classify(gray, candidates)
    assert worker.classify(gray, candidates) == in_process.classify(gray, candidates)
    assert worker.pid not in (None, first)


def test_bad_bank_file_is_raised_by_the_constructor(config: ClassifierConfig,
                                                    tmp_path: Path) -> None:
    broken = tmp_path / 'broken.npz'
    broken.write_bytes(b'not a bank')
    with pytest.raises(BankFileError, match='broken.npz'):
        ClassifierProcess(dataclasses.replace(config, bank_file=str(broken)))


def test_close_stops_the_worker(config: ClassifierConfig, in_process: Classifier) -> None:
    process = ClassifierProcess(config)
    pid = process.pid
    assert pid is not None and _alive(pid)
    process.close()
    assert process.pid is None and not _alive(pid)
    process.close()  # idempotent


def test_pipeline_setting_starts_swaps_and_stops_workers(config: ClassifierConfig,
                                                         in_process: Classifier) -> None:
    gray, _ = _frame()
    settings = PipelineConfig(backend='numpy', classifier=config, classifier_process=True)
    with Pipeline(dataclasses.replace(settings, classifier_process=False)) as reference:
        expected = reference.process(gray, 0.0)
    pipeline = Pipeline(settings)
    [worker] = pipeline._classifiers
    assert isinstance(worker, ClassifierProcess)
    pid = worker.pid
    assert pid is not None
    result = pipeline.process(gray, 0.0)
    assert result.detections == expected.detections
    pipeline.reconfigure(dataclasses.replace(settings, classifier_process=False))
    [in_place] = pipeline._classifiers
    assert isinstance(in_place, Classifier) and not _alive(pid)
    pipeline.reconfigure(settings)
    [worker] = pipeline._classifiers
    assert isinstance(worker, ClassifierProcess)
    pid = worker.pid
    assert pid is not None and _alive(pid)
    pipeline.close()
    assert not _alive(pid)


def test_several_workers_start_together_read_alike_and_follow_reconfigure(
        config: ClassifierConfig) -> None:
    """``classifier_workers`` 2: two worker processes, each giving the in-process
    answers through ``Pipeline.classify``; back to 1, the second one stops."""
    gray, _ = _frame()
    settings = PipelineConfig(backend='numpy', classifier=config, classifier_process=True,
                              classifier_workers=2)
    with Pipeline(dataclasses.replace(settings, classifier_process=False,
                                      classifier_workers=1)) as reference:
        expected = reference.process(gray, 0.0)
    with Pipeline(settings) as pipeline:
        assert pipeline.classifier_workers == 2
        assert pipeline.classifier_location == '2 worker processes'
        pids = [worker.pid for worker in pipeline._classifiers]
        assert None not in pids and len(set(pids)) == 2 and all(map(_alive, pids))
        detected = pipeline.detect(gray, 0.0)
        for worker in (0, 1):
            classified = pipeline.classify(detected, worker)
            assert classified.classifications == tuple(
                detection.classification for detection in expected.detections)
        with pytest.raises(IndexError, match='worker 2 is outside'):
            pipeline.classify(detected, 2)
        pipeline.reconfigure(dataclasses.replace(settings, classifier_workers=1))
        assert pipeline.classifier_workers == 1
        assert pipeline.classifier_location == '1 worker process'
        assert [worker.pid for worker in pipeline._classifiers] != pids
        assert not any(map(_alive, pids))
        pid = pipeline._classifiers[0].pid
        pipeline.reconfigure(dataclasses.replace(settings, classifier_process=False,
                                                 classifier_workers=1))
        assert pipeline.classifier_location == 'in this process'
        pipeline.reconfigure(dataclasses.replace(settings, classify=False,
                                                 classifier_process=False,
                                                 classifier_workers=1))
        assert (pipeline.classifier_location, pipeline.classifier_workers) == ('off', 1)
    assert pid is not None and not _alive(pid)


def test_several_workers_need_worker_processes() -> None:
    with pytest.raises(ConfigError, match='classifier_workers .2. above 1 needs '
                                          'classifier_process'):
        PipelineConfig(classifier_workers=2)
    with pytest.raises(ConfigError, match='classifier_workers = 17 is above its maximum'):
        PipelineConfig(classifier_process=True, classifier_workers=17)


def test_a_worker_that_cannot_build_stops_the_others(tmp_path: Path) -> None:
    """Two workers started together on a corrupt bank file: the error of the first is
    raised, and neither worker is left running."""
    broken = tmp_path / 'broken.npz'
    broken.write_bytes(b'not a bank')
    before = set(child_processes(CLASSIFIER_WORKER))
    with pytest.raises(BankFileError):
        start_classifier_processes(dataclasses.replace(SMALL_BANKS, bank_file=str(broken)), 2)
    assert set(child_processes(CLASSIFIER_WORKER)) <= before


def test_interrupt_of_the_process_group_leaves_the_worker_to_its_parent(
        worker: ClassifierProcess, in_process: Classifier) -> None:
    """Ctrl+C in a terminal reaches the worker too: it ignores it, and stops only when
    its parent closes it."""
    gray, candidates = _frame()
    pid = worker.pid
    assert pid is not None
    sigint_bit = 1 << (signal.SIGINT - 1)
    assert signal_mask(pid, 'SigIgn') & sigint_bit, 'the worker does not ignore SIGINT'
    os.kill(pid, signal.SIGINT)
    wait_until(lambda: not (signal_mask(pid, 'SigPnd') | signal_mask(pid, 'ShdPnd'))
               & sigint_bit, 'the SIGINT to leave the pending signals of the worker')
    assert process_state(pid) not in (None, 'Z')
    assert worker.classify(gray, candidates) == in_process.classify(gray, candidates)
    assert worker.pid == pid


def test_hung_worker_is_killed_after_the_answer_timeout_then_replaced(
        config: ClassifierConfig, in_process: Classifier) -> None:
    gray, candidates = _frame()
    with ClassifierProcess(config, answer_timeout_s=1.0) as process:
        hung = process.pid
        assert hung is not None
        os.kill(hung, signal.SIGSTOP)  # as a deadlocked worker: alive, never answering
        wait_until(lambda: process_state(hung) == 'T', 'the worker to stop')
        with pytest.raises(ClassifierProcessError, match='did not answer within 1 s'):
            process.classify(gray, candidates)
        assert not _alive(hung)
        assert process.classify(gray, candidates) == in_process.classify(gray, candidates)
        assert process.pid not in (None, hung)


def test_answer_timeout_must_be_positive(config: ClassifierConfig) -> None:
    with pytest.raises(ValueError, match='answer_timeout_s'):
        ClassifierProcess(config, answer_timeout_s=0.0)


def test_worker_not_ready_in_time_is_killed_and_reported(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Building banks from scratch (no cache) takes seconds: with a start timeout of
    0.3 s the worker is taken for hung, killed, and the constructor says so."""
    from speed_sign_detector.recognition import classifier_process
    monkeypatch.setattr(classifier_process, 'START_TIMEOUT_S', 0.3)
    before = set(child_processes(CLASSIFIER_WORKER))
    with pytest.raises(ClassifierProcessError,
                       match='did not answer within 0.3 s.*before it was ready'):
        ClassifierProcess(ClassifierConfig(cache_dir=''))
    assert set(child_processes(CLASSIFIER_WORKER)) <= before  # none left running

