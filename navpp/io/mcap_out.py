"""``trajectory.mcap``: the fused solution as ROS 2 messages that ROS tools and Foxglove open as
they are.

Every message is CDR encoded (ROS 2) on a channel whose schema is the full ``ros2msg``
definition, dependencies included (``===`` separated, as rosbag2 stores them), so a reader
needs nothing but the file.  The header profile is ``ros2``.

Topics
------
Frames: ``map`` is the local ENU frame of :mod:`navpp.io.frames` (x east, y north, z up, in
metres, origin at :func:`~navpp.io.frames.anchor_for`, recorded in the file's ``navpp``
metadata record); ``base_link`` is navpp's body frame (the IMU's, after the mounting rotation),
FLU (x forward, y left, z up).

- ``/navpp/fix`` ``sensor_msgs/msg/NavSatFix``, one per solution row, frame ``base_link``:
  latitude, longitude (deg) and ellipsoidal altitude (m) of the body origin;
  ``position_covariance`` = diag(std_e², std_n², std_u²) (m², ENU about the reported position,
  as the message defines it), ``COVARIANCE_TYPE_DIAGONAL_KNOWN``; status ``STATUS_FIX``,
  service ``SERVICE_GPS``.
- ``/navpp/odometry`` ``nav_msgs/msg/Odometry``, one per solution row, frame ``map``, child
  ``base_link``: ``pose.position`` the body origin in ``map`` (m); ``pose.orientation`` the
  rotation taking ``base_link`` vectors into ``map`` (:func:`~navpp.io.frames.body_to_map`);
  ``twist.linear`` the velocity in ``base_link`` (m/s, :func:`~navpp.io.frames.velocity_body`);
  ``twist.angular`` zero.  Covariances (row-major 6x6, x y z then rotations about x y z, all
  off-diagonal elements 0): the pose's position block is diag(std_e², std_n², std_u²) (ENU m²;
  the map's axes differ from the local ENU axes by the tiny rotation described in
  :mod:`navpp.io.frames`).  Everything navpp's :class:`~navpp.recording.Solution` does not
  carry is marked "not estimated" with the variance :data:`NOT_ESTIMATED_VARIANCE` (1e6, in
  rad² or m²/s² or rad²/s²): the orientation variances, and the whole twist diagonal (the
  solution has no velocity sigma, and the angular velocity is not estimated at all).  ROS
  defines no "unknown" marker for Odometry; zero would claim a perfect estimate to any
  consumer that weights by the covariance (robot_localization, planners), whereas a huge
  variance makes such a consumer ignore the value, which is the truth.
- ``/tf`` ``tf2_msgs/msg/TFMessage``, one per solution row: the transform ``map`` ->
  ``base_link`` with the odometry's pose, so 3-D views show the vehicle moving.  No
  ``/tf_static``: navpp has no fixed frame to publish (the body frame is the IMU's; the GNSS
  lever arm is configuration, not part of the solution).
- ``/navpp/bias/gyro`` and ``/navpp/bias/accel`` ``geometry_msgs/msg/Vector3Stamped``, frame
  ``base_link``, one per GNSS epoch the filter processed
  (:class:`~navpp.engine.BiasHistory`): the estimated gyro (rad/s) and accelerometer (m/s²)
  biases, body FLU.
- ``/navpp/forward/fix`` and ``/navpp/forward/odometry`` (only for a smoothed run, ``forward``
  given): the forward filter's solution as ``/navpp/fix`` and ``/navpp/odometry`` carry it,
  same frames and anchor, so the forward and smoothed tracks overlay in Foxglove; the main
  topics and the biases then carry the smoothed solution.
- ``/navpp/diagnostics`` ``navpp_msgs/msg/FilterDiagnostics``
  (:data:`~navpp.io.roswrite.FILTER_DIAGNOSTICS_MSGDEF`), frame ``map``, one per GNSS epoch
  (:class:`~navpp.engine.Diagnostics`): ``innovation_enu`` (m), ``nis``, ``accepted``,
  ``forced``, ``r_std_enu`` (the measurement 1-sigma the filter used, m), and every adaptive
  value of ``Diagnostics.adaptive`` as ``names[i]`` / ``values[i]`` (named as the columns of
  ``diagnostics.csv``: ``key`` for a single value, ``key_<i>`` otherwise; e.g. VCE's
  ``q_factor_*`` / ``r_factor_*``, AUKF ``fading``, SIF ``si_iterations_*``, RWCKF
  ``weights_<i>``).  A custom type because no standard message carries these numbers as
  numbers: ``diagnostic_msgs/DiagnosticArray`` holds strings, which plots cannot use, and
  ``std_msgs/Float64MultiArray`` has no header (no stamp) and no field names.  Every number here
  is a plain field or an element of a primitive array, so Foxglove plots ``.nis``,
  ``.innovation_enu[0]`` or ``.values[3]`` directly; the definition travels in the file, so
  no ``navpp_msgs`` package is needed to read it.

Every message's log time = publish time = header stamp: integer ns on the log's own time base,
``recording.t0_ns + round(t * 1e9)`` (:func:`navpp.io.roswrite.stamps_ns`).

Embedded input (``embed_input=True``): the IMU and GNSS that navpp processed, in the same file,
so one file replays everything.  From an MCAP input whose IMU / GNSS topics are CDR encoded,
the raw Message records of those topics are copied (payload, log and publish time, sequence;
bytes identical) with their schemas, topics and channel metadata (e.g. rosbag2's QoS
profiles); a GNSS velocity topic goes with the GNSS when the recording used one.  Anything
else (CSV, ROS 1 bag, ROS 2 bag, a ROS 1 encoded MCAP, or an MCAP whose topic does not hold the
recording's data, e.g. GNSS replaced by ``--gnss FILE.pos``) is encoded from the Recording:
``sensor_msgs/msg/Imu`` on ``/imu/data`` (frame ``imu_link``), ``sensor_msgs/msg/NavSatFix``
on ``/gnss/fix`` (frame ``gnss``) and, with GNSS velocity,
``geometry_msgs/msg/TwistWithCovarianceStamped`` on ``/gnss/vel``, exactly as
:func:`navpp.io.roswrite.write_mcap_ros2` writes them (navpp reads them back as the same
arrays).  The copied topics are identified by content: the recording's IMU stamps (header or
log) and GNSS positions must all be found in the topic; a topic the copy cannot take whole (the
last, partial chunk of a cut-off recording, which navpp's reader still decodes) is encoded too.

File layout and speed
---------------------
All messages are in log-time order (stable: embedded input first, then the topics above, at
equal times), in chunks of about :data:`CHUNK_SIZE` bytes compressed with zstd, each followed
by its message indexes; Schema, Channel and the ``navpp`` Metadata record come first; the
summary repeats schemas and channels and holds statistics, the metadata and chunk indexes and
summary offsets; CRCs of chunks and summary are written.  That is the layout of the ``mcap``
package's ``Writer`` (``mcap`` reads it back, tested), but the records are assembled here in
bulk: payloads are packed a chunk at a time by numpy (:mod:`navpp.io.roswrite`'s ``pack_*``)
and laid out as Message records by a numba kernel, because the ``mcap`` Writer's
``add_message`` costs ~2.5 us per message in Python (an hour at 125 Hz is 1.35 M messages).
The file is written atomically (:func:`navpp.io.writers.atomic_write`).
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from numba import njit

from navpp.io import frames, roswrite
from navpp.io.writers import adaptive_columns, atomic_write
from navpp.recording import Recording, Solution

__all__ = [
    "BODY_FRAME",
    "CHUNK_SIZE",
    "MAP_FRAME",
    "NOT_ESTIMATED_VARIANCE",
    "TOPICS",
    "adaptive_columns",
    "write_trajectory_mcap",
]

MAP_FRAME = "map"
BODY_FRAME = "base_link"
#: Variance written for what navpp does not estimate (see the module docstring).
NOT_ESTIMATED_VARIANCE = 1.0e6
#: Target uncompressed size of a chunk, bytes.
CHUNK_SIZE = 4 * 2**20

TOPIC_FIX = "/navpp/fix"
TOPIC_ODOMETRY = "/navpp/odometry"
TOPIC_TF = "/tf"
TOPIC_BIAS_GYRO = "/navpp/bias/gyro"
TOPIC_BIAS_ACCEL = "/navpp/bias/accel"
TOPIC_DIAGNOSTICS = "/navpp/diagnostics"
TOPIC_FORWARD_FIX = "/navpp/forward/fix"
TOPIC_FORWARD_ODOMETRY = "/navpp/forward/odometry"
#: Topics of the solution -> ROS 2 message type.
TOPICS = {
    TOPIC_FIX: "sensor_msgs/msg/NavSatFix",
    TOPIC_ODOMETRY: "nav_msgs/msg/Odometry",
    TOPIC_TF: "tf2_msgs/msg/TFMessage",
    TOPIC_BIAS_GYRO: "geometry_msgs/msg/Vector3Stamped",
    TOPIC_BIAS_ACCEL: "geometry_msgs/msg/Vector3Stamped",
    TOPIC_DIAGNOSTICS: roswrite.FILTER_DIAGNOSTICS_TYPE,
}
#: Topics a smoothed run adds (the forward filter's solution) -> ROS 2 message type.
FORWARD_TOPICS = {
    TOPIC_FORWARD_FIX: "sensor_msgs/msg/NavSatFix",
    TOPIC_FORWARD_ODOMETRY: "nav_msgs/msg/Odometry",
}
_ALL_TOPICS = {**TOPICS, **FORWARD_TOPICS}
#: Topics of the input when it is encoded from the Recording (those of ``write_mcap_ros2``).
EMBED_IMU_TOPIC = "/imu/data"
EMBED_GNSS_TOPIC = "/gnss/fix"
EMBED_GNSS_VEL_TOPIC = "/gnss/vel"

_MSGDEFS = {
    "sensor_msgs/msg/NavSatFix": roswrite.NAVSATFIX_MSGDEF,
    "sensor_msgs/msg/Imu": roswrite.IMU_MSGDEF,
    "geometry_msgs/msg/TwistWithCovarianceStamped": roswrite.TWIST_WITH_COVARIANCE_STAMPED_MSGDEF,
    "nav_msgs/msg/Odometry": roswrite.ODOMETRY_MSGDEF,
    "tf2_msgs/msg/TFMessage": roswrite.TF_MESSAGE_MSGDEF,
    "geometry_msgs/msg/Vector3Stamped": roswrite.VECTOR3_STAMPED_MSGDEF,
    roswrite.FILTER_DIAGNOSTICS_TYPE: roswrite.FILTER_DIAGNOSTICS_MSGDEF,
}

_MAGIC = b"\x89MCAP0\r\n"
_OP_MESSAGE_INDEX = 0x07
_MESSAGE_OVERHEAD = 1 + 8 + 2 + 4 + 8 + 8  # opcode, length, channel, sequence, log and publish time
_COMPRESSIONS = ("zstd", "lz4", "none")


# --------------------------------------------------------------------------- message streams


@dataclass(frozen=True)
class _Packed:
    """Fixed-size payloads made on demand: ``pack(i0, i1)`` is the packed array of messages i0..i1-1."""

    n: int
    pack: Callable[[int, int], np.ndarray]
    size: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", int(self.pack(0, 0).dtype.itemsize))

    def lengths(self) -> np.ndarray:
        return np.full(self.n, self.size, dtype=np.int64)

    def block(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        arr = np.ascontiguousarray(self.pack(i0, i1))
        if arr.shape != (i1 - i0,) or arr.dtype.itemsize != self.size:
            raise ValueError(f"packed {arr.shape} x {arr.dtype.itemsize} B, expected ({i1 - i0},) x {self.size} B")
        return arr.view(np.uint8).reshape(-1), np.full(i1 - i0, self.size, dtype=np.int64)


@dataclass(frozen=True)
class _Raw:
    """Payloads held as bytes: message ``i`` is ``data[offsets[i]:offsets[i + 1]]``."""

    data: np.ndarray  # (total,) uint8
    offsets: np.ndarray  # (N + 1,) int64

    def lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    def block(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        return self.data[self.offsets[i0]:self.offsets[i1]], np.diff(self.offsets[i0:i1 + 1])


@dataclass(frozen=True)
class _Stream:
    """One channel's messages, sorted by log time."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    log_ns: np.ndarray  # (N,) int64
    publish_ns: np.ndarray  # (N,) int64
    sequence: np.ndarray  # (N,) int64 (stored as u32)
    payloads: _Packed | _Raw
    metadata: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.log_ns.shape[0])


