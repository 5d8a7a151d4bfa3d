"""Randomly weighted cubature Kalman filter, RWCKF (paper 001 eqs 22-32).

The CKF with its common weight ``1/(2n)`` replaced, at each measurement epoch, by random
weights ``beta ~ Dirichlet(1, ..., 1)`` (eq 23).  One weight vector enters the predicted state
and covariance (eqs 24-25) and the predicted measurement, its covariance and the
cross-covariance (eqs 26-28); gain, update and covariance are eqs 29-32.

Readings (ALGORITHMS.md, "Randomly weighted CKF"):

- The measurement update redraws points from ``P*-`` around ``x*-`` (eq 10) and every statistic
  is centred on a weighted mean (see ``covariance``), so with uniform weights RWCKF is exactly
  the CKF (``weights = "uniform"``, the oracle option).
- Time updates that do not end at a measurement (outages, the engine's coasting steps) use
  uniform weights; the last time update before a measurement keeps its propagated points so
  that the epoch's weight vector can be applied to it.
- The paper "adaptively selects" the weights from the prediction residuals without a rule.
  ``select = "likelihood"`` (default): draw ``candidates`` Dirichlet vectors plus the uniform
  vector and keep the one maximising the Gaussian likelihood of the innovation
  (minimising ``d' Pzz*^-1 d + log det Pzz*``); ``"residual"``: the smallest ``|d|`` (the
  paper's words, literally); ``"none"``: one Dirichlet draw per epoch.
- ``covariance`` says where the random weights enter the covariances.  ``"random"`` is the
  paper's eqs 25, 27, 28.  On the 15-state INS this collapses the covariance: a Dirichlet
  weight rescales each cubature direction by ``n (beta_i + beta_n+i)``, a factor with mean 1
  but mean logarithm ``psi(2) - log 2 = -0.27``, so directions that the measurements do not
  refill (the biases) shrink geometrically until the filter rejects every fix.  ``"uniform"``
  (navpp's default) lets the weights move the means (eqs 24, 26: the residual reduction of
  eqs 33-37 is about the means) and keeps the covariances at their cubature values: uniform
  weights, centred on the uniform (CKF) means, so the joint covariance of state and measurement
  is the CKF's and the update can never make P indefinite.  (Centring them on the
  beta-weighted means, as navpp did first, adds the outer product of the mean shift to Pzz and
  Pxz but not to P; against a near-perfect measurement such as a ZUPT that made
  ``P - K S K^T`` indefinite: a -6e-3 m^2/s^2 velocity variance at the first stop of the
  sample drive.)

Because selection looks at the measurement, RWCKF's NIS/NEES are optimistic by construction.
Randomness comes from one seeded generator (``seed``), so runs repeat exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .base import GaussianState, MeasurementPrediction, Update, register, symmetrise
from .rules import CubatureRule, DirichletWeights
from .sigma import SigmaPointFilter, combine_points

SELECT = ("likelihood", "residual", "none")
COVARIANCE = ("uniform", "random")
WEIGHTS = ("dirichlet", "uniform")


@dataclass(frozen=True)
class RWCKFOptions:
    """``[filter.rwckf]``: weight selection rule, number of candidates, seed, where the random
    weights enter the covariances, and ``weights = "uniform"`` (the CKF exactly)."""

    select: str = "likelihood"
    candidates: int = 16
    seed: int = 0
    covariance: str = "uniform"
    weights: str = "dirichlet"

    def __post_init__(self) -> None:
        if self.select not in SELECT:
            raise ValueError(f"select must be one of {', '.join(SELECT)}; got {self.select!r}")
        if self.covariance not in COVARIANCE:
            raise ValueError(f"covariance must be one of {', '.join(COVARIANCE)}; got {self.covariance!r}")
        if self.weights not in WEIGHTS:
            raise ValueError(f"weights must be one of {', '.join(WEIGHTS)}; got {self.weights!r}")
        if isinstance(self.candidates, bool) or int(self.candidates) != self.candidates or self.candidates < 1:
            raise ValueError(f"candidates must be an integer >= 1, got {self.candidates!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")


@register("rwckf")
class RWCKF(SigmaPointFilter):
    paper = "paper 001 eqs 22-32"
    summary = ("Randomly weighted CKF: Dirichlet weights on the cubature points, chosen per epoch "
               "by the innovation likelihood.")
    Options = RWCKFOptions
    oracle_options: ClassVar[dict[str, Any]] = {"weights": "uniform"}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._dirichlet = DirichletWeights()
        self._beta: np.ndarray | None = None           # the epoch's weights (None: uniform)
        self._pending: tuple | None = None             # (prior state, f(x), dY, Q) of the last time update
        self.chosen_uniform = 0                        # epochs where the uniform vector won
        self.last_weights: np.ndarray | None = None    # the weights chosen at the last epoch
        self.epochs = 0

    def rule(self) -> CubatureRule:
        return CubatureRule()

    def weights_for(self, wm: np.ndarray, wc: np.ndarray, *, measurement: bool):
        if not measurement or self._beta is None:
            return wm, wc
        return self._beta, (self._beta if self.options.covariance == "random" else wc)

    def covariance_centre(self, wm: np.ndarray, wc: np.ndarray) -> np.ndarray:
        return wm if self.options.covariance == "random" else wc

    # time update: the template's (uniform weights); its points are kept for the epoch's weights
    def after_predict(self, prior: GaussianState, x_ref: np.ndarray, dY: np.ndarray, Q: np.ndarray,
                      wc: np.ndarray) -> None:
        self._pending = (prior, x_ref, dY, Q, wc)

    # measurement update: choose the epoch's weight vector, then the shared template ---------
    def _candidates(self, m: int) -> list[np.ndarray | None]:
        if self.options.weights == "uniform":
            return [None]
        if self.options.select == "none":
            return [self._dirichlet.draw(self.rng, m)]
        return [None, *self._dirichlet.draw(self.rng, m, self.options.candidates)]

    def _prior_with(self, beta: np.ndarray | None, state: GaussianState, model) -> GaussianState:
        """The epoch's prior under weights ``beta`` (the kept time-update points), or ``state``."""
        pending = self._pending
        if beta is None or pending is None or pending[0] is not state:
            return state
        _, x_ref, dY, Q, wc = pending
        if self.options.covariance == "random":
            return combine_points(model, state.t, x_ref, dY, beta, beta, Q)
        return combine_points(model, state.t, x_ref, dY, beta, wc, Q, centre=wc)

    def _score(self, pred: MeasurementPrediction, R: np.ndarray) -> float:
        if self.options.select == "residual":
            return float(pred.nu @ pred.nu)
        L = np.linalg.cholesky(symmetrise(pred.Pzz + R))
        w = np.linalg.solve(L, pred.nu)
        return float(w @ w + 2.0 * np.log(np.diagonal(L)).sum())

    def _scores(self, state: GaussianState, model, meas, betas: np.ndarray) -> np.ndarray:
        """Selection score of every candidate weight vector (rows of ``betas``, (C, 2n)), all
        candidates at once: one batched factorisation and one call of the measurement model.

        Candidate c's prior is ``x_ref ⊞ M_c`` (``M_c = beta_c dY``) with its covariance; its
        cubature points are taken relative to ``x_ref`` as ``x_ref ⊞ (M_c + dX)``, which equals
        ``(x_ref ⊞ M_c) ⊞ dX`` except for the second-order composition of attitude errors.  The
        chosen candidate's update itself goes through the exact template path.
        """
        n = state.P.shape[0]
        m = 2 * n
        C = betas.shape[0]
        random_cov = self.options.covariance == "random"
        pending = self._pending
        if pending is not None and pending[0] is state:
            _, x_ref, dY, Q, _wc = pending
            M = betas @ dY                                            # (C, n) candidate means about x_ref
            if random_cov:
                dev = dY[None, :, :] - M[:, None, :]
                P = np.einsum("ci,cij,cik->cjk", betas, dev, dev) + Q
            else:                                                     # the CKF covariance, whatever the mean
                P = np.broadcast_to(state.P, (C, n, n))
        else:                                         # no kept time update: weights on the measurement only
            x_ref, M = state.x, np.zeros((C, n))
            P = np.broadcast_to(state.P, (C, n, n))
        S = np.linalg.cholesky(0.5 * (P + np.swapaxes(P, 1, 2)))       # (C, n, n)
        cols = np.sqrt(n) * np.swapaxes(S, 1, 2)                       # row i = sqrt(n) S e_i
        dX = np.concatenate([cols, -cols], axis=1)                     # (C, m, n)
        pts = np.concatenate([M, (M[:, None, :] + dX).reshape(C * m, n)])
        Zall = meas.predict_points(x_ref, pts)
        Z0, Z = Zall[:C], Zall[C:].reshape(C, m, -1) - Zall[:C, None, :]
        z_hat = np.einsum("ci,cip->cp", betas, Z)
        nu = meas.innovation_at(x_ref)[None, :] - Z0 - z_hat
        if self.options.select == "residual":
            return np.einsum("cp,cp->c", nu, nu)
        wz = betas if random_cov else np.full((C, m), 1.0 / m)
        dz = Z - (z_hat if random_cov else np.einsum("ci,cip->cp", wz, Z))[:, None, :]
        Pzz = np.einsum("ci,cip,ciq->cpq", wz, dz, dz) + self.measurement_noise(meas, None)
        L = np.linalg.cholesky(0.5 * (Pzz + np.swapaxes(Pzz, 1, 2)))
        w = np.linalg.solve(L, nu[:, :, None])[:, :, 0]
        return np.einsum("cp,cp->c", w, w) + 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)

    def update(self, state: GaussianState, model, meas) -> Update:
        m = 2 * state.P.shape[0]
        cands = self._candidates(m)
        best = cands[0]
        if len(cands) > 1:
            betas = np.vstack([np.full(m, 1.0 / m) if b is None else b for b in cands])
            try:
                scores = self._scores(state, model, meas, betas)
            except np.linalg.LinAlgError:
                scores = np.array([self._score_one(b, state, model, meas) for b in cands])
            scores = np.where(np.isfinite(scores), scores, np.inf)
            best = cands[int(np.argmin(scores))]
        best_state = self._prior_with(best, state, model)
        self._beta = best
        self._pending = None
        self.last_weights = np.full(m, 1.0 / m) if best is None else np.asarray(best, dtype=float)
        self.epochs += 1
        self.chosen_uniform += best is None
        try:
            return super().update(best_state, model, meas)
        finally:
            self._beta = None

    def _score_one(self, beta, state: GaussianState, model, meas) -> float:
        """One candidate's score through the template path (used when a batched factorisation
        fails: a candidate that breaks definiteness is not a candidate)."""
        self._beta = beta
        try:
            prior = self._prior_with(beta, state, model)
            pred = self.adjust_prediction(self.predict_measurement(prior, model, meas))
            return self._score(pred, self.measurement_noise(meas, pred))
        except (np.linalg.LinAlgError, FloatingPointError):
            return np.inf
        finally:
            self._beta = None

    def noise_report(self) -> dict[str, np.ndarray]:
        """The weights chosen at the last epoch (``weights``, (2n,), points ``+sqrt(n) S e_i``
        first, then the minus points) and the fraction of epochs so far where the uniform (CKF)
        weights won the selection."""
        out = {"uniform_chosen_fraction": np.array([self.chosen_uniform / max(self.epochs, 1)])}
        if self.last_weights is not None:
            out["weights"] = self.last_weights.copy()
        return out
