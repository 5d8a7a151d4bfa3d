"""End-to-end speed of `navpp process` on a simulated 1-hour, 125 Hz IMU + 5 Hz GNSS CSV log.

Usage:  python benchmarks/bench_process.py [--duration 3600] [--filter ekf] [--smooth] [--workdir DIR]

With ``--smooth`` the runs also smooth backwards (RTS, issue 7): the processing figure then
includes the smoothing, which is printed on its own line with its share of the forward filter's
time and the memory its stored forward run took.

Simulates the log once (cached in the work directory), warms the numba compile cache in a
first run, then measures in a fresh process: reading + validation, processing (alignment +
filter), writing the IMU-rate trajectory.csv, and that process's peak resident memory; then,
in the same process after freeing those results and resetting the peak, the peak memory (and
time) of a whole ``navpp process`` run, metrics against reference.csv included
(``api.process`` writing into a temporary directory).  Prints per-stage seconds and
microseconds per IMU sample.

Peak memory is the kernel's high-water mark of the measuring process, ``VmHWM`` in
``/proc/self/status`` (Linux): it belongs to the exec'd child alone, unlike
``getrusage(RUSAGE_SELF).ru_maxrss``, which on Linux carries the parent's high-water mark
into a forked and exec'd child (a parent that simulated the log in-process would show through).
Where ``/proc`` is absent, ``ru_maxrss`` is used and the output says so.
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


def _vm_hwm_kb() -> int | None:
    """This process's peak resident set size, kB, from /proc/self/status (None without /proc)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def peak_memory_mb() -> tuple[float, str]:
    """(peak resident MB, where it comes from)."""
    kb = _vm_hwm_kb()
    if kb is not None:
        return kb / 1024.0, "VmHWM"
    import resource

    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return maxrss / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0), "ru_maxrss"


def _vm_rss_mb() -> float | None:
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def reset_peak_memory() -> float | None:
    """Give freed heap back to the OS, then reset VmHWM to the current resident size (Linux >= 4.0).

    Returns the resident MB the peak was reset to, or None if it could not be reset.
    """
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
    except OSError:
        return None
    return _vm_rss_mb()


def measure(log: Path, filter_name: str, out: Path, smooth: bool = False) -> dict:
    import gc

    t_import = time.perf_counter()
    from navpp import api, engine
    from navpp.io import writers
    t_import = time.perf_counter() - t_import

    cfg = api.resolve_config(log, None)
    filt = api.make_filter(filter_name, cfg)
    t0 = time.perf_counter()
    rec = api.read_log(log, cfg)
    t1 = time.perf_counter()
    res = engine.run(rec, cfg, filt, smooth=smooth)
    t2 = time.perf_counter()
    smoothing = ({"smoothing_s": res.smoothed.runtime_s, "store_mb": res.smoothed.store_mb,
                  "nodes": res.smoothed.nodes} if smooth else {})
    out.mkdir(parents=True, exist_ok=True)
    sol = res.smoothed.solution if smooth else res.solution
    writers.write_trajectory_csv(out / "trajectory.csv", sol, t0_s=rec.t0_ns * 1e-9)
    t3 = time.perf_counter()
    peak_rpw, source = peak_memory_mb()
    n, gnss_epochs = len(rec.imu), res.gnss_epochs

    # the whole `navpp process` (read, filter, metrics against reference.csv, write all files)
    del rec, res, filt, sol
    gc.collect()
    reset_to = reset_peak_memory()
    with tempfile.TemporaryDirectory(prefix="navpp-bench-") as tmp:
        t4 = time.perf_counter()
        full = api.process(log, filter_name=filter_name, out_dir=Path(tmp) / "out", write=True, smooth=smooth)
        t5 = time.perf_counter()
        has_metrics = full.metrics is not None
        del full
    peak_full, _ = peak_memory_mb()
    return {"imu_samples": n, "gnss_epochs": gnss_epochs, "import_s": t_import, "read_s": t1 - t0,
            "process_s": t2 - t1, "write_s": t3 - t2, "us_per_sample": (t2 - t1) / n * 1e6,
            "full_s": t5 - t4, "full_has_metrics": has_metrics,
            "peak_read_process_write_mb": peak_rpw, "peak_full_mb": peak_full, "peak_source": source,
            "peak_reset": reset_to, **smoothing}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--filter", default="ekf")
    ap.add_argument("--smooth", action="store_true", help="also smooth backwards (RTS)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench")
    ap.add_argument("--measure", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.filter, args.workdir / f"out-{args.filter}", args.smooth)))
        return

    log = args.workdir / f"sim-{int(args.duration)}s"
    if not (log / "imu.csv").exists():
        from navpp import api
        t = time.perf_counter()
        api.simulate_log(log, duration_s=args.duration, imu_rate_hz=125.0, gnss_rate_hz=5.0, seed=7)
        print(f"simulated {args.duration:.0f} s log in {time.perf_counter() - t:.1f} s -> {log}")
    cmd = [sys.executable, __file__, "--measure", str(log), "--filter", args.filter, "--workdir", str(args.workdir)]
    cmd += ["--smooth"] if args.smooth else []
    for attempt in ("warm-up", "measure"):                         # the first run warms the numba cache
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"bench_process: the {attempt} run failed:\n{proc.stderr}")
    r = json.loads(proc.stdout)
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
    if "smoothing_s" in r:
        fwd = r["process_s"] - r["smoothing_s"]
        print(f"  of which RTS    {r['smoothing_s']:7.3f} s   ({100.0 * r['smoothing_s'] / fwd:.0f}% of the forward "
              f"run's {fwd:.3f} s; {r['nodes']} nodes, stored forward run {r['store_mb']:.0f} MB)")
    print(f"read + process    {r['read_s'] + r['process_s']:7.3f} s")
    print(f"write trajectory  {r['write_s']:7.3f} s   ({r['imu_samples']} rows)")
    print(f"full navpp process{r['full_s']:7.3f} s   (read, filter, "
          f"{'metrics vs reference.csv, ' if r['full_has_metrics'] else 'no reference: no metrics, '}write)")
    if r["peak_source"] == "VmHWM":
        how = "VmHWM of the measuring process, /proc/self/status"
    else:
        how = "ru_maxrss: /proc absent; may include the parent's peak"
    print(f"peak memory       {r['peak_read_process_write_mb']:7.0f} MB  read+process+write ({how})")
    if r["peak_reset"] is None:
        since = "the peak could not be reset: at least the figure above"
    else:   # freed memory the allocator keeps and modules the first part imported stay resident
        since = f"peak reset before it, to the {r['peak_reset']:.0f} MB the first part left resident"
    print(f"peak memory       {r['peak_full_mb']:7.0f} MB  full `navpp process` incl. metrics ({since})")


if __name__ == "__main__":
    main()
