"""Choosing between the GL detector and the CPU one by timing both on the first frames.

On a software OpenGL renderer (Mesa llvmpipe) the "GPU" passes run on the same CPU cores
as everything else, and whether they beat the vectorised CPU path
(:mod:`.gradients_cpu`, :mod:`.voting_cpu`) depends on the frame size, the scene and
what else the machine is doing. ``backend: auto`` therefore detects the first frames
with both, in alternating order, and keeps the faster: :class:`BackendTrial` holds the
times and makes the decision; :class:`~.detector.Detector` runs the paths.
"""
from __future__ import annotations

import statistics
from dataclasses import dataclass, field

TRIAL_PATHS: tuple[str, ...] = ('gl', 'cpu')
"""The paths a trial times, by backend name."""
WARMUP_FRAMES = 1
"""Frames each path runs before it is timed (GL builds its resources, the CPU its
stencils, on the first frame of a size)."""
TIMED_FRAMES = 5
"""Frames each path is timed on; the median decides."""


@dataclass(frozen=True)
class TrialDecision:
    """The outcome of a trial.

    Attributes:
        backend: the faster path, ``'gl'`` or ``'cpu'``.
        median_ms: median detection time of each path over the timed frames, ms.
        frames: frames timed per path.
        renderer: the GL renderer that was timed.
    """

    backend: str
    median_ms: dict[str, float]
    frames: int
    renderer: str

    def describe(self) -> str:
        """One line for logs and diagnostics, e.g. ``auto: cpu, 21.0 ms per frame
        against gl 35.2 ms on llvmpipe (...) (median of 5 frames)``."""
        other = next(name for name in self.median_ms if name != self.backend)
        return (f'auto: {self.backend}, {self.median_ms[self.backend]:.1f} ms per frame '
                f'against {other} {self.median_ms[other]:.1f} ms on {self.renderer} '
                f'(median of {self.frames} frames)')


@dataclass
class BackendTrial:
    """Times of the GL and CPU detection paths on the same frames, and the choice.

    Args:
        renderer: the GL renderer string (named in the decision).
        warmup_frames, timed_frames: per path, see :data:`WARMUP_FRAMES`,
            :data:`TIMED_FRAMES`.
    """

    renderer: str
    warmup_frames: int = WARMUP_FRAMES
    timed_frames: int = TIMED_FRAMES
    frames_seen: int = 0
    times_ms: dict[str, list[float]] = field(
        default_factory=lambda: {name: [] for name in TRIAL_PATHS})

    def order(self) -> tuple[str, ...]:
        """The order to run the paths in on the next frame (alternating, so that
        neither always runs on a warm or a cold cache)."""
        return TRIAL_PATHS if self.frames_seen % 2 == 0 else TRIAL_PATHS[::-1]

    def record(self, times_ms: dict[str, float]) -> TrialDecision | None:
        """Book one frame's time of each path (ms); the decision once every path has
        been timed on ``timed_frames`` frames after its warm-up, else None."""
        if set(times_ms) != set(TRIAL_PATHS):
            raise ValueError(f'a trial frame needs a time for each of {TRIAL_PATHS}, '
                             f'got {sorted(times_ms)}')
        self.frames_seen += 1
        if self.frames_seen > self.warmup_frames:
            for name, elapsed_ms in times_ms.items():
                self.times_ms[name].append(float(elapsed_ms))
        if self.frames_seen < self.warmup_frames + self.timed_frames:
            return None
        medians = {name: statistics.median(times) for name, times in self.times_ms.items()}
        fastest = min(TRIAL_PATHS, key=lambda name: (medians[name], name != 'gl'))
        return TrialDecision(fastest, medians, self.timed_frames, self.renderer)
