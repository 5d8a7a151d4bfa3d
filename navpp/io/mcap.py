"""MCAP reader: ROS 2 (CDR) and ROS 1 encoded ``sensor_msgs/Imu``, ``sensor_msgs/NavSatFix``,
``geometry_msgs/TwistWithCovarianceStamped`` / ``TwistStamped`` and ``nav_msgs/Odometry`` (its
twist: wheel odometry) into :class:`LogContents` (Twist and Odometry topics in ``twist``).

The ``mcap`` package reads the summary (for :func:`list_topics`) and parses Schema and Channel
records; the bulk of the file (Message records, in chunks or at top level) is scanned by a
numba kernel (:func:`_scan_kernel`) over the raw record stream, as the MCAP specification lays it
out: ``opcode u8, length u64, content``; a Message's content is ``channel_id u16, sequence u32,
log_time u64, publish_time u64, data``.  Chunks are decompressed (zstd / lz4 / none, as the
``mcap`` package does), their CRC checked, scanned, and the payload spans of each decoded
topic handed to :class:`navpp.io.messages.TopicDecoder` chunk by chunk, so memory holds one
window of the file, one chunk and the decoded arrays.

The file is read front to back whether or not it has a summary, so files without a summary
and files whose recording was cut off (no footer, a partial last record) read the same way;
a cut-off file yields the messages up to the cut and a warning saying where it stopped.

``engine="library"`` reads through ``mcap``'s own message iteration and the ``mcap_ros2`` /
``mcap_ros1`` decoders, one Python object per message (far slower): the cross-check the
tests use, and an escape hatch.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Iterable
from dataclasses import fields, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from navpp import jitmode, spill
from navpp.errors import InputError
from navpp.findings import Finding
from navpp.io.messages import (
    ENCODINGS,
    Messages,
    TopicDecoder,
    build_messages,
    decode_with_library,
    plausible_count,
)
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    SUPPORTED_TYPES,
    LogContents,
    TopicInfo,
    normalise_type,
)
from navpp.kernel import njit

__all__ = ["MCAP_MAGIC", "list_topics", "read_mcap"]

MCAP_MAGIC = b"\x89MCAP0\r\n"

_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_DATA_END = 0x0F
_RECORD_HEADER = 9  # opcode u8 + length u64
_FOOTER_RECORD = _RECORD_HEADER + 8 + 8 + 4
_MESSAGE_PREFIX = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time
_CHUNK_PREFIX = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression len
_WINDOW = 16 * 2**20  # bytes of the top-level record stream read at a time

# Scan status.
_END = 0         # consumed the span exactly
_DATA_END = 1    # stopped after a DataEnd or Footer record (top level only)
_PARTIAL = 2     # the last record runs past the span
_BAD_MESSAGE = 3  # a Message record too short to hold its fixed fields

#: Schema encodings whose text :func:`navpp.io.messages.schema_is_standard` can check.
_MSG_SCHEMAS = {"cdr": "ros2msg", "ros1": "ros1msg"}


# --------------------------------------------------------------------------- record scanning


@njit(cache=True, inline="always")
def _u64(buf, p):  # pragma: no cover - compiled
    v = np.uint64(0)
    for k in range(8):
        v |= np.uint64(buf[p + k]) << np.uint64(8 * k)
    return v


@njit(cache=True)
def _scan_kernel(buf, start, stop, top_level, fill, msg_chan, msg_log, msg_pos, msg_len,
          rec_op, rec_pos, rec_len):  # pragma: no cover - compiled
    """Walk the records of ``buf[start:stop]``.

    With ``fill``, Message records go to ``msg_*`` (channel id, log time, payload position and
    length) and the other records to ``rec_*`` (opcode, content position and length); without,
    only counts.  Returns ``(n_messages, n_other, stop position, status)``; at top level the
    walk ends after a DataEnd or Footer record.
    """
    pos = start
    n_msg = 0
    n_rec = 0
    status = 0
    while True:
        if pos == stop:
            status = 0
            break
        if pos + 9 > stop:
            status = 2
            break
        op = buf[pos]
        length_u = _u64(buf, pos + 1)
        if length_u > np.uint64(stop - pos - 9):
            status = 2
            break
        length = np.int64(length_u)
        content = pos + 9
        if op == 5:
            if length < 22:
                status = 3
                break
            if fill:
                msg_chan[n_msg] = np.int64(buf[content]) | (np.int64(buf[content + 1]) << 8)
                msg_log[n_msg] = np.int64(_u64(buf, content + 6))
                msg_pos[n_msg] = content + 22
                msg_len[n_msg] = length - 22
            n_msg += 1
        else:
            if fill:
                rec_op[n_rec] = op
                rec_pos[n_rec] = content
                rec_len[n_rec] = length
            n_rec += 1
            if top_level and (op == 15 or op == 2):
                pos = content + length
                status = 1
                break
        pos = content + length
    return n_msg, n_rec, pos, status


_RECORD = struct.Struct("<BQ")        # opcode, content length
_MESSAGE = struct.Struct("<HIQ")      # channel id, sequence, log time


def _scan_struct(buf, start, stop, top_level, fill, msg_chan, msg_log, msg_pos, msg_len,
                 rec_op, rec_pos, rec_len):
    """:func:`_scan_kernel` with ``struct`` reads, for runs whose kernels are interpreted
    (:mod:`navpp.jitmode`): the same arguments and results, a few times faster than the
    kernel's byte loops run as Python."""
    view = memoryview(buf)
    pos = start
    n_msg = n_rec = 0
    while True:
        if pos == stop:
            return n_msg, n_rec, pos, _END
        if pos + _RECORD_HEADER > stop:
            return n_msg, n_rec, pos, _PARTIAL
        op, length = _RECORD.unpack_from(view, pos)
        if length > stop - pos - _RECORD_HEADER:
            return n_msg, n_rec, pos, _PARTIAL
        content = pos + _RECORD_HEADER
        if op == _OP_MESSAGE:
            if length < _MESSAGE_PREFIX:
                return n_msg, n_rec, pos, _BAD_MESSAGE
            if fill:
                chan, _, log = _MESSAGE.unpack_from(view, content)
                msg_chan[n_msg] = chan
                msg_log[n_msg] = log if log < 2**63 else log - 2**64
                msg_pos[n_msg] = content + _MESSAGE_PREFIX
                msg_len[n_msg] = length - _MESSAGE_PREFIX
            n_msg += 1
        else:
            if fill:
                rec_op[n_rec] = op
                rec_pos[n_rec] = content
                rec_len[n_rec] = length
            n_rec += 1
            if top_level and op in (_OP_DATA_END, _OP_FOOTER):
                return n_msg, n_rec, content + length, _DATA_END
        pos = content + length


