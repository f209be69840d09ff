"""Candidate sign centres: block-max reduction, non-maximum suppression, top-N.

The result type :class:`Candidate` is shared by every backend.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Candidate:
    """One possible sign found by radial-symmetry voting.

    Attributes:
        x_px: centre column in pixels (0 = left edge of the frame, pixel centres at +0.5
            are *not* used: pixel (i, j) has centre (j, i)).
        y_px: centre row in pixels.
        radius_px: estimated radius of the sign's outer ring, in pixels.
        score: detector score (normalised vote; larger is more sign-like). Comparable
            between candidates of one frame, not an absolute probability.
        band: index of the radius band that won (0 = smallest radii).
    """

    x_px: float
    y_px: float
    radius_px: float
    score: float
    band: int = 0
