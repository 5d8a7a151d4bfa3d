"""Read ROS bags with ``rosbags``: ROS 1 ``.bag`` files and ROS 2 bag directories.

Handled through :class:`rosbags.highlevel.AnyReader` (ROS 1 bags through navpp's own index
reader first, below): ROS 1 bags (uncompressed, bz2 or lz4
chunks), several ROS 1 files read as one (split bags, merged in log-time order), ROS 2 bag
directories with ``sqlite3`` (``.db3``) or ``mcap`` storage (file or message compression
too), and message definitions stored in the bag (no typestore entry is needed: AnyReader
registers the bag's own definitions; a ROS 2 bag without any, as Foxy/Galactic wrote them,
is decoded with the ROS 2 Humble definitions).

ROS 1 bags are read through navpp's own index reader (:mod:`navpp.io.ros1index`: index entries
straight into numpy arrays, a chunk at a time, where rosbags' reader builds an object per message
when it opens a bag), with rosbags for the stored message definitions; a bag that reader does not
take (damaged, unusual layout) is read by AnyReader, with a warning that says why.

Decoding: the raw payloads of each wanted topic (no message objects) go in batches -- a ROS 1
chunk at a time, or a few MB of rosbags' iteration -- to the vectorised decoder
:class:`navpp.io.messages.TopicDecoder` when the bag's definition of the type has the standard
layout, the decoded rows onto a spill file beyond the ``memory`` budget (:mod:`navpp.spill`), so
memory does not grow with the bag; otherwise each message is deserialised by rosbags and its
fields copied into the arrays.  Both give the same arrays (tested).

Every failure is an :class:`~navpp.errors.InputError` with one line naming the file, and the
topic and message where one is at fault.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path, PosixPath, WindowsPath
from typing import Any

import numpy as np

from navpp.errors import InputError, NavppError
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    ODOM_TYPE,
    SUPPORTED_TYPES,
    TWIST_COV_TYPE,
    TWIST_TYPE,
    FixMessages,
    ImuMessages,
    LogContents,
    TopicInfo,
    TwistMessages,
    normalise_type,
)
from navpp.io.ros1index import BagIndex, Connection, IndexRecord, Ros1IndexError, read_index

__all__ = ["list_topics", "read_rosbag"]

_BAG_MAGIC = b"#ROSBAG V"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_MCAP_MAGIC = b"\x89MCAP0\r\n"

#: Fields each supported type must have (dotted paths), checked before decoding.
_REQUIRED_FIELDS: dict[str, tuple[str, ...]] = {
    IMU_TYPE: ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id", "angular_velocity.x",
               "angular_velocity.y", "angular_velocity.z", "angular_velocity_covariance",
               "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z",
               "linear_acceleration_covariance"),
    FIX_TYPE: ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id", "status.status", "latitude",
               "longitude", "altitude", "position_covariance", "position_covariance_type"),
    TWIST_COV_TYPE: ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id", "twist.twist.linear.x",
                     "twist.twist.linear.y", "twist.twist.linear.z", "twist.covariance"),
    TWIST_TYPE: ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id", "twist.linear.x",
                 "twist.linear.y", "twist.linear.z", "twist.angular.z"),
    ODOM_TYPE: ("header.stamp.sec", "header.stamp.nanosec", "header.frame_id", "child_frame_id",
                "twist.twist.linear.x", "twist.twist.linear.y", "twist.twist.linear.z", "twist.twist.angular.z",
                "twist.covariance"),
}

Messages = ImuMessages | FixMessages | TwistMessages
#: Read ROS 1 bags through navpp's own index (:class:`_Ros1Bags`, :func:`_collect_ros1`); tests
#: switch it off to compare with rosbags' AnyReader.
_FAST_ROS1 = True

_RESULT_CLASS = {IMU_TYPE: ImuMessages, FIX_TYPE: FixMessages, TWIST_COV_TYPE: TwistMessages,
                 TWIST_TYPE: TwistMessages, ODOM_TYPE: TwistMessages}


# --------------------------------------------------------------------------- public API


def list_topics(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> tuple[TopicInfo, ...]:
    """Every topic of a bag (or of several ROS 1 bag files read together), cheaply.

    Counts come from the bag's index (ROS 1 chunk infos) or metadata (ROS 2
    ``metadata.yaml`` / MCAP summary); no message is decoded.  ``first_ns`` / ``last_ns``
    (log time) are filled for ROS 1 bags, whose index holds every message's time, and are
    None for ROS 2 bags, whose metadata only gives the bag's overall span.

    Raises
    ------
    InputError : not a bag, empty, truncated or damaged, unknown message definitions.
    """
    files = _check_paths(paths)
    infos = None
    if _ros1_fast(files):
        with suppress(Ros1IndexError), _Ros1Bags.open(files) as bags:
            infos = _topic_infos(bags)
    if infos is None:   # ROS 2, or a ROS 1 bag navpp's index reader leaves to rosbags
        with _open(files) as reader:
            infos = _topic_infos(reader)
    if sum(t.count for t in infos) == 0:
        raise InputError(f"{_label(files)}: the bag holds no messages")
    return infos


def read_rosbag(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                topics: Iterable[str] | None = None, *, memory: int | None = None) -> LogContents:
    """Decode a bag's IMU, NavSatFix, GNSS-velocity and wheel-odometry topics into numpy arrays.

    Parameters
    ----------
    paths : a ROS 1 ``.bag`` file, several of them (a split recording, merged by log time),
        or a ROS 2 bag directory (with ``metadata.yaml``; ``sqlite3`` or ``mcap`` storage).
    topics : the topics to decode; None decodes every topic of a supported type
        (``sensor_msgs/Imu``, ``sensor_msgs/NavSatFix``,
        ``geometry_msgs/TwistWithCovarianceStamped``, ``geometry_msgs/TwistStamped``,
        ``nav_msgs/Odometry``).
    memory : bytes (``[output] memory``): a topic's decoded messages holding more are written to
        a spill file (:mod:`navpp.spill`) as they are decoded, batch by batch (an IMU topic's
        arrays are then views of it); None: they stay in memory.

    Returns
    -------
    LogContents : ``topics`` lists every topic of the bag (decoded ones with their exact
        log-time span); ``imu`` / ``fix`` / ``twist`` hold the decoded topics (``twist``: the
        Twist and the Odometry topics).

    Raises
    ------
    InputError : one line naming the file (and topic / message): not a bag, empty, truncated
        or damaged, a ROS 2 directory without ``metadata.yaml``, an unknown topic or an
        unsupported type asked for, a message definition without the needed fields, or a
        message that cannot be decoded.
    """
    files = _check_paths(paths)
    label = _label(files)
    notes: list[str] = []
    size = _log_bytes(files)
    fast_error: str | None = None
    if _ros1_fast(files):
        try:
            with _Ros1Bags.open(files) as bags:
                return _read(label, size, bags, topics, memory, [])
        except Ros1IndexError as exc:     # its own notes are dropped: the fallback makes them again
            fast_error = str(exc)
            notes.append(f"{exc}; the bag is read with rosbags' reader instead (slower, and its index of every "
                         "message makes memory grow with the bag)")
    try:
        with _open(files) as reader:
            return _read(label, size, reader, topics, memory, notes)
    except InputError as exc:
        if fast_error is None:
            raise
        raise InputError(f"{exc} (navpp's own index reader: {fast_error})") from None


def _read(label: str, size: int, reader: Any, topics: Iterable[str] | None, memory: int | None,
          warnings: list[str]) -> LogContents:
    """:func:`read_rosbag` with ``reader`` open: an AnyReader, or :class:`_Ros1Bags` (ROS 1 bags
    through navpp's own index; it raises Ros1IndexError when the bag is not as expected)."""
    from navpp.io.messages import plausible_count

    infos = _topic_infos(reader)
    if sum(t.count for t in infos) == 0:
        raise InputError(f"{label}: the bag holds no messages")
    by_name = {t.topic: t for t in infos}
    wanted = _wanted_topics(label, infos, topics)
    std_store = _standard_typestore(reader)
    plans = {}
    for topic in wanted:
        plans[topic] = _plan(label, reader, std_store, topic, by_name[topic].msgtype, _connections(reader, topic),
                             warnings)
    sinks = {t: _Sink(label, t, plans[t], by_name[t].encoding, memory, plausible_count(by_name[t].count, size))
             for t in wanted}
    if isinstance(reader, _Ros1Bags):
        _collect_ros1(reader, wanted, sinks)
    else:
        _collect(label, reader, [c for t in wanted for c in _connections(reader, t)], sinks)
    imu: dict[str, ImuMessages] = {}
    fix: dict[str, FixMessages] = {}
    twist: dict[str, TwistMessages] = {}
    spans: dict[str, tuple[int, int | None, int | None]] = {}
    for topic in wanted:
        got = sinks.pop(topic)
        if reader.is2 and got.count == 0 and by_name[topic].count > 0:
            raise InputError(f"{label}: topic {topic!r}: metadata.yaml lists {by_name[topic].count} messages but "
                             "the bag's storage holds none (the metadata does not match the storage file)")
        msgs = got.result(reader)
        spans[topic] = (got.count, got.first, got.last)
        del got
        if isinstance(msgs, ImuMessages):
            imu[topic] = msgs
        elif isinstance(msgs, FixMessages):
            fix[topic] = msgs
        else:
            twist[topic] = msgs
    infos = tuple(
        TopicInfo(t.topic, t.msgtype, *spans[t.topic], t.encoding) if t.topic in spans else t
        for t in infos
    )
    return LogContents(label, infos, imu, fix, twist, tuple(warnings))


# --------------------------------------------------------------------------- opening


def _as_list(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    if isinstance(paths, (str, os.PathLike)):
        return [Path(paths)]
    return [Path(p) for p in paths]


def _label(files: Sequence[Path]) -> str:
    return str(files[0]) if len(files) == 1 else " + ".join(str(f) for f in files)


def _log_bytes(files: Sequence[Path]) -> int:
    """Bytes of the bag: its files' sizes (a ROS 2 bag directory's files inside it)."""
    total = 0
    for path in files:
        inside = [p for p in path.iterdir() if p.is_file()] if path.is_dir() else [path]
        total += sum(p.stat().st_size for p in inside)
    return total


def _head(path: Path, n: int = 16) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(n)
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _check_paths(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The bag paths, checked: they exist, are bags of one kind; ROS 1 files keep a ``.bag`` suffix
    for AnyReader (which tells ROS 1 from ROS 2 by it)."""
    files = _as_list(paths)
    if not files:
        raise InputError("no ROS bag given")
    kinds = []
    out: list[Path] = []
    for p in files:
        if not p.exists():
            raise InputError(f"{p}: no such file or directory")
        if p.is_dir():
            if not (p / "metadata.yaml").is_file():
                raise InputError(f"{p}: a ROS 2 bag directory needs metadata.yaml, and it has none (rosbag2 writes "
                                 f"it when a recording closes; `ros2 bag reindex {p}` recreates it)")
            kinds.append("ROS 2")
            out.append(_as_seen_by_anyreader(p, ros1=False))
            continue
        head = _head(p)
        if not head:
            raise InputError(f"{p}: empty file")
        if head.startswith(_BAG_MAGIC):
            kinds.append("ROS 1")
            out.append(_as_seen_by_anyreader(p, ros1=True))
        elif (head.startswith(_SQLITE_MAGIC) and p.suffix == ".db3") or (head.startswith(_MCAP_MAGIC)
                                                                        and p.suffix == ".mcap"):
            kinds.append("ROS 2")  # a ROS 2 bag's storage file on its own: rosbags reads it too
            out.append(p)
        else:
            raise InputError(f"{p}: not a ROS bag (expected a ROS 1 .bag file or a ROS 2 bag directory with "
                             "metadata.yaml)")
    if len(set(kinds)) > 1:
        raise InputError(f"{_label(files)}: ROS 1 and ROS 2 bags cannot be read together")
    return out


class _BagPosixPath(PosixPath):
    """A path that AnyReader takes for a ROS 1 bag (it tells ROS 1 from ROS 2 by the suffix)."""

    @property
    def suffix(self) -> str:
        return ".bag"


class _Ros2PosixPath(PosixPath):
    """A path that AnyReader takes for ROS 2 (e.g. a bag directory named ``drive.bag``)."""

    @property
    def suffix(self) -> str:
        return ""


class _BagWindowsPath(WindowsPath):
    @property
    def suffix(self) -> str:
        return ".bag"


class _Ros2WindowsPath(WindowsPath):
    @property
    def suffix(self) -> str:
        return ""


def _as_seen_by_anyreader(p: Path, ros1: bool) -> Path:
    """``p`` itself when its suffix tells AnyReader the right ROS version, else a view that does."""
    if (p.suffix == ".bag") == ros1:
        return p
    if os.name == "nt":
        return _BagWindowsPath(p) if ros1 else _Ros2WindowsPath(p)
    return _BagPosixPath(p) if ros1 else _Ros2PosixPath(p)


def _one_line(text: object, limit: int = 300) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _reason(exc: BaseException) -> str:
    msg = _one_line(exc.args[0] if len(exc.args) == 1 else exc) if exc.args else type(exc).__name__
    return msg.rstrip(".")


def _ros1_index_pos(path: Path) -> int | None:
    """``index_pos`` from a ROS 1 bag header (None when unreadable)."""
    try:
        with open(path, "rb") as f:
            if not f.readline().startswith(_BAG_MAGIC):
                return None
            (hlen,) = struct.unpack("<I", f.read(4))
            header = f.read(hlen)
        i = 0
        while i + 4 <= len(header):
            (flen,) = struct.unpack_from("<I", header, i)
            name, _, value = header[i + 4:i + 4 + flen].partition(b"=")
            if name == b"index_pos" and len(value) == 8:
                return int(struct.unpack("<Q", value)[0])
            i += 4 + flen
    except (OSError, struct.error):
        return None
    return None


def _open_error(path: Path, kind: str, exc: BaseException) -> InputError:
    reason = _reason(exc)
    if kind == "ROS 1":
        index_pos = _ros1_index_pos(path)
        size = path.stat().st_size
        if index_pos == 0:
            return InputError(f"{path}: ROS 1 bag has no index (its recording was not closed properly); "
                              f"run `rosbag reindex {path}` first")
        if index_pos is not None and index_pos >= size:
            return InputError(f"{path}: ROS 1 bag is truncated: its index should start at byte {index_pos} "
                              f"but the file has {size} bytes")
    if kind == "ROS 2" and path.is_dir():
        cut = _truncated_mcap(path)
        if cut is not None:
            return InputError(f"{cut}: the ROS 2 bag's MCAP storage file is truncated (no end magic; the recording "
                              f"was not closed); navpp reads a cut-off .mcap given on its own: process {cut.name}")
    if _is_definition_error(path, kind, exc):
        return InputError(f"{path}: the message definitions stored in the {kind} bag cannot be used: {reason}")
    return InputError(f"{path}: cannot read {kind} bag: {reason}")


def _truncated_mcap(bag_dir: Path) -> Path | None:
    """The first ``.mcap`` storage file of a ROS 2 bag directory that does not end with the MCAP
    magic (cut off while recording), or None."""
    for f in sorted(bag_dir.glob("*.mcap")):
        try:
            size = f.stat().st_size
            with open(f, "rb") as fh:
                fh.seek(max(size - len(_MCAP_MAGIC), 0))
                tail = fh.read(len(_MCAP_MAGIC))
        except OSError:
            continue
        if tail != _MCAP_MAGIC:
            return f
    return None


def _is_definition_error(path: Path, kind: str, exc: BaseException) -> bool:
    """A message-definition problem: a rosbags ``TypesysError`` (AnyReader re-raises it as an
    AnyReaderError, with the TypesysError as its context), or a stored definition that does not
    hash to the digest stored beside it (:func:`_digest_mismatch`)."""
    from rosbags.typesys import TypesysError

    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, TypesysError):
            return True
        seen = seen.__context__ if seen.__context__ is not seen else None
    return _digest_mismatch(path, kind == "ROS 1")


#: The separator between the definitions of a ROS 2 IDL message-definition bundle.
_IDL_SEPARATOR = "=" * 80 + "\n"


def _digest_mismatch(path: Path, ros1: bool) -> bool:
    """True when a message definition stored in the bag at ``path`` does not hash to the digest
    stored with it (ROS 1: the MD5 sum; ROS 2: the RIHS01 type hash), the check rosbags'
    AnyReader makes when it opens a bag; rosbags reports it as a plain AnyReaderError, so it is
    redone here with rosbags' typesys.  False when the bag cannot be opened this way."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    try:
        with (Reader1 if ros1 else Reader2)(path) as reader:
            stored = [c for c in reader.connections if c.msgdef.format != MessageDefinitionFormat.NONE]
            types: dict[str, Any] = {}
            for conn in stored:
                text = conn.msgdef.data
                if conn.msgdef.format == MessageDefinitionFormat.MSG:
                    types.update(get_types_from_msg(text, conn.msgtype))
                else:
                    parts = text.split(_IDL_SEPARATOR)[1:] if text.startswith(f"{_IDL_SEPARATOR}IDL: ") else [text]
                    for part in parts:
                        types.update(get_types_from_idl(part.split("\n", 1)[1] if part.startswith("IDL: ") else part))
            store = get_typestore(Stores.EMPTY)
            store.register(types)
            for conn in stored:
                if conn.digest:
                    digest = store.generate_msgdef(conn.msgtype)[1] if ros1 else store.hash_rihs01(conn.msgtype)
                    if digest != conn.digest:
                        return True
    except Exception:  # noqa: BLE001 - a bag this cannot open is not a digest mismatch
        return False
    return False


@contextmanager
def _open(files: Sequence[Path]) -> Iterator[Any]:
    """An open AnyReader over ``files``; every failure to open becomes an InputError."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    is2 = any(f.suffix != ".bag" for f in files)
    default = get_typestore(Stores.ROS2_HUMBLE if is2 else Stores.ROS1_NOETIC)
    try:
        reader = AnyReader(list(files), default_typestore=default)
        reader.open()
    except NavppError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds for damaged files (ReaderError, KeyError...)
        raise _first_bad(files, is2, exc) from None
    try:
        if is2:
            _check_ros2_connections(files, reader)
        yield reader
    finally:
        with suppress(Exception):  # closing a damaged bag must not hide the real error
            reader.close()


def _ros1_fast(files: Sequence[Path]) -> bool:
    """ROS 1 bags (as :func:`_check_paths` gives them) to be read through navpp's own index."""
    return _FAST_ROS1 and all(f.suffix == ".bag" for f in files)


@contextmanager
def _naming(path: Path) -> Iterator[None]:
    """A Ros1IndexError or OSError raised in the block, as a Ros1IndexError whose line starts with
    ``path``."""
    try:
        yield
    except Ros1IndexError as exc:
        raise Ros1IndexError(f"{path}: {exc}") from None
    except OSError as exc:
        raise Ros1IndexError(f"{path}: cannot read: {exc.strerror or exc}") from None


class _Ros1Bags:
    """ROS 1 bag files read through navpp's own index (:mod:`navpp.io.ros1index`), with what
    :func:`_read` uses of an AnyReader: the topics, and the message definitions stored in the
    bags as a rosbags typestore (for the layout checks and message-by-message decoding), checked
    against their MD5 sums as AnyReader checks them.  :meth:`open` raises Ros1IndexError naming
    the file when a bag is not as expected (rosbags then reads it and reports any damage)."""

    is2 = False

    def __init__(self, bags: list[BagIndex]) -> None:
        self.bags = bags
        conns = [(i, c) for i, bag in enumerate(bags) for c in bag.connections]
        #: topic -> [(file number, connection)], file and record order (AnyReader's)
        self.topics: dict[str, list[tuple[int, Connection]]] = {}
        for i, c in sorted(conns, key=lambda ic: ic[1].topic):
            self.topics.setdefault(c.topic, []).append((i, c))
        self.counts = [bag.counts() for bag in bags]
        self.typestore = self._typestore([c for _, c in conns])

    @classmethod
    @contextmanager
    def open(cls, files: Sequence[Path]) -> Iterator[_Ros1Bags]:
        bags: list[BagIndex] = []
        try:
            for path in files:
                with _naming(path):
                    bags.append(read_index(path))
            yield cls(bags)
        finally:
            for bag in bags:
                bag.close()

    def _typestore(self, conns: Sequence[Connection]) -> Any:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        label = _label([b.path for b in self.bags])
        try:
            types: dict[str, Any] = {}
            for c in conns:
                types.update(get_types_from_msg(c.definition, c.msgtype))
            store = get_typestore(Stores.EMPTY)
            store.register(types)
            digest_ok = all(store.generate_msgdef(c.msgtype)[1] == c.md5sum for c in conns if c.md5sum)
        except Exception as exc:  # noqa: BLE001 - rosbags' typesys raises several kinds; rosbags reports them
            raise Ros1IndexError(f"{label}: the stored message definitions cannot be used ({_reason(exc)})") from None
        if not digest_ok:
            raise Ros1IndexError(f"{label}: a stored message definition does not match its MD5 sum")
        return store

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_ros1(raw, msgtype)

    def topic_infos(self) -> tuple[TopicInfo, ...]:
        """Every topic as AnyReader's topics give it: counts from the chunk infos, the first and
        last log time from the index entries (of the few chunks that can hold them)."""
        infos = []
        for name, conns in self.topics.items():
            count = sum(self.counts[i][c.conn] for i, c in conns)
            infos.append(TopicInfo(name, _joined_type(c.msgtype for _, c in conns), count, *self._span(conns),
                                   "ros1"))
        return tuple(infos)

    def _span(self, conns: Sequence[tuple[int, Connection]]) -> tuple[int | None, int | None]:
        """(first, last) log time (ns) of the connections' messages, None without any: the index
        entries of the chunks, taken earliest start first (latest end first), until no chunk left
        can hold an earlier (later) message."""
        ids = {(i, c.conn) for i, c in conns}
        held = [(chunk, r, self.bags[i]) for i, bag in enumerate(self.bags) for chunk in bag.chunks
                for r in chunk.records if (i, r.conn) in ids and r.count]
        first = last = None
        for chunk, r, bag in sorted(held, key=lambda h: h[0].start_ns):
            if first is not None and chunk.start_ns >= first:
                break
            t = int(self._times(bag, r, chunk).min())
            first = t if first is None else min(first, t)
        for chunk, r, bag in sorted(held, key=lambda h: -h[0].end_ns):
            if last is not None and chunk.end_ns <= last:
                break
            t = int(self._times(bag, r, chunk).max())
            last = t if last is None else max(last, t)
        return first, last

    @staticmethod
    def _times(bag: BagIndex, record: IndexRecord, chunk: Any) -> np.ndarray:
        """The log times (ns) of an index-data record; Ros1IndexError naming the file."""
        with _naming(bag.path):
            return bag.entries(record, chunk)[0]


def _check_ros2_connections(files: Sequence[Path], reader: Any) -> None:
    """InputError naming metadata.yaml when a topic entry lacks a usable name, type or count
    (rosbags takes damaged metadata as it is and fails later with a TypeError)."""
    where = files[0] / "metadata.yaml" if files[0].is_dir() else files[0]
    for i, conn in enumerate(reader.connections):
        checks = (("name", conn.topic, isinstance(conn.topic, str) and bool(conn.topic)),
                  ("type", conn.msgtype, isinstance(conn.msgtype, str) and "/" in conn.msgtype),
                  ("message_count", conn.msgcount,
                   isinstance(conn.msgcount, int) and not isinstance(conn.msgcount, bool) and conn.msgcount >= 0))
        for field, value, ok in checks:
            if not ok:
                raise InputError(f"{where}: topic entry {i + 1} has an invalid {field} ({_one_line(repr(value), 60)}); "
                                 "the bag's metadata is damaged")
    fmt = [getattr(c.ext, "serialization_format", None) for c in reader.connections]
    for i, value in enumerate(fmt):
        if not isinstance(value, str):
            raise InputError(f"{where}: topic entry {i + 1} has an invalid serialization_format "
                             f"({_one_line(repr(value), 60)}); the bag's metadata is damaged")


def _first_bad(files: Sequence[Path], is2: bool, exc: BaseException) -> InputError:
    """Name the file that cannot be opened (with several files, open each to find it)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    kind = "ROS 2" if is2 else "ROS 1"
    if len(files) > 1:
        default = get_typestore(Stores.ROS2_HUMBLE if is2 else Stores.ROS1_NOETIC)
        for f in files:
            try:
                with AnyReader([f], default_typestore=default):
                    pass
            except Exception as one:  # noqa: BLE001 - reported below
                return _open_error(f, kind, one)
        label = _label(files)
        return InputError(f"{label}: cannot read these {kind} bags together: {_reason(exc)}")
    return _open_error(files[0], kind, exc)


# --------------------------------------------------------------------------- topics


def _connections(reader: Any, topic: str) -> list[Any]:
    """The connections of ``topic`` (rosbags' or :class:`navpp.io.ros1index.Connection`), in file
    and record order."""
    if isinstance(reader, _Ros1Bags):
        return [c for _, c in reader.topics[topic]]
    return list(reader.topics[topic].connections)


def _joined_type(msgtypes: Iterable[str]) -> str:
    """A topic's message type as its connections give it, normalised; several joined by commas."""
    return ",".join(sorted({normalise_type(m) for m in msgtypes}))


def _topic_infos(reader: Any) -> tuple[TopicInfo, ...]:
    if isinstance(reader, _Ros1Bags):
        return reader.topic_infos()
    infos = []
    for name, info in reader.topics.items():
        conns = info.connections
        msgtype = _joined_type(c.msgtype for c in conns)
        if reader.is2:
            encs = sorted({getattr(c.ext, "serialization_format", "") or "" for c in conns})
            encoding = ",".join(encs)
        else:
            encoding = "ros1"
        first = last = None
        if not reader.is2:
            times = [(idx[0].time, idx[-1].time) for c in conns if (idx := c.owner.indexes.get(c.id))]
            if times:
                first, last = min(t[0] for t in times), max(t[1] for t in times)
        infos.append(TopicInfo(name, msgtype, int(info.msgcount), first, last, encoding))
    return tuple(infos)


def _wanted_topics(label: str, infos: Sequence[TopicInfo], topics: Iterable[str] | None) -> list[str]:
    if topics is None:
        return [t.topic for t in infos if t.msgtype in SUPPORTED_TYPES]
    by_name = {t.topic: t for t in infos}
    wanted: list[str] = []
    for topic in topics:
        if topic not in by_name:
            raise InputError(f"{label}: no topic {topic!r}; topics: {', '.join(sorted(by_name)) or 'none'}")
        if by_name[topic].msgtype not in SUPPORTED_TYPES:
            raise InputError(f"{label}: topic {topic!r} is {by_name[topic].msgtype}, which navpp does not decode "
                             f"(supported: {', '.join(SUPPORTED_TYPES)})")
        if topic not in wanted:
            wanted.append(topic)
    return wanted


# --------------------------------------------------------------------------- message layouts


def _standard_typestore(reader: Any) -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE if reader.is2 else Stores.ROS1_NOETIC)


def _shape(ts: Any, msgtype: str, depth: int = 0) -> tuple:
    """Field names and types of ``msgtype``, nested types expanded (constants ignored)."""
    from rosbags.typesys.base import Nodetype

    if depth > 20:
        raise ValueError(f"message type {msgtype} nests too deeply")

    def node(desc: tuple) -> tuple:
        kind, arg = desc
        if kind == Nodetype.BASE:
            return ("base", arg[0])
        if kind == Nodetype.NAME:
            return ("msg", _shape(ts, arg, depth + 1))
        if kind == Nodetype.ARRAY:
            return ("array", node(arg[0]), arg[1])
        return ("sequence", node(arg[0]))

    return tuple((name, node(desc)) for name, desc in ts.fielddefs[msgtype][1])


def _has_field(shape: tuple, dotted: str) -> bool:
    fields = dict(shape)
    head, _, rest = dotted.partition(".")
    if head not in fields:
        return False
    if not rest:
        return True
    kind = fields[head]
    return kind[0] == "msg" and _has_field(kind[1], rest)


def _plan(label: str, reader: Any, std_store: Any, topic: str, msgtype: str, conns: Sequence[Any],
          warnings: list[str]) -> tuple[str, str, bool]:
    """(normalised type, rosbags type name, standard layout?) of a topic, validated before decoding."""
    rosnames = {c.msgtype for c in conns}
    if len(rosnames) != 1:
        raise InputError(f"{label}: topic {topic!r} carries several message types ({', '.join(sorted(rosnames))})")
    rosname = rosnames.pop()
    try:
        shape = _shape(reader.typestore, rosname)
    except (KeyError, ValueError) as exc:
        raise InputError(f"{label}: topic {topic!r}: the bag has no usable message definition for {msgtype} "
                         f"({_reason(exc)})") from None
    missing = [f for f in _REQUIRED_FIELDS[msgtype] if not _has_field(shape, f)]
    if missing:
        raise InputError(f"{label}: topic {topic!r}: the bag's definition of {msgtype} has no field "
                         f"{', '.join(missing)}")
    standard = shape == _shape(std_store, rosname)
    if not standard:
        warnings.append(f"{label}: topic {topic!r}: the bag's definition of {msgtype} differs from the standard "
                        "one; decoded message by message")
    return msgtype, rosname, standard


# --------------------------------------------------------------------------- reading and decoding


@dataclass
class _Payloads:
    """One topic's raw messages, in order: message ``i`` is ``buffer[starts[i]:starts[i] + lengths[i]]``
    (one buffer instead of a Python object per message), with its log time ``log_ns[i]``."""

    buffer: bytearray
    starts: np.ndarray
    lengths: np.ndarray
    log_ns: np.ndarray

    def __len__(self) -> int:
        return int(self.starts.shape[0])

    def message(self, i: int) -> bytes:
        s = int(self.starts[i])
        return bytes(self.buffer[s:s + int(self.lengths[i])])


def _gathered(buffer: Any, starts: np.ndarray, lengths: np.ndarray) -> tuple[bytearray, np.ndarray]:
    """Messages ``buffer[starts[i]:starts[i] + lengths[i]]`` copied into one buffer of their own,
    one after the other, with their starts in it."""
    lengths = np.asarray(lengths, np.int64)
    ends = np.cumsum(lengths)
    if ends.size == 0:
        return bytearray(), ends
    take = np.arange(int(ends[-1]), dtype=np.int64) + np.repeat(starts - (ends - lengths), lengths)
    return bytearray(memoryview(np.frombuffer(buffer, dtype=np.uint8)[take])), ends - lengths


class _Sink:
    """One topic's messages as the bag is read, piece by piece in log-time order: decoded as they
    come (:class:`navpp.io.messages.TopicDecoder`, onto a spill file beyond ``memory`` bytes) when
    the bag's definition has the standard layout, else kept as payloads for rosbags'
    per-message decoding (:func:`_decode_each`); the count and first / last log time (ns)."""

    def __init__(self, label: str, topic: str, plan: tuple[str, str, bool], encoding: str, memory: int | None,
                 expected: int) -> None:
        self.label, self.topic = label, topic
        self.msgtype, self.rosname, standard = plan
        decoder = _bulk_decoder() if standard else None
        self.decoder = None if decoder is None else self._checked(
            lambda: decoder(topic, self.msgtype, encoding, source=label, memory=memory, expected=expected))
        self.parts: list[_Payloads] = []
        self.count = 0
        self.first: int | None = None
        self.last: int | None = None

    def _checked(self, call: Callable[[], Any]) -> Any:
        """``call()``, its InputError naming the bag first."""
        try:
            return call()
        except InputError as exc:
            text = str(exc)
            raise InputError(text if text.startswith(self.label) else f"{self.label}: {text}") from None

    def add(self, buffer: Any, starts: np.ndarray, lengths: np.ndarray, log_ns: np.ndarray) -> None:
        """Messages ``buffer[starts[i]:starts[i] + lengths[i]]`` with their log times (ns), in order."""
        n = int(starts.shape[0])
        if n == 0:
            return
        decoder = self.decoder
        if decoder is not None:
            self._checked(lambda: decoder.add(buffer, starts, lengths, log_ns))
        else:
            data, data_starts = _gathered(buffer, starts, lengths)
            self.parts.append(_Payloads(data, data_starts, np.asarray(lengths, np.int64), np.array(log_ns)))
        if self.first is None:
            self.first = int(log_ns[0])
        self.last = int(log_ns[-1])
        self.count += n

    def result(self, reader: Any) -> Messages:
        if self.decoder is not None and self.count:
            out = self.decoder.result()
            if not isinstance(out, _RESULT_CLASS[self.msgtype]):
                raise TypeError(f"the decoder returned {type(out).__name__} for {self.msgtype}")
            return out
        parts = self.parts or [_Payloads(bytearray(), *(np.zeros(0, np.int64),) * 3)]
        base = np.cumsum([0] + [len(p.buffer) for p in parts[:-1]])
        payloads = _Payloads(bytearray().join(p.buffer for p in parts),
                             np.concatenate([p.starts + b for p, b in zip(parts, base.tolist())]),
                             np.concatenate([p.lengths for p in parts]), np.concatenate([p.log_ns for p in parts]))
        self.parts = []
        return _decode_each(self.label, reader, self.topic, self.msgtype, self.rosname, payloads)


#: Bytes of a topic's payloads gathered from rosbags' iteration before they are decoded.
_BATCH_BYTES = 4 << 20


def _collect(label: str, reader: Any, conns: Sequence[Any], sinks: dict[str, _Sink]) -> None:
    """The wanted topics' payloads and log times in one pass over the bag (rosbags' iteration,
    log-time order), handed to their sinks in batches of about :data:`_BATCH_BYTES`."""
    acc: dict[str, tuple[list[int], list[int], bytearray]] = {t: ([], [], bytearray()) for t in sinks}
    last: list[Any] = [None, None]

    def flush(topic: str) -> None:
        times, lengths, buf = acc[topic]
        lens = np.array(lengths, dtype=np.int64)
        starts = np.zeros(lens.size, dtype=np.int64)
        np.cumsum(lens[:-1], out=starts[1:])
        sinks[topic].add(buf, starts, lens, np.array(times, dtype=np.int64))
        acc[topic] = ([], [], bytearray())

    if conns:
        try:
            for conn, t, data in reader.messages(connections=conns):
                times, lengths, buf = acc[conn.topic]
                times.append(t)
                lengths.append(len(data))
                buf += data
                last[0] = conn.topic
                last[1] = t
                if len(buf) >= _BATCH_BYTES:
                    flush(conn.topic)
        except NavppError:
            raise
        except Exception as exc:  # noqa: BLE001 - damaged chunks / pages: rosbags' backends raise many kinds
            topic, t = last
            n = sum(len(v[0]) + sinks[k].count for k, v in acc.items())
            where = (f"after message {sinks[topic].count + len(acc[topic][0]) - 1} of topic {topic!r} (log time "
                     f"{t * 1e-9:.9f} s)" if topic is not None else "before the first message")
            raise InputError(f"{label}: cannot read the bag {where}, {n} messages read: {_reason(exc)} "
                             "(truncated or damaged file?)") from None
    for topic in sinks:
        flush(topic)


#: Length of a ROS 1 message-data record header: the fields op (8 bytes with its length
#: prefix), conn (13) and time (17), in any order.
_ROS1_MSG_HEADER_LEN = 38
_ROS1_OP_FIELD_POS = (0, 13, 17, 30)  # where the op field can start inside that header
_ROS1_OP_MSG_DATA = np.frombuffer(b"\x04\x00\x00\x00op=\x02", dtype=np.uint8)  # the op field of a message record


def _ros1_payloads(b: np.ndarray, offs: np.ndarray, chunk_pos: int) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of the payloads of the message-data records at byte offsets ``offs`` of an
    uncompressed chunk ``b``, found from the record headers with numpy, not record by record: each
    record's header length, op field and payload length taken in one gather of its first bytes."""
    head = 4 + _ROS1_MSG_HEADER_LEN + 4   # header length, header, payload length
    if offs.size and offs.max() + head > b.size:
        raise Ros1IndexError(f"chunk at byte {chunk_pos}: an index entry points past the chunk's end")
    first = b[offs[:, None] + np.arange(head)]

    def u32(col: int) -> np.ndarray:
        return np.ascontiguousarray(first[:, col:col + 4]).view("<u4")[:, 0].astype(np.int64)

    is_msg = np.zeros(offs.size, dtype=bool)
    for p in _ROS1_OP_FIELD_POS:
        is_msg |= (first[:, 4 + p:12 + p] == _ROS1_OP_MSG_DATA).all(axis=1)
    if not (is_msg & (u32(0) == _ROS1_MSG_HEADER_LEN)).all():
        raise Ros1IndexError(f"chunk at byte {chunk_pos}: an index entry does not point at a message-data record "
                             "of the usual layout")
    lengths = u32(head - 4)
    starts = offs + head
    if np.any(starts + lengths > b.size):
        raise Ros1IndexError(f"chunk at byte {chunk_pos}: a message runs past the chunk's end")
    return starts, lengths


#: A log time (ns) after every other: no later chunk holds the topic.
_NO_LATER_NS = np.iinfo(np.int64).max


class _Ros1Order:
    """One topic's messages handed to its sink in AnyReader's order -- by log time, ties by
    connection (file, then record order), chunk and index entry -- while the chunks are read one
    by one in file order.  A message is handed on once no later chunk can hold an earlier one of
    the topic (its log time is before ``bound``, the earliest start of a later chunk holding the
    topic); the others are held back, copied out of their chunk.  Recorders write chunks in log
    time order, so only messages at a chunk boundary's very time are ever held; a bag whose log
    time goes back across chunks holds more, until the chunks it overlaps are read."""

    def __init__(self, sink: _Sink) -> None:
        self.sink = sink
        self.held: tuple[bytearray, np.ndarray, np.ndarray, tuple[np.ndarray, ...]] | None = None

    def add(self, b: Any, starts: np.ndarray, lengths: np.ndarray, keys: tuple[np.ndarray, ...], bound: int) -> None:
        """A chunk's messages ``b[starts[i]:starts[i] + lengths[i]]`` in key order; ``keys``: log time
        (ns), connection, chunk and entry numbers, each int64."""
        if self.held is not None:
            held_b, held_starts, held_lengths, held_keys = self.held
            new_b, new_starts = _gathered(b, starts, lengths)
            b = held_b + new_b
            starts = np.concatenate([held_starts, new_starts + len(held_b)])
            lengths = np.concatenate([held_lengths, lengths])
            keys = tuple(np.concatenate(pair) for pair in zip(held_keys, keys))
            order = np.lexsort(keys[::-1])
            starts, lengths, keys = starts[order], lengths[order], tuple(k[order] for k in keys)
        cut = int(np.searchsorted(keys[0], bound))
        self.sink.add(b, starts[:cut], lengths[:cut], keys[0][:cut])
        if cut == starts.size:
            self.held = None
        else:
            rest_b, rest_starts = _gathered(b, starts[cut:], lengths[cut:])
            self.held = (rest_b, rest_starts, lengths[cut:], tuple(k[cut:] for k in keys))

    def flush(self) -> None:
        if self.held is not None:
            empty = np.zeros(0, np.int64)
            self.add(bytearray(), empty, empty, (empty,) * 4, _NO_LATER_NS)


def _collect_ros1(bags: _Ros1Bags, wanted: Sequence[str], sinks: dict[str, _Sink]) -> None:
    """The wanted topics' payloads from ROS 1 bags through navpp's own index, chunk by chunk.

    Each chunk holding a wanted topic is read and decompressed once; its index entries come
    into numpy arrays and its message records are located with numpy (:func:`_ros1_payloads`);
    each topic's messages go to its sink straight from the chunk, in AnyReader's order
    (:class:`_Ros1Order`), so memory holds a chunk at a time besides the sinks' tables.
    Raises Ros1IndexError when the bag is not as expected (the caller reads it with rosbags).
    """
    where: dict[tuple[int, int], tuple[str, int]] = {}  # (file, conn id) -> (topic, connection number)
    for topic in wanted:
        for k, (i, c) in enumerate(bags.topics[topic]):
            where[(i, c.conn)] = (topic, k)
    chunks = [(i, chunk) for i, bag in enumerate(bags.bags) for chunk in bag.chunks]
    mine: list[dict[str, list[tuple[int, IndexRecord]]]] = []
    for i, chunk in chunks:
        here: dict[str, list[tuple[int, IndexRecord]]] = {}
        for r in chunk.records:
            if (hit := where.get((i, r.conn))) is not None and r.count:
                here.setdefault(hit[0], []).append((hit[1], r))
        mine.append(here)
    bounds = []     # per chunk: each topic's earliest log time (ns) in the chunks after it
    later = dict.fromkeys(wanted, int(_NO_LATER_NS))
    for (_, chunk), here in zip(reversed(chunks), reversed(mine)):
        bounds.append(dict(later))
        for topic in here:
            later[topic] = min(later[topic], chunk.start_ns)
    bounds.reverse()
    order = {topic: _Ros1Order(sinks[topic]) for topic in wanted}
    for n, ((i, chunk), here) in enumerate(zip(chunks, mine)):
        if not here:
            continue
        bag = bags.bags[i]
        with _naming(bag.path):
            b = np.frombuffer(bag.chunk_data(chunk), dtype=np.uint8)
            for topic, records in here.items():
                entries = [bag.entries(r, chunk) for _, r in records]
                log_ns = np.concatenate([e[0] for e in entries])
                conn = np.concatenate([np.full(r.count, k, dtype=np.int64) for k, r in records])
                entry = np.arange(log_ns.size, dtype=np.int64)
                s = np.lexsort((entry, conn, log_ns))
                starts, lengths = _ros1_payloads(b, np.concatenate([e[1] for e in entries])[s], chunk.pos)
                keys = (log_ns[s], conn[s], np.full(s.size, n, dtype=np.int64), entry[s])
                order[topic].add(b, starts, lengths, keys, bounds[n][topic])
        del b
    for topic in wanted:
        order[topic].flush()


def _bulk_decoder() -> Callable[..., Any] | None:
    """:class:`navpp.io.messages.TopicDecoder` (the bulk decoder; tests replace it with None to
    decode every message with rosbags)."""
    from navpp.io.messages import TopicDecoder

    return TopicDecoder


def _decode_each(label: str, reader: Any, topic: str, msgtype: str, rosname: str, payloads: _Payloads) -> Messages:
    """The library path: rosbags deserialises each message; fields are copied into arrays."""
    msgs = []
    log_ns = payloads.log_ns
    for i in range(len(payloads)):
        try:
            msgs.append(reader.deserialize(payloads.message(i), rosname))
        except Exception as exc:  # noqa: BLE001 - rosbags raises several kinds for bad payloads
            raise InputError(f"{label}: topic {topic!r} message {i} (log time {log_ns[i] * 1e-9:.9f} s): cannot "
                             f"decode {msgtype}: {_reason(exc)}") from None
    n = len(msgs)
    stamp_ns = np.fromiter((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs),
                           dtype=np.int64, count=n)
    frame_id = msgs[0].header.frame_id if msgs else ""

    def vec(get: Callable[[Any], Any]) -> np.ndarray:
        return np.array([(v.x, v.y, v.z) for v in map(get, msgs)], dtype=np.float64).reshape(n, 3)

    def scalar(get: Callable[[Any], Any], dtype: Any) -> np.ndarray:
        return np.fromiter(map(get, msgs), dtype=dtype, count=n)

    if msgtype == IMU_TYPE:
        return ImuMessages(
            topic, stamp_ns, log_ns,
            gyro=vec(lambda m: m.angular_velocity),
            accel=vec(lambda m: m.linear_acceleration),
            gyro_cov0=scalar(lambda m: m.angular_velocity_covariance[0], np.float64),
            accel_cov0=scalar(lambda m: m.linear_acceleration_covariance[0], np.float64),
            frame_id=frame_id,
        )
    if msgtype == FIX_TYPE:
        cov = np.array([m.position_covariance for m in msgs], dtype=np.float64).reshape(n, -1 if n else 9)
        if cov.shape[1] != 9:
            raise InputError(f"{label}: topic {topic!r}: position_covariance has {cov.shape[1]} elements, expected 9")
        return FixMessages(
            topic, stamp_ns, log_ns,
            status=scalar(lambda m: m.status.status, np.int8),
            lat_deg=scalar(lambda m: m.latitude, np.float64),
            lon_deg=scalar(lambda m: m.longitude, np.float64),
            alt=scalar(lambda m: m.altitude, np.float64),
            cov=cov,
            cov_type=scalar(lambda m: m.position_covariance_type, np.uint8),
            frame_id=frame_id,
        )
    if msgtype in (TWIST_COV_TYPE, ODOM_TYPE):
        cov = np.array([m.twist.covariance for m in msgs], dtype=np.float64).reshape(n, -1 if n else 36)
        if cov.shape[1] != 36:
            raise InputError(f"{label}: topic {topic!r}: twist.covariance has {cov.shape[1]} elements, expected 36")
        child = str(msgs[0].child_frame_id) if msgs and msgtype == ODOM_TYPE else ""
        return TwistMessages(topic, stamp_ns, log_ns, vel=vec(lambda m: m.twist.twist.linear),
                             cov_diag=np.ascontiguousarray(cov[:, [0, 7, 14]]), frame_id=frame_id,
                             angular=vec(lambda m: m.twist.twist.angular), var_yaw_rate=cov[:, 35].copy(),
                             child_frame_id=child)
    return TwistMessages(topic, stamp_ns, log_ns, vel=vec(lambda m: m.twist.linear), cov_diag=None,
                         frame_id=frame_id, angular=vec(lambda m: m.twist.angular))
