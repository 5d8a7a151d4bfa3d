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
from numba import njit

from ..attitude import quat_to_dcm
from ..model import plus
from .base import Aid, skew


@njit(cache=True)
def _h(x, p):
    cvb = p[0:9].reshape(3, 3)
    vb = quat_to_dcm(x[0:4]).T @ x[4:7] + np.cross(p[9:12] - x[10:13], p[12:15])
    return (cvb @ vb)[1:3].copy()


@njit(cache=True)
def _H(x, p):
    cvb = np.ascontiguousarray(p[0:9]).reshape(3, 3)
    Ct = np.ascontiguousarray(quat_to_dcm(x[0:4]).T)
    H = np.zeros((3, 15))
    H[:, 0:3] = Ct @ skew(x[4:7])
    H[:, 3:6] = Ct
    H[:, 9:12] = skew(p[12:15])
    return (cvb @ H)[1:3].copy()


@njit(cache=True)
def _points(x, dX, p):
    """``h(x ⊞ dX_i) - h(x)``, (m, k)."""
    z0 = _h(x, p)
    Z = np.empty((dX.shape[0], z0.shape[0]))
    for i in range(dX.shape[0]):
        Z[i] = _h(plus(x, dX[i]), p) - z0
    return Z


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