class _Scan:
    """The records of one span: messages (chan, log, pos, len) and others (op, pos, len)."""

    def __init__(self, buf: np.ndarray, start: int, stop: int, top_level: bool) -> None:
        empty = np.zeros(0, dtype=np.int64)
        _scan = _scan_struct if jitmode.interpreted() else _scan_kernel
        n_msg, n_rec, _, _ = _scan(buf, start, stop, top_level, False,
                                   empty, empty, empty, empty, empty, empty, empty)
        self.chan = np.empty(n_msg, dtype=np.int64)
        self.log = np.empty(n_msg, dtype=np.int64)
        self.pos = np.empty(n_msg, dtype=np.int64)
        self.len = np.empty(n_msg, dtype=np.int64)
        self.rec_op = np.empty(n_rec, dtype=np.int64)
        self.rec_pos = np.empty(n_rec, dtype=np.int64)
        self.rec_len = np.empty(n_rec, dtype=np.int64)
        _, _, end, status = _scan(buf, start, stop, top_level, True, self.chan, self.log,
                                  self.pos, self.len, self.rec_op, self.rec_pos, self.rec_len)
        self.end = int(end)
        self.status = int(status)


def _readonly_u8(data: Any) -> np.ndarray:
    arr = np.frombuffer(data, dtype=np.uint8)
    if arr.flags.writeable:
        arr = arr.view()
        arr.flags.writeable = False
    return arr


# --------------------------------------------------------------------------- helpers


def _time_text(ns: int | None) -> str:
    if ns is None:
        return "?"
    ns = int(ns)
    sign = "-" if ns < 0 else ""
    ns = abs(ns)
    return f"{sign}{ns // 1_000_000_000}.{ns % 1_000_000_000:09d} s"


