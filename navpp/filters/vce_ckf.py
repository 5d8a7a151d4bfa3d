"""VCE-adaptive cubature Kalman filter (paper 003): the CKF with a Helmert VCE noise adapter.

The cubature rule and sigma-point template of the CKF; the process noise of every time update
is the model's noise groups scaled by the adapter's factors, the measurement noise is the
given R scaled per axis, and every update that passed the gate feeds the adapter
(:mod:`navpp.filters.vce`).  With ``adapt = "none"`` it is the CKF exactly.

References: paper 003 eqs 6-18, 35-39 (VCE), 19-34 (CKF); ALGORITHMS.md.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from .base import GaussianState, Innovation, MeasurementPrediction, Prediction, Update, register
from .rules import CubatureRule
from .sigma import SigmaPointFilter
from .vce import HelmertVCE, VCEOptions


@register("vce-ckf")
class VCECKF(SigmaPointFilter):
    """CKF + Helmert VCE of the process-noise groups and the measurement noise per axis.

    ``noise_report()``: ``q_factor`` (G,) in the order of :attr:`q_group_names` and
    ``r_factor`` (m,), both relative to the configured noise (the R used is recorded from the
    :class:`~navpp.filters.base.Innovation`).
    """

    paper = "paper 003 eqs 6-18, 35-39 (VCE) with eqs 19-34 (CKF)"
    summary = "CKF with Helmert variance component estimation of the process-noise groups and R."
    Options = VCEOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": "none"}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.adapter = HelmertVCE(self.options)
        self._prior_P: np.ndarray | None = None

    @property
    def q_group_names(self) -> list[str]:
        """Names of the process-noise groups, in the order of ``noise_report()["q_factor"]``."""
        return list(self.adapter.q_group_names or [])

    def rule(self) -> CubatureRule:
        return CubatureRule()

    def process_noise(self, model, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        return self.adapter.process_noise(model, x, interval)

    def predict(self, state: GaussianState, model, interval: tuple[float, float]) -> Prediction:
        out = super().predict(state, model, interval)
        self.adapter.propagate(state.P, out.cross_cov)
        return out

    def update(self, state: GaussianState, model, meas) -> Update:
        out = super().update(state, model, meas)
        inn = out.innovation
        if inn.accepted:                      # every applied update shrinks the groups' shares
            self.adapter.corrected(state.P, inn.Pxz, inn.S, reset=inn.forced)
        return out

    def predict_measurement(self, state: GaussianState, model, meas) -> MeasurementPrediction:
        self._prior_P = state.P               # P⁻ of this update, for A = (P⁻)⁻¹
        return super().predict_measurement(state, model, meas)

    def measurement_noise(self, meas, pred: MeasurementPrediction) -> np.ndarray:
        self._axes = getattr(meas, "axes", None)
        return self.adapter.measurement_noise(meas.R)

    def after_update(self, innovation: Innovation, pred: MeasurementPrediction) -> None:
        self.adapter.learn(self._prior_P, innovation.nu, innovation.S, innovation.Pxz, forced=innovation.forced)

    def noise_report(self) -> dict[str, np.ndarray]:
        return self.adapter.report()

    def noise_report_labels(self) -> dict[str, list[str]]:
        labels = {"q_factor": self.q_group_names}
        if getattr(self, "_axes", None):
            labels["r_factor"] = list(self._axes)
        return labels
