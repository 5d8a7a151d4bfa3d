"""Start-up cost of navpp's numba kernels: cold (empty compile cache) against warm runs.

Usage:  python benchmarks/bench_startup.py [--cases default,rwckf,smooth,compare] [--log sample_data/drive.mcap]

Each case is a ``navpp`` command run as a child process (``python -m navpp ...``):

- ``default``: ``navpp process LOG`` (the Quick start job, default filter);
- ``rwckf``: ``navpp process LOG --filter rwckf``;
- ``smooth``: ``navpp process LOG --smooth``;
- ``compare``: ``navpp compare LOG`` (the five default filters, one process).

For each case the command runs first with ``NUMBA_CACHE_DIR`` pointing at a fresh, empty
temporary directory (cold: every kernel it needs is compiled), then again with that directory
(warm: loaded from the cache).  Then, after ``default`` has filled one shared cache, each other
case once more ("after default": what a new filter or option costs once the Quick start ran).
For every run: wall time and CPU time (user + sys of the child, from ``os.wait4``), s; for each
case the cold-minus-warm difference; and whether the run said it was compiling (the
``compiling navpp's numba kernels`` line on stderr, :class:`navpp.jitcache.CompileAnnouncer`):
it must on every cold run and never on a warm one.  The outputs of the cold and the warm run
are compared byte for byte (trajectory.csv; metrics.json without its timing fields).

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
    cmd = [sys.executable, "-m", "navpp", *args, "--out", str(out), "--quiet"]
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
    print(f"log: {args.log}; CPU = user + sys of the child (s); cold = empty NUMBA_CACHE_DIR")
    print(f"{'case':<22} {'cold wall':>9} {'cold CPU':>9} {'warm wall':>9} {'warm CPU':>9} {'CPU diff':>9}  "
          f"announced (cold/warm)  outputs")
    with tempfile.TemporaryDirectory(prefix="navpp-bench-startup-") as tmp:
        root = Path(tmp)
        for case in cases:
            cmd = [a.format(log=args.log) for a in CASES[case]]
            cache = root / f"cache-{case}"
            cold = run(cmd, cache, root / f"{case}-cold")
            warm = run(cmd, cache, root / f"{case}-warm")
            print(f"{case:<22} {cold['wall']:9.1f} {cold['cpu']:9.1f} {warm['wall']:9.1f} {warm['cpu']:9.1f} "
                  f"{cold['cpu'] - warm['cpu']:9.1f}  {cold['announced']}/{warm['announced']:<19}  "
                  f"{same_outputs(cold['out'], warm['out'])}", flush=True)
        if "default" in cases:
            shared = root / "cache-default"      # filled by the default case's runs
            for case in cases:
                if case == "default":
                    continue
                cmd = [a.format(log=args.log) for a in CASES[case]]
                first = run(cmd, shared, root / f"{case}-after")
                again = run(cmd, shared, root / f"{case}-after-warm")
                print(f"{case + ' after default':<22} {first['wall']:9.1f} {first['cpu']:9.1f} {again['wall']:9.1f} "
                      f"{again['cpu']:9.1f} {first['cpu'] - again['cpu']:9.1f}  "
                      f"{first['announced']}/{again['announced']:<19}  "
                      f"{same_outputs(first['out'], again['out'])}", flush=True)


if __name__ == "__main__":
    main()
