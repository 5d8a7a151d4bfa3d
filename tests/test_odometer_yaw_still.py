"""The odometry's yaw rate as an aid, and zero odometer speed as evidence of standing still
(issue 18).

Oracles: the closed-form yaw rate of a known state, finite differences of the measurement
function, the simulator's truth (its gyro bias, its still periods), and the same run with the
feature off.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from navpp import api, engine
from navpp.aiding import odometry_zero
from navpp.config import config_from_dict
from navpp.geodesy import OMEGA_E
from navpp.ins.aids.yaw_rate import OdometerYawRate
from navpp.ins.attitude import rph_to_dcm
from navpp.ins.model import plus
from navpp.ins.state import N_ERR, NOMINAL_SIZE
from navpp.simulate import SimulationSpec, simulate


def _state(heading_deg: float = 30.0, bias_z: float = 0.004) -> np.ndarray:
    """A nominal (16,) at 45 deg N, level, heading ``heading_deg`` (clockwise from north), a
    vertical gyro bias ``bias_z`` rad/s."""
    yaw = -math.radians(heading_deg)                # about up, counter-clockwise
    x = np.zeros(NOMINAL_SIZE)
    x[0], x[3] = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    x[7], x[8], x[9] = math.radians(45.0), math.radians(7.0), 300.0
    x[10:13] = (0.001, -0.002, bias_z)              # gyro bias, body FLU rad/s
    return x


def test_yaw_rate_of_a_known_state():
    """Level vehicle, body = vehicle frame: the yaw rate w.r.t. the Earth is the gyro's z minus its
    bias minus the Earth rate's vertical part, W sin(lat)."""
    x = _state()
    gyro = np.array([0.01, 0.02, 0.25])
    aid = OdometerYawRate.at(2.0, 0.24, 0.002, np.eye(3), gyro, 1e-6)
    expected = 0.25 - 0.004 - OMEGA_E * math.sin(math.radians(45.0))
    assert aid.model(x, aid.p)[0] == pytest.approx(expected, abs=1e-12)
    assert aid.R[0, 0] == pytest.approx(0.002 ** 2 + 1e-6)
    assert aid.kind == "odometer_yaw" and not aid.forceable


def test_yaw_rate_jacobian_matches_finite_differences():
    x = _state(heading_deg=-70.0)
    x[0:4] = [0.99, 0.05, -0.08, 0.3]
    x[0:4] /= np.linalg.norm(x[0:4])
    c_vb = rph_to_dcm(0.02, -0.05, 0.1)
    aid = OdometerYawRate.at(1.0, 0.1, 0.002, c_vb, np.array([0.03, -0.01, 0.12]), 0.0)
    H = aid.jacobian(x)
    assert H.shape == (1, N_ERR)
    eps = 1e-6
    for j in range(N_ERR):
        d = np.zeros(N_ERR)
        d[j] = eps
        fd = -(aid.innovation_at(plus(x, d)) - aid.innovation_at(plus(x, -d))) / (2 * eps)
        assert fd[0] == pytest.approx(H[0, j], abs=1e-9, rel=1e-6), j
    assert H[0, 11] == pytest.approx(-c_vb[2, 2])        # -e_z^T C_vb on the gyro bias
    dX = np.random.default_rng(0).normal(scale=1e-4, size=(5, N_ERR))
    np.testing.assert_allclose(aid.predict_points(x, dX), dX @ H.T, rtol=1e-4, atol=1e-12)


def _bias_z(res, t: float) -> tuple[float, float]:
    b = res.biases
    k = int(np.searchsorted(b.t, t))
    return float(b.gyro[k, 2]), float(b.gyro_std[k, 2])


@pytest.fixture(scope="module")
def biased():
    """A drive whose gyro reads 0.3 deg/s high on z, odometry with yaw rate (0.002 rad/s noise)."""
    return simulate(SimulationSpec(duration_s=400.0, seed=0, still_s=5.0, odometry=True, odometry_yaw_rate=True,
                                   preset="consumer", gyro_bias_dps=(0.0, 0.0, 0.3)))


