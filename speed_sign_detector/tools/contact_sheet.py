"""The contact sheet of ``speed_sign_eval bag --contact-sheet``: a drive at a glance.

:class:`ContactSheetCollector` is offered every processed frame and keeps few of them,
chosen around the limit changes, while the drive streams by (memory stays bounded):

1. every frame in which a limit (or an end of limit) was newly recognized;
2. for each of those, the frame :data:`LEAD_S` seconds earlier, while the sign was
   still approaching (from a short buffer of recent frames);
3. evenly spaced frames of the whole drive, to fill the sheet.

At most :data:`SHEET_TILES` tiles, in that order of preference (each group thinned
evenly when it does not fit), shown in time order. Each tile is drawn at its size on
the sheet, so the words are legible at 100 % zoom: a caption with the time since the
start of the drive and the active limit after the frame, the recognition it shows, and
the candidates (green: read as a speed limit, with value and PSR; orange: read as no
limit; cyan: not classified). A header names the drive; a legend explains the colours.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.errors import BagError
from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.visualization import contact_sheet, draw_tile

__all__ = ['ContactSheetCollector', 'LEAD_S', 'SHEET_COLUMNS', 'SHEET_TILES', 'TILE_WIDTH_PX']

#: Tiles on a sheet, and per row.
SHEET_TILES = 9
SHEET_COLUMNS = 3
#: Width of a tile: three tiles and two 4 px gaps make a 1280 px wide sheet.
TILE_WIDTH_PX = 424
#: How long before a recognition the "approaching" tile is taken, seconds.
LEAD_S = 0.7
#: Most frames kept per group while the drive streams by (thinned evenly beyond).
KEPT_PER_GROUP = 4 * SHEET_TILES


@dataclass(frozen=True)
class _KeptFrame:
    """A frame kept for the sheet, already reduced to the tile's width."""

    index: int
    time_s: float
    small: np.ndarray
    result: FrameResult
    tag: str


def _thinned(frames: list[_KeptFrame], count: int) -> list[_KeptFrame]:
    """``count`` frames spread evenly over ``frames`` (all when there are not more)."""
    if len(frames) <= count:
        return list(frames)
    if count <= 0:
        return []
    picks = np.linspace(0, len(frames) - 1, count).round().astype(int)
    return [frames[pick] for pick in picks]


def _scaled_result(result: FrameResult, scale: float) -> FrameResult:
    """The result with its candidates' pixel coordinates multiplied by ``scale``."""
    detections = tuple(replace(detection, candidate=replace(
        detection.candidate, x_px=detection.candidate.x_px * scale,
        y_px=detection.candidate.y_px * scale,
        radius_px=detection.candidate.radius_px * scale)) for detection in result.detections)
    return replace(result, detections=detections)


class ContactSheetCollector:
    """Keeps the frames of a contact sheet while a drive is processed, then draws it.

    Args:
        path: the PNG (or JPEG) file to write.
        total_frames: frames expected (None when unknown), for the spacing of group 3.
    """

    def __init__(self, path: Path, total_frames: int | None) -> None:
        self.path = Path(path)
        self.spacing = max(1, (total_frames or 300) // SHEET_TILES)
        self.first_stamp_s: float | None = None
        self.frames_seen = 0
        self.recognitions: list[_KeptFrame] = []
        self.approaches: list[_KeptFrame] = []
        self.spaced: list[_KeptFrame] = []
        self._recent: deque[_KeptFrame] = deque()

    def offer(self, index: int, stamp_s: float, gray: np.ndarray, result: FrameResult,
              recognized_kmh: list[int]) -> None:
        """Offer one processed frame (in order).

        Args:
            index: the frame's index in the drive (0-based).
            stamp_s: its stamp, seconds.
            gray: the processed frame, (H, W) uint8.
            result: what the pipeline found in it.
            recognized_kmh: limits newly recognized in it (0 = end of limit).
        """
        if self.first_stamp_s is None:
            self.first_stamp_s = stamp_s
        self.frames_seen += 1
        time_s = stamp_s - self.first_stamp_s
        scale = TILE_WIDTH_PX / gray.shape[1]
        small = cv2.resize(gray, (TILE_WIDTH_PX, int(round(gray.shape[0] * scale))),
                           interpolation=cv2.INTER_AREA)
        frame = _KeptFrame(index, time_s, small, _scaled_result(result, scale), '')
        self._recent.append(frame)   # [0]: the latest frame at least LEAD_S old, if any
        while len(self._recent) > 1 and self._recent[1].time_s <= time_s - LEAD_S:
            self._recent.popleft()
        if recognized_kmh:
            values = ', '.join(str(value) if value else 'end' for value in recognized_kmh)
            self._keep(self.recognitions, _KeptFrame(index, time_s, small, frame.result,
                                                     f'{values} recognized'))
            lead = self._recent[0]
            if lead.time_s <= time_s - 0.5 * LEAD_S:
                self._keep(self.approaches, _KeptFrame(
                    lead.index, lead.time_s, lead.small, lead.result,
                    f'{time_s - lead.time_s:.1f} s before'))
        elif index % self.spacing == self.spacing // 2:
            self._keep(self.spaced, frame)

    @staticmethod
    def _keep(group: list[_KeptFrame], frame: _KeptFrame) -> None:
        group.append(frame)
        if len(group) > KEPT_PER_GROUP:
            del group[1::2]

    def chosen(self) -> list[_KeptFrame]:
        """The frames of the sheet, in time order (recognitions, approaches, spacing)."""
        chosen = _thinned(self.recognitions, SHEET_TILES)
        taken = {frame.index for frame in chosen}
        for group in (self.approaches, self.spaced):
            free = [frame for frame in group if frame.index not in taken]
            added = _thinned(free, SHEET_TILES - len(chosen))
            chosen += added
            taken |= {frame.index for frame in added}
        return sorted(chosen, key=lambda frame: frame.index)

    def write(self, header: str, notes: list[str]) -> bool:
        """Draw and write the sheet; False when no frame was offered (nothing written).

        Args:
            header: the line above the tiles (the drive's name and length).
            notes: lines under the colour legend (the recognized limits, ...).

        Raises:
            BagError: the file cannot be written.
        """
        frames = self.chosen()
        if not frames:
            return False
        tiles = []
        for frame in frames:
            limit = frame.result.active_limit_kmh
            caption = f't {frame.time_s:6.2f} s   limit {limit if limit else "-"}'
            tiles.append(draw_tile(frame.small, frame.result, TILE_WIDTH_PX, caption,
                                   frame.tag))
        notes = ['caption: time since the first frame of the drive, active limit after the '
                 'frame (- = none known yet); tag: what the frame shows'] + notes
        sheet = contact_sheet(tiles, SHEET_COLUMNS, header, notes)
        try:
            ok = cv2.imwrite(str(self.path), sheet)
        except cv2.error as err:
            raise BagError(f'cannot write contact sheet {self.path}: {err}') from err
        if not ok:
            raise BagError(f'cannot write contact sheet {self.path}')
        return True
