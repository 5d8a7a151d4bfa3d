"""Write a :class:`~navpp.recording.Recording` as ROS logs: ROS 2 MCAP, ROS 1 bag, ROS 2 bag.

These are navpp's own writers of *input* logs: they build ``sample_data/`` and the test
files of the ROS readers, so a log written here and read back must give the same arrays
(stamps to the nanosecond, values bit for bit).

What is written
---------------
- ``sensor_msgs/Imu`` on ``imu_topic``: ``angular_velocity`` = ``rec.imu.gyro`` (rad/s),
  ``linear_acceleration`` = ``rec.imu.accel`` (m/s^2), body FLU, frame ``frame_id_imu``.
  Orientation is not provided: identity quaternion with ``orientation_covariance[0] = -1``.
  ``angular_velocity_covariance`` / ``linear_acceleration_covariance`` are all zero
  ("unknown") unless ``gyro_var`` / ``accel_var`` (per-sample variance, rad^2/s^2 and
  m^2/s^4) are given, which fill their diagonals.
- ``sensor_msgs/NavSatFix`` on ``gnss_topic``: latitude/longitude (deg), altitude (m,
  ellipsoidal), status 0 (STATUS_FIX), service 1 (GPS); ``position_covariance`` diagonal
  = ``rec.gnss.std_enu**2`` (ENU, m^2) with covariance type 2 (DIAGONAL_KNOWN), or zeros
  with type 0 (UNKNOWN) when the recording has no std.
- ``geometry_msgs/TwistWithCovarianceStamped`` on ``gnss_vel_topic`` when the recording has
  GNSS velocity: ``twist.twist.linear`` = ``vel_enu`` (m/s); covariance diagonal elements
  0, 7, 14 = ``std_vel_enu**2`` (others 0).
- ``sensor_msgs/NavSatFix`` on ``reference_topic`` (when given and the recording has a
  reference): the reference position, covariance type 0, frame ``"reference"``.
- ``nav_msgs/Odometry`` on ``odometry_topic`` when the recording has odometry (wheel
  odometry as a Husky / Jackal controller publishes it): frame ``odom``, child frame
  ``frame_id_odometry`` (``base_link``); ``twist.twist.linear.x`` = ``rec.odometry.speed``
  (m/s), ``twist.twist.angular.z`` = ``yaw_rate`` (rad/s, 0 when absent), twist covariance
  elements 0 and 35 = ``std_speed**2`` / ``std_yaw_rate**2`` when given (else 0: unknown); the
  pose is left at zero (identity orientation).

The same bulk serialisation packs navpp's *output* messages for ``trajectory.mcap``
(:mod:`navpp.io.mcap_out`): ``nav_msgs/Odometry``, ``tf2_msgs/TFMessage``,
``geometry_msgs/Vector3Stamped`` and navpp's ``navpp_msgs/FilterDiagnostics``.  The ``pack_*``
functions return the messages as one packed numpy array (row ``i`` is message ``i``'s payload);
the ``encode_*`` functions return the same payloads as a list of ``bytes``.

Time: header stamps are the absolute stamps ``t0_ns + round(t * 1e9)`` (integer ns, see
:func:`stamps_ns`); the log (receive) time of each message is its stamp plus
``log_offset_ns``.  Messages of all topics are written in log-time order.

Payloads are serialised in bulk: one numpy structured array per message type whose dtype is
the message's exact CDR / ROS 1 byte layout (:class:`_Layout`, see :func:`pack_imu`), so no
Python object is built per message; the bytes equal what ``rosbags``' ``serialize_cdr`` /
``serialize_ros1`` and ``mcap_ros2``'s encoder produce (tested).  The containers are the
libraries': ``mcap``'s :class:`mcap.writer.Writer` for MCAP, ``rosbags``' ``rosbag1.Writer`` and
``rosbag2.Writer`` for bags.

Every writer is atomic: files are written to a temporary name in the target directory and
renamed when complete; a ROS 2 bag directory is built inside a temporary directory and
renamed into place.  An existing target is replaced.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from navpp.io.writers import atomic_write
from navpp.recording import Recording

__all__ = [
    "FILTER_DIAGNOSTICS_MSGDEF",
    "FILTER_DIAGNOSTICS_TYPE",
    "IMU_MSGDEF",
    "MSGDEFS",
    "NAVSATFIX_MSGDEF",
    "ODOMETRY_MSGDEF",
    "TF_MESSAGE_MSGDEF",
    "TWIST_STAMPED_MSGDEF",
    "TWIST_WITH_COVARIANCE_STAMPED_MSGDEF",
    "VECTOR3_STAMPED_MSGDEF",
    "encode_imu",
    "encode_navsatfix",
    "encode_twist",
    "encode_twist_with_covariance",
    "pack_filter_diagnostics",
    "pack_imu",
    "pack_navsatfix",
    "pack_odometry",
    "pack_tf_message",
    "pack_twist_with_covariance",
    "pack_vector3_stamped",
    "payload_bytes",
    "stamps_ns",
    "write_mcap_ros2",
    "write_ros1_bag",
    "write_ros2_bag",
]

# --------------------------------------------------------------------------- ROS 2 message definitions

_SEP = "=" * 80 + "\n"

_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_TIME = "int32 sec\nuint32 nanosec\n"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_NAVSATSTATUS = (
    "int8 STATUS_NO_FIX = -1\nint8 STATUS_FIX = 0\nint8 STATUS_SBAS_FIX = 1\nint8 STATUS_GBAS_FIX = 2\n"
    "uint16 SERVICE_GPS = 1\nuint16 SERVICE_GLONASS = 2\nuint16 SERVICE_COMPASS = 4\n"
    "uint16 SERVICE_GALILEO = 8\n"
    "int8 status\nuint16 service\n"
)
_TWIST = "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"
_TWIST_WITH_COVARIANCE = "geometry_msgs/Twist twist\nfloat64[36] covariance\n"


def _concatenated(main: str, deps: Sequence[tuple[str, str]]) -> str:
    """rosbag2's ``ros2msg`` schema text: the main definition, then each dependency."""
    return main + "".join(f"{_SEP}MSG: {name}\n{text}" for name, text in deps)


