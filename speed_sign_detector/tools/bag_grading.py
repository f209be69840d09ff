"""The grading of a drive: the pipeline's limit recognitions matched to the truth signs.

What ``speed_sign_eval bag --truth`` reports per sign and per drive (the fields are
described in :mod:`speed_sign_detector.tools.eval_bag`):

- :func:`new_limit_events`: the limits (and ends of limit) a frame's result newly
  recognized, as :class:`LimitEvent` s.
- :func:`score_drive`: those events matched to the truth tracks
  (:mod:`speed_sign_detector.truth`): a :class:`SignOutcome` per sign and the counts of
  a :class:`DriveScore` (recognized, wrong limits and their kinds, end-of-limit signs,
  signs cut off by an early stop).
- :func:`drive_metrics`: the metric fields of a summary from its counts, the same for
  one drive and for many (:func:`sum_drive_metrics`, ``speed_sign_eval fleet``).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from speed_sign_detector.recognition.classification import LABEL_END_OF_LIMIT
from speed_sign_detector.truth import TruthTrack, is_end_of_limit_kind

#: Default grace after a sign left the image within which recognizing it still counts, s.
DEFAULT_GRACE_S = 1.0
#: How long before a sign's first listed frame recognizing its value (or its end of limit)
#: still counts for it, s: the truth lists a sign from 5 px (3.5 px for end signs) and 3/4
#: inside the image, and a sign can be read a few frames before that.
EARLY_RECOGNITION_S = 0.5
#: Per-sign counts of a drive's summary that add up over drives (with ``drive_time_s``).
DRIVE_COUNT_KEYS: tuple[str, ...] = (
    'signs', 'recognized', 'wrong_limits', 'lookalike_limits', 'misread_limits',
    'phantom_limits', 'end_of_limit_signs', 'end_of_limit_recognized',
    'wrong_end_of_limits')


@dataclass(frozen=True)
class LimitEvent:
    """A limit newly recognized by the pipeline.

    Attributes:
        stamp_s: frame time, seconds.
        limit_kmh: the recognized value; 0 for an end-of-limit sign.
        x_px, y_px: where the recognizing track was (NaN when unknown).
        track_id: the pipeline's track id (-1 when unknown).
    """

    stamp_s: float
    limit_kmh: int
    x_px: float = math.nan
    y_px: float = math.nan
    track_id: int = -1


@dataclass
class SignOutcome:
    """What happened to one truth sign (a row of the per-sign table)."""

    track_id: int
    kind: str
    limit_kmh: int
    first_s: float
    last_s: float
    max_radius_px: float
    recognized: bool = False
    recognized_after_s: float | None = None
    radius_at_recognition_px: float | None = None
    wrong_values: list[int] = field(default_factory=list)
    cut: bool = False


@dataclass(frozen=True)
class DriveScore:
    """Per-sign metrics of a drive (see the module docstring)."""

    signs: int
    recognized: int
    recall: float | None
    wrong_limits: int
    lookalike_limits: int
    misread_limits: int
    phantom_limits: int
    false_limits_per_hour: float
    end_of_limit_signs: int
    end_of_limit_recognized: int
    wrong_end_of_limits: int
    outcomes: tuple[SignOutcome, ...]
    drive_time_s: float = 0.0
    cut_signs: int = 0


def recall_of(recognized: int, signs: int) -> float | None:
    """recognized / signs; None when there is no sign."""
    return recognized / signs if signs else None


def per_hour(count: int, drive_time_s: float) -> float:
    """``count`` per hour of ``drive_time_s`` seconds (0 when the count is 0)."""
    if count == 0:
        return 0.0
    return count / max(drive_time_s / 3600.0, 1e-9)


def drive_metrics(counts: Mapping[str, int], drive_time_s: float) -> dict[str, Any]:
    """The per-sign metric fields of a summary from its counts.

    Args:
        counts: a value for each of :data:`DRIVE_COUNT_KEYS`.
        drive_time_s: the drive time the counts were taken over, seconds.

    Returns:
        The counts, ``recall``, ``false_limits_per_hour`` and ``drive_time_s``, keyed as
        in ``speed_sign_eval bag --json``.
    """
    metrics: dict[str, Any] = {key: int(counts[key]) for key in DRIVE_COUNT_KEYS}
    metrics['recall'] = recall_of(metrics['recognized'], metrics['signs'])
    metrics['false_limits_per_hour'] = per_hour(metrics['wrong_limits'], drive_time_s)
    metrics['drive_time_s'] = drive_time_s
    return metrics


def sum_drive_metrics(summaries: Iterable[Mapping[str, Any]]) -> dict[str, Any] | None:
    """The per-sign metrics of many drives: counts and drive times summed, then
    :func:`drive_metrics`.

    Args:
        summaries: ``speed_sign_eval bag --json`` objects; those without truth (no
            ``signs`` field) are left out.

    Returns:
        The summed metrics plus ``drives`` (how many had truth), or None when none had.
    """
    with_truth = [summary for summary in summaries if 'signs' in summary]
    if not with_truth:
        return None
    counts = {key: sum(int(summary[key]) for summary in with_truth)
              for key in DRIVE_COUNT_KEYS}
    metrics = drive_metrics(counts, math.fsum(float(summary['drive_time_s'])
                                              for summary in with_truth))
    metrics['drives'] = len(with_truth)
    return metrics


def score_drive(tracks: Sequence[TruthTrack], events: Sequence[LimitEvent],
                frame_stamps_s: Sequence[float], grace_s: float = DEFAULT_GRACE_S,
                stopped_early: bool = False) -> DriveScore:
    """Match the pipeline's limit recognitions to the truth signs.

    Args:
        tracks: truth tracks (:func:`speed_sign_detector.truth.group_tracks`).
        events: limits (and end-of-limit signs, ``limit_kmh`` 0) the pipeline newly
            recognized, in time order.
        frame_stamps_s: stamps of the processed frames, seconds (ascending); truth signs
            that first appear after the last processed frame are not counted.
        grace_s: a recognition up to this long after a sign's last visible frame counts.
            A recognition of a sign's own value (or of an end of limit for an end-of-limit
            sign) up to :data:`EARLY_RECOGNITION_S` before its first listed frame counts
            for it when no sign in view explains it.
        stopped_early: the frames end before the recording does (a truncated bag, Ctrl-C):
            signs not recognized whose time to be recognized (visible, then ``grace_s``)
            reaches past the last processed frame are cut (``SignOutcome.cut``), counted
            in ``cut_signs`` and left out of ``signs``, ``recall`` and the end-of-limit
            counts.

    Returns:
        The metrics; ``recall`` is None when there is no speed-limit sign.
    """
    stamps = np.asarray(frame_stamps_s, dtype=np.float64)
    period_s = float(np.median(np.diff(stamps))) if stamps.size > 1 else 0.0
    tolerance_s = 0.5 * period_s + 1e-4
    last_stamp = float(stamps[-1]) if stamps.size else -math.inf
    first_stamp = float(stamps[0]) if stamps.size else 0.0
    seen = [track for track in tracks if track.first_stamp_s <= last_stamp + tolerance_s]
    outcomes = {track.track_id: SignOutcome(
        track.track_id, track.kind, track.limit_kmh, track.first_stamp_s - first_stamp,
        track.last_stamp_s - first_stamp, track.max_radius_px) for track in seen}
    lookalike = misread = phantom = wrong_ends = 0
    for event in events:
        in_view = [track for track in seen
                   if track.first_stamp_s - tolerance_s <= event.stamp_s
                   <= track.last_stamp_s + grace_s]
        coming = [track for track in seen
                  if track.first_stamp_s - EARLY_RECOGNITION_S <= event.stamp_s
                  < track.first_stamp_s - tolerance_s]
        if event.limit_kmh == 0:
            ends = [track for track in in_view if track.is_end_of_limit] or \
                [track for track in coming if track.is_end_of_limit]
            if ends:
                best = min(ends, key=lambda track: _distance_px(track, event))
                outcomes[best.track_id].recognized = True
            else:
                wrong_ends += 1
                if in_view:
                    nearest = min(in_view, key=lambda track: _distance_px(track, event))
                    outcomes[nearest.track_id].wrong_values.append(0)
            continue
        matches = [track for track in in_view if track.limit_kmh == event.limit_kmh] or \
            [track for track in coming if track.limit_kmh == event.limit_kmh]
        if matches:
            best = min(matches, key=lambda track: (_distance_px(track, event),
                                                   outcomes[track.track_id].recognized,
                                                   track.first_stamp_s))
            outcome = outcomes[best.track_id]
            if not outcome.recognized:
                outcome.recognized = True
                outcome.recognized_after_s = event.stamp_s - best.first_stamp_s
                outcome.radius_at_recognition_px = _nearest_row(best, event.stamp_s).radius_px
            continue
        limit_tracks = [track for track in in_view if track.is_limit]
        if limit_tracks:
            misread += 1
            nearest = min(limit_tracks, key=lambda track: _distance_px(track, event))
            outcomes[nearest.track_id].wrong_values.append(event.limit_kmh)
        elif in_view:
            lookalike += 1
            nearest = min(in_view, key=lambda track: _distance_px(track, event))
            outcomes[nearest.track_id].wrong_values.append(event.limit_kmh)
        else:
            phantom += 1
    if stopped_early:
        for track in seen:
            outcome = outcomes[track.track_id]
            outcome.cut = (not outcome.recognized and (track.is_limit or track.is_end_of_limit)
                           and track.last_stamp_s + grace_s > last_stamp + tolerance_s)
    limit_outcomes = [outcome for outcome in outcomes.values()
                      if outcome.limit_kmh > 0 and not outcome.cut]
    end_outcomes = [outcome for outcome in outcomes.values()
                    if is_end_of_limit_kind(outcome.kind) and not outcome.cut]
    recognized = sum(outcome.recognized for outcome in limit_outcomes)
    wrong = lookalike + misread + phantom
    drive_time_s = last_stamp - first_stamp + period_s if stamps.size else 0.0
    return DriveScore(
        signs=len(limit_outcomes), recognized=recognized,
        recall=recall_of(recognized, len(limit_outcomes)),
        wrong_limits=wrong, lookalike_limits=lookalike, misread_limits=misread,
        phantom_limits=phantom, false_limits_per_hour=per_hour(wrong, drive_time_s),
        end_of_limit_signs=len(end_outcomes),
        end_of_limit_recognized=sum(outcome.recognized for outcome in end_outcomes),
        wrong_end_of_limits=wrong_ends,
        outcomes=tuple(sorted(outcomes.values(), key=lambda outcome: outcome.first_s)),
        drive_time_s=drive_time_s,
        cut_signs=sum(outcome.cut and outcome.limit_kmh > 0 for outcome in outcomes.values()))


def _nearest_row(track: TruthTrack, stamp_s: float) -> Any:
    return min(track.rows, key=lambda row: abs(row.stamp_s - stamp_s))


def _distance_px(track: TruthTrack, event: LimitEvent) -> float:
    """Distance from the event's position to the sign's box centre at that time."""
    if math.isnan(event.x_px):
        return 0.0
    centre_x, centre_y = _nearest_row(track, event.stamp_s).centre_px
    return math.hypot(centre_x - event.x_px, centre_y - event.y_px)


def new_limit_events(result: Any, recognized_track_ids: set[int]) -> list[LimitEvent]:
    """Limits newly recognized in one :class:`FrameResult` (updates ``recognized_track_ids``).

    A track of the pipeline recognizes its label once; each newly recognized track with a
    numeric label is an event at the track's position, one labelled end of limit an event
    with ``limit_kmh`` 0. A ``recognized_limit_kmh`` without
    such a track (should not happen) is still an event, without position.
    """
    events = []
    for track in result.tracks:
        if track.recognized and track.track_id not in recognized_track_ids:
            recognized_track_ids.add(track.track_id)
            if track.label.isdigit() or track.label == LABEL_END_OF_LIMIT:
                limit_kmh = int(track.label) if track.label.isdigit() else 0
                events.append(LimitEvent(result.stamp_s, limit_kmh, track.x_px,
                                         track.y_px, track.track_id))
    if result.recognized_limit_kmh and not any(
            event.limit_kmh == result.recognized_limit_kmh for event in events):
        events.append(LimitEvent(result.stamp_s, int(result.recognized_limit_kmh)))
    return events
