"""The filter core: immutable Gaussian states, innovation records, the filter template, registry.

A filter is a template with hooks (ARCHITECTURE.md, "The filter core"):

- :meth:`Filter.predict` (abstract): time update over an ``interval = (t_start, t_end)``.
- :meth:`Filter.update` (template): :meth:`predict_measurement` (Jacobian or points) ->
  :meth:`measurement_noise` (fixed R, or an adaptive estimate) -> chi-square gate ->
  :meth:`correct` (shared: Cholesky solves, Joseph form, symmetrised P) ->
  :meth:`after_update` (adaptive filters learn from the :class:`Innovation`).

Models supply ``plus``/``minus`` (⊞/⊟ between states and error vectors), ``transition``
(nominal propagation with Phi and Qd) and ``propagate_points``; measurements supply
``innovation_at``, ``jacobian``, ``predict_points`` and ``R``.  A variant is a small subclass,
registered by name with :func:`register`.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import njit
from scipy.special import chdtri

from ..errors import ConfigError, FilterDivergedError


@dataclass(frozen=True)
class GaussianState:
    """A filter state at time ``t`` (s): model state ``x`` and error covariance ``P`` (n, n)."""

    t: float
    x: np.ndarray
    P: np.ndarray


@dataclass(frozen=True)
class Innovation:
    """What one measurement update saw and did.

    nu : (m,) innovation ``z ⊟ ẑ``; S : (m, m) its covariance incl. R; Pxz : (n, m);
    R : (m, m) measurement noise used; nis : ``nu^T S^-1 nu``; accepted : applied to the state;
    forced : applied although it failed the gate (after ``reanchor_after_s`` of rejections,
    with the covariance re-anchored first; ``nis`` is the value before re-anchoring).
    """

    t: float
    nu: np.ndarray
    S: np.ndarray
    Pxz: np.ndarray
    R: np.ndarray
    nis: float
    accepted: bool
    forced: bool = False


@dataclass(frozen=True)
class MeasurementPrediction:
    """Predicted-measurement moments before R is added.

    nu : (m,) innovation; Pzz : (m, m) predicted-measurement covariance without R;
    Pxz : (n, m) state-measurement cross-covariance; H : (m, n) Jacobian when the filter is
    linearised (enables the Joseph form), else None.
    """

    nu: np.ndarray
    Pzz: np.ndarray
    Pxz: np.ndarray
    H: np.ndarray | None = None


@dataclass(frozen=True)
class Prediction:
    """What a time update produced.

    state : the prior at the interval's end; cross_cov : (n, n) cross-covariance
    ``E[dx_start dx_end^T]`` of the errors at the interval's start (the input state) and end
    (the prior), for RTS smoothing (:mod:`navpp.filters.smoother`); x_ref : the nominal state
    the model propagated over the interval (the path it recorded).
    """

    state: GaussianState
    cross_cov: np.ndarray
    x_ref: np.ndarray


@dataclass(frozen=True)
class Update:
    """What a measurement update produced.

    state : the posterior (the input state when the measurement was rejected); innovation :
    what the update saw and did; prior_used : the prior the correction was applied to (an
    adaptive filter may have changed it after the time update, a forced fix re-anchors it),
    None when the measurement was rejected.
    """

    state: GaussianState
    innovation: Innovation
    prior_used: GaussianState | None


@dataclass(frozen=True)
class NoOptions:
    """A filter without options of its own."""


FILTERS: dict[str, type[Filter]] = {}


def register(name: str):
    """Class decorator adding a filter to :data:`FILTERS` under ``name``."""
    def deco(cls: type[Filter]) -> type[Filter]:
        cls.name = name
        FILTERS[name] = cls
        return cls
    return deco


def get_filter(name: str) -> type[Filter]:
    """The filter class registered as ``name``; ConfigError listing the choices otherwise."""
    try:
        return FILTERS[name]
    except KeyError:
        raise ConfigError(f"unknown filter {name!r}; choose one of: {', '.join(sorted(FILTERS))}") from None


def symmetrise(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)


@njit(cache=True)
def _chol_solve(L, B):
    """Solve ``(L L^T) X = B`` for lower-triangular ``L`` (m, m), ``B`` (m, k)."""
    m, k = B.shape
    Y = np.empty((m, k))
    for c in range(k):
        for i in range(m):
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * Y[j, c]
            Y[i, c] = s / L[i, i]
        for i in range(m - 1, -1, -1):
            s = Y[i, c]
            for j in range(i + 1, m):
                s -= L[j, i] * Y[j, c]
            Y[i, c] = s / L[i, i]
    return Y


@njit(cache=True)
def _cholesky(S):
    """Lower Cholesky factor of ``S`` and whether ``S`` is (numerically) positive definite."""
    m = S.shape[0]
    L = np.zeros((m, m))
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:            # also catches NaN
            return L, False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, m):
            v = S[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / L[j, j]
    return L, True


@njit(cache=True)
def _gain_and_nis(Pxz, S, nu):
    """Kalman gain ``K = Pxz S^-1`` and ``nis = nu^T S^-1 nu`` by Cholesky solves; ``ok`` is
    False when S is not positive definite (K and nis are then meaningless)."""
    L, ok = _cholesky(S)
    if not ok:
        return np.zeros_like(Pxz), np.inf, False
    Kt = _chol_solve(L, np.ascontiguousarray(Pxz.T))
    w = _chol_solve(L, nu.reshape(-1, 1))[:, 0].copy()
    return Kt.T.copy(), float(nu @ w), True


@njit(cache=True)
def _joseph(P, K, H, R):
    I_KH = np.eye(P.shape[0]) - K @ H
    Pn = I_KH @ P @ I_KH.T + K @ R @ K.T
    return 0.5 * (Pn + Pn.T)


@njit(cache=True)
def _sigma_posterior(P, K, S):
    Pn = P - K @ S @ K.T
    return 0.5 * (Pn + Pn.T)


class Filter:
    """Template for every navpp filter (see module docstring).

    Parameters
    ----------
    options : the filter's own ``Options`` dataclass (``[filter.<name>]`` in the config).
    gate_probability : chi-square gate on the NIS; 0 disables gating.
    reanchor_after_s : when every measurement has failed the gate for this long (s), the next
        one is accepted with the covariance re-anchored on it (a filter must not lock itself
        out); shorter bursts of outliers are rejected whole.
    rng : the only source of randomness for random filters.
    """

    name: ClassVar[str] = ""
    paper: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    Options: ClassVar[type] = NoOptions
    #: options under which the filter is the plain Kalman filter (adaptation off): the oracle
    #: tests run every registered filter with these against the closed-form update
    oracle_options: ClassVar[dict[str, Any]] = {}

    def __init__(self, options: Any = None, *, gate_probability: float = 0.0,
                 reanchor_after_s: float = 10.0, rng: np.random.Generator | None = None) -> None:
        self.options = options if options is not None else self.Options()
        self.gate_probability = float(gate_probability)
        self.reanchor_after_s = float(reanchor_after_s)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._gate_cache: dict[int, float] = {}
        self._rejecting_since: dict[str, float] = {}     # measurement kind -> first rejection of the run
        self.rejected = 0

    @classmethod
    def options_from_mapping(cls, data: Mapping[str, Any] | None, source: str = "config") -> Any:
        """Build ``Options`` from a ``[filter.<name>]`` table; unknown keys name the nearest one."""
        data = dict(data or {})
        fields = {f.name: f for f in dataclasses.fields(cls.Options)}
        for key in data:
            if key not in fields:
                near = difflib.get_close_matches(key, list(fields), n=1)
                hint = f"; did you mean {near[0]!r}?" if near else (
                    f"; valid keys: {', '.join(fields)}" if fields else "; this filter has no options")
                raise ConfigError(f"{source}: unknown key {key!r} in [filter.{cls.name}]{hint}")
        try:
            return cls.Options(**data)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: [filter.{cls.name}]: {exc}") from None

    # hooks -------------------------------------------------------------------------------
    def predict(self, state: GaussianState, model: Any, interval: tuple[float, float]) -> Prediction:
        raise NotImplementedError

    def predict_measurement(self, state: GaussianState, model: Any, meas: Any) -> MeasurementPrediction:
        raise NotImplementedError

    def adjust_prediction(self, pred: MeasurementPrediction) -> MeasurementPrediction:
        """Hook: e.g. remove an estimated measurement-noise mean from the innovation."""
        return pred

    def measurement_noise(self, meas: Any, pred: MeasurementPrediction) -> np.ndarray:
        """R to use for this update; adaptive filters override."""
        return meas.R

    def process_noise(self, model: Any, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        """Additive process noise Qd over ``interval`` for sigma-point time updates; adaptive
        filters (VCE) override to rescale the model's noise groups."""
        return model.process_noise(x, interval)

    def noise_report_labels(self) -> dict[str, list[str]]:
        """Names of the elements of :meth:`noise_report` entries that have several (e.g. VCE's
        noise groups); entries without labels are numbered."""
        return {}

    def noise_report(self) -> dict[str, np.ndarray]:
        """What an adaptive filter has decided so far (e.g. VCE group factors), recorded by the
        engine after every GNSS epoch: name -> 1-D array, fixed length per name.  The R used is
        recorded separately from the :class:`Innovation`."""
        return {}

    def after_update(self, innovation: Innovation, pred: MeasurementPrediction) -> None:
        """Called after every gated update; adaptive filters learn here."""

    # template ----------------------------------------------------------------------------
    def gate_threshold(self, m: int) -> float:
        if self.gate_probability <= 0.0:
            return np.inf
        thr = self._gate_cache.get(m)
        if thr is None:
            thr = self._gate_cache[m] = float(chdtri(m, 1.0 - self.gate_probability))  # chi2 quantile
        return thr

    def update(self, state: GaussianState, model: Any, meas: Any) -> Update:
        """Gate and apply one measurement.

        Measurement attributes the template honours (defaults for the GNSS position):
        ``adaptive`` (True): adaptive filters may adapt R to it and learn from it (False for
        the aids of :mod:`navpp.ins.aids`, whose R is used as given); ``forceable`` (True): after
        ``reanchor_after_s`` of rejections the next one is forced in; ``kind``: rejection runs
        are tracked per kind, so a rejected ZUPT does not count towards a GNSS re-anchoring.
        """
        adaptive = getattr(meas, "adaptive", True)
        kind = getattr(meas, "kind", "")
        pred = self.predict_measurement(state, model, meas)
        if adaptive:
            pred = self.adjust_prediction(pred)
        R = self.measurement_noise(meas, pred) if adaptive else meas.R
        S, K, nis = self._moments(state, pred, R)
        accepted = nis <= self.gate_threshold(pred.nu.shape[0])
        forced = False
        since = self._rejecting_since.get(kind)
        if (not accepted and since is not None and getattr(meas, "forceable", True)
                and state.t - since >= self.reanchor_after_s):
            # Rejections for that long mean the prior, not the measurements, is wrong: never
            # lock the GNSS out. Re-anchor the covariance on this measurement, then apply it.
            forced = accepted = True
            state = GaussianState(state.t, state.x, self._reanchored(state, meas, pred, R, nis))
            pred = self.predict_measurement(state, model, meas)
            if adaptive:
                pred = self.adjust_prediction(pred)
            S, K, _ = self._moments(state, pred, R)
        innovation = Innovation(state.t, pred.nu, S, pred.Pxz, R, nis, accepted, forced)
        if not accepted:
            self._rejecting_since.setdefault(kind, state.t)
            self.rejected += 1
            return Update(state, innovation, None)
        self._rejecting_since.pop(kind, None)
        new, prior_used = self.correct(state, model, pred, K, S, R)
        if adaptive:
            self.after_update(innovation, pred)
        return Update(new, innovation, prior_used)

    def _moments(self, state: GaussianState, pred: MeasurementPrediction, R: np.ndarray):
        S = symmetrise(pred.Pzz + R)
        K, nis, ok = _gain_and_nis(pred.Pxz, S, pred.nu)
        if not ok:
            raise FilterDivergedError(
                f"{self.name}: innovation covariance is not positive definite at t={state.t:.3f} s")
        return S, K, nis

    def _reanchored(self, state: GaussianState, meas: Any, pred: MeasurementPrediction, R: np.ndarray,
                    nis: float) -> np.ndarray:
        """Covariance to use for a forced update: the measurement's own re-anchoring when it has
        one (GNSS position: the position block restarts from the innovation), else P inflated so
        that the innovation sits on the gate."""
        reanchor = getattr(meas, "reanchor", None)
        if reanchor is not None:
            return reanchor(state.P, pred.nu, R)
        return state.P * max(1.0, nis / self.gate_threshold(pred.nu.shape[0]))

    def correct(self, state: GaussianState, model: Any, pred: MeasurementPrediction,
                K: np.ndarray, S: np.ndarray, R: np.ndarray) -> tuple[GaussianState, GaussianState]:
        """Shared correction: ``x ⊞ K nu``; Joseph form when linearised, else ``P - K S K^T``.
        Returns the posterior and the prior it was corrected from."""
        x = model.plus(state.x, K @ pred.nu)
        P = _joseph(state.P, K, pred.H, R) if pred.H is not None else _sigma_posterior(state.P, K, S)
        if not (np.isfinite(x.sum()) and np.isfinite(P.sum())):
            raise FilterDivergedError(f"{self.name}: state became non-finite at t={state.t:.3f} s")
        return GaussianState(state.t, x, P), state
