"""``speed_sign_synth``: write a synthetic drive as a bag, with its truth file.

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
:mod:`speed_sign_detector.truth`. The same arguments give the same bag.
"""
from __future__ import annotations

import argparse
import logging
import re
import sys
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector import __version__
from speed_sign_detector.bag_io import (
    BAG_FORMATS,
    COMPRESSED_IMAGE_MSGTYPE,
    IMAGE_MSGTYPE,
    BagWriter,
)
from speed_sign_detector.errors import BagError, SpeedSignError
from speed_sign_detector.ros.messages import build, image_message
from speed_sign_detector.synthetic import (
    LIGHTING_CHOICES,
    DriveConfig,
    SyntheticDrive,
    SyntheticFrame,
)
from speed_sign_detector.tools.output_paths import (
    prepare_output_bag,
    prepare_output_file,
)
from speed_sign_detector.tools.progress import progress_bar
from speed_sign_detector.truth import TruthRow, write_truth

LOGGER = logging.getLogger(__name__)
DEFAULT_TOPIC = '/camera/image_raw'
JPEG_QUALITY = 90
#: Names of :class:`DriveConfig` fields in its messages -> the options that set them.
OPTION_OF_FIELD: dict[str, str] = {'duration_s': '--duration', 'speed_mps': '--speed',
                                   'fps': '--fps', 'lighting': '--lighting',
                                   'image size': 'image size (--width x --height)'}
#: The file name ending of a ROS 1 bag.
ROS1_SUFFIX = '.bag'


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments of ``speed_sign_synth``."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_synth',
        description='Write a deterministic synthetic drive (640x480 camera approaching '
        'speed-limit signs, look-alikes and distractors) as a bag, with its truth file.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('out_bag', type=Path, help='bag to create (a folder for ROS 2, a '
                        '.bag file for ROS 1: .bag is added when missing); must not exist')
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


def write_drive(frames: Iterable[SyntheticFrame], out_bag: Path, bag_format: str = 'mcap',
                compressed: bool = False, topic: str | None = None,
                progress: bool = False) -> list[TruthRow]:
    """Write frames (a :class:`SyntheticDrive`, or frames rendered before) into a new bag.

    Args:
        frames: the frames, in order (a drive renders them while they are written).
        out_bag: the bag to create.
        bag_format: one of :data:`speed_sign_detector.bag_io.BAG_FORMATS`.
        compressed: JPEG CompressedImage messages instead of raw ``bgr8`` Images.
        topic: image topic name (default :data:`DEFAULT_TOPIC`, ``.../compressed``).
        progress: show a progress bar on stderr (when it is a terminal).

    Returns:
        The truth rows of the whole drive, in frame order.

    Raises:
        BagError: the bag cannot be created or written.
    """
    topic = topic or (f'{DEFAULT_TOPIC}/compressed' if compressed else DEFAULT_TOPIC)
    rows: list[TruthRow] = []
    with BagWriter(out_bag, bag_format) as writer:
        msgtype = COMPRESSED_IMAGE_MSGTYPE if compressed else IMAGE_MSGTYPE
        writer.add_topic(topic, msgtype)
        message_class = writer.message_class(msgtype)
        total = frames.frame_count if isinstance(frames, SyntheticDrive) else None
        bar = progress_bar(total, 'frames', 'frame', enabled=progress)
        for frame in frames:
            header = writer.header(frame.stamp_ns, frame_id='camera')
            if compressed:
                ok, encoded = cv2.imencode('.jpg', frame.bgr,
                                           [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
                if not ok:
                    raise BagError(f'JPEG encoding of frame {frame.index} failed')
                message = build(message_class, header=header, format='bgr8; jpeg compressed bgr8',
                                data=np.asarray(encoded, np.uint8).reshape(-1))
            else:
                message = image_message(frame.bgr, header, image_class=message_class)
            writer.write(topic, frame.stamp_ns, message)
            rows.extend(frame.truth)
            bar.update(1)
        bar.close()
    return rows


def bag_path_for_format(out_bag: Path, bag_format: str) -> Path:
    """The bag path to write: for ROS 1, ``.bag`` added when missing."""
    if bag_format == 'ros1' and out_bag.suffix != ROS1_SUFFIX:
        return out_bag.with_name(out_bag.name + ROS1_SUFFIX)
    return out_bag


def option_names(message: str) -> str:
    """A :class:`DriveConfig` message with its field names replaced by the options."""
    for field_name, option in OPTION_OF_FIELD.items():
        message = re.sub(rf'\b{re.escape(field_name)}\b', option, message)
    return message


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_synth``; returns the exit status.

    ``speed_sign_synth approach SCENES_DIR OUT_BAG ...`` makes approach sequences from
    real scenes instead (:mod:`speed_sign_detector.tools.synth_approach`).
    """
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['approach']:
        from speed_sign_detector.tools import synth_approach
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
        print(f'speed_sign_synth: error: {option_names(str(err))}', file=sys.stderr)
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
