"""Recovery of truncated bags: a sequential scan of an MCAP or ROS 1 file.

A recorder killed before it closed its file leaves an MCAP file without its footer, or
a ROS 1 bag without its index, which rosbags cannot open. :func:`scan_file` walks such
a file record by record (into chunks, compressed or not), registers the message
definitions it finds, and keeps every complete message; it stops at the first cut
record and says where (:attr:`SalvagedBag.cut`). :class:`speed_sign_detector.bag_io.BagReader`
uses it as its "salvage mode".

Errors are :class:`speed_sign_detector.errors.BagError`.
"""
from __future__ import annotations

import bz2
import logging
import struct
from dataclasses import dataclass, field
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from speed_sign_detector.errors import BagError

LOGGER = logging.getLogger(__name__)

#: First bytes of an MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'
#: First bytes of a ROS 1 bag (format 2.0).
ROS1_MAGIC = b'#ROSBAG V2.0\n'


def normalize_msgtype(msgtype: str) -> str:
    """``sensor_msgs/Image`` (ROS 1 name) -> ``sensor_msgs/msg/Image``."""
    parts = msgtype.split('/')
    return f'{parts[0]}/msg/{parts[1]}' if len(parts) == 2 else msgtype


@dataclass
class SalvageConnection:
    """A topic found by the scan; ``count`` messages of it were recovered."""

    topic: str
    msgtype: str
    count: int = 0


@dataclass
class SalvagedBag:
    """Messages recovered by a sequential scan of a file whose index or end is missing."""

    reason: str
    is_ros2: bool
    typestore: Typestore
    connections: dict[int, SalvageConnection] = field(default_factory=dict)
    records: list[tuple[int, int, bytes]] = field(default_factory=list)  # conn, time, raw
    cut: str = ''   # why the scan stopped early ('' = reached a clean end)


def scan_file(path: Path, reason: str) -> SalvagedBag:
    """Recover the complete messages of a truncated MCAP or ROS 1 file.

    Raises:
        BagError: the file is neither (e.g. a damaged sqlite3 database).
    """
    try:
        data = path.read_bytes()
    except OSError as err:
        raise BagError(f'cannot read {path}: {err}') from err
    if data.startswith(MCAP_MAGIC):
        salvage = SalvagedBag(reason, True, get_typestore(Stores.ROS2_JAZZY))
        _scan_mcap(data, salvage)
    elif data.startswith(ROS1_MAGIC):
        salvage = SalvagedBag(reason, False, get_typestore(Stores.ROS1_NOETIC))
        _scan_ros1(data, salvage)
    elif path.suffix == '.db3':
        raise BagError(f'cannot open bag {path}: {reason} (a damaged or truncated sqlite3 '
                       f'bag cannot be recovered; MCAP and ROS 1 recordings can)')
    else:
        raise BagError(f'cannot open bag {path}: {reason}')
    if not salvage.connections:
        raise BagError(f'bag {path} is truncated or damaged ({reason}) and no topic could '
                       f'be recovered from it')
    return salvage


def _register(salvage: SalvagedBag, msgdef: str, msgtype: str) -> None:
    """Add the types of a ``.msg`` definition to the salvage typestore (best effort)."""
    if not msgdef:
        return
    try:
        salvage.typestore.register(get_types_from_msg(msgdef, msgtype))
    except Exception as err:  # noqa: BLE001 - keep the built-in definition then
        LOGGER.debug('could not register type %s from the bag: %s', msgtype, err)


