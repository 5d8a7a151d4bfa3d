"""A simulated run as the engine's loop (:func:`navpp.engine.loop.run_epochs`) takes it: one
measurement epoch per simulated measurement, a source that hands the loop that measurement,
and a recorder base whose steps do nothing until a benchmark's recorder overrides them.

The papers' benchmarks run their filters through this loop, the one that runs a log, so a
benchmark exercises the same predict / update sequence as ``navpp process``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..engine.loop import EpochOutcome
from ..engine.schedule import Epoch
from ..filters import GaussianState, Prediction, Update


def measurement_epochs(times: Sequence[float] | np.ndarray) -> list[Epoch]:
    """One measurement epoch per time of ``times`` (s, increasing); ``Epoch.index`` is the
    position in ``times`` (the index of the run's measurement at that time)."""
    return [Epoch(float(t), index=k) for k, t in enumerate(times)]


@dataclass(frozen=True)
class OneMeasurementPerEpoch:
    """The measurement source of a simulated run: at the epoch of ``index`` k, one stage holding
    ``per_epoch[k]``; the state goes on from each update's posterior."""

    per_epoch: Sequence[Any]

    def measurements(self, epoch: Epoch, stage: int, state: GaussianState) -> Sequence[Any] | None:
        """``[per_epoch[epoch.index]]`` at stage 0; None after it."""
        return [self.per_epoch[epoch.index]] if stage == 0 else None

    def observed(self, epoch: Epoch, meas: Any, update: Update) -> GaussianState:
        """The update's posterior (a simulated run resets nothing)."""
        return update.state


class Recorder:
    """A recorder that keeps nothing: the loop's three calls as no-ops, for a benchmark's
    recorder to override the ones it needs."""

    def predicted(self, epoch: Epoch, prediction: Prediction) -> None:
        """The time update to ``epoch``."""

    def updated(self, epoch: Epoch, meas: Any, update: Update) -> None:
        """One measurement update at ``epoch``."""

    def epoch_done(self, epoch: Epoch, outcome: EpochOutcome) -> None:
        """The epoch's measurement is applied; ``outcome.state`` is the posterior."""
