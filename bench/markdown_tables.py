"""Number formatting and Markdown tables shared by the renderers of bench/RESULTS.md.

``results_markdown.py`` (the stages ``make bench`` runs) and ``long_runs_markdown.py``
(the long runs whose JSON files it is given) both write their tables with these.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ['number', 'percent', 'table']


def number(value: float | None, digits: int = 1) -> str:
    """``value`` with ``digits`` decimals, or '-' for None and NaN."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return f'{value:.{digits}f}'


def percent(rate: float | None, digits: int = 2) -> str:
    """A rate (0..1) as a percentage with ``digits`` decimals ('0.18 %'), '-' for None."""
    if rate is None or (isinstance(rate, float) and math.isnan(rate)):
        return '-'
    return f'{100.0 * rate:.{digits}f} %'


def table(header: Sequence[str], rows: Sequence[Sequence[str]],
          right_aligned_from: int = 1) -> list[str]:
    """A Markdown table; columns from ``right_aligned_from`` on are right-aligned."""
    rule = ['---' if index < right_aligned_from else '---:' for index in range(len(header))]
    return ['| ' + ' | '.join(header) + ' |', '|' + '|'.join(rule) + '|'] + [
        '| ' + ' | '.join(row) + ' |' for row in rows]
