"""``navpp compare``: several filters on several logs, one MAE/RMSE table, a report and CI gates.

Every filter runs on every log (one *run* per log x filter) with the log's own configuration
(``config`` or the log's ``navpp.toml``).  A log that cannot be read, or a filter that fails on
a log (divergence, a configuration it rejects), becomes a row whose ``status`` is the one-line
reason; it never stops the other runs.

Parallel runs (``jobs > 1``) use a :class:`concurrent.futures.ProcessPoolExecutor` with the
``spawn`` start method (safe with numba and threads, and the same on every OS; a script that
calls :func:`compare` with ``jobs > 1`` needs the usual ``if __name__ == "__main__":`` guard):
one task per run, log by log with each log's costliest filters first, each
worker reading the log itself and keeping the last recording it read, so a log is read a few
times at most instead of once per filter.  Each log's figures are drawn in the pool as well,
one task per figure, as soon as that log's runs are done.  Workers return
the row and the few decimated series the report plots (:class:`RunSeries`, :class:`LogSeries`),
never whole solutions.  The figures are those of a serial run, bit for bit (only the measured
``runtime_s`` differs).

Outputs (all written atomically, :func:`navpp.io.writers.atomic_write`): ``summary.csv``
(:data:`SUMMARY_COLUMNS`), ``report.md`` with its PNG figures beside it, and the self-contained
``report.html`` (:mod:`navpp.report`).

CI gates (:meth:`CompareResult.check_baseline`, :meth:`CompareResult.check_limits`) compare the
summary values, as written in ``summary.csv`` (metres, rounded to 0.1 mm), with an earlier
``summary.csv`` or with fixed limits; see :func:`check_baseline` and :func:`check_limits`.

Python use::

    from navpp.comparison import compare, read_baseline
    result = compare(["drive.mcap", "city/"], ["ekf", "vce-ckf"], jobs=2, out_dir="out")
    result.summary                       # pandas DataFrame, the content of out/summary.csv
    verdict = result.check_baseline(read_baseline("old/summary.csv"), tolerance_pct=5.0)
    verdict.passed, verdict.failures
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import interrupts
from .errors import ConfigError, NavppError
from .outdir import OutDirLock

if TYPE_CHECKING:                       # heavy imports only when used
    import numpy as np
    import pandas as pd

SUMMARY_COLUMNS = ("log", "filter", "status", "epochs", "east_mae", "east_rmse", "north_mae", "north_rmse",
                   "up_mae", "up_rmse", "horizontal_mae", "horizontal_rmse", "horizontal_p95", "3d_rmse",
                   "gnss_epochs", "gnss_rejected", "runtime_s",
                   # added for the report; appended so readers of the first columns keep working
                   "horizontal_max", "up_max", "imu_samples", "reference")

#: Position-error columns of ``summary.csv`` (m); the report highlights the minimum of each per log.
ERROR_COLUMNS = ("east_mae", "east_rmse", "north_mae", "north_rmse", "up_mae", "up_rmse",
                 "horizontal_mae", "horizontal_rmse")

#: Columns ``--baseline`` compares (m): horizontal and vertical RMSE.
BASELINE_METRICS = ("horizontal_rmse", "up_rmse")

#: ``--max-rmse`` keys (case-insensitive) -> ``summary.csv`` column (m).
LIMIT_KEYS = {"h": "horizontal_rmse", "horizontal": "horizontal_rmse", "e": "east_rmse", "east": "east_rmse",
              "n": "north_rmse", "north": "north_rmse", "u": "up_rmse", "up": "up_rmse", "3d": "3d_rmse"}

#: Files a comparison writes into its output directory (``*``: figure names ending so), whose
#: temporary files a killed run may leave behind (:func:`navpp.outdir.remove_leftovers`).
COMPARE_FILES = ("summary.csv", "report.md", "report.html", "*_trajectory.png", "*_error_time.png",
                 "*_error_cdf.png", "*_adaptive.png")

#: Default ``--tolerance`` with ``--baseline``, percent.
DEFAULT_TOLERANCE_PCT = 5.0

#: Slack (m) on the baseline limit ``baseline * (1 + tolerance)``: absorbs the floating-point
#: rounding of that product (a value exactly at the limit passes); far below the 0.1 mm
#: resolution of the summary values, so it never changes a real decision.
_LIMIT_SLACK_M = 1e-9

#: Probabilities at which the horizontal-error CDF is sampled for the report.
CDF_POINTS = 201
# Points kept for the plots, about one per pixel column of a figure (or finer):
_TRACK_POINTS = 2000      # trajectory points per run (stride decimation)
_ERROR_BINS = 500         # error-vs-time bins; each keeps its minimum and maximum (spikes survive)
_DIAG_POINTS = 1000       # diagnostics points per run (stride)

ProgressFn = Callable[[str, float], None]   # progress(stage label, fraction done 0..1)


# --------------------------------------------------------------------------- rows


@dataclass(frozen=True)
class CompareRow:
    """One filter on one log.

    ``status`` is "ok" or the one-line reason the run failed; ``metrics`` the
    :func:`navpp.metrics.compute_metrics` dict (None without a reference or on failure);
    ``runtime_s`` the filter's processing time (s, without kernel compilation);
    ``gnss_epochs`` / ``gnss_rejected`` the GNSS fixes used / rejected by the gate;
    ``imu_samples`` the IMU samples read; ``reference`` the reference's source ("" without);
    ``warnings`` what reading and filtering noticed (as ``navpp process`` prints them).
    """

    log: str
    filter: str
    status: str
    metrics: dict | None
    gnss_epochs: int = 0
    gnss_rejected: int = 0
    runtime_s: float = float("nan")
    imu_samples: int = 0
    reference: str = ""
    warnings: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def summary(self) -> dict[str, object]:
        """The row as ``summary.csv`` values (position errors in metres, ENU, rounded to 0.1 mm);
        keys without a value (no reference, failed run) are left out."""
        out: dict[str, object] = {"log": self.log, "filter": self.filter, "status": self.status,
                                  "gnss_epochs": self.gnss_epochs, "gnss_rejected": self.gnss_rejected,
                                  "runtime_s": round(self.runtime_s, 4), "imu_samples": self.imu_samples,
                                  "reference": self.reference}
        m = self.metrics
        if m is not None:
            pos = m["position_m"]
            out["epochs"] = m["epochs"]
            for axis in ("east", "north", "up", "horizontal"):
                out[f"{axis}_mae"] = round(pos[axis]["mae"], 4)
                out[f"{axis}_rmse"] = round(pos[axis]["rmse"], 4)
            out["horizontal_p95"] = round(pos["horizontal"]["p95"], 4)
            out["3d_rmse"] = round(pos["3d"]["rmse"], 4)
            out["horizontal_max"] = round(pos["horizontal"]["max"], 4)
            out["up_max"] = round(pos["up"]["max"], 4)
        return out

    def summary_record(self) -> dict[str, object]:
        """:meth:`summary` with every column of :data:`SUMMARY_COLUMNS` (None where empty), for JSON."""
        s = self.summary()
        out = {c: s.get(c) for c in SUMMARY_COLUMNS}
        if isinstance(out["runtime_s"], float) and not math.isfinite(out["runtime_s"]):
            out["runtime_s"] = None
        return out


# --------------------------------------------------------------------------- plot series


@dataclass(frozen=True)
class LogSeries:
    """What the report plots of a log itself, in the log's local ENU frame (m) about ``anchor``
    (lat deg, lon deg, alt m: the first GNSS fix): the GNSS fixes and the reference track
    (None without a reference)."""

    anchor: tuple[float, float, float]
    gnss_east_m: np.ndarray
    gnss_north_m: np.ndarray
    ref_east_m: np.ndarray | None = None
    ref_north_m: np.ndarray | None = None


@dataclass(frozen=True)
class RunSeries:
    """What the report plots of one run, decimated.

    east_m, north_m : (K,) trajectory in the log's local ENU frame (m, see :class:`LogSeries`).
    err_t_s, err_h_m : (L,) horizontal position error (m) against the reference at reference
        epochs, time since log start (s); the minimum and maximum of each of up to 500 bins;
        None without a reference.
    cdf_m : (CDF_POINTS,) horizontal error (m) at probabilities ``linspace(0, 1, CDF_POINTS)``
        (linear quantiles of all reference epochs); None without a reference.
    adaptive : True for filters that adapt their noise (a noise adapter or adaptive factors).
    diag_t_s : (M,) GNSS epochs (s since log start); r_std_m : (M, 3) the measurement noise
        1-sigma used, E/N/U (m); factors : name -> (M,) adaptive scale factors (dimensionless,
        1 = as configured: VCE ``q_factor_*`` / ``r_factor_*``, the AUKF ``fading``).
    """

    east_m: np.ndarray
    north_m: np.ndarray
    err_t_s: np.ndarray | None = None
    err_h_m: np.ndarray | None = None
    cdf_m: np.ndarray | None = None
    adaptive: bool = False
    diag_t_s: np.ndarray | None = None
    r_std_m: np.ndarray | None = None
    factors: dict[str, np.ndarray] = field(default_factory=dict)


# --------------------------------------------------------------------------- tasks and workers


@dataclass(frozen=True)
class _Task:
    """One run to do; plain values only, so it pickles small."""

    index: int                  # position of the row (log-major)
    log: str
    filter: str
    config: str | None
    reference: str | None
    imu_topic: str | None
    gnss_topic: str | None
    reference_topic: str | None
    series: bool                # collect the plot series
    log_series: bool            # also the log's own series (the first filter of each log)
    smooth: bool = False        # also smooth the run: a second row, "<filter>+rts"
    path: str | None = None     # where to read the log (absolute for remote workers); None: ``log``
    time_limit_s: float = 0.0   # the watchdog's s per 100,000 IMU samples (:func:`watchdog_limit_s`); 0: off


@dataclass(frozen=True)
class _Outcome:
    index: int
    row: CompareRow
    series: RunSeries | None = None
    log_series: LogSeries | None = None
    smoothed: tuple[CompareRow, RunSeries | None] | None = None    # the "<filter>+rts" row of a smoothed run

    def rows(self) -> list[tuple[CompareRow, RunSeries | None]]:
        """The forward row and, for a smoothed run, the smoothed one after it, with their series."""
        return [(self.row, self.series)] + ([self.smoothed] if self.smoothed is not None else [])


#: Where ``compare`` runs the tasks (:func:`compare`'s ``executor``).
EXECUTORS = ("local", "dask")

#: Suffix of the filter name in the row of a smoothed run (``ekf+rts``).
SMOOTHED_SUFFIX = "+rts"


def smoothed_name(filter_name: str) -> str:
    """The row label of ``filter_name``'s smoothed run: ``"ekf"`` -> ``"ekf+rts"``."""
    return filter_name + SMOOTHED_SUFFIX


