"""The aggregate of a fleet run: what was evaluated, how fast, and the summed metrics.

:func:`build_report` turns the bags' outcomes into a :class:`FleetReport`; its
:meth:`FleetReport.to_json_dict` is what ``speed_sign_eval fleet --json`` prints as its
last stdout line and writes to ``OUT/fleet.json``:

``bags``
    bags in the run (given on the command line or in the manifest).
``bags_done``, ``bags_resumed``
    bags evaluated completely, and how many of them an earlier run with the same folder
    had done (skipped by this one).
``bags_failed``
    ``[{"bag", "key", "reason"}]``: bags that could not be evaluated completely (missing,
    corrupt, truncated, a worker that died for good).
``bags_not_run``
    bags not started because the run was interrupted.
``frames``
    frames of the done bags (earlier runs' included).
``frames_this_run``, ``wall_s``, ``fps``, ``bags_per_hour``
    frames this run processed (also of failed bags), its wall-clock time from the
    engine's start (Ray joined or started) to the last result, frames per second over
    that time, and bags this run evaluated completely per hour of it.
``workers``
    per worker process (``host:pid``): bags, frames, seconds busy, frames per busy
    second, and the seconds it spent building its pipeline.
``signs``, ``recognized``, ``recall``, ``wrong_limits``, ... (as ``eval bag``), with
    ``bags_with_truth``: the per-sign metrics of the done bags that have truth, their
    counts summed (:func:`speed_sign_detector.tools.bag_grading.sum_drive_metrics`); absent
    when no bag has truth.

:func:`format_table` is the terminal table, :func:`write_summary_png` the picture
(recall and wrong limits per bag, frames over time per worker).
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from speed_sign_detector.tools.bag_grading import sum_drive_metrics
from speed_sign_detector.tools.eval_bag import numpy_json_default, summary_json
from speed_sign_detector.tools.fleet_jobs import BagOutcome, FleetError

#: Longest bag name shown in the table, characters.
TABLE_NAME_CHARS = 32


@dataclass(frozen=True)
class WorkerThroughput:
    """What one worker process did in this run.

    Attributes:
        worker: ``host:pid``.
        bags: bags it evaluated (done or not).
        frames: frames it processed.
        busy_s: seconds its calls took (start-up included), wall clock.
        setup_s: seconds of that spent building its pipeline.
        fps: frames / busy_s.
    """

    worker: str
    bags: int
    frames: int
    busy_s: float
    setup_s: float
    fps: float


@dataclass(frozen=True)
class FleetReport:
    """The aggregate of a run (fields described in the module docstring).

    Attributes:
        outcomes: every bag's outcome, in the order the bags were given (not in JSON:
            the per-bag details are the summaries in the output folder).
        started_unix_s: when this run's engine started, seconds since the epoch.
    """

    bags: int
    bags_done: int
    bags_resumed: int
    bags_failed: tuple[dict[str, str], ...]
    bags_not_run: int
    frames: int
    frames_this_run: int
    wall_s: float
    fps: float
    bags_per_hour: float
    workers: tuple[WorkerThroughput, ...]
    metrics: dict[str, Any] | None
    interrupted: bool
    out_dir: str
    outcomes: tuple[BagOutcome, ...]
    started_unix_s: float

    @property
    def all_done(self) -> bool:
        """True when every bag of the run was evaluated completely."""
        return self.bags_done == self.bags

    def to_json_dict(self) -> dict[str, Any]:
        """The aggregate as printed with ``--json`` (JSON-ready)."""
        result: dict[str, Any] = {
            'bags': self.bags, 'bags_done': self.bags_done,
            'bags_resumed': self.bags_resumed, 'bags_failed': list(self.bags_failed),
            'bags_not_run': self.bags_not_run, 'frames': self.frames,
            'frames_this_run': self.frames_this_run, 'wall_s': self.wall_s,
            'fps': self.fps, 'bags_per_hour': self.bags_per_hour,
            'workers': [vars(worker) for worker in self.workers],
            'interrupted': self.interrupted, 'out_dir': self.out_dir,
        }
        if self.metrics is not None:
            metrics = dict(self.metrics)
            result['bags_with_truth'] = metrics.pop('drives')
            result.update(metrics)
        return result

    def to_json(self) -> str:
        """One line of JSON."""
        return summary_json(self.to_json_dict())


def build_report(outcomes: Sequence[BagOutcome], bags: int, started_unix_s: float,
                 finished_unix_s: float, out_dir: Path, interrupted: bool = False
                 ) -> FleetReport:
    """Aggregate the outcomes of a run.

    Args:
        outcomes: one per bag that finished (done or failed), resumed ones included.
        bags: bags in the run (those without an outcome were not run).
        started_unix_s, finished_unix_s: this run's wall-clock span, seconds since the
            epoch.
        out_dir: the output folder.
        interrupted: the run was stopped before every bag was tried.
    """
    done = [outcome for outcome in outcomes if outcome.done]
    this_run = [outcome for outcome in outcomes if not outcome.resumed]
    wall_s = max(finished_unix_s - started_unix_s, 1e-9)
    frames_this_run = sum(outcome.frames for outcome in this_run)
    by_worker: dict[str, list[BagOutcome]] = {}
    for outcome in this_run:
        if outcome.worker:
            by_worker.setdefault(outcome.worker, []).append(outcome)
    workers = []
    for worker, worked in sorted(by_worker.items()):
        busy_s = sum(outcome.finished_unix_s - outcome.started_unix_s for outcome in worked)
        frames = sum(outcome.frames for outcome in worked)
        workers.append(WorkerThroughput(
            worker, len(worked), frames, busy_s,
            sum(outcome.setup_s for outcome in worked), frames / busy_s if busy_s > 0 else 0.0))
    return FleetReport(
        bags=bags, bags_done=len(done),
        bags_resumed=sum(outcome.resumed for outcome in outcomes),
        bags_failed=tuple({'bag': outcome.bag, 'key': outcome.key,
                           'reason': outcome.reason or ''}
                          for outcome in outcomes if not outcome.done),
        bags_not_run=bags - len(outcomes),
        frames=sum(outcome.frames for outcome in done),
        frames_this_run=frames_this_run, wall_s=wall_s, fps=frames_this_run / wall_s,
        bags_per_hour=sum(outcome.done for outcome in this_run) / wall_s * 3600.0,
        workers=tuple(workers),
        metrics=sum_drive_metrics(outcome.summary for outcome in done
                                  if outcome.summary is not None),
        interrupted=interrupted, out_dir=str(out_dir), outcomes=tuple(outcomes),
        started_unix_s=started_unix_s)


def format_table(report: FleetReport) -> str:
    """The per-bag table and the aggregate, for the terminal."""
    lines = [f'{"bag":<{TABLE_NAME_CHARS}} {"status":<8} {"frames":>7} {"fps":>6} '
             f'{"recall":>6} {"wrong":>5}  worker']
    for outcome in report.outcomes:
        summary = outcome.summary or {}
        status = ('resumed' if outcome.resumed else 'done') if outcome.done else 'FAILED'
        recall = summary.get('recall')
        lines.append(
            f'{_short_name(outcome.bag):<{TABLE_NAME_CHARS}} {status:<8} {outcome.frames:>7} '
            + (f'{summary["fps"]:6.1f} ' if 'fps' in summary and not outcome.resumed
               else f'{"-":>6} ')
            + (f'{recall:6.3f} ' if recall is not None else f'{"-":>6} ')
            + (f'{summary["wrong_limits"]:>5}  ' if 'wrong_limits' in summary
               else f'{"-":>5}  ')
            + (outcome.worker if not outcome.resumed else '(earlier run)'))
    lines.append('')
    lines.append(f'bags {report.bags}: {report.bags_done} done ({report.bags_resumed} by an '
                 f'earlier run), {len(report.bags_failed)} failed'
                 + (f', {report.bags_not_run} not run (interrupted)' if report.bags_not_run
                    else ''))
    lines.append(f'frames {report.frames} in the done bags; this run {report.frames_this_run} '
                 f'frames in {report.wall_s:.1f} s wall clock: {report.fps:.1f} fps, '
                 f'{report.bags_per_hour:.0f} bags/hour')
    metrics = report.metrics
    if metrics is not None:
        recall = metrics['recall']
        lines.append(
            f'{metrics["drives"]} bags with truth: signs {metrics["signs"]}, recognized '
            f'{metrics["recognized"]}, recall '
            + (f'{recall:.3f}' if recall is not None else 'n/a')
            + f'; wrong limits {metrics["wrong_limits"]} (look-alike '
            f'{metrics["lookalike_limits"]}, misread {metrics["misread_limits"]}, phantom '
            f'{metrics["phantom_limits"]}), {metrics["false_limits_per_hour"]:.1f} per hour; '
            f'end-of-limit signs {metrics["end_of_limit_signs"]}, read '
            f'{metrics["end_of_limit_recognized"]}, wrong {metrics["wrong_end_of_limits"]}')
    if report.workers:
        lines.append('workers:')
        for worker in report.workers:
            lines.append(f'  {worker.worker:<28} {worker.bags:>4} bags {worker.frames:>7} '
                         f'frames  busy {worker.busy_s:7.1f} s  {worker.fps:6.1f} fps  '
                         f'(pipeline start-up {worker.setup_s:.1f} s)')
    for failed in report.bags_failed:
        lines.append(f'FAILED {failed["bag"]}: {failed["reason"]}')
    if report.interrupted:
        lines.append('INTERRUPTED: run the same command again to evaluate the rest')
    lines.append(f'outputs in {report.out_dir}')
    return '\n'.join(lines)


def write_report_json(report: FleetReport, path: Path, scratch: Path) -> None:
    """Write the aggregate as JSON (temporary file, then ``os.replace``).

    Raises:
        FleetError: it cannot be written.
    """
    temporary = scratch / path.name
    try:
        temporary.write_text(json.dumps(report.to_json_dict(), indent=1,
                                        default=numpy_json_default) + '\n', encoding='utf-8')
        os.replace(temporary, path)
    except OSError as err:
        raise FleetError(f'cannot write {path}: {err}') from err


def write_summary_png(report: FleetReport, path: Path, scratch: Path) -> None:
    """The run as a picture: recall and wrong limits per bag (top), cumulative frames
    over the run's wall-clock time, per worker and in all (bottom).

    Raises:
        FleetError: matplotlib is missing or the file cannot be written.
    """
    try:
        import matplotlib
        matplotlib.use('Agg')
        from matplotlib import pyplot
    except ImportError as err:
        raise FleetError(f'cannot draw {path}: matplotlib is not installed '
                         f'(pip install "speed_sign_detector[fleet]")') from err
    figure, (bags_axes, time_axes) = pyplot.subplots(2, 1, figsize=(10, 7.5))
    try:
        scored = [outcome for outcome in report.outcomes
                  if outcome.summary is not None and 'signs' in outcome.summary]
        if scored:
            names = [_short_name(outcome.bag, 18) + ('' if outcome.done else ' (!)')
                     for outcome in scored]
            positions = range(len(scored))
            recalls = [outcome.summary['recall'] for outcome in scored]
            bags_axes.bar([p - 0.2 for p in positions],
                          [math.nan if recall is None else recall for recall in recalls],
                          width=0.4, color='tab:green', label='recall')
            for position, recall in zip(positions, recalls, strict=True):
                if recall is None:   # no speed-limit sign in this bag's truth
                    bags_axes.text(position - 0.2, 0.02, 'no sign', rotation=90,
                                   ha='center', va='bottom', fontsize=7, color='gray')
            bags_axes.set_ylim(0, 1.05)
            bags_axes.set_ylabel('recall')
            wrong_axes = bags_axes.twinx()
            wrongs = [outcome.summary['wrong_limits'] for outcome in scored]
            wrong_axes.bar([p + 0.2 for p in positions], wrongs, width=0.4,
                           color='tab:red', label='wrong limits')
            wrong_axes.set_ylim(0, max(1, *wrongs) * 1.1)
            wrong_axes.set_ylabel('wrong limits')
            bags_axes.set_xticks(list(positions), names, rotation=45, ha='right', fontsize=7)
            handles = [*bags_axes.get_legend_handles_labels()[0],
                       *wrong_axes.get_legend_handles_labels()[0]]
            bags_axes.legend(handles=handles, loc='upper right', fontsize=8)
        else:
            bags_axes.text(0.5, 0.5, 'no bag with truth', ha='center', va='center')
        metrics = report.metrics
        bags_axes.set_title(
            f'{report.bags_done}/{report.bags} bags done, {len(report.bags_failed)} failed'
            + (f'; recall {metrics["recall"]:.3f}, {metrics["wrong_limits"]} wrong limits'
               if metrics is not None and metrics['recall'] is not None else ''))
        this_run = sorted((outcome for outcome in report.outcomes if not outcome.resumed),
                          key=lambda outcome: outcome.finished_unix_s)
        by_worker: dict[str, list[tuple[float, int]]] = {}
        total: list[tuple[float, int]] = [(0.0, 0)]
        for outcome in this_run:
            at_s = outcome.finished_unix_s - report.started_unix_s
            points = by_worker.setdefault(outcome.worker or '?', [(0.0, 0)])
            points.append((at_s, points[-1][1] + outcome.frames))
            total.append((at_s, total[-1][1] + outcome.frames))
        for worker, points in sorted(by_worker.items()):
            time_axes.step(*zip(*points, strict=True), where='post', label=worker)
        time_axes.step(*zip(*total, strict=True), where='post', color='black', linewidth=2,
                       label=f'all: {report.fps:.1f} fps')
        time_axes.set_xlabel('seconds since the run started (wall clock)')
        time_axes.set_ylabel('frames evaluated')
        time_axes.set_title(f'throughput: {report.frames_this_run} frames in '
                            f'{report.wall_s:.1f} s, {report.bags_per_hour:.0f} bags/hour')
        time_axes.legend(loc='upper left', fontsize=8)
        figure.tight_layout()
        temporary = scratch / path.name
        figure.savefig(temporary, dpi=90)
        os.replace(temporary, path)
    except OSError as err:
        raise FleetError(f'cannot write {path}: {err}') from err
    finally:
        pyplot.close(figure)


def _short_name(bag: str, limit: int = TABLE_NAME_CHARS) -> str:
    name = Path(bag).name or bag
    return name if len(name) <= limit else name[:limit - 1] + '~'


