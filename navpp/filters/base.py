"""The filter template and the registry of filters.

A filter writes two steps, :meth:`Filter.time_update` (predict over ``interval = (t_start,
t_end)``) and :meth:`Filter.predict_measurement` (Jacobian or points), and gets the rest from
the template:

- :meth:`Filter.predict`: the time update, then the adaptation's ``predicted`` step;
- :meth:`Filter.update`: measurement prediction -> R (the adaptation's, or the measurement's
  own) -> the adaptation's ``prepare`` -> chi-square gate (forcing a fix in after a run of
  rejections) -> the shared correction (Cholesky solves; Joseph form when linearised) -> the
  adaptation's ``corrected`` step.

Adaptive variants are the same filter with an adaptation object (:mod:`navpp.filters.adaptation`)
from :meth:`Filter.make_adapter`; a variant is registered by name with :func:`register`.
Models and measurements are the protocols of :mod:`navpp.filters.protocols`.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np

from ..chi2 import chdtri
from ..errors import ConfigError, FilterDivergedError
from .adaptation import Adaptation, Predictor
from .linalg import all_finite, innovation_gain, joseph_correction, sigma_posterior, symmetrise
from .protocols import Interval, Measurement, Model
from .states import GaussianState, Innovation, MeasurementPrediction, Prediction, Update


@dataclass(frozen=True)
class NoOptions:
    """A filter without options of its own."""


FILTERS: dict[str, type[Filter]] = {}

F = TypeVar("F", bound="type[Filter]")


def register(name: str) -> Callable[[F], F]:
    """Class decorator adding a filter to :data:`FILTERS` under ``name``."""
    def deco(cls: F) -> F:
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


class Filter:
    """Template for every navpp filter (see module docstring).

    Parameters
    ----------
    options : the filter's own ``Options`` dataclass (``[filter.<name>]`` in the config).
    gate_probability : chi-square gate on the NIS; 0 disables gating.
    reanchor_after_s : when every measurement of a kind has failed the gate for this long (s),
        the next forceable one is accepted with the covariance re-anchored on it (a filter must
        not lock itself out); shorter bursts of outliers are rejected whole.
    rng : the only source of randomness for random filters.

    Attributes
    ----------
    adapter : the adaptation (:class:`~navpp.filters.adaptation.Adaptation`), from
        :meth:`make_adapter`.
    rejected : measurements rejected by the gate so far.
    """

    name: ClassVar[str] = ""
    paper: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    Options: ClassVar[type[Any]] = NoOptions
    #: options under which the filter is the plain Kalman filter (adaptation off): the oracle
    #: tests run every registered filter with these against the closed-form update
    oracle_options: ClassVar[dict[str, Any]] = {}
    #: the update moves the mean by a random amount the covariance does not carry (random
    #: weights): long-memory states such as the Gauss-Markov GNSS error accumulate it, so the
    #: engine's ``error_model = "auto"`` does not add them to such a filter (docs/ins.md)
    random_mean: ClassVar[bool] = False

    def __init__(self, options: Any = None, *, gate_probability: float = 0.0,
                 reanchor_after_s: float = 10.0, rng: np.random.Generator | None = None) -> None:
        self.options = options if options is not None else self.Options()
        self.gate_probability = float(gate_probability)
        self.reanchor_after_s = float(reanchor_after_s)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._gate_cache: dict[int, float] = {}
        self._rejecting_since: dict[str, float] = {}     # measurement kind -> first rejection of the run
        self.rejected = 0
        self.adapter = self.make_adapter()

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

    # the steps a variant writes -------------------------------------------------------------
    def make_adapter(self) -> Adaptation:
        """The adaptation this filter runs with (none by default)."""
        return Adaptation()

    def time_update(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        """Propagate ``state`` over ``interval`` (its end is the prior's time)."""
        raise NotImplementedError

    def predict_measurement(self, state: GaussianState, model: Model, meas: Measurement) -> MeasurementPrediction:
        """Predicted-measurement moments of ``meas`` about ``state`` (before R)."""
        raise NotImplementedError

    # reports --------------------------------------------------------------------------------
    @property
    def adapts_noise(self) -> bool:
        """Whether the filter chooses its noise (R, or Q and R) as it runs."""
        return self.adapter.adapts_noise

    def noise_report(self) -> dict[str, np.ndarray]:
        """What an adaptive filter has decided so far (e.g. VCE group factors), recorded by the
        engine after every GNSS epoch: name -> 1-D array, fixed length per name.  The R used is
        recorded separately from the :class:`Innovation`."""
        return self.adapter.report()

    def noise_report_labels(self) -> dict[str, list[str]]:
        """Names of the elements of :meth:`noise_report` entries that have several (e.g. VCE's
        noise groups); entries without labels are numbered."""
        return self.adapter.labels()

    # template -------------------------------------------------------------------------------
    def predict(self, state: GaussianState, model: Model, interval: Interval) -> Prediction:
        """Time update over ``interval``: the prior at its end, the cross-covariance and the
        propagated nominal (:class:`Prediction`)."""
        out = self.time_update(state, model, interval)
        self.adapter.predicted(state, out)
        return out

    def update(self, state: GaussianState, model: Model, meas: Measurement) -> Update:
        """Gate and apply one measurement (:meth:`apply_measurement` with this filter's
        measurement prediction)."""
        def predictor(prior: GaussianState) -> MeasurementPrediction:
            return self.predict_measurement(prior, model, meas)
        return self.apply_measurement(state, model, meas, predictor)

    def gate_threshold(self, m: int) -> float:
        """NIS threshold of an m-element measurement: the chi-square(m) quantile
        ``gate_probability``; inf without a gate."""
        if self.gate_probability <= 0.0:
            return np.inf
        thr = self._gate_cache.get(m)
        if thr is None:
            thr = self._gate_cache[m] = float(chdtri(m, 1.0 - self.gate_probability))  # chi2 quantile
        return thr

    def apply_measurement(self, state: GaussianState, model: Model, meas: Measurement,
                          predictor: Predictor) -> Update:
        """Gate and apply ``meas`` to ``state``, predicting it with ``predictor``.

        The measurement's attributes (:class:`~navpp.filters.protocols.Measurement`):
        ``adaptive`` False: R is used as given; ``forceable``: after ``reanchor_after_s`` of
        rejections of its ``kind`` the next one is forced in, with the covariance re-anchored.
        """
        raw = predictor(state)
        R = self.adapter.measurement_noise(meas, raw) if meas.adaptive else meas.R
        gate = self.gate_threshold(raw.nu.shape[0])
        prior, pred = self.adapter.prepare(state, meas, raw, R, gate, predictor)
        S, K, nis = self._moments(prior, pred, R)
        accepted = nis <= gate
        forced = False
        since = self._rejecting_since.get(meas.kind)
        if (not accepted and since is not None and meas.forceable
                and state.t - since >= self.reanchor_after_s):
            # Rejections for that long mean the prior, not the measurements, is wrong: never
            # lock the GNSS out. Re-anchor the covariance on this measurement, then apply it.
            forced = accepted = True
            state = GaussianState(state.t, state.x, self._reanchored(state, meas, pred, R, nis))
            raw = predictor(state)
            prior, pred = self.adapter.prepare(state, meas, raw, R, gate, predictor)
            S, K, _ = self._moments(prior, pred, R)
        innovation = Innovation(state.t, pred.nu, S, pred.Pxz, R, nis, accepted, forced)
        if not accepted:
            self._rejecting_since.setdefault(meas.kind, state.t)
            self.rejected += 1
            return Update(state, innovation, None)
        self.accepted(meas.kind)
        posterior = self._correct(prior, model, pred, K, S, R)
        self.adapter.corrected(prior, raw, innovation, meas)
        return Update(posterior, innovation, prior)

    def accepted(self, kind: str) -> None:
        """A measurement of ``kind`` passed the gate: its run of rejections (if any) is over."""
        self._rejecting_since.pop(kind, None)

    def rejecting_since(self, kind: str) -> float | None:
        """When the current run of gate rejections of ``kind`` began (s; None: its last
        measurement passed, or none was gated yet)."""
        return self._rejecting_since.get(kind)

    def gated(self, kind: str, n_rejected: int, since: float | None) -> None:
        """Measurements of ``kind`` gated outside :meth:`update` (the loop's compiled path,
        :mod:`navpp.engine.fused`), none forced: ``n_rejected`` of them rejected, and the current
        run of rejections began at ``since`` (s; None: the last one passed)."""
        self.rejected += n_rejected
        if since is None:
            self.accepted(kind)
        else:
            self._rejecting_since[kind] = since

    def _moments(self, state: GaussianState, pred: MeasurementPrediction,
                 R: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Innovation covariance ``S = Pzz + R``, gain and NIS; divergence when S is not
        positive definite."""
        S, K, nis, ok = innovation_gain(pred.Pzz, R, pred.Pxz, pred.nu)
        if not ok:
            raise FilterDivergedError.in_filter(
                self.name, f"innovation covariance is not positive definite at t={state.t:.3f} s")
        return S, K, nis

    def _reanchored(self, state: GaussianState, meas: Measurement, pred: MeasurementPrediction, R: np.ndarray,
                    nis: float) -> np.ndarray:
        """Covariance to use for a forced update: the measurement's own re-anchoring when it has
        one (GNSS position: the position block restarts from the innovation), else P inflated so
        that the innovation sits on the gate."""
        P = meas.reanchor(state.P, pred.nu, R)
        if P is not None:
            return P
        return state.P * max(1.0, nis / self.gate_threshold(pred.nu.shape[0]))

    def _correct(self, state: GaussianState, model: Model, pred: MeasurementPrediction,
                 K: np.ndarray, S: np.ndarray, R: np.ndarray) -> GaussianState:
        """The posterior: ``x ⊞ K nu``; Joseph form when linearised, else ``P - K S K^T``."""
        if pred.H is not None:
            dx, P = joseph_correction(state.P, K, pred.H, R, pred.nu)
        else:
            dx, P = K @ pred.nu, sigma_posterior(state.P, K, S)
        x = model.plus(state.x, dx)
        if not all_finite(x, P):
            raise FilterDivergedError.in_filter(self.name, f"state became non-finite at t={state.t:.3f} s")
        return GaussianState(state.t, x, P)


__all__ = ["FILTERS", "Filter", "GaussianState", "Innovation", "MeasurementPrediction", "NoOptions",
           "Prediction", "Update", "get_filter", "register", "symmetrise"]