#: The compare watchdog (:func:`watchdog_limit_s`): a run may take ``time_limit`` s for every
#: 100,000 IMU samples of its log (about 15 minutes at 100 Hz), and never less than
#: WATCHDOG_MIN_S.  The default, 600 s, is about 60 times what the EKF takes on the 2-core
#: reference machine and 7 times the slowest filter (RWCKF) with smoothing: generous, since
#: the watchdog is for a run that hangs, not for a slow one.
DEFAULT_TIME_LIMIT_S = 600.0
WATCHDOG_MIN_S = 120.0
#: While the log is read its sample count is not known: the files' size over this many bytes
#: (less than any reader's IMU row or message takes) stands for it.
WATCHDOG_BYTES_PER_SAMPLE = 40.0


def watchdog_limit_s(time_limit_s: float, n_imu: float) -> float:
    """The watchdog's limit (s) for a run on a log of ``n_imu`` IMU samples; 0: no watchdog."""
    if not time_limit_s > 0.0:
        return 0.0
    return max(WATCHDOG_MIN_S, time_limit_s * n_imu / 1e5)


class _WatchdogExpired(BaseException):
    """Raised in a run by the watchdog's alarm (a BaseException: no ``except Exception`` of the
    run's own code swallows it)."""


class _Watchdog:
    """``with _Watchdog(seconds):`` raises :class:`_WatchdogExpired` in the block once
    ``seconds`` have passed (SIGALRM).  Only on the main thread of a POSIX process (the CLI,
    and the worker processes of ``--jobs``); elsewhere (Dask's worker threads) it does nothing.
    The alarm is handled when the interpreter next runs Python code: a compiled kernel that never
    returns is not interrupted."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.old: Any = None

    def __enter__(self) -> _Watchdog:
        import signal
        import threading

        on_main = threading.current_thread() is threading.main_thread()
        if self.seconds > 0.0 and hasattr(signal, "setitimer") and on_main:
            def expired(signum, frame):
                raise _WatchdogExpired(self.seconds)

            self.old = signal.signal(signal.SIGALRM, expired)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        return self

    def __exit__(self, *exc) -> None:
        import signal

        if self.old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self.old)
            self.old = None


def _log_bytes(path: Path) -> int:
    """Size of a log on disk (a file, or the files of a directory), bytes; 0 if unreadable."""
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def _watchdog_message(task: _Task, seconds: float, n_imu: int | None) -> str:
    what = (f"the limit for {n_imu} IMU samples" if n_imu is not None else "reading the log")
    return (f"{task.log}: stopped by the watchdog after {seconds:.0f} s ({what}; compare --time-limit sets it, "
            f"{task.time_limit_s:g} s per 100,000 samples)")


class _RecordingCache:
    """The last (config, recording) read, keyed by what determines them; read errors are kept
    too, so the other filters of an unreadable log fail at once with the same message."""

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.value: Any = None

    def get(self, task: _Task, progress: ProgressFn | None):
        from . import api

        key = (task.log, task.config, task.reference, task.imu_topic, task.gnss_topic, task.reference_topic)
        if key != self.key:
            self.key, self.value = None, None          # free the previous recording first
            log = Path(task.path or task.log)
            label = f"reading {Path(task.log).name}"
            limit = watchdog_limit_s(task.time_limit_s, _log_bytes(log) / WATCHDOG_BYTES_PER_SAMPLE)
            try:
                cfg = api.resolve_config(log, task.config)
                with _Watchdog(limit):
                    rec = api.read_log(log, cfg, reference=task.reference, imu_topic=task.imu_topic,
                                       gnss_topic=task.gnss_topic, reference_topic=task.reference_topic,
                                       progress=(lambda f: progress(label, f)) if progress else None)
                if progress:
                    progress(label, 1.0)
                # [gnss] outages of the log's config: the same simulated outages as `navpp process`
                rec, removed = api.apply_outages(rec, cfg.gnss.outages, str(log))
                self.value = (cfg, rec, [w["gnss_removed"] for w in removed])
            except NavppError as exc:
                self.value = exc
            except _WatchdogExpired:      # the log's other runs fail at once with the same message
                self.value = NavppError(_watchdog_message(task, limit, None))
            except Exception as exc:  # noqa: BLE001  (a bug, or a file no reader expected: a row, not a crash)
                self.value = NavppError(_internal(exc))
            self.key = key
        if isinstance(self.value, NavppError):
            raise self.value
        return self.value

    def clear(self) -> None:
        self.key, self.value = None, None


def _internal(exc: BaseException) -> str:
    first = (str(exc).strip().splitlines() or [""])[0]
    return f"internal error: {type(exc).__name__}: {first}" if first else f"internal error: {type(exc).__name__}"


def _naming_log(warning: str, log: str | Path) -> str:
    """A reader or engine warning as ``compare`` prints it among several logs' warnings: naming
    the log (a CSV reader's ``imu.csv: ...`` becomes ``LOG/imu.csv: ...``)."""
    log_text = str(log)
    if warning.startswith(log_text):
        return warning
    head, sep, rest = warning.partition(": ")
    if sep and head and "/" not in head and " " not in head and Path(log_text, head).exists():
        return f"{Path(log_text, head)}: {rest}"
    return f"{log_text}: {warning}"


def _failed(task: _Task, status: str, log_series: LogSeries | None = None) -> _Outcome:
    row = CompareRow(task.log, task.filter, " ".join(status.split()), None)
    smoothed = (replace(row, filter=smoothed_name(task.filter)), None) if task.smooth else None
    return _Outcome(task.index, row, None, log_series, smoothed)


def _execute(task: _Task, cache: _RecordingCache, progress: ProgressFn | None) -> _Outcome:
    """Run one filter on one log; every failure becomes the row's status."""
    from . import api, engine

    try:
        cfg, rec, removed = cache.get(task, progress)
    except NavppError as exc:
        return _failed(task, str(exc))
    log_series = None
    try:
        log_series = _log_series(rec) if task.log_series else None
        label = f"{Path(task.log).name} {task.filter}"
        filt = api.make_filter(task.filter, cfg)
        limit = watchdog_limit_s(task.time_limit_s, len(rec.imu))
        with _Watchdog(limit):
            res = engine.run(rec, cfg, filt, progress=(lambda f: progress(label, f)) if progress else None,
                             smooth=task.smooth)
        # the forward row's time is the forward filter's; the smoothed row's includes the smoothing
        forward_s = res.forward_runtime_s

        def metrics_of(sol, name: str, runtime_s: float) -> dict | None:
            return api.run_metrics(rec, cfg, res, sol, filter_name=name, log=task.log, runtime_s=runtime_s,
                                   windows=cfg.gnss.outages, removed=removed)

        metrics = metrics_of(res.solution, task.filter, forward_s)
        series = _run_series(rec, res.solution, res.diagnostics, filt) if task.series else None
        smoothed = None
        if res.smoothed is not None:
            name = smoothed_name(task.filter)
            sm_metrics = metrics_of(res.smoothed.solution, name, res.runtime_s)
            sm_series = None
            if task.series:      # the diagnostics are the forward filter's: plotted once, with its row
                sm_series = replace(_run_series(rec, res.smoothed.solution, res.diagnostics, filt), adaptive=False,
                                    diag_t_s=None, r_std_m=None, factors={})
            smoothed = (sm_metrics, sm_series)
    except NavppError as exc:
        return _failed(task, str(exc), log_series)
    except _WatchdogExpired:
        return _failed(task, _watchdog_message(task, limit, len(rec.imu)), log_series)
    except Exception as exc:  # noqa: BLE001  (a bug in one filter must not lose the other runs)
        return _failed(task, _internal(exc), log_series)
    ref_source = (rec.reference.source or "reference") if rec.reference is not None else ""
    warnings = tuple(_naming_log(w, task.log) for w in (*rec.warnings, *res.warnings))
    row = CompareRow(task.log, task.filter, "ok", metrics, res.gnss_epochs, res.gnss_rejected, forward_s,
                     len(rec.imu), ref_source, warnings)
    sm_row = None
    if smoothed is not None:
        sm_row = (replace(row, filter=smoothed_name(task.filter), metrics=smoothed[0], runtime_s=res.runtime_s),
                  smoothed[1])
    return _Outcome(task.index, row, series, log_series, sm_row)


# worker-process state (spawned processes only)
_WORKER_CACHE: _RecordingCache | None = None
_WORKER_QUEUE: Any = None


def _init_worker(queue: Any, parent_pid: int | None = None) -> None:
    import atexit

    _die_with_parent(parent_pid)
    global _WORKER_CACHE, _WORKER_QUEUE
    _WORKER_CACHE = _RecordingCache()
    _WORKER_QUEUE = queue
    if queue is not None:
        queue.cancel_join_thread()       # progress is best effort: never wait at exit to flush it
    atexit.register(_exit_at_once)


def _die_with_parent(parent_pid: int | None) -> None:
    """A worker stops with the comparison that started it: it ignores SIGINT (a Ctrl-C reaches
    the whole process group; the parent alone decides, and stops the workers), and on Linux the
    kernel sends it SIGKILL when the parent dies, however the parent dies (``PR_SET_PDEATHSIG``),
    so no worker is left waiting forever."""
    import os
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent_pid is None or not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)           # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:                          # the parent died before the prctl
        os._exit(1)