def _ros2_stream(topic: str, msgtype: str, stamps: np.ndarray,
                 pack: Callable[[np.ndarray, slice], np.ndarray]) -> _Stream:
    """A navpp-encoded CDR stream: log time = publish time = stamp; ``pack(stamps, rows)``."""
    stamps = np.asarray(stamps, dtype=np.int64)
    if stamps.size > 1 and bool(np.any(np.diff(stamps) < 0)):
        raise ValueError(f"{topic}: stamps must not decrease")
    return _Stream(topic, msgtype, "ros2msg", _MSGDEFS[msgtype].encode(), "cdr", stamps, stamps,
                   np.arange(stamps.size, dtype=np.int64),
                   _Packed(stamps.size, lambda i0, i1: pack(stamps[i0:i1], slice(i0, i1))))


def _solution_streams(solution: Solution, recording: Recording, diagnostics: Any,
                      biases: Any, forward: Solution | None = None) -> tuple[list[_Stream], frames.Anchor]:
    if len(solution) == 0:
        raise ValueError("the solution is empty: nothing to write")
    anchor = frames.anchor_for(solution, recording)
    streams = _pose_streams(solution, recording, anchor, TOPIC_FIX, TOPIC_ODOMETRY, tf=True)
    if forward is not None:
        streams += _pose_streams(forward, recording, anchor, TOPIC_FORWARD_FIX, TOPIC_FORWARD_ODOMETRY, tf=False)
    if biases is not None:
        b_stamps = roswrite.stamps_ns(recording, biases.t)
        gyro = np.asarray(biases.gyro, dtype=np.float64)
        accel = np.asarray(biases.accel, dtype=np.float64)
        streams.append(_ros2_stream(TOPIC_BIAS_GYRO, TOPICS[TOPIC_BIAS_GYRO], b_stamps,
                                    lambda st, r: roswrite.pack_vector3_stamped(
                                        st, gyro[r], encoding="cdr", frame_id=BODY_FRAME)))
        streams.append(_ros2_stream(TOPIC_BIAS_ACCEL, TOPICS[TOPIC_BIAS_ACCEL], b_stamps,
                                    lambda st, r: roswrite.pack_vector3_stamped(
                                        st, accel[r], encoding="cdr", frame_id=BODY_FRAME)))
    if diagnostics is not None:
        streams.append(_diagnostics_stream(recording, diagnostics))
    return streams, anchor