def _check_file(path: Path) -> int:
    """Size of the file; InputError when missing, empty or not an MCAP file."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if size == 0:
        raise InputError(f"{path}: empty file")
    if head != MCAP_MAGIC:
        raise InputError(f"{path}: not an MCAP file (the first bytes are not the MCAP magic)")
    return size


def _read_summary(path: Path, size: int) -> Any:
    """The ``mcap`` Summary, or None when the file has none (or it cannot be read)."""
    from mcap.reader import make_reader

    if size < 2 * len(MCAP_MAGIC) + _FOOTER_RECORD:
        return None
    with open(path, "rb") as f:
        f.seek(size - len(MCAP_MAGIC))
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            return None  # no footer: cut off, or still being written
        f.seek(0)
        try:
            return make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - a damaged summary: read the data section instead
            return None


def _parse_record(cls: Any, content: Any) -> Any:
    """Parse a Schema / Channel record's content with the ``mcap`` package."""
    from mcap.data_stream import ReadDataStream

    return cls.read(ReadDataStream(io.BytesIO(bytes(content))))


def _take(msgs: Messages, order: np.ndarray) -> Messages:
    """``msgs`` with every per-message array reordered by ``order``."""
    changes = {}
    for f in fields(msgs):
        value = getattr(msgs, f.name)
        if isinstance(value, np.ndarray):
            changes[f.name] = value[order]
    return replace(msgs, **changes)


def _in_log_order(msgs: Messages) -> Messages:
    """Messages in log-time order (stable, as the ``mcap`` reader yields them).  Spilled
    messages (:mod:`navpp.spill`) are checked window by window; only out-of-order ones are
    taken into memory in order."""
    log = msgs.log_ns
    if any(bool(np.any(log[max(a - 1, 0) + 1:b] < log[max(a - 1, 0):b - 1]))
           for a, b in spill.windows(log.shape[0], log)):
        return _take(msgs, np.argsort(log, kind="stable"))
    return msgs


