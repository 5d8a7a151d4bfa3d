"""Linear Gaussian models in the filter-core protocol.

Used as the closed-form oracle for every registered filter (on a linear model each must
reproduce the Kalman filter) and as the base of the papers' benchmark models.  States are
plain vectors, so ``plus``/``minus`` are addition and subtraction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LinearModel:
    """``x_k = Phi x_{k-1} + w``, ``w ~ N(0, Q)``, for any interval (``Phi``, ``Q`` per step).

    Phi : (n, n); Q : (n, n).
    """

    Phi: np.ndarray
    Q: np.ndarray

    @property
    def dim(self) -> int:
        return int(self.Phi.shape[0])

    @staticmethod
    def plus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return x + dx

    @staticmethod
    def minus(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        return x1 - x0

    def transition(self, x: np.ndarray, interval) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.Phi @ x, self.Phi, self.Q

    def process_noise(self, x: np.ndarray, interval) -> np.ndarray:
        return self.Q

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval) -> tuple[np.ndarray, np.ndarray]:
        return self.Phi @ x, dX @ self.Phi.T


@dataclass(frozen=True)
class LinearMeasurement:
    """``z = H x + v``, ``v ~ N(0, R)``; z : (m,), H : (m, n), R : (m, m)."""

    t: float
    z: np.ndarray
    H: np.ndarray
    R: np.ndarray

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        return self.z - self.H @ x

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        return dX @ self.H.T
