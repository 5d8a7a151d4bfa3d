"""The CI gates of ``navpp compare``: ``--baseline`` (no metric worse than an earlier
``summary.csv`` by more than a tolerance) and ``--max-rmse`` (fixed limits).

Both compare the summary values as written in ``summary.csv`` (metres, rounded to 0.1 mm) and
return a :class:`GateVerdict`: the failures, the number of comparisons made, and notes on what
was not compared and why.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError
from .rows import RAW_GNSS, SUMMARY_COLUMNS, CompareRow

#: Columns ``--baseline`` compares (m): horizontal and vertical RMSE.
BASELINE_METRICS = ("horizontal_rmse", "up_rmse")

#: ``--max-rmse`` keys (case-insensitive) -> ``summary.csv`` column (m).
LIMIT_KEYS = {"h": "horizontal_rmse", "horizontal": "horizontal_rmse", "e": "east_rmse", "east": "east_rmse",
              "n": "north_rmse", "north": "north_rmse", "u": "up_rmse", "up": "up_rmse", "3d": "3d_rmse"}


#: Default ``--tolerance`` with ``--baseline``, percent.
DEFAULT_TOLERANCE_PCT = 5.0

#: Slack (m) on the baseline limit ``baseline * (1 + tolerance)``: absorbs the floating-point
#: rounding of that product (a value exactly at the limit passes); far below the 0.1 mm
#: resolution of the summary values, so it never changes a real decision.
_LIMIT_SLACK_M = 1e-9


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
        if (rec.get("filter") or "") == RAW_GNSS:       # the log's GNSS fixes, not a run: never gated
            continue
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
