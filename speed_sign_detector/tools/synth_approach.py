"""``speed_sign_synth approach``: approach sequences from real scenes as a bag, with truth.

Example::

    speed_sign_synth approach ../shared/data/gtsdb-dev /work/approach/gtsdb_approach \\
        --truth /work/approach/gtsdb_approach_truth.csv --compressed
    speed_sign_eval bag /work/approach/gtsdb_approach \\
        --truth /work/approach/gtsdb_approach_truth.csv --json

For each speed-limit sign of at least ``--min-sign-px`` in a GTSDB-format folder
(``images/``, ``gt.txt``): ``--frames`` frames at ``--fps`` closing in on the sign,
resampled from the real pixels, then ``--gap-frames`` sign-free frames; the geometry
and the truth are described in :mod:`speed_sign_detector.approach_sequences`. The same
arguments give the same bag. A scene that cannot be read is skipped: the bag and truth
of the others are still written, and the exit status is 1 naming it.
"""
from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Iterator
from pathlib import Path

from speed_sign_detector.approach_sequences import (
    ApproachConfig,
    ApproachSceneError,
    ApproachStream,
)
from speed_sign_detector.bag_io import BAG_FORMATS
from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.synthetic import SyntheticFrame
from speed_sign_detector.tools.cli_types import (
    non_negative_integer,
    non_negative_number,
    option_names,
)
from speed_sign_detector.tools.progress import progress_bar
from speed_sign_detector.tools.synthetic_bag import write_drive
from speed_sign_detector.truth import write_truth

