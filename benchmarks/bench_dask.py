"""`navpp compare` on a Dask cluster against the local process pool (issue 9).

Usage:  python benchmarks/bench_dask.py [--logs 8] [--duration 900] [--filters ekf,aekf,ckf,vce-ckf,rwckf]
                                        [--workers 2] [--repeat 1] [--workdir DIR]

Simulates the logs once (cached; a different seed per log), starts a Dask scheduler and
``--workers`` single-threaded Dask worker processes (``dask scheduler`` / ``dask worker``, as a
team's existing cluster would be), warms numba's compile cache on both sides, then times the
whole command-line run, as a user sees it, each in a fresh process:

- ``navpp compare LOGS --jobs W`` (the local process pool, W workers);
- ``navpp compare LOGS --executor dask --scheduler ADDR`` (the running cluster);
- ``navpp compare LOGS --executor dask --jobs W`` (a LocalCluster started by the command).

While the cluster run goes, the scheduler process's resident memory is sampled every 50 ms:
printed at the start, its peak and at the end.  Prints the wall times, the ratios to the local
pool, and checks that the three summaries hold the same figures.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

FIGURES = ("east_rmse", "north_rmse", "up_rmse", "horizontal_rmse", "horizontal_p95", "3d_rmse", "gnss_rejected",
           "status")


def figures(summary: Path) -> list[tuple[str, ...]]:
    with open(summary, newline="") as f:
        return [tuple(r[c] for c in ("log", "filter", *FIGURES)) for r in csv.DictReader(f)]


def timed(cmd: list[str]) -> float:
    t = time.perf_counter()
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if proc.returncode not in (0, 1):
        sys.exit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-2000:]}")
    return wall


class RssSampler:
    """Resident memory (MB) of one process, sampled every ``period`` s in a thread."""

    def __init__(self, pid: int, period: float = 0.05) -> None:
        import psutil

        self.proc = psutil.Process(pid)
        self.period = period
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.samples.append(self.proc.memory_info().rss / 1e6)
            time.sleep(self.period)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def start_cluster(workdir: Path, workers: int) -> tuple[str, list[subprocess.Popen]]:
    sched_file = workdir / "scheduler.json"
    sched_file.unlink(missing_ok=True)
    bindir = Path(sys.executable).parent
    if not (bindir / "dask").exists():
        sys.exit("bench_dask: the `dask` command is not installed: pip install 'navpp[dask]'")
    dask = [str(bindir / "dask")]
    log = open(workdir / "cluster.log", "w")     # noqa: SIM115  (open for the cluster's lifetime)
    procs = [subprocess.Popen([*dask, "scheduler", "--scheduler-file", str(sched_file), "--no-dashboard",
                               "--port", "0"], stdout=log, stderr=log)]
    for _ in range(200):
        if sched_file.exists() and sched_file.stat().st_size > 0:
            break
        time.sleep(0.1)
    import json

    addr = json.loads(sched_file.read_text())["address"]
    for _ in range(workers):
        procs.append(subprocess.Popen([*dask, "worker", addr, "--nthreads", "1", "--nworkers", "1",
                                       "--no-dashboard", "--memory-limit", "0"], stdout=log, stderr=log))
    from distributed import Client

    with Client(addr, timeout="30s") as c:
        c.wait_for_workers(workers, timeout=60)
    return addr, procs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=8)
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--filters", default="ekf,aekf,ckf,vce-ckf,rwckf")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1, help="runs of each; the fastest is kept")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench-dask")
    args = ap.parse_args()
    from navpp import api

    args.workdir.mkdir(parents=True, exist_ok=True)
    logs = []
    for k in range(args.logs):
        log = args.workdir / f"sim-{int(args.duration)}s-seed{k + 1}"
        if not (log / "imu.csv").is_file():
            api.simulate_log(log, duration_s=args.duration, seed=k + 1)
        logs.append(str(log))
    warm = args.workdir / "warm-up"
    if not (warm / "imu.csv").is_file():
        api.simulate_log(warm, duration_s=60.0, still_s=20.0, seed=99)

    base = [sys.executable, "-m", "navpp", "compare", "--filters", args.filters, "--quiet"]
    addr, procs = start_cluster(args.workdir, args.workers)
    try:
        timed([*base, str(warm), "--out", str(args.workdir / "out-warm"), "--jobs", "1"])
        timed([*base, str(warm), "--out", str(args.workdir / "out-warm-dask"), "--executor", "dask",
               "--scheduler", addr])
        best = {"local": float("inf"), "dask": float("inf"), "localcluster": float("inf")}
        mem = None
        for _ in range(max(args.repeat, 1)):
            best["local"] = min(best["local"], timed([*base, *logs, "--jobs", str(args.workers), "--out",
                                                      str(args.workdir / "out-local")]))
            with RssSampler(procs[0].pid) as sampler:
                wall = timed([*base, *logs, "--executor", "dask", "--scheduler", addr, "--out",
                              str(args.workdir / "out-dask")])
            best["dask"] = min(best["dask"], wall)
            mem = sampler.samples
            best["localcluster"] = min(best["localcluster"], timed(
                [*base, *logs, "--executor", "dask", "--jobs", str(args.workers), "--out",
                 str(args.workdir / "out-localcluster")]))
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
    ref = figures(args.workdir / "out-local" / "summary.csv")
    same = all(figures(args.workdir / d / "summary.csv") == ref for d in ("out-dask", "out-localcluster"))
    n_runs = args.logs * len(args.filters.split(","))
    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    print(f"navpp compare: {args.logs} logs x {len(args.filters.split(','))} filters = {n_runs} runs "
          f"({args.duration:.0f} s logs, 125 Hz IMU, 5 Hz GNSS); {cpu}, {os.cpu_count()} CPUs")
    print(f"  local pool, --jobs {args.workers}                   {best['local']:7.2f} s")
    print(f"  Dask, running cluster ({args.workers} workers)        {best['dask']:7.2f} s   "
          f"ratio {best['dask'] / best['local']:.3f}")
    print(f"  Dask, LocalCluster started by the command  {best['localcluster']:7.2f} s   "
          f"ratio {best['localcluster'] / best['local']:.3f}")
    if mem:
        print(f"  scheduler resident memory: {mem[0]:.0f} MB at the start, peak {max(mem):.0f} MB, "
              f"{mem[-1]:.0f} MB at the end ({len(mem)} samples)")
    print(f"  same figures in all three summaries: {'yes' if same else 'NO'}")
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
