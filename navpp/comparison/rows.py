"""The rows of a comparison: one filter on one log, and ``summary.csv`` made of them.

Values in ``summary.csv`` are metres (position errors, ENU and horizontal, rounded to
0.1 mm), counts, and seconds (``runtime_s``); a row whose run failed has its reason in
``status`` and empty metric cells.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..outfiles import write_text_file

if TYPE_CHECKING:
    import pandas as pd

#: Columns of ``summary.csv``, in file order: position errors in metres (MAE, RMSE, 95th
#: percentile and maximum; ENU, horizontal, 3-D), counts, ``runtime_s`` (s), the reference's
#: source.  Readers index them by name; new columns go at the end.
SUMMARY_COLUMNS = ("log", "filter", "status", "epochs", "east_mae", "east_rmse", "north_mae", "north_rmse",
                   "up_mae", "up_rmse", "horizontal_mae", "horizontal_rmse", "horizontal_p95", "3d_rmse",
                   "gnss_epochs", "gnss_rejected", "runtime_s", "horizontal_max", "up_max", "imu_samples", "reference")

#: Position-error columns of ``summary.csv`` (m); the report highlights the minimum of each per log.
ERROR_COLUMNS = ("east_mae", "east_rmse", "north_mae", "north_rmse", "up_mae", "up_rmse",
                 "horizontal_mae", "horizontal_rmse")


#: ``filter`` of the row of a log's raw GNSS fixes against the reference (one per log with a
#: reference, after the log's filter rows): not a run, no run time, never in a CI gate.
RAW_GNSS = "raw GNSS"

#: Suffix of the filter name in the row of a smoothed run (``ekf+rts``).
SMOOTHED_SUFFIX = "+rts"


def smoothed_name(filter_name: str) -> str:
    """The row label of ``filter_name``'s smoothed run: ``"ekf"`` -> ``"ekf+rts"``."""
    return filter_name + SMOOTHED_SUFFIX


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

    @property
    def is_raw_gnss(self) -> bool:
        """True for a log's raw-GNSS row (:func:`raw_gnss_rows`), not a filter's run."""
        return self.filter == RAW_GNSS

    def summary(self) -> dict[str, object]:
        """The row as ``summary.csv`` values (position errors in metres, ENU, rounded to 0.1 mm);
        keys without a value (no reference, failed run) are left out."""
        out: dict[str, object] = {"log": self.log, "filter": self.filter, "status": self.status,
                                  "gnss_epochs": self.gnss_epochs, "gnss_rejected": self.gnss_rejected,
                                  "runtime_s": round(self.runtime_s, 4), "imu_samples": self.imu_samples,
                                  "reference": self.reference}
        if self.is_raw_gnss:          # the fixes themselves: no run, so no run figures
            for key in ("gnss_rejected", "runtime_s", "imu_samples"):
                del out[key]
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


def raw_gnss_row(rows: Sequence[CompareRow], log: str) -> CompareRow | None:
    """The raw-GNSS row of ``log``: its GNSS fixes against the reference antenna position
    (``metrics["gnss_position_m"]`` of :func:`navpp.metrics.compute_metrics`, the same for every
    filter of the log: taken from its first ok row), filter :data:`RAW_GNSS`, ``epochs`` and
    ``gnss_epochs`` the fixes compared; None without a reference or a fix inside it."""
    for r in rows:
        if r.log != log or not r.ok or r.is_raw_gnss or r.metrics is None:
            continue
        g = r.metrics.get("gnss_position_m")
        if not g or not g.get("epochs"):
            return None
        return CompareRow(log, RAW_GNSS, "ok", {"epochs": int(g["epochs"]), "position_m": g},
                          gnss_epochs=int(g["epochs"]), reference=r.reference)
    return None


def with_raw_gnss(rows: Sequence[CompareRow]) -> list[CompareRow]:
    """``rows`` with each log's raw-GNSS row (:func:`raw_gnss_row`) after the log's last row."""
    out: list[CompareRow] = []
    logs = list(dict.fromkeys(r.log for r in rows if not r.is_raw_gnss))
    for log in logs:
        out += [r for r in rows if r.log == log and not r.is_raw_gnss]
        raw = raw_gnss_row(rows, log)
        if raw is not None:
            out.append(raw)
    return out


def summary_csv(rows: Sequence[CompareRow]) -> str:
    """The rows as CSV text with :data:`SUMMARY_COLUMNS` (empty cells where not applicable),
    each log's raw-GNSS row (:func:`with_raw_gnss`) after its filters' rows."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in with_raw_gnss(rows):
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