def _stop_workers(ex: Any) -> None:
    """Stop the pool's worker processes now (SIGTERM), not after their current task: the
    comparison was interrupted or failed, and nothing will read their results."""
    for proc in list((getattr(ex, "_processes", None) or {}).values()):
        with suppress(OSError, ValueError, AttributeError):
            proc.terminate()
    ex.shutdown(wait=False, cancel_futures=True)


def _exit_at_once() -> None:
    """A worker's last act: skip the interpreter's teardown (about 0.5 s once numba kernels and
    matplotlib are loaded, paid at every shutdown of the pool).  Nothing is lost: results went
    back through the executor's queue synchronously before the worker was told to stop."""
    import os
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


class _QueueProgress:
    """Progress from a worker: (stage, fraction) on the queue, at most every 2 %."""

    def __init__(self, queue: Any) -> None:
        self.queue = queue
        self.sent: dict[str, float] = {}

    def __call__(self, stage: str, fraction: float) -> None:
        last = self.sent.get(stage, -1.0)
        if fraction >= 1.0 or fraction - last >= 0.02:
            self.sent[stage] = fraction
            self.queue.put((stage, float(fraction)))


def _execute_in_worker(task: _Task) -> _Outcome:
    if _WORKER_CACHE is None:
        raise RuntimeError("navpp.comparison: worker process used without _init_worker")
    progress = _QueueProgress(_WORKER_QUEUE) if _WORKER_QUEUE is not None else None
    return _execute(task, _WORKER_CACHE, progress)


