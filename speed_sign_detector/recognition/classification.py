"""What the classifier answers: :class:`Classification` and its labels.

:class:`Classification` is the contract between the classifier, the tracker and the node.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ['LABEL_END_OF_LIMIT', 'LABEL_NO_SIGN', 'LABEL_OTHER_SIGN', 'Classification',
           'label_of_class']

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
        psr: peak-to-sidelobe ratio of the winning class (dimensionless): the mean of
            its ``class_score_top`` best filters (sizes x in-plane rotations).
        radius_px: the sign's radius (size of the winning class's best filter), pixels.
        rotation_deg: in-plane rotation of the winning class's best filter, degrees
            (counter-clockwise).
        margin: PSR of the winner minus PSR of the best class with a different label.
        x_px, y_px: the sign's centre as the best filter's correlation peak placed it,
            frame pixels (crop pixels for :meth:`Classifier.classify_crop`).
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


#: Filter classes read as the end of the limit: end-of-limit signs (VZ 278) and the end of
#: all restrictions (VZ 282), which ends the limit in force too.
END_OF_LIMIT_CLASSES: frozenset[str] = frozenset({'end_of_limit', 'end_of_restrictions'})


def label_of_class(class_name: str) -> str:
    """The label a filter class name stands for: the limit's value, ``'end_of_limit'``
    (:data:`END_OF_LIMIT_CLASSES`), or ``'other_sign'`` for every other sign drawn
    (look-alikes)."""
    if class_name.isdigit():
        return class_name
    if class_name in END_OF_LIMIT_CLASSES:
        return LABEL_END_OF_LIMIT
    return LABEL_OTHER_SIGN