def _pose_streams(solution: Solution, recording: Recording, anchor: frames.Anchor, fix_topic: str,
                  odom_topic: str, tf: bool) -> list[_Stream]:
    """NavSatFix, Odometry (and with ``tf`` the map -> base_link transform) of every row."""
    n = len(solution)
    if n == 0:
        raise ValueError("the solution is empty: nothing to write")
    if solution.t0_ns not in (0, recording.t0_ns):
        raise ValueError(f"solution.t0_ns {solution.t0_ns} differs from recording.t0_ns {recording.t0_ns}")
    stamps = roswrite.stamps_ns(recording, solution.t)
    pos_map = anchor.enu(solution.lat_deg, solution.lon_deg, solution.alt)
    quat = frames.quat_xyzw(frames.body_to_map(solution, anchor))
    vel_b = frames.velocity_body(solution)
    lat = np.asarray(solution.lat_deg, dtype=np.float64)
    lon = np.asarray(solution.lon_deg, dtype=np.float64)
    alt = np.asarray(solution.alt, dtype=np.float64)
    var = np.square(np.asarray(solution.std_enu, dtype=np.float64))
    pose_var = np.empty((n, 6))
    pose_var[:, :3] = var
    pose_var[:, 3:] = NOT_ESTIMATED_VARIANCE
    twist_var = np.full(6, NOT_ESTIMATED_VARIANCE)
    zeros3 = np.zeros((1, 3))

    streams = [
        _ros2_stream(fix_topic, _ALL_TOPICS[fix_topic], stamps, lambda st, r: roswrite.pack_navsatfix(
            st, lat[r], lon[r], alt[r], encoding="cdr", frame_id=BODY_FRAME, cov_diag=var[r])),
        _ros2_stream(odom_topic, _ALL_TOPICS[odom_topic], stamps, lambda st, r: roswrite.pack_odometry(
            st, pos_map[r], quat[r], vel_b[r], np.broadcast_to(zeros3, (st.size, 3)), encoding="cdr",
            frame_id=MAP_FRAME, child_frame_id=BODY_FRAME, pose_var=pose_var[r], twist_var=twist_var)),
    ]
    if tf:
        streams.append(_ros2_stream(TOPIC_TF, TOPICS[TOPIC_TF], stamps, lambda st, r: roswrite.pack_tf_message(
            st, pos_map[r], quat[r], encoding="cdr", frame_id=MAP_FRAME, child_frame_id=BODY_FRAME)))
    return streams