class _Channels:
    """Schemas and channels seen so far, per-channel counts and the decoders of the topics."""

    def __init__(self, source: str, topics: set[str] | None, memory: int | None = None) -> None:
        self.source = source
        self.wanted = topics
        self.memory = memory
        #: messages per topic in the summary's statistics (the decoders' first sizes)
        self.expected: dict[str, int] = {}
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, Any] = {}
        self.count: dict[int, int] = {}
        self.first: dict[int, int] = {}
        self.last: dict[int, int] = {}
        self.decoders: dict[str, TopicDecoder] = {}
        self.by_channel: dict[int, TopicDecoder] = {}
        self.warnings: list[str] = []
        self._unknown_channels: set[int] = set()

    def msgtype(self, channel: Any) -> str:
        schema = self.schemas.get(channel.schema_id)
        return normalise_type(schema.name) if schema is not None else ""

    def add_schema(self, schema: Any) -> None:
        self.schemas.setdefault(schema.id, schema)

    def add_channel(self, channel: Any) -> None:
        if channel.id in self.channels:
            return
        self.channels[channel.id] = channel
        topic, encoding = channel.topic, channel.message_encoding
        msgtype = self.msgtype(channel)
        if self.wanted is None:
            if msgtype not in SUPPORTED_TYPES or encoding not in ENCODINGS:
                return
        elif topic not in self.wanted:
            return
        elif msgtype not in SUPPORTED_TYPES or encoding not in ENCODINGS:
            raise InputError(f"{self.source}: topic {topic!r} has type {msgtype or 'unknown'!r} "
                             f"(encoding {encoding!r}); navpp decodes {', '.join(SUPPORTED_TYPES)} "
                             f"in {' or '.join(ENCODINGS)} encoding")
        decoder = self.decoders.get(topic)
        if decoder is None:
            schema = self.schemas.get(channel.schema_id)
            text = None
            if schema is not None and schema.encoding == _MSG_SCHEMAS[encoding]:
                text = schema.data.decode("utf-8", errors="replace")
            decoder = TopicDecoder(topic, msgtype, encoding, source=self.source,
                                   schema_name=schema.name if schema is not None else None,
                                   schema_text=text, memory=self.memory,
                                   expected=self.expected.get(topic, 0))
            self.decoders[topic] = decoder
        elif decoder.msgtype != msgtype or decoder.encoding != encoding:
            self.warnings.append(f"{self.source}: topic {topic!r} has channels of different types "
                                 f"({decoder.msgtype}, {msgtype}); only the {decoder.msgtype} "
                                 "messages are read")
            return
        self.by_channel[channel.id] = decoder

    def messages(self, buf: np.ndarray, chan: np.ndarray, log: np.ndarray, pos: np.ndarray,
                 length: np.ndarray) -> None:
        """Count and decode a run of Message records (file order) whose payloads are in buf."""
        if chan.shape[0] == 0:
            return
        if bool(np.all(chan == chan[0])):
            groups = [(int(chan[0]), None)]
        else:
            order = np.argsort(chan, kind="stable")
            ids, first, counts = np.unique(chan[order], return_index=True, return_counts=True)
            groups = [(int(c), order[a:a + n]) for c, a, n in zip(ids, first, counts)]
        for cid, idx in groups:
            c_log = log if idx is None else log[idx]
            if cid not in self.channels:
                if cid not in self._unknown_channels:
                    self._unknown_channels.add(cid)
                    self.warnings.append(f"{self.source}: messages on channel id {cid}, which has "
                                         "no Channel record, are ignored")
                continue
            self.count[cid] = self.count.get(cid, 0) + c_log.shape[0]
            lo, hi = int(c_log.min()), int(c_log.max())
            self.first[cid] = min(self.first.get(cid, lo), lo)
            self.last[cid] = max(self.last.get(cid, hi), hi)
            decoder = self.by_channel.get(cid)
            if decoder is not None:
                if idx is None:
                    decoder.add(buf, pos, length, log)
                else:
                    decoder.add(buf, pos[idx], length[idx], c_log)

    def topic_infos(self) -> tuple[TopicInfo, ...]:
        """One TopicInfo per topic, in the order channels were first declared."""
        merged: dict[str, dict[str, Any]] = {}
        for cid, ch in self.channels.items():
            info = merged.setdefault(ch.topic, {"msgtype": self.msgtype(ch), "count": 0,
                                                "first": None, "last": None,
                                                "encoding": ch.message_encoding})
            info["count"] += self.count.get(cid, 0)
            if cid in self.first:
                f, la = self.first[cid], self.last[cid]
                info["first"] = f if info["first"] is None else min(info["first"], f)
                info["last"] = la if info["last"] is None else max(info["last"], la)
        return tuple(TopicInfo(topic=t, msgtype=i["msgtype"], count=i["count"],
                               first_ns=i["first"], last_ns=i["last"], encoding=i["encoding"])
                     for t, i in merged.items())

    def check_wanted(self) -> None:
        """InputError for a requested topic that is not in the log."""
        if self.wanted is None:
            return
        present = {ch.topic for ch in self.channels.values()}
        missing = sorted(self.wanted - present)
        if missing:
            listed = ", ".join(sorted(present)) or "none"
            raise InputError(f"{self.source}: topic {missing[0]!r} not found in the log "
                             f"(topics: {listed})")


# --------------------------------------------------------------------------- the fast reader


