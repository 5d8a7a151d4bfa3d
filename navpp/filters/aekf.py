"""Adaptive EKFs of paper 002: the standard Sage-Husa filter and the improved AEKF.

Both are the EKF with a measurement-noise adapter (:mod:`navpp.filters.noise`); the improved
one gains with the previous epoch's R and drops the ``- H P- H^T`` term, so R stays positive
definite.  Only fixes that pass the innovation gate are learnt into R (not those forced
through it after a run of rejections).

References: paper 002 section 3; ALGORITHMS.md "Sage-Husa and the improved adaptive EKF".
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from .base import Innovation, MeasurementPrediction, register
from .ekf import EKF
from .noise import SageHusaAdapter, SageHusaOptions, centred


class _AdaptiveEKF(EKF):
    Options = SageHusaOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": False}
    improved: ClassVar[bool] = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.adapter = SageHusaAdapter(self.options, self.improved)
        self._nu_raw = np.zeros(0)
        self._HPHt = np.zeros((0, 0))

    def adjust_prediction(self, pred: MeasurementPrediction) -> MeasurementPrediction:
        self._nu_raw, self._HPHt = pred.nu, pred.Pzz
        return centred(pred, self.adapter)

    def measurement_noise(self, meas, pred: MeasurementPrediction) -> np.ndarray:
        return self.adapter.noise_for_gain(meas.R, self._nu_raw, self._HPHt)

    def after_update(self, innovation: Innovation, pred: MeasurementPrediction) -> None:
        if innovation.forced:      # admitted after a run of rejections: an outlier-sized innovation
            return
        self.adapter.learn(self._nu_raw)


@register("aekf")
class AEKF(_AdaptiveEKF):
    paper = "paper 002 section 3, eqs 6-16 (improved Sage-Husa)"
    summary = "Improved adaptive EKF: R learnt from the innovations (gain with R_k-1, no -HPH' term)."
    improved = True


@register("sage-husa")
class SageHusaEKF(_AdaptiveEKF):
    paper = "paper 002 section 3, eqs 6-13 (standard Sage-Husa)"
    summary = "Standard Sage-Husa adaptive EKF: R_k = (1-d) R_k-1 + d (e e' - H P H'), before the gain."
    improved = False
