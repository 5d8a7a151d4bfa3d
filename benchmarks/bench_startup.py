"""Start-up cost of navpp's numba kernels: cold (empty compile cache) against warm runs.

Usage:  python benchmarks/bench_startup.py [--cases default,rwckf,smooth,compare] [--log sample_data/drive.mcap]

Each case is a ``navpp`` command run as a child process (``python -m navpp ...``):

- ``default``: ``navpp process LOG`` (the Quick start job, default filter);
- ``rwckf``: ``navpp process LOG --filter rwckf``;
- ``smooth``: ``navpp process LOG --smooth``;
- ``compare``: ``navpp compare LOG`` (the five default filters, one process).

First ``navpp compile`` fills one cache (its CPU is printed).  Then each case runs three
times, each a child process: "cold auto" with ``NUMBA_CACHE_DIR`` at a fresh, empty directory
and the default ``--jit auto`` (navpp chooses interpreted or compiled, :mod:`navpp.jitmode`;
the mode taken is printed); "cold --jit on" in another fresh directory (everything the path
needs is compiled: the cost of compiling on a first run); "warm" with the compiled cache.
For every run: CPU time (user + sys of the child, from ``os.wait4``), s, and the cold-minus-
warm differences; whether the run said it was compiling (the ``compiling navpp's numba
kernels`` line on stderr, :class:`navpp.jitcache.CompileAnnouncer`): it must on the forced
cold run, never on a warm or an interpreted one.  The outputs of the cold runs are compared
with the warm run's byte for byte (trajectory.csv; metrics.json without its timing fields).

Figures depend on the machine (printed first) and on what else runs on it: the CPU seconds
are the better measure on a busy machine.
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

ANNOUNCE = "compiling navpp's numba kernels"
INTERPRETED = "kernels ran interpreted"
CASES = {
    "default": ["process", "{log}"],
    "rwckf": ["process", "{log}", "--filter", "rwckf"],
    "smooth": ["process", "{log}", "--smooth"],
    "compare": ["compare", "{log}"],
}
#: metrics.json keys that are timings (differ between any two runs)
TIMING_KEYS = {"runtime_s", "compile_s", "smoothing_s"}


def machine() -> str:
    """CPU count and model, Python and numba versions."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba

    return (f"{os.cpu_count()} CPUs ({model}), {platform.system()} {platform.release()}, Python "
            f"{platform.python_version()}, numba {numba.__version__}")


def run(args: list[str], cache_dir: Path, out: Path) -> dict:
    """One ``navpp`` command in a child process; wall and CPU seconds, whether it announced compiling."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    cmd = [sys.executable, "-m", "navpp", *args, "--out", str(out)]
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stderr}")
    return {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime, "announced": stderr.count(ANNOUNCE),
            "interpreted": INTERPRETED in stderr,
            "out": out}


def _untimed(value: object) -> object:
    """A metrics.json value with the timing keys dropped at every level."""
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if k not in TIMING_KEYS}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def _untimed_csv(path: Path) -> list[dict]:
    """summary.csv's rows without the timing columns."""
    import csv

    with open(path, newline="", encoding="utf-8") as f:
        return [{k: v for k, v in row.items() if "runtime" not in k} for row in csv.DictReader(f)]


def same_outputs(a: Path, b: Path) -> str:
    """'same' when trajectory.csv (byte for byte), summary.csv and metrics.json (timings left out) agree."""
    if (a / "trajectory.csv").exists() and (a / "trajectory.csv").read_bytes() != (b / "trajectory.csv").read_bytes():
        return "trajectory.csv differs"
    if (a / "summary.csv").exists() and _untimed_csv(a / "summary.csv") != _untimed_csv(b / "summary.csv"):
        return "summary.csv differs"
    if (a / "metrics.json").exists():
        ma, mb = (_untimed(json.loads((d / "metrics.json").read_text())) for d in (a, b))
        if ma != mb:
            return "metrics.json differs"
    return "same"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    ap.add_argument("--log", default="sample_data/drive.mcap")
    args = ap.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    for c in cases:
        if c not in CASES:
            raise SystemExit(f"--cases: unknown case {c!r} (known: {', '.join(CASES)})")
    print(f"machine: {machine()}")
    print(f"log: {args.log}; CPU = user + sys of the child (s); cold = empty NUMBA_CACHE_DIR; "
          "warm = after `navpp compile`")
    with tempfile.TemporaryDirectory(prefix="navpp-bench-startup-") as tmp:
        root = Path(tmp)
        shared = root / "cache-compiled"
        t0 = time.perf_counter()
        env = dict(os.environ, NUMBA_CACHE_DIR=str(shared))
        with tempfile.TemporaryFile() as err:
            proc = subprocess.Popen([sys.executable, "-m", "navpp", "compile"], env=env,
                                    stdout=subprocess.DEVNULL, stderr=err)
            _, status, usage = os.wait4(proc.pid, 0)
            if os.waitstatus_to_exitcode(status) != 0:
                err.seek(0)
                raise SystemExit(f"navpp compile failed:\n{err.read().decode(errors='replace')}")
        print(f"navpp compile (every filter, smoother, readers): {time.perf_counter() - t0:.1f} s wall, "
              f"{usage.ru_utime + usage.ru_stime:.1f} s CPU")
        print(f"{'case':<9} {'cold auto':>17} {'cold --jit on':>14} {'warm':>6} {'auto-warm':>10} "
              f"{'on-warm':>8}  announced (auto/on/warm)  outputs (auto, on vs warm)")
        for case in cases:
            cmd = [a.format(log=args.log) for a in CASES[case]]
            auto = run(cmd, root / f"cache-{case}-auto", root / f"{case}-auto")
            forced = run([*cmd, "--jit", "on"], root / f"cache-{case}-on", root / f"{case}-on")
            warm = run(cmd, shared, root / f"{case}-warm")
            mode = "interpreted" if auto["interpreted"] else "compiled"
            print(f"{case:<9} {auto['cpu']:5.1f} {mode:>11} {forced['cpu']:14.1f} {warm['cpu']:6.1f} "
                  f"{auto['cpu'] - warm['cpu']:10.1f} {forced['cpu'] - warm['cpu']:8.1f}  "
                  f"{auto['announced']}/{forced['announced']}/{warm['announced']:<20}  "
                  f"{same_outputs(auto['out'], warm['out'])}, {same_outputs(forced['out'], warm['out'])}",
                  flush=True)


if __name__ == "__main__":
    main()
