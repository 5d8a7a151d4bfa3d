"""What the filter core asks of a model and of a measurement.

A filter never looks inside a state: it moves between nominal states ``x`` and error vectors
``dx`` through the model's ⊞ / ⊟, propagates the nominal (with its linearisation, or with
points in the error space), and asks each measurement for its innovation, Jacobian and
point images.  These protocols are those calls; :class:`MeasurementBase` states the defaults
of the measurement attributes the update template honours.

Shapes: ``x`` (n_x,) nominal state; ``dx`` (n,) error state; ``dX`` (p, n) error points;
``interval = (t_start, t_end)`` in seconds; a measurement has m elements.
"""

from __future__ import annotations

from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

Interval = tuple[float, float]


class Model(Protocol):
    """A state-space model in the filter core's terms (the INS, the linear models, the papers'
    benchmark models)."""

    def plus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``x ⊞ dx``: the nominal state moved by the error vector ``dx``."""
        ...

    def minus(self, x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """``x1 ⊟ x0``: the error vector (n,) from ``x0`` to ``x1``."""
        ...

    def transition(self, x: np.ndarray, interval: Interval) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nominal propagation over ``interval``: ``(f(x), Phi (n, n), Qd (n, n))``."""
        ...

    def process_noise(self, x: np.ndarray, interval: Interval) -> np.ndarray:
        """Discrete process noise Qd (n, n) added over ``interval``."""
        ...

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval: Interval) -> tuple[np.ndarray, np.ndarray]:
        """``(f(x), f(x ⊞ dX_i) ⊟ f(x))``: the propagated nominal and the points' images (p, n)."""
        ...


@runtime_checkable
class GroupedNoiseModel(Model, Protocol):
    """A model whose process noise splits into named groups (variance component estimation).

    ``noise_share`` is what a group's redundancy is best measured on when VCE is left to
    choose (``q_share = "auto"``): ``"propagated"``, the group's whole share of the prior
    covariance (a noise that reaches the measurements through many time updates, as on the
    INS at the GNSS rate), or ``"step"``, the noise of the time updates since the last fix.
    """

    noise_share: ClassVar[str]

    def noise_groups(self, x: np.ndarray, interval: Interval, per: str) -> tuple[list[str], np.ndarray]:
        """``(names, Qs (G, n, n))`` with ``Qs.sum(0)`` the process noise over ``interval``.
        ``per`` selects a grouping where the model has several (the INS: ``"triad"`` or
        ``"axis"``); a model with one grouping ignores it."""
        ...


class SmoothableModel(Model, Protocol):
    """A model the RTS smoother can run on: the backward mean recursion over packed nodes."""

    def rts_means(self, x_post: np.ndarray, x_prior: np.ndarray, gains: np.ndarray,
                  reset: np.ndarray) -> np.ndarray:
        """Smoothed nominal states (M, n_x): ``xs[M-1] = x_post[M-1]``; for k = M-2 .. 0,
        ``xs[k] = x_post[k]`` where ``reset[k + 1]``, else
        ``x_post[k] ⊞ gains[k + 1] (xs[k + 1] ⊟ x_prior[k + 1])``."""
        ...


class Measurement(Protocol):
    """One measurement at time ``t`` (s) with noise covariance ``R`` (m, m).

    kind : name of the measurement type; runs of gate rejections are tracked per kind.
    axes : names of the m elements (reports label per-axis values with them; may be empty).
    adaptive : adaptive filters may adapt R to it and learn from it (False: R used as given).
    forceable : after ``reanchor_after_s`` of rejections the next one is forced through the gate.
    """

    t: float
    R: np.ndarray
    kind: ClassVar[str]
    axes: ClassVar[tuple[str, ...]]
    adaptive: ClassVar[bool]
    forceable: ClassVar[bool]

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        """``z ⊟ h(x)`` (m,)."""
        ...

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """``dh / d(dx)`` at ``x``, (m, n)."""
        ...

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) ⊟ h(x)`` for error points ``dX`` (p, n): (p, m)."""
        ...

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        """Covariance (n, n) to use when this measurement is forced through the gate (prior
        ``P``, innovation ``nu``, noise ``R``), or None: the filter inflates ``P`` itself."""
        ...


class MeasurementBase:
    """Defaults of the measurement attributes (see :class:`Measurement`): a GNSS-like fix that
    adaptive filters learn from and that is forced in after a run of rejections, with no
    re-anchoring of its own.  Subclasses state what differs."""

    kind: ClassVar[str] = ""
    axes: ClassVar[tuple[str, ...]] = ()
    adaptive: ClassVar[bool] = True
    forceable: ClassVar[bool] = True

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        """No re-anchoring of its own: the filter inflates P (see :class:`Measurement`)."""
        return None


__all__ = ["GroupedNoiseModel", "Interval", "Measurement", "MeasurementBase", "Model", "SmoothableModel"]
