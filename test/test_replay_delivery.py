"""``speed_sign_replay``'s delivery check with real rclpy: a reliable publisher waits
until every subscriber has acknowledged its first message, and warns, then plays on,
when one does not.

The subscriber is a real rclpy process; to make it stop acknowledging, the test freezes
it with SIGSTOP after it has matched the publisher (and thaws it afterwards).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator

import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_spin import module_domain
from std_msgs.msg import String

from speed_sign_detector.tools.replay import confirm_delivery

DOMAIN_ID = module_domain('test_replay_delivery')
MATCH_TIMEOUT_S = 30.0
SUBSCRIBER = f'''
import sys
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init(domain_id={DOMAIN_ID})
node = rclpy.create_node('delivery_probe_listener')
node.create_subscription(String, sys.argv[1], lambda message: None,
                         QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
print('subscribed', flush=True)
rclpy.spin(node)
'''


@pytest.fixture()
def publisher_and_listener() -> Iterator[tuple[object, object, subprocess.Popen]]:
    """A reliable publisher in this process, matched with a subscriber process, on a topic
    of their own (the endpoints of an ended process stay known to DDS for a while)."""
    topic = f'/delivery_probe_{uuid.uuid4().hex[:12]}'
    listener = subprocess.Popen([sys.executable, '-c', SUBSCRIBER, topic],
                                stdout=subprocess.PIPE, text=True,
                                env=dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID)))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    node = rclpy.create_node('delivery_probe_publisher', context=context)
    publisher = node.create_publisher(
        String, topic, QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    try:
        assert listener.stdout is not None and listener.stdout.readline().strip() == \
            'subscribed'
        deadline = time.monotonic() + MATCH_TIMEOUT_S
        while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert publisher.get_subscription_count() == 1, 'the subscriber never matched'
        yield publisher, node, listener
    finally:
        listener.kill()   # a helper, not under test: its shutdown is not checked
        listener.wait(timeout=10)
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_delivery_is_confirmed_by_a_live_subscriber(
        publisher_and_listener: tuple[object, object, subprocess.Popen],
        capfd: pytest.CaptureFixture[str]) -> None:
    publisher, node, _ = publisher_and_listener
    publisher.publish(String(data='first'))
    assert confirm_delivery(publisher, node, timeout_s=MATCH_TIMEOUT_S) is True
    assert 'not acknowledged' not in capfd.readouterr().err


def test_a_silent_subscriber_gives_a_warning_and_the_replay_plays_on(
        publisher_and_listener: tuple[object, object, subprocess.Popen],
        capfd: pytest.CaptureFixture[str]) -> None:
    publisher, node, listener = publisher_and_listener
    listener.send_signal(signal.SIGSTOP)
    publisher.publish(String(data='first'))
    started = time.monotonic()
    assert confirm_delivery(publisher, node, timeout_s=1.0) is False
    assert time.monotonic() - started >= 0.9   # it waited for the acknowledgement
    err = capfd.readouterr().err
    assert (f'the first message on {publisher.topic_name} was not acknowledged within 1 s; '
            'playing on') in err