def _diagnostics_stream(recording: Recording, diagnostics: Any) -> _Stream:
    stamps = roswrite.stamps_ns(recording, diagnostics.t)
    m = stamps.size
    nu = np.asarray(diagnostics.nu, dtype=np.float64).reshape(m, 3)
    nis = np.asarray(diagnostics.nis, dtype=np.float64).reshape(m)
    accepted = np.asarray(diagnostics.accepted, dtype=bool).reshape(m)
    forced = np.asarray(diagnostics.forced, dtype=bool).reshape(m)
    r_std = np.asarray(diagnostics.r_std, dtype=np.float64).reshape(m, 3)
    names, values = adaptive_columns(diagnostics)
    return _ros2_stream(TOPIC_DIAGNOSTICS, TOPICS[TOPIC_DIAGNOSTICS], stamps,
                        lambda st, r: roswrite.pack_filter_diagnostics(
                            st, nu[r], nis[r], accepted[r], forced[r], r_std[r], names, values[r],
                            encoding="cdr", frame_id=MAP_FRAME))


# --------------------------------------------------------------------------- embedded input


def _encoded_imu(recording: Recording) -> _Stream:
    imu = recording.imu
    gyro, accel = np.asarray(imu.gyro, dtype=np.float64), np.asarray(imu.accel, dtype=np.float64)
    return _ros2_stream(EMBED_IMU_TOPIC, "sensor_msgs/msg/Imu", roswrite.stamps_ns(recording, imu.t),
                        lambda st, r: roswrite.pack_imu(st, gyro[r], accel[r], encoding="cdr",
                                                        frame_id="imu_link"))


def _encoded_gnss(recording: Recording, with_velocity: bool) -> list[_Stream]:
    g = recording.gnss
    stamps = roswrite.stamps_ns(recording, g.t)
    lat, lon, alt = (np.asarray(a, dtype=np.float64) for a in (g.lat_deg, g.lon_deg, g.alt))
    var = None if g.std_enu is None else np.square(np.asarray(g.std_enu, dtype=np.float64))
    out = [_ros2_stream(EMBED_GNSS_TOPIC, "sensor_msgs/msg/NavSatFix", stamps,
                        lambda st, r: roswrite.pack_navsatfix(st, lat[r], lon[r], alt[r], encoding="cdr",
                                                              frame_id="gnss",
                                                              cov_diag=None if var is None else var[r]))]
    if with_velocity and g.vel_enu is not None:
        vel = np.asarray(g.vel_enu, dtype=np.float64)
        vvar = None if g.std_vel_enu is None else np.square(np.asarray(g.std_vel_enu, dtype=np.float64))
        out.append(_ros2_stream(EMBED_GNSS_VEL_TOPIC, "geometry_msgs/msg/TwistWithCovarianceStamped", stamps,
                                lambda st, r: roswrite.pack_twist_with_covariance(
                                    st, vel[r], encoding="cdr", frame_id="gnss",
                                    cov_diag=None if vvar is None else vvar[r])))
    return out


def _input_streams(recording: Recording, input_log: str | os.PathLike[str] | None) -> list[_Stream]:
    """The input's IMU and GNSS: copied from an MCAP input where possible, else encoded."""
    if input_log is not None:
        from navpp.io.detect import log_kind

        kind, where = log_kind(Path(input_log))
        if kind == "mcap":
            return _mcap_input_streams(where, recording)
    return [_encoded_imu(recording), *_encoded_gnss(recording, with_velocity=True)]


def _reference_topic(recording: Recording) -> str | None:
    ref = recording.reference
    prefix = f"{recording.source}:"
    if ref is not None and ref.source.startswith(prefix):
        return ref.source[len(prefix):]
    return None


def _contains_all(have: np.ndarray, values: np.ndarray) -> bool:
    """Whether every element of ``values`` is in ``have`` (exact comparison)."""
    have = np.sort(np.asarray(have))
    values = np.asarray(values)
    if have.size == 0:
        return values.size == 0
    idx = np.minimum(np.searchsorted(have, values), have.size - 1)
    return bool(np.all(have[idx] == values))


