"""The papers' benchmarks, run with the same filter code that processes logs.

Each benchmark is registered by name (``navpp bench NAME``) and returns a :class:`BenchResult`:
rows of our figure next to the paper's, plus notes saying which readings of the paper
(ALGORITHMS.md, "The papers' benchmarks: readings") were taken and where we differ.

Nothing here is tuned toward a paper's number: the models follow the papers' equations, the
filters are the registry's filters with their documented defaults.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ..errors import ConfigError


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
    series: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Benchmark:
    """A registered benchmark: ``run(runs, seed, filters) -> BenchResult``; ``default_runs``
    is the paper's number of Monte Carlo runs; ``filters`` the filters the paper compares."""

    name: str
    title: str
    run: Callable[[int, int, Sequence[str]], BenchResult]
    default_runs: int
    filters: tuple[str, ...]


BENCHMARKS: dict[str, Benchmark] = {}


def register_benchmark(name: str, title: str, default_runs: int, filters: Sequence[str]):
    """Decorator registering ``run(runs, seed, filters) -> BenchResult`` under ``name``."""
    def deco(fn: Callable[[int, int, Sequence[str]], BenchResult]):
        BENCHMARKS[name] = Benchmark(name, title, fn, int(default_runs), tuple(filters))
        return fn
    return deco


def _load() -> None:
    """Import the modules that register benchmarks (kept separate: each is self-contained)."""
    from . import bench_sins, bench_small  # noqa: F401


def parse_filter_spec(spec: str) -> tuple[str, dict]:
    """``"rwckf"`` -> ("rwckf", {}); ``"rwckf[covariance=random; candidates=32]"`` -> the name and
    its options (values read as TOML values, bare words as strings), checked against the
    filter's Options (ConfigError naming the key otherwise)."""
    import tomllib

    from . import get_filter

    spec = spec.strip()
    name, opts = spec, {}
    if "[" in spec:
        if not spec.endswith("]"):
            raise ConfigError(f"filter {spec!r}: write options as name[key=value; key=value]")
        name, body = spec[:-1].split("[", 1)
        name = name.strip()
        for item in filter(None, (part.strip() for part in body.split(";"))):
            if "=" not in item:
                raise ConfigError(f"filter {spec!r}: option {item!r} is not key=value")
            key, value = (v.strip() for v in item.split("=", 1))
            try:
                opts[key] = tomllib.loads(f"v = {value}")["v"]
            except tomllib.TOMLDecodeError:
                opts[key] = value
    cls = get_filter(name)
    cls.options_from_mapping(opts, f"filter {spec!r}")
    return name, opts


def make_bench_filter(spec: str, seed: int):
    """A fresh filter for a benchmark run, as :func:`navpp.api.make_filter` builds it from the
    spec's options: a seeded generator and the chi-square gate off (the papers' filters do not
    gate; navpp's gate is a GNSS setting)."""
    from ..api import make_filter
    from ..config import Config, GnssConfig

    name, opts = parse_filter_spec(spec)
    return make_filter(name, Config(gnss=GnssConfig(gate_probability=0.0), filters={name: opts}), seed=seed)


def get_benchmark(name: str) -> Benchmark:
    _load()
    try:
        return BENCHMARKS[name]
    except KeyError:
        raise ConfigError(f"unknown benchmark {name!r}; choose one of: {', '.join(sorted(BENCHMARKS))}") from None


def run_benchmark(name: str, *, runs: int | None = None, seed: int = 0,
                  filters: Sequence[str] | None = None) -> BenchResult:
    """Run benchmark ``name`` with ``runs`` Monte Carlo runs (default: the paper's) and the
    given filters (default: the paper's comparison); the wall time is filled in."""
    bench = get_benchmark(name)
    n = bench.default_runs if runs is None else int(runs)
    if n < 1:
        raise ConfigError(f"--runs must be >= 1, got {n}")
    chosen = tuple(filters) if filters else bench.filters
    for f in chosen:
        parse_filter_spec(f)              # unknown names and options fail with the choices
    t0 = time.perf_counter()
    result = bench.run(n, int(seed), chosen)
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
