"""``navpp compare``: several filters on several logs, one MAE/RMSE table, a report and CI gates.

Every filter runs on every log (one *run* per log x filter) with the log's own configuration
(``config`` or the log's ``navpp.toml``).  A log that cannot be read, or a filter that fails on
a log (divergence, a configuration it rejects), becomes a row whose ``status`` is the one-line
reason; it never stops the other runs.  The rows are the same, bit for bit, whichever executor
ran them (only the measured ``runtime_s`` differs).

Outputs (all written atomically, :func:`navpp.io.writers.atomic_write`): ``summary.csv``
(:data:`SUMMARY_COLUMNS`), ``report.md`` with its PNG figures beside it, and the self-contained
``report.html``.

The modules, each one job:

- :mod:`~navpp.comparison.runner`: :func:`compare` (checks the arguments, runs the tasks on
  the chosen executor, writes the files) and :class:`CompareResult`;
- :mod:`~navpp.comparison.runs`: one run (a filter on a log) from a pickle-small task to a row,
  with the recording cache a worker keeps;
- :mod:`~navpp.comparison.pool` (this process, or spawned worker processes),
  :mod:`~navpp.comparison.dask_executor` (a Dask cluster), in
  :mod:`~navpp.comparison.schedule` order;
- :mod:`~navpp.comparison.watchdog`: stops a run that hangs;
- :mod:`~navpp.comparison.rows`: :class:`CompareRow` and ``summary.csv``;
- :mod:`~navpp.comparison.series`: the decimated plot series a run returns;
- :mod:`~navpp.comparison.figures`, :mod:`~navpp.comparison.report`: the PNG figures, and
  ``report.md`` / ``report.html``;
- :mod:`~navpp.comparison.gates`: the CI gates (:func:`check_baseline`, :func:`check_limits`),
  on the summary values as written in ``summary.csv`` (metres, rounded to 0.1 mm).

Python use::

    from navpp.comparison import compare, read_baseline
    result = compare(["drive.mcap", "city/"], ["ekf", "vce-ckf"], jobs=2, out_dir="out")
    result.summary                       # pandas DataFrame, the content of out/summary.csv
    verdict = result.check_baseline(read_baseline("old/summary.csv"), tolerance_pct=5.0)
    verdict.passed, verdict.failures
"""

from __future__ import annotations

from .gates import (
    BASELINE_METRICS,
    DEFAULT_TOLERANCE_PCT,
    LIMIT_KEYS,
    GateFailure,
    GateVerdict,
    check_baseline,
    check_limits,
    parse_limits,
    parse_tolerance,
    read_baseline,
)
from .rows import (
    ERROR_COLUMNS,
    SMOOTHED_SUFFIX,
    SUMMARY_COLUMNS,
    CompareRow,
    smoothed_name,
    summary_csv,
    summary_frame,
    write_summary,
)
from .runner import COMPARE_FILES, EXECUTORS, CompareResult, compare, parse_filters
from .schedule import RELATIVE_COST
from .series import CDF_POINTS, FACTOR_PREFIXES, LogSeries, RunSeries, minmax_decimate
from .watchdog import DEFAULT_TIME_LIMIT_S, WATCHDOG_BYTES_PER_SAMPLE, WATCHDOG_MIN_S, watchdog_limit_s

__all__ = [
    "BASELINE_METRICS",
    "CDF_POINTS",
    "COMPARE_FILES",
    "DEFAULT_TIME_LIMIT_S",
    "DEFAULT_TOLERANCE_PCT",
    "ERROR_COLUMNS",
    "EXECUTORS",
    "FACTOR_PREFIXES",
    "LIMIT_KEYS",
    "RELATIVE_COST",
    "SMOOTHED_SUFFIX",
    "SUMMARY_COLUMNS",
    "WATCHDOG_BYTES_PER_SAMPLE",
    "WATCHDOG_MIN_S",
    "CompareResult",
    "CompareRow",
    "GateFailure",
    "GateVerdict",
    "LogSeries",
    "RunSeries",
    "check_baseline",
    "check_limits",
    "compare",
    "minmax_decimate",
    "parse_filters",
    "parse_limits",
    "parse_tolerance",
    "read_baseline",
    "smoothed_name",
    "summary_csv",
    "summary_frame",
    "watchdog_limit_s",
    "write_summary",
]
