"""The Monte Carlo core of the papers' small benchmarks (paper 001's tracking, paper 003's
bearing-only and coordinated-turn runs): one run's inputs (:class:`Case`), a filter's run over
them (:class:`Track`), the runs of every filter (:func:`monte_carlo`) and the errors pooled
over runs (:class:`Stats`, :func:`rmse`), with their spread over runs (:func:`rmse_interval`,
:func:`paired_rmse_difference`, :func:`spread_note`).

Within a run every filter sees the same truth and measurements and gets a fresh instance
(:func:`~navpp.papers.filter_spec.make_bench_filter`: default options, the chi-square gate off,
a seed derived from the benchmark seed, the run and the filter's name, so runs repeat exactly
and adding a filter changes nobody else's numbers).  The filters are the registry's,
unchanged; only the truth simulation and the models' point propagation are vectorised.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..engine.loop import EpochOutcome, run_epochs
from ..engine.schedule import Epoch
from ..errors import ConfigError, FilterDivergedError
from ..filters import Filter, GaussianState
from ..filters.vce import HelmertVCE
from .filter_spec import make_bench_filter
from .simulated import OneMeasurementPerEpoch, Recorder, measurement_epochs


@dataclass
class Case:
    """One Monte Carlo run's inputs, shared by every filter.

    model : the filters' model; times : (N+1,) s, ``times[0]`` the start; measurements : N
    measurement objects at ``times[1:]``; truth : (N+1, n) true states at ``times``;
    x0, P0 : the filters' initial mean and covariance; runaway : the truth ran away (the run is
    excluded, and counted).
    """

    model: Any
    times: np.ndarray
    measurements: list
    truth: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    runaway: bool = False


@dataclass
class Track:
    """One filter over one run: posterior means ``x`` (N, n) and covariances ``P`` (N, n, n) at
    the measurement epochs, ``report`` (name -> (N, k) from ``noise_report()``, NaN where not
    reported), the wall time of the predict/update loop in s, the divergence message, and
    ``diagnostics`` read at the end (a noise adapter's pooled redundancy, when it has one)."""

    x: np.ndarray
    P: np.ndarray
    report: dict[str, np.ndarray] = field(default_factory=dict)
    seconds: float = 0.0
    error: str | None = None
    diagnostics: dict[str, np.ndarray] = field(default_factory=dict)


def filter_seed(seed: int, run: int, name: str) -> int:
    """Seed of filter ``name`` in run ``run`` of a benchmark seeded with ``seed``."""
    ss = np.random.SeedSequence(seed, spawn_key=(run, zlib.crc32(name.encode())))
    return int(ss.generate_state(1, np.uint32)[0])


def truth_rng(seed: int, run: int) -> np.random.Generator:
    """The generator of run ``run``'s truth and measurements (independent of the run count)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run,)))


class TrackRecorder(Recorder):
    """Keeps what a :class:`Track` holds: the posterior mean (N, n) and covariance (N, n, n) at
    each measurement epoch and the filter's ``noise_report()`` after it."""

    def __init__(self, filt: Filter, n: int, N: int) -> None:
        self.filt = filt
        self.x, self.P = np.full((N, n), np.nan), np.full((N, n, n), np.nan)
        self.reports: list[dict[str, np.ndarray]] = []

    def epoch_done(self, epoch: Epoch, outcome: EpochOutcome) -> None:
        self.x[epoch.index], self.P[epoch.index] = outcome.state.x, outcome.state.P
        self.reports.append({key: np.array(v, dtype=float).ravel() for key, v in self.filt.noise_report().items()})


def run_filter(filt: Filter, case: Case) -> Track:
    """Run ``filt`` over ``case`` on the engine's loop (predict to each measurement time,
    update) and record its :class:`Track`; a divergence ends the track with its message."""
    N = len(case.measurements)
    rec = TrackRecorder(filt, case.x0.shape[0], N)
    state = GaussianState(float(case.times[0]), np.array(case.x0, dtype=float), np.array(case.P0, dtype=float))
    t0 = time.perf_counter()
    try:
        run_epochs(filt, case.model, state, measurement_epochs(case.times[1:]),
                   OneMeasurementPerEpoch(case.measurements), rec)
    except FilterDivergedError as exc:
        return Track(rec.x, rec.P, _stack_reports(rec.reports, N), time.perf_counter() - t0, str(exc))
    seconds = time.perf_counter() - t0
    diagnostics = ({f"redundancy_{k}": np.asarray(v, dtype=float) for k, v in filt.adapter.pooled_redundancy().items()}
                   if isinstance(filt.adapter, HelmertVCE) else {})
    return Track(rec.x, rec.P, _stack_reports(rec.reports, N), seconds, None, diagnostics)


def _stack_reports(reports: list[dict[str, np.ndarray]], N: int) -> dict[str, np.ndarray]:
    names = {key: v.size for rep in reports for key, v in rep.items()}
    out = {key: np.full((N, size), np.nan) for key, size in names.items()}
    for k, rep in enumerate(reports):
        for key, v in rep.items():
            if v.size == out[key].shape[1]:
                out[key][k] = v
    return out


def monte_carlo(make_case: Callable[[np.random.Generator], Case], runs: int, seed: int,
                filters: Sequence[str]) -> tuple[list[Case], dict[str, list[Track | None]]]:
    """Cases of ``runs`` runs and every filter's track on each (None on runaway runs).

    Each filter first runs three steps of the first usable case on a throwaway instance, so that
    one-off costs (imports, compiled-kernel loading) do not land in the first run's time.
    """
    if seed < 0:
        raise ConfigError(f"benchmark seed must be an integer >= 0, got {seed}")
    cases = [make_case(truth_rng(seed, r)) for r in range(runs)]
    tracks: dict[str, list[Track | None]] = {f: [] for f in filters}
    usable = next((c for c in cases if not c.runaway), None)
    for name in filters:
        if usable is not None:
            short = Case(usable.model, usable.times[:4], usable.measurements[:3], usable.truth[:4], usable.x0,
                         usable.P0)
            run_filter(make_bench_filter(name, 0), short)
        for r, case in enumerate(cases):
            tracks[name].append(None if case.runaway else
                                run_filter(make_bench_filter(name, filter_seed(seed, r, name)), case))
    return cases, tracks


@dataclass
class Stats:
    """Errors of one filter over the runs it completed: ``err`` (R, N, n) estimate minus truth,
    ``nees`` (R, N), ``seconds`` (R,),
    ``reports`` name -> (R, N, k); ``diverged`` runs are excluded and counted; ``runs`` (R,) the
    indices of the kept runs in the cases (for pairing two filters' runs)."""

    err: np.ndarray
    nees: np.ndarray
    seconds: np.ndarray
    reports: dict[str, np.ndarray]
    diverged: int
    messages: list[str]
    diagnostics: dict[str, np.ndarray] = field(default_factory=dict)
    runs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))


