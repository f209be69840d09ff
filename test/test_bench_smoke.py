"""Smoke test of the benchmark driver: bench/run_all.py on 2 scenes and 3 crops.

Runs the real stages (GL, CPU and numpy detectors, cv2.HoughCircles, radsym, the classifier
against the NCC baseline, the Pipeline) on a few real frames and crops into tmp_path,
and checks that the JSON, the table and the PNG plots are written with the expected
keys. No timing figure is asserted; the node stage (DDS, a second process) is left to
test_node*.py and to ``make bench``.
"""
from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from speed_sign_detector.config import ClassifierConfig

BENCH_DIR = Path(__file__).resolve().parents[1] / 'bench'
METHODS = {'gl', 'cpu', 'numpy', 'hough_gradient', 'hough_gradient_alt', 'radsym_rsd', 'radsym_frst'}


def bench_module(name: str) -> Any:
    """A script of bench/ imported as a module (bench/ is a folder of scripts, not a
    package)."""
    sys.path.insert(0, str(BENCH_DIR))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(BENCH_DIR))


@pytest.fixture(scope='module')
def run_all():
    """The bench/run_all.py module (bench/ is a folder of scripts, not a package)."""
    pytest.importorskip('radsym', reason='radsym (setup.py extra "bench") not installed')
    pytest.importorskip('matplotlib', reason='matplotlib (setup.py extra "bench") not installed')
    sys.path.insert(0, str(BENCH_DIR))
    try:
        yield importlib.import_module('run_all')
    finally:
        sys.path.remove(str(BENCH_DIR))


