"""Paper 001 Table 5's protocol on the real logs navpp has (``navpp bench paper001-table5-real``).

Paper 001 scores CKF and RWCKF on a car against a DGPS reference: mean absolute error and RMSE of
the longitude error (east, m) and of the latitude error (north, m).  Its log is not public, so the
same four figures are measured here, for every filter and for the raw GNSS, on the real logs of
``../shared/data/real`` (its README):

- ``walk_0827``: hand-held RTK receiver + raw MEMS IMU; the RTK fixes of two 15-s windows
  (``outages.csv``) are withheld from ``gnss.csv`` and are the reference
  (``reference_outages.csv``; ``reference.csv`` in the repository's copy ``sample_data/walk_0827``).
- ``car_balzer82``: car, consumer GNSS, no reference: the GNSS is withheld in 10-s windows every
  30 s (:data:`CAR_WINDOWS_S`, on the fixes' stamps) and the trajectory is compared with the
  withheld fixes, taken at the time they are valid (the log README's 0.51 s latency,
  :data:`CAR_LATENCY_S`).  Those fixes
  carry 3-5 m errors of their own, so this reference is far looser than a DGPS one.

"Raw GNSS" is a receiver that holds its last fix through each window: at each reference epoch,
the last fix before it (before the window, for the car).  Errors are taken only inside the
windows, where the filters run on the IMU alone.  Every run uses navpp's defaults with every
``[auto]`` step on and the log's own facts (``mounting.toml`` / ``navpp.toml``), as
``benchmarks/bench_real.py`` does; filters that draw random numbers (``rwckf``, ``sif``: those
with a ``seed`` option) run ``runs`` seeds (``seed``, ``seed + 1``, ...), the others once.

The logs are found in ``--data DIR`` (``python -m navpp.papers.table5_real --data DIR``) or in
the ``NAVPP_REAL_DATA`` environment variable (a folder holding ``walk_0827/`` and/or
``car_balzer82/``); with neither, the repository's ``sample_data/walk_0827`` is used alone.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConfigError, NavppError
from .filter_spec import parse_filter_spec
from .registry import BenchResult, Row, register_benchmark

if TYPE_CHECKING:
    from ..config import Config

NAME = "paper001-table5-real"
ENV = "NAVPP_REAL_DATA"
FILTERS = ("ekf", "aekf", "ckf", "ukf", "vce-ckf", "rwckf", "aukf", "sif")
#: Paper 001 Table 5 (m): filter -> ((longitude MAE, RMSE), (latitude MAE, RMSE)).
PAPER_TABLE5 = {"ckf": ((6.2985, 9.3567), (4.9886, 8.3168)),
                "rwckf": ((3.1482, 4.9667), (2.3516, 3.6235))}
CAR_LATENCY_S = 0.51                                          #: car_balzer82's GNSS latency (its README), s
CAR_WINDOWS_S = tuple((float(s), 10.0) for s in np.arange(30.0, 200.0, 30.0))  #: (start, length) after t0, s
HELD = "gnss-held"                                            #: the raw-GNSS row's filter column
_SHIPPED = Path(__file__).resolve().parents[2] / "sample_data" / "walk_0827"


@dataclass(frozen=True)
class RealLog:
    """One log to score: its folder, configuration file and, for walk_0827, the reference CSV."""

    name: str
    folder: Path
    config: Path | None
    reference: Path | None


def find_logs(data: str | Path | None = None) -> tuple[list[RealLog], list[str]]:
    """The logs under ``data`` (else ``$NAVPP_REAL_DATA``, else the shipped walk_0827) and notes
    on what is missing; :class:`ConfigError` (one line) when no log is found."""
    where = data if data is not None else os.environ.get(ENV) or None
    notes: list[str] = []
    if where is None:
        if not (_SHIPPED / "imu.csv").is_file():
            raise ConfigError(f"{NAME}: no real logs: pass --data DIR or set {ENV} to the folder holding "
                              f"walk_0827/ and car_balzer82/")
        notes.append(f"logs: the repository's sample_data/walk_0827 only; set {ENV} (or --data) to the "
                     f"real-logs folder to add car_balzer82")
        return [RealLog("walk_0827", _SHIPPED, _SHIPPED / "navpp.toml", _SHIPPED / "reference.csv")], notes
    root = Path(where)
    label = "--data" if data is not None else ENV
    if not root.is_dir():
        raise ConfigError(f"{NAME}: {label} {root}: no such folder (it should hold walk_0827/ and car_balzer82/)")
    logs = []
    walk = root / "walk_0827"
    if walk.is_dir():
        ref = walk / "reference_outages.csv"
        if not ref.is_file():
            ref = walk / "reference.csv"      # the repository's copy names the withheld fixes so
        cfg = walk / "mounting.toml"
        if not cfg.is_file():
            cfg = walk / "navpp.toml"
        if not ref.is_file():
            raise ConfigError(f"{NAME}: {walk}: no reference_outages.csv (the withheld RTK fixes)")
        logs.append(RealLog("walk_0827", walk, cfg if cfg.is_file() else None, ref))
    else:
        notes.append(f"no walk_0827/ in {root}")
    car = root / "car_balzer82"
    if car.is_dir():
        logs.append(RealLog("car_balzer82", car, None, None))
    else:
        notes.append(f"no car_balzer82/ in {root}")
    if not logs:
        raise ConfigError(f"{NAME}: {label} {root} holds neither walk_0827/ nor car_balzer82/")
    return logs, notes


def east_north_errors(t_ref: np.ndarray, lat_ref_deg: np.ndarray, lon_ref_deg: np.ndarray, t_est: np.ndarray,
                      lat_est_deg: np.ndarray, lon_est_deg: np.ndarray) -> np.ndarray:
    """(K, 2) east (longitude) and north (latitude) errors in m of an estimate interpolated
    linearly in time at the reference epochs ``t_ref`` (s), in the ENU frame of the first
    reference point (heights left out)."""
    from .. import geodesy

    lat = np.interp(t_ref, t_est, lat_est_deg)
    lon = np.interp(t_ref, t_est, lon_est_deg)
    lat0, lon0 = math.radians(float(lat_ref_deg[0])), math.radians(float(lon_ref_deg[0]))
    zero = np.zeros(len(t_ref))
    a = geodesy.geodetic_to_enu(np.radians(lat), np.radians(lon), zero, lat0, lon0, 0.0)
    b = geodesy.geodetic_to_enu(np.radians(lat_ref_deg), np.radians(lon_ref_deg), zero, lat0, lon0, 0.0)
    return np.asarray((a - b)[:, :2], dtype=float)


def _held(t_fix: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Index of the last fix strictly before each query time (-1 for none)."""
    return np.searchsorted(t_fix, t_query, side="left") - 1


