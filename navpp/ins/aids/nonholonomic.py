"""Non-holonomic constraint: a wheeled vehicle on the road neither slides sideways nor leaves
the ground, so the velocity of its constraint point (e.g. the rear axle's centre) has no
lateral or vertical component in the vehicle frame.

Vehicle frame v (FLU) = ``C_vb`` times the IMU body frame (``[vehicle] mounting_rpy_deg``:
the vehicle's roll/pitch/yaw relative to the body).  The constraint point sits at ``l`` (body
FLU, m) and moves with ``v_b = C^T v + w x l`` in the body frame, ``w = w_m - b_g``.
``z = [0, 0]``, ``h(x) = S C_vb (C^T v + w x l)`` with ``S`` the lateral and vertical rows;
with ``C_true = exp([phi x]) C``, ``C_true^T v = C^T v + C^T [v x] phi``:
``H = S C_vb [C^T [v x], C^T, 0, [l x], 0]``.  ``p = [C_vb (9, row-major), w_m (3), l (3)]``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from navpp.kernel import njit

from ..attitude import quat_to_dcm, skew
from ..state import ATT, BG, N_ERR, NOMINAL_BG, NOMINAL_Q, NOMINAL_VEL, VEL
from .base import Aid, points_kernel

P_C_VB = slice(0, 9)      #: ``p``: C_vb, body -> vehicle, row-major
P_GYRO = slice(9, 12)     #: ``p``: gyro output at the epoch, body FLU, rad/s
P_POINT = slice(12, 15)   #: ``p``: the constraint point, body FLU, m
LATERAL_VERTICAL = slice(1, 3)    #: rows of the vehicle frame (FLU) the constraint holds to zero


@njit(cache=True)
def vehicle_velocity(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Velocity of the point ``p[P_POINT]`` in the vehicle frame, ``C_vb (C^T v + w x l)`` (3,) m/s
    (the odometer, :mod:`navpp.ins.aids.odometer`, reads its forward row)."""
    cvb = np.ascontiguousarray(p[P_C_VB]).reshape(3, 3)
    vb = quat_to_dcm(x[NOMINAL_Q]).T @ x[NOMINAL_VEL] + np.cross(p[P_GYRO] - x[NOMINAL_BG], p[P_POINT])
    v: np.ndarray = cvb @ vb
    return v


@njit(cache=True)
def vehicle_velocity_jacobian(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``d(vehicle_velocity)/d(dx)`` (3, 15): ``C_vb [C^T [v x], C^T, 0, [l x], 0]``."""
    cvb = np.ascontiguousarray(p[P_C_VB]).reshape(3, 3)
    Ct = np.ascontiguousarray(quat_to_dcm(x[NOMINAL_Q]).T)
    H = np.zeros((3, N_ERR))
    H[:, ATT] = Ct @ skew(x[NOMINAL_VEL])
    H[:, VEL] = Ct
    H[:, BG] = skew(p[P_POINT])
    J: np.ndarray = cvb @ H
    return J


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    z: np.ndarray = vehicle_velocity(x, p)[LATERAL_VERTICAL].copy()
    return z


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    Hz: np.ndarray = vehicle_velocity_jacobian(x, p)[LATERAL_VERTICAL].copy()
    return Hz


_points = points_kernel(_h)


class NonHolonomic(Aid):
    """NHC at ``t``; build with :meth:`at`."""

    kind: ClassVar[str] = "nhc"
    axes: ClassVar[tuple[str, ...]] = ("lateral", "vertical")
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, std_mps: tuple[float, float], c_vb: np.ndarray, gyro: np.ndarray,
           point_b: np.ndarray) -> NonHolonomic:
        """``std_mps`` (lateral, vertical) 1-sigma m/s; ``c_vb`` (3, 3) body -> vehicle;
        ``gyro`` (3,) rad/s at ``t``; ``point_b`` (3,) m, the constraint point in the body frame."""
        p = np.concatenate([np.asarray(c_vb, dtype=float).ravel(), np.asarray(gyro, dtype=float),
                            np.asarray(point_b, dtype=float)])
        return cls(t, np.zeros(2), np.diag(np.square(np.asarray(std_mps, dtype=float))), p)