@pytest.fixture(scope='module')
def results(run_all, shared_data_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp('bench')
    settings = run_all.BenchSettings(
        out_dir=out, gtsdb_dir=shared_data_dir / 'gtsdb-dev',
        gtsrb_dir=shared_data_dir / 'gtsrb-dev', detector_frames=2, large_frames=1,
        detector_sizes=('640x480', '816x480'), sweep_frames=1, max_radii_px=(20.0, 40.0),
        gradient_thresholds=(40.0, 120.0), crop_every=1500, speed_frames=1,
        pipeline_frames=3, camera_sizes=((320, 240),), camera_drive_s=1.0,
        approach_sequences=1, node_seconds=0.0, pipeline_params=None,
        classifier_config=ClassifierConfig(max_radius_px=24.0),
        bank_cache=out / 'banks', quick=True, results_md=out / 'report' / 'RESULTS.md',
        command=('test',))
    returned = run_all.run_benchmark(settings)
    return {'returned': returned, 'out': out}


def test_writes_json_table_and_plots(results: dict) -> None:
    out: Path = results['out']
    saved = json.loads((out / 'results.json').read_text())
    assert saved['quick'] is True
    for key in ('date_utc', 'machine', 'settings', 'paper_figures_quoted_not_measured',
                'detector', 'classifier', 'pipeline', 'node', 'elapsed_s', 'plots'):
        assert key in saved, key
    assert 'skipped' in saved['node']
    assert isinstance(saved['detector']['software_renderer'], bool)
    for stage in ('detector', 'classifier', 'pipeline'):
        assert 'error' not in saved[stage], saved[stage]
    names = {Path(path).name for path in saved['plots']}
    assert names == {'detector_time_vs_frame_size.png', 'detector_recall.png',
                     'detector_sweeps.png', 'classifier_accuracy_vs_size.png'}
    for name in names:
        assert (out / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n', name
    table = (out / 'table.txt').read_text()
    assert 'QUOTED' in table and 'plain NCC' in table and 'radsym RSD' in table


def test_writes_the_markdown_report_of_the_run(results: dict) -> None:
    """``results_md`` (``make bench``: bench/RESULTS.md) is the renderer's text of this
    very run, marked as a smoke run, with the host's GL renderer named in its summary."""
    out: Path = results['out']
    written = (out / 'report' / 'RESULTS.md').read_text()
    saved = json.loads((out / 'results.json').read_text())
    markdown = bench_module('results_markdown')
    assert written == markdown.render_results_markdown(saved)
    assert markdown.SMOKE_NOTE in written
    summary = written.split('## Summary', 1)[1].split('\n## ', 1)[0]
    assert saved['detector']['renderer'] in summary
    assert saved['machine']['cpu_model'] in summary
    assert f"| {markdown.METHOD_LABELS['cpu']} |" in written  # the CPU path's row
    assert saved['pipeline']['backend_choice'] in written


def test_detector_section_has_every_method_size_and_sweep(results: dict) -> None:
    detector = results['returned']['detector']
    assert set(detector['sizes']) == {'640x480', '816x480'}
    for size in detector['sizes'].values():
        other_vote_method = {'scatter': 'gl_raster', 'raster': 'gl_scatter'}[
            detector['gl_vote_method']]
        assert set(size['methods']) == METHODS | {other_vote_method}
        assert size['frames'] == 2 and size['signs'] >= 2
        assert 0.0 < size['gl_floor_ms'] < size['methods']['gl']['median_ms']
        # both vote methods add the same votes: the same signs are found
        assert size['methods'][other_vote_method]['recall'] == size['methods']['gl']['recall']
        for row in size['methods'].values():
            assert row['median_ms'] > 0
            assert 0.0 <= row['recall'] <= 1.0
        # auto keeps the faster of GL and CPU on a software renderer, GL on a hardware one
        faster = min(('gl', 'cpu'), key=lambda name: size['methods'][name]['median_ms'])
        assert size['auto_pick'] == (faster if detector['software_renderer'] else 'gl')
    sweeps = detector['sweeps']
    assert [row['max_radius_px'] for row in sweeps['max_radius']] == [20.0, 40.0]
    low, high = sweeps['edge_count']
    assert low['edges'] > high['edges'] > 0  # a higher gradient threshold keeps fewer edges
    assert all(row['gl_ms'] > 0 and row['cpu_ms'] > 0 and row['numpy_ms'] > 0
               for row in sweeps['max_radius'] + sweeps['edge_count'])


def test_classifier_and_pipeline_sections(results: dict) -> None:
    classifier = results['returned']['classifier']
    assert classifier['crops'] == 3
    for key in ('classifier_accuracy', 'ncc_baseline_accuracy'):
        assert 0.0 <= classifier[key] <= 1.0
    assert sum(classifier['count_by_size_px'].values()) == 3
    assert set(classifier['classifier_by_size_px']) == set(classifier['count_by_size_px'])
    pipeline = results['returned']['pipeline']
    assert pipeline['frames'] == 3 and pipeline['fps'] > 0
    assert {'detect', 'classify', 'track', 'total'} <= set(pipeline['stage_p50_ms'])
    assert pipeline['backend'] in {'gl', 'cpu', 'numpy'}
    assert pipeline['backend_choice']  # how the backend was chosen, in words


def test_eval_bag_at_each_camera_size(results: dict) -> None:
    """The installed speed_sign_synth and speed_sign_eval ran on a drive and an approach
    bag of the camera size; the bags are gone afterwards; RESULTS.md has the section."""
    camera_sizes = results['returned']['camera_sizes']
    assert 'error' not in camera_sizes, camera_sizes
    row = camera_sizes['sizes']['320x240']
    drive, approach = row['drive'], row['approach']
    assert drive['frames'] == 30 and drive['fps'] > 0
    assert {'detect', 'classify', 'total'} <= set(drive['stage_ms_p50'])
    assert drive['made_by'] == ('speed_sign_synth drive_320x240 --truth drive_320x240.csv '
                                '--duration 1 --seed 5 --compressed --width 320 --height 240')
    assert drive['command'] == 'speed_sign_eval bag drive_320x240 --truth drive_320x240.csv --json'
    assert approach['made_by'].startswith('speed_sign_synth approach ')
    assert approach['signs'] >= 1 and 0 <= approach['recognized'] <= approach['signs']
    assert approach['wrong_limits'] >= 0
    assert not (results['out'] / 'camera_sizes').exists()
    report = (results['out'] / 'report' / 'RESULTS.md').read_text()
    section = report.split('## speed_sign_eval bag at each camera size')[1].split('\n## ')[0]
    assert '| 320x240 |' in section and drive['made_by'] in section


def test_run_all_without_the_node_stage_needs_no_rclpy() -> None:
    """A machine with the GL stack and no ROS (a lent GPU machine, say) runs
    ``run_all.py --skip-node``: the module and its sibling scripts load with rclpy and
    the message packages made unimportable, and it asks for one BLAS thread, as the
    node does, before numpy loads."""
    pytest.importorskip('radsym', reason='radsym (setup.py extra "bench") not installed')
    pytest.importorskip('matplotlib', reason='matplotlib (setup.py extra "bench") not installed')
    script = (
        'import os, sys\n'
        'for name in ("rclpy", "sensor_msgs", "std_msgs", "diagnostic_msgs"):\n'
        '    sys.modules[name] = None\n'
        'os.environ.pop("OPENBLAS_NUM_THREADS", None)\n'
        'os.environ.pop("MKL_NUM_THREADS", None)\n'
        f'sys.path.insert(0, {str(BENCH_DIR)!r})\n'
        'import run_all\n'
        'print(os.environ["OPENBLAS_NUM_THREADS"], "rclpy" in sys.modules '
        'and sys.modules["rclpy"] is not None)\n')
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ['1', 'False']


def test_classifier_threads_bench_reports_both_timings(tmp_path: Path) -> None:
    """``bench_classifier.py --threads``: two classifiers on two threads classify the
    same frame; the figures come back for both and the throughput ratio is positive
    (no timing threshold: the machine is shared)."""
    figures = bench_module('bench_classifier').bench_threads(
        ClassifierConfig(cache_dir=str(tmp_path), max_radius_px=24.0), frames=1, threads=2)
    assert figures['threads'] == 2
    assert figures['ms_per_frame_alone'] > 0 and figures['ms_per_frame_together'] > 0
    assert figures['throughput_ratio'] > 0


def test_stage_contention_bench_reports_every_figure(tmp_path: Path) -> None:
    """``bench_stage_contention.py``: detection alone and beside a classifying thread and
    a classifying worker process (a real one); every figure comes back positive (no
    timing threshold: the machine is shared)."""
    figures = bench_module('bench_stage_contention').bench_contention(
        ClassifierConfig(cache_dir=str(tmp_path), max_radius_px=24.0), 'auto', seconds=0.05)
    for where in ('alone', 'beside_thread', 'beside_process'):
        assert figures[f'detect_ms_{where}'] > 0
        assert figures[f'classify_ms_{where}'] > 0
