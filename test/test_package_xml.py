"""Every dependency key of package.xml must resolve with rosdep on ROS 2 Jazzy.

`rosdep install --from-paths src` stops at the first key it does not know (it did on
`python3-moderngl-pip`). The keys below were looked up by hand, with where each one is
defined; a key added to package.xml must be verified the same way and added here.
"""
from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

PACKAGE_XML = Path(__file__).resolve().parents[1] / 'package.xml'

#: rosdep keys verified to exist for Jazzy, and where they are defined.
VERIFIED_ROSDEP_KEYS: dict[str, str] = {
    # ros/rosdistro rosdep/python.yaml (system packages on Ubuntu 24.04 'noble')
    'python3-numpy': 'ros/rosdistro rosdep/python.yaml: ubuntu [python3-numpy]',
    'python3-opencv': 'ros/rosdistro rosdep/python.yaml: ubuntu [python3-opencv]',
    'python3-yaml': 'ros/rosdistro rosdep/python.yaml: ubuntu [python3-yaml]',
    'python3-tqdm': "ros/rosdistro rosdep/python.yaml: ubuntu '*' [python3-tqdm]",
    'python3-pytest': 'ros/rosdistro rosdep/python.yaml: ubuntu [python3-pytest]',
    # ros/rosdistro rosdep/python.yaml, pip rule (added by ros/rosdistro PR #37795)
    'python3-rosbags-pip': 'ros/rosdistro rosdep/python.yaml: ubuntu pip [rosbags] '
                           '(ros/rosdistro#37795, merged 2023-06)',
    # ROS packages: keys are the package names released in jazzy/distribution.yaml
    'sensor_msgs': 'ros/rosdistro jazzy/distribution.yaml: common_interfaces',
    'std_msgs': 'ros/rosdistro jazzy/distribution.yaml: common_interfaces',
    'diagnostic_msgs': 'ros/rosdistro jazzy/distribution.yaml: common_interfaces',
    'rclpy': 'ros/rosdistro jazzy/distribution.yaml: rclpy (ROS 2 core)',
    'rcl_interfaces': 'ros/rosdistro jazzy/distribution.yaml: rcl_interfaces (core)',
    'lifecycle_msgs': 'ros/rosdistro jazzy/distribution.yaml: rcl_interfaces (core)',
    'launch': 'ros/rosdistro jazzy/distribution.yaml: launch (ROS 2 core)',
    'launch_ros': 'ros/rosdistro jazzy/distribution.yaml: launch_ros (ROS 2 core)',
    'ament_index_python': 'ros/rosdistro jazzy/distribution.yaml: ament_index (core)',
}
#: Looked up and NOT defined in ros/rosdistro rosdep/*.yaml: must not be declared.
KNOWN_MISSING_KEYS = frozenset({'python3-moderngl-pip', 'python3-moderngl',
                                'python3-glcontext-pip'})
DEPEND_TAGS = ('depend', 'build_depend', 'build_export_depend', 'exec_depend',
               'test_depend', 'buildtool_depend', 'doc_depend')


def declared_keys() -> list[str]:
    root = ElementTree.parse(PACKAGE_XML).getroot()
    return [element.text.strip() for tag in DEPEND_TAGS for element in root.iter(tag)]


def test_every_dependency_key_is_a_verified_rosdep_key() -> None:
    keys = declared_keys()
    assert keys, 'package.xml declares no dependency'
    unknown = [key for key in keys if key not in VERIFIED_ROSDEP_KEYS]
    assert not unknown, (f'package.xml declares keys not verified for Jazzy: {unknown}; '
                         'look each up in ros/rosdistro (rosdep/base.yaml, rosdep/python.yaml '
                         'or jazzy/distribution.yaml) and add it to VERIFIED_ROSDEP_KEYS')
    assert not KNOWN_MISSING_KEYS & set(keys)


def test_the_python_dependencies_of_setup_py_are_declared_or_documented() -> None:
    """setup.py's runtime requirements are rosdep keys, except moderngl (README)."""
    keys = set(declared_keys())
    expected = {'numpy': 'python3-numpy', 'opencv-python-headless': 'python3-opencv',
                'rosbags': 'python3-rosbags-pip', 'PyYAML': 'python3-yaml',
                'tqdm': 'python3-tqdm'}
    setup_text = (PACKAGE_XML.parent / 'setup.py').read_text()
    for requirement, key in expected.items():
        assert f"'{requirement}" in setup_text, requirement
        assert key in keys, f'{requirement} is required by setup.py but {key} not declared'
    readme = (PACKAGE_XML.parent / 'README.md').read_text()
    assert 'moderngl' in readme and 'no rosdep key' in readme
