"""Stochastic integration filter (SIF): every Gaussian integral by the randomised SI rule.

Each Gaussian integral of the filter, the time-update moments (predicted mean and covariance)
and the measurement-update moments (``z_hat``, ``Pzz``, ``Pxz``), is computed by the
third-degree stochastic integration rule (:mod:`navpp.filters.stochastic`) and averaged over
iterations ``j = 1..J``: each iteration draws a fresh random orthogonal ``U`` and radius
``rho ~ chi(n + 2)`` from ``self.rng``, places the points ``x ⊞ S xi`` in the model's error space
(``S`` the lower Cholesky factor of P, ``xi`` the standardised points), pushes them through the
model (on the INS: all 2n points through the real strapdown in one compiled call per
iteration), and the running mean ``I_j = I_{j-1} + (SR_j - I_{j-1}) / j`` accumulates.

Stopping (``J``): after ``max_iter`` iterations, or earlier, once at least ``min_iter``
iterations have run, when the estimated integration error is at most ``tol``.  The error
estimate is the largest element-wise standard error of the running mean (sample standard
deviation of the iteration values over ``sqrt(j)``), each element divided by the standard
deviations it is measured in: a first moment of component i by ``sd_i``, a second moment of
components (i, k) by ``sd_i sd_k`` (``sd`` from the averaged covariance's diagonal).  The
measure is dimensionless (radians, metres and m/s mix in the INS state), so ``tol = 0.01``
means "every moment known to 1 % of its standard deviations".  The default ``tol = 1e-3``
stops as soon as the moments agree to 0.1 % of a standard deviation: on a linear model (the rule
is exact) and on the INS between GNSS epochs (a short propagation, where the iterations agree
far better than that) that is after ``min_iter`` = 2 iterations; ``tol = 0`` always runs
``max_iter`` iterations (docs/papers.md gives the run-time figures).  The draws for all
``max_iter`` iterations are taken from the Generator up front (one compiled call), so the random stream
advances by the same amount per integral whatever ``tol`` stops at.

Centred covariances (docs/algorithms.md, "Sigma-point filters on the INS").  Per iteration the
rule gives first and second moments about a *fixed* reference: in the time update the propagated nominal ``f(x_hat)``
(the image of the centre point), in the measurement update ``h(x_hat-)``; the points are error
vectors ``f(x ⊞ dX_i) ⊟ f(x)``, already small.  Those moments are averaged over the iterations,
and the covariance is formed once from the averages: ``P = M_bar - m_bar m_bar^T``.  This is
exact, not an approximation: for any fixed reference r,
``E[(y - mu)(y - mu)^T] = E[(y - r)(y - r)^T] - (mu - r)(mu - r)^T``, and since every
iteration's estimate is a linear functional of the integrand, the identity holds for the
averaged estimates too (centring each iteration on its own mean instead would not average to
this).  It is well conditioned because ``m_bar = mu - r`` is only the shift of the mean caused by
the nonlinearity, small against the spread: the subtraction loses about
``log10(1 + |m_bar|^2 / sd^2)`` digits, nothing in practice (the papers' raw form
``E[y y^T] - mu mu^T`` on positions in metres loses all of them).  The centre point is the
reference itself, so its error-space image is 0 by definition: it contributes nothing to the
moments about the reference whatever its (possibly large, negative) weight, and it is not
propagated.  Each iteration's own moments are exact for polynomials of degree <= 3, so on a
linear model the filter is the Kalman filter for every draw.  (With a negative centre weight
the estimate is not positive semi-definite by construction when f is strongly nonlinear; a
covariance that lost definiteness is repaired and counted like any sigma-point filter's,
``SIF.repairs``.)

References: J. Dunik, O. Straka, M. Simandl, "Stochastic integration filter", IEEE Trans.
Automatic Control 58(6):1561-1566, 2013 (paper 001's ref [13], a comparison filter);
docs/algorithms.md "Paper 001's comparison filters (AUKF, SIF)".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .base import Filter, register
from .linalg import symmetrise
from .protocols import Interval, Measurement, Model
from .sigma import factor
from .states import GaussianState, MeasurementPrediction, Prediction
from .stochastic import IterationAverage, StochasticIntegrationRule


@dataclass(frozen=True)
class SIFOptions:
    """``[filter.sif]``.

    max_iter : iterations of the SI rule per integral (the paper's N_max), >= 1.
    min_iter : iterations before the ``tol`` test may stop early, >= 2 (a standard error needs
        two values).
    tol : stop once the scaled standard error of every moment is <= tol (dimensionless, see
        the module docstring), default 1e-3; 0 = always ``max_iter``.
    seed : seed of the filter's Generator when none is passed in (``navpp.api.make_filter``
        passes one built from this seed, or from the run's ``--seed``).
    """

    max_iter: int = 10
    min_iter: int = 2
    tol: float = 1e-3
    seed: int = 0

    def __post_init__(self) -> None:
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            raise ValueError(f"max_iter must be an integer >= 1, got {self.max_iter!r}")
        if int(self.min_iter) != self.min_iter or self.min_iter < 2:
            raise ValueError(f"min_iter must be an integer >= 2, got {self.min_iter!r}")
        if not (np.isfinite(self.tol) and self.tol >= 0.0):
            raise ValueError(f"tol must be a finite number >= 0, got {self.tol!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")


def _scaled_error(se: list[np.ndarray], scales: list[np.ndarray]) -> float:
    """Largest ``|se| / scale`` over the moments (scale 0 only where se is 0 too)."""
    worst = 0.0
    for s, c in zip(se, scales):
        worst = max(worst, float(np.max(s / np.where(c > 0.0, c, 1.0))))
    return worst


def _sd(P_diag: np.ndarray) -> np.ndarray:
    sd: np.ndarray = np.sqrt(np.maximum(P_diag, 0.0))
    return sd


@register("sif")
class SIF(Filter):
    """Stochastic integration filter (see module docstring); ``self.rng`` drives every draw.

    Attributes: ``iterations`` (2,), the iterations of the last time and measurement updates;
    ``repairs``, covariances repaired by eigenvalue clipping.
    """

    paper = "paper 001 (comparison filter); Dunik, Straka & Simandl 2013"
    summary = "Stochastic integration filter: randomised 3rd-degree rule averaged over iterations."
    Options = SIFOptions
    #: exact on linear models for any draw: the defaults are the oracle options
    oracle_options: ClassVar[dict[str, Any]] = {}

    def __init__(self, options: Any = None, *, gate_probability: float = 0.0,
                 reanchor_after_s: float = 10.0, rng: np.random.Generator | None = None) -> None:
        options = options if options is not None else SIFOptions()
        super().__init__(options, gate_probability=gate_probability, reanchor_after_s=reanchor_after_s,
                         rng=rng if rng is not None else np.random.default_rng(options.seed))
        self.si_rule = StochasticIntegrationRule()
        self.iterations = np.zeros(2)
        self.repairs = 0

    def noise_report(self) -> dict[str, np.ndarray]:
        """Iterations of the last time and measurement updates (constant when ``tol = 0``)."""
        return {"si_iterations": self.iterations.copy()}

    def _done(self, acc: IterationAverage, scales: Callable[[], list[np.ndarray]]) -> bool:
        o: SIFOptions = self.options
        if acc.count >= o.max_iter:
            return True
        return o.tol > 0.0 and acc.count >= o.min_iter and _scaled_error(acc.standard_error(), scales()) <= o.tol

    def time_update(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        S = factor(state.P, state.t, self.name, self)
        n = S.shape[0]
        acc = IterationAverage()
        x_ref = state.x

        def scales() -> list[np.ndarray]:
            sd = _sd(np.diagonal(acc.mean[1]))
            return [sd, np.outer(sd, sd)]

        xis, ws = self.si_rule.draws(self.rng, n, self.options.max_iter)
        for xi, w in zip(xis, ws):
            # the centre point is the reference: its image f(x ⊞ 0) ⊟ f(x) is 0, not propagated
            dX = xi[1:] @ S.T
            x_ref, dY = model.propagate_points(state.x, dX, interval)
            wp = w[1:]
            Yw = dY * wp[:, None]
            # SR_j: moments about f(x_hat); the cross moment (last two) only for the smoother
            acc.add((wp @ dY, Yw.T @ dY, wp @ dX, (dX * wp[:, None]).T @ dY))
            if self._done(acc, scales):
                break
        mean, second, x_mean, cross = acc.mean
        self.iterations[0] = acc.count
        P = second - np.outer(mean, mean) + self.adapter.process_noise(model, state.x, interval)
        return Prediction(GaussianState(interval[1], model.plus(x_ref, mean), symmetrise(P)),
                          cross - np.outer(x_mean, mean), x_ref)

    def predict_measurement(self, state: GaussianState, model: Model, meas: Measurement) -> MeasurementPrediction:
        S = factor(state.P, state.t, self.name, self)
        n = S.shape[0]
        sd_x = _sd(np.diagonal(state.P))
        acc = IterationAverage()

        def scales() -> list[np.ndarray]:
            sd_z = _sd(np.diagonal(acc.mean[1]))
            return [sd_z, np.outer(sd_z, sd_z), sd_x, np.outer(sd_x, sd_z)]

        xis, ws = self.si_rule.draws(self.rng, n, self.options.max_iter)
        for xi, w in zip(xis, ws):
            dX = xi[1:] @ S.T
            Z = meas.predict_points(state.x, dX)                   # h(x ⊞ dX_i) ⊟ h(x); centre: 0
            wp = w[1:]
            Zw = Z * wp[:, None]
            acc.add((wp @ Z, Zw.T @ Z, wp @ dX, (dX * wp[:, None]).T @ Z))
            if self._done(acc, scales):
                break
        z_mean, zz, x_mean, xz = acc.mean
        self.iterations[1] = acc.count
        Pzz = zz - np.outer(z_mean, z_mean)                        # centred once, on the averages
        Pxz = xz - np.outer(x_mean, z_mean)
        nu = meas.innovation_at(state.x) - z_mean
        return MeasurementPrediction(nu, symmetrise(Pzz), Pxz, None)
