"""How an adaptive part plugs into a filter: the :class:`Adaptation` steps and their no-op defaults.

A filter owns one adaptation object (``Filter.adapter``) and calls it at fixed steps of its
time and measurement updates; the object keeps whatever adaptive state it needs (learnt R,
noise factors, the noise added since the last update).  The adaptations of navpp:

- :class:`navpp.filters.noise.SageHusaAdapter`: R learnt from the innovations (AEKF, Sage-Husa);
- :class:`navpp.filters.vce.HelmertVCE`: variance components of Q and R (VCE-CKF);
- :class:`navpp.filters.aukf.Fading`: the prior inflated when the innovation is too large (AUKF).

What each step receives is everything it needs: the raw measurement prediction and the prior
go to :meth:`Adaptation.corrected`, so nothing is parked between steps.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from .protocols import Interval, Measurement, Model
from .states import GaussianState, Innovation, MeasurementPrediction, Prediction

#: the filter's measurement prediction from a given prior (the measurement and model bound)
Predictor = Callable[[GaussianState], MeasurementPrediction]


class Adaptation:
    """No adaptation: the model's Q and the measurement's R as given.  Subclasses override the
    steps they adapt; a measurement whose ``adaptive`` is False is always used as given.

    ``adapts_noise``: the adaptation chooses the noise (R, or Q and R) the filter uses, as
    opposed to adjusting the prior or the weights.
    """

    adapts_noise: ClassVar[bool] = False

    def process_noise(self, model: Model, x: np.ndarray, interval: Interval) -> np.ndarray:
        """Qd (n, n) for a sigma-point time update over ``interval`` about nominal ``x``."""
        return model.process_noise(x, interval)

    def predicted(self, before: GaussianState, prediction: Prediction) -> None:
        """After every time update: the state it started from and what it produced."""

    def measurement_noise(self, meas: Measurement, raw: MeasurementPrediction) -> np.ndarray:
        """R (m, m) for an update with ``meas``; ``raw`` is the filter's measurement prediction."""
        return meas.R

    def prepare(self, prior: GaussianState, meas: Measurement, raw: MeasurementPrediction,
                R: np.ndarray, gate: float, predictor: Predictor) -> tuple[GaussianState, MeasurementPrediction]:
        """The prior and measurement prediction the gain is made from (e.g. the innovation less
        an estimated noise mean, or a faded prior with the prediction redone by ``predictor``);
        ``gate`` is the NIS threshold of the update (inf: no gate)."""
        return prior, raw

    def corrected(self, prior: GaussianState, raw: MeasurementPrediction, innovation: Innovation,
                  meas: Measurement) -> None:
        """After every applied update: the prior it corrected, the raw prediction of that
        prior and what the update saw and did (``innovation.forced``: a fix forced through
        the gate, whose innovation is outlier-sized)."""

    def report(self) -> dict[str, np.ndarray]:
        """What the adaptation has decided so far: name -> 1-D array, fixed length per name."""
        return {}

    def labels(self) -> dict[str, list[str]]:
        """Names of the elements of :meth:`report` entries that have several."""
        return {}


__all__ = ["Adaptation", "Predictor"]