def _mcap_input_streams(path: Path, recording: Recording) -> list[_Stream]:
    """Find the MCAP topics the recording's IMU and GNSS came from; copy them or encode."""
    from navpp.io.mcap import list_topics, read_mcap
    from navpp.io.ros import FIX_TYPE, IMU_TYPE, TWIST_COV_TYPE, TWIST_TYPE

    infos = list_topics(path)
    cdr = [t for t in infos if t.encoding == "cdr"]
    exclude = _reference_topic(recording)
    imu_cands = [t.topic for t in cdr if t.msgtype == IMU_TYPE]
    fix_cands = [t.topic for t in cdr if t.msgtype == FIX_TYPE and t.topic != exclude]
    contents = read_mcap(path, imu_cands + fix_cands) if imu_cands or fix_cands else None

    imu_topic = None
    want = roswrite.stamps_ns(recording, recording.imu.t)
    for topic in imu_cands:
        msgs = contents.imu[topic]
        if _contains_all(msgs.stamp_ns, want) or _contains_all(msgs.log_ns, want):
            imu_topic = topic
            break
    gnss_topic = None
    g = recording.gnss
    for topic in fix_cands:
        msgs = contents.fix[topic]
        if _contains_all(msgs.lat_deg, g.lat_deg) and _contains_all(msgs.lon_deg, g.lon_deg):
            gnss_topic = topic
            break
    vel_topic = None
    twists = [t for t in infos if t.msgtype in (TWIST_COV_TYPE, TWIST_TYPE)]
    if gnss_topic is not None and g.vel_enu is not None and len(twists) == 1 and twists[0].encoding == "cdr":
        vel_topic = twists[0].topic

    copied = [t for t in (imu_topic, gnss_topic, vel_topic) if t is not None]
    streams = _copy_topics(path, copied) if copied else []
    # a cut-off file: the reader may have decoded messages a copy cannot take whole; encode instead
    expected = {t.topic: t.count for t in infos}
    short = {t for t in copied if sum(len(s) for s in streams if s.topic == t) != expected[t]}
    if gnss_topic in short:
        short.add(vel_topic)
    streams = [s for s in streams if s.topic not in short]
    imu_topic, gnss_topic, vel_topic = (None if t in short else t for t in (imu_topic, gnss_topic, vel_topic))
    if imu_topic is None:
        streams.append(_encoded_imu(recording))
    if gnss_topic is None:
        streams += _encoded_gnss(recording, with_velocity=True)
    elif vel_topic is None and g.vel_enu is not None:
        streams += _encoded_gnss(recording, with_velocity=True)[1:]
    return streams


@njit(cache=True, nogil=True)
def _copy_spans(dst, dst_off, src, src_off, length):  # pragma: no cover - compiled
    """``dst[dst_off[i]:+length[i]] = src[src_off[i]:+length[i]]`` for every i."""
    for i in range(length.shape[0]):
        a = dst_off[i]
        b = src_off[i]
        for k in range(length[i]):
            dst[a + k] = src[b + k]


def _exclusive_cumsum(a: np.ndarray) -> np.ndarray:
    out = np.zeros(a.shape[0] + 1, dtype=np.int64)
    np.cumsum(a, out=out[1:])
    return out


def _le_fields(buf: np.ndarray, pos: np.ndarray, width: int) -> np.ndarray:
    """Little-endian unsigned integers of ``width`` bytes at ``buf[pos]`` (vectorised), as int64."""
    raw = buf[pos[:, None] + np.arange(width)]
    return raw.copy().view(f"<u{width}").reshape(-1).astype(np.int64)


class _RawCollector:
    """The Message records of some channels, gathered chunk by chunk."""

    def __init__(self) -> None:
        self.parts: dict[int, list[tuple[np.ndarray, ...]]] = {}

    def add(self, buf: np.ndarray, chan: np.ndarray, log: np.ndarray, pos: np.ndarray,
            length: np.ndarray, wanted: set[int]) -> None:
        for cid in sorted(wanted):
            m = chan == cid
            if not m.any():
                continue
            ln = length[m]
            p = pos[m]
            seq = _le_fields(buf, p - 20, 4)
            pub = _le_fields(buf, p - 8, 8)
            off = _exclusive_cumsum(ln)
            data = np.empty(int(off[-1]), dtype=np.uint8)
            _copy_spans(data, off[:-1], buf, p, ln)
            self.parts.setdefault(cid, []).append((log[m], pub, seq, data, ln))

    def result(self, cid: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, _Raw]:
        parts = self.parts.get(cid, [])
        log = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
        pub = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, np.int64)
        seq = np.concatenate([p[2] for p in parts]) if parts else np.zeros(0, np.int64)
        data = np.concatenate([p[3] for p in parts]) if parts else np.zeros(0, np.uint8)
        length = np.concatenate([p[4] for p in parts]) if parts else np.zeros(0, np.int64)
        off = _exclusive_cumsum(length)
        if log.size > 1 and bool(np.any(np.diff(log) < 0)):
            order = np.argsort(log, kind="stable")
            log, pub, seq, length = log[order], pub[order], seq[order], length[order]
            new_off = _exclusive_cumsum(length)
            moved = np.empty_like(data)
            _copy_spans(moved, new_off[:-1], data, off[:-1][order], length)
            data, off = moved, new_off
        return log, pub, seq, _Raw(data, off)


def _copy_topics(path: Path, topics: Sequence[str]) -> list[_Stream]:
    """The raw Message records of ``topics`` (one stream per input channel), with their schemas."""
    from mcap.records import Channel, Chunk, Message, Schema

    # navpp's MCAP reader's record scanner (numba) and record parser: one reading of the format
    from navpp.io.mcap import _parse_record, _Scan

    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    wanted: set[int] = set()
    collector = _RawCollector()

    def channel(record: Any) -> None:
        if record.id not in channels:
            channels[record.id] = record
            if record.topic in topics:
                wanted.add(record.id)

    for op, content in _top_level_records(path):
        if op == 0x03:
            s = _parse_record(Schema, content)
            schemas.setdefault(s.id, s)
        elif op == 0x04:
            channel(_parse_record(Channel, content))
        elif op == 0x05:
            record = _parse_record_sized(Message, content)
            if record.channel_id in wanted:
                data = np.frombuffer(record.data, dtype=np.uint8)
                collector.parts.setdefault(record.channel_id, []).append(
                    (np.array([record.log_time]), np.array([record.publish_time]),
                     np.array([record.sequence]), data.copy(), np.array([data.size])))
        elif op == 0x06:
            raw = _decompress(_parse_record(Chunk, content))
            scan = _Scan(raw, 0, raw.shape[0], False)
            for r_op, pos, length in zip(scan.rec_op.tolist(), scan.rec_pos.tolist(), scan.rec_len.tolist()):
                if r_op == 0x03:
                    s = _parse_record(Schema, raw[pos:pos + length])
                    schemas.setdefault(s.id, s)
                elif r_op == 0x04:
                    channel(_parse_record(Channel, raw[pos:pos + length]))
            if wanted:
                collector.add(raw, scan.chan, scan.log, scan.pos, scan.len, wanted)
    streams = []
    for cid in sorted(wanted):
        ch = channels[cid]
        schema = schemas.get(ch.schema_id)
        if schema is None:
            raise ValueError(f"{path}: channel {cid} ({ch.topic}) has no schema")
        log, pub, seq, raw_payloads = collector.result(cid)
        streams.append(_Stream(ch.topic, schema.name, schema.encoding, bytes(schema.data), ch.message_encoding,
                               log, pub, seq, raw_payloads, dict(ch.metadata)))
    return streams


