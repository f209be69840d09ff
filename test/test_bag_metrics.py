"""Per-sign scoring of a drive: matching recognized limits to truth signs."""
from __future__ import annotations

import pytest

from speed_sign_detector.tools.bag_grading import (
    DRIVE_COUNT_KEYS,
    EARLY_RECOGNITION_S,
    LimitEvent,
    drive_metrics,
    score_drive,
    sum_drive_metrics,
)
from speed_sign_detector.truth import TruthRow, group_tracks

FPS = 10.0
STAMPS = [100.0 + index / FPS for index in range(100)]   # 10 s of drive


def sign_rows(track_id: int, kind: str, limit: int, first: int, last: int,
              x_px: float = 400.0) -> list[TruthRow]:
    return [TruthRow(STAMPS[index], index, track_id, kind, limit, x_px - 10, 190.0,
                     x_px + 10, 210.0) for index in range(first, last + 1)]


TRACKS = group_tracks(sign_rows(1, '50', 50, 0, 20) + sign_rows(2, 'no_overtaking', 0, 30, 45)
                      + sign_rows(3, '80', 80, 50, 70) + sign_rows(4, '30', 30, 80, 95))


def test_all_recognized_in_time_gives_full_recall() -> None:
    events = [LimitEvent(STAMPS[10], 50, 400.0, 200.0), LimitEvent(STAMPS[65], 80),
              LimitEvent(STAMPS[90], 30)]
    score = score_drive(TRACKS, events, STAMPS)
    assert (score.signs, score.recognized, score.recall) == (3, 3, 1.0)
    assert score.wrong_limits == 0 and score.false_limits_per_hour == 0.0
    first = score.outcomes[0]
    assert first.recognized and first.recognized_after_s == pytest.approx(1.0)
    assert first.radius_at_recognition_px == pytest.approx(10.0)
    assert [outcome.track_id for outcome in score.outcomes] == [1, 2, 3, 4]


def test_grace_after_the_sign_left_and_late_recognition() -> None:
    # Sign 1 leaves at frame 20 (102.0 s): 0.8 s later counts, 1.5 s later does not.
    within = score_drive(TRACKS, [LimitEvent(STAMPS[28], 50)], STAMPS, grace_s=1.0)
    assert within.recognized == 1 and within.wrong_limits == 0
    late = score_drive(TRACKS, [LimitEvent(STAMPS[35], 50)], STAMPS, grace_s=1.0)
    assert late.recognized == 0
    # At 103.5 s the look-alike (track 2) is in view: a 50 there is a look-alike limit.
    assert (late.wrong_limits, late.lookalike_limits) == (1, 1)
    assert late.outcomes[1].wrong_values == [50]


def test_wrong_values_are_split_by_what_was_in_view() -> None:
    events = [LimitEvent(STAMPS[5], 60),     # sign 50 in view: misread
              LimitEvent(STAMPS[40], 70),    # only the look-alike in view
              LimitEvent(STAMPS[76], 120)]   # nothing in view (sign 80 left at 70 + 0.6 s)
    score = score_drive(TRACKS, events, STAMPS, grace_s=0.5)
    assert (score.misread_limits, score.lookalike_limits, score.phantom_limits) == (1, 1, 1)
    assert score.wrong_limits == 3 and score.recognized == 0 and score.recall == 0.0
    assert score.false_limits_per_hour == pytest.approx(3 / (10.0 / 3600.0))
    assert score.outcomes[0].wrong_values == [60]


def test_a_second_event_for_a_recognized_sign_is_not_wrong() -> None:
    score = score_drive(TRACKS, [LimitEvent(STAMPS[5], 50), LimitEvent(STAMPS[15], 50)],
                        STAMPS)
    assert score.recognized == 1 and score.wrong_limits == 0


def test_signs_after_the_last_processed_frame_are_not_counted() -> None:
    score = score_drive(TRACKS, [LimitEvent(STAMPS[10], 50)], STAMPS[:40])
    assert score.signs == 1 and score.recall == 1.0
    assert [outcome.track_id for outcome in score.outcomes] == [1, 2]


def test_position_decides_between_two_signs_of_the_same_value() -> None:
    rows = sign_rows(1, '50', 50, 0, 20, x_px=100.0) + sign_rows(2, '50', 50, 0, 20, x_px=500.0)
    score = score_drive(group_tracks(rows), [LimitEvent(STAMPS[10], 50, 498.0, 200.0)], STAMPS)
    recognized = {outcome.track_id: outcome.recognized for outcome in score.outcomes}
    assert recognized == {1: False, 2: True}
    assert score.recall == 0.5


def test_drive_without_limit_signs_has_no_recall() -> None:
    score = score_drive(group_tracks(sign_rows(1, 'no_entry', 0, 0, 10)), [], STAMPS)
    assert score.signs == 0 and score.recall is None and score.wrong_limits == 0


def test_end_of_limit_recognitions_are_matched_to_end_of_limit_signs() -> None:
    tracks = group_tracks(sign_rows(1, '50', 50, 0, 20)
                          + sign_rows(2, 'end_of_limit_50', 0, 30, 45))
    events = [LimitEvent(STAMPS[10], 50), LimitEvent(STAMPS[40], 0),   # right
              LimitEvent(STAMPS[15], 0), LimitEvent(STAMPS[70], 0)]     # wrong twice
    score = score_drive(tracks, events, STAMPS)
    assert (score.end_of_limit_signs, score.end_of_limit_recognized) == (1, 1)
    assert score.wrong_end_of_limits == 2
    assert score.wrong_limits == 0 and score.recall == 1.0
    assert score.outcomes[0].wrong_values == [0]


