"""Pipeline results -> ROS messages, for rclpy message classes and rosbags classes alike.

The live node builds rclpy messages; the bag tools write the same topics into bags with
rosbags typestore classes. Every function here therefore takes the message class(es) to
build as arguments and imports no message package: the field values are computed once,
and only the last step (:func:`build`) adapts them to the class (rclpy wants
``array.array('B')`` for byte arrays and ``bytes`` for a ``byte`` field, rosbags wants
numpy arrays and ints).

Outputs of one frame carry the input image's header (pass it as ``header``).

Topics and contents:
    ``candidates``: sensor_msgs/PointCloud2, one point per candidate with the fields of
        :data:`CANDIDATE_DTYPE` (read back with :func:`pointcloud_to_array`).
    ``speed_limit``: std_msgs/UInt16, the active limit in km/h, 0 = none known.
    ``debug_image``: sensor_msgs/Image bgr8, the frame with candidates and limit drawn.
    ``/diagnostics``: diagnostic_msgs/DiagnosticArray from a :class:`DiagnosticsSnapshot`.
"""
from __future__ import annotations

import array
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from speed_sign_detector.image_conversion import image_fields
from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.visualization import draw_frame_result

#: One candidate as a PointCloud2 point (little endian, 28 bytes):
#: ``u``, ``v``: centre column and row, pixels; ``radius``: pixels; ``score``: detector
#: score; ``limit_kmh``: the classified limit, 0 when the candidate is not a limit or not
#: classified; ``psr``: peak-to-sidelobe ratio of the classification (NaN when not
#: classified); ``rotation_deg``: in-plane rotation of the winning filter (NaN when not
#: classified).
CANDIDATE_DTYPE = np.dtype({
    'names': ['u', 'v', 'radius', 'score', 'limit_kmh', 'psr', 'rotation_deg'],
    'formats': ['<f4', '<f4', '<f4', '<f4', '<u2', '<f4', '<f4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24],
    'itemsize': 28,
})

#: sensor_msgs/PointField datatype constants <-> numpy (little-endian) types.
POINT_FIELD_TYPES: dict[int, str] = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4',
                                     7: 'f4', 8: 'f8'}
_NUMPY_TO_POINT_FIELD = {np.dtype(code).str[1:]: datatype
                         for datatype, code in POINT_FIELD_TYPES.items()}


def is_rosbags_class(message_class: type) -> bool:
    """True for a rosbags typestore class (dataclass with ``__msgtype__``), False for rclpy."""
    return hasattr(message_class, '__msgtype__')


def build(message_class: type, **fields: Any) -> Any:
    """Construct ``message_class`` from plain field values, adapting byte arrays.

    ``numpy.ndarray`` values of dtype uint8 become ``array.array('B')`` for rclpy classes
    (its fast path; a bytes object would be checked element by element) and stay numpy
    arrays for rosbags classes. Every field of a rosbags class must be given.
    """
    if not is_rosbags_class(message_class):
        fields = {name: array.array('B', value.tobytes())
                  if isinstance(value, np.ndarray) and value.dtype == np.uint8 else value
                  for name, value in fields.items()}
    return message_class(**fields)


def candidate_points(result: FrameResult) -> np.ndarray:
    """This frame's candidates as a structured array of :data:`CANDIDATE_DTYPE`, best first."""
    points = np.zeros(len(result.detections), dtype=CANDIDATE_DTYPE)
    for index, detection in enumerate(result.detections):
        candidate, classification = detection.candidate, detection.classification
        points[index]['u'] = candidate.x_px
        points[index]['v'] = candidate.y_px
        points[index]['radius'] = candidate.radius_px
        points[index]['score'] = candidate.score
        if classification is None:
            points[index]['psr'] = math.nan
            points[index]['rotation_deg'] = math.nan
        else:
            points[index]['limit_kmh'] = classification.limit_kmh or 0
            points[index]['psr'] = classification.psr
            points[index]['rotation_deg'] = classification.rotation_deg
    return points


