"""Reading ROS logs (MCAP, ROS 2 bag, ROS 1 bag): the read stage and a whole `navpp process`, CPU and peak memory.

Usage:  python benchmarks/bench_read_ros.py LOG [LOG ...] [--no-process] [--memory 128MB]

For each log, two fresh children, one after the other:

- the read stage: ``navpp.reading.read_log`` (decoding the topics and building the validated
  Recording, IMU samples beyond ``--memory`` on the spill file), its CPU seconds (user + sys,
  ``time.process_time``), microseconds of CPU per IMU sample, and the child's peak resident
  memory (``VmHWM``, /proc/self/status: interpreter and imports included) with its resident
  size before reading;
- a whole ``navpp process LOG`` (EKF, outputs to a temporary directory) under ``/usr/bin/time -v``:
  user + sys CPU seconds and the maximum resident set size.

Write the logs once from the cached simulated CSV logs with ``navpp.io.roswrite`` (e.g.
``write_mcap_ros2``, ``write_ros2_bag``, ``write_ros1_bag``); run the same command with the old
and the new tree side by side (PYTHONPATH) to compare.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _status_mb(field: str) -> float:
    """A ``/proc/self/status`` memory field (``VmHWM``, ``VmRSS``) in MB."""
    with open("/proc/self/status", encoding="ascii") as f:
        line = next(x for x in f if x.startswith(field + ":"))
    return int(line.split()[1]) / 1024.0


def read_stage(log: str, memory: str | None) -> dict:
    """Read ``log`` in this process: CPU s, IMU samples, VmRSS before and VmHWM after (MB)."""
    from navpp import reading
    from navpp.config import with_memory

    cfg = reading.resolve_config(Path(log), None)
    if memory is not None:
        cfg = with_memory(cfg, memory)
    rss0 = _status_mb("VmRSS")
    c0 = time.process_time()
    rec = reading.read_log(log, cfg)
    cpu = time.process_time() - c0
    n = len(rec.imu)
    return {"imu_samples": n, "read_cpu_s": cpu, "us_per_sample": cpu / n * 1e6, "rss_before_mb": rss0,
            "peak_mb": _status_mb("VmHWM")}


def whole_process(log: str, memory: str | None) -> dict:
    """``navpp process log`` under ``/usr/bin/time -v``: user + sys CPU s and max RSS (MB)."""
    with tempfile.TemporaryDirectory(prefix="navpp-bench-ros-") as tmp:
        cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "navpp", "process", log, "--out", str(Path(tmp) / "out")]
        if memory is not None:
            cmd += ["--memory", memory]
        done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"navpp process {log} failed:\n{done.stderr[-2000:]}")

    def field(name: str) -> float:
        return float(re.search(rf"{name}: ([0-9.]+)", done.stderr).group(1))

    return {"process_cpu_s": field("User time \\(seconds\\)") + field("System time \\(seconds\\)"),
            "process_peak_mb": field("Maximum resident set size \\(kbytes\\)") / 1024.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--no-process", action="store_true", help="the read stage only")
    ap.add_argument("--memory", default=None, help="--memory of the runs (default: the config's, 128MB)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(read_stage(args.logs[0], args.memory)))
        return
    print(f"navpp from {os.environ.get('PYTHONPATH') or 'the installed package'}; load {os.getloadavg()[0]:.1f}")
    print(f"{'log':<28} {'IMU':>10} {'read CPU s':>10} {'us/sample':>9} {'read peak MB':>12} "
          f"{'process CPU s':>13} {'process peak MB':>15}")
    for log in args.logs:
        cmd = [sys.executable, __file__, log, "--child"] + (["--memory", args.memory] if args.memory else [])
        r = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.splitlines()[-1])
        p = {} if args.no_process else whole_process(log, args.memory)
        print(f"{Path(log).name:<28} {r['imu_samples']:>10,} {r['read_cpu_s']:>10.2f} {r['us_per_sample']:>9.3f} "
              f"{r['peak_mb']:>12.0f} {p.get('process_cpu_s', float('nan')):>13.2f} "
              f"{p.get('process_peak_mb', float('nan')):>15.0f}", flush=True)


if __name__ == "__main__":
    main()
