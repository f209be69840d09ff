"""``speed_sign_eval scenes DIR``: detection and recognition metrics on GTSDB-format scenes.

``DIR`` holds ``images/`` and a GTSDB ``gt.txt`` (``file;x1;y1;x2;y2;classId`` per sign,
box corners in pixels). Every image is read as grayscale and run through the detector,
then (unless ``--no-classify``) the classifier, one frame at a time (no tracking).
A speed-limit sign (classes 0-5, 7, 8) counts as found when one of the frame's top-N
candidates has its centre within ``max(3 px, 0.35 r)`` of the box centre, with
``r = (w + h) / 4``; as recognized when such a candidate is also classified as its
limit. A false limit is a candidate classified as a limit that lies on no speed-limit
sign of that value (background, another sign such as end of 80, or a misread value).

Output (``--json``: one JSON object as the last stdout line): ``frames``, ``signs``,
``found``, ``candidate_recall``, ``ms_per_frame`` (everything per frame: reading,
conversion, detection, scoring), ``detector_ms_per_frame`` (``Detector.detect`` alone),
``backend``, ``renderer``, ``vote_method``, ``max_candidates``, ``recall_by_size`` (per
sign radius range),
``radius_ratio_median`` (candidate radius / box radius over the found signs: the
detector reports the radius of the edge that voted, mostly the inner edge of the ring);
with classification: ``recognized``, ``recognition_recall``, ``false_limits``,
``false_limits_per_frame``, ``classifier_ms_per_frame``. Run state: ``frames_planned``,
``partial`` (true after Ctrl-C: the metrics cover the ``frames`` done, exit status 130),
``unreadable`` (image files that could not be read or used, e.g. smaller than the
detector's window, ``{file, reason}``: skipped, the rest evaluated, exit status 1).
Rates over no frame or no sign are 0.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml, parameter_specs
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.errors import InvalidFrameError, TruthFileError
from speed_sign_detector.image_files import (
    UnreadableImage,
    UnreadableImageError,
    read_gray_image,
)
from speed_sign_detector.recognition.classifier import Classification, Classifier
from speed_sign_detector.scene_truth import (
    count_false_limits,
    is_recognized,
    matching_candidate,
    read_gtsdb_truth,
    scene_image_files,
)
from speed_sign_detector.tools.cli_types import integer_in_range, non_negative_integer
from speed_sign_detector.tools.run_control import (
    EXIT_INTERRUPTED,
    ItemProgress,
    stop_on_interrupt,
)

#: Radius ranges (pixels) of the per-size recall figures.
SIZE_BINS_PX: tuple[tuple[float, float], ...] = ((0.0, 8.0), (8.0, 12.0), (12.0, 20.0),
                                                 (20.0, 1000.0))
#: Allowed --max-candidates: the range of detector.max_candidates.
MAX_CANDIDATES_RANGE: tuple[int, int] = next(
    (int(spec.low), int(spec.high)) for spec in parameter_specs()
    if spec.name == 'detector.max_candidates')
#: What ``scenes --help`` says (the module docstring is for the API documentation).
HELP_DESCRIPTION = """\
Detection and single-frame recognition metrics on GTSDB-format scenes.

DIR holds images/ (JPEG, PNG or PPM) and a GTSDB gt.txt (file;x1;y1;x2;y2;classId per
sign, box corners in pixels). Every image goes through the detector, then (unless
--no-classify) the classifier, one frame at a time (no tracking).

A speed-limit sign (classes 0-5, 7, 8) counts as found when one of the frame's top-N
candidates has its centre within max(3 px, 0.35 r) of the box centre, r = (w + h) / 4;
as recognized when such a candidate is also read as its limit. A false limit is a
candidate read as a limit that lies on no speed-limit sign of that value.

