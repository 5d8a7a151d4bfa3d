"""The index of a ROS 1 bag (format 2.0), read without a Python object per message.

A ROS 1 bag is the line ``#ROSBAG V2.0``, then records, each ``header_len`` (u32), a header of
fields (each ``field_len`` u32 and ``name=value``), ``data_len`` (u32) and the data:

- the bag header (op 0x03): ``index_pos`` (u64, byte of the index), ``conn_count`` and
  ``chunk_count`` (u32);
- chunk records (op 0x05: ``compression`` none / bz2 / lz4, ``size`` the uncompressed bytes),
  each followed by one index-data record (op 0x04: ``ver`` 1, ``conn``, ``count``) per connection
  with messages in the chunk, whose data is ``count`` entries of (sec u32, nsec u32, offset u32):
  a message's log time and where its record starts inside the uncompressed chunk;
- at ``index_pos``: ``conn_count`` connection records (op 0x07: ``conn``, ``topic``; data: a
  header holding ``type``, ``md5sum``, ``message_definition``), then ``chunk_count``
  chunk-info records (op 0x06: ``ver`` 1, ``chunk_pos``, ``start_time``, ``end_time``, ``count``;
  data: ``count`` pairs (conn u32, messages u32)).

:func:`read_index` parses the bag header, the connection and chunk-info records and, per chunk,
the chunk and index-data record headers (Python work per chunk and per connection of a chunk,
not per message); :meth:`BagIndex.entries` reads one index-data record's entries straight into
numpy arrays and :meth:`BagIndex.chunk_data` a chunk's uncompressed bytes, so a reader walks the
bag chunk by chunk in flat memory.  Anything that does not follow the format raises
:class:`Ros1IndexError` naming the byte where it was found.
"""

from __future__ import annotations

import bz2
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

__all__ = ["BagIndex", "Chunk", "Connection", "IndexRecord", "Ros1IndexError", "read_index"]

_OP_MSG_DATA, _OP_BAG_HEADER, _OP_INDEX_DATA, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7

#: One index-data entry: log time (seconds and nanoseconds) and the message record's offset
#: (bytes) inside the uncompressed chunk.
ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])


class Ros1IndexError(Exception):
    """The bag does not follow the ROS 1 format 2.0 as expected (damaged, unindexed, encrypted...)."""


@dataclass(frozen=True)
class Connection:
    """A connection record: ``conn`` (its id in the file), the topic and message type named as
    rosbags names them (``/imu/data``, ``sensor_msgs/msg/Imu``), the MD5 sum and the message
    definition text stored with it."""

    conn: int
    topic: str
    msgtype: str
    md5sum: str
    definition: str


@dataclass(frozen=True)
class IndexRecord:
    """An index-data record of a chunk: ``count`` entries of connection ``conn`` at file byte ``pos``."""

    conn: int
    count: int
    pos: int


@dataclass(frozen=True)
class Chunk:
    """A chunk: its compressed data (``data_size`` bytes at file byte ``data_pos``, ``size`` bytes
    uncompressed), its log-time span from the chunk-info record (ns, both ends included), the
    message count per connection (chunk info) and its index-data records."""

    pos: int
    data_pos: int
    data_size: int
    compression: str
    size: int
    start_ns: int
    end_ns: int
    counts: dict[int, int]
    records: tuple[IndexRecord, ...]


