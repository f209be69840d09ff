"""bench/RESULTS.md as ``make bench`` writes it: bench/results_markdown.py on a small fake run.

The fake results dict has the shape of ``run_all.run_benchmark``'s (two detector sizes, the
classifier, the pipeline, the node at two rates); the tests check that the summary comes
first and names the host, that every benchmark has its table holding the run's figures,
and that a smoke run and a failed stage say so. ``report.py --results-md`` renders the same
text from a saved results.json.
"""
from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from test_bench_smoke import bench_module

@pytest.fixture(scope='module')
def markdown() -> ModuleType:
    return bench_module('results_markdown')


def _method(median_ms: float, recall: float | None) -> dict[str, Any]:
    return {'median_ms': median_ms, 'p90_ms': median_ms * 1.2, 'best_ms': median_ms * 0.9,
            'recall': recall,
            'recall_by_radius_px': None if recall is None else {'4-8': recall - 0.1,
                                                                '8-16': recall}}


def fake_results() -> dict[str, Any]:
    """A run's results with figures unlike each other, so that each can be found."""
    methods_640 = {'gl': _method(20.25, 0.989), 'gl_raster': _method(29.5, 0.987),
                   'cpu': _method(12.75, 0.984), 'numpy': _method(85.5, 0.988), 'hough_gradient': _method(2.75, 0.193),
                   'hough_gradient_alt': _method(9.25, 0.331),
                   'radsym_rsd': _method(40.5, 0.612), 'radsym_frst': _method(55.75, 0.871)}
    methods_816 = {name: _method(item['median_ms'] * 1.3 + 0.1, item['recall'])
                   for name, item in methods_640.items()}
    methods_1080 = {name: _method(item['median_ms'] * 6.1, None)
                    for name, item in methods_640.items()}
    return {
        'date_utc': '2000-01-01T00:00:00+00:00', 'command': ['python', 'bench/run_all.py',
                                                             '--out', 'out/bench'],
        'quick': False, 'elapsed_s': 1234.0,
        'machine': {'cpus': 12, 'cpu_model': 'Example CPU 9000 @ 3.1GHz',
                    'platform': 'Linux-6.0-x86_64', 'processor': 'x86_64', 'python': '3.11.9',
                    'opencv': '4.10.0', 'load_average_at_start': [0.5, 0.4, 0.3]},
        'paper_figures_quoted_not_measured': {
            'paper_a': {'source': 'Paper A (IVS 2011)', 'fps': 33.0, 'frame_size': '640x480',
                        'detection_rate': 0.88, 'hardware': 'GPU A', 'note': 'per sign'}},
        'detector': {
            'renderer': 'Example GL Renderer 7', 'software_renderer': False,
            'gl_vote_method': 'scatter', 'frames_available': 214, 'top_n': 7,
            'sizes': {
                '640x480': {'width': 640, 'height': 480, 'how': 'crop', 'frames': 60,
                            'signs': 75, 'signs_by_radius_px': None, 'methods': methods_640,
                            'gl_floor_ms': 1.25, 'auto_pick': 'gl'},
                '816x480': {'width': 816, 'height': 480, 'how': 'native', 'frames': 60,
                            'signs': 80, 'signs_by_radius_px': {'4-8': 30, '8-16': 50},
                            'methods': methods_816, 'gl_floor_ms': 1.5, 'auto_pick': 'gl'},
                '1920x1080': {'width': 1920, 'height': 1080, 'how': 'resize', 'frames': 2,
                              'signs': None, 'signs_by_radius_px': None,
                              'methods': methods_1080, 'gl_floor_ms': None,
                              'auto_pick': 'gl'}},
            'sweeps': {'size': '816x480', 'frames': 6,
                       'max_radius': [{'max_radius_px': 20.0, 'gl_ms': 11.5, 'cpu_ms': 7.5,
                                       'numpy_ms': 61.5},
                                      {'max_radius_px': 80.0, 'gl_ms': 31.5, 'cpu_ms': 17.25,
                                       'numpy_ms': 161.5}],
                       'edge_count': [{'gradient_threshold': 40.0, 'edges': 12345.0,
                                       'gl_ms': 21.5, 'cpu_ms': 9.75, 'numpy_ms': 91.5}]}},
        'classifier': {'crops': 4400, 'crop_every': 1, 'classifier_accuracy': 0.9713,
                       'classifier_ms_per_crop': 4.56, 'ncc_baseline_accuracy': 0.5821,
                       'ncc_baseline_ms_per_crop': 7.89,
                       'count_by_size_px': {'<20': 462, '20-40': 3938},
                       'classifier_by_size_px': {'<20': 0.912, '20-40': 0.978},
                       'ncc_baseline_by_size_px': {'<20': 0.401, '20-40': 0.603},
                       'ms_per_frame_7_candidates': 17.6, 'ms_per_candidate': 17.6 / 7,
                       'rendered_bank': {'ms_per_frame_7_candidates': 13.9,
                                         'ms_per_candidate': 13.9 / 7},
                       'speed_frames': 10, 'bank_mb': 3.4, 'bank_load_or_build_s': 0.7,
                       'crops_seen_in_training': True},
        'pipeline': {'frames': 90, 'width': 640, 'height': 480, 'backend': 'gl',
                     'backend_choice': 'auto: gl on a hardware renderer (Example GL Renderer 7)',
                     'renderer': 'Example GL Renderer 7', 'fps': 26.4, 'overlapped_fps': 33.2,
                     'latency_p50_ms': 37.5, 'latency_p95_ms': 48.5,
                     'stage_p50_ms': {'detect': 20.5, 'classify': 16.5, 'total': 37.5}},
        'node': {'width': 640, 'height': 480, 'backend': 'gl',
                 'backend_choice': 'asked for gl (Example GL Renderer 7)',
                 'renderer': 'Example GL Renderer 7',
                 'rates': [{'publish_hz': 10.0, 'seconds': 8.0, 'published': 80,
                            'answered': 80, 'dropped': 0, 'output_fps': 10.0,
                            'latency_p50_ms': 46.5, 'latency_p95_ms': 70.5, 'rss_mb': 222.0},
                           {'publish_hz': 30.0, 'seconds': 8.0, 'published': 241,
                            'answered': 233, 'dropped': 8, 'output_fps': 29.1,
                            'latency_p50_ms': 55.5, 'latency_p95_ms': 90.5,
                            'rss_mb': 231.0}]},
    }


