"""Small dense linear algebra of the filter core, compiled: Cholesky factor and solves, the
Kalman gain with the NIS, the Joseph-form and sigma-point posterior covariances.

Matrices are tiny (n = 15 states, m <= 3 measurement elements on the INS), so hand-written
loops compiled by numba beat LAPACK calls through numpy; they run without BLAS threading.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from navpp.kernel import njit

F = TypeVar("F", bound=Callable[..., Any])


def compiled(fn: F) -> F:
    """``numba.njit(cache=True)`` keeping the function's signature for type checkers."""
    return njit(cache=True)(fn)


def symmetrise(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` (a new array; halved in place, the same figures as ``0.5 * (P + P.T)``)."""
    out: np.ndarray = P + P.T
    out *= 0.5
    return out


@compiled
def propagated_covariance(P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's covariance time update in one call: the prior ``Phi P Phi^T + Qd`` (n, n),
    symmetrised (:func:`symmetrise`'s figures), and the cross-covariance ``P Phi^T`` of the errors
    at the interval's start and end (the smoother's)."""
    PPhit = P @ Phi.T
    Pn = Phi @ PPhit + Qd
    out = Pn + Pn.T
    out *= 0.5
    return out, PPhit


@compiled
def linear_moments(P: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted-measurement moments of a linearised measurement with Jacobian ``H`` (m, n)
    about the covariance ``P`` (n, n): ``P H^T`` (n, m) and ``H P H^T`` (m, m), before R."""
    PHt = P @ H.T
    return PHt, H @ PHt


@compiled
def all_finite(x: np.ndarray, P: np.ndarray) -> bool:
    """Whether the sums of the state ``x`` (n,) and its covariance ``P`` (m, m) are finite (so is
    every element then)."""
    return bool(np.isfinite(x.sum() + P.sum()))


@compiled
def finite_with_positive_variances(x: np.ndarray, P: np.ndarray) -> bool:
    """Whether :func:`all_finite` holds for the state ``x`` (n,) and its covariance ``P`` (m, m)
    and every variance on ``P``'s diagonal is positive: a state that needs no closer look
    (:func:`navpp.engine.verdict.state_fault`)."""
    if not all_finite(x, P):
        return False
    for i in range(P.shape[0]):  # noqa: SIM110 (compiled: a loop, no copy of the diagonal; all finite, so min > 0 is every > 0)
        if not P[i, i] > 0.0:
            return False
    return True


@compiled
def chol_solve(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Solve ``(L L^T) X = B`` for lower-triangular ``L`` (m, m), ``B`` (m, k)."""
    m, k = B.shape
    Y = np.empty((m, k))
    Bt, Yt = B.T, Y.T              # column c of B and Y as row c: the substitutions of _chol_solve_row
    for c in range(k):
        _chol_solve_row(L, Bt, c, Yt)
    return Y


@compiled
def cholesky(S: np.ndarray) -> tuple[np.ndarray, bool]:
    """Lower Cholesky factor of ``S`` and whether ``S`` is (numerically) positive definite."""
    m = S.shape[0]
    L = np.zeros((m, m))
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:            # also catches NaN
            return L, False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, m):
            v = S[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / L[j, j]
    return L, True


@compiled
def gain_and_nis(Pxz: np.ndarray, S: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, float, bool]:
    """Kalman gain ``K = Pxz S^-1`` and ``nis = nu^T S^-1 nu`` by Cholesky solves; ``ok`` is
    False when S is not positive definite (K and nis are then meaningless)."""
    L, ok = cholesky(S)
    if not ok:
        return np.zeros_like(Pxz), np.inf, False
    # chol_solve's substitutions (the same operations in the same order) on each row of Pxz, the
    # solution written straight into K's row, and on nu: no transposed copies
    n, m = Pxz.shape
    K = np.empty((n, m))
    for c in range(n):
        _chol_solve_row(L, Pxz, c, K)
    nu2 = np.empty((1, m))
    for i in range(m):
        nu2[0, i] = nu[i]
    _chol_solve_row(L, nu2, 0, nu2)
    w = nu2[0]
    return K, float(nu @ w), True


@njit(cache=True, inline="always")
def _chol_solve_row(L: np.ndarray, B: np.ndarray, c: int, out: np.ndarray) -> None:
    """``out[c] = (L L^T)^-1 B[c]`` for lower-triangular ``L`` (m, m): forward then backward
    substitution on row ``c`` (:func:`chol_solve` runs it on each column); ``out`` may be ``B``."""
    m = L.shape[0]
    for i in range(m):
        s = B[c, i]
        for j in range(i):
            s -= L[i, j] * out[c, j]
        out[c, i] = s / L[i, i]
    for i in range(m - 1, -1, -1):
        s = out[c, i]
        for j in range(i + 1, m):
            s -= L[j, i] * out[c, j]
        out[c, i] = s / L[i, i]


@compiled
def innovation_gain(Pzz: np.ndarray, R: np.ndarray, Pxz: np.ndarray, nu: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """Innovation covariance ``S = Pzz + R`` (m, m), symmetrised (:func:`symmetrise`'s figures),
    with :func:`gain_and_nis` about it: ``(S, K, nis, ok)``."""
    m = Pzz.shape[0]
    S = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            S[i, j] = ((Pzz[i, j] + R[i, j]) + (Pzz[j, i] + R[j, i])) * 0.5
    K, nis, ok = gain_and_nis(Pxz, S, nu)
    return S, K, nis, ok


@compiled
def joseph(P: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Joseph-form posterior ``(I - K H) P (I - K H)^T + K R K^T``, symmetrised."""
    I_KH = np.eye(P.shape[0]) - K @ H
    Pn = I_KH @ P @ I_KH.T + K @ R @ K.T
    out: np.ndarray = 0.5 * (Pn + Pn.T)
    return out


@compiled
def joseph_correction(P: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray, nu: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """A linearised filter's correction in one call: the error estimate ``K nu`` (n,) and the
    Joseph-form posterior covariance (:func:`joseph`)."""
    dx: np.ndarray = K @ nu
    return dx, joseph(P, K, H, R)


@compiled
def sigma_posterior(P: np.ndarray, K: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Posterior ``P - K S K^T`` of a filter without a Jacobian, symmetrised."""
    Pn = P - K @ S @ K.T
    out: np.ndarray = 0.5 * (Pn + Pn.T)
    return out


@compiled
def nis_and_logdet(S: np.ndarray, nu: np.ndarray) -> tuple[float, float, bool]:
    """``nu^T S^-1 nu`` and ``log det S`` by a Cholesky factor of ``S`` (m, m); ``ok`` is False
    when S is not positive definite (both values are then inf)."""
    L, ok = cholesky(S)
    if not ok:
        return np.inf, np.inf, False
    m = nu.shape[0]
    w = np.empty(m)
    nis = 0.0
    logdet = 0.0
    for i in range(m):
        s = nu[i]
        for j in range(i):
            s -= L[i, j] * w[j]
        w[i] = s / L[i, i]
        nis += w[i] * w[i]
        logdet += 2.0 * np.log(L[i, i])
    return nis, logdet, True
