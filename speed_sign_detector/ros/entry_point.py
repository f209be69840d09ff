"""The ``speed_sign_detector`` executable: command line, start-up checks, clean stop.

* ``--help`` prints the usage (ROS arguments, topics, where the parameters are
  described) and exits 0; an unknown option is an error (exit 2), as is a
  ``--params-file`` that cannot be read.
* Without rclpy (or a message package) it says what to install, in one line (exit 1).
* SIGINT and SIGTERM stop the spin loop; the worker threads are stopped and the node
  destroyed *before* the ROS context shuts down (rclpy's own signal handlers would shut
  the context down first, under a thread that may be publishing).
* ``--lifecycle`` runs the managed node
  (:class:`~speed_sign_detector.ros.lifecycle_node.ManagedSpeedSignDetectorNode`).

This module imports no ROS package at import time.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType

from speed_sign_detector.blas_threads import use_one_blas_thread

PROGRAM = 'speed_sign_detector'
#: What to install when rclpy or a message package is missing.
ROS_INSTALL_HINT = ('source /opt/ros/jazzy/setup.bash (ROS 2 Jazzy), or in a virtualenv: '
                    'pip install ros-jazzy-rclpy ros-jazzy-rmw-fastrtps-cpp '
                    'ros-jazzy-common-interfaces')
#: Seconds the spin loop waits for work before it looks at the stop flag again.
SPIN_PERIOD_S = 0.1

USAGE_EPILOG = """\
ROS arguments (after --ros-args):
  -r image:=/camera/image_raw            remap the raw image topic
  -r image/compressed:=/camera/image_raw/compressed
  -r __ns:=/front                        namespace of the node and its topics
  -p detector.min_radius_px:=8           set one parameter
  --params-file FILE                     load parameters from a ROS 2 YAML file
  --log-level debug                      logging level

Topics (relative names, remappable):
  in   image (sensor_msgs/Image), image/compressed (sensor_msgs/CompressedImage):
       sensor-data QoS (best effort, volatile, keep last 5)
  out  candidates (sensor_msgs/PointCloud2), speed_limit (std_msgs/UInt16, latched),
       debug_image (sensor_msgs/Image), /diagnostics (diagnostic_msgs/DiagnosticArray)

Parameters: every one, with its description, default and range, is in the installed
share/speed_sign_detector/config/speed_sign_detector.yaml; `ros2 param describe
/speed_sign_detector <name>` shows them on a running node. README: "Topics, parameters,
diagnostics".

Raw images over DDS: export FASTRTPS_DEFAULT_PROFILES_FILE=<share>/config/
fastdds_large_images.xml for the camera driver and this node (see the README).

Examples:
  speed_sign_detector --ros-args -r image:=/camera/image_raw
  speed_sign_detector --lifecycle --ros-args --params-file my.yaml
"""


def build_parser() -> argparse.ArgumentParser:
    """Options of the executable itself (ROS arguments follow ``--ros-args``)."""
    parser = argparse.ArgumentParser(
        prog=PROGRAM, usage=f'{PROGRAM} [-h] [--lifecycle] [--ros-args ROS_ARGUMENTS ...]',
        description='ROS 2 node that detects and reads EU speed-limit signs in camera '
        'images (GPU radial-symmetry voting, FFT template recognition).',
        epilog=USAGE_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--lifecycle', action='store_true',
                        help='run as a managed (lifecycle) node: it waits for the '
                        'configure and activate transitions (ros2 lifecycle set)')
    return parser


def split_ros_arguments(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(own arguments, ROS arguments): ROS ones run from each ``--ros-args`` to the
    next ``--`` or the end."""
    own: list[str] = []
    ros: list[str] = []
    inside = False
    for argument in argv:
        if argument == '--ros-args':
            inside = True
            ros.append(argument)
        elif inside and argument == '--':
            inside = False
            ros.append(argument)
        else:
            (ros if inside else own).append(argument)
    return own, ros


def unreadable_parameter_files(ros_arguments: Sequence[str]) -> list[str]:
    """One problem per ``--params-file`` argument that names no readable file."""
    problems = []
    for index, argument in enumerate(ros_arguments):
        if argument != '--params-file':
            continue
        if index + 1 >= len(ros_arguments) or ros_arguments[index + 1].startswith('-'):
            problems.append('--params-file needs a file name')
            continue
        path = ros_arguments[index + 1]
        if not os.path.isfile(path):
            problems.append(f'parameter file {path} does not exist')
        elif not os.access(path, os.R_OK):
            problems.append(f'parameter file {path} is not readable')
    return problems


def error(message: str, status: int) -> int:
    """Print ``speed_sign_detector: error: message`` on stderr; return ``status``."""
    print(f'{PROGRAM}: error: {message}', file=sys.stderr)
    return status


def missing_ros_message(program: str, err: ImportError) -> str:
    """One line saying which ROS module is missing and how to get it."""
    name = getattr(err, 'name', None) or str(err)
    return (f'{program}: error: the ROS 2 Python package {name!r} cannot be imported; '
            f'{ROS_INSTALL_HINT}')


def main(argv: Sequence[str] | None = None) -> int:
    """Run the node until SIGINT or SIGTERM; returns the exit status."""
    use_one_blas_thread()   # before numpy is loaded (by the node, below)
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_arguments = split_ros_arguments(argv)
    args = build_parser().parse_args(own)  # --help exits 0, an unknown option 2
    problems = unreadable_parameter_files(ros_arguments)
    if problems:
        return error('; '.join(problems), 2)
    try:
        import rclpy
        from rclpy.exceptions import ParameterException
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from speed_sign_detector.ros.lifecycle_node import ManagedSpeedSignDetectorNode
        from speed_sign_detector.ros.node import SpeedSignDetectorNode
    except ImportError as err:
        print(missing_ros_message(PROGRAM, err), file=sys.stderr)
        return 1
    from speed_sign_detector.errors import SpeedSignError

    try:
        rclpy.init(args=[PROGRAM, *ros_arguments],
                   signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - rclpy raises RCLError / RuntimeError
        return error(f'cannot start: invalid ROS arguments: {_first_line(err)}', 2)
    stop = threading.Event()
    previous_handlers = _install_stop_handlers(stop)
    node = None
    executor = SingleThreadedExecutor()
    try:
        node_class = ManagedSpeedSignDetectorNode if args.lifecycle else SpeedSignDetectorNode
        try:
            node = node_class()
        except (SpeedSignError, ParameterException, ValueError) as err:
            rclpy.logging.get_logger(PROGRAM).fatal(f'cannot start: {_first_line(err)}')
            return 1
        executor.add_node(node)
        while not stop.is_set():
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()  # stops the worker threads first
        executor.shutdown()
        rclpy.try_shutdown()
        for number, handler in previous_handlers.items():
            signal.signal(number, handler)
    return 0


def _install_stop_handlers(stop: threading.Event) -> dict[int, object]:
    def request_stop(number: int, frame: FrameType | None) -> None:
        stop.set()
    previous = {}
    for number in (signal.SIGINT, signal.SIGTERM):
        previous[number] = signal.signal(number, request_stop)
    return previous


def _first_line(err: BaseException) -> str:
    text = str(err).strip() or type(err).__name__
    return text.splitlines()[0]


if __name__ == '__main__':
    sys.exit(main())