# --------------------------------------------------------------------------- series (in the workers)


def _stride(n: int, keep: int) -> np.ndarray:
    """Indices of about ``keep`` evenly strided samples of ``n``, the last one always included."""
    import numpy as np

    if n <= keep:
        return np.arange(n)
    idx = np.arange(0, n, math.ceil(n / keep))
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def minmax_decimate(t: np.ndarray, y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep, of each of ``bins`` equal runs of samples, its minimum and its maximum in time order:
    a line plot of the result shows every peak of the original.  NaNs are dropped first."""
    import numpy as np

    ok = np.isfinite(y)
    t, y = np.asarray(t, dtype=float)[ok], np.asarray(y, dtype=float)[ok]
    n = y.size
    if n <= 2 * bins:
        return t, y
    edges = np.linspace(0, n, bins + 1).astype(int)
    keep = []
    for a, b in itertools.pairwise(edges):
        i, j = a + int(np.argmin(y[a:b])), a + int(np.argmax(y[a:b]))
        keep += sorted({i, j})
    idx = np.asarray(keep)
    return t[idx], y[idx]


def _anchor(rec) -> Any:
    import numpy as np

    from .io.frames import Anchor

    g = rec.gnss
    ok = np.flatnonzero(np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg) & np.isfinite(g.alt))
    if ok.size:
        i = int(ok[0])
        return Anchor(float(g.lat_deg[i]), float(g.lon_deg[i]), float(g.alt[i]))
    if rec.reference is not None and len(rec.reference.t):
        r = rec.reference
        return Anchor(float(r.lat_deg[0]), float(r.lon_deg[0]), float(r.alt[0]))
    return None


def _log_series(rec) -> LogSeries | None:
    import numpy as np

    anchor = _anchor(rec)
    if anchor is None:
        return None
    g = rec.gnss
    ok = np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg) & np.isfinite(g.alt)
    gi = np.flatnonzero(ok)[_stride(int(ok.sum()), 2 * _TRACK_POINTS)]
    genu = anchor.enu(g.lat_deg[gi], g.lon_deg[gi], g.alt[gi]).reshape(-1, 3)
    ref_e = ref_n = None
    if rec.reference is not None:
        r = rec.reference
        rok = np.flatnonzero(np.isfinite(r.lat_deg) & np.isfinite(r.lon_deg) & np.isfinite(r.alt))
        ri = rok[_stride(rok.size, _TRACK_POINTS)]
        renu = anchor.enu(r.lat_deg[ri], r.lon_deg[ri], r.alt[ri]).reshape(-1, 3)
        ref_e, ref_n = renu[:, 0], renu[:, 1]
    return LogSeries((anchor.lat_deg, anchor.lon_deg, anchor.alt), genu[:, 0], genu[:, 1], ref_e, ref_n)


#: Adaptive entries plotted as scale factors (prefixes of the Diagnostics ``adaptive`` names).
FACTOR_PREFIXES = ("q_factor", "r_factor", "fading")


def _run_series(rec, sol, diag, filt) -> RunSeries:
    """The plot series of one solution (forward or smoothed) with the run's diagnostics."""
    import numpy as np

    from .metrics import associate, interpolate_solution, position_errors_enu

    anchor = _anchor(rec)
    si = _stride(len(sol.t), _TRACK_POINTS)
    if anchor is not None:
        enu = anchor.enu(sol.lat_deg[si], sol.lon_deg[si], sol.alt[si]).reshape(-1, 3)
        east, north = enu[:, 0], enu[:, 1]
    else:
        east = north = np.zeros(0)
    err_t = err_h = cdf = None
    if rec.reference is not None:
        ref = rec.reference
        ref_ok = np.isfinite(ref.lat_deg) & np.isfinite(ref.lon_deg) & np.isfinite(ref.alt)
        assoc = associate(np.asarray(sol.t, dtype=float), np.where(ref_ok, np.asarray(ref.t, dtype=float), np.nan),
                          skip_holes=True)
        if assoc.idx_ref.size:
            i = assoc.idx_ref
            est = interpolate_solution(sol, assoc.t)
            err = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"],
                                      ref.lat_deg[i], ref.lon_deg[i], ref.alt[i])
            h = np.hypot(err[:, 0], err[:, 1])
            err_t, err_h = minmax_decimate(assoc.t, h, _ERROR_BINS)
            cdf = np.quantile(h, np.linspace(0.0, 1.0, CDF_POINTS))
    factors = {k: np.asarray(v, dtype=float).reshape(len(diag.t), -1)[:, 0]
               for k, v in diag.adaptive.items()
               if k.startswith(FACTOR_PREFIXES) and np.asarray(v).reshape(len(diag.t), -1).shape[1] == 1}
    adaptive = filt.adapts_noise or bool(factors)
    di = _stride(len(diag.t), _DIAG_POINTS)
    return RunSeries(east, north, err_t, err_h, cdf, adaptive,
                     np.asarray(diag.t, dtype=float)[di] if adaptive else None,
                     np.asarray(diag.r_std, dtype=float)[di] if adaptive else None,
                     {k: v[di] for k, v in factors.items()} if adaptive else {})


# --------------------------------------------------------------------------- the comparison


def parse_filters(text: str) -> list[str]:
    """``"ekf,aekf, ckf"`` -> names, checked against the registry (ConfigError lists the choices)."""
    from .filters import get_filter

    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise ConfigError("--filters: give at least one filter name, e.g. --filters ekf,aekf,ckf")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"--filters: {', '.join(dup)} given more than once")
    for n in names:
        if "[" in n:
            _refuse_options(n)
        get_filter(n)
    return names


def _refuse_options(spec: str) -> None:
    """``compare`` runs each filter with the config's ``[filter.<name>]`` options; a spec with
    options in brackets (``bench``'s syntax) is refused, naming an unknown key and the valid ones."""
    import dataclasses
    import difflib

    from .filters import get_filter

    name, _, body = spec.partition("[")
    cls = get_filter(name.strip())
    valid = [f.name for f in dataclasses.fields(cls.Options)]
    for item in filter(None, (part.strip() for part in body.rstrip("]").split(";"))):
        key = item.partition("=")[0].strip()
        if key not in valid:
            near = difflib.get_close_matches(key, valid, n=1)
            raise ConfigError(f"--filters: {spec!r}: unknown key {key!r} for {cls.name}"
                              + (f" (did you mean {near[0]!r}?)" if near else "")
                              + f"; valid keys: {', '.join(valid) or 'none'}")
    raise ConfigError(f"--filters: {spec!r}: compare takes filter names only; set the options in the config's "
                      f"[filter.{cls.name}] table (--config FILE.toml)")


