"""``speed_sign_eval scenes DIR``: detection metrics on GTSDB-format scenes.

``DIR`` holds ``images/`` and a GTSDB ``gt.txt`` (``file;x1;y1;x2;y2;classId`` per sign,
box corners in pixels). Every image is read as grayscale and run through the detector.
A speed-limit sign (classes 0-5, 7, 8) counts as found when one of the frame's top-N
candidates has its centre within ``max(3 px, 0.35 r)`` of the box centre, with
``r = (w + h) / 4``.

Output (``--json``: one JSON object as the last stdout line): ``frames``, ``signs``,
``found``, ``candidate_recall``, ``ms_per_frame`` (everything per frame: reading,
conversion, detection, scoring), ``detector_ms_per_frame`` (``Detector.detect`` alone),
``backend``, ``renderer``, ``max_candidates``, ``recall_by_size`` (per sign radius range),
``radius_ratio_median`` (candidate radius / box radius over the found signs: the
detector reports the radius of the edge that voted, mostly the inner edge of the ring).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2

from speed_sign_detector.config import DetectorConfig, load_yaml
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.errors import TruthFileError

LOGGER = logging.getLogger(__name__)

#: GTSDB class id -> speed limit in km/h (class 6, end of 80, is not a limit).
SPEED_LIMIT_CLASSES: dict[int, int] = {0: 20, 1: 30, 2: 50, 3: 60, 4: 70, 5: 80, 7: 100,
                                       8: 120}
#: Radius ranges (pixels) of the per-size recall figures.
SIZE_BINS_PX: tuple[tuple[float, float], ...] = ((0.0, 8.0), (8.0, 12.0), (12.0, 20.0),
                                                 (20.0, 1000.0))


@dataclass(frozen=True)
class SceneSign:
    """One sign of a GTSDB scene.

    Attributes:
        file: image file name (relative to ``images/``).
        x1_px, y1_px, x2_px, y2_px: its box, pixels.
        class_id: GTSDB class id.
    """

    file: str
    x1_px: float
    y1_px: float
    x2_px: float
    y2_px: float
    class_id: int

    @property
    def centre_px(self) -> tuple[float, float]:
        """Box centre (x, y), pixels."""
        return 0.5 * (self.x1_px + self.x2_px), 0.5 * (self.y1_px + self.y2_px)

    @property
    def radius_px(self) -> float:
        """``(w + h) / 4``, pixels."""
        return 0.25 * ((self.x2_px - self.x1_px) + (self.y2_px - self.y1_px))

    @property
    def limit_kmh(self) -> int:
        """Speed limit of the sign, km/h; 0 when it is not a speed-limit sign."""
        return SPEED_LIMIT_CLASSES.get(self.class_id, 0)


def read_gtsdb_truth(path: Path) -> dict[str, list[SceneSign]]:
    """Read a GTSDB ``gt.txt``: signs per image file.

    Raises:
        TruthFileError: missing file or a malformed line (named with its number).
    """
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as err:
        raise TruthFileError(f'cannot read GTSDB truth file {path}: {err}') from err
    signs: dict[str, list[SceneSign]] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.strip().split(';')
        if len(fields) != 6:
            raise TruthFileError(f'{path}:{number}: expected file;x1;y1;x2;y2;classId, '
                                 f'got {line!r}')
        try:
            x1, y1, x2, y2 = (float(value) for value in fields[1:5])
            class_id = int(fields[5])
        except ValueError as err:
            raise TruthFileError(f'{path}:{number}: not a number in {line!r}') from err
        if x2 <= x1 or y2 <= y1:
            raise TruthFileError(f'{path}:{number}: empty box in {line!r}')
        signs.setdefault(fields[0], []).append(SceneSign(fields[0], x1, y1, x2, y2, class_id))
    return signs


def matching_candidate(sign: SceneSign, candidates: Sequence[Candidate]) -> Candidate | None:
    """The best candidate whose centre lies within ``max(3, 0.35 r)`` px of the sign's centre."""
    x, y = sign.centre_px
    tolerance = max(3.0, 0.35 * sign.radius_px)
    return next((c for c in candidates if math.hypot(c.x_px - x, c.y_px - y) <= tolerance),
                None)