def _top_level_records(path: Path) -> Iterator[tuple[int, bytes]]:
    """(opcode, content) of the data section's Schema, Channel, Message and Chunk records; the
    others (message indexes, attachments, ...) are skipped unread.  Stops at DataEnd / Footer,
    or before a record the file does not hold whole (a cut-off recording)."""
    wanted = (0x03, 0x04, 0x05, 0x06)
    size = path.stat().st_size
    with open(path, "rb") as f:
        pos = len(_MAGIC)
        while pos + 9 <= size:
            f.seek(pos)
            op, length = struct.unpack("<BQ", f.read(9))
            if op in (0x0F, 0x02) or pos + 9 + length > size:
                return
            if op in wanted:
                yield op, f.read(length)
            pos += 9 + length


def _parse_record_sized(cls: Any, content: bytes) -> Any:
    """Parse a record whose reader needs its length (Message)."""
    import io

    from mcap.data_stream import ReadDataStream

    return cls.read(ReadDataStream(io.BytesIO(content)), len(content))


def _decompress(chunk: Any) -> np.ndarray:
    if chunk.compression == "":
        data = chunk.data
    elif chunk.compression == "zstd":
        import zstandard

        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame

        data = lz4.frame.decompress(chunk.data)
    else:
        raise ValueError(f"unsupported chunk compression {chunk.compression!r}")
    return np.frombuffer(data, dtype=np.uint8)


# --------------------------------------------------------------------------- the container


@njit(cache=True, inline="always")
def _put(out, p, value, nbytes):  # pragma: no cover - compiled
    v = np.uint64(value)
    for k in range(nbytes):
        out[p + k] = np.uint8((v >> np.uint64(8 * k)) & np.uint64(0xFF))


@njit(cache=True, nogil=True)
def _message_records(out, src, src_off, length, chan, seq, log, pub):  # pragma: no cover - compiled
    """Lay out MCAP Message records (opcode 0x05, u64 length, u16 channel, u32 sequence, u64
    log time, u64 publish time, payload) back to back in ``out``; returns the bytes written."""
    p = 0
    for i in range(length.shape[0]):
        n = length[i]
        out[p] = 5
        _put(out, p + 1, 22 + n, 8)
        _put(out, p + 9, chan[i], 2)
        _put(out, p + 11, seq[i] & 0xFFFFFFFF, 4)
        _put(out, p + 15, log[i], 8)
        _put(out, p + 23, pub[i], 8)
        q = p + 31
        s = src_off[i]
        for k in range(n):
            out[q + k] = src[s + k]
        p = q + n
    return p


class _Output:
    """A binary file and the number of bytes written to it."""

    def __init__(self, f: IO[bytes]) -> None:
        self.f = f
        self.pos = 0

    def write(self, data: Any) -> None:
        self.f.write(data)
        self.pos += memoryview(data).nbytes


def _record_bytes(*records: Any) -> bytes:
    from mcap.data_stream import RecordBuilder

    builder = RecordBuilder()
    for r in records:
        r.write(builder)
    return bytes(builder.end())


def _compressor(compression: str) -> tuple[str, Callable[[np.ndarray], Any]]:
    if compression == "zstd":
        import zstandard

        return "zstd", zstandard.ZstdCompressor(level=1).compress
    if compression == "lz4":
        import lz4.frame

        return "lz4", lambda data: lz4.frame.compress(data)
    if compression == "none":
        return "", lambda data: data
    raise ValueError(f"compression must be one of {_COMPRESSIONS}, got {compression!r}")


def _message_index_records(chan: np.ndarray, log: np.ndarray, rec_off: np.ndarray) -> tuple[bytes, dict[int, int]]:
    """Message Index records (one per channel of the chunk): bytes and each record's offset."""
    parts: list[bytes] = []
    offsets: dict[int, int] = {}
    pos = 0
    for cid in np.unique(chan).tolist():
        m = chan == cid
        entries = np.empty((int(np.count_nonzero(m)), 2), dtype="<u8")
        entries[:, 0] = log[m]
        entries[:, 1] = rec_off[m]
        body = entries.tobytes()
        head = struct.pack("<BQHI", _OP_MESSAGE_INDEX, 2 + 4 + len(body), cid, len(body))
        offsets[cid] = pos
        parts += [head, body]
        pos += len(head) + len(body)
    return b"".join(parts), offsets