#: ``sensor_msgs/msg/Imu`` (ROS 2 Humble definition, comments removed), as an MCAP ``ros2msg`` schema.
IMU_MSGDEF = _concatenated(
    "std_msgs/Header header\n"
    "geometry_msgs/Quaternion orientation\n"
    "float64[9] orientation_covariance\n"
    "geometry_msgs/Vector3 angular_velocity\n"
    "float64[9] angular_velocity_covariance\n"
    "geometry_msgs/Vector3 linear_acceleration\n"
    "float64[9] linear_acceleration_covariance\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
     ("geometry_msgs/Quaternion", _QUATERNION), ("geometry_msgs/Vector3", _VECTOR3)],
)

#: ``sensor_msgs/msg/NavSatFix`` (ROS 2 Humble definition, comments removed).
NAVSATFIX_MSGDEF = _concatenated(
    "uint8 COVARIANCE_TYPE_UNKNOWN = 0\n"
    "uint8 COVARIANCE_TYPE_APPROXIMATED = 1\n"
    "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2\n"
    "uint8 COVARIANCE_TYPE_KNOWN = 3\n"
    "std_msgs/Header header\n"
    "sensor_msgs/NavSatStatus status\n"
    "float64 latitude\n"
    "float64 longitude\n"
    "float64 altitude\n"
    "float64[9] position_covariance\n"
    "uint8 position_covariance_type\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
     ("sensor_msgs/NavSatStatus", _NAVSATSTATUS)],
)

#: ``geometry_msgs/msg/TwistWithCovarianceStamped`` (ROS 2 Humble definition).
TWIST_WITH_COVARIANCE_STAMPED_MSGDEF = _concatenated(
    "std_msgs/Header header\ngeometry_msgs/TwistWithCovariance twist\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
     ("geometry_msgs/TwistWithCovariance", _TWIST_WITH_COVARIANCE), ("geometry_msgs/Twist", _TWIST),
     ("geometry_msgs/Vector3", _VECTOR3)],
)

#: ``geometry_msgs/msg/TwistStamped`` (ROS 2 Humble definition).
TWIST_STAMPED_MSGDEF = _concatenated(
    "std_msgs/Header header\ngeometry_msgs/Twist twist\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
     ("geometry_msgs/Twist", _TWIST), ("geometry_msgs/Vector3", _VECTOR3)],
)

_POINT = "float64 x\nfloat64 y\nfloat64 z\n"
_POSE = "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"
_POSE_WITH_COVARIANCE = "geometry_msgs/Pose pose\nfloat64[36] covariance\n"
_TRANSFORM = "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
_TRANSFORM_STAMPED = "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"

#: ``nav_msgs/msg/Odometry`` (ROS 2 Humble definition, comments removed).
ODOMETRY_MSGDEF = _concatenated(
    "std_msgs/Header header\n"
    "string child_frame_id\n"
    "geometry_msgs/PoseWithCovariance pose\n"
    "geometry_msgs/TwistWithCovariance twist\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
     ("geometry_msgs/PoseWithCovariance", _POSE_WITH_COVARIANCE), ("geometry_msgs/Pose", _POSE),
     ("geometry_msgs/Point", _POINT), ("geometry_msgs/Quaternion", _QUATERNION),
     ("geometry_msgs/TwistWithCovariance", _TWIST_WITH_COVARIANCE), ("geometry_msgs/Twist", _TWIST),
     ("geometry_msgs/Vector3", _VECTOR3)],
)

#: ``tf2_msgs/msg/TFMessage`` (ROS 2 Humble definition).
TF_MESSAGE_MSGDEF = _concatenated(
    "geometry_msgs/TransformStamped[] transforms\n",
    [("geometry_msgs/TransformStamped", _TRANSFORM_STAMPED), ("std_msgs/Header", _HEADER),
     ("builtin_interfaces/Time", _TIME), ("geometry_msgs/Transform", _TRANSFORM),
     ("geometry_msgs/Vector3", _VECTOR3), ("geometry_msgs/Quaternion", _QUATERNION)],
)

#: ``geometry_msgs/msg/Vector3Stamped`` (ROS 2 Humble definition).
VECTOR3_STAMPED_MSGDEF = _concatenated(
    "std_msgs/Header header\ngeometry_msgs/Vector3 vector\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME), ("geometry_msgs/Vector3", _VECTOR3)],
)

#: Name of navpp's own per-GNSS-epoch filter diagnostics message (:data:`FILTER_DIAGNOSTICS_MSGDEF`).
FILTER_DIAGNOSTICS_TYPE = "navpp_msgs/msg/FilterDiagnostics"

#: ``navpp_msgs/msg/FilterDiagnostics``: what the filter saw and decided at one GNSS epoch.  Plain
#: fields and arrays of primitives, so plotting tools address every number by a path
#: (``nis``, ``innovation_enu[0]``, ``values[3]``).
FILTER_DIAGNOSTICS_MSGDEF = _concatenated(
    "# navpp: the filter's view of one GNSS position fix.\n"
    "std_msgs/Header header  # stamp: the GNSS epoch\n"
    "float64[3] innovation_enu  # m, measured minus predicted antenna position, east/north/up\n"
    "float64 nis  # normalised innovation squared (chi-square with 3 dof when consistent)\n"
    "bool accepted  # passed the innovation gate and was applied\n"
    "bool forced  # applied after a run of rejections although outside the gate\n"
    "float64[3] r_std_enu  # m, 1-sigma of the measurement noise the filter used, east/north/up\n"
    "string[] names  # the filter's adaptive quantities (the same list in every message of a file)\n"
    "float64[] values  # their values after this epoch, in the order of names\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME)],
)