@dataclass
class BagIndex:
    """A ROS 1 bag's connections and chunks (chunk-info order), with the file open for reading
    entries and chunk data; close it with :meth:`close` (or use it as a context manager)."""

    path: Path
    file: BinaryIO
    size: int
    connections: tuple[Connection, ...]
    chunks: tuple[Chunk, ...]

    def __enter__(self) -> BagIndex:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.file.close()

    def counts(self) -> dict[int, int]:
        """Messages per connection id, summed over the chunk infos."""
        total = {c.conn: 0 for c in self.connections}
        for chunk in self.chunks:
            for conn, n in chunk.counts.items():
                if conn in total:
                    total[conn] += n
        return total

    def entries(self, record: IndexRecord, chunk: Chunk) -> tuple[np.ndarray, np.ndarray]:
        """(log time ns int64, offset in the uncompressed chunk int64) of an index-data record's
        entries, checked: inside the chunk's log-time span and its uncompressed bytes."""
        raw = _read_at(self.file, record.pos, record.count * ENTRY.itemsize, "index-data entries")
        e = np.frombuffer(raw, dtype=ENTRY)
        t_ns = e["sec"].astype(np.int64) * 1_000_000_000 + e["nsec"].astype(np.int64)
        offset = e["offset"].astype(np.int64)
        if e.size and (t_ns.min() < chunk.start_ns or t_ns.max() > chunk.end_ns or offset.max() >= chunk.size):
            raise Ros1IndexError(f"index-data record at byte {record.pos}: an entry lies outside its chunk "
                                 f"(chunk at byte {chunk.pos})")
        return t_ns, offset

    def chunk_data(self, chunk: Chunk) -> bytes:
        """The chunk's uncompressed bytes (``chunk.size`` of them, checked)."""
        raw = _read_at(self.file, chunk.data_pos, chunk.data_size, "chunk data")
        try:
            # at most one byte more than the header's size: damaged or crafted data cannot inflate further
            if chunk.compression == "bz2":
                raw = bz2.BZ2Decompressor().decompress(raw, max_length=chunk.size + 1)
            elif chunk.compression == "lz4":
                from lz4.frame import LZ4FrameDecompressor  # type: ignore[import-untyped]  # rosbags' dependency

                raw = LZ4FrameDecompressor().decompress(raw, max_length=chunk.size + 1)
        except Exception as exc:  # noqa: BLE001 - the decompressors raise several kinds for damaged data
            raise Ros1IndexError(f"chunk at byte {chunk.pos}: cannot decompress its {chunk.compression} data "
                                 f"({exc})") from None
        if len(raw) != chunk.size:
            raise Ros1IndexError(f"chunk at byte {chunk.pos}: {len(raw)} bytes uncompressed, its header says "
                                 f"{chunk.size}")
        return raw


def read_index(path: str | os.PathLike[str]) -> BagIndex:
    """Open the ROS 1 bag at ``path`` and read its index (see the module docstring).

    Raises
    ------
    Ros1IndexError : not a version 2.0 bag, encrypted, not indexed (``index_pos`` 0), or a
        record that does not follow the format (its byte position in the message).
    OSError : the file cannot be read.
    """
    path = Path(path)
    f = open(path, "rb")  # noqa: SIM115 - kept open by the BagIndex
    try:
        size = os.fstat(f.fileno()).st_size
        if f.readline(64) != b"#ROSBAG V2.0\n":
            raise Ros1IndexError("not a ROS 1 bag of format 2.0")
        pos = f.tell()
        fields, _ = _record(f, size, _OP_BAG_HEADER, "bag header")
        if fields.get(b"encryptor"):
            raise Ros1IndexError("the bag is encrypted")
        index_pos = _uint(fields, b"index_pos", 8, pos, "bag header")
        conn_count = _uint(fields, b"conn_count", 4, pos, "bag header")
        chunk_count = _uint(fields, b"chunk_count", 4, pos, "bag header")
        if index_pos == 0:
            raise Ros1IndexError("the bag is not indexed")
        if chunk_count == 0:     # rosbags reads no connection either: a bag without messages
            return BagIndex(path, f, size, (), ())
        if index_pos >= size or conn_count > size // 16 or chunk_count > size // 16:
            raise Ros1IndexError(f"the bag header (byte {pos}) does not fit the file: index at byte {index_pos}, "
                                 f"{conn_count} connections, {chunk_count} chunks in {size} bytes")
        f.seek(index_pos)
        connections = tuple(_connection(f, size) for _ in range(conn_count))
        if len({c.conn for c in connections}) != len(connections):
            raise Ros1IndexError(f"the index at byte {index_pos} holds a connection id twice")
        infos = [_chunk_info(f, size) for _ in range(chunk_count)]
        if len({info[0] for info in infos}) != len(infos):
            raise Ros1IndexError(f"the index at byte {index_pos} gives a chunk position twice")
        chunks = tuple(_chunk(f, size, *info) for info in infos)
    except BaseException:
        f.close()
        raise
    return BagIndex(path, f, size, connections, chunks)