class _FastReader:
    def __init__(self, path: Path, size: int, topics: set[str] | None, memory: int | None = None) -> None:
        self.path = path
        self.source = str(path)
        self.size = size
        self.reg = _Channels(self.source, topics, memory)
        self.n_messages = 0
        self.last_log: int | None = None
        self._cut_reason = ""

    # -- records ---------------------------------------------------------------------------

    def _other(self, buf: np.ndarray, op: int, pos: int, length: int, file_pos: int, *,
               in_chunk: bool = False) -> None:
        from mcap.records import Channel, Schema

        if op in (_OP_SCHEMA, _OP_CHANNEL):
            cls = Schema if op == _OP_SCHEMA else Channel
            try:
                record = _parse_record(cls, buf[pos:pos + length])
            except Exception as exc:  # noqa: BLE001 - mcap raises EndOfFile, UnicodeDecodeError, struct.error...
                reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                where = f"in the chunk at byte {file_pos}" if in_chunk else f"at byte {file_pos}"
                raise InputError(f"{self.source}: {cls.__name__} record {where} is corrupted: "
                                 f"{' '.join(reason.split())}") from None
            if op == _OP_SCHEMA:
                self.reg.add_schema(record)
            else:
                self.reg.add_channel(record)
        elif op == _OP_CHUNK:
            self._chunk(buf, pos, length, file_pos, partial=False)

    def _messages(self, buf: np.ndarray, scan: _Scan, a: int, b: int) -> None:
        if b <= a:
            return
        self.reg.messages(buf, scan.chan[a:b], scan.log[a:b], scan.pos[a:b], scan.len[a:b])
        self.n_messages += b - a
        self.last_log = int(scan.log[b - 1])

    def _records(self, buf: np.ndarray, scan: _Scan, base: int) -> None:
        """Process a scanned span in file order: other records interleaved with message runs."""
        keep = np.isin(scan.rec_op, (_OP_SCHEMA, _OP_CHANNEL, _OP_CHUNK))
        ops, poss, lens = scan.rec_op[keep], scan.rec_pos[keep], scan.rec_len[keep]
        split = np.searchsorted(scan.pos, poss)
        done = 0
        for op, pos, length, s in zip(ops.tolist(), poss.tolist(), lens.tolist(), split.tolist()):
            self._messages(buf, scan, done, s)
            done = s
            self._other(buf, op, pos, length, base + pos - _RECORD_HEADER)
        self._messages(buf, scan, done, scan.chan.shape[0])

    # -- chunks ----------------------------------------------------------------------------

    def _chunk_error(self, file_pos: int, t0: int | None, t1: int | None, what: str) -> InputError:
        return InputError(f"{self.source}: chunk at byte {file_pos} (log time {_time_text(t0)} to "
                          f"{_time_text(t1)}) is corrupted: {what}")

    def _chunk(self, buf: np.ndarray, pos: int, length: int, file_pos: int, *,
               partial: bool) -> None:
        content = memoryview(buf)[pos:pos + length]
        if len(content) < _CHUNK_PREFIX.size:
            if partial:
                return
            raise self._chunk_error(file_pos, None, None, "record too short")
        t0, t1, usize, crc, clen = _CHUNK_PREFIX.unpack_from(content, 0)
        head = _CHUNK_PREFIX.size + clen + 8
        if len(content) < head:
            if partial:
                return
            raise self._chunk_error(file_pos, t0, t1, "record too short")
        compression = bytes(content[_CHUNK_PREFIX.size:_CHUNK_PREFIX.size + clen]).decode(
            "utf-8", errors="replace")
        (dlen,) = struct.unpack_from("<Q", content, head - 8)
        data = content[head:head + dlen]
        if len(data) < dlen and not partial:
            raise self._chunk_error(file_pos, t0, t1, "data shorter than declared")
        try:
            raw = self._decompress(compression, data, usize, partial=partial)
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001 - zstd / lz4 errors have no common base
            if partial:
                return
            raise self._chunk_error(file_pos, t0, t1, f"cannot decompress {compression} data "
                                    f"({type(exc).__name__}: {exc})") from None
        if not partial:
            if len(raw) != usize:
                raise self._chunk_error(file_pos, t0, t1, f"{len(raw)} bytes after decompression, "
                                        f"{usize} declared")
            if crc != 0:
                actual = zlib.crc32(raw)
                if actual != crc:
                    raise self._chunk_error(file_pos, t0, t1, f"CRC mismatch (stored 0x{crc:08x}, "
                                            f"computed 0x{actual:08x})")
        arr = _readonly_u8(raw)
        scan = _Scan(arr, 0, arr.shape[0], False)
        if scan.status != _END and not partial:
            what = ("is too short for a Message record" if scan.status == _BAD_MESSAGE
                    else "runs past the end of the decompressed data")
            raise self._chunk_error(file_pos, t0, t1, f"record at offset {scan.end} {what}")
        # Channel records of a chunk precede its messages; register them all first.
        for op, rpos, rlen in zip(scan.rec_op.tolist(), scan.rec_pos.tolist(),
                                  scan.rec_len.tolist()):
            if op in (_OP_SCHEMA, _OP_CHANNEL):
                self._other(arr, op, rpos, rlen, file_pos, in_chunk=True)
        self._messages(arr, scan, 0, scan.chan.shape[0])

    def _decompress(self, compression: str, data: memoryview, usize: int, *,
                    partial: bool) -> Any:
        if compression == "":
            return data
        if compression == "zstd":
            import zstandard

            if partial:
                return zstandard.ZstdDecompressor().decompressobj().decompress(bytes(data))
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
        if compression == "lz4":
            import lz4.frame

            if partial:
                return lz4.frame.LZ4FrameDecompressor().decompress(bytes(data))
            return lz4.frame.decompress(data)
        raise InputError(f"{self.source}: unsupported chunk compression {compression!r} "
                         "(navpp reads zstd, lz4 and uncompressed chunks)")

    # -- the file ----------------------------------------------------------------------------

    def run(self) -> LogContents:
        summary = _read_summary(self.path, self.size)
        if summary is not None:
            counts = summary.statistics.channel_message_counts if summary.statistics is not None else {}
            for cid, channel in summary.channels.items():
                self.reg.expected[channel.topic] = self.reg.expected.get(channel.topic, 0) + counts.get(cid, 0)
            for topic, count in self.reg.expected.items():     # a damaged count: no more than the file holds
                self.reg.expected[topic] = plausible_count(count, self.size)
            for schema in summary.schemas.values():
                self.reg.add_schema(schema)
            for channel in summary.channels.values():
                self.reg.add_channel(channel)
            self.reg.check_wanted()
        cut = self._read_data_section()
        self.reg.check_wanted()
        warnings = list(self.reg.warnings)
        if cut is not None:
            where = (f"the last message read has log time {_time_text(self.last_log)}"
                     if self.last_log is not None else "no message could be read")
            warnings.append(Finding("recording-cut-off", f"{self.source}: the recording is cut off: the file ends at "
                                    f"byte {self.size} {self._cut_reason.format(pos=cut)}; read "
                                    f"{self.n_messages} messages, {where}"))
        contents: dict[str, dict[str, Any]] = {"imu": {}, "fix": {}, "twist": {}}
        for topic, decoder in self.reg.decoders.items():
            msgs = _in_log_order(decoder.result())
            kind = "imu" if decoder.msgtype == IMU_TYPE else "fix" if decoder.msgtype == FIX_TYPE else "twist"
            contents[kind][topic] = msgs
        return LogContents(source=self.source, topics=self.reg.topic_infos(),
                           imu=contents["imu"], fix=contents["fix"], twist=contents["twist"],
                           warnings=tuple(warnings))

    def _read_data_section(self) -> int | None:
        """Scan the top-level records; the byte offset where the file is cut off, or None."""
        pos = len(MCAP_MAGIC)
        window = _WINDOW
        with open(self.path, "rb") as f:
            while True:
                f.seek(pos)
                data = f.read(window)
                if not data:
                    self._cut_reason = "without a DataEnd record and footer"
                    return pos
                buf = _readonly_u8(data)
                scan = _Scan(buf, 0, buf.shape[0], True)
                self._records(buf, scan, pos)
                if scan.status == _DATA_END:
                    return None
                if scan.status == _BAD_MESSAGE:
                    raise InputError(f"{self.source}: Message record at byte {pos + scan.end} is "
                                     "too short to be one (corrupted file)")
                pos += scan.end
                if scan.status == _END:
                    continue  # the window ended on a record boundary
                # _PARTIAL: the next record runs past the window.
                rest = buf.shape[0] - scan.end
                if rest >= _RECORD_HEADER:
                    (length,) = struct.unpack_from("<Q", data, scan.end + 1)
                    need = _RECORD_HEADER + length
                else:
                    need = _RECORD_HEADER
                if pos + need <= self.size:
                    window = max(window, need)
                    continue
                # Cut off inside this record: read what a partial chunk still holds.
                self._cut_reason = "inside the record starting at byte {pos}"
                if rest > _RECORD_HEADER and data[scan.end] == _OP_CHUNK:
                    self._chunk(buf, scan.end + _RECORD_HEADER, rest - _RECORD_HEADER, pos,
                                partial=True)
                return pos


