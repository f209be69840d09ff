"""How a crop frames its sign: the sign radius to search around, per framing.

Crops come framed three ways:

- ``'margin'``: GTSRB's framing, a margin of 10 % of the sign's size but at least 5 pixels
  on each side;
- ``'tight'``: the box is the sign (most labelling tools);
- ``'padded'``: a margin of 10 % of the sign's size with no least margin (tools that pad
  the box in proportion). Above about 60 px it is the same as ``'margin'``; below, GTSRB's
  5 pixels make ``'margin'`` expect a much smaller sign (a 20 px crop: radius 5 px instead
  of 8 px).

``'auto'`` (:meth:`~speed_sign_detector.recognition.classifier.Classifier.crop_evidence`)
correlates the ``'margin'`` and ``'tight'`` radii and keeps the clearer classification; a
small crop that it answers "no sign" is tried once more as ``'padded'``, and any crop so
answered once more with the search held to its framing (:mod:`.crop_reading`).
"""
from __future__ import annotations

from speed_sign_detector.errors import ClassifierInputError

__all__ = ['AUTO_FRAMINGS', 'CROP_FRAMINGS', 'crop_sign_radius', 'padded_fallback_radius']

#: Crop framings :meth:`~speed_sign_detector.recognition.classifier.Classifier.classify_crop`
#: accepts.
CROP_FRAMINGS: tuple[str, ...] = ('auto', 'margin', 'tight', 'padded')
#: The framings ``'auto'`` compares first.
AUTO_FRAMINGS: tuple[str, ...] = ('margin', 'tight')
#: The sign's share of a ``'margin'`` or ``'padded'`` crop's side (10 % margin each side).
SIGN_SHARE_OF_PADDED_SIDE = 1.0 / 1.2
#: GTSRB's least margin on each side, pixels.
GTSRB_LEAST_MARGIN_PX = 5.0
#: ``'padded'`` is worth a try only where its radius exceeds ``'margin'``'s by this factor.
PADDED_DIFFERENCE = 1.05


def crop_sign_radius(shape: tuple[int, ...], framing: str) -> float:
    """The sign radius to search around for a crop of ``shape`` (h, w), pixels.

    Args:
        shape: the crop's (height, width), pixels.
        framing: ``'margin'``, ``'tight'`` or ``'padded'`` (see the module docstring;
            ``'auto'`` tries several: it has no single radius).

    Raises:
        ClassifierInputError: (a ``ValueError``) for ``'auto'`` or an unknown framing.
    """
    if framing not in CROP_FRAMINGS or framing == 'auto':
        raise ClassifierInputError(f'unknown crop framing {framing!r}; expected one of '
                                   f'{", ".join(CROP_FRAMINGS)}')
    side = float(min(shape[0], shape[1]))
    if framing == 'tight':
        return side / 2.0
    proportional = side * SIGN_SHARE_OF_PADDED_SIDE
    if framing == 'padded' or side <= 2.0 * GTSRB_LEAST_MARGIN_PX:
        return proportional / 2.0
    return min(proportional, side - 2.0 * GTSRB_LEAST_MARGIN_PX) / 2.0


def padded_fallback_radius(shape: tuple[int, ...]) -> float | None:
    """The ``'padded'`` radius (pixels) that ``'auto'`` tries after "no sign", or ``None``
    where it is within :data:`PADDED_DIFFERENCE` of the ``'margin'`` radius (crops of
    about 60 px and more)."""
    padded = crop_sign_radius(shape, 'padded')
    return padded if padded > crop_sign_radius(shape, 'margin') * PADDED_DIFFERENCE else None
