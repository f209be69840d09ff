"""``speed_sign_eval fleet``: evaluate many recorded drives on Ray, locally or on a cluster.

Example::

    speed_sign_eval fleet --manifest drives.csv --out fleet_out --json
    speed_sign_eval fleet 'drives/*.mcap' drives/old/*.bag --out fleet_out
    speed_sign_eval fleet --manifest drives.csv --out fleet_out --address HEAD:6379

- Input: bag paths or glob patterns, or a manifest CSV (``bag,truth`` per row), see
  :mod:`speed_sign_detector.tools.fleet_jobs`. Every bag format ``eval bag`` reads.
- Engine: Ray Core. Without ``--address`` (and without ``RAY_ADDRESS``) Ray starts on
  this machine with its cores; with it, the run joins that cluster. Each worker is one
  actor process holding one pipeline (:mod:`speed_sign_detector.tools.fleet_worker`),
  built once per process; each bag is one call, its frames in order on that worker.
  Where the cluster has GPUs each worker asks for a share of one (``--gpus-per-worker``),
  so the workers spread over them.
- Output: each bag's results bag and JSON line are in the output folder as soon as it
  finishes; a re-run with the same folder and settings skips the bags already done.
- Faults: a bag that cannot be read is reported with the reason and the run goes on; a
  worker process that dies is started again and its bag retried (``--retries`` times per
  worker); once a worker has no restart left, its bag is reported failed and a fresh
  worker takes the remaining bags. Ctrl-C stops the run, reports what was done, and a
  re-run goes on from there.
- The aggregate (:mod:`speed_sign_detector.tools.fleet_report`): a table on the
  terminal, with ``--json`` one JSON object as the last stdout line, and
  ``OUT/fleet.json`` + ``OUT/fleet.png``. Exit status 0 only when every bag was
  evaluated, 1 otherwise, 130 when interrupted.

On a cluster every node needs this package (and Ray) installed, and the bags, truth
files and output folder at the same paths (a shared file system).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.tools.cli_types import (
    non_negative_integer,
    number_in_range,
    positive_integer,
)
from speed_sign_detector.tools.eval_bag import add_pipeline_options
from speed_sign_detector.tools.fleet_jobs import (
    BagJob,
    BagOutcome,
    EvaluationSettings,
    FleetError,
    FleetFolder,
    jobs_from_manifest,
    jobs_from_paths,
)
from speed_sign_detector.tools.fleet_report import (
    FleetReport,
    build_report,
    format_table,
    write_report_json,
    write_summary_png,
)
from speed_sign_detector.tools.progress import progress_bar
from speed_sign_detector.tools.run_control import EXIT_INTERRUPTED

if TYPE_CHECKING:
    from speed_sign_detector.tools.fleet_worker import WorkerProgress

#: Default restarts of a dead worker process (and retries of its bag).
DEFAULT_RETRIES = 2
#: Object store of a Ray this command starts itself, bytes (results are small dicts).
LOCAL_OBJECT_STORE_BYTES = 256 * 1024 * 1024
#: How often the driver asks the busy workers how far they are, seconds.
PROGRESS_POLL_S = 0.5
#: After Ctrl-C, how long the driver waits for the results of bags its workers have
#: already finished (their outputs are on disk), seconds.
INTERRUPT_COLLECT_S = 1.0

ProgressHook = Callable[[BagJob, 'WorkerProgress', Any], None]
"""``on_progress(job, progress, actor)``: a busy worker's answer about the bag it evaluates
(the driver asks every :data:`PROGRESS_POLL_S`)."""


@dataclass(frozen=True)
class FleetOptions:
    """How a run uses Ray.

    Attributes:
        workers: worker processes; None = the cluster's CPUs (at most one per bag).
        retries: restarts of a worker process that died, and retries of its bag.
        address: a Ray cluster to join (``HOST:PORT``, ``auto``); None = ``RAY_ADDRESS``,
            else a Ray started on this machine. Ignored when Ray is already initialized
            in this process (the run then uses that one and leaves it running).
        gpus_per_worker: the GPU share each worker asks for; None = the cluster's GPUs
            divided among the workers (at most 1 each), 0 when it has none.
        progress: draw progress bars on stderr (when it is a terminal).
        verbose: forward the workers' logs to stderr.
    """

    workers: int | None = None
    retries: int = DEFAULT_RETRIES
    address: str | None = None
    gpus_per_worker: float | None = None
    progress: bool = True
    verbose: bool = False


def run_fleet(jobs: Sequence[BagJob], settings: EvaluationSettings, folder: FleetFolder,
              options: FleetOptions = FleetOptions(), on_progress: ProgressHook | None = None
              ) -> FleetReport:
    """Evaluate the bags on Ray, skipping those the folder holds as done.

    Writes each bag's outputs as it finishes, then ``fleet.json`` and ``fleet.png``.
    Ctrl-C (KeyboardInterrupt) stops the run; the report then says what was done.

    Raises:
        FleetError: Ray is missing or cannot be started or joined.
    """
    started_unix_s = time.time()
    folder.clear_partial()
    outcomes: dict[str, BagOutcome] = {}
    to_run: list[BagJob] = []
    for job in jobs:
        summary = folder.done_summary(job.key)
        if summary is None:
            to_run.append(job)
        else:
            outcomes[job.key] = BagOutcome(job.key, str(job.bag), True, None, summary, '',
                                           0.0, 0.0, resumed=True)
    interrupted = False
    if to_run:
        bags_bar = progress_bar(len(jobs), 'bags', 'bag', enabled=options.progress,
                                position=0)
        frames_bar = progress_bar(None, 'frames', 'frame', enabled=options.progress,
                                  position=1)
        bags_bar.update(len(outcomes))
        try:
            with _RayEngine(options) as engine:
                started_unix_s = engine.started_unix_s
                interrupted = _Dispatcher(engine, settings, folder, options, on_progress,
                                          bags_bar, frames_bar).run(to_run, outcomes)
        finally:
            frames_bar.close()
            bags_bar.close()
    finished_unix_s = time.time()
    report = build_report([outcomes[job.key] for job in jobs if job.key in outcomes],
                          len(jobs), started_unix_s, finished_unix_s, folder.root,
                          interrupted)
    scratch = folder.new_partial_dir()
    try:
        write_report_json(report, folder.aggregate_json, scratch)
        write_summary_png(report, folder.aggregate_png, scratch)
    finally:
        folder.clear_partial()
    return report


class _RayEngine:
    """Ray for one run: joined or started on enter, shut down on exit when we started it."""

    def __init__(self, options: FleetOptions) -> None:
        try:
            import ray
        except ImportError as err:
            raise FleetError('Ray is not installed: pip install "speed_sign_detector[fleet]" '
                             '(or pip install ray)') from err
        self.ray = ray
        self.options = options
        self.started_here = False
        self.started_unix_s = time.time()

    def __enter__(self) -> _RayEngine:
        ray = self.ray
        if not ray.is_initialized():
            address = self.options.address or os.environ.get('RAY_ADDRESS') or None
            try:
                if address is not None:
                    ray.init(address=address, log_to_driver=self.options.verbose)
                else:   # 'local': a new Ray here, not one another user left running
                    ray.init(address='local', include_dashboard=False,
                             log_to_driver=self.options.verbose,
                             object_store_memory=LOCAL_OBJECT_STORE_BYTES)
            except (ConnectionError, RuntimeError, ValueError) as err:
                hint = ('; if the cluster uses token authentication (Ray >= 2.59 starts it '
                        'so), set RAY_AUTH_MODE=token and its token (ray get-auth-token)'
                        if address is not None and not os.environ.get('RAY_AUTH_MODE')
                        else '')
                raise FleetError(f'cannot start or join Ray'
                                 f'{f" at {address}" if address else ""}: '
                                 f'{_first_line(err)}{hint}') from err
            self.started_here = True
        self.started_unix_s = time.time()
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.started_here:
            self.ray.shutdown()

    def resources(self) -> dict[str, float]:
        """The cluster's total resources (``CPU``, ``GPU``, ...)."""
        return dict(self.ray.cluster_resources())