def candidates_message(result: FrameResult, header: Any, *, pointcloud_class: type,
                       pointfield_class: type) -> Any:
    """sensor_msgs/PointCloud2 of the frame's candidates (unordered cloud: height 1).

    Args:
        result: the pipeline's result for the frame.
        header: the input image's header (copied as is).
        pointcloud_class, pointfield_class: PointCloud2 and PointField classes (rclpy
            or rosbags).
    """
    points = candidate_points(result)
    fields = [build(pointfield_class, name=name,
                    offset=int(CANDIDATE_DTYPE.fields[name][1]),
                    datatype=_NUMPY_TO_POINT_FIELD[CANDIDATE_DTYPE.fields[name][0].str[1:]],
                    count=1)
              for name in CANDIDATE_DTYPE.names]
    return build(pointcloud_class, header=header, height=1, width=len(points), fields=fields,
                 is_bigendian=False, point_step=CANDIDATE_DTYPE.itemsize,
                 row_step=CANDIDATE_DTYPE.itemsize * len(points),
                 data=np.frombuffer(points.tobytes(), dtype=np.uint8), is_dense=True)


def pointcloud_to_array(msg: Any) -> np.ndarray:
    """Read any PointCloud2 (rclpy or rosbags) into a structured numpy array.

    Returns:
        Shape (height * width,), dtype built from the message's ``fields`` (each field
        with ``count`` 1 is a scalar column, larger counts a sub-array).

    Raises:
        ValueError: for an unknown PointField datatype or data shorter than declared.
    """
    byte_order = '>' if msg.is_bigendian else '<'
    names, formats, offsets = [], [], []
    for point_field in msg.fields:
        code = POINT_FIELD_TYPES.get(int(point_field.datatype))
        if code is None:
            raise ValueError(f'PointField {point_field.name!r} has unknown datatype '
                             f'{point_field.datatype}')
        count = int(point_field.count) or 1
        names.append(str(point_field.name))
        formats.append((byte_order + code, (count,)) if count > 1 else byte_order + code)
        offsets.append(int(point_field.offset))
    dtype = np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                      'itemsize': int(msg.point_step)})
    count = int(msg.width) * int(msg.height)
    data = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, np.ndarray)
                         else msg.data.tobytes(), dtype=np.uint8)
    if data.size < count * dtype.itemsize:
        raise ValueError(f'PointCloud2 data holds {data.size} B, {count} points of '
                         f'{dtype.itemsize} B need {count * dtype.itemsize} B')
    return np.frombuffer(data[:count * dtype.itemsize].tobytes(), dtype=dtype)


def speed_limit_message(limit_kmh: int, *, uint16_class: type) -> Any:
    """std_msgs/UInt16 holding the active limit in km/h (0 = none known)."""
    return build(uint16_class, data=int(limit_kmh))


def image_message(array_bgr_or_gray: np.ndarray, header: Any, *, image_class: type) -> Any:
    """sensor_msgs/Image (``bgr8`` or ``mono8``) of an array, with the given header."""
    return build(image_class, header=header, **image_fields(array_bgr_or_gray))


def debug_image_message(frame: np.ndarray, result: FrameResult, header: Any, *,
                        image_class: type) -> Any:
    """sensor_msgs/Image bgr8 of the frame with the result drawn on it, with the input header.

    Args:
        frame: the processed frame, gray (H, W) or BGR (H, W, 3), uint8.
        result: the pipeline's result for it (drawn by
            :func:`speed_sign_detector.visualization.draw_frame_result`).
    """
    return image_message(draw_frame_result(frame, result), header, image_class=image_class)


@dataclass(frozen=True)
class DiagnosticsSnapshot:
    """The node's health at one moment, as published on ``/diagnostics``.

    Attributes:
        name: status name (``'<node name>: pipeline'``).
        hardware_id: what runs the voting (backend and renderer).
        level: ``'OK'``, ``'WARN'``, ``'ERROR'`` or ``'STALE'``.
        message: one-line summary.
        values: the key/value pairs (frames processed and dropped, fps, latency
            percentiles in ms, backend, renderer, last error, ...), already formatted.
    """

    name: str
    hardware_id: str
    level: str
    message: str
    values: Mapping[str, str]


def diagnostics_message(snapshot: DiagnosticsSnapshot, header: Any, *, array_class: type,
                        status_class: type, key_value_class: type) -> Any:
    """diagnostic_msgs/DiagnosticArray with one status built from ``snapshot``.

    ``level`` is looked up on ``status_class`` (``OK`` is ``b'\\x00'`` in rclpy and
    ``0`` in rosbags).
    """
    status = build(status_class, level=getattr(status_class, snapshot.level),
                   name=snapshot.name, message=snapshot.message,
                   hardware_id=snapshot.hardware_id,
                   values=[build(key_value_class, key=key, value=str(value))
                           for key, value in snapshot.values.items()])
    return build(array_class, header=header, status=[status])
