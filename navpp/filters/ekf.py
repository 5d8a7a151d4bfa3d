"""Extended Kalman filter: the closed-loop error-state filter of the loosely coupled INS.

After each update the estimated error is fed back into the nominal state (``x ⊞ K nu``) and
the error mean is reset to zero, so the filter never carries an error estimate between epochs.

References: paper 002 section 2 (15-state loosely coupled SINS/GPS model, eqs 1-3);
Groves (2013) ch. 14.
"""

from __future__ import annotations

from .base import Filter, register
from .linalg import linear_moments, propagated_covariance
from .protocols import Interval, Measurement, Model
from .states import GaussianState, MeasurementPrediction, Prediction


@register("ekf")
class EKF(Filter):
    paper = "paper 002 section 2, eqs 1-3"
    summary = "Closed-loop error-state extended Kalman filter (the reference filter)."

    def time_update(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        x, Phi, Qd = model.transition(state.x, interval)
        P, PPhit = propagated_covariance(state.P, Phi, Qd)    # P- = Phi P Phi^T + Qd; P Phi^T
        return Prediction(GaussianState(interval[1], x, P), PPhit, x)

    def predict_measurement(self, state: GaussianState, model: Model, meas: Measurement) -> MeasurementPrediction:
        H = meas.jacobian(state.x)
        PHt, Pzz = linear_moments(state.P, H)
        return MeasurementPrediction(meas.innovation_at(state.x), Pzz, PHt, H)
