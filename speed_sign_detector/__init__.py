"""Detection and recognition of EU speed-limit signs in camera images.

The maths (``detection``, ``recognition``, ``tracking``, ``pipeline``) is plain Python
over numpy arrays and imports nothing from ROS; ``ros`` holds the rclpy node and
``tools`` the command-line programs (evaluation, bag replay, synthetic drives, monitor).
"""
from speed_sign_detector.errors import SpeedSignError

__all__ = ['SpeedSignError']
__version__ = '0.1.0'
