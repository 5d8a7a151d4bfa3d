"""Speed of ``write_trajectory_csv`` against ``pandas.DataFrame.to_csv``.

Run from the repository root::

    python benchmarks/bench_writer.py [--rows 450000] [--repeat 3]

Builds a realistic solution (a 100 Hz drive of 75 min at 450 000 rows: unix times, a wandering
track near 30.5 N 114.3 E, velocities, attitude, position std) and prints the best wall time of
each writer (including the fsync and rename of the atomic write for navpp) and the file sizes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from navpp.io.writers import TRAJECTORY_COLUMNS, write_trajectory_csv
from navpp.recording import Solution


def realistic_solution(n: int, seed: int = 0) -> Solution:
    """A 100 Hz car drive with plausible magnitudes in every column."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(n) * dt
    heading = np.cumsum(rng.normal(0, 0.05, n)) % 360.0
    speed = np.clip(12.0 + np.cumsum(rng.normal(0, 0.01, n)), 0.0, 35.0)
    ve = speed * np.sin(np.radians(heading))
    vn = speed * np.cos(np.radians(heading))
    vu = rng.normal(0, 0.05, n)
    lat = 30.5 + np.cumsum(vn) * dt / 111_000.0
    lon = 114.3 + np.cumsum(ve) * dt / (111_000.0 * np.cos(np.radians(30.5)))
    alt = 25.0 + np.cumsum(vu) * dt
    roll = rng.normal(0, 1.5, n)
    pitch = rng.normal(0, 1.0, n)
    std = np.abs(rng.normal(0.05, 0.5, (n, 3)))
    return Solution(t=t, lat_deg=lat, lon_deg=lon, alt=alt, vel_enu=np.stack([ve, vn, vu], -1),
                    rph_deg=np.stack([roll, pitch, heading], -1), std_enu=std)


def best_of(repeat: int, fn) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=450_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    sol = realistic_solution(args.rows)
    t0_s = 1_700_000_000.0
    with tempfile.TemporaryDirectory() as tmp:
        ours = Path(tmp) / "trajectory.csv"
        theirs = Path(tmp) / "pandas.csv"
        t_ours = best_of(args.repeat, lambda: write_trajectory_csv(ours, sol, t0_s=t0_s))

        def with_pandas() -> None:
            df = pd.DataFrame(np.column_stack([
                t0_s + sol.t, sol.lat_deg, sol.lon_deg, sol.alt, sol.vel_enu, sol.rph_deg,
                sol.std_enu]), columns=list(TRAJECTORY_COLUMNS))
            df.to_csv(theirs, index=False)

        t_pandas = best_of(args.repeat, with_pandas)
        print(f"rows: {args.rows}")
        print(f"navpp write_trajectory_csv: {t_ours:.3f} s  ({ours.stat().st_size / 1e6:.1f} MB)")
        print(f"pandas DataFrame.to_csv:    {t_pandas:.3f} s  ({theirs.stat().st_size / 1e6:.1f} MB)")
        print(f"speed-up: {t_pandas / t_ours:.1f}x")


if __name__ == "__main__":
    main()
