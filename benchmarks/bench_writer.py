"""Speed of navpp's writers: ``write_trajectory_csv`` against ``pandas.DataFrame.to_csv``, and
whole ``navpp process --format mcap`` runs of one or more checkouts side by side.

Run from the repository root::

    python benchmarks/bench_writer.py [--rows 450000] [--repeat 3]
    python benchmarks/bench_writer.py --mcap-process [--repo DIR ...] [--duration 3600] [--repeat 3]

The first form builds a realistic solution (a 100 Hz drive of 75 min at 450 000 rows: unix
times, a wandering track near 30.5 N 114.3 E, velocities, attitude, position std) and prints the
best wall time of each writer (including the fsync and rename of the atomic write for navpp) and
the file sizes.

The second measures what decides between a library writer and hand-written encoding: the wall
time of a whole ``navpp process LOG --format mcap`` run (read, filter, metrics, all files
written), each in a fresh ``python -m navpp`` process of the checkout given by ``--repo`` (its
directory on ``PYTHONPATH``; default this checkout).  The log is simulated once with ``navpp
simulate --duration D --seed 7`` (125 Hz IMU, 5 Hz GNSS, as ``bench_process.py``) into the work
directory.  Every checkout first runs once unmeasured (numba compile cache and page cache warm),
then the checkouts run alternately ``--repeat`` times (A B A B ...), and each also runs the same
command with ``--format csv``, so the difference shows what writing ``trajectory.mcap`` costs.
Prints per checkout the best and median seconds and each checkout's best against the first's.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from navpp.io.writers import TRAJECTORY_COLUMNS, write_trajectory_csv
from navpp.recording import Solution

REPO = Path(__file__).resolve().parents[1]


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


def _navpp(repo: Path, args: list[str]) -> float:
    """Wall seconds of ``python -m navpp ARGS`` run in ``repo`` with ``repo`` on ``PYTHONPATH``."""
    env = {**os.environ, "PYTHONPATH": str(repo)}
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "navpp", *args], cwd=repo, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"bench_writer: navpp {' '.join(args)} failed in {repo}:\n{proc.stderr}")
    return seconds


def mcap_process(repos: list[Path], duration: float, repeat: int, workdir: Path) -> None:
    """Whole ``navpp process --format mcap`` (and ``--format csv``) runs of ``repos``, alternated."""
    log = workdir / f"sim-{int(duration)}s"
    if not (log / "imu.csv").exists():
        t = _navpp(repos[0], ["simulate", str(log), "--duration", str(duration), "--seed", "7"])
        print(f"simulated {duration:.0f} s log in {t:.1f} s -> {log}")
    out = workdir / "out"
    times: dict[tuple[int, str], list[float]] = {}
    for rnd in range(repeat + 1):                           # round 0 warms the caches, unmeasured
        for fmt in ("mcap", "csv"):
            for i, repo in enumerate(repos):
                shutil.rmtree(out, ignore_errors=True)
                t = _navpp(repo, ["process", str(log), "--format", fmt, "--out", str(out), "-q"])
                if fmt == "mcap":
                    size = (out / "trajectory.mcap").stat().st_size
                if rnd:
                    times.setdefault((i, fmt), []).append(t)
    shutil.rmtree(out, ignore_errors=True)
    print(f"log: {log} ({duration:.0f} s, 125 Hz IMU, 5 Hz GNSS), {repeat} alternating runs per checkout and "
          f"format; last trajectory.mcap {size / 1e6:.1f} MB")
    best0 = min(times[(0, "mcap")])
    for i, repo in enumerate(repos):
        mc, cs = times[(i, "mcap")], times[(i, "csv")]
        print(f"{repo}:")
        print(f"  process --format mcap  best {min(mc):7.2f} s  median {statistics.median(mc):7.2f} s  "
              f"({best0 / min(mc):.2f}x the first checkout's speed)")
        print(f"  process --format csv   best {min(cs):7.2f} s  median {statistics.median(cs):7.2f} s  "
              f"(mcap - csv, best: {min(mc) - min(cs):+.2f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=450_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--mcap-process", action="store_true",
                        help="time whole `navpp process --format mcap` runs of --repo checkouts")
    parser.add_argument("--repo", type=Path, action="append",
                        help="a checkout of navpp to run (repeatable; default: this one)")
    parser.add_argument("--duration", type=float, default=3600.0, help="simulated log length, s")
    parser.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench-writer")
    args = parser.parse_args()
    if args.mcap_process:
        args.workdir.mkdir(parents=True, exist_ok=True)
        mcap_process([r.resolve() for r in (args.repo or [REPO])], args.duration, args.repeat, args.workdir)
        return

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