def collect(cases: list[Case], tracks: list[Track | None]) -> Stats:
    """One filter's :class:`Stats` over ``cases`` (runaway runs have no track; diverged are counted)."""
    errs, nees, secs, reps, msgs, diags, kept = [], [], [], [], [], [], []
    for r, (case, tr) in enumerate(zip(cases, tracks)):
        if tr is None:
            continue
        if tr.error is not None:
            msgs.append(tr.error)
            continue
        e = tr.x - case.truth[1:]
        errs.append(e)
        nees.append(np.einsum("ki,ki->k", e, np.linalg.solve(tr.P, e[..., None])[..., 0]))
        secs.append(tr.seconds)
        reps.append(tr.report)
        diags.append(tr.diagnostics)
        kept.append(r)
    n = cases[0].x0.shape[0]
    N = len(cases[0].measurements)
    reports = {key: np.array([rep[key] for rep in reps if key in rep]) for key in (reps[0] if reps else {})}
    diagnostics = {key: np.mean([d[key] for d in diags], axis=0) for key in (diags[0] if diags else {})
                   if all(key in d and np.shape(d[key]) == np.shape(diags[0][key]) for d in diags)}
    return Stats(np.array(errs).reshape(-1, N, n), np.array(nees).reshape(-1, N), np.array(secs), reports,
                 len(msgs), msgs, diagnostics, np.array(kept, dtype=int))


def rmse(err: np.ndarray, idx: Sequence[int]) -> float:
    """``sqrt(mean over runs and epochs of sum_i err_i^2)`` over the states ``idx``: the RMS of
    the error norm (paper 003 eq 44, pooled over time)."""
    if err.shape[0] == 0:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(err[..., list(idx)] ** 2, axis=-1))))


