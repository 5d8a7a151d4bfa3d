"""Paper 001 section 4.2 (SINS/XPN on an orbit): the full benchmark with its run time.

    python benchmarks/bench_xpn.py                      # 100 runs, 150,000 s, all five filters
    python benchmarks/bench_xpn.py --runs 2 --duration 20000 --window 5000 10000
    python benchmarks/bench_xpn.py --added filter       # the other reading of the added errors

Prints the table beside the paper's Table 3 (``navpp bench paper001-xpn`` runs the default
scenario; this script also takes a shorter span and the other reading) and the wall time.
"""

from __future__ import annotations

import argparse
import time

from navpp.papers import format_result
from navpp.papers.xpn import XpnScenario, run_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=150_000.0, help="span, s")
    ap.add_argument("--window", type=float, nargs=2, default=(49_866.0, 99_732.0), help="added-error window, s")
    ap.add_argument("--added", choices=("truth", "filter"), default="truth")
    ap.add_argument("--filters", default="ckf,ukf,sif,aukf,rwckf")
    a = ap.parse_args()
    sc = XpnScenario(duration_s=a.duration, window_s=tuple(a.window), added=a.added)
    t0 = time.perf_counter()
    res = run_scenario(sc, a.runs, a.seed, [f for f in a.filters.split(",") if f])
    res.seconds = time.perf_counter() - t0
    print(format_result(res))
    print(f"\nwall time {res.seconds:.0f} s for {a.runs} runs x {len(a.filters.split(','))} filters x "
          f"{a.duration:g} s")


if __name__ == "__main__":
    main()
