"""FrameResult -> ROS messages, built with rclpy classes and with rosbags classes.

Each message goes through its own CDR serialization and is read back.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import Image, PointCloud2, PointField
from std_msgs.msg import Header, UInt16

from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.image_conversion import image_to_gray
from speed_sign_detector.pipeline import Detection, FrameResult
from speed_sign_detector.recognition.classifier import Classification
from speed_sign_detector.ros.messages import (
    CANDIDATE_DTYPE,
    DiagnosticsSnapshot,
    candidates_message,
    debug_image_message,
    diagnostics_message,
    pointcloud_to_array,
    speed_limit_message,
)

pytestmark = pytest.mark.ros

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
BAG = {name.rsplit('/', 1)[1]: cls for name, cls in TYPESTORE.types.items()
       if name.startswith(('sensor_msgs/msg/', 'std_msgs/msg/', 'diagnostic_msgs/msg/',
                           'builtin_interfaces/msg/'))}
RCLPY = {'Image': Image, 'PointCloud2': PointCloud2, 'PointField': PointField,
         'UInt16': UInt16, 'DiagnosticArray': DiagnosticArray,
         'DiagnosticStatus': DiagnosticStatus, 'KeyValue': KeyValue}
FLAVOURS = ('rclpy', 'rosbags')


def classes(flavour: str) -> dict[str, type]:
    return RCLPY if flavour == 'rclpy' else BAG


def header(flavour: str) -> Any:
    if flavour == 'rclpy':
        msg = Header(frame_id='cam')
        msg.stamp.sec, msg.stamp.nanosec = 12, 345
        return msg
    return BAG['Header'](stamp=BAG['Time'](sec=12, nanosec=345), frame_id='cam')


def round_trip(flavour: str, msg: Any) -> Any:
    if flavour == 'rclpy':
        return deserialize_message(serialize_message(msg), type(msg))
    return TYPESTORE.deserialize_cdr(TYPESTORE.serialize_cdr(msg, msg.__msgtype__),
                                     msg.__msgtype__)


def frame_result() -> FrameResult:
    limit = Classification('80', 80, 14.5, 21.0, -3.0, 4.0, 101.0, 52.0)
    other = Classification('no_entry', None, 9.0, 11.0, 0.0, 2.0, 30.0, 40.0)
    detections = (Detection(Candidate(100.5, 51.5, 20.0, 3.5, 2), limit),
                  Detection(Candidate(30.0, 40.0, 11.0, 1.5, 1), other),
                  Detection(Candidate(70.0, 20.0, 8.0, 0.5, 0), None))
    return FrameResult(stamp_s=12.0, width_px=160, height_px=120, detections=detections,
                       tracks=(), active_limit_kmh=80, recognized_limit_kmh=80,
                       timings_ms={'detect': 1.0, 'classify': 2.0, 'track': 0.1, 'total': 3.1})


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_candidates_cloud_is_typed_and_readable(flavour: str) -> None:
    found = classes(flavour)
    msg = round_trip(flavour, candidates_message(
        frame_result(), header(flavour), pointcloud_class=found['PointCloud2'],
        pointfield_class=found['PointField']))
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == \
        (12, 345, 'cam')
    assert (msg.height, msg.width, msg.point_step) == (1, 3, CANDIDATE_DTYPE.itemsize)
    assert [field.name for field in msg.fields] == list(CANDIDATE_DTYPE.names)
    points = pointcloud_to_array(msg)
    np.testing.assert_allclose(points['u'], [100.5, 30.0, 70.0])
    np.testing.assert_allclose(points['v'], [51.5, 40.0, 20.0])
    np.testing.assert_allclose(points['radius'], [20.0, 11.0, 8.0])
    np.testing.assert_allclose(points['score'], [3.5, 1.5, 0.5])
    assert points['limit_kmh'].tolist() == [80, 0, 0]
    assert points['limit_kmh'].dtype == np.uint16
    np.testing.assert_allclose(points['psr'][:2], [14.5, 9.0])
    assert np.isnan(points['psr'][2]) and np.isnan(points['rotation_deg'][2])
    np.testing.assert_allclose(points['rotation_deg'][:2], [-3.0, 0.0])


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_empty_frame_gives_an_empty_cloud(flavour: str) -> None:
    found = classes(flavour)
    empty = FrameResult(12.0, 160, 120, (), (), 0, 0, {})
    msg = round_trip(flavour, candidates_message(
        empty, header(flavour), pointcloud_class=found['PointCloud2'],
        pointfield_class=found['PointField']))
    assert msg.width == 0 and pointcloud_to_array(msg).size == 0


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_speed_limit_and_debug_image(flavour: str) -> None:
    found = classes(flavour)
    assert round_trip(flavour, speed_limit_message(
        130, uint16_class=found['UInt16'])).data == 130
    gray = np.full((120, 160), 90, np.uint8)
    msg = round_trip(flavour, debug_image_message(gray, frame_result(), header(flavour),
                                                  image_class=found['Image']))
    assert (msg.encoding, msg.width, msg.height, msg.step) == ('bgr8', 160, 120, 480)
    assert msg.header.frame_id == 'cam'
    drawn = image_to_gray(msg)
    assert drawn.shape == gray.shape and np.any(drawn != 90)


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_diagnostics(flavour: str) -> None:
    found = classes(flavour)
    snapshot = DiagnosticsSnapshot(name='speed_sign_detector: pipeline',
                                   hardware_id='gl: llvmpipe', level='WARN',
                                   message='no image for 6 s',
                                   values={'frames_processed': '10', 'backend': 'gl'})
    msg = round_trip(flavour, diagnostics_message(
        snapshot, header(flavour), array_class=found['DiagnosticArray'],
        status_class=found['DiagnosticStatus'], key_value_class=found['KeyValue']))
    [status] = msg.status
    assert status.level == found['DiagnosticStatus'].WARN
    assert (status.name, status.message, status.hardware_id) == (
        'speed_sign_detector: pipeline', 'no image for 6 s', 'gl: llvmpipe')
    assert {kv.key: kv.value for kv in status.values} == {'frames_processed': '10',
                                                          'backend': 'gl'}