# --------------------------------------------------------------------------- the library path


def _read_with_library(path: Path, topics: set[str] | None) -> LogContents:
    """Messages through ``mcap``'s iteration (log-time order) and the library decoders."""
    from mcap.reader import make_reader

    source = str(path)
    reg = _Channels(source, topics)
    payloads: dict[str, list[bytes]] = {}
    logs: dict[str, list[int]] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            if summary is not None:
                for schema in summary.schemas.values():
                    reg.add_schema(schema)
                for channel in summary.channels.values():
                    reg.add_channel(channel)
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                if schema is not None:
                    reg.add_schema(schema)
                reg.add_channel(channel)
                cid = channel.id
                reg.count[cid] = reg.count.get(cid, 0) + 1
                reg.first[cid] = min(reg.first.get(cid, message.log_time), message.log_time)
                reg.last[cid] = max(reg.last.get(cid, message.log_time), message.log_time)
                decoder = reg.by_channel.get(cid)
                if decoder is not None:
                    payloads.setdefault(decoder.topic, []).append(message.data)
                    logs.setdefault(decoder.topic, []).append(message.log_time)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - McapError, CRC, zstd / lz4 errors: all bad input
        raise InputError(f"{source}: cannot read ({type(exc).__name__}: {exc})") from None
    reg.check_wanted()
    out: dict[str, dict[str, Any]] = {"imu": {}, "fix": {}, "twist": {}}
    for topic, decoder in reg.decoders.items():
        children: list[str] = []
        table, stamps, frame_ids = decode_with_library(
            decoder.msgtype, decoder.encoding, payloads.get(topic, []),
            schema_name=decoder.schema_name, schema_text=decoder.schema_text, child_frame_ids=children)
        msgs = build_messages(decoder.msgtype, topic, table, stamps,
                               np.asarray(logs.get(topic, []), dtype=np.int64),
                               frame_ids[0] if frame_ids else "", children[0] if children else "")
        kind = "imu" if decoder.msgtype == IMU_TYPE else "fix" if decoder.msgtype == FIX_TYPE else "twist"
        out[kind][topic] = msgs
    return LogContents(source=source, topics=reg.topic_infos(), imu=out["imu"], fix=out["fix"],
                       twist=out["twist"], warnings=tuple(reg.warnings))


