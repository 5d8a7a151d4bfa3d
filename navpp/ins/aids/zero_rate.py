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

from navpp.kernel import njit

from ...geodesy import OMEGA_E
from ..attitude import quat_to_dcm, skew
from ..state import DX_ATT, DX_BG, N_ERR, NOMINAL_BG, NOMINAL_Q, X_LAT
from .base import Aid, points_kernel


@njit(cache=True, inline="always")
def earth_rate_n(lat: float) -> np.ndarray:
    """Earth rotation rate in ENU at latitude ``lat`` (rad), rad/s."""
    return np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    w: np.ndarray = x[NOMINAL_BG] + quat_to_dcm(x[NOMINAL_Q]).T @ earth_rate_n(x[X_LAT])
    return w


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    H = np.zeros((3, N_ERR))
    M = quat_to_dcm(x[NOMINAL_Q]).T @ skew(earth_rate_n(x[X_LAT]))
    for r in range(3):              # element loops, not slice assignment (see navpp/jitcache.py)
        for c in range(3):
            H[r, DX_ATT + c] = M[r, c]
    H[0, DX_BG] = H[1, DX_BG + 1] = H[2, DX_BG + 2] = 1.0
    return H


_points = points_kernel(_h)


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
        var = cls.variance(duration_s, gyro_arw, floor_rps)
        return cls(t, np.asarray(mean_gyro, dtype=float), np.eye(3) * var, np.zeros(0))

    @staticmethod
    def variance(duration_s: float, gyro_arw: float, floor_rps: float) -> float:
        """Each axis's variance, (rad/s)^2, of a mean rate over ``duration_s`` (s) of white noise
        ``gyro_arw`` (rad/sqrt(s)) with the floor ``floor_rps`` (rad/s)."""
        return gyro_arw ** 2 / max(duration_s, 1e-9) + floor_rps ** 2