def sections(text: str) -> dict[str, str]:
    """The text under each '## ' heading, by heading (in order)."""
    parts = re.split(r'^## (.+)$', text, flags=re.MULTILINE)
    return {parts[index].strip(): parts[index + 1] for index in range(1, len(parts), 2)}


def table_rows(text: str) -> list[list[str]]:
    """The cells of every Markdown table row in ``text`` (rule rows left out)."""
    rows = []
    for line in text.splitlines():
        if line.startswith('|') and not re.fullmatch(r'\|[-:|]+\|', line):
            rows.append([cell.strip() for cell in line.strip('|').split('|')])
    return rows


def first_table(text: str) -> list[list[str]]:
    """The rows of the first Markdown table in ``text`` (before any '### ' subsection)."""
    return table_rows(text.split('\n### ')[0])


def row_starting(rows: list[list[str]], first_cell: str) -> list[str]:
    matches = [row for row in rows if row[0] == first_cell]
    assert len(matches) == 1, (first_cell, rows)
    return matches[0]


def test_summary_is_first_and_names_the_host(markdown: ModuleType) -> None:
    results = fake_results()
    text = markdown.render_results_markdown(results)
    headings = list(sections(text))
    assert headings[0] == 'Summary', headings
    summary = sections(text)['Summary']
    machine = results['machine']
    host = next(line for line in summary.splitlines() if line.startswith('Host:'))
    assert machine['cpu_model'] in host
    assert f"{machine['cpus']} cores" in host
    assert results['detector']['renderer'] in host
    assert 'BLAS' not in host  # a record without BLAS libraries names none
    assert 'Smoke run' not in text
    results['machine']['blas'] = [{'internal_api': 'openblas', 'prefix': 'libscipy_openblas',
                                   'version': '0.3.31', 'architecture': 'Haswell',
                                   'num_threads': 1}]
    summary = sections(markdown.render_results_markdown(results))['Summary']
    host = next(line for line in summary.splitlines() if line.startswith('Host:'))
    assert host.endswith('; BLAS libscipy_openblas 0.3.31 Haswell kernel.'), host


