"""ZUPT: while the vehicle stands still its velocity is zero.

``z = 0`` (3,), ``h(x) = v`` (ENU, m/s, of the body origin), ``H = [0, I, 0, 0, 0]``;
``R = zupt_std^2 I``.  Applied by the engine when :mod:`.standstill` says still.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numba import njit

from ..model import plus
from .base import Aid


@njit(cache=True)
def _h(x, p):
    return x[4:7].copy()


@njit(cache=True)
def _H(x, p):
    H = np.zeros((3, 15))
    H[0, 3] = H[1, 4] = H[2, 5] = 1.0
    return H


@njit(cache=True)
def _points(x, dX, p):
    """``h(x ⊞ dX_i) - h(x)``, (m, k)."""
    z0 = _h(x, p)
    Z = np.empty((dX.shape[0], z0.shape[0]))
    for i in range(dX.shape[0]):
        Z[i] = _h(plus(x, dX[i]), p) - z0
    return Z


class ZeroVelocity(Aid):
    """ZUPT at ``t``; build with :meth:`at`."""

    kind: ClassVar[str] = "zupt"
    axes: ClassVar[tuple[str, ...]] = ("ve", "vn", "vu")
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, std_mps: float) -> ZeroVelocity:
        return cls(t, np.zeros(3), np.eye(3) * std_mps ** 2, np.zeros(0))