def test_a_sign_read_just_before_it_is_listed_counts_for_it() -> None:
    """The truth lists a sign from 5 px and 3/4 inside the image; read a few frames
    earlier, its value (or its end) counts for it, not as a wrong answer on the sign in
    view; earlier than EARLY_RECOGNITION_S, or another value, it does not."""
    tracks = group_tracks(sign_rows(1, '20', 20, 0, 60)
                          + sign_rows(2, 'end_of_limit_20', 0, 43, 60, x_px=500.0)
                          + sign_rows(3, '70', 70, 80, 95, x_px=300.0))
    early = round(EARLY_RECOGNITION_S * FPS)
    events = [LimitEvent(STAMPS[5], 20), LimitEvent(STAMPS[43 - early + 1], 0),
              LimitEvent(STAMPS[80 - early + 1], 70)]
    score = score_drive(tracks, events, STAMPS, grace_s=0.0)
    assert (score.end_of_limit_recognized, score.wrong_end_of_limits) == (1, 0)
    assert score.recognized == 2 and score.wrong_limits == 0
    too_early = score_drive(tracks, [LimitEvent(STAMPS[5], 20),
                                     LimitEvent(STAMPS[43 - early - 3], 0)], STAMPS, grace_s=0.0)
    assert (too_early.end_of_limit_recognized, too_early.wrong_end_of_limits) == (0, 1)
    assert too_early.outcomes[0].wrong_values == [0]
    other = score_drive(tracks, [LimitEvent(STAMPS[80 - early + 1], 30)], STAMPS, grace_s=0.0)
    assert other.recognized == 0 and other.wrong_limits == 1


def test_metrics_of_many_drives_are_their_counts_summed() -> None:
    """Two drives scored separately, summed: counts and drive time add, the rates follow."""
    first = score_drive(TRACKS, [LimitEvent(STAMPS[10], 50), LimitEvent(STAMPS[76], 120)],
                        STAMPS, grace_s=0.5)
    second = score_drive(TRACKS, [LimitEvent(STAMPS[65], 80)], STAMPS[:60])
    summaries = [drive_metrics({key: getattr(score, key) for key in DRIVE_COUNT_KEYS},
                               score.drive_time_s) for score in (first, second)]
    assert summaries[0]['recall'] == first.recall
    assert summaries[0]['false_limits_per_hour'] == first.false_limits_per_hour
    assert first.drive_time_s == pytest.approx(10.0) and second.drive_time_s == pytest.approx(6.0)
    total = sum_drive_metrics([*summaries, {'frames': 3}])   # a drive without truth: left out
    assert total is not None and total['drives'] == 2
    assert total['signs'] == first.signs + second.signs == 3 + 2
    assert total['recognized'] == first.recognized + second.recognized == 1 + 1
    assert total['recall'] == pytest.approx(2 / 5)
    assert total['drive_time_s'] == pytest.approx(16.0)
    assert total['false_limits_per_hour'] == pytest.approx(1 / (16.0 / 3600.0))
    assert sum_drive_metrics([{'frames': 3}]) is None


def test_signs_cut_off_by_an_early_stop_are_not_missed() -> None:
    """The frames end at frame 60 (a truncated bag, Ctrl-C): the 80 sign (frames 50-70)
    was in view and not yet recognized: cut, out of signs and recall. The 50 sign
    (recognized) still counts; so would a sign that left view more than the grace
    before the stop."""
    stopped = score_drive(TRACKS, [LimitEvent(STAMPS[10], 50)], STAMPS[:61],
                          grace_s=1.0, stopped_early=True)
    assert (stopped.signs, stopped.recognized, stopped.recall, stopped.cut_signs) == \
        (1, 1, 1.0, 1)
    assert {outcome.track_id: outcome.cut for outcome in stopped.outcomes} == {
        1: False, 2: False, 3: True}
    # the same frames from a recording that really ends there: the 80 sign is missed
    ended = score_drive(TRACKS, [LimitEvent(STAMPS[10], 50)], STAMPS[:61], grace_s=1.0)
    assert (ended.signs, ended.recall, ended.cut_signs) == (2, 0.5, 0)
    # recognized before the stop: counted, not cut
    early = score_drive(TRACKS, [LimitEvent(STAMPS[10], 50), LimitEvent(STAMPS[55], 80)],
                        STAMPS[:61], stopped_early=True)
    assert (early.signs, early.recognized, early.cut_signs) == (2, 2, 0)
    # a sign whose grace ends before the stop is judged: missed
    late_stop = score_drive(TRACKS, [], STAMPS[:30], grace_s=0.5, stopped_early=True)
    assert (late_stop.signs, late_stop.recognized, late_stop.cut_signs) == (1, 0, 0)
    # ... but within the grace it is cut
    within = score_drive(TRACKS, [], STAMPS[:25], grace_s=0.5, stopped_early=True)
    assert (within.signs, within.cut_signs) == (0, 1) and within.recall is None
