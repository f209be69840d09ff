"""ROS image messages <-> numpy arrays, for rclpy messages and rosbags messages alike.

Nothing here imports rclpy or a message package: the functions read and write the
fields of ``sensor_msgs/msg/Image`` (``height``, ``width``, ``encoding``,
``is_bigendian``, ``step``, ``data``) and ``sensor_msgs/msg/CompressedImage``
(``format``, ``data``) on whatever object carries them, so the live node (rclpy
messages, ``data`` an ``array.array``) and the bag tools (rosbags typestore messages,
``data`` a numpy array) share one conversion.

Direction message -> array: :func:`message_to_gray` (dispatches to :func:`image_to_gray`
or :func:`compressed_to_gray`). Direction array -> message: :func:`image_fields` gives the
field values of a ``mono8``/``bgr8`` Image for a gray or BGR array.

Encoding names follow ``sensor_msgs/image_encodings.hpp``: ``yuv422`` and ``uyvy`` are
UYVY (U0 Y0 V0 Y1), ``yuv422_yuy2`` and ``yuyv`` are YUYV (Y0 U0 Y1 V0); Bayer
patterns are named by the colours of the top-left 2x2 block, row by row.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from speed_sign_detector.errors import ImageConversionError


@dataclass(frozen=True)
class EncodingLayout:
    """How one raw encoding lays out a pixel.

    Attributes:
        channels: values per pixel in the data (a YUV 4:2:2 pixel counts 2 bytes = 2 channels).
        bytes_per_channel: 1 or 2.
        to_gray: cv2 colour conversion code to gray for an 8-bit array of shape
            (H, W, channels), or None when the data already is gray (or is YUV: see
            ``luma_offset``).
        luma_offset: for YUV 4:2:2, index (0 or 1) of the luma byte within each
            2-byte pixel; None otherwise.
    """

    channels: int
    bytes_per_channel: int
    to_gray: int | None = None
    luma_offset: int | None = None

    @property
    def bytes_per_pixel(self) -> int:
        """Bytes one pixel occupies in a row."""
        return self.channels * self.bytes_per_channel


#: BT.601 studio-range luma (16..235) -> full-range gray (0..255), as YUV -> BGR -> gray.
_STUDIO_TO_FULL_RANGE = np.clip(np.round((np.arange(256) - 16) * 255.0 / 219.0),
                                0, 255).astype(np.uint8)


def _bayer_code(pattern: str) -> int:
    """cv2 demosaic-to-gray code for a Bayer pattern named as in ROS (e.g. 'RGGB')."""
    return int(getattr(cv2, f'COLOR_Bayer{pattern}2GRAY'))


#: Raw encodings understood by :func:`image_to_gray`.
ENCODINGS: dict[str, EncodingLayout] = {
    'mono8': EncodingLayout(1, 1),
    '8UC1': EncodingLayout(1, 1),
    'mono16': EncodingLayout(1, 2),
    '16UC1': EncodingLayout(1, 2),
    'bgr8': EncodingLayout(3, 1, cv2.COLOR_BGR2GRAY),
    '8UC3': EncodingLayout(3, 1, cv2.COLOR_BGR2GRAY),
    'rgb8': EncodingLayout(3, 1, cv2.COLOR_RGB2GRAY),
    'bgra8': EncodingLayout(4, 1, cv2.COLOR_BGRA2GRAY),
    '8UC4': EncodingLayout(4, 1, cv2.COLOR_BGRA2GRAY),
    'rgba8': EncodingLayout(4, 1, cv2.COLOR_RGBA2GRAY),
    'bgr16': EncodingLayout(3, 2, cv2.COLOR_BGR2GRAY),
    'rgb16': EncodingLayout(3, 2, cv2.COLOR_RGB2GRAY),
    'bgra16': EncodingLayout(4, 2, cv2.COLOR_BGRA2GRAY),
    'rgba16': EncodingLayout(4, 2, cv2.COLOR_RGBA2GRAY),
    'yuv422': EncodingLayout(2, 1, luma_offset=1),
    'uyvy': EncodingLayout(2, 1, luma_offset=1),
    'yuv422_yuy2': EncodingLayout(2, 1, luma_offset=0),
    'yuyv': EncodingLayout(2, 1, luma_offset=0),
    **{f'bayer_{pattern.lower()}{bits}': EncodingLayout(1, bits // 8, _bayer_code(pattern))
       for pattern in ('RGGB', 'BGGR', 'GBRG', 'GRBG') for bits in (8, 16)},
}


def image_to_gray(msg: Any) -> np.ndarray:
    """Convert a ``sensor_msgs/Image`` (rclpy or rosbags) to an 8-bit gray frame.

    Honours ``step`` (row padding) and ``is_bigendian`` (16-bit encodings); 16-bit
    values are scaled to 8 bit by dropping the low byte (``value >> 8``). Bayer images are
    demosaiced with cv2, YUV 4:2:2 images give their luma plane (BT.601 studio range
    16..235 stretched to 0..255, as a conversion through BGR would).

    Args:
        msg: object with fields ``height``, ``width``, ``encoding``, ``is_bigendian``,
            ``step``, ``data`` (bytes-like or uint8 array).

    Returns:
        Gray frame, shape (height, width), dtype uint8, C-contiguous (a copy: it does not
        alias the message buffer).

    Raises:
        ImageConversionError: unknown encoding, zero size, ``step`` shorter than a row,
            data shorter than ``step * height``, odd width for YUV 4:2:2.
    """
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    encoding = str(msg.encoding)
    layout = ENCODINGS.get(encoding)
    if layout is None:
        raise ImageConversionError(
            f'unsupported image encoding {encoding!r}; supported are: '
            f'{", ".join(sorted(ENCODINGS))}')
    if height <= 0 or width <= 0:
        raise ImageConversionError(f'image has zero size ({width}x{height} px, {encoding})')
    row_bytes = width * layout.bytes_per_pixel
    if step < row_bytes:
        raise ImageConversionError(
            f'step {step} B is shorter than one row of {width} px of {encoding} '
            f'({row_bytes} B)')
    if layout.luma_offset is not None and width % 2:
        raise ImageConversionError(f'{encoding} needs an even width, got {width} px')
    buffer = _as_bytes(msg.data)
    if buffer.size < step * height:
        raise ImageConversionError(
            f'image data is truncated: {buffer.size} B for {height} rows of step {step} B '
            f'({step * height} B expected, {width}x{height} px {encoding})')

    if layout.luma_offset is not None:
        rows = buffer[:step * height].reshape(height, step)
        luma = np.ascontiguousarray(rows[:, layout.luma_offset:row_bytes:2])
        return cv2.LUT(luma, _STUDIO_TO_FULL_RANGE)

    byte_order = '>' if msg.is_bigendian else '<'
    dtype = np.dtype(np.uint8) if layout.bytes_per_channel == 1 else np.dtype(f'{byte_order}u2')
    pixels = np.ndarray(shape=(height, width, layout.channels), dtype=dtype, buffer=buffer,
                        strides=(step, layout.bytes_per_pixel, layout.bytes_per_channel))
    if dtype.itemsize == 2:
        pixels = (pixels >> 8).astype(np.uint8)
    if layout.to_gray is None:
        return np.array(pixels[:, :, 0], order='C')
    source = pixels[:, :, 0] if layout.channels == 1 else pixels
    return cv2.cvtColor(np.ascontiguousarray(source), layout.to_gray)


def compressed_to_gray(msg: Any) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` (JPEG or PNG) to an 8-bit gray frame.

    Args:
        msg: object with fields ``format`` (e.g. ``'jpeg'``, ``'bgr8; jpeg compressed
            bgr8'``) and ``data`` (the encoded bytes).

    Returns:
        Gray frame, shape (H, W), dtype uint8. A 16-bit PNG is scaled to 8 bit.

    Raises:
        ImageConversionError: empty data, a ``compressedDepth`` stream (depth, not a
            camera image), or data cv2 cannot decode.
    """
    image_format = str(getattr(msg, 'format', ''))
    if 'compresseddepth' in image_format.lower():
        raise ImageConversionError(
            f'compressed image format {image_format!r} is a depth stream, not a camera image')
    buffer = _as_bytes(msg.data)
    if buffer.size == 0:
        raise ImageConversionError(f'compressed image ({image_format!r}) has no data')
    decoded = cv2.imdecode(buffer, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)
    if decoded is None or decoded.size == 0:
        raise ImageConversionError(
            f'cannot decode compressed image of format {image_format!r} '
            f'({buffer.size} B, starting {bytes(buffer[:4]).hex()}): not a valid JPEG or PNG')
    if decoded.dtype == np.uint16:
        decoded = (decoded >> 8).astype(np.uint8)
    return decoded


