"""Image messages -> gray frames, with real rclpy messages and real rosbags messages.

Each encoding is built from a reference BGR picture the way a camera driver lays it out
(cv2 for YUV 4:2:2, an explicit mosaic for Bayer), sent through the message type's own
serialization (rclpy CDR, rosbags CDR) and converted back.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import CompressedImage as RclpyCompressedImage
from sensor_msgs.msg import Image as RclpyImage

from speed_sign_detector.errors import ImageConversionError
from speed_sign_detector.image_conversion import (
    ENCODINGS,
    compressed_to_gray,
    image_fields,
    image_to_gray,
    message_to_gray,
)
from speed_sign_detector.ros.messages import build

pytestmark = pytest.mark.ros

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
BagImage = TYPESTORE.types['sensor_msgs/msg/Image']
BagCompressedImage = TYPESTORE.types['sensor_msgs/msg/CompressedImage']
BagHeader = TYPESTORE.types['std_msgs/msg/Header']
BagTime = TYPESTORE.types['builtin_interfaces/msg/Time']

HEIGHT, WIDTH = 24, 32
BAYER_CHANNEL = {'r': 2, 'g': 1, 'b': 0}


def reference_bgr() -> np.ndarray:
    """Smooth coloured picture (H, W, 3) uint8: gradients plus a little noise."""
    rng = np.random.default_rng(7)
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    bgr = np.stack([cols * 255 / WIDTH, rows * 255 / HEIGHT,
                    (cols + rows) * 255 / (WIDTH + HEIGHT)], axis=2)
    return np.clip(bgr + rng.normal(0, 3, bgr.shape), 0, 255).astype(np.uint8)


def make_image(flavour: str, encoding: str, pixels: np.ndarray, *, padding: int = 0,
               bigendian: bool = False) -> Any:
    """Image message (rclpy or rosbags) of ``pixels`` (H, W[, C]); rows padded by bytes."""
    if pixels.dtype == np.uint16:
        pixels = pixels.astype('>u2' if bigendian else '<u2')
    height, width = pixels.shape[:2]
    rows = np.ascontiguousarray(pixels).view(np.uint8).reshape(height, -1)
    rows = np.concatenate([rows, np.full((height, padding), 0xAB, np.uint8)], axis=1)
    fields = dict(height=height, width=width, encoding=encoding, is_bigendian=int(bigendian),
                  step=rows.shape[1], data=rows.reshape(-1))
    return _round_trip(flavour, _message(flavour, 'image', fields))


def make_compressed(flavour: str, image_format: str, data: bytes) -> Any:
    """CompressedImage message (rclpy or rosbags) holding ``data``."""
    fields = dict(format=image_format, data=np.frombuffer(data, np.uint8))
    return _round_trip(flavour, _message(flavour, 'compressed', fields))


def _message(flavour: str, kind: str, fields: dict[str, Any]) -> Any:
    if flavour == 'rclpy':
        cls = RclpyImage if kind == 'image' else RclpyCompressedImage
        msg = build(cls, **fields)
        msg.header.frame_id = 'camera'
        return msg
    cls = BagImage if kind == 'image' else BagCompressedImage
    return build(cls, header=BagHeader(stamp=BagTime(sec=1, nanosec=2), frame_id='camera'),
                 **fields)


def _round_trip(flavour: str, msg: Any) -> Any:
    """Serialize and deserialize with the flavour's own CDR code (as DDS / a bag would)."""
    if flavour == 'rclpy':
        return deserialize_message(serialize_message(msg), type(msg))
    return TYPESTORE.deserialize_cdr(TYPESTORE.serialize_cdr(msg, msg.__msgtype__),
                                     msg.__msgtype__)


def bayer_mosaic(bgr: np.ndarray, pattern: str) -> np.ndarray:
    """Single-channel Bayer mosaic of ``bgr``; ``pattern`` names the 2x2 block row by row."""
    mosaic = np.zeros(bgr.shape[:2], bgr.dtype)
    for colour, (dy, dx) in zip(pattern, ((0, 0), (0, 1), (1, 0), (1, 1))):
        mosaic[dy::2, dx::2] = bgr[dy::2, dx::2, BAYER_CHANNEL[colour]]
    return mosaic


def _to16(pixels: np.ndarray) -> np.ndarray:
    """8-bit values into the high byte, noise in the low byte (which must be ignored)."""
    low = np.random.default_rng(3).integers(0, 256, pixels.shape)
    return (pixels.astype(np.uint16) << 8) | low.astype(np.uint16)


