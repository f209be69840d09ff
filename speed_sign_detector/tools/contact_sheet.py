"""The contact sheet of ``speed_sign_eval bag --contact-sheet``: a drive a person can check.

:class:`ContactSheetCollector` is offered every processed frame and keeps few of them
while the drive streams by (memory stays bounded), then chooses the tiles:

1. with a truth file, one tile for every truth sign never recognized (a speed limit or
   an end of limit: "missed"): the frame where it was largest (whole in the frame
   when it ever was), up to :data:`MOST_MISSED_TILES`;
2. every frame in which a limit (or an end of limit) was newly recognized;
3. for each of those, the frame :data:`LEAD_S` seconds earlier, while the sign was
   still approaching (from a short buffer of recent frames);
4. evenly spaced frames of the whole drive, to fill the sheet.

Groups 2 to 4 fill the sheet to :data:`SHEET_TILES` tiles (or the missed signs' tiles
and a row more) in that order of preference (each group thinned evenly when it does
not fit); the tiles are shown in time order. What each tile shows is decided here
and handed to :mod:`speed_sign_detector.tools.contact_sheet_drawing` as data
(:meth:`ContactSheetCollector.tiles`):

- every candidate read as a speed limit or end of limit ("a reading") gets a circle and
  a zoomed view; it is "published" when the tracker confirmed that value on that sign
  (a limit event of the track the reading belongs to), else a "single-frame reading,
  not published";
- with a truth file, every truth sign in view gets a box and a word for what became of
  it over the drive (right, WRONG, MISSED, look-alike), and every reading a verdict
  against the sign it lies on (or "no sign in the truth here").
"""
from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from speed_sign_detector.errors import BagError
from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.recognition.classification import LABEL_END_OF_LIMIT
from speed_sign_detector.tools.contact_sheet_drawing import (
    ZOOM_PX,
    SheetMark,
    SheetTile,
    SignZoom,
    draw_sheet,
    legend_lines,
)
from speed_sign_detector.truth import TruthRow, TruthTrack, is_end_of_limit_kind

__all__ = ['ContactSheetCollector', 'LEAD_S', 'MOST_MISSED_TILES', 'SHEET_COLUMNS',
           'SHEET_TILES', 'TILE_WIDTH_PX']

#: Tiles on a sheet besides those of missed signs, and tiles per row.
SHEET_TILES = 9
SHEET_COLUMNS = 3
#: Most tiles given to missed signs (one each; a longer list is named in the notes).
MOST_MISSED_TILES = 2 * SHEET_TILES
#: Width of a tile: three tiles and two 4 px gaps make a 1280 px wide sheet.
TILE_WIDTH_PX = 424
#: How long before a recognition the "approaching" tile is taken, seconds.
LEAD_S = 0.7
#: Most frames kept per group while the drive streams by, per tile of the sheet
#: (thinned evenly beyond).
KEPT_PER_TILE = 4
#: Most zoomed views under a tile (further readings are counted, not shown).
MOST_ZOOMS = 4


class RecognitionEvent(Protocol):
    """A limit the tracker newly recognized (``bag_grading.LimitEvent``)."""

    limit_kmh: int   # 0: end of limit
    track_id: int    # the pipeline's track, -1 when unknown


class SignResult(Protocol):
    """What became of a truth sign over the drive (``bag_grading.SignOutcome``)."""

    track_id: int
    recognized: bool
    wrong_values: list[int]
    cut: bool


@dataclass(frozen=True)
class _Reading:
    """A candidate read as a limit or end of limit, full-frame pixels."""

    label: str
    psr: float
    x_px: float
    y_px: float
    radius_px: float
    track_id: int
    zoom: np.ndarray


@dataclass(frozen=True)
class _TruthView:
    """A truth sign in a frame, full-frame pixels."""

    row: TruthRow
    zoom: np.ndarray