def test_yaw_rate_update_observes_the_vertical_gyro_bias(biased):
    """With the yaw rate the vertical gyro bias is better known (its sigma at 60 s under 0.9 of
    the run's without it: 0.0089 against 0.0101 deg/s, for GNSS and NHC already observe it through
    the heading) and agrees with the truth (0.3 deg/s plus the simulated Gauss-Markov drift) within
    3 sigma; the 60 s outage ends closer to the truth (2.1 against 3.2 m)."""
    rec = biased.recording()
    truth_t = rec.imu.t
    gm = biased.sensor_errors["gyro_gauss_markov"][:, 2]
    runs = {}
    for yaw in (False, True):
        cfg = config_from_dict({"imu": {"preset": "consumer"}, "vehicle": {"type": "car"},
                                "odometry": {"use_yaw_rate": yaw}}, "test")
        cut, _ = api.apply_outages(rec, [(150.0, 60.0)], "test")
        runs[yaw] = engine.run(cut, cfg, api.make_filter("ekf", cfg))
    assert "odometer_yaw" not in runs[False].updates
    assert runs[True].updates["odometer_yaw"]["applied"] > 1500     # 5 Hz constraint epochs
    (b0, s0), (b1, s1) = _bias_z(runs[False], 60.0), _bias_z(runs[True], 60.0)
    true = math.radians(0.3) + float(np.interp(60.0, truth_t, gm))
    print(f"bias z at 60 s: without {math.degrees(b0):.4f} +- {math.degrees(s0):.4f}, with {math.degrees(b1):.4f} "
          f"+- {math.degrees(s1):.4f} deg/s, truth {math.degrees(true):.4f}")
    assert s1 < 0.9 * s0
    assert abs(b1 - true) < 3.0 * s1
    from navpp.metrics import compute_metrics

    ends = [compute_metrics(r.solution, rec.reference, filter_name="ekf", log="t", reference="truth",
                            runtime_s=0.0, imu_samples=0, gnss_epochs=0, gnss_rejected=0,
                            outages=[(150.0, 60.0)])["outages"][0]["horizontal_m"]["end"] for r in runs.values()]
    print(f"outage end {ends[0]:.2f} m without, {ends[1]:.2f} m with")
    assert ends[1] < ends[0]
    d = runs[True].diagnostics
    assert np.nanmean(d.aids["yaw"][1]) < 2.0                # the yaw-rate NIS is consistent (mean 1)
    from navpp.io.writers import diagnostics_columns

    names, cols, decimals = diagnostics_columns(d)
    k = names.index("nu_yaw")
    np.testing.assert_array_equal(cols[k], d.aids["yaw"][0])
    assert names[k + 1:k + 3] == ["nis_yaw", "yaw_accepted"] and decimals[k] == 6


def test_a_yaw_rate_left_unused_is_said(tmp_path):
    sim = simulate(SimulationSpec(duration_s=120.0, seed=3, still_s=20.0, odometry=True, odometry_yaw_rate=True))
    from navpp.simulate import write_csv_log

    write_csv_log(sim, tmp_path / "log")
    res = api.process(tmp_path / "log", filter_name="ekf", out_dir=tmp_path / "out")
    assert any("its yaw rate is not ([odometry] use_yaw_rate = true fuses it)" in n for n in res.notes), res.notes
    assert "odometer_yaw" not in res.run.updates


def test_odometry_zero_closed_form():
    """Zero within the window on both sides, no gap, at least two samples: evidence; one moving
    sample, a NaN or a gap in the window: none."""
    odo_t = np.arange(0.0, 10.0, 0.1)
    speed = np.where((odo_t >= 2.0) & (odo_t <= 6.0), 0.0, 3.0)
    speed[50] = 0.005                                  # under the threshold: still zero
    t = np.array([1.8, 2.5, 4.0, 5.45, 5.65, 8.0])
    np.testing.assert_array_equal(odometry_zero(t, odo_t, speed, 0.01, 0.5, 0.2),
                                  [False, True, True, True, False, False])
    speed[40] = np.nan
    assert not odometry_zero(np.array([4.0]), odo_t, speed, 0.01, 0.5, 0.2)[0]
    speed[40] = 0.0
    keep = np.abs(odo_t - 4.0) > 0.25                  # a 0.5 s hole around 4 s
    assert not odometry_zero(np.array([4.0]), odo_t[keep], speed[keep], 0.01, 0.5, 0.2)[0]
    assert odometry_zero(np.array([4.0]), odo_t[keep], speed[keep], 0.01, 0.5, 0.6)[0]


def test_zero_odometry_is_evidence_of_standstill():
    """An idling engine shakes the IMU (2 deg/s, 0.13 m/s^2 at rest) beyond the fixed-threshold
    detector's floors (the self-calibrated detector off): without odometry, or with the evidence
    off, no ZUPT; with the simulator's odometry (wheels at rest read exactly 0) ZUPTs run where the
    truth stands still, and the velocity there is better."""
    sim = simulate(SimulationSpec(duration_s=300.0, seed=4, still_s=30.0, odometry=True,
                                  vibration_gyro_dps=(2.0, 0.5), vibration_accel_mps2=(0.13, 0.03)))
    rec = sim.recording()
    e = sim.sensor_errors
    assert np.all(rec.odometry.speed[e["odometry_true_speed"] == 0.0] == 0.0)      # wheels at rest read 0
    runs = {}
    for name, odo, zero in (("none", None, 0.01), ("off", rec.odometry, 0.0), ("on", rec.odometry, 0.01)):
        cfg = config_from_dict({"imu": {"preset": "automotive"}, "vehicle": {"type": "car"},
                                "auto": {"standstill": False}, "odometry": {"still_speed_mps": zero}}, "test")
        runs[name] = engine.run(replace(rec, odometry=odo), cfg, api.make_filter("ekf", cfg))
    zupt = {name: r.updates.get("zupt", {}).get("applied", 0) for name, r in runs.items()}
    print(zupt)
    assert zupt["none"] == 0 and zupt["off"] == 0 and zupt["on"] > 100
    ref = rec.reference
    still = np.linalg.norm(ref.vel_enu, axis=1) == 0.0
    still &= ref.t > 40.0                             # the stops after the start
    assert still.sum() > 20
    from navpp.metrics import interpolate_solution

    err = {}
    for name in ("off", "on"):
        est = interpolate_solution(runs[name].solution, ref.t[still])
        err[name] = float(np.sqrt(np.mean(np.sum(np.square(est["vel_enu"]), axis=1))))
    print(err)
    assert err["on"] < 0.7 * err["off"]             # 0.0056 against 0.0106 m/s
    # the evidence holds only where the truth stands still
    zero = odometry_zero(rec.imu.t, rec.odometry.t, rec.odometry.speed, 0.01, 0.5, 0.2)
    moving = np.interp(rec.imu.t, e["odometry_true_t"], e["odometry_true_speed"]) > 0.0
    assert zero.sum() > 1000 and not np.any(zero & moving)


