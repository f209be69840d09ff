"""``speed_sign_eval fleet`` on a real local Ray (2 CPUs): synthetic bags in several formats,
a truncated one, a worker process killed in the middle of a bag, an interrupted run that
resumes, and the aggregate against ``eval bag`` run on each bag and summed."""
from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import pytest

ray = pytest.importorskip('ray', reason='Ray is not installed: pip install -e ".[test]"')

from speed_sign_detector.bag_io import BagReader  # noqa: E402
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive  # noqa: E402
from speed_sign_detector.tools import eval as eval_tool  # noqa: E402
from speed_sign_detector.tools import fleet  # noqa: E402
from speed_sign_detector.tools.bag_grading import DRIVE_COUNT_KEYS  # noqa: E402
from speed_sign_detector.tools.fleet_jobs import (  # noqa: E402
    BagJob,
    EvaluationSettings,
    FleetError,
    FleetFolder,
    job_key,
    jobs_from_manifest,
    jobs_from_paths,
)
from speed_sign_detector.tools.synth import write_drive  # noqa: E402
from speed_sign_detector.truth import write_truth  # noqa: E402

#: Two small drives (each with one speed-limit sign), each written in two formats.
DRIVES = {'d2': DriveConfig(seed=2, duration_s=2.0, fps=15, width_px=320, height_px=240),
          'd6': DriveConfig(seed=6, duration_s=2.0, fps=15, width_px=320, height_px=240)}
BAGS = {'d2_mcap_raw': ('d2', 'mcap', False), 'd2_ros1_jpeg': ('d2', 'ros1', True),
        'd6_sqlite3_jpeg': ('d6', 'sqlite3', True), 'd6_ros1_raw': ('d6', 'ros1', False)}
#: A longer drive for the killed-worker runs (60 frames: time to kill mid-bag).
LONG_DRIVE = DriveConfig(seed=1, duration_s=4.0, fps=15, width_px=320, height_px=240)
#: Ray for the whole module: 2 CPUs, a small object store (results are small dicts).
RAY_OBJECT_STORE_BYTES = 80 * 1024 * 1024


