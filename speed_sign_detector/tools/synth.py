"""``speed_sign_synth``: write a synthetic drive as a bag, with its truth file; or, as
``speed_sign_synth approach SCENES OUT``, approach sequences from real scenes
(:mod:`speed_sign_detector.tools.synth_approach`). In both modes OUT, the first path
given to the mode, is the bag to write (``drive_day`` below is a path, not a mode).

Example::

    speed_sign_synth drive_day --truth drive_day.csv --seed 1 --duration 20 --fps 30
    speed_sign_synth drive_night.bag --format ros1 --lighting night --compressed
    speed_sign_synth approach ../shared/data/gtsdb-dev approach_bag --truth approach.csv

A ROS 1 bag is a file whose name ends in ``.bag`` (rosbags tells the formats apart by
it): with ``--format ros1`` the suffix is added when it is missing. A ROS 2 bag is a
folder. The output paths are checked before the first frame is drawn; missing parent
folders are created. Ctrl-C stops the drive with exit status 130 and leaves a valid bag
of the frames written so far.

The scene (road, signs, look-alikes, distractors, lighting, blur, noise) is described
in :mod:`speed_sign_detector.synthetic`, the truth format in
:mod:`speed_sign_detector.truth`, the bag writing (shared by both modes) in
:mod:`speed_sign_detector.tools.synthetic_bag`. The same arguments give the same bag.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from speed_sign_detector import __version__
from speed_sign_detector.bag_io import BAG_FORMATS
from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.synthetic import LIGHTING_CHOICES, DriveConfig, SyntheticDrive
from speed_sign_detector.tools import synth_approach
from speed_sign_detector.tools.cli_types import option_names
from speed_sign_detector.tools.output_paths import (
    prepare_output_bag,
    prepare_output_file,
)
from speed_sign_detector.tools.synthetic_bag import DEFAULT_TOPIC, JPEG_QUALITY, write_drive
from speed_sign_detector.truth import write_truth

__all__ = ['DEFAULT_TOPIC', 'JPEG_QUALITY', 'build_parser', 'main', 'write_drive']

LOGGER = logging.getLogger(__name__)
#: Names of :class:`DriveConfig` fields in its messages -> the options that set them.
OPTION_OF_FIELD: dict[str, str] = {'duration_s': '--duration', 'speed_mps': '--speed',
                                   'fps': '--fps', 'lighting': '--lighting',
                                   'image size': 'image size (--width x --height)'}
#: The file name ending of a ROS 1 bag.
ROS1_SUFFIX = '.bag'
USAGE = ('%(prog)s [options] OUT                  (1: a synthetic drive)\n'
         f'       %(prog)s {synth_approach.MODE} SCENES OUT [options]  (2: from real scenes)')
HELP_DESCRIPTION = f"""\
Two modes; in both, OUT is the output path: the bag to create.

1. speed_sign_synth OUT [options]: write a deterministic synthetic drive (a 640x480
   camera approaching speed-limit signs, look-alikes and distractors) to the bag OUT,
   with its truth file (--truth). The options below belong to this mode.
2. speed_sign_synth {synth_approach.MODE} SCENES OUT [options]: turn an annotated
   scene folder SCENES (GTSDB format: images/ and gt.txt) into a bag OUT of approach
   sequences closing in on each real speed-limit sign. Its options:
   speed_sign_synth {synth_approach.MODE} --help.
"""
HELP_EPILOG = f"""\
examples:
  speed_sign_synth drive_day --truth drive_day.csv --seed 1 --duration 20
      (drive_day is the output bag, not a mode)
  speed_sign_synth {synth_approach.MODE} ../shared/data/gtsdb-dev approach_bag --truth approach.csv