def test_forward_acceleration_is_the_vehicles():
    """The acceleration the slip term uses (mean specific force plus gravity, rotated with the
    attitude) against the simulator's: the reference's speed differentiated, within 0.05 m/s^2."""
    from navpp.aiding import Aiding
    from navpp.ins.attitude import dcm_to_quat, rph_deg_to_dcm

    sim = simulate(SimulationSpec(duration_s=200.0, seed=1, still_s=20.0, odometry=True, odometry_rate_hz=20.0,
                                  errors=False))
    rec = sim.recording()
    cfg = config_from_dict({"vehicle": {"type": "car"}}, "test")
    aid = Aiding(cfg, rec.imu.t, rec.imu.gyro, rec.imu.accel, 1e-4, 1e-3, rec.gnss, np.arange(len(rec.gnss)),
                 odometry=rec.odometry)
    ref = rec.reference
    speed = np.linalg.norm(ref.vel_enu, axis=1)
    accel = np.gradient(speed, ref.t)
    worst, hard = 0.0, 0
    for k in range(10, ref.t.size - 10, 7):
        x = np.zeros(NOMINAL_SIZE)
        x[0:4] = dcm_to_quat(rph_deg_to_dcm(ref.rph_deg[k]))
        x[7], x[8], x[9] = math.radians(ref.lat_deg[k]), math.radians(ref.lon_deg[k]), ref.alt[k]
        a = aid.forward_acceleration(float(ref.t[k]), x)
        worst = max(worst, abs(a - accel[k]))
        hard += abs(accel[k]) > 1.5
    print(f"worst {worst:.4f} m/s^2 over {hard} hard samples")
    assert hard > 10 and worst < 0.05


def test_slip_widens_the_odometer_sigma_under_hard_braking():
    """Odometry that slips braking hard (0.3 m/s per m/s^2 beyond 2 m/s^2, up to 0.38 m/s): taken
    at its 0.02 m/s the slip creeps into the velocity and the correct readings after it are gated
    out (24 here); with [odometry] slip_per_g the sigma widens there, nothing is gated, and the run
    is closer to the truth (horizontal RMSE 0.407 -> 0.387 m, velocity 0.046 -> 0.036 m/s)."""
    from navpp.metrics import compute_metrics

    sim = simulate(SimulationSpec(duration_s=300.0, still_s=30.0, seed=2026, lever_arm_m=(0.3, 0.0, 1.2),
                                  odometry=True, odometry_rate_hz=20.0,
                                  odometry_scale_error_pct=2.0, odometry_quantum_mps=0.01, odometry_slip=0.3))
    rec = sim.recording()
    assert np.abs(sim.sensor_errors["odometry_slip_mps"]).max() > 0.3
    runs, rmse = {}, {}
    for k in (0.0, 0.1):
        cfg = config_from_dict({"imu": {"preset": "automotive"}, "gnss": {"lever_arm_m": [0.3, 0.0, 1.2]},
                                "odometry": {"slip_per_g": k}}, "test")
        runs[k] = engine.run(rec, cfg, api.make_filter("ekf", cfg))
        m = compute_metrics(runs[k].solution, rec.reference, filter_name="ekf", log="t", reference="truth",
                            runtime_s=0.0, imu_samples=0, gnss_epochs=0, gnss_rejected=0)
        rmse[k] = (m["position_m"]["horizontal"]["rmse"], m["velocity_mps"]["horizontal"]["rmse"])
    rejected = {k: r.updates["odometer"]["rejected"] for k, r in runs.items()}
    print(rejected, rmse)
    assert rejected[0.0] >= 10 and rejected[0.1] == 0
    assert rmse[0.1][0] < rmse[0.0][0] and rmse[0.1][1] < rmse[0.0][1]
