"""Limit in force and time in correct limit on hand-made drives with exact answers."""
from __future__ import annotations

import pytest

from speed_sign_detector.limit_in_force import (
    limit_in_force_kmh,
    limit_sign_passings,
    score_time_in_limit,
)
from speed_sign_detector.truth import TruthRow, group_tracks

#: 10 Hz frames 0.0 .. 10.0 s (101 frames: 100 periods of 0.1 s).
STAMPS_S = [round(0.1 * index, 6) for index in range(101)]


def sign(track_id: int, kind: str, limit_kmh: int, first_s: float, last_s: float
         ) -> list[TruthRow]:
    """Rows of a sign visible from ``first_s`` to ``last_s`` (every 0.1 s)."""
    count = int(round((last_s - first_s) / 0.1)) + 1
    return [TruthRow(round(first_s + 0.1 * index, 6), 0, track_id, kind, limit_kmh,
                     100.0, 100.0, 120.0, 120.0) for index in range(count)]


#: A 50 passed at 2.0 s, a look-alike in between, an end of limit passed at 6.0 s, a 30
#: in view from 7.0 s and passed at 8.0 s.
TRACKS = group_tracks(sign(1, '50', 50, 1.0, 2.0) + sign(2, 'no_overtaking', 0, 3.0, 4.0)
                      + sign(3, 'end_of_limit_50', 0, 5.0, 6.0) + sign(4, '30', 30, 7.0, 8.0))


def test_limit_in_force_changes_when_each_sign_is_passed() -> None:
    passings = limit_sign_passings(TRACKS)
    assert [(p.passed_stamp_s, p.limit_kmh) for p in passings] == [(2.0, 50), (6.0, 0),
                                                                    (8.0, 30)]
    assert limit_in_force_kmh(passings, 1.9) is None
    assert limit_in_force_kmh(passings, 2.0) == 50
    assert limit_in_force_kmh(passings, 5.9) == 50
    assert limit_in_force_kmh(passings, 6.0) == 0
    assert limit_in_force_kmh(passings, 9.9) == 30


def test_perfect_publication_scores_one_over_the_time_after_the_first_sign() -> None:
    score = score_time_in_limit(TRACKS, STAMPS_S, [(2.0, 50), (6.0, 0), (8.0, 30)])
    assert score.judged_s == pytest.approx(8.0)
    assert score.time_in_correct_limit == pytest.approx(1.0)
    assert score.time_in_correct_limit_strict == pytest.approx(1.0)


def test_late_and_wrong_limits_lose_exactly_their_time() -> None:
    # 50 published 0.5 s late; the end of limit missed (50 held 2 s too long);
    # 80 published at 9.0 s for no reason: 0.5 + 2.0 + 1.0 = 3.5 s of 8 s wrong.
    changes = [(2.5, 50), (8.0, 30), (9.0, 80)]
    score = score_time_in_limit(TRACKS, STAMPS_S, changes)
    assert score.time_in_correct_limit == pytest.approx(4.5 / 8.0)
    assert score.time_in_correct_limit_strict == pytest.approx(4.5 / 8.0)


def test_announcing_the_next_sign_in_view_is_accepted_but_not_strictly() -> None:
    # the 30 shown from 7.5 s, while it is in view and the next sign to be passed
    changes = [(2.0, 50), (6.0, 0), (7.5, 30)]
    score = score_time_in_limit(TRACKS, STAMPS_S, changes)
    assert score.time_in_correct_limit == pytest.approx(1.0)
    assert score.time_in_correct_limit_strict == pytest.approx(7.5 / 8.0)


def test_a_far_sign_shown_before_the_near_one_is_passed_is_wrong() -> None:
    """A 50 passed at 0.5 s; a near 30 (in view from 0.5 s, passed at 2.0 s) and a far
    20 (in view from 1.0 s, passed at 4.0 s). Showing the 20 from 1.5 s, while the 30
    is still ahead, is wrong until the 30 is passed (0.5 s); from then on the 20 is the
    next sign and in view: announced, accepted."""
    tracks = group_tracks(sign(1, '50', 50, 0.0, 0.5) + sign(2, '30', 30, 0.5, 2.0)
                          + sign(3, '20', 20, 1.0, 4.0))
    stamps = STAMPS_S[:51]   # 0 .. 5 s; judged from 0.5 s: 4.5 s
    score = score_time_in_limit(tracks, stamps, [(0.5, 50), (1.0, 30), (1.5, 20)])
    assert score.judged_s == pytest.approx(4.5)
    assert score.time_in_correct_limit == pytest.approx(4.0 / 4.5)
    # exact: 50 from 0.5 to 1.0 s and 20 from 4.0 to 5.0 s
    assert score.time_in_correct_limit_strict == pytest.approx(1.5 / 4.5)
    # the near sign governing until it is passed, then the far one: all acceptable
    fixed = score_time_in_limit(tracks, stamps, [(0.5, 50), (1.0, 30), (2.3, 20)])
    assert fixed.time_in_correct_limit == pytest.approx(1.0)
    assert fixed.time_in_correct_limit_strict == pytest.approx((0.5 + 0.3 + 1.0) / 4.5)


