"""The node's input warnings, worded without a node."""
from __future__ import annotations

from speed_sign_detector.ros.input_warnings import (
    COMPRESSED_LOSS_CAUSE,
    TRANSPORT_LOSS_FIX,
    no_image_warning,
    transport_loss_warning,
)


def test_raw_frames_lost_name_the_fast_dds_profile() -> None:
    text = transport_loss_warning(['/camera/image_raw'], 0.25, 30, 90, 1 / 30)
    assert text.startswith('frames are lost before they reach this node on /camera/image_raw:')
    assert '25 % recently, 30 of 120 since start' in text
    assert "the source's 33.3 ms frame period" in text
    assert text.endswith(TRANSPORT_LOSS_FIX)
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' in TRANSPORT_LOSS_FIX


def test_compressed_frames_lost_point_at_cpu_or_network() -> None:
    text = transport_loss_warning(['/camera/image_raw/compressed'], 0.1, 3, 27, None)
    assert text.endswith(COMPRESSED_LOSS_CAUSE)
    assert 'frame period' not in text


def test_no_image_names_topics_qos_and_publishers_seen() -> None:
    text = no_image_warning(12.4, '/image', '/image/compressed', 'best effort, keep last 5',
                            ['/image: 0 publisher(s)', '/image/compressed: 1 publisher(s)'])
    assert text.startswith('no image received for 12 s on /image (sensor_msgs/Image) or '
                           '/image/compressed (sensor_msgs/CompressedImage).')
    assert 'QoS best effort, keep last 5 (sensor data)' in text
    assert text.endswith('Seen: /image: 0 publisher(s); /image/compressed: 1 publisher(s)')
