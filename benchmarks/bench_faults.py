"""GNSS faults on simulated drives: outliers against the innovation gate, and outages.

Usage::

    python benchmarks/bench_faults.py [--seeds 0,1,2] [--duration 900] [--filters ekf,aekf,ckf,vce-ckf]
                                      [--fraction 0.02] [--outage 30] [--skip-outliers] [--skip-outages]

Each seed simulates an automotive-grade drive (125 Hz IMU, 5 Hz GNSS, 1.8 m horizontal /
2.5 m vertical white noise; the simulator's truth is the reference).

(a) Outliers: ``--fraction`` of the fixes after the alignment (the still period plus 20 s) are
    displaced by 15-60 m (uniform) in a uniformly random 3-D direction (seeded).  For every
    filter: the horizontal RMSE (m) of the clean run, of the run with outliers and the default
    gate (``[gnss] gate_probability = 0.9999``) and with the gate off (``gate_probability = 0``),
    with the ratios to the clean run (target: gate <= 1.2x clean), the fixes rejected and the
    fixes forced through the gate.
(b) Outages: ``--outage`` s without GNSS at several places of each drive (fixed starts and the
    straightest and the most turning stretch found on the truth); the horizontal error at the
    end of the outage (target <= 10 m), the largest inside it and the heading change (deg) of
    the vehicle over the window.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

#: Outlier displacement range, m.
OUTLIER_RANGE_M = (15.0, 60.0)
#: Fixes this long after the still period are left clean: the alignment averages them.
ALIGN_MARGIN_S = 20.0


def with_outliers(gnss, fraction: float, seed: int, *, after_s: float = 0.0,
                  range_m: tuple[float, float] = OUTLIER_RANGE_M):
    """GNSS fixes with a share replaced by outliers.

    Parameters
    ----------
    gnss : :class:`navpp.recording.GnssData`.
    fraction : share of the fixes after ``after_s`` to displace, in [0, 1].
    seed : seed of the random choice of fixes, directions and distances.
    after_s : s (recording time); fixes at or before it are never displaced.
    range_m : (min, max) displacement, m, drawn uniformly; the direction is uniform on the sphere.

    Returns
    -------
    (GnssData, idx) : the modified fixes and the (sorted) indices of the displaced ones.
    """
    from navpp import geodesy

    rng = np.random.default_rng(seed)
    eligible = np.flatnonzero(np.asarray(gnss.t) > after_s)
    n = round(fraction * eligible.size)
    idx = np.sort(rng.choice(eligible, size=n, replace=False))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    offset = d * rng.uniform(*range_m, size=(n, 1))
    lat0, lon0 = np.radians(gnss.lat_deg[idx]), np.radians(gnss.lon_deg[idx])
    lat, lon, alt = geodesy.enu_to_geodetic(offset, lat0, lon0, np.asarray(gnss.alt[idx], dtype=float))
    new_lat, new_lon, new_alt = (np.array(a, dtype=float) for a in (gnss.lat_deg, gnss.lon_deg, gnss.alt))
    new_lat[idx], new_lon[idx], new_alt[idx] = np.degrees(lat), np.degrees(lon), alt
    return replace(gnss, lat_deg=new_lat, lon_deg=new_lon, alt=new_alt), idx


def run_filter(rec, name: str, *, gate_probability: float = 0.9999,
               outages: tuple[tuple[float, float], ...] = ()):
    """One filter on a recording (automotive noise): ``(metrics dict, RunResult)``; with
    ``outages`` the fixes inside the windows are removed first (as ``navpp process
    --gnss-outage``) and the metrics hold ``outages``."""
    from navpp import api, engine
    from navpp.config import config_from_dict
    from navpp.metrics import compute_metrics

    cfg = config_from_dict({"imu": {"preset": "automotive"}, "gnss": {"gate_probability": gate_probability}},
                           "bench")
    rec, info = api.apply_outages(rec, outages, "bench")
    res = engine.run(rec, cfg, api.make_filter(name, cfg))
    m = compute_metrics(res.solution, rec.reference, filter_name=name, log="sim", reference="truth",
                        runtime_s=res.runtime_s, imu_samples=len(rec.imu), gnss_epochs=res.gnss_epochs,
                        gnss_rejected=res.gnss_rejected, outages=outages,
                        outages_removed=[w["gnss_removed"] for w in info])
    return m, res


def heading_change_deg(ref, start: float, end: float) -> float:
    """Total absolute heading change (deg) of the reference over ``[start, end]`` s."""
    sel = (ref.t >= start) & (ref.t <= end)
    h = np.unwrap(np.radians(ref.rph_deg[sel, 2]))
    return float(np.degrees(np.sum(np.abs(np.diff(h)))))


def outage_starts(ref, duration: float, still_s: float, n_fixed: int = 3) -> list[tuple[str, float]]:
    """Outage starts: ``n_fixed`` spread over the drive, the straightest and the most turning
    window (heading change of the truth, on a 5 s grid, while moving > 5 m/s)."""
    t_end = float(ref.t[-1])
    first = still_s + 120.0                       # after the heading has converged
    grid = np.arange(first, t_end - duration - 5.0, 5.0)
    speed = np.hypot(ref.vel_enu[:, 0], ref.vel_enu[:, 1])
    moving = [g for g in grid if speed[(ref.t >= g) & (ref.t <= g + duration)].min() > 5.0]
    turns = [heading_change_deg(ref, g, g + duration) for g in moving]
    out = [(f"fixed {i + 1}", float(s)) for i, s in enumerate(np.linspace(first, t_end - duration - 10.0, n_fixed))]
    if moving:
        out.append(("straightest", float(moving[int(np.argmin(turns))])))
        out.append(("most turning", float(moving[int(np.argmax(turns))])))
    return out


def _table(head: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    for r in [head, *rows]:
        print("  ".join(x.ljust(w) for x, w in zip(r, widths)))


def bench_outliers(sims, names, fraction: float) -> None:
    print(f"\n(a) {100 * fraction:g}% of the fixes displaced by {OUTLIER_RANGE_M[0]:g}-{OUTLIER_RANGE_M[1]:g} m; "
          "horizontal RMSE, m (ratio to the clean run)")
    rows = []
    for name in names:
        clean, gate, off, rej, forced, wall = [], [], [], [], [], []
        for seed, sim in sims:
            rec = sim.recording()
            g, _ = with_outliers(rec.gnss, fraction, seed + 1000, after_s=sim.spec.still_effective_s + ALIGN_MARGIN_S)
            bad = replace(rec, gnss=g)
            t0 = time.perf_counter()
            clean.append(run_filter(rec, name)[0]["position_m"]["horizontal"]["rmse"])
            m, res = run_filter(bad, name)
            gate.append(m["position_m"]["horizontal"]["rmse"])
            rej.append(res.gnss_rejected)
            forced.append(int(np.count_nonzero(res.diagnostics.forced)))
            off.append(run_filter(bad, name, gate_probability=0.0)[0]["position_m"]["horizontal"]["rmse"])
            wall.append(time.perf_counter() - t0)
        c, gm, om = np.mean(clean), np.mean(gate), np.mean(off)
        worst = max(a / b for a, b in zip(gate, clean))
        rows.append([name, f"{c:.3f}", f"{gm:.3f} (x{gm / c:.2f}, worst x{worst:.2f})", f"{om:.3f} (x{om / c:.2f})",
                     f"{np.mean(rej):.0f}", f"{np.mean(forced):.1f}", f"{np.mean(wall):.1f}"])
    _table(["filter", "clean", "outliers, gate 0.9999", "outliers, gate off", "rejected", "forced", "s/seed"], rows)


def bench_outages(sims, names, duration: float) -> None:
    print(f"\n(b) {duration:g} s GNSS outages; horizontal error at the outage end / max inside (the filter's "
          "horizontal 1-sigma at the end), m; heading change over the window, deg")
    rows = []
    ends: dict[str, list[float]] = {n: [] for n in names}
    for seed, sim in sims:
        ref = sim.recording().reference
        for label, start in outage_starts(ref, duration, sim.spec.still_effective_s):
            turn = heading_change_deg(ref, start, start + duration)
            cells = [str(seed), f"{label} {start:.0f}-{start + duration:.0f} s", f"{turn:.0f}"]
            for name in names:
                m, res = run_filter(sim.recording(), name, outages=((start, duration),))
                w = m["outages"][0]
                sol = res.solution
                k = min(np.searchsorted(sol.t, w["end_epoch_s"]), len(sol.t) - 1)
                sigma_h = float(np.hypot(sol.std_enu[k, 0], sol.std_enu[k, 1]))
                ends[name].append(w["horizontal_m"]["end"])
                cells.append(f"{w['horizontal_m']['end']:.2f} / {w['horizontal_m']['max']:.2f} ({sigma_h:.1f})")
            rows.append(cells)
    _table(["seed", "window", "turn deg", *names], rows)
    for name in names:
        e = np.asarray(ends[name])
        print(f"{name}: error at the outage end median {np.median(e):.2f} m, max {e.max():.2f} m, "
              f"<= 10 m in {np.count_nonzero(e <= 10.0)} of {e.size}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--duration", type=float, default=900.0, help="drive length, s")
    ap.add_argument("--filters", default="ekf,aekf,ckf,vce-ckf")
    ap.add_argument("--fraction", type=float, default=0.02, help="share of fixes made outliers")
    ap.add_argument("--outage", type=float, default=30.0, help="outage length, s")
    ap.add_argument("--outage-filters", default="ekf,aekf")
    ap.add_argument("--skip-outliers", action="store_true")
    ap.add_argument("--skip-outages", action="store_true")
    args = ap.parse_args()

    from navpp.simulate import SimulationSpec, simulate

    seeds = [int(s) for s in args.seeds.split(",")]
    sims = [(s, simulate(SimulationSpec(duration_s=args.duration, seed=s, preset="automotive", gnss_rate_hz=5.0,
                                        gnss_std_h_m=1.8, gnss_std_u_m=2.5))) for s in seeds]
    print(f"automotive drives of {args.duration:g} s, seeds {seeds}, 5 Hz GNSS, 1.8 m / 2.5 m")
    if not args.skip_outliers:
        bench_outliers(sims, args.filters.split(","), args.fraction)
    if not args.skip_outages:
        bench_outages(sims, args.outage_filters.split(","), args.outage)


if __name__ == "__main__":
    main()