_IMU = "sensor_msgs/msg/Imu"
_FIX = "sensor_msgs/msg/NavSatFix"
_TWIST_COV = "geometry_msgs/msg/TwistWithCovarianceStamped"
_TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
_ODOMETRY = "nav_msgs/msg/Odometry"

#: ROS 2 message type -> its ``ros2msg`` schema text (every type navpp writes).
MSGDEFS = {
    _IMU: IMU_MSGDEF,
    _FIX: NAVSATFIX_MSGDEF,
    _TWIST_COV: TWIST_WITH_COVARIANCE_STAMPED_MSGDEF,
    _TWIST_STAMPED: TWIST_STAMPED_MSGDEF,
    "nav_msgs/msg/Odometry": ODOMETRY_MSGDEF,
    "tf2_msgs/msg/TFMessage": TF_MESSAGE_MSGDEF,
    "geometry_msgs/msg/Vector3Stamped": VECTOR3_STAMPED_MSGDEF,
    FILTER_DIAGNOSTICS_TYPE: FILTER_DIAGNOSTICS_MSGDEF,
}

_ENCODINGS = ("cdr", "ros1")

# --------------------------------------------------------------------------- bulk serialisation


class _Layout:
    """Byte layout of one fixed-size message: field offsets under CDR or ROS 1 rules.

    CDR (little endian, ``CDR_LE`` encapsulation): every primitive is aligned to its own
    size (at most 8) relative to the end of the 4-byte encapsulation header; strings are a
    uint32 length counting the terminating NUL, then the bytes and the NUL.  ROS 1: packed,
    no alignment; strings are a uint32 length (no NUL) then the bytes.
    """

    def __init__(self, encoding: str) -> None:
        if encoding not in _ENCODINGS:
            raise ValueError(f"encoding must be one of {_ENCODINGS}, got {encoding!r}")
        self.cdr = encoding == "cdr"
        self.names: list[str] = []
        self.formats: list[Any] = []
        self.offsets: list[int] = []
        self.pos = 0
        if self.cdr:
            self.field("encapsulation", "u1", 4)

    def field(self, name: str, dtype: str, count: int | None = None) -> None:
        """A field of one ``dtype`` value, or with ``count`` an array of ``count`` values (even of one)."""
        dt = np.dtype(dtype).newbyteorder("<")
        if self.cdr and name != "encapsulation":
            align = 1 if dt.kind == "S" else min(dt.itemsize, 8)
            rel = self.pos - 4
            self.pos = 4 + -(-rel // align) * align
        self.names.append(name)
        self.formats.append(dt if count is None else (dt, (count,)))
        self.offsets.append(self.pos)
        self.pos += dt.itemsize * (1 if count is None else count)

    def string(self, name: str, text: str) -> bytes:
        raw = text.encode("utf-8")
        stored = raw + b"\0" if self.cdr else raw
        self.field(f"{name}_len", "u4")
        if stored:
            self.field(name, f"S{len(stored)}")
        return stored

    def header(self, frame_id: str) -> bytes:
        if not self.cdr:
            self.field("seq", "u4")
            self.field("sec", "u4")
            self.field("nanosec", "u4")
        else:
            self.field("sec", "i4")
            self.field("nanosec", "u4")
        return self.string("frame_id", frame_id)

    def array(self, n: int) -> np.ndarray:
        dtype = np.dtype({"names": self.names, "formats": self.formats, "offsets": self.offsets,
                          "itemsize": self.pos})
        arr = np.zeros(n, dtype=dtype)
        if self.cdr:
            arr["encapsulation"] = (0, 1, 0, 0)
        return arr


def _fill_header(arr: np.ndarray, layout: _Layout, stamps: np.ndarray, frame: bytes) -> None:
    sec, nsec = np.divmod(stamps, 1_000_000_000)
    limit = 2**31 if layout.cdr else 2**32
    if stamps.size and (sec.min() < 0 or sec.max() >= limit):
        raise ValueError(f"stamps outside the range of a ROS time ({sec.min()} .. {sec.max()} s)")
    arr["sec"] = sec
    arr["nanosec"] = nsec
    if not layout.cdr:
        arr["seq"] = np.arange(stamps.size, dtype=np.uint32)
    arr["frame_id_len"] = len(frame)
    if frame:
        arr["frame_id"] = frame


def _payloads(arr: np.ndarray) -> list[bytes]:
    size = arr.dtype.itemsize
    buf = arr.tobytes()
    return [buf[i:i + size] for i in range(0, len(buf), size)]


def _stamps_array(stamps: np.ndarray) -> np.ndarray:
    s = np.asarray(stamps)
    if s.ndim != 1 or not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"stamps must be a 1-D integer array of ns, got {s.dtype} {s.shape}")
    return s.astype(np.int64, copy=False)


def _vectors(name: str, a: np.ndarray, n: int, width: int = 3) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n, width):
        raise ValueError(f"{name} has shape {a.shape}, expected ({n}, {width})")
    return a


def encode_imu(stamps: np.ndarray, gyro: np.ndarray, accel: np.ndarray, *, encoding: str,
               frame_id: str = "imu_link", gyro_var: float | None = None,
               accel_var: float | None = None) -> list[bytes]:
    """Serialise ``sensor_msgs/Imu`` messages in bulk: :func:`pack_imu` as N ``bytes``."""
    return _payloads(pack_imu(stamps, gyro, accel, encoding=encoding, frame_id=frame_id, gyro_var=gyro_var,
                              accel_var=accel_var))


