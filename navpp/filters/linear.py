"""Linear Gaussian models in the filter-core protocols (:mod:`navpp.filters.protocols`).

Used as the closed-form oracle for every registered filter (on a linear model each must
reproduce the Kalman filter) and as the base of the papers' benchmark models.  States are
plain vectors, so ``plus``/``minus`` are addition and subtraction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .protocols import Interval, MeasurementBase


class VectorSpace:
    """⊞ / ⊟ of a model whose states are plain vectors: addition and subtraction."""

    @staticmethod
    def plus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        out: np.ndarray = x + dx
        return out

    @staticmethod
    def minus(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        out: np.ndarray = x1 - x0
        return out

    @staticmethod
    def rts_means(x_post: np.ndarray, x_prior: np.ndarray, gains: np.ndarray, reset: np.ndarray) -> np.ndarray:
        """The RTS smoother's mean recursion (:class:`~navpp.filters.protocols.SmoothableModel`)."""
        m = x_post.shape[0]
        xs = np.empty_like(x_post)
        xs[m - 1] = x_post[m - 1]
        for k in range(m - 2, -1, -1):
            if reset[k + 1]:
                xs[k] = x_post[k]
                continue
            xs[k] = x_post[k] + gains[k + 1] @ (xs[k + 1] - x_prior[k + 1])
        return xs


@dataclass(frozen=True)
class LinearModel(VectorSpace):
    """``x_k = Phi x_{k-1} + w``, ``w ~ N(0, Q)``, for any interval (``Phi``, ``Q`` per step).

    Phi : (n, n); Q : (n, n).
    Q_groups : optional split of Q by noise source for variance component estimation, a tuple
        of ``(name, (n, n) array)`` summing to Q (e.g. paper 003's coordinated turn: ``q1`` for
        both position-velocity blocks, ``q2`` for the turn rate).  See :meth:`noise_groups`.
    """

    Phi: np.ndarray
    Q: np.ndarray
    Q_groups: tuple[tuple[str, np.ndarray], ...] | None = None
    #: every step's noise reaches the next measurement directly: VCE measures it per step
    noise_share: ClassVar[str] = "step"

    @property
    def dim(self) -> int:
        return int(self.Phi.shape[0])

    def transition(self, x: np.ndarray, interval: Interval) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.Phi @ x, self.Phi, self.Q

    def process_noise(self, x: np.ndarray, interval: Interval) -> np.ndarray:
        return self.Q

    def noise_groups(self, x: np.ndarray, interval: Interval, per: str = "") -> tuple[list[str], np.ndarray]:
        """Q split by noise source: ``(names, Qs (G, n, n))`` with ``Qs.sum(0) == Q`` (one
        grouping: ``per`` is ignored).

        ``Q_groups`` when given; otherwise one group per nonzero diagonal element of a
        diagonal Q (``q0``, ``q1``, ... by state index: paper 003's per-element factors), else
        the single group ``Q``.
        """
        if self.Q_groups is not None:
            return [name for name, _ in self.Q_groups], np.array([np.asarray(q, dtype=float) for _, q in self.Q_groups])
        Q = np.asarray(self.Q, dtype=float)
        d = np.diagonal(Q)
        if np.count_nonzero(Q - np.diag(d)) == 0:
            idx = np.flatnonzero(d)
            Qs = np.zeros((idx.size, Q.shape[0], Q.shape[0]))
            Qs[np.arange(idx.size), idx, idx] = d[idx]
            return [f"q{i}" for i in idx], Qs
        return ["Q"], Q[None, :, :].copy()

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval: Interval) -> tuple[np.ndarray, np.ndarray]:
        return self.Phi @ x, dX @ self.Phi.T


@dataclass(frozen=True)
class LinearMeasurement(MeasurementBase):
    """``z = H x + v``, ``v ~ N(0, R)``; z : (m,), H : (m, n), R : (m, m).  The attributes of
    :class:`~navpp.filters.protocols.MeasurementBase` (adaptive, forceable, no axes)."""

    t: float
    z: np.ndarray
    H: np.ndarray
    R: np.ndarray

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        nu: np.ndarray = self.z - self.H @ x
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        Z: np.ndarray = dX @ self.H.T
        return Z
