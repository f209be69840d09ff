"""Reading the image files of an evaluation folder, with the reason when one cannot be read.

OpenCV's ``imread`` answers ``None`` for a missing, empty, truncated or foreign file
alike. :func:`read_gray_image` reads the bytes itself and decodes them, so that the
evaluation and training tools can skip such a file and list it with its reason
(:class:`UnreadableImage`) instead of stopping the whole run. OpenCV's own log lines
about a broken file (``[ WARN:0@0.079] ... grfmt_png.cpp ...``) are silenced while it
decodes: the tool's message names the file and the reason.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.errors import SpeedSignError

__all__ = ['UnreadableImage', 'UnreadableImageError', 'read_gray_image']


class UnreadableImageError(SpeedSignError):
    """An image file is missing, empty, or does not decode; the message is the reason."""


@dataclass(frozen=True)
class UnreadableImage:
    """A file an evaluation skipped.

    Attributes:
        file: its name as the data set lists it (relative to the data folder).
        reason: why it could not be read, one line.
    """

    file: str
    reason: str


def read_gray_image(path: Path) -> np.ndarray:
    """Read an image file (PNG, JPEG, PPM, ...) as grayscale.

    Returns:
        The image, (H, W) uint8.

    Raises:
        UnreadableImageError: the file is missing or unreadable (the OS's reason), empty,
            or its bytes do not decode as an image.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise UnreadableImageError(err.strerror or str(err)) from err
    if not data:
        raise UnreadableImageError('empty file (0 bytes)')
    try:
        with _opencv_log_silenced():
            gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    except cv2.error as err:
        raise UnreadableImageError(f'does not decode as an image: {err}') from err
    if gray is None or gray.size == 0:
        raise UnreadableImageError(f'does not decode as an image ({len(data)} bytes; '
                                   f'corrupt, truncated or not an image format OpenCV reads)')
    return gray


@contextmanager
def _opencv_log_silenced() -> Iterator[None]:
    """OpenCV's log level (process-wide) set to silent inside the block, restored after."""
    previous = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(previous)
