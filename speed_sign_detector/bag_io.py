"""Reading and writing bags with rosbags: ROS 2 (MCAP, sqlite3) and ROS 1.

Reading (:class:`BagReader`):

- Opens a ROS 2 bag directory (``metadata.yaml`` + storage files), a bare ``.mcap`` or
  ``.db3`` file, or a ROS 1 bag file with rosbags' ``AnyReader``. A ROS 1 bag is
  recognized by its content (``#ROSBAG V2.0``), also when its name lacks ``.bag``.
- Finds the image topic (``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``):
  :meth:`BagReader.image_topic` picks the only one, or the one asked for, and otherwise
  raises :class:`BagError` listing the candidates.
- Truncated recordings (a recorder killed before it closed the file): an MCAP file
  without its footer, or a ROS 1 bag without its index, cannot be opened by rosbags.
  :class:`BagReader` then falls back to scanning the file record by record
  ("salvage mode", :mod:`speed_sign_detector.bag_salvage`), yields every complete
  message, and raises :class:`BagError` once it reaches the cut, so callers can report
  what came before. The same happens when
  a storage error (e.g. a damaged sqlite3 page) interrupts iteration.

Writing (:class:`BagWriter`): ROS 2 MCAP or sqlite3 bags and ROS 1 bags, with message
classes from the matching rosbags typestore (``ROS2_JAZZY`` or ``ROS1_NOETIC``) and
:meth:`BagWriter.header` to build a ``std_msgs/Header`` for either.

All failures are raised as :class:`speed_sign_detector.errors.BagError` whose message
names the bag and the problem.
"""
from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag1 import WriterError as Ros1WriterError
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.rosbag2 import WriterError as Ros2WriterError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from speed_sign_detector.bag_salvage import (
    ROS1_MAGIC,
    SalvagedBag,
    normalize_msgtype,
    scan_file,
)
from speed_sign_detector.errors import BagError

LOGGER = logging.getLogger(__name__)

#: Bag formats :class:`BagWriter` can write.
BAG_FORMATS: tuple[str, ...] = ('mcap', 'sqlite3', 'ros1')
IMAGE_MSGTYPE = 'sensor_msgs/msg/Image'
COMPRESSED_IMAGE_MSGTYPE = 'sensor_msgs/msg/CompressedImage'
#: Message types an image topic may have.
IMAGE_MSGTYPES: tuple[str, ...] = (IMAGE_MSGTYPE, COMPRESSED_IMAGE_MSGTYPE)

def latched_qos() -> Qos:
    """QoS of a latched topic (reliable, transient local, depth 1), e.g. ``speed_limit``."""
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
               QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)


def is_ros1_bag_file(path: Path) -> bool:
    """True when ``path`` is a file that starts like a ROS 1 bag, whatever its name."""
    try:
        with path.open('rb') as stream:
            return stream.read(len(ROS1_MAGIC)) == ROS1_MAGIC
    except OSError:
        return False


@dataclass(frozen=True)
class TopicSummary:
    """A topic of a bag.

    Attributes:
        name: topic name.
        msgtype: message type, ROS 2 style (``sensor_msgs/msg/Image``).
        count: number of messages the bag's index declares (-1 when unknown, e.g. in
            salvage mode).
    """

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class BagMessage:
    """One message read from a bag.

    Attributes:
        topic: topic name.
        msgtype: message type, ROS 2 style.
        log_time_ns: the bag's record time, nanoseconds since the epoch.
        raw: the serialized bytes as stored (CDR for ROS 2, ROS 1 serialization for ROS 1).
        message: the deserialized rosbags message.
    """

    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes
    message: Any


def header_stamp_ns(message: Any, fallback_ns: int) -> int:
    """A message's ``header.stamp`` in nanoseconds, or ``fallback_ns`` when it is zero
    or the message has no header."""
    header = getattr(message, 'header', None)
    stamp = getattr(header, 'stamp', None)
    if stamp is None:
        return fallback_ns
    sec = getattr(stamp, 'sec', getattr(stamp, 'secs', 0))
    nanosec = getattr(stamp, 'nanosec', getattr(stamp, 'nsecs', 0))
    value = int(sec) * 1_000_000_000 + int(nanosec)
    return value if value > 0 else fallback_ns


