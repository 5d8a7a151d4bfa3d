"""Bulk decoding of serialized ROS messages into the arrays of :mod:`navpp.io.ros`.

Decodes ``sensor_msgs/Imu``, ``sensor_msgs/NavSatFix``,
``geometry_msgs/TwistWithCovarianceStamped`` and ``geometry_msgs/TwistStamped`` payloads in
ROS 2 CDR (little or big endian, chosen per message by the 4-byte encapsulation header) and
ROS 1 serialization, without building a Python object per message.

The layout of these messages is fixed except for ``header.frame_id``, a string near the start:

* ROS 2 CDR: ``[encapsulation 4][stamp.sec i32][stamp.nanosec u32][len u32][frame_id len bytes
  incl. NUL]`` then the fixed fields, each aligned to its own size *relative to the byte after
  the encapsulation header* (so the padding after frame_id depends on its length);
* ROS 1: ``[seq u32][stamp.secs u32][stamp.nsecs u32][len u32][frame_id len bytes]`` then the
  fixed fields, packed (no alignment).

Both put the frame_id length at byte 12.  One numba kernel (:func:`_decode_kernel`) walks the
fixed part of every message from a ``(buffer, starts, lengths)`` description of the payloads,
computing each message's field offsets from its own frame_id length and copying the raw bits
of the wanted fields (byte-swapped where the message is big endian) into a ``uint64`` table
that is then viewed as ``float64``: values are bit-exact (NaN payloads included).

Falls back to the library decoders (``mcap_ros2`` / ``mcap_ros1`` generated from the schema
text when there is one, otherwise ``rosbags``' typestores) for

* a whole topic whose schema text differs from the standard definition (checked field by
  field in :func:`schema_is_standard`), and
* single messages whose length does not match the standard layout.

Payloads with a CDR encapsulation other than plain CDR (e.g. XCDR2 or parameter lists) are an
:class:`~navpp.errors.InputError`: neither decoder reads them correctly.

Entry points: :func:`decode` (one topic's payloads at once) and :class:`TopicDecoder`
(accumulates a topic piece by piece, e.g. chunk by chunk of an MCAP file).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from navpp import jitmode, spill
from navpp.errors import InputError
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    ODOM_TYPE,
    SUPPORTED_TYPES,
    TWIST_COV_TYPE,
    TWIST_TYPE,
    FixMessages,
    ImuMessages,
    TwistMessages,
    normalise_type,
)
from navpp.kernel import njit

__all__ = [
    "ENCODINGS",
    "Messages",
    "Payloads",
    "TopicDecoder",
    "build_messages",
    "decode",
    "decode_with_library",
    "schema_is_standard",
]

Messages = ImuMessages | FixMessages | TwistMessages
#: A topic's payloads: a sequence of bytes-like objects, or ``(buffer, starts, lengths)``
#: with ``buffer`` bytes-like / uint8 array and ``starts``, ``lengths`` integer arrays (bytes).
Payloads = Sequence[Any] | tuple[Any, np.ndarray, np.ndarray]

#: Message encodings decoded here (MCAP channel ``message_encoding`` names).
ENCODINGS = ("cdr", "ros1")

# Per-message flags set by the kernel.
_OK = 0
_SHORT = 1          # shorter than the standard layout
_LONG = 2           # longer than the standard layout (beyond CDR's trailing padding)
_ENCAPSULATION = 3  # CDR encapsulation kind other than CDR_BE / CDR_LE
_FLAG_TEXT = {
    _SHORT: "shorter than the standard layout",
    _LONG: "longer than the standard layout",
}
_CDR_MAX_TRAILING_PADDING = 3  # XCDR1 writers may pad the payload to a multiple of 4 bytes

# --------------------------------------------------------------------------- layouts


@dataclass(frozen=True)
class _Field:
    """A run of ``count`` primitives of ``size`` bytes; its first ``n_out`` elements go to the
    output table from column ``col`` (``col`` -1: skipped)."""

    name: str
    size: int
    count: int
    col: int = -1
    n_out: int = 0


@dataclass(frozen=True)
class _Layout:
    """The fixed part of a message type after ``header`` and the output table it fills."""

    fields: tuple[_Field, ...]
    n_cols: int
    #: Columns holding integers (zero-extended raw bits) rather than float64 bits.
    int_cols: tuple[int, ...] = ()

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(size, count, col, n_out) as int64 arrays for the kernel."""
        return tuple(np.array([getattr(f, a) for f in self.fields], dtype=np.int64)
                     for a in ("size", "count", "col", "n_out"))  # type: ignore[return-value]


