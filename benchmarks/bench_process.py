"""End-to-end speed of `navpp process` on a simulated 1-hour, 125 Hz IMU + 5 Hz GNSS CSV log.

Usage:  python benchmarks/bench_process.py [--duration 3600] [--filter ekf] [--smooth] [--workdir DIR]
        python benchmarks/bench_process.py --hours 1,4,8 [--repeats 3] [--filter ekf] [--workdir DIR]
        python benchmarks/bench_process.py --duration 14400 --memory-map [--smooth]

``--hours``: for each duration, ``process`` and ``process --smooth`` in one table: per-stage
seconds (read + validate, forward filter incl. alignment, RTS smoothing, trajectory.csv write)
with microseconds per IMU sample, CPU seconds, and the measuring child's VmHWM; the median of
``--repeats`` runs (each a fresh child, one at a time); then the growth per hour of log, the
slope of a least-squares line through the durations.  ``--memory-map``: where the memory of
one run goes (see :func:`memory_map`); slower, not a timing.

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


def kernels_line() -> str:
    """What navpp's kernels ran on in this process: the native module (numba never imported),
    numba's dispatchers, or the native module with numba for the calls it did not fit."""
    from navpp import kernel

    if kernel.native() is None:
        return "numba (no native module for these sources: navpp compile builds one)"
    if "numba" in sys.modules:
        return "native module, numba for calls it had no entry point for"
    return "native module (numba not imported)"


