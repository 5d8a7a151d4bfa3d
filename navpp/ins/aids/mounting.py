"""The vehicle frame's pitch and yaw relative to the IMU body frame, from a solution.

A car moves along its own x axis, so in the IMU body frame its velocity points along the
vehicle's x axis: ``v_b = C_nb^T v_n = s R e_x = s [cos p cos y, cos p sin y, -sin p]`` for the
vehicle frame rotated by ``R = Rz(y) Ry(p)`` from the body.  Over the samples where the vehicle
moves fast and straight (speed above ``min_speed``, heading and pitch turning slower than
``max_rate``), ``y = atan2(v_by, v_bx)`` and ``p = atan2(-v_bz, hypot(v_bx, v_by))``; navpp takes
their medians (a robust estimate: turns, slips and the odd bad epoch do not pull it).  The roll
of the vehicle frame is not observable this way and is left at zero (a roll misalignment moves
no velocity out of the lateral-vertical plane).

The engine runs this on a first forward pass without the non-holonomic constraint when
``[vehicle] mounting_rpy_deg = "auto"`` (:func:`estimate_mounting`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..attitude import rph_deg_to_dcm


@dataclass(frozen=True)
class MountingEstimate:
    """pitch_deg, yaw_deg : the vehicle frame relative to the body (deg, rpy convention of
    ``[vehicle] mounting_rpy_deg``); spread_deg : (pitch, yaw) median absolute deviation of the
    per-sample values (deg); seconds : time of motion used (s)."""

    pitch_deg: float
    yaw_deg: float
    spread_deg: tuple[float, float]
    seconds: float


def estimate_mounting(t: np.ndarray, vel_enu: np.ndarray, rph_deg: np.ndarray, *, min_speed: float = 5.0,
                      max_rate_dps: float = 2.0) -> MountingEstimate | None:
    """Estimate the mounting from a solution (``t`` (N,) s; ``vel_enu`` (N, 3) m/s; ``rph_deg``
    (N, 3) navigation convention); None with less than 10 s of usable motion."""
    t = np.asarray(t, dtype=float)
    vel = np.asarray(vel_enu, dtype=float)
    rph = np.asarray(rph_deg, dtype=float)
    if t.size < 3:
        return None
    dt = np.gradient(t)
    heading_rate = np.abs(np.gradient(np.unwrap(np.radians(rph[:, 2])), t))
    pitch_rate = np.abs(np.gradient(np.radians(rph[:, 1]), t))
    speed = np.linalg.norm(vel[:, :2], axis=1)
    use = ((speed > min_speed) & (heading_rate < math.radians(max_rate_dps))
           & (pitch_rate < math.radians(max_rate_dps)) & np.all(np.isfinite(vel), axis=1))
    seconds = float(dt[use].sum())
    if seconds < 10.0:
        return None
    vb = np.einsum("nji,nj->ni", rph_deg_to_dcm(rph[use]), vel[use])
    yaw = np.degrees(np.arctan2(vb[:, 1], vb[:, 0]))
    pitch = np.degrees(np.arctan2(-vb[:, 2], np.hypot(vb[:, 0], vb[:, 1])))
    my, mp = float(np.median(yaw)), float(np.median(pitch))
    spread = (float(np.median(np.abs(pitch - mp))), float(np.median(np.abs(yaw - my))))
    return MountingEstimate(mp, my, spread, seconds)
