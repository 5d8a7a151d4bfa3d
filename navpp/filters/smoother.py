"""Rauch-Tung-Striebel smoothing over a stored forward run, generic over the model.

The forward filter is closed-loop: after each update the estimated error is fed back into the
nominal state, so the forward run is a chain of *nodes* (the start, then the end of every time
update, with or without a measurement there).  At node ``k`` the store keeps

- ``x_prior[k], P_prior[k]``: the prior the measurement update used (for most filters the time
  update's output; the prior an adaptive filter actually corrected, e.g. the AUKF's faded
  covariance or the RWCKF's re-weighted moments);
- ``x_post[k], P_post[k]``: the posterior (= the prior when nothing was applied);
- ``D[k]``: the cross-covariance of the error at node ``k - 1`` (posterior) with the error at
  node ``k`` (prior), ``E[dx_{k-1} dx_k^T]``: ``P_{k-1}^+ Phi^T`` for the EKF, the weighted sum
  of centred point deviations ``sum_i w_i dX_i dY_i^T`` for the sigma-point filters (the
  unscented / cubature RTS smoother, Särkkä 2008);
- ``x_ref[k]``: the nominal the time update propagated to node ``k`` (the path the model
  recorded between nodes: the EKF's prior mean, the sigma-point filters' central point);
- ``reset[k]``: the update re-anchored the covariance (a fix forced through the gate): no
  information is carried back across it (the forward filter itself declared its prior wrong).

Backward, for ``k = M-2 .. 0`` (docs/algorithms.md; error-state form of Rauch, Tung & Striebel 1965):

``C_k = D_{k+1} (P_{k+1}^-)^{-1}`` (Cholesky solve),
``x_k^s = x_k^+ ⊞ C_k (x_{k+1}^s ⊟ x_{k+1}^-)``,
``P_k^s = P_k^+ + C_k (P_{k+1}^s - P_{k+1}^-) C_k^T`` (symmetrised).

Memory: the store holds three (n, n) matrices and three nominal states per node; the backward
pass overwrites ``D`` with the gains and ``P_post`` with the smoothed covariance in place (an
hour of 5 Hz GNSS with 1 s coast knots on the 15-state INS: about 120 MB).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import FilterDivergedError
from .linalg import chol_solve, cholesky, compiled
from .protocols import SmoothableModel
from .states import GaussianState, Prediction


class ForwardStore:
    """What RTS smoothing needs of a forward run, node by node (see the module docstring).

    The forward run only keeps references to the states and matrices the filter made anyway
    (filter states are immutable: every time and measurement update makes new arrays), so
    storing costs the forward run next to nothing; :meth:`arrays` packs them into contiguous
    arrays for the backward pass, one field at a time, releasing the references as it goes.

    Parameters
    ----------
    n_err : error-state dimension n (the covariance is (n, n)).
    n_x : nominal state length.
    """

    FIELDS = ("t", "x_post", "P_post", "x_prior", "P_prior", "D", "x_ref", "reset")

    def __init__(self, n_err: int, n_x: int) -> None:
        self.n_err, self.n_x = int(n_err), int(n_x)
        self._nodes: dict[str, list[Any]] = {name: [] for name in self.FIELDS}

    @property
    def n(self) -> int:
        """Nodes stored so far."""
        return len(self._nodes["t"])

    def start(self, state: GaussianState) -> None:
        """Node 0: the initial state (its prior is itself; no cross-covariance)."""
        if self.n:
            raise ValueError("ForwardStore.start: the store already has nodes")
        self._append(state, np.zeros((self.n_err, self.n_err)), state.x)

    def _append(self, prior: GaussianState, cross: np.ndarray, x_ref: np.ndarray) -> None:
        nd = self._nodes
        nd["t"].append(prior.t)
        nd["x_prior"].append(prior.x)
        nd["x_post"].append(prior.x)
        nd["P_prior"].append(prior.P)
        nd["P_post"].append(prior.P)
        nd["D"].append(cross)
        nd["x_ref"].append(x_ref)
        nd["reset"].append(False)

    def predicted(self, prediction: Prediction) -> None:
        """A time update ended at ``prediction.state.t``: a new node whose posterior is the
        prior until :meth:`updated` says otherwise, with the update's cross-covariance and
        propagated nominal."""
        if self.n == 0:
            raise ValueError("ForwardStore.predicted: call start() first")
        if prediction.cross_cov.shape != (self.n_err, self.n_err):
            raise ValueError(f"ForwardStore.predicted: cross_cov has shape {prediction.cross_cov.shape}, "
                             f"expected ({self.n_err}, {self.n_err})")
        self._append(prediction.state, prediction.cross_cov, prediction.x_ref)

    def updated(self, used_prior: GaussianState | None, posterior: GaussianState, reset: bool = False) -> None:
        """The last node's measurement update: the prior it corrected (None: the time update's
        output), the posterior, and whether the covariance was re-anchored (forced fix)."""
        nd = self._nodes
        if used_prior is not None:
            nd["x_prior"][-1] = used_prior.x
            nd["P_prior"][-1] = used_prior.P
        nd["x_post"][-1] = posterior.x
        nd["P_post"][-1] = posterior.P
        nd["reset"][-1] = bool(reset)

    def arrays(self) -> dict[str, np.ndarray]:
        """The nodes as contiguous arrays (``t`` (M,), ``x_*`` (M, n_x), ``P_*`` and ``D``
        (M, n, n), ``reset`` (M,) bool); empties the store."""
        out = {}
        for name in self.FIELDS:
            items = self._nodes[name]
            out[name] = (np.array(items, dtype=float) if name == "t" else
                         np.array(items, dtype=bool) if name == "reset" else
                         np.array(items) if name.startswith("x") else np.stack(items))
            self._nodes[name] = []
        return out


@dataclass(frozen=True)
class Smoothed:
    """The smoothed nodes: ``t`` (M,) s, ``x`` (M, n_x) nominal states, ``P`` (M, n, n) error
    covariances (a view of the store's memory), ``gains`` (M, n, n): ``gains[k + 1]`` is
    ``C_k`` (zero across a reset), ``breaks``: resets crossed (no smoothing across), and
    ``repaired``: steps where the prior covariance was not positive definite and the step was
    treated as a break."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    gains: np.ndarray
    breaks: int
    repaired: int


@compiled
def _backward_covariances(P_post: np.ndarray, P_prior: np.ndarray, D: np.ndarray, reset: np.ndarray, m: int) -> int:
    """In place: ``P_post[k] <- P_k^s`` and ``D[k + 1] <- C_k`` for k = m-2 .. 0; returns the
    number of steps whose prior was not positive definite (then treated as a reset)."""
    bad = 0
    for k in range(m - 2, -1, -1):
        if reset[k + 1]:
            D[k + 1][:, :] = 0.0
            continue
        L, ok = cholesky(P_prior[k + 1])
        if not ok:
            D[k + 1][:, :] = 0.0
            bad += 1
            continue
        Ct = chol_solve(L, np.ascontiguousarray(D[k + 1].T))      # P^-1 D^T = C^T (P symmetric)
        C = np.ascontiguousarray(Ct.T)
        dP = P_post[k + 1] - P_prior[k + 1]
        Ps = P_post[k] + C @ dP @ Ct
        P_post[k] = 0.5 * (Ps + Ps.T)
        D[k + 1] = C
    return bad


def rts_smooth(store: ForwardStore, model: SmoothableModel) -> Smoothed:
    """Smooth the stored forward run (see the module docstring); empties the store.  The
    model's ``rts_means`` runs the mean recursion (compiled on the INS)."""
    if store.n == 0:
        raise ValueError("rts_smooth: the store is empty")
    a = store.arrays()
    return smooth_arrays(a, model)


def smooth_arrays(a: dict[str, np.ndarray], model: SmoothableModel) -> Smoothed:
    """:func:`rts_smooth` on the packed nodes of :meth:`ForwardStore.arrays` (``a["P_post"]``
    becomes the smoothed covariance and ``a["D"]`` the gains, in place)."""
    m = a["t"].shape[0]
    reset = a["reset"]
    bad = _backward_covariances(a["P_post"], a["P_prior"], a["D"], reset, m)
    gains = a["D"]
    xs = model.rts_means(a["x_post"], a["x_prior"], gains, reset)
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(a["P_post"]))):
        raise FilterDivergedError("RTS smoother: the smoothed state became non-finite")
    return Smoothed(a["t"], xs, a["P_post"], gains, int(reset[1:].sum()), int(bad))


__all__ = ["ForwardStore", "Smoothed", "rts_smooth"]
