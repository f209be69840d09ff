"""Ground truth of a recorded or synthetic drive: which sign is where, frame by frame.

Truth file format (CSV)
-----------------------
A UTF-8 text file with comma-separated values. Lines starting with ``#`` are comments
(``speed_sign_synth`` writes the drive's settings there). The first other line is the
header, naming these columns in any order (further columns are ignored):

=============  ===============================================================
``stamp_s``    frame time: the image message's header stamp, seconds since the
               epoch (decimal; written with 6 decimals, matched to
               the nearest image stamp)
``frame``      index of the frame in the image topic, 0-based (informative)
``track_id``   integer id of the physical sign; all rows of one sign share it
``kind``       what the sign is: the limit in km/h (``30``), or a look-alike such
               as ``no_overtaking``, ``end_of_limit_80``, ``weight_limit``
``limit_kmh``  the speed limit the sign sets, km/h; ``0`` for any other sign
``x1,y1``      top-left corner of the sign's box, pixels (may be fractional)
``x2,y2``      bottom-right corner of the sign's box, pixels (x2 > x1, y2 > y1)
=============  ===============================================================

One row per frame in which the sign is visible (``speed_sign_synth`` lists a sign
while its radius is at least 5 px, 3.5 px for end signs, which have no red ring, and 3/4
of its box lies inside the image). Signs
that set no limit (``limit_kmh = 0``: look-alikes, end-of-limit signs) are listed too:
evaluation counts a limit reported on them as a wrong limit, and checks that
end-of-limit signs (kind ``end_of_limit...``) are read as such.
Example::

    # speed_sign_synth seed=1 fps=30 lighting=day
    stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2
    1700000000.300000,9,1,50,50,371.2,180.4,391.8,201.0
    1700000000.333333,10,1,50,50,372.0,179.9,393.1,201.0
"""
from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from speed_sign_detector.errors import TruthFileError

#: Column names of a truth file, in the order they are written.
TRUTH_COLUMNS: tuple[str, ...] = ('stamp_s', 'frame', 'track_id', 'kind', 'limit_kmh',
                                  'x1', 'y1', 'x2', 'y2')
#: How the ``kind`` of every end-of-limit sign begins (``end_of_limit_50``, ...).
END_OF_LIMIT_KIND_PREFIX = 'end_of_limit'


#: The kind of the end of all restrictions (VZ 282), which ends the limit in force too.
END_OF_ALL_RESTRICTIONS_KIND = 'end_of_restrictions'


def is_end_of_limit_kind(kind: str) -> bool:
    """True when a truth ``kind`` names a sign that ends the limit in force: an end of limit
    (``end_of_limit_50``, ...) or the end of all restrictions."""
    return kind.startswith(END_OF_LIMIT_KIND_PREFIX) or kind == END_OF_ALL_RESTRICTIONS_KIND


@dataclass(frozen=True)
class TruthRow:
    """One sign seen in one frame.

    Attributes:
        stamp_s: frame time (image header stamp), seconds.
        frame: 0-based index of the frame in the image topic.
        track_id: id of the physical sign.
        kind: the sign's kind (``'50'``, ``'no_overtaking'``, ...).
        limit_kmh: speed limit set by the sign, km/h; 0 for other signs.
        x1_px, y1_px, x2_px, y2_px: the sign's box, pixels (x2 > x1, y2 > y1).
    """

    stamp_s: float
    frame: int
    track_id: int
    kind: str
    limit_kmh: int
    x1_px: float
    y1_px: float
    x2_px: float
    y2_px: float

    @property
    def centre_px(self) -> tuple[float, float]:
        """Centre of the box (x, y), pixels."""
        return (0.5 * (self.x1_px + self.x2_px), 0.5 * (self.y1_px + self.y2_px))

    @property
    def radius_px(self) -> float:
        """Half the larger side of the box, pixels."""
        return 0.5 * max(self.x2_px - self.x1_px, self.y2_px - self.y1_px)


@dataclass(frozen=True)
class TruthTrack:
    """All rows of one physical sign.

    Attributes:
        track_id: the sign's id.
        kind: the sign's kind.
        limit_kmh: speed limit, km/h (0 for a sign that is not a limit).
        first_stamp_s, last_stamp_s: first and last frame time it is visible, seconds.
        rows: its rows in time order.
    """

    track_id: int
    kind: str
    limit_kmh: int
    first_stamp_s: float
    last_stamp_s: float
    rows: tuple[TruthRow, ...]

    @property
    def is_limit(self) -> bool:
        """True for a speed-limit sign."""
        return self.limit_kmh > 0

    @property
    def is_end_of_limit(self) -> bool:
        """True for an end-of-limit sign."""
        return is_end_of_limit_kind(self.kind)

    @property
    def max_radius_px(self) -> float:
        """Largest radius the sign reaches while visible, pixels."""
        return max(row.radius_px for row in self.rows)


