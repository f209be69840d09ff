"""Launch the speed_sign_detector node with the installed parameter file.

Usage:
    ros2 launch speed_sign_detector speed_sign_detector.launch.py \
        image:=/camera/image_raw [compressed_image:=/camera/image_raw/compressed] \
        [params_file:=/path/to/my.yaml] [namespace:=front] [log_level:=info] \
        [lifecycle:=true]

With ``lifecycle:=true`` the node is the managed one (``--lifecycle``): it waits for
the configure and activate transitions from the stack's lifecycle manager (or
``ros2 lifecycle set /speed_sign_detector configure``).
"""
from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

PACKAGE = 'speed_sign_detector'


def generate_launch_description() -> LaunchDescription:
    """One node (plain or managed), its parameters from ``share/speed_sign_detector/config``,
    topics remapped."""
    default_params = os.path.join(get_package_share_directory(PACKAGE), 'config',
                                  'speed_sign_detector.yaml')
    arguments = [
        DeclareLaunchArgument('image', default_value='image',
                              description='sensor_msgs/Image topic of the camera'),
        DeclareLaunchArgument('compressed_image', default_value='image/compressed',
                              description='sensor_msgs/CompressedImage topic (JPEG/PNG)'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS 2 parameter file of the node'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node and its topics'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='logging level (debug, info, warn, error)'),
        DeclareLaunchArgument('lifecycle', default_value='false',
                              description='run the managed (lifecycle) node'),
    ]
    common = dict(
        package=PACKAGE,
        executable='speed_sign_detector',
        name='speed_sign_detector',
        namespace=LaunchConfiguration('namespace'),
        parameters=[LaunchConfiguration('params_file')],
        remappings=[('image', LaunchConfiguration('image')),
                    ('image/compressed', LaunchConfiguration('compressed_image'))],
        output='screen',
        emulate_tty=True,
    )
    log_level = ['--ros-args', '--log-level', LaunchConfiguration('log_level')]
    plain = Node(arguments=log_level,
                 condition=UnlessCondition(LaunchConfiguration('lifecycle')), **common)
    managed = LifecycleNode(arguments=['--lifecycle', *log_level],
                            condition=IfCondition(LaunchConfiguration('lifecycle')), **common)
    return LaunchDescription([*arguments, plain, managed])
