"""The randomised third-degree stochastic integration (SI) rule and its iteration average.

One draw of the rule, in standardised space (``xi ~ N(0, I_n)``): a uniformly random orthogonal
matrix ``U`` and a radius ``rho ~ chi(n + 2)``; points ``0`` and ``+-rho U e_i`` (i = 1..n) with
weights ``w0 = 1 - n / rho^2`` and ``w+- = 1 / (2 rho^2)``.  For every draw the rule is exact for
polynomials of degree <= 3 (weights sum to 1, odd moments vanish by symmetry, and
``sum w+- rho^2 U e_i e_i^T U^T = U U^T = I``).  Higher-degree moments are random but unbiased:
e.g. ``E[rule(xi_1^4)] = E[rho^2] E[sum_i U_1i^4] = (n + 2) * 3 / (n + 2) = 3``.  Averaging
independent draws therefore converges to the Gaussian integral (the "stochastic integration"
of Dunik et al.), at the Monte-Carlo rate of the residual, while degree-3 parts stay exact.

:class:`IterationAverage` is the running mean ``I_j = I_{j-1} + (SR_j - I_{j-1}) / j`` of the
iteration values together with Welford's running sum of squared deviations, from which the
standard error of the mean estimates the integration error (the stopping rule's input).

References: J. Dunik, O. Straka, M. Simandl, "Stochastic integration filter", IEEE Trans.
Automatic Control 58(6):1561-1566, 2013 (its ref [13] in paper 001); the spherical-radial
randomisation goes back to Genz & Monahan (1998).  docs/algorithms.md "Paper 001's comparison
filters (AUKF, SIF)".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linalg import compiled


@compiled
def _haar_from_gaussian(G: np.ndarray) -> np.ndarray:
    """Orthonormalise the columns of ``G`` (n, n) by modified Gram-Schmidt, run twice.

    This is the QR factorisation ``G = U R`` with ``R``'s diagonal positive, i.e. numpy's QR
    with the column signs fixed by ``sign(diag R)``; for a standard Gaussian ``G`` the result is
    Haar distributed (Mezzadri 2007).  The second pass ("twice is enough") keeps ``U^T U = I``
    to round-off even for an ill-conditioned ``G``.
    """
    n = G.shape[0]
    U = G.copy()
    for j in range(n):
        for _ in range(2):
            for k in range(j):
                d = 0.0
                for i in range(n):
                    d += U[i, k] * U[i, j]
                for i in range(n):
                    U[i, j] -= d * U[i, k]
        s = 0.0
        for i in range(n):
            s += U[i, j] * U[i, j]
        s = np.sqrt(s)
        for i in range(n):
            U[i, j] /= s
    return U


@compiled
def _si_draws(G: np.ndarray, rho2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standardised points (J, 2n + 1, n) and weights (J, 2n + 1) for J draws ``G`` (J, n, n),
    ``rho2`` (J,): row 0 the centre, rows 1..n ``rho U e_i``, rows n+1..2n their negatives."""
    J, n = G.shape[0], G.shape[1]
    xi = np.zeros((J, 2 * n + 1, n))
    w = np.empty((J, 2 * n + 1))
    for j in range(J):
        U = _haar_from_gaussian(G[j])
        rho = np.sqrt(rho2[j])
        for i in range(n):
            for c in range(n):
                xi[j, 1 + i, c] = rho * U[c, i]
                xi[j, 1 + n + i, c] = -rho * U[c, i]
        w[j, :] = 0.5 / rho2[j]
        w[j, 0] = 1.0 - n / rho2[j]              # may be large and negative for a small rho
    return xi, w


def random_orthogonal(rng: np.random.Generator, n: int) -> np.ndarray:
    """A uniformly (Haar) distributed orthogonal matrix (n, n): QR of a standard Gaussian
    matrix with the signs of R's diagonal fixed (see :func:`_haar_from_gaussian`)."""
    return _haar_from_gaussian(rng.standard_normal((n, n)))


@dataclass(frozen=True)
class StochasticIntegrationRule:
    """Third-degree SI rule: independent random draws of standardised points and weights."""

    def draws(self, rng: np.random.Generator, n: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``count`` independent draws: standardised points ``xi`` (count, 2n + 1, n) and
        weights (count, 2n + 1).

        Per draw, row 0 is the centre (0), rows ``1..n`` are ``rho U e_i`` and rows
        ``n+1..2n`` their negatives, with ``U`` Haar orthogonal and ``rho^2 ~ chi^2(n + 2)``;
        weights ``1 - n / rho^2`` (centre) and ``1 / (2 rho^2)``.  The Generator always
        advances by ``count`` draws: ``count`` Gaussian (n, n) matrices, then ``count`` radii.
        """
        G = rng.standard_normal((count, n, n))
        rho2 = rng.chisquare(n + 2, size=count)   # rho^2 ~ chi^2(n + 2), i.e. rho ~ chi(n + 2)
        return _si_draws(G, rho2)

    def points(self, S: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One draw as error-space points ``dX = S xi`` (2n + 1, n) for ``P = S S^T``, with
        weights (wm, wc) as the deterministic rules of :mod:`navpp.filters.rules` give them."""
        xi, w = self.draws(rng, S.shape[0], 1)
        return xi[0] @ S.T, w[0], w[0]


class IterationAverage:
    """Running mean and standard error of the per-iteration values of several arrays.

    ``add(values)`` takes one iteration's arrays (a fixed tuple of shapes); ``mean`` is the
    running mean ``I_j``; ``standard_error()`` the element-wise standard error of that mean,
    ``sqrt(s^2 / j)`` with ``s^2`` the unbiased sample variance of the iteration values
    (undefined, inf, before two iterations).
    """

    def __init__(self) -> None:
        self.count = 0
        self.mean: list[np.ndarray] = []
        self._m2: list[np.ndarray] = []

    def add(self, values: tuple[np.ndarray, ...]) -> None:
        self.count += 1
        j = self.count
        if j == 1:
            self.mean = [np.array(v, dtype=float) for v in values]
            self._m2 = [np.zeros_like(m) for m in self.mean]
            return
        for mean, m2, v in zip(self.mean, self._m2, values):
            delta = v - mean
            mean += delta / j                   # I_j = I_{j-1} + (SR_j - I_{j-1}) / j
            m2 += delta * (v - mean)            # Welford: sum of squared deviations

    def standard_error(self) -> list[np.ndarray]:
        j = self.count
        if j < 2:
            return [np.full_like(m, np.inf) for m in self.mean]
        return [np.sqrt(np.maximum(m2, 0.0) / ((j - 1) * j)) for m2 in self._m2]
