"""``compare()``: every filter on every log, on the chosen executor, then ``summary.csv`` and the report.

The arguments are checked first (a bad one raises :class:`~navpp.errors.ConfigError` before
anything runs); then one :class:`~navpp.comparison.runs.RunTask` per log x filter runs in this
process, on a pool of worker processes (:mod:`navpp.comparison.pool`) or on Dask
(:mod:`navpp.comparison.dask_executor`), and the rows, the summary and the figures are
collected into a :class:`CompareResult`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .. import interrupts
from ..config import parse_memory
from ..errors import ConfigError
from ..outfiles import claimed_out_dir
from .dask_executor import run_dask
from .figures import FigurePlan, Plot
from .gates import DEFAULT_TOLERANCE_PCT, GateVerdict, check_baseline, check_limits, parse_limits, read_baseline
from .pool import run_parallel, run_serial
from .report import write_report
from .rows import CompareRow, smoothed_name, summary_frame, write_summary
from .runs import ProgressFn, RunOutcome, RunTask
from .series import LogSeries, RunSeries
from .watchdog import DEFAULT_TIME_LIMIT_S

if TYPE_CHECKING:
    import pandas as pd

#: Files a comparison writes into its output directory (``*``: figure names ending so), whose
#: temporary files a killed run may leave behind (:func:`navpp.outdir.remove_leftovers`).
COMPARE_FILES = ("summary.csv", "report.md", "report.html", "*_trajectory.png", "*_error_time.png",
                 "*_error_cdf.png", "*_adaptive.png", "*_errors.png", "*_innovations.png",
                 "*_map.html")

#: Where ``compare`` runs the tasks (:func:`compare`'s ``executor``).
EXECUTORS = ("local", "dask")


def parse_filters(text: str) -> list[str]:
    """``"ekf,aekf, ckf"`` -> names, checked against the registry (ConfigError lists the choices)."""
    from ..filters import get_filter

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

    from ..filters import get_filter

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
            time_limit_s: float = DEFAULT_TIME_LIMIT_S, odometry_topic: str | None = None,
            jit: str | None = None, reference_anchor: str | Sequence[float] | None = None,
            memory: str | int | None = None) -> CompareResult:
    """Run every filter on every log; rows in (log, filter) order.

    Parameters
    ----------
    logs : log paths (anything :func:`navpp.api.read_log` reads).
    filters : registry names (:func:`parse_filters` checks a comma-separated list).
    config : a TOML file for every log; None: each log's ``navpp.toml``, else the defaults.
        Problems with this file, or with the filter options it gives, raise
        :class:`~navpp.errors.ConfigError` before anything runs; problems with a log's own
        ``navpp.toml`` are that log's rows.
    reference : a reference CSV or TUM file; only with a single log (else each log's ``reference.csv``).
    reference_anchor : origin of a local-frame reference (a TUM file, an Odometry / PoseStamped
        ``reference_topic``) as ``(lat_deg, lon_deg, alt_m)`` or ``"LAT,LON,ALT"``, as for
        :func:`navpp.api.process`; checked before anything runs (:class:`InputError`).
    jobs : worker processes, >= 1; 1 runs everything in this process (Dask: the LocalCluster size).
    out_dir : write ``summary.csv`` and (with ``report``) ``report.md``, ``report.html`` and the
        PNG figures there (the directory must exist); None writes nothing.
    imu_topic, gnss_topic, reference_topic, odometry_topic : topic choices for ROS logs
        (``odometry_topic="none"``: no odometry, any log).
    report : collect the plot series and, with ``out_dir``, write the report.
    progress : ``progress(stage, fraction)``: stages ``"reading <log>"``, ``"<log> <filter>"`` and
        ``"all runs"`` (fraction of runs finished).
    executor : ``"local"`` (this process, or a pool of ``jobs`` processes) or ``"dask"``
        (:mod:`navpp.comparison.dask_executor`: the runs as tasks on a Dask cluster; needs
        ``pip install 'navpp[dask]'``).  The rows are the same, bit for bit, either way.
    scheduler : with ``executor="dask"``, the address of a running scheduler
        (``tcp://host:8786``); None starts a ``LocalCluster`` of ``jobs`` worker processes
        (one per CPU when ``jobs`` is 1).  The workers must see the logs at the same paths.
    smooth : also smooth every run backwards (Rauch-Tung-Striebel): each (log, filter) gives two
        rows, the forward filter's (``runtime_s`` its own time) and ``"<filter>+rts"`` (the
        smoothed solution; ``runtime_s`` forward plus smoothing), side by side in the summary,
        the report and its plots.
    memory : memory each run's smoother store and IMU-rate output may each hold before they spill
        to a temporary file (``"500MB"``, ``"1GB"``, bytes); overrides ``[output] memory``; None uses it.
    time_limit_s : the watchdog: a run (reading its log included) that takes longer than this
        many seconds per 100,000 IMU samples (at least :data:`WATCHDOG_MIN_S`) is stopped and
        becomes a failed row naming the log; the other runs go on.  0 turns it off.  Local runs
        only (the CLI's process and ``jobs`` workers), not Dask.
    jit : ``"on"`` (compiled; the default unless ``$NAVPP_JIT`` says otherwise), ``"off"`` or
        ``"auto"``: compiled or interpreted kernels, here and in the ``jobs`` workers
        (:mod:`navpp.jitmode`); fixed in a process once its first run decided it.

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
        An output file cannot be written, or ``reference_anchor`` is not a position.
    """
    t_start = time.perf_counter()
    log_names = [str(p) for p in logs]
    names = list(filters)
    from .. import jitmode

    jitmode.choose(jit, [Path(p) for p in log_names], names, bool(smooth))
    _check_arguments(log_names, names, config=config, reference=reference, jobs=jobs, executor=executor,
                     scheduler=scheduler, time_limit_s=time_limit_s)
    anchor = _anchor_text(reference_anchor)
    budget = None if memory is None else parse_memory(memory, "--memory")
    tasks = [RunTask(i * len(names) + j, log, name, None if config is None else str(config),
                     None if reference is None else str(reference), imu_topic, gnss_topic, reference_topic,
                     report, report and j == 0, bool(smooth), time_limit_s=float(time_limit_s),
                     odometry_topic=odometry_topic, reference_anchor=anchor, memory=budget)
             for i, log in enumerate(log_names) for j, name in enumerate(names)]
    out = Path(out_dir) if out_dir is not None else None
    labels = [x for n in names for x in ((n, smoothed_name(n)) if smooth else (n,))]
    draw = FigurePlan(log_names, labels) if report and out is not None else None
    # created (and proved writable) before any run; removed again if the comparison fails
    with claimed_out_dir(out, "out_dir", COMPARE_FILES, lock_label="--out") if out is not None else nullcontext():
        outcomes, plots, workers = _run_tasks(tasks, executor, jobs, scheduler, progress, draw)
        rows = tuple(row for o in outcomes for row, _ in o.rows())
        log_series = {o.row.log: o.log_series for o in outcomes if tasks[o.index].log_series}
        run_series = {(row.log, row.filter): series for o in outcomes for row, series in o.rows()
                      if series is not None}
        files: list[Path] = []
        if out is not None:
            with interrupts.commit():        # an interrupt from here on lets the writing finish
                files.append(write_summary(out / "summary.csv", rows))
                if draw is not None:
                    files += write_report(out, rows, plots)
    return CompareResult(rows, tuple(files), out, workers, time.perf_counter() - t_start, log_series, run_series)


def _anchor_text(anchor: str | Sequence[float] | None) -> str | None:
    """``reference_anchor`` as the ``"LAT,LON,ALT"`` text the runs take, checked as ``navpp process``
    checks it (:func:`navpp.io.refposes.parse_anchor`: the same one-line :class:`InputError`)."""
    from ..io.refposes import parse_anchor

    text = anchor if anchor is None or isinstance(anchor, str) else ",".join(repr(float(v)) for v in anchor)
    if text is not None:
        parse_anchor(text)
    return text


def _check_arguments(logs: Sequence[str], names: Sequence[str], *, config: str | Path | None,
                     reference: str | Path | None, jobs: int, executor: str, scheduler: str | None,
                     time_limit_s: float) -> None:
    """:class:`~navpp.errors.ConfigError` for the first bad argument of :func:`compare`."""
    from .. import api
    from ..filters import get_filter

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


def _run_tasks(tasks: Sequence[RunTask], executor: str, jobs: int, scheduler: str | None,
               progress: ProgressFn | None, draw: FigurePlan | None
               ) -> tuple[list[RunOutcome], dict[str, list[Plot]], int]:
    """The tasks on the chosen executor: (outcomes in task order, figures per log, workers used)."""
    workers = min(jobs, len(tasks))
    if executor == "dask":
        return run_dask(tasks, jobs if jobs > 1 else None, scheduler, progress, draw)
    if workers == 1:
        outcomes, plots = run_serial(tasks, progress, draw)
    else:
        outcomes, plots = run_parallel(tasks, workers, progress, draw)
    return outcomes, plots, workers
