"""``speed_sign_replay``: publish a bag's image topic into the live ROS graph.

Example (with the node listening on ``/camera/image_raw``)::

    speed_sign_detector --ros-args -r image:=/camera/image_raw &
    speed_sign_replay drive_day --rate 1.0 --loop

For machines without ``ros2 bag play``. Reads ROS 2 (MCAP, sqlite3) and ROS 1 bags with
rosbags and publishes ``sensor_msgs/Image`` or ``CompressedImage`` with the recorded
timing (record-time gaps divided by ``--rate``):

- ROS 2 bags: the stored CDR bytes are published as they are (no re-serialization),
  unless ``--restamp`` asks for new header stamps.
- ROS 1 bags: each message is rebuilt as the ROS 2 message (same header stamp and
  frame id, same image fields).

The topic is published under its recorded name, or ``--publish-as NAME``. By default
the publisher waits up to ``--wait`` seconds for a subscriber before the first message,
then half a second for the subscriber's side of discovery, and (reliable QoS) after the
first message until every subscriber has acknowledged it, so a node started at the same
time sees the whole drive. QoS: reliable, keep last
``--depth`` (compatible with the node's best-effort sensor-data subscription); pass
``--best-effort`` for sensor-data QoS. ROS arguments (``--ros-args -r ...``) are accepted.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from speed_sign_detector import __version__
from speed_sign_detector.bag_io import (
    COMPRESSED_IMAGE_MSGTYPE,
    BagMessage,
    BagReader,
    header_stamp_ns,
)
from speed_sign_detector.errors import BagError, SpeedSignError
from speed_sign_detector.tools.cli_types import (
    non_negative_number,
    positive_integer,
    positive_number,
)

#: After a subscriber appears, how long the publisher waits for the subscriber's side of
#: discovery before the first message, seconds.
DISCOVERY_SETTLE_S = 0.5
#: After the last message, how long the publisher stays for reliable subscribers to take
#: it, seconds.
FINAL_DELIVERY_S = 0.5


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments of ``speed_sign_replay``."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_replay',
        description='Publish the image topic of a ROS 2 (MCAP/sqlite3) or ROS 1 bag with '
        'the recorded timing.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('bag', type=Path, help='bag directory, .mcap/.db3 file or .bag file')
    parser.add_argument('--topic', help='image topic of the bag (needed when it has several)')
    parser.add_argument('--publish-as', help='publish under this topic name instead of the '
                        'recorded one')
    parser.add_argument('--rate', type=positive_number, default=1.0,
                        help='playback speed factor (default 1.0 = recorded timing)')
    parser.add_argument('--loop', action='store_true', help='start again at the end')
    parser.add_argument('--restamp', action='store_true',
                        help='set header stamps to the time each message is due (the '
                        'recorded timing from now on, like a camera\'s capture times: a '
                        'message published late shows as latency, not as a stamp gap)')
    parser.add_argument('--wait', type=non_negative_number, default=5.0,
                        help='seconds to wait for a subscriber before playing (default 5)')
    parser.add_argument('--depth', type=positive_integer, default=5,
                        help='publisher queue depth (default 5)')
    parser.add_argument('--best-effort', action='store_true',
                        help='best-effort QoS (sensor data) instead of reliable')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress on stderr')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_replay``; returns the exit status."""
    import rclpy
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(['speed_sign_replay', *argv])[1:])
    try:
        bag = BagReader(args.bag)
        topic = bag.image_topic(args.topic)
    except SpeedSignError as err:
        print(f'speed_sign_replay: error: {err}', file=sys.stderr)
        return 1
    rclpy.init(args=['speed_sign_replay', *argv])
    try:
        return _play(bag, topic.name, topic.msgtype, args)
    except KeyboardInterrupt:
        return 130
    except SpeedSignError as err:
        print(f'speed_sign_replay: error: {err}', file=sys.stderr)
        return 1
    except Exception:
        # Ctrl-C: rclpy's signal handler shuts the context down before Python raises
        # KeyboardInterrupt, so a publish in between fails with "context is invalid"
        if not rclpy.ok():
            return 130
        raise
    finally:
        bag.close()
        rclpy.try_shutdown()


