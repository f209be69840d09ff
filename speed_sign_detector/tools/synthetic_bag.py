"""Writing rendered frames into a new bag, with their truth rows: what both modes of
``speed_sign_synth`` share (a synthetic drive, :mod:`speed_sign_detector.tools.synth`;
approach sequences from real scenes, :mod:`speed_sign_detector.tools.synth_approach`).

Kept apart from both so that neither tool module imports the other's.
"""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.bag_io import (
    COMPRESSED_IMAGE_MSGTYPE,
    IMAGE_MSGTYPE,
    BagWriter,
)
from speed_sign_detector.errors import BagError
from speed_sign_detector.ros.messages import build, image_message
from speed_sign_detector.synthetic import SyntheticDrive, SyntheticFrame
from speed_sign_detector.tools.progress import progress_bar
from speed_sign_detector.truth import TruthRow

DEFAULT_TOPIC = '/camera/image_raw'
JPEG_QUALITY = 90


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