def is_found(sign: SceneSign, candidates: Sequence[Candidate]) -> bool:
    """True when a candidate centre lies within ``max(3, 0.35 r)`` px of the sign's centre."""
    return matching_candidate(sign, candidates) is not None


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``scenes`` subcommand."""
    parser = subparsers.add_parser('scenes', help='detection metrics on GTSDB-format scenes',
                                   description=__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('directory', type=Path, help='folder with images/ and gt.txt')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--backend', choices=('auto', 'gl', 'numpy'), default='auto')
    parser.add_argument('--config', type=Path, default=None,
                        help='ROS 2 parameter YAML file (detector section used)')
    parser.add_argument('--max-candidates', type=int, default=None,
                        help='top-N candidates per frame (default: the config, 7)')
    parser.add_argument('--limit', type=int, default=0,
                        help='evaluate only the first N images (0 = all)')
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate the detector on a scene folder; prints the metrics."""
    directory: Path = args.directory
    truth = read_gtsdb_truth(directory / 'gt.txt')
    image_dir = directory / 'images'
    if not image_dir.is_dir():
        raise TruthFileError(f'{directory} has no images/ folder')
    files = sorted(path.name for path in image_dir.iterdir()
                   if path.suffix.lower() in ('.jpg', '.jpeg', '.png', '.ppm'))
    if args.limit > 0:
        files = files[:args.limit]
    if not files:
        raise TruthFileError(f'no images in {image_dir}')
    config = load_yaml(args.config).detector if args.config else DetectorConfig()
    if args.max_candidates is not None:
        config = dataclasses.replace(config, max_candidates=args.max_candidates)
    signs = found = 0
    bins_total = [0] * len(SIZE_BINS_PX)
    bins_found = [0] * len(SIZE_BINS_PX)
    detector_s = 0.0
    radius_ratios: list[float] = []
    start = time.perf_counter()
    with Detector(config, backend=args.backend) as detector:
        for index, name in enumerate(files):
            gray = cv2.imread(str(image_dir / name), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise TruthFileError(f'cannot read image {image_dir / name}')
            tick = time.perf_counter()
            candidates = detector.detect(gray)
            detector_s += time.perf_counter() - tick
            for sign in truth.get(name, ()):
                if not sign.limit_kmh:
                    continue
                match = matching_candidate(sign, candidates)
                hit = match is not None
                if hit:
                    radius_ratios.append(match.radius_px / sign.radius_px)
                signs += 1
                found += hit
                for bin_index, (low, high) in enumerate(SIZE_BINS_PX):
                    if low <= sign.radius_px < high:
                        bins_total[bin_index] += 1
                        bins_found[bin_index] += hit
            if (index + 1) % 50 == 0:
                LOGGER.info('%d/%d frames, recall so far %.3f', index + 1, len(files),
                            found / max(signs, 1))
        backend, renderer = detector.backend_name, detector.renderer
    elapsed_s = time.perf_counter() - start
    result = {
        'frames': len(files),
        'signs': signs,
        'found': found,
        'candidate_recall': found / signs if signs else 0.0,
        'ms_per_frame': 1e3 * elapsed_s / len(files),
        'detector_ms_per_frame': 1e3 * detector_s / len(files),
        'backend': backend,
        'renderer': renderer,
        'max_candidates': config.max_candidates,
        'radius_ratio_median': (statistics.median(radius_ratios) if radius_ratios else None),
        'recall_by_size': {f'{low:g}-{high:g}px': {
            'signs': total, 'recall': (hits / total if total else None)}
            for (low, high), total, hits in zip(SIZE_BINS_PX, bins_total, bins_found)},
    }
    if args.json:
        print(json.dumps(result), file=sys.stdout)
    else:
        _print_table(result)
    return 0


def _print_table(result: dict) -> None:
    print(f"scenes: {result['frames']} frames, {result['signs']} speed-limit signs")
    print(f"backend: {result['backend']} ({result['renderer']})")
    print(f"{'metric':<28}{'value':>12}")
    print(f"{'candidate recall (top ' + str(result['max_candidates']) + ')':<28}"
          f"{result['candidate_recall']:>12.3f}")
    print(f"{'found / signs':<28}{str(result['found']) + '/' + str(result['signs']):>12}")
    print(f"{'ms per frame':<28}{result['ms_per_frame']:>12.1f}")
    print(f"{'detector ms per frame':<28}{result['detector_ms_per_frame']:>12.1f}")
    if result['radius_ratio_median'] is not None:
        print(f"{'radius ratio (median)':<28}{result['radius_ratio_median']:>12.2f}")
    for name, item in result['recall_by_size'].items():
        recall = '-' if item['recall'] is None else f"{item['recall']:.3f}"
        print(f"{'recall, radius ' + name:<28}{recall:>12}  ({item['signs']} signs)")
