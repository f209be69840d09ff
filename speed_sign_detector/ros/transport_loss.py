"""Frames lost before they reached the node, estimated from the gaps between header stamps.

A camera stamps its frames at a steady period T (with some jitter). When best-effort DDS
drops a frame (a ~1 MB raw image overflowing the socket buffer is lost whole), the next
frame that arrives is stamped ~2T after the previous one: a gap of k periods means k - 1
frames were lost on the way.

The period is not configured: it is estimated from the gaps themselves, separately on
each side of the gap being judged, so that a source that changes rate is not mistaken
for one that loses frames:

* each gap is judged once the ``lookahead_gaps`` gaps after it are known (a report
  judges the newest gaps provisionally, with the later gaps there are);
* the period before it is estimated from up to ``history_gaps`` earlier gaps, the period
  after it from the following ones: the smallest gap of a side, then the median of the
  gaps below 1.5 x that smallest one (the single-period gaps: robust to jitter and to
  losses, which only make gaps longer);
* a gap counts ``min(round(gap / period_before), round(gap / period_after)) - 1`` lost
  frames. A camera that slows from 30 to 10 Hz shows 3T gaps before the change, but T'
  = 3T gaps after it: nothing is counted. A camera that speeds up is the mirror case.
  When the gaps after are whole but *different* multiples of the period before (2T,
  4T, 3T, ...), the source did not slow down: it is losing most of its frames, and
  the period before stands for both.

Gaps of zero (the same stamp twice), stamps going back (a restarted source or a looped
bag) and gaps longer than ``pause_s`` (a source that paused) are not losses: a jump
back or a pause restarts the estimate. Nor are the first gaps of a stream (the first
:data:`MIN_GAPS_FOR_PERIOD`, after the start or a restart): while the subscription and
the publisher are still matching, the first frame that arrives may be one sent before
the match, delivered late by a reliable publisher (``speed_sign_replay`` stamps its
first frame, waits for it to be acknowledged, then plays on), and the frames sent in
between never arrive: start-up, not transport loss. A gap counts only against a period
established before it. A source that stamps frames when it publishes
them (a replay with ``--restamp``, some drivers) and is starved of CPU sends late
frames in bursts: a long gap followed by very short ones. The short ("burst") gaps are
left out of the period estimate, and each repays one frame of an apparent loss among
the gaps just before it: the frames were late, not lost. Pure Python, no ROS: the node
feeds it stamps.
"""
from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass

#: Gaps shorter than this factor times the smallest gap of a window count as one period.
SINGLE_PERIOD_FACTOR = 1.5
#: Earlier gaps needed before they give a period of their own; a gap with fewer before
#: it (the start of a stream) counts no loss.
MIN_GAPS_FOR_PERIOD = 3
#: Periods before and after a gap closer than this fraction are the same rate.
SAME_PERIOD_TOLERANCE = 0.15
#: Gaps shorter than this fraction of the median gap are bursts, not periods.
BURST_FRACTION = 0.3
#: No camera stream runs faster than this period (500 Hz): shorter gaps are bursts.
MIN_FRAME_PERIOD_NS = 2_000_000


@dataclass(frozen=True)
class TransportLossReport:
    """What an estimator knows now.

    Attributes:
        frames_received: stamps fed (every frame that reached the node).
        frames_lost: frames estimated lost before reaching the node.
        frame_period_s: the source's current frame period estimate, seconds (None until
            two gaps were seen).
    """

    frames_received: int
    frames_lost: int
    frame_period_s: float | None

    @property
    def lost_share(self) -> float:
        """Lost frames / frames the source sent (received + lost); 0 with no frames."""
        sent = self.frames_received + self.frames_lost
        return self.frames_lost / sent if sent else 0.0


def period_from_gaps(gaps_ns: list[int]) -> int | None:
    """The frame period of a run of gaps (ns): the median of the single-period gaps.

    Burst gaps (see :func:`burst_threshold_ns`) are left out. Returns None when no gap
    is left.
    """
    if not gaps_ns:
        return None
    threshold = burst_threshold_ns(gaps_ns)
    regular = [gap for gap in gaps_ns if gap >= threshold]
    if not regular:
        return None
    smallest = min(regular)
    singles = [gap for gap in regular if gap < SINGLE_PERIOD_FACTOR * smallest]
    return int(statistics.median(singles))


