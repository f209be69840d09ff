"""Classifier: decides the value of a sign at a candidate, or rejects it.

The result type :class:`Classification` is the contract with the tracker and node.
"""
from __future__ import annotations

from dataclasses import dataclass

#: Speed limits the classifier can read, in km/h.
SPEED_LIMITS_KMH: tuple[int, ...] = (5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130)
#: Labels that are not a speed limit.
LABEL_END_OF_LIMIT = 'end_of_limit'
LABEL_OTHER_SIGN = 'other_sign'
LABEL_NO_SIGN = 'no_sign'


@dataclass(frozen=True)
class Classification:
    """What the classifier says about one candidate or crop.

    Attributes:
        label: the limit as a string of its km/h value (``'30'``), or one of
            ``'end_of_limit'``, ``'other_sign'``, ``'no_sign'``.
        limit_kmh: the speed limit in km/h, or ``None`` when the label is not a limit.
        psr: peak-to-sidelobe ratio of the winning filter (dimensionless).
        radius_px: the sign's radius as the detection filters sized it, in pixels.
        rotation_deg: in-plane rotation of the winning filter, degrees (counter-clockwise).
        margin: PSR of the winner minus PSR of the best different label.
        x_px, y_px: the sign's centre as the correlation peak placed it, frame pixels.
    """

    label: str
    limit_kmh: int | None
    psr: float
    radius_px: float
    rotation_deg: float
    margin: float
    x_px: float
    y_px: float

    @property
    def is_limit(self) -> bool:
        """True when the answer is a speed limit."""
        return self.limit_kmh is not None