# --------------------------------------------------------------------------- reading
class BagReader:
    """Read a bag's topics and messages; use as a context manager.

    Args:
        path: a ROS 2 bag directory, a ``.mcap`` / ``.db3`` file, or a ROS 1 ``.bag``.

    Raises:
        BagError: the path is missing, not a bag, or unreadable (the message says why).

    Example:
        >>> with BagReader('drive_mcap') as bag:                 # doctest: +SKIP
        ...     topic = bag.image_topic()
        ...     for item in bag.messages(topic.name):
        ...         print(item.log_time_ns, item.message.header.stamp)
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._reader: AnyReader | None = None
        self._salvage: SalvagedBag | None = None
        self._alias_folder: tempfile.TemporaryDirectory[str] | None = None
        if not self.path.exists():
            raise BagError(f'bag {self.path} does not exist')
        try:
            reader = AnyReader([self._reader_path()],
                               default_typestore=get_typestore(Stores.ROS2_JAZZY))
            reader.open()
            self._reader = reader
        except (AnyReaderError, FileNotFoundError, OSError, ValueError, KeyError) as err:
            salvage_file = self._storage_file()
            if salvage_file is None:
                raise BagError(f'cannot open bag {self.path}: {err}') from err
            self._salvage = scan_file(salvage_file, reason=str(err))
            LOGGER.warning('bag %s could not be opened normally (%s); recovered %d complete '
                           'messages by scanning %s', self.path, err,
                           len(self._salvage.records), salvage_file.name)

    # ------------------------------------------------------------------ info
    @property
    def is_ros2(self) -> bool:
        """True for a ROS 2 bag (CDR messages), False for ROS 1."""
        if self._salvage is not None:
            return self._salvage.is_ros2
        assert self._reader is not None
        return bool(self._reader.is2)

    @property
    def salvage_reason(self) -> str | None:
        """Why the bag is read in salvage mode (truncated or unindexed), else None."""
        return self._salvage.reason if self._salvage is not None else None

    @property
    def typestore(self) -> Typestore:
        """The typestore holding the bag's message types."""
        if self._salvage is not None:
            return self._salvage.typestore
        assert self._reader is not None
        return self._reader.typestore

    def topics(self) -> dict[str, TopicSummary]:
        """Every topic of the bag by name."""
        if self._salvage is not None:
            summaries: dict[str, TopicSummary] = {}
            for connection in self._salvage.connections.values():
                old = summaries.get(connection.topic)
                count = connection.count + (old.count if old else 0)
                summaries[connection.topic] = TopicSummary(connection.topic,
                                                           connection.msgtype, count)
            return summaries
        assert self._reader is not None
        summaries = {}
        for connection in self._reader.connections:
            old = summaries.get(connection.topic)
            count = max(connection.msgcount, 0) + (old.count if old else 0)
            summaries[connection.topic] = TopicSummary(
                connection.topic, normalize_msgtype(connection.msgtype), count)
        return summaries

    def image_topic(self, requested: str | None = None) -> TopicSummary:
        """The image topic to read: ``requested``, or the only Image/CompressedImage topic.

        Raises:
            BagError: the requested topic is absent or not an image topic; there is no
                image topic; or several and none was requested (the message lists them).
        """
        topics = self.topics()
        images = {name: topic for name, topic in topics.items()
                  if topic.msgtype in IMAGE_MSGTYPES}
        listing = ', '.join(f'{name} ({topic.msgtype}, {topic.count} messages)'
                            for name, topic in sorted(topics.items())) or 'none'
        if requested is not None:
            if requested not in topics:
                raise BagError(f'bag {self.path} has no topic {requested!r}; its topics: '
                               f'{listing}')
            if requested not in images:
                raise BagError(f'topic {requested!r} of bag {self.path} is a '
                               f'{topics[requested].msgtype}, not a sensor_msgs/Image or '
                               f'sensor_msgs/CompressedImage')
            return images[requested]
        if not images:
            raise BagError(f'bag {self.path} has no sensor_msgs/Image or CompressedImage '
                           f'topic; its topics: {listing}')
        if len(images) > 1:
            raise BagError(f'bag {self.path} has {len(images)} image topics; choose one with '
                           f'--topic: {", ".join(sorted(images))}')
        return next(iter(images.values()))

    # ------------------------------------------------------------------ messages
    def messages(self, topic: str, deserialize: bool = True) -> Iterator[BagMessage]:
        """Messages of one topic in record-time order.

        Args:
            topic: the topic name.
            deserialize: build the rosbags message (``message`` is None otherwise).

        Raises:
            BagError: when the bag turns out to be truncated or damaged at some point
                (after every message before that point was yielded), or a message does
                not deserialize.
        """
        if self._salvage is not None:
            yield from self._salvage_messages(topic, deserialize)
            return
        reader = self._reader
        assert reader is not None
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            raise BagError(f'bag {self.path} has no topic {topic!r}')
        count = 0
        iterator = reader.messages(connections=connections)
        while True:
            try:
                connection, log_time_ns, raw = next(iterator)
            except StopIteration:
                return
            except Exception as err:  # noqa: BLE001 - storage errors of any kind
                raise BagError(f'bag {self.path} is damaged or truncated: reading topic '
                               f'{topic} failed after {count} messages: '
                               f'{type(err).__name__}: {err}') from err
            message = None
            if deserialize:
                try:
                    message = reader.deserialize(raw, connection.msgtype)
                except Exception as err:  # noqa: BLE001 - serde errors of any kind
                    raise BagError(f'bag {self.path}: message {count} of {topic} '
                                   f'({connection.msgtype}) does not deserialize: {err}'
                                   ) from err
            count += 1
            yield BagMessage(topic, normalize_msgtype(connection.msgtype), log_time_ns,
                             bytes(raw), message)

    def _salvage_messages(self, topic: str, deserialize: bool) -> Iterator[BagMessage]:
        salvage = self._salvage
        assert salvage is not None
        wanted = {cid: conn for cid, conn in salvage.connections.items() if conn.topic == topic}
        if not wanted:
            raise BagError(f'bag {self.path} has no topic {topic!r} (in the part that could '
                           f'be read: {salvage.reason})')
        count = 0
        for connection_id, log_time_ns, raw in salvage.records:
            connection = wanted.get(connection_id)
            if connection is None:
                continue
            message = None
            if deserialize:
                try:
                    message = (salvage.typestore.deserialize_cdr(raw, connection.msgtype)
                               if salvage.is_ros2 else
                               salvage.typestore.deserialize_ros1(raw, connection.msgtype))
                except Exception as err:  # noqa: BLE001 - serde errors of any kind
                    raise BagError(f'bag {self.path}: message {count} of {topic} does not '
                                   f'deserialize: {err}') from err
            count += 1
            yield BagMessage(topic, connection.msgtype, log_time_ns, raw, message)
        raise BagError(f'bag {self.path} is truncated ({salvage.cut or salvage.reason}); '
                       f'read {count} complete messages of {topic} before the cut')

    # ------------------------------------------------------------------ helpers
    def _reader_path(self) -> Path:
        """What AnyReader should open: the directory, or the storage file of a directory
        that lacks metadata.yaml (a recording that was never closed). rosbags takes a
        path ending in ``.bag`` for ROS 1 and any other for ROS 2, so a ROS 1 file named
        otherwise, or a ROS 2 folder named ``*.bag``, is opened through an alias."""
        if self.path.is_file() and self.path.suffix != '.bag' and is_ros1_bag_file(self.path):
            return self._alias(f'{self.path.name}.bag')
        if self.path.is_dir():
            if not (self.path / 'metadata.yaml').exists():
                storage = self._storage_file()
                if storage is not None:
                    return storage
                raise BagError(f'{self.path} is a directory without metadata.yaml or a '
                               f'.mcap/.db3 file: not a ROS 2 bag')
            if self.path.suffix == '.bag':
                return self._alias(f'{self.path.stem}_ros2')
        return self.path

    def _alias(self, name: str) -> Path:
        """A symbolic link called ``name`` to this bag, in a private temporary folder."""
        self._alias_folder = tempfile.TemporaryDirectory(prefix='speed_sign_bag_')
        alias = Path(self._alias_folder.name) / name
        try:
            os.symlink(self.path.resolve(), alias)
        except OSError as err:
            raise BagError(f'cannot open {self.path}: its name does not match its format '
                           f'(ROS 1 bags end in .bag, ROS 2 bag folders do not) and no alias '
                           f'could be made ({err}); rename it') from err
        return alias

    def _storage_file(self) -> Path | None:
        """The single .mcap or .bag file a salvage scan can read, if any."""
        if self.path.is_file():
            return (self.path if self.path.suffix in ('.mcap', '.bag', '.db3')
                    or is_ros1_bag_file(self.path) else None)
        files = sorted(self.path.glob('*.mcap')) + sorted(self.path.glob('*.db3'))
        return files[0] if len(files) == 1 else None

    def close(self) -> None:
        """Close the bag."""
        if self._reader is not None:
            self._reader.close()
            self._reader = None
        if self._alias_folder is not None:
            self._alias_folder.cleanup()
            self._alias_folder = None

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


