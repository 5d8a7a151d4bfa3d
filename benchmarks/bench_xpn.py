"""Paper 001 section 4.2 (SINS/XPN on an orbit): the full benchmark with its run time.

    python benchmarks/bench_xpn.py                      # 100 runs, 150,000 s, all five filters
    python benchmarks/bench_xpn.py --runs 2 --duration 20000 --window 5000 10000
    python benchmarks/bench_xpn.py --added filter       # the other reading of the added errors
    python benchmarks/bench_xpn.py --runs 10 --jobs 2   # 10 runs on two worker processes

Prints the table beside the paper's Table 3 (``navpp bench paper001-xpn`` runs the default
scenario; this script also takes a shorter span and the other reading) and the wall time.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import time

import numpy as np

from navpp.errors import ConfigError
from navpp.papers import format_result, parse_filter_spec
from navpp.papers.xpn import XpnScenario, run_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=150_000.0, help="span, s")
    ap.add_argument("--window", type=float, nargs=2, default=(49_866.0, 99_732.0), help="added-error window, s")
    ap.add_argument("--added", choices=("truth", "filter"), default="truth")
    ap.add_argument("--filters", default="ckf,ukf,sif,aukf,rwckf")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes, one run each at a time")
    ap.add_argument("--save", help="write the series (ANEES and RMSE curves per filter) to this .npz")
    ap.add_argument("--plot", nargs="+", metavar=("PNG", "NPZ"),
                    help="only plot: PNG from the saved NPZ files (no run)")
    a = ap.parse_args()
    if a.plot:
        plot(a.plot[0], a.plot[1:], a.window)
        return
    t0, c0 = time.perf_counter(), _cpu()
    try:
        sc = XpnScenario(duration_s=a.duration, window_s=(a.window[0], a.window[1]), added=a.added)
        for f in a.filters.split(","):
            parse_filter_spec(f)
        res = run_scenario(sc, a.runs, a.seed, [f for f in a.filters.split(",") if f], jobs=a.jobs)
    except ConfigError as exc:
        raise SystemExit(f"bench_xpn: {exc}") from None
    res.seconds = time.perf_counter() - t0
    print(format_result(res))
    if a.save:
        np.savez_compressed(a.save, **res.series)
    print(f"\nwall time {res.seconds:.0f} s, CPU {_cpu() - c0:.0f} s (this process and its workers) for "
          f"{a.runs} runs x {len(a.filters.split(','))} filters x {a.duration:g} s, --jobs {a.jobs}; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")


def _cpu() -> float:
    """User + system CPU (s) of this process and its finished children."""
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def plot(png: str, npzs: list[str], window: tuple[float, float]) -> None:
    """Figs 12-13's counterpart: position and velocity ANEES per filter over time (600 s means)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for path in npzs:
        d = np.load(path)
        t = d["t"]
        for key in d.files:
            if not key.startswith("anees/"):
                continue
            m = (t.size // 600) * 600
            tt = t[:m].reshape(-1, 600).mean(1)
            for j, ax in enumerate(axes):
                ax.plot(tt, d[key][:m, j].reshape(-1, 600).mean(1), label=key.split("/", 1)[1], lw=1)
    for ax, what in zip(axes, ("position", "velocity")):
        ax.axvspan(*window, color="0.9")
        ax.axhline(1.0, color="k", lw=0.5)
        ax.set_ylabel(f"ANEES {what}")
    axes[0].legend(ncol=5, fontsize=8)
    axes[1].set_xlabel("time (s); shaded: the added errors")
    fig.tight_layout()
    fig.savefig(png, dpi=90)


if __name__ == "__main__":
    main()
