"""Sigma-point rules: where the points go and how they are weighted.

A rule turns a covariance factor ``S`` (``P = S S^T``, lower Cholesky) into error-space points
``dX`` (m, n) around the mean, with mean weights ``wm`` and covariance weights ``wc`` (m,).

References: cubature rule, paper 001 eqs 3-6 and paper 003 eqs 19-22 (Arasaratnam & Haykin
2009); scaled unscented transform, Wan & van der Merwe (2000).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

#: error-space points dX (p, n), mean weights wm (p,), covariance weights wc (p,)
Points = tuple[np.ndarray, np.ndarray, np.ndarray]


class SigmaRule(Protocol):
    """Where the points of a sigma-point filter go and how they are weighted."""

    def points(self, S: np.ndarray) -> Points:
        """Points and weights for the covariance factor ``S`` (n, n), ``P = S S^T``."""
        ...


@dataclass(frozen=True)
class CubatureRule:
    """Third-degree spherical-radial cubature: ``xi = +-sqrt(n) e_i``, weights ``1 / (2n)``."""

    def points(self, S: np.ndarray) -> Points:
        n = S.shape[0]
        cols = np.sqrt(n) * S.T                  # row i = sqrt(n) S e_i
        dX = np.vstack([cols, -cols])
        w = np.full(2 * n, 1.0 / (2 * n))
        return dX, w, w


@dataclass(frozen=True)
class UnscentedRule:
    """Scaled unscented transform with ``alpha``, ``beta``, ``kappa``: ``lambda = alpha^2 (n +
    kappa) - n``; points ``0, +-sqrt(n + lambda) S e_i``; ``wm0 = lambda / (n + lambda)``,
    ``wc0 = wm0 + 1 - alpha^2 + beta``, others ``1 / (2 (n + lambda))``.  Small alphas give a
    large negative centre weight on 15 states (paper 001's warning)."""

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def points(self, S: np.ndarray) -> Points:
        n = S.shape[0]
        lam = self.alpha ** 2 * (n + self.kappa) - n
        c = n + lam
        if c <= 0:
            raise ValueError(f"unscented rule: n + lambda = {c:g} must be > 0 (alpha={self.alpha}, kappa={self.kappa})")
        cols = np.sqrt(c) * S.T
        dX = np.vstack([np.zeros((1, n)), cols, -cols])
        wm = np.full(2 * n + 1, 0.5 / c)
        wc = wm.copy()
        wm[0] = lam / c
        wc[0] = lam / c + 1.0 - self.alpha ** 2 + self.beta
        return dX, wm, wc


@dataclass(frozen=True)
class DirichletWeights:
    """Random weights ``beta ~ Dirichlet(1, ..., 1)`` over ``m`` points (paper 001 eq 23).

    The paper draws them as the gaps between sorted uniforms, ``beta_j = U_(j) - U_(j-1)``;
    ``Generator.dirichlet`` samples the same distribution.  Every vector sums to 1 and has
    non-negative entries, mean ``1/m`` each.
    """

    def draw(self, rng: np.random.Generator, m: int, size: int | None = None) -> np.ndarray:
        """One (m,) weight vector, or (size, m) when ``size`` is given."""
        out: np.ndarray = rng.dirichlet(np.ones(m), size=size)
        return out
