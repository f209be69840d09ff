"""Bookkeeping of the node's frames: the waiting frame, counters, latencies, log throttling.

No ROS here beyond the message objects passed through; the node's threads share one
:class:`FrameStatistics` under its lock.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from speed_sign_detector.ros.transport_loss import TransportLossMonitor

#: Latency samples kept for the percentiles in the diagnostics.
LATENCY_WINDOW = 300


@dataclass(frozen=True)
class ReceivedFrame:
    """A message waiting for the worker.

    Attributes:
        message: the sensor_msgs/Image or CompressedImage.
        topic: the resolved topic it came on.
        received_ns: node clock (ROS time) at receipt, nanoseconds.
        received_monotonic_s: ``time.monotonic()`` at receipt, seconds.
    """

    message: Any
    topic: str
    received_ns: int
    received_monotonic_s: float


class LogThrottle:
    """Log at most once per period; count what was held back and say so in the next log."""

    def __init__(self) -> None:
        self._last_s = -float('inf')
        self._suppressed = 0
        self._lock = threading.Lock()

    def admit(self, period_s: float) -> int | None:
        """Return the number of suppressed messages if one may be logged now, else None."""
        now = time.monotonic()
        with self._lock:
            if now - self._last_s < period_s:
                self._suppressed += 1
                return None
            suppressed, self._suppressed, self._last_s = self._suppressed, 0, now
            return suppressed


class FrameStatistics:
    """Counters and latency samples, written by the node's threads (guarded by ``lock``).

    ``transport_loss`` estimates the frames lost before they reached the node from the
    header stamps of those that did; ``lost_reported_by_middleware`` holds what the
    middleware's message-lost events counted, per topic.
    """

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.received = 0
        self.processed = 0
        self.dropped_stale = 0
        self.rejected = 0
        self.transport_loss = TransportLossMonitor()
        self.lost_reported_by_middleware: dict[str, int] = {}
        self.last_error = ''
        self.last_received_monotonic_s: float | None = None
        self.stamp_latency_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.processing_latency_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.stage_ms: dict[str, deque[float]] = {}
        self.active_limit_kmh = 0

    @property
    def dropped(self) -> int:
        """Frames received but not processed: replaced while waiting, or rejected."""
        return self.dropped_stale + self.rejected


def percentiles_ms(samples: deque[float]) -> tuple[float, float]:
    """(p50, p95) of the samples, NaN for none."""
    if not samples:
        return float('nan'), float('nan')
    p50, p95 = np.percentile(np.fromiter(samples, float), (50, 95))
    return float(p50), float(p95)


def describe_qos(qos: Any, *, with_history: bool = True) -> str:
    """'best_effort, volatile, keep_last 5' for a QoSProfile."""
    text = f'{qos.reliability.name.lower()}, {qos.durability.name.lower()}'
    return text + (f', {qos.history.name.lower()} {qos.depth}' if with_history else '')