def _config(log: RealLog, filt: str, seed: int) -> tuple[str, Config]:
    from ..config import AutoConfig, load_config

    cfg = load_config(log.config)
    name, opts = parse_filter_spec(filt)
    cls_opts = dict(opts)
    if _is_random(filt):
        cls_opts["seed"] = int(seed)
    filters = dict(cfg.filters)
    filters[name] = {**dict(filters.get(name, {})), **cls_opts}
    return name, replace(cfg, auto=AutoConfig(), filters=filters)


def _is_random(filt: str) -> bool:
    """A filter that draws random numbers: its options carry a ``seed``."""
    from ..filters import get_filter

    name, _ = parse_filter_spec(filt)
    return "seed" in getattr(get_filter(name).Options, "__dataclass_fields__", {})


def _walk_errors(log: RealLog, filt: str, seed: int) -> np.ndarray:
    import pandas as pd

    import navpp

    name, cfg = _config(log, filt, seed)
    res = navpp.process(log.folder, filter_name=name, config=cfg, reference=log.reference, write=False)
    ref = pd.read_csv(log.reference)
    t = ref["t"].to_numpy() - res.recording.t0_ns * 1e-9
    sol = res.solution
    return east_north_errors(t, ref["lat"].to_numpy(), ref["lon"].to_numpy(), sol.t, sol.lat_deg, sol.lon_deg)


