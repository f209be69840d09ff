"""Temporal integration of classified candidates, and the active speed limit.

Follows IVS 2011 section III-C and DAGM 2010 section 4: a running table of sign
candidates over the last ~10 frames. A candidate joins the track whose predicted centre
is nearest (within ``association_radius_factor`` radii, or
``unpredicted_association_radius_factor`` for a track observed once, whose velocity is not
known yet). Each observation votes for its label with its PSR, multiplied by
``growth_boost`` when the sign is larger than at the oldest observation still in the
window (an approaching sign; at 30 fps a sign grows a few per cent per frame, within the
noise of one frame to the next, so growth is judged over the window), by
``shrink_penalty`` when it is smaller, and by ``rotation_penalty`` when its in-plane
rotation jumps from the previous observation. A track's evidence for
a label is the sum of its votes inside the window (``window_frames`` frames and
``window_s`` seconds of message time, whichever is shorter): an artifact that stays the
same size for ever never gathers more than a window of unboosted votes. A limit is
recognized once its evidence reaches ``recognition_threshold`` and holds the majority
of the track's evidence; each track decides once.

The active limit follows the sign being passed: among the decided tracks still in the
table (a speed limit, or end of limit = 0), the **nearest** one, i.e. the one with the
largest radius, governs, and its value is the active limit; when no decided track is
left (the signs were passed and their tracks expired), the last value is held. So a far
sign decided while a nearer decided sign is still in view waits until the nearer one
has been passed and its track has expired (e.g. a near 30 and a far 20: 30 until the 30
is passed, then 20), and a far sign decided first gives way to a nearer one once that
is decided. A lone sign takes effect as soon as it is decided, as before: the display
announces the sign the driver is looking at.

Tracks expire when unobserved for the same window, so dropped frames do not stretch
their memory.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from speed_sign_detector.config import TrackerConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.recognition.classifier import (
    LABEL_END_OF_LIMIT,
    LABEL_NO_SIGN,
    Classification,
)

#: Relative size change under which a sign counts as neither growing nor shrinking.
SIZE_CHANGE_TOLERANCE = 0.03
#: A frame this many seconds older than the previous one means the source restarted
#: (a bag replayed again): the tracker resets. Smaller steps back (frames slightly out
#: of order) are integrated as they come.
RESTART_JUMP_BACK_S = 1.0


@dataclass(frozen=True)
class TrackState:
    """One track of the table as seen after a frame.

    Attributes:
        track_id: unique, increasing id.
        x_px, y_px: centre of the last observation, pixels.
        radius_px: radius of the last observation, pixels.
        label: the label with the most evidence so far.
        evidence: that label's accumulated evidence (sum of weighted PSRs).
        total_evidence: evidence summed over all labels.
        observations: number of frames the track was observed in.
        first_stamp_s, last_stamp_s: message times of the first and last observation.
        recognized: True once the track's label was recognized (reported once).
    """

    track_id: int
    x_px: float
    y_px: float
    radius_px: float
    label: str
    evidence: float
    total_evidence: float
    observations: int
    first_stamp_s: float
    last_stamp_s: float
    recognized: bool


@dataclass(frozen=True)
class TrackerUpdate:
    """What one frame changed.

    Attributes:
        tracks: the table after the frame.
        active_limit_kmh: the limit in force, 0 when none is known: the value of the
            nearest decided sign still tracked, else the last one held.
        recognized_limit_kmh: a limit recognized in this frame, 0 when none.
        recognized_end_of_limit: True when an end-of-limit sign was recognized now.
        tracks_reset: True when this frame's time jumped back more than
            :data:`RESTART_JUMP_BACK_S` and the tracker started afresh.
    """

    tracks: tuple[TrackState, ...]
    active_limit_kmh: int
    recognized_limit_kmh: int
    recognized_end_of_limit: bool
    tracks_reset: bool = False


@dataclass
class _Track:
    track_id: int
    x_px: float
    y_px: float
    radius_px: float
    rotation_deg: float
    first_stamp_s: float
    last_stamp_s: float
    last_frame_index: int
    velocity_px_per_s: tuple[float, float] = (0.0, 0.0)
    #: votes inside the window: (frame index, stamp s, label, weighted vote, radius px)
    votes: deque[tuple[int, float, str, float, float]] = field(default_factory=deque)
    observations: int = 0
    recognized: bool = False
    #: the limit this track decided, km/h (0 = end of limit); None while undecided or
    #: when it decided another sign
    decided_limit_kmh: int | None = None

    @property
    def evidence(self) -> dict[str, float]:
        """Sum of the votes inside the window, by label."""
        totals: dict[str, float] = {}
        for _, _, label, vote, _ in self.votes:
            totals[label] = totals.get(label, 0.0) + vote
        return totals

    def forget_votes_before(self, frame_index: int, stamp_s: float) -> None:
        """Drop votes older than the window (``frame_index``/``stamp_s`` are its start)."""
        while self.votes and (self.votes[0][0] < frame_index or self.votes[0][1] < stamp_s):
            self.votes.popleft()

    def predicted_centre(self, stamp_s: float) -> tuple[float, float]:
        elapsed_s = max(0.0, stamp_s - self.last_stamp_s)
        return (self.x_px + self.velocity_px_per_s[0] * elapsed_s,
                self.y_px + self.velocity_px_per_s[1] * elapsed_s)

    def snapshot(self) -> TrackState:
        evidence = self.evidence
        label, leading = (max(evidence.items(), key=lambda item: item[1]) if evidence
                          else (LABEL_NO_SIGN, 0.0))
        return TrackState(self.track_id, self.x_px, self.y_px, self.radius_px, label,
                          leading, sum(evidence.values()), self.observations,
                          self.first_stamp_s, self.last_stamp_s, self.recognized)


class Tracker:
    """Tracking table and active-limit state; feed it one frame at a time.

    Example:
        >>> tracker = Tracker(TrackerConfig())
        >>> update = tracker.update(0.0, [])
        >>> update.active_limit_kmh
        0
    """

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self._tracks: list[_Track] = []
        self._next_track_id = 1
        self._frame_index = -1
        self._last_stamp_s: float | None = None
        self.active_limit_kmh = 0

    def reset(self) -> None:
        """Forget every track and the active limit (e.g. a bag was restarted)."""
        self._tracks.clear()
        self._frame_index = -1
        self._last_stamp_s = None
        self.active_limit_kmh = 0

    def update(self, stamp_s: float,
               observations: Sequence[tuple[Candidate, Classification | None]]) -> TrackerUpdate:
        """Integrate one frame's classified candidates.

        Args:
            stamp_s: message time of the frame, seconds. A time more than
                :data:`RESTART_JUMP_BACK_S` before the previous frame's resets the
                tracker (a replay restarted).
            observations: (candidate, classification) pairs; pairs without a
                classification or answered ``'no_sign'`` are ignored.

        Returns:
            The table after the frame and the limit state.
        """
        if not math.isfinite(stamp_s):
            raise ValueError(f'stamp_s must be a finite number of seconds, got {stamp_s}')
        tracks_reset = (self._last_stamp_s is not None
                        and stamp_s < self._last_stamp_s - RESTART_JUMP_BACK_S)
        if tracks_reset:
            self.reset()
        self._frame_index += 1
        self._last_stamp_s = stamp_s
        self._expire(stamp_s)

        recognized_limit_kmh = 0
        recognized_end = False
        claimed: set[int] = set()
        signs = [classification for _, classification in observations
                 if classification is not None and classification.label != LABEL_NO_SIGN]
        # Strongest observations pick their tracks first.
        signs.sort(key=lambda classification: -classification.psr)
        for classification in signs:
            track = self._associate(classification, stamp_s, claimed)
            claimed.add(track.track_id)
            self._observe(track, classification, stamp_s)
            decided = self._decide(track)
            if decided is None:
                continue
            if decided == LABEL_END_OF_LIMIT:
                recognized_end = True
                track.decided_limit_kmh = 0
            else:
                recognized_limit_kmh = int(decided)
                track.decided_limit_kmh = recognized_limit_kmh
        governing = self._governing_track()
        if governing is not None and governing.decided_limit_kmh is not None:
            self.active_limit_kmh = governing.decided_limit_kmh
        return TrackerUpdate(tuple(track.snapshot() for track in self._tracks),
                             self.active_limit_kmh, recognized_limit_kmh, recognized_end,
                             tracks_reset)

    def _governing_track(self) -> _Track | None:
        """The nearest (largest radius) decided limit or end-of-limit track, if any."""
        decided = [track for track in self._tracks if track.decided_limit_kmh is not None]
        if not decided:
            return None
        return max(decided, key=lambda track: (track.radius_px, track.last_stamp_s))

    def _expire(self, stamp_s: float) -> None:
        config = self.config
        self._tracks = [
            track for track in self._tracks
            if stamp_s - track.last_stamp_s <= config.window_s
            and self._frame_index - track.last_frame_index <= config.window_frames]

    def _associate(self, classification: Classification, stamp_s: float,
                   claimed: set[int]) -> _Track:
        x_px, y_px = classification.x_px, classification.y_px
        best: _Track | None = None
        best_distance = math.inf
        for track in self._tracks:
            if track.track_id in claimed:
                continue
            predicted_x, predicted_y = track.predicted_centre(stamp_s)
            distance = math.hypot(x_px - predicted_x, y_px - predicted_y)
            factor = (self.config.association_radius_factor if track.observations > 1
                      else self.config.unpredicted_association_radius_factor)
            gate = factor * max(track.radius_px, classification.radius_px)
            if distance <= gate and distance < best_distance:
                best, best_distance = track, distance
        if best is not None:
            return best
        track = _Track(self._next_track_id, x_px, y_px, classification.radius_px,
                       classification.rotation_deg, stamp_s, stamp_s, self._frame_index)
        self._next_track_id += 1
        self._tracks.append(track)
        return track

    def _observe(self, track: _Track, classification: Classification, stamp_s: float) -> None:
        config = self.config
        track.forget_votes_before(self._frame_index - config.window_frames + 1,
                                  stamp_s - config.window_s)
        weight = 1.0
        if track.votes:
            reference_radius_px = track.votes[0][4]
            growth = classification.radius_px / max(reference_radius_px, 1e-6) - 1.0
            if growth > SIZE_CHANGE_TOLERANCE:
                weight *= config.growth_boost
            elif growth < -SIZE_CHANGE_TOLERANCE:
                weight *= config.shrink_penalty
        if track.observations > 0:
            if abs(classification.rotation_deg - track.rotation_deg) > config.rotation_jump_deg:
                weight *= config.rotation_penalty
            elapsed_s = stamp_s - track.last_stamp_s
            if elapsed_s > 0:
                track.velocity_px_per_s = ((classification.x_px - track.x_px) / elapsed_s,
                                           (classification.y_px - track.y_px) / elapsed_s)
        track.votes.append((self._frame_index, stamp_s, classification.label,
                            weight * max(classification.psr, 0.0), classification.radius_px))
        track.x_px, track.y_px = classification.x_px, classification.y_px
        track.radius_px = classification.radius_px
        track.rotation_deg = classification.rotation_deg
        track.last_stamp_s = stamp_s
        track.last_frame_index = self._frame_index
        track.observations += 1

    def _decide(self, track: _Track) -> str | None:
        """The label this track newly recognizes, if any (each track decides once)."""
        if track.recognized:
            return None
        evidence = track.evidence
        label, leading = max(evidence.items(), key=lambda item: item[1])
        if leading < self.config.recognition_threshold:
            return None
        if leading <= 0.5 * sum(evidence.values()):
            return None
        if label != LABEL_END_OF_LIMIT and not label.isdigit():
            return None  # another sign (no overtaking, ...): tracked, never reported
        track.recognized = True
        return label
