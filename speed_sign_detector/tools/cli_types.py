"""Argument types of the command-line tools that check a number's range.

Given as ``type=`` to ``argparse``, a value out of range is a usage error naming the
option, as argparse gives for any other bad argument (exit status 2)::

    speed_sign_eval scenes: error: argument --limit: must be an integer >= 0, got '-3'

One helper for every tool, so that eval, synth, replay, monitor and train word the
same problem the same way. Where a config class checks the values itself,
:func:`option_names` puts the options' names into its message.
"""
from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable, Mapping


def integer_in_range(minimum: int | None = None,
                     maximum: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer within ``[minimum, maximum]`` (a bound of None: none).

    Returns:
        A function from the argument's text to its value that raises
        :class:`argparse.ArgumentTypeError` naming the range for anything else.
    """
    wanted = 'an integer' + _range_text(minimum, maximum, above=None)

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f'must be {wanted}, got {text!r}') from err
        if (minimum is not None and value < minimum) or (maximum is not None
                                                          and value > maximum):
            raise argparse.ArgumentTypeError(f'must be {wanted}, got {text!r}')
        return value

    parse.__name__ = 'integer'
    return parse


def number_in_range(minimum: float | None = None, maximum: float | None = None, *,
                    above: float | None = None) -> Callable[[str], float]:
    """An argparse type: a finite number within ``[minimum, maximum]`` and, when ``above``
    is given, strictly greater than it (a bound of None: none).

    Returns:
        A function from the argument's text to its value (float) that raises
        :class:`argparse.ArgumentTypeError` naming the range for anything else (NaN and
        infinities included).
    """
    wanted = 'a number' + _range_text(minimum, maximum, above)

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f'must be {wanted}, got {text!r}') from err
        if (not math.isfinite(value) or (minimum is not None and value < minimum)
                or (maximum is not None and value > maximum)
                or (above is not None and value <= above)):
            raise argparse.ArgumentTypeError(f'must be {wanted}, got {text!r}')
        return value

    parse.__name__ = 'number'
    return parse


def _range_text(minimum: float | None, maximum: float | None, above: float | None) -> str:
    """`` >= 0``, `` > 0``, `` from 1 to 64``: the range in words ('' when unbounded)."""
    if above is not None and maximum is None:
        return f' > {above:g}'
    if above is not None:
        return f' > {above:g} and <= {maximum:g}'
    if minimum is not None and maximum is not None:
        return f' from {minimum:g} to {maximum:g}'
    if minimum is not None:
        return f' >= {minimum:g}'
    if maximum is not None:
        return f' <= {maximum:g}'
    return ''


def option_names(message: str, option_of_field: Mapping[str, str]) -> str:
    """A config's error message with its field names replaced by the options that set
    them (``duration_s must be ...`` -> ``--duration must be ...``)."""
    for field_name, option in option_of_field.items():
        message = re.sub(rf'\b{re.escape(field_name)}\b', option, message)
    return message


#: Common cases.
non_negative_integer = integer_in_range(minimum=0)
positive_integer = integer_in_range(minimum=1)
non_negative_number = number_in_range(minimum=0.0)
positive_number = number_in_range(above=0.0)
