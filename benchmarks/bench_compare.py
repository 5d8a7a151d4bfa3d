"""Wall time of `navpp compare` serial versus `--jobs N` on simulated logs.

Usage:  python benchmarks/bench_compare.py [--logs 3] [--duration 900] [--filters ekf,aekf,ckf,vce-ckf,rwckf]
                                           [--jobs 2] [--repeat 1] [--workdir DIR]

Simulates the logs once (cached in the work directory; a different seed per log), warms numba's
on-disk compile cache with one short `navpp compare` of the same filters, then times the whole
command-line run, as a user sees it (process start, reading, filtering, summary.csv and the
report with its figures), first with `--jobs 1` and then with `--jobs N`, each in a fresh
process.  With `--repeat R` each is run R times, alternating, and the fastest is kept.  Prints
both wall times, the ratio parallel / serial, and checks that both runs wrote the same figures.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SUMMARY_FIGURES = ("east_rmse", "north_rmse", "up_rmse", "horizontal_rmse", "horizontal_p95", "3d_rmse",
                   "gnss_rejected", "status")


def compare_cmd(logs: list[Path], filters: str, jobs: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "navpp", "compare", *map(str, logs), "--filters", filters, "--jobs", str(jobs),
            "--out", str(out), "--quiet"]


def timed(cmd: list[str]) -> float:
    t = time.perf_counter()
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if proc.returncode not in (0, 1):        # 1: some runs failed; they are rows like the others
        sys.exit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr}")
    return wall


def figures(summary: Path) -> list[tuple[str, ...]]:
    with open(summary, newline="") as f:
        return [tuple(r[c] for c in ("log", "filter", *SUMMARY_FIGURES)) for r in csv.DictReader(f)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=3, help="number of simulated logs")
    ap.add_argument("--duration", type=float, default=900.0, help="length of each log, s")
    ap.add_argument("--filters", default="ekf,aekf,ckf,vce-ckf,rwckf")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes of the parallel run")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each; the fastest is kept")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench-compare")
    args = ap.parse_args()

    from navpp import api

    args.workdir.mkdir(parents=True, exist_ok=True)
    logs = []
    for k in range(args.logs):
        log = args.workdir / f"sim-{int(args.duration)}s-seed{k + 1}"
        if not (log / "imu.csv").is_file():
            t = time.perf_counter()
            api.simulate_log(log, duration_s=args.duration, imu_rate_hz=125.0, gnss_rate_hz=5.0, seed=k + 1)
            print(f"simulated {args.duration:.0f} s log in {time.perf_counter() - t:.1f} s -> {log}")
        logs.append(log)

    warm = args.workdir / "warm-up"
    if not (warm / "imu.csv").is_file():
        api.simulate_log(warm, duration_s=60.0, still_s=20.0, seed=99)
    t = time.perf_counter()
    timed(compare_cmd([warm], args.filters, 1, args.workdir / "out-warm"))
    print(f"warm-up (numba cache) {time.perf_counter() - t:.1f} s")

    best = {1: float("inf"), args.jobs: float("inf")}
    for _ in range(max(args.repeat, 1)):
        for jobs in (1, args.jobs):
            wall = timed(compare_cmd(logs, args.filters, jobs, args.workdir / f"out-jobs{jobs}"))
            best[jobs] = min(best[jobs], wall)
    same = figures(args.workdir / "out-jobs1" / "summary.csv") == figures(
        args.workdir / f"out-jobs{args.jobs}" / "summary.csv")
    n_runs = args.logs * len(args.filters.split(","))
    failed = [f"{r[1]} on {Path(r[0]).name}" for r in figures(args.workdir / "out-jobs1" / "summary.csv")
              if r[-1] != "ok"]
    print(f"navpp compare: {args.logs} logs x {len(args.filters.split(','))} filters = {n_runs} runs "
          f"({args.duration:.0f} s logs, 125 Hz IMU, 5 Hz GNSS) on {os.cpu_count()} CPUs")
    print(f"  --jobs 1         {best[1]:7.2f} s")
    print(f"  --jobs {args.jobs:<9} {best[args.jobs]:7.2f} s")
    print(f"  ratio            {best[args.jobs] / best[1]:7.3f}   (same figures: {'yes' if same else 'NO'})")
    if failed:
        print(f"  (runs that failed, timed like the others: {', '.join(failed)})")
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