def machine_line() -> str:
    """``machine: CPU model, N cores, Python X.Y.Z`` (the model from /proc/cpuinfo where there is one)."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"machine: {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


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


def measure(log: Path, filter_name: str, out: Path, smooth: bool = False, full: bool = True) -> dict:
    """Time and peak memory of one run in this process (see the module docstring); ``full``:
    then also the whole ``api.process`` after resetting the peak.  ``*_cpu_s``: this process's
    CPU time (user + sys, all threads) over the same stage."""
    import gc

    t_import = time.perf_counter()
    from navpp import api, engine
    from navpp.io import writers
    from navpp.spill import allow_large_block_mapping
    t_import = time.perf_counter() - t_import
    allow_large_block_mapping()     # as the navpp command does

    cfg = api.resolve_config(log, None)
    filt = api.make_filter(filter_name, cfg)
    c0, t0 = time.process_time(), time.perf_counter()
    rec = api.read_log(log, cfg)
    c1, t1 = time.process_time(), time.perf_counter()
    res = engine.run(rec, cfg, filt, smooth=smooth)
    c2, t2 = time.process_time(), time.perf_counter()
    smoothing = ({"smoothing_s": res.smoothed.runtime_s, "store_mb": res.smoothed.store_mb,
                  "nodes": res.smoothed.nodes} if smooth else {})
    out.mkdir(parents=True, exist_ok=True)
    sol = res.smoothed.solution if smooth else res.solution
    writers.write_trajectory_csv(out / "trajectory.csv", sol, t0_s=rec.t0_ns * 1e-9)
    c3, t3 = time.process_time(), time.perf_counter()
    peak_rpw, source = peak_memory_mb()
    n, gnss_epochs = len(rec.imu), res.gnss_epochs
    stages = {"imu_samples": n, "gnss_epochs": gnss_epochs, "import_s": t_import, "read_s": t1 - t0,
              "process_s": t2 - t1, "write_s": t3 - t2, "us_per_sample": (t2 - t1) / n * 1e6,
              "read_cpu_s": c1 - c0, "process_cpu_s": c2 - c1, "write_cpu_s": c3 - c2,
              "peak_read_process_write_mb": peak_rpw, "peak_source": source, "kernels": kernels_line(), **smoothing}
    if not full:
        return stages

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
    return {**stages, "full_s": t5 - t4, "full_has_metrics": has_metrics, "peak_full_mb": peak_full,
            "peak_reset": reset_to}


def _enclosing_functions(filename: str) -> list[tuple[int, int, str]]:
    """(first line, last line, qualified name) of every function in a source file."""
    import ast

    try:
        with open(filename, encoding="utf-8") as f:
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, ValueError):
        return []
    spans: list[tuple[int, int, str]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    spans.append((child.lineno, child.end_lineno or child.lineno, name))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return spans


class _Where:
    """Allocation site -> ``module:function:line`` of the innermost navpp frame (else the innermost frame)."""

    def __init__(self) -> None:
        self._spans: dict[str, list[tuple[int, int, str]]] = {}

    def __call__(self, tb) -> str:
        frames = list(tb)[::-1]          # tracemalloc orders a traceback oldest frame first
        frame = next((f for f in frames if f"{os.sep}navpp{os.sep}" in f.filename), frames[0])
        fn = frame.filename
        if fn not in self._spans:
            self._spans[fn] = _enclosing_functions(fn)
        inner = [s for s in self._spans[fn] if s[0] <= frame.lineno <= s[1]]
        func = max(inner, key=lambda s: s[0])[2] if inner else "<module>"
        mod = fn.split(f"{os.sep}navpp{os.sep}", 1)[-1] if f"{os.sep}navpp{os.sep}" in fn else os.path.basename(fn)
        return f"{mod.removesuffix('.py').replace(os.sep, '.')}:{func}:{frame.lineno}"


def _arrays(obj, name: str, out: dict, seen: set, depth: int = 0) -> None:
    """Every numpy array reachable from ``obj`` (dataclass fields, attributes, dicts, lists; up to
    depth 4), by dotted name: (dtype, shape, owned bytes, bytes of views); a list of arrays is
    summed into one entry ``name[*]``."""
    import dataclasses

    import numpy as np

    if id(obj) in seen or depth > 4:
        return
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        owned = obj.nbytes if obj.base is None else 0
        out[name] = (str(obj.dtype), obj.shape, owned, obj.nbytes - owned)
        return
    if isinstance(obj, (list, tuple)) and obj and all(isinstance(a, np.ndarray) for a in obj[:50]):
        arrs = [a for a in obj if isinstance(a, np.ndarray)]
        uniq = {id(a): a for a in arrs}.values()
        owned = sum(a.nbytes for a in uniq if a.base is None)
        # each small array also costs its ndarray object (~112 B) and a malloc'd block
        out[name + "[*]"] = (str(arrs[0].dtype), (len(arrs), len(uniq), *arrs[0].shape), owned,
                             sum(a.nbytes for a in uniq) - owned)
        return
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        items = [(f.name, getattr(obj, f.name, None)) for f in dataclasses.fields(obj)]
    elif isinstance(obj, dict):
        items = [(str(k), v) for k, v in obj.items()]
    elif isinstance(obj, (list, tuple)):
        items = [(str(i), v) for i, v in enumerate(obj[:20])]
    elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("navpp"):
        items = list(vars(obj).items())
    else:
        return
    for k, v in items:
        _arrays(v, f"{name}.{k}", out, seen, depth + 1)


def memory_map(log: Path, filter_name: str, out: Path, smooth: bool) -> None:
    """Where the memory of one run goes: at the stage boundaries and at hooks inside
    ``engine.run`` (wrapping navpp functions in this process only), VmRSS and the VmHWM since
    the previous checkpoint (reset at each); for the read and the write, tracemalloc's top
    allocation sites still alive (numpy registers its buffers with tracemalloc); then the numpy
    arrays the recording, the engine (prepared model, recorder), the smoother's store and the
    result hold, with dtype, shape and size."""
    import functools
    import importlib
    import tracemalloc

    from navpp import api, engine
    from navpp.engine import output as eng_output
    from navpp.spill import allow_large_block_mapping

    allow_large_block_mapping()     # as the navpp command does
    from navpp.io import writers

    eng_run = importlib.import_module("navpp.engine.run")   # the module: navpp.engine.run is also a function
    where = _Where()
    n_imu = [0]
    held: dict[str, object] = {}

    def checkpoint(label: str, top: int = 10) -> None:
        rss = _vm_rss_mb()
        hwm, _ = peak_memory_mb()
        reset_peak_memory()     # the next checkpoint's VmHWM is the peak between the two
        print(f"\n== {label}: VmRSS {rss:.0f} MB, VmHWM since the previous checkpoint {hwm:.0f} MB", flush=True)
        if not tracemalloc.is_tracing():
            return
        cur, peak = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        snap = tracemalloc.take_snapshot()
        sites: dict[str, list[int]] = {}
        for st in snap.statistics("traceback"):
            key = where(st.traceback)
            e = sites.setdefault(key, [0, 0])
            e[0] += st.size
            e[1] += st.count
        print(f"   traced now {cur / 1e6:.0f} MB, traced peak since the previous checkpoint {peak / 1e6:.0f} MB; "
              "top allocation sites alive:")
        for key, (size, count) in sorted(sites.items(), key=lambda kv: -kv[1][0])[:top]:
            if size < 1e6:
                break
            print(f"   {size / 1e6:8.1f} MB  {count:>9} blocks  {key}")

    def hook(mod, name: str, before: str | None, after: str | None, walk=None):
        fn = getattr(mod, name)

        @functools.wraps(fn)
        def wrapped(*a, **k):
            if before:
                checkpoint(before)
            if walk is not None:
                walk(a)
            r = fn(*a, **k)
            if after:
                checkpoint(after)
            return r
        setattr(mod, name, wrapped)

    hook(eng_run, "prepared", None, "engine: after prepare (checks, calibrated IMU copies, nominal path, alignment)")
    def walk_finished(a) -> None:    # finished(recording, config, filt, prep, recorder, source, ...)
        seen: set = set()
        _arrays(a[0], "recording", {}, seen)      # the recording's own arrays are listed after reading
        _arrays(a[3], "prepared", held.setdefault("engine", {}), seen)
        _arrays(a[4], "recorder", held["engine"], seen)

    def walk_store(a) -> None:
        _arrays(a[0]._blocks, "ForwardStore._blocks", held.setdefault("store", {}), set())

    hook(eng_run, "finished", "engine: forward run done, before output (recorder full)", None, walk_finished)
    hook(eng_run, "solution_from_path", "engine.finished: forward solution (std interpolated, body rate)", None)
    if smooth:
        hook(eng_output, "rts_smooth", "smoothing: before the backward pass (the store's blocks)",
             "smoothing: after the backward pass (rts_smooth)", walk_store)
        hook(eng_output, "solution_from_path", "smoothing: smoothed IMU-rate path corrected, before its solution", None)

    cfg = api.resolve_config(log, None)
    filt = api.make_filter(filter_name, cfg)
    checkpoint("start (navpp imported)")
    tracemalloc.start(16)       # tracing the read and the write only: the filter loop's many small
    rec = api.read_log(log, cfg)  # allocations would make a traced run many times slower
    n_imu[0] = len(rec.imu)
    checkpoint("after read_log")
    tracemalloc.stop()
    _arrays(rec, "recording", held.setdefault("reader", {}), set())
    res = engine.run(rec, cfg, filt, smooth=smooth)
    checkpoint("after engine.run (result held)")
    out.mkdir(parents=True, exist_ok=True)
    sol = res.smoothed.solution if smooth else res.solution
    tracemalloc.start(16)
    writers.write_trajectory_csv(out / "trajectory.csv", sol, t0_s=rec.t0_ns * 1e-9)
    checkpoint("after write_trajectory_csv")
    tracemalloc.stop()
    _arrays(res, "result", held.setdefault("result", {}), set(map(id, [rec.imu.t])))

    n, m = n_imu[0], res.gnss_epochs
    hours = n / 125.0 / 3600.0
    print(f"\nnumpy arrays held (IMU rate: {n} rows, GNSS: {m} fixes; {hours:.2f} h): owned MB (views share "
          "their base's memory); for a list of small arrays: (list length, distinct arrays, shape of one)")
    for section in ("reader", "engine", "store", "result"):
        arrays = held.get(section, {})
        total = sum(v[2] for v in arrays.values())
        print(f"  {section} (owned total {total / 1e6:.0f} MB, {total / 1e6 / hours:.0f} MB/h)")
        for name, (dtype, shape, owned, view) in sorted(arrays.items(), key=lambda kv: -(kv[1][2] + kv[1][3])):
            if owned + view < 0.5e6:
                continue
            rate = "IMU" if shape and shape[0] == n else ("GNSS" if shape and shape[0] == m else "")
            vtxt = f"(+{view / 1e6:.1f} MB view)" if view else ""
            print(f"   {owned / 1e6:8.1f} MB {vtxt:>18} {owned / 1e6 / hours:7.1f} MB/h  {dtype:<8} "
                  f"{shape!s:<20} {rate:<4} {name}")
    print("  (a view's memory belongs to its base: the solution's columns are views of the path)")


def _loadavg() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "n/a"


def _lsq(x: list[float], y: list[float]) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope * x + intercept."""
    import numpy as np

    if len(set(x)) < 2:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(np.asarray(x, float), np.asarray(y, float), 1)
    return float(slope), float(intercept)


