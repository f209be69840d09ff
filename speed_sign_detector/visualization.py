"""Drawing of pipeline results onto frames (debug image, contact sheet). No ROS imports."""
from __future__ import annotations

import cv2
import numpy as np

from speed_sign_detector.pipeline import Detection, FrameResult
from speed_sign_detector.recognition.classifier import LABEL_END_OF_LIMIT

#: BGR colours of the overlay.
COLOUR_LIMIT = (0, 200, 0)
COLOUR_OTHER = (0, 165, 255)
COLOUR_UNCLASSIFIED = (200, 200, 0)
COLOUR_TEXT = (255, 255, 255)


def to_bgr(frame: np.ndarray) -> np.ndarray:
    """A BGR copy of a gray (H, W) or BGR (H, W, 3) uint8 frame."""
    if frame.ndim == 2:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    if frame.ndim == 3 and frame.shape[2] == 3:
        return frame.copy()
    raise ValueError(f'expected a (H, W) or (H, W, 3) frame, got shape {frame.shape}')


def draw_frame_result(frame: np.ndarray, result: FrameResult) -> np.ndarray:
    """Draw candidates (circle of the estimated radius, rank, label, PSR) and the active limit.

    Args:
        frame: the processed frame, gray (H, W) or BGR (H, W, 3), uint8.
        result: what the pipeline found in it.

    Returns:
        A new BGR (H, W, 3) uint8 image.
    """
    canvas = to_bgr(frame)
    for rank, detection in enumerate(result.detections, start=1):
        candidate, classification = detection.candidate, detection.classification
        centre = (int(round(candidate.x_px)), int(round(candidate.y_px)))
        radius = max(1, int(round(candidate.radius_px)))
        if classification is None:
            colour, text = COLOUR_UNCLASSIFIED, f'#{rank}'
        elif classification.is_limit:
            colour, text = COLOUR_LIMIT, f'{classification.label} psr {classification.psr:.0f}'
        else:
            colour, text = COLOUR_OTHER, f'#{rank} {classification.label}'
        cv2.circle(canvas, centre, radius, colour, 1, cv2.LINE_AA)
        cv2.putText(canvas, text, (centre[0] - radius, centre[1] - radius - 3),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1, cv2.LINE_AA)
    banner = (f'limit {result.active_limit_kmh} km/h' if result.active_limit_kmh
              else 'limit unknown')
    cv2.rectangle(canvas, (0, 0), (170, 22), (0, 0, 0), -1)
    cv2.putText(canvas, banner, (5, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, COLOUR_TEXT, 1,
                cv2.LINE_AA)
    return canvas


#: Font of the contact sheet's words, drawn at the sheet's own scale (100 % zoom legible).
SHEET_FONT = cv2.FONT_HERSHEY_SIMPLEX
SHEET_FONT_SCALE = 0.55
#: Height of a tile's caption bar, pixels.
CAPTION_HEIGHT_PX = 24
COLOUR_CAPTION = (0, 0, 0)
COLOUR_EVENT = (80, 255, 80)


def _text(canvas: np.ndarray, text: str, origin: tuple[int, int], colour: tuple[int, ...],
          scale: float = SHEET_FONT_SCALE) -> None:
    """Anti-aliased text with a dark outline, so it reads on any background (the outline
    is the same text shifted by a pixel: a thicker stroke would also space it wider)."""
    x, y = origin
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1), (0, 2), (2, 0), (0, -2), (-2, 0)):
        cv2.putText(canvas, text, (x + dx, y + dy), SHEET_FONT, scale, (0, 0, 0), 1,
                    cv2.LINE_AA)
    cv2.putText(canvas, text, origin, SHEET_FONT, scale, colour, 1, cv2.LINE_AA)


def detection_style(detection: Detection) -> tuple[tuple[int, int, int], str]:
    """(BGR colour, short text) of a candidate on the contact sheet: green with value and
    PSR when read as a limit, orange when read as something else (``end`` for an
    end-of-limit sign, no text otherwise), cyan when not classified."""
    classification = detection.classification
    if classification is None:
        return COLOUR_UNCLASSIFIED, ''
    if classification.is_limit:
        return COLOUR_LIMIT, f'{classification.label} psr {classification.psr:.0f}'
    if classification.label == LABEL_END_OF_LIMIT:
        return COLOUR_OTHER, f'end psr {classification.psr:.0f}'
    return COLOUR_OTHER, ''


