"""The loop: one filter run over a schedule of epochs.

At each epoch the filter predicts from the current state to the epoch's time; at a coasting
stop that is all.  Otherwise the state is checked and the epoch's measurements are applied in
stages: the measurement source gives each stage's measurements from the state the previous
stages left (so an aid may depend on the posterior of the fix before it), and after each update
says which state to go on from (its own reset, e.g. a velocity re-aligned after a forced fix).
The recorder sees every step's result.  Only the filter's public steps are used:
:meth:`~navpp.filters.base.Filter.predict` returns a :class:`~navpp.filters.base.Prediction`,
:meth:`~navpp.filters.base.Filter.update` an :class:`~navpp.filters.base.Update`.

The same loop runs a log (:mod:`navpp.engine.run`) and a simulated Monte-Carlo run: for the
latter, epochs with ``t`` and ``coast = False``, a source that gives one stage with the epoch's
measurement, and a recorder that keeps what the benchmark scores.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from ..filters.base import Filter, GaussianState, Prediction, Update
from ..spill import Behind


class EpochLike(Protocol):
    """What the loop reads of an epoch: its time ``t`` (s) and whether it is a coasting stop
    (a time update only).  Sources and recorders may read more (:class:`navpp.engine.schedule.Epoch`)."""

    @property
    def t(self) -> float: ...

    @property
    def coast(self) -> bool: ...


E = TypeVar("E", bound=EpochLike, contravariant=True)


@dataclass(frozen=True)
class EpochOutcome:
    """What one measurement epoch did.

    prior : the state after the time update; state : after every update and the source's resets;
    prior_used : the prior the first applied update corrected (an adaptive filter may have
    changed it after the time update; None when no update was applied); applied : whether any
    update was applied; reset : whether an applied update re-anchored the covariance (forced).
    """

    prior: GaussianState
    state: GaussianState
    prior_used: GaussianState | None
    applied: bool
    reset: bool


class MeasurementSource(Protocol[E]):
    """The measurements of each epoch, in stages."""

    def measurements(self, epoch: E, stage: int, state: GaussianState) -> Sequence[Any] | None:
        """The measurements of stage ``stage`` (0, 1, ...) at ``epoch`` given the current
        ``state``; None when the epoch has no further stage."""
        ...

    def observed(self, epoch: E, meas: Any, update: Update) -> GaussianState:
        """What the update of ``meas`` did; returns the state to go on from (``update.state``,
        or a state the source resets)."""
        ...


class Recorder(Protocol[E]):
    """Receives every step's result."""

    def predicted(self, epoch: E, prediction: Prediction) -> None:
        """The time update to ``epoch`` (coasting stops included)."""
        ...

    def updated(self, epoch: E, meas: Any, update: Update) -> None:
        """One measurement update at ``epoch`` (after the source has seen it)."""
        ...

    def epoch_done(self, epoch: E, outcome: EpochOutcome) -> None:
        """All of ``epoch``'s measurements are applied (not called at coasting stops)."""
        ...


class StateCheck(Protocol):
    """Raises when a state must not be carried on (e.g. a non-finite covariance)."""

    def __call__(self, state: GaussianState, t: float) -> None: ...


class FastPath(Protocol):
    """Runs stretches of common epochs faster than the generic loop, with the same result
    (:class:`navpp.engine.fused.FusedRunner`)."""

    def run(self, i: int, state: GaussianState, stop: int) -> tuple[int, GaussianState, bool]:
        """Epochs ``i`` .. at most ``stop - 1`` of the run from ``state`` (the state before
        epoch ``i``); returns the first epoch it did not run (``i``: none), the state before it
        and whether that epoch is one it leaves to the generic loop (False: it cut the stretch
        short there, and may run that epoch when asked again)."""
        ...


def run_epochs(filt: Filter, model: Any, state: GaussianState, epochs: Iterable[E],
               source: MeasurementSource[E], recorder: Recorder[E], check: StateCheck | None = None,
               fast: FastPath | None = None) -> GaussianState:
    """Run ``filt`` on ``model`` from ``state`` over ``epochs`` (increasing times, after
    ``state.t``); returns the last state.  ``check`` (when given) sees the state after the time
    update of every measurement epoch and after every update.  A
    :class:`~navpp.errors.FilterDivergedError` of the filter or the check propagates.  ``fast``
    (built for this run's epochs, a sequence then) runs what it can; each epoch it leaves goes
    through :func:`epoch_step` at once (``fast`` tries each epoch once; a stretch it cuts short, at
    its buffer's length or a progress report, it goes on with when asked again).  The spilled IMU
    rows the run has passed leave memory (:class:`~navpp.spill.Behind`)."""
    ins = getattr(model, "ins", model)          # the INS under an augmented model
    behind = Behind(getattr(ins, "t", None), getattr(ins, "gyro", None), getattr(ins, "accel", None))
    if fast is None:
        for epoch in epochs:
            state = epoch_step(filt, model, epoch, state, source, recorder, check)
            behind(state.t)
        return state
    run = epochs if isinstance(epochs, Sequence) else list(epochs)
    i, n = 0, len(run)
    while i < n:
        j, state, leaves = fast.run(i, state, n)
        if leaves:
            state = epoch_step(filt, model, run[j], state, source, recorder, check)
            j += 1
        i = j
        behind(state.t)
    return state


def epoch_step(filt: Filter, model: Any, epoch: E, state: GaussianState, source: MeasurementSource[E],
               recorder: Recorder[E], check: StateCheck | None = None) -> GaussianState:
    """One epoch of :func:`run_epochs` from ``state``: the time update to ``epoch.t``, then (at a
    measurement epoch) the state check and :func:`measure`; returns the state after it."""
    prediction = filt.predict(state, model, (state.t, epoch.t))
    recorder.predicted(epoch, prediction)
    state = prediction.state
    if epoch.coast:
        return state
    if check is not None:
        check(state, epoch.t)
    return measure(filt, model, epoch, state, source, recorder, check)


def measure(filt: Filter, model: Any, epoch: E, prior: GaussianState, source: MeasurementSource[E],
            recorder: Recorder[E], check: StateCheck | None = None) -> GaussianState:
    """Apply the measurements of ``epoch``, stage by stage, to ``prior`` (the state after its
    time update); returns the state after them."""
    state, used, applied, reset = prior, None, False, False
    stage = 0
    while (batch := source.measurements(epoch, stage, state)) is not None:
        for meas in batch:
            update = filt.update(state, model, meas)
            if check is not None:
                check(update.state, epoch.t)
            if update.innovation.accepted:
                used = update.prior_used if not applied else used
                applied = True
                reset |= update.innovation.forced
            state = source.observed(epoch, meas, update)
            recorder.updated(epoch, meas, update)
        stage += 1
    recorder.epoch_done(epoch, EpochOutcome(prior, state, used, applied, reset))
    return state
