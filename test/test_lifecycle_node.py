"""The managed (lifecycle) node driven by real lifecycle service calls from another node.

In-process: the node under test and a client node (lifecycle_msgs ChangeState/GetState
calls, the image probe of test_node) in a private context, one executor thread. The
failed configure runs the installed executable with EGL unable to find a device.
"""
from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_spin import module_domain, ros_domain_environment, spinning
from scene_helpers import textured_background
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from test_node import Probe, send_and_wait, wait_for
from test_node_cli import tool

from speed_sign_detector.ros.lifecycle_node import ManagedSpeedSignDetectorNode
from speed_sign_detector.ros.messages import image_message

DOMAIN_ID = module_domain('test_lifecycle_node')
#: The domains of the tests that start a node of their own.
EXECUTABLE_DOMAIN_ID = module_domain('test_lifecycle_node', 1)
UNCONFIGURED_DOMAIN_ID = module_domain('test_lifecycle_node', 2)
pytestmark = pytest.mark.ros


class LifecycleClient(Node):
    """Calls the managed node's lifecycle services, as `ros2 lifecycle set` does."""

    def __init__(self, target: str = 'speed_sign_detector', **kwargs: object) -> None:
        super().__init__('lifecycle_test_client', **kwargs)
        self.change = self.create_client(ChangeState, f'/{target}/change_state')
        self.get = self.create_client(GetState, f'/{target}/get_state')

    def _call(self, client: object, request: object, timeout_s: float = 120.0) -> object:
        wait_for(client.service_is_ready, f'{client.srv_name}', timeout_s=timeout_s)
        future = client.call_async(request)
        wait_for(future.done, f'the response of {client.srv_name}', timeout_s=timeout_s)
        return future.result()

    def transition(self, transition_id: int) -> bool:
        request = ChangeState.Request(transition=Transition(id=transition_id))
        return self._call(self.change, request).success

    def state(self) -> str:
        return self._call(self.get, GetState.Request()).current_state.label


@pytest.fixture(scope='module')
def managed(request: pytest.FixtureRequest
            ) -> Iterator[tuple[ManagedSpeedSignDetectorNode, LifecycleClient, Probe]]:
    with ros_domain_environment(DOMAIN_ID):
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=DOMAIN_ID)
        bank_cache = request.config.cache.mkdir('speed_sign_classifier_banks')
        node = ManagedSpeedSignDetectorNode(context=context, parameter_overrides=[
            Parameter('classifier.cache_dir', value=str(bank_cache)),
            Parameter('diagnostics_period_s', value=0.5)])
        client = LifecycleClient(context=context)
        probe = Probe(context=context)
        with spinning(context, node, client, probe):
            yield node, client, probe


def send_frame(probe: Probe, seed: int) -> None:
    send_and_wait(probe, image_message(textured_background(seed), Header(),
                                       image_class=Image), probe.image_pub)


