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
from typing import Any, ClassVar

import numpy as np
from numba import njit

from .model import InsModel, minus, plus
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

    def decay(self, dt: float) -> float:
        """``exp(-dt / tau)`` over ``dt`` s."""
        return math.exp(-max(dt, 0.0) / self.tau_s)


@njit(cache=True)
def plus_gm(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """``x ⊞ dx`` on the augmented state: (19,) ⊞ (18,) -> (19,); the INS part by
    :func:`navpp.ins.model.plus`, the GNSS error additively."""
    y = plus(x, dx[:N_ERR])
    for i in range(3):
        y[NOMINAL_SIZE + i] = x[NOMINAL_SIZE + i] + dx[N_ERR + i]
    return y


@njit(cache=True)
def minus_gm(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x1 ⊟ x0`` on the augmented state, (18,)."""
    dx = np.empty(N_ERR + 3)
    dx[:N_ERR] = minus(x1, x0)
    for i in range(3):
        dx[N_ERR + i] = x1[NOMINAL_SIZE + i] - x0[NOMINAL_SIZE + i]
    return dx


@njit(cache=True)
def rts_means_gm(x_post: np.ndarray, x_prior: np.ndarray, gains: np.ndarray, reset: np.ndarray) -> np.ndarray:
    """The smoother's mean recursion on the augmented nominal (as :func:`navpp.ins.model.rts_means`):
    (M, 19) states, gains (M, 18, 18)."""
    m = x_post.shape[0]
    xs = np.empty_like(x_post)
    xs[m - 1] = x_post[m - 1]
    for k in range(m - 2, -1, -1):
        if reset[k + 1]:
            xs[k] = x_post[k]
        else:
            xs[k] = plus_gm(x_post[k], gains[k + 1] @ minus_gm(xs[k + 1], x_prior[k + 1]))
    return xs


def _ins_part(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x[:NOMINAL_SIZE])


class GnssErrorModel:
    """An :class:`~navpp.ins.model.InsModel` with the Gauss-Markov GNSS error appended (module
    docstring): 18 error elements, 19 nominal.  ``ins`` is the wrapped model (its path is the
    run's IMU-rate path); ``settings`` the error's time constant and stationary sigma."""

    #: VCE: the INS noise groups reach the fixes through many time updates
    noise_share: ClassVar[str] = "propagated"

    def __init__(self, ins: InsModel, settings: GnssErrorSettings) -> None:
        self.ins, self.settings = ins, settings
        self.dim = N_ERR_GM
        self._var = settings.variance

    # ⊞ / ⊟ -----------------------------------------------------------------------------------
    @staticmethod
    def plus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return plus_gm(x, np.ascontiguousarray(dx, dtype=float))

    @staticmethod
    def minus(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        return minus_gm(x1, x0)

    rts_means = staticmethod(rts_means_gm)

    # propagation -----------------------------------------------------------------------------
    def _block(self, interval: tuple[float, float]) -> tuple[float, np.ndarray]:
        """(decay a, Qd diagonal (3,)) of the GNSS error over ``interval``."""
        a = self.settings.decay(interval[1] - interval[0])
        return a, self._var * (1.0 - a * a)

    def _nominal(self, xn_ins: np.ndarray, x: np.ndarray, a: float) -> np.ndarray:
        out = np.empty(NOMINAL_SIZE_GM)
        out[:NOMINAL_SIZE] = xn_ins
        out[NOMINAL_GM] = a * x[NOMINAL_GM]
        return out

    def _augmented(self, M15: np.ndarray, diag3: np.ndarray) -> np.ndarray:
        M = np.zeros((N_ERR_GM, N_ERR_GM))
        M[:N_ERR, :N_ERR] = M15
        M[GM, GM] = np.diag(diag3)
        return M

    def transition(self, x: np.ndarray, interval: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The INS's transition with the GNSS error's decay and drive appended."""
        xn, Phi, Qd = self.ins.transition(_ins_part(x), interval)
        a, q = self._block(interval)
        return self._nominal(xn, x, a), self._augmented(Phi, np.full(3, a)), self._augmented(Qd, q)

    def process_noise(self, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        """Qd (18, 18) over the interval."""
        _, q = self._block(interval)
        return self._augmented(self.ins.process_noise(_ins_part(x), interval), q)

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """The INS's points through the strapdown; the GNSS error part decays linearly."""
        dX = np.asarray(dX, dtype=float)
        xn, dY = self.ins.propagate_points(_ins_part(x), np.ascontiguousarray(dX[:, :N_ERR]), interval)
        a, _ = self._block(interval)
        out = np.empty((dX.shape[0], N_ERR_GM))
        out[:, :N_ERR] = dY
        out[:, N_ERR:] = a * dX[:, N_ERR:]
        return self._nominal(xn, x, a), out

    def noise_groups(self, x: np.ndarray, interval: tuple[float, float], per: str = "triad"
                     ) -> tuple[list[str], np.ndarray]:
        """The INS's noise groups (padded to 18) and one more, ``gnss_error``: the drive of the
        GNSS error block (variance component estimation may scale it like the others)."""
        names, Qs = self.ins.noise_groups(_ins_part(x), interval, per)
        out = np.zeros((len(names) + 1, N_ERR_GM, N_ERR_GM))
        if len(names):
            out[:-1, :N_ERR, :N_ERR] = Qs
        _, q = self._block(interval)
        out[-1, GM, GM] = np.diag(q)
        return [*names, "gnss_error"], out

    # start -----------------------------------------------------------------------------------
    def start(self, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The augmented start state from the INS's (16,) ``x`` and (15, 15) ``P``: the GNSS
        error estimate zero with its stationary variance.  The start position came from the fixes,
        so its error holds the (unknown) GNSS error with the opposite sign: the position variance
        grows by ``sigma_c^2`` and the two blocks correlate by ``-sigma_c^2`` (the Schur complement
        is the INS's own position variance, so the result stays positive definite)."""
        xa = np.zeros(NOMINAL_SIZE_GM)
        xa[:NOMINAL_SIZE] = x[:NOMINAL_SIZE]
        Pa = np.zeros((N_ERR_GM, N_ERR_GM))
        Pa[:N_ERR, :N_ERR] = P
        v = np.diag(self._var)
        Pa[POS, POS] += v
        Pa[POS, GM] = -v
        Pa[GM, POS] = -v
        Pa[GM, GM] = v
        return xa, Pa

    def measurement(self, meas: Any) -> Any:
        """``meas`` of the 15-element model as a measurement of this one: the GNSS position fix
        with the error in its prediction, anything else padded (:class:`Padded`)."""
        from .model import GnssPosition

        if isinstance(meas, GnssPosition):
            return GnssPositionGM(meas, self._var)
        return Padded(meas)


class Padded:
    """A measurement of the 15-element INS model on the augmented one: the same innovation and
    R, zero Jacobian columns for the GNSS error, its points taken on the INS part; every other
    attribute is the wrapped measurement's (``inner``)."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner

    def __getattr__(self, name: str) -> Any:      # kind, axes, adaptive, forceable, t, R, ...
        if name == "inner":                       # not set yet (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        nu: np.ndarray = self.inner.innovation_at(_ins_part(x))
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        H15 = self.inner.jacobian(_ins_part(x))
        H = np.zeros((H15.shape[0], N_ERR_GM))
        H[:, :N_ERR] = H15
        return H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        Z: np.ndarray = self.inner.predict_points(_ins_part(x), np.ascontiguousarray(np.asarray(dX)[:, :N_ERR]))
        return Z

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        out: np.ndarray | None = self.inner.reanchor(P, nu, R)
        return out


class GnssPositionGM(Padded):
    """The GNSS position fix with the Gauss-Markov error: ``z = antenna + b + w``; the
    innovation is the INS's minus the estimated ``b``, ``H = [H_ins, I]``, R the white part.
    A forced fix re-anchors the position as the INS's fix does and restarts the GNSS error block
    from its stationary variance, uncorrelated with the rest (a jump is not the slow error)."""

    def __init__(self, inner: Any, variance: np.ndarray) -> None:
        super().__init__(inner)
        self.variance = variance

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        nu: np.ndarray = self.inner.innovation_at(_ins_part(x)) - x[NOMINAL_GM]
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
