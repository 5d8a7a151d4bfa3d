"""Model-free tools for bounds and empirical bests of the small benchmarks: the posterior
Cramér-Rao bound (PCRB) recursion and its information blocks, a bootstrap particle filter, and
bootstrap intervals over Monte Carlo runs.  The models' own parts (paper 001's tracking:
:func:`navpp.papers.tracking.tracking_pcrb`, :func:`~navpp.papers.tracking.tracking_pf`) live
with the experiments; this module imports none of them.

PCRB: Tichavský, Muravchik and Nehorai, "Posterior Cramér-Rao bounds for discrete-time nonlinear
filtering", IEEE Trans. Signal Processing 46(5), 1998, eq 21: the information of x_k obeys
``J_k = D22 - D21 (J_{k-1} + D11)^-1 D12`` with ``J_0 = P0^-1`` and

- ``D11 = E[-d2/dx_{k-1}^2 log p(x_k | x_{k-1})]``,
- ``D12 = E[-d2/dx_{k-1} dx_k log p(x_k | x_{k-1})]`` (``D21 = D12'``),
- ``D22 = E[-d2/dx_k^2 log p(x_k | x_{k-1})] + E[-d2/dx_k^2 log p(z_k | x_k)]``,

the expectations taken over the truth (Monte Carlo over simulated truths).  Any estimator's
error covariance at k is at least ``J_k^-1``.  With additive Gaussian process noise the blocks
follow from the Jacobians of the transition (:func:`additive_blocks`); otherwise from the scores,
``D_ij = E[s_i s_j']`` (:func:`score_blocks`; the Fisher information identity).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

#: particles of the bootstrap filter: doubling it to 8,000 moves the 100-run RMSE by 0.06 %
#: on paper 001's tracking (measured, see docs/papers.md)
PF_PARTICLES = 4_000


def pcrb_recursion(J0: np.ndarray, D11: np.ndarray, D12: np.ndarray, D22: np.ndarray) -> np.ndarray:
    """The PCRB information recursion (Tichavský et al. 1998, eq 21).

    J0 : (n, n) prior information; D11, D12, D22 : (K, n, n) the expected blocks of step
    k = 1..K.  Returns the bound covariances ``J_k^-1``, (K, n, n).
    """
    J = np.asarray(J0, dtype=float)
    out = np.empty_like(np.asarray(D22, dtype=float))
    for k in range(out.shape[0]):
        J = D22[k] - D12[k].T @ np.linalg.solve(J + D11[k], D12[k])
        J = 0.5 * (J + J.T)
        out[k] = np.linalg.inv(J)
    return out


def linear_blocks(Phi: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray,
                  steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """D11, D12, D22 (steps, n, n) of ``x_k = Phi x_{k-1} + w``, w ~ N(0, Q), z = H x + v, v ~ N(0, R)."""
    Qi_Phi = np.linalg.solve(Q, Phi)
    D11 = Phi.T @ Qi_Phi
    D12 = -Qi_Phi.T
    D22 = np.linalg.inv(Q) + H.T @ np.linalg.solve(R, H)
    return tuple(np.broadcast_to(D, (steps,) + D.shape).copy() for D in (D11, D12, D22))  # type: ignore[return-value]


def additive_blocks(A: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray,
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """D11, D12, D22 (K, n, n) of ``x_k = f(x_{k-1}) + w``, w ~ N(0, Q), z = H x + v, v ~ N(0, R),
    from the Jacobians ``A = df/dx`` (runs, K, n, n) at the truths x_0 .. x_{K-1}:
    ``D11 = E[A' Q^-1 A]``, ``D12 = -E[A'] Q^-1``, ``D22 = Q^-1 + H' R^-1 H``."""
    Qi = np.linalg.inv(Q)
    D11 = np.mean(np.swapaxes(A, -1, -2) @ (Qi @ A), axis=0)
    D12 = -np.swapaxes(np.mean(A, axis=0), -1, -2) @ Qi
    D22 = np.broadcast_to(Qi + H.T @ np.linalg.solve(R, H), D11.shape).copy()
    return D11, D12, D22