"""


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments of ``speed_sign_synth``."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_synth', usage=USAGE, description=HELP_DESCRIPTION,
        epilog=HELP_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('out_bag', type=Path, metavar='OUT', help='output path: the bag to '
                        'create (a folder for ROS 2, a .bag file for ROS 1: .bag is added '
                        'when missing); must not exist')
    parser.add_argument('--truth', type=Path, help='write the truth CSV here (replaced '
                        'when it exists)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--duration', type=float, default=20.0,
                        help='length of the drive, seconds (default 20)')
    parser.add_argument('--fps', type=float, default=30.0, help='camera rate (default 30)')
    parser.add_argument('--lighting', choices=LIGHTING_CHOICES, default='day',
                        help='day, dusk, night, or mixed (day to night over the drive; '
                        'default day)')
    parser.add_argument('--format', dest='bag_format', choices=BAG_FORMATS, default='mcap',
                        help='bag format (default mcap)')
    parser.add_argument('--compressed', action='store_true',
                        help='write sensor_msgs/CompressedImage (JPEG) instead of raw bgr8')
    parser.add_argument('--topic', help=f'image topic (default {DEFAULT_TOPIC}, '
                        f'{DEFAULT_TOPIC.rsplit("/", 1)[0]}/image_raw/compressed with '
                        f'--compressed)')
    parser.add_argument('--width', type=int, default=640,
                        help='image width, px (default 640)')
    parser.add_argument('--height', type=int, default=480,
                        help='image height, px (default 480)')
    parser.add_argument('--speed', type=float, default=12.0,
                        help='mean driving speed, m/s (default 12)')
    parser.add_argument('--no-distractors', action='store_true',
                        help='leave out lamps, mirrors, the vehicle ahead and stickers')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress on stderr')
    return parser


def bag_path_for_format(out_bag: Path, bag_format: str) -> Path:
    """The bag path to write: for ROS 1, ``.bag`` added when missing."""
    if bag_format == 'ros1' and out_bag.suffix != ROS1_SUFFIX:
        return out_bag.with_name(out_bag.name + ROS1_SUFFIX)
    return out_bag


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_synth``; returns the exit status.

    ``speed_sign_synth approach SCENES_DIR OUT_BAG ...`` makes approach sequences from
    real scenes instead (:mod:`speed_sign_detector.tools.synth_approach`).
    """
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == [synth_approach.MODE]:
        return synth_approach.main(argv[1:])
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s',
                        stream=sys.stderr)
    try:
        config = DriveConfig(seed=args.seed, duration_s=args.duration, fps=args.fps,
                             lighting=args.lighting, width_px=args.width,
                             height_px=args.height, speed_mps=args.speed,
                             distractors=not args.no_distractors)
    except ValueError as err:
        print(f'speed_sign_synth: error: {option_names(str(err), OPTION_OF_FIELD)}',
              file=sys.stderr)
        return 2
    out_bag = args.out_bag
    try:
        out_bag = prepare_output_bag(bag_path_for_format(args.out_bag, args.bag_format),
                                     'output bag')
        if args.truth is not None:
            prepare_output_file(args.truth, '--truth')
        if out_bag != args.out_bag:
            LOGGER.info('writing the ROS 1 bag as %s (ROS 1 bags end in .bag)', out_bag)
        drive = SyntheticDrive(config)
        rows = write_drive(drive, out_bag, args.bag_format, args.compressed, args.topic,
                           progress=not args.quiet)
        if args.truth is not None:
            write_truth(args.truth, rows, comments=[
                f'speed_sign_synth seed={config.seed} duration_s={config.duration_s} '
                f'fps={config.fps} lighting={config.lighting} size={config.width_px}x'
                f'{config.height_px} speed_mps={config.speed_mps}'])
    except SpeedSignError as err:
        print(f'speed_sign_synth: error: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'speed_sign_synth: interrupted; {out_bag} holds the frames written so far '
              f'(no truth file written)', file=sys.stderr)
        return 130
    limits = [sign for sign in drive.signs if sign.limit_kmh]
    print(f'wrote {drive.frame_count} frames ({config.duration_s:g} s at {config.fps:g} fps, '
          f'{config.lighting}) to {out_bag}: {len(limits)} speed-limit signs'
          + (f' ({", ".join(sign.kind for sign in limits)})' if limits else '') + ', '
          f'{len(drive.signs) - len(limits)} look-alikes'
          + (f'; truth in {args.truth}' if args.truth else ''), file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
