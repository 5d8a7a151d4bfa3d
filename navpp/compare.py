"""``navpp compare``: several filters on one or more logs, one MAE/RMSE table.

Each log is read once; every filter runs on the same :class:`~navpp.recording.Recording` with
the log's own configuration (``--config`` or the log's ``navpp.toml``).  A filter that fails on
a log (divergence, a configuration it rejects) becomes a row with its one-line reason and
does not stop the others.  The table is also written as ``summary.csv`` (atomically).

Full reports (plots, HTML) and parallel execution are later work (INTERFACES.md).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from .errors import ConfigError, NavppError

SUMMARY_COLUMNS = ("log", "filter", "status", "epochs", "east_mae", "east_rmse", "north_mae", "north_rmse",
                   "up_mae", "up_rmse", "horizontal_mae", "horizontal_rmse", "horizontal_p95", "3d_rmse",
                   "gnss_epochs", "gnss_rejected", "runtime_s")


@dataclass(frozen=True)
class CompareRow:
    """One filter on one log: ``status`` is "ok" or the one-line reason it failed; ``metrics``
    the :func:`navpp.metrics.compute_metrics` dict (None without a reference or on failure);
    ``runtime_s`` the filter's processing time (s, without kernel compilation)."""

    log: str
    filter: str
    status: str
    metrics: dict | None
    gnss_epochs: int = 0
    gnss_rejected: int = 0
    runtime_s: float = float("nan")

    def summary(self) -> dict[str, object]:
        """The row as ``summary.csv`` values (position errors in metres, ENU)."""
        out: dict[str, object] = {"log": self.log, "filter": self.filter, "status": self.status,
                                  "gnss_epochs": self.gnss_epochs, "gnss_rejected": self.gnss_rejected,
                                  "runtime_s": round(self.runtime_s, 4)}
        m = self.metrics
        if m is not None:
            pos = m["position_m"]
            out["epochs"] = m["epochs"]
            for axis in ("east", "north", "up", "horizontal"):
                out[f"{axis}_mae"] = round(pos[axis]["mae"], 4)
                out[f"{axis}_rmse"] = round(pos[axis]["rmse"], 4)
            out["horizontal_p95"] = round(pos["horizontal"]["p95"], 4)
            out["3d_rmse"] = round(pos["3d"]["rmse"], 4)
        return out


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
        get_filter(n)
    return names


def compare(logs: Sequence[str | Path], filters: Sequence[str], *, config: str | Path | None = None,
            reference: str | Path | None = None, imu_topic: str | None = None, gnss_topic: str | None = None,
            reference_topic: str | None = None,
            progress: Callable[[str, float], None] | None = None) -> list[CompareRow]:
    """Run every filter on every log; rows in (log, filter) order.

    A log that cannot be read raises (nothing to compare on it); a filter that fails on a log
    gives a row whose ``status`` is the reason.  Configuration problems that concern the
    filter itself (unknown option in ``[filter.<name>]``) are raised: they are the user's to fix
    before any comparison means something.
    """
    from . import api, engine
    from .metrics import compute_metrics

    rows: list[CompareRow] = []
    for log in logs:
        log = Path(log)
        cfg = api.resolve_config(log, config)
        made = {name: api.make_filter(name, cfg) for name in filters}     # option errors first
        rec = api.read_log(log, cfg, reference=reference, imu_topic=imu_topic, gnss_topic=gnss_topic,
                           reference_topic=reference_topic,
                           progress=(lambda f, s=f"reading {log.name}": progress(s, f)) if progress else None)
        for name in filters:
            filt = made[name]
            try:
                res = engine.run(rec, cfg, filt, progress=(lambda f, s=f"{log.name} {name}": progress(s, f))
                                 if progress else None)
            except NavppError as exc:
                rows.append(CompareRow(str(log), name, str(exc), None))
                continue
            metrics = None
            if rec.reference is not None:
                metrics = compute_metrics(res.solution, rec.reference, filter_name=name, log=str(log),
                                          reference=rec.reference.source or "", runtime_s=res.runtime_s,
                                          imu_samples=len(rec.imu), gnss_epochs=res.gnss_epochs,
                                          gnss_rejected=res.gnss_rejected, gnss=rec.gnss,
                                          lever_arm_m=cfg.gnss.lever_arm_m)
            rows.append(CompareRow(str(log), name, "ok", metrics, res.gnss_epochs, res.gnss_rejected, res.runtime_s))
    return rows


def summary_csv(rows: Sequence[CompareRow]) -> str:
    """The rows as CSV text with :data:`SUMMARY_COLUMNS` (empty cells where not applicable)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r.summary())
    return buf.getvalue()


def write_summary(path: Path, rows: Sequence[CompareRow]) -> None:
    from .io.writers import atomic_write

    text = summary_csv(rows)
    atomic_write(path, lambda f: f.write(text))