@dataclass(frozen=True)
class _KeptFrame:
    """A frame kept for the sheet: the picture at tile width and what it shows."""

    index: int
    time_s: float
    picture: np.ndarray
    scale: float
    active_limit_kmh: int
    readings: tuple[_Reading, ...]
    others: tuple[tuple[float, float, float, str], ...]   # x, y, radius (full px), style
    truths: tuple[_TruthView, ...]
    tag: str = ''


def _thinned(frames: list[_KeptFrame], count: int) -> list[_KeptFrame]:
    """``count`` frames spread evenly over ``frames`` (all when there are not more)."""
    if len(frames) <= count:
        return list(frames)
    if count <= 0:
        return []
    picks = np.linspace(0, len(frames) - 1, count).round().astype(int)
    return [frames[pick] for pick in picks]


def _zoom(gray: np.ndarray, x_px: float, y_px: float, half_px: float) -> np.ndarray:
    """The square of half side ``half_px`` around (x, y) scaled to ZOOM_PX (borders
    replicated where it leaves the frame). Returns (ZOOM_PX, ZOOM_PX) uint8."""
    side = max(16, int(round(2 * half_px)))
    patch = cv2.getRectSubPix(gray, (side, side), (float(x_px), float(y_px)))
    interpolation = cv2.INTER_CUBIC if side < ZOOM_PX else cv2.INTER_AREA
    return cv2.resize(patch, (ZOOM_PX, ZOOM_PX), interpolation=interpolation)


def _shown(label: str) -> str:
    """A reading's label in words (``'80'``, ``'end of limit'``)."""
    return 'end of limit' if label == LABEL_END_OF_LIMIT else label


def _truth_shown(row: TruthRow) -> str:
    """A truth sign in words: its limit, ``'end of limit'`` or its kind."""
    if row.limit_kmh > 0:
        return str(row.limit_kmh)
    return 'end of limit' if is_end_of_limit_kind(row.kind) else row.kind


def _verdict(row: TruthRow, result: SignResult) -> str:
    """What became of a truth sign: right, wrong, missed, lookalike or cut."""
    if result.cut:
        return 'cut'
    if result.wrong_values:
        return 'wrong'
    if row.limit_kmh > 0 or is_end_of_limit_kind(row.kind):
        return 'right' if result.recognized else 'missed'
    return 'lookalike'


#: Word drawn under a truth box for each verdict.
VERDICT_WORDS = {'right': 'right', 'wrong': 'WRONG', 'missed': 'MISSED',
                 'lookalike': 'look-alike', 'cut': 'cut off'}


