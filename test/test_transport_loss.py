"""The transport-loss estimate from header stamps (plain Python, no ROS)."""
from __future__ import annotations

import numpy as np
import pytest

from speed_sign_detector.ros.transport_loss import (
    TransportLossEstimator,
    TransportLossMonitor,
    period_from_gaps,
)

PERIOD_NS = 33_333_333  # 30 Hz


def estimate(stamps_ns: list[int]) -> tuple[int, float | None]:
    estimator = TransportLossEstimator()
    for stamp in stamps_ns:
        estimator.add(stamp)
    report = estimator.report()
    return report.frames_lost, report.frame_period_s


def jittered(indices: list[int], jitter_ns: int, seed: int, period_ns: int = PERIOD_NS,
             start_ns: int = 1_700_000_000_000_000_000) -> list[int]:
    rng = np.random.default_rng(seed)
    return [start_ns + index * period_ns + int(rng.integers(-jitter_ns, jitter_ns + 1))
            for index in indices]


def test_a_regular_stream_loses_nothing() -> None:
    lost, period_s = estimate(jittered(list(range(300)), 4_000_000, seed=1))
    assert lost == 0
    assert period_s == pytest.approx(PERIOD_NS * 1e-9, rel=0.1)


def test_skipped_stamps_are_counted_exactly() -> None:
    sent = list(range(200))
    skipped = {5, 17, 18, 40, 41, 42, 90, 120, 121, 160}
    lost, _ = estimate(jittered([i for i in sent if i not in skipped], 3_000_000, seed=2))
    assert lost == len(skipped)


def test_half_the_frames_lost_at_random_is_estimated_closely() -> None:
    rng = np.random.default_rng(3)
    kept = [i for i in range(600) if i in (0, 599) or rng.random() < 0.5]
    lost, _ = estimate(jittered(kept, 2_000_000, seed=4))
    assert abs(lost - (600 - len(kept))) <= 0.05 * (600 - len(kept))


def test_most_frames_lost_is_not_mistaken_for_a_slower_source() -> None:
    """56 % lost at random (a raw 640x480 stream with Fast DDS defaults, measured here):
    stretches of 2T, 3T, 4T gaps are losses, not a new rate."""
    rng = np.random.default_rng(5)
    kept = [i for i in range(600) if i in (0, 599) or rng.random() < 0.44]
    lost, _ = estimate(jittered(kept, 2_000_000, seed=6))
    assert abs(lost - (600 - len(kept))) <= 0.03 * (600 - len(kept))


@pytest.mark.parametrize('first_hz, then_hz', [(30, 10), (10, 30), (30, 15)])
def test_a_source_changing_rate_is_not_a_loss(first_hz: int, then_hz: int) -> None:
    first, then = 1_000_000_000 // first_hz, 1_000_000_000 // then_hz
    stamps = [index * first for index in range(90)]
    stamps += [stamps[-1] + (index + 1) * then for index in range(90)]
    lost, period_s = estimate(stamps)
    assert lost == 0
    assert period_s == pytest.approx(then * 1e-9, rel=0.05)


def test_restart_pause_and_duplicates_are_not_losses() -> None:
    base = 5_000_000_000
    stamps = [base + i * PERIOD_NS for i in range(30)]
    stamps += [stamps[-1]]                                          # same frame twice
    stamps += [base + i * PERIOD_NS for i in range(30)]             # source restarted
    stamps += [stamps[-1] + 3_000_000_000 + i * PERIOD_NS for i in range(30)]  # pause
    lost, _ = estimate(stamps)
    assert lost == 0


def test_losses_right_at_the_end_are_reported_before_later_frames_confirm_them() -> None:
    estimator = TransportLossEstimator()
    for index in [*range(50), 52]:   # frames 50 and 51 lost, nothing after
        estimator.add(index * PERIOD_NS + 1)
    assert estimator.report().frames_lost == 2


def test_monitor_keeps_topics_apart_and_reports_the_last_interval() -> None:
    monitor = TransportLossMonitor()
    for index in range(40):
        monitor.add('/camera/image_raw', 1 + index * PERIOD_NS)
        if index % 2 == 0:  # the compressed topic runs at half the rate: no loss
            monitor.add('/camera/image_raw/compressed', 1 + index * PERIOD_NS)
    assert monitor.since_last_call().frames_lost == 0
    for index in range(40, 80):
        if index % 4 != 1:
            monitor.add('/camera/image_raw', 1 + index * PERIOD_NS)
    recent = monitor.since_last_call()
    assert recent.frames_lost == 10
    assert recent.lost_share == pytest.approx(10 / 40)
    assert monitor.totals().frames_lost == 10
    assert monitor.since_last_call(monitor.totals()).frames_lost == 0   # nothing new
    monitor.add('/camera/image_raw', 0)  # unstamped frames are ignored
    assert monitor.totals().frames_received == 40 + 20 + 30


def test_period_of_gaps() -> None:
    assert period_from_gaps([]) is None
    ms = 1_000_000
    assert period_from_gaps([100 * ms, 210 * ms, 95 * ms, 105 * ms, 300 * ms]) == 100 * ms
    assert period_from_gaps([ms // 2, 100 * ms, ms // 2, 100 * ms]) == 100 * ms  # bursts


def test_late_frames_sent_in_bursts_are_not_losses() -> None:
    """A source stamping at publish time, starved of CPU: three frames late, then sent
    0.5 ms apart; the stamps span the right time, nothing is lost."""
    stamps, now = [], 1_000_000_000
    for index in range(200):
        if index % 10 == 5:
            now += 3 * PERIOD_NS
            stamps += [now, now + 500_000, now + 1_000_000]
            now += 1_000_000
        elif index % 10 not in (6, 7):
            now += PERIOD_NS
            stamps.append(now)
    lost, period_s = estimate(stamps)
    assert lost == 0
    assert period_s == pytest.approx(PERIOD_NS * 1e-9, rel=0.1)


@pytest.mark.parametrize('late_by_periods', [1, 2, 28])
def test_a_first_frame_sent_before_the_match_is_not_a_loss(late_by_periods: int) -> None:
    """The start-up of a replay or camera: the first frame that arrives was sent before
    the subscription matched (``late_by_periods`` periods before the next one to arrive,
    the frames in between never came); then a steady stream. No loss; a skipped frame
    later in the same stream still counts."""
    steady = jittered(list(range(1, 120)), 3_000_000, seed=7)
    first = steady[0] - (late_by_periods + 1) * PERIOD_NS
    lost, period_s = estimate([first, *steady])
    assert lost == 0
    assert period_s == pytest.approx(PERIOD_NS * 1e-9, rel=0.1)
    skipped_later = [first, *steady[:60], *steady[61:]]
    assert estimate(skipped_later)[0] == 1


def test_the_first_gaps_after_a_restart_are_start_up_too() -> None:
    """A looped bag starts again (stamps jump back): its first frame came late as well."""
    first_pass = [1_000_000_000 + index * PERIOD_NS for index in range(60)]
    second_pass = [1_000_000_000 + index * PERIOD_NS for index in (0, *range(4, 60))]
    monitor = TransportLossMonitor()
    for stamp in [*first_pass, *second_pass]:
        monitor.add('/camera/image_raw', stamp)
    assert monitor.totals().frames_lost == 0
    assert monitor.totals().frames_received == len(first_pass) + len(second_pass)