def test_transitions_build_serve_pause_and_release(managed: tuple) -> None:
    node, client, probe = managed
    assert client.state() == 'unconfigured'
    assert not node.pipeline_running and node.count_publishers('candidates') == 0

    assert client.transition(Transition.TRANSITION_CONFIGURE)
    assert client.state() == 'inactive'
    assert node.pipeline_running                          # GL context and banks built
    assert node.count_publishers('candidates') == 1
    assert probe.image_pub.get_subscription_count() == 0  # not taking images yet

    assert client.transition(Transition.TRANSITION_ACTIVATE)
    assert client.state() == 'active'
    wait_for(lambda: probe.image_pub.get_subscription_count() > 0, 'the image subscription')
    wait_for(lambda: probe.limits == [0], 'the latched speed_limit')
    send_frame(probe, 11)
    wait_for(lambda: probe.diagnostics, 'diagnostics while active')

    assert client.transition(Transition.TRANSITION_DEACTIVATE)
    assert client.state() == 'inactive'
    wait_for(lambda: probe.image_pub.get_subscription_count() == 0, 'unsubscribing')
    assert node.pipeline_running                          # the GL context is kept
    with probe.lock:
        answered = len(probe.candidates)
    probe.image_pub.publish(image_message(textured_background(12), Header(),
                                          image_class=Image))
    time.sleep(1.0)
    assert len(probe.candidates) == answered              # nothing processed

    assert client.transition(Transition.TRANSITION_ACTIVATE)
    wait_for(lambda: probe.image_pub.get_subscription_count() > 0, 'resubscribing')
    send_frame(probe, 13)                                 # served by the same pipeline

    assert client.transition(Transition.TRANSITION_DEACTIVATE)
    assert client.transition(Transition.TRANSITION_CLEANUP)
    assert client.state() == 'unconfigured'
    assert not node.pipeline_running
    wait_for(lambda: node.count_publishers('candidates') == 0, 'publishers destroyed')

    assert client.transition(Transition.TRANSITION_CONFIGURE)   # and again
    assert client.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN
                             if client.state() == 'unconfigured'
                             else Transition.TRANSITION_INACTIVE_SHUTDOWN)
    assert client.state() == 'finalized'
    assert not node.pipeline_running


def test_a_configure_that_cannot_build_the_pipeline_fails_with_the_reason(
        tmp_path: Path) -> None:
    """The installed executable with --lifecycle, backend gl and no EGL device."""
    environment = dict(os.environ, ROS_DOMAIN_ID=str(EXECUTABLE_DOMAIN_ID), PYTHONUNBUFFERED='1',
                       __EGL_VENDOR_LIBRARY_FILENAMES=str(tmp_path / 'no_vendor.json'))
    log_path = tmp_path / 'node.log'
    with log_path.open('w') as log:
        process = subprocess.Popen([tool('speed_sign_detector'), '--lifecycle', '--ros-args',
                                    '-p', 'backend:=gl', '-p', 'classify:=false'],
                                   env=environment, stdout=log, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=EXECUTABLE_DOMAIN_ID)
    client = LifecycleClient(context=context)
    with spinning(context, client):
        try:
            assert client.state() == 'unconfigured'
            assert not client.transition(Transition.TRANSITION_CONFIGURE)
            assert client.state() == 'unconfigured'
            assert process.poll() is None                  # the node keeps running
        finally:
            process.terminate()
            status = process.wait(timeout=60)
    output = log_path.read_text()
    assert status == 0, output
    assert 'configure failed' in output and 'OpenGL' in output, output
    assert 'Traceback' not in output, output


def test_a_parameter_set_while_unconfigured_is_built_in_not_applied_again(
        request: pytest.FixtureRequest) -> None:
    """The pipeline that configure builds already has the change: the worker does not
    apply it a second time (which logged a spurious "parameters applied"); a change while
    configured is applied."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=UNCONFIGURED_DOMAIN_ID)
    bank_cache = request.config.cache.mkdir('speed_sign_classifier_banks')
    node = ManagedSpeedSignDetectorNode(context=context, parameter_overrides=[
        Parameter('classifier.cache_dir', value=str(bank_cache))])
    client = LifecycleClient(context=context)
    applied: list[float] = []
    apply = node._reconfigure

    def counting_apply(pipeline: object, config: object) -> None:
        applied.append(config.classifier.psr_threshold)   # type: ignore[attr-defined]
        apply(pipeline, config)

    node._reconfigure = counting_apply   # type: ignore[method-assign]
    with spinning(context, node, client):
        result = node.set_parameters([Parameter('classifier.psr_threshold', value=7.5)])
        assert result[0].successful
        assert client.transition(Transition.TRANSITION_CONFIGURE)
        assert node.pipeline_running
        time.sleep(1.0)                     # time for a second application, if any
        assert applied == []
        assert node._pipeline_config.classifier.psr_threshold == 7.5
        assert node.set_parameters([Parameter('classifier.psr_threshold', value=9.0)])[0] \
            .successful
        wait_for(lambda: applied == [9.0], 'the change applied while configured')
        assert client.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN)