class _Dispatcher:
    """The driver's loop: one bag per idle worker, results as they finish, progress polls."""

    def __init__(self, engine: _RayEngine, settings: EvaluationSettings, folder: FleetFolder,
                 options: FleetOptions, on_progress: ProgressHook | None, bags_bar: Any,
                 frames_bar: Any) -> None:
        from speed_sign_detector.tools.fleet_worker import worker_actor_class

        self.ray = engine.ray
        self.engine = engine
        self.settings = settings
        self.folder = folder
        self.options = options
        self.on_progress = on_progress
        self.bags_bar = bags_bar
        self.frames_bar = frames_bar
        self.actor_class = worker_actor_class(options.retries)
        self.actors: list[Any] = []
        self.frames_finished = 0
        self.frames_under_way: dict[str, int] = {}

    def run(self, jobs: Sequence[BagJob], outcomes: dict[str, BagOutcome]) -> bool:
        """Evaluate ``jobs``, adding their outcomes; returns True when interrupted."""
        ray = self.ray
        pending = list(reversed(jobs))
        running: dict[Any, tuple[BagJob, Any, float]] = {}
        polls: dict[Any, tuple[BagJob, Any]] = {}
        last_poll: dict[int, float] = {}   # by id() of the actor handle
        workers = self._worker_count(len(jobs))
        gpus = self._gpus_per_worker(workers)
        idle = [self._new_actor(gpus) for _ in range(workers)]
        try:
            while pending or running:
                while idle and pending:
                    actor, job = idle.pop(), pending.pop()
                    running[actor.evaluate.remote(job)] = (job, actor, time.time())
                now = time.monotonic()
                for job, actor, _ in running.values():
                    if now - last_poll.get(id(actor), 0.0) >= PROGRESS_POLL_S and not any(
                            polled is actor for _, polled in polls.values()):
                        polls[actor.progress.remote()] = (job, actor)
                        last_poll[id(actor)] = now
                ready, _ = ray.wait([*running, *polls], num_returns=1,
                                    timeout=PROGRESS_POLL_S)
                for ref in ready:
                    if ref in polls:
                        self._progress_answer(ref, *polls.pop(ref), running)
                        continue
                    # the call stays in `running` until its outcome is kept: Ctrl-C while
                    # the driver reads a finished bag (just as its summary appeared) must
                    # leave it to _collect_finished, not lose it
                    job, actor, submitted = running[ref]
                    outcome, actor_alive = self._result(ref, job, submitted)
                    outcomes[job.key] = outcome
                    del running[ref]
                    self._finished(outcome)
                    if actor_alive:
                        idle.append(actor)
                    else:
                        self.actors.remove(actor)
                        if pending:   # a fresh worker takes the dead one's place
                            idle.append(self._new_actor(gpus))
            return False
        except KeyboardInterrupt:
            self._collect_finished(running, outcomes)
            print('speed_sign_eval fleet: interrupted; the bags done so far are kept, run '
                  'the same command again to go on', file=sys.stderr)
            return True
        finally:
            for actor in self.actors:
                try:
                    ray.kill(actor)
                except Exception:  # noqa: BLE001 - already gone
                    pass

    def _collect_finished(self, running: dict[Any, tuple[BagJob, Any, float]],
                          outcomes: dict[str, BagOutcome]) -> None:
        """After Ctrl-C: the outcomes of the bags that finished as it came (a worker
        writes a bag's outputs before the driver hears of it), waiting at most
        :data:`INTERRUPT_COLLECT_S`; the bags still running are left."""
        if not running:
            return
        try:
            ready, _ = self.ray.wait(list(running), num_returns=len(running),
                                     timeout=INTERRUPT_COLLECT_S)
            for ref in ready:
                job, _, submitted = running.pop(ref)
                if job.key in outcomes:
                    continue   # kept just before Ctrl-C came
                outcome, _ = self._result(ref, job, submitted)
                if outcome.done:
                    outcomes[job.key] = outcome
                    self._finished(outcome)
        except KeyboardInterrupt:   # Ctrl-C again: stop at once
            pass

    def _worker_count(self, bags: int) -> int:
        if self.options.workers is not None:
            return max(1, min(self.options.workers, bags))
        cpus = int(self.engine.resources().get('CPU', 1))
        return max(1, min(cpus, bags))

    def _gpus_per_worker(self, workers: int) -> float:
        if self.options.gpus_per_worker is not None:
            return self.options.gpus_per_worker
        gpus = self.engine.resources().get('GPU', 0.0)
        return min(1.0, round(gpus / workers, 4)) if gpus > 0 else 0.0

    def _new_actor(self, gpus: float) -> Any:
        actor = self.actor_class.options(num_gpus=gpus).remote(
            self.settings, str(self.folder.root.absolute()))
        self.actors.append(actor)
        return actor

    def _result(self, ref: Any, job: BagJob, submitted_unix_s: float
                ) -> tuple[BagOutcome, bool]:
        """A call's outcome, and whether its worker can take another bag."""
        ray = self.ray
        try:
            return ray.get(ref), True
        except (ray.exceptions.ActorDiedError, ray.exceptions.RayActorError) as err:
            # ActorDiedError: the process died and had no restart left (ActorUnavailable
            # is the other RayActorError): this bag fails, the others go on.
            reason = (f'the worker process died while evaluating it and had no restart left '
                      f'(--retries {self.options.retries}): {_first_line(err)}')
            alive = False
        except ray.exceptions.RayError as err:
            reason = f'the evaluation call failed: {_first_line(err)}'
            alive = True
        return BagOutcome(job.key, str(job.bag), False, reason, None, '', submitted_unix_s,
                          time.time()), alive

    def _progress_answer(self, ref: Any, job: BagJob, actor: Any,
                         running: dict[Any, tuple[BagJob, Any, float]]) -> None:
        try:
            progress = self.ray.get(ref)
        except self.ray.exceptions.RayError:
            return   # a worker that died: its call's result says so
        if progress.key != job.key or not any(item[0].key == job.key
                                              for item in running.values()):
            return
        self.frames_under_way[job.key] = progress.frames_done
        self._draw_frames()
        if self.on_progress is not None:
            self.on_progress(job, progress, actor)

    def _finished(self, outcome: BagOutcome) -> None:
        self.frames_under_way.pop(outcome.key, None)
        self.frames_finished += outcome.frames
        self._draw_frames()
        self.bags_bar.update(1)
        if not outcome.done:
            self.bags_bar.write(f'FAILED {outcome.bag}: {outcome.reason}', file=sys.stderr)

    def _draw_frames(self) -> None:
        self.frames_bar.n = self.frames_finished + sum(self.frames_under_way.values())
        self.frames_bar.refresh()


