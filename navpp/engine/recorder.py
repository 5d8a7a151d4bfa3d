"""The recorder of a run: it owns every output array the loop fills.

Per GNSS fix: the innovation, NIS, gate decision, forced flag, the noise the filter used, what
an adaptive filter decided, the biases and their 1-sigma, the GNSS velocity's innovation.  Per
stop: the position variance knots of the output's 1-sigma.  With smoothing: the forward run's
nodes (:class:`~navpp.filters.smoother.ForwardStore`).  At the IMU rate: the nominal path
(:func:`new_path`), which the model writes while it propagates and the recorder overwrites with
the posterior at a sample that is an epoch.
"""

from __future__ import annotations

from array import array
from collections.abc import Callable
from typing import Any

import numpy as np

from ..filters.base import GaussianState, Prediction, Update
from ..filters.smoother import DEFAULT_BUDGET_BYTES, ForwardStore
from ..ins.model import ATT, BA, BG, POS, VEL
from ..ins.strapdown import NOMINAL_BA, NOMINAL_BG, PATH_SIZE
from ..spill import empty_rows, full_rows, release_all, release_before, spilled
from .loop import EpochOutcome
from .results import BiasHistory, Diagnostics
from .schedule import Epoch, GnssFixes

#: one-element aids recorded at the GNSS epochs: kind -> the short name of their columns
#: (``nu_<name>``, ``nis_<name>``, ``<name>_accepted``)
AID_COLUMNS = {"odometer": "odo", "odometer_yaw": "yaw"}
#: the error-state elements whose variance each knot records: attitude, velocity, position (ENU)
KNOT = slice(ATT.start, POS.stop)
_KNOT_N = KNOT.stop - KNOT.start
assert (ATT.stop, VEL.start, VEL.stop, POS.start) == (3, 3, 6, 6) and _KNOT_N == 9
#: doubles per knot record: the time, then the prior and the posterior variances
_KNOT_DOUBLES = 1 + 2 * _KNOT_N
#: knot records a run beside a spilled path holds in memory before they go to a spill file
#: (8-hour log: 23 MB of knots)
KNOT_CHUNK = 1 << 14
#: the gyro then accelerometer biases, adjacent in the nominal and in the error state: each
#: recorded per fix in one copy
BIASES_X = slice(NOMINAL_BG.start, NOMINAL_BA.stop)
BIASES_DX = slice(BG.start, BA.stop)
assert (NOMINAL_BG.stop, BG.stop) == (NOMINAL_BA.start, BA.start)

ProgressFn = Callable[[float], None]   # called with the fraction done, 0..1


#: bytes per IMU sample of a run's output: the (N, PATH_SIZE) float64 path, the float32 position,
#: velocity and attitude 1-sigma (N, 3) each, the float64 body rate (N, 3)
OUTPUT_ROW_BYTES = PATH_SIZE * 8 + 3 * 3 * 4 + 3 * 8


def new_path(n_samples: int, budget_bytes: int | None = None) -> np.ndarray:
    """The IMU-rate nominal path of a run: (N, PATH_SIZE) rows ``(q_nb, vel_enu, lat, lon, h)``,
    NaN until written (:class:`~navpp.ins.model.InsModel` writes it while propagating); on a
    spill file (:mod:`navpp.spill`, and the output arrays made from it with it) when the
    run's IMU-rate output, :data:`OUTPUT_ROW_BYTES` per sample, exceeds
    ``budget_bytes`` (``[output] memory``; None: never)."""
    spill = budget_bytes is not None and n_samples * OUTPUT_ROW_BYTES > budget_bytes
    return full_rows(n_samples, (PATH_SIZE,), np.nan, spill)


