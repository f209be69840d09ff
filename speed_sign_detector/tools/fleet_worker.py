"""The worker of a fleet run: a Ray actor holding one Pipeline, evaluating one bag per call.

:class:`BagEvaluationWorker` builds its :class:`~speed_sign_detector.pipeline.Pipeline`
(GL context, filter banks) once, on its first bag, and resets it before each bag, so a
worker process pays the start-up once, not per bag. A bag's frames stay in order on one
worker (tracking is stateful): one call evaluates one whole bag with
:func:`speed_sign_detector.tools.eval_bag.evaluate_bag` and writes its results bag and
JSON line into the output folder (:class:`~speed_sign_detector.tools.fleet_jobs.FleetFolder`)
before it returns.

:func:`worker_actor_class` makes the Ray actor class: one CPU per worker (a GPU share
where the cluster has GPUs, given at creation), ``max_restarts`` and
``max_task_retries`` so that a worker process that dies (killed, out of memory,
crashed) is started again and its bag evaluated anew. ``get_pid`` and ``progress``
run in their own concurrency group, so they answer while a bag is being evaluated.
The evaluation runs on the actor's one default-group thread, which therefore owns the
pipeline's GL context.

Everything a bag can do wrong (missing, corrupt, truncated, unreadable truth) comes
back as a :class:`BagOutcome` with the reason; only a dying process reaches the caller
as Ray's ``ActorDiedError``.
"""
from __future__ import annotations

import os
import shutil
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import ray

from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.tools.eval_bag import evaluate_bag, summary_json
from speed_sign_detector.tools.fleet_jobs import (
    BagJob,
    BagOutcome,
    EvaluationSettings,
    FleetFolder,
)

if TYPE_CHECKING:
    from speed_sign_detector.pipeline import Pipeline

#: The concurrency group of the calls that answer while a bag is evaluated.
CONTROL_GROUP = 'control'


@dataclass(frozen=True)
class WorkerProgress:
    """Where a worker is: the bag it evaluates and how far it got.

    Attributes:
        key: the job key of the bag under way, None when idle.
        frames_done: frames of that bag evaluated so far.
        frames_total: frames the bag holds, None when unknown.
        worker: ``host:pid``.
    """

    key: str | None
    frames_done: int
    frames_total: int | None
    worker: str


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f'{socket.gethostname()}:{os.getpid()}'


def evaluate_job(job: BagJob, settings: EvaluationSettings, folder: FleetFolder,
                 pipeline: Pipeline, on_frame: Any = None, setup_s: float = 0.0
                 ) -> BagOutcome:
    """Evaluate one bag with an existing pipeline and publish its outputs.

    The results bag is written under ``folder``'s work-in-progress folder, then moved to
    ``results/KEY``; the JSON line (``out_bag`` naming the moved bag) goes to
    ``summaries/KEY.json`` last.

    Args:
        job: the bag.
        settings: how to evaluate it.
        folder: the run's output folder.
        pipeline: built on this thread; reset before the bag, left open.
        on_frame: ``on_frame(frames_done, frames_total)`` after each frame, or None.
        setup_s: seconds spent building the pipeline for this call (recorded).

    Returns:
        The outcome; a bag that cannot be (fully) evaluated is not done, with the reason.
    """
    started = time.time() - setup_s
    scratch = folder.new_partial_dir()
    written = scratch / job.key
    summary: dict[str, Any] | None = None
    reason: str | None = None
    try:
        evaluation = evaluate_bag(job.bag, settings.topic, job.truth, written,
                                  settings.debug_images, grace_s=settings.grace_s,
                                  progress=False, pipeline=pipeline, on_frame=on_frame)
        summary = dict(evaluation.summary)
        summary['out_bag'] = str(folder.publish_results_bag(written, job.key))
        folder.publish_summary(summary_json(summary), job.key, scratch)
        if evaluation.stopped_by is not None:
            reason = str(evaluation.stopped_by)
    except SpeedSignError as err:
        reason = str(err)
    except Exception as err:  # noqa: BLE001 - an unforeseen fault of one bag is its failure
        reason = f'{type(err).__name__}: {err}'
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return BagOutcome(job.key, str(job.bag), reason is None, reason, summary, worker_name(),
                      started, time.time(), setup_s)


class BagEvaluationWorker:
    """One worker process of a fleet run (wrap with :func:`worker_actor_class`).

    Args:
        settings: how every bag is evaluated (the pipeline's parameters among them).
        out_dir: the run's output folder, reachable at this path from the worker.
    """

    def __init__(self, settings: EvaluationSettings, out_dir: str) -> None:
        self._settings = settings
        self._folder = FleetFolder(Path(out_dir))
        self._pipeline: Pipeline | None = None
        self._progress = WorkerProgress(None, 0, None, worker_name())

    @ray.method(concurrency_group=CONTROL_GROUP)
    def get_pid(self) -> int:
        """The worker's process id (answers while a bag is evaluated)."""
        return os.getpid()

    @ray.method(concurrency_group=CONTROL_GROUP)
    def progress(self) -> WorkerProgress:
        """The bag under way and its frames so far (answers while a bag is evaluated)."""
        return self._progress

    def evaluate(self, job: BagJob) -> BagOutcome:
        """Evaluate one bag (see :func:`evaluate_job`); the first call builds the pipeline."""
        from speed_sign_detector.pipeline import Pipeline

        name = worker_name()
        self._progress = WorkerProgress(job.key, 0, None, name)
        setup_s = 0.0
        if self._pipeline is None:
            started = time.time()
            try:
                self._pipeline = Pipeline(self._settings.config)
            except Exception as err:  # noqa: BLE001 - reported as this bag's failure
                return BagOutcome(job.key, str(job.bag), False,
                                  f'the worker could not build its pipeline: '
                                  f'{type(err).__name__}: {err}', None, name, started,
                                  time.time(), time.time() - started)
            setup_s = time.time() - started

        def on_frame(frames_done: int, frames_total: int | None) -> None:
            self._progress = WorkerProgress(job.key, frames_done, frames_total, name)

        try:
            return evaluate_job(job, self._settings, self._folder, self._pipeline, on_frame,
                                setup_s)
        finally:
            self._progress = WorkerProgress(None, 0, None, name)


def worker_actor_class(retries: int) -> Any:
    """The Ray actor class of :class:`BagEvaluationWorker`.

    Args:
        retries: how often a worker process that died is started again, and how often a
            call it was running is retried (``max_restarts`` = ``max_task_retries``).

    Returns:
        The actor class; create workers with ``.options(num_gpus=...).remote(...)``.
    """
    return ray.remote(num_cpus=1, max_restarts=retries, max_task_retries=retries,
                      concurrency_groups={CONTROL_GROUP: 1})(BagEvaluationWorker)