_LAYOUTS: dict[str, _Layout] = {
    IMU_TYPE: _Layout((
        _Field("orientation", 8, 4),
        _Field("orientation_covariance", 8, 9),
        _Field("angular_velocity", 8, 3, 0, 3),
        _Field("angular_velocity_covariance", 8, 9, 3, 1),
        _Field("linear_acceleration", 8, 3, 4, 3),
        _Field("linear_acceleration_covariance", 8, 9, 7, 1),
    ), n_cols=8),
    FIX_TYPE: _Layout((
        _Field("status.status", 1, 1, 0, 1),
        _Field("status.service", 2, 1),
        _Field("latitude,longitude,altitude", 8, 3, 1, 3),
        _Field("position_covariance", 8, 9, 4, 9),
        _Field("position_covariance_type", 1, 1, 13, 1),
    ), n_cols=14, int_cols=(0, 13)),
    TWIST_COV_TYPE: _Layout((
        _Field("twist.twist.linear", 8, 3, 0, 3),
        _Field("twist.twist.angular", 8, 3, 3, 3),
        _Field("twist.covariance", 8, 36, 6, 36),  # 0, 7, 14: linear diagonal; 35: yaw rate
    ), n_cols=42),
    TWIST_TYPE: _Layout((
        _Field("twist.linear", 8, 3, 0, 3),
        _Field("twist.angular", 8, 3, 3, 3),
    ), n_cols=6),
    # The same output columns as TWIST_COV_TYPE; size 0 marks a string (u32 length + bytes).
    ODOM_TYPE: _Layout((
        _Field("child_frame_id", 0, 1),
        _Field("pose.pose", 8, 7),
        _Field("pose.covariance", 8, 36),
        _Field("twist.twist.linear", 8, 3, 0, 3),
        _Field("twist.twist.angular", 8, 3, 3, 3),
        _Field("twist.covariance", 8, 36, 6, 36),
    ), n_cols=42),
}

# --------------------------------------------------------------------------- the kernel


@njit(cache=True, inline="always")
def _load(buf, p, size, little):  # pragma: no cover - compiled
    """Unsigned integer of ``size`` bytes at ``buf[p]``, zero-extended to uint64."""
    v = np.uint64(0)
    if little:
        for k in range(size):
            v |= np.uint64(buf[p + k]) << np.uint64(8 * k)
    else:
        for k in range(size):
            v = (v << np.uint64(8)) | np.uint64(buf[p + k])
    return v


