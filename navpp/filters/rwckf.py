"""Randomly weighted cubature Kalman filter, RWCKF (paper 001 eqs 22-32).

The CKF with its common weight ``1/(2n)`` replaced, at each measurement epoch, by random
weights ``beta ~ Dirichlet(1, ..., 1)`` (eq 23).  One weight vector enters the predicted state
and covariance (eqs 24-25) and the predicted measurement, its covariance and the
cross-covariance (eqs 26-28); gain, update and covariance are eqs 29-32.

Readings (docs/algorithms.md, "Randomly weighted CKF"):

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
  ``candidates`` defaults to 1 (the uniform vector against one Dirichlet draw): on the
  simulated INS drives more candidates measure worse (issue 20: 1 / 4 / 16 / 64 candidates,
  docs/papers.md gives the figures), because the likelihood selection fits the mean to the
  measurement noise of the epoch, more closely the more vectors it may choose from; 16 was the
  default before.
- ``covariance`` says where the random weights enter the covariances.  ``"random"`` is the
  paper's eqs 25, 27, 28.  On the 15-state INS this collapses the covariance: a Dirichlet
  weight rescales each cubature direction by ``n (beta_i + beta_n+i)``, a factor with mean 1
  but mean logarithm ``log n + psi(2) - psi(2n)`` (-0.254 for the INS's n = 15, -0.207 for
  n = 4; ``psi(2) - log 2 = -0.270`` as n grows), so directions that the measurements do not
  refill (the biases) shrink geometrically until the filter rejects every fix.  ``"uniform"``
  (navpp's default) lets the weights move the means (eqs 24, 26: the residual reduction of
  eqs 33-37 is about the means) and keeps the covariances at their cubature values: uniform
  weights, centred on the uniform (CKF) means, so the joint covariance of state and measurement
  is the CKF's and the update can never make P indefinite.  (Centring them on the
  beta-weighted means would add the outer product of the mean shift to Pzz and Pxz but not to
  P; against a near-perfect measurement such as a ZUPT that makes ``P - K S K^T`` indefinite.)

Because selection looks at the measurement, RWCKF's NIS/NEES are optimistic by construction.
Randomness comes from one seeded generator (``seed``), so runs repeat exactly.

The selection state (the kept time-update points, the weights chosen, the counts) lives in the
filter's adaptation, :class:`DirichletWeighting`; the time update's points have to be kept
there because the next measurement update receives only the prior.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .adaptation import Adaptation
from .base import register
from .linalg import nis_and_logdet, symmetrise
from .protocols import Interval, Measurement, Model
from .rules import CubatureRule, DirichletWeights
from .sigma import PropagatedPoints, SigmaPointFilter, combine_points, factor, measurement_moments
from .states import GaussianState, MeasurementPrediction, Prediction, Update

SELECT = ("likelihood", "residual", "none")
COVARIANCE = ("uniform", "random")
WEIGHTS = ("dirichlet", "uniform")


@dataclass(frozen=True)
class RWCKFOptions:
    """``[filter.rwckf]``: weight selection rule, number of Dirichlet candidates (default 1,
    besides the uniform vector), seed, where the random weights enter the covariances, and
    ``weights = "uniform"`` (the CKF exactly)."""

    select: str = "likelihood"
    candidates: int = 1
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


Weights = np.ndarray | None          # an epoch's weight vector (2n,); None: the uniform (CKF) weights


class DirichletWeighting(Adaptation):
    """The RWCKF's weight selection state: the last time update's points, the weights chosen.

    Attributes
    ----------
    chosen_uniform : epochs where the uniform vector won.
    last_weights : (2n,) the weights chosen at the last epoch (None before).
    epochs : measurement epochs so far.
    """

    def __init__(self, options: RWCKFOptions) -> None:
        self.o = options
        self.dirichlet = DirichletWeights()
        self._kept: tuple[GaussianState, PropagatedPoints] | None = None
        self.chosen_uniform = 0
        self.last_weights: np.ndarray | None = None
        self.epochs = 0

    def keep(self, prior: GaussianState, points: PropagatedPoints) -> None:
        """The points of the time update that produced ``prior``."""
        self._kept = (prior, points)

    def points_for(self, prior: GaussianState) -> PropagatedPoints | None:
        """The kept points when ``prior`` is the kept time update's output, else None."""
        return self._kept[1] if self._kept is not None and self._kept[0] is prior else None

    def candidates(self, rng: np.random.Generator, m: int) -> list[Weights]:
        """The epoch's candidate weight vectors over ``m`` points (drawn from ``rng``)."""
        if self.o.weights == "uniform":
            return [None]
        if self.o.select == "none":
            return [self.dirichlet.draw(rng, m)]
        return [None, *self.dirichlet.draw(rng, m, self.o.candidates)]

    def chose(self, beta: Weights, m: int) -> None:
        """Record the epoch's choice; the kept points are used up."""
        self._kept = None
        self.last_weights = np.full(m, 1.0 / m) if beta is None else np.asarray(beta, dtype=float)
        self.epochs += 1
        self.chosen_uniform += beta is None

    def report(self) -> dict[str, np.ndarray]:
        """The weights chosen at the last epoch (``weights``, (2n,), points ``+sqrt(n) S e_i``
        first, then the minus points) and the fraction of epochs so far where the uniform (CKF)
        weights won the selection."""
        out = {"uniform_chosen_fraction": np.array([self.chosen_uniform / max(self.epochs, 1)])}
        if self.last_weights is not None:
            out["weights"] = self.last_weights.copy()
        return out