def _scan_mcap(data: bytes, salvage: SalvagedBag) -> None:
    """Walk MCAP records (into chunks) until the data ends or a record is cut."""
    schemas: dict[int, tuple[str, str, str]] = {}

    def walk(buffer: bytes, start: int, inside_chunk: bool) -> bool:
        position = start
        while position < len(buffer):
            if position + 9 > len(buffer):
                salvage.cut = f'record header cut at byte {position}'
                return False
            opcode = buffer[position]
            (length,) = struct.unpack_from('<Q', buffer, position + 1)
            body_start, body_end = position + 9, position + 9 + length
            if body_end > len(buffer):
                if opcode == 0x06 and not inside_chunk:
                    walk_partial_chunk(buffer[body_start:])
                salvage.cut = f'record 0x{opcode:02x} cut at byte {position}'
                return False
            body = buffer[body_start:body_end]
            if opcode == 0x02:  # footer: clean end
                return True
            if opcode == 0x03:
                handle_schema(body)
            elif opcode == 0x04:
                handle_channel(body)
            elif opcode == 0x05:
                channel_id, _sequence, log_time = struct.unpack_from('<HIQ', body, 0)
                if channel_id in salvage.connections:
                    salvage.connections[channel_id].count += 1
                    salvage.records.append((channel_id, log_time, bytes(body[22:])))
            elif opcode == 0x06 and not inside_chunk:
                if not handle_chunk(body):
                    return False
            position = body_end
        return True

    def read_string(body: bytes, offset: int) -> tuple[str, int]:
        (size,) = struct.unpack_from('<I', body, offset)
        return body[offset + 4:offset + 4 + size].decode('utf-8'), offset + 4 + size

    def handle_schema(body: bytes) -> None:
        (schema_id,) = struct.unpack_from('<H', body, 0)
        name, offset = read_string(body, 2)
        encoding, offset = read_string(body, offset)
        (size,) = struct.unpack_from('<I', body, offset)
        schemas[schema_id] = (name, encoding,
                              body[offset + 4:offset + 4 + size].decode('utf-8', 'replace'))

    def handle_channel(body: bytes) -> None:
        channel_id, schema_id = struct.unpack_from('<HH', body, 0)
        topic, _ = read_string(body, 4)
        name, encoding, text = schemas.get(schema_id, ('', '', ''))
        if encoding == 'ros2msg':
            _register(salvage, text, name)
        salvage.connections[channel_id] = SalvageConnection(topic, name)

    def chunk_records(body: bytes) -> tuple[str, bytes]:
        offset = 8 + 8 + 8 + 4
        compression, offset = read_string(body, offset)
        (size,) = struct.unpack_from('<Q', body, offset)
        return compression, body[offset + 8:offset + 8 + size]

    def handle_chunk(body: bytes) -> bool:
        compression, records = chunk_records(body)
        try:
            if compression == 'zstd':
                from backports import zstd
                records = zstd.decompress(records)
            elif compression == 'lz4':
                import lz4.frame
                records = lz4.frame.decompress(records)
            elif compression:
                salvage.cut = f'unsupported chunk compression {compression!r}'
                return False
        except Exception as err:  # noqa: BLE001 - a damaged chunk ends the scan
            salvage.cut = f'chunk does not decompress: {err}'
            return False
        return walk(records, 0, True)

    def walk_partial_chunk(body: bytes) -> None:
        try:
            compression, records = chunk_records(body)
        except (struct.error, UnicodeDecodeError):
            return
        if not compression:
            walk(records, 0, True)

    if not walk(data, len(MCAP_MAGIC), False) and not salvage.cut:
        salvage.cut = 'data ends early'
    elif not salvage.cut:
        salvage.cut = 'no footer'


def _scan_ros1(data: bytes, salvage: SalvagedBag) -> None:
    """Walk ROS 1 records (into chunks) until the data ends or a record is cut."""

    def parse_header(buffer: bytes) -> dict[str, bytes]:
        fields: dict[str, bytes] = {}
        position = 0
        while position + 4 <= len(buffer):
            (size,) = struct.unpack_from('<I', buffer, position)
            name, _, value = buffer[position + 4:position + 4 + size].partition(b'=')
            fields[name.decode('ascii', 'replace')] = value
            position += 4 + size
        return fields

    def walk(buffer: bytes, start: int) -> bool:
        position = start
        while position < len(buffer):
            if position + 4 > len(buffer):
                salvage.cut = f'record cut at byte {position}'
                return False
            (header_size,) = struct.unpack_from('<I', buffer, position)
            data_at = position + 4 + header_size
            if data_at + 4 > len(buffer):
                salvage.cut = f'record header cut at byte {position}'
                return False
            header = parse_header(buffer[position + 4:data_at])
            (data_size,) = struct.unpack_from('<I', buffer, data_at)
            end = data_at + 4 + data_size
            opcode = header.get('op', b'\x00')[0]
            if end > len(buffer):
                if opcode == 0x05 and header.get('compression', b'none') == b'none':
                    walk(buffer[data_at + 4:], 0)   # the complete records of a cut chunk
                salvage.cut = f'record data cut at byte {position}'
                return False
            body = buffer[data_at + 4:end]
            if opcode == 0x05:  # chunk
                compression = header.get('compression', b'none').decode()
                try:
                    if compression == 'bz2':
                        body = bz2.decompress(body)
                    elif compression == 'lz4':
                        import lz4.frame
                        body = lz4.frame.decompress(body)
                    elif compression != 'none':
                        salvage.cut = f'unsupported chunk compression {compression!r}'
                        return False
                except Exception as err:  # noqa: BLE001 - a damaged chunk ends the scan
                    salvage.cut = f'chunk does not decompress: {err}'
                    return False
                if not walk(body, 0):
                    return False
            elif opcode == 0x07:  # connection
                (connection_id,) = struct.unpack_from('<I', header['conn'])
                details = parse_header(body)
                msgtype = normalize_msgtype(details.get('type', b'').decode())
                _register(salvage, details.get('message_definition', b'').decode(
                    'utf-8', 'replace'), msgtype)
                salvage.connections.setdefault(connection_id, SalvageConnection(
                    header.get('topic', b'').decode(), msgtype))
            elif opcode == 0x02:  # message data
                (connection_id,) = struct.unpack_from('<I', header['conn'])
                sec, nsec = struct.unpack_from('<II', header['time'])
                if connection_id in salvage.connections:
                    salvage.connections[connection_id].count += 1
                    salvage.records.append((connection_id, sec * 1_000_000_000 + nsec,
                                            bytes(body)))
            position = end
        return True

    if walk(data, len(ROS1_MAGIC)) and not salvage.cut:
        salvage.cut = 'no index'


__all__ = ['MCAP_MAGIC', 'ROS1_MAGIC', 'SalvageConnection', 'SalvagedBag', 'normalize_msgtype',
           'scan_file']