Output: a table, or with --json one JSON object as the last stdout line (frames,
signs, found, candidate_recall, recall_by_size, ms_per_frame, detector_ms_per_frame,
backend, ...; with classification recognized, recognition_recall, false_limits,
false_limits_per_frame). Unreadable images are skipped and listed ("unreadable"),
exit status 1. Ctrl-C reports the frames done, marked "partial", exit status 130.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``scenes`` subcommand."""
    parser = subparsers.add_parser('scenes', help='detection and recognition metrics on '
                                   'GTSDB-format scenes (DIR/images, DIR/gt.txt)',
                                   description=HELP_DESCRIPTION,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('directory', type=Path, metavar='DIR',
                        help='folder with images/ and gt.txt')
    parser.add_argument('--json', action='store_true', help='print one JSON object as the '
                        'last line on stdout (instead of the table)')
    parser.add_argument('--backend', choices=('auto', 'gl', 'cpu', 'numpy'), default='auto',
                        help='radial-symmetry voting: gl (OpenGL, EGL), cpu (vectorised '
                        'CPU path), numpy (the reference), auto (gl on a GPU; on a '
                        'software renderer the faster of gl and cpu on the first frames; '
                        'cpu without GL; default)')
    parser.add_argument('--config', type=Path, default=None,
                        help='ROS 2 parameter YAML file of the node')
    parser.add_argument('--no-classify', action='store_true',
                        help='detection metrics only (no classifier)')
    parser.add_argument('--max-candidates', type=integer_in_range(*MAX_CANDIDATES_RANGE),
                        default=None,
                        help='top-N candidates per frame (default: the config, 7)')
    parser.add_argument('--limit', type=non_negative_integer, default=0,
                        help='evaluate only the first N images (default 0 = all)')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress on stderr')
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate the detector on a scene folder; prints the metrics."""
    directory: Path = args.directory
    truth = read_gtsdb_truth(directory / 'gt.txt')
    image_dir = directory / 'images'
    files = scene_image_files(directory)
    if args.limit > 0:
        files = files[:args.limit]
    if not files:
        raise TruthFileError(f'no images in {image_dir}')
    pipeline_config = load_yaml(args.config) if args.config else PipelineConfig()
    config = pipeline_config.detector
    classifier = None if args.no_classify else Classifier(pipeline_config.classifier)
    if args.max_candidates is not None:
        config = dataclasses.replace(config, max_candidates=args.max_candidates)
    signs = found = 0
    bins_total = [0] * len(SIZE_BINS_PX)
    bins_found = [0] * len(SIZE_BINS_PX)
    detector_s = classifier_s = 0.0
    recognized = false_limits = 0
    radius_ratios: list[float] = []
    unreadable: list[UnreadableImage] = []
    done = 0
    start = time.perf_counter()
    with Detector(config, backend=args.backend) as detector, \
            stop_on_interrupt('speed_sign_eval scenes') as stop:
        bar = ItemProgress(len(files), 'frames', 'frame', enabled=not args.quiet)
        for name in files:
            if stop.requested:
                break
            done += 1
            bar.update()
            try:
                gray = read_gray_image(image_dir / name)
            except UnreadableImageError as err:
                unreadable.append(UnreadableImage(f'images/{name}', str(err)))
                continue
            tick = time.perf_counter()
            try:
                candidates = detector.detect(gray)
            except InvalidFrameError as err:   # e.g. smaller than the voting window
                unreadable.append(UnreadableImage(f'images/{name}', str(err)))
                continue
            detector_s += time.perf_counter() - tick
            classifications: tuple[Classification, ...] = ()
            if classifier is not None:
                tick = time.perf_counter()
                classifications = classifier.classify(gray, candidates)
                classifier_s += time.perf_counter() - tick
                false_limits += count_false_limits(truth.get(name, ()), candidates,
                                                   classifications)
            for sign in truth.get(name, ()):
                if not sign.limit_kmh:
                    continue
                match = matching_candidate(sign, candidates)
                hit = match is not None
                recognized += is_recognized(sign, candidates, classifications)
                if hit:
                    radius_ratios.append(match.radius_px / sign.radius_px)
                signs += 1
                found += hit
                for bin_index, (low, high) in enumerate(SIZE_BINS_PX):
                    if low <= sign.radius_px < high:
                        bins_total[bin_index] += 1
                        bins_found[bin_index] += hit
        bar.close()
        backend, renderer = detector.backend_name, detector.renderer
        vote_method = detector.vote_method
    elapsed_s = time.perf_counter() - start
    frames = done - len(unreadable)
    per_frame_ms = 1e3 / frames if frames else 0.0
    result = {
        'frames': frames,
        'frames_planned': len(files),
        'partial': done < len(files),
        'unreadable': [dataclasses.asdict(item) for item in unreadable],
        'signs': signs,
        'found': found,
        'candidate_recall': found / signs if signs else 0.0,
        'ms_per_frame': elapsed_s * per_frame_ms,
        'detector_ms_per_frame': detector_s * per_frame_ms,
        'backend': backend,
        'renderer': renderer,
        'vote_method': vote_method,
        'max_candidates': config.max_candidates,
        'radius_ratio_median': (statistics.median(radius_ratios) if radius_ratios else None),
        'recall_by_size': {f'{low:g}-{high:g}px': {
            'signs': total, 'recall': (hits / total if total else None)}
            for (low, high), total, hits in zip(SIZE_BINS_PX, bins_total, bins_found)},
    }
    if classifier is not None:
        result.update({
            'recognized': recognized,
            'recognition_recall': recognized / signs if signs else 0.0,
            'false_limits': false_limits,
            'false_limits_per_frame': false_limits / frames if frames else 0.0,
            'classifier_ms_per_frame': classifier_s * per_frame_ms,
        })
    if args.json:
        print(json.dumps(result), file=sys.stdout)
    else:
        _print_table(result)
    if unreadable:
        print(f'speed_sign_eval scenes: {len(unreadable)} image(s) could not be read or used '
              f"and were skipped (listed under 'unreadable')", file=sys.stderr)
    if result['partial']:
        return EXIT_INTERRUPTED
    return 1 if unreadable else 0


