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
  ``twist.angular`` the body rate (:attr:`~navpp.recording.Solution.rate_body`: gyro minus
  the estimated bias, Earth and transport rate; base_link, rad/s).  Covariances (row-major
  6x6, x y z then rotations about x y z; :func:`odometry_covariances`): the pose's position
  block diag(std_e², std_n², std_u²) (ENU m²; the map's axes differ from the local ENU axes by
  the tiny rotation described in :mod:`navpp.io.frames`), its orientation block diag of the
  filter's attitude-error variances about E, N, U (rad²); the twist's linear block the ENU
  velocity variances rotated into base_link (``C_bn diag(σ²) C_nb``, m²/s², not diagonal), its
  angular block the gyro-bias variance after the last fix plus the gyro's white noise per
  sample (rad²/s²).  A Solution that carries no such sigma (one made by hand) gets
  :data:`NOT_ESTIMATED_VARIANCE` (1e6) there: ROS defines no "unknown" marker for Odometry;
  zero would claim a perfect estimate, a huge variance makes a consumer ignore the value.
- ``/tf`` ``tf2_msgs/msg/TFMessage``, one per solution row: ``odom`` -> ``base_link`` with the
  odometry's pose.  ``/tf_static`` (one message at the first row's stamp, QoS transient local):
  ``map`` -> ``odom`` identity, ``base_link`` -> ``imu_link`` (the IMU's mounting rotation,
  ``[imu] mounting_rpy_deg`` or the gross mounting the run found) and ``base_link`` -> ``gnss``
  (the antenna lever arm ``[gnss] lever_arm_m``), so the tree is map -> odom -> base_link ->
  {imu_link, gnss} as REP-105 names it.  REP-105 wants ``odom`` continuous and ``map``
  globally correct; navpp's GNSS-aided solution is both at once (one estimate, corrected at
  each fix by a few cm, with no separate dead-reckoning track), so ``map`` -> ``odom`` is the
  identity and all of the pose is in ``odom`` -> ``base_link``; the Odometry's header keeps
  ``map`` (the same frame).  A robot that has its own ``odom`` should take ``/navpp/odometry``
  into its own localisation rather than this tree.
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

Embedded input (``embed_input=True``): the input log in the same file, every topic as it was,
so one file replays everything.

