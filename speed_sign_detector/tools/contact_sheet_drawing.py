"""Drawing of the contact sheet (``speed_sign_eval bag --contact-sheet``). No ROS imports.

What a tile shows is decided by :mod:`speed_sign_detector.tools.contact_sheet` and
handed here as data (:class:`SheetTile`), so tests can read the choices without
reading pixels. A tile is, top to bottom:

- a caption bar: time since the first frame, the published limit after the frame, and
  at the right why the frame was chosen;
- the frame, reduced to the tile's width, with circles around the candidates (colour:
  what was read; see :data:`STYLE_COLOURS`) and, with a truth file, a box around each
  truth sign in view with a word saying what became of it (right, WRONG, MISSED);
- a panel of zoomed views (:data:`ZOOM_PX` px square) of each sign read in the frame
  (and of the missed sign a tile was chosen for), each with a few lines of words.

Colours are BGR and always come with a word, so the sheet reads in gray too.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ['CAPTION_HEIGHT_PX', 'SheetMark', 'SheetTile', 'SignZoom', 'STYLE_COLOURS',
           'ZOOM_PX', 'draw_sheet', 'draw_tile', 'legend_lines']

#: Side of a zoomed view of a sign, pixels (the brief asks for at least 64).
ZOOM_PX = 96
#: Height of one row of the zoom panel (a zoomed view and its words), pixels.
ZOOM_ROW_PX = ZOOM_PX + 6
#: Height of a tile's caption bar, pixels.
CAPTION_HEIGHT_PX = 24
#: Font of the sheet's words, drawn at the sheet's own scale (legible at 100 % zoom).
SHEET_FONT = cv2.FONT_HERSHEY_SIMPLEX
SHEET_FONT_SCALE = 0.55
#: Smallest font scale a line is shrunk to when it does not fit its width.
SMALLEST_FONT_SCALE = 0.42

#: BGR colour of each style a mark, a zoomed view or a line of words can have.
STYLE_COLOURS: dict[str, tuple[int, int, int]] = {
    'published': (0, 220, 0),        # reading the tracker confirmed: on speed_limit
    'single_frame': (0, 230, 255),   # a frame's reading the tracker never confirmed
    'end': (0, 140, 255),            # read as end of limit
    'no_limit': (150, 150, 150),     # candidate read as no speed-limit sign
    'unclassified': (200, 200, 0),   # candidate not classified
    'right': (255, 170, 60),         # truth sign whose limit was published
    'wrong': (60, 60, 255),          # truth sign with a wrong limit published on it
    'missed': (255, 60, 255),        # truth sign never recognized
    'lookalike': (200, 200, 200),    # truth sign that sets no limit, nothing wrong on it
    'cut': (200, 200, 200),          # truth sign cut off by an early stop
    'text': (255, 255, 255),
    'note': (190, 190, 190),
    'tag': (80, 255, 80),
}
#: Styles of truth signs (drawn as boxes; the others are candidates, drawn as circles).
TRUTH_STYLES = frozenset({'right', 'wrong', 'missed', 'lookalike', 'cut'})


@dataclass(frozen=True)
class SheetMark:
    """A circle (a candidate) or a box (a truth sign) drawn on a tile's picture.

    Attributes:
        shape: ``'circle'`` or ``'box'``.
        style: a key of :data:`STYLE_COLOURS`.
        x1_px, y1_px, x2_px, y2_px: the mark's bounding box in tile-picture pixels (a
            circle's is the square around it).
        words: drawn beside the mark ('' for none).
    """

    shape: str
    style: str
    x1_px: float
    y1_px: float
    x2_px: float
    y2_px: float
    words: str = ''


@dataclass(frozen=True)
class SignZoom:
    """A zoomed view of one sign of a tile, with its words.

    Attributes:
        subject: ``'reading'`` (a candidate read as a limit or end of limit) or
            ``'truth'`` (a truth sign, e.g. the missed sign a tile was chosen for).
        label: what was read (``'80'``, ``'end_of_limit'``) or the truth sign's kind.
        published: for a reading, whether the tracker confirmed that value on that
            sign (it was published on ``speed_limit``); False for a truth subject.
        verdict: against the truth: ``'right'``, ``'wrong'``, ``'missed'``,
            ``'lookalike'``, ``'cut'``, or ``''`` without a truth file.
        truth_track_id: the truth sign it shows or lies on, -1 for none.
        style: border colour, a key of :data:`STYLE_COLOURS`.
        image: the zoomed view, gray (ZOOM_PX, ZOOM_PX) uint8.
        lines: (style, words) lines drawn beside it.
    """

    subject: str
    label: str
    published: bool
    verdict: str
    truth_track_id: int
    style: str
    image: np.ndarray
    lines: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class SheetTile:
    """Everything one tile shows.

    Attributes:
        frame_index: the frame's index in the drive (0-based).
        time_s: seconds since the first frame.
        caption: the caption bar's words (time, published limit).
        reasons: why the frame was chosen (``'60 recognized'``, ``'end MISSED'``, ...),
            drawn at the caption's right.
        missed_track_ids: truth signs never recognized that this tile was chosen for.
        picture: the frame reduced to the tile's width, gray (h, w) uint8.
        marks: circles and boxes to draw on the picture.
        zooms: the zoomed views under the picture, most important first.
        more_readings: readings in the frame left out of the zoom panel (no room).
    """

    frame_index: int
    time_s: float
    caption: str
    reasons: tuple[str, ...]
    missed_track_ids: tuple[int, ...]
    picture: np.ndarray
    marks: tuple[SheetMark, ...]
    zooms: tuple[SignZoom, ...]
    more_readings: int = 0


def _text(canvas: np.ndarray, text: str, origin: tuple[int, int], colour: tuple[int, ...],
          scale: float = SHEET_FONT_SCALE) -> None:
    """Anti-aliased text with a dark outline, so it reads on any background (the outline
    is the same text shifted by a pixel: a thicker stroke would also space it wider)."""
    x, y = origin
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1), (0, 2), (2, 0), (0, -2), (-2, 0)):
        cv2.putText(canvas, text, (x + dx, y + dy), SHEET_FONT, scale, (0, 0, 0), 1,
                    cv2.LINE_AA)
    cv2.putText(canvas, text, origin, SHEET_FONT, scale, colour, 1, cv2.LINE_AA)


def _fitting_scale(text: str, width_px: int, scale: float = SHEET_FONT_SCALE) -> float:
    """The largest font scale up to ``scale`` (down to SMALLEST_FONT_SCALE) that fits."""
    while scale > SMALLEST_FONT_SCALE:
        (text_width, _), _ = cv2.getTextSize(text, SHEET_FONT, scale, 1)
        if text_width <= width_px:
            break
        scale -= 0.02
    return max(scale, SMALLEST_FONT_SCALE)


def _draw_marks(picture: np.ndarray, marks: tuple[SheetMark, ...]) -> None:
    """Boxes and circles, then their words over all of them (readings drawn last)."""
    order = {'no_limit': 0, 'unclassified': 0}
    ordered = sorted(marks, key=lambda mark: order.get(mark.style, 1))
    height, width = picture.shape[:2]
    for mark in ordered:
        colour = STYLE_COLOURS[mark.style]
        thin = mark.style in order
        if mark.shape == 'box':
            cv2.rectangle(picture, (int(mark.x1_px), int(mark.y1_px)),
                          (int(round(mark.x2_px)), int(round(mark.y2_px))), colour, 1,
                          cv2.LINE_AA)
        else:
            centre = (int(round(0.5 * (mark.x1_px + mark.x2_px))),
                      int(round(0.5 * (mark.y1_px + mark.y2_px))))
            radius = max(3, int(round(0.5 * (mark.x2_px - mark.x1_px))))
            cv2.circle(picture, centre, radius, colour, 1 if thin else 2, cv2.LINE_AA)
    for mark in ordered:
        if not mark.words:
            continue
        (text_width, _), _ = cv2.getTextSize(mark.words, SHEET_FONT, SHEET_FONT_SCALE, 1)
        x = int(min(max(2, 0.5 * (mark.x1_px + mark.x2_px) - text_width / 2),
                    width - text_width - 2))
        if mark.shape == 'box':   # truth words under the box, readings' over the circle
            y = int(mark.y2_px) + 16
            y = y if y < height - 2 else int(mark.y1_px) - 20
        else:
            y = int(mark.y1_px) - 5
            y = y if y > 14 else int(mark.y2_px) + 16
        _text(picture, mark.words, (x, y), STYLE_COLOURS[mark.style])


def _zoom_panel(zooms: tuple[SignZoom, ...], rows: int, width_px: int,
                more_readings: int) -> np.ndarray:
    """``rows`` rows of zoomed views with their words (empty rows stay dark)."""
    panel = np.full((rows * ZOOM_ROW_PX, width_px, 3), 24, np.uint8)
    if not zooms:
        _text(panel, 'no sign read in this frame', (10, ZOOM_ROW_PX // 2 + 5),
              STYLE_COLOURS['note'])
    for row, zoom in enumerate(zooms[:rows]):
        top, left = row * ZOOM_ROW_PX + 3, 4
        image = cv2.cvtColor(zoom.image, cv2.COLOR_GRAY2BGR)
        panel[top:top + ZOOM_PX, left:left + ZOOM_PX] = image
        cv2.rectangle(panel, (left - 2, top - 2), (left + ZOOM_PX + 1, top + ZOOM_PX + 1),
                      STYLE_COLOURS[zoom.style], 2)
        text_left = left + ZOOM_PX + 10
        text_width = width_px - text_left - 4
        line_height = ZOOM_PX // max(3, len(zoom.lines))
        for number, (style, words) in enumerate(zoom.lines):
            _text(panel, words, (text_left, top + line_height * number + line_height - 8),
                  STYLE_COLOURS[style], _fitting_scale(words, text_width))
    if more_readings:
        words = f'+{more_readings} more reading(s) in this frame, not zoomed'
        _text(panel, words, (width_px - 8 - cv2.getTextSize(
            words, SHEET_FONT, 0.45, 1)[0][0], rows * ZOOM_ROW_PX - 6),
              STYLE_COLOURS['note'], 0.45)
    return panel


def draw_tile(tile: SheetTile, zoom_rows: int) -> np.ndarray:
    """One tile: caption bar, the picture with its marks, ``zoom_rows`` rows of zooms.

    Returns:
        BGR (CAPTION_HEIGHT_PX + h + zoom_rows * ZOOM_ROW_PX, w, 3) uint8, where (h, w)
        is the picture's shape.
    """
    picture = cv2.cvtColor(tile.picture, cv2.COLOR_GRAY2BGR)
    _draw_marks(picture, tile.marks)
    width = picture.shape[1]
    bar = np.zeros((CAPTION_HEIGHT_PX, width, 3), np.uint8)
    _text(bar, tile.caption, (6, CAPTION_HEIGHT_PX - 7), STYLE_COLOURS['text'])
    right = width - 6
    for reason in reversed(tile.reasons):
        style = 'missed' if reason.endswith('MISSED') else 'tag'
        (reason_width, _), _ = cv2.getTextSize(reason, SHEET_FONT, SHEET_FONT_SCALE, 1)
        right -= reason_width
        _text(bar, reason, (right, CAPTION_HEIGHT_PX - 7), STYLE_COLOURS[style])
        right -= 14
    panel = _zoom_panel(tile.zooms, zoom_rows, width, tile.more_readings)
    return np.vstack([bar, picture, panel])


def legend_lines(with_truth: bool) -> list[tuple[str, str]]:
    """The legend in plain words: (style, line) pairs; a style of a colour key starts
    the line with a swatch of that colour."""
    lines = [
        ('text', 'Each tile: time since the first frame; "limit" = the limit published on '
                 'speed_limit after that frame (- = none: not known yet, or ended); at the '
                 'right, why the frame was chosen.'),
        ('published', 'green circle: a reading the tracker confirmed over several frames '
                      'and published as the limit ("published at ...").'),
        ('single_frame', 'yellow circle: a single-frame reading: read in some frame(s) '
                         'but never confirmed, so never published.'),
        ('end', 'orange circle: an end-of-limit reading never published (green when '
                'published).      gray circle: a candidate read as no speed-limit sign.'),
    ]
    if with_truth:
        lines += [
            ('right', 'truth boxes (from the truth file): blue "right" = its limit was '
                      'published; red "WRONG" = a wrong limit was published on it;'),
            ('missed', 'magenta "MISSED" = never recognized (such a sign gets a tile of its '
                       'own: the frame where it was largest); gray = look-alike, sets no '
                       'limit.'),
        ]
    lines.append(('text', f'Under each frame: {ZOOM_PX} px zoomed views of every sign read in '
                          'it (and of the missed sign), with what was read, whether it was '
                          'published'
                          + (', and the truth' if with_truth else '') + '.'))
    lines.append(('text', '"peak" = correlation peak strength (PSR): how far the best template '
                          'match stands above its surroundings; larger = surer.'))
    return lines


def _legend_strip(width_px: int, lines: list[tuple[str, str]]) -> np.ndarray:
    line_height = 22
    strip = np.full((line_height * len(lines) + 12, width_px, 3), 32, np.uint8)
    for number, (style, words) in enumerate(lines, start=1):
        y = line_height * number
        x = 10
        if style in TRUTH_STYLES:   # truth signs are boxes, candidates circles
            cv2.rectangle(strip, (x, y - 12), (x + 14, y + 2), STYLE_COLOURS[style], 2)
            x += 22
        elif style not in ('text', 'note'):
            cv2.circle(strip, (x + 7, y - 5), 7, STYLE_COLOURS[style], 2, cv2.LINE_AA)
            x += 22
        _text(strip, words, (x, y), STYLE_COLOURS['text'],
              _fitting_scale(words, width_px - x - 8))
    return strip


def draw_sheet(tiles: list[SheetTile], columns: int, header: str,
               legend: list[tuple[str, str]], gap_px: int = 4) -> np.ndarray:
    """Tiles in rows of ``columns`` (time order), under a header and above the legend.

    Args:
        tiles: what each tile shows; their pictures must share one shape.
        columns: tiles per row.
        header: the line above the tiles.
        legend: (style, line) pairs (:func:`legend_lines` and notes).

    Returns:
        BGR (H, W, 3) uint8, ``W = columns * tile width + (columns - 1) * gap_px``.

    Raises:
        ValueError: no tile.
    """
    if not tiles:
        raise ValueError('draw_sheet needs at least one tile')
    zoom_rows = max(1, max(len(tile.zooms) for tile in tiles))
    drawn = [draw_tile(tile, zoom_rows) for tile in tiles]
    tile_height, tile_width = drawn[0].shape[:2]
    rows = -(-len(drawn) // columns)
    width = columns * tile_width + (columns - 1) * gap_px
    header_strip = np.full((34, width, 3), 32, np.uint8)
    _text(header_strip, header, (10, 24), STYLE_COLOURS['text'], 0.65)
    grid = np.full((rows * tile_height + (rows - 1) * gap_px, width, 3), 64, np.uint8)
    for index, tile in enumerate(drawn):
        row, column = divmod(index, columns)
        top, left = row * (tile_height + gap_px), column * (tile_width + gap_px)
        grid[top:top + tile.shape[0], left:left + tile.shape[1]] = tile
    return np.vstack([header_strip, grid, _legend_strip(width, legend)])