def pack_imu(stamps: np.ndarray, gyro: np.ndarray, accel: np.ndarray, *, encoding: str,
             frame_id: str = "imu_link", gyro_var: float | None = None,
             accel_var: float | None = None) -> np.ndarray:
    """Serialise ``sensor_msgs/Imu`` messages in bulk, as a packed array.

    Parameters
    ----------
    stamps : (N,) int, header stamps in ns.
    gyro, accel : (N, 3) float, rad/s and m/s^2.
    encoding : ``"cdr"`` (ROS 2) or ``"ros1"``.
    frame_id : header frame.
    gyro_var, accel_var : per-sample variance for the covariance diagonals; None -> all zero.

    Returns
    -------
    (N,) structured array whose row ``i`` (``arr[i].tobytes()``) is message ``i``'s payload
    (see :func:`payload_bytes`).  Orientation: identity, ``orientation_covariance[0] = -1``.
    """
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("orientation", "f8", 4)
    lay.field("orientation_covariance", "f8", 9)
    lay.field("angular_velocity", "f8", 3)
    lay.field("angular_velocity_covariance", "f8", 9)
    lay.field("linear_acceleration", "f8", 3)
    lay.field("linear_acceleration_covariance", "f8", 9)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["orientation"] = (0.0, 0.0, 0.0, 1.0)
    arr["orientation_covariance"][:, 0] = -1.0
    arr["angular_velocity"] = _vectors("gyro", gyro, n)
    arr["linear_acceleration"] = _vectors("accel", accel, n)
    if gyro_var is not None:
        arr["angular_velocity_covariance"][:, [0, 4, 8]] = gyro_var
    if accel_var is not None:
        arr["linear_acceleration_covariance"][:, [0, 4, 8]] = accel_var
    return arr


def encode_navsatfix(stamps: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray, *,
                     encoding: str, frame_id: str = "gnss", cov_diag: np.ndarray | None = None,
                     status: int | np.ndarray = 0, service: int = 1) -> list[bytes]:
    """Serialise ``sensor_msgs/NavSatFix`` messages in bulk: :func:`pack_navsatfix` as N ``bytes``."""
    return _payloads(pack_navsatfix(stamps, lat_deg, lon_deg, alt, encoding=encoding, frame_id=frame_id,
                                    cov_diag=cov_diag, status=status, service=service))


def pack_navsatfix(stamps: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray, *,
                   encoding: str, frame_id: str = "gnss", cov_diag: np.ndarray | None = None,
                   status: int | np.ndarray = 0, service: int = 1) -> np.ndarray:
    """Serialise ``sensor_msgs/NavSatFix`` messages in bulk, as a packed array (one row per
    message, see :func:`pack_imu`).

    Parameters
    ----------
    stamps : (N,) int, header stamps in ns.
    lat_deg, lon_deg, alt : (N,) float, degrees / degrees / m (ellipsoidal).
    encoding : ``"cdr"`` or ``"ros1"``.
    cov_diag : (N, 3) float m^2 (ENU variances) -> covariance type 2 (DIAGONAL_KNOWN);
        None -> zero covariance with type 0 (UNKNOWN).
    status : NavSatStatus.status, scalar or (N,) int (0 = fix, -1 = no fix).
    service : NavSatStatus.service (1 = GPS).
    """
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("status", "i1")
    lay.field("service", "u2")
    lay.field("latitude", "f8")
    lay.field("longitude", "f8")
    lay.field("altitude", "f8")
    lay.field("position_covariance", "f8", 9)
    lay.field("position_covariance_type", "u1")
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["status"] = status
    arr["service"] = service
    for name, values in (("latitude", lat_deg), ("longitude", lon_deg), ("altitude", alt)):
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (n,):
            raise ValueError(f"{name} has shape {v.shape}, expected ({n},)")
        arr[name] = v
    if cov_diag is not None:
        arr["position_covariance"][:, [0, 4, 8]] = _vectors("cov_diag", cov_diag, n)
        arr["position_covariance_type"] = 2
    return arr


def encode_twist_with_covariance(stamps: np.ndarray, vel: np.ndarray, *, encoding: str,
                                 frame_id: str = "gnss",
                                 cov_diag: np.ndarray | None = None) -> list[bytes]:
    """Serialise ``geometry_msgs/TwistWithCovarianceStamped`` in bulk: :func:`pack_twist_with_covariance`
    as N ``bytes``."""
    return _payloads(pack_twist_with_covariance(stamps, vel, encoding=encoding, frame_id=frame_id,
                                                cov_diag=cov_diag))


def pack_twist_with_covariance(stamps: np.ndarray, vel: np.ndarray, *, encoding: str,
                               frame_id: str = "gnss", cov_diag: np.ndarray | None = None) -> np.ndarray:
    """Serialise ``geometry_msgs/TwistWithCovarianceStamped`` in bulk, as a packed array.

    vel : (N, 3) m/s into ``twist.twist.linear``; angular zero.  cov_diag : (N, 3) m^2/s^2
    into covariance elements 0, 7, 14 (None -> all zero).
    """
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("linear", "f8", 3)
    lay.field("angular", "f8", 3)
    lay.field("covariance", "f8", 36)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["linear"] = _vectors("vel", vel, n)
    if cov_diag is not None:
        arr["covariance"][:, [0, 7, 14]] = _vectors("cov_diag", cov_diag, n)
    return arr


