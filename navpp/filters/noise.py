"""Measurement-noise adapters: Sage-Husa (standard) and the improved adaptive EKF of paper 002.

Forgetting factor ``b`` (paper: 0.978) and weight ``d_k = (1 - b) / (1 - b^(k+1))``; the
configured R counts as ``prior_epochs`` epochs (the index starts there; 0 is the paper's
literal start, where d = 1 replaces R by one outer product).  ``e_k = d_k_raw - r_{k-1}`` is
the innovation less the estimated noise mean ``r`` (``estimate_mean``).

``estimate_mean`` defaults to off: in a closed-loop filter the noise mean is not observable
apart from the position error.  Once r is subtracted, the filter follows ``z - r``, the
innovation's mean then equals r, and r wanders like a random walk (docs/papers.md gives the
figures on the sample drive).

- standard (``sage-husa``): ``R_k = (1-d) R_{k-1} + d (e e^T - H P- H^T)`` *before* the gain;
  when that loses positive definiteness the previous R is kept for the epoch and counted.
- improved (``aekf``): the gain uses ``R_{k-1}``; afterwards ``R_k = (1-d) R_{k-1} + d e e^T``
  (no subtraction, so R stays positive definite).

References: paper 002 section 3 (eqs 6-13 for Sage-Husa, 14-16 for the improvements);
docs/algorithms.md "Sage-Husa and the improved adaptive EKF".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .adaptation import Adaptation, Predictor
from .protocols import Measurement
from .states import GaussianState, Innovation, MeasurementPrediction


@dataclass(frozen=True)
class SageHusaOptions:
    """``[filter.aekf]`` / ``[filter.sage-husa]``: forgetting factor ``b`` in (0, 1), the
    configured R's weight in epochs ``prior_epochs`` >= 0, whether the noise mean r is
    estimated, and ``adapt`` (false: the EKF exactly)."""

    forgetting_factor: float = 0.978
    prior_epochs: int = 20
    estimate_mean: bool = False
    adapt: bool = True

    def __post_init__(self) -> None:
        if not 0.0 < self.forgetting_factor < 1.0:
            raise ValueError(f"forgetting_factor must be in (0, 1), got {self.forgetting_factor!r}")
        if int(self.prior_epochs) != self.prior_epochs or self.prior_epochs < 0:
            raise ValueError(f"prior_epochs must be an integer >= 0, got {self.prior_epochs!r}")


class SageHusaAdapter(Adaptation):
    """The Sage-Husa recursion as a filter's adaptation (module docstring).

    Attributes
    ----------
    R : (m, m) the learnt measurement noise (None before the first adaptive measurement).
    r : (m,) the estimated noise mean (zeros unless ``estimate_mean``).
    k : the epoch index of the weight ``d_k`` (starts at ``prior_epochs``).
    kept : epochs where the standard update lost positive definiteness and the previous R was kept.
    """

    adapts_noise = True

    def __init__(self, options: SageHusaOptions, improved: bool) -> None:
        self.o = options
        self.improved = improved
        self.R: np.ndarray | None = None
        self.r: np.ndarray | None = None
        self.k = int(options.prior_epochs)
        self.kept = 0
        self._for_gain: np.ndarray | None = None   # standard: this epoch's R, committed when the fix is applied

    def weight(self) -> float:
        """``d_k = (1 - b) / (1 - b^(k+1))``."""
        b = self.o.forgetting_factor
        return (1.0 - b) / (1.0 - b ** (self.k + 1))

    def _init(self, R_meas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.R is None or self.r is None:
            self.R = np.array(R_meas, dtype=float)
            self.r = np.zeros(R_meas.shape[0])
        return self.R, self.r

    def centre(self, nu: np.ndarray) -> np.ndarray:
        """The innovation less the estimated noise mean (when it is estimated)."""
        return nu - self.r if (self.r is not None and self.o.estimate_mean) else nu

    def measurement_noise(self, meas: Measurement, raw: MeasurementPrediction) -> np.ndarray:
        """R for the gain: the configured R (adapt off), the previous epoch's (improved), or the
        standard recursion with ``- H P- H^T`` (the previous R when that is not positive definite)."""
        R_prev, _ = self._init(meas.R)
        if not self.o.adapt or self.improved:
            return R_prev if self.o.adapt else meas.R
        d = self.weight()
        e = self.centre(raw.nu)
        R_new = (1.0 - d) * R_prev + d * (np.outer(e, e) - raw.Pzz)
        R_new = 0.5 * (R_new + R_new.T)
        if np.all(np.linalg.eigvalsh(R_new) > 0.0):
            self._for_gain = R_new
        else:
            self._for_gain = R_prev
            self.kept += 1
        return self._for_gain

    def prepare(self, prior: GaussianState, meas: Measurement, raw: MeasurementPrediction,
                R: np.ndarray, gate: float, predictor: Predictor) -> tuple[GaussianState, MeasurementPrediction]:
        """The prediction with the estimated noise mean removed from the innovation."""
        if not meas.adaptive or self.r is None or not self.o.estimate_mean or not self.o.adapt:
            return prior, raw
        return prior, replace(raw, nu=raw.nu - self.r)

    def corrected(self, prior: GaussianState, raw: MeasurementPrediction, innovation: Innovation,
                  meas: Measurement) -> None:
        """After an applied adaptive fix that passed the gate: the mean, R, the epoch index."""
        if not meas.adaptive or innovation.forced or not self.o.adapt:
            return
        R_prev, r = self._init(meas.R)
        d = self.weight()
        e = self.centre(raw.nu)
        if self.improved:
            R_new = (1.0 - d) * R_prev + d * np.outer(e, e)
            self.R = 0.5 * (R_new + R_new.T)
        else:
            self.R = self._for_gain
        if self.o.estimate_mean:
            self.r = (1.0 - d) * r + d * raw.nu
        self.k += 1