@njit(cache=True)
def _decode_kernel(buf, starts, lengths, cdr, f_size, f_count, f_col, f_nout,
                   out, stamp_ns, frame_len, flag):  # pragma: no cover - compiled
    """Decode every payload ``buf[starts[i]:starts[i] + lengths[i]]`` into ``out[i]``.

    ``out`` (N, n_cols) uint64 receives raw field bits; ``stamp_ns`` the header stamp;
    ``frame_len`` the frame_id byte length (CDR: including the NUL); ``flag`` 0 or a reason
    the message was not decoded (then the row is left untouched).
    """
    n = starts.shape[0]
    n_fields = f_size.shape[0]
    for i in range(n):
        s = starts[i]
        ln = lengths[i]
        if ln < 16:
            flag[i] = 1
            continue
        little = True
        if cdr:
            if buf[s] != 0 or buf[s + 1] > 1:
                flag[i] = 3
                continue
            little = buf[s + 1] == 1
        sec = np.int64(_load(buf, s + 4, 4, little))
        if cdr and sec >= 2147483648:  # builtin_interfaces/Time.sec is int32
            sec -= 4294967296
        nsec = np.int64(_load(buf, s + 8, 4, little))
        str_len = np.int64(_load(buf, s + 12, 4, little))
        pos = 16 + str_len
        if pos > ln:
            flag[i] = 1
            continue
        ok = True
        for f in range(n_fields):
            size = f_size[f]
            if size == 0:  # a string: u32 length (4-aligned in CDR), then the bytes
                if cdr:
                    pos = 4 + ((pos - 4 + 3) // 4) * 4
                if pos + 4 > ln:
                    ok = False
                    break
                pos += 4 + np.int64(_load(buf, s + pos, 4, little))
                continue
            if cdr and size > 1:
                pos = 4 + ((pos - 4 + size - 1) // size) * size
            end = pos + size * f_count[f]
            if end > ln:
                ok = False
                break
            col = f_col[f]
            for k in range(f_nout[f]):
                out[i, col + k] = _load(buf, s + pos + k * size, size, little)
            pos = end
        if not ok:
            flag[i] = 1
            continue
        if ln - pos > (3 if cdr else 0):
            flag[i] = 2
            continue
        stamp_ns[i] = sec * 1_000_000_000 + nsec
        frame_len[i] = str_len
        flag[i] = 0


def _load_vec(buf: np.ndarray, at: np.ndarray, size: int, little: np.ndarray) -> np.ndarray:
    """Unsigned integers of ``size`` bytes at ``buf[at[i]]``, zero-extended to uint64, little-
    or big-endian per element (``little``): the array form of :func:`_load`."""
    b = buf[at[:, None] + np.arange(size)].astype(np.uint64)
    shifts = np.arange(size, dtype=np.uint64) * np.uint64(8)
    le = (b << shifts).sum(axis=1, dtype=np.uint64)     # disjoint bits: the sum is the OR
    if little.all():
        return le
    be = (b << shifts[::-1]).sum(axis=1, dtype=np.uint64)
    return np.where(little, le, be)


def _decode_arrays(buf, starts, lengths, cdr, f_size, f_count, f_col, f_nout,
                   out, stamp_ns, frame_len, flag) -> None:
    """:func:`_decode_kernel` with numpy array operations over all messages at once, for runs
    whose kernels are interpreted (:mod:`navpp.jitmode`): the same arguments, the same results
    (rows and flags), without a Python loop over the messages."""
    n = starts.shape[0]
    alive = lengths >= 16
    flag[~alive] = _SHORT
    little = np.ones(n, dtype=bool)
    if cdr:
        idx = np.flatnonzero(alive)
        b0, b1 = buf[starts[idx]], buf[starts[idx] + 1]
        wrong = (b0 != 0) | (b1 > 1)
        flag[idx[wrong]] = _ENCAPSULATION
        alive[idx[wrong]] = False
        little[idx] = b1 == 1
    idx = np.flatnonzero(alive)
    s, ln, lt = starts[idx], lengths[idx], little[idx]
    ok = np.ones(idx.size, dtype=bool)
    sec = _load_vec(buf, s + 4, 4, lt).astype(np.int64)
    if cdr:                                   # builtin_interfaces/Time.sec is int32
        sec = np.where(sec >= 2147483648, sec - 4294967296, sec)
    nsec = _load_vec(buf, s + 8, 4, lt).astype(np.int64)
    str_len = _load_vec(buf, s + 12, 4, lt).astype(np.int64)
    pos = 16 + str_len
    ok &= pos <= ln
    for size, count, col, n_out in zip(f_size.tolist(), f_count.tolist(), f_col.tolist(), f_nout.tolist()):
        if size == 0:                         # a string: u32 length (4-aligned in CDR), then the bytes
            if cdr:
                pos = 4 + ((pos - 4 + 3) // 4) * 4
            ok &= pos + 4 <= ln
            length = _load_vec(buf, s + np.where(ok, pos, 0), 4, lt).astype(np.int64)
            pos = pos + 4 + np.where(ok, length, 0)
            continue
        if cdr and size > 1:
            pos = 4 + ((pos - 4 + size - 1) // size) * size
        end = pos + size * count
        ok &= end <= ln
        rows = idx[ok]
        for k in range(n_out):
            out[rows, col + k] = _load_vec(buf, s[ok] + pos[ok] + k * size, size, lt[ok])
        pos = end
    long_ = ok & (ln - pos > (3 if cdr else 0))
    flag[idx[~ok]] = _SHORT
    flag[idx[long_]] = _LONG
    good = ok & ~long_
    stamp_ns[idx[good]] = sec[good] * 1_000_000_000 + nsec[good]
    frame_len[idx[good]] = str_len[good]
    flag[idx[good]] = _OK


# --------------------------------------------------------------------------- schema check

_SECTION_SPLIT = re.compile(r"^=+\s*$", re.MULTILINE)
_CONSTANT = re.compile(r"^\S+\s+\w+\s*=")

#: Top-level fields of each supported type, as (type basename, field name).
_TOP_FIELDS: dict[str, list[tuple[str, str]]] = {
    IMU_TYPE: [("Header", "header"), ("Quaternion", "orientation"),
               ("float64[9]", "orientation_covariance"), ("Vector3", "angular_velocity"),
               ("float64[9]", "angular_velocity_covariance"), ("Vector3", "linear_acceleration"),
               ("float64[9]", "linear_acceleration_covariance")],
    FIX_TYPE: [("Header", "header"), ("NavSatStatus", "status"), ("float64", "latitude"),
               ("float64", "longitude"), ("float64", "altitude"),
               ("float64[9]", "position_covariance"), ("uint8", "position_covariance_type")],
    TWIST_COV_TYPE: [("Header", "header"), ("TwistWithCovariance", "twist")],
    TWIST_TYPE: [("Header", "header"), ("Twist", "twist")],
    ODOM_TYPE: [("Header", "header"), ("string", "child_frame_id"), ("PoseWithCovariance", "pose"),
                ("TwistWithCovariance", "twist")],
}
#: Nested definitions the fixed layout relies on, checked when the schema text includes them.
_NESTED_FIELDS: dict[str, dict[str, list[tuple[str, str]]]] = {
    "ros1": {
        "Header": [("uint32", "seq"), ("time", "stamp"), ("string", "frame_id")],
    },
    "cdr": {
        "Header": [("Time", "stamp"), ("string", "frame_id")],
        "Time": [("int32", "sec"), ("uint32", "nanosec")],
    },
    "": {
        "Quaternion": [("float64", "x"), ("float64", "y"), ("float64", "z"), ("float64", "w")],
        "Vector3": [("float64", "x"), ("float64", "y"), ("float64", "z")],
        "NavSatStatus": [("int8", "status"), ("uint16", "service")],
        "Twist": [("Vector3", "linear"), ("Vector3", "angular")],
        "TwistWithCovariance": [("Twist", "twist"), ("float64[36]", "covariance")],
        "PoseWithCovariance": [("Pose", "pose"), ("float64[36]", "covariance")],
        "Pose": [("Point", "position"), ("Quaternion", "orientation")],
        "Point": [("float64", "x"), ("float64", "y"), ("float64", "z")],
    },
}


def _fields_of(section: str) -> tuple[str, list[tuple[str, str]]]:
    """(``MSG:`` name or '', [(type basename, field name)]) of one schema section."""
    name = ""
    fields: list[tuple[str, str]] = []
    for raw in section.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("MSG:"):
            name = line[4:].strip()
            continue
        if _CONSTANT.match(line):
            continue
        parts = line.split()
        if len(parts) < 2:
            fields.append((line, ""))
            continue
        fields.append((parts[0].split("/")[-1], parts[1]))
    return name, fields


def schema_is_standard(msgtype: str, encoding: str, schema_text: str) -> bool:
    """True when ``schema_text`` (a ``ros1msg`` / ``ros2msg`` definition, concatenated with its
    dependencies) defines ``msgtype`` exactly as the standard message the fast path assumes.

    Only the top-level fields and the nested definitions the layout depends on (Header, Time,
    Vector3, Quaternion, NavSatStatus, Twist, TwistWithCovariance) are compared; sections the
    text does not include are assumed standard.
    """
    msgtype = normalise_type(msgtype)
    if msgtype not in _TOP_FIELDS:
        return False
    sections = _SECTION_SPLIT.split(schema_text)
    if _fields_of(sections[0])[1] != _TOP_FIELDS[msgtype]:
        return False
    nested = {**_NESTED_FIELDS[""], **_NESTED_FIELDS.get(encoding, {})}
    for section in sections[1:]:
        name, fields = _fields_of(section)
        expected = nested.get(name.split("/")[-1])
        if expected is not None and fields != expected:
            return False
    return True


# --------------------------------------------------------------------------- library decoders

_LibDecoder = Callable[[bytes], Any]


def _library_decoder(msgtype: str, encoding: str, schema_name: str | None,
                     schema_text: str | None) -> _LibDecoder:
    """A per-message decoder: ``mcap_ros2`` / ``mcap_ros1`` generated from the schema text when
    given, otherwise ``rosbags``' standard typestore (ROS 2 latest / ROS 1 Noetic)."""
    if schema_text:
        from mcap.records import Schema

        name = schema_name or msgtype
        if encoding == "cdr":
            from mcap_ros2.decoder import DecoderFactory as Ros2Factory

            schema = Schema(id=1, name=name, encoding="ros2msg", data=schema_text.encode())
            decoder = Ros2Factory().decoder_for("cdr", schema)
        else:
            from mcap_ros1.decoder import DecoderFactory as Ros1Factory

            schema = Schema(id=1, name=name, encoding="ros1msg", data=schema_text.encode())
            decoder = Ros1Factory().decoder_for("ros1", schema)
        if decoder is None:  # pragma: no cover - the factories accept these encodings
            raise ValueError(f"no library decoder for {name!r} ({encoding})")
        return decoder
    from rosbags.typesys import Stores, get_typestore

    pkg, _, name = msgtype.partition("/")
    ros2_name = f"{pkg}/msg/{name}"
    if encoding == "cdr":
        store = get_typestore(Stores.LATEST)
        return lambda data: store.deserialize_cdr(data, ros2_name)
    store = get_typestore(Stores.ROS1_NOETIC)
    return lambda data: store.deserialize_ros1(data, ros2_name)


def _stamp_ns(header: Any) -> int:
    """Header stamp in ns from a ROS 2 (sec/nanosec) or genpy ROS 1 (secs/nsecs) message."""
    stamp = header.stamp
    if hasattr(stamp, "nanosec"):
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return int(stamp.secs) * 1_000_000_000 + int(stamp.nsecs)


def _row_from_object(msgtype: str, msg: Any, row: np.ndarray) -> None:
    """Fill one uint64 output row from a library-decoded message (same columns as the kernel)."""
    f = row.view(np.float64)
    if msgtype == IMU_TYPE:
        w, a = msg.angular_velocity, msg.linear_acceleration
        f[0:3] = (w.x, w.y, w.z)
        f[3] = msg.angular_velocity_covariance[0]
        f[4:7] = (a.x, a.y, a.z)
        f[7] = msg.linear_acceleration_covariance[0]
    elif msgtype == FIX_TYPE:
        row[0] = int(msg.status.status) & 0xFF
        f[1:4] = (msg.latitude, msg.longitude, msg.altitude)
        f[4:13] = list(msg.position_covariance)
        row[13] = int(msg.position_covariance_type) & 0xFF
    elif msgtype in (TWIST_COV_TYPE, ODOM_TYPE):
        v, w = msg.twist.twist.linear, msg.twist.twist.angular
        f[0:6] = (v.x, v.y, v.z, w.x, w.y, w.z)
        f[6:42] = list(msg.twist.covariance)
    else:
        v, w = msg.twist.linear, msg.twist.angular
        f[0:6] = (v.x, v.y, v.z, w.x, w.y, w.z)


def decode_with_library(msgtype: str, encoding: str, payloads: Sequence[Any], *,
                        schema_name: str | None = None, schema_text: str | None = None,
                        child_frame_ids: list[str] | None = None,
                        ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Decode ``payloads`` one by one with the library decoder.

    Returns ``(table (N, n_cols) uint64, stamp_ns (N,) int64, frame_ids)`` in the kernel's
    format; an Odometry's ``child_frame_id`` of each message is appended to ``child_frame_ids``
    when that list is given.  Exceptions of the decoder (or a missing field:
    ``AttributeError``) propagate.
    """
    msgtype = normalise_type(msgtype)
    layout = _LAYOUTS[msgtype]
    decoder = _library_decoder(msgtype, encoding, schema_name, schema_text)
    n = len(payloads)
    table = np.zeros((n, layout.n_cols), dtype=np.uint64)
    stamps = np.zeros(n, dtype=np.int64)
    frame_ids: list[str] = []
    for i, payload in enumerate(payloads):
        msg = decoder(bytes(payload))
        _row_from_object(msgtype, msg, table[i])
        stamps[i] = _stamp_ns(msg.header)
        frame_ids.append(str(msg.header.frame_id))
        if child_frame_ids is not None and msgtype == ODOM_TYPE:
            child_frame_ids.append(str(msg.child_frame_id))
    return table, stamps, frame_ids


# --------------------------------------------------------------------------- accumulation


def _as_readonly_u8(buffer: Any) -> np.ndarray:
    """A read-only uint8 view of ``buffer`` (one numba specialisation for every caller)."""
    arr = buffer.reshape(-1).view(np.uint8) if isinstance(buffer, np.ndarray) else np.frombuffer(buffer, dtype=np.uint8)
    if arr.flags.writeable:
        arr = arr.view()
        arr.flags.writeable = False
    return arr


def _child_frame_id(buf: np.ndarray, start: int, pos: int, cdr: bool) -> str:
    """The string right after the header (an Odometry's ``child_frame_id``) of the message at
    ``buf[start:]``; ``pos`` is the byte after ``header.frame_id`` (relative to ``start``)."""
    little = not cdr or int(buf[start + 1]) == 1
    if cdr:
        pos = 4 + ((pos - 4 + 3) // 4) * 4
    n = int.from_bytes(bytes(buf[start + pos:start + pos + 4]), "little" if little else "big")
    raw = bytes(buf[start + pos + 4:start + pos + 4 + n])
    return raw.rstrip(b"\0").decode("utf-8", errors="replace")


def _time_text(ns: int) -> str:
    sign = "-" if ns < 0 else ""
    ns = abs(int(ns))
    return f"{sign}{ns // 1_000_000_000}.{ns % 1_000_000_000:09d} s"


class TopicDecoder:
    """Decodes one topic's messages, piece by piece, into one :data:`Messages` object.

    Parameters
    ----------
    topic, msgtype, encoding :
        Topic name, message type (ROS 1 or ROS 2 form) and ``"cdr"`` / ``"ros1"``.
    source :
        The file the payloads come from, for error messages.
    schema_name, schema_text :
        The schema record of the channel when known.  A schema that is not the standard
        definition sends the whole topic through the library decoder; without one the
        standard layout is assumed.
    memory :
        Bytes (``[output] memory``) beyond which the decoded rows go to a spill file
        (:mod:`navpp.spill`) as they are added, each piece's pages released once written;
        None: the rows stay in memory.  With a budget the rows are kept in one table
        (:class:`_Rows`) and the result's arrays of an IMU topic are views of it.
    expected :
        Messages the topic is expected to hold (a log's index or summary), the table's first
        size (it grows if more come); 0: unknown.
    """

    def __init__(self, topic: str, msgtype: str, encoding: str, *, source: str = "",
                 schema_name: str | None = None, schema_text: str | None = None,
                 memory: int | None = None, expected: int = 0) -> None:
        self.topic = topic
        self.msgtype = normalise_type(msgtype)
        self.encoding = encoding
        self.source = source
        self.schema_name = schema_name
        self.schema_text = schema_text
        if self.msgtype not in SUPPORTED_TYPES:
            raise InputError(f"{self._where()}: message type {msgtype!r} is not one navpp decodes "
                             f"({', '.join(SUPPORTED_TYPES)})")
        if encoding not in ENCODINGS:
            raise InputError(f"{self._where()}: message encoding {encoding!r} is not supported "
                             f"(expected one of {', '.join(ENCODINGS)})")
        self._layout = _LAYOUTS[self.msgtype]
        self._layout_arrays = self._layout.arrays()
        self.fast = schema_text is None or schema_is_standard(self.msgtype, encoding, schema_text)
        self._lib: _LibDecoder | None = None
        self._tables: list[np.ndarray] = []
        self._stamps: list[np.ndarray] = []
        self._logs: list[np.ndarray] = []
        self._rows = None if memory is None else _Rows(self._layout.n_cols, memory, expected)
        self.count = 0
        self.n_fallback = 0  # messages decoded by the library decoder
        self.frame_id: str | None = None
        self.child_frame_id: str | None = None  # nav_msgs/Odometry only

    def _where(self, index: int | None = None, log_ns: int | None = None) -> str:
        where = f"{self.source}: topic {self.topic!r}" if self.source else f"topic {self.topic!r}"
        if index is not None:
            where += f", message #{index}"
            if log_ns is not None:
                where += f" (log time {_time_text(log_ns)})"
        return where

    def add(self, buffer: Any, starts: np.ndarray, lengths: np.ndarray,
            log_ns: np.ndarray) -> None:
        """Decode the payloads ``buffer[starts[i]:starts[i] + lengths[i]]`` (in message order)
        with their log times ``log_ns`` (ns)."""
        buf = _as_readonly_u8(buffer)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        lengths = np.ascontiguousarray(lengths, dtype=np.int64)
        log_ns = np.array(log_ns, dtype=np.int64)  # a copy: the caller's array may be a view
        n = starts.shape[0]
        if n == 0:
            return
        if int((starts + lengths).max()) > buf.shape[0] or int(starts.min()) < 0:
            raise ValueError("payload spans reach outside the buffer")
        table = np.zeros((n, self._layout.n_cols), dtype=np.uint64)
        stamps = np.zeros(n, dtype=np.int64)
        if self.fast:
            frame_len = np.zeros(n, dtype=np.int64)
            flag = np.zeros(n, dtype=np.uint8)
            decode = _decode_arrays if jitmode.interpreted() else _decode_kernel
            decode(buf, starts, lengths, self.encoding == "cdr", *self._layout_arrays,
                   table, stamps, frame_len, flag)
            bad = np.flatnonzero(flag)
            if self.frame_id is None and bad.size < n:
                i = int(np.flatnonzero(flag == 0)[0])
                raw = bytes(buf[starts[i] + 16: starts[i] + 16 + frame_len[i]])
                self.frame_id = raw.rstrip(b"\0").decode("utf-8", errors="replace")
                if self.msgtype == ODOM_TYPE:
                    self.child_frame_id = _child_frame_id(buf, int(starts[i]), 16 + int(frame_len[i]),
                                                          self.encoding == "cdr")
        else:
            bad = np.arange(n)
            flag = np.full(n, _LONG, dtype=np.uint8)
        for k in bad:
            self._fallback(int(k), int(flag[k]), buf, starts, lengths, log_ns, table, stamps)
        if self._rows is not None:
            self._rows.append(table, stamps, log_ns)
        else:
            self._tables.append(table)
            self._stamps.append(stamps)
            self._logs.append(log_ns)
        self.count += n

    def _fallback(self, i: int, flag: int, buf: np.ndarray, starts: np.ndarray,
                  lengths: np.ndarray, log_ns: np.ndarray, table: np.ndarray,
                  stamps: np.ndarray) -> None:
        payload = bytes(buf[starts[i]: starts[i] + lengths[i]])
        index = self.count + i
        if flag == _ENCAPSULATION:
            kind = int.from_bytes(payload[:2], "big")
            raise InputError(f"{self._where(index, int(log_ns[i]))}: unsupported CDR encapsulation "
                             f"0x{kind:04x} (navpp reads plain CDR, little or big endian)")
        if self._lib is None:
            import contextlib
            import io

            try:   # the bundled definition parser also prints to stderr: keep the one-line contract
                with contextlib.redirect_stderr(io.StringIO()):
                    self._lib = _library_decoder(self.msgtype, self.encoding, self.schema_name,
                                                 self.schema_text)
            except Exception as exc:  # noqa: BLE001 - a broken definition is bad input
                raise InputError(f"{self._where(index, int(log_ns[i]))}: cannot parse the message definition "
                                 f"of {self.msgtype} ({type(exc).__name__}: {exc})") from None
        try:
            msg = self._lib(payload)
            _row_from_object(self.msgtype, msg, table[i])
            stamps[i] = _stamp_ns(msg.header)
        except AttributeError as exc:
            raise InputError(f"{self._where(index, int(log_ns[i]))}: unknown message definition for "
                             f"{self.msgtype} (no field {exc.name!r})") from None
        except Exception as exc:  # noqa: BLE001 - any decoder failure is bad input
            reason = _FLAG_TEXT.get(flag, "")
            detail = f"{len(payload)} bytes, {reason}; " if reason and self.fast else ""
            raise InputError(f"{self._where(index, int(log_ns[i]))}: cannot decode {self.msgtype} "
                             f"({detail}{type(exc).__name__}: {exc})") from None
        if self.frame_id is None:
            self.frame_id = str(msg.header.frame_id)
        if self.child_frame_id is None and self.msgtype == ODOM_TYPE:
            self.child_frame_id = str(msg.child_frame_id)
        self.n_fallback += 1

    def result(self) -> Messages:
        """The decoded messages (in the order they were added)."""
        n_cols = self._layout.n_cols
        if self._rows is not None:
            table, stamps, logs = self._rows.result()
            self._rows = None
            return build_messages(self.msgtype, self.topic, table, stamps, logs, self.frame_id or "",
                                  self.child_frame_id or "", views=spill.spilled(table))
        table = (np.concatenate(self._tables) if self._tables
                 else np.zeros((0, n_cols), dtype=np.uint64))
        stamps = np.concatenate(self._stamps) if self._stamps else np.zeros(0, dtype=np.int64)
        logs = np.concatenate(self._logs) if self._logs else np.zeros(0, dtype=np.int64)
        self._tables, self._stamps, self._logs = [], [], []
        return build_messages(self.msgtype, self.topic, table, stamps, logs, self.frame_id or "",
                              self.child_frame_id or "")


def build_messages(msgtype: str, topic: str, table: np.ndarray, stamp_ns: np.ndarray,
                   log_ns: np.ndarray, frame_id: str, child_frame_id: str = "", *,
                   views: bool = False) -> Messages:
    """The ros.py container for ``msgtype`` from a (N, n_cols) uint64 table in the kernel's
    format (as :func:`decode_with_library` returns it); ``child_frame_id``: Odometry only.
    ``views``: an IMU topic's arrays are views of ``table`` (strided columns, no copy: a
    spilled table stays on its file), not contiguous copies."""
    f = table.view(np.float64)
    if msgtype == IMU_TYPE and views:
        return ImuMessages(topic=topic, stamp_ns=stamp_ns, log_ns=log_ns, gyro=f[:, 0:3], accel=f[:, 4:7],
                           gyro_cov0=f[:, 3], accel_cov0=f[:, 7], frame_id=frame_id)
    if msgtype == IMU_TYPE:
        return ImuMessages(topic=topic, stamp_ns=stamp_ns, log_ns=log_ns,
                           gyro=np.ascontiguousarray(f[:, 0:3]),
                           accel=np.ascontiguousarray(f[:, 4:7]),
                           gyro_cov0=f[:, 3].copy(), accel_cov0=f[:, 7].copy(),
                           frame_id=frame_id)
    if msgtype == FIX_TYPE:
        return FixMessages(topic=topic, stamp_ns=stamp_ns, log_ns=log_ns,
                           status=table[:, 0].astype(np.uint8).view(np.int8),
                           lat_deg=f[:, 1].copy(), lon_deg=f[:, 2].copy(), alt=f[:, 3].copy(),
                           cov=np.ascontiguousarray(f[:, 4:13]),
                           cov_type=table[:, 13].astype(np.uint8), frame_id=frame_id)
    if msgtype in (TWIST_COV_TYPE, ODOM_TYPE):
        return TwistMessages(topic=topic, stamp_ns=stamp_ns, log_ns=log_ns,
                             vel=np.ascontiguousarray(f[:, 0:3]),
                             cov_diag=np.ascontiguousarray(f[:, [6, 6 + 7, 6 + 14]]),
                             frame_id=frame_id, angular=np.ascontiguousarray(f[:, 3:6]),
                             var_yaw_rate=f[:, 6 + 35].copy(), child_frame_id=child_frame_id)
    return TwistMessages(topic=topic, stamp_ns=stamp_ns, log_ns=log_ns,
                         vel=np.ascontiguousarray(f[:, 0:3]), cov_diag=None, frame_id=frame_id,
                         angular=np.ascontiguousarray(f[:, 3:6]))


#: The fewest bytes any supported message takes serialized (a TwistStamped with an empty frame
#: id: header 16 + twist 48, either encoding): a log of N bytes holds at most N / this many.
MIN_MESSAGE_BYTES = 64


def plausible_count(expected: int, log_bytes: int) -> int:
    """A message count from a log's index or summary (``expected``) as a first table size: at most
    what ``log_bytes`` bytes of log can hold (:data:`MIN_MESSAGE_BYTES` each), so that a damaged
    count cannot ask for a table larger than the log (the table grows if more messages come)."""
    return max(0, min(int(expected), int(log_bytes) // MIN_MESSAGE_BYTES))


class _Rows:
    """A topic's decoded rows in one growing (capacity, n_cols + 2) uint64 table: the kernel's
    columns, then the header stamp and the log time (ns, int64 bits).  On a spill file
    (:mod:`navpp.spill`) once the table would hold more than ``memory`` bytes, the rows written
    released behind (:func:`navpp.spill.release_before`); ``expected`` rows: the first capacity."""

    def __init__(self, n_cols: int, memory: int, expected: int) -> None:
        self.n_cols = n_cols
        self.memory = memory
        self.n = 0
        self.table = self._empty(max(int(expected), 0), False)

    def _empty(self, capacity: int, spilled: bool) -> np.ndarray:
        spilled = spilled or capacity * (self.n_cols + 2) * 8 > self.memory
        return spill.empty_rows(capacity, (self.n_cols + 2,), np.uint64, spilled, "the decoded messages")

    def append(self, table: np.ndarray, stamps: np.ndarray, log_ns: np.ndarray) -> None:
        """Rows ``table`` (n, n_cols) with their stamps and log times (n,) int64 after the others."""
        n, end = table.shape[0], self.n + table.shape[0]
        if end > self.table.shape[0]:       # grown by a quarter (a log without an index)
            bigger = self._empty(max(end, self.table.shape[0] * 5 // 4 + 1024), spill.spilled(self.table))
            for a, b in spill.windows(self.n, self.table, bigger):
                bigger[a:b] = self.table[a:b]
            self.table = bigger
        rows = self.table[self.n:end]
        rows[:, :self.n_cols] = table
        rows[:, self.n_cols] = stamps.view(np.uint64)
        rows[:, self.n_cols + 1] = log_ns.view(np.uint64)
        self.n = end
        spill.release_before(self.table, end - n)

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(table (N, n_cols) uint64, stamp_ns (N,), log_ns (N,) int64): views of the rows."""
        rows = self.table[:self.n]
        spill.release_all(rows)
        stamps, logs = rows[:, self.n_cols].view(np.int64), rows[:, self.n_cols + 1].view(np.int64)
        if not spill.spilled(rows):
            stamps, logs = stamps.copy(), logs.copy()
        return rows[:, :self.n_cols], stamps, logs


def _as_buffer(payloads: Payloads) -> tuple[Any, np.ndarray, np.ndarray]:
    """``(buffer, starts, lengths)`` from either payload form."""
    if (isinstance(payloads, tuple) and len(payloads) == 3
            and isinstance(payloads[1], np.ndarray) and isinstance(payloads[2], np.ndarray)):
        return payloads
    items = list(payloads)
    lengths = np.fromiter((len(p) if not isinstance(p, memoryview) else p.nbytes for p in items),
                          dtype=np.int64, count=len(items))
    starts = np.zeros(len(items), dtype=np.int64)
    if len(items) > 1:
        np.cumsum(lengths[:-1], out=starts[1:])
    return b"".join(items), starts, lengths


def decode(msgtype: str, encoding: str, payloads: Payloads, log_ns: Any, topic: str, *,
           source: str = "", schema_name: str | None = None,
           schema_text: str | None = None) -> Messages:
    """Decode one topic's serialized messages.

    Parameters
    ----------
    msgtype :
        ``sensor_msgs/Imu``, ``sensor_msgs/NavSatFix``,
        ``geometry_msgs/TwistWithCovarianceStamped`` or ``geometry_msgs/TwistStamped``
        (ROS 2 names such as ``sensor_msgs/msg/Imu`` are accepted).
    encoding :
        ``"cdr"`` (ROS 2) or ``"ros1"``.
    payloads :
        The raw messages in order: a sequence of bytes-like objects, or
        ``(buffer, starts, lengths)`` describing them inside one buffer.
    log_ns : (N,) int
        Log (record) time of each message, ns.
    topic :
        The topic name, stored in the result and named in errors.
    source :
        The file, named in errors.
    schema_name, schema_text :
        The message definition stored with the log, if any (see :class:`TopicDecoder`).

    Returns
    -------
    ImuMessages | FixMessages | TwistMessages
        By message type; stamps from the header, in ns.

    Raises
    ------
    InputError
        Unsupported type or encoding, or a message that cannot be decoded (names the file,
        topic, message index and log time).
    """
    buffer, starts, lengths = _as_buffer(payloads)
    log_ns = np.asarray(log_ns, dtype=np.int64).reshape(-1)
    if log_ns.shape[0] != starts.shape[0]:
        raise ValueError(f"{log_ns.shape[0]} log times for {starts.shape[0]} payloads")
    dec = TopicDecoder(topic, msgtype, encoding, source=source, schema_name=schema_name,
                       schema_text=schema_text)
    dec.add(buffer, starts, lengths, log_ns)
    return dec.result()