def studio_to_full(luma: np.ndarray) -> np.ndarray:
    """BT.601 studio-range luma (16..235) stretched to 0..255."""
    return np.clip(np.round((luma.astype(float) - 16) * 255 / 219), 0, 255).astype(np.uint8)


#: encoding -> (pixels as the driver sends them, expected gray)
def encoded_cases() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    bgr = reference_bgr()
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    bgra = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
    uyvy = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_UYVY)
    yuyv = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_YUYV)
    return {
        'mono8': (gray, gray),
        'mono16': (_to16(gray), gray),
        'bgr8': (bgr, gray),
        'rgb8': (bgr[:, :, ::-1].copy(), gray),
        'bgra8': (bgra, gray),
        'rgba8': (cv2.cvtColor(bgr, cv2.COLOR_BGR2RGBA), gray),
        'bgr16': (_to16(bgr), gray),
        'rgb16': (_to16(bgr[:, :, ::-1].copy()), gray),
        'bgra16': (_to16(bgra), gray),
        'rgba16': (_to16(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGBA)), gray),
        'yuv422': (uyvy, studio_to_full(uyvy[:, :, 1])),
        'uyvy': (uyvy, studio_to_full(uyvy[:, :, 1])),
        'yuv422_yuy2': (yuyv, studio_to_full(yuyv[:, :, 0])),
        'yuyv': (yuyv, studio_to_full(yuyv[:, :, 0])),
    }


FLAVOURS = ('rclpy', 'rosbags')


@pytest.mark.parametrize('flavour', FLAVOURS)
@pytest.mark.parametrize('encoding', sorted(encoded_cases()))
@pytest.mark.parametrize('padding', (0, 5))
def test_encoding_gives_the_gray_frame(flavour: str, encoding: str, padding: int) -> None:
    pixels, expected = encoded_cases()[encoding]
    gray = image_to_gray(make_image(flavour, encoding, pixels, padding=padding))
    assert gray.dtype == np.uint8 and gray.shape == (HEIGHT, WIDTH)
    assert gray.flags.c_contiguous
    np.testing.assert_array_equal(gray, expected)


def test_yuv_luma_follows_the_picture() -> None:
    """Both 4:2:2 layouts give the BGR picture's gray (luma, not chroma, in full range)."""
    bgr = reference_bgr()
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(int)
    for encoding, code in (('yuv422', cv2.COLOR_BGR2YUV_UYVY),
                           ('yuv422_yuy2', cv2.COLOR_BGR2YUV_YUYV)):
        luma = image_to_gray(make_image('rclpy', encoding, cv2.cvtColor(bgr, code)))
        assert np.abs(luma.astype(int) - gray).max() <= 3, encoding


