"""Odometry yaw rate: the vehicle's turn rate about its own z axis (up), w.r.t. the Earth, as a
wheel odometer (differential wheel speeds, a ROS ``nav_msgs/Odometry`` twist) reports it.  While
driving, the gyro's vertical bias is what separates the gyro's rate from the wheels' one, so this
makes it observable without stopping (ZARU needs a standstill).

Vehicle frame v (FLU) = ``C_vb`` times the IMU body frame (``[vehicle] mounting_rpy_deg``).  The
body turns w.r.t. the Earth at ``w_eb = w_m - b_g - C^T w_ie^n(lat)`` (``w_m`` the gyro output,
``C`` = C_nb of the nominal, ``w_ie^n = [0, W cos lat, W sin lat]``), so
``h(x) = e_z^T C_vb (w_m - b_g - C^T w_ie^n)``; with ``C_true = exp([phi x]) C``
(``C_true^T w = C^T w + C^T [w x] phi``):
``H = -e_z^T C_vb [C^T [w_ie^n x], 0, 0, I, 0]``.  ``p = [C_vb (9, row-major), w_m (3)]``;
``w_m`` is the mean gyro output over the odometry's own sampling interval centred on the epoch,
whose white noise (``ARW^2 / T``) is added to ``R``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from navpp.kernel import njit

from ..attitude import quat_to_dcm, skew
from ..state import ATT, DX_BG, N_ERR, NOMINAL_BG, NOMINAL_Q, X_LAT
from .base import Aid, points_kernel
from .zero_rate import earth_rate_n

P_C_VB = slice(0, 9)      #: ``p``: C_vb, body -> vehicle, row-major
P_GYRO = slice(9, 12)     #: ``p``: mean gyro output around the epoch, body FLU, rad/s


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    cvb = np.ascontiguousarray(p[P_C_VB]).reshape(3, 3)
    w_eb = p[P_GYRO] - x[NOMINAL_BG] - quat_to_dcm(x[NOMINAL_Q]).T @ earth_rate_n(x[X_LAT])
    z = np.empty(1)
    z[0] = (cvb @ w_eb)[2]
    return z


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    cvb = np.ascontiguousarray(p[P_C_VB]).reshape(3, 3)
    J = np.zeros((3, N_ERR))
    J[:, ATT] = np.ascontiguousarray(quat_to_dcm(x[NOMINAL_Q]).T) @ skew(earth_rate_n(x[X_LAT]))
    J[0, DX_BG] = J[1, DX_BG + 1] = J[2, DX_BG + 2] = 1.0
    H: np.ndarray = -(cvb @ J)[2:3].copy()
    return H


_points = points_kernel(_h)


class OdometerYawRate(Aid):
    """The odometry's yaw rate at ``t``; build with :meth:`at`."""

    kind: ClassVar[str] = "odometer_yaw"
    axes: ClassVar[tuple[str, ...]] = ("yaw_rate",)
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, yaw_rate_rps: float, std_rps: float, c_vb: np.ndarray, mean_gyro: np.ndarray,
           gyro_var: float) -> OdometerYawRate:
        """``yaw_rate_rps`` the odometry's reading and ``std_rps`` its 1-sigma, rad/s; ``c_vb`` (3, 3)
        body -> vehicle; ``mean_gyro`` (3,) rad/s, the gyro's mean around ``t`` and ``gyro_var``
        its white-noise variance, (rad/s)^2."""
        p = np.concatenate([np.asarray(c_vb, dtype=float).ravel(), np.asarray(mean_gyro, dtype=float)])
        return cls(t, np.array([float(yaw_rate_rps)]), np.array([[float(std_rps) ** 2 + float(gyro_var)]]), p)


__all__ = ["OdometerYawRate"]