@dataclass(frozen=True)
class CompareResult:
    """Outcome of :func:`compare`.

    Attributes
    ----------
    rows : the :class:`CompareRow` of every run, log-major in the order given.
    files : files written (``summary.csv``, ``report.md``, ``report.html``, the PNG figures);
        empty without ``out_dir``.
    out_dir : where they are, or None.
    jobs : worker processes used (1: in this process; with Dask: the cluster's workers).
    wall_s : wall time of the whole comparison, s (reading, filtering, report).
    log_series, run_series : the decimated plot data (by log; by (log, filter)).
    """

    rows: tuple[CompareRow, ...]
    files: tuple[Path, ...] = ()
    out_dir: Path | None = None
    jobs: int = 1
    wall_s: float = float("nan")
    log_series: Mapping[str, LogSeries | None] = field(default_factory=dict, repr=False)
    run_series: Mapping[tuple[str, str], RunSeries] = field(default_factory=dict, repr=False)

    @property
    def summary(self) -> pd.DataFrame:
        """``summary.csv`` as a DataFrame (columns :data:`SUMMARY_COLUMNS`, NaN for empty cells)."""
        return summary_frame(self.rows)

    @property
    def failed(self) -> list[CompareRow]:
        """The runs that failed (their ``status`` says why)."""
        return [r for r in self.rows if not r.ok]

    def check_baseline(self, baseline: Sequence[Mapping[str, object]] | str | Path,
                       tolerance_pct: float = DEFAULT_TOLERANCE_PCT) -> GateVerdict:
        """:func:`check_baseline` of these rows (``baseline``: rows of :func:`read_baseline` or a path)."""
        if not isinstance(baseline, Sequence) or isinstance(baseline, str):
            baseline = read_baseline(baseline)
        return check_baseline(self.rows, baseline, tolerance_pct)

    def check_limits(self, limits: Mapping[str, float] | str) -> GateVerdict:
        """:func:`check_limits` of these rows (``limits``: ``{"horizontal_rmse": 1.0}`` or ``"H=1.0,U=1.5"``)."""
        return check_limits(self.rows, parse_limits(limits) if isinstance(limits, str) else limits)

    def gate(self, *, baseline: Sequence[Mapping[str, object]] | str | Path | None = None,
             tolerance_pct: float = DEFAULT_TOLERANCE_PCT,
             max_rmse: Mapping[str, float] | str | None = None) -> GateVerdict:
        """Both gates at once (either may be None); one verdict."""
        parts = []
        if baseline is not None:
            parts.append(self.check_baseline(baseline, tolerance_pct))
        if max_rmse is not None:
            parts.append(self.check_limits(max_rmse))
        return GateVerdict.merge(parts)


def compare(logs: Sequence[str | Path], filters: Sequence[str], *, config: str | Path | None = None,
            reference: str | Path | None = None, jobs: int = 1, out_dir: str | Path | None = None,
            imu_topic: str | None = None, gnss_topic: str | None = None, reference_topic: str | None = None,
            report: bool = True, progress: ProgressFn | None = None, smooth: bool = False,
            executor: str = "local", scheduler: str | None = None,
            time_limit_s: float = DEFAULT_TIME_LIMIT_S) -> CompareResult:
    """Run every filter on every log; rows in (log, filter) order.

    Parameters
    ----------
    logs : log paths (anything :func:`navpp.api.read_log` reads).
    filters : registry names (:func:`parse_filters` checks a comma-separated list).
    config : a TOML file for every log; None: each log's ``navpp.toml``, else the defaults.
        Problems with this file, or with the filter options it gives, raise
        :class:`~navpp.errors.ConfigError` before anything runs; problems with a log's own
        ``navpp.toml`` are that log's rows.
    reference : a reference CSV; only with a single log (else each log's ``reference.csv``).
    jobs : worker processes, >= 1; 1 runs everything in this process (Dask: the LocalCluster size).
    out_dir : write ``summary.csv`` and (with ``report``) ``report.md``, ``report.html`` and the
        PNG figures there (the directory must exist); None writes nothing.
    imu_topic, gnss_topic, reference_topic : topic choices for ROS logs.
    report : collect the plot series and, with ``out_dir``, write the report.
    progress : ``progress(stage, fraction)``: stages ``"reading <log>"``, ``"<log> <filter>"`` and
        ``"all runs"`` (fraction of runs finished).
    executor : ``"local"`` (this process, or a pool of ``jobs`` processes) or ``"dask"``
        (:mod:`navpp.dask_executor`: the runs as tasks on a Dask cluster; needs
        ``pip install 'navpp[dask]'``).  The rows are the same, bit for bit, either way.
    scheduler : with ``executor="dask"``, the address of a running scheduler
        (``tcp://host:8786``); None starts a ``LocalCluster`` of ``jobs`` worker processes
        (one per CPU when ``jobs`` is 1).  The workers must see the logs at the same paths.
    smooth : also smooth every run backwards (Rauch-Tung-Striebel): each (log, filter) gives two
        rows, the forward filter's (``runtime_s`` its own time) and ``"<filter>+rts"`` (the
        smoothed solution; ``runtime_s`` forward plus smoothing), side by side in the summary,
        the report and its plots.
    time_limit_s : the watchdog: a run (reading its log included) that takes longer than this
        many seconds per 100,000 IMU samples (at least :data:`WATCHDOG_MIN_S`) is stopped and
        becomes a failed row naming the log; the other runs go on.  0 turns it off.  Local runs
        only (the CLI's process and ``jobs`` workers), not Dask.

    Returns
    -------
    CompareResult
        Failed runs are rows whose ``status`` is the reason; nothing raises for them.

    Raises
    ------
    ConfigError
        Bad arguments (no logs, ``jobs < 1``, ``reference`` with several logs, unknown filter,
        a bad ``config``).
    InputError
        An output file cannot be written.
    """
    from . import api
    from .filters import get_filter

    t_start = time.perf_counter()
    logs = [str(p) for p in logs]
    names = list(filters)
    if not logs:
        raise ConfigError("compare: give at least one log")
    if not names:
        raise ConfigError("compare: give at least one filter")
    for n in names:
        get_filter(n)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"--jobs must be an integer >= 1, got {jobs!r}")
    if isinstance(time_limit_s, bool) or not (isinstance(time_limit_s, (int, float)) and time_limit_s >= 0.0
                                              and math.isfinite(time_limit_s)):
        raise ConfigError(f"--time-limit must be a number of seconds >= 0 (0: no watchdog), got {time_limit_s!r}")
    if executor not in EXECUTORS:
        raise ConfigError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if scheduler is not None and executor != "dask":
        raise ConfigError("--scheduler names a Dask scheduler: use it with --executor dask")
    dup = sorted({p for p in logs if logs.count(p) > 1})
    if dup:
        raise ConfigError(f"compare: {', '.join(dup)} given more than once")
    if reference is not None and len(logs) > 1:
        raise ConfigError("--reference names one reference file; with several logs put a "
                          "reference.csv (or <log>.reference.csv) beside each log")
    if config is not None:
        cfg = api.resolve_config(Path(logs[0]), config)      # the explicit file, whatever the log
        for n in names:                         # option errors first: they concern every log
            api.make_filter(n, cfg)
    tasks = [_Task(i * len(names) + j, log, name, None if config is None else str(config),
                   None if reference is None else str(reference), imu_topic, gnss_topic, reference_topic,
                   report, report and j == 0, bool(smooth), time_limit_s=float(time_limit_s))
             for i, log in enumerate(logs) for j, name in enumerate(names)]
    workers = min(jobs, len(tasks))
    out = Path(out_dir) if out_dir is not None else None
    # created (and proved writable) before any run; removed again if the comparison fails
    created = api.prepare_out_dir(out, "out_dir") if out is not None else []
    labels = [x for n in names for x in ((n, smoothed_name(n)) if smooth else (n,))]
    draw = _FigurePlan(logs, labels) if report and out is not None else None
    lock = OutDirLock(out, "--out", extra_leftovers=COMPARE_FILES) if out is not None else None
    try:
        if lock is not None:         # held until the files are written: a second run into out fails at once
            lock.acquire()
        if executor == "dask":
            from .dask_executor import run_dask

            outcomes, plots, workers = run_dask(tasks, jobs if jobs > 1 else None, scheduler, progress, draw)
        elif workers == 1:
            outcomes, plots = _run_serial(tasks, progress, draw)
        else:
            outcomes, plots = _run_parallel(tasks, workers, progress, draw)
        rows = tuple(row for o in outcomes for row, _ in o.rows())
        log_series = {o.row.log: o.log_series for o in outcomes if tasks[o.index].log_series}
        run_series = {(row.log, row.filter): series for o in outcomes for row, series in o.rows()
                      if series is not None}
        files: list[Path] = []
        if out is not None:
            with interrupts.commit():        # an interrupt from here on lets the writing finish
                files.append(write_summary(out / "summary.csv", rows))
                if draw is not None:
                    from .report import write_report

                    files += write_report(out, rows, plots)
    except BaseException:
        if lock is not None:
            lock.release()
        api.remove_created_dirs(created)
        raise
    if lock is not None:
        lock.release()
    return CompareResult(rows, tuple(files), out, workers, time.perf_counter() - t_start, log_series, run_series)


