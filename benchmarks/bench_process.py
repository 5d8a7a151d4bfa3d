"""End-to-end speed of `navpp process` on a simulated 1-hour, 125 Hz IMU + 5 Hz GNSS CSV log.

Usage:  python benchmarks/bench_process.py [--duration 3600] [--filter ekf] [--workdir DIR]

Simulates the log once (cached in the work directory), warms the numba compile cache in a
first run, then measures in a fresh process: reading + validation, processing (alignment +
filter), writing the IMU-rate trajectory.csv, and the process's peak resident memory.
Prints per-stage seconds and microseconds per IMU sample.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def measure(log: Path, filter_name: str, out: Path) -> dict:
    import resource

    t_import = time.perf_counter()
    from navpp import api, engine
    from navpp.io import writers
    t_import = time.perf_counter() - t_import

    cfg = api.resolve_config(log, None)
    filt = api.make_filter(filter_name, cfg)
    t0 = time.perf_counter()
    rec = api.read_log(log, cfg)
    t1 = time.perf_counter()
    res = engine.run(rec, cfg, filt)
    t2 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    writers.write_trajectory_csv(out / "trajectory.csv", res.solution, t0_s=rec.t0_ns * 1e-9)
    t3 = time.perf_counter()
    n = len(rec.imu)
    return {"imu_samples": n, "gnss_epochs": res.gnss_epochs, "import_s": t_import, "read_s": t1 - t0,
            "process_s": t2 - t1, "write_s": t3 - t2, "us_per_sample": (t2 - t1) / n * 1e6,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--filter", default="ekf")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench")
    ap.add_argument("--measure", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.filter, args.workdir / f"out-{args.filter}")))
        return

    log = args.workdir / f"sim-{int(args.duration)}s"
    if not (log / "imu.csv").exists():
        from navpp import api
        t = time.perf_counter()
        api.simulate_log(log, duration_s=args.duration, imu_rate_hz=125.0, gnss_rate_hz=5.0, seed=7)
        print(f"simulated {args.duration:.0f} s log in {time.perf_counter() - t:.1f} s -> {log}")
    cmd = [sys.executable, __file__, "--measure", str(log), "--filter", args.filter, "--workdir", str(args.workdir)]
    subprocess.run(cmd, check=True, capture_output=True)          # warm the numba cache
    r = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    print(f"machine: {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"log: {r['imu_samples']} IMU samples (125 Hz), {r['gnss_epochs']} GNSS epochs (5 Hz), filter {args.filter}")
    print(f"import navpp      {r['import_s']:7.3f} s")
    print(f"read + validate   {r['read_s']:7.3f} s")
    print(f"process           {r['process_s']:7.3f} s   ({r['us_per_sample']:.2f} us per IMU sample)")
    print(f"read + process    {r['read_s'] + r['process_s']:7.3f} s")
    print(f"write trajectory  {r['write_s']:7.3f} s   ({r['imu_samples']} rows)")
    print(f"peak memory       {r['peak_rss_mb']:7.0f} MB (resident, whole process)")


if __name__ == "__main__":
    main()