@register("rwckf")
class RWCKF(SigmaPointFilter):
    paper = "paper 001 eqs 22-32"
    summary = ("Randomly weighted CKF: Dirichlet weights on the cubature points, chosen per epoch "
               "by the innovation likelihood.")
    Options = RWCKFOptions
    oracle_options: ClassVar[dict[str, Any]] = {"weights": "uniform"}
    random_mean: ClassVar[bool] = True      # eqs 24 and 26 (see the module docstring)
    adapter: DirichletWeighting

    def make_rule(self) -> CubatureRule:
        return CubatureRule()

    def make_adapter(self) -> DirichletWeighting:
        return DirichletWeighting(self.options)

    # time update: the CKF's (uniform weights); its points are kept for the epoch's weights
    def time_update(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        points = self.propagate(state, model, interval)
        out = self.combine(points, model, interval[1])
        self.adapter.keep(out.state, points)
        return out

    # measurement update: choose the epoch's weight vector, then the shared template ---------
    def update(self, state: GaussianState, model: Model, meas: Measurement) -> Update:
        m = 2 * state.P.shape[0]
        cands = self.adapter.candidates(self.rng, m)
        best = cands[0]
        if len(cands) > 1:
            betas = np.vstack([np.full(m, 1.0 / m) if b is None else b for b in cands])
            try:
                scores = self._scores(state, model, meas, betas)
            except np.linalg.LinAlgError:
                scores = np.array([self._score_one(b, state, model, meas) for b in cands])
            scores = np.where(np.isfinite(scores), scores, np.inf)
            best = cands[int(np.argmin(scores))]
        prior = self._prior_with(best, state, model)
        self.adapter.chose(best, m)

        def predictor(s: GaussianState) -> MeasurementPrediction:
            return self.measure(s, meas, best)
        return self.apply_measurement(prior, model, meas, predictor)

    def _weights(self, beta: Weights, wm: np.ndarray,
                 wc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Mean weights, covariance weights and the centre of the covariances (None: the mean)
        of a measurement prediction under the epoch's weights ``beta``."""
        if self.options.covariance == "random":
            return (wm, wc, None) if beta is None else (beta, beta, None)
        return (wm if beta is None else beta), wc, wc

    def measure(self, state: GaussianState, meas: Measurement, beta: Weights) -> MeasurementPrediction:
        """The cubature measurement prediction of ``meas`` about ``state`` under weights ``beta``."""
        S = factor(state.P, state.t, self.name, self)
        dX, wm0, wc0 = self.rule.points(S)
        wm, wc, centre = self._weights(beta, wm0, wc0)
        Z = meas.predict_points(state.x, dX)                          # h(x ⊞ dX_i) ⊟ h(x)
        return measurement_moments(Z, dX, meas.innovation_at(state.x), wm, wc, centre)

    def _prior_with(self, beta: Weights, state: GaussianState, model: Model) -> GaussianState:
        """The epoch's prior under weights ``beta`` (the kept time-update points), or ``state``."""
        p = self.adapter.points_for(state)
        if beta is None or p is None:
            return state
        if self.options.covariance == "random":
            return combine_points(model, state.t, p.x_ref, p.dY, beta, beta, p.Q)
        return combine_points(model, state.t, p.x_ref, p.dY, beta, p.wc, p.Q, centre=p.wc)

    def _score(self, pred: MeasurementPrediction, R: np.ndarray) -> float:
        """Selection score: ``|nu|^2`` (residual) or ``nu' S^-1 nu + log det S`` (likelihood)."""
        if self.options.select == "residual":
            return float(pred.nu @ pred.nu)
        nis, logdet, ok = nis_and_logdet(symmetrise(pred.Pzz + R), pred.nu)
        if not ok:
            raise np.linalg.LinAlgError("the candidate's innovation covariance is not positive definite")
        return nis + logdet

    def _scores(self, state: GaussianState, model: Model, meas: Measurement, betas: np.ndarray) -> np.ndarray:
        """Selection score of every candidate weight vector (rows of ``betas``, (C, 2n)), with
        one call of the measurement model for all candidates' points.

        Candidate c's prior is ``x_ref ⊞ M_c`` (``M_c = beta_c dY``) with its covariance; its
        cubature points are taken relative to ``x_ref`` as ``x_ref ⊞ (M_c + dX)``, which equals
        ``(x_ref ⊞ M_c) ⊞ dX`` except for the second-order composition of attitude errors.  The
        chosen candidate's update itself goes through the exact template path.
        """
        C, m = betas.shape
        p = self.adapter.points_for(state)
        if p is not None:
            x_ref, M = p.x_ref, betas @ p.dY                          # (C, n) candidate means about x_ref
        else:                                         # no kept time update: weights on the measurement only
            x_ref, M = state.x, np.zeros((C, state.P.shape[0]))
        points: list[np.ndarray] = []
        for c in range(C):
            if p is not None and self.options.covariance == "random":
                P = combine_points(model, state.t, x_ref, p.dY, betas[c], betas[c], p.Q).P
            elif c == 0:
                P = state.P                                           # the CKF covariance, whatever the mean
            else:
                points.append(points[0])
                continue
            dX, _, wc = self.rule.points(np.linalg.cholesky(symmetrise(P)))
            points.append(dX)
        Zall = meas.predict_points(x_ref, np.concatenate([M, *(M[c] + points[c] for c in range(C))]))
        nu_ref = meas.innovation_at(x_ref)
        scores = np.empty(C)
        for c in range(C):
            Z = Zall[C + c * m:C + (c + 1) * m] - Zall[c]
            wm, wcc, centre = self._weights(betas[c], wc, wc)
            pred = measurement_moments(Z, points[c], nu_ref - Zall[c], wm, wcc, centre)
            scores[c] = self._score(pred, meas.R)
        return scores

    def _score_one(self, beta: Weights, state: GaussianState, model: Model, meas: Measurement) -> float:
        """One candidate's score through the template path (used when a candidate's covariance
        cannot be factored in :meth:`_scores`: a candidate that breaks definiteness is not a
        candidate)."""
        try:
            prior = self._prior_with(beta, state, model)
            return self._score(self.measure(prior, meas, beta), meas.R)
        except (np.linalg.LinAlgError, FloatingPointError):
            return np.inf