class _FigurePlan:
    """Which figures to draw: file stems per log and a colour per filter, fixed before any run
    finishes so that a log's figures can be drawn as soon as its own runs are done."""

    def __init__(self, logs: Sequence[str], filters: Sequence[str]) -> None:
        from .report import figure_names

        self.slugs, self.colors = figure_names(logs, filters)

    def job(self, log: str, outcomes: Sequence[_Outcome]):
        from .report import FigureJob

        log_series = next((o.log_series for o in outcomes if o.log_series is not None), None)
        runs = {row.filter: series for o in outcomes for row, series in o.rows() if row.ok and series is not None}
        return FigureJob(log, self.slugs[log], log_series, runs, self.colors)


def _run_serial(tasks: Sequence[_Task], progress: ProgressFn | None, draw: _FigurePlan | None
                ) -> tuple[list[_Outcome], dict[str, list]]:
    cache = _RecordingCache()
    out: list[_Outcome] = []
    try:
        for k, task in enumerate(tasks):
            interrupts.check()            # an interrupt a run turned into a failed row stops here
            out.append(_execute(task, cache, progress))
            if progress:
                progress("all runs", (k + 1) / len(tasks))
    finally:
        cache.clear()
    plots: dict[str, list] = {}
    if draw is not None:
        from .report import render_figures

        for log in dict.fromkeys(t.log for t in tasks):
            plots[log] = render_figures(draw.job(log, [o for o in out if o.row.log == log]))
    return out, plots


#: Run time of each filter relative to the EKF on the same log (rounded; measured on
#: sample_data/drive and on 900 s simulated drives); used only to order the parallel tasks.
RELATIVE_COST = {"ekf": 1.0, "aekf": 1.0, "sage-husa": 1.2, "ckf": 4.0, "ukf": 4.0, "aukf": 4.0,
                 "vce-ckf": 6.0, "rwckf": 8.0, "sif": 8.0}


def _relative_cost(name: str) -> float:
    """:data:`RELATIVE_COST`; for a filter not in it, 5 for a sigma-point filter (it pushes
    2n+1 points through the strapdown at every step) and 1 otherwise."""
    if name in RELATIVE_COST:
        return RELATIVE_COST[name]
    from .filters import get_filter
    from .filters.sigma import SigmaPointFilter

    return 5.0 if issubclass(get_filter(name), SigmaPointFilter) else 1.0


def _schedule(tasks: Sequence[_Task]) -> list[_Task]:
    """Submission order for the pool: log by log (consecutive tasks of a log tend to meet the
    worker that read it, and a log's figures can be drawn while the next log runs), the costly
    filters of each log first (longest processing time first: the last tasks to start are short
    ones, so no worker idles long at the end)."""
    cost = {name: _relative_cost(name) for name in dict.fromkeys(t.filter for t in tasks)}
    log_order = {log: k for k, log in enumerate(dict.fromkeys(t.log for t in tasks))}
    return sorted(tasks, key=lambda t: (log_order[t.log], -cost[t.filter], t.index))


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread (POSIX): a process spawned meanwhile inherits the mask, so
    a Ctrl-C during its start-up (before :func:`_die_with_parent` runs) cannot print a
    traceback from it.  A SIGINT arriving meanwhile is delivered here on leaving."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _run_parallel(tasks: Sequence[_Task], workers: int, progress: ProgressFn | None, draw: _FigurePlan | None
                  ) -> tuple[list[_Outcome], dict[str, list]]:
    """The tasks on ``workers`` spawned processes, in :func:`_schedule` order.  Each log's
    figures are drawn by the pool too (one task per figure), as soon as that log's runs are
    done, while the other runs go on."""
    import multiprocessing
    import queue as queue_mod
    from collections import Counter, deque
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    from .report import FIGURE_KINDS, render_figures

    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue() if progress else None

    def drain() -> None:
        while q is not None:
            try:
                stage, fraction = q.get_nowait()
            except queue_mod.Empty:
                return
            progress(stage, fraction)

    results: dict[int, _Outcome] = {}
    drawn: dict[tuple[str, str], list] = {}          # (log, figure kind) -> plots
    left = Counter(t.log for t in tasks)
    todo_runs = deque(_schedule(tasks))
    todo_figures: deque = deque()                    # FigureJobs, drawn before further runs start
    in_flight: dict[Any, Any] = {}                   # future -> _Task or FigureJob
    ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(q, os.getpid()))

    def draw_here(job) -> None:                      # the pool broke: draw it in this process
        drawn[job.log, job.kinds[0]] = render_figures(job)

    try:
        # the executor runs what it is given in order: hand it only a little more than it can
        # run, so a log's figures overtake the runs still waiting
        while todo_runs or todo_figures or in_flight:
            while (todo_runs or todo_figures) and len(in_flight) < workers + 1:
                item = todo_figures.popleft() if todo_figures else todo_runs.popleft()
                try:
                    with _sigint_blocked():       # a worker started now is born deaf to Ctrl-C
                        fut = ex.submit(_execute_in_worker if isinstance(item, _Task) else render_figures, item)
                except (BrokenProcessPool, RuntimeError):
                    if isinstance(item, _Task):
                        results[item.index] = _failed(item, "a worker process died (killed, or out of memory?)")
                        left[item.log] -= 1
                    else:
                        draw_here(item)
                    continue
                in_flight[fut] = item
            done, _ = wait(in_flight, timeout=0.1 if progress else None, return_when=FIRST_COMPLETED)
            drain()
            for fut in done:
                item = in_flight.pop(fut)
                if not isinstance(item, _Task):
                    try:
                        drawn[item.log, item.kinds[0]] = fut.result()
                    except BrokenProcessPool:
                        draw_here(item)
                    continue
                try:
                    results[item.index] = fut.result()
                except BrokenProcessPool:
                    results[item.index] = _failed(item, "a worker process died (killed, or out of memory?)")
                except Exception as exc:  # noqa: BLE001  (e.g. a result that does not unpickle: a row, not a crash)
                    results[item.index] = _failed(item, _internal(exc))
                if progress:
                    progress("all runs", len(results) / len(tasks))
                left[item.log] -= 1
            for log in [log for log, n in left.items() if n == 0]:
                del left[log]
                if draw is not None:
                    whole = draw.job(log, [results[t.index] for t in tasks if t.log == log])
                    todo_figures.extend(replace(whole, kinds=(kind,)) for kind in FIGURE_KINDS)
        drain()
    except BaseException:
        _stop_workers(ex)
        raise
    ex.shutdown(wait=True)
    if q is not None:
        q.close()
    return [results[t.index] for t in tasks], plots_by_log(tasks, drawn) if draw is not None else {}


