"""Issue 14's targets, run as a new user would: the default config on realistic logs.

The simulated logs (``navpp simulate --realism consumer-car``: engine vibration, turn-on biases,
scale factors, non-orthogonality, stale rows, a late IMU clock) are scored against the
simulator's exact truth; the bundled real walk (``sample_data/walk_0827``) against the RTK fixes
withheld in its two outages.  ``benchmarks/bench_realism.py`` runs the same cases over more seeds.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import navpp
from navpp import api, engine, geodesy
from navpp.config import config_from_dict
from navpp.metrics import compute_metrics
from navpp.simulate import SimulationSpec, simulate

WALK = Path(__file__).resolve().parents[1] / "sample_data" / "walk_0827"


def _no_config_run(spec: SimulationSpec):
    sim = simulate(spec)
    rec = sim.recording()
    cfg = config_from_dict({}, "test")                      # no config at all
    res = engine.run(rec, cfg, api.make_filter("ekf", cfg))
    m = compute_metrics(res.solution, rec.reference, filter_name="ekf", log="", reference="", runtime_s=0.0,
                        imu_samples=0, gnss_epochs=0, gnss_rejected=0, gnss=rec.gnss)
    return res, m


def _no_worse_than_the_fixes(m) -> None:
    for axis in ("horizontal", "up"):
        assert m["position_m"][axis]["rmse"] <= m["gnss_position_m"][axis]["rmse"], (axis, m["position_m"][axis],
                                                                                     m["gnss_position_m"][axis])


@pytest.mark.parametrize("seed", [1, 2])
def test_a_phone_log_starting_at_speed_with_no_config_beats_its_fixes(seed):
    """Like issue 14's log 3: 60 s at 104 Hz starting at 8 m/s, 5 Hz fixes of 0.5 / 0.8 m, no
    config: the accelerometer biases (30-40 mg) cannot be read from a standstill, yet the height
    must not wander off the fixes."""
    spec = SimulationSpec(duration_s=60.0, seed=seed, realism="consumer-car", start_in_motion=True, imu_rate_hz=104.0,
                          gnss_rate_hz=5.0, gnss_std_h_m=0.5, gnss_std_u_m=0.8, gnss_gap_s=0.0)
    res, m = _no_config_run(spec)
    _no_worse_than_the_fixes(m)
    assert any("no still stretch to measure the accelerometer biases on" in n for n in res.notes), res.notes


@pytest.mark.parametrize("seed", [2, 3])
def test_a_y_up_30_hz_robot_log_with_no_config_beats_its_fixes(seed):
    """Like issue 14's log 4: gravity on the IMU's +y, 30 Hz, 2.5 Hz fixes of 1.5 / 2.5 m, no
    config, a smooth pull-away after the idle (which the standstill detector alone runs into):
    the mounting is found and named, and the run beats the fixes."""
    spec = SimulationSpec(duration_s=300.0, seed=seed, realism="consumer-car", mounting_rpy_deg=(90.0, 0.0, 0.0),
                          imu_rate_hz=30.0, gnss_rate_hz=2.5, gnss_std_h_m=1.5, gnss_std_u_m=2.5, gnss_gap_s=0.0)
    res, m = _no_config_run(spec)
    _no_worse_than_the_fixes(m)
    assert any("gravity is on the IMU's +y axis" in w and "mounting_rpy_deg" in w for w in res.warnings)


def test_the_consumer_car_smoothed_outages_meet_the_target():
    """Like issue 14's log 1, config = lever arm + vehicle type: 15-s outages every 60 s.  The
    smoothed target (<= 0.4 m) is met; the forward one (<= 1.5 m) is not yet (about 2 m:
    benchmarks/bench_realism.py), so here the forward run is only held to not diverging and to
    a consistent error/sigma inside the outages."""
    spec = SimulationSpec(duration_s=400.0, seed=1, realism="consumer-car")
    sim = simulate(spec)
    rec = sim.recording()
    outs = [(float(t0), 15.0) for t0 in np.arange(90.0, 380.0, 60.0)]
    cut, _ = api.apply_outages(rec, outs, "test")
    cfg = config_from_dict({"gnss": {"lever_arm_m": list(spec.lever_arm_m)}, "vehicle": {"type": "car"}}, "test")
    res = engine.run(cut, cfg, api.make_filter("ekf", cfg), smooth=True)
    sm = compute_metrics(res.smoothed.solution, rec.reference, filter_name="ekf", log="", reference="", runtime_s=0.0,
                         imu_samples=0, gnss_epochs=0, gnss_rejected=0, outages=outs)["outages"]
    h = math.sqrt(sum(o["horizontal_m"]["rmse"] ** 2 * o["epochs"] for o in sm) / sum(o["epochs"] for o in sm))
    assert h <= 0.4, h
    # the forward run inside the outages: errors over the reported sigma near 1
    sol = res.solution
    inside = np.zeros(rec.reference.t.shape, bool)
    for t0, d in outs:
        inside |= (rec.reference.t >= t0) & (rec.reference.t < t0 + d)
    tr = rec.reference.t[inside]
    lat0, lon0 = math.radians(float(rec.reference.lat_deg[0])), math.radians(float(rec.reference.lon_deg[0]))
    e = (geodesy.geodetic_to_enu(np.radians(np.interp(tr, sol.t, sol.lat_deg)),
                                 np.radians(np.interp(tr, sol.t, sol.lon_deg)), np.zeros(tr.size), lat0, lon0, 0.0)
         - geodesy.geodetic_to_enu(np.radians(rec.reference.lat_deg[inside]), np.radians(rec.reference.lon_deg[inside]),
                                   np.zeros(tr.size), lat0, lon0, 0.0))
    s = np.stack([np.interp(tr, sol.t, sol.std_enu[:, 0]), np.interp(tr, sol.t, sol.std_enu[:, 1])], axis=1)
    ratio = math.sqrt(float(np.mean((e[:, :2] / s) ** 2)))
    assert 0.5 < ratio < 2.0, ratio


def _held_fix_rmse(gnss: pd.DataFrame, ref: pd.DataFrame) -> float:
    """A receiver that holds its last fix through the outage: the baseline to beat."""
    k = np.searchsorted(gnss["t"].to_numpy(), ref["t"].to_numpy()) - 1
    lat0, lon0 = math.radians(float(ref["lat"][0])), math.radians(float(ref["lon"][0]))

    def enu(lat, lon):
        return geodesy.geodetic_to_enu(np.radians(lat), np.radians(lon), np.zeros(len(lat)), lat0, lon0, 0.0)

    e = enu(gnss["lat"].to_numpy()[k], gnss["lon"].to_numpy()[k]) - enu(ref["lat"].to_numpy(), ref["lon"].to_numpy())
    return math.sqrt(float(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))


def test_the_bundled_real_walk_beats_holding_the_last_fix_with_honest_sigmas():
    """sample_data/walk_0827, its own navpp.toml (mounting, lever arm, time base: no noise
    figures): inside the two outages, better than the last fix held, and error/sigma near 1."""
    res = navpp.process(WALK, filter_name="ekf", write=False)
    h = res.metrics["position_m"]["horizontal"]["rmse"]
    held = _held_fix_rmse(pd.read_csv(WALK / "gnss.csv"), pd.read_csv(WALK / "reference.csv"))
    assert h < 0.7 * held, (h, held)
    ref = pd.read_csv(WALK / "reference.csv")
    sol = res.solution
    t = ref["t"].to_numpy() - res.recording.t0_ns * 1e-9
    lat0, lon0 = math.radians(float(ref["lat"][0])), math.radians(float(ref["lon"][0]))
    a = geodesy.geodetic_to_enu(np.radians(np.interp(t, sol.t, sol.lat_deg)),
                                np.radians(np.interp(t, sol.t, sol.lon_deg)), np.zeros(t.size), lat0, lon0, 0.0)
    b = geodesy.geodetic_to_enu(np.radians(ref["lat"].to_numpy()), np.radians(ref["lon"].to_numpy()), np.zeros(t.size),
                                lat0, lon0, 0.0)
    s = np.stack([np.interp(t, sol.t, sol.std_enu[:, 0]), np.interp(t, sol.t, sol.std_enu[:, 1])], axis=1)
    ratio = math.sqrt(float(np.mean(((a - b)[:, :2] / s) ** 2)))
    assert 0.5 < ratio < 2.0, ratio
    assert any("stale rows" in w for w in res.warnings)
