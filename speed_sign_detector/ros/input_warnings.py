"""The node's warnings about its input: frames lost before they reach it, and no images
at all. Plain text builders (no ROS), so that the wording is tested without a node."""
from __future__ import annotations

from collections.abc import Sequence

__all__ = ['COMPRESSED_LOSS_CAUSE', 'TRANSPORT_LOSS_FIX', 'no_image_warning',
           'transport_loss_warning']

#: What a user does about raw frames lost in transport.
TRANSPORT_LOSS_FIX = (
    'Raw images of ~1 MB are lost whole by best-effort DDS with Fast DDS defaults; export '
    'FASTRTPS_DEFAULT_PROFILES_FILE=$(ros2 pkg prefix speed_sign_detector)/share/'
    'speed_sign_detector/config/fastdds_large_images.xml for the camera driver (or '
    '`ros2 bag play`) AND this node, or subscribe to image/compressed.')
#: The same for compressed images, which are small enough for Fast DDS's defaults.
COMPRESSED_LOSS_CAUSE = (
    'Compressed images are small, so the usual cause is this node starved of CPU (its '
    'subscription queue, keep last 5, overflows: give it a core, or a deeper queue with '
    'qos_overrides.<topic>.subscription.depth) or a lossy network between the hosts.')


def transport_loss_warning(lossy_topics: Sequence[str], recent_share: float,
                           frames_lost: int, frames_received: int,
                           frame_period_s: float | None) -> str:
    """The warning for frames lost before they reached the node.

    Args:
        lossy_topics: the image topics frames were lost on.
        recent_share: share of the recent frames lost, 0 to 1.
        frames_lost, frames_received: counts since the start.
        frame_period_s: the source's frame period the gaps were measured against, s
            (``None`` or 0: unknown).
    """
    raw_lost = any(not topic.endswith('compressed') for topic in lossy_topics)
    timing = (f' (gaps in the header stamps against the source\'s '
              f'{frame_period_s * 1e3:.1f} ms frame period)' if frame_period_s else '')
    return (f'frames are lost before they reach this node on {", ".join(lossy_topics)}: '
            f'{100 * recent_share:.0f} % recently, {frames_lost} of '
            f'{frames_received + frames_lost} since start{timing}. '
            + (TRANSPORT_LOSS_FIX if raw_lost else COMPRESSED_LOSS_CAUSE))


def no_image_warning(silent_s: float, image_topic: str, compressed_topic: str,
                     subscription_qos: str, publishers: Sequence[str]) -> str:
    """The warning for a node that has received no image for ``silent_s`` seconds.

    Args:
        silent_s: seconds since the last image (or the start).
        image_topic, compressed_topic: the resolved topics subscribed to.
        subscription_qos: the subscriptions' QoS in words.
        publishers: per topic, its publishers and their QoS in words.
    """
    return (f'no image received for {silent_s:.0f} s on {image_topic} '
            f'(sensor_msgs/Image) or {compressed_topic} '
            f'(sensor_msgs/CompressedImage). This node subscribes with QoS '
            f'{subscription_qos} (sensor data); a publisher must '
            f'offer compatible QoS, and the topic must be remapped to the camera '
            f'(e.g. -r image:=/camera/image_raw). Seen: {"; ".join(publishers)}')
