"""RTS smoothing across GNSS outages (issue 7): forward filter vs its smoothed run.

Usage:  python benchmarks/bench_smoother.py [--seeds 3] [--duration 900] [--preset automotive]
                                            [--filters ekf,aekf,ckf,ukf,vce-ckf] [--outages 200:30,450:30,700:30]

Simulates a car drive per seed (``navpp.simulate``, 125 Hz IMU, 5 Hz GNSS with 1.8 m / 2.5 m
white noise), removes the GNSS inside the outage windows, runs every filter with smoothing on,
and compares both solutions with the simulator's truth at the 10 Hz reference epochs:

- horizontal RMSE inside the outages (all outage epochs of the drive pooled) and the ratio
  smoothed / forward (issue 7's target: <= 0.3);
- horizontal error at each outage's end (median over windows);
- horizontal RMSE over the whole drive (target: smoothed better than forward);
- the smoothing's time as a share of the forward run's.

Prints one row per (seed, filter) and the pooled figures per filter.  Speed and memory on a
1-hour log: ``python benchmarks/bench_process.py --smooth``.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np


def parse_outages(text: str) -> list[tuple[float, float]]:
    out = []
    for part in text.split(","):
        start, dur = part.split(":")
        out.append((float(start), float(dur)))
    return out


def run(log: Path, filt: str, outages: list[tuple[float, float]]) -> dict:
    from navpp import api

    res = api.process(log, filter_name=filt, write=False, smooth=True, gnss_outages=outages)
    m, f = res.metrics, res.metrics["forward"]

    def pooled(windows: list[dict]) -> tuple[float, int]:
        sq = sum(w["horizontal_m"]["rmse"] ** 2 * w["epochs"] for w in windows if w.get("epochs"))
        n = sum(w["epochs"] for w in windows if w.get("epochs"))
        return math.sqrt(sq / n) if n else float("nan"), n

    (out_s, n), (out_f, _) = pooled(m["outages"]), pooled(f["outages"])
    return {"out_f": out_f, "out_s": out_s, "out_epochs": n,
            "end_f": float(np.median([w["horizontal_m"]["end"] for w in f["outages"]])),
            "end_s": float(np.median([w["horizontal_m"]["end"] for w in m["outages"]])),
            "all_f": f["position_m"]["horizontal"]["rmse"], "all_s": m["position_m"]["horizontal"]["rmse"],
            "up_f": f["position_m"]["up"]["rmse"], "up_s": m["position_m"]["up"]["rmse"],
            "fwd_s": f["runtime_s"], "rts_s": m["smoothing_s"],
            "sq_f": out_f ** 2 * n, "sq_s": out_s ** 2 * n, "sq_all_f": f["position_m"]["horizontal"]["rmse"] ** 2,
            "sq_all_s": m["position_m"]["horizontal"]["rmse"] ** 2}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--preset", default="automotive")
    ap.add_argument("--filters", default="ekf,aekf,ckf,ukf,vce-ckf")
    ap.add_argument("--outages", default="200:30,450:30,700:30")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench-smoother")
    args = ap.parse_args()
    from navpp import api

    outages = parse_outages(args.outages)
    filters = [f.strip() for f in args.filters.split(",") if f.strip()]
    print(f"{args.seeds} simulated {args.duration:.0f} s drives ({args.preset} IMU 125 Hz, GNSS 5 Hz), "
          f"GNSS outages {args.outages} (start:duration s); errors against the simulator's truth")
    print(f"{'seed':>4} {'filter':<9} {'outage H RMSE fwd':>17} {'smoothed':>9} {'ratio':>6}  "
          f"{'end fwd':>8} {'end sm':>7}  {'all H fwd':>9} {'all sm':>7}  {'rts/fwd time':>12}")
    acc: dict[str, list[dict]] = {f: [] for f in filters}
    for seed in range(args.seeds):
        log = args.workdir / f"drive-{args.preset}-{int(args.duration)}s-seed{seed}"
        if not (log / "imu.csv").exists():
            api.simulate_log(log, duration_s=args.duration, seed=seed, preset=args.preset)
        for f in filters:
            t = time.perf_counter()
            try:
                r = run(log, f, outages)
            except Exception as exc:  # noqa: BLE001  (report, go on)
                print(f"{seed:>4} {f:<9} failed: {str(exc)[:120]}")
                continue
            acc[f].append(r)
            print(f"{seed:>4} {f:<9} {r['out_f']:>15.2f} m {r['out_s']:>7.2f} m {r['out_s'] / r['out_f']:>6.2f}  "
                  f"{r['end_f']:>6.2f} m {r['end_s']:>5.2f} m  {r['all_f']:>7.3f} m {r['all_s']:>5.3f} m  "
                  f"{100 * r['rts_s'] / r['fwd_s']:>10.0f} %   ({time.perf_counter() - t:.1f} s)")
    print()
    print("pooled over the seeds (RMSE over every outage epoch / every epoch of all drives):")
    for f, rows in acc.items():
        if not rows:
            continue
        n = sum(r["out_epochs"] for r in rows)
        of = math.sqrt(sum(r["sq_f"] for r in rows) / n)
        os_ = math.sqrt(sum(r["sq_s"] for r in rows) / n)
        af = math.sqrt(np.mean([r["sq_all_f"] for r in rows]))
        as_ = math.sqrt(np.mean([r["sq_all_s"] for r in rows]))
        share = sum(r["rts_s"] for r in rows) / sum(r["fwd_s"] for r in rows)
        verdict = "meets" if os_ <= 0.3 * of and as_ < af else "MISSES"
        print(f"  {f:<9} outages: forward {of:.2f} m, smoothed {os_:.2f} m, ratio {os_ / of:.3f}; whole drive: "
              f"{af:.3f} m -> {as_:.3f} m; smoothing {100 * share:.0f}% of the forward time; {verdict} the target "
              f"({len(rows)} of {args.seeds} drives)")


if __name__ == "__main__":
    main()
