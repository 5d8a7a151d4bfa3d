"""Land-vehicle aiding (issue 8): what GNSS velocity, NHC, ZUPT and ZARU buy on simulated drives.

Usage:  python benchmarks/bench_aiding.py [--seeds 3] [--filter ekf] [--only velocity|outages|zaru]

Three experiments, each against the same run without the aid, errors against the simulator's
truth:

1. ``velocity``: 15-minute automotive drives, 5 Hz GNSS with velocity (0.02 m/s 1-sigma):
   horizontal RMSE with the velocity against positions only (target <= 0.25).
2. ``outages``: 15-minute automotive drives with three 30 s GNSS outages (200, 450 and 700 s, as
   in bench_smoother.py: a turn with a dip, a stop, a straight hill; and at 300, 500, 700 s, all
   on the straight hill at 20 m/s): horizontal error at each outage's end with NHC + ZUPT
   (+ ZARU) against neither (target: median ratio <= 0.4).
3. ``zaru``: 10-minute consumer-grade drives with two 10 s stops (still 30 s first): heading
   error with ZARU against without (ZUPT in both): at the end, RMSE after the first stop, and
   the vertical gyro bias's 1-sigma at the end of the second stop (target: heading <= 0.5).

Prints one line per drive and the pooled figures.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

#: ``[auto]`` keys turned off (``--auto-off``)
AUTO: dict[str, bool] = {}


def _run(rec, filt: str, preset: str, vehicle: dict, gnss: dict | None = None, outages=(),
         odometry: dict | None = None):
    from navpp import api, engine
    from navpp.config import config_from_dict
    from navpp.metrics import compute_metrics

    cfg = config_from_dict({"imu": {"preset": preset}, "vehicle": vehicle, "gnss": gnss or {}, "auto": AUTO,
                            "odometry": odometry or {}}, "bench")
    cut, _ = api.apply_outages(rec, list(outages), "sim")
    res = engine.run(cut, cfg, api.make_filter(filt, cfg))
    m = compute_metrics(res.solution, rec.reference, filter_name=filt, log="sim", reference="truth",
                        runtime_s=res.runtime_s, imu_samples=len(rec.imu), gnss_epochs=res.gnss_epochs,
                        gnss_rejected=res.gnss_rejected, outages=list(outages), updates=res.updates)
    return res, m


def velocity(seeds: int, filt: str) -> float:
    """Pooled ratio of horizontal RMSE, GNSS velocity on / off."""
    from navpp.simulate import SimulationSpec, simulate

    sq_v = sq_p = 0.0
    for seed in range(seeds):
        rec = simulate(SimulationSpec(duration_s=900.0, seed=seed, gnss_velocity=True,
                                      gnss_std_vel_mps=0.02)).recording()
        _, mp = _run(rec, filt, "automotive", {}, {"use_velocity": False})
        _, mv = _run(rec, filt, "automotive", {})
        hp, hv = mp["position_m"]["horizontal"]["rmse"], mv["position_m"]["horizontal"]["rmse"]
        sq_p, sq_v = sq_p + hp * hp, sq_v + hv * hv
        print(f"  velocity seed {seed}: positions only {hp:.3f} m, with velocity {hv:.3f} m, ratio {hv / hp:.3f}")
    ratio = math.sqrt(sq_v / sq_p)
    print(f"velocity: pooled horizontal RMSE ratio {ratio:.3f} (target <= 0.25)")
    return ratio


OUTAGE_SETS = {"turn-stop-hill": [(200.0, 30.0), (450.0, 30.0), (700.0, 30.0)],
               "straight hill": [(300.0, 30.0), (500.0, 30.0), (700.0, 30.0)]}


def outages(seeds: int, filt: str) -> dict[str, float]:
    """Median ratio of the outage-end errors, constraints on / off, per outage set."""
    from dataclasses import replace

    from navpp.simulate import SimulationSpec, simulate

    out = {}
    for name, windows in OUTAGE_SETS.items():
        ends_off, ends_on, ends_odo, ends_yaw, rmse_on, rmse_odo, rmse_yaw = [], [], [], [], [], [], []
        for seed in range(seeds):
            # the odometry (1 % scale error, 0.02 m/s noise, 10 Hz; yaw rate 0.002 rad/s noise) is
            # drawn from a stream of its own: the IMU and GNSS are those of the log without it
            with_odo = simulate(SimulationSpec(duration_s=900.0, seed=seed, odometry=True, odometry_yaw_rate=True,
                                               odometry_scale_error_pct=1.0)).recording()
            rec = replace(with_odo, odometry=None)
            _, m0 = _run(rec, filt, "automotive", {"type": "none", "zupt": False, "zaru": False}, outages=windows)
            _, m1 = _run(rec, filt, "automotive", {"type": "car"}, outages=windows)
            _, m2 = _run(with_odo, filt, "automotive", {"type": "car"}, outages=windows)
            _, m3 = _run(with_odo, filt, "automotive", {"type": "car"}, outages=windows,
                         odometry={"use_yaw_rate": True})
            e0 = [w["horizontal_m"]["end"] for w in m0["outages"]]
            e1 = [w["horizontal_m"]["end"] for w in m1["outages"]]
            e2 = [w["horizontal_m"]["end"] for w in m2["outages"]]
            e3 = [w["horizontal_m"]["end"] for w in m3["outages"]]
            ends_off += e0
            ends_on += e1
            ends_odo += e2
            ends_yaw += e3
            rmse_on.append(m1["position_m"]["horizontal"]["rmse"])
            rmse_odo.append(m2["position_m"]["horizontal"]["rmse"])
            rmse_yaw.append(m3["position_m"]["horizontal"]["rmse"])
            print(f"  outages {name} seed {seed}: end errors without {np.round(e0, 2).tolist()} m, "
                  f"with NHC+ZUPT {np.round(e1, 2).tolist()} m, + odometer {np.round(e2, 2).tolist()} m, "
                  f"+ its yaw rate {np.round(e3, 2).tolist()} m")
        ratio = float(np.median(ends_on) / np.median(ends_off))
        out[name] = ratio
        print(f"outages ({name}): median end error {np.median(ends_off):.2f} m -> {np.median(ends_on):.2f} m, "
              f"ratio {ratio:.3f} (target <= 0.4; {len(ends_on)} outages); with the odometer "
              f"{np.median(ends_odo):.2f} m (target <= 1.0 m), whole-drive RMSE {np.mean(rmse_on):.3f} -> "
              f"{np.mean(rmse_odo):.3f} m; with its yaw rate too {np.median(ends_yaw):.2f} m, RMSE "
              f"{np.mean(rmse_yaw):.3f} m")
    return out


def zaru(seeds: int, filt: str) -> dict[str, float]:
    """Heading error ratios, ZARU on / off (consumer IMU)."""
    from navpp.metrics import interpolate_solution, wrap_deg
    from navpp.simulate import SimulationSpec, simulate

    acc = {"end": [[], []], "after": [[], []], "bz_std": [[], []]}
    for seed in range(seeds):
        sim = simulate(SimulationSpec(duration_s=600.0, still_s=30.0, seed=seed, preset="consumer"))
        rec = sim.recording()
        ref = rec.reference
        for j, veh in enumerate(({"zaru": False}, {})):
            res, _ = _run(rec, filt, "consumer", veh)
            est = interpolate_solution(res.solution, ref.t)
            err = np.abs(wrap_deg(est["rph_deg"][:, 2] - ref.rph_deg[:, 2]))
            after = ref.t > 230.0
            k = int(np.searchsorted(res.biases.t, 429.0))
            acc["end"][j].append(float(err[-1]))
            acc["after"][j].append(float(np.sqrt(np.mean(err[after] ** 2))))
            acc["bz_std"][j].append(float(np.degrees(res.biases.gyro_std[k, 2]) * 3600.0))
        print(f"  zaru seed {seed}: heading at the end {acc['end'][0][-1]:.3f} -> {acc['end'][1][-1]:.3f} deg, "
              f"RMSE after the first stop {acc['after'][0][-1]:.3f} -> {acc['after'][1][-1]:.3f} deg, "
              f"gyro z bias sigma at the second stop {acc['bz_std'][0][-1]:.1f} -> {acc['bz_std'][1][-1]:.1f} deg/h")
    out = {}
    for key, (off, on) in acc.items():
        out[key] = float(np.sqrt(np.mean(np.square(on))) / np.sqrt(np.mean(np.square(off))))
    print(f"zaru: ratio with / without: heading at the end {out['end']:.3f}, heading RMSE after the first stop "
          f"{out['after']:.3f}, gyro z bias sigma {out['bz_std']:.3f} (target heading <= 0.5)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--filter", default="ekf")
    ap.add_argument("--only", choices=("velocity", "outages", "zaru"))
    ap.add_argument("--auto-off", default="", help="[auto] steps to turn off, comma-separated, or 'all' "
                    "(what the calibration from the data changes)")
    args = ap.parse_args()
    from navpp.config import AutoConfig

    steps = [f.name for f in __import__("dataclasses").fields(AutoConfig)]
    off = steps if args.auto_off == "all" else [k for k in args.auto_off.split(",") if k]
    AUTO.update({k: False for k in off})
    if args.only in (None, "velocity"):
        velocity(args.seeds, args.filter)
    if args.only in (None, "outages"):
        outages(args.seeds, args.filter)
    if args.only in (None, "zaru"):
        zaru(args.seeds, args.filter)


if __name__ == "__main__":
    main()