def encode_twist(stamps: np.ndarray, vel: np.ndarray, *, encoding: str, frame_id: str = "gnss") -> list[bytes]:
    """Serialise ``geometry_msgs/TwistStamped`` in bulk (vel (N, 3) m/s as ``twist.linear``)."""
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("linear", "f8", 3)
    lay.field("angular", "f8", 3)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["linear"] = _vectors("vel", vel, n)
    return _payloads(arr)


def payload_bytes(arr: np.ndarray) -> list[bytes]:
    """The payloads of a packed array (from a ``pack_*`` function) as N ``bytes``."""
    return _payloads(arr)


def _diagonal(name: str, values: np.ndarray, n: int, width: int) -> np.ndarray:
    """(n, width) float64 from (width,) or (n, width) values (broadcast)."""
    v = np.asarray(values, dtype=np.float64)
    if v.shape not in ((width,), (n, width)):
        raise ValueError(f"{name} has shape {v.shape}, expected ({width},) or ({n}, {width})")
    return np.broadcast_to(v, (n, width))


def pack_odometry(stamps: np.ndarray, position: np.ndarray, orientation_xyzw: np.ndarray,
                  linear: np.ndarray, angular: np.ndarray, *, encoding: str, frame_id: str = "map",
                  child_frame_id: str = "base_link", pose_var: np.ndarray | None = None,
                  twist_var: np.ndarray | None = None) -> np.ndarray:
    """Serialise ``nav_msgs/Odometry`` messages in bulk, as a packed array (see :func:`pack_imu`).

    Parameters
    ----------
    stamps : (N,) int, header stamps in ns.
    position : (N, 3) float, m, ``pose.pose.position`` in ``frame_id``.
    orientation_xyzw : (N, 4) float, ``pose.pose.orientation`` (x, y, z, w): the rotation taking
        ``child_frame_id`` vectors into ``frame_id``.
    linear, angular : (N, 3) float, m/s and rad/s, ``twist.twist`` (in ``child_frame_id``, as
        the message defines it).
    encoding : ``"cdr"`` or ``"ros1"``.
    pose_var, twist_var : (6,) or (N, 6) float, the diagonals of ``pose.covariance`` and
        ``twist.covariance`` (x, y, z, rotation about x, y, z); off-diagonal elements are 0.
        None: all zero.
    """
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    child = lay.string("child_frame_id", child_frame_id)
    lay.field("position", "f8", 3)
    lay.field("orientation", "f8", 4)
    lay.field("pose_covariance", "f8", 36)
    lay.field("linear", "f8", 3)
    lay.field("angular", "f8", 3)
    lay.field("twist_covariance", "f8", 36)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["child_frame_id_len"] = len(child)
    if child:
        arr["child_frame_id"] = child
    arr["position"] = _vectors("position", position, n)
    arr["orientation"] = _vectors("orientation_xyzw", orientation_xyzw, n, 4)
    arr["linear"] = _vectors("linear", linear, n)
    arr["angular"] = _vectors("angular", angular, n)
    diag = [0, 7, 14, 21, 28, 35]
    if pose_var is not None:
        arr["pose_covariance"][:, diag] = _diagonal("pose_var", pose_var, n, 6)
    if twist_var is not None:
        arr["twist_covariance"][:, diag] = _diagonal("twist_var", twist_var, n, 6)
    return arr


def pack_tf_message(stamps: np.ndarray, translation: np.ndarray, rotation_xyzw: np.ndarray, *,
                    encoding: str, frame_id: str = "map", child_frame_id: str = "base_link") -> np.ndarray:
    """Serialise ``tf2_msgs/TFMessage`` messages of one transform each, in bulk, as a packed array.

    Transform ``i``: ``frame_id`` -> ``child_frame_id`` at ``stamps[i]`` with ``translation``
    (N, 3) m (the child's origin in ``frame_id``) and ``rotation_xyzw`` (N, 4) (the rotation
    taking ``child_frame_id`` vectors into ``frame_id``).
    """
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    lay.field("transforms_len", "u4")
    frame = lay.header(frame_id)
    child = lay.string("child_frame_id", child_frame_id)
    lay.field("translation", "f8", 3)
    lay.field("rotation", "f8", 4)
    arr = lay.array(n)
    arr["transforms_len"] = 1
    _fill_header(arr, lay, s, frame)
    arr["child_frame_id_len"] = len(child)
    if child:
        arr["child_frame_id"] = child
    arr["translation"] = _vectors("translation", translation, n)
    arr["rotation"] = _vectors("rotation_xyzw", rotation_xyzw, n, 4)
    return arr


def pack_vector3_stamped(stamps: np.ndarray, vector: np.ndarray, *, encoding: str,
                         frame_id: str = "base_link") -> np.ndarray:
    """Serialise ``geometry_msgs/Vector3Stamped`` messages (vector (N, 3)) in bulk, as a packed array."""
    s = _stamps_array(stamps)
    n = s.size
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("vector", "f8", 3)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["vector"] = _vectors("vector", vector, n)
    return arr


