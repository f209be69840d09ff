"""Build script for the speed_sign_detector ament_python package.

Works both under ``colcon build`` on a ROS 2 Jazzy install and under ``pip install .``
on a machine without ROS, where rclpy and the message packages come from PyPI.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'speed_sign_detector'
# `speed_sign_eval fleet`: Ray Core, matplotlib for the summary picture. The test and
# bench extras include it, so `make test` / `make bench` install it.
FLEET_REQUIRES = ['ray>=2.10', 'matplotlib']

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        (f'share/{PACKAGE_NAME}/config', glob('config/*.yaml') + glob('config/*.xml')),
        (f'share/{PACKAGE_NAME}/launch', glob('launch/*.launch.py')),
    ],
    python_requires='>=3.11',
    install_requires=[
        'setuptools',
        'numpy>=1.24',
        'opencv-python-headless>=4.8',
        'moderngl>=5.8',
        'rosbags>=0.10',
        'PyYAML>=6',
        'tqdm>=4.64',
        'threadpoolctl>=3',
        # rclpy and the message packages as wheels from PyPI; on a ROS 2 Jazzy
        # install they are already on the path and colcon does not read this list.
        'ros-jazzy-rclpy>=7.1',
        'ros-jazzy-rmw-fastrtps-cpp>=8.4',
        'ros-jazzy-common-interfaces>=5.3',
    ],
    extras_require={
        'fleet': FLEET_REQUIRES,
        'test': ['pytest>=7', 'colcon-core', 'colcon-ros', *FLEET_REQUIRES],
        'bench': ['radsym', 'matplotlib', *FLEET_REQUIRES],
    },
    package_data={PACKAGE_NAME: ['recognition/data/*.npz']},
    zip_safe=False,
    maintainer='speed_sign_detector maintainers',
    maintainer_email='maintainers@speed-sign-detector.invalid',
    description='Real-time EU speed-limit sign detection and recognition (GPU RSD + FFT MACE).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'speed_sign_detector = speed_sign_detector.ros.entry_point:main',
            'speed_sign_eval = speed_sign_detector.tools.eval:main',
            'speed_sign_synth = speed_sign_detector.tools.synth:main',
            'speed_sign_replay = speed_sign_detector.tools.replay:main',
            'speed_sign_monitor = speed_sign_detector.tools.monitor:main',
            'speed_sign_train = speed_sign_detector.tools.train:main',
        ],
    },
)
