"""One run of a comparison: one filter on one log, from names to a row and its plot series.

A :class:`RunTask` holds plain values only (paths, names, flags), so it pickles small and can
be sent to a worker process or a Dask worker; :func:`run_task` reads the log (through a
:class:`RecordingCache`, so the filters of one log that meet the same worker read it once),
runs the filter and returns a :class:`RunOutcome`: the row, and the decimated series the
report plots.  Every failure (an unreadable log, a diverging filter, the watchdog, a bug)
becomes the row's ``status``; nothing raises.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..config import with_memory
from ..errors import NavppError
from .rows import CompareRow, smoothed_name
from .series import LogSeries, RunSeries, log_series_of, run_series_of
from .watchdog import (
    WATCHDOG_BYTES_PER_SAMPLE,
    Watchdog,
    WatchdogExpired,
    log_size_bytes,
    watchdog_limit_s,
    watchdog_message,
)

ProgressFn = Callable[[str, float], None]   # progress(stage label, fraction done 0..1)


@dataclass(frozen=True)
class RunTask:
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
    odometry_topic: str | None = None   # --odometry-topic (None: automatic, "none": off)
    reference_anchor: str | None = None  # --reference-anchor "LAT,LON,ALT" of a local-frame reference
    memory: int | None = None   # --memory: bytes the smoother's store may hold (None: [output] memory)


@dataclass(frozen=True)
class RunOutcome:
    """What a run returns: its row (and, for a smoothed run, the ``"<filter>+rts"`` row after
    it), with the plot series of each and, for the first filter of a log, the log's own series."""

    index: int
    row: CompareRow
    series: RunSeries | None = None
    log_series: LogSeries | None = None
    smoothed: tuple[CompareRow, RunSeries | None] | None = None    # the "<filter>+rts" row of a smoothed run

    def rows(self) -> list[tuple[CompareRow, RunSeries | None]]:
        """The forward row and, for a smoothed run, the smoothed one after it, with their series."""
        return [(self.row, self.series)] + ([self.smoothed] if self.smoothed is not None else [])


class RecordingCache:
    """The last (config, recording) read, keyed by what determines them; read errors are kept
    too, so the other filters of an unreadable log fail at once with the same message."""

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.value: Any = None

    def get(self, task: RunTask, progress: ProgressFn | None) -> tuple[Any, Any, list[int]]:
        """(config, recording with the config's simulated outages removed, fixes each outage
        removed) of the task's log; the read error again (a NavppError) for an unreadable one."""
        from .. import api

        key = (task.log, task.config, task.reference, task.imu_topic, task.gnss_topic, task.reference_topic,
               task.odometry_topic, task.reference_anchor)
        if key != self.key:
            self.key, self.value = None, None          # free the previous recording first
            log = Path(task.path or task.log)
            label = f"reading {Path(task.log).name}"
            limit = watchdog_limit_s(task.time_limit_s, log_size_bytes(log) / WATCHDOG_BYTES_PER_SAMPLE)
            try:
                cfg = api.resolve_config(log, task.config)
                if task.memory is not None:
                    cfg = with_memory(cfg, task.memory)
                with Watchdog(limit):
                    rec = api.read_log(log, cfg, reference=task.reference, imu_topic=task.imu_topic,
                                       gnss_topic=task.gnss_topic, reference_topic=task.reference_topic,
                                       odometry_topic=task.odometry_topic,
                                       reference_anchor=task.reference_anchor,
                                       progress=(lambda f: progress(label, f)) if progress else None)
                if progress:
                    progress(label, 1.0)
                # [gnss] outages of the log's config: the same simulated outages as `navpp process`
                rec, removed = api.apply_outages(rec, cfg.gnss.outages, str(log))
                self.value = (cfg, rec, [w["gnss_removed"] for w in removed])
            except NavppError as exc:
                self.value = exc
            except WatchdogExpired:      # the log's other runs fail at once with the same message
                self.value = NavppError(watchdog_message(task.log, task.time_limit_s, limit, None))
            except Exception as exc:  # noqa: BLE001  (a bug, or a file no reader expected: a row, not a crash)
                self.value = NavppError(internal_error(exc))
            self.key = key
        if isinstance(self.value, NavppError):
            raise self.value
        return self.value

    def clear(self) -> None:
        """Forget the cached recording (frees its memory)."""
        self.key, self.value = None, None