def plots_by_log(tasks: Sequence[_Task], drawn: Mapping[tuple[str, str], list]) -> dict[str, list]:
    """The figures drawn per (log, figure kind) as each log's list, in report order."""
    from .report import FIGURE_KINDS

    return {log: [p for kind in FIGURE_KINDS for p in drawn.get((log, kind), [])]
            for log in dict.fromkeys(t.log for t in tasks)}


# --------------------------------------------------------------------------- summary.csv


def summary_csv(rows: Sequence[CompareRow]) -> str:
    """The rows as CSV text with :data:`SUMMARY_COLUMNS` (empty cells where not applicable)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r.summary())
    return buf.getvalue()


def summary_frame(rows: Sequence[CompareRow]) -> pd.DataFrame:
    """``summary.csv`` as pandas reads it back (empty cells are NaN, nothing else is)."""
    import pandas as pd

    return pd.read_csv(io.StringIO(summary_csv(rows)), keep_default_na=False, na_values=[""],
                       dtype={"log": str, "filter": str, "status": str, "reference": str})


def write_summary(path: Path, rows: Sequence[CompareRow]) -> Path:
    """Write ``summary.csv`` atomically; :class:`~navpp.errors.InputError` if it cannot be written."""
    write_text_file(path, summary_csv(rows))
    return path


def write_text_file(path: Path, data: str | bytes) -> None:
    """``data`` to ``path`` atomically (text as UTF-8, bytes as they are);
    :class:`~navpp.errors.InputError` naming the file."""
    from .api import _os_reason
    from .errors import InputError
    from .io.writers import atomic_write

    try:
        atomic_write(path, lambda f: f.write(data), mode="wb" if isinstance(data, bytes) else "w")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({_os_reason(exc)})") from None


# --------------------------------------------------------------------------- CI gates


@dataclass(frozen=True)
class GateFailure:
    """One metric of one row beyond its gate.

    ``gate`` is ``"baseline"`` or ``"max-rmse"``; ``reference`` the baseline value or the limit
    (m); ``allowed`` the largest value that passes (m); ``value`` this run's value (m; None when
    there is none, e.g. no reference); ``worse_pct`` how much ``value`` exceeds ``reference``, %
    of ``reference`` (inf for a zero reference; None without a value).
    """

    log: str
    filter: str
    metric: str
    gate: str
    reference: float
    allowed: float
    value: float | None
    worse_pct: float | None
    reason: str = ""

    def as_dict(self) -> dict[str, object]:
        d = {k: getattr(self, k) for k in ("log", "filter", "metric", "gate", "reference", "allowed", "value",
                                           "worse_pct", "reason")}
        if isinstance(d["worse_pct"], float) and not math.isfinite(d["worse_pct"]):
            d["worse_pct"] = None
        return d


@dataclass(frozen=True)
class GateVerdict:
    """Outcome of the CI gates: ``failures`` (empty = passed), ``checks`` (metric comparisons
    made), ``notes`` (what was not compared and why: rows missing from the baseline, baseline
    rows not run, failed runs skipped)."""

    failures: tuple[GateFailure, ...] = ()
    checks: int = 0
    notes: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return not self.failures

    @staticmethod
    def merge(parts: Iterable[GateVerdict]) -> GateVerdict:
        parts = list(parts)
        return GateVerdict(tuple(f for p in parts for f in p.failures), sum(p.checks for p in parts),
                           tuple(n for p in parts for n in p.notes))

    def as_dict(self) -> dict[str, object]:
        return {"passed": self.passed, "checks": self.checks, "failures": [f.as_dict() for f in self.failures],
                "notes": list(self.notes)}


def parse_tolerance(text: str | float) -> float:
    """``"5%"`` or ``"5"`` (or 5.0) -> 5.0 percent; ConfigError unless a finite number >= 0."""
    s = str(text).strip()
    num = s[:-1].strip() if s.endswith("%") else s
    try:
        value = float(num)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value < 0.0 or not num:
        raise ConfigError(f"--tolerance must be a percentage >= 0 such as 5% (or 5), got {str(text)!r}")
    return value


def parse_limits(text: str) -> dict[str, float]:
    """``"H=1.0,U=1.5"`` -> ``{"horizontal_rmse": 1.0, "up_rmse": 1.5}`` (metres).

    Keys (case-insensitive): ``H``/``horizontal``, ``E``/``east``, ``N``/``north``, ``U``/``up``,
    ``3D``; values finite numbers >= 0 (m).  ConfigError for anything else, a repeated key, or
    an empty list.
    """
    out: dict[str, float] = {}
    items = [s.strip() for s in str(text).split(",") if s.strip()]
    if not items:
        raise ConfigError(f"--max-rmse: give limits such as H=1.0,U=1.5 (metres), got {text!r}")
    for item in items:
        key, eq, val = item.partition("=")
        column = LIMIT_KEYS.get(key.strip().lower())
        if not eq or column is None:
            raise ConfigError(f"--max-rmse: {item!r} is not KEY=METRES with KEY one of H, E, N, U, 3D "
                              "(or horizontal, east, north, up)")
        try:
            limit = float(val)
        except ValueError:
            limit = float("nan")
        if not math.isfinite(limit) or limit < 0.0:
            raise ConfigError(f"--max-rmse: {item!r}: the limit must be a finite number of metres >= 0")
        if column in out:
            raise ConfigError(f"--max-rmse: {key.strip()} ({column}) given more than once")
        out[column] = limit
    return out


def read_baseline(path: str | Path) -> list[dict[str, object]]:
    """Rows of an earlier ``summary.csv``: ``log``, ``filter``, ``status`` and the metric columns
    it has, as floats (None for empty cells).

    Raises ConfigError naming the file (and line) if it cannot be read, lacks the ``log`` /
    ``filter`` columns and every one of :data:`BASELINE_METRICS`, holds a non-numeric metric,
    or repeats a (log, filter) row.
    """
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            records = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ConfigError(f"--baseline {path}: cannot read ({reason.lower()})") from None
    missing = [c for c in ("log", "filter") if c not in header]
    if missing or not any(m in header for m in BASELINE_METRICS):
        raise ConfigError(f"--baseline {path}: not a navpp compare summary.csv (needs the columns log, filter "
                          f"and {' or '.join(BASELINE_METRICS)}; found {', '.join(header) or 'none'})")
    metric_cols = [c for c in SUMMARY_COLUMNS if c in header and (c.endswith(("_mae", "_rmse", "_p95", "_max")))]
    rows: list[dict[str, object]] = []
    seen: set[tuple[str, str]] = set()
    for line, rec in enumerate(records, start=2):
        row: dict[str, object] = {"log": rec.get("log") or "", "filter": rec.get("filter") or "",
                                  "status": rec.get("status") or "ok"}
        for c in metric_cols:
            cell = (rec.get(c) or "").strip()
            try:
                row[c] = float(cell) if cell else None
            except ValueError:
                raise ConfigError(f"--baseline {path}, line {line}: {c} = {cell!r} is not a number") from None
        key = (str(row["log"]), str(row["filter"]))
        if key in seen:
            raise ConfigError(f"--baseline {path}, line {line}: {key[1]} on {key[0]} appears twice")
        seen.add(key)
        rows.append(row)
    return rows


def _log_name(log: str) -> str:
    return Path(log).name or log


def _match_baseline(rows: Sequence[CompareRow], baseline: Sequence[Mapping[str, object]]
                    ) -> tuple[list[tuple[CompareRow, Mapping[str, object] | None]], list[Mapping[str, object]]]:
    """Pair rows with baseline rows: the same ``log`` text and filter; else the same log *name*
    (last path component) and filter, when that name is unique among this run's logs and among
    the baseline's.  Returns the pairs and the baseline rows no row matched."""
    exact = {(str(b["log"]), str(b["filter"])): b for b in baseline}
    by_name: dict[tuple[str, str], list[Mapping[str, object]]] = {}
    for b in baseline:
        by_name.setdefault((_log_name(str(b["log"])), str(b["filter"])), []).append(b)
    base_names: dict[str, set[str]] = {}
    for b in baseline:
        base_names.setdefault(_log_name(str(b["log"])), set()).add(str(b["log"]))
    run_names: dict[str, set[str]] = {}
    for r in rows:
        run_names.setdefault(_log_name(r.log), set()).add(r.log)
    pairs, used = [], set()
    for r in rows:
        b = exact.get((r.log, r.filter))
        if b is None:
            name = _log_name(r.log)
            cands = by_name.get((name, r.filter), [])
            if len(cands) == 1 and len(run_names[name]) == 1 and len(base_names.get(name, ())) == 1:
                b = cands[0]
        if b is not None:
            used.add(id(b))
        pairs.append((r, b))
    return pairs, [b for b in baseline if id(b) not in used]