- MCAP file, ROS 2 bag: every Message record copied as it is (:func:`_copied_input_streams`):
  payload bytes, log time, topic, schema (name, encoding, definition) and, where the input has
  them (MCAP files, rosbag2's mcap storage), publish time, sequence number and channel metadata
  (e.g. rosbag2's QoS profiles).  A sqlite3 (or compressed) ROS 2 bag is read with rosbags: the
  CDR payloads after the bag's own decompression, its one receive time as log and publish
  time, its message definition (else ROS 2 Humble's) and QoS profiles.  A ROS 1 encoded MCAP
  channel is converted to ROS 2 CDR as a ROS 1 bag is.
- ROS 1 bag: every topic converted to ROS 2 CDR (:func:`_ros1_input_streams`).
- CSV: the recording encoded: ``sensor_msgs/msg/Imu`` on ``/imu/data`` (frame ``imu_link``),
  ``sensor_msgs/msg/NavSatFix`` on ``/gnss/fix`` (frame ``gnss``) and, with GNSS velocity,
  ``geometry_msgs/msg/TwistWithCovarianceStamped`` on ``/gnss/vel`` and, with wheel odometry
  (``Recording.odometry``), ``nav_msgs/msg/Odometry`` on ``/wheel/odom`` (child frame
  ``base_link``), exactly as :func:`navpp.io.roswrite.write_mcap_ros2` writes them (navpp reads
  them back as the same arrays).

Left out, and listed (one ``"TOPIC (TYPE): reason"`` each, in the ``navpp`` metadata's
``embedded_input_skipped`` and returned by :func:`write_trajectory_mcap` for the run's notes): an
input topic named like one of navpp's output topics (``/tf``, ``/tf_static``, ``/navpp/...``),
a channel neither CDR nor ROS 1 encoded (JSON, Protobuf, ...: the file's profile is ``ros2``), a
topic of several types, a type that cannot be converted or has no definition.  The topics the
recording's IMU, GNSS (with its velocity) and odometry came from are found by content (the
recording's IMU stamps, header or log, and GNSS positions must all be found in the topic); what
the copy does not hold is encoded from the recording as for CSV: GNSS from ``--gnss FILE.pos``,
or a topic the copy cannot take whole (the last, partial chunk of a cut-off recording, which
navpp's reader still decodes) on its own name; a name the input already uses becomes
``/navpp/input/<name>``.

The input's own frames join the tf tree: ``/tf_static`` also gets ``base_link`` -> the
``header.frame_id`` of the embedded IMU messages navpp used (the IMU mounting, as for
``imu_link``) and -> that of its GNSS NavSatFix messages (the lever arm, as for ``gnss``), when
they are not already frames of the tree, so every embedded IMU and GNSS message resolves to
``map``.  ``imu_link`` and ``gnss`` stay (navpp's own names, used by an encoded input).  Other
sensors' frames are not linked: navpp does not know where they are mounted.

File layout
-----------
The container is written by the ``mcap`` package's :class:`mcap.writer.Writer`: profile
``ros2``, the ``navpp`` Metadata record ahead of the data, messages in log-time order (stable:
embedded input first, then the topics above, at equal times) in zstd chunks of about
:data:`CHUNK_SIZE` bytes, each followed by its message indexes; the summary holds the schemas,
channels, statistics, chunk and metadata indexes and the summary offsets, with CRCs.  The
payloads are serialised in bulk by numpy (:mod:`navpp.io.roswrite`'s ``pack_*``, one structured
array per stream and block of about a chunk), then handed to the Writer as one ``bytes`` per
message.  The file is written atomically (:func:`navpp.io.writers.atomic_write`).
"""

from __future__ import annotations

import functools
import os
import struct
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from operator import itemgetter
from pathlib import Path
from typing import IO, Any

import numpy as np

from navpp.io import frames, roswrite
from navpp.io.writers import adaptive_columns, atomic_write
from navpp.recording import Recording, Solution

__all__ = [
    "BODY_FRAME",
    "CHUNK_SIZE",
    "COMPRESSIONS",
    "GNSS_FRAME",
    "IMU_FRAME",
    "MAP_FRAME",
    "NOT_ESTIMATED_VARIANCE",
    "ODOM_FRAME",
    "TOPICS",
    "adaptive_columns",
    "write_trajectory_mcap",
]

MAP_FRAME = "map"
ODOM_FRAME = "odom"
BODY_FRAME = "base_link"
IMU_FRAME = "imu_link"
GNSS_FRAME = "gnss"
#: Variance written for what navpp does not estimate (see the module docstring).
NOT_ESTIMATED_VARIANCE = 1.0e6
#: Target uncompressed size of a chunk, bytes.
CHUNK_SIZE = 4 * 2**20

TOPIC_FIX = "/navpp/fix"
TOPIC_ODOMETRY = "/navpp/odometry"
TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"
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
    TOPIC_TF_STATIC: "tf2_msgs/msg/TFMessage",
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
EMBED_ODOMETRY_TOPIC = "/wheel/odom"

#: Chunk compressions :func:`write_trajectory_mcap` takes ("none": uncompressed chunks).
COMPRESSIONS = ("zstd", "lz4", "none")


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

    def block(self, i0: int, i1: int) -> list[bytes]:
        arr = self.pack(i0, i1)
        if arr.shape != (i1 - i0,) or arr.dtype.itemsize != self.size:
            raise ValueError(f"packed {arr.shape} x {arr.dtype.itemsize} B, expected ({i1 - i0},) x {self.size} B")
        return roswrite.payload_bytes(arr)


@dataclass(frozen=True)
class _Raw:
    """Payloads held as ``bytes``, one per message."""

    data: list[bytes]

    def lengths(self) -> np.ndarray:
        return np.fromiter((len(d) for d in self.data), dtype=np.int64, count=len(self.data))

    def block(self, i0: int, i1: int) -> list[bytes]:
        return self.data[i0:i1]


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
    sequence: np.ndarray  # (N,) int64, each in the u32 range
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
    return _Stream(topic, msgtype, "ros2msg", roswrite.MSGDEFS[msgtype].encode(), "cdr", stamps, stamps,
                   np.arange(stamps.size, dtype=np.int64),
                   _Packed(stamps.size, lambda i0, i1: pack(stamps[i0:i1], slice(i0, i1))))


def _solution_streams(solution: Solution, recording: Recording, diagnostics: Any,
                      biases: Any, forward: Solution | None = None, *,
                      static: tuple[np.ndarray, np.ndarray] | None = None,
                      rate_noise_std: float = 0.0,
                      input_frames: tuple[Sequence[str], Sequence[str]] = ((), ())
                      ) -> tuple[list[_Stream], frames.Anchor]:
    if len(solution) == 0:
        raise ValueError("the solution is empty: nothing to write")
    anchor = frames.anchor_for(solution, recording)
    streams = _pose_streams(solution, recording, anchor, TOPIC_FIX, TOPIC_ODOMETRY, tf=True, biases=biases,
                            rate_noise_std=rate_noise_std)
    mounting, lever = static if static is not None else (np.eye(3), np.zeros(3))
    streams.append(_tf_static_stream(int(roswrite.stamps_ns(recording, solution.t[:1])[0]), mounting, lever,
                                     *input_frames))
    if forward is not None:
        streams += _pose_streams(forward, recording, anchor, TOPIC_FORWARD_FIX, TOPIC_FORWARD_ODOMETRY, tf=False,
                                 biases=None, rate_noise_std=rate_noise_std)
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
                  odom_topic: str, tf: bool, biases: Any = None, rate_noise_std: float = 0.0) -> list[_Stream]:
    """NavSatFix, Odometry (and with ``tf`` the odom -> base_link transform) of every row."""
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
    angular = (np.zeros((n, 3)) if solution.rate_body is None
               else np.asarray(solution.rate_body, dtype=np.float64).reshape(n, 3))

    def pack_odometry(st: np.ndarray, r: slice) -> np.ndarray:
        arr = roswrite.pack_odometry(st, pos_map[r], quat[r], vel_b[r], angular[r], encoding="cdr",
                                     frame_id=MAP_FRAME, child_frame_id=BODY_FRAME)
        pose_cov, twist_cov = odometry_covariances(solution, biases, rate_noise_std, rows=r)
        arr["pose_covariance"] = pose_cov.reshape(-1, 36)
        arr["twist_covariance"] = twist_cov.reshape(-1, 36)
        return arr

    streams = [
        _ros2_stream(fix_topic, _ALL_TOPICS[fix_topic], stamps, lambda st, r: roswrite.pack_navsatfix(
            st, lat[r], lon[r], alt[r], encoding="cdr", frame_id=BODY_FRAME, cov_diag=var[r])),
        _ros2_stream(odom_topic, _ALL_TOPICS[odom_topic], stamps, pack_odometry),
    ]
    if tf:
        streams.append(_ros2_stream(TOPIC_TF, TOPICS[TOPIC_TF], stamps, lambda st, r: roswrite.pack_tf_message(
            st, pos_map[r], quat[r], encoding="cdr", frame_id=ODOM_FRAME, child_frame_id=BODY_FRAME)))
    return streams


def odometry_covariances(solution: Solution, biases: Any = None, rate_noise_std: float = 0.0,
                         rows: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """``pose.covariance`` and ``twist.covariance`` (N, 6, 6) of ``/navpp/odometry`` (module
    docstring): position diag(std_e², std_n², std_u²) m²; orientation diag of ``std_att²`` rad²
    (rotations about the map's x y z = E N U axes); linear twist ``C_bn diag(std_vel_enu²) C_nb``
    (m²/s², base_link axes); angular twist diag(gyro bias variance after the last fix at or before
    the row + ``rate_noise_std²``) rad²/s².  What the solution does not carry:
    :data:`NOT_ESTIMATED_VARIANCE` on the diagonal.  ``rows``: of these rows only (the writer
    makes them a block at a time)."""

    def cut(a: Any) -> Any:
        return None if a is None else np.asarray(a)[rows]

    t = np.asarray(solution.t, dtype=float)[rows]
    n = t.shape[0]
    std_enu, std_att, std_vel, rate = (cut(solution.std_enu), cut(solution.std_att), cut(solution.std_vel_enu),
                                       cut(solution.rate_body))
    pose = np.zeros((n, 6, 6))
    twist = np.zeros((n, 6, 6))
    i3 = np.arange(3)
    pose[:, i3, i3] = np.square(np.asarray(std_enu, dtype=np.float64).reshape(n, 3))
    if std_att is not None:
        pose[:, i3 + 3, i3 + 3] = np.square(np.asarray(std_att, dtype=np.float64).reshape(n, 3))
    else:
        pose[:, i3 + 3, i3 + 3] = NOT_ESTIMATED_VARIANCE
    if std_vel is not None:
        rph = np.radians(np.asarray(solution.rph_deg, dtype=float)[rows])
        from ..ins.attitude import rph_to_dcm

        c_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
        v = np.square(np.asarray(std_vel, dtype=np.float64).reshape(n, 3))
        twist[:, :3, :3] = np.einsum("nji,nj,njk->nik", c_nb, v, c_nb)
    else:
        twist[:, i3, i3] = NOT_ESTIMATED_VARIANCE
    if rate is not None and biases is not None and len(biases.t):
        k = np.searchsorted(np.asarray(biases.t, dtype=float), t, side="right") - 1
        bstd = np.asarray(biases.gyro_std, dtype=np.float64).reshape(-1, 3)[np.maximum(k, 0)]
        twist[:, i3 + 3, i3 + 3] = np.square(bstd) + float(rate_noise_std) ** 2
    elif rate is not None and rate_noise_std > 0.0:
        twist[:, i3 + 3, i3 + 3] = float(rate_noise_std) ** 2
    else:
        twist[:, i3 + 3, i3 + 3] = NOT_ESTIMATED_VARIANCE
    return pose, twist


def _tf_static_stream(stamp_ns: int, mounting: np.ndarray, lever_arm_m: np.ndarray,
                      imu_frames: Sequence[str] = (), gnss_frames: Sequence[str] = ()) -> _Stream:
    """One ``/tf_static`` message: map -> odom (identity), base_link -> imu_link (the IMU's
    mounting: the rotation taking sensor vectors into base_link), base_link -> gnss (the antenna
    lever arm, m, base_link FLU), and the same two transforms to the embedded input's own IMU and
    GNSS frame ids (``imu_frames``, ``gnss_frames``) that the tree does not have yet."""
    ts = _humble_typestore()
    t = ts.types
    q = frames.quat_xyzw(np.asarray(mounting, dtype=float).reshape(1, 3, 3))[0]
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)

    def transform(parent: str, child: str, xyz: Any, xyzw: Any) -> Any:
        header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                          frame_id=parent)
        return t["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id=child, transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                rotation=t["geometry_msgs/msg/Quaternion"](x=float(xyzw[0]), y=float(xyzw[1]), z=float(xyzw[2]),
                                                           w=float(xyzw[3]))))

    lever = np.asarray(lever_arm_m, dtype=float).reshape(3)
    transforms = [
        transform(MAP_FRAME, ODOM_FRAME, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        transform(BODY_FRAME, IMU_FRAME, (0.0, 0.0, 0.0), q),
        transform(BODY_FRAME, GNSS_FRAME, lever, (0.0, 0.0, 0.0, 1.0)),
    ]
    known = {MAP_FRAME, ODOM_FRAME, BODY_FRAME, IMU_FRAME, GNSS_FRAME}
    for frames_of, xyz, xyzw in ((imu_frames, (0.0, 0.0, 0.0), q), (gnss_frames, lever, (0.0, 0.0, 0.0, 1.0))):
        for frame in frames_of:
            if frame not in known:
                known.add(frame)
                transforms.append(transform(BODY_FRAME, frame, xyz, xyzw))
    msg = t["tf2_msgs/msg/TFMessage"](transforms=transforms)
    data = bytes(ts.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
    st = np.array([stamp_ns], dtype=np.int64)
    msgtype = TOPICS[TOPIC_TF_STATIC]
    return _Stream(TOPIC_TF_STATIC, msgtype, "ros2msg", roswrite.MSGDEFS[msgtype].encode(), "cdr", st, st,
                   np.zeros(1, dtype=np.int64), _Raw([data]),
                   {"offered_qos_profiles": _TRANSIENT_LOCAL_QOS})


#: rosbag2's QoS metadata of a latched topic (``/tf_static``): keep last 1, reliable, transient
#: local (rmw enum values: history 1 keep last, reliability 1 reliable, durability 1 transient
#: local, liveliness 1 automatic), so ``ros2 bag play`` offers it to late subscribers.
_TRANSIENT_LOCAL_QOS = ("- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n"
                        "  deadline:\n    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n"
                        "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n"
                        "  avoid_ros_namespace_conventions: false\n")


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


def _encoded_odometry(recording: Recording) -> list[_Stream]:
    """``recording.odometry`` as ``nav_msgs/msg/Odometry`` on :data:`EMBED_ODOMETRY_TOPIC` (as
    :func:`navpp.io.roswrite.write_mcap_ros2` writes it); none without odometry."""
    od = recording.odometry
    if od is None or len(od) == 0:
        return []
    return [_ros2_stream(EMBED_ODOMETRY_TOPIC, "nav_msgs/msg/Odometry", roswrite.stamps_ns(recording, od.t),
                         lambda st, r: _odometry_rows(recording, r, st))]


def _odometry_rows(recording: Recording, rows: slice, stamps: np.ndarray) -> np.ndarray:
    """Packed ``nav_msgs/Odometry`` of ``recording.odometry`` rows: speed (m/s) as linear x, yaw
    rate (rad/s) as angular z, their variances as twist covariance [0] / [35] (0 when not given)."""
    od = recording.odometry
    assert od is not None
    n = stamps.size
    linear, angular, var = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 6))
    linear[:, 0] = od.speed[rows]
    if od.yaw_rate is not None:
        angular[:, 2] = od.yaw_rate[rows]
    for col, std in ((0, od.std_speed), (5, od.std_yaw_rate)):
        if std is not None:
            var[:, col] = np.nan_to_num(np.square(std[rows]), nan=0.0)
    quat = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), (n, 4))
    return roswrite.pack_odometry(stamps, np.zeros((n, 3)), quat, linear, angular, encoding="cdr",
                                  frame_id="odom", child_frame_id="base_link", twist_var=var)


@dataclass(frozen=True)
class _Embedded:
    """The embedded input: its streams, the input topics left out (one line each), and the
    header frame ids of the input IMU and GNSS messages navpp used (for ``/tf_static``)."""

    streams: list[_Stream]
    skipped: list[str] = field(default_factory=list)
    imu_frames: tuple[str, ...] = ()
    gnss_frames: tuple[str, ...] = ()


def _input_streams(recording: Recording, input_log: str | os.PathLike[str] | None) -> _Embedded:
    """The input: every topic of an MCAP file or a ROS 2 bag copied as it was
    (:func:`_copied_input_streams`); every topic of a ROS 1 bag, converted
    (:func:`_ros1_input_streams`); else (CSV) the recording encoded."""
    if input_log is not None:
        from navpp.io.detect import log_kind

        kind, where = log_kind(Path(input_log))
        if kind in ("mcap", "ros2"):
            return _copied_input_streams(kind, where, recording)
        if kind == "ros1":
            return _ros1_input_streams(where, recording)
    return _Embedded([_encoded_imu(recording), *_encoded_gnss(recording, with_velocity=True),
                      *_encoded_odometry(recording)])


def _output_topic_collision(topic: str) -> bool:
    """Whether an input topic is named like one of navpp's output topics (it is left out)."""
    return topic in _ALL_TOPICS


def _free_topic(topic: str, taken: set[str]) -> str:
    """``topic``, or ``/navpp/input<topic>`` when an embedded input topic already has that name."""
    return topic if topic not in taken else "/navpp/input" + topic


def _header_frames(streams: Sequence[_Stream], topic: str | None) -> tuple[str, ...]:
    """The distinct ``header.frame_id`` of the CDR messages of ``topic`` among ``streams``, read
    from the raw bytes (a ROS 2 message with a header starts with it: 4 bytes of CDR
    encapsulation, ``stamp.sec``, ``stamp.nanosec``, then the frame id as a u32 length and
    its NUL-terminated characters)."""
    found: dict[str, None] = {}
    for s in streams:
        if s.topic != topic or s.message_encoding != "cdr" or not isinstance(s.payloads, _Raw):
            continue
        for data in s.payloads.data:
            if len(data) < 16:
                continue
            little = data[1] == 1
            (n,) = struct.unpack_from("<I" if little else ">I", data, 12)
            if 0 < n <= len(data) - 16:
                found.setdefault(data[16:16 + n - 1].decode("utf-8", "replace"), None)
    return tuple(f for f in found if f)


def _copied_input_streams(kind: str, path: Path, recording: Recording) -> _Embedded:
    """Every topic of an MCAP file or a ROS 2 bag, copied as it was (:func:`_raw_mcap_streams`,
    :func:`_raw_ros2_streams`), except the topics named like navpp's output topics and those
    not ROS 2 CDR encoded (listed as skipped).  The topics the recording's IMU, GNSS (with its
    velocity) and odometry came from are found by content: the recording's IMU stamps (header
    or log) and GNSS positions must all be in the topic.  What the copy does not hold (GNSS
    from ``--gnss FILE.pos``, a ROS 1 encoded topic, the last, partial chunk of a cut-off file
    that navpp's reader still decodes) is encoded from the recording: a topic copied short on
    its own name, the rest on ``/imu/data``, ``/gnss/fix``, ``/gnss/vel`` and ``/wheel/odom``
    (``/navpp/input/...`` when the input has that name)."""
    from navpp.io.detect import gnss_velocity_topics, list_topics, read_topics
    from navpp.io.ros import FIX_TYPE, IMU_TYPE, ODOMETRY_TYPES, VELOCITY_TYPES

    if kind == "mcap":
        streams, skipped = _raw_mcap_streams([path])
    else:
        streams, skipped = _raw_ros2_streams(path)
    infos = [t for t in list_topics(kind, path) if any(s.topic == t.topic for s in streams)]
    exclude = _reference_topic(recording)
    imu_cands = [t.topic for t in infos if t.msgtype == IMU_TYPE]
    fix_cands = [t.topic for t in infos if t.msgtype == FIX_TYPE and t.topic != exclude]
    od = recording.odometry
    odom_cands = [t.topic for t in infos if od is not None and t.topic == od.source and t.msgtype in ODOMETRY_TYPES]
    vel_cands = [t.topic for t in infos if t.msgtype in VELOCITY_TYPES]
    decode = list(dict.fromkeys(imu_cands + fix_cands + odom_cands + vel_cands))
    contents = read_topics(kind, path, decode) if decode else None

    imu_topic = gnss_topic = odom_topic = vel_topic = None
    g = recording.gnss
    if contents is not None:
        want = roswrite.stamps_ns(recording, recording.imu.t)
        imu_topic = next((t for t in imu_cands if _contains_all(contents.imu[t].stamp_ns, want)
                          or _contains_all(contents.imu[t].log_ns, want)), None)
        gnss_topic = next((t for t in fix_cands if _contains_all(contents.fix[t].lat_deg, g.lat_deg)
                           and _contains_all(contents.fix[t].lon_deg, g.lon_deg)), None)
        if od is not None and odom_cands:
            msgs = contents.twist[odom_cands[0]]
            want = roswrite.stamps_ns(recording, od.t)
            if _contains_all(msgs.stamp_ns, want) or _contains_all(msgs.log_ns, want):
                odom_topic = odom_cands[0]
        twists = gnss_velocity_topics(contents, od.source if od is not None else None)
        if gnss_topic is not None and g.vel_enu is not None and len(twists) == 1:
            vel_topic = twists[0]
    # a cut-off file: the reader may have decoded messages a copy cannot take whole; encode those
    expected = {t.topic: t.count for t in infos}
    short = {t for t in (imu_topic, gnss_topic, vel_topic, odom_topic)
             if t is not None and sum(len(s) for s in streams if s.topic == t) != expected[t]}
    if gnss_topic in short and vel_topic is not None:
        short.add(vel_topic)
    streams = [s for s in streams if s.topic not in short]
    taken = {s.topic for s in streams}
    encoded: list[_Stream] = []
    if imu_topic is None or imu_topic in short:
        encoded.append(replace(_encoded_imu(recording), topic=imu_topic or _free_topic(EMBED_IMU_TOPIC, taken)))
    if gnss_topic is None or gnss_topic in short:
        fix, *vel = _encoded_gnss(recording, with_velocity=True)
        encoded.append(replace(fix, topic=gnss_topic or _free_topic(EMBED_GNSS_TOPIC, taken)))
        encoded += [replace(v, topic=_free_topic(EMBED_GNSS_VEL_TOPIC, taken) if vel_topic is None else vel_topic)
                    for v in vel]
    elif (vel_topic is None or vel_topic in short) and g.vel_enu is not None:
        encoded += [replace(v, topic=vel_topic or _free_topic(EMBED_GNSS_VEL_TOPIC, taken))
                    for v in _encoded_gnss(recording, with_velocity=True)[1:]]
    if od is not None and (odom_topic is None or odom_topic in short):
        encoded += [replace(o, topic=odom_topic or _free_topic(EMBED_ODOMETRY_TOPIC, taken))
                    for o in _encoded_odometry(recording)]
    copied_imu = None if imu_topic in short else imu_topic
    copied_gnss = None if gnss_topic in short else gnss_topic
    return _Embedded(streams + encoded, skipped, _header_frames(streams, copied_imu),
                     _header_frames(streams, copied_gnss))


def _raw_mcap_streams(paths: Sequence[Path]) -> tuple[list[_Stream], list[str]]:
    """Every channel of the MCAP files ``paths`` (read together, e.g. the storage files of a
    ROS 2 bag), its Message records copied as they are (:func:`_copy_topics`), except the topics
    named like navpp's output topics and channels that are neither CDR nor ROS 1 encoded: those
    are listed, one line per topic.  A ROS 1 encoded channel is converted to ROS 2 CDR
    (:func:`_ros1_channel_as_cdr`).  Channels of the same topic, schema and metadata are joined
    into one."""
    streams: list[_Stream] = []
    for p in paths:
        streams += _copy_topics(p, None)
    skipped: dict[str, str] = {}
    kept: list[_Stream] = []
    stores: list[Any] = []              # the ROS 1 and ROS 2 typestores, made for the first ROS 1 channel
    for s in streams:
        if _output_topic_collision(s.topic):
            skipped.setdefault(s.topic, f"{s.topic} ({s.schema_name}): a navpp output topic")
        elif s.message_encoding == "ros1":
            try:
                kept.append(_ros1_channel_as_cdr(s, stores))
            except Exception as exc:  # noqa: BLE001 -- any failure: the type cannot be converted
                skipped.setdefault(s.topic, f"{s.topic} ({s.schema_name}): cannot convert the ROS 1 type ({exc})")
        elif s.message_encoding != "cdr":
            skipped.setdefault(s.topic, f"{s.topic} ({s.schema_name}): {s.message_encoding or 'no'} encoding, not "
                                        "ROS 2 CDR (trajectory.mcap is a ros2-profile file)")
        else:
            kept.append(s)
    types: dict[str, set[str]] = {}
    for s in kept:
        types.setdefault(s.topic, set()).add(s.schema_name)
    for topic, names in types.items():
        if len(names) > 1:
            skipped[topic] = f"{topic} ({', '.join(sorted(names))}): more than one message type"
    return _joined([s for s in kept if s.topic not in skipped]), list(skipped.values())


def _ros1_channel_as_cdr(stream: _Stream, stores: list[Any]) -> _Stream:
    """A ROS 1 encoded MCAP channel as ROS 2 CDR, as a ROS 1 bag's topics are embedded
    (:func:`_ros1_input_streams`): each message deserialised with rosbags from the channel's own
    ``ros1msg`` schema and serialised as the ROS 2 Humble type of the same name (only
    ``header.seq`` does not carry over); log and publish times and sequence numbers kept, the
    ROS 1 channel metadata (md5sum, callerid, latching) not.
    ``stores``: [ROS 1, ROS 2] typestores, filled on first use and shared across channels."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from .ros import normalise_type

    if not stores:
        stores += [get_typestore(Stores.ROS1_NOETIC), get_typestore(Stores.ROS2_HUMBLE)]
    ts1, ts2 = stores
    if stream.schema_encoding != "ros1msg":
        raise ValueError(f"schema encoding {stream.schema_encoding!r}, not ros1msg")
    found = get_types_from_msg(stream.schema_data.decode(), stream.schema_name)
    msgtype = next(k for k in found if normalise_type(k) == normalise_type(stream.schema_name))
    ts1.register({k: v for k, v in found.items() if k not in ts1.fielddefs})
    ts2.register({k: v for k, v in found.items() if k not in ts2.fielddefs})
    assert isinstance(stream.payloads, _Raw)
    data = [bytes(ts2.serialize_cdr(ts1.deserialize_ros1(d, msgtype), msgtype)) for d in stream.payloads.data]
    schema = roswrite.MSGDEFS.get(msgtype) or ts2.generate_msgdef(msgtype, ros_version=2)[0]
    return replace(stream, schema_name=msgtype, schema_encoding="ros2msg", schema_data=schema.encode(),
                   message_encoding="cdr", payloads=_Raw(data), metadata={})


def _joined(streams: Sequence[_Stream]) -> list[_Stream]:
    """Streams of the same topic, schema, encoding and channel metadata as one (log-time order)."""
    groups: dict[tuple[Any, ...], list[_Stream]] = {}
    for s in streams:
        key = (s.topic, s.schema_name, s.schema_encoding, s.schema_data, s.message_encoding,
               tuple(sorted(s.metadata.items())))
        groups.setdefault(key, []).append(s)
    out = []
    for group in groups.values():
        if len(group) == 1:
            out.append(group[0])
            continue
        log = np.concatenate([s.log_ns for s in group])
        order = np.argsort(log, kind="stable")
        data = [d for s in group for d in s.payloads.block(0, len(s))]
        out.append(replace(group[0], log_ns=log[order],
                           publish_ns=np.concatenate([s.publish_ns for s in group])[order],
                           sequence=np.concatenate([s.sequence for s in group])[order],
                           payloads=_Raw([data[i] for i in order.tolist()])))
    return out


def _raw_ros2_streams(path: Path) -> tuple[list[_Stream], list[str]]:
    """Every topic of a ROS 2 bag directory as it was.  MCAP storage without per-message
    compression: the storage files' records copied (:func:`_raw_mcap_streams`: payloads, log
    and publish times, sequence, schemas, QoS metadata).  Otherwise (sqlite3, compressed files or messages) read with
    rosbags: the CDR payloads as stored (after the bag's own decompression), log time = publish
    time = the bag's receive time (all a sqlite3 bag keeps), the schema the bag's message
    definition (else ROS 2 Humble's), the offered QoS profiles as rosbag2 writes them.  Topics
    named like navpp's output topics, not CDR encoded, of several types, or without a definition
    are left out and listed."""
    from rosbags.rosbag2 import Reader

    from navpp.io.mcap import MCAP_MAGIC

    ts = _humble_typestore()
    streams: list[_Stream] = []
    skipped: list[str] = []
    with Reader(path) as reader:
        files = sorted(path.glob("*.mcap"))
        plain = (not reader.compression_mode and bool(files) and all(_starts_with(f, MCAP_MAGIC) for f in files)
                 and not any(f.is_file() and not f.name.endswith(".mcap") and f.name != "metadata.yaml"
                             for f in path.iterdir()))
        if plain:            # mcap storage, payloads not compressed one by one: copy the records
            return _raw_mcap_streams(files)
        topics: dict[str, list[Any]] = {}
        for conn in reader.connections:
            topics.setdefault(conn.topic, []).append(conn)
        for topic, conns in topics.items():
            msgtype = conns[0].msgtype
            encoding = getattr(conns[0].ext, "serialization_format", "cdr") or "cdr"
            schema = _ros2_schema(conns[0], ts)
            reason = ("a navpp output topic" if _output_topic_collision(topic)
                      else "more than one message type" if any(c.msgtype != msgtype for c in conns)
                      else f"{encoding} encoding, not ROS 2 CDR" if encoding != "cdr"
                      else "no message definition in the bag, and not a ROS 2 Humble type" if schema is None
                      else "")
            if reason:
                skipped.append(f"{topic} ({msgtype}): {reason}")
                continue
            assert schema is not None
            log, data = [], []
            for _, stamp, raw in reader.messages(connections=conns):
                log.append(int(stamp))
                data.append(bytes(raw))
            log_ns = np.asarray(log, dtype=np.int64)
            order = np.argsort(log_ns, kind="stable")
            qos = _qos_yaml(getattr(conns[0].ext, "offered_qos_profiles", None))
            streams.append(_Stream(topic, msgtype, schema[0], schema[1], "cdr", log_ns[order], log_ns[order],
                                   np.arange(log_ns.size, dtype=np.int64), _Raw([data[i] for i in order.tolist()]),
                                   {"offered_qos_profiles": qos} if qos else {}))
    return streams, skipped


def _starts_with(path: Path, magic: bytes) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(magic)) == magic
    except OSError:
        return False


def _ros2_schema(conn: Any, ts: Any) -> tuple[str, bytes] | None:
    """(schema encoding, schema data) of a rosbag2 connection: its stored definition (``.msg``
    or ``.idl``), else ROS 2 Humble's for a standard type, else None."""
    msgdef = getattr(conn, "msgdef", None)
    text = getattr(msgdef, "data", "") if msgdef is not None else ""
    if text:
        fmt = str(getattr(getattr(msgdef, "format", None), "name", "MSG"))
        return ("ros2idl" if fmt == "IDL" else "ros2msg"), text.encode()
    if conn.msgtype in roswrite.MSGDEFS:
        return "ros2msg", roswrite.MSGDEFS[conn.msgtype].encode()
    if conn.msgtype in ts.fielddefs:
        return "ros2msg", ts.generate_msgdef(conn.msgtype, ros_version=2)[0].encode()
    return None


def _qos_yaml(profiles: Any) -> str:
    """rosbags' offered QoS profiles as the YAML text rosbag2 keeps in a channel's
    ``offered_qos_profiles`` (rosbags' own dump); '' when there are none."""
    if not profiles:
        return ""
    if isinstance(profiles, str):
        return profiles
    from rosbags.rosbag2.metadata import dump_qos_v8

    return str(dump_qos_v8(list(profiles)))


def _ros1_input_streams(path: Path, recording: Recording) -> _Embedded:
    """Every topic of a ROS 1 bag (a ``.bag`` file, or every ``.bag`` in a directory) as it was:
    same topic names, message types and field values, each message converted to ROS 2 CDR
    (rosbags: ROS 1 deserialise, ROS 2 Humble serialise; the ROS 1 ``header.seq``, which ROS 2
    messages do not have, is the only field that does not carry over), log time = the bag's
    receive time, schemas the ROS 2 definitions.  A topic named like one of navpp's output
    topics (e.g. an input ``/tf``) is left out, and so is a type neither ROS 2
    Humble nor the bag's own definitions describe; both are listed in the file's metadata
    (``embedded_input_skipped``, :func:`write_trajectory_mcap`).  When the recording's GNSS is
    not one of the bag's NavSatFix topics (``--gnss FILE.pos``), it is encoded as for a CSV
    input on ``/gnss/fix``, or on ``/navpp/input/gnss/fix`` if the bag has that name."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from .ros import FIX_TYPE, IMU_TYPE, normalise_type

    ts2 = _humble_typestore()
    paths = sorted(path.glob("*.bag")) if path.is_dir() else [path]
    streams: list[_Stream] = []
    skipped: list[str] = []
    fix_found = False
    imu_topic = gnss_topic = None
    want_imu = roswrite.stamps_ns(recording, recording.imu.t)
    g = recording.gnss
    with AnyReader(paths, default_typestore=ts2) as reader:
        topics: dict[str, list[Any]] = {}
        for conn in reader.connections:
            topics.setdefault(conn.topic, []).append(conn)
        for topic, conns in topics.items():
            msgtype = conns[0].msgtype
            collides = _output_topic_collision(topic)
            if collides or any(c.msgtype != msgtype for c in conns):
                skipped.append(f"{topic} ({msgtype}): " + ("a navpp output topic" if collides
                                                          else "more than one message type"))
                continue
            if msgtype not in ts2.fielddefs:
                try:
                    if ts2 is _humble_typestore():          # the shared one stays standard
                        ts2 = get_typestore(Stores.ROS2_HUMBLE)
                    found = get_types_from_msg(conns[0].msgdef.data, msgtype)
                    ts2.register({k: v for k, v in found.items() if k not in ts2.fielddefs})
                except Exception as exc:  # noqa: BLE001 -- any failure: the type cannot be converted
                    skipped.append(f"{topic} ({msgtype}): cannot convert the type ({exc})")
                    continue
            role = normalise_type(msgtype)      # rosbags names ROS 1 types as ROS 2 ones
            log, data, lats, lons, stamps = [], [], [], [], []
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                log.append(int(stamp))
                data.append(bytes(ts2.serialize_cdr(msg, msgtype)))
                if role == FIX_TYPE:
                    lats.append(msg.latitude)
                    lons.append(msg.longitude)
                elif role == IMU_TYPE:
                    stamps.append(int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec))
            if role == FIX_TYPE and len(g) and _contains_all(np.array(lats), g.lat_deg) \
                    and _contains_all(np.array(lons), g.lon_deg):
                fix_found = True
                gnss_topic = gnss_topic or topic
            if role == IMU_TYPE and imu_topic is None and (
                    _contains_all(np.array(stamps, dtype=np.int64), want_imu)
                    or _contains_all(np.array(log, dtype=np.int64), want_imu)):
                imu_topic = topic
            schema = roswrite.MSGDEFS.get(msgtype) or ts2.generate_msgdef(msgtype, ros_version=2)[0]
            log_ns = np.asarray(log, dtype=np.int64)
            order = np.argsort(log_ns, kind="stable")
            streams.append(_Stream(topic, msgtype, "ros2msg", schema.encode(), "cdr", log_ns[order], log_ns[order],
                                   np.arange(log_ns.size, dtype=np.int64), _Raw([data[i] for i in order.tolist()])))
    if not fix_found:
        enc = _encoded_gnss(recording, with_velocity=True)
        taken = {s.topic for s in streams}
        if EMBED_GNSS_TOPIC in taken:
            enc = [replace(e, topic="/navpp/input" + e.topic) for e in enc]
        streams += enc
    return _Embedded(streams, skipped, _header_frames(streams, imu_topic), _header_frames(streams, gnss_topic))


@functools.cache
def _humble_typestore() -> Any:
    """rosbags' ROS 2 Humble typestore, built once (about half a second); never registered into."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


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


def _copy_topics(path: Path, topics: Sequence[str] | None) -> list[_Stream]:
    """The Message records of ``topics`` (None: every topic) in the data section (one stream per
    input channel), with
    their schemas and channels, read with ``mcap``'s streaming reader.  Reading stops at the data
    section's end or before a record the file does not hold whole (a cut-off recording)."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, DataEnd, Footer, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    wanted: set[int] = set()
    messages: dict[int, list[Message]] = {}
    with open(path, "rb") as f:
        records = StreamReader(f).records
        while True:
            try:
                record = next(records)
            except (StopIteration, EndOfFile, struct.error):    # the end, or a record cut short
                break
            if isinstance(record, Message):
                if record.channel_id in wanted:
                    messages[record.channel_id].append(record)
            elif isinstance(record, Schema):
                schemas.setdefault(record.id, record)
            elif isinstance(record, Channel):
                if record.id not in channels:
                    channels[record.id] = record
                    if topics is None or record.topic in topics:
                        wanted.add(record.id)
                        messages[record.id] = []
            elif isinstance(record, (DataEnd, Footer)):
                break
    streams = []
    for cid in sorted(wanted):
        ch = channels[cid]
        schema = schemas.get(ch.schema_id)
        if schema is None:
            raise ValueError(f"{path}: channel {cid} ({ch.topic}) has no schema")
        msgs = messages[cid]
        log = np.array([m.log_time for m in msgs], dtype=np.int64)
        order = np.argsort(log, kind="stable")
        msgs = [msgs[i] for i in order.tolist()]
        streams.append(_Stream(ch.topic, schema.name, schema.encoding, bytes(schema.data), ch.message_encoding,
                               log[order], np.array([m.publish_time for m in msgs], dtype=np.int64),
                               np.array([m.sequence for m in msgs], dtype=np.int64),
                               _Raw([bytes(m.data) for m in msgs]), dict(ch.metadata)))
    return streams


# --------------------------------------------------------------------------- the container


class _Timeline:
    """Every message of ``streams`` in log-time order (stable: stream order at equal times),
    cut into blocks of about ``block_size`` bytes of payload.

    Each stream's messages are sorted by log time, so every block holds a contiguous run of
    each stream's messages, packed in one call.
    """

    def __init__(self, streams: Sequence[_Stream], block_size: int) -> None:
        if not streams:
            raise ValueError("no message stream to write")
        self.streams = streams
        counts = [len(s) for s in streams]
        log = np.concatenate([s.log_ns for s in streams])
        order = np.argsort(log, kind="stable")
        self.log = log[order]
        self.stream = np.repeat(np.arange(len(streams), dtype=np.int64), counts)[order]
        self.index = np.concatenate([np.arange(c, dtype=np.int64) for c in counts])[order]
        self.publish = np.concatenate([s.publish_ns for s in streams])[order]
        self.sequence = np.concatenate([s.sequence for s in streams])[order]
        length = np.concatenate([s.payloads.lengths() for s in streams])[order]
        start = np.cumsum(length) - length
        cuts = np.flatnonzero(np.diff(start // max(int(block_size), 1))) + 1
        self.bounds = np.concatenate([[0], cuts, [self.log.size]]).astype(np.int64)

    def blocks(self) -> Iterator[tuple[int, int]]:
        for a, b in zip(self.bounds[:-1].tolist(), self.bounds[1:].tolist()):
            if b > a:
                yield a, b

    def payloads(self, a: int, b: int) -> list[bytes]:
        """The payloads of messages a..b-1 of the timeline, in its order."""
        which = self.stream[a:b]
        index = self.index[a:b]
        parts: list[bytes] = []
        for sid in np.unique(which).tolist():
            idx = index[which == sid]
            i0, i1 = int(idx[0]), int(idx[-1]) + 1
            if i1 - i0 != idx.size:
                raise AssertionError(f"{self.streams[sid].topic}: messages out of log-time order")
            parts += self.streams[sid].payloads.block(i0, i1)
        # parts holds the block's messages grouped by stream; rank[k] is message k's place there
        rank = np.empty(b - a, dtype=np.int64)
        rank[np.argsort(which, kind="stable")] = np.arange(b - a)
        return list(itemgetter(*rank.tolist())(parts)) if b - a > 1 else parts


def _compression_type(compression: str) -> Any:
    from mcap.writer import CompressionType

    if compression not in COMPRESSIONS:
        raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
    return {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]


def _write_container(f: IO[bytes], streams: Sequence[_Stream], metadata: dict[str, str], *,
                     chunk_size: int, compression: str) -> None:
    """Write an MCAP file (profile ``ros2``) holding ``streams`` (channel ``i + 1`` for stream
    ``i``) in log-time order, with ``mcap``'s Writer."""
    from mcap.writer import Writer

    from navpp.version import __version__

    timeline = _Timeline(streams, chunk_size)
    writer = Writer(f, chunk_size=max(int(chunk_size), 1), compression=_compression_type(compression))
    writer.start(profile="ros2", library=f"navpp {__version__}")
    schema_ids: dict[tuple[str, str, bytes], int] = {}
    for s in streams:
        key = (s.schema_name, s.schema_encoding, s.schema_data)
        if key not in schema_ids:
            schema_ids[key] = writer.register_schema(s.schema_name, s.schema_encoding, s.schema_data)
        writer.register_channel(s.topic, s.message_encoding, schema_ids[key], dict(s.metadata))
    writer.add_metadata("navpp", dict(metadata))
    add = writer.add_message
    for a, b in timeline.blocks():
        for channel, log, publish, sequence, data in zip(
                (timeline.stream[a:b] + 1).tolist(), timeline.log[a:b].tolist(), timeline.publish[a:b].tolist(),
                timeline.sequence[a:b].tolist(), timeline.payloads(a, b)):
            add(channel, log, data, publish, sequence)
    writer.finish()


# --------------------------------------------------------------------------- entry point


def _write(path: str | os.PathLike[str], streams: Sequence[_Stream], metadata: dict[str, str], *,
           chunk_size: int = CHUNK_SIZE, compression: str = "zstd") -> None:
    types: dict[str, str] = {}
    for s in streams:
        if types.setdefault(s.topic, s.schema_name) != s.schema_name:
            raise ValueError(f"topic {s.topic} would carry both {types[s.topic]} and {s.schema_name} "
                             "(an input topic named like one of navpp's output topics?)")
    _compression_type(compression)  # a bad name fails before the file is created
    atomic_write(path, lambda f: _write_container(f, streams, metadata, chunk_size=chunk_size,
                                                  compression=compression), mode="wb")


def write_trajectory_mcap(path: str | os.PathLike[str], *, solution: Solution, recording: Recording,
                          diagnostics: Any = None, biases: Any = None, embed_input: bool = False,
                          input_log: str | os.PathLike[str] | None = None, filter_name: str = "",
                          forward: Solution | None = None, chunk_size: int = CHUNK_SIZE,
                          compression: str = "zstd", imu_mounting_rpy_deg: Sequence[float] = (0.0, 0.0, 0.0),
                          gnss_lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0), rate_noise_std: float = 0.0
                          ) -> list[str]:
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
    embed_input : also write the input log, every topic as it was (module docstring: copied from
        an MCAP file or a ROS 2 bag, converted from ROS 1, encoded from ``recording`` for CSV).
    input_log : the input log's path (used with ``embed_input``).
    filter_name : recorded in the file's ``navpp`` metadata.
    forward : for a smoothed ``solution``, the forward filter's solution (same rows' time base):
        written to ``/navpp/forward/fix`` and ``/navpp/forward/odometry``; the metadata's
        ``solution`` says ``smoothed`` (else ``forward``).
    chunk_size : target uncompressed size of a chunk, bytes.
    compression : chunk compression, one of :data:`COMPRESSIONS`.
    imu_mounting_rpy_deg : (3,) deg, the IMU's mounting (sensor -> base_link, roll pitch yaw
        about x y z, as ``[imu] mounting_rpy_deg``): the ``base_link -> imu_link`` rotation of
        ``/tf_static``.
    gnss_lever_arm_m : (3,) m, the antenna in base_link FLU (``[gnss] lever_arm_m``): the
        ``base_link -> gnss`` translation of ``/tf_static``.
    rate_noise_std : rad/s, the gyro's white noise per sample (``[imu]`` ARW x sqrt(IMU rate)),
        added to the angular-velocity variance of ``/navpp/odometry``.

    Returns
    -------
    list of str : the input topics ``embed_input`` left out, one ``"TOPIC (TYPE): reason"`` each
        (also the file's ``embedded_input_skipped`` metadata); empty without ``embed_input``.

    Raises
    ------
    ValueError
        An empty solution, a solution on another time base, stamps outside the ROS time range,
        an input topic named like one of navpp's output topics but of another type, or an
        unknown ``compression``.
    navpp.errors.InputError
        ``input_log`` cannot be read.
    """
    from ..ins.attitude import rpy_deg_to_dcm

    static = (rpy_deg_to_dcm(np.asarray(imu_mounting_rpy_deg, dtype=float).reshape(3)),
              np.asarray(gnss_lever_arm_m, dtype=float).reshape(3))
    embedded = _input_streams(recording, input_log) if embed_input else _Embedded([])
    linked = [f for f in (*embedded.imu_frames, *embedded.gnss_frames)
              if f not in (MAP_FRAME, ODOM_FRAME, BODY_FRAME, IMU_FRAME, GNSS_FRAME)]
    streams, anchor = _solution_streams(solution, recording, diagnostics, biases, forward, static=static,
                                        rate_noise_std=rate_noise_std,
                                        input_frames=(embedded.imu_frames, embedded.gnss_frames))
    streams = embedded.streams + streams
    skipped = embedded.skipped
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
        "tf_tree": "map -> odom (static identity) -> base_link (/tf); base_link -> imu_link, base_link -> gnss "
                   + "".join(f", base_link -> {f}" for f in dict.fromkeys(linked)) + " (/tf_static)",
        "not_estimated_variance": repr(NOT_ESTIMATED_VARIANCE),
    }
    if skipped:
        metadata["embedded_input_skipped"] = "; ".join(skipped)
    _write(path, streams, metadata, chunk_size=chunk_size, compression=compression)
    return skipped