def internal_error(exc: BaseException) -> str:
    """The status of a run stopped by an unexpected exception (a bug): its type and first line."""
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


def failed_outcome(task: RunTask, status: str, log_series: LogSeries | None = None) -> RunOutcome:
    """The outcome of a run that failed: its row(s) with ``status`` (on one line) and no metrics."""
    row = CompareRow(task.log, task.filter, " ".join(status.split()), None)
    smoothed = (replace(row, filter=smoothed_name(task.filter)), None) if task.smooth else None
    return RunOutcome(task.index, row, None, log_series, smoothed)


def run_task(task: RunTask, cache: RecordingCache, progress: ProgressFn | None) -> RunOutcome:
    """Run one filter on one log; every failure becomes the row's status."""
    from .. import api, engine

    try:
        cfg, rec, removed = cache.get(task, progress)
    except NavppError as exc:
        return failed_outcome(task, str(exc))
    log_series = None
    try:
        log_series = log_series_of(rec, tuple(cfg.gnss.outages)) if task.log_series else None
        label = f"{Path(task.log).name} {task.filter}"
        filt = api.make_filter(task.filter, cfg)
        limit = watchdog_limit_s(task.time_limit_s, len(rec.imu))
        with Watchdog(limit):
            res = engine.run(rec, cfg, filt, progress=(lambda f: progress(label, f)) if progress else None,
                             smooth=task.smooth)
        # the forward row's time is the forward filter's; the smoothed row's includes the smoothing
        forward_s = res.forward_runtime_s

        def metrics_of(sol, name: str, runtime_s: float) -> dict | None:
            return api.run_metrics(rec, cfg, res, sol, filter_name=name, log=task.log, runtime_s=runtime_s,
                                   windows=cfg.gnss.outages, removed=removed)

        metrics = metrics_of(res.solution, task.filter, forward_s)
        series = run_series_of(rec, res.solution, res.diagnostics, filt) if task.series else None
        smoothed = None
        if res.smoothed is not None:
            name = smoothed_name(task.filter)
            sm_metrics = metrics_of(res.smoothed.solution, name, res.runtime_s)
            sm_series = None
            if task.series:      # the diagnostics are the forward filter's: plotted once, with its row
                sm_series = replace(run_series_of(rec, res.smoothed.solution, res.diagnostics, filt), adaptive=False,
                                    diag_t_s=None, r_std_m=None, factors={})
            smoothed = (sm_metrics, sm_series)
    except NavppError as exc:
        return failed_outcome(task, str(exc), log_series)
    except WatchdogExpired:
        return failed_outcome(task, watchdog_message(task.log, task.time_limit_s, limit, len(rec.imu)), log_series)
    except Exception as exc:  # noqa: BLE001  (a bug in one filter must not lose the other runs)
        return failed_outcome(task, internal_error(exc), log_series)
    ref_source = (rec.reference.source or "reference") if rec.reference is not None else ""
    warnings = tuple(_naming_log(w, task.log) for w in (*rec.warnings, *res.warnings))
    row = CompareRow(task.log, task.filter, "ok", metrics, res.gnss_epochs, res.gnss_rejected, forward_s,
                     len(rec.imu), ref_source, warnings)
    sm_row = None
    if smoothed is not None:
        sm_row = (replace(row, filter=smoothed_name(task.filter), metrics=smoothed[0], runtime_s=res.runtime_s),
                  smoothed[1])
    return RunOutcome(task.index, row, series, log_series, sm_row)