# --------------------------------------------------------------------------- public API


def read_mcap(path: str | os.PathLike[str], topics: Iterable[str] | None = None, *,
              engine: Literal["fast", "library"] = "fast", memory: int | None = None) -> LogContents:
    """Read an MCAP file's topics and decode the supported ones.

    Parameters
    ----------
    path :
        The ``.mcap`` file (ROS 2 CDR and/or ROS 1 encoded channels).
    topics :
        Topics to decode; ``None`` decodes every topic of a supported type
        (``sensor_msgs/Imu``, ``sensor_msgs/NavSatFix``,
        ``geometry_msgs/TwistWithCovarianceStamped``, ``geometry_msgs/TwistStamped``,
        ``nav_msgs/Odometry``).
        ``LogContents.topics`` lists every topic of the file either way.
    engine :
        ``"fast"`` (bulk scan and decode) or ``"library"`` (``mcap``'s per-message iteration and
        the ``mcap_ros2`` / ``mcap_ros1`` decoders; for cross-checks).
    memory :
        Bytes (``[output] memory``): a topic's decoded messages holding more are written to a
        spill file (:mod:`navpp.spill`) chunk by chunk as they are decoded (an IMU topic's
        arrays are then views of it); None: they stay in memory.  The fast engine only.

    Returns
    -------
    LogContents
        Decoded messages per topic in log-time order (stable: file order among equal log
        times, as the ``mcap`` reader yields them), and warnings (e.g. where a cut-off recording
        stops).

    Raises
    ------
    InputError
        Not an MCAP file, empty file, a corrupted chunk (CRC mismatch, undecompressable data),
        a requested topic missing or of a type navpp does not decode, an undecodable message.
    """
    path = Path(path)
    size = _check_file(path)
    wanted = None if topics is None else {str(t) for t in ([topics] if isinstance(topics, str)
                                                          else topics)}
    if engine == "library":
        return _read_with_library(path, wanted)
    if engine != "fast":
        raise ValueError(f"engine must be 'fast' or 'library', not {engine!r}")
    return _FastReader(path, size, wanted, memory).run()


def list_topics(path: str | os.PathLike[str]) -> tuple[TopicInfo, ...]:
    """Every topic of an MCAP file with its type, encoding and message count.

    From the summary section when the file has one with statistics (cheap; the per-topic time
    span is then unknown: ``first_ns`` / ``last_ns`` None); otherwise the data section is
    scanned without decoding any message.
    """
    path = Path(path)
    size = _check_file(path)
    summary = _read_summary(path, size)
    if summary is not None and summary.statistics is not None:
        reg = _Channels(str(path), set())
        for schema in summary.schemas.values():
            reg.add_schema(schema)
        for channel in summary.channels.values():
            reg.add_channel(channel)
        reg.count.update(summary.statistics.channel_message_counts)
        return reg.topic_infos()
    return _FastReader(path, size, set()).run().topics
