"""GNSS velocity: the antenna's ENU velocity.

The antenna at lever arm ``l`` (body FLU, m) moves with ``v + C (w x l)``, ``w = w_m - b_g``
the body rate (gyro output ``w_m`` at the epoch, rad/s, minus the nominal gyro bias; the
Earth-rate part of the lever-arm term, below 1e-4 m/s for metre lever arms, is left out).
``h(x) = v + C (w x l)``; with ``C_true = exp([phi x]) C``:
``H = [-[(C (w x l)) x], I, 0, C [l x], 0]`` (a larger gyro bias means a smaller rate:
``d(w x l) = -(db_g x l) = [l x] db_g``).  ``p = [w_m (3), l (3)]``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..model import plus
from .base import Aid, skew


@njit(cache=True)
def _h(x, p):
    w = p[0:3] - x[10:13]
    return x[4:7] + quat_to_dcm(x[0:4]) @ np.cross(w, p[3:6])


@njit(cache=True)
def _H(x, p):
    C = quat_to_dcm(x[0:4])
    w = p[0:3] - x[10:13]
    H = np.zeros((3, 15))
    H[:, 0:3] = -skew(C @ np.cross(w, p[3:6]))
    H[0, 3] = H[1, 4] = H[2, 5] = 1.0
    H[:, 9:12] = C @ skew(p[3:6])
    return H


@njit(cache=True)
def _points(x, dX, p):
    """``h(x ⊞ dX_i) - h(x)``, (m, k)."""
    z0 = _h(x, p)
    Z = np.empty((dX.shape[0], z0.shape[0]))
    for i in range(dX.shape[0]):
        Z[i] = _h(plus(x, dX[i]), p) - z0
    return Z


class GnssVelocity(Aid):
    """GNSS velocity fix at ``t``; build with :meth:`at`."""

    kind: ClassVar[str] = "gnss_velocity"
    axes: ClassVar[tuple[str, ...]] = ("ve", "vn", "vu")
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, vel_enu: np.ndarray, var_enu: np.ndarray, gyro: np.ndarray,
           lever_arm_b: np.ndarray) -> GnssVelocity:
        """``vel_enu`` (3,) m/s, ``var_enu`` (3,) m^2/s^2, ``gyro`` (3,) rad/s at ``t``,
        ``lever_arm_b`` (3,) m."""
        p = np.concatenate([np.asarray(gyro, dtype=float), np.asarray(lever_arm_b, dtype=float)])
        return cls(t, np.asarray(vel_enu, dtype=float), np.diag(np.asarray(var_enu, dtype=float)), p)