def _walk_held(log: RealLog) -> np.ndarray:
    import pandas as pd

    g, r = pd.read_csv(log.folder / "gnss.csv"), pd.read_csv(log.reference)
    k = _held(g["t"].to_numpy(), r["t"].to_numpy())
    if np.any(k < 0):
        raise ConfigError(f"{NAME}: {log.reference}: a reference epoch precedes the first fix of gnss.csv")
    return east_north_errors(r["t"].to_numpy(), r["lat"].to_numpy(), r["lon"].to_numpy(), r["t"].to_numpy(),
                             g["lat"].to_numpy()[k], g["lon"].to_numpy()[k])


def _car_fixes(log: RealLog) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The car's fixes: stamps as logged (s after t0), latitude, longitude (deg)."""
    from .. import api
    from ..config import Config

    gn = api.read_log(log.folder, Config.default()).gnss
    return gn.t, gn.lat_deg, gn.lon_deg


def _car_windows(t_stamp: np.ndarray, by_valid_time: bool) -> list[np.ndarray]:
    """Per window, which fixes are scored: those withheld (stamp inside the window: the outages
    are cut on the stamps, before navpp's clock-offset estimate moves them); with
    ``by_valid_time``, bench_real.py's choice (valid time inside the window), which scores
    about 5 fixes per window that the filter used and leaves out 5 withheld ones."""
    if by_valid_time:
        t = t_stamp - CAR_LATENCY_S
        return [(t >= s) & (t < s + dur) for s, dur in CAR_WINDOWS_S]
    # the windows remove start <= stamp <= start + duration (navpp.outages.apply_outages)
    return [(t_stamp >= s) & (t_stamp <= s + dur) for s, dur in CAR_WINDOWS_S]


def _car_errors(log: RealLog, filt: str, seed: int, by_valid_time: bool = False) -> np.ndarray:
    import navpp

    stamp, lat, lon = _car_fixes(log)
    t = stamp - CAR_LATENCY_S                   # the time a fix is valid at
    name, cfg = _config(log, filt, seed)
    sol = navpp.process(log.folder, filter_name=name, config=cfg, gnss_outages=list(CAR_WINDOWS_S),
                        write=False).solution
    out = [east_north_errors(t[sel], lat[sel], lon[sel], sol.t, sol.lat_deg, sol.lon_deg)
           for sel in _car_windows(stamp, by_valid_time)]
    return np.concatenate(out)


def _car_held(log: RealLog) -> np.ndarray:
    stamp, lat, lon = _car_fixes(log)
    out = []
    for (s, _), sel in zip(CAR_WINDOWS_S, _car_windows(stamp, False)):
        k = int(_held(stamp, np.array([s]))[0])       # the last fix given before the window
        n = int(sel.sum())
        out.append(east_north_errors(stamp[sel], lat[sel], lon[sel], stamp[sel], np.full(n, lat[k]),
                                     np.full(n, lon[k])))
    return np.concatenate(out)


def figures(err: np.ndarray) -> dict[str, float]:
    """MAE and RMSE (m) of the east (longitude) and north (latitude) columns of ``err`` (K, 2),
    and the horizontal RMSE (bench_real's figure)."""
    e, n = err[:, 0], err[:, 1]
    return {"lon_mae": float(np.mean(np.abs(e))), "lon_rmse": math.sqrt(float(np.mean(e ** 2))),
            "lat_mae": float(np.mean(np.abs(n))), "lat_rmse": math.sqrt(float(np.mean(n ** 2))),
            "h_rmse": math.sqrt(float(np.mean(e ** 2 + n ** 2)))}