def _first_line(error: BaseException) -> str:
    text = str(error).strip()
    return f'{type(error).__name__}: {text.splitlines()[0] if text else ""}'


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fleet`` subcommand to ``speed_sign_eval``."""
    parser = subparsers.add_parser(
        'fleet', help='evaluate many bags on Ray (this machine or a cluster), resumable',
        description='Evaluate many recorded drives like "eval bag", one Ray actor per '
        'worker process holding a pipeline, one call per bag. Each bag\'s results bag and '
        'JSON line are written to OUT as it finishes; running the same command again '
        'skips the bags done. Exit status 0 only when every bag was evaluated.')
    parser.add_argument('bags', nargs='*', metavar='BAG',
                        help='bags or glob patterns (quote them to let this command expand '
                        'them, "**" included)')
    parser.add_argument('--manifest', type=Path, metavar='CSV',
                        help='CSV with a header "bag,truth" and a row per bag (truth may be '
                        'empty); paths relative to the manifest\'s folder')
    parser.add_argument('--out', type=Path, required=True, metavar='DIR',
                        help='output folder (created; reuse it to resume)')
    parser.add_argument('--address', help='Ray cluster to join (HOST:PORT or "auto"; '
                        'default: $RAY_ADDRESS, else start Ray on this machine)')
    parser.add_argument('--workers', type=positive_integer, help='worker processes '
                        '(default: the cluster\'s CPUs, at most one per bag)')
    parser.add_argument('--retries', type=non_negative_integer, default=DEFAULT_RETRIES,
                        help=f'restarts of a worker process that dies, each retrying its bag '
                        f'(default {DEFAULT_RETRIES})')
    # a share of one GPU: a worker runs one pipeline, on one device
    parser.add_argument('--gpus-per-worker', type=number_in_range(minimum=0.0, maximum=1.0),
                        help='GPU share per worker, from 0 to 1 (default: the cluster\'s '
                        'GPUs divided among the workers, at most 1; 0 without GPUs)')
    parser.add_argument('--topic', help='image topic (needed when a bag has several)')
    add_pipeline_options(parser)
    parser.add_argument('--debug-images', action='store_true',
                        help='also write /debug_image into the results bags')
    parser.add_argument('--json', action='store_true',
                        help='print the aggregate as one JSON object (last stdout line)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bars')
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``speed_sign_eval fleet``; returns the exit status."""
    if not args.bags and args.manifest is None:
        raise FleetError('give bags (paths or glob patterns) or --manifest CSV')
    config = load_yaml(args.config) if args.config is not None else PipelineConfig()
    if args.backend is not None:
        config = dataclasses.replace(config, backend=args.backend)
    settings = EvaluationSettings(config, args.topic, args.grace, args.debug_images)
    jobs = jobs_from_paths(args.bags, settings) if args.bags else []
    if args.manifest is not None:
        known = {job.key for job in jobs}
        jobs += [job for job in jobs_from_manifest(args.manifest, settings)
                 if job.key not in known]
    options = FleetOptions(workers=args.workers, retries=args.retries, address=args.address,
                           gpus_per_worker=args.gpus_per_worker,
                           progress=not args.no_progress,
                           verbose=getattr(args, 'verbose', False))
    report = run_fleet(jobs, settings, FleetFolder(args.out), options)
    print(report.to_json() if args.json else format_table(report))
    if report.interrupted:
        return EXIT_INTERRUPTED
    return 0 if report.all_done else 1
