"""Progress bars for the command-line tools, on stderr, through tqdm.

One place decides how the tools show progress, so ``eval bag``, ``eval scenes``,
``eval crops`` and the fleet runner (bags and frames, nested) look alike and all show a
rate and an ETA. Bars are drawn only when stderr is a terminal and the caller wants them;
otherwise they count silently, so callers never branch on whether a bar is shown.
"""
from __future__ import annotations

import sys

from tqdm import tqdm

__all__ = ['progress_bar']


def progress_bar(total: int | None, description: str, unit: str, *,
                 enabled: bool = True, position: int = 0, leave: bool = True) -> tqdm:
    """A tqdm bar on stderr for ``total`` items of ``unit`` (``None`` when unknown).

    Args:
        total: number of items expected, or ``None`` when unknown (no ETA then).
        description: short label in front of the bar, for example ``'frames'``.
        unit: the item's name, for example ``'frame'`` or ``'bag'``; the rate is per unit.
        enabled: ``False`` keeps the bar silent (it still counts ``n``).
        position: line offset for nested bars (0 = the outer bar, 1 = the one below it).
        leave: keep the finished bar on screen.

    Returns:
        The bar; call ``update(n)`` and ``close()`` (or use it as a context manager).
    """
    return tqdm(total=total, desc=description, unit=unit, file=sys.stderr,
                disable=not (enabled and sys.stderr.isatty()), position=position,
                leave=leave, dynamic_ncols=True, smoothing=0.1)