def draw_tile(frame: np.ndarray, result: FrameResult, width_px: int, caption: str,
              tag: str = '') -> np.ndarray:
    """One contact-sheet tile: the frame scaled to ``width_px``, the candidates drawn at
    that scale (so the words keep a legible size), a caption bar on top.

    Args:
        frame: the processed frame, gray (H, W) or BGR (H, W, 3), uint8, full size.
        result: what the pipeline found in it (pixel coordinates of ``frame``).
        width_px: the tile's width; the height keeps the frame's aspect ratio.
        caption: the caption bar's text (time, active limit).
        tag: a highlighted note at the caption's right (``'50 recognized'``).

    Returns:
        BGR (CAPTION_HEIGHT_PX + h, width_px, 3) uint8.
    """
    scale = width_px / frame.shape[1]
    height_px = int(round(frame.shape[0] * scale))
    picture = cv2.resize(to_bgr(frame), (width_px, height_px), interpolation=cv2.INTER_AREA)
    marks = []
    for detection in result.detections:
        colour, words = detection_style(detection)
        candidate = detection.candidate
        centre = (int(round(candidate.x_px * scale)), int(round(candidate.y_px * scale)))
        radius = max(3, int(round(candidate.radius_px * scale)) + 2)
        marks.append((colour == COLOUR_LIMIT, centre, radius, colour, words))
    marks.sort(key=lambda mark: mark[0])   # limits drawn last, on top
    for _, centre, radius, colour, _ in marks:
        cv2.circle(picture, centre, radius, colour, 2 if colour == COLOUR_LIMIT else 1,
                   cv2.LINE_AA)
    for _, centre, radius, colour, words in marks:   # words over every circle
        if words:
            (text_width, _), _ = cv2.getTextSize(words, SHEET_FONT, SHEET_FONT_SCALE, 1)
            x = min(max(2, centre[0] - text_width // 2), width_px - text_width - 2)
            y = centre[1] - radius - 5
            _text(picture, words, (x, y if y > 14 else centre[1] + radius + 16), colour)
    tile = np.zeros((CAPTION_HEIGHT_PX + height_px, width_px, 3), np.uint8)
    tile[:CAPTION_HEIGHT_PX] = COLOUR_CAPTION
    tile[CAPTION_HEIGHT_PX:] = picture
    _text(tile, caption, (6, CAPTION_HEIGHT_PX - 7), COLOUR_TEXT)
    if tag:
        (tag_width, _), _ = cv2.getTextSize(tag, SHEET_FONT, SHEET_FONT_SCALE, 1)
        _text(tile, tag, (width_px - tag_width - 6, CAPTION_HEIGHT_PX - 7), COLOUR_EVENT)
    return tile


def legend_strip(width_px: int, lines: list[str]) -> np.ndarray:
    """The contact sheet's legend: the three circle colours, then ``lines`` of text.

    Returns:
        BGR (h, width_px, 3) uint8.
    """
    line_height = 24
    strip = np.full((line_height * (1 + len(lines)) + 10, width_px, 3), 32, np.uint8)
    x, y = 10, line_height
    for colour, words in ((COLOUR_LIMIT, 'read as a speed limit (value, PSR)'),
                          (COLOUR_OTHER, 'candidate read as no limit ("end": end of limit)'),
                          (COLOUR_UNCLASSIFIED, 'candidate not classified')):
        cv2.circle(strip, (x + 8, y - 6), 8, colour, 2, cv2.LINE_AA)
        _text(strip, words, (x + 24, y), COLOUR_TEXT)
        (text_width, _), _ = cv2.getTextSize(words, SHEET_FONT, SHEET_FONT_SCALE, 1)
        x += 24 + text_width + 30
    for number, line in enumerate(lines, start=2):
        _text(strip, line, (10, line_height * number), COLOUR_TEXT)
    return strip


def contact_sheet(tiles: list[np.ndarray], columns: int, header: str,
                  legend_lines: list[str], gap_px: int = 4) -> np.ndarray:
    """Tiles (from :func:`draw_tile`, all the same size) in rows of ``columns``, under a
    header line and above a legend (:func:`legend_strip`).

    Returns:
        BGR (H, W, 3) uint8, ``W = columns * tile width + (columns - 1) * gap_px``.

    Raises:
        ValueError: no tile.
    """
    if not tiles:
        raise ValueError('contact_sheet needs at least one tile')
    tile_height, tile_width = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    width = columns * tile_width + (columns - 1) * gap_px
    header_strip = np.full((34, width, 3), 32, np.uint8)
    _text(header_strip, header, (10, 24), COLOUR_TEXT, 0.65)
    grid = np.full((rows * tile_height + (rows - 1) * gap_px, width, 3), 64, np.uint8)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        top, left = row * (tile_height + gap_px), column * (tile_width + gap_px)
        grid[top:top + tile.shape[0], left:left + tile.shape[1]] = tile
    return np.vstack([header_strip, grid, legend_strip(width, legend_lines)])
