"""Accuracy of every registered filter on simulated 15-minute drives, with the GNSS standard
deviation the filter is told right, 4x too large and 4x too small (issue 4's targets).

Usage:  python benchmarks/bench_filters.py [--seeds 0,1,2] [--duration 900] [--filters ekf,aekf,...]
                                          [--gnss-velocity]

``--filters`` takes the papers' benchmark specs, ``name[key=value; ...]`` (e.g.
``"aukf[max_fading=1000]"``; separate several with commas outside the brackets).

Each seed simulates an automotive-grade drive (125 Hz IMU, 5 Hz GNSS with 1.8 m horizontal /
2.5 m vertical white noise; the simulator's truth is the reference).  The fixes carry their
true 1-sigma; the "x4" and "/4" cases replace it by 4x and 1/4 of the truth, so the filters
are given a wrong R (the adaptive papers' situation).  Prints horizontal and vertical RMSE
(m) per filter and case, averaged over the seeds, with the seed-to-seed standard deviation of
the horizontal RMSE (``± sd``), the ratio to the EKF's mean, the paired difference to the EKF
on the same drives (mean over seeds of ``H_filter - H_ekf``, ``± sd`` of those differences
seed to seed; a 95 % interval for the mean difference is ``± t(0.975, seeds-1) sd / sqrt(seeds)``,
printed below the table), and the wall time per run.  A run that diverges is shown as such and
left out of the means and of the paired differences.  ``--gnss-velocity`` adds the simulator's
GNSS velocity fixes (0.05 m/s) to every drive.
"""

from __future__ import annotations

import argparse
import platform
import time
from dataclasses import replace

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--duration", type=float, default=900.0)
    ap.add_argument("--filters", default=None, help="comma-separated; default: every registered filter")
    ap.add_argument("--cases", default="1,4,0.25", help="factors on the GNSS std given to the filter")
    ap.add_argument("--gnss-velocity", action="store_true", help="add GNSS velocity fixes to the drives")
    args = ap.parse_args()

    from scipy.stats import t as student_t

    from navpp import api, engine
    from navpp.config import config_from_dict
    from navpp.errors import NavppError
    from navpp.filters import FILTERS
    from navpp.metrics import compute_metrics
    from navpp.papers.filter_spec import parse_filter_spec
    from navpp.simulate import SimulationSpec, simulate

    names = split_specs(args.filters) if args.filters else sorted(FILTERS, key=lambda n: (n != "ekf", n))
    if "ekf" not in names:
        names.insert(0, "ekf")                   # the reference of the ratios and paired differences
    seeds = [int(s) for s in args.seeds.split(",")]
    cases = [float(c) for c in args.cases.split(",")]
    cfgs = {}
    for n in names:
        base, opts = parse_filter_spec(n)
        cfgs[n] = (base, config_from_dict({"imu": {"preset": "automotive"}, "filter": {base: opts}}, "bench"))
    print(f"machine: {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}; {len(seeds)} seeds x {args.duration:.0f} s drives"
          + (", GNSS velocity" if args.gnss_velocity else ""))
    h = {(n, c): {} for n in names for c in cases}         # seed -> horizontal RMSE m
    u = {(n, c): {} for n in names for c in cases}
    wall = {n: [] for n in names}
    failed = {(n, c): 0 for n in names for c in cases}
    for seed in seeds:
        sim = simulate(SimulationSpec(duration_s=args.duration, seed=seed, gnss_std_h_m=1.8, gnss_std_u_m=2.5,
                                      gnss_velocity=args.gnss_velocity))
        base = sim.recording()
        for c in cases:
            rec = replace(base, gnss=replace(base.gnss, std_enu=base.gnss.std_enu * c))
            for n in names:
                fname, cfg = cfgs[n]
                t0 = time.perf_counter()
                try:
                    res = engine.run(rec, cfg, api.make_filter(fname, cfg))
                except NavppError:
                    failed[(n, c)] += 1
                    continue
                if c == 1.0:
                    wall[n].append(time.perf_counter() - t0)
                m = compute_metrics(res.solution, rec.reference, filter_name=fname, log="sim", reference="truth",
                                    runtime_s=res.runtime_s, imu_samples=len(rec.imu), gnss_epochs=res.gnss_epochs,
                                    gnss_rejected=res.gnss_rejected, gnss=rec.gnss, lever_arm_m=(0, 0, 0))
                h[(n, c)][seed] = m["position_m"]["horizontal"]["rmse"]
                u[(n, c)][seed] = m["position_m"]["up"]["rmse"]

    def cell(n, c):
        if failed[(n, c)] == len(seeds):
            return "diverged"
        hs = np.array(list(h[(n, c)].values()))
        hv, uv = np.mean(hs), np.mean(list(u[(n, c)].values()))
        ref = np.mean(list(h[("ekf", c)].values())) if h[("ekf", c)] else np.nan
        tag = f" ({failed[(n, c)]} div.)" if failed[(n, c)] else ""
        text = f"{hv:.3f}±{sd(hs):.3f}/{uv:.3f} x{hv / ref:.2f}"
        if n != "ekf":
            d = paired(h[(n, c)], h[("ekf", c)])
            text += f" d{np.mean(d):+.3f}±{sd(d):.3f}" if d.size else " d-"
        return text + tag

    head = ["filter"] + [f"std x{c:g}: H±sd/U RMSE m, H vs EKF, H-EKF paired ±sd" for c in cases] + ["s/run"]
    rows = [[n] + [cell(n, c) for c in cases] + [f"{np.mean(wall[n]):.2f}" if wall[n] else "-"] for n in names]
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    for r in [head, *rows]:
        print("  ".join(x.ljust(w) for x, w in zip(r, widths)))
    k = len(seeds)
    if k > 1:
        print(f"sd: seed-to-seed sample standard deviation over {k} drives; 95 % interval of a mean (or of the "
              f"mean paired difference): ± {student_t.ppf(0.975, k - 1) / np.sqrt(k):.2f} sd")


def sd(values) -> float:
    """Sample standard deviation (ddof 1; 0 for a single value)."""
    v = np.asarray(values, dtype=float)
    return float(np.std(v, ddof=1)) if v.size > 1 else 0.0


def paired(a: dict, b: dict) -> np.ndarray:
    """Differences ``a[seed] - b[seed]`` over the seeds both have."""
    return np.array([a[s] - b[s] for s in a if s in b])


def split_specs(text: str) -> list[str]:
    """``"ekf,aukf[max_fading=2; fade=observed],rwckf"`` -> the three specs (commas inside
    brackets stay with their spec)."""
    out, depth, cur = [], 0, ""
    for ch in text:
        depth += (ch == "[") - (ch == "]")
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    return [x for x in [*out, cur.strip()] if x]


if __name__ == "__main__":
    main()