class _Timeline:
    """Every message of ``streams`` in log-time order (stable: stream order at equal times),
    cut into chunks of about ``chunk_size`` bytes of records.

    Each stream's messages are sorted by log time, so every chunk holds a contiguous run of
    each stream's messages, packed in one call.
    """

    def __init__(self, streams: Sequence[_Stream], chunk_size: int) -> None:
        if not streams:
            raise ValueError("no message stream to write")
        self.streams = streams
        self.counts = np.array([len(s) for s in streams], dtype=np.int64)
        log = np.concatenate([s.log_ns for s in streams])
        order = np.argsort(log, kind="stable")
        self.log = log[order]
        self.stream = np.repeat(np.arange(len(streams), dtype=np.int64), self.counts)[order]
        self.index = np.concatenate([np.arange(c, dtype=np.int64) for c in self.counts])[order]
        self.publish = np.concatenate([s.publish_ns for s in streams])[order]
        self.sequence = np.concatenate([s.sequence for s in streams])[order]
        self.length = np.concatenate([s.payloads.lengths() for s in streams])[order]
        self.record_length = self.length + _MESSAGE_OVERHEAD
        self.start = np.cumsum(self.record_length) - self.record_length
        cuts = np.flatnonzero(np.diff(self.start // max(int(chunk_size), 1))) + 1
        self.bounds = np.concatenate([[0], cuts, [self.log.size]]).astype(np.int64)

    def chunks(self) -> Iterator[tuple[int, int]]:
        for a, b in zip(self.bounds[:-1].tolist(), self.bounds[1:].tolist()):
            if b > a:
                yield a, b

    def records(self, a: int, b: int) -> np.ndarray:
        """The Message records of messages a..b-1 (channel id = stream index + 1), laid out."""
        which = self.stream[a:b]
        length = self.length[a:b]
        src_off = np.empty(b - a, dtype=np.int64)
        blocks = []
        base = 0
        for sid in np.unique(which).tolist():
            mine = which == sid
            idx = self.index[a:b][mine]
            i0, i1 = int(idx[0]), int(idx[-1]) + 1
            flat, lens = self.streams[sid].payloads.block(i0, i1)
            if i1 - i0 != idx.size or not np.array_equal(lens, length[mine]):
                raise AssertionError(f"{self.streams[sid].topic}: messages out of order or of unexpected size")
            src_off[mine] = base + _exclusive_cumsum(lens)[:-1]
            blocks.append(flat)
            base += flat.size
        src = np.concatenate(blocks) if len(blocks) > 1 else blocks[0]
        out = np.empty(int(self.start[b - 1] + self.record_length[b - 1] - self.start[a]), dtype=np.uint8)
        _message_records(out, src, src_off, length, which + 1, self.sequence[a:b], self.log[a:b],
                         self.publish[a:b])
        return out


class _McapWriter:
    """The records of an MCAP file (profile ``ros2``), written front to back.

    Schema, Channel and the Metadata record first; then each chunk followed by its Message Index
    records; DataEnd; the summary (schemas, channels, statistics, metadata index, chunk indexes),
    the summary offsets and the footer.
    """

    def __init__(self, f: IO[bytes], compression: str) -> None:
        self.out = _Output(f)
        self.compression, self.compress = _compressor(compression)
        self.schemas: list[Any] = []
        self.channels: list[Any] = []
        self.metadata_indexes: list[Any] = []
        self.chunk_indexes: list[Any] = []

    def start(self, streams: Sequence[_Stream], metadata: dict[str, str]) -> None:
        from mcap.records import Channel, Header, Metadata, MetadataIndex, Schema

        from navpp import __version__

        self.out.write(_MAGIC)
        self.out.write(_record_bytes(Header(profile="ros2", library=f"navpp {__version__}")))
        schema_ids: dict[tuple[str, str, bytes], int] = {}
        for s in streams:              # channel id i + 1 for stream i
            key = (s.schema_name, s.schema_encoding, s.schema_data)
            if key not in schema_ids:
                schema_ids[key] = len(self.schemas) + 1
                self.schemas.append(Schema(id=schema_ids[key], name=s.schema_name, encoding=s.schema_encoding,
                                           data=s.schema_data))
            self.channels.append(Channel(id=len(self.channels) + 1, topic=s.topic,
                                         message_encoding=s.message_encoding, schema_id=schema_ids[key],
                                         metadata=dict(s.metadata)))
        self.out.write(_record_bytes(*self.schemas, *self.channels))
        meta = _record_bytes(Metadata(name="navpp", metadata=dict(metadata)))
        self.metadata_indexes.append(MetadataIndex(offset=self.out.pos, length=len(meta), name="navpp"))
        self.out.write(meta)

    def chunk(self, records: np.ndarray, channel: np.ndarray, log: np.ndarray, offsets: np.ndarray) -> None:
        """A Chunk of Message ``records`` (per message: channel, log time, offset in ``records``),
        then its Message Index records."""
        from mcap.records import ChunkIndex

        name = self.compression
        packed = self.compress(records)
        t0, t1 = int(log.min()), int(log.max())
        head = struct.pack("<BQQQQI", 0x06, 8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(packed), t0, t1,
                           records.size, zlib.crc32(records))
        head += struct.pack("<I", len(name)) + name.encode() + struct.pack("<Q", len(packed))
        chunk_start = self.out.pos
        self.out.write(head)
        self.out.write(packed)
        chunk_length = self.out.pos - chunk_start
        index_start = self.out.pos
        index, where = _message_index_records(channel, log, offsets)
        self.out.write(index)
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=t0, message_end_time=t1, chunk_start_offset=chunk_start, chunk_length=chunk_length,
            message_index_offsets={c: index_start + o for c, o in where.items()}, message_index_length=len(index),
            compression=name, compressed_size=len(packed), uncompressed_size=records.size))

    def finish(self, counts: np.ndarray, log_start: int, log_end: int) -> None:
        from mcap.records import DataEnd, Footer, Statistics, SummaryOffset

        self.out.write(_record_bytes(DataEnd(data_section_crc=0)))
        stats = Statistics(message_count=int(counts.sum()), schema_count=len(self.schemas),
                           channel_count=len(self.channels), attachment_count=0,
                           metadata_count=len(self.metadata_indexes), chunk_count=len(self.chunk_indexes),
                           message_start_time=log_start, message_end_time=log_end,
                           channel_message_counts={i + 1: int(c) for i, c in enumerate(counts.tolist()) if c})
        summary_start = self.out.pos
        summary = b""
        offsets = []
        for opcode, group in ((0x03, self.schemas), (0x04, self.channels), (0x0B, [stats]),
                              (0x0D, self.metadata_indexes), (0x08, self.chunk_indexes)):
            data = _record_bytes(*group)
            if data:
                offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + len(summary),
                                             group_length=len(data)))
                summary += data
        offsets_start = summary_start + len(summary)
        summary += _record_bytes(*offsets)
        # summary CRC: the summary section and the footer up to its summary_offset_start field
        footer_head = struct.pack("<BQQQ", 0x02, 8 + 8 + 4, summary_start, offsets_start)
        self.out.write(summary)
        self.out.write(_record_bytes(Footer(summary_start=summary_start, summary_offset_start=offsets_start,
                                            summary_crc=zlib.crc32(footer_head, zlib.crc32(summary)))))
        self.out.write(_MAGIC)


