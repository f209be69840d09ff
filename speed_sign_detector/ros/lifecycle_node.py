"""The managed (lifecycle) node, for vehicle stacks that bring nodes up in order.

``speed_sign_detector --lifecycle`` runs it (the plain node stays the default). Same
parameters, topics and diagnostics as the plain node
(:class:`~speed_sign_detector.ros.detector_node_base.DetectorNodeBase`); the transitions
decide when its parts exist:

* configure: read the parameters, build the pipeline (GL context, classifier filter
  banks) on its worker thread, create the (lifecycle) publishers. A failure is a failed
  transition with the reason logged; the node stays unconfigured.
* activate: subscribe to ``image`` and ``image/compressed``, start the diagnostics,
  enable the publishers, publish the active limit (latched).
* deactivate: unsubscribe, finish the frames in flight; the pipeline and its GL context
  stay alive, so activate resumes at once.
* cleanup: stop the worker (the pipeline closes on its thread), destroy the publishers.
* shutdown: from any state, release everything; also from :meth:`destroy_node`.

rclpy has no lifecycle subscription, so the image subscriptions are created on activate
and destroyed on deactivate. Transition callbacks catch their own errors and return
``FAILURE`` (an exception escaping one is swallowed by rclpy without a trace).
"""
from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.ros.detector_node_base import DetectorNodeBase
from speed_sign_detector.ros.parameters import NODE_NAME


class ManagedSpeedSignDetectorNode(DetectorNodeBase, LifecycleNode):
    """The detector as a lifecycle node; see the module docstring.

    Raises (from the constructor):
        ConfigError: for invalid initial parameters (they are declared at construction,
            so that ``ros2 param`` works in every state).
    """

    def __init__(self, node_name: str = NODE_NAME, **node_kwargs: Any) -> None:
        LifecycleNode.__init__(self, node_name, **node_kwargs)
        try:
            self.init_detector()
        except BaseException:
            LifecycleNode.destroy_node(self)
            raise
        self.get_logger().info('managed node: waiting for the configure transition')

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the pipeline and the publishers."""
        try:
            self._pipeline_config, self._options = self.read_parameters()
            self.start_pipeline()
            self.create_outputs(self.create_lifecycle_publisher)
        except SpeedSignError as err:
            self.get_logger().error(f'configure failed: {err}')
            self._release()
            return TransitionCallbackReturn.FAILURE
        except Exception as err:  # noqa: BLE001 - rclpy would swallow it silently
            self.get_logger().error(f'configure failed: {type(err).__name__}: {err}')
            self._release()
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info(f'configured: voting backend {self._backend} '
                               f'({self._renderer}, {self._vote_method} voting)')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers, subscribe to the images, publish the active limit."""
        try:
            result = super().on_activate(state)  # enables the lifecycle publishers
            self.subscribe_images()
            self.publish_speed_limit(self._published_limit_kmh or 0)
        except Exception as err:  # noqa: BLE001 - rclpy would swallow it silently
            self.get_logger().error(f'activate failed: {type(err).__name__}: {err}')
            self.unsubscribe_images()
            return TransitionCallbackReturn.FAILURE
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking images; frames in flight are published; the pipeline stays."""
        try:
            self.unsubscribe_images()
            if not self.finish_frames_in_flight():
                self.get_logger().warn('frames in flight not finished on deactivate')
        except Exception as err:  # noqa: BLE001 - rclpy would swallow it silently
            self.get_logger().error(f'deactivate failed: {type(err).__name__}: {err}')
            return TransitionCallbackReturn.FAILURE
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the pipeline (GL context, banks) and the publishers."""
        return self._release_for('cleanup')

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything, from whichever state."""
        return self._release_for('shutdown')

    def _release_for(self, transition: str) -> TransitionCallbackReturn:
        """Release everything; a failure is logged and fails ``transition``."""
        try:
            self._release()
        except Exception as err:  # noqa: BLE001 - rclpy would swallow it silently
            self.get_logger().error(f'{transition} failed: {type(err).__name__}: {err}')
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """After a failed transition: release everything, go back to unconfigured."""
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def destroy_node(self) -> None:
        """Release everything (idempotent), then destroy the node."""
        self._release()
        LifecycleNode.destroy_node(self)

    def _release(self) -> None:
        self.unsubscribe_images()
        self.stop_pipeline()
        self.destroy_outputs(self.destroy_lifecycle_publisher)
        self._published_limit_kmh = None