def simulated_log(workdir: Path, duration_s: float) -> Path:
    """The cached simulated log of ``duration_s`` (simulated on first use, seed 7)."""
    log = workdir / f"sim-{int(duration_s)}s"
    if not (log / "imu.csv").exists():
        from navpp import api
        t = time.perf_counter()
        api.simulate_log(log, duration_s=duration_s, imu_rate_hz=125.0, gnss_rate_hz=5.0, seed=7)
        print(f"simulated {duration_s:.0f} s log in {time.perf_counter() - t:.1f} s -> {log}", flush=True)
    return log


def _child(log: Path, filter_name: str, workdir: Path, smooth: bool, stages_only: bool) -> dict:
    cmd = [sys.executable, __file__, "--measure", str(log), "--filter", filter_name, "--workdir", str(workdir)]
    cmd += ["--smooth"] if smooth else []
    cmd += ["--stages-only"] if stages_only else []
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"bench_process: the run of {log} failed:\n{proc.stderr}")
    return json.loads(proc.stdout)


def sweep(hours: list[float], filter_name: str, workdir: Path, repeats: int) -> None:
    """Per-stage times, us per IMU sample and peak memory of ``process`` and ``process --smooth``
    for each duration, the median of ``repeats`` runs, one measuring child per run, run one at
    a time (durations and modes alternate within a repeat); then the growth per hour."""
    import statistics

    logs = {h: simulated_log(workdir, h * 3600.0) for h in hours}
    print(f"load average before: {_loadavg()}", flush=True)
    for smooth in (False, True):        # warm the numba cache for both modes on the shortest log
        _child(logs[min(hours)], filter_name, workdir, smooth, True)
    runs: dict[tuple[float, bool], list[dict]] = {(h, sm): [] for h in hours for sm in (False, True)}
    for rep in range(repeats):
        for h in hours:
            for smooth in (False, True):
                runs[(h, smooth)].append(_child(logs[h], filter_name, workdir, smooth, True))
        print(f"  repeat {rep + 1}/{repeats} done, load average {_loadavg()}", flush=True)
    print(f"load average after: {_loadavg()}")

    def med(rs: list[dict], key: str) -> float:
        return statistics.median(r.get(key, 0.0) for r in rs)

    rows = []
    for (h, smooth), rs in runs.items():
        n = rs[0]["imu_samples"]
        smooth_s = med(rs, "smoothing_s")
        proc_s = med(rs, "process_s")
        row = {"h": h, "smooth": smooth, "n": n, "m": rs[0]["gnss_epochs"], "read": med(rs, "read_s"),
               "filter": statistics.median(r["process_s"] - r.get("smoothing_s", 0.0) for r in rs),
               "smooth_s": smooth_s, "process": proc_s, "write": med(rs, "write_s"),
               "total": statistics.median(r["read_s"] + r["process_s"] + r["write_s"] for r in rs),
               "cpu": statistics.median(r["read_cpu_s"] + r["process_cpu_s"] + r["write_cpu_s"] for r in rs),
               "peak": med(rs, "peak_read_process_write_mb"),
               "peak_min": min(r["peak_read_process_write_mb"] for r in rs),
               "peak_max": max(r["peak_read_process_write_mb"] for r in rs), "store_mb": med(rs, "store_mb")}
        rows.append(row)
    rows.sort(key=lambda r: (r["smooth"], r["h"]))
    print("kernels: " + "; ".join(sorted({r.get("kernels", "?") for rs in runs.values() for r in rs})))
    print(f"\nfilter {filter_name}, 125 Hz IMU + 5 Hz GNSS simulated CSV logs, median of {repeats} runs; "
          "seconds wall (us per IMU sample); peak = VmHWM of the measuring child (MB)")
    head = (f"{'run':<17}{'IMU samples':>12}{'read s (us)':>16}{'filter s (us)':>16}{'smooth s (us)':>16}"
            f"{'write s (us)':>16}{'total s':>9}{'CPU s':>8}{'peak MB':>9}{'store MB':>9}")
    print(head)
    print("-" * len(head))
    for r in rows:
        us = 1e6 / r["n"]
        name = f"{r['h']:g} h " + ("--smooth" if r["smooth"] else "process")
        sm = f"{r['smooth_s']:7.2f} ({r['smooth_s'] * us:4.2f})" if r["smooth"] else f"{'-':>14}"
        print(f"{name:<17}{r['n']:>12}{r['read']:>8.2f} ({r['read'] * us:4.2f}){r['filter']:>8.2f} "
              f"({r['filter'] * us:4.2f})  {sm}{r['write']:>8.2f} ({r['write'] * us:4.2f}){r['total']:>9.2f}"
              f"{r['cpu']:>8.2f}{r['peak']:>9.0f}{(r['store_mb'] if r['smooth'] else float('nan')):>9.0f}")
    print("\ngrowth per hour of log (least-squares line through the durations: slope, intercept at 0 h)")
    for smooth in (False, True):
        sel = [r for r in rows if r["smooth"] == smooth]
        hs = [r["h"] for r in sel]
        parts = []
        for key, unit in (("peak", "MB"), ("total", "s"), ("read", "s"), ("filter", "s"), ("smooth_s", "s"),
                          ("write", "s")):
            if key == "smooth_s" and not smooth:
                continue
            k, b = _lsq(hs, [r[key] for r in sel])
            parts.append(f"{key.replace('_s', '')} {k:.1f} {unit}/h (+{b:.1f})" if unit == "MB"
                         else f"{key.replace('_s', '')} {k:.2f} {unit}/h ({b:+.2f})")
        print(f"  {'--smooth' if smooth else 'process':<9} " + "; ".join(parts))
    spread = max((r["peak_max"] - r["peak_min"]) for r in rows)
    print(f"(largest spread of the peak over the repeats: {spread:.0f} MB)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--filter", default="ekf")
    ap.add_argument("--smooth", action="store_true", help="also smooth backwards (RTS)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench")
    ap.add_argument("--hours", help="comma-separated log durations in hours, e.g. 1,4,8: per-stage table "
                    "of `process` and `process --smooth` for each, and the growth per hour")
    ap.add_argument("--repeats", type=int, default=3, help="runs per cell with --hours (median), default 3")
    ap.add_argument("--memory-map", action="store_true", help="where the memory goes in one run "
                    "(tracemalloc at the stage boundaries, per-array sizes); slow, not a timing")
    ap.add_argument("--measure", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--stages-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        out = args.workdir / f"out-{args.filter}"
        if args.memory_map:
            memory_map(args.measure, args.filter, out, args.smooth)
            return
        print(json.dumps(measure(args.measure, args.filter, out, args.smooth, full=not args.stages_only)))
        return
    if args.hours:
        try:
            hours = [float(h) for h in args.hours.split(",")]
        except ValueError:
            sys.exit(f"bench_process: --hours takes numbers separated by commas, got {args.hours!r}")
        if not hours or min(hours) <= 0 or args.repeats < 1:
            sys.exit("bench_process: --hours needs positive durations and --repeats at least 1")
        sweep(hours, args.filter, args.workdir, args.repeats)
        return

    log = simulated_log(args.workdir, args.duration)
    if args.memory_map:
        cmd = [sys.executable, __file__, "--measure", str(log), "--filter", args.filter, "--workdir",
               str(args.workdir), "--memory-map"] + (["--smooth"] if args.smooth else [])
        sys.exit(subprocess.run(cmd).returncode)
    cmd = [sys.executable, __file__, "--measure", str(log), "--filter", args.filter, "--workdir", str(args.workdir)]
    cmd += ["--smooth"] if args.smooth else []
    for attempt in ("warm-up", "measure"):                         # the first run warms the numba cache
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"bench_process: the {attempt} run failed:\n{proc.stderr}")
    r = json.loads(proc.stdout)
    print(machine_line())
    print(f"log: {r['imu_samples']} IMU samples (125 Hz), {r['gnss_epochs']} GNSS epochs (5 Hz), filter {args.filter}")
    print(f"kernels: {r['kernels']}")
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