# --------------------------------------------------------------------------- writing
class BagWriter:
    """Write a bag: ROS 2 MCAP or sqlite3, or ROS 1; use as a context manager.

    Build messages with :meth:`message_class` / :meth:`header` (the typestore of the
    format: ROS 2 Jazzy or ROS 1 Noetic), add topics with :meth:`add_topic`, then
    :meth:`write`. The bag is closed (and usable) even when the ``with`` block raises,
    so whatever was written before an error is kept.

    Args:
        path: the bag to create: a directory for ROS 2, a ``.bag`` file for ROS 1.
        bag_format: one of :data:`BAG_FORMATS`.

    Raises:
        BagError: unknown format, or the path exists already.
    """

    def __init__(self, path: str | Path, bag_format: str = 'mcap') -> None:
        if bag_format not in BAG_FORMATS:
            raise BagError(f'unknown bag format {bag_format!r}; choose one of '
                           f'{", ".join(BAG_FORMATS)}')
        self.path = Path(path)
        self.bag_format = bag_format
        if self.path.exists():
            raise BagError(f'{self.path} exists already; remove it or choose another output')
        self.typestore = get_typestore(Stores.ROS1_NOETIC if bag_format == 'ros1'
                                       else Stores.ROS2_JAZZY)
        try:
            if bag_format == 'ros1':
                self._writer: Ros1Writer | Ros2Writer = Ros1Writer(self.path)
            else:
                plugin = StoragePlugin.MCAP if bag_format == 'mcap' else StoragePlugin.SQLITE3
                self._writer = Ros2Writer(self.path, version=Ros2Writer.VERSION_LATEST,
                                          storage_plugin=plugin)
            self._writer.open()
        except (Ros1WriterError, Ros2WriterError, OSError) as err:
            raise BagError(f'cannot create bag {self.path}: {err}') from err
        self._connections: dict[str, Any] = {}
        self._seq = 0
        self._closed = False

    @property
    def is_ros2(self) -> bool:
        """True when writing ROS 2 (CDR) messages."""
        return self.bag_format != 'ros1'

    def message_class(self, msgtype: str) -> type:
        """The typestore class of a message type (``sensor_msgs/msg/Image``)."""
        return self.typestore.types[msgtype]

    def header(self, stamp_ns: int, frame_id: str = '') -> Any:
        """A ``std_msgs/Header`` for this format (ROS 1 headers carry a sequence number)."""
        types = self.typestore.types
        stamp = types['builtin_interfaces/msg/Time'](sec=stamp_ns // 1_000_000_000,
                                                     nanosec=stamp_ns % 1_000_000_000)
        if self.is_ros2:
            return types['std_msgs/msg/Header'](stamp=stamp, frame_id=frame_id)
        self._seq += 1
        return types['std_msgs/msg/Header'](seq=self._seq, stamp=stamp, frame_id=frame_id)

    def add_topic(self, topic: str, msgtype: str, latched: bool = False) -> None:
        """Declare a topic; ``latched`` gives it transient-local QoS (ROS 1: latching)."""
        if topic in self._connections:
            raise BagError(f'topic {topic} was added to {self.path} twice')
        try:
            if isinstance(self._writer, Ros1Writer):
                connection = self._writer.add_connection(
                    topic, msgtype, typestore=self.typestore, latching=1 if latched else None)
            else:
                connection = self._writer.add_connection(
                    topic, msgtype, typestore=self.typestore,
                    offered_qos_profiles=[latched_qos()] if latched else [])
        except (Ros1WriterError, Ros2WriterError, KeyError) as err:
            raise BagError(f'cannot add topic {topic} ({msgtype}) to {self.path}: {err}'
                           ) from err
        self._connections[topic] = connection

    def write(self, topic: str, log_time_ns: int, message: Any) -> None:
        """Serialize and write one message of a topic added before."""
        connection = self._connections.get(topic)
        if connection is None:
            raise BagError(f'topic {topic} was not added to {self.path}')
        try:
            if self.is_ros2:
                data = self.typestore.serialize_cdr(message, connection.msgtype)
            else:
                data = self.typestore.serialize_ros1(message, connection.msgtype)
            self._writer.write(connection, int(log_time_ns), data)
        except (Ros1WriterError, Ros2WriterError, OSError) as err:
            raise BagError(f'cannot write to {self.path}: {err}') from err

    def close(self) -> None:
        """Finish the bag (index, metadata); safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
        except (Ros1WriterError, Ros2WriterError, OSError) as err:
            raise BagError(f'cannot finish bag {self.path}: {err}') from err

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def read_all(path: str | Path, topic: str) -> list[BagMessage]:
    """Every message of one topic (convenience for tests and small bags).

    Raises:
        BagError: as :meth:`BagReader.messages`.
    """
    with BagReader(path) as bag:
        return list(bag.messages(topic))


__all__ = ['BAG_FORMATS', 'IMAGE_MSGTYPES', 'BagMessage', 'BagReader', 'BagWriter',
           'TopicSummary', 'header_stamp_ns', 'is_ros1_bag_file', 'latched_qos',
           'normalize_msgtype', 'read_all']
