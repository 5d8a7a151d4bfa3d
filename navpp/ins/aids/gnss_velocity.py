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

from navpp.kernel import njit

from ..attitude import quat_to_dcm, skew
from ..state import ATT, BG, DX_VEL, N_ERR, NOMINAL_BG, NOMINAL_Q, NOMINAL_VEL
from .base import Aid, points_kernel

P_GYRO = slice(0, 3)      #: ``p``: gyro output at the epoch, body FLU, rad/s
P_LEVER = slice(3, 6)     #: ``p``: antenna lever arm, body FLU, m


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    w = p[P_GYRO] - x[NOMINAL_BG]
    v_antenna: np.ndarray = x[NOMINAL_VEL] + quat_to_dcm(x[NOMINAL_Q]) @ np.cross(w, p[P_LEVER])
    return v_antenna


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    C = quat_to_dcm(x[NOMINAL_Q])
    w = p[P_GYRO] - x[NOMINAL_BG]
    H = np.zeros((3, N_ERR))
    H[:, ATT] = -skew(C @ np.cross(w, p[P_LEVER]))
    H[0, DX_VEL] = H[1, DX_VEL + 1] = H[2, DX_VEL + 2] = 1.0
    H[:, BG] = C @ skew(p[P_LEVER])
    return H


_points = points_kernel(_h)


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
