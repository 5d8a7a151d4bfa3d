"""What running navpp's kernels interpreted costs per IMU sample, per filter: the figures behind
``--jit auto``'s choice (:data:`navpp.jitmode.INTERPRETED_US` and :data:`navpp.jitmode.SMOOTH_US`).

Usage:  python benchmarks/bench_interpreted.py [--log sample_data/drive] [--seconds 60,120]
        [--filters ekf,aekf,...] [--smooth]

The CSV log is cut to its first S seconds for each S of ``--seconds`` (rows of imu.csv, gnss.csv and
reference.csv up to that time, its navpp.toml kept).  For each filter and each cut, two children:
``navpp process CUT --filter F --jit off`` (interpreted) and the same with ``--jit on`` (compiled,
after one untimed run that fills the cache).  The CPU (user + sys, ``os.wait4``) of each is printed,
and the extra CPU of the interpreted run per IMU sample, measured as a slope between the two
lengths so that what does not grow with the log (imports, set-up) drops out:
((off - on) at the longer cut - (off - on) at the shorter) / (samples between them).
With ``--smooth`` each run adds ``--smooth`` and the smoother's own share is the difference from
the forward run's figure.  Figures depend on the machine (printed) and on its load.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ALL = ("ekf", "aekf", "ckf", "ukf", "vce-ckf", "rwckf", "aukf", "sif")


def cut(log: Path, seconds: float, out: Path) -> int:
    """``log``'s CSV files cut to their first ``seconds`` of IMU time into ``out``; the IMU rows kept."""
    out.mkdir(parents=True, exist_ok=True)
    t_end = None
    kept = 0
    for name in ("imu.csv", "gnss.csv", "reference.csv"):
        src = log / name
        if not src.exists():
            continue
        with open(src) as f, open(out / name, "w") as g:
            g.write(f.readline())
            for line in f:
                t = float(line.split(",", 1)[0])
                if t_end is None:
                    t_end = t + seconds
                if t > t_end:
                    break
                g.write(line)
                kept += name == "imu.csv"
    for extra in ("navpp.toml",):
        if (log / extra).exists():
            (out / extra).write_bytes((log / extra).read_bytes())
    return kept


def cpu(args: list[str], out: Path) -> float:
    """CPU seconds (user + sys) of ``python -m navpp process ARGS -q`` with its outputs in a new
    directory under ``out``; fails loudly."""
    out = Path(tempfile.mkdtemp(dir=out))
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([sys.executable, "-m", "navpp", "process", *args, "--out", str(out), "-q"],
                                stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            err.seek(0)
            raise SystemExit(f"navpp process {' '.join(args)} failed:\n{err.read().decode(errors='replace')}")
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--log", default="sample_data/drive", type=Path)
    ap.add_argument("--seconds", default="60,120")
    ap.add_argument("--filters", default=",".join(ALL))
    ap.add_argument("--smooth", action="store_true")
    args = ap.parse_args()
    lengths = sorted(float(s) for s in args.seconds.split(","))
    if len(lengths) != 2:
        raise SystemExit("--seconds: two lengths, e.g. 60,120")
    filters = [f.strip() for f in args.filters.split(",") if f.strip()]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.1f}")
    extra = ["--smooth"] if args.smooth else []
    with tempfile.TemporaryDirectory(prefix="navpp-bench-interp-") as tmp:
        root = Path(tmp)
        (root / "runs").mkdir()
        cuts = [(cut(args.log, s, root / f"cut{int(s)}"), root / f"cut{int(s)}") for s in lengths]
        print(f"log {args.log} cut to {lengths[0]:g} s ({cuts[0][0]} IMU samples) and {lengths[1]:g} s "
              f"({cuts[1][0]}); CPU s of the child, interpreted (off) and compiled (on)"
              + ("; with --smooth" if args.smooth else ""))
        print(f"{'filter':<8} {'off short':>9} {'on short':>9} {'off long':>9} {'on long':>8} {'extra µs/sample':>16}")
        for f in filters:
            cpu([str(cuts[0][1]), "--filter", f, "--jit", "on", *extra], root / "runs")
            row = []
            for _, path in cuts:
                row += [cpu([str(path), "--filter", f, "--jit", "off", *extra], root / "runs"),
                        cpu([str(path), "--filter", f, "--jit", "on", *extra], root / "runs")]
            slope = ((row[2] - row[3]) - (row[0] - row[1])) / (cuts[1][0] - cuts[0][0]) * 1e6
            print(f"{f:<8} {row[0]:9.1f} {row[1]:9.1f} {row[2]:9.1f} {row[3]:8.1f} {slope:16.0f}", flush=True)


if __name__ == "__main__":
    main()
