"""Drawing of pipeline results onto frames (debug image; the styles of the Foxglove
annotations). No ROS imports. The contact sheet is drawn by
:mod:`speed_sign_detector.tools.contact_sheet_drawing`."""
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


def detection_style(detection: Detection) -> tuple[tuple[int, int, int], str]:
    """(BGR colour, short text) of a candidate in the Foxglove annotations: green with
    value and PSR when read as a limit, orange when read as something else (``end`` for an
    end-of-limit sign, no text otherwise), cyan when not classified."""
    classification = detection.classification
    if classification is None:
        return COLOUR_UNCLASSIFIED, ''
    if classification.is_limit:
        return COLOUR_LIMIT, f'{classification.label} psr {classification.psr:.0f}'
    if classification.label == LABEL_END_OF_LIMIT:
        return COLOUR_OTHER, f'end psr {classification.psr:.0f}'
    return COLOUR_OTHER, ''
