#!/usr/bin/env python3
"""All benchmarks in one run: detector, classifier, pipeline and node, against the peers.

``make bench`` runs this. On the same frames, in the same process and run, it measures:

detector stage (GTSDB scenes, ``../shared/data/gtsdb-dev``)
    per-frame time (median over the frames) and candidate recall@7 (top 7 candidates;
    hit: centre within ``max(3, 0.35 r)`` px of the sign's box centre, as ``speed_sign_eval
    scenes``) of the GL detector (both vote methods), the CPU path (``backend: cpu``),
    the numpy reference, ``cv2.HoughCircles``
    (HOUGH_GRADIENT and HOUGH_GRADIENT_ALT) and ``radsym`` (RSD and FRST), with the peers'
    tuned parameters of ``bench_detector.py``. Frame sizes:

    - ``640x480``: the central 640 columns of the 816x480 scenes (VGA with square pixels;
      squeezing 816 to 640 would turn the signs into ellipses);
    - ``816x480``: the data as stored;
    - ``1280x720``: the scenes resized (x 1.569, y 1.5), truth boxes scaled alike;
    - ``1920x1080``: resized, time only (fewer frames).

    All methods keep their radius range (4..40 px for the peers, the DetectorConfig's for
    ours) at every size, so the resized sizes show how time grows with pixels, and
    signs upscaled beyond 40 px radius are missed by every method alike.
    Methods are interleaved frame by frame, so machine load hits them alike.
    Per size, ``auto_pick`` is the backend ``backend: auto`` keeps on this host (the
    faster of GL and CPU on a software renderer, else GL).
    Sweeps (816x480, GL, CPU and numpy): time vs ``max_radius_px`` and time vs edge count
    (``gradient_threshold`` varied; edges counted with ``voting_numpy.compute_edges``).

classifier (GTSRB crops, ``../shared/data/gtsrb-dev``)
    accuracy and ms per crop of the MACE/kth-law/PSR classifier against a plain
    ``cv2.matchTemplate`` NCC baseline with the same rendered templates
    (``bench_classifier.bench_crops``), overall and by sign width; plus ms per 640x480
    frame of 7 candidates (``bench_classifier.bench_speed``).

end to end
    ``Pipeline`` (the node's parameter file, classifier banks cached) on 640x480 frames of
    a synthetic drive: frames per second and per-frame latency; ``speed_sign_eval bag``
    (the installed executable) at 640x480, 1280x720 and 1920x1080 on a synthetic drive
    (fps, stage times) and on approach sequences made from the GTSDB scenes (signs
    recognized, wrong limits), ``bench_camera_sizes.py``; and the node through DDS
    (``bench_node.main``: the installed executable, 640x480 frames published at 10 Hz,
    then 30 Hz; then 1280x720 frames at 30 Hz).

The papers' headline figures are printed beside them, labelled as quoted.

The stages are in ``run_all_stages.py``; this script runs them, records the host and
the papers' figures, and writes the outputs.

Output under ``--out DIR``: ``results.json``, ``table.txt`` (the table printed) and PNG
plots (see ``report.py``); with ``--results-md PATH`` also the Markdown report
(``results_markdown.py``; ``make bench`` writes bench/RESULTS.md so). ``--quick`` uses a
handful of frames/crops (smoke test, not figures to quote). Usage::

    python bench/run_all.py --out out/bench [--results-md bench/RESULTS.md] [--quick]
        [--skip-node] [--params FILE|defaults] [--validation PATH] [--value-holdout PATH]
        [--designs PATH] [--soak PATH]

The last four name the JSON files of the runs too long for ``make bench`` (``make
validate``: 5 folds by track, leave one value out, rendered designs; ``make soak``): their
figures join results.json and get their sections in the Markdown report
(``long_runs_markdown.py``); ``make bench`` passes the ones under out/ that exist.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()  # as the node does, before numpy loads its BLAS: the node's figures

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:  # the sibling bench scripts are plain modules
    sys.path.insert(0, str(BENCH_DIR))

import bench_inputs  # noqa: E402
import long_runs_markdown  # noqa: E402
import report  # noqa: E402
import results_markdown  # noqa: E402
from host_record import machine_record  # noqa: E402
from run_all_stages import (  # noqa: E402
    DATA_DIR,
    BenchSettings,
    camera_sizes_stage,
    classifier_stage,
    detector_stage,
    log,
    node_hd_stage,
    node_stage,
    pipeline_config,
    pipeline_stage,
)

from speed_sign_detector.config_parameters import to_parameters
from speed_sign_detector.errors import SpeedSignError  # noqa: E402

#: The papers' headline figures: quoted from /work/shared/papers, NOT measured here.
PAPER_FIGURES: dict[str, dict[str, object]] = {
    'rsd_gpu_detection_ivs2011': {
        'source': 'Glavtchev et al., Feature-Based Speed Limit Sign Detection Using a GPU '
                  '(IVS 2011), abstract and section V-B',
        'fps': 33.0, 'frame_size': '640x480', 'detection_rate': 0.88,
        'hardware': 'Intel Atom 230 @ 1.67 GHz + NVIDIA GeForce 9400M GS',
        'note': '144 of 164 signs in 43 min of video, up to 7 candidates per frame, with '
                'tracking (a per-sign rate over a drive, not per-frame recall@7)'},
    'template_fft_recognition_dagm2010': {
        'source': 'Muyan-Ozcelik et al., A Template-Based Approach for Real-Time '
                  'Speed-Limit-Sign Recognition on an Embedded System Using GPU Computing '
                  '(DAGM 2010)',
        'fps': 18.5, 'frame_size': '640x240', 'recognition_rate': 0.90,
        'hardware': 'Intel Core2 Duo P8600 2.4 GHz + NVIDIA GeForce 9600M GT',
        'note': '120 EU speed-limit signs in 45 min of video (per sign, with temporal '
                'integration), not per-crop accuracy'},
}


#: ``--quick``: a few frames and crops, to check the machinery (figures not to quote).
QUICK: dict[str, object] = {
    'detector_frames': 3, 'large_frames': 1, 'sweep_frames': 1, 'max_radii_px': (20.0, 40.0),
    'gradient_thresholds': (40.0, 100.0), 'crop_every': 1500, 'speed_frames': 2,
    'pipeline_frames': 6, 'camera_drive_s': 1.0, 'approach_sequences': 2,
    'node_seconds': 2.0}


# ----------------------------------------------------------------------------- driver
#: The host record (bench_soak.py takes it from here).
_machine = machine_record


Stage = Callable[[BenchSettings], dict[str, object]]


def run_benchmark(settings: BenchSettings,
                  long_runs: dict[str, dict[str, object]] | None = None) -> dict[str, object]:
    """Run every stage, write results.json, table.txt, the plots and (when
    ``settings.results_md`` is set) the Markdown report; returns the results.

    A stage that fails is recorded as ``{'error': message}`` (and reported) while the
    others still run. ``long_runs``: the figures of the long runs given as JSON files
    (``long_runs_markdown.load_long_runs``), added to the results under their keys.
    """
    settings.out_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    results: dict[str, object] = {
        'date_utc': datetime.now(UTC).isoformat(timespec='seconds'),
        'command': list(settings.command), 'quick': settings.quick,
        'machine': machine_record(),
        'settings': {k: (str(v) if isinstance(v, Path) else v)
                     for k, v in dataclasses.asdict(settings).items()},
        'paper_figures_quoted_not_measured': PAPER_FIGURES,
    }
    stages: list[tuple[str, Stage]] = [('detector', detector_stage),
                                       ('classifier', classifier_stage),
                                       ('pipeline', pipeline_stage)]
    if settings.camera_sizes:
        stages.append(('camera_sizes', camera_sizes_stage))
    else:
        results['camera_sizes'] = {'skipped': 'no camera sizes'}
    if settings.node_seconds > 0:
        stages.append(('node', node_stage))
        if settings.node_hd_rates_hz:
            stages.append(('node_hd', node_hd_stage))
    else:
        results['node'] = results['node_hd'] = {'skipped': 'node_seconds = 0'}
    for name, stage in stages:
        stage_started = time.perf_counter()
        try:
            results[name] = stage(settings)
        except (SpeedSignError, OSError, RuntimeError, ValueError) as err:
            log(f'{name} stage FAILED: {type(err).__name__}: {err}')
            results[name] = {'error': f'{type(err).__name__}: {err}'}
        results[name]['stage_s'] = time.perf_counter() - stage_started
    if 'pipeline' in results and 'error' not in results['pipeline']:
        with contextlib.suppress(SpeedSignError, OSError):
            results['pipeline']['config'] = to_parameters(pipeline_config(settings))
    results['elapsed_s'] = time.perf_counter() - started
    results.update(long_runs or {})
    table = report.format_table(results)
    results['plots'] = [str(path) for path in report.write_plots(results, settings.out_dir)]
    report.write_json(results, settings.out_dir / 'results.json')
    (settings.out_dir / 'table.txt').write_text(table + '\n')
    if settings.results_md is not None:
        results_markdown.write_results_markdown(results, settings.results_md)
    print(table)
    return results


def main(argv: list[str] | None = None) -> int:
    """Parse the options, run, print the table; 1 when a stage failed."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output folder')
    parser.add_argument('--results-md', type=Path, metavar='PATH',
                        help='also write the Markdown report there (make bench: '
                             'bench/RESULTS.md)')
    parser.add_argument('--quick', action='store_true',
                        help='a few frames/crops only (smoke test; figures not to quote)')
    parser.add_argument('--gtsdb', type=Path, default=DATA_DIR / 'gtsdb-dev')
    parser.add_argument('--gtsrb', type=Path, default=DATA_DIR / 'gtsrb-dev')
    parser.add_argument('--detector-frames', type=int,
                        help='GTSDB speed-limit scenes for time + recall (0 = all 214)')
    parser.add_argument('--crop-every', type=int, help='use every Nth GTSRB crop')
    parser.add_argument('--pipeline-frames', type=int)
    parser.add_argument('--node-seconds', type=float, help='0 = do not run the node')
    parser.add_argument('--skip-node', action='store_true', help='same as --node-seconds 0')
    long_runs_markdown.add_arguments(parser)
    parser.add_argument('--params', default=str(bench_inputs.PARAMS_FILE),
                        help="parameter file of the pipeline and classifier stages (the "
                             "node's, which the node stage uses); 'defaults' = PipelineConfig()")
    args = parser.parse_args(argv)
    overrides: dict[str, object] = dict(QUICK) if args.quick else {}
    for option, name in (('detector_frames', 'detector_frames'), ('crop_every', 'crop_every'),
                         ('pipeline_frames', 'pipeline_frames'),
                         ('node_seconds', 'node_seconds')):
        if getattr(args, option) is not None:
            overrides[name] = getattr(args, option)
    if args.skip_node:
        overrides['node_seconds'] = 0.0
    command = ('python', 'bench/run_all.py', *(sys.argv[1:] if argv is None else argv))
    params = None if args.params == 'defaults' else Path(args.params)
    settings = BenchSettings(out_dir=args.out, gtsdb_dir=args.gtsdb, gtsrb_dir=args.gtsrb,
                             pipeline_params=params, quick=args.quick, command=command,
                             results_md=args.results_md,
                             **overrides)
    for folder in (settings.gtsdb_dir, settings.gtsrb_dir):
        if not folder.is_dir():
            print(f'data folder {folder} not found (see ../shared/data/README)',
                  file=sys.stderr)
            return 2
    results = run_benchmark(settings, long_runs_markdown.load_long_runs(args))
    failed = [name for name, value in results.items()
              if isinstance(value, dict) and 'error' in value]
    print(f'\nwrote {settings.out_dir}/results.json, table.txt and {len(results["plots"])} '
          f'plots' + (f', and {settings.results_md}' if settings.results_md else '')
          + f' in {results["elapsed_s"]:.0f} s'
          + (f'; FAILED stages: {failed}' if failed else ''))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
