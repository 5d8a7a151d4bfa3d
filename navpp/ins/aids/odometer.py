"""Odometer: the vehicle's own forward speed (wheel odometry, CAN wheel speed) with a scale-factor
state.

Vehicle frame v (FLU) = ``C_vb`` times the IMU body frame (``[vehicle] mounting_rpy_deg``, as
for the non-holonomic constraint).  The odometry point sits at ``l`` (body FLU, m; ``[odometry]
lever_arm_m``: the wheel axle's centre) and moves with ``v_b = C^T v + w x l``, ``w = w_m - b_g``.
The odometer reads ``z = (1 + s) e_x^T C_vb v_b + noise``: ``s`` is its scale-factor error (a
wheel radius a little off, tyre pressure), carried as an extra state of the augmented INS
(:mod:`navpp.ins.augmented`, block :data:`BLOCK_NAME`, a random constant with a slow random walk).

With ``u(x) = e_x^T C_vb (C^T v + w x l)`` (the speed the INS predicts) and ``C_true = exp([phi x])
C``: ``du/d(dx) = e_x^T C_vb [C^T [v x], C^T, 0, [l x], 0]`` (the NHC's rows,
:mod:`navpp.ins.aids.nonholonomic`, the forward one), so ``H = [(1 + s) du/d(dx), u]`` with the
``u`` in the scale state's column.  ``p``: as the NHC's, ``[C_vb (9, row-major), w_m (3), l (3)]``
(:func:`~navpp.ins.aids.nonholonomic.vehicle_velocity`).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from navpp.kernel import njit

from ..augmented import StateBlock, ins_part
from ..state import N_ERR
from .base import Aid, points_kernel
from .nonholonomic import vehicle_velocity, vehicle_velocity_jacobian

#: the augmented INS block of the odometer's scale-factor error (dimensionless)
BLOCK_NAME = "odometer_scale"


def scale_block(sigma: float, walk_per_sqrt_h: float) -> StateBlock:
    """The scale-factor block: a random constant of initial 1-sigma ``sigma`` (e.g. 0.02 = 2 %)
    that walks by ``walk_per_sqrt_h`` per square-root hour (tyres warming, load)."""
    return StateBlock(BLOCK_NAME, ("odometer_scale",), float("inf"), (float(sigma),),
                      (float(walk_per_sqrt_h) ** 2 / 3600.0,))


@njit(cache=True)
def _h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    z: np.ndarray = vehicle_velocity(x, p)[0:1].copy()
    return z


@njit(cache=True)
def _H(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    Hz: np.ndarray = vehicle_velocity_jacobian(x, p)[0:1].copy()
    return Hz


_points = points_kernel(_h)


class OdometerSpeed(Aid):
    """The odometer's forward speed at ``t``, without a scale state (the INS's 15 elements: the
    odometer taken as exact in scale); build with :meth:`at`.  On an augmented INS with the
    :data:`BLOCK_NAME` block, :meth:`for_model` gives the measurement with the scale state."""

    kind: ClassVar[str] = "odometer"
    axes: ClassVar[tuple[str, ...]] = ("speed",)
    model = staticmethod(_h)
    model_jacobian = staticmethod(_H)
    model_points = staticmethod(_points)

    @classmethod
    def at(cls, t: float, speed_mps: float, std_mps: float, c_vb: np.ndarray, gyro: np.ndarray,
           point_b: np.ndarray) -> OdometerSpeed:
        """``speed_mps`` the odometer's reading and ``std_mps`` its 1-sigma, m/s; ``c_vb`` (3, 3)
        body -> vehicle; ``gyro`` (3,) rad/s at ``t``; ``point_b`` (3,) m, the odometry point."""
        p = np.concatenate([np.asarray(c_vb, dtype=float).ravel(), np.asarray(gyro, dtype=float),
                            np.asarray(point_b, dtype=float)])
        return cls(t, np.array([float(speed_mps)]), np.array([[float(std_mps) ** 2]]), p)

    def for_model(self, model: Any) -> Any:
        """This reading as a measurement of the augmented ``model`` (with the scale state when it
        has the :data:`BLOCK_NAME` block)."""
        from ..augmented import Padded

        if not model.has(BLOCK_NAME):
            return Padded(self, model.dim)
        return ScaledOdometerSpeed(self, model.dim, model.err_slice(BLOCK_NAME).start,
                                   model.nominal_slice(BLOCK_NAME).start)


class ScaledOdometerSpeed:
    """:class:`OdometerSpeed` on an augmented INS with the scale state (``n`` error elements; the
    scale at error index ``i_err`` and nominal index ``i_nom``): ``h = (1 + s) u(x)`` (module
    docstring); every other attribute is the reading's (``inner``)."""

    def __init__(self, inner: OdometerSpeed, n: int, i_err: int, i_nom: int) -> None:
        self.inner, self.n, self.i_err, self.i_nom = inner, n, i_err, i_nom

    def __getattr__(self, name: str) -> Any:
        if name in ("inner", "n", "i_err", "i_nom"):
            raise AttributeError(name)
        return getattr(self.inner, name)

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        u = _h(ins_part(x), self.inner.p)
        nu: np.ndarray = self.inner.z - (1.0 + x[self.i_nom]) * u
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        xi = ins_part(x)
        H = np.zeros((1, self.n))
        H[:, :N_ERR] = (1.0 + x[self.i_nom]) * _H(xi, self.inner.p)
        H[0, self.i_err] = _h(xi, self.inner.p)[0]
        return H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) - h(x)`` = ``(1 + s) (u_i - u) + ds_i u_i`` with ``u_i = u(x ⊞ dX_i)``."""
        dX = np.asarray(dX, dtype=float)
        xi = ins_part(x)
        u0 = _h(xi, self.inner.p)[0]
        du = _points(xi, np.ascontiguousarray(dX[:, :N_ERR]), self.inner.p)[:, 0]
        s = x[self.i_nom]
        ds = dX[:, self.i_err]
        Z: np.ndarray = ((1.0 + s) * du + ds * (u0 + du))[:, None]
        return Z

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        return None


__all__ = ["BLOCK_NAME", "OdometerSpeed", "ScaledOdometerSpeed", "scale_block"]