def _play(bag: BagReader, topic: str, msgtype: str, args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import CompressedImage, Image

    message_class = CompressedImage if msgtype == COMPRESSED_IMAGE_MSGTYPE else Image
    node = rclpy.create_node('speed_sign_replay')
    try:
        qos = (qos_profile_sensor_data if args.best_effort else
               QoSProfile(depth=args.depth, reliability=ReliabilityPolicy.RELIABLE))
        out_topic = args.publish_as or topic
        publisher = node.create_publisher(message_class, out_topic, qos)
        deadline = time.monotonic() + max(args.wait, 0.0)
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        if publisher.get_subscription_count() == 0 and args.wait > 0:
            node.get_logger().warning(f'no subscriber on {publisher.topic_name} after '
                                      f'{args.wait:g} s; playing anyway')
        elif args.wait > 0:
            # The publisher sees the subscriber before the subscriber has matched the
            # publisher; DDS drops what is sent in between (the first frames, even reliable).
            # A reliable publisher also waits, after the first message, until every
            # subscriber has acknowledged it (_play_once): on a loaded machine the settle
            # time alone was not enough.
            _spin_for(node, DISCOVERY_SETTLE_S)
        total = 0
        passes = 0
        while True:
            passes += 1
            published, error = _play_once(bag, topic, message_class, publisher, node, args,
                                          confirm_first=passes == 1 and args.wait > 0
                                          and not args.best_effort)
            total += published
            if error is not None:
                print(f'\nspeed_sign_replay: error: {error}', file=sys.stderr)
                return 1
            if not args.loop:
                break
        if not args.quiet:
            print(f'\npublished {total} messages of {topic} on {publisher.topic_name} '
                  f'({passes} pass{"es" if passes > 1 else ""})', file=sys.stderr)
        _spin_for(node, FINAL_DELIVERY_S)   # reliable subscribers take the last messages
        return 0
    finally:
        node.destroy_node()


def _spin_for(node: Any, seconds: float) -> None:
    """Serve ``node``'s events (discovery, acknowledgements) for ``seconds``."""
    import rclpy

    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def confirm_delivery(publisher: Any, node: Any, timeout_s: float) -> bool:
    """Wait until every subscriber has acknowledged what ``publisher`` (reliable) sent.

    Returns:
        True when all did within ``timeout_s`` seconds; else False, with a warning
        through ``node``'s logger (the replay plays on).
    """
    from rclpy.duration import Duration

    if publisher.wait_for_all_acked(Duration(nanoseconds=int(timeout_s * 1e9))):
        return True
    node.get_logger().warning(f'the first message on {publisher.topic_name} was not '
                              f'acknowledged within {timeout_s:g} s; playing on')
    return False


def _play_once(bag: BagReader, topic: str, message_class: type, publisher: Any, node: Any,
               args: argparse.Namespace, confirm_first: bool = False
               ) -> tuple[int, BagError | None]:
    """One pass over the bag with the recorded timing; returns (published, error).

    ``confirm_first``: after the first message, wait (up to ``args.wait`` seconds) until
    every matched subscriber has acknowledged it, i.e. has matched the publisher too; the
    recorded timing then starts from there.
    """
    first_log_ns: int | None = None
    started = time.monotonic()
    started_clock_ns = node.get_clock().now().nanoseconds
    published = 0
    progress = not args.quiet and sys.stderr.isatty()
    deserialize = args.restamp or not bag.is_ros2
    try:
        for item in bag.messages(topic, deserialize=deserialize):
            if first_log_ns is None:
                first_log_ns = item.log_time_ns
            offset_ns = int((item.log_time_ns - first_log_ns) / args.rate)
            due = started + offset_ns * 1e-9
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if bag.is_ros2 and not args.restamp:
                publisher.publish(item.raw)
            else:
                publisher.publish(to_rclpy(item, message_class, started_clock_ns + offset_ns
                                           if args.restamp else None))
            published += 1
            if confirm_first and published == 1:
                confirm_delivery(publisher, node, args.wait)
                started = time.monotonic() - offset_ns * 1e-9
                started_clock_ns = node.get_clock().now().nanoseconds - offset_ns
            if progress and published % 10 == 0:
                print(f'\r{published} messages', end='', file=sys.stderr, flush=True)
    except BagError as err:
        return published, err
    return published, None


def to_rclpy(item: BagMessage, message_class: type, restamp_ns: int | None = None) -> Any:
    """Build the rclpy Image / CompressedImage equal to a rosbags message (ROS 1 or 2).

    Args:
        item: a message read with :class:`speed_sign_detector.bag_io.BagReader`.
        message_class: ``sensor_msgs.msg.Image`` or ``CompressedImage``.
        restamp_ns: when given, the header stamp (ns since the epoch).
    """
    from builtin_interfaces.msg import Time
    from std_msgs.msg import Header

    from speed_sign_detector.ros.messages import build

    source = item.message
    stamp_ns = header_stamp_ns(source, item.log_time_ns)
    if restamp_ns is not None:
        stamp_ns = restamp_ns
    stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    header = Header(stamp=stamp, frame_id=str(source.header.frame_id))
    if item.msgtype == COMPRESSED_IMAGE_MSGTYPE:
        return build(message_class, header=header, format=str(source.format),
                     data=source.data)
    return build(message_class, header=header, height=int(source.height),
                 width=int(source.width), encoding=str(source.encoding),
                 is_bigendian=int(source.is_bigendian), step=int(source.step),
                 data=source.data)


if __name__ == '__main__':
    sys.exit(main())