LOGGER = logging.getLogger(__name__)
#: The first argument of ``speed_sign_synth`` that selects this mode.
MODE = 'approach'
#: Names of :class:`ApproachConfig` fields in its messages -> the options that set them.
OPTION_OF_FIELD: dict[str, str] = {
    'frames_per_sequence': '--frames', 'gap_frames': '--gap-frames', 'fps': '--fps',
    'output size': 'output size (--width x --height)', 'growth_min': '--growth MIN',
    'growth_max': '--growth MAX', 'min_sign_px': '--min-sign-px',
    'max_sequences': '--max-sequences'}


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments of ``speed_sign_synth approach``."""
    defaults = ApproachConfig()
    parser = argparse.ArgumentParser(
        prog='speed_sign_synth approach',
        description='Turn an annotated scene folder (GTSDB format: images/ and gt.txt) '
        'into a bag of approach sequences (the view closing in on each speed-limit sign, '
        'resampled from the real pixels, with sign-free gaps) and its truth CSV.')
    parser.add_argument('scenes_dir', type=Path, metavar='SCENES',
                        help='input: GTSDB-format folder (images/, gt.txt)')
    parser.add_argument('out_bag', type=Path, metavar='OUT', help='output path: the bag '
                        'to create (a directory for ROS 2, a .bag file for ROS 1); must '
                        'not exist')
    parser.add_argument('--truth', type=Path, help='write the truth CSV here')
    parser.add_argument('--scenes', action='append', default=[], metavar='FILE[,FILE...]',
                        help='only these image files of gt.txt (repeatable, comma-separated)')
    parser.add_argument('--max-sequences', type=non_negative_integer, default=0,
                        help='stop after this many sequences (default: all)')
    parser.add_argument('--frames', type=int, default=defaults.frames_per_sequence,
                        help=f'frames per approach (default {defaults.frames_per_sequence})')
    parser.add_argument('--gap-frames', type=int, default=defaults.gap_frames,
                        help=f'sign-free frames after each approach (default '
                        f'{defaults.gap_frames})')
    parser.add_argument('--fps', type=float, default=defaults.fps,
                        help=f'frame rate (default {defaults.fps:g})')
    parser.add_argument('--min-sign-px', type=non_negative_number,
                        default=defaults.min_sign_px,
                        help=f'smallest sign approached, mean of box width and height '
                        f'(default {defaults.min_sign_px:g})')
    parser.add_argument('--growth', type=float, nargs=2, metavar=('MIN', 'MAX'),
                        default=(defaults.growth_min, defaults.growth_max),
                        help='range of the sign\'s growth over an approach (default '
                        f'{defaults.growth_min:g} {defaults.growth_max:g})')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--width', type=int, default=defaults.width_px, help='image width, px')
    parser.add_argument('--height', type=int, default=defaults.height_px,
                        help='image height, px')
    parser.add_argument('--format', dest='bag_format', choices=BAG_FORMATS, default='mcap',
                        help='bag format (default mcap)')
    parser.add_argument('--compressed', action='store_true',
                        help='write sensor_msgs/CompressedImage (JPEG) instead of raw bgr8')
    parser.add_argument('--topic', help='image topic (default as speed_sign_synth)')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress on stderr')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_synth approach``; returns the exit status."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s',
                        stream=sys.stderr)
    scenes = tuple(name.strip() for value in args.scenes for name in value.split(',')
                   if name.strip())
    try:
        config = ApproachConfig(frames_per_sequence=args.frames, gap_frames=args.gap_frames,
                                fps=args.fps, width_px=args.width, height_px=args.height,
                                min_sign_px=args.min_sign_px, growth_min=args.growth[0],
                                growth_max=args.growth[1], seed=args.seed, scenes=scenes,
                                max_sequences=args.max_sequences)
    except ApproachSceneError as err:
        print(f'speed_sign_synth approach: error: {option_names(str(err), OPTION_OF_FIELD)}',
              file=sys.stderr)
        return 2
    written = 0
    try:
        stream = ApproachStream(args.scenes_dir, config)
        if not stream.sequences:
            raise ApproachSceneError(
                f'no speed-limit sign of at least {config.min_sign_px:g} px in '
                f'{args.scenes_dir}' + (f' ({len(stream.unreadable_scenes)} scene(s) could '
                                        f'not be read)' if stream.unreadable_scenes else ''))
        bar = progress_bar(stream.frame_count, 'frames', 'frame', enabled=not args.quiet)

        def counted() -> Iterator[SyntheticFrame]:
            nonlocal written
            for frame in stream:
                yield frame
                written += 1
                bar.update(1)

        try:
            rows = write_drive(counted(), args.out_bag, args.bag_format, args.compressed,
                               args.topic)
        finally:
            bar.close()
        if args.truth is not None:
            write_truth(args.truth, rows, comments=[
                f'speed_sign_synth approach {args.scenes_dir} seed={config.seed} '
                f'frames={config.frames_per_sequence} gap_frames={config.gap_frames} '
                f'fps={config.fps:g} min_sign_px={config.min_sign_px:g} growth='
                f'{config.growth_min:g}-{config.growth_max:g} size={config.width_px}x'
                f'{config.height_px}',
                *(f'sequence {sequence.index}: {sequence.scene_file} {sequence.sign.limit_kmh} '
                  f'km/h sign of {sequence.sign.x2_px - sequence.sign.x1_px:.0f} px, growth '
                  f'{sequence.growth:.2f}, frames {sequence.first_frame}-'
                  f'{sequence.first_frame + sequence.frame_count - 1}'
                  + (' (gap blurred)' if sequence.gap_blurred else '')
                  for sequence in stream.sequences)])
    except SpeedSignError as err:
        print(f'speed_sign_synth approach: error: {err}' + (
            f' ({written} frames were written to {args.out_bag})' if written else ''),
            file=sys.stderr)
        return 1
    count = len(stream.sequences)
    print(f'wrote {written} frames ({count} approach sequence{"" if count == 1 else "s"} of '
          f'{config.frames_per_sequence} frames + {config.gap_frames} gap frames at '
          f'{config.fps:g} fps) from {args.scenes_dir} to {args.out_bag}'
          + (f'; truth in {args.truth}' if args.truth else ''), file=sys.stderr)
    if stream.unreadable_scenes:
        print(f'speed_sign_synth approach: error: {len(stream.unreadable_scenes)} scene(s) '
              f'could not be read and were skipped: {", ".join(stream.unreadable_scenes)}',
              file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
