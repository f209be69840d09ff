"""How the GL scatter pass stores a band group's votes as integers.

Each vote adds two numbers to its pixel, ``profile / u`` (the weight, which scores) and
``profile`` (the count; count / weight is the radius estimate). The scatter pass adds
them with integer atomics, which are most of its cost on a software renderer. When the
largest sums a pixel can reach leave room, both go into one 32-bit integer, the weight
in the high bits and the count in the low bits, so that each vote costs one atomic
instead of two (on llvmpipe the vote pass took 40 % less time, bench/RESULTS.md).

The bound that makes the packing safe is geometric. A vote reaches a pixel only from
edge pixels between ``r0`` and ``r1 * sqrt(1 + tan^2(pi/8))`` away (edge-level pixels),
and each edge pixel adds at most 1 to its count and at most ``1 / (r0 / 2)`` to its
weight (the scatter pass clamps ``u`` at ``r0 / 2``). An edge pixel reaches a pixel
through at most one of its two vote directions (the two trapezoids lie on opposite
sides of it). Edge pixels are distinct lattice points, and a disc of radius ``R``
holds at most ``pi (R + sqrt(1/2))^2`` of them, an annulus at most that minus
``pi (r - sqrt(1/2))^2``. Integer rounding adds at most half a unit per vote to the
weight, and a count never rounds above 1 (``profile <= 1``). So the count field needs
``count_bound * count_one`` and the weight field ``count_bound * (weight_one * 2 / r0 +
1/2)`` to stay below their sizes, whatever the frame; :func:`vote_fixed_point` picks the
finest power-of-two units for which they do. When no split keeps at least
:data:`MIN_COUNT_ONE` and :data:`MIN_WEIGHT_ONE` (a single band spanning many radii),
the votes are not packed: two integers per pixel in units of :data:`UNPACKED_ONE`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from speed_sign_detector.detection.voting_numpy import SPREAD, RadiusBand

UNPACKED_ONE = 65536.0
"""Integer units per 1.0 of weight and of count when the votes are not packed."""
MIN_COUNT_ONE = 32
"""Coarsest count unit allowed in packed votes: 1/32 of a full-profile vote."""
MIN_WEIGHT_ONE = 256
"""Coarsest weight unit allowed in packed votes: 1/256 (a vote weighs 1/u, u >= r0)."""
_WORD_BITS = 32
_HALF_DIAGONAL = math.sqrt(0.5)


@dataclass(frozen=True)
class VoteFixedPoint:
    """The integer format of one band group's scatter votes.

    Attributes:
        count_bits: low bits of the packed integer that hold the count; 0 when the votes
            are not packed (weight and count in separate integers).
        weight_one: integer units per 1.0 of weight (``sum profile / u``, 1/pixel).
        count_one: integer units per 1.0 of count (``sum profile``).
    """

    count_bits: int
    weight_one: float
    count_one: float

    @property
    def packed(self) -> bool:
        """True when weight and count share one 32-bit integer per pixel."""
        return self.count_bits > 0

    @property
    def count_mask(self) -> int:
        """The bits of a packed integer that hold the count."""
        return (1 << self.count_bits) - 1


def votes_per_pixel_bound(min_radius: float, max_radius: float) -> float:
    """Most edge pixels that can vote for one pixel of a band group (edge-level radii).

    Lattice points in the annulus between ``min_radius`` and the trapezoid's farthest
    corner, ``max_radius * sqrt(1 + tan^2(pi/8))``, with half a pixel diagonal of slack
    on both sides.
    """
    outer = max_radius * math.hypot(1.0, SPREAD) + _HALF_DIAGONAL
    inner = max(0.0, min_radius - _HALF_DIAGONAL)
    return math.pi * (outer * outer - inner * inner)


def vote_fixed_point(bands: tuple[RadiusBand, ...]) -> VoteFixedPoint:
    """The finest safe integer format for a band group's votes (see the module text).

    ``bands`` share edge and vote levels; their radii are contiguous, smallest first.
    """
    min_radius = bands[0].level_radii[0]
    max_radius = bands[-1].level_radii[1]
    votes = votes_per_pixel_bound(min_radius, max_radius)
    max_vote_weight = 2.0 / min_radius  # the scatter pass clamps u at min_radius / 2
    best: VoteFixedPoint | None = None
    best_slack = -math.inf
    for count_bits in range(1, _WORD_BITS):
        count_one = _largest_power_of_two(lambda one: votes * one < 2 ** count_bits)
        weight_one = _largest_power_of_two(
            lambda one: votes * (one * max_vote_weight + 0.5) < 2 ** (_WORD_BITS - count_bits))
        if count_one < MIN_COUNT_ONE or weight_one < MIN_WEIGHT_ONE:
            continue
        slack = min(math.log2(count_one / MIN_COUNT_ONE), math.log2(weight_one / MIN_WEIGHT_ONE))
        if slack > best_slack:
            best, best_slack = VoteFixedPoint(count_bits, float(weight_one),
                                              float(count_one)), slack
    return best or VoteFixedPoint(0, UNPACKED_ONE, UNPACKED_ONE)


def _largest_power_of_two(fits: Callable[[int], bool]) -> int:
    """The largest ``2^k`` (``0 <= k <= 31``) for which ``fits(2^k)``; 0 when none does."""
    for exponent in range(_WORD_BITS - 1, -1, -1):
        if fits(1 << exponent):
            return 1 << exponent
    return 0