def test_summary_sets_ours_against_the_peers(markdown: ModuleType) -> None:
    results = fake_results()
    rows = table_rows(sections(markdown.render_results_markdown(results))['Summary'])
    detector_rows = [row for row in rows if row[0].startswith('detector')]
    # one row per size with recall (640x480 and 816x480; 1920x1080 is time only)
    assert len(detector_rows) == 2
    methods = results['detector']['sizes']['640x480']['methods']
    ours, peers = detector_rows[0][1], detector_rows[0][2]
    # a hardware renderer: auto keeps GL, named first; the CPU path beside it
    assert ours.startswith('GL, what `backend: auto` runs here'), ours
    assert f"{methods['gl']['recall']:.3f}" in ours and f"{methods['gl']['median_ms']:.1f}" in ours
    assert f"CPU: recall {methods['cpu']['recall']:.3f}, {methods['cpu']['median_ms']:.1f} ms" \
        in ours
    peer_names = [name for name in methods if not markdown.is_ours(name)]
    assert 'cpu' not in peer_names and 'hough_gradient' in peer_names
    fastest = min(peer_names, key=lambda name: methods[name]['median_ms'])
    best = max(peer_names, key=lambda name: methods[name]['recall'])
    assert markdown.METHOD_LABELS[fastest] in peers and markdown.METHOD_LABELS[best] in peers
    classifier = results['classifier']
    classifier_row = next(row for row in rows if row[0].startswith('classifier'))
    assert f"{classifier['classifier_accuracy']:.3f}" in classifier_row[1]
    assert f"{classifier['ncc_baseline_accuracy']:.3f}" in classifier_row[2]
    node_rows = [row for row in rows if row[0].startswith('node')]
    assert len(node_rows) == len(results['node']['rates'])


def test_summary_names_the_cpu_path_when_auto_keeps_it(markdown: ModuleType) -> None:
    """On a software renderer auto keeps the faster of GL and CPU: the summary names it
    first, and says why; the detector section names auto's pick at each size."""
    results = copy.deepcopy(fake_results())
    detector = results['detector']
    detector['renderer'], detector['software_renderer'] = 'llvmpipe (LLVM 17.0.6)', True
    for size in detector['sizes'].values():
        size['auto_pick'] = 'cpu'
    parts = sections(markdown.render_results_markdown(results))
    ours = [row[1] for row in table_rows(parts['Summary']) if row[0].startswith('detector')]
    methods = detector['sizes']['640x480']['methods']
    assert ours[0].startswith('CPU, what `backend: auto` runs here (the faster of GL and CPU '
                              'on this software renderer): recall '
                              f"{methods['cpu']['recall']:.3f}, "
                              f"{methods['cpu']['median_ms']:.1f} ms; GL: recall"), ours[0]
    assert 'keeps the faster: CPU at 640x480, CPU at 816x480, CPU at 1920x1080' \
        in parts['Detector']


def test_a_run_without_the_cpu_row_keeps_gl_in_the_summary(markdown: ModuleType) -> None:
    """A results.json from before the CPU path (no ``cpu`` method, sweep column, auto_pick
    or backend_choice) still renders: GL is ours, the sweeps have GL and numpy only."""
    results = copy.deepcopy(fake_results())
    for size in results['detector']['sizes'].values():
        del size['methods']['cpu'], size['auto_pick']
    for row in results['detector']['sweeps']['max_radius'] + \
            results['detector']['sweeps']['edge_count']:
        del row['cpu_ms']
    del results['pipeline']['backend_choice'], results['node']['backend_choice']
    parts = sections(markdown.render_results_markdown(results))
    methods = results['detector']['sizes']['640x480']['methods']
    ours = next(row[1] for row in table_rows(parts['Summary']) if row[0].startswith('detector'))
    assert ours == f"recall {methods['gl']['recall']:.3f}, {methods['gl']['median_ms']:.1f} ms"
    assert ['max_radius_px', 'GL ms', 'numpy ms'] in table_rows(parts['Detector'])
    assert 'detector backend gl.' in parts['Pipeline']