def _print_table(result: dict) -> None:
    print(f"scenes: {result['frames']} frames, {result['signs']} speed-limit signs")
    print(f"backend: {result['backend']} ({result['renderer']}), "
          f"{result['vote_method']} voting")
    print(f"{'metric':<28}{'value':>12}")
    print(f"{'candidate recall (top ' + str(result['max_candidates']) + ')':<28}"
          f"{result['candidate_recall']:>12.3f}")
    print(f"{'found / signs':<28}{str(result['found']) + '/' + str(result['signs']):>12}")
    print(f"{'ms per frame':<28}{result['ms_per_frame']:>12.1f}")
    print(f"{'detector ms per frame':<28}{result['detector_ms_per_frame']:>12.1f}")
    if result['radius_ratio_median'] is not None:
        print(f"{'radius ratio (median)':<28}{result['radius_ratio_median']:>12.2f}")
    if 'recognized' in result:
        print(f"{'recognition recall':<28}{result['recognition_recall']:>12.3f}")
        print(f"{'recognized / signs':<28}"
              f"{str(result['recognized']) + '/' + str(result['signs']):>12}")
        print(f"{'false limits (per frame)':<28}{result['false_limits']:>12}"
              f"  ({result['false_limits_per_frame']:.4f})")
        print(f"{'classifier ms per frame':<28}{result['classifier_ms_per_frame']:>12.1f}")
    for name, item in result['recall_by_size'].items():
        recall = '-' if item['recall'] is None else f"{item['recall']:.3f}"
        print(f"{'recall, radius ' + name:<28}{recall:>12}  ({item['signs']} signs)")
    if result['unreadable']:
        print(f"UNREADABLE {len(result['unreadable'])} images (skipped):")
        for item in result['unreadable']:
            print(f"  {item['file']}: {item['reason']}")
    if result['partial']:
        print(f"PARTIAL: interrupted after {result['frames'] + len(result['unreadable'])} of "
              f"{result['frames_planned']} images")
