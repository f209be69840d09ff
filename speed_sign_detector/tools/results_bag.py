"""The results bag of ``speed_sign_eval bag --out``: the node's outputs at the input stamps.

A ROS 2 MCAP bag (:class:`ResultsBagWriter`) with, per processed frame:

- ``/candidates`` (sensor_msgs/PointCloud2, every frame) and ``/speed_limit``
  (std_msgs/UInt16, transient local; on the first frame and on every change of the
  active limit), as the node publishes them;
- with ``debug_images``: ``/debug_image`` (sensor_msgs/Image bgr8, the node's drawing);
- with ``with_images``: ``/image/compressed`` (sensor_msgs/CompressedImage: the input
  image's own JPEG/PNG bytes, or the raw input encoded as JPEG) and
  ``/image/annotations`` (foxglove_msgs/ImageAnnotations, see
  :mod:`speed_sign_detector.tools.foxglove_annotations`), so that Foxglove's Image panel
  shows the drive with the detections drawn over it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from speed_sign_detector.bag_io import COMPRESSED_IMAGE_MSGTYPE, BagWriter
from speed_sign_detector.errors import BagError
from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.ros import messages
from speed_sign_detector.tools.foxglove_annotations import (
    IMAGE_ANNOTATIONS_MSGTYPE,
    image_annotations_message,
    register_foxglove_types,
)

__all__ = ['OUTPUT_TOPICS', 'ResultsBagWriter', 'compressed_image_bytes']

#: Topic of each output in the results bag.
OUTPUT_TOPICS: dict[str, str] = {
    'candidates': '/candidates', 'speed_limit': '/speed_limit', 'debug_image': '/debug_image',
    'image': '/image/compressed', 'annotations': '/image/annotations'}
#: JPEG quality of raw input images written with ``with_images``.
JPEG_QUALITY = 90
_JPEG_MAGIC = b'\xff\xd8'
_PNG_MAGIC = b'\x89PNG'


def compressed_image_bytes(message: Any, gray: np.ndarray) -> tuple[str, np.ndarray]:
    """(format, bytes) of an input image for a CompressedImage: its own bytes when it is
    a JPEG or PNG CompressedImage; else a JPEG of the raw image (colour for ``bgr8`` and
    ``rgb8``, the processed gray frame for other encodings).

    Raises:
        BagError: the frame cannot be encoded.
    """
    if getattr(message, '__msgtype__', '') == COMPRESSED_IMAGE_MSGTYPE:
        data = np.asarray(message.data, dtype=np.uint8).reshape(-1)
        head = data[:4].tobytes()
        if head.startswith(_JPEG_MAGIC):
            return 'jpeg', data
        if head.startswith(_PNG_MAGIC):
            return 'png', data
    picture = gray
    encoding = str(getattr(message, 'encoding', ''))
    if encoding in ('bgr8', 'rgb8'):
        height, width = int(message.height), int(message.width)
        rows = np.asarray(message.data, dtype=np.uint8).reshape(height, int(message.step))
        picture = rows[:, :3 * width].reshape(height, width, 3)
        if encoding == 'rgb8':
            picture = picture[..., ::-1]
    ok, encoded = cv2.imencode('.jpg', np.ascontiguousarray(picture),
                               [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise BagError('JPEG encoding of an input frame failed')
    return 'jpeg', np.asarray(encoded, dtype=np.uint8).reshape(-1)


class ResultsBagWriter:
    """Writes the outputs of each processed frame into a new ROS 2 MCAP bag.

    Args:
        path: the bag to create (must not exist).
        debug_images: also write ``/debug_image``.
        with_images: also write the input images and Foxglove annotations.

    Raises:
        BagError: the bag cannot be created.
    """

    def __init__(self, path: Path, debug_images: bool = False,
                 with_images: bool = False) -> None:
        self.writer = BagWriter(path, 'mcap')
        self.debug_images = debug_images
        self.with_images = with_images
        writer = self.writer
        try:
            writer.add_topic(OUTPUT_TOPICS['candidates'], 'sensor_msgs/msg/PointCloud2')
            writer.add_topic(OUTPUT_TOPICS['speed_limit'], 'std_msgs/msg/UInt16', latched=True)
            if debug_images:
                writer.add_topic(OUTPUT_TOPICS['debug_image'], 'sensor_msgs/msg/Image')
            if with_images:
                register_foxglove_types(writer.typestore)
                writer.add_topic(OUTPUT_TOPICS['image'], COMPRESSED_IMAGE_MSGTYPE)
                writer.add_topic(OUTPUT_TOPICS['annotations'], IMAGE_ANNOTATIONS_MSGTYPE)
        except BagError:
            writer.close()
            raise
        self._published_limit: int | None = None

    def write(self, stamp_ns: int, frame_id: str, gray: np.ndarray, result: FrameResult,
              input_message: Any = None) -> None:
        """Write one frame's outputs at its stamp.

        Args:
            stamp_ns: the input image's stamp, nanoseconds (log time and header stamp).
            frame_id: the input image's frame id.
            gray: the processed frame, (H, W) uint8.
            result: what the pipeline found in it.
            input_message: the input Image / CompressedImage (needed with ``with_images``).
        """
        writer = self.writer
        header = writer.header(stamp_ns, frame_id)
        writer.write(OUTPUT_TOPICS['candidates'], stamp_ns, messages.candidates_message(
            result, header, pointcloud_class=writer.message_class('sensor_msgs/msg/PointCloud2'),
            pointfield_class=writer.message_class('sensor_msgs/msg/PointField')))
        if result.active_limit_kmh != self._published_limit:
            writer.write(OUTPUT_TOPICS['speed_limit'], stamp_ns, messages.speed_limit_message(
                result.active_limit_kmh, uint16_class=writer.message_class('std_msgs/msg/UInt16')))
            self._published_limit = result.active_limit_kmh
        if self.debug_images:
            writer.write(OUTPUT_TOPICS['debug_image'], stamp_ns, messages.debug_image_message(
                gray, result, header, image_class=writer.message_class('sensor_msgs/msg/Image')))
        if self.with_images:
            image_format, data = compressed_image_bytes(input_message, gray)
            writer.write(OUTPUT_TOPICS['image'], stamp_ns, messages.build(
                writer.message_class(COMPRESSED_IMAGE_MSGTYPE), header=header,
                format=image_format, data=data))
            writer.write(OUTPUT_TOPICS['annotations'], stamp_ns,
                         image_annotations_message(result, stamp_ns, writer.typestore))

    def close(self) -> None:
        """Finish the bag (safe to call twice)."""
        self.writer.close()
