"""bag_io with real rosbags bags: the three formats, image topic choice, damaged bags."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from speed_sign_detector.bag_io import BagReader, BagWriter, header_stamp_ns
from speed_sign_detector.errors import BagError
from speed_sign_detector.image_conversion import message_to_gray
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.synth import write_drive

FRAMES = 6
CONFIG = DriveConfig(seed=4, duration_s=FRAMES / 10, fps=10, width_px=160, height_px=120,
                     focal_px=190.0)


def bag_path(tmp_path: Path, bag_format: str, name: str = 'drive') -> Path:
    return tmp_path / (f'{name}.bag' if bag_format == 'ros1' else name)


def storage_file(path: Path) -> Path:
    return path if path.is_file() else next(p for p in path.iterdir()
                                            if p.suffix in ('.mcap', '.db3'))


@pytest.mark.parametrize('compressed', [False, True], ids=['raw', 'compressed'])
@pytest.mark.parametrize('bag_format', ['mcap', 'sqlite3', 'ros1'])
def test_synthetic_drive_round_trips_through_every_format(tmp_path: Path, bag_format: str,
                                                          compressed: bool) -> None:
    drive = SyntheticDrive(CONFIG)
    path = bag_path(tmp_path, bag_format)
    write_drive(drive, path, bag_format, compressed)
    with BagReader(path) as bag:
        assert bag.is_ros2 == (bag_format != 'ros1')
        assert bag.salvage_reason is None
        topic = bag.image_topic()
        assert topic.count == FRAMES
        assert topic.msgtype.endswith('CompressedImage' if compressed else '/Image')
        items = list(bag.messages(topic.name))
    assert len(items) == FRAMES
    for index, item in enumerate(items):
        expected_ns = CONFIG.stamp_ns(index)
        assert item.log_time_ns == expected_ns
        assert header_stamp_ns(item.message, 0) == expected_ns
        gray = message_to_gray(item.message)
        assert gray.shape == (120, 160)
        reference = drive.frame(index).bgr.astype(np.float32) @ np.float32([0.114, 0.587,
                                                                            0.299])
        tolerance = 6.0 if compressed else 1.0
        assert np.abs(gray.astype(np.float32) - reference).mean() < tolerance


def write_topics(path: Path, bag_format: str, topics: dict[str, str]) -> None:
    with BagWriter(path, bag_format) as writer:
        for topic, msgtype in topics.items():
            writer.add_topic(topic, msgtype)
        image = writer.message_class('sensor_msgs/msg/Image')(
            header=writer.header(1_000_000_000, 'cam'), height=2, width=2, encoding='mono8',
            is_bigendian=0, step=2, data=np.zeros(4, np.uint8))
        for topic, msgtype in topics.items():
            if msgtype == 'sensor_msgs/msg/Image':
                writer.write(topic, 1_000_000_000, image)
            else:
                writer.write(topic, 1_000_000_000, writer.message_class(msgtype)(data=7))


@pytest.mark.parametrize('bag_format', ['mcap', 'ros1'])
def test_image_topic_choice_and_errors(tmp_path: Path, bag_format: str) -> None:
    path = bag_path(tmp_path, bag_format)
    write_topics(path, bag_format, {'/left/image': 'sensor_msgs/msg/Image',
                                    '/right/image': 'sensor_msgs/msg/Image',
                                    '/speed': 'std_msgs/msg/UInt16'})
    with BagReader(path) as bag:
        with pytest.raises(BagError, match='2 image topics.*--topic.*/left/image, /right/image'):
            bag.image_topic()
        assert bag.image_topic('/right/image').name == '/right/image'
        with pytest.raises(BagError, match="no topic '/front'.*/speed"):
            bag.image_topic('/front')
        with pytest.raises(BagError, match='UInt16, not a sensor_msgs/Image'):
            bag.image_topic('/speed')


def test_bag_without_image_topic_names_its_topics(tmp_path: Path) -> None:
    path = tmp_path / 'no_images'
    write_topics(path, 'sqlite3', {'/speed': 'std_msgs/msg/UInt16'})
    with BagReader(path) as bag, pytest.raises(
            BagError, match=r'no sensor_msgs/Image or CompressedImage topic.*/speed '
                            r'\(std_msgs/msg/UInt16, 1 messages\)'):
        bag.image_topic()


@pytest.mark.parametrize('bag_format', ['mcap', 'ros1'])
def test_truncated_bag_yields_complete_messages_then_bag_error(tmp_path: Path,
                                                               bag_format: str) -> None:
    path = bag_path(tmp_path, bag_format)
    write_drive(SyntheticDrive(CONFIG), path, bag_format)
    data_file = storage_file(path)
    size = data_file.stat().st_size
    with data_file.open('r+b') as stream:
        stream.truncate(size * 2 // 3)
    received = []
    with BagReader(path) as bag:
        assert bag.salvage_reason
        topic = bag.image_topic()
        with pytest.raises(BagError, match='truncated'):
            for item in bag.messages(topic.name):
                received.append(item)
    assert 1 <= len(received) < FRAMES
    for index, item in enumerate(received):
        assert item.log_time_ns == CONFIG.stamp_ns(index)
        assert message_to_gray(item.message).shape == (120, 160)


def test_damaged_sqlite3_bag_and_missing_paths_are_bag_errors(tmp_path: Path) -> None:
    path = tmp_path / 'drive'
    write_drive(SyntheticDrive(CONFIG), path, 'sqlite3')
    database = storage_file(path)
    with database.open('r+b') as stream:
        stream.truncate(database.stat().st_size // 2)
    with pytest.raises(BagError, match='drive'):
        with BagReader(path) as bag:
            list(bag.messages(bag.image_topic().name))
    with pytest.raises(BagError, match='does not exist'):
        BagReader(tmp_path / 'absent')
    not_a_bag = tmp_path / 'notes.txt'
    not_a_bag.write_text('hello')
    with pytest.raises(BagError, match='cannot open bag'):
        BagReader(not_a_bag)


def test_writer_refuses_existing_path_and_unknown_format(tmp_path: Path) -> None:
    (tmp_path / 'taken').mkdir()
    with pytest.raises(BagError, match='exists already'):
        BagWriter(tmp_path / 'taken')
    with pytest.raises(BagError, match='unknown bag format'):
        BagWriter(tmp_path / 'x', 'rosbag3')


def test_latched_topic_keeps_transient_local_qos(tmp_path: Path) -> None:
    path = tmp_path / 'latched'
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic('/speed_limit', 'std_msgs/msg/UInt16', latched=True)
        writer.write('/speed_limit', 5, writer.message_class('std_msgs/msg/UInt16')(data=50))
    metadata = (path / 'metadata.yaml').read_text()
    assert 'durability: 1' in metadata or 'transient_local' in metadata.lower()
    with BagReader(path) as bag:
        (item,) = bag.messages('/speed_limit')
    assert item.message.data == 50


def test_bags_named_against_their_format_are_read_by_content(tmp_path: Path) -> None:
    """rosbags tells ROS 1 from ROS 2 by the name (.bag); BagReader by the content: a
    ROS 1 bag without .bag (as speed_sign_synth once wrote them), a ROS 2 folder named
    *.bag, and a truncated ROS 1 bag without .bag (salvage mode)."""
    frames = list(SyntheticDrive(CONFIG))
    ros1 = tmp_path / 'ros1_drive.bag'
    write_drive(frames, ros1, 'ros1')
    unnamed = ros1.rename(tmp_path / 'ros1_drive')
    ros2 = tmp_path / 'ros2_drive'
    write_drive(frames, ros2, 'mcap')
    named_bag = ros2.rename(tmp_path / 'ros2_drive.bag')
    for path, is_ros2 in ((unnamed, False), (named_bag, True)):
        with BagReader(path) as bag:
            assert bag.is_ros2 == is_ros2 and bag.salvage_reason is None
            items = list(bag.messages(bag.image_topic().name))
        assert [header_stamp_ns(item.message, 0) for item in items] == [
            CONFIG.stamp_ns(index) for index in range(FRAMES)]
        reference = frames[2].bgr.astype(np.float32) @ np.float32([0.114, 0.587, 0.299])
        assert np.abs(message_to_gray(items[2].message) - reference).mean() < 1.0
    cut = tmp_path / 'ros1_cut'
    cut.write_bytes(unnamed.read_bytes()[:unnamed.stat().st_size * 2 // 3])
    with BagReader(cut) as bag:
        assert bag.salvage_reason is not None and not bag.is_ros2
        read = []
        with pytest.raises(BagError, match='truncated'):
            for item in bag.messages(bag.image_topic().name):
                read.append(item)
    assert 0 < len(read) < FRAMES
