"""The ROS 2 node (plain, the default of ``ros2 run``): camera images in, candidates /
speed limit / debug image / diagnostics out.

Everything it does is in :class:`~speed_sign_detector.ros.detector_node_base.DetectorNodeBase`
(threads, topics, diagnostics); this class starts it all in its constructor. The managed
(lifecycle) variant is :mod:`speed_sign_detector.ros.lifecycle_node`; the executable's
command line is :mod:`speed_sign_detector.ros.entry_point`.

Topics (relative, remappable): in ``image`` (sensor_msgs/Image) and ``image/compressed``
(sensor_msgs/CompressedImage), both with sensor-data QoS (best effort, volatile, keep
last 5; overridable with ``qos_overrides./<topic>.subscription.*`` parameters); out
``candidates`` (sensor_msgs/PointCloud2), ``speed_limit`` (std_msgs/UInt16, reliable +
transient local, on change), ``debug_image`` (sensor_msgs/Image bgr8, only while
subscribed) and ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).

Run: ``ros2 run speed_sign_detector speed_sign_detector --ros-args --params-file
config/speed_sign_detector.yaml -r image:=/camera/image_raw``.
"""
from __future__ import annotations

from typing import Any

from rclpy.node import Node

from speed_sign_detector.ros.detector_node_base import DetectorNodeBase
from speed_sign_detector.ros.parameters import (
    NODE_NAME,
    READ_ONLY_PARAMETERS,
    default_parameter_file,
    parameter_descriptor,
)

__all__ = ['NODE_NAME', 'READ_ONLY_PARAMETERS', 'SpeedSignDetectorNode',
           'default_parameter_file', 'parameter_descriptor']


class SpeedSignDetectorNode(DetectorNodeBase, Node):
    """Detects and reads speed-limit signs in the images of one camera.

    Parameters: every field of :class:`~speed_sign_detector.config.PipelineConfig` as
    ``section.field`` (see ``config/speed_sign_detector.yaml``) plus
    :class:`~speed_sign_detector.config.NodeOptions`. Changes are validated (an invalid
    value or combination is rejected with the reason) and applied by the worker before
    its next frame.

    Raises (from the constructor):
        ConfigError: for invalid initial parameters.
        SpeedSignError: when the pipeline cannot be built (e.g. backend 'gl' without GL).
    """

    def __init__(self, node_name: str = NODE_NAME, **node_kwargs: Any) -> None:
        Node.__init__(self, node_name, **node_kwargs)
        try:
            self.init_detector()
            self.create_outputs(self.create_publisher)
            self.start_pipeline()
        except BaseException:
            self.stop_pipeline()
            Node.destroy_node(self)
            raise
        self.publish_speed_limit(0)
        self.subscribe_images()

    def destroy_node(self) -> None:
        """Stop the worker threads (the pipeline closes on its own thread), then the node."""
        self.stop_pipeline()
        Node.destroy_node(self)