class ContactSheetCollector:
    """Keeps the frames of a contact sheet while a drive is processed, then draws it.

    Args:
        path: the PNG (or JPEG) file to write.
        total_frames: frames expected (None when unknown), for the spacing of group 4.
        truth_tracks: the drive's truth signs (:func:`speed_sign_detector.truth.
            group_tracks`), or None without a truth file.
        sheet_tiles: tiles besides those of missed signs (a number as large as the
            frames makes every frame a tile).
    """

    def __init__(self, path: Path, total_frames: int | None,
                 truth_tracks: Sequence[TruthTrack] | None = None,
                 sheet_tiles: int = SHEET_TILES) -> None:
        self.path = Path(path)
        self.sheet_tiles = sheet_tiles
        self.spacing = max(1, (total_frames or 300) // sheet_tiles)
        self.first_stamp_s: float | None = None
        self.frames_seen = 0
        self.recognitions: list[_KeptFrame] = []
        self.approaches: list[_KeptFrame] = []
        self.spaced: list[_KeptFrame] = []
        #: The tiles of the last :meth:`write` (empty before).
        self.last_tiles: list[SheetTile] = []
        self._recent: deque[_KeptFrame] = deque()
        self._published: dict[int, list[tuple[str, float]]] = {}   # track -> (label, s)
        # truth track -> ((whole in the frame, radius px), the frame where it was largest)
        self._largest: dict[int, tuple[tuple[bool, float], _KeptFrame]] = {}
        self._truth_tracks = {track.track_id: track for track in truth_tracks or ()}
        rows = sorted((row for track in truth_tracks or () for row in track.rows),
                      key=lambda row: row.stamp_s)
        self._truth_stamps = np.array(sorted({row.stamp_s for row in rows}))
        self._truth_rows: dict[float, list[TruthRow]] = {}
        for row in rows:
            self._truth_rows.setdefault(row.stamp_s, []).append(row)
        steps = np.diff(self._truth_stamps)
        self._truth_tolerance_s = 0.5 * float(np.median(steps)) if steps.size else 0.02

    def offer(self, index: int, stamp_s: float, gray: np.ndarray, result: FrameResult,
              recognized: Sequence[RecognitionEvent]) -> None:
        """Offer one processed frame (in order).

        Args:
            index: the frame's index in the drive (0-based).
            stamp_s: its stamp, seconds.
            gray: the processed frame, (H, W) uint8.
            result: what the pipeline found in it.
            recognized: limits the tracker newly recognized in it (``limit_kmh`` 0: end
                of limit), with the tracks that recognized them.
        """
        if self.first_stamp_s is None:
            self.first_stamp_s = stamp_s
        self.frames_seen += 1
        time_s = stamp_s - self.first_stamp_s
        for event in recognized:
            label = str(event.limit_kmh) if event.limit_kmh else LABEL_END_OF_LIMIT
            self._published.setdefault(event.track_id, []).append((label, time_s))
        frame = self._kept_frame(index, time_s, gray, result)
        self._recent.append(frame)   # [0]: the latest frame at least LEAD_S old, if any
        while len(self._recent) > 1 and self._recent[1].time_s <= time_s - LEAD_S:
            self._recent.popleft()
        height_px, width_px = gray.shape[:2]
        for view in frame.truths:   # the largest view of each sign, whole in the frame first
            row = view.row
            if row.limit_kmh > 0 or is_end_of_limit_kind(row.kind):
                whole = (row.x1_px >= 0 and row.y1_px >= 0 and row.x2_px <= width_px
                         and row.y2_px <= height_px)
                size = (whole, row.radius_px)
                best = self._largest.get(row.track_id)
                if best is None or size > best[0]:
                    self._largest[row.track_id] = (size, frame)
        if recognized:
            values = ', '.join(str(event.limit_kmh) if event.limit_kmh else 'end'
                               for event in recognized)
            self._keep(self.recognitions, replace(frame, tag=f'{values} recognized'))
            lead = self._recent[0]
            if lead.time_s <= time_s - 0.5 * LEAD_S:
                self._keep(self.approaches,
                           replace(lead, tag=f'{time_s - lead.time_s:.1f} s before'))
        elif index % self.spacing == self.spacing // 2:
            self._keep(self.spaced, frame)

    def _keep(self, group: list[_KeptFrame], frame: _KeptFrame) -> None:
        """Add a frame to a group, halving the group evenly when it grows too long."""
        group.append(frame)
        if len(group) > KEPT_PER_TILE * self.sheet_tiles:
            del group[1::2]

    def _kept_frame(self, index: int, time_s: float, gray: np.ndarray,
                    result: FrameResult) -> _KeptFrame:
        """The frame at tile width with its readings, other candidates and truth signs."""
        scale = TILE_WIDTH_PX / gray.shape[1]
        picture = cv2.resize(gray, (TILE_WIDTH_PX, int(round(gray.shape[0] * scale))),
                             interpolation=cv2.INTER_AREA)
        observed = [track for track in result.tracks if track.last_stamp_s == result.stamp_s]
        readings, others = [], []
        for detection in result.detections:
            candidate, classification = detection.candidate, detection.classification
            if classification is None or not (classification.is_limit
                                              or classification.label == LABEL_END_OF_LIMIT):
                style = 'unclassified' if classification is None else 'no_limit'
                others.append((candidate.x_px, candidate.y_px, candidate.radius_px, style))
                continue
            x_px, y_px = classification.x_px, classification.y_px
            # the tracker moves a track to the classification that it observed
            track_id = next((track.track_id for track in observed
                             if abs(track.x_px - x_px) < 1e-3
                             and abs(track.y_px - y_px) < 1e-3), -1)
            radius_px = max(classification.radius_px, candidate.radius_px)
            readings.append(_Reading(classification.label, classification.psr, x_px, y_px,
                                     radius_px, track_id,
                                     _zoom(gray, x_px, y_px, 1.3 * radius_px + 2)))
        truths = tuple(_TruthView(row, _zoom(gray, *row.centre_px, 1.2 * row.radius_px + 2))
                       for row in self._rows_at(result.stamp_s))
        return _KeptFrame(index, time_s, picture, scale, result.active_limit_kmh,
                          tuple(readings), tuple(others), truths)

    def _rows_at(self, stamp_s: float) -> list[TruthRow]:
        """The truth rows of the frame stamped ``stamp_s`` (nearest truth stamp)."""
        if not self._truth_stamps.size:
            return []
        position = int(np.searchsorted(self._truth_stamps, stamp_s))
        nearby = [self._truth_stamps[i] for i in (position - 1, position)
                  if 0 <= i < self._truth_stamps.size]
        nearest = min(nearby, key=lambda value: abs(value - stamp_s))
        if abs(nearest - stamp_s) > self._truth_tolerance_s:
            return []
        return self._truth_rows[float(nearest)]

    def missed_track_ids(self, outcomes: Sequence[SignResult]) -> list[int]:
        """Truth signs never recognized (limits and ends of limit, a wrong value published
        on them or not) that were in a processed frame, not cut off, in time order."""
        by_id = {outcome.track_id: outcome for outcome in outcomes}
        missed = [track_id for track_id in self._largest   # limits and ends of limit only
                  if track_id in by_id and not by_id[track_id].recognized
                  and not by_id[track_id].cut]
        return sorted(missed, key=lambda track_id: self._truth_tracks[track_id].first_stamp_s)

    def tiles(self, outcomes: Sequence[SignResult] | None = None) -> list[SheetTile]:
        """What the sheet shows, tile by tile in time order.

        Args:
            outcomes: what became of each truth sign (``DriveScore.outcomes``), or None
                without a truth file (no truth drawn, no missed tiles).
        """
        results = {outcome.track_id: outcome for outcome in outcomes or ()}
        missed = self.missed_track_ids(outcomes or ())[:MOST_MISSED_TILES]
        chosen: dict[int, tuple[_KeptFrame, list[str], list[int]]] = {}
        for track_id in missed:
            frame = self._largest[track_id][1]
            entry = chosen.setdefault(frame.index, (frame, [], []))
            entry[1].append(f'{_truth_shown(_frame_row(frame, track_id))} MISSED')
            entry[2].append(track_id)
        # the other groups fill the sheet; recognitions get a row even beside many misses
        tiles_in_all = max(self.sheet_tiles, len(chosen) + SHEET_COLUMNS)
        for group in (self.recognitions, self.approaches, self.spaced):
            free = [frame for frame in group if frame.index not in chosen]
            for frame in _thinned(free, tiles_in_all - len(chosen)):
                chosen[frame.index] = (frame, [frame.tag] if frame.tag else [], [])
        for index, (frame, reasons, _) in chosen.items():
            for other in self.recognitions:   # a missed sign's frame may also recognize
                if other.index == index and other.tag not in reasons:
                    reasons.insert(0, other.tag)
        return [self._tile(frame, reasons, missed_ids, results)
                for _, (frame, reasons, missed_ids) in sorted(chosen.items())]

    def _tile(self, frame: _KeptFrame, reasons: list[str], missed_ids: list[int],
              results: dict[int, SignResult]) -> SheetTile:
        """One tile's marks and zoomed views (see the module docstring)."""
        scale = frame.scale
        marks = [SheetMark('circle', style, *_square(x_px, y_px, radius_px + 2, scale))
                 for x_px, y_px, radius_px, style in frame.others]
        verdicts = {view.row.track_id: _verdict(view.row, results[view.row.track_id])
                    for view in frame.truths if view.row.track_id in results}
        for view in frame.truths:
            verdict = verdicts.get(view.row.track_id)
            if verdict is not None:
                row = view.row
                words = ('look-alike' if verdict == 'lookalike'
                         else f'{_truth_shown(row)} {VERDICT_WORDS[verdict]}')
                marks.append(SheetMark('box', verdict, row.x1_px * scale, row.y1_px * scale,
                                       row.x2_px * scale, row.y2_px * scale, words))
        read_on: dict[int, list[str]] = {}   # truth track -> what was read on it here
        reading_zooms = []
        for reading in sorted(frame.readings, key=lambda reading: -reading.psr):
            events = [time_s for label, time_s in self._published.get(reading.track_id, ())
                      if label == reading.label]
            style = ('published' if events else
                     'end' if reading.label == LABEL_END_OF_LIMIT else 'single_frame')
            marks.append(SheetMark('circle', style, *_square(
                reading.x_px, reading.y_px, reading.radius_px + 2, scale),
                'end' if reading.label == LABEL_END_OF_LIMIT else reading.label))
            lines = [(style, f'read {_shown(reading.label)}: published at {events[0]:.2f} s'
                      if events else
                      f'read {_shown(reading.label)}: single frame, not published')]
            verdict, truth_id = '', -1
            if results:
                view = _truth_under(frame.truths, reading)
                verdict, line = _reading_verdict(reading, view)
                lines.append(line)
                if view is not None:
                    truth_id = view.row.track_id
                    read_on.setdefault(truth_id, []).append(_shown(reading.label))
            lines.append(('note', f'peak {reading.psr:.1f}, radius {reading.radius_px:.0f} px'))
            reading_zooms.append(SignZoom('reading', reading.label, bool(events), verdict,
                                          truth_id, style, reading.zoom, tuple(lines)))
        zooms = [self._truth_zoom(view, 'missed', results[view.row.track_id],
                                  read_on.get(view.row.track_id, []), largest=True)
                 for view in frame.truths if view.row.track_id in missed_ids]
        room = MOST_ZOOMS - len(zooms)
        zooms += reading_zooms[:room]
        for view in frame.truths:   # signs in view that nothing was read on, while room
            track_id = view.row.track_id
            if (len(zooms) < MOST_ZOOMS and track_id not in read_on
                    and track_id not in missed_ids
                    and verdicts.get(track_id) in ('right', 'wrong', 'missed', 'cut')):
                zooms.append(self._truth_zoom(view, verdicts[track_id], results[track_id],
                                              [], largest=False))
        limit = frame.active_limit_kmh
        return SheetTile(frame.index, frame.time_s,
                         f't {frame.time_s:6.2f} s   limit {limit if limit else "-"}',
                         tuple(reasons), tuple(missed_ids), frame.picture, tuple(marks),
                         tuple(zooms), max(0, len(reading_zooms) - room))

    @staticmethod
    def _truth_zoom(view: _TruthView, verdict: str, result: SignResult, read_here: list[str],
                    largest: bool) -> SignZoom:
        """The zoomed view of a truth sign (the subject of a missed sign's tile, or a sign
        in view that nothing was read on)."""
        row = view.row
        shown = _truth_shown(row)
        wrong = ', '.join(str(value) if value else 'end' for value in result.wrong_values)
        first = {'missed': f'truth {shown}: MISSED, never recognized',
                 'right': f'truth {shown}: right (its limit was published)',
                 'cut': f'truth {shown}: cut off by the early stop',
                 'wrong': f'truth {shown}: WRONG, {wrong} published on it'}[verdict]
        if verdict == 'missed' and wrong:
            second = ('wrong', f'WRONG limit published on it: {wrong}')
        elif read_here:
            second = ('note', f'read here as {", ".join(read_here)}')
        else:
            second = ('note', 'not read in this frame')
        size = f'radius {row.radius_px:.0f} px' + (', its largest in view' if largest else '')
        return SignZoom('truth', row.kind, False, verdict, row.track_id, verdict, view.zoom,
                        ((verdict, first), second, ('note', size)))

    def write(self, header: str, notes: list[str],
              outcomes: Sequence[SignResult] | None = None) -> bool:
        """Draw and write the sheet; False when no frame was offered (nothing written).

        Args:
            header: the line above the tiles (the drive's name and length).
            notes: lines under the legend (the published limits, ...).
            outcomes: what became of each truth sign, or None without a truth file.

        Raises:
            BagError: the file cannot be written.
        """
        self.last_tiles = self.tiles(outcomes)
        if not self.last_tiles:
            return False
        notes = list(notes)
        if outcomes is not None:
            missed = self.missed_track_ids(outcomes)
            if len(missed) > MOST_MISSED_TILES:
                notes.append(f'{len(missed) - MOST_MISSED_TILES} more missed signs have no '
                             f'tile (see the per-sign table)')
        legend = legend_lines(outcomes is not None) + [('note', note) for note in notes]
        sheet = draw_sheet(self.last_tiles, SHEET_COLUMNS, header, legend)
        try:
            ok = cv2.imwrite(str(self.path), sheet)
        except cv2.error as err:
            raise BagError(f'cannot write contact sheet {self.path}: {err}') from err
        if not ok:
            raise BagError(f'cannot write contact sheet {self.path}')
        return True


def _frame_row(frame: _KeptFrame, track_id: int) -> TruthRow:
    """The truth row of sign ``track_id`` in a kept frame."""
    return next(view.row for view in frame.truths if view.row.track_id == track_id)


def _square(x_px: float, y_px: float, radius_px: float, scale: float
            ) -> tuple[float, float, float, float]:
    """The square around a circle, scaled to the tile."""
    return ((x_px - radius_px) * scale, (y_px - radius_px) * scale,
            (x_px + radius_px) * scale, (y_px + radius_px) * scale)


def _truth_under(truths: tuple[_TruthView, ...], reading: _Reading) -> _TruthView | None:
    """The truth sign whose box (grown by a quarter each way) holds the reading's
    centre, the nearest if several; None when none does."""
    holding = []
    for view in truths:
        row = view.row
        grow_x, grow_y = 0.25 * (row.x2_px - row.x1_px), 0.25 * (row.y2_px - row.y1_px)
        if (row.x1_px - grow_x <= reading.x_px <= row.x2_px + grow_x
                and row.y1_px - grow_y <= reading.y_px <= row.y2_px + grow_y):
            centre_x, centre_y = row.centre_px
            holding.append((np.hypot(centre_x - reading.x_px, centre_y - reading.y_px), view))
    return min(holding, key=lambda item: item[0])[1] if holding else None


def _reading_verdict(reading: _Reading, view: _TruthView | None) -> tuple[str, tuple[str, str]]:
    """(verdict, (style, words)) of a reading against the truth sign it lies on."""
    if view is None:
        return 'wrong', ('wrong', 'no sign in the truth here: WRONG')
    row = view.row
    if row.limit_kmh > 0:
        right = reading.label == str(row.limit_kmh)
    elif is_end_of_limit_kind(row.kind):
        right = reading.label == LABEL_END_OF_LIMIT
    else:
        return 'wrong', ('wrong', f'truth: look-alike ({row.kind}): WRONG')
    verdict = 'right' if right else 'wrong'
    return verdict, (verdict, f'truth {_truth_shown(row)}: '
                              f'{"reading right" if right else "reading WRONG"}')