def score_blocks(s1: np.ndarray, s2: np.ndarray, H: np.ndarray, R: np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """D11, D12, D22 (K, n, n) in the score form ``D_ij = E[s_i s_j']`` from the scores
    s1 = d/dx_{k-1} log p(x_k | x_{k-1}), s2 = d/dx_k log p(x_k | x_{k-1}), each (runs, K, n) at
    the truths; the measurement adds ``H' R^-1 H`` (linear measurement) to D22."""
    D11 = np.mean(s1[..., :, None] * s1[..., None, :], axis=0)
    D12 = np.mean(s1[..., :, None] * s2[..., None, :], axis=0)
    D22 = np.mean(s2[..., :, None] * s2[..., None, :], axis=0) + H.T @ np.linalg.solve(R, H)
    return D11, D12, D22


def position_bound(bound_cov: np.ndarray, idx: Sequence[int] = (0, 2)) -> tuple[float, np.ndarray]:
    """Position RMSE bound ``sqrt(mean_k tr P_pos)`` and its curve (K,) from (K, n, n) bounds."""
    tr = np.sum(bound_cov[:, list(idx), list(idx)], axis=-1)
    return float(np.sqrt(np.mean(tr))), np.sqrt(tr)


def bootstrap_pf(Z: np.ndarray, rng: np.random.Generator, step: Callable[[np.ndarray, np.ndarray], np.ndarray],
                 Q: np.ndarray, H: np.ndarray, R: np.ndarray, x0: np.ndarray, P0: np.ndarray,
                 particles: int = PF_PARTICLES) -> np.ndarray:
    """A bootstrap particle filter: ``x_k = step(x_{k-1}, w_k)``, w ~ N(0, Q); z_k = H x_k + v, v ~ N(0, R).

    Z : (K, m) measurements at k = 1..K; ``step`` maps (N, n) particles and (N, n) noises to
    (N, n); x0, P0 : the Gaussian start.  Returns the posterior means (K, n), taken before
    resampling; systematic resampling every step.  Particles that run away to non-finite values
    get zero weight.

    References: Gordon, Salmond and Smith, "Novel approach to nonlinear/non-Gaussian Bayesian
    state estimation", IEE Proc. F 140(2), 1993.
    """
    n = x0.shape[0]
    L = np.linalg.cholesky(Q)
    Ri_half = np.linalg.inv(np.linalg.cholesky(R))           # whitens the residual
    X = x0 + rng.standard_normal((particles, n)) @ np.linalg.cholesky(P0).T
    means = np.empty((Z.shape[0], n))
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(Z.shape[0]):
            X = step(X, rng.standard_normal((particles, n)) @ L.T)
            d = (Z[k] - X @ H.T) @ Ri_half.T
            logw = -0.5 * np.sum(d * d, axis=1)
            logw[~np.isfinite(logw)] = -np.inf
            wts = np.exp(logw - np.max(logw))
            wts /= np.sum(wts)
            means[k] = wts @ np.where(wts[:, None] > 0, X, 0.0)
            edges = np.cumsum(wts)
            edges[-1] = 1.0
            X = X[np.searchsorted(edges, (rng.random() + np.arange(particles)) / particles)]
    return means


def rmse_interval(err: np.ndarray, idx: Sequence[int] = (0, 2), draws: int = 2000,
                  seed: int = 0) -> tuple[float, float]:
    """95 % bootstrap interval over runs of the pooled RMSE; err (runs, K, n)."""
    per_run = np.mean(np.sum(err[..., list(idx)] ** 2, axis=-1), axis=1)
    if per_run.size < 2:
        return float("nan"), float("nan")
    pick = np.random.default_rng(seed).integers(0, per_run.size, (draws, per_run.size))
    lo, hi = np.percentile(np.sqrt(np.mean(per_run[pick], axis=1)), [2.5, 97.5])
    return float(lo), float(hi)




def ratio_interval(err_a: np.ndarray, err_b: np.ndarray, idx: Sequence[int] = (0, 2), draws: int = 2000,
                   seed: int = 0) -> tuple[float, float]:
    """95 % paired bootstrap interval over runs of RMSE(a) / RMSE(b); err_a, err_b (runs, K, n) on
    the same runs."""
    a, b = (np.mean(np.sum(e[..., list(idx)] ** 2, axis=-1), axis=1) for e in (err_a, err_b))
    if a.size < 2:
        return float("nan"), float("nan")
    pick = np.random.default_rng(seed).integers(0, a.size, (draws, a.size))
    lo, hi = np.percentile(np.sqrt(np.mean(a[pick], axis=1) / np.mean(b[pick], axis=1)), [2.5, 97.5])
    return float(lo), float(hi)
