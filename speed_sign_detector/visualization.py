"""Drawing of pipeline results onto frames (debug image, demo pictures). No ROS imports."""
from __future__ import annotations

import cv2
import numpy as np

from speed_sign_detector.pipeline import FrameResult

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


def contact_sheet(images: list[np.ndarray], columns: int = 4,
                  tile_width_px: int = 320) -> np.ndarray:
    """Tile BGR images (resized to ``tile_width_px`` wide) into one BGR image."""
    if not images:
        raise ValueError('contact_sheet needs at least one image')
    tiles = []
    for image in images:
        scale = tile_width_px / image.shape[1]
        tiles.append(cv2.resize(to_bgr(image), (tile_width_px, int(round(image.shape[0] * scale))),
                                interpolation=cv2.INTER_AREA))
    tile_height_px = max(tile.shape[0] for tile in tiles)
    rows = -(-len(tiles) // columns)
    sheet = np.zeros((rows * tile_height_px, columns * tile_width_px, 3), np.uint8)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        sheet[row * tile_height_px:row * tile_height_px + tile.shape[0],
              column * tile_width_px:(column + 1) * tile_width_px] = tile
    return sheet
