"""Sigma-point filters: the template shared by the CKF, UKF and their adaptive variants.

Points are drawn in the model's error space around the mean (``x ⊞ dX_i``), pushed through
the model itself (on the INS: every point through the real strapdown over the IMU samples of
the interval, in one compiled call), brought back to error space about the propagated
nominal, and recombined.  Covariances come from centred deviations, never from raw second
moments (docs/algorithms.md).  A rule (:mod:`navpp.filters.rules`) decides the points and weights.

References: paper 001 eqs 3-18, paper 003 eqs 19-34 (CKF); Wan & van der Merwe (2000) (UKF).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..errors import FilterDivergedError
from .base import Filter
from .linalg import symmetrise
from .protocols import Interval, Measurement, Model
from .rules import SigmaRule
from .states import GaussianState, MeasurementPrediction, Prediction


class RepairCounter(Protocol):
    """A filter that counts the covariances it repaired."""

    repairs: int


def factor(P: np.ndarray, t: float, name: str, filt: RepairCounter | None = None) -> np.ndarray:
    """Lower Cholesky factor of P; a P that lost positive definiteness (random weights can do
    that) is repaired by clipping its eigenvalues, and the repair is counted on ``filt``
    (without one, such a P is a divergence)."""
    P = symmetrise(P)
    if not np.all(np.isfinite(P)):
        raise FilterDivergedError.in_filter(name, f"covariance is not finite at t={t:.3f} s (not positive definite)")
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        if filt is None:
            raise FilterDivergedError.in_filter(name, f"covariance is not positive definite at t={t:.3f} s") from None
    vals, vecs = np.linalg.eigh(P)
    floor = max(float(vals.max()), 1e-300) * 1e-12
    filt.repairs += 1
    return np.linalg.cholesky(symmetrise((vecs * np.maximum(vals, floor)) @ vecs.T))


def weighted_cov(wc: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``sum_i wc_i A_i B_i^T`` for centred deviation rows ``A`` (p, k), ``B`` (p, l)."""
    out: np.ndarray = (A * wc[:, None]).T @ B
    return out


def combine_points(model: Model, t: float, x_ref: np.ndarray, dY: np.ndarray, wm: np.ndarray, wc: np.ndarray,
                   Q: np.ndarray, centre: np.ndarray | None = None) -> GaussianState:
    """The Gaussian at ``t`` of propagated error points ``dY`` about ``x_ref``: mean ``x_ref ⊞
    wm dY``, covariance of the deviations weighted by ``wc``, plus ``Q``.  The deviations are
    taken from that mean, or from ``centre @ dY`` when weights ``centre`` are given (a filter
    whose mean weights differ from its covariance weights, RWCKF)."""
    mean = wm @ dY
    dev = dY - (mean if centre is None else centre @ dY)
    return GaussianState(t, model.plus(x_ref, mean), symmetrise(weighted_cov(wc, dev, dev) + Q))


def measurement_moments(Z: np.ndarray, dX: np.ndarray, innovation: np.ndarray, wm: np.ndarray,
                        wc: np.ndarray, centre: np.ndarray | None = None) -> MeasurementPrediction:
    """Predicted-measurement moments from the images ``Z`` (p, m) of error points ``dX``
    (p, n) about a reference whose innovation is ``innovation`` (m,): ``nu = innovation -
    wm Z``; ``Pzz`` and ``Pxz`` weighted by ``wc``, centred on the ``wm`` mean, or on the
    ``centre`` mean when given."""
    z_mean = wm @ Z
    cw = wm if centre is None else centre
    dz = Z - (z_mean if centre is None else centre @ Z)
    nu = innovation - z_mean
    return MeasurementPrediction(nu, symmetrise(weighted_cov(wc, dz, dz)), weighted_cov(wc, dX - cw @ dX, dz), None)


@dataclass(frozen=True)
class PropagatedPoints:
    """The points of one sigma-point time update: error points ``dX`` (p, n) about the start,
    their images ``dY`` (p, n) about the propagated nominal ``x_ref``, the weights ``wm``,
    ``wc`` (p,) and the process noise ``Q`` (n, n) added."""

    dX: np.ndarray
    dY: np.ndarray
    x_ref: np.ndarray
    wm: np.ndarray
    wc: np.ndarray
    Q: np.ndarray


class SigmaPointFilter(Filter):
    """Template: a subclass says its rule (:meth:`make_rule`) and, if adaptive, its adaptation.

    Attributes: ``rule`` (from :meth:`make_rule`); ``repairs``, covariances repaired by
    eigenvalue clipping (counted, reported).
    """

    repairs = 0

    def __init__(self, options: Any = None, *, gate_probability: float = 0.0,
                 reanchor_after_s: float = 10.0, rng: np.random.Generator | None = None) -> None:
        super().__init__(options, gate_probability=gate_probability, reanchor_after_s=reanchor_after_s, rng=rng)
        self.rule = self.make_rule()

    def make_rule(self) -> SigmaRule:
        """The rule that places the points and weights them."""
        raise NotImplementedError

    def propagate(self, state: GaussianState, model: Model, interval: Interval) -> PropagatedPoints:
        """The rule's points about ``state`` through the model over ``interval``."""
        S = factor(state.P, state.t, self.name, self)
        dX, wm, wc = self.rule.points(S)
        x_ref, dY = model.propagate_points(state.x, dX, interval)    # f(x ⊞ dX_i) ⊟ f(x)
        Q = self.adapter.process_noise(model, state.x, interval)
        return PropagatedPoints(dX, dY, x_ref, wm, wc, Q)

    def time_update(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        return self.combine(self.propagate(state, model, interval), model, interval[1])

    def combine(self, p: PropagatedPoints, model: Model, t: float) -> Prediction:
        """The prior at ``t`` from propagated points, with the smoother's cross-covariance
        ``E[dx_k dx_k+1^T]`` from the centred deviations of the points and their images."""
        out = combine_points(model, t, p.x_ref, p.dY, p.wm, p.wc, p.Q)
        cross = weighted_cov(p.wc, p.dX - p.wm @ p.dX, p.dY - p.wm @ p.dY)
        return Prediction(out, cross, p.x_ref)

    def predict_measurement(self, state: GaussianState, model: Model, meas: Measurement) -> MeasurementPrediction:
        S = factor(state.P, state.t, self.name, self)
        dX, wm, wc = self.rule.points(S)
        Z = meas.predict_points(state.x, dX)                          # h(x ⊞ dX_i) ⊟ h(x)
        return measurement_moments(Z, dX, meas.innovation_at(state.x), wm, wc)
