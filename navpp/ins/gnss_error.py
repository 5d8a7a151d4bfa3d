"""Time-correlated GNSS position errors as three extra filter states (``[gnss] error_model``).

Single-point and SBAS fixes, multipath and the atmosphere give position errors that stay for
tens of seconds.  A filter that takes them as white follows them: successive fixes say the same
wrong thing, and it believes each one.  Here the fix error is split into a first-order
Gauss-Markov part ``b`` (ENU m, correlation time ``tau``, stationary 1-sigma ``sigma_c`` per
axis) and a white part (the fix's R):

``fix = antenna position + b + w``,   ``b' = -b / tau + noise``,   ``E[b b^T] = diag(sigma_c^2)``.

The filter state grows from 15 to 18 error elements (:data:`GM`, after the accelerometer bias)
and the nominal from 16 to 19 (:data:`NOMINAL_GM`: the estimated ``b``, ENU m).  Over an interval
of ``T`` s: ``b <- a b`` with ``a = exp(-T / tau)``, ``Phi_b = a I``, ``Qd_b = diag(sigma_c^2)
(1 - a^2)`` (exact discretisation); the block does not couple to the INS in the dynamics, only
through the position fix, whose Jacobian gains an identity: ``H = [H_ins, I]``.

:class:`GnssErrorModel` wraps an :class:`~navpp.ins.model.InsModel` so that every filter (EKF
and sigma-point), the RTS smoother and variance component estimation see the 18-element model;
:class:`GnssPositionGM` is the position fix with ``b`` in its prediction, and :class:`Padded`
carries any other measurement of the 15-element model (velocity, NHC, ZUPT, ZARU) over unchanged
(zero columns for ``b``).

Detection (``error_model = "auto"``): :func:`innovation_correlation` measures how alike the
innovations are several seconds apart; white fix errors leave them nearly independent, correlated
ones do not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .augmented import AugmentedInsModel, Padded, StateBlock, ins_part, minus_aug, plus_aug, rts_means_aug
from .model import InsModel
from .state import N_ERR, NOMINAL_SIZE, POS

#: error-state slice of the GNSS error block (ENU m), after the 15 INS error states
GM = slice(N_ERR, N_ERR + 3)
#: nominal-state slice of the estimated GNSS error (ENU m), after the 16 INS nominal elements
NOMINAL_GM = slice(NOMINAL_SIZE, NOMINAL_SIZE + 3)
#: sizes of the augmented error and nominal states
N_ERR_GM = N_ERR + 3
NOMINAL_SIZE_GM = NOMINAL_SIZE + 3
#: names of the new error states (diagnostics, VCE groups)
GM_STATE_NAMES = ("gnss_error_e", "gnss_error_n", "gnss_error_u")


@dataclass(frozen=True)
class GnssErrorSettings:
    """The Gauss-Markov GNSS error: ``tau_s`` correlation time (s, > 0) and ``sigma_enu`` (3,)
    stationary 1-sigma per ENU axis (m)."""

    tau_s: float
    sigma_enu: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tau_s) and self.tau_s > 0.0):
            raise ValueError(f"GnssErrorSettings: tau_s must be a finite number of s > 0, got {self.tau_s!r}")
        sig = tuple(float(s) for s in self.sigma_enu)
        if len(sig) != 3 or not all(math.isfinite(s) and s > 0.0 for s in sig):
            raise ValueError(f"GnssErrorSettings: sigma_enu must be three finite numbers of m > 0, got "
                             f"{self.sigma_enu!r}")
        object.__setattr__(self, "sigma_enu", sig)

    @property
    def variance(self) -> np.ndarray:
        """Stationary variance per ENU axis, m^2 (3,)."""
        var: np.ndarray = np.square(np.asarray(self.sigma_enu))
        return var

    def block(self) -> StateBlock:
        """The error as a block of the augmented INS (:mod:`navpp.ins.augmented`)."""
        return StateBlock("gnss_error", tuple(GM_STATE_NAMES), self.tau_s, self.sigma_enu)


#: ``x ⊞ dx`` / ``x1 ⊟ x0`` / the smoother's mean recursion on the augmented state (19 / 18 elements
#: with the GNSS error alone; any number of extra elements, :mod:`navpp.ins.augmented`)
plus_gm = plus_aug
minus_gm = minus_aug
rts_means_gm = rts_means_aug


class GnssErrorModel(AugmentedInsModel):
    """An :class:`~navpp.ins.model.InsModel` with the Gauss-Markov GNSS error appended first
    (module docstring; :data:`GM`, :data:`NOMINAL_GM`), then any ``more`` blocks (e.g. the
    odometer's scale factor).  ``settings``: the error's time constant and stationary sigma."""

    def __init__(self, ins: InsModel, settings: GnssErrorSettings, more: tuple[StateBlock, ...] = ()) -> None:
        super().__init__(ins, (settings.block(), *more))
        self.settings = settings
        self._var = settings.variance

    def _block(self, interval: tuple[float, float]) -> tuple[float, np.ndarray]:
        """(decay a, Qd diagonal (3,)) of the GNSS error over ``interval``."""
        b = self.blocks[0]
        dt = interval[1] - interval[0]
        return b.decay(dt), b.drive(dt)

    def start(self, x: np.ndarray, P: np.ndarray, averaged: tuple[float, int] | None = None, share: float = 1.0
              ) -> tuple[np.ndarray, np.ndarray]:
        """The augmented start (:meth:`AugmentedInsModel.start`) with the GNSS error correlated
        to the position: the start position came from the fixes, so its error holds their (unknown)
        GNSS error.

        From one fix (``averaged`` None): the position's error is that fix's ``b`` at the start,
        so the position variance grows by ``sigma_c^2`` and the two blocks correlate by
        ``-sigma_c^2`` (the Schur complement is the INS's own position variance).  From the mean
        of ``count`` fixes over ``span`` s (``averaged = (span, count)``, a still start): the
        position's error is the mean of ``b`` over the span, whose variance is ``sigma_c^2 g(x)``,
        ``g(x) = 2 (x - 1 + exp(-x)) / x^2`` with ``x = span / tau``, and whose covariance with ``b``
        at the start is ``-sigma_c^2 (1 - exp(-x)) / x``; the position keeps ``P``'s variance (the
        mean's, from the fixes' own scatter) when that is larger, and is divided by ``share``, the
        share of the averaged fixes' information the start holds (the filter takes the fixes again
        with the rest, :func:`navpp.engine.prepare.start_fixes`).  The correlation is held below
        0.99 so that the start stays positive definite.  Adding ``sigma_c^2`` there would count the
        averaged error twice (the filter then pulled a 200 s still start by metres towards its
        first fixes)."""
        xa, Pa = super().start(x, P)
        v = np.diag(self._var)
        if averaged is None or averaged[1] < 2 or not averaged[0] > 0.0:
            Pa[POS, POS] += v
            Pa[POS, GM] = -v
            Pa[GM, POS] = -v
            return xa, Pa
        xr = averaged[0] / self.settings.tau_s
        if xr < 1e-4:        # series: the closed forms cancel
            g, h = 1.0 - xr / 3.0, 1.0 - xr / 2.0
        else:
            g = 2.0 * (xr - 1.0 + math.exp(-xr)) / (xr * xr)
            h = -math.expm1(-xr) / xr
        var_p = np.maximum(np.diag(Pa[POS, POS]), self._var * g) / share
        cov = -np.minimum(self._var * h, 0.99 * np.sqrt(var_p * self._var))
        Pa[POS, POS] = np.diag(var_p)
        Pa[POS, GM] = np.diag(cov)
        Pa[GM, POS] = np.diag(cov)
        return xa, Pa

    def measurement(self, meas: Any) -> Any:
        """The GNSS position fix with the error in its prediction, the rest as
        :meth:`AugmentedInsModel.measurement` builds them."""
        from .model import GnssPosition

        if isinstance(meas, GnssPosition):
            return GnssPositionGM(meas, self._var, self.dim)
        return super().measurement(meas)


class GnssPositionGM(Padded):
    """The GNSS position fix with the Gauss-Markov error: ``z = antenna + b + w``; the
    innovation is the INS's minus the estimated ``b``, ``H = [H_ins, I, 0]``, R the white part.
    A forced fix re-anchors the position as the INS's fix does and restarts the GNSS error block
    from its stationary variance, uncorrelated with the rest (a jump is not the slow error)."""

    def __init__(self, inner: Any, variance: np.ndarray, n: int = N_ERR_GM) -> None:
        super().__init__(inner, n)
        self.variance = variance

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        nu: np.ndarray = self.inner.innovation_at(ins_part(x)) - x[NOMINAL_GM]
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        H = super().jacobian(x)
        H[:, GM] = np.eye(3)
        return H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        dX = np.asarray(dX)
        Z: np.ndarray = super().predict_points(x, dX) + dX[:, GM]
        return Z

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        Pr: np.ndarray | None = self.inner.reanchor(P, nu, R)
        if Pr is None:
            return None
        Pr[GM, :] = 0.0
        Pr[:, GM] = 0.0
        Pr[GM, GM] = np.diag(self.variance)
        return Pr


@dataclass(frozen=True)
class Correlation:
    """The innovations' correlation ``rho`` (-1..1) at ``lag_s`` s, from ``pairs`` pairs of
    accepted fixes that far apart, pooled over the ENU axes (each axis centred and scaled by its
    own spread); ``threshold`` the value above which the errors count as correlated."""

    rho: float
    lag_s: float
    pairs: int
    threshold: float

    @property
    def correlated(self) -> bool:
        return self.pairs > 0 and self.rho > self.threshold


#: The lag at which the detection compares innovations, s: long enough that the INS between the
#: two fixes is fixed by the fixes in between (an honest white-noise filter leaves its innovations
#: nearly independent after a second or two), short against the tens of seconds a correlated
#: error lasts.
DETECTION_LAG_S = 5.0
#: The detection's threshold on the lag correlation: white fix errors give about 0 +- 1/sqrt(pairs)
#: (|rho| < 0.01 on simulated white drives, with and without GNSS velocity, and on consumer-car
#: realism drives); correlated ones 0.5 with GNSS velocity and 0.14-0.27 without (the INS then
#: follows the fixes more, which whitens the innovations); the real RTK walk gives 0.006, the real
#: consumer car 0.05 (its receiver's errors last a second or two).  The test is the larger of this
#: and 5 standard errors.
DETECTION_RHO = 0.1


def innovation_correlation(t: np.ndarray, nu: np.ndarray, accepted: np.ndarray,
                           lag_s: float = DETECTION_LAG_S) -> Correlation:
    """How alike the GNSS position innovations are ``lag_s`` s apart (module docstring).

    ``t`` (M,) fix times s; ``nu`` (M, 3) innovations ENU m; ``accepted`` (M,) bool.  Each pair
    is an accepted fix and the accepted fix nearest ``lag_s`` s later (within a quarter of the
    lag); per axis the innovations are centred and divided by their standard deviation, and the
    correlation is the mean product over the pairs and the three axes.
    """
    t = np.asarray(t, dtype=float)
    ok = np.asarray(accepted, bool) & np.all(np.isfinite(nu), axis=1)
    ts, z = t[ok], np.asarray(nu, dtype=float)[ok]
    if ts.size < 10:
        return Correlation(0.0, lag_s, 0, DETECTION_RHO)
    sd = z.std(axis=0)
    sd[sd <= 0.0] = 1.0
    z = (z - z.mean(axis=0)) / sd
    j = np.searchsorted(ts, ts + lag_s)
    j = np.clip(j, 1, ts.size - 1)
    j = np.where(np.abs(ts[j - 1] - ts - lag_s) < np.abs(ts[j] - ts - lag_s), j - 1, j)
    keep = np.abs(ts[j] - ts - lag_s) <= 0.25 * lag_s
    i = np.nonzero(keep)[0]
    n = int(i.size)
    if n < 10:
        return Correlation(0.0, lag_s, n, DETECTION_RHO)
    rho = float(np.mean(np.sum(z[i] * z[j[i]], axis=1)) / 3.0)
    return Correlation(rho, lag_s, n, max(DETECTION_RHO, 5.0 / math.sqrt(n)))


__all__ = [
    "DETECTION_LAG_S", "DETECTION_RHO", "GM", "GM_STATE_NAMES", "NOMINAL_GM", "NOMINAL_SIZE_GM", "N_ERR_GM",
    "Correlation", "GnssErrorModel", "GnssErrorSettings", "GnssPositionGM", "Padded", "innovation_correlation",
    "minus_gm", "plus_gm", "rts_means_gm",
]
