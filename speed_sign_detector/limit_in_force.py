"""The speed limit in force along a drive, and how long the published limit was right.

What a driver experiences is not how many signs were read but whether the limit shown
is the one in force. This module derives the limit in force from a truth file
(:mod:`speed_sign_detector.truth`) and scores a published active limit against it.

Limit in force
    A sign rules from the place where it stands: its limit comes into force when the car
    passes it, taken as the sign's **last visible frame** in the truth (``last_stamp_s``
    of its track; a synthetic drive lists a sign until it leaves the image, an approach
    sequence until its last, nearest frame). Speed-limit signs set their value,
    end-of-limit signs (kind ``end_of_limit...``) set "none" (0). Look-alikes change
    nothing. Before the first such sign is passed nothing is known to be in force, and
    that time is not judged.

Time in correct limit (``time_in_correct_limit``)
    The share of the judged time (from the first limit-setting sign being passed to the
    last processed frame) in which the published active limit is acceptable. Each
    processed frame holds until the next frame's stamp. The published value is
    acceptable when it equals the limit in force, or when it equals the value of the
    **next** limit-setting sign to be passed while that sign is already in view: a
    display may announce the sign the driver is looking at, but not a farther sign while
    a nearer one is still ahead (the bug of a far 20 shown while a near 30 fills the
    frame counts as wrong).

Strict time in correct limit (``time_in_correct_limit_strict``)
    The share in which the published value equals the limit in force exactly (a limit
    shown while its sign is approached counts as wrong until the sign is passed).
"""
from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

from speed_sign_detector.truth import TruthTrack


@dataclass(frozen=True)
class LimitSignPassing:
    """A limit-setting sign of the truth, and when it is passed.

    Attributes:
        first_stamp_s: its first visible frame, seconds.
        passed_stamp_s: its last visible frame, when its value comes into force, seconds.
        limit_kmh: the value it sets, km/h; 0 for an end-of-limit sign.
        track_id: its truth track id.
        last_radius_px: its radius in its last visible frame, pixels (of signs passed
            at the same frame, the largest, nearest one is passed last and rules).
    """

    first_stamp_s: float
    passed_stamp_s: float
    limit_kmh: int
    track_id: int
    last_radius_px: float = 0.0


@dataclass(frozen=True)
class LimitTimeScore:
    """Time in correct limit of a drive (see the module docstring).

    Attributes:
        time_in_correct_limit: acceptable share of the judged time, 0..1; None when no
            limit-setting sign was passed before the last processed frame.
        time_in_correct_limit_strict: share in which the published limit equals the
            limit in force exactly, 0..1; None likewise.
        judged_s: the judged time, seconds.
    """

    time_in_correct_limit: float | None
    time_in_correct_limit_strict: float | None
    judged_s: float


def limit_sign_passings(tracks: Sequence[TruthTrack]) -> tuple[LimitSignPassing, ...]:
    """The truth's limit-setting signs (limits and end-of-limit signs), in passing order."""
    passings = [LimitSignPassing(track.first_stamp_s, track.last_stamp_s, track.limit_kmh,
                                 track.track_id, track.rows[-1].radius_px)
                for track in tracks
                if track.is_limit or track.is_end_of_limit]
    passings.sort(key=lambda passing: (passing.passed_stamp_s, passing.last_radius_px,
                                       passing.track_id))
    return tuple(passings)


def limit_in_force_kmh(passings: Sequence[LimitSignPassing], stamp_s: float,
                       tolerance_s: float = 0.0) -> int | None:
    """The limit in force at ``stamp_s`` (km/h, 0 = none), None before any sign was passed.

    Args:
        passings: :func:`limit_sign_passings` of the truth.
        stamp_s: the time, seconds.
        tolerance_s: a sign counts as passed this much before its last visible stamp
            (half a frame period absorbs the rounding of stamps in truth files).
    """
    passed_stamps = [passing.passed_stamp_s for passing in passings]
    count = bisect.bisect_right(passed_stamps, stamp_s + tolerance_s)
    return passings[count - 1].limit_kmh if count else None


def score_time_in_limit(tracks: Sequence[TruthTrack], frame_stamps_s: Sequence[float],
                        limit_changes: Sequence[tuple[float, int]],
                        tolerance_s: float | None = None) -> LimitTimeScore:
    """Score a published active limit against the limit in force.

    Args:
        tracks: truth tracks (:func:`speed_sign_detector.truth.group_tracks`).
        frame_stamps_s: stamps of the processed frames, seconds, ascending.
        limit_changes: (stamp s, active limit km/h) each time the published active limit
            changed, in time order; before the first change the published limit is 0.
        tolerance_s: stamp tolerance for "passed" and "in view", seconds; default half
            the median frame period.

    Returns:
        The shares over the judged time (each frame counts until the next frame's stamp).
    """
    stamps = list(frame_stamps_s)
    if tolerance_s is None:
        periods = sorted(later - earlier for earlier, later in zip(stamps, stamps[1:]))
        tolerance_s = 0.5 * periods[len(periods) // 2] + 1e-4 if periods else 1e-4
    passings = limit_sign_passings(tracks)
    # passings are in passing order: each frame finds its place with one bisection
    # (O((frames + changes) log signs), not a scan of every sign per frame)
    passed_stamps = [passing.passed_stamp_s for passing in passings]
    change_stamps = [stamp for stamp, _ in limit_changes]
    judged_s = acceptable_s = exact_s = 0.0
    for stamp_s, next_stamp_s in zip(stamps, stamps[1:]):
        passed_count = bisect.bisect_right(passed_stamps, stamp_s + tolerance_s)
        if not passed_count:
            continue
        in_force = passings[passed_count - 1].limit_kmh
        change_index = bisect.bisect_right(change_stamps, stamp_s + 1e-9)
        published = limit_changes[change_index - 1][1] if change_index else 0
        duration_s = next_stamp_s - stamp_s
        judged_s += duration_s
        if published == in_force:
            exact_s += duration_s
            acceptable_s += duration_s
        elif published in _announced_kmh(passings, passed_stamps, passed_count, stamp_s,
                                         tolerance_s):
            acceptable_s += duration_s
    if judged_s <= 0.0:
        return LimitTimeScore(None, None, 0.0)
    return LimitTimeScore(acceptable_s / judged_s, exact_s / judged_s, judged_s)


def _announced_kmh(passings: Sequence[LimitSignPassing], passed_stamps: Sequence[float],
                   passed_count: int, stamp_s: float, tolerance_s: float) -> set[int]:
    """Values of the next signs to be passed (those passed at the earliest upcoming
    stamp) that are in view at ``stamp_s``; empty when none is. ``passed_count``: how
    many of the (passing-ordered) ``passings`` are passed by then, ``passed_stamps``
    their passing stamps."""
    if passed_count >= len(passings):
        return set()
    next_stamp_s = passed_stamps[passed_count]
    group_end = bisect.bisect_right(passed_stamps, next_stamp_s + 1e-9, lo=passed_count)
    return {passing.limit_kmh for passing in passings[passed_count:group_end]
            if passing.first_stamp_s <= stamp_s + tolerance_s}
