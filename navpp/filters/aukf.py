"""Adaptive fading UKF (AUKF): the UKF whose prior is inflated when the innovation is too large.

After the unscented measurement prediction (``nu``, ``Pzz`` *without* R as in
:class:`~navpp.filters.states.MeasurementPrediction`, ``Pxz``), the fading factor is

    ``lambda_k = min(max_fading, max(1, (nu^T nu - tr R) / tr(Pzz)))``

i.e. docs/algorithms.md's ``(d^T d - tr R) / tr(Pzz' - R)`` with ``Pzz' = Pzz + R`` the innovation
covariance including R (so the denominator is the trace of the predicted-measurement spread
alone).  ``nu^T nu`` is the squared innovation in the measurement's units (GNSS: m^2, ENU).
When ``lambda_k > 1`` the propagated part of the prior is inflated, leaving the process noise
alone,

    ``P- <- lambda_k (P- - Q) + Q``,

the sigma points are redrawn from the new P- and ``nu, Pzz, Pxz`` recomputed before the gain;
the posterior covariance is then ``P- - K S K^T`` about the inflated P-.  With ``adapt = false``
(the oracle option) ``lambda_k = 1`` always and the filter is the UKF exactly.

Readings and choices (the original is not at hand; docs/algorithms.md "Paper 001's comparison
filters"):

- ``Q`` is the process noise added since the last applied update: the adaptation's
  ``process_noise`` step records every Qd it hands to the time update, and the record is summed over all time updates
  between two applied measurement updates (the engine splits long GNSS gaps into 1 s
  predictions) and cleared after an applied update.  With one prediction per update, the
  normal case, ``P- - Q`` is exactly the propagated posterior; over a gap the sum neglects the
  propagation of earlier Qd through later intervals (``Phi Q Phi^T`` vs ``Q``), so a little of the
  early noise is inflated with the propagated part.
- The chi-square gate (``gate_probability``) is applied to the *unfaded* UKF innovation: a fix
  that fails it is not used to fade (lambda = 1) and is rejected as by the UKF.  Fading first
  would inflate ``Pzz`` until any outlier passes the gate; a strong-tracking filter cannot tell an
  outlier from a manoeuvre, the gate can.
- ``max_fading`` (default 2) caps lambda.  On the INS the gated, detected fades are chi-square
  false alarms far more often than manoeuvres the INS cannot follow, and a fade multiplies the
  covariance of every state, the weakly observable ones (attitude, biases) included: with the
  cap at 1e3 (the default before issue 20) lambda reached 20-1000 and AUKF was 14-63 % worse
  than the EKF on the simulated drives; a cap of 2 leaves it within 1-3 % of the EKF there
  while still fading enough to recover from an unmodelled manoeuvre several times faster than
  the UKF (docs/papers.md gives the measurements).  ``max_fading = inf`` with
  ``detect_probability = 0`` is the strong-tracking rule as written, without a cap.
- ``fade`` (default "all", the paper's): what is inflated.  "observed" adds
  ``(lambda - 1) Pxz Pzz^+ Pxz^T`` to the prior instead, the part of P the measurement sees:
  for a linear measurement this multiplies ``Pzz`` and ``Pxz`` by lambda, as fading the whole
  prior does, and leaves the covariance of the states uncorrelated with the measurement alone.
  On the INS drives it was no better than "all" at the same cap (docs/papers.md).
- ``detect_probability`` (default 0.999; 0 is docs/algorithms.md's rule as written): with p > 0 the
  filter fades only when the unfaded NIS exceeds the chi-square quantile p (a fault-detection test before
  adapting, as in Hajiyev and Soken's adaptive filters as we understand them; their papers
  are not at hand).  On the INS the rule as written fades on many GNSS epochs, because one
  epoch's ``nu^T nu`` scatters by several ``tr R`` when R dominates the innovation: every
  fade multiplies the attitude and bias covariance too, which the position fixes observe
  weakly (heading not at all while still), so those covariances ratchet up until the sigma
  points span tens of degrees and the filter diverges.  A detection test at p = 0.999 keeps
  the fading to the innovations that are inconsistent with the UKF's prediction, hence
  navpp's default; the rule as written stays one option away and is reported next to it in
  the paper 001 benchmark (docs/papers.md gives the figures).

``noise_report()`` gives ``{"fading": array([lambda_k])}``: the factor applied at the last
measurement update (1 when not fading, rejected or ``adapt = false``).

References: paper 001 (comparison filter, its refs [6]/[12]); H. E. Soken, C. Hajiyev, adaptive
fading UKF (2011); the strong-tracking fading factor of Zhou & Frank (1996); docs/algorithms.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from ..chi2 import chdtri
from .adaptation import Adaptation, Predictor
from .base import register
from .linalg import symmetrise
from .protocols import Interval, Measurement, Model
from .states import GaussianState, Innovation, MeasurementPrediction
from .ukf import UKF, UKFOptions

FADE = ("all", "observed")


@dataclass(frozen=True)
class AUKFOptions(UKFOptions):
    """``[filter.aukf]``: the UKF's ``alpha``, ``beta``, ``kappa`` plus the fading options.

    adapt : apply the fading factor (false: the UKF exactly).
    max_fading : upper bound on lambda_k, >= 1, default 2 (inf: no cap; see the module docstring).
    detect_probability : in [0, 1), default 0.999.  0 (docs/algorithms.md's rule): fade whenever
        lambda_k > 1.  p > 0: fade only when the unfaded NIS exceeds the chi-square(m)
        quantile p, i.e. when a test at significance 1 - p finds the innovation inconsistent
        with the UKF's prediction (see the module docstring).
    fade : "all" (the paper's strong tracking: the whole propagated prior times lambda_k) or
        "observed" (only the part of the prior the measurement sees:
        ``P- + (lambda_k - 1) Pxz Pzz^-1 Pxz^T``; see the module docstring).
    """

    adapt: bool = True
    max_fading: float = 2.0
    detect_probability: float = 0.999
    fade: str = "all"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.fade not in FADE:
            raise ValueError(f"fade must be one of {', '.join(FADE)}; got {self.fade!r}")
        if not 0.0 <= self.detect_probability < 1.0:
            raise ValueError(f"detect_probability must be in [0, 1), got {self.detect_probability!r}")
        if not (isinstance(self.max_fading, (int, float)) and not isinstance(self.max_fading, bool)
                and self.max_fading >= 1.0):
            raise ValueError(f"max_fading must be a number >= 1 (inf: no cap), got {self.max_fading!r}")


def fading_factor(nu: np.ndarray, Pzz: np.ndarray, R: np.ndarray, max_fading: float = np.inf) -> float:
    """``min(max_fading, max(1, (nu^T nu - tr R) / tr Pzz))``; ``Pzz`` (m, m) excludes R.

    A non-positive ``tr Pzz`` (a degenerate spread) gives 1: there is nothing to inflate.
    """
    spread = float(np.trace(Pzz))
    if not spread > 0.0:
        return 1.0
    lam = (float(nu @ nu) - float(np.trace(R))) / spread
    return float(min(max_fading, max(1.0, lam)))


def observed_part(Pxz: np.ndarray, Pzz: np.ndarray) -> np.ndarray:
    """``Pxz Pzz^+ Pxz^T`` (n, n): the part of the prior covariance the measurement sees.

    For a linear measurement ``z = H x`` (``Pxz = P H^T``, ``Pzz = H P H^T``) adding
    ``(lambda - 1)`` times it to P multiplies ``Pzz`` and ``Pxz`` by lambda, as fading the whole
    prior does, and leaves the covariance of the states uncorrelated with z unchanged.  The
    pseudo-inverse keeps it defined (and positive semi-definite) when ``Pzz`` is singular.
    """
    out: np.ndarray = Pxz @ np.linalg.pinv(symmetrise(Pzz), hermitian=True) @ Pxz.T
    return out


class Fading(Adaptation):
    """The AUKF's fading adjustment as a filter's adaptation (see the module docstring).

    Attributes
    ----------
    fading : lambda_k applied at the last measurement update (1: not faded).
    Q_since_update : (n, n) the process noise added since the last applied update (None: none).
    """

    def __init__(self, options: AUKFOptions) -> None:
        self.o = options
        self.fading = 1.0
        self.Q_since_update: np.ndarray | None = None

    def report(self) -> dict[str, np.ndarray]:
        return {"fading": np.array([self.fading])}

    def _detect_threshold(self, m: int) -> float:
        """chi-square(m) quantile ``detect_probability`` (-inf when 0: always test lambda)."""
        p = self.o.detect_probability
        return float(chdtri(m, 1.0 - p)) if p > 0.0 else -np.inf

    def process_noise(self, model: Model, x: np.ndarray, interval: Interval) -> np.ndarray:
        Q = model.process_noise(x, interval)
        self.Q_since_update = Q.copy() if self.Q_since_update is None else self.Q_since_update + Q
        return Q

    def prepare(self, prior: GaussianState, meas: Measurement, raw: MeasurementPrediction,
                R: np.ndarray, gate: float, predictor: Predictor) -> tuple[GaussianState, MeasurementPrediction]:
        """The faded prior and its prediction when the innovation is too large, else the UKF's."""
        self.fading = 1.0
        if not self.o.adapt or not meas.adaptive:
            return prior, raw
        S = symmetrise(raw.Pzz + R)
        nis = float(raw.nu @ np.linalg.solve(S, raw.nu))
        if nis > gate:
            return prior, raw                    # an outlier for the UKF: the gate decides, no fading
        if nis <= self._detect_threshold(raw.nu.shape[0]):
            return prior, raw                    # consistent with the UKF's own prediction: no fading
        lam = fading_factor(raw.nu, raw.Pzz, R, self.o.max_fading)
        if lam <= 1.0:
            return prior, raw
        if self.o.fade == "observed":
            faded = replace(prior, P=symmetrise(prior.P + (lam - 1.0) * observed_part(raw.Pxz, raw.Pzz)))
        else:
            Q = self.Q_since_update if self.Q_since_update is not None else np.zeros_like(prior.P)
            faded = replace(prior, P=symmetrise(lam * (prior.P - Q) + Q))  # inflate the propagated part only
        self.fading = lam
        return faded, predictor(faded)                                       # points redrawn from the faded P

    def corrected(self, prior: GaussianState, raw: MeasurementPrediction, innovation: Innovation,
                  meas: Measurement) -> None:
        """The next prior's propagated part starts after any applied update (an aid such as a
        ZUPT too: the noise added before it is no longer inside what it left of P)."""
        self.Q_since_update = None


@register("aukf")
class AUKF(UKF):
    """Adaptive fading UKF (see module docstring)."""

    paper = "paper 001 (comparison filter); Soken & Hajiyev 2011 (adaptive fading UKF)"
    summary = "Adaptive fading UKF: the propagated prior is inflated by lambda when innovations are too large."
    Options = AUKFOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": False}
    adapter: Fading

    def make_adapter(self) -> Fading:
        return Fading(self.options)

    @property
    def fading(self) -> float:
        """lambda_k applied at the last measurement update."""
        return self.adapter.fading
