"""Worse copies of training images: what a poorer camera, a farther sign or an inexact
location would give. Used to train the second opinion on crops and on scenes."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ['degraded', 'jittered']


def degraded(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A copy of a (h, w) uint8 image as a worse camera would see it: blur, JPEG,
    contrast loss and down-scaling, each drawn at random (same size as the input)."""
    out = image.astype(np.float32)
    if rng.random() < 0.6:
        out = cv2.GaussianBlur(out, (0, 0), float(rng.uniform(0.5, 1.5)))
    if rng.random() < 0.5:
        factor = float(rng.uniform(0.45, 0.8))
        height, width = out.shape
        small = cv2.resize(out, (max(4, round(width * factor)), max(4, round(height * factor))),
                           interpolation=cv2.INTER_AREA)
        out = cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)
    if rng.random() < 0.6:
        gain = float(rng.uniform(0.35, 0.8))
        out = (out - out.mean()) * gain + out.mean() + float(rng.uniform(-30, 30))
    out = np.clip(out + rng.normal(0.0, float(rng.uniform(0.0, 4.0)), out.shape), 0, 255)
    out = out.astype(np.uint8)
    if rng.random() < 0.6:
        quality = int(rng.integers(15, 60))
        ok, encoded = cv2.imencode('.jpg', out, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = cv2.imdecode(encoded, cv2.IMREAD_GRAYSCALE)
    return out


def jittered(sign: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(x, y, radius) moved by up to 6% of the radius and scaled by up to +-6%: the
    run-time location is not exact."""
    x_px, y_px, radius_px = sign
    shift = rng.uniform(-0.06, 0.06, 2) * radius_px
    return np.asarray([x_px + shift[0], y_px + shift[1],
                       radius_px * float(rng.uniform(0.94, 1.06))])