_QUANTITIES = (("lon_mae", "longitude (east) MAE", 0, 0), ("lon_rmse", "longitude (east) RMSE", 0, 1),
               ("lat_mae", "latitude (north) MAE", 1, 0), ("lat_rmse", "latitude (north) RMSE", 1, 1),
               ("h_rmse", "horizontal RMSE", -1, -1))


def _rows(log: str, filt: str, runs: list[dict[str, float]]) -> list[Row]:
    rows = []
    paper = PAPER_TABLE5.get(filt)
    for key, label, i, j in _QUANTITIES:
        v = np.array([r[key] for r in runs])
        note = f"mean of {v.size} seeds, sd {np.std(v, ddof=1):.3f} m" if v.size > 1 else ""
        rows.append(Row(f"{log} {label}", filt, float(v.mean()), paper[i][j] if paper and i >= 0 else None, "m",
                        note))
    return rows


def run_table5_real(runs: int, seed: int, filters: Sequence[str], data: str | Path | None = None) -> BenchResult:
    """Table 5's four figures per log for each filter (random filters over ``runs`` seeds) and for
    the raw GNSS holding its last fix."""
    logs, notes = find_logs(data)
    rows: list[Row] = []
    for log in logs:
        walk = log.name == "walk_0827"
        rows += _rows(log.name, HELD, [figures(_walk_held(log) if walk else _car_held(log))])
        for filt in filters:
            seeds = [seed + k for k in range(runs)] if _is_random(filt) else [seed]
            try:
                got = [figures(_walk_errors(log, filt, s) if walk else _car_errors(log, filt, s)) for s in seeds]
            except NavppError as exc:
                notes.append(f"{log.name} {filt}: failed: {str(exc)[:240]}")
                continue
            rows += _rows(log.name, filt, got)
    notes += [
        "paper: a car, SINS 125 Hz + GPS 5 Hz, 1000 s, DGPS reference (0.5 m), GPS outages not stated; here "
        "the errors are inside GNSS windows withheld from the filters (IMU alone), against RTK fixes "
        "(walk_0827, 2 x 15 s) or the withheld consumer fixes themselves (car_balzer82, 6 x 10 s, 3-5 m errors)",
        f"{HELD}: a receiver holding its last fix through each window; filters with a seed option (rwckf, "
        f"sif): seeds {seed}..{seed + runs - 1}, sd = seed-to-seed standard deviation; the others: one run",
    ]
    return BenchResult(NAME, "Paper 001 Table 5 protocol on real logs (longitude/latitude MAE, RMSE)", rows, notes,
                       runs, seed)


@register_benchmark(NAME, "Paper 001 Table 5 protocol on real logs (walk_0827, car_balzer82)", 3, FILTERS)
def run(runs: int, seed: int, filters: Sequence[str]) -> BenchResult:
    """``navpp bench paper001-table5-real``: the logs from ``$NAVPP_REAL_DATA`` (else the shipped walk)."""
    return run_table5_real(runs, seed, filters)


def main(argv: list[str] | None = None) -> int:
    """``python -m navpp.papers.table5_real [--data DIR] [--runs N] [--seed S] [--filters a,b]``."""
    import time

    from .registry import format_result

    ap = argparse.ArgumentParser(prog="python -m navpp.papers.table5_real", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=None, help=f"folder holding walk_0827/, car_balzer82/ (default: ${ENV})")
    ap.add_argument("--runs", type=int, default=3, help="seeds of the random filters (rwckf, sif)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--filters", default=",".join(FILTERS))
    args = ap.parse_args(argv)
    try:
        if args.runs < 1 or args.seed < 0:
            raise ConfigError("--runs must be >= 1 and --seed >= 0")
        chosen = [f.strip() for f in args.filters.split(",") if f.strip()]
        for f in chosen:
            parse_filter_spec(f)
        t0 = time.perf_counter()
        result = run_table5_real(args.runs, args.seed, chosen, args.data)
        result.seconds = time.perf_counter() - t0
    except NavppError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(format_result(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
