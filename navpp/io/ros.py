"""The contract between navpp's ROS-log readers (MCAP, ROS 1 bag, ROS 2 bag) and the rest.

A reader decodes the topics it was asked for into per-topic numpy arrays (no per-message
Python objects on the hot path) and returns a :class:`LogContents`; :mod:`navpp.io.assemble`
picks the topic roles and turns them into a validated :class:`navpp.recording.Recording`.

Message types are named in ROS 1 form (``sensor_msgs/Imu``) whatever the encoding
(``sensor_msgs/msg/Imu`` in ROS 2 is normalised by :func:`normalise_type`).
Times are integer nanoseconds: ``stamp_ns`` from the message header, ``log_ns`` the log
(record / receive) time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

IMU_TYPE = "sensor_msgs/Imu"
FIX_TYPE = "sensor_msgs/NavSatFix"
TWIST_COV_TYPE = "geometry_msgs/TwistWithCovarianceStamped"
TWIST_TYPE = "geometry_msgs/TwistStamped"
ODOM_TYPE = "nav_msgs/Odometry"
#: A pose in a local frame: read only as a reference (:mod:`navpp.io.refposes`), not in SUPPORTED_TYPES.
POSE_TYPE = "geometry_msgs/PoseStamped"
SUPPORTED_TYPES = (IMU_TYPE, FIX_TYPE, TWIST_COV_TYPE, TWIST_TYPE, ODOM_TYPE)
#: Types that can carry GNSS velocity (ENU) or, in a vehicle frame, wheel odometry.
VELOCITY_TYPES = (TWIST_COV_TYPE, TWIST_TYPE)
#: Types that can carry wheel odometry (forward speed and yaw rate in the vehicle frame).
ODOMETRY_TYPES = (ODOM_TYPE, TWIST_COV_TYPE, TWIST_TYPE)


def normalise_type(name: str) -> str:
    """``sensor_msgs/msg/Imu`` -> ``sensor_msgs/Imu``; ROS 1 names unchanged."""
    parts = name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return f"{parts[0]}/{parts[2]}"
    return name


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log: name, message type (normalised), message count, time span (log
    time, ns; None when unknown) and the encoding (``cdr`` / ``ros1``)."""

    topic: str
    msgtype: str
    count: int
    first_ns: int | None = None
    last_ns: int | None = None
    encoding: str = ""


@dataclass(frozen=True)
class ImuMessages:
    """``sensor_msgs/Imu`` of one topic, in message order.

    stamp_ns, log_ns : (N,) int64.  gyro : (N, 3) rad/s, accel : (N, 3) m/s^2, in the
    message's frame.  gyro_cov0, accel_cov0 : (N,) float, element 0 of the covariance arrays
    (-1 means 'not provided').  Orientation is not decoded.
    """

    topic: str
    stamp_ns: np.ndarray
    log_ns: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    gyro_cov0: np.ndarray | None = None
    accel_cov0: np.ndarray | None = None
    frame_id: str = ""


@dataclass(frozen=True)
class FixMessages:
    """``sensor_msgs/NavSatFix`` of one topic, in message order.

    status : (N,) int8 (-1 no fix, 0 fix, 1 SBAS, 2 GBAS); lat_deg, lon_deg, alt : (N,)
    degrees / degrees / m (WGS-84 ellipsoid); cov : (N, 9) m^2, ENU row-major;
    cov_type : (N,) uint8 (0 unknown, 1 approximated, 2 diagonal known, 3 known).
    """

    topic: str
    stamp_ns: np.ndarray
    log_ns: np.ndarray
    status: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt: np.ndarray
    cov: np.ndarray
    cov_type: np.ndarray
    frame_id: str = ""


@dataclass(frozen=True)
class TwistMessages:
    """``TwistWithCovarianceStamped`` / ``TwistStamped`` / ``nav_msgs/Odometry`` (its twist part).

    vel : (N, 3) m/s, the linear part: ENU for a GNSS velocity topic, the vehicle frame
    (``child_frame_id`` of an Odometry, ``frame_id`` of a Twist) for wheel odometry.
    cov_diag : (N, 3) m^2/s^2, covariance elements 0, 7, 14 (None for ``TwistStamped``).
    angular : (N, 3) rad/s, the angular part (same frame), None when not decoded.
    var_yaw_rate : (N,) rad^2/s^2, covariance element 35 (None without a covariance).
    frame_id, child_frame_id : of the first message (child: Odometry only).
    """

    topic: str
    stamp_ns: np.ndarray
    log_ns: np.ndarray
    vel: np.ndarray
    cov_diag: np.ndarray | None = None
    frame_id: str = ""
    angular: np.ndarray | None = None
    var_yaw_rate: np.ndarray | None = None
    child_frame_id: str = ""


@dataclass(frozen=True)
class LogContents:
    """What a reader found: every topic (for ``inspect`` and role detection) and the decoded
    messages of the topics it was asked to decode."""

    source: str
    topics: tuple[TopicInfo, ...]
    imu: dict[str, ImuMessages] = field(default_factory=dict)
    fix: dict[str, FixMessages] = field(default_factory=dict)
    twist: dict[str, TwistMessages] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
