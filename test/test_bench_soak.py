"""The soak benchmark (bench/bench_soak.py), run for real but briefly.

The script makes a 3 s synthetic drive (320x240 JPEG) with the installed
``speed_sign_synth``, starts the installed node as its own process and feeds it the drive
in a loop at 30 Hz for 24 s, so that the stamps jump back several times. The JSON it
prints last and the RSS time series it writes are checked: loops done and the node's
tracks reset at each jump, the node the same process at the end, every published frame
answered or counted, no error logged, memory sampled. No timing figure is asserted.
"""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from ros_spin import module_domain

PROJECT_ROOT = Path(__file__).resolve().parents[1]
BENCH_SOAK = PROJECT_ROOT / 'bench' / 'bench_soak.py'
DOMAIN_ID = module_domain('test_bench_soak')
SOAK_MINUTES = 0.4
RSS_INTERVAL_S = 2.0
#: Longest the whole script may take (drive, node start-up, soak, shutdown), seconds.
SCRIPT_TIMEOUT_S = 600

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture(scope='module')
def soak(pytestconfig: pytest.Config, tmp_path_factory: pytest.TempPathFactory
         ) -> dict[str, Any]:
    """One short soak: its JSON summary, its output folder and its stderr."""
    out = tmp_path_factory.mktemp('soak')
    command = [sys.executable, str(BENCH_SOAK), '--minutes', f'{SOAK_MINUTES:g}',
               '--width', '320', '--height', '240', '--loop-seconds', '3', '--seed', '2',
               '--rss-interval', f'{RSS_INTERVAL_S:g}', '--progress-interval', '10',
               '--rss-csv', str(out / 'rss.csv'), '--node-log', str(out / 'node.log'),
               '--domain-id', str(DOMAIN_ID),
               '--bank-cache', str(pytestconfig.cache.mkdir('speed_sign_filter_banks')),
               '--json']
    completed = subprocess.run(command, capture_output=True, text=True,
                               timeout=SCRIPT_TIMEOUT_S, cwd=PROJECT_ROOT)
    assert completed.returncode == 0, completed.stderr[-4000:]
    summary = json.loads(completed.stdout.strip().splitlines()[-1])
    return {'summary': summary, 'out': out, 'stderr': completed.stderr}


def test_the_stamps_jump_back_at_each_loop_without_a_restart(soak: dict[str, Any]) -> None:
    summary = soak['summary']
    assert summary['drive']['frames_per_loop'] == 90
    assert (summary['width'], summary['height']) == (320, 240)
    assert summary['loops'] >= 2
    assert summary['stamp_jumps_published'] == summary['loops'] - 1
    # the node logs each jump once, on the first frame it processes after it
    assert summary['stamp_jumps_logged_by_node'] == summary['stamp_jumps_published']
    logged = (soak['out'] / 'node.log').read_text().count('image stamps jumped back')
    assert logged == summary['stamp_jumps_published']
    node = summary['node']
    assert node['same_process_at_end'] is True
    assert node['counter_resets'] == 0
    assert node['exit_code_after_sigint'] == 0
    assert summary['meets_restart_target'] is True


def test_every_published_frame_is_answered_or_counted(soak: dict[str, Any]) -> None:
    frames = soak['summary']['frames']
    assert frames['published'] > soak['summary']['drive']['frames_per_loop']
    assert frames['answered'] > 0
    # each processed frame answered once, by its own stamp in its own loop
    assert frames['answered'] == frames['node_processed']
    assert frames['duplicate_answers'] == 0 and frames['unmatched_answers'] == 0
    # what the node received is what it processed or dropped; the rest was lost on the way
    assert frames['node_received'] == frames['node_processed'] + frames['node_dropped']
    assert frames['lost_in_transport'] == frames['published'] - frames['node_received']
    assert frames['unaccounted'] == 0
    assert frames['node_dropped'] == (frames['node_dropped_stale']
                                      + frames['node_rejected_bad_input'])


def test_no_error_logged_or_reported(soak: dict[str, Any]) -> None:
    errors = soak['summary']['errors']
    assert errors['log_error_lines'] == 0, errors['first_errors']
    assert errors['log_tracebacks'] == 0, errors['first_errors']
    assert errors['diagnostics_error_statuses'] == 0, errors['first_error_statuses']
    assert soak['summary']['meets_error_target'] is True


def test_rss_is_sampled_and_summarized(soak: dict[str, Any]) -> None:
    summary = soak['summary']
    with (soak['out'] / 'rss.csv').open(newline='') as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == summary['rss_mib']['samples']
    assert len(rows) >= SOAK_MINUTES * 60 / RSS_INTERVAL_S
    elapsed = [float(row['elapsed_s']) for row in rows]
    assert elapsed == sorted(elapsed) and elapsed[0] == 0.0
    assert all(float(row['rss_mib']) > 50 for row in rows)   # a node with GL and banks
    published = [int(row['published']) for row in rows]
    assert published == sorted(published) and published[-1] > 0
    rss = summary['rss_mib']
    assert rss['end'] == pytest.approx(float(rows[-1]['rss_mib']), abs=0.01)
    assert rss['growth_percent'] == pytest.approx(
        100 * (rss['end'] / rss['at_reference'] - 1), abs=0.02)
    assert summary['meets_rss_target'] == (rss['growth_percent'] <= 5.0)


def test_host_and_progress_are_reported(soak: dict[str, Any]) -> None:
    summary = soak['summary']
    assert summary['renderer'] and summary['renderer'] in summary['host']
    assert summary['machine']['cpus'] >= 1
    assert summary['machine']['cpu_model'] in summary['host']
    assert summary['backend'] in ('gl', 'cpu', 'numpy')
    assert ' min: published ' in soak['stderr']   # the progress lines