def pack_filter_diagnostics(stamps: np.ndarray, innovation_enu: np.ndarray, nis: np.ndarray,
                            accepted: np.ndarray, forced: np.ndarray, r_std_enu: np.ndarray,
                            names: Sequence[str], values: np.ndarray, *, encoding: str,
                            frame_id: str = "map") -> np.ndarray:
    """Serialise ``navpp_msgs/FilterDiagnostics`` (:data:`FILTER_DIAGNOSTICS_MSGDEF`) in bulk.

    Parameters
    ----------
    stamps : (N,) int, header stamps in ns.
    innovation_enu, r_std_enu : (N, 3) float, m.
    nis : (N,) float.
    accepted, forced : (N,) bool.
    names : K names, the same in every message.
    values : (N, K) float.
    encoding : ``"cdr"`` or ``"ros1"``.

    Returns
    -------
    A packed array (see :func:`pack_imu`): with the names fixed, every message has the same size.
    """
    s = _stamps_array(stamps)
    n = s.size
    k = len(names)
    lay = _Layout(encoding)
    frame = lay.header(frame_id)
    lay.field("innovation_enu", "f8", 3)
    lay.field("nis", "f8")
    lay.field("accepted", "u1")
    lay.field("forced", "u1")
    lay.field("r_std_enu", "f8", 3)
    lay.field("names_len", "u4")
    stored = [lay.string(f"name_{i}", str(name)) for i, name in enumerate(names)]
    lay.field("values_len", "u4")
    if k:
        lay.field("values", "f8", k)
    arr = lay.array(n)
    _fill_header(arr, lay, s, frame)
    arr["innovation_enu"] = _vectors("innovation_enu", innovation_enu, n)
    arr["r_std_enu"] = _vectors("r_std_enu", r_std_enu, n)
    for name, v, dtype in (("nis", nis, np.float64), ("accepted", accepted, bool), ("forced", forced, bool)):
        a = np.asarray(v, dtype=dtype)
        if a.shape != (n,):
            raise ValueError(f"{name} has shape {a.shape}, expected ({n},)")
        arr[name] = a
    arr["names_len"] = k
    for i, raw in enumerate(stored):
        arr[f"name_{i}_len"] = len(raw)
        if raw:
            arr[f"name_{i}"] = raw
    arr["values_len"] = k
    if k:
        arr["values"] = _vectors("values", values, n, k)
    return arr


# --------------------------------------------------------------------------- recording -> message streams


def stamps_ns(rec: Recording, t: np.ndarray) -> np.ndarray:
    """Absolute integer-ns stamps of relative times ``t`` (s): ``t0_ns + round(t * 1e9)``."""
    return rec.t0_ns + np.rint(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)


@dataclass(frozen=True)
class _Stream:
    topic: str
    msgtype: str  # ROS 2 name, e.g. sensor_msgs/msg/Imu
    log_ns: np.ndarray
    payloads: list[bytes]


@dataclass(frozen=True)
class _Topics:
    imu_topic: str
    gnss_topic: str
    gnss_vel_topic: str | None
    reference_topic: str | None
    frame_id_imu: str
    frame_id_gnss: str
    gyro_var: float | None
    accel_var: float | None
    time_range: tuple[float, float] | None
    log_offset_ns: int
    odometry_topic: str | None = None
    frame_id_odometry: str = "base_link"


def _odometry_payloads(rec: Recording, k: np.ndarray, st: np.ndarray, encoding: str, child: str) -> list[bytes]:
    """``rec.odometry`` rows ``k`` (stamps ``st`` ns) as ``nav_msgs/Odometry`` payloads."""
    od = rec.odometry
    assert od is not None
    n = st.size
    linear = np.zeros((n, 3))
    linear[:, 0] = od.speed[k]
    angular = np.zeros((n, 3))
    if od.yaw_rate is not None:
        angular[:, 2] = od.yaw_rate[k]
    var = np.zeros((n, 6))
    if od.std_speed is not None:
        var[:, 0] = np.square(od.std_speed[k])
    if od.std_yaw_rate is not None:
        var[:, 5] = np.square(od.std_yaw_rate[k])
    quat = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), (n, 4))
    return payload_bytes(pack_odometry(st, np.zeros((n, 3)), quat, linear, angular, encoding=encoding,
                                       frame_id="odom", child_frame_id=child, twist_var=var))


def _streams(rec: Recording, encoding: str, opts: _Topics) -> list[_Stream]:
    """The recording's messages per topic, serialised, restricted to ``time_range``."""

    def keep(t: np.ndarray) -> np.ndarray:
        if opts.time_range is None:
            return np.ones(t.shape[0], dtype=bool)
        lo, hi = opts.time_range
        return (t >= lo) & (t < hi)

    out: list[_Stream] = []
    imu = rec.imu
    k = keep(imu.t)
    st = stamps_ns(rec, imu.t[k])
    out.append(_Stream(opts.imu_topic, _IMU, st + opts.log_offset_ns,
                       encode_imu(st, imu.gyro[k], imu.accel[k], encoding=encoding, frame_id=opts.frame_id_imu,
                                  gyro_var=opts.gyro_var, accel_var=opts.accel_var)))
    g = rec.gnss
    k = keep(g.t)
    st = stamps_ns(rec, g.t[k])
    cov = None if g.std_enu is None else np.square(g.std_enu[k])
    out.append(_Stream(opts.gnss_topic, _FIX, st + opts.log_offset_ns,
                       encode_navsatfix(st, g.lat_deg[k], g.lon_deg[k], g.alt[k], encoding=encoding,
                                        frame_id=opts.frame_id_gnss, cov_diag=cov)))
    if opts.gnss_vel_topic and g.vel_enu is not None:
        vcov = None if g.std_vel_enu is None else np.square(g.std_vel_enu[k])
        out.append(_Stream(opts.gnss_vel_topic, _TWIST_COV, st + opts.log_offset_ns,
                           encode_twist_with_covariance(st, g.vel_enu[k], encoding=encoding,
                                                        frame_id=opts.frame_id_gnss, cov_diag=vcov)))
    ref = rec.reference
    if opts.reference_topic and ref is not None:
        k = keep(ref.t)
        st = stamps_ns(rec, ref.t[k])
        out.append(_Stream(opts.reference_topic, _FIX, st + opts.log_offset_ns,
                           encode_navsatfix(st, ref.lat_deg[k], ref.lon_deg[k], ref.alt[k], encoding=encoding,
                                            frame_id="reference")))
    if opts.odometry_topic and rec.odometry is not None:
        k = keep(rec.odometry.t)
        st = stamps_ns(rec, rec.odometry.t[k])
        out.append(_Stream(opts.odometry_topic, _ODOMETRY, st + opts.log_offset_ns,
                           _odometry_payloads(rec, k, st, encoding, opts.frame_id_odometry)))
    topics = [s.topic for s in out]
    if len(set(topics)) != len(topics):
        raise ValueError(f"topic names must differ, got {topics}")
    return out


