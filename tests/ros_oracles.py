"""Oracles shared by the ROS decoding tests: what navpp's arrays must hold, computed from the
libraries' own decoded message objects (an independent implementation)."""

from __future__ import annotations

import numpy as np

from navpp.io.ros import FIX_TYPE, IMU_TYPE, ODOM_TYPE, TWIST_COV_TYPE


def ros2_name(msgtype: str) -> str:
    pkg, name = msgtype.split("/")
    return f"{pkg}/msg/{name}"


def expected_from_objects(msgtype: str, msgs: list) -> dict[str, np.ndarray]:
    """The arrays navpp should produce, from library-decoded objects (genpy or ROS 2 style)."""

    def stamp(m) -> int:
        s = m.header.stamp
        if hasattr(s, "nanosec"):
            return int(s.sec) * 1_000_000_000 + int(s.nanosec)
        return int(s.secs) * 1_000_000_000 + int(s.nsecs)

    def xyz(v) -> list[float]:
        return [v.x, v.y, v.z]

    out: dict[str, np.ndarray] = {"stamp_ns": np.array([stamp(m) for m in msgs], dtype=np.int64)}
    if msgtype == IMU_TYPE:
        out["gyro"] = np.array([xyz(m.angular_velocity) for m in msgs]).reshape(-1, 3)
        out["accel"] = np.array([xyz(m.linear_acceleration) for m in msgs]).reshape(-1, 3)
        out["gyro_cov0"] = np.array([m.angular_velocity_covariance[0] for m in msgs])
        out["accel_cov0"] = np.array([m.linear_acceleration_covariance[0] for m in msgs])
    elif msgtype == FIX_TYPE:
        out["status"] = np.array([m.status.status for m in msgs], dtype=np.int8)
        out["lat_deg"] = np.array([m.latitude for m in msgs])
        out["lon_deg"] = np.array([m.longitude for m in msgs])
        out["alt"] = np.array([m.altitude for m in msgs])
        out["cov"] = np.array([list(m.position_covariance) for m in msgs]).reshape(-1, 9)
        out["cov_type"] = np.array([m.position_covariance_type for m in msgs], dtype=np.uint8)
    elif msgtype in (TWIST_COV_TYPE, ODOM_TYPE):
        out["vel"] = np.array([xyz(m.twist.twist.linear) for m in msgs]).reshape(-1, 3)
        out["angular"] = np.array([xyz(m.twist.twist.angular) for m in msgs]).reshape(-1, 3)
        out["cov_diag"] = np.array([[m.twist.covariance[k] for k in (0, 7, 14)]
                                    for m in msgs]).reshape(-1, 3)
        out["var_yaw_rate"] = np.array([m.twist.covariance[35] for m in msgs])
    else:
        out["vel"] = np.array([xyz(m.twist.linear) for m in msgs]).reshape(-1, 3)
        out["angular"] = np.array([xyz(m.twist.angular) for m in msgs]).reshape(-1, 3)
    return out


def fill_genpy(target, values: dict) -> None:
    """Set a genpy (ROS 1) message object's fields from a nested dict (stamp as sec/nanosec)."""
    for key, value in values.items():
        if key == "stamp":
            target.stamp.secs, target.stamp.nsecs = value["sec"], value["nanosec"]
        elif isinstance(value, dict):
            fill_genpy(getattr(target, key), value)
        else:
            setattr(target, key, value)
