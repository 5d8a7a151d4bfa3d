"""What filter steps take and return: Gaussian states, measurement predictions, innovation
records, and the results of a time update (:class:`Prediction`) and of a measurement update
(:class:`Update`).  Frozen: a step makes new arrays and never changes its inputs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


__all__ = ["GaussianState", "Innovation", "MeasurementPrediction", "Prediction", "Update"]
