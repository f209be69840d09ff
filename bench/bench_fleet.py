#!/usr/bin/env python3
"""Fleet evaluation on Ray: bags per hour and frames per second with 1 and 2 workers.

Writes ``--bags`` synthetic drives (MCAP, raw bgr8, ``--width`` x ``--height``,
``--seconds`` at 15 fps, one seed each) with their truth, starts one local Ray with
``--cpus`` CPUs, and runs ``speed_sign_eval fleet``'s :func:`run_fleet` on all of them
once per worker count (``--workers``, default 1 and 2), each into a fresh output
folder (nothing resumed), in the same run. Per worker count:

- ``wall_s``: from the run's start on an already running Ray to its last result:
  worker processes started, pipelines built, every bag evaluated and written;
- ``fps``, ``bags_per_hour``: frames and bags over ``wall_s``;
- ``worker_fps``: frames per busy second of each worker, ``worker_setup_s``: the
  seconds each worker spent building its pipeline on its first bag;
- ``scaling``: fps with N workers / fps with 1 worker.

It also times Ray's own start (``ray_start_s``, paid once per run on one machine, or
once per cluster) and prints a **projection** (not a measurement) for a cluster of
``--project-machines`` such machines: each machine contributes its measured 2-worker
rate; a run of B bags of F frames with W = 2 x machines workers takes about
``start-up + ceil(B / W) x F / worker_fps``, so bags fewer than workers, or bags of very
different sizes, leave workers idle, and the per-worker start-up weighs on short runs.

Usage::

    python bench/bench_fleet.py [--bags 6] [--seconds 6] [--out DIR] [--json]

Progress goes to stderr; with ``--json`` the last stdout line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.fleet import FleetOptions, run_fleet
from speed_sign_detector.tools.fleet_jobs import (
    BagJob,
    EvaluationSettings,
    FleetFolder,
    job_key,
)
from speed_sign_detector.tools.synth import write_drive
from speed_sign_detector.truth import write_truth

PROJECT_ROOT = Path(__file__).resolve().parents[1]
PARAMS_FILE = PROJECT_ROOT / 'config' / 'speed_sign_detector.yaml'
DRIVE_FPS = 15.0
#: Object store of the benchmark's Ray, bytes (results are small dicts).
OBJECT_STORE_BYTES = 128 * 1024 * 1024


@dataclass(frozen=True)
class FleetBenchSettings:
    """What the benchmark runs.

    Attributes:
        out_dir: where the bags, the fleet output folders and ``results.json`` go.
        bags: synthetic drives to evaluate.
        seconds: length of each drive, s (at 15 fps).
        width_px, height_px: frame size.
        worker_counts: worker counts to measure, in order (the first is the baseline).
        cpus: CPUs of the local Ray (None: this machine's).
        project_machines: machines of the projected cluster.
        params_file: the node's parameter file (None: defaults).
    """

    out_dir: Path
    bags: int = 6
    seconds: float = 6.0
    width_px: int = 640
    height_px: int = 480
    worker_counts: tuple[int, ...] = (1, 2)
    cpus: int | None = 2
    project_machines: int = 10
    params_file: Path | None = PARAMS_FILE


def write_bags(settings: FleetBenchSettings) -> list[tuple[Path, Path]]:
    """The synthetic drives as MCAP bags with truth files: ``[(bag, truth)]``."""
    folder = settings.out_dir / 'bags'
    folder.mkdir(parents=True, exist_ok=True)
    pairs = []
    for seed in range(settings.bags):
        bag, truth = folder / f'drive_{seed:03d}', folder / f'drive_{seed:03d}.csv'
        if not bag.exists():
            config = DriveConfig(seed=seed, duration_s=settings.seconds, fps=DRIVE_FPS,
                                 width_px=settings.width_px, height_px=settings.height_px)
            write_truth(truth, write_drive(SyntheticDrive(config), bag))
        pairs.append((bag, truth))
        print(f'bag {seed + 1}/{settings.bags} ready', file=sys.stderr)
    return pairs


def measure(settings: FleetBenchSettings) -> dict[str, Any]:
    """Run the fleet once per worker count on one local Ray; the figures as a dict."""
    import ray

    config = (load_yaml(settings.params_file) if settings.params_file is not None
              else PipelineConfig())
    evaluation = EvaluationSettings(config)
    pairs = write_bags(settings)
    jobs = [BagJob(job_key(bag, truth, evaluation), bag, truth) for bag, truth in pairs]
    started_here = not ray.is_initialized()
    ray_start_s = 0.0
    if started_here:
        started = time.perf_counter()
        ray.init(address='local', num_cpus=settings.cpus, object_store_memory=OBJECT_STORE_BYTES,
                 include_dashboard=False, log_to_driver=False)
        ray_start_s = time.perf_counter() - started
    runs = []
    try:
        for workers in settings.worker_counts:
            out = settings.out_dir / f'fleet_{workers}_workers'
            if out.exists():
                shutil.rmtree(out)
            print(f'fleet run with {workers} worker(s) ...', file=sys.stderr)
            report = run_fleet(jobs, evaluation, FleetFolder(out),
                               FleetOptions(workers=workers, progress=False))
            if not report.all_done:
                raise RuntimeError(f'fleet run with {workers} workers failed bags: '
                                   f'{report.bags_failed}')
            runs.append({
                'workers': workers, 'bags': report.bags_done, 'frames': report.frames,
                'wall_s': report.wall_s, 'fps': report.fps,
                'bags_per_hour': report.bags_per_hour,
                'worker_fps': [worker.fps for worker in report.workers],
                'worker_setup_s': [worker.setup_s for worker in report.workers],
                'recall': report.metrics['recall'] if report.metrics else None,
            })
    finally:
        if started_here:
            ray.shutdown()
    baseline = runs[0]['fps']
    for run in runs:
        run['scaling'] = run['fps'] / baseline if baseline > 0 else None
    frames_per_bag = runs[0]['frames'] / max(runs[0]['bags'], 1)
    return {'runs': runs, 'ray_start_s': ray_start_s, 'frames_per_bag': frames_per_bag,
            'projection': project(runs[-1], frames_per_bag, settings.bags,
                                  settings.project_machines)}


def project(run: dict[str, Any], frames_per_bag: float, bags: int, machines: int
            ) -> dict[str, Any]:
    """PROJECTED (not measured) figures for ``machines`` machines like this one.

    Each machine runs ``run['workers']`` workers at the measured per-worker rate
    (``worker_fps``, median) after the measured per-worker start-up; the cluster's
    scheduling overhead per bag (one call) is taken as negligible next to a bag.

    Returns:
        ``machines``, ``workers``, ``fps`` (the steady rate: machines x the measured
        rate of one machine), ``bags_per_hour`` for a long run, and ``wall_s`` for the
        benchmark's own ``bags`` bags (ceil(bags / workers) rounds), with the rule.
    """
    workers = machines * run['workers']
    worker_fps = statistics.median(run['worker_fps'])
    setup_s = statistics.median(run['worker_setup_s'])
    bag_s = frames_per_bag / worker_fps
    rounds = math.ceil(bags / workers)
    return {
        'projected_not_measured': True, 'machines': machines, 'workers': workers,
        'fps': machines * run['fps'], 'bags_per_hour': machines * run['fps'] * 3600.0
        / frames_per_bag,
        'wall_s_for_bench_bags': setup_s + rounds * bag_s, 'bench_bags': bags,
        'rule': 'machines x measured fps of one machine; a run of B bags takes about '
                'setup + ceil(B / workers) x frames_per_bag / worker_fps',
    }


def format_table(results: dict[str, Any]) -> str:
    """The figures as a small table."""
    lines = [f'{"workers":>7} {"bags":>5} {"frames":>7} {"wall s":>7} {"fps":>6} '
             f'{"bags/h":>7} {"scaling":>7}  per-worker fps (pipeline start-up s)']
    for run in results['runs']:
        per_worker = ', '.join(f'{fps:.1f} ({setup:.1f})' for fps, setup in
                               zip(run['worker_fps'], run['worker_setup_s'], strict=True))
        lines.append(f'{run["workers"]:>7} {run["bags"]:>5} {run["frames"]:>7} '
                     f'{run["wall_s"]:7.1f} {run["fps"]:6.1f} {run["bags_per_hour"]:7.0f} '
                     f'{run["scaling"]:7.2f}  {per_worker}')
    projection = results['projection']
    lines.append(f'Ray start {results["ray_start_s"]:.1f} s; {results["frames_per_bag"]:.0f} '
                 f'frames per bag')
    lines.append(f'PROJECTED, not measured: {projection["machines"]} such machines '
                 f'({projection["workers"]} workers): ~{projection["fps"]:.0f} fps, '
                 f'~{projection["bags_per_hour"]:.0f} bags/hour of this size; the '
                 f'{projection["bench_bags"]} bags here would take '
                 f'~{projection["wall_s_for_bench_bags"]:.1f} s (too few bags to fill them)')
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, help='output folder (default: a temporary one)')
    parser.add_argument('--bags', type=int, default=6, help='synthetic drives (default 6)')
    parser.add_argument('--seconds', type=float, default=6.0,
                        help='seconds per drive at 15 fps (default 6)')
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--workers', type=int, nargs='+', default=[1, 2],
                        help='worker counts to measure (default 1 2)')
    parser.add_argument('--cpus', type=int, default=2, help='CPUs of the local Ray')
    parser.add_argument('--project-machines', type=int, default=10,
                        help='machines of the projected cluster (default 10)')
    parser.add_argument('--json', action='store_true', help='last stdout line: one JSON object')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='bench_fleet_') as scratch:
        settings = FleetBenchSettings(
            out_dir=args.out or Path(scratch), bags=args.bags, seconds=args.seconds,
            width_px=args.width, height_px=args.height, worker_counts=tuple(args.workers),
            cpus=args.cpus, project_machines=args.project_machines)
        started = time.perf_counter()
        results = measure(settings)
        results.update({
            'date_utc': datetime.now(UTC).isoformat(timespec='seconds'),
            'machine': {'node': platform.node(), 'python': platform.python_version(),
                        'cpus_given_to_ray': settings.cpus},
            'settings': {'bags': settings.bags, 'seconds': settings.seconds,
                         'size': f'{settings.width_px}x{settings.height_px}',
                         'worker_counts': list(settings.worker_counts)},
            'elapsed_s': time.perf_counter() - started,
        })
        if args.out is not None:
            (args.out / 'results.json').write_text(json.dumps(results, indent=1) + '\n')
        print(json.dumps(results) if args.json else format_table(results))
    return 0


if __name__ == '__main__':
    sys.exit(main())