def _write_container(f: IO[bytes], streams: Sequence[_Stream], metadata: dict[str, str], *,
                     chunk_size: int = CHUNK_SIZE, compression: str = "zstd") -> None:
    """Write an MCAP file holding ``streams`` (channel ``i + 1`` for stream ``i``), in log-time order."""
    timeline = _Timeline(streams, chunk_size)
    writer = _McapWriter(f, compression)
    writer.start(streams, metadata)
    for a, b in timeline.chunks():
        writer.chunk(timeline.records(a, b), timeline.stream[a:b] + 1, timeline.log[a:b],
                     timeline.start[a:b] - timeline.start[a])
    log = timeline.log
    writer.finish(timeline.counts, int(log[0]) if log.size else 0, int(log[-1]) if log.size else 0)


# --------------------------------------------------------------------------- entry point


def _write(path: str | os.PathLike[str], streams: Sequence[_Stream], metadata: dict[str, str], *,
           chunk_size: int = CHUNK_SIZE, compression: str = "zstd") -> None:
    types: dict[str, str] = {}
    for s in streams:
        if types.setdefault(s.topic, s.schema_name) != s.schema_name:
            raise ValueError(f"topic {s.topic} would carry both {types[s.topic]} and {s.schema_name} "
                             "(an input topic named like one of navpp's output topics?)")
    _compressor(compression)  # a bad name fails before the file is created
    atomic_write(path, lambda f: _write_container(f, streams, metadata, chunk_size=chunk_size,
                                                  compression=compression), mode="wb")


def write_trajectory_mcap(path: str | os.PathLike[str], *, solution: Solution, recording: Recording,
                          diagnostics: Any = None, biases: Any = None, embed_input: bool = False,
                          input_log: str | os.PathLike[str] | None = None, filter_name: str = "",
                          forward: Solution | None = None) -> None:
    """Write ``trajectory.mcap``: the solution, biases and filter diagnostics as ROS 2 messages.

    See the module docstring for the topics, frames, units and covariances.

    Parameters
    ----------
    path : output file; written atomically (a temporary name in the same directory, renamed when
        complete: a failure leaves no file, and an existing file as it was).
    solution : the solution to write (e.g. at ``--output-rate``), ``t`` relative to
        ``recording.t0_ns``.
    recording : the input recording (time base, the map anchor's GNSS, the embedded input).
    diagnostics : :class:`navpp.engine.Diagnostics` -> ``/navpp/diagnostics``; None: no topic.
    biases : :class:`navpp.engine.BiasHistory` -> ``/navpp/bias/gyro``, ``/navpp/bias/accel``;
        None: no topics.
    embed_input : also write the input IMU and GNSS messages (copied from an MCAP
        ``input_log``, else encoded from ``recording``).
    input_log : the input log's path (used with ``embed_input``).
    filter_name : recorded in the file's ``navpp`` metadata.
    forward : for a smoothed ``solution``, the forward filter's solution (same rows' time base):
        written to ``/navpp/forward/fix`` and ``/navpp/forward/odometry``; the metadata's
        ``solution`` says ``smoothed`` (else ``forward``).

    Raises
    ------
    ValueError
        An empty solution, a solution on another time base, stamps outside the ROS time range,
        or an input topic named like one of navpp's output topics but of another type.
    navpp.errors.InputError
        ``input_log`` cannot be read.
    """
    streams, anchor = _solution_streams(solution, recording, diagnostics, biases, forward)
    if embed_input:
        streams = _input_streams(recording, input_log) + streams
    metadata = {
        "filter": filter_name,
        "solution": "smoothed (Rauch-Tung-Striebel)" if forward is not None else "forward",
        "source": str(recording.source),
        "time_base": recording.time_base,
        "t0_ns": str(int(recording.t0_ns)),
        "map_frame": "ENU (x east, y north, z up), m, tangent plane at the anchor",
        "map_anchor_lat_deg": repr(anchor.lat_deg),
        "map_anchor_lon_deg": repr(anchor.lon_deg),
        "map_anchor_alt_m": repr(anchor.alt),
        "body_frame": "FLU (x forward, y left, z up)",
        "not_estimated_variance": repr(NOT_ESTIMATED_VARIANCE),
    }
    _write(path, streams, metadata)