def _time_order(streams: Sequence[_Stream]) -> tuple[np.ndarray, np.ndarray]:
    """(stream index, message index) of every message, sorted by log time (stable)."""
    log = np.concatenate([s.log_ns for s in streams])
    which = np.concatenate([np.full(s.log_ns.size, i, dtype=np.int64) for i, s in enumerate(streams)])
    index = np.concatenate([np.arange(s.log_ns.size, dtype=np.int64) for s in streams])
    order = np.argsort(log, kind="stable")
    return which[order], index[order]


def _options(imu_topic: str, gnss_topic: str, gnss_vel_topic: str | None, reference_topic: str | None,
             frame_id_imu: str, frame_id_gnss: str, gyro_var: float | None, accel_var: float | None,
             time_range: tuple[float, float] | None, log_offset_ns: int, odometry_topic: str | None = None,
             frame_id_odometry: str = "base_link") -> _Topics:
    return _Topics(imu_topic, gnss_topic, gnss_vel_topic, reference_topic, frame_id_imu, frame_id_gnss,
                   gyro_var, accel_var, time_range, int(log_offset_ns), odometry_topic, frame_id_odometry)


# --------------------------------------------------------------------------- writers

_MCAP_COMPRESSION = ("zstd", "lz4", "none")


def write_mcap_ros2(rec: Recording, path: str | os.PathLike[str], *, imu_topic: str = "/imu/data",
                    gnss_topic: str = "/gnss/fix", gnss_vel_topic: str | None = "/gnss/vel",
                    reference_topic: str | None = None, frame_id_imu: str = "imu_link",
                    frame_id_gnss: str = "gnss", gyro_var: float | None = None,
                    accel_var: float | None = None, compression: str = "zstd",
                    chunk_size: int = 1 << 20, time_range: tuple[float, float] | None = None,
                    log_offset_ns: int = 0, odometry_topic: str | None = "/wheel/odom",
                    frame_id_odometry: str = "base_link") -> None:
    """Write ``rec`` as a ROS 2 MCAP file (CDR messages, ``ros2msg`` schemas, ``ros2`` profile).

    The file is what ``mcap_ros2.writer.Writer`` makes (same profile, schema encoding and
    channel encoding; ``mcap_ros2`` reads it back, tested), written through the
    ``mcap.writer.Writer`` underneath it with the bulk-serialised payloads, since
    ``mcap_ros2``'s ``write_message`` encodes one Python message object at a time.

    Parameters
    ----------
    rec : the recording.
    path : output ``.mcap`` file (replaced atomically).
    imu_topic, gnss_topic : topics of the IMU and GNSS messages.
    gnss_vel_topic : topic of the GNSS velocity (written only when ``rec.gnss.vel_enu``
        exists); None to leave it out.
    reference_topic : topic for the reference as NavSatFix (e.g. ``"/reference/fix"``);
        None (default) leaves the reference out.
    frame_id_imu, frame_id_gnss : header frame ids.
    gyro_var, accel_var : IMU covariance diagonals (see module docstring).
    compression : chunk compression, ``"zstd"``, ``"lz4"`` or ``"none"``.
    chunk_size : target uncompressed chunk size in bytes; 0 writes an unchunked file.
    time_range : ``(start_s, stop_s)`` relative to ``rec.t0_ns``: only messages with
        ``start_s <= t < stop_s`` (for split or partial logs).
    log_offset_ns : log time minus header stamp, ns (0: log time = stamp).
    odometry_topic : topic of the wheel odometry (``nav_msgs/Odometry``, written only when
        ``rec.odometry`` exists); None to leave it out.
    frame_id_odometry : its ``child_frame_id`` (the vehicle frame).
    """
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    if compression not in _MCAP_COMPRESSION:
        raise ValueError(f"compression must be one of {_MCAP_COMPRESSION}, got {compression!r}")
    opts = _options(imu_topic, gnss_topic, gnss_vel_topic, reference_topic, frame_id_imu, frame_id_gnss,
                    gyro_var, accel_var, time_range, log_offset_ns, odometry_topic, frame_id_odometry)
    streams = _streams(rec, "cdr", opts)
    which, index = _time_order(streams)
    ctype = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]

    def write(f: IO[bytes]) -> None:
        w = McapWriter(f, chunk_size=max(int(chunk_size), 1), compression=ctype,
                       use_chunking=chunk_size > 0)
        w.start(profile="ros2", library="navpp")
        schema_ids: dict[str, int] = {}
        channels = []
        for s in streams:
            if s.msgtype not in schema_ids:
                schema_ids[s.msgtype] = w.register_schema(s.msgtype, "ros2msg", MSGDEFS[s.msgtype].encode())
            channels.append(w.register_channel(s.topic, "cdr", schema_ids[s.msgtype]))
        logs = [s.log_ns.tolist() for s in streams]
        add = w.add_message
        for i, j in zip(which.tolist(), index.tolist()):
            t = logs[i][j]
            add(channel_id=channels[i], log_time=t, data=streams[i].payloads[j], publish_time=t, sequence=j)
        w.finish()

    atomic_write(path, write, mode="wb")


_ROS1_COMPRESSION = ("none", "bz2", "lz4")