def burst_threshold_ns(gaps_ns: list[int]) -> float:
    """Gaps below this are bursts: frames published late in a row (a source stamping at
    publish time while starved of CPU), not the camera's period: below
    :data:`BURST_FRACTION` of the median gap, or below :data:`MIN_FRAME_PERIOD_NS`."""
    return max(MIN_FRAME_PERIOD_NS, BURST_FRACTION * statistics.median(gaps_ns))


class TransportLossEstimator:
    """Counts frames missing from one stream of header stamps (one topic).

    Args:
        history_gaps: earlier gaps used for the period before a gap.
        lookahead_gaps: later gaps a gap waits for before it is judged (its count then
            is committed; until then reports judge it provisionally with fewer).
        pause_s: a longer gap is a pause of the source, not a loss.
    """

    def __init__(self, history_gaps: int = 30, lookahead_gaps: int = 8,
                 pause_s: float = 1.0) -> None:
        if history_gaps < 1 or lookahead_gaps < 1 or pause_s <= 0:
            raise ValueError('history_gaps and lookahead_gaps must be >= 1, pause_s > 0')
        self._history_gaps = history_gaps
        self._lookahead_gaps = lookahead_gaps
        self._pause_ns = int(pause_s * 1e9)
        self._judged: deque[int] = deque(maxlen=history_gaps)
        self._pending: list[int] = []
        self._last_stamp_ns: int | None = None
        self._received = 0
        self._ledger = LossLedger(lookahead_gaps)

    def add(self, stamp_ns: int) -> None:
        """Feed the header stamp (ns) of the next frame that arrived."""
        self._received += 1
        last, self._last_stamp_ns = self._last_stamp_ns, stamp_ns
        if last is None:
            return
        gap = stamp_ns - last
        if gap == 0:
            return  # the same frame twice (or two topics of one camera): no gap
        if gap < 0 or gap > self._pause_ns:
            self._restart()
            return
        self._pending.append(gap)
        while len(self._pending) > self._lookahead_gaps:
            self._judge_first()

    def flush(self) -> None:
        """Judge the gaps still waiting for their lookahead, with the gaps there are."""
        while self._pending:
            self._judge_first()

    def report(self) -> TransportLossReport:
        """Counts so far. Gaps still waiting for their lookahead are judged provisionally
        (with the later gaps there are), without committing their count."""
        history = deque(self._judged, maxlen=self._history_gaps)
        ledger = self._ledger.copy()
        for index, gap in enumerate(self._pending):
            ledger.apply(lost_in_gap(gap, list(history), self._pending[index + 1:]))
            history.append(gap)
        recent = list(self._judged) + self._pending
        period = period_from_gaps(recent) if len(recent) >= 2 else None
        return TransportLossReport(self._received, ledger.lost,
                                   period * 1e-9 if period is not None else None)

    def _judge_first(self) -> None:
        gap = self._pending.pop(0)
        self._ledger.apply(lost_in_gap(gap, list(self._judged), self._pending))
        self._judged.append(gap)

    def _restart(self) -> None:
        """A jump back or a pause: judge what is pending, start a fresh period estimate."""
        self.flush()
        self._judged.clear()


