"""Synthetic scenes with known answers, shared by the pipeline and node tests."""
from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from speed_sign_detector.recognition.templates import render_sign

WIDTH, HEIGHT = 320, 240


def textured_background(seed: int, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """Road-scene-like clutter: smoothed noise, BGR (height, width, 3) uint8."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(110, 40, (height // 8, width // 8, 3)).astype(np.float32)
    smooth = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    grain = rng.normal(0, 4, (height, width, 3))
    return np.clip(smooth + grain, 0, 255).astype(np.uint8)


def paste(frame: np.ndarray, bgr: np.ndarray, alpha: np.ndarray, left: int, top: int) -> None:
    """Alpha-blend a (D, D, 3) sign image into ``frame`` at (left, top), in place."""
    height, width = alpha.shape
    region = frame[top:top + height, left:left + width].astype(np.float32)
    blended = region * (1 - alpha[..., None]) + bgr.astype(np.float32) * alpha[..., None]
    frame[top:top + height, left:left + width] = blended.astype(np.uint8)


def approach_frames(kind: str, count: int, seed: int,
                    background: np.ndarray | None = None
                    ) -> Iterator[tuple[np.ndarray, float, float, float]]:
    """A sign approaching the camera: it grows and drifts outward frame by frame.

    Yields:
        (bgr frame, centre x px, centre y px, radius px).
    """
    background = textured_background(seed) if background is None else background
    for index in range(count):
        diameter = 26 + 2 * index
        x, y = 200 + 2 * index, 80 - index
        bgr, alpha = render_sign(kind, diameter)
        frame = background.copy()
        top, left = y - diameter // 2, x - diameter // 2
        paste(frame, bgr, alpha, left, top)
        frame = cv2.GaussianBlur(frame, (3, 3), 0.6)
        yield frame, left + diameter / 2, top + diameter / 2, diameter / 2