@pytest.fixture(scope='module')
def ray_cluster() -> Any:
    """One local Ray for the module's tests, as Ray's own tests do."""
    # address='local': a new instance even where /tmp/ray names one running on this machine
    ray.init(address='local', num_cpus=2, object_store_memory=RAY_OBJECT_STORE_BYTES,
             include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture(scope='module')
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The bags (4 formats), their truth files, a truncated bag, a manifest listing all."""
    folder = tmp_path_factory.mktemp('drives')
    bags: dict[str, Path] = {}
    truths: dict[str, Path] = {}
    for drive_name, config in DRIVES.items():
        frames = list(SyntheticDrive(config))
        for name, (source, bag_format, compressed) in BAGS.items():
            if source != drive_name:
                continue
            path = folder / (f'{name}.bag' if bag_format == 'ros1' else name)
            rows = write_drive(frames, path, bag_format, compressed)
            bags[name] = path
            truths[name] = folder / f'{drive_name}.csv'
            write_truth(truths[name], rows)
    truncated = folder / 'truncated'
    truncated.mkdir()
    source = bags['d2_mcap_raw']
    (truncated / 'metadata.yaml').write_bytes((source / 'metadata.yaml').read_bytes())
    data = (source / 'd2_mcap_raw.mcap').read_bytes()
    (truncated / 'd2_mcap_raw.mcap').write_bytes(data[:len(data) * 3 // 5])
    manifest = folder / 'manifest.csv'
    manifest.write_text('bag,truth\n' + ''.join(
        f'{bags[name].name},{truths[name].name}\n' for name in BAGS)
        + f'truncated,{truths["d2_mcap_raw"].name}\n')
    long_bag = folder / 'long_drive'
    write_truth(folder / 'long_drive.csv', write_drive(SyntheticDrive(LONG_DRIVE), long_bag))
    return {'bags': bags, 'truths': truths, 'manifest': manifest, 'truncated': truncated,
            'long_bag': long_bag, 'long_truth': folder / 'long_drive.csv'}


def run_eval(*args: str) -> tuple[int, str, str]:
    """``speed_sign_eval ARGS`` in this process: (status, stdout, stderr)."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = eval_tool.main(list(args))
    return status, stdout.getvalue(), stderr.getvalue()


def last_json(stdout: str) -> dict[str, Any]:
    return json.loads(stdout.strip().splitlines()[-1])


@pytest.fixture(scope='module')
def single_bag_summaries(drives: dict[str, Any], bank_config: Path) -> dict[str, Any]:
    """``speed_sign_eval bag BAG --truth TRUTH --json`` of every good bag (and the long one)."""
    summaries = {}
    for name, bag in [*drives['bags'].items(), ('long_drive', drives['long_bag'])]:
        truth = drives['truths'].get(name, drives['long_truth'])
        status, stdout, stderr = run_eval('bag', str(bag), '--truth', str(truth), '--json',
                                          '--config', str(bank_config))
        assert status == 0, stderr
        summaries[name] = last_json(stdout)
    return summaries


def settings_of(bank_config: Path) -> EvaluationSettings:
    return EvaluationSettings(load_yaml(bank_config))


def job_of(bag: Path, truth: Path, settings: EvaluationSettings) -> BagJob:
    return BagJob(job_key(bag, truth, settings), bag, truth)


# ------------------------------------------------------------------ without Ray
def test_manifest_rows_resolve_beside_the_manifest(tmp_path: Path) -> None:
    manifest = tmp_path / 'm.csv'
    manifest.write_text('# drives of Monday\nbag,truth\nsub/a.mcap,a.csv\nb.bag,\n'
                        'sub/a.mcap,a.csv\n')
    jobs = jobs_from_manifest(manifest, EvaluationSettings(PipelineConfig()))
    assert [(job.bag, job.truth) for job in jobs] == [
        (tmp_path / 'sub' / 'a.mcap', tmp_path / 'a.csv'), (tmp_path / 'b.bag', None)]
    assert len({job.key for job in jobs}) == 2 and jobs[0].key.startswith('a.mcap-')
    (tmp_path / 'bad.csv').write_text('path,truth\nx.bag,\n')
    with pytest.raises(FleetError, match="no 'bag' column"):
        jobs_from_manifest(tmp_path / 'bad.csv', EvaluationSettings(PipelineConfig()))
    with pytest.raises(FleetError, match='cannot read manifest'):
        jobs_from_manifest(tmp_path / 'absent.csv', EvaluationSettings(PipelineConfig()))


def test_globs_name_bag_directories_and_keys_follow_the_settings(
        drives: dict[str, Any]) -> None:
    settings = EvaluationSettings(PipelineConfig())
    folder = drives['bags']['d2_mcap_raw'].parent
    jobs = jobs_from_paths([str(folder / '*' / 'metadata.yaml'), str(folder / '*.bag')],
                           settings)
    assert {job.bag for job in jobs} == {
        drives['bags']['d2_mcap_raw'], drives['bags']['d6_sqlite3_jpeg'],
        drives['truncated'], drives['long_bag'], drives['bags']['d2_ros1_jpeg'],
        drives['bags']['d6_ros1_raw']}
    with pytest.raises(FleetError, match='no bag matches'):
        jobs_from_paths([str(folder / '*.nothing')], settings)
    bag = drives['bags']['d2_mcap_raw']
    other_cache = EvaluationSettings(load_yaml_text(folder, 'classifier:\n  cache_dir: ""\n'))
    numpy_backend = EvaluationSettings(PipelineConfig(backend='numpy'))
    assert job_key(bag, None, settings) == job_key(bag, None, other_cache)
    assert job_key(bag, None, settings) != job_key(bag, None, numpy_backend)
    assert job_key(bag, None, settings) != job_key(bag, bag.with_suffix('.csv'), settings)


def load_yaml_text(folder: Path, text: str) -> PipelineConfig:
    path = folder / 'other_params.yaml'
    path.write_text(text)
    return load_yaml(path)


def test_fleet_without_bags_is_a_usage_error(tmp_path: Path) -> None:
    status, _, stderr = run_eval('fleet', '--out', str(tmp_path / 'out'))
    assert status == 1 and 'give bags' in stderr


# ------------------------------------------------------------------ on Ray
def test_aggregate_equals_eval_bag_on_each_bag_summed(
        ray_cluster: Any, drives: dict[str, Any], bank_config: Path,
        single_bag_summaries: dict[str, Any], tmp_path: Path) -> None:
    out = tmp_path / 'fleet_out'
    status, stdout, stderr = run_eval('fleet', '--manifest', str(drives['manifest']),
                                      '--out', str(out), '--workers', '2', '--json',
                                      '--config', str(bank_config))
    assert status == 1, stderr   # the truncated bag was not evaluated completely
    report = last_json(stdout)
    assert (report['bags'], report['bags_done'], report['bags_not_run']) == (5, 4, 0)
    [failed] = report['bags_failed']
    assert failed['bag'] == str(drives['truncated']) and 'truncated' in failed['reason']
    assert f'FAILED {drives["truncated"]}' in stderr
    singles = [single_bag_summaries[name] for name in BAGS]
    assert report['frames'] == sum(summary['frames'] for summary in singles)
    assert report['bags_with_truth'] == 4
    for key in DRIVE_COUNT_KEYS:
        assert report[key] == sum(summary[key] for summary in singles), key
    assert report['signs'] >= 2
    assert report['recall'] == pytest.approx(
        sum(summary['recognized'] for summary in singles) / report['signs'])
    assert report['drive_time_s'] == pytest.approx(
        sum(summary['drive_time_s'] for summary in singles))
    assert report['fps'] > 0 and sum(worker['bags'] for worker in report['workers']) == 5
    # Per bag: the JSON line has eval bag's fields and values; the results bag its frames.
    folder = FleetFolder(out)
    jobs = {job.bag: job for job in jobs_from_manifest(drives['manifest'],
                                                        settings_of(bank_config))}
    for name, bag in drives['bags'].items():
        line = folder.summary_path(jobs[bag].key).read_text()
        assert line.count('\n') == 1
        summary, single = json.loads(line), single_bag_summaries[name]
        assert summary.keys() == single.keys()
        for field in ('frames', 'topic', 'msgtype', 'limit_events', 'final_limit_kmh',
                      'per_sign', 'recall', 'truncated', 'error', *DRIVE_COUNT_KEYS):
            assert summary[field] == single[field], (name, field)
        assert summary['out_bag'] == str(folder.results_path(jobs[bag].key))
        with BagReader(summary['out_bag']) as results:
            assert len(list(results.messages('/candidates'))) == summary['frames']
    truncated = json.loads(folder.summary_path(jobs[drives['truncated']].key).read_text())
    assert 0 < truncated['frames'] < single_bag_summaries['d2_mcap_raw']['frames']
    assert json.loads((out / 'fleet.json').read_text()) == report
    picture = cv2.imread(str(out / 'fleet.png'))
    assert picture is not None and picture.shape[0] > 300
    assert not list(folder.partial_dir.iterdir())


def kill_mid_bag(killed: list[int]) -> fleet.ProgressHook:
    """A progress hook that kills the worker process once, in the middle of its bag."""
    def on_progress(job: Any, progress: Any, actor: Any) -> None:
        if not killed and progress.frames_total and \
                0 < progress.frames_done < progress.frames_total:
            pid = ray.get(actor.get_pid.remote())
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
    return on_progress


def test_killed_worker_is_restarted_and_its_bag_retried(
        ray_cluster: Any, drives: dict[str, Any], bank_config: Path,
        single_bag_summaries: dict[str, Any], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fleet, 'PROGRESS_POLL_S', 0.1)
    settings = settings_of(bank_config)
    jobs = [job_of(drives['long_bag'], drives['long_truth'], settings)]
    killed: list[int] = []
    report = fleet.run_fleet(jobs, settings, FleetFolder(tmp_path / 'out'),
                             fleet.FleetOptions(workers=1, retries=1, progress=False),
                             on_progress=kill_mid_bag(killed))
    assert killed, 'the bag finished before a progress poll saw it under way'
    assert report.all_done, report.bags_failed
    [outcome] = report.outcomes
    assert int(outcome.worker.rsplit(':', 1)[1]) != killed[0]   # a new worker process
    single = single_bag_summaries['long_drive']
    for field in ('frames', 'limit_events', 'per_sign', *DRIVE_COUNT_KEYS):
        assert outcome.summary[field] == single[field], field


def test_worker_without_restarts_left_fails_its_bag_and_the_run_goes_on(
        ray_cluster: Any, drives: dict[str, Any], bank_config: Path, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fleet, 'PROGRESS_POLL_S', 0.1)
    settings = settings_of(bank_config)
    jobs = jobs_from_paths([str(drives['long_bag']), str(drives['bags']['d2_mcap_raw'])],
                           settings)
    killed: list[int] = []
    report = fleet.run_fleet(jobs, settings, FleetFolder(tmp_path / 'out'),
                             fleet.FleetOptions(workers=1, retries=0, progress=False),
                             on_progress=kill_mid_bag(killed))
    assert killed and not report.all_done and not report.interrupted
    [failed] = report.bags_failed
    assert failed['bag'] == str(drives['long_bag'])
    assert 'worker process died' in failed['reason'] and '--retries 0' in failed['reason']
    assert report.bags_done == 1 and report.outcomes[1].done   # a fresh worker took it
    assert not FleetFolder(tmp_path / 'out').summary_path(jobs[0].key).exists()


def _default_interrupt_handling() -> None:
    """In the child before it starts: SIGINT as a terminal's Ctrl-C finds it. A test run
    started in the background of a shell without job control inherits SIGINT ignored,
    and Python then leaves it ignored (as every program should in a background job)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def test_interrupted_run_resumes_where_it_stopped(
        ray_cluster: Any, drives: dict[str, Any], bank_config: Path, tmp_path: Path) -> None:
    """Ctrl-C to a real ``speed_sign_eval fleet`` process that joined this module's Ray
    with --address; the same command again skips the bags it had done."""
    out = tmp_path / 'out'
    # the long drive in the middle: Ctrl-C lands while it runs, not after the last bag
    bags = [str(drives['bags']['d2_mcap_raw']), str(drives['long_bag']),
            str(drives['bags']['d6_ros1_raw'])]
    arguments = ['fleet', *bags, '--out', str(out), '--workers', '1', '--json',
                 '--config', str(bank_config)]
    executable = Path(sys.executable).parent / 'speed_sign_eval'
    address = ray.get_runtime_context().gcs_address
    summaries = out / 'summaries'
    with open(tmp_path / 'stdout', 'w') as stdout, open(tmp_path / 'stderr', 'w') as stderr:
        process = subprocess.Popen([str(executable), *arguments, '--address', address],
                                   stdout=stdout, stderr=stderr,
                                   preexec_fn=_default_interrupt_handling)
        try:
            deadline = time.monotonic() + 300   # a guard against hanging, not a threshold
            while not (summaries.is_dir() and any(summaries.iterdir())):
                assert process.poll() is None, (tmp_path / 'stderr').read_text()
                assert time.monotonic() < deadline, 'no bag finished'
                time.sleep(0.05)
            process.send_signal(signal.SIGINT)
            status = process.wait(timeout=120)
        finally:
            if process.poll() is None:
                process.kill()
    assert status == 130, (tmp_path / 'stderr').read_text() + (tmp_path / 'stdout').read_text()
    first = last_json((tmp_path / 'stdout').read_text())
    assert first['interrupted'] is True and first['bags'] == 3
    assert 1 <= first['bags_done'] < 3 and first['bags_done'] + first['bags_not_run'] == 3
    done_before = {path.name: path.stat().st_mtime_ns for path in summaries.iterdir()}
    assert len(done_before) >= first['bags_done']

    status, stdout, stderr = run_eval(*arguments)   # uses this module's Ray
    assert status == 0, stderr
    second = last_json(stdout)
    # A bag may have finished between Ctrl-C and the workers' end: done all the same.
    assert second['bags_done'] == 3 and second['bags_resumed'] == len(done_before)
    assert second['bags_resumed'] >= first['bags_done']
    assert second['bags_failed'] == [] and not second['interrupted']
    for name, mtime_ns in done_before.items():   # not evaluated again
        assert (summaries / name).stat().st_mtime_ns == mtime_ns
    assert len(list(summaries.iterdir())) == 3



def test_fleet_benchmark_projection_is_marked_and_follows_its_rule() -> None:
    """bench/bench_fleet.py's projection and table (its runs are run_fleet, tested above)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
    try:
        import bench_fleet
    finally:
        sys.path.pop(0)
    runs = [{'workers': 1, 'bags': 6, 'frames': 540, 'wall_s': 90.0, 'fps': 6.0,
             'bags_per_hour': 240.0, 'worker_fps': [6.0], 'worker_setup_s': [0.5],
             'scaling': 1.0},
            {'workers': 2, 'bags': 6, 'frames': 540, 'wall_s': 50.0, 'fps': 10.8,
             'bags_per_hour': 432.0, 'worker_fps': [5.0, 6.0], 'worker_setup_s': [0.4, 0.6],
             'scaling': 1.8}]
    projection = bench_fleet.project(runs[1], frames_per_bag=90.0, bags=6, machines=4)
    assert projection['projected_not_measured'] is True and projection['workers'] == 8
    assert projection['fps'] == pytest.approx(4 * 10.8)
    assert projection['bags_per_hour'] == pytest.approx(4 * 10.8 * 3600 / 90)
    # 6 bags on 8 workers: one round of a 90-frame bag at the median 5.5 fps, after start-up
    assert projection['wall_s_for_bench_bags'] == pytest.approx(0.5 + 90 / 5.5)
    table = bench_fleet.format_table({'runs': runs, 'ray_start_s': 10.0,
                                      'frames_per_bag': 90.0, 'projection': projection})
    assert 'PROJECTED, not measured' in table and '1.80' in table


class _ReadInterruptedRay:
    """A stand-in for Ray in the driver's loop: one worker, its bag finishes at once, and
    Ctrl-C comes as the driver reads that bag's result (``get`` raises
    KeyboardInterrupt once); after it the result reads as it would."""

    exceptions = ray.exceptions

    def __init__(self, outcome: Any) -> None:
        self.outcome = outcome
        self.interrupted = False

    def wait(self, refs: list[Any], num_returns: int = 1, timeout: float | None = None
             ) -> tuple[list[Any], list[Any]]:
        finished = [ref for ref in refs if ref[0] == 'evaluate']
        return finished[:num_returns], []

    def get(self, ref: Any) -> Any:
        if ref[0] == 'evaluate' and not self.interrupted:
            self.interrupted = True
            raise KeyboardInterrupt
        return self.outcome

    def kill(self, actor: Any) -> None:
        pass


def test_a_bag_finishing_as_ctrl_c_comes_is_kept(tmp_path: Path, monkeypatch) -> None:
    """Ctrl-C while the driver reads a finished bag's result (its summary written: what
    the resume test waits for) still counts that bag: its call stays among the running
    ones until its outcome is kept, and the collection after Ctrl-C reads it."""
    job = BagJob('bag_key', tmp_path / 'bag', None)
    outcome = fleet.BagOutcome('bag_key', str(job.bag), True, None, None, 'host:1', 0.0, 1.0)
    stand_in = _ReadInterruptedRay(outcome)

    class Actor:
        class evaluate:   # noqa: N801 - the shape of a Ray actor method
            @staticmethod
            def remote(job: BagJob) -> tuple[str, str]:
                return ('evaluate', job.key)

        class progress:   # noqa: N801
            @staticmethod
            def remote() -> tuple[str]:
                return ('progress',)

    class Bar:
        n = 0

        def update(self, count: int) -> None:
            pass

        def write(self, text: str, file: Any = None) -> None:
            pass

        def refresh(self) -> None:
            pass

    dispatcher = object.__new__(fleet._Dispatcher)
    dispatcher.ray, dispatcher.actors, dispatcher.on_progress = stand_in, [], None
    dispatcher.bags_bar, dispatcher.frames_bar = Bar(), Bar()
    dispatcher.frames_finished, dispatcher.frames_under_way = 0, {}
    monkeypatch.setattr(dispatcher, '_worker_count', lambda bags: 1, raising=False)
    monkeypatch.setattr(dispatcher, '_gpus_per_worker', lambda workers: 0.0, raising=False)
    monkeypatch.setattr(dispatcher, '_new_actor', lambda gpus: Actor(), raising=False)
    outcomes: dict[str, Any] = {}
    assert dispatcher.run([job], outcomes) is True   # interrupted
    assert stand_in.interrupted and outcomes == {'bag_key': outcome}