def _write_into_temp(target: Path, build: Callable[[Path], None]) -> None:
    """Run ``build(tmp_target)`` in a temporary directory beside ``target``, then move the
    result (file or directory) onto ``target`` atomically (a directory target is replaced:
    the old one is moved aside first and removed after)."""
    parent = target.parent if str(target.parent) else Path(".")
    tmpdir = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.", suffix=".tmp"))
    try:
        built = tmpdir / target.name
        build(built)
        if built.is_dir() and target.is_dir():
            old = tmpdir / (target.name + ".old")
            os.replace(target, old)
            os.replace(built, target)
        else:
            os.replace(built, target)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def write_ros1_bag(rec: Recording, path: str | os.PathLike[str], *, imu_topic: str = "/imu/data",
                   gnss_topic: str = "/gnss/fix", gnss_vel_topic: str | None = "/gnss/vel",
                   reference_topic: str | None = None, frame_id_imu: str = "imu_link",
                   frame_id_gnss: str = "gnss", gyro_var: float | None = None,
                   accel_var: float | None = None, compression: str = "none",
                   chunk_size: int = 1 << 20, time_range: tuple[float, float] | None = None,
                   log_offset_ns: int = 0, odometry_topic: str | None = "/wheel/odom",
                   frame_id_odometry: str = "base_link") -> None:
    """Write ``rec`` as a ROS 1 bag (format 2.0) with ``rosbags.rosbag1.Writer``.

    Message definitions and md5sums come from rosbags' ROS 1 Noetic typestore and are stored
    in the bag.  ``compression``: ``"none"``, ``"bz2"`` or ``"lz4"`` (per chunk);
    ``chunk_size``: uncompressed bytes per chunk.  Other parameters as in
    :func:`write_mcap_ros2`.
    """
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    if compression not in _ROS1_COMPRESSION:
        raise ValueError(f"compression must be one of {_ROS1_COMPRESSION}, got {compression!r}")
    opts = _options(imu_topic, gnss_topic, gnss_vel_topic, reference_topic, frame_id_imu, frame_id_gnss,
                    gyro_var, accel_var, time_range, log_offset_ns, odometry_topic, frame_id_odometry)
    streams = _streams(rec, "ros1", opts)
    which, index = _time_order(streams)
    typestore = get_typestore(Stores.ROS1_NOETIC)

    def build(tmp: Path) -> None:
        writer = Writer(tmp)
        if compression != "none":
            writer.set_compression(Writer.CompressionFormat[compression.upper()])
        writer.chunk_threshold = int(chunk_size)
        with writer:
            conns = [writer.add_connection(s.topic, s.msgtype, typestore=typestore, callerid="/navpp")
                     for s in streams]
            _write_all(writer.write, conns, streams, which, index)

    _write_into_temp(Path(path), build)


def _write_all(write: Callable[[Any, int, bytes], None], conns: Sequence[Any], streams: Sequence[_Stream],
               which: np.ndarray, index: np.ndarray) -> None:
    logs = [s.log_ns.tolist() for s in streams]
    for i, j in zip(which.tolist(), index.tolist()):
        write(conns[i], logs[i][j], streams[i].payloads[j])


_ROS2_STORAGE = ("sqlite3", "mcap")
_ROS2_COMPRESSION = ("none", "file", "message", "storage")


def write_ros2_bag(rec: Recording, dirpath: str | os.PathLike[str], *, storage: str = "sqlite3",
                   imu_topic: str = "/imu/data", gnss_topic: str = "/gnss/fix",
                   gnss_vel_topic: str | None = "/gnss/vel", reference_topic: str | None = None,
                   frame_id_imu: str = "imu_link", frame_id_gnss: str = "gnss",
                   gyro_var: float | None = None, accel_var: float | None = None,
                   compression: str = "none", time_range: tuple[float, float] | None = None,
                   log_offset_ns: int = 0, odometry_topic: str | None = "/wheel/odom",
                   frame_id_odometry: str = "base_link") -> None:
    """Write ``rec`` as a ROS 2 bag directory (rosbag2 format version 9) with ``rosbags.rosbag2.Writer``.

    ``storage``: ``"sqlite3"`` (``<name>.db3``) or ``"mcap"`` (``<name>.mcap``).  Message
    definitions (ROS 2 Humble typestore) and type hashes are stored in the bag.
    ``compression`` (zstd): ``"none"``, ``"file"`` (whole storage file), ``"message"`` (each
    payload) or ``"storage"`` (MCAP chunks; mcap storage only).  The directory is built under
    a temporary name and renamed into place; an existing ``dirpath`` is replaced.  Other
    parameters as in :func:`write_mcap_ros2`.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    if storage not in _ROS2_STORAGE:
        raise ValueError(f"storage must be one of {_ROS2_STORAGE}, got {storage!r}")
    if compression not in _ROS2_COMPRESSION:
        raise ValueError(f"compression must be one of {_ROS2_COMPRESSION}, got {compression!r}")
    if compression == "storage" and storage != "mcap":
        raise ValueError("compression 'storage' needs storage='mcap'")
    opts = _options(imu_topic, gnss_topic, gnss_vel_topic, reference_topic, frame_id_imu, frame_id_gnss,
                    gyro_var, accel_var, time_range, log_offset_ns, odometry_topic, frame_id_odometry)
    streams = _streams(rec, "cdr", opts)
    which, index = _time_order(streams)
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP

    def build(tmp: Path) -> None:
        writer = Writer(tmp, version=Writer.VERSION_LATEST, storage_plugin=plugin)
        if compression != "none":
            writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
        with writer:
            conns = [writer.add_connection(s.topic, s.msgtype, typestore=typestore) for s in streams]
            _write_all(writer.write, conns, streams, which, index)

    _write_into_temp(Path(dirpath), build)