# --------------------------------------------------------------------------- records


def _read_at(f: BinaryIO, pos: int, n: int, what: str) -> bytes:
    f.seek(pos)
    raw = f.read(n)
    if len(raw) != n:
        raise Ros1IndexError(f"{what} at byte {pos}: the file ends after {len(raw)} of {n} bytes")
    return raw


#: The most bytes a record header may have, and the data of a record read whole (bag header,
#: connection, chunk info: a message definition is the largest, some kB): a damaged length
#: beyond these is an error, not a read of up to 4 GiB.
MAX_HEADER_BYTES = 1 << 20
MAX_RECORD_DATA_BYTES = 16 << 20


def _u32(f: BinaryIO, size: int, what: str, limit: int | None = None) -> int:
    """The little-endian length at the file position, checked against the file's ``size`` and
    ``limit`` bytes."""
    pos = f.tell()
    raw = f.read(4)
    if len(raw) != 4:
        raise Ros1IndexError(f"{what} at byte {pos}: the file ends")
    n = int(struct.unpack("<I", raw)[0])
    if pos + 4 + n > size:
        raise Ros1IndexError(f"{what} at byte {pos}: a length of {n} bytes runs past the end of the file")
    if limit is not None and n > limit:
        raise Ros1IndexError(f"{what} at byte {pos}: a length of {n} bytes, more than such a record holds "
                             f"({limit} at most)")
    return n


def _fields(header: bytes, pos: int, what: str) -> dict[bytes, bytes]:
    """The ``name=value`` fields of a record header (a later field of the same name wins)."""
    out: dict[bytes, bytes] = {}
    i = 0
    while i < len(header):
        if i + 4 > len(header):
            raise Ros1IndexError(f"{what} at byte {pos}: a field length is cut off")
        (n,) = struct.unpack_from("<I", header, i)
        field = header[i + 4:i + 4 + n]
        name, eq, value = field.partition(b"=")
        if len(field) != n or not eq:
            raise Ros1IndexError(f"{what} at byte {pos}: a damaged header field")
        out[name] = value
        i += 4 + n
    return out


def _header(f: BinaryIO, size: int, op: int, what: str) -> dict[bytes, bytes]:
    """The header fields of the record at the file position, its op checked; the file is left at
    the record's ``data_len``."""
    pos = f.tell()
    fields = _fields(f.read(_u32(f, size, what, MAX_HEADER_BYTES)), pos, what)
    have = fields.get(b"op")
    if have != bytes([op]):
        raise Ros1IndexError(f"{what} at byte {pos}: record op {have!r}, expected {op:#04x}")
    return fields


def _record(f: BinaryIO, size: int, op: int, what: str) -> tuple[dict[bytes, bytes], bytes]:
    """The header fields (op checked) and the data of the record at the file position."""
    fields = _header(f, size, op, what)
    return fields, f.read(_u32(f, size, what, MAX_RECORD_DATA_BYTES))


