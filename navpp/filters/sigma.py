"""Sigma-point filters: the template shared by the CKF, UKF and their adaptive variants.

Points are drawn in the model's error space around the mean (``x ⊞ dX_i``), pushed through
the model itself (on the INS: every point through the real strapdown over the IMU samples of
the interval, in one compiled call), brought back to error space about the propagated
nominal, and recombined.  Covariances come from centred deviations, never from raw second
moments (ALGORITHMS.md).  A rule (:mod:`navpp.filters.rules`) decides the points and weights.

References: paper 001 eqs 3-18, paper 003 eqs 19-34 (CKF); Wan & van der Merwe (2000) (UKF).
"""

from __future__ import annotations

import numpy as np

from ..errors import FilterDivergedError
from .base import Filter, GaussianState, MeasurementPrediction, Prediction, symmetrise


def _factor(P: np.ndarray, t: float, name: str, filt: SigmaPointFilter | None = None) -> np.ndarray:
    """Lower Cholesky factor of P; a P that lost positive definiteness (random weights can do
    that) is repaired by clipping its eigenvalues, and the repair is counted on ``filt``."""
    P = symmetrise(P)
    if not np.all(np.isfinite(P)):
        raise FilterDivergedError(f"{name}: covariance is not finite at t={t:.3f} s (not positive definite)")
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        if filt is None:
            raise FilterDivergedError(f"{name}: covariance is not positive definite at t={t:.3f} s") from None
    vals, vecs = np.linalg.eigh(P)
    floor = max(float(vals.max()), 1e-300) * 1e-12
    filt.repairs += 1
    return np.linalg.cholesky(symmetrise((vecs * np.maximum(vals, floor)) @ vecs.T))


def _weighted_cov(wc: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``sum_i wc_i A_i B_i^T`` for centred deviation rows ``A`` (m, p), ``B`` (m, q)."""
    return (A * wc[:, None]).T @ B


def combine_points(model, t: float, x_ref: np.ndarray, dY: np.ndarray, wm: np.ndarray, wc: np.ndarray,
                   Q: np.ndarray, centre: np.ndarray | None = None) -> GaussianState:
    """The Gaussian at ``t`` of propagated error points ``dY`` about ``x_ref``: mean ``x_ref ⊞
    wm dY``, covariance of the deviations weighted by ``wc``, plus ``Q``.  The deviations are
    taken from that mean, or from ``centre @ dY`` when weights ``centre`` are given (a filter
    whose mean weights differ from its covariance weights, RWCKF)."""
    mean = wm @ dY
    dev = dY - (mean if centre is None else centre @ dY)
    return GaussianState(t, model.plus(x_ref, mean), symmetrise(_weighted_cov(wc, dev, dev) + Q))


class SigmaPointFilter(Filter):
    """Template: subclasses provide :meth:`rule` (and may override the hooks of :class:`Filter`)."""

    repairs = 0      # covariances repaired by eigenvalue clipping (counted, reported)

    def rule(self):
        raise NotImplementedError

    def weights_for(self, wm: np.ndarray, wc: np.ndarray, *, measurement: bool) -> tuple[np.ndarray, np.ndarray]:
        """Hook: the weights actually used (random-weighting filters override)."""
        return wm, wc

    def covariance_centre(self, wm: np.ndarray, wc: np.ndarray) -> np.ndarray:
        """Hook: the weights of the mean the measurement covariances are centred on: the mean
        weights (every rule here); RWCKF with CKF covariances centres them on the CKF mean."""
        return wm

    def predict(self, state: GaussianState, model, interval: tuple[float, float]) -> Prediction:
        S = _factor(state.P, state.t, self.name, self)
        dX, wm, wc = self.rule().points(S)
        wm, wc = self.weights_for(wm, wc, measurement=False)
        x_ref, dY = model.propagate_points(state.x, dX, interval)    # f(x ⊞ dX_i) ⊟ f(x)
        Q = self.process_noise(model, state.x, interval)
        out = combine_points(model, interval[1], x_ref, dY, wm, wc, Q)
        # for the smoother: E[dx_k dx_k+1^T] from the centred deviations of the points and images
        cross = _weighted_cov(wc, dX - wm @ dX, dY - wm @ dY)
        self.after_predict(out, x_ref, dY, Q, wc)
        return Prediction(out, cross, x_ref)

    def after_predict(self, prior: GaussianState, x_ref: np.ndarray, dY: np.ndarray, Q: np.ndarray,
                      wc: np.ndarray) -> None:
        """Hook: the propagated points of a time update (RWCKF re-weights them at the next fix)."""

    def predict_measurement(self, state: GaussianState, model, meas) -> MeasurementPrediction:
        S = _factor(state.P, state.t, self.name, self)
        dX, wm, wc = self.rule().points(S)
        wm, wc = self.weights_for(wm, wc, measurement=True)
        Z = meas.predict_points(state.x, dX)                          # h(x ⊞ dX_i) ⊟ h(x)
        z_mean = wm @ Z
        cw = self.covariance_centre(wm, wc)
        dz = Z - (z_mean if cw is wm else cw @ Z)
        nu = meas.innovation_at(state.x) - z_mean
        return MeasurementPrediction(nu, symmetrise(_weighted_cov(wc, dz, dz)),
                                     _weighted_cov(wc, dX - cw @ dX, dz), None)