def test_each_benchmark_has_its_table(markdown: ModuleType) -> None:
    results = fake_results()
    parts = sections(markdown.render_results_markdown(results))
    for heading in ('Detector', 'Classifier', 'Pipeline', 'Node through DDS',
                    'The papers (quoted, not measured here)'):
        assert table_rows(parts[heading]), heading
    detector_rows = first_table(parts['Detector'])
    sizes = results['detector']['sizes']
    for method in sizes['640x480']['methods']:
        row = row_starting(detector_rows, markdown.METHOD_LABELS[method])
        # per size: ms, then recall where measured (640 ms, 640 recall, 816 ms, 816 recall,
        # 1080 ms)
        expected = []
        for size in sizes.values():
            expected.append(f"{size['methods'][method]['median_ms']:.1f}")
            if size['signs'] is not None:
                expected.append(f"{size['methods'][method]['recall']:.3f}")
        assert row[1:] == expected, (method, row)
    classifier_rows = table_rows(parts['Classifier'])
    assert any(f"{results['classifier']['classifier_ms_per_crop']:.2f}" in row
               for row in classifier_rows)
    for width, count in results['classifier']['count_by_size_px'].items():
        assert row_starting(classifier_rows, width)[1] == str(count)
    sweep_rows = table_rows(parts['Detector'].split('### Time against')[1])
    assert row_starting(sweep_rows, '20') == ['20', '11.5', '7.5', '61.5']  # GL, CPU, numpy
    assert results['pipeline']['backend_choice'] in parts['Pipeline']
    assert results['node']['backend_choice'] in parts['Node through DDS']
    pipeline_rows = table_rows(parts['Pipeline'])
    assert f"{results['pipeline']['overlapped_fps']:.1f}" in {row[-1] for row in pipeline_rows}
    node_rows = table_rows(parts['Node through DDS'])
    for rate in results['node']['rates']:
        row = row_starting(node_rows, f"{rate['publish_hz']:g}")
        assert row[2] == f"{rate['output_fps']:.1f}"
        assert row[3] == f"{rate['dropped']} of {rate['published']}"


def test_a_smoke_run_and_a_failed_stage_say_so(markdown: ModuleType) -> None:
    results = copy.deepcopy(fake_results())
    results['quick'] = True
    results['node'] = {'error': 'SpeedSignError: the node did not start'}
    results['classifier'] = {'skipped': 'no crops'}
    text = markdown.render_results_markdown(results)
    assert markdown.SMOKE_NOTE in text
    assert text.index(markdown.SMOKE_NOTE) < text.index('## Summary')
    parts = sections(text)
    assert 'the node did not start' in parts['Node through DDS']
    assert not table_rows(parts['Node through DDS'])
    assert 'not run: no crops' in parts['Classifier'].lower()
    assert table_rows(parts['Detector'])  # the stages that ran keep their tables


def test_the_hd_node_stage_gets_its_own_section_and_summary_row(
        markdown: ModuleType) -> None:
    """The node fed 1280x720 frames is reported beside the 640x480 one; a run saved
    before that stage existed renders as before."""
    results = copy.deepcopy(fake_results())
    results['node_hd'] = copy.deepcopy(results['node'])
    results['node_hd'].update(width=1280, height=720)
    results['node_hd']['rates'] = [dict(results['node']['rates'][-1], output_fps=28.6,
                                        dropped=14, published=240)]
    text = markdown.render_results_markdown(results)
    parts = sections(text)
    hd_rows = table_rows(parts[markdown.HD_NODE_TITLE])
    assert hd_rows[-1][2:4] == ['28.6', '14 of 240']
    summary = [row for row in table_rows(parts['Summary']) if row[0].startswith('node')]
    assert any(row[0].startswith('node through DDS, 1280x720') and
               row[1].startswith('28.6 fps, 14 of 240 unanswered') for row in summary)
    results['node_hd'] = {'error': 'SpeedSignError: the node did not start'}
    assert 'the node did not start' in sections(
        markdown.render_results_markdown(results))[markdown.HD_NODE_TITLE]
    del results['node_hd']
    assert markdown.HD_NODE_TITLE not in markdown.render_results_markdown(results)