def _uint(fields: dict[bytes, bytes], name: bytes, nbytes: int, pos: int, what: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != nbytes:
        raise Ros1IndexError(f"{what} at byte {pos}: no {nbytes}-byte field {name.decode()}")
    return int.from_bytes(value, "little")


def _time_ns(fields: dict[bytes, bytes], name: bytes, pos: int, what: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 8:
        raise Ros1IndexError(f"{what} at byte {pos}: no time field {name.decode()}")
    sec, nsec = struct.unpack("<II", value)
    return int(sec) * 1_000_000_000 + int(nsec)


def _text(fields: dict[bytes, bytes], name: bytes, pos: int, what: str, default: str | None = None) -> str:
    value = fields.get(name)
    if value is None:
        if default is not None:
            return default
        raise Ros1IndexError(f"{what} at byte {pos}: no field {name.decode()}")
    try:
        return value.decode()
    except UnicodeDecodeError:
        raise Ros1IndexError(f"{what} at byte {pos}: field {name.decode()} is not UTF-8 text") from None


def _connection(f: BinaryIO, size: int) -> Connection:
    from rosbags.typesys.msg import normalize_msgtype

    pos = f.tell()
    fields, data = _record(f, size, _OP_CONNECTION, "connection record")
    conn = _uint(fields, b"conn", 4, pos, "connection record")
    topic = _text(fields, b"topic", pos, "connection record")
    if not topic:
        raise Ros1IndexError(f"connection record at byte {pos}: an empty topic name")
    info = _fields(data, pos, "connection record")
    msgtype = _text(info, b"type", pos, "connection record")
    # names as rosbags gives them: repeated and trailing slashes dropped, ROS 2 style type names
    topic = ("/" if topic.startswith("/") else "") + "/".join(p for p in topic.split("/") if p)
    return Connection(conn, topic, normalize_msgtype(msgtype), _text(info, b"md5sum", pos, "connection record"),
                      _text(info, b"message_definition", pos, "connection record"))


def _chunk_info(f: BinaryIO, size: int) -> tuple[int, int, int, dict[int, int]]:
    """(chunk position, start ns, end ns, messages per connection) of a chunk-info record."""
    pos = f.tell()
    what = "chunk-info record"
    fields, data = _record(f, size, _OP_CHUNK_INFO, what)
    if (ver := _uint(fields, b"ver", 4, pos, what)) != 1:
        raise Ros1IndexError(f"{what} at byte {pos}: version {ver} is not 1")
    count = _uint(fields, b"count", 4, pos, what)
    if len(data) != 8 * count:
        raise Ros1IndexError(f"{what} at byte {pos}: {len(data)} data bytes for {count} connections")
    pairs = np.frombuffer(data, dtype="<u4").reshape(count, 2)
    counts = dict(zip(pairs[:, 0].tolist(), pairs[:, 1].tolist()))
    if len(counts) != count:
        raise Ros1IndexError(f"{what} at byte {pos}: a connection listed twice")
    return (_uint(fields, b"chunk_pos", 8, pos, what), _time_ns(fields, b"start_time", pos, what),
            _time_ns(fields, b"end_time", pos, what), counts)


def _chunk(f: BinaryIO, size: int, chunk_pos: int, start_ns: int, end_ns: int, counts: dict[int, int]) -> Chunk:
    """The chunk record at ``chunk_pos`` and the index-data records after it (one per connection
    of its chunk info, with the counts the chunk info gives)."""
    what = "chunk record"
    if chunk_pos >= size:
        raise Ros1IndexError(f"chunk info: a chunk at byte {chunk_pos}, past the end of the file ({size} bytes)")
    f.seek(chunk_pos)
    fields = _header(f, size, _OP_CHUNK, what)
    compression = _text(fields, b"compression", chunk_pos, what)
    if compression not in ("none", "bz2", "lz4"):
        raise Ros1IndexError(f"{what} at byte {chunk_pos}: compression {compression!r} is not supported")
    data_size = _u32(f, size, what)
    data_pos = f.tell()
    uncompressed = _uint(fields, b"size", 4, chunk_pos, what)
    f.seek(data_pos + data_size)
    records = []
    for _ in range(len(counts)):
        pos = f.tell()
        idx = _header(f, size, _OP_INDEX_DATA, "index-data record")
        if _uint(idx, b"ver", 4, pos, "index-data record") != 1:
            raise Ros1IndexError(f"index-data record at byte {pos}: version is not 1")
        conn = _uint(idx, b"conn", 4, pos, "index-data record")
        count = _uint(idx, b"count", 4, pos, "index-data record")
        if (_u32(f, size, "index-data record") != count * ENTRY.itemsize or counts.get(conn) != count
                or any(r.conn == conn for r in records)):
            raise Ros1IndexError(f"index-data record at byte {pos}: {count} entries of connection {conn} do not "
                                 f"match its length or the chunk info, or repeat its connection")
        entries_pos = f.tell()
        records.append(IndexRecord(conn, count, entries_pos))
        f.seek(entries_pos + count * ENTRY.itemsize)
    return Chunk(chunk_pos, data_pos, data_size, compression, uncompressed, start_ns, end_ns, counts, tuple(records))