def test_no_limit_sign_passed_gives_no_share() -> None:
    tracks = group_tracks(sign(1, 'no_entry', 0, 1.0, 2.0) + sign(2, '60', 60, 8.0, 12.0))
    score = score_time_in_limit(tracks, STAMPS_S, [(9.0, 60)])
    assert score.time_in_correct_limit is None and score.judged_s == 0.0


def test_of_signs_passed_together_the_nearest_rules_and_either_may_be_announced() -> None:
    """Two limit signs leave the view in the same frame (an approach sequence on one sign
    with a second, smaller one in the scene): the larger, nearer one sets the limit."""
    near = sign(1, '60', 60, 1.0, 3.0)
    far = [TruthRow(row.stamp_s, 0, 2, '80', 80, 10.0, 10.0, 16.0, 16.0)
           for row in sign(2, '80', 80, 1.0, 3.0)]
    tracks = group_tracks(sign(3, '50', 50, 0.0, 0.5) + far + near)
    assert limit_in_force_kmh(limit_sign_passings(tracks), 3.0) == 60
    score = score_time_in_limit(tracks, STAMPS_S[:51], [(0.5, 50), (2.0, 80), (3.0, 60)])
    assert score.time_in_correct_limit == pytest.approx(1.0)
    # the 80 announced from 2.0 to 3.0 s is not the limit in force (50)
    assert score.time_in_correct_limit_strict == pytest.approx(3.5 / 4.5)


def _reference_score(tracks: list, stamps: list[float], changes: list[tuple[float, int]],
                     tolerance_s: float) -> tuple[float, float, float]:
    """The module docstring's definitions, read literally: every sign examined at every
    frame (slow, obviously right)."""
    passings = limit_sign_passings(tracks)
    judged = acceptable = exact = 0.0
    for stamp, following in zip(stamps, stamps[1:]):
        passed = [p for p in passings if p.passed_stamp_s <= stamp + tolerance_s]
        if not passed:
            continue
        in_force = passed[-1].limit_kmh
        published = 0
        for change_stamp, value in changes:
            if change_stamp <= stamp + 1e-9:
                published = value
        upcoming = [p for p in passings if p.passed_stamp_s > stamp + tolerance_s]
        announced = {p.limit_kmh for p in upcoming
                     if p.passed_stamp_s <= upcoming[0].passed_stamp_s + 1e-9
                     and p.first_stamp_s <= stamp + tolerance_s} if upcoming else set()
        judged += following - stamp
        exact += (following - stamp) * (published == in_force)
        acceptable += (following - stamp) * (published == in_force or published in announced)
    return judged, acceptable, exact


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_time_in_limit_matches_the_literal_definition_on_random_drives(seed: int) -> None:
    """Many overlapping signs (some passed at the same frame) and random publications:
    the bisecting implementation gives the literal definition's shares."""
    import random
    generator = random.Random(seed)
    rows: list[TruthRow] = []
    for track_id in range(1, 41):
        first_s = round(generator.randrange(0, 90) * 0.1, 6)
        last_s = round(first_s + generator.randrange(0, 15) * 0.1, 6)
        limit_kmh = generator.choice([30, 50, 70, 0])
        kind = str(limit_kmh) if limit_kmh else generator.choice(['end_of_limit_50',
                                                                  'no_overtaking'])
        rows += sign(track_id, kind, limit_kmh, first_s, last_s)
    tracks = group_tracks(sorted(rows, key=lambda row: row.stamp_s))
    changes = sorted((round(generator.randrange(0, 100) * 0.1, 6),
                      generator.choice([0, 30, 50, 70])) for _ in range(25))
    score = score_time_in_limit(tracks, STAMPS_S, changes)
    judged, acceptable, exact = _reference_score(tracks, STAMPS_S, changes, 0.05 + 1e-4)
    assert judged > 0.0
    assert score.judged_s == pytest.approx(judged)
    assert score.time_in_correct_limit == pytest.approx(acceptable / judged)
    assert score.time_in_correct_limit_strict == pytest.approx(exact / judged)
