"""Synthetic scenes with known answers, shared by the pipeline and node tests."""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

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


def write_gtsdb_scenes(folder: Path,
                       scenes: Sequence[tuple[str, Sequence[tuple[str, int, int, int, int]]]],
                       width: int, height: int) -> Path:
    """A GTSDB-format folder (``images/`` and ``gt.txt``) of rendered signs pasted on
    desaturated clutter (no sign-red in the background, so the red ring marks the sign).

    Args:
        folder: where to write.
        scenes: (file, [(kind, GTSDB class, diameter px, centre x, centre y)]) per image.
        width, height: image size, pixels.
    """
    (folder / 'images').mkdir(parents=True, exist_ok=True)
    lines = []
    for seed, (name, signs) in enumerate(scenes):
        clutter = textured_background(seed, width, height)
        gray = cv2.cvtColor(clutter, cv2.COLOR_BGR2GRAY)[..., None].astype(np.float32)
        scene = (0.3 * clutter + 0.7 * gray).astype(np.uint8)
        for kind, class_id, diameter, x, y in signs:
            bgr, alpha = render_sign(kind, diameter)
            left, top = x - diameter // 2, y - diameter // 2
            paste(scene, bgr, alpha, left, top)
            lines.append(f'{name};{left};{top};{left + diameter};{top + diameter};{class_id}')
        assert cv2.imwrite(str(folder / 'images' / name), scene,
                           [cv2.IMWRITE_JPEG_QUALITY, 95])
    (folder / 'gt.txt').write_text('\n'.join(lines) + '\n')
    return folder