@pytest.mark.parametrize('flavour', FLAVOURS)
@pytest.mark.parametrize('pattern', ('rggb', 'bggr', 'gbrg', 'grbg'))
@pytest.mark.parametrize('bits', (8, 16))
def test_bayer_is_demosaiced_with_its_own_pattern(flavour: str, pattern: str,
                                                  bits: int) -> None:
    """A red left half and a blue right half: a wrong pattern would swap their grays."""
    bgr = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    bgr[:, :WIDTH // 2] = (20, 40, 220)
    bgr[:, WIDTH // 2:] = (220, 40, 20)
    mosaic = bayer_mosaic(bgr, pattern)
    if bits == 16:
        mosaic = _to16(mosaic)
    gray = image_to_gray(make_image(flavour, f'bayer_{pattern}{bits}', mosaic, padding=3))
    expected = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(int)
    inner = (slice(2, -2), np.r_[2:WIDTH // 2 - 2, WIDTH // 2 + 2:WIDTH - 2])
    assert gray.shape == (HEIGHT, WIDTH)
    assert np.abs(gray[inner].astype(int) - expected[inner]).max() <= 2


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_big_endian_mono16(flavour: str) -> None:
    values = np.arange(HEIGHT * WIDTH, dtype=np.uint16).reshape(HEIGHT, WIDTH) * 83
    little = image_to_gray(make_image(flavour, 'mono16', values))
    big = image_to_gray(make_image(flavour, 'mono16', values, bigendian=True, padding=2))
    np.testing.assert_array_equal(little, (values >> 8).astype(np.uint8))
    np.testing.assert_array_equal(big, little)


def test_every_declared_encoding_is_tested() -> None:
    tested = set(encoded_cases()) | {f'bayer_{p}{b}' for p in ('rggb', 'bggr', 'gbrg', 'grbg')
                                     for b in (8, 16)}
    aliases = {'8UC1', '8UC3', '8UC4', '16UC1'}
    assert set(ENCODINGS) - aliases == tested


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_generic_opencv_aliases(flavour: str) -> None:
    pixels, expected = encoded_cases()['bgr8']
    np.testing.assert_array_equal(image_to_gray(make_image(flavour, '8UC3', pixels)), expected)
    gray = expected
    np.testing.assert_array_equal(image_to_gray(make_image(flavour, '8UC1', gray)), gray)


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_result_does_not_alias_the_message(flavour: str) -> None:
    gray = encoded_cases()['mono8'][0]
    msg = make_image(flavour, 'mono8', gray)
    frame = image_to_gray(msg)
    frame[:] = 0
    np.testing.assert_array_equal(image_to_gray(msg), gray)


def _expect_error(build_message: Callable[[], Any], *words: str) -> None:
    with pytest.raises(ImageConversionError) as info:
        message_to_gray(build_message())
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_bad_images_raise_naming_the_problem(flavour: str) -> None:
    gray = encoded_cases()['mono8'][0]
    bgr = reference_bgr()
    _expect_error(lambda: make_image(flavour, 'hsv8', bgr), "'hsv8'", 'mono8')

    def truncated() -> Any:
        msg = make_image(flavour, 'bgr8', bgr)
        msg.data = msg.data[:-10]
        return msg
    _expect_error(truncated, 'truncated', str(HEIGHT * WIDTH * 3))

    def short_step() -> Any:
        msg = make_image(flavour, 'bgr8', bgr)
        msg.step = WIDTH * 3 - 1
        return msg
    _expect_error(short_step, 'step', str(WIDTH * 3 - 1))

    def zero_size() -> Any:
        msg = make_image(flavour, 'mono8', gray)
        msg.height = 0
        return msg
    _expect_error(zero_size, 'zero size')

    def odd_yuv() -> Any:
        msg = make_image(flavour, 'yuv422', encoded_cases()['yuv422'][0])
        msg.width = WIDTH - 1
        return msg
    _expect_error(odd_yuv, 'even width')


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_compressed_png_is_exact_and_jpeg_close(flavour: str) -> None:
    bgr = reference_bgr()
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    png = cv2.imencode('.png', gray)[1].tobytes()
    np.testing.assert_array_equal(message_to_gray(make_compressed(flavour, 'png', png)), gray)
    jpeg = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
    decoded = compressed_to_gray(make_compressed(flavour, 'bgr8; jpeg compressed bgr8', jpeg))
    assert decoded.shape == gray.shape and decoded.dtype == np.uint8
    assert np.abs(decoded.astype(int) - gray).mean() < 3
    png16 = cv2.imencode('.png', _to16(gray))[1].tobytes()
    np.testing.assert_array_equal(message_to_gray(make_compressed(flavour, 'png', png16)), gray)


@pytest.mark.parametrize('flavour', FLAVOURS)
def test_bad_compressed_images_raise(flavour: str) -> None:
    jpeg = cv2.imencode('.jpg', reference_bgr())[1].tobytes()
    _expect_error(lambda: make_compressed(flavour, 'jpeg', b'\xff\xd8 not really a jpeg'),
                  'cannot decode', "'jpeg'")
    _expect_error(lambda: make_compressed(flavour, 'jpeg', jpeg[:40]), 'cannot decode')
    _expect_error(lambda: make_compressed(flavour, 'jpeg', b''), 'no data')
    _expect_error(lambda: make_compressed(flavour, '16UC1; compressedDepth png', jpeg),
                  'depth')


def test_other_messages_are_refused() -> None:
    header = BagHeader(stamp=BagTime(sec=0, nanosec=0), frame_id='')
    with pytest.raises(ImageConversionError, match='neither'):
        message_to_gray(header)


@pytest.mark.parametrize('flavour', FLAVOURS)
@pytest.mark.parametrize('channels', (1, 3))
def test_array_to_image_and_back(flavour: str, channels: int) -> None:
    bgr = reference_bgr()
    array = bgr if channels == 3 else cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    fields = image_fields(array[:, 1:])  # a non-contiguous view
    assert fields['encoding'] == ('bgr8' if channels == 3 else 'mono8')
    assert fields['step'] == (WIDTH - 1) * channels
    msg = _round_trip(flavour, _message(flavour, 'image', fields))
    expected = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)[:, 1:]
    np.testing.assert_array_equal(image_to_gray(msg), expected)


@pytest.mark.parametrize('bad', (np.zeros((4, 4), np.float32), np.zeros((4, 4, 4), np.uint8),
                                 np.zeros((0, 4), np.uint8)))
def test_image_fields_refuses_bad_arrays(bad: np.ndarray) -> None:
    with pytest.raises(ImageConversionError):
        image_fields(bad)