class RunRecorder:
    """What one run records (see the module docstring); a
    :class:`~navpp.engine.loop.Recorder` of :class:`~navpp.engine.schedule.Epoch`.

    Parameters
    ----------
    fixes : the run's GNSS fixes (the per-fix arrays have their length).
    path : the IMU-rate path (:func:`new_path`), the one the model writes.
    start : the start state; ``start_sample`` its IMU sample (its path row is written here).
    noise_report : the filter's :meth:`~navpp.filters.base.Filter.noise_report`, read after each fix.
    velocity : whether the run has GNSS velocity measurements.
    smooth : keep the forward run for smoothing; ``store_bytes`` the memory its store may hold
        before it spills to a temporary file (``[output] memory``).
    progress, n_epochs : called with the fraction of the ``n_epochs`` measurement epochs done.
    """

    def __init__(self, fixes: GnssFixes, path: np.ndarray, start: GaussianState, start_sample: int,
                 noise_report: Callable[[], dict[str, np.ndarray]], *, velocity: bool, smooth: bool,
                 store_bytes: int = DEFAULT_BUDGET_BYTES,
                 progress: ProgressFn | None = None, n_epochs: int = 1,
                 extra_states: list[tuple[str, int, int]] | None = None, aids: tuple[str, ...] = ()) -> None:
        m = len(fixes)
        self.path = path
        self.n_path = path.shape[1]
        path[start_sample] = start.x[:self.n_path]
        # the per-fix records of more than a few values a fix go on spill files beside a spilled
        # path (8-hour log: 42 MB), their rows released behind the run (:meth:`_released_before`)
        self.spill = spill = spilled(path)
        self.fix_t = fixes.t           # the fixes' times, s, increasing
        self.nu = full_rows(m, (3,), np.nan, spill)
        self.nis = np.full(m, np.nan)
        self.accepted = np.zeros(m, bool)
        self.forced = np.zeros(m, bool)
        # each fix's innovation covariance and R as the filter had them
        self.s_used = full_rows(m, (3, 3), np.nan, spill)
        self.r_used = full_rows(m, (3, 3), np.nan, spill)
        self.adaptive: dict[str, np.ndarray] = {}
        self.bias = empty_rows(m, (6,), np.float64, spill, "per-fix biases")
        self.bias_var = empty_rows(m, (6,), np.float64, spill, "per-fix biases")
        # the model's extra states after each fix (the GNSS error, ENU m; the odometer's scale) and
        # their variance: (label, error index, nominal index) each
        self.extra = list(extra_states or [])
        self.extra_values = np.full((m, 2 * len(self.extra)), np.nan) if self.extra else None
        # GNSS velocity: innovation (M, 3) m/s, NIS (M,), applied (M,: 1, 0, NaN without one)
        self.vel = (np.full((m, 3), np.nan), np.full(m, np.nan), np.full(m, np.nan)) if velocity else None
        # one-element aids' updates at a GNSS epoch, by kind (AID_COLUMNS): innovation (M,), NIS,
        # applied (1, 0, NaN without one)
        self.aids = {kind: (np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)) for kind in aids}
        self.noise_report = noise_report
        self.t = start.t            # time of the last state the loop made, s
        # covariance knots for the output's 1-sigma: flat (t, prior E/N/U variance, posterior E/N/U
        # variance) records, one per stop; long gaps between fixes get coasting stops.  Beside a
        # spilled path, every KNOT_CHUNK records move to a spill file of their own (knot_chunks)
        self.knots = array("d")
        self.knot_chunks: list[np.ndarray] = []
        self._chunk_doubles = KNOT_CHUNK * _KNOT_DOUBLES if spill else None
        self.store: ForwardStore | None = None
        self.epoch_node = np.zeros(m, np.int64)       # the smoother's node of each GNSS epoch
        if smooth:
            self.store = ForwardStore(start.P.shape[0], start.x.shape[0], budget_bytes=store_bytes)
            self.store.start(start)
        self.progress, self.n_epochs = progress, n_epochs
        self.tick = max(1, n_epochs // 200)
        self.knot(start)

    def knot(self, state: GaussianState, prior: GaussianState | None = None) -> None:
        """A knot at ``state.t``: attitude, velocity and position variance (:data:`KNOT`) before
        (``prior``'s, default the state's) and after (appended as the doubles' bytes: a fraction
        of the cost of extending by array elements)."""
        v = state.P.diagonal()[KNOT].tobytes()
        self.knots.append(state.t)
        self.knots.frombytes(v if prior is None else prior.P.diagonal()[KNOT].tobytes())
        self.knots.frombytes(v)
        if self._chunk_doubles is not None and len(self.knots) >= self._chunk_doubles:
            self._spilled_knots()

    def _spilled_knots(self) -> None:
        """The knot records in memory onto a spill file of their own (:attr:`knot_chunks`), its
        pages released (a run beside a spilled path: the knots' memory stays a chunk's)."""
        rows = np.frombuffer(self.knots, dtype=float).reshape(-1, _KNOT_DOUBLES)
        chunk = empty_rows(rows.shape[0], (_KNOT_DOUBLES,), np.float64, True, "covariance knots")
        chunk[:] = rows
        release_all(chunk)
        self.knot_chunks.append(chunk)
        del rows
        self.knots = array("d")

    # the loop's Recorder -------------------------------------------------------------------
    def predicted(self, epoch: Epoch, prediction: Prediction) -> None:
        self.t = prediction.state.t
        if self.store is not None:
            self.store.predicted(prediction)
        if epoch.coast:
            self.knot(prediction.state)

    def updated(self, epoch: Epoch, meas: Any, update: Update) -> None:
        k, inn = epoch.fix, update.innovation
        if meas.kind == "gnss_position":
            self.nu[k] = inn.nu
            self.nis[k] = inn.nis
            self.accepted[k] = inn.accepted
            self.forced[k] = inn.forced
            self.s_used[k] = inn.S
            self.r_used[k] = inn.R
            for name, value in self.noise_report().items():
                if name not in self.adaptive:
                    self.adaptive[name] = np.full((len(self.nis), np.size(value)), np.nan)
                self.adaptive[name][k] = value
        elif meas.kind in self.aids and k >= 0:
            nu, nis, acc = self.aids[meas.kind]
            nu[k], nis[k], acc[k] = inn.nu[0], inn.nis, float(inn.accepted)
        elif meas.kind == "gnss_velocity" and self.vel is not None:
            self.vel[0][k], self.vel[1][k], self.vel[2][k] = inn.nu, inn.nis, float(inn.accepted)

    def epoch_done(self, epoch: Epoch, outcome: EpochOutcome) -> None:
        state = outcome.state
        if self.store is not None:
            self.store.updated(outcome.prior_used, state, outcome.reset)
        if outcome.applied and epoch.sample >= 0:
            self.path[epoch.sample] = state.x[:self.n_path]     # the epoch's own sample shows the posterior
        self._released_before(epoch.sample, state.t)      # rows before the epoch are final
        self.knot(state, outcome.prior)
        k = epoch.fix
        if k >= 0:
            if self.store is not None:
                self.epoch_node[k] = self.store.n - 1
            self.bias[k] = state.x[BIASES_X]
            variance = state.P.diagonal()
            self.bias_var[k] = variance[BIASES_DX]
            if self.extra_values is not None:
                n = len(self.extra)
                for j, (_, ie, ix) in enumerate(self.extra):
                    self.extra_values[k, j] = state.x[ix]
                    self.extra_values[k, n + j] = state.P[ie, ie]
        if self.progress is not None and epoch.index % self.tick == 0:
            self.progress(epoch.index / self.n_epochs)

    def fused_epochs(self, knots: np.ndarray, t: float, sample: int = -1) -> None:
        """After a stretch of epochs run by the loop's compiled path (:mod:`navpp.engine.fused`),
        which wrote the per-fix arrays and the path rows: its knot records (K, 19) (t, prior and
        posterior variances of :data:`KNOT`, :meth:`knot`'s layout), the time of its last
        state ``t`` (s) and the IMU sample of its last epoch ``sample`` (-1: none), before which
        the path's rows are final (a spilled path releases them, as :meth:`epoch_done` does)."""
        self.knots.frombytes(np.ascontiguousarray(knots).tobytes())
        if self._chunk_doubles is not None and len(self.knots) >= self._chunk_doubles:
            self._spilled_knots()
        self.t = t
        if sample >= 0:
            self._released_before(sample, t)

    def _released_before(self, sample: int, t: float) -> None:
        """The spilled path's rows before IMU sample ``sample`` and the spilled per-fix records of
        the fixes before ``t`` (s) out of memory (:func:`~navpp.spill.release_before`: once they
        make a window's worth)."""
        if not self.spill:
            return
        release_before(self.path, sample)
        k = int(np.searchsorted(self.fix_t, t))
        for a in (self.nu, self.s_used, self.r_used, self.bias, self.bias_var):
            release_before(a, k)

    def fused_nodes(self, t: np.ndarray, fix: np.ndarray, coast: np.ndarray, nodes_x: np.ndarray,
                    nodes_P: np.ndarray) -> None:
        """The smoother's nodes of a stretch of epochs run by the loop's compiled path, in order:
        times ``t`` (L,) s, fix index ``fix`` and ``coast`` (L,) of each epoch, its states as
        :func:`~navpp.engine.fused.ekf_epochs` keeps them (``nodes_x`` (L, 2, n_x), ``nodes_P``
        (L, 3, n, n)): what :meth:`predicted` and :meth:`epoch_done` give the store."""
        store = self.store
        assert store is not None
        for e in range(t.shape[0]):
            tt, x = float(t[e]), nodes_x[e]
            prior = GaussianState(tt, x[0], nodes_P[e, 0])
            store.predicted(Prediction(prior, nodes_P[e, 2], x[0]))
            if not coast[e]:
                store.updated(prior, GaussianState(tt, x[1], nodes_P[e, 1]), False)
                if fix[e] >= 0:     # a still epoch's constraints alone have no fix (as epoch_done)
                    self.epoch_node[fix[e]] = store.n - 1

    # results -------------------------------------------------------------------------------
    @property
    def r_std(self) -> np.ndarray:
        """Each fix's 1-sigma noise as the filter used it (M, 3) ENU m (NaN where none was
        recorded): the square roots of :attr:`r_used`'s diagonals, taken once at the end."""
        out: np.ndarray = np.sqrt(np.diagonal(self.r_used, axis1=1, axis2=2))
        release_all(self.r_used)        # a spilled record's pages this pass touched
        return out

    def knot_values(self, cols: slice) -> np.ndarray:
        """A copy of the columns ``cols`` of the knots as recorded, (K, C) float64 in recording
        order: of the (K, 19) rows of time (s), prior then posterior variance of :data:`KNOT`
        (:meth:`knot`'s layout); the spilled chunks read and released one at a time (an 8-hour
        run's 20 MB of them are never resident together)."""
        last = np.frombuffer(self.knots, dtype=float).reshape(-1, _KNOT_DOUBLES)[:, cols]
        n = sum(chunk.shape[0] for chunk in self.knot_chunks) + last.shape[0]
        out = np.empty((n, last.shape[1]))
        a = 0
        for chunk in self.knot_chunks:      # each chunk's pages released once its columns are copied
            out[a:a + chunk.shape[0]] = chunk[:, cols]
            release_all(chunk)
            a += chunk.shape[0]
        out[a:] = last
        return out

    def drop_knots(self) -> None:
        """Free the knots once the output's 1-sigma is made from them (8-hour log: 23 MB)."""
        self.knots = array("d")
        self.knot_chunks = []

    def diagnostics(self, t: np.ndarray, labels: dict[str, list[str]]) -> Diagnostics:
        """The per-fix record at the fix times ``t`` (s); an adaptive report with ``labels`` (the
        filter's :meth:`~navpp.filters.base.Filter.noise_report_labels`) is split per element."""
        named: dict[str, np.ndarray] = {}
        for key, values in self.adaptive.items():
            lab = labels.get(key)
            if lab is not None and len(lab) == values.shape[1] and values.shape[1] > 1:
                named.update({f"{key}_{name}": values[:, [i]] for i, name in enumerate(lab)})
            else:
                named[key] = values
        vel_nu, vel_nis, vel_accepted = self.vel if self.vel is not None else (None, None, None)
        states: dict[str, np.ndarray] = {}
        if self.extra_values is not None:
            n = len(self.extra)
            std = np.sqrt(np.maximum(self.extra_values[:, n:], 0.0))
            for j, (label, _, _) in enumerate(self.extra):
                states[label] = self.extra_values[:, [j]]
            for j, (label, _, _) in enumerate(self.extra):
                states[label + "_std"] = std[:, [j]]
        aids = {AID_COLUMNS[kind]: values for kind, values in self.aids.items()}
        return Diagnostics(t, self.nu, self.nis, self.accepted, self.forced, self.r_std, named, vel_nu, vel_nis,
                           vel_accepted, states, aids)

    def bias_history(self, t: np.ndarray) -> BiasHistory:
        """The biases after each fix at the fix times ``t`` (s), with their 1-sigma."""
        std = np.sqrt(np.maximum(self.bias_var, 0.0))     # a diverged run is reported by the checks
        release_all(self.bias_var)      # a spilled record's pages this pass touched
        return BiasHistory(t, self.bias[:, :3], self.bias[:, 3:], std[:, :3], std[:, 3:])
