"""bench/RESULTS.md rendered from the ``results.json`` of one ``run_all.py`` run.

``make bench`` writes it (``run_all.py --results-md bench/RESULTS.md``); ``report.py
results.json --results-md PATH`` renders it again from a saved run. The file is generated,
never edited by hand: a summary first (the host, then today's accuracy and speed of each
stage against the peers), then one table per benchmark. It holds the figures of that one
run only; older runs live in git's history. The long runs ``make bench`` is given as JSON
files (``make validate``, ``make soak``: recognition per value, leave one value out,
rendered designs, soak) follow, each with its own command and host
(``long_runs_markdown.py``).
"""
from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from long_runs_markdown import long_run_lines, summary_rows
from markdown_tables import number as _number
from markdown_tables import table as _table

from speed_sign_detector.training.training_host import describe_blas

#: The heading of the node stage fed 1280x720 frames (``run_all_stages.node_hd_stage``).
HD_NODE_TITLE = 'Node through DDS, an HD camera'
#: The node stages of a run, by results key: their section headings, in report order.
NODE_STAGE_TITLES = {'node': 'Node through DDS', 'node_hd': HD_NODE_TITLE}


def node_stage_results(results: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """``(key, section)`` of each node stage the run reports, in report order: the
    640x480 stage always (missing or failed included), the HD stage where the run has
    it (a run saved before that stage existed has none)."""
    return [(key, results.get(key)) for key in NODE_STAGE_TITLES
            if key == 'node' or key in results]

#: Labels of the detector methods (the keys of results['detector']['sizes'][...]['methods']).
METHOD_LABELS: dict[str, str] = {
    'gl': 'ours, GL (default vote method)',
    'gl_raster': 'ours, GL raster (the paper\'s)',
    'gl_scatter': 'ours, GL scatter',
    'cpu': 'ours, CPU',
    'numpy': 'ours, numpy reference',
    'hough_gradient': 'cv2 HOUGH_GRADIENT',
    'hough_gradient_alt': 'cv2 HOUGH_GRADIENT_ALT',
    'radsym_rsd': 'radsym RSD',
    'radsym_frst': 'radsym FRST',
}

#: Short names of the backends ``backend: auto`` chooses between (summary rows).
AUTO_LABELS: dict[str, str] = {'gl': 'GL', 'cpu': 'CPU'}

SMOKE_NOTE = ('> **Smoke run** (`--quick`): a handful of frames and crops, run to check the '
              'machinery. These figures are not measurements; run `make bench` for them.')


def _label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def is_ours(method: str) -> bool:
    """True for our detector methods (GL of either vote method, CPU, numpy)."""
    return method.startswith('gl') or method in ('cpu', 'numpy')


def backend_phrase(section: Mapping[str, Any]) -> str:
    """The detector backend of a pipeline or node section, with how auto chose it when
    the run recorded that (``backend_choice``), e.g. ``cpu (auto: cpu, 21.0 ms ...)``."""
    choice = section.get('backend_choice')
    return f"{section.get('backend', '?')}" + (f' ({choice})' if choice else '')


def _problem(section: Any) -> str | None:
    """Why a stage has no figures ('failed: ...', 'not run: ...'), or None when it has."""
    if not isinstance(section, Mapping):
        return 'not run'
    if 'error' in section:
        return f"failed: {section['error']}"
    if 'skipped' in section:
        return f"not run: {section['skipped']}"
    return None


def gl_renderer(results: Mapping[str, Any]) -> str:
    """The GL renderer the run measured (detector stage, else pipeline), or 'unknown'."""
    for stage in ('detector', 'pipeline', 'node'):
        section = results.get(stage)
        if isinstance(section, Mapping) and section.get('renderer'):
            return str(section['renderer'])
    return 'unknown'


def host_line(results: Mapping[str, Any]) -> str:
    """The host in words: CPU model, core count, GL renderer, OS, Python, OpenCV, and the
    BLAS libraries with their kernels where the record has them (another kernel rounds
    training otherwise)."""
    machine: Mapping[str, Any] = results.get('machine', {})
    cpu = machine.get('cpu_model') or machine.get('processor') or 'unknown CPU'
    detector = results.get('detector')
    software = isinstance(detector, Mapping) and detector.get('software_renderer')
    kind = ' (a software renderer: the GL work runs on the CPU cores)' if software else ''
    return (f"{cpu}, {machine.get('cpus', '?')} cores; GL renderer {gl_renderer(results)}"
            f"{kind}; {machine.get('platform', '?')}, Python {machine.get('python', '?')}, "
            f"OpenCV {machine.get('opencv', '?')}"
            + (f"; BLAS {describe_blas(machine['blas'])}" if machine.get('blas') else ''))


# ------------------------------------------------------------------------------ summary
def _ours_summary(detector: Mapping[str, Any], size: Mapping[str, Any]) -> str:
    """Our cell of a detector summary row: the backend ``backend: auto`` keeps on this host
    (``auto_pick``; on a run without a CPU row, GL), then the other of GL and CPU."""
    methods = size['methods']
    if 'cpu' not in methods:
        ours = methods['gl']
        return f"recall {_number(ours['recall'], 3)}, {_number(ours['median_ms'])} ms"
    pick = size.get('auto_pick') or 'gl'
    other = 'cpu' if pick == 'gl' else 'gl'
    why = ('the faster of GL and CPU on this software renderer'
           if detector.get('software_renderer') else 'auto keeps GL on a hardware renderer')
    return (f"{AUTO_LABELS[pick]}, what `backend: auto` runs here ({why}): recall "
            f"{_number(methods[pick]['recall'], 3)}, {_number(methods[pick]['median_ms'])} "
            f"ms; {AUTO_LABELS[other]}: recall {_number(methods[other]['recall'], 3)}, "
            f"{_number(methods[other]['median_ms'])} ms")


def _detector_summary(detector: Mapping[str, Any]) -> list[str]:
    """Summary rows of the detector: ours (the backend auto keeps here, and the other of GL
    and CPU) against the fastest peer and the best-recall one."""
    rows = []
    for name, size in detector['sizes'].items():
        if size['signs'] is None:
            continue
        methods = size['methods']
        peers = [m for m in methods if not is_ours(m)]
        fastest = min(peers, key=lambda m: methods[m]['median_ms'])
        best = max(peers, key=lambda m: methods[m]['recall'] or 0.0)
        rows.append([
            f"detector, {name}: candidate recall@{detector['top_n']}, median ms per frame",
            _ours_summary(detector, size),
            f"fastest: {_label(fastest)}, recall {_number(methods[fastest]['recall'], 3)}, "
            f"{_number(methods[fastest]['median_ms'])} ms; highest recall: {_label(best)}, "
            f"recall {_number(methods[best]['recall'], 3)}, "
            f"{_number(methods[best]['median_ms'])} ms"])
    return rows


def summary_lines(results: Mapping[str, Any]) -> list[str]:
    """The summary: host, then one row per stage (ours against the peers)."""
    lines = ['## Summary', '', f'Host: {host_line(results)}.', '']
    rows: list[list[str]] = []
    detector = results.get('detector')
    if _problem(detector):
        rows.append(['detector', _problem(detector) or '', ''])
    else:
        rows += _detector_summary(detector)
    classifier = results.get('classifier')
    if _problem(classifier):
        rows.append(['classifier', _problem(classifier) or '', ''])
    else:
        seen = ' (crops the shipped bank was trained on)' \
            if classifier.get('crops_seen_in_training') else ''
        rows.append([f"classifier, {classifier['crops']} GTSRB-dev crops{seen}: accuracy, "
                     f"ms per crop",
                     f"{_number(classifier['classifier_accuracy'], 3)}, "
                     f"{_number(classifier['classifier_ms_per_crop'], 2)} ms",
                     f"plain NCC: {_number(classifier['ncc_baseline_accuracy'], 3)}, "
                     f"{_number(classifier['ncc_baseline_ms_per_crop'], 2)} ms"])
    pipeline = results.get('pipeline')
    if _problem(pipeline):
        rows.append(['pipeline', _problem(pipeline) or '', ''])
    else:
        rows.append([f"pipeline, {pipeline['width']}x{pipeline['height']} synthetic drive: "
                     f"frames per second",
                     f"{_number(pipeline.get('overlapped_fps'))} fps overlapped, "
                     f"{_number(pipeline['fps'])} serial; detector backend "
                     f"{pipeline.get('backend', '?')}", '-'])
    camera_sizes = results.get('camera_sizes')
    if 'camera_sizes' in results:   # a run saved before this stage has none
        rows.append(['speed_sign_eval bag at each camera size', _problem(camera_sizes) or '',
                     ''] if _problem(camera_sizes) else camera_sizes_summary(camera_sizes))
    for key, node in node_stage_results(results):
        if _problem(node):
            rows.append([f'node through DDS ({key})', _problem(node) or '', ''])
            continue
        for rate in node['rates']:
                rows.append([f"node through DDS, {node['width']}x{node['height']} at "
                             f"{rate['publish_hz']:g} Hz: frames answered per second",
                             f"{_number(rate['output_fps'])} fps, "
                             f"{rate['dropped']} of {rate['published']} unanswered; detector "
                             f"backend {node.get('backend') or '?'}", '-'])
    rows += summary_rows(results)
    lines += _table(['benchmark', 'ours', 'peers'], rows, right_aligned_from=3)
    if isinstance(classifier, Mapping) and classifier.get('crops_seen_in_training'):
        lines += ['', 'The shipped bank learned from gtsrb-dev, so its accuracy on those '
                  'crops is not a held-out figure; held-out figures come from `speed_sign_train '
                  'validate` (k folds split by track), see the README.']
    return lines


# ------------------------------------------------------------------------ one per stage
def _auto_sentence(detector: Mapping[str, Any]) -> str:
    """' `backend: auto` here: ...' naming the backend auto keeps at each size, or ''."""
    picks = {name: size['auto_pick'] for name, size in detector['sizes'].items()
             if size.get('auto_pick')}
    if not picks:
        return ''
    if detector.get('software_renderer'):
        rule, basis = 'times GL and CPU on its first frames and keeps the faster', \
            ' (the lower median of this run)'
    else:
        rule, basis = 'keeps GL (a hardware renderer)', ''
    return (f' `backend: auto` on this host {rule}: ' + ', '.join(
        f'{AUTO_LABELS.get(pick, pick)} at {name}' for name, pick in picks.items())
            + f'{basis}.')


def detector_lines(detector: Mapping[str, Any]) -> list[str]:
    """Detector tables: time and recall per method and size; recall by radius; sweeps."""
    sizes: Mapping[str, Any] = detector['sizes']
    lines = ['## Detector', '',
             f"GTSDB-dev scenes holding a speed-limit sign ({detector['frames_available']} "
             f"available; frames used per size below), top-{detector['top_n']} candidates; a "
             f"sign is found when a candidate centre lies within max(3, 0.35 r) px of it. "
             f"Default vote method: {detector.get('gl_vote_method', '?')}."
             + _auto_sentence(detector), '']
    header = ['method']
    for name, size in sizes.items():
        header.append(f'{name} ms')
        if size['signs'] is not None:
            header.append(f'{name} recall')
    rows = []
    for method in next(iter(sizes.values()))['methods']:
        row = [_label(method)]
        for size in sizes.values():
            item = size['methods'][method]
            row.append(_number(item['median_ms']))
            if size['signs'] is not None:
                row.append(_number(item['recall'], 3))
        rows.append(row)
    lines += _table(header, rows)
    lines += ['', 'Frames (signs): ' + ', '.join(
        f"{name} {size['how']} {size['frames']}"
        + (f" ({size['signs']})" if size['signs'] is not None else ' (time only)')
        for name, size in sizes.items()) + '.']
    floors = [f"{name} {_number(size['gl_floor_ms'], 2)} ms" for name, size in sizes.items()
              if size.get('gl_floor_ms') is not None]
    if floors:
        lines.append('Least time of a GL pass (frame upload, one trivial compute pass, read '
                     'back): ' + ', '.join(floors) + '.')
    native = next((name for name, size in sizes.items()
                   if size['how'] == 'native' and size.get('signs_by_radius_px')), None)
    if native:
        counts: Mapping[str, int] = sizes[native]['signs_by_radius_px']
        lines += ['', f'### Recall by sign radius, {native}', '']
        lines += _table(['method'] + [f'{name} px ({count})' for name, count in counts.items()],
                        [[_label(method)] + [_number(item['recall_by_radius_px'][name], 2)
                                             for name in counts]
                         for method, item in sizes[native]['methods'].items()])
    sweeps = detector.get('sweeps')
    if sweeps:
        lines += ['', f"### Time against max radius and edge count, {sweeps['size']} "
                      f"({sweeps['frames']} frames, median ms)", '']
        backends = [name for name in ('gl', 'cpu', 'numpy')
                    if f'{name}_ms' in sweeps['max_radius'][0]]
        titles = [f"{AUTO_LABELS.get(name, name)} ms" for name in backends]
        lines += _table(['max_radius_px', *titles],
                        [[f"{row['max_radius_px']:g}",
                          *(_number(row[f'{name}_ms']) for name in backends)]
                         for row in sweeps['max_radius']])
        lines.append('')
        lines += _table(['gradient_threshold', 'edge pixels', *titles],
                        [[f"{row['gradient_threshold']:g}", f"{row['edges']:.0f}",
                          *(_number(row[f'{name}_ms']) for name in backends)]
                         for row in sweeps['edge_count']])
    return lines


def classifier_lines(classifier: Mapping[str, Any]) -> list[str]:
    """Classifier tables: ours against plain NCC, overall and by sign width."""
    every = classifier['crop_every']
    subset = 'all' if every == 1 else f'every {every}th'
    lines = ['## Classifier', '',
             f"GTSRB-dev, {classifier['crops']} crops ({subset} of labels.csv); both "
             f"methods use the same rendered templates.", '']
    lines += _table(['method', 'accuracy', 'ms per crop'], [
        ['ours: kth-law MACE, PSR, trained bank', _number(classifier['classifier_accuracy'], 3),
         _number(classifier['classifier_ms_per_crop'], 2)],
        ['plain NCC (cv2.matchTemplate, 5 scales)',
         _number(classifier['ncc_baseline_accuracy'], 3),
         _number(classifier['ncc_baseline_ms_per_crop'], 2)]])
    counts = classifier.get('count_by_size_px') or {}
    if counts:
        lines += ['', '### Accuracy by sign width', '']
        lines += _table(['sign width px', 'crops', 'ours', 'plain NCC'], [
            [name, str(count), _number(classifier['classifier_by_size_px'][name], 3),
             _number(classifier['ncc_baseline_by_size_px'][name], 3)]
            for name, count in counts.items()])
    rendered = classifier.get('rendered_bank') or {}
    lines += ['', '### Time per frame', '']
    lines += _table(['bank', 'ms per 640x480 frame of 7 candidates', 'ms per candidate'], [
        ['shipped bank', _number(classifier['ms_per_frame_7_candidates']),
         _number(classifier['ms_per_candidate'], 2)],
        ['renderings only (`bank_file: none`)',
         _number(rendered.get('ms_per_frame_7_candidates')),
         _number(rendered.get('ms_per_candidate'), 2)]])
    lines += ['', f"{classifier['speed_frames']} frames timed; banks "
                  f"{classifier['bank_mb']:.1f} MB, loaded or built in "
                  f"{classifier['bank_load_or_build_s']:.1f} s."]
    return lines


def pipeline_lines(pipeline: Mapping[str, Any]) -> list[str]:
    """The pipeline table: fps serial and overlapped, latency, stage medians."""
    lines = ['## Pipeline', '',
             f"`Pipeline` on {pipeline['frames']} frames of a synthetic drive at "
             f"{pipeline['width']}x{pipeline['height']}, detector backend "
             f"{backend_phrase(pipeline)}.", '']
    lines += _table(['figure', 'value'], [
        ['fps, one frame at a time', _number(pipeline['fps'])],
        ['fps, detection overlapping recognition (the node\'s default)',
         _number(pipeline.get('overlapped_fps'))],
        ['latency p50 ms', _number(pipeline['latency_p50_ms'])],
        ['latency p95 ms', _number(pipeline['latency_p95_ms'])],
        *[[f'stage {name} p50 ms', _number(value)]
          for name, value in pipeline['stage_p50_ms'].items()]])
    return lines


#: The heading of the ``eval bag`` stage at each camera size (``bench_camera_sizes.py``).
CAMERA_SIZES_TITLE = 'speed_sign_eval bag at each camera size'


def _against_target(value: float | None, target: float | None, text: str) -> str:
    """``text``, followed by the target and whether ``value`` meets it (where one is set)."""
    if target is None or value is None:
        return text
    return f"{text} (target {target:g}: {'met' if value >= target else 'NOT met'})"


def _approach_cell(approach: Mapping[str, Any]) -> str:
    """'44 of 51 (0.863), 0 wrong' for an approach summary, or why there is none."""
    if 'skipped' in approach:
        return f"not run: {approach['skipped']}"
    return (f"{approach['recognized']} of {approach['signs']} "
            f"({_number(approach['recall'], 3)}), {approach['wrong_limits']} wrong")


def camera_sizes_summary(camera_sizes: Mapping[str, Any]) -> list[str]:
    """The summary row of the ``eval bag`` stage: fps per size, approach signs recognized."""
    sizes = camera_sizes['sizes']
    fps = ' / '.join(_number(row['drive']['fps']) for row in sizes.values())
    recognized = ' / '.join(
        '-' if 'skipped' in row['approach'] else str(row['approach']['recognized'])
        for row in sizes.values())
    wrong = sum(row['drive']['wrong_limits'] + row['approach'].get('wrong_limits', 0)
                for row in sizes.values())
    return [f"speed_sign_eval bag at {' / '.join(sizes)}: fps on a synthetic drive; "
            f"approach sequences (real pixels) recognized",
            f'{fps} fps; recognized {recognized}; {wrong} wrong limits in all', '-']


def camera_sizes_lines(camera_sizes: Mapping[str, Any]) -> list[str]:
    """The ``eval bag`` table: one row per camera size, then the commands."""
    sizes = camera_sizes['sizes']
    targets = camera_sizes.get('drive_fps_targets', {})
    first = next(iter(sizes.values()))
    lines = [f'## {CAMERA_SIZES_TITLE}', '',
             f"The installed `speed_sign_eval bag`, each run in its own process, on a "
             f"{camera_sizes['drive_seconds']:g} s synthetic drive (seed "
             f"{camera_sizes['drive_seed']}) and on {camera_sizes['approach_sequences']} "
             f"approach sequences resampled from the GTSDB scenes, both made at each camera "
             f"size (JPEG). Detector backend {first['drive'].get('backend_choice') or '?'} "
             f"(at the first size). The drive's exact answers show that the speed was not "
             f"bought with misses; the shipped bank learned from the GTSDB scenes, so compare "
             f"the approach figures between sizes (held-out ones come from `make validate`).",
             '']
    rows = []
    for name, row in sizes.items():
        drive = row['drive']
        stages = drive.get('stage_ms_p50') or {}
        rows.append([name, _against_target(drive['fps'], targets.get(name),
                                           _number(drive['fps'])),
                     _number(drive['latency_ms_p50']), _number(drive['latency_ms_p95']),
                     _number(stages.get('detect')), _number(stages.get('classify')),
                     f"{_number(drive['recall'], 3)}, {drive['wrong_limits']} wrong",
                     _approach_cell(row['approach'])])
    lines += _table(['camera', 'drive fps', 'latency p50 ms', 'latency p95 ms',
                     'detect p50 ms', 'classify p50 ms', 'drive recall, wrong limits',
                     'approach signs recognized, wrong limits'], rows)
    commands = [f"`{row[kind]['made_by']}` + `{row[kind]['command']}`"
                for row in sizes.values() for kind in ('drive', 'approach')
                if 'made_by' in row[kind]]
    lines += ['', 'Commands: ' + '; '.join(commands) + '.']
    return lines


def node_lines(node: Mapping[str, Any], title: str = 'Node through DDS') -> list[str]:
    """The node table under ``title``: one row per publishing rate."""
    lines = [f'## {title}', '',
             f"The installed `speed_sign_detector` fed {node['width']}x{node['height']} "
             f"frames over DDS (detector backend {backend_phrase(node)}).", '']
    lines += _table(['published Hz', 'seconds', 'fps answered', 'unanswered',
                     'latency p50 ms', 'latency p95 ms', 'RSS MiB'],
                    [[f"{rate['publish_hz']:g}", f"{rate['seconds']:g}",
                      _number(rate['output_fps']), f"{rate['dropped']} of {rate['published']}",
                      _number(rate['latency_p50_ms']), _number(rate['latency_p95_ms']),
                      _number(rate['rss_mb'], 0)] for rate in node['rates']])
    return lines


def paper_lines(papers: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """The papers' headline figures, quoted (not measured)."""
    rows = []
    for item in papers.values():
        kind = 'detection' if 'detection_rate' in item else 'recognition'
        rate = item.get('detection_rate', item.get('recognition_rate'))
        rows.append([str(item['source']), f"{item['fps']:g} fps at {item['frame_size']}",
                     f'{rate:.0%} {kind}', str(item['hardware']), str(item['note'])])
    return ['## The papers (quoted, not measured here)', ''] + _table(
        ['paper', 'speed', 'rate', 'hardware', 'what the rate counts'], rows,
        right_aligned_from=5)


def render_results_markdown(results: Mapping[str, Any]) -> str:
    """RESULTS.md of one run: a note, the summary, then one section per benchmark.

    Args:
        results: what ``run_all.run_benchmark`` returns (or its results.json, loaded).

    Returns:
        Markdown text ending in a newline.
    """
    command = ' '.join(results.get('command') or ['python', 'bench/run_all.py'])
    merged_by = results.get('long_runs_merged_by')
    merged = (f"; the long runs' files merged into it afterwards by `{' '.join(merged_by)}`"
              if merged_by else '')
    lines = ['# Benchmark results', '',
             f'Generated by `make bench` from the run\'s `results.json` (this run: '
             f"`{command}`, {results.get('elapsed_s', 0):.0f} s{merged}); do not edit by hand. "
             'Accuracy and speed of each stage against its peers, measured in one run on '
             'one host.', '']
    if results.get('quick'):
        lines += [SMOKE_NOTE, '']
    lines += summary_lines(results)
    sections = [('detector', 'Detector', detector_lines),
                ('classifier', 'Classifier', classifier_lines),
                ('pipeline', 'Pipeline', pipeline_lines)]
    if 'camera_sizes' in results:
        sections.append(('camera_sizes', CAMERA_SIZES_TITLE, camera_sizes_lines))
    sections += [(key, NODE_STAGE_TITLES[key],
                  functools.partial(node_lines, title=NODE_STAGE_TITLES[key]))
                 for key, _ in node_stage_results(results)]
    for key, title, render in sections:
        lines.append('')
        problem = _problem(results.get(key))
        lines += [f'## {title}', '', f'{problem[0].upper()}{problem[1:]}.'] if problem \
            else render(results[key])
    lines += long_run_lines(results)
    papers = results.get('paper_figures_quoted_not_measured')
    if papers:
        lines += [''] + paper_lines(papers)
    return '\n'.join(lines) + '\n'


def write_results_markdown(results: Mapping[str, Any], path: Path) -> None:
    """Write ``render_results_markdown(results)`` to ``path`` (folders created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_results_markdown(results))
