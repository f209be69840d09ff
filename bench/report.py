#!/usr/bin/env python3
"""Terminal table, JSON file and PNG plots of the results of ``run_all.py``.

``run_all.py`` calls these functions; run on its own, this module redraws the table
and the plots of a saved run::

    python bench/report.py out/bench/results.json [--out DIR] [--results-md bench/RESULTS.md]
        [--validation PATH] [--value-holdout PATH] [--designs PATH] [--soak PATH]

(``--results-md`` renders bench/RESULTS.md again from the saved run, see
``results_markdown.py``. The last four add the JSON files of the long runs, ``make
validate`` and ``make soak``, to the saved results.json, which is written again with them,
and so to the report: ``long_runs_markdown.py``.)

Plots (PNG, matplotlib with the Agg backend):
    ``detector_time_vs_frame_size.png``: median ms per frame vs megapixels, per method;
    ``detector_recall.png``: recall@7 per method, at each measured frame size;
    ``detector_sweeps.png``: GL and numpy ms vs max radius and vs edge count;
    ``classifier_accuracy_vs_size.png``: accuracy vs sign width, classifier vs NCC.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

METHOD_LABELS: dict[str, str] = {
    'gl': 'ours, GL (default)',
    'gl_raster': 'ours, GL raster (paper)',
    'gl_scatter': 'ours, GL scatter',
    'cpu': 'ours, CPU',
    'numpy': 'ours, numpy reference',
    'hough_gradient': 'cv2 HOUGH_GRADIENT',
    'hough_gradient_alt': 'cv2 HOUGH_GRADIENT_ALT',
    'radsym_rsd': 'radsym RSD',
    'radsym_frst': 'radsym FRST',
}


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f'not JSON serializable: {type(value).__name__}')


def write_json(results: Mapping[str, Any], path: Path) -> None:
    """Write the results as indented JSON (numpy scalars become numbers)."""
    path.write_text(json.dumps(results, indent=1, default=_json_default) + '\n')


def _number(value: float | None, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return f'{value:.{digits}f}'


def _failed(section: Any) -> str | None:
    if not isinstance(section, Mapping):
        return 'missing'
    if 'error' in section:
        return f"FAILED: {section['error']}"
    if 'skipped' in section:
        return f"skipped: {section['skipped']}"
    return None


def _detector_lines(detector: Mapping[str, Any]) -> list[str]:
    sizes: Mapping[str, Any] = detector['sizes']
    lines = [(f"Detector stage: GTSDB-dev scenes holding a speed-limit sign "
              f"({detector['frames_available']} available), top-{detector['top_n']} "
              f"candidates; recall = a candidate centre within max(3, 0.35 r) px of the sign"),
             f"GL renderer: {detector['renderer']}"
             + (' (software rasterizer on the CPU: no GPU figure)'
                if detector.get('software_renderer') else ' (hardware)')
             + f"; default vote method: {detector.get('gl_vote_method', '?')}"]
    header = f"{'method':<24}"
    for name, size in sizes.items():
        header += f"{name + ' ms':>13}" + (f"{'recall':>8}" if size['signs'] is not None else '')
    lines.append(header)
    methods = next(iter(sizes.values()))['methods']
    for method in methods:
        row = f"{METHOD_LABELS.get(method, method):<24}"
        for size in sizes.values():
            item = size['methods'][method]
            row += f"{_number(item['median_ms']):>13}"
            if size['signs'] is not None:
                row += f"{_number(item['recall'], 3):>8}"
        lines.append(row)
    lines.append('frames (signs): ' + ', '.join(
        f"{name} {size['how']} {size['frames']}"
        + (f" ({size['signs']})" if size['signs'] is not None else ' (time only)')
        for name, size in sizes.items()))
    for name, size in sizes.items():
        rows = size['methods']
        gl = rows['gl']
        peers = [m for m in rows if not m.startswith('gl') and m not in ('cpu', 'numpy')]
        fastest = min(peers, key=lambda m: rows[m]['median_ms'])
        text = (f"  {name}: GL {_number(gl['median_ms'])} ms; fastest peer "
                f"{METHOD_LABELS.get(fastest, fastest)} {_number(rows[fastest]['median_ms'])} "
                f"ms (GL {rows[fastest]['median_ms'] / gl['median_ms']:.2f}x its speed)")
        if gl['recall'] is not None:
            close = [m for m in peers if rows[m]['recall'] is not None
                     and rows[m]['recall'] >= gl['recall'] - 0.05]
            if close:
                best = min(close, key=lambda m: rows[m]['median_ms'])
                text += (f"; fastest peer within 0.05 of GL's recall: "
                         f"{METHOD_LABELS.get(best, best)} {_number(rows[best]['median_ms'])} ms")
            else:
                top = max(peers, key=lambda m: rows[m]['recall'])
                text += (f"; no peer within 0.05 of GL's recall {gl['recall']:.3f} (best peer "
                         f"{METHOD_LABELS.get(top, top)} {rows[top]['recall']:.3f})")
        if 'cpu' in rows:
            text += (f"; CPU {_number(rows['cpu']['median_ms'])} ms; backend: auto keeps "
                     f"{size.get('auto_pick', '?')} here")
        lines.append(text)
        if size.get('gl_floor_ms') is not None:
            lines.append(f"    GL floor at {name} (frame upload, one trivial compute pass, "
                         f"block list read back): {_number(size['gl_floor_ms'], 2)} ms; half the "
                         f"fastest peer's time: {_number(rows[fastest]['median_ms'] / 2, 2)} ms")
    native = next((name for name, size in sizes.items() if size['how'] == 'native'), None)
    if native and sizes[native]['signs_by_radius_px']:
        counts = sizes[native]['signs_by_radius_px']
        lines.append(f"Recall by sign radius at {native}, px (signs): " + ', '.join(
            f'{name} ({count})' for name, count in counts.items()))
        for method, item in sizes[native]['methods'].items():
            lines.append(f"  {METHOD_LABELS.get(method, method):<24}" + ''.join(
                f"{item['recall_by_radius_px'][name]:>8.2f}" for name in counts))
    sweeps = detector.get('sweeps')
    if sweeps:
        lines.append(f"Sweeps at {sweeps['size']} ({sweeps['frames']} frames), median ms "
                     f"(GL / numpy):")
        lines.append('  max radius px: ' + '; '.join(
            f"{row['max_radius_px']:g}: {_number(row['gl_ms'])} / {_number(row['numpy_ms'])}"
            for row in sweeps['max_radius']))
        lines.append('  edges (gradient threshold): ' + '; '.join(
            f"{row['edges']:.0f} ({row['gradient_threshold']:g}): {_number(row['gl_ms'])} / "
            f"{_number(row['numpy_ms'])}" for row in sweeps['edge_count']))
    return lines


def _classifier_lines(classifier: Mapping[str, Any]) -> list[str]:
    every = classifier['crop_every']
    lines = [(f"Classifier: GTSRB-dev, {classifier['crops']} crops ("
              + ('all' if every == 1 else f'every {every}th') + ' of labels.csv), same '
              'rendered templates'),
             f"{'method':<40}{'accuracy':>9}{'ms/crop':>9}",
             (f"{'ours: MACE + kth-law + PSR':<40}"
              f"{_number(classifier['classifier_accuracy'], 3):>9}"
              f"{_number(classifier['classifier_ms_per_crop'], 2):>9}"),
             (f"{'plain NCC (cv2.matchTemplate, 5 scales)':<40}"
              f"{_number(classifier['ncc_baseline_accuracy'], 3):>9}"
              f"{_number(classifier['ncc_baseline_ms_per_crop'], 2):>9}")]
    if classifier.get('count_by_size_px'):
        lines.append('  by sign width px (n): ' + '; '.join(
            f"{name} ({count}): {classifier['classifier_by_size_px'][name]:.2f} vs "
            f"{classifier['ncc_baseline_by_size_px'][name]:.2f}"
            for name, count in classifier['count_by_size_px'].items()))
    lines.append(f"  640x480 frame with 7 candidates: "
                 f"{_number(classifier['ms_per_frame_7_candidates'])} ms "
                 f"({_number(classifier['ms_per_candidate'], 2)} ms/candidate, "
                 f"{classifier['speed_frames']} frames); banks {classifier['bank_mb']:.1f} MB, "
                 f"loaded/built in {classifier['bank_load_or_build_s']:.1f} s")
    return lines


def format_table(results: Mapping[str, Any]) -> str:
    """The human-readable summary of a run (what run_all prints)."""
    machine = results['machine']
    load = ', '.join(f'{value:.2f}' for value in machine['load_average_at_start'] or [])
    lines = [(f"Benchmark {results['date_utc']}: {machine['cpus']} CPUs, {machine['platform']}"
              + (' -- QUICK RUN: smoke-test subsets, do not quote' if results['quick']
                 else '')),
             (f"load average (1, 5, 15 min) at start: {load}; "
              f"elapsed {results.get('elapsed_s', 0):.0f} s"), '']
    detector = results.get('detector')
    problem = _failed(detector)
    lines += [f'Detector stage {problem}'] if problem else _detector_lines(detector)
    lines.append('')
    classifier = results.get('classifier')
    problem = _failed(classifier)
    lines += [f'Classifier {problem}'] if problem else _classifier_lines(classifier)
    lines.append('')
    pipeline = results.get('pipeline')
    problem = _failed(pipeline)
    if problem:
        lines.append(f'Pipeline {problem}')
    else:
        stages = ', '.join(f'{key} {_number(value)}'
                           for key, value in pipeline['stage_p50_ms'].items())
        lines.append(f"Pipeline 640x480 ({pipeline['backend']}, {pipeline['renderer']}), "
                     f"{pipeline['frames']} synthetic-drive frames: "
                     f"{_number(pipeline['fps'])} fps serial, "
                     f"{_number(pipeline.get('overlapped_fps'))} fps with detection "
                     f"overlapping recognition (the node's default); latency p50 "
                     f"{_number(pipeline['latency_p50_ms'])} ms, p95 "
                     f"{_number(pipeline['latency_p95_ms'])} ms; stage p50 ms: {stages}")
    from results_markdown import node_stage_results  # a sibling script of bench/
    for key, node in node_stage_results(results):
        problem = _failed(node)
        if problem:
            lines.append(f'Node through DDS ({key}) {problem}')
            continue
        for rate in node['rates']:
            lines.append(f"Node through DDS {node['width']}x{node['height']} "
                         f"({node['backend']}): published {rate['publish_hz']:g} Hz for "
                         f"{rate['seconds']:g} s -> {_number(rate['output_fps'])} fps out, "
                         f"latency p50 {_number(rate['latency_p50_ms'])} ms, p95 "
                         f"{_number(rate['latency_p95_ms'])} ms, "
                         f"{rate['dropped']}/{rate['published']} unanswered, "
                         f"RSS {_number(rate['rss_mb'], 0)} MiB")
    lines.append('')
    lines.append('Papers (QUOTED from the papers, NOT measured here):')
    for item in results['paper_figures_quoted_not_measured'].values():
        rate = item.get('detection_rate', item.get('recognition_rate'))
        kind = 'detection' if 'detection_rate' in item else 'recognition'
        lines.append(f"  {item['fps']:g} fps at {item['frame_size']}, {rate:.0%} {kind} "
                     f"on {item['hardware']} ({item['note']})")
    return '\n'.join(lines)


def _plot_time_vs_size(detector: Mapping[str, Any], path: Path) -> None:
    import matplotlib.pyplot as plt

    sizes = detector['sizes']
    figure, axes = plt.subplots(figsize=(7, 4.5))
    methods = next(iter(sizes.values()))['methods']
    for method in methods:
        points = sorted((size['width'] * size['height'] / 1e6,
                         size['methods'][method]['median_ms']) for size in sizes.values())
        axes.plot([p[0] for p in points], [p[1] for p in points], marker='o',
                  label=METHOD_LABELS.get(method, method))
    axes.set_xlabel('frame size, megapixels')
    axes.set_ylabel('median time per frame, ms')
    axes.set_yscale('log')
    axes.set_title(f"Detector time vs frame size ({detector['renderer']})", fontsize=9)
    axes.grid(True, which='both', alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _plot_recall(detector: Mapping[str, Any], path: Path) -> None:
    import matplotlib.pyplot as plt

    sizes = {name: size for name, size in detector['sizes'].items() if size['signs']}
    methods = list(next(iter(detector['sizes'].values()))['methods'])
    figure, axes = plt.subplots(figsize=(8, 4.5))
    width = 0.8 / max(len(sizes), 1)
    for index, (name, size) in enumerate(sizes.items()):
        values = [size['methods'][m]['recall'] or 0.0 for m in methods]
        axes.bar(np.arange(len(methods)) + (index - (len(sizes) - 1) / 2) * width, values,
                 width, label=f"{name} ({size['signs']} signs)")
    axes.set_xticks(np.arange(len(methods)),
                    [METHOD_LABELS.get(m, m) for m in methods], rotation=20, fontsize=8)
    axes.set_ylabel(f"candidate recall@{detector['top_n']}")
    axes.set_ylim(0, 1)
    axes.set_title('Detector recall on GTSDB-dev speed-limit signs', fontsize=9)
    axes.grid(True, axis='y', alpha=0.3)
    axes.legend(fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.22), ncol=3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _plot_sweeps(sweeps: Mapping[str, Any], path: Path) -> None:
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 4))
    for backend in ('gl', 'cpu', 'numpy'):
        if f'{backend}_ms' not in sweeps['max_radius'][0]:
            continue  # a run from before the CPU path
        label = METHOD_LABELS[backend]
        left.plot([r['max_radius_px'] for r in sweeps['max_radius']],
                  [r[f'{backend}_ms'] for r in sweeps['max_radius']], marker='o', label=label)
        right.plot([r['edges'] for r in sweeps['edge_count']],
                   [r[f'{backend}_ms'] for r in sweeps['edge_count']], marker='o', label=label)
    left.set_xlabel('max_radius_px')
    right.set_xlabel('edge pixels per frame (gradient_threshold varied)')
    for axes in (left, right):
        axes.set_ylabel('median ms per frame')
        axes.grid(True, alpha=0.3)
        axes.legend(fontsize=8)
    figure.suptitle(f"Detector time at {sweeps['size']} ({sweeps['frames']} frames)",
                    fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _plot_classifier(classifier: Mapping[str, Any], path: Path) -> None:
    import matplotlib.pyplot as plt

    bins = list(classifier['count_by_size_px'])
    figure, axes = plt.subplots(figsize=(7, 4.5))
    positions = np.arange(len(bins))
    axes.plot(positions, [classifier['classifier_by_size_px'][b] for b in bins], marker='o',
              label=f"ours: MACE + kth-law + PSR ({classifier['classifier_accuracy']:.3f})")
    axes.plot(positions, [classifier['ncc_baseline_by_size_px'][b] for b in bins], marker='s',
              label=f"plain NCC baseline ({classifier['ncc_baseline_accuracy']:.3f})")
    axes.set_xticks(positions, [f"{b}\n(n={classifier['count_by_size_px'][b]})" for b in bins],
                    fontsize=8)
    axes.set_xlabel('sign width, px (GTSRB ROI)')
    axes.set_ylabel('accuracy')
    axes.set_ylim(0, 1)
    axes.set_title(f"Classifier accuracy vs sign size, {classifier['crops']} GTSRB-dev crops",
                   fontsize=9)
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def write_plots(results: Mapping[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG plots of the stages that ran; returns their paths."""
    import matplotlib

    matplotlib.use('Agg')
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    detector = results.get('detector')
    if not _failed(detector):
        for name, plot in (('detector_time_vs_frame_size.png', _plot_time_vs_size),
                           ('detector_recall.png', _plot_recall)):
            plot(detector, out_dir / name)
            written.append(out_dir / name)
        if detector.get('sweeps'):
            _plot_sweeps(detector['sweeps'], out_dir / 'detector_sweeps.png')
            written.append(out_dir / 'detector_sweeps.png')
    classifier = results.get('classifier')
    if not _failed(classifier) and classifier.get('count_by_size_px'):
        _plot_classifier(classifier, out_dir / 'classifier_accuracy_vs_size.png')
        written.append(out_dir / 'classifier_accuracy_vs_size.png')
    return written


def main(argv: list[str] | None = None) -> int:
    """Redraw the table and plots of a saved results.json."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('results', type=Path, help='results.json written by run_all.py')
    parser.add_argument('--out', type=Path, help='folder for the plots (default: beside it)')
    parser.add_argument('--results-md', type=Path, metavar='PATH',
                        help='also render the Markdown report (bench/RESULTS.md) there')
    from long_runs_markdown import add_arguments, load_long_runs  # a sibling script

    add_arguments(parser)
    args = parser.parse_args(argv)
    results = json.loads(args.results.read_text())
    long_runs = load_long_runs(args)
    if long_runs:
        results.update(long_runs)
        results['long_runs_merged_by'] = ['python', 'bench/report.py',
                                          *(sys.argv[1:] if argv is None else argv)]
        write_json(results, args.results)
        print(f"merged {', '.join(long_runs)} into {args.results}", file=sys.stderr)
    print(format_table(results))
    if args.results_md is not None:
        from results_markdown import write_results_markdown  # a sibling script of bench/

        write_results_markdown(results, args.results_md)
        print(f'wrote {args.results_md}', file=sys.stderr)
    for path in write_plots(results, args.out or args.results.parent):
        print(f'wrote {path}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