def rmse_curve(err: np.ndarray, idx: Sequence[int]) -> np.ndarray:
    """RMSE(k) of paper 003 eq 44: ``sqrt(mean over runs of sum_i err_i(k)^2)``, (N,)."""
    if err.shape[0] == 0:
        return np.full(err.shape[1], np.nan)
    return np.sqrt(np.mean(np.sum(err[..., list(idx)] ** 2, axis=-1), axis=0))


def diverged_note(s: Stats, runs: int) -> str:
    """The row note for ``s.diverged`` runs of ``runs`` (empty when none diverged)."""
    return f"{s.diverged} of {runs} runs diverged, excluded" if s.diverged else ""



#: resamples of the paired bootstrap over runs behind the 95 % intervals
BOOTSTRAP_RESAMPLES = 2000


def _run_mse(err: np.ndarray, idx: Sequence[int]) -> np.ndarray:
    """Per run, the mean over epochs of ``sum_i err_i^2`` over the states ``idx``: (R,)."""
    out: np.ndarray = np.mean(np.sum(err[..., list(idx)] ** 2, axis=-1), axis=-1)
    return out


def _resamples(n: int, seed: int = 0) -> np.ndarray:
    """(BOOTSTRAP_RESAMPLES, n) run indices drawn with replacement (fixed seed: repeatable)."""
    out: np.ndarray = np.random.default_rng(seed).integers(0, n, size=(BOOTSTRAP_RESAMPLES, n))
    return out


def rmse_interval(err: np.ndarray, idx: Sequence[int]) -> tuple[float, float, float]:
    """:func:`rmse` with its spread over runs: ``(rmse, sd of the per-run RMSE, half-width of
    the 95 % interval of the pooled RMSE)``, the interval from a bootstrap over runs (runs drawn
    with replacement, the pooled RMSE recomputed; half the 2.5-97.5 % range).  NaNs without runs."""
    if err.shape[0] == 0:
        return float("nan"), float("nan"), float("nan")
    mse = _run_mse(err, idx)
    per_run = np.sqrt(mse)
    boot = np.sqrt(np.mean(mse[_resamples(mse.size)], axis=1))
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return float(np.sqrt(np.mean(mse))), float(np.std(per_run, ddof=1)) if mse.size > 1 else 0.0, float(0.5 * (hi - lo))


def paired_rmse_difference(a: Stats, b: Stats, idx: Sequence[int]) -> tuple[float, float, int]:
    """Pooled RMSE of ``a`` minus that of ``b`` over the runs both completed, with the half-width
    of its 95 % interval from a paired bootstrap (the same resampled runs for both): ``(difference,
    half-width, runs)``.  Both filters saw the same truth and measurements in a run, so the
    pairing removes the run-to-run spread they share."""
    common, ia, ib = np.intersect1d(a.runs, b.runs, return_indices=True)
    if common.size == 0:
        return float("nan"), float("nan"), 0
    ma, mb = _run_mse(a.err[ia], idx), _run_mse(b.err[ib], idx)
    pick = _resamples(common.size)
    boot = np.sqrt(np.mean(ma[pick], axis=1)) - np.sqrt(np.mean(mb[pick], axis=1))
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return float(np.sqrt(np.mean(ma)) - np.sqrt(np.mean(mb))), float(0.5 * (hi - lo)), int(common.size)


def spread_note(stats: dict[str, Stats], idx: Sequence[int], what: str, reference: str | None = None,
                unit: str = "m") -> str:
    """One note line: each filter's ``what`` RMSE with its run-to-run sd and 95 % interval
    (:func:`rmse_interval`) and, when ``reference`` is among them, its paired difference to the
    reference (:func:`paired_rmse_difference`)."""
    parts = []
    for name, s in stats.items():
        value, sd, half = rmse_interval(s.err, idx)
        text = f"{name} {value:.3f} ± {half:.3f} (sd per run {sd:.3f})"
        if reference is not None and reference in stats and name != reference:
            diff, dhalf, _ = paired_rmse_difference(s, stats[reference], idx)
            text += f", {diff:+.3f} ± {dhalf:.3f} vs {reference}"
        parts.append(text)
    return (f"Spread of the {what} RMSE ({unit}) over runs: value ± half-width of its 95 % interval (bootstrap "
            f"over runs, {BOOTSTRAP_RESAMPLES} resamples), the sd of the per-run RMSE, and the paired difference "
            f"to {reference or 'the first filter'} with its 95 % interval (same runs resampled for both): "
            + "; ".join(parts) + ".")
