"""The papers' benchmarks by name: what a run returns (:class:`BenchResult` of :class:`Row`),
the table ``navpp bench`` reads (:data:`BENCHMARKS`) and how a run is started and printed.

Each experiment module of :mod:`navpp.papers` registers its run function here with
:func:`register_benchmark`; the package ``__init__`` imports those modules, so this module
imports none of them.  Nothing here is tuned toward a paper's number: the models follow the
papers' equations, the filters are the registry's filters with their documented defaults.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from .filter_spec import parse_filter_spec


@dataclass(frozen=True)
class Row:
    """One figure: ``quantity`` (e.g. "position RMSE") of ``filter``, ours next to the paper's.

    unit : the unit of ``ours`` and ``paper``; paper : None when the paper gives no number;
    note : a short qualifier (e.g. "mean over 100 runs, 3 runs diverged").
    """

    quantity: str
    filter: str
    ours: float
    paper: float | None
    unit: str
    note: str = ""


@dataclass
class BenchResult:
    """What a benchmark run measured: rows, notes (readings, differences), the runs and seed
    used, and the wall time in s; ``series`` holds optional time series (name -> array) for
    plots and tests, e.g. VCE group factors over time."""

    name: str
    title: str
    rows: list[Row]
    notes: list[str]
    runs: int
    seed: int
    seconds: float = 0.0
    series: dict[str, np.ndarray] = field(default_factory=dict)


#: A benchmark's run function: ``run(runs, seed, filters) -> BenchResult``.
RunFunction = Callable[[int, int, Sequence[str]], BenchResult]


@dataclass(frozen=True)
class Benchmark:
    """A registered benchmark: ``run(runs, seed, filters) -> BenchResult``; ``default_runs``
    is the paper's number of Monte Carlo runs; ``filters`` the filters the paper compares.
    ``parallel``: ``run`` also takes ``jobs=N`` (worker processes); ``cpu_s_per_run``: the
    measured CPU seconds of one run of the paper's filters (0: short enough not to mention)."""

    name: str
    title: str
    run: RunFunction
    default_runs: int
    filters: tuple[str, ...]
    parallel: bool = False
    cpu_s_per_run: float = 0.0


#: name -> benchmark; filled by the experiment modules as :mod:`navpp.papers` imports them.
BENCHMARKS: dict[str, Benchmark] = {}


def register_benchmark(name: str, title: str, default_runs: int, filters: Sequence[str], *,
                       parallel: bool = False, cpu_s_per_run: float = 0.0
                       ) -> Callable[[RunFunction], RunFunction]:
    """Decorator registering ``run(runs, seed, filters) -> BenchResult`` under ``name``
    (``run(runs, seed, filters, jobs=N)`` too when ``parallel``)."""
    def deco(fn: RunFunction) -> RunFunction:
        BENCHMARKS[name] = Benchmark(name, title, fn, int(default_runs), tuple(filters), parallel,
                                     float(cpu_s_per_run))
        return fn
    return deco


def expected_cpu_s(name: str, runs: int | None, filters: Sequence[str] | None) -> float:
    """About how many CPU seconds benchmark ``name`` will take (0 when it is short): the measured
    cost per run scaled by the runs and the share of the paper's filters chosen."""
    bench = get_benchmark(name)
    n = bench.default_runs if runs is None else int(runs)
    share = len(filters) / len(bench.filters) if filters else 1.0
    return bench.cpu_s_per_run * n * share


def get_benchmark(name: str) -> Benchmark:
    """The benchmark registered as ``name``; :class:`ConfigError` listing the names otherwise."""
    try:
        return BENCHMARKS[name]
    except KeyError:
        raise ConfigError(f"unknown benchmark {name!r}; choose one of: {', '.join(sorted(BENCHMARKS))}") from None


def run_benchmark(name: str, *, runs: int | None = None, seed: int = 0,
                  filters: Sequence[str] | None = None, jobs: int = 1) -> BenchResult:
    """Run benchmark ``name`` with ``runs`` Monte Carlo runs (default: the paper's) and the
    given filters (default: the paper's comparison), on ``jobs`` worker processes where the
    benchmark can split its runs (the figures do not depend on ``jobs``; a benchmark that
    cannot says so in a note); the wall time is filled in."""
    bench = get_benchmark(name)
    n = bench.default_runs if runs is None else int(runs)
    if n < 1:
        raise ConfigError(f"--runs must be >= 1, got {n}")
    if jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {jobs}")
    chosen = tuple(filters) if filters else bench.filters
    for f in chosen:
        parse_filter_spec(f)              # unknown names and options fail with the choices
    t0 = time.perf_counter()
    if bench.parallel:
        result = bench.run(n, int(seed), chosen, jobs=int(jobs))  # type: ignore[call-arg]
    else:
        result = bench.run(n, int(seed), chosen)
        if jobs > 1:
            result.notes.append(f"--jobs {jobs} ignored: {name} runs in one process (it is short)")
    result.seconds = time.perf_counter() - t0
    return result


def format_result(result: BenchResult) -> str:
    """Plain-text table: quantity, filter, ours, paper, difference; then the notes."""
    runs = f"{result.runs} run{'s' if result.runs != 1 else ''}"
    lines = [f"{result.title}  ({runs}, seed {result.seed}, {result.seconds:.1f} s)", ""]
    head = ("quantity", "filter", "ours", "paper", "ours/paper")
    body = []
    for r in result.rows:
        paper = "-" if r.paper is None else f"{r.paper:.4g} {r.unit}"
        ratio = "-" if (r.paper is None or r.paper == 0) else f"{r.ours / r.paper:.2f}"
        body.append((r.quantity + (f" ({r.note})" if r.note else ""), r.filter, f"{r.ours:.4g} {r.unit}", paper,
                     ratio))
    widths = [max(len(str(c)) for c in col) for col in zip(head, *body)]
    for row in (head, *body):
        lines.append("  ".join(str(c).ljust(w) for c, w in zip(row, widths)).rstrip())
    if result.notes:
        lines.append("")
        lines.extend(f"- {n}" for n in result.notes)
    return "\n".join(lines)