def _value(row: CompareRow, column: str) -> float | None:
    v = row.summary().get(column)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def check_baseline(rows: Sequence[CompareRow], baseline: Sequence[Mapping[str, object]],
                   tolerance_pct: float = DEFAULT_TOLERANCE_PCT,
                   metrics: Sequence[str] = BASELINE_METRICS) -> GateVerdict:
    """The ``--baseline`` gate: no metric worse than the baseline by more than ``tolerance_pct``.

    For every ok row matched to a baseline row (:func:`_match_baseline`: same log and filter)
    and every metric in ``metrics`` (default horizontal and up RMSE, m) that the baseline row
    has, the row fails when ``value > baseline * (1 + tolerance_pct / 100)`` (a value exactly at
    that limit passes; the comparison allows 1e-9 m for rounding), or when the row has no value
    (e.g. its log lost its reference).  Not failures, but listed in ``notes``: rows not in the
    baseline (new logs or filters), baseline rows not run, baseline rows without that metric,
    and rows whose run failed (those already fail the command with exit code 1).
    """
    tol = parse_tolerance(tolerance_pct)
    failures, notes, checks = [], [], 0
    pairs, unused = _match_baseline(rows, baseline)
    for r, b in pairs:
        what = f"{r.filter} on {r.log}"
        if b is None:
            notes.append(f"{what}: not in the baseline (not compared)")
            continue
        if not r.ok:
            notes.append(f"{what}: the run failed (not compared)")
            continue
        for m in metrics:
            base = b.get(m)
            if not isinstance(base, (int, float)) or not math.isfinite(base):
                notes.append(f"{what}: the baseline has no {m} (not compared)")
                continue
            checks += 1
            base = float(base)
            allowed = base * (1.0 + tol / 100.0)
            value = _value(r, m)
            if value is None:
                failures.append(GateFailure(r.log, r.filter, m, "baseline", base, allowed, None, None,
                                            "no value in this run (no reference?)"))
            elif value > allowed + _LIMIT_SLACK_M:
                worse = (value - base) / base * 100.0 if base > 0 else math.inf
                failures.append(GateFailure(r.log, r.filter, m, "baseline", base, allowed, value, worse,
                                            f"more than {tol:g}% above the baseline"))
    for b in unused:
        notes.append(f"{b['filter']} on {b['log']}: in the baseline but not run")
    return GateVerdict(tuple(failures), checks, tuple(notes))


def check_limits(rows: Sequence[CompareRow], limits: Mapping[str, float]) -> GateVerdict:
    """The ``--max-rmse`` gate: ``value <= limit`` (m) for every ok row and every limited column
    (:data:`LIMIT_KEYS` values: ``horizontal_rmse``, ``east_rmse``, ``north_rmse``, ``up_rmse``,
    ``3d_rmse``).  A row without the value (no reference) fails: the limit cannot be shown to
    hold.  Failed runs are listed in ``notes`` (they already fail the command with exit code 1).
    """
    valid = set(LIMIT_KEYS.values())
    for k, v in limits.items():
        if k not in valid:
            raise ConfigError(f"--max-rmse: unknown metric {k!r}; use one of {', '.join(sorted(valid))}")
        if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ConfigError(f"--max-rmse: the limit for {k} must be a finite number of metres >= 0, got {v!r}")
    failures, notes, checks = [], [], 0
    for r in rows:
        if not r.ok:
            notes.append(f"{r.filter} on {r.log}: the run failed (not checked)")
            continue
        for m, limit in limits.items():
            checks += 1
            value = _value(r, m)
            if value is None:
                failures.append(GateFailure(r.log, r.filter, m, "max-rmse", float(limit), float(limit), None, None,
                                            "no value in this run (no reference?)"))
            elif value > limit:
                worse = (value - limit) / limit * 100.0 if limit > 0 else math.inf
                failures.append(GateFailure(r.log, r.filter, m, "max-rmse", float(limit), float(limit), value,
                                            worse, "above the limit"))
    return GateVerdict(tuple(failures), checks, tuple(notes))

