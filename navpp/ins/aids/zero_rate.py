"""ZARU: while the vehicle stands still it turns only with the Earth, so the gyro measures its
bias plus the Earth rate, which makes the gyro bias (the vertical one above all, which nothing
else observes at a stop) observable.

``z`` = mean gyro output over the still interval (body FLU, rad/s);
``h(x) = b_g + C^T w_ie^n(lat)`` (``C`` = C_nb of the nominal, ``w_ie^n = [0, W cos lat, W sin lat]``);
with ``C_true = exp([phi x]) C``: ``H = [C^T [w_ie^n x], 0, 0, I, 0]``;
``R = (ARW^2 / T + floor^2) I`` for a mean over ``T`` seconds.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numba import njit

from ...geodesy import OMEGA_E
from ..attitude import quat_to_dcm
from ..model import plus
from .base import Aid, skew


@njit(cache=True, inline="always")
def _earth_rate(lat):
    return np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])


@njit(cache=True)
def _h(x, p):
    return x[10:13] + quat_to_dcm(x[0:4]).T @ _earth_rate(x[7])


@njit(cache=True)
def _H(x, p):
    H = np.zeros((3, 15))
    H[:, 0:3] = quat_to_dcm(x[0:4]).T @ skew(_earth_rate(x[7]))
    H[0, 9] = H[1, 10] = H[2, 11] = 1.0
    return H


@njit(cache=True)
def _points(x, dX, p):
    """``h(x ⊞ dX_i) - h(x)``, (m, k)."""
    z0 = _h(x, p)
    Z = np.empty((dX.shape[0], z0.shape[0]))
    for i in range(dX.shape[0]):
        Z[i] = _h(plus(x, dX[i]), p) - z0
    return Z


class ZeroRate(Aid):
    """ZARU at ``t``; build with :meth:`at`."""

    kind: ClassVar[str] = "zaru"
    axes: ClassVar[tuple[str, ...]] = ("wx", "wy", "wz")
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, mean_gyro: np.ndarray, duration_s: float, gyro_arw: float,
           floor_rps: float) -> ZeroRate:
        """``mean_gyro`` (3,) rad/s averaged over ``duration_s``; ``gyro_arw`` rad/sqrt(s)."""
        var = gyro_arw ** 2 / max(duration_s, 1e-9) + floor_rps ** 2
        return cls(t, np.asarray(mean_gyro, dtype=float), np.eye(3) * var, np.zeros(0))