def write_truth(path: str | Path, rows: Iterable[TruthRow],
                comments: Sequence[str] = ()) -> None:
    """Write truth rows as CSV (format in the module docstring).

    Args:
        path: the file to (over)write.
        rows: the rows, written in the given order.
        comments: lines written first, each prefixed with ``# ``.

    Raises:
        TruthFileError: when the file cannot be written.
    """
    path = Path(path)
    try:
        with path.open('w', newline='', encoding='utf-8') as stream:
            for comment in comments:
                stream.write(f'# {comment}\n')
            writer = csv.writer(stream, lineterminator='\n')
            writer.writerow(TRUTH_COLUMNS)
            for row in rows:
                writer.writerow([f'{row.stamp_s:.6f}', row.frame, row.track_id, row.kind,
                                 row.limit_kmh, f'{row.x1_px:.2f}', f'{row.y1_px:.2f}',
                                 f'{row.x2_px:.2f}', f'{row.y2_px:.2f}'])
    except OSError as err:
        raise TruthFileError(f'cannot write truth file {path}: {err}') from err


def read_truth(path: str | Path) -> tuple[TruthRow, ...]:
    """Read a truth file (format in the module docstring).

    Returns:
        The rows in file order.

    Raises:
        TruthFileError: naming the file and line when the file is missing, lacks a
            column, holds a value that is not a number, or a box with x2 <= x1 or
            y2 <= y1, or a track whose kind or limit changes between rows.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as err:
        raise TruthFileError(f'cannot read truth file {path}: {err}') from err
    numbered = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith('#')]
    if not numbered:
        raise TruthFileError(f'truth file {path} is empty: expected a header line '
                             f'{",".join(TRUTH_COLUMNS)}')
    header_number, header_line = numbered[0]
    header = [name.strip() for name in next(csv.reader([header_line]))]
    missing = [name for name in TRUTH_COLUMNS if name not in header]
    if missing:
        raise TruthFileError(f'{path}:{header_number}: header lacks column(s) '
                             f'{", ".join(missing)}; expected {",".join(TRUTH_COLUMNS)}')
    index = {name: header.index(name) for name in TRUTH_COLUMNS}
    rows: list[TruthRow] = []
    track_identity: dict[int, tuple[str, int]] = {}
    for number, line in numbered[1:]:
        values = [value.strip() for value in next(csv.reader([line]))]
        if len(values) < len(header):
            raise TruthFileError(f'{path}:{number}: expected {len(header)} values, '
                                 f'got {len(values)}')
        try:
            row = TruthRow(
                stamp_s=_finite(values[index['stamp_s']]),
                frame=int(values[index['frame']]),
                track_id=int(values[index['track_id']]),
                kind=values[index['kind']],
                limit_kmh=int(values[index['limit_kmh']]),
                x1_px=_finite(values[index['x1']]), y1_px=_finite(values[index['y1']]),
                x2_px=_finite(values[index['x2']]), y2_px=_finite(values[index['y2']]))
        except ValueError as err:
            raise TruthFileError(f'{path}:{number}: {err}') from err
        if row.x2_px <= row.x1_px or row.y2_px <= row.y1_px:
            raise TruthFileError(f'{path}:{number}: box ({row.x1_px}, {row.y1_px}, '
                                 f'{row.x2_px}, {row.y2_px}) is empty (need x2 > x1, y2 > y1)')
        if row.limit_kmh < 0 or not row.kind:
            raise TruthFileError(f'{path}:{number}: limit_kmh must be >= 0 and kind '
                                 f'non-empty, got {row.limit_kmh!r}, {row.kind!r}')
        identity = track_identity.setdefault(row.track_id, (row.kind, row.limit_kmh))
        if identity != (row.kind, row.limit_kmh):
            raise TruthFileError(f'{path}:{number}: track {row.track_id} changes from '
                                 f'{identity} to {(row.kind, row.limit_kmh)}')
        rows.append(row)
    return tuple(rows)


def group_tracks(rows: Iterable[TruthRow]) -> tuple[TruthTrack, ...]:
    """Group rows by track id; tracks ordered by first appearance time."""
    by_track: dict[int, list[TruthRow]] = {}
    for row in rows:
        by_track.setdefault(row.track_id, []).append(row)
    tracks = []
    for track_id, track_rows in by_track.items():
        track_rows.sort(key=lambda row: row.stamp_s)
        first = track_rows[0]
        tracks.append(TruthTrack(track_id, first.kind, first.limit_kmh, first.stamp_s,
                                 track_rows[-1].stamp_s, tuple(track_rows)))
    tracks.sort(key=lambda track: (track.first_stamp_s, track.track_id))
    return tuple(tracks)


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f'{text!r} is not a finite number')
    return value