def message_to_gray(msg: Any) -> np.ndarray:
    """Convert an Image or a CompressedImage message to an 8-bit gray frame (H, W).

    The kind is told by the fields: ``encoding`` means Image, ``format`` means
    CompressedImage.

    Raises:
        ImageConversionError: for a message of neither kind or one that cannot convert.
    """
    if hasattr(msg, 'encoding') and hasattr(msg, 'step'):
        return image_to_gray(msg)
    if hasattr(msg, 'format') and hasattr(msg, 'data'):
        return compressed_to_gray(msg)
    raise ImageConversionError(
        f'{type(msg).__name__} is neither a sensor_msgs/Image nor a '
        f'sensor_msgs/CompressedImage')


def image_fields(array: np.ndarray) -> dict[str, Any]:
    """Field values of a ``sensor_msgs/Image`` holding a gray or BGR array.

    Args:
        array: uint8, shape (H, W) (-> ``mono8``) or (H, W, 3) BGR (-> ``bgr8``).

    Returns:
        ``height``, ``width``, ``encoding``, ``is_bigendian`` (0), ``step`` (bytes per
        row, no padding) and ``data`` (1-D uint8 numpy array, a copy). The caller adds the
        header and converts ``data`` to what its message class wants (see
        ``speed_sign_detector.ros.messages``).

    Raises:
        ImageConversionError: for another dtype or shape.
    """
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        raise ImageConversionError(
            f'image array must be a uint8 numpy array, got '
            f'{getattr(array, "dtype", type(array).__name__)}')
    if array.ndim == 2:
        encoding = 'mono8'
    elif array.ndim == 3 and array.shape[2] == 3:
        encoding = 'bgr8'
    else:
        raise ImageConversionError(
            f'image array must have shape (H, W) or (H, W, 3), got {array.shape}')
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise ImageConversionError(f'image array has zero size: {array.shape}')
    contiguous = np.ascontiguousarray(array)
    return {
        'height': int(array.shape[0]),
        'width': int(array.shape[1]),
        'encoding': encoding,
        'is_bigendian': 0,
        'step': int(contiguous.strides[0]),
        'data': contiguous.reshape(-1).copy(),
    }


def _as_bytes(data: Any) -> np.ndarray:
    """View message data (bytes, bytearray, array.array, list or uint8 array) as uint8 1-D."""
    if isinstance(data, np.ndarray):
        return data.reshape(-1).view(np.uint8) if data.dtype.itemsize == 1 \
            else data.reshape(-1).astype(np.uint8)
    try:
        return np.frombuffer(data, dtype=np.uint8)
    except TypeError:
        return np.asarray(data, dtype=np.uint8).reshape(-1)
