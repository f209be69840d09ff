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

A crop under 20 px cannot be GTSRB-framed (:func:`auto_framings`): its 5 px margins would
leave a sign of radius under ``min_sign_radius_px`` (5 px), which no filter reads, so
``'auto'`` correlates its ``'padded'`` and ``'tight'`` radii instead (GTSRB's crops are
25 px and more). On gtsdb-dev's limit signs cut as crops and read with banks trained
without their scene (5 folds by scene), this read 36 more of the 284 signs padded in
proportion (265 instead of 229) and 4 more cut tight (270 instead of 266); the one new
wrong limit is a 12 px 30 km/h sign that the tight cut already read as 80.
"""
from __future__ import annotations

from speed_sign_detector.errors import ClassifierInputError

__all__ = ['AUTO_FRAMINGS', 'CROP_FRAMINGS', 'auto_framings', 'crop_sign_radius',
           'padded_fallback_radius']

#: Crop framings :meth:`~speed_sign_detector.recognition.classifier.Classifier.classify_crop`
#: accepts.
CROP_FRAMINGS: tuple[str, ...] = ('auto', 'margin', 'tight', 'padded')
#: The framings ``'auto'`` compares first (for a crop of 20 px and more, see
#: :func:`auto_framings`).
AUTO_FRAMINGS: tuple[str, ...] = ('margin', 'tight')
#: The framings ``'auto'`` compares in a crop too small for GTSRB's framing.
SMALL_CROP_AUTO_FRAMINGS: tuple[str, ...] = ('padded', 'tight')
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


def auto_framings(shape: tuple[int, ...], min_radius_px: float) -> tuple[str, ...]:
    """The framings ``'auto'`` compares first for a crop of ``shape`` (h, w).

    :data:`AUTO_FRAMINGS`, unless the ``'margin'`` framing would put a sign of radius under
    ``min_radius_px`` in the crop (a crop under 20 px for GTSRB's 5 px margins and a least
    radius of 5 px): no such sign is read, so the crop is not GTSRB-framed, and
    :data:`SMALL_CROP_AUTO_FRAMINGS` (a margin in proportion, or none) are compared instead.
    """
    if crop_sign_radius(shape, 'margin') < min_radius_px:
        return SMALL_CROP_AUTO_FRAMINGS
    return AUTO_FRAMINGS
