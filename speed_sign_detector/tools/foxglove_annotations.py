"""Foxglove image annotations of the pipeline's results, for results bags.

Foxglove's Image panel draws ``foxglove_msgs/msg/ImageAnnotations`` over an image topic
whose stamps match. :func:`register_foxglove_types` adds the ROS 2 definitions of that
message and of the messages it uses (below, as published in the foxglove/schemas
repository, ``ros_foxglove_msgs/ros2``) to a rosbags typestore, so that a rosbags
writer can serialize them and stores their definitions in the bag (MCAP schemas);
:func:`image_annotations_message` draws one frame's results as the contact sheet does
(:func:`speed_sign_detector.visualization.detection_style`): a circle per candidate
(green when read as a speed limit, orange otherwise, cyan when not classified), the
value and PSR above a limit (``end`` and PSR above an end of limit), and the active
limit in the top-left corner.
No ROS installation is needed (the messages are rosbags classes).
"""
from __future__ import annotations

from typing import Any

from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from speed_sign_detector.errors import BagError
from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.visualization import COLOUR_TEXT, detection_style

__all__ = ['IMAGE_ANNOTATIONS_MSGTYPE', 'FOXGLOVE_MESSAGE_DEFINITIONS',
           'image_annotations_message', 'register_foxglove_types']

IMAGE_ANNOTATIONS_MSGTYPE = 'foxglove_msgs/msg/ImageAnnotations'

#: ROS 2 ``.msg`` definitions (foxglove/schemas, ros_foxglove_msgs/ros2), comments left out.
FOXGLOVE_MESSAGE_DEFINITIONS: dict[str, str] = {
    'foxglove_msgs/msg/Color': '''
float64 r
float64 g
float64 b
float64 a
''',
    'foxglove_msgs/msg/Point2': '''
float64 x
float64 y
''',
    'foxglove_msgs/msg/CircleAnnotation': '''
builtin_interfaces/Time timestamp
foxglove_msgs/Point2 position
float64 diameter
float64 thickness
foxglove_msgs/Color fill_color
foxglove_msgs/Color outline_color
''',
    'foxglove_msgs/msg/PointsAnnotation': '''
builtin_interfaces/Time timestamp
uint8 UNKNOWN=0
uint8 POINTS=1
uint8 LINE_LOOP=2
uint8 LINE_STRIP=3
uint8 LINE_LIST=4
uint8 type
foxglove_msgs/Point2[] points
foxglove_msgs/Color outline_color
foxglove_msgs/Color[] outline_colors
foxglove_msgs/Color fill_color
float64 thickness
''',
    'foxglove_msgs/msg/TextAnnotation': '''
builtin_interfaces/Time timestamp
foxglove_msgs/Point2 position
string text
float64 font_size
foxglove_msgs/Color text_color
foxglove_msgs/Color background_color
''',
    IMAGE_ANNOTATIONS_MSGTYPE: '''
foxglove_msgs/CircleAnnotation[] circles
foxglove_msgs/PointsAnnotation[] points
foxglove_msgs/TextAnnotation[] labels
''',
}

RGBA_TEXT_BACKGROUND = (0.0, 0.0, 0.0, 0.6)
RGBA_NONE = (0.0, 0.0, 0.0, 0.0)
#: Font size of the labels, pixels of the image.
FONT_SIZE_PX = 14.0
#: Outline thickness of the circles, pixels.
CIRCLE_THICKNESS_PX = 2.0


def rgba(bgr: tuple[int, int, int]) -> tuple[float, float, float, float]:
    """An OpenCV BGR colour (0..255) as Foxglove's opaque RGBA (0..1)."""
    return (bgr[2] / 255.0, bgr[1] / 255.0, bgr[0] / 255.0, 1.0)


def register_foxglove_types(typestore: Typestore) -> None:
    """Add the Foxglove annotation messages to ``typestore`` (once; again is harmless).

    Raises:
        BagError: rosbags refuses a definition.
    """
    if IMAGE_ANNOTATIONS_MSGTYPE in typestore.types:
        return
    types: dict[str, Any] = {}
    try:
        for msgtype, definition in FOXGLOVE_MESSAGE_DEFINITIONS.items():
            types.update(get_types_from_msg(definition, msgtype))
        typestore.register(types)
    except Exception as err:  # noqa: BLE001 - rosbags raises several kinds
        raise BagError(f'cannot register the Foxglove annotation messages: {err}') from err


def image_annotations_message(result: FrameResult, stamp_ns: int, typestore: Typestore
                              ) -> Any:
    """The ``ImageAnnotations`` of one frame's results, stamped like its image.

    Args:
        result: what the pipeline found in the frame.
        stamp_ns: the image's header stamp, nanoseconds (each annotation carries it).
        typestore: a typestore holding the Foxglove types (:func:`register_foxglove_types`).

    Returns:
        A rosbags ``foxglove_msgs/msg/ImageAnnotations``: one circle per candidate (its
        detected radius), a text above each candidate read as a limit (``'50 psr 12'``)
        or an end of limit (``'end psr 9'``), and the active limit at the top left.
    """
    types = typestore.types
    time = types['builtin_interfaces/msg/Time'](sec=stamp_ns // 1_000_000_000,
                                                nanosec=stamp_ns % 1_000_000_000)
    color = types['foxglove_msgs/msg/Color']
    point = types['foxglove_msgs/msg/Point2']
    circle = types['foxglove_msgs/msg/CircleAnnotation']
    text = types['foxglove_msgs/msg/TextAnnotation']

    def label(x_px: float, y_px: float, words: str,
              colour: tuple[float, float, float, float]) -> Any:
        return text(timestamp=time, position=point(x=x_px, y=y_px), text=words,
                    font_size=FONT_SIZE_PX, text_color=color(*colour),
                    background_color=color(*RGBA_TEXT_BACKGROUND))

    circles, labels = [], []
    for detection in result.detections:
        candidate = detection.candidate
        colour, words = detection_style(detection)
        circles.append(circle(timestamp=time, position=point(x=candidate.x_px, y=candidate.y_px),
                              diameter=2.0 * candidate.radius_px,
                              thickness=CIRCLE_THICKNESS_PX, fill_color=color(*RGBA_NONE),
                              outline_color=color(*rgba(colour))))
        if words:
            labels.append(label(candidate.x_px - candidate.radius_px,
                                max(0.0, candidate.y_px - candidate.radius_px - FONT_SIZE_PX),
                                words, rgba(colour)))
    banner = (f'limit {result.active_limit_kmh} km/h' if result.active_limit_kmh
              else 'limit unknown')
    labels.append(label(4.0, 4.0, banner, rgba(COLOUR_TEXT)))
    return types[IMAGE_ANNOTATIONS_MSGTYPE](circles=circles, points=[], labels=labels)