def _camera_size_row(width: int, height: int, fps: float, recognized: int) -> dict[str, Any]:
    name = f'{width}x{height}'
    return {'width': width, 'height': height,
            'drive': {'frames': 120, 'fps': fps, 'latency_ms_p50': 1000.0 / fps + 0.25,
                      'latency_ms_p95': 2000.0 / fps, 'backend_choice': 'auto: cpu',
                      'stage_ms_p50': {'detect': 300.0 / fps, 'classify': 7.75},
                      'recall': 1.0, 'wrong_limits': 0, 'signs': 3, 'recognized': 3,
                      'made_by': f'speed_sign_synth drive_{name} --width {width}',
                      'command': f'speed_sign_eval bag drive_{name} --json'},
            'approach': {'signs': 51, 'recognized': recognized, 'recall': recognized / 51,
                         'wrong_limits': 0, 'made_by': f'speed_sign_synth approach {name}',
                         'command': f'speed_sign_eval bag approach_{name} --json'}}


def test_eval_bag_at_each_camera_size_has_its_section_and_summary_row(
        markdown: ModuleType) -> None:
    """fps per camera size against issue 33's targets, the approach signs recognized, the
    commands; a failed stage says so; a run saved before the stage renders as before."""
    results = copy.deepcopy(fake_results())
    results['camera_sizes'] = {
        'sizes': {'640x480': _camera_size_row(640, 480, 52.5, 40),
                  '1920x1080': _camera_size_row(1920, 1080, 23.5, 43)},
        'drive_fps_targets': {'640x480': 50.0, '1920x1080': 25.0},
        'drive_seconds': 4.0, 'drive_seed': 5, 'approach_sequences': 40}
    parts = sections(markdown.render_results_markdown(results))
    section = parts[markdown.CAMERA_SIZES_TITLE]
    rows = table_rows(section)
    assert rows[1][:2] == ['640x480', '52.5 (target 50: met)']
    assert rows[2][:2] == ['1920x1080', '23.5 (target 25: NOT met)']
    assert rows[2][4:] == ['12.8', '7.8', '1.000, 0 wrong', '43 of 51 (0.843), 0 wrong']
    assert '`speed_sign_synth drive_1920x1080 --width 1920` + ' \
           '`speed_sign_eval bag drive_1920x1080 --json`' in section
    summary = [row for row in table_rows(parts['Summary']) if row[0].startswith('speed_sign')]
    assert summary == [['speed_sign_eval bag at 640x480 / 1920x1080: fps on a synthetic drive; '
                        'approach sequences (real pixels) recognized',
                        '52.5 / 23.5 fps; recognized 40 / 43; 0 wrong limits in all', '-']]
    results['camera_sizes'] = {'error': 'CameraSizeBenchError: speed_sign_eval exited with 1'}
    assert 'exited with 1' in sections(
        markdown.render_results_markdown(results))[markdown.CAMERA_SIZES_TITLE]
    del results['camera_sizes']
    assert markdown.CAMERA_SIZES_TITLE not in markdown.render_results_markdown(results)


def test_no_run_date_in_the_report(markdown: ModuleType) -> None:
    """The report holds one run's figures, not when it ran (results.json keeps that)."""
    results = fake_results()
    text = markdown.render_results_markdown(results)
    assert results['date_utc'][:10] not in text


def test_report_script_renders_it_from_a_saved_run(tmp_path: Path,
                                                   markdown: ModuleType) -> None:
    pytest.importorskip('matplotlib', reason='matplotlib (setup.py extra "bench") not installed')
    report = bench_module('report')
    results = fake_results()
    saved = tmp_path / 'results.json'
    saved.write_text(json.dumps(results))
    written = tmp_path / 'docs' / 'RESULTS.md'
    assert report.main([str(saved), '--out', str(tmp_path / 'plots'),
                        '--results-md', str(written)]) == 0
    assert written.read_text() == markdown.render_results_markdown(results)
