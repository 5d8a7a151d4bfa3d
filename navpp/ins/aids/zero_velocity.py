"""ZUPT: while the vehicle stands still its velocity is zero.

``z = 0`` (3,), ``h(x) = v`` (ENU, m/s, of the body origin), ``H = [0, I, 0, 0, 0]``;
``R = zupt_std^2 I``.  Applied by the engine when :mod:`.standstill` says still.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from navpp.kernel import njit

from ..state import DX_VEL, N_ERR, NOMINAL_VEL
from .base import Aid, points_kernel


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    v: np.ndarray = x[NOMINAL_VEL].copy()
    return v


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    H = np.zeros((3, N_ERR))
    H[0, DX_VEL] = H[1, DX_VEL + 1] = H[2, DX_VEL + 2] = 1.0
    return H


_points = points_kernel(_h)


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
