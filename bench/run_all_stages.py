"""The stages of ``run_all.py``: the detector, classifier, pipeline and node benchmarks.

Each stage takes the run's :class:`BenchSettings` and returns its figures as a dict (the
stage's section of ``results.json``); what each one measures, and how, is told in
``run_all.py``'s docstring. ``run_all.py`` runs them in order and records the host, the
papers' quoted figures and the outputs; ``profile_stages.py`` profiles on the same frames
(:data:`DETECTOR_SIZES`, :func:`_spaced`, :func:`_frame_at`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()  # as the node does, before numpy loads its BLAS: the node's figures

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import bench_camera_sizes  # noqa: E402
import bench_classifier  # noqa: E402
import bench_detector  # noqa: E402
import bench_inputs  # noqa: E402
from bench_inputs import DATA_DIR  # noqa: E402

from speed_sign_detector.config import (  # noqa: E402
    ClassifierConfig,
    DetectorConfig,
    PipelineConfig,
)
from speed_sign_detector.config_parameters import load_yaml, to_parameters  # noqa: E402
from speed_sign_detector.detection.backend_trial import (  # noqa: E402
    TIMED_FRAMES,
    WARMUP_FRAMES,
)
from speed_sign_detector.detection.detector import (  # noqa: E402
    Detector,
    is_software_renderer,
)
from speed_sign_detector.detection.voting_numpy import compute_edges  # noqa: E402
from speed_sign_detector.errors import SpeedSignError  # noqa: E402
from speed_sign_detector.overlapped_pipeline import OverlappedPipeline  # noqa: E402
from speed_sign_detector.pipeline import FrameResult, Pipeline  # noqa: E402
from speed_sign_detector.recognition.classifier import Classifier  # noqa: E402
from speed_sign_detector.scene_truth import SceneSign, read_gtsdb_truth  # noqa: E402
from speed_sign_detector.tools.eval_scenes import SIZE_BINS_PX  # noqa: E402

PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: Where the classifier's filter banks are cached; bench_node's default, so the node
#: started by the node stage loads the banks the classifier stage built.
BANK_CACHE = Path(tempfile.gettempdir()) / 'speed_sign_detector_banks'
NODE_DOMAIN_ID = 131

#: Frame sizes of the detector stage: (name, width, height, how, recall measured).
#: how: 'crop' = central columns of the scene, 'resize' = cv2.resize of the scene.
DETECTOR_SIZES: tuple[tuple[str, int, int, str, bool], ...] = (
    ('640x480', 640, 480, 'crop', True),
    ('816x480', 816, 480, 'native', True),
    ('1280x720', 1280, 720, 'resize', True),
    ('1920x1080', 1920, 1080, 'resize', False),
)
#: Our detector backends timed in the sweeps (``{name}_ms`` columns).
OUR_METHODS = ('gl', 'cpu', 'numpy')
#: The backends ``backend: auto`` chooses between (the CPU path only on a software renderer).
AUTO_CANDIDATES = ('gl', 'cpu')
PEER_METHODS = ('hough_gradient', 'hough_gradient_alt', 'radsym_rsd', 'radsym_frst')


@dataclass(frozen=True)
class BenchSettings:
    """How much of each benchmark to run (see ``--help``); defaults are the full run.

    Attributes:
        out_dir: folder for results.json, table.txt and the PNG plots.
        gtsdb_dir, gtsrb_dir: the real-data folders.
        detector_sizes: names of the DETECTOR_SIZES measured.
        detector_frames: GTSDB scenes with a speed-limit sign, evenly spaced through the
            sorted list, used for time and recall at every size (0 = all 214).
        large_frames: of those, how many are timed at the time-only sizes (1920x1080).
        sweep_frames: of those, how many are timed in the radius / edge-count sweeps.
        max_radii_px: the max_radius_px values of the radius sweep.
        gradient_thresholds: the gradient_threshold values of the edge-count sweep.
        crop_every: GTSRB crops used: every Nth of labels.csv (1 = all 4,400).
        speed_frames: synthetic 640x480 frames of 7 candidates timed for the classifier.
        pipeline_frames: synthetic drive frames run through the Pipeline at 640x480.
        camera_sizes: the camera sizes of the ``eval bag`` stage, (width, height) px
            (empty = stage not run).
        camera_drive_s: length of its synthetic drive at each size, seconds.
        approach_sequences: its approach sequences per size (0 = none made).
        node_seconds: seconds the node is fed at each rate (0 = node not run).
        node_rates_hz: publishing rates of the node stage, run in order (one it can keep
            up with: latency without queueing; 30 Hz: throughput).
        node_hd_rates_hz: publishing rates of the second node stage, fed 1280x720 frames
            (an HD camera, detected at the working width; empty = not run).
        pipeline_params: ROS parameter file the pipeline and classifier stages load
            (the node's); None = PipelineConfig() defaults.
        classifier_config: overrides the parameter file's classifier config (tests).
        bank_cache: filter-bank cache folder shared by the classifier, pipeline and node.
        quick: recorded in the JSON: figures from a smoke run, not to be quoted.
        results_md: where to write the Markdown report (bench/RESULTS.md for ``make
            bench``); None = not written.
        command: the command line, recorded in the JSON.
    """

    out_dir: Path
    gtsdb_dir: Path = DATA_DIR / 'gtsdb-dev'
    gtsrb_dir: Path = DATA_DIR / 'gtsrb-dev'
    detector_frames: int = 60
    detector_sizes: tuple[str, ...] = tuple(size[0] for size in DETECTOR_SIZES)
    large_frames: int = 2
    sweep_frames: int = 6
    max_radii_px: tuple[float, ...] = (20.0, 40.0, 60.0, 80.0)
    gradient_thresholds: tuple[float, ...] = (20.0, 40.0, 80.0, 160.0)
    crop_every: int = 1
    speed_frames: int = 10
    pipeline_frames: int = 90
    camera_sizes: tuple[tuple[int, int], ...] = bench_camera_sizes.CAMERA_SIZES
    camera_drive_s: float = 4.0
    approach_sequences: int = 40
    node_seconds: float = 8.0
    node_rates_hz: tuple[float, ...] = (10.0, 30.0)
    node_hd_rates_hz: tuple[float, ...] = (30.0,)
    pipeline_params: Path | None = bench_inputs.PARAMS_FILE
    classifier_config: ClassifierConfig | None = None
    bank_cache: Path = BANK_CACHE
    quick: bool = False
    results_md: Path | None = None
    command: tuple[str, ...] = field(default_factory=tuple)


def log(message: str) -> None:
    """Print ``[HH:MM:SS] message`` on stderr (a stage's progress)."""
    print(f'[{time.strftime("%H:%M:%S")}] {message}', file=sys.stderr, flush=True)


def _median(values: Sequence[float]) -> float | None:
    return statistics.median(values) if values else None


def _percentile(values: Sequence[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


# --------------------------------------------------------------------------- detector
def _spaced(items: Sequence[str], count: int) -> list[str]:
    """``count`` items evenly spaced through ``items`` (all when count <= 0)."""
    if count <= 0 or count >= len(items):
        return list(items)
    return [items[int(i * len(items) / count)] for i in range(count)]


def _frame_at(gray: np.ndarray, signs: Sequence[SceneSign], width: int, height: int,
              how: str) -> tuple[np.ndarray, list[SceneSign]]:
    """The scene at ``width x height`` and its speed-limit signs in that frame's pixels."""
    limit_signs = [sign for sign in signs if sign.limit_kmh]
    if how == 'native':
        return gray, limit_signs
    if how == 'crop':
        image, offset = bench_detector._crop(gray, width)
        moved = [dataclasses.replace(sign, x1_px=sign.x1_px - offset, x2_px=sign.x2_px - offset)
                 for sign in limit_signs]
        return image, [sign for sign in moved if 0 <= sign.centre_px[0] < width]
    sx, sy = width / gray.shape[1], height / gray.shape[0]
    image = cv2.resize(gray, (width, height), interpolation=cv2.INTER_LINEAR)
    return image, [dataclasses.replace(sign, x1_px=sign.x1_px * sx, x2_px=sign.x2_px * sx,
                                       y1_px=sign.y1_px * sy, y2_px=sign.y2_px * sy)
                   for sign in limit_signs]


def _size_bin(radius_px: float) -> str:
    for low, high in SIZE_BINS_PX:
        if low <= radius_px < high:
            return f'{low:g}-{high:g}' if high < 1000 else f'{low:g}+'
    return 'other'


def _in_bin_order(counts: dict[str, int]) -> dict[str, int]:
    """``counts`` keyed by size-bin name, in the order of SIZE_BINS_PX."""
    order = [_size_bin(low) for low, _ in SIZE_BINS_PX]
    return {name: counts[name] for name in sorted(counts, key=order.index)}


def detector_methods(config: DetectorConfig) -> tuple[dict[str, bench_detector.Method],
                                                      list[Detector]]:
    """Every detector method by name, and our Detector objects (to close).

    ``gl`` is the config as given (``vote_method='auto'`` picks scatter); ``gl_raster``
    or ``gl_scatter`` is the other vote method; ``cpu`` is the vectorised CPU path
    (``backend: cpu``), ``numpy`` the reference.
    """
    gl = Detector(config, backend='gl')
    other_method = 'raster' if gl.vote_method == 'scatter' else 'scatter'
    other = Detector(dataclasses.replace(config, vote_method=other_method), backend='gl')
    cpu = Detector(config, backend='cpu')
    numpy_detector = Detector(config, backend='numpy')
    methods = {'gl': bench_detector._detector_method(gl),
               f'gl_{other_method}': bench_detector._detector_method(other),
               'cpu': bench_detector._detector_method(cpu),
               'numpy': bench_detector._detector_method(numpy_detector),
               'hough_gradient': bench_detector.hough_gradient,
               'hough_gradient_alt': bench_detector.hough_gradient_alt,
               'radsym_rsd': bench_detector._radsym_method('rsd'),
               'radsym_frst': bench_detector._radsym_method('frst')}
    return methods, [gl, other, cpu, numpy_detector]


def auto_pick(rows: dict[str, dict[str, object]], software_renderer: bool) -> str:
    """The backend ``backend: auto`` keeps on this host, from one size's method rows.

    On a software renderer auto times GL and the CPU path on the first frames and keeps
    the faster (here: the lower median of the run; a tie keeps GL, as the trial does); on
    a hardware renderer it keeps GL without timing the CPU path.
    """
    if not software_renderer or 'cpu' not in rows:
        return 'gl'
    return min(AUTO_CANDIDATES, key=lambda name: (rows[name]['median_ms'], name != 'gl'))


def detector_stage(settings: BenchSettings) -> dict[str, object]:
    """Time and recall@7 of every method at every size, on the same frames."""
    truth = read_gtsdb_truth(settings.gtsdb_dir / 'gt.txt')
    limit_files = sorted(name for name, signs in truth.items()
                         if any(sign.limit_kmh for sign in signs))
    files = _spaced(limit_files, settings.detector_frames)
    scenes = {}
    for name in files:
        gray = cv2.imread(str(settings.gtsdb_dir / 'images' / name), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise SpeedSignError(f'cannot read {settings.gtsdb_dir / "images" / name}')
        scenes[name] = gray
    config = DetectorConfig()
    methods, detectors = detector_methods(config)
    renderer = detectors[0].renderer
    our_warmed = [name for name in methods if name.startswith('gl') or name == 'cpu']
    result: dict[str, object] = {
        'renderer': renderer, 'backend_gl': detectors[0].backend_name,
        'gl_vote_method': detectors[0].vote_method,
        'software_renderer': is_software_renderer(renderer),
        'config': dataclasses.asdict(config), 'frames_available': len(limit_files),
        'top_n': bench_detector.TOP_N, 'peer_radius_px': [bench_detector.MIN_RADIUS_PX,
                                                          bench_detector.MAX_RADIUS_PX],
        'sizes': {}}
    try:
        for size_name, width, height, how, with_recall in DETECTOR_SIZES:
            if size_name not in settings.detector_sizes:
                continue
            size_files = files if with_recall else files[:settings.large_frames]
            times: dict[str, list[float]] = {name: [] for name in methods}
            found: dict[str, int] = {name: 0 for name in methods}
            found_by_bin: dict[str, dict[str, int]] = {name: {} for name in methods}
            signs_by_bin: dict[str, int] = {}
            signs_total = 0
            started = time.perf_counter()
            for index, name in enumerate(size_files):
                image, signs = _frame_at(scenes[name], truth[name], width, height, how)
                for sign in signs:
                    signs_by_bin[_size_bin(sign.radius_px)] = \
                        signs_by_bin.get(_size_bin(sign.radius_px), 0) + 1
                signs_total += len(signs)
                for method_name, method in methods.items():
                    if index == 0 and method_name in our_warmed:
                        method(image)  # warm-up: shaders, per-size GL resources, stencils
                    start = time.perf_counter()
                    centres = method(image)
                    times[method_name].append(1e3 * (time.perf_counter() - start))
                    for sign in signs:
                        if bench_detector._found(sign, centres, 0.0):
                            found[method_name] += 1
                            bin_name = _size_bin(sign.radius_px)
                            found_by_bin[method_name][bin_name] = \
                                found_by_bin[method_name].get(bin_name, 0) + 1
            rows = {}
            for method_name in methods:
                rows[method_name] = {
                    'median_ms': _median(times[method_name]),
                    'p90_ms': _percentile(times[method_name], 90),
                    'best_ms': min(times[method_name]),
                    'recall': (found[method_name] / signs_total
                               if with_recall and signs_total else None),
                    'recall_by_radius_px': ({b: found_by_bin[method_name].get(b, 0) / n
                                             for b, n in _in_bin_order(signs_by_bin).items()}
                                            if with_recall else None)}
            result['sizes'][size_name] = {
                'width': width, 'height': height, 'how': how, 'frames': len(size_files),
                'signs': signs_total if with_recall else None,
                'signs_by_radius_px': _in_bin_order(signs_by_bin) if with_recall
                else None, 'methods': rows}
            fastest = min(PEER_METHODS, key=lambda m: rows[m]['median_ms'])
            result['sizes'][size_name]['fastest_peer'] = fastest
            result['sizes'][size_name]['auto_pick'] = auto_pick(
                rows, bool(result['software_renderer']))
            result['sizes'][size_name]['gl_floor_ms'] = bench_detector.gl_floor_ms(width, height)
            log(f'detector {size_name}: {len(size_files)} frames, {signs_total} signs, '
                 f'{time.perf_counter() - started:.0f} s; ' + ', '.join(
                     f'{m} {rows[m]["median_ms"]:.0f} ms' for m in methods))
    finally:
        for detector in detectors:
            detector.close()
    result['frames'] = files
    result['sweeps'] = detector_sweeps(settings, [scenes[name] for name in
                                                  files[:settings.sweep_frames]], config)
    return result


def _time_detector(config: DetectorConfig, backend: str, frames: Sequence[np.ndarray]
                   ) -> float:
    """Median ms per frame of a fresh Detector (one warm-up call first)."""
    with Detector(config, backend=backend) as detector:
        detector.detect(frames[0])
        times = []
        for gray in frames:
            start = time.perf_counter()
            detector.detect(gray)
            times.append(1e3 * (time.perf_counter() - start))
    return statistics.median(times)


def detector_sweeps(settings: BenchSettings, frames: Sequence[np.ndarray],
                    base: DetectorConfig) -> dict[str, list[dict[str, float]]]:
    """GL, CPU and numpy time vs max radius, and vs edge count (gradient threshold varied)."""
    radius_rows = []
    for max_radius in settings.max_radii_px:
        config = dataclasses.replace(base, max_radius_px=max_radius)
        radius_rows.append({'max_radius_px': max_radius,
                            **{f'{b}_ms': _time_detector(config, b, frames)
                               for b in OUR_METHODS}})
    edge_rows = []
    for threshold in settings.gradient_thresholds:
        config = dataclasses.replace(base, gradient_threshold=threshold)
        edges = statistics.median(sum(level.count for level in compute_edges(gray, config))
                                  for gray in frames)
        edge_rows.append({'gradient_threshold': threshold, 'edges': edges,
                          **{f'{b}_ms': _time_detector(config, b, frames)
                             for b in OUR_METHODS}})
    log(f'detector sweeps: {len(frames)} frames at 816x480')
    return {'frames': len(frames), 'size': '816x480', 'max_radius': radius_rows,
            'edge_count': edge_rows}


# ------------------------------------------------------------------------- classifier
def pipeline_config(settings: BenchSettings) -> PipelineConfig:
    """The node's pipeline config (or the defaults), banks cached in ``bank_cache``."""
    config = (load_yaml(settings.pipeline_params) if settings.pipeline_params is not None
              else PipelineConfig())
    classifier = settings.classifier_config or config.classifier
    return dataclasses.replace(config, classifier=dataclasses.replace(
        classifier, cache_dir=str(settings.bank_cache)))


def classifier_stage(settings: BenchSettings) -> dict[str, object]:
    """Classifier vs NCC baseline on GTSRB crops, and ms per frame of 7 candidates."""
    config = pipeline_config(settings).classifier
    started = time.perf_counter()
    classifier = Classifier(config)
    result: dict[str, object] = {'bank_load_or_build_s': time.perf_counter() - started,
                                 'bank_mb': classifier.bank_nbytes / 1e6,
                                 'config': dataclasses.asdict(config),
                                 'crop_every': settings.crop_every}
    result.update(bench_classifier.bench_speed(classifier, settings.speed_frames))
    result['speed_frames'] = settings.speed_frames
    # the rendered templates alone, timed in the same run (the previous bank)
    rendered = Classifier(dataclasses.replace(config, bank_file='none'))
    result['rendered_bank'] = bench_classifier.bench_speed(rendered, settings.speed_frames)
    log(f'classifier: {result["ms_per_frame_7_candidates"]:.1f} ms per frame of 7 candidates '
         f'(rendered-only bank {result["rendered_bank"]["ms_per_frame_7_candidates"]:.1f} ms)')
    # the default bank was trained on gtsrb-dev: its crop accuracy here is on crops it saw;
    # the held-out figures come from speed_sign_train validate (k-fold split by track)
    result['crops_seen_in_training'] = config.bank_file.strip().lower() != 'none'
    started = time.perf_counter()
    result.update(bench_classifier.bench_crops(classifier, settings.gtsrb_dir,
                                               settings.crop_every))
    log(f'classifier: {result["crops"]} crops in {time.perf_counter() - started:.0f} s, '
         f'accuracy {result["classifier_accuracy"]:.3f} vs NCC '
         f'{result["ncc_baseline_accuracy"]:.3f}')
    return result


# ------------------------------------------------------------------------ end to end
def pipeline_stage(settings: BenchSettings) -> dict[str, object]:
    """Pipeline fps and per-frame latency at 640x480 on a synthetic drive."""
    # warm-up: GL resources of this size, FFT plans, and backend: auto's trial of GL
    # against the CPU path on a software renderer
    warmup = WARMUP_FRAMES + TIMED_FRAMES
    frames = [cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
              for bgr in bench_inputs.drive_frames(640, 480, settings.pipeline_frames + warmup)]
    config = pipeline_config(settings)
    with Pipeline(config) as pipeline:
        for index in range(warmup):
            pipeline.process(frames[index], stamp_s=index / 30.0)
        pipeline.reset()
        stages: dict[str, list[float]] = {}
        recognized = []
        started = time.perf_counter()
        for index, gray in enumerate(frames[warmup:]):
            frame_result = pipeline.process(gray, stamp_s=index / 30.0)
            for key, value in frame_result.timings_ms.items():
                stages.setdefault(key, []).append(value)
            if frame_result.recognized_limit_kmh:
                recognized.append(frame_result.recognized_limit_kmh)
        elapsed = time.perf_counter() - started
        backend, renderer = pipeline.backend_name, pipeline.renderer
        backend_choice = pipeline.backend_choice
        # the same frames with detection overlapping recognition (the node's default)
        pipeline.reset()
        overlapped_recognized: list[int] = []

        def collect(frame_result: FrameResult, _: object) -> None:
            if frame_result.recognized_limit_kmh:
                overlapped_recognized.append(frame_result.recognized_limit_kmh)

        def fail(error: Exception, _: object) -> None:
            raise error

        started = time.perf_counter()
        with OverlappedPipeline(pipeline, collect, fail) as overlapped:
            for index, gray in enumerate(frames[warmup:]):
                overlapped.submit(gray, stamp_s=index / 30.0)
        overlapped_elapsed = time.perf_counter() - started
    result = {'frames': len(frames) - warmup, 'width': 640, 'height': 480, 'backend': backend,
              'backend_choice': backend_choice, 'renderer': renderer,
              'fps': (len(frames) - warmup) / elapsed,
              'overlapped_fps': (len(frames) - warmup) / overlapped_elapsed,
              'overlapped_limits_recognized': overlapped_recognized,
              'latency_p50_ms': _percentile(stages['total'], 50),
              'latency_p95_ms': _percentile(stages['total'], 95),
              'stage_p50_ms': {key: _percentile(values, 50) for key, values in stages.items()},
              'limits_recognized': recognized,
              'params_file': str(settings.pipeline_params) if settings.pipeline_params
              else None}
    log(f'pipeline: {result["fps"]:.1f} fps serial, {result["overlapped_fps"]:.1f} fps '
         f'overlapped, p50 {result["latency_p50_ms"]:.0f} ms; detector {backend_choice}')
    return result


def camera_sizes_stage(settings: BenchSettings) -> dict[str, object]:
    """``speed_sign_eval bag`` at each camera size: synthetic drives (fps) and approach
    sequences from the GTSDB scenes (signs recognized), ``bench_camera_sizes``; the bags
    are written under ``out_dir/camera_sizes`` and removed afterwards."""
    work_dir = settings.out_dir / 'camera_sizes'
    shutil.rmtree(work_dir, ignore_errors=True)   # speed_sign_synth makes only new bags
    try:   # a failing tool raises CameraSizeBenchError, a RuntimeError: the stage fails
        return bench_camera_sizes.measure_camera_sizes(bench_camera_sizes.CameraSizeSettings(
            work_dir=work_dir, sizes=settings.camera_sizes, gtsdb_dir=settings.gtsdb_dir,
            drive_seconds=settings.camera_drive_s,
            approach_sequences=settings.approach_sequences))
    finally:
        shutil.rmtree(work_dir, ignore_errors=True)


def node_stage(settings: BenchSettings) -> dict[str, object]:
    """The node through DDS (``bench_node.main``), 640x480 frames at each of
    ``node_rates_hz``."""
    return _node_through_dds(settings, 640, 480, settings.node_rates_hz)


def node_hd_stage(settings: BenchSettings) -> dict[str, object]:
    """The node through DDS fed 1280x720 frames at each of ``node_hd_rates_hz``."""
    return _node_through_dds(settings, 1280, 720, settings.node_hd_rates_hz)


def _node_through_dds(settings: BenchSettings, width: int, height: int,
                      rates_hz: tuple[float, ...]) -> dict[str, object]:
    """``bench_node.main`` on ``width`` x ``height`` frames at each rate in ``rates_hz``.

    The node gets, after its own parameter file, ``node_params.yaml`` (in ``out_dir``)
    holding the pipeline stage's config, so node and pipeline run the same settings.
    """
    import bench_node  # needs rclpy: imported here so that --skip-node runs without it
    import yaml

    from speed_sign_detector.ros.node import NODE_NAME

    params_file = settings.out_dir / 'node_params.yaml'
    params_file.write_text(yaml.safe_dump(
        {NODE_NAME: {
            'ros__parameters': to_parameters(pipeline_config(settings))}}))
    argv = ['--rates', *(f'{rate:g}' for rate in rates_hz),
            '--width', str(width), '--height', str(height),
            '--seconds', f'{settings.node_seconds:g}',
            '--frames', '60', '--domain-id', str(NODE_DOMAIN_ID),
            '--bank-cache', str(settings.bank_cache),
            '--node-arg=--params-file', f'--node-arg={params_file}', '--json']
    captured = io.StringIO()
    with contextlib.redirect_stdout(captured):
        code = bench_node.main(argv)
    lines = captured.getvalue().strip().splitlines()
    if code != 0 or not lines:
        raise SpeedSignError(f'bench_node.main({argv}) exited with {code} (see its stderr)')
    result = json.loads(lines[-1])
    result['argv'] = argv
    return result