def lost_in_gap(gap_ns: int, earlier_ns: list[int], later_ns: list[int]) -> int:
    """Frames lost in a gap, judged against the periods before and after it (see module);
    -1 for a burst gap (a frame that came early: it repays an apparent loss just before).

    With fewer than :data:`MIN_GAPS_FOR_PERIOD` earlier gaps (a stream that just began:
    its first frames may have been sent before the subscription matched) nothing is
    counted; with no later gap yet (the newest gap), the period before it stands for
    both. When both periods agree (within :data:`SAME_PERIOD_TOLERANCE`), their gaps are
    pooled for one, finer estimate.
    """
    if len(earlier_ns) < MIN_GAPS_FOR_PERIOD:
        return 0   # start-up: no period established before this gap
    before = period_from_gaps(earlier_ns)
    after = period_from_gaps([gap_ns, *later_ns]) if later_ns else None
    before, after = before or after, after or before
    if before is None or after is None:
        return 0
    if after > (1 + SAME_PERIOD_TOLERANCE) * before and irregular_multiples(
            [gap_ns, *later_ns], before):
        after = before  # heavy loss, not a slower source: see irregular_multiples
    if abs(before - after) <= SAME_PERIOD_TOLERANCE * min(before, after):
        pooled = period_from_gaps([*earlier_ns, gap_ns, *later_ns])
        before = after = pooled if pooled is not None else before
    if gap_ns < 0.5 * min(before, after):
        return -1
    periods = min(round(gap_ns / before), round(gap_ns / after))
    return max(periods - 1, 0)


def irregular_multiples(gaps_ns: list[int], period_ns: int) -> bool:
    """True when the gaps are whole multiples of ``period_ns`` (within 0.2) but not all
    the same multiple: frames lost at random from a source still at that period. A
    source that slowed down gives the same (or a fractional) multiple every time."""
    ratios = [gap / period_ns for gap in gaps_ns]
    whole = all(abs(ratio - round(ratio)) < 0.2 for ratio in ratios)
    return whole and len({round(ratio) for ratio in ratios}) > 1


class LossLedger:
    """Running count of lost frames; a burst gap repays an apparent loss among the last
    ``window`` gaps (frames that were late, not lost), never an older one."""

    def __init__(self, window: int) -> None:
        self.lost = 0
        self._recent: deque[int] = deque(maxlen=window)

    def copy(self) -> LossLedger:
        twin = LossLedger(self._recent.maxlen or 1)
        twin.lost, twin._recent = self.lost, deque(self._recent, maxlen=self._recent.maxlen)
        return twin

    def apply(self, contribution: int) -> None:
        """Book one judged gap (a :func:`lost_in_gap` result)."""
        if contribution >= 0:
            self.lost += contribution
            self._recent.append(contribution)
        elif sum(self._recent) > 0:
            self.lost -= 1
            self._recent.append(-1)
        else:
            self._recent.append(0)


class TransportLossMonitor:
    """One estimator per topic, and the loss between two reports (for warnings).

    Not thread-safe: the node calls it under its statistics lock.
    """

    def __init__(self, **estimator_options: float) -> None:
        self._options = estimator_options
        self._estimators: dict[str, TransportLossEstimator] = {}
        self._reported = (0, 0)

    def add(self, topic: str, stamp_ns: int) -> None:
        """Feed a frame's header stamp (ns) as it arrives on ``topic``."""
        if stamp_ns <= 0:
            return  # unstamped frames carry no timing
        estimator = self._estimators.get(topic)
        if estimator is None:
            estimator = self._estimators[topic] = TransportLossEstimator(**self._options)
        estimator.add(stamp_ns)

    def totals(self) -> TransportLossReport:
        """Every topic's counts summed; the period is the busiest topic's."""
        reports = [estimator.report() for estimator in self._estimators.values()]
        if not reports:
            return TransportLossReport(0, 0, None)
        busiest = max(reports, key=lambda report: report.frames_received)
        return TransportLossReport(sum(r.frames_received for r in reports),
                                   sum(r.frames_lost for r in reports),
                                   busiest.frame_period_s)

    def lost_by_topic(self) -> dict[str, int]:
        """Frames estimated lost so far, per topic."""
        return {topic: estimator.report().frames_lost
                for topic, estimator in self._estimators.items()}

    def since_last_call(self, totals: TransportLossReport | None = None
                        ) -> TransportLossReport:
        """Totals minus those at the previous call: the loss over the last interval.

        Args:
            totals: :meth:`totals` just taken, when the caller has them (saves computing
                them again).
        """
        totals = totals if totals is not None else self.totals()
        received, lost = self._reported
        self._reported = (totals.frames_received, totals.frames_lost)
        return TransportLossReport(totals.frames_received - received,
                                   totals.frames_lost - lost, totals.frame_period_s)
