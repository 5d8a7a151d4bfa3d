"""Paper 002's SINS/GPS benchmark: truth and IMU, the position + velocity measurement, runs."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from navpp import geodesy
from navpp import papers as benchmarks
from navpp.errors import ConfigError
from navpp.ins.model import minus, plus
from navpp.ins.strapdown import free_inertial
from navpp.papers import sins as bs

SHORT = replace(bs.Paper002Scenario(), duration_s=60.0)


def _err_truth(sc: bs.Paper002Scenario, out: np.ndarray, t: np.ndarray) -> np.ndarray:
    truth = bs.truth_states(sc, t)
    return np.array([minus(truth[k], out[k]) for k in range(t.size)])


@pytest.mark.parametrize("heading_deg", [90.0, 270.0])
def test_error_free_imu_integrates_back_to_the_truth(heading_deg):
    sc = replace(bs.Paper002Scenario(), heading_deg=heading_deg)
    t = bs.imu_times(sc)
    gyro, accel = bs.ideal_imu(sc)
    out = free_inertial(bs.truth_states(sc, t[:1])[0], t, np.tile(gyro, (t.size, 1)), np.tile(accel, (t.size, 1)))
    dx = _err_truth(sc, out[::500], t[::500])
    assert t[-1] == pytest.approx(400.0)
    assert np.abs(dx[:, 6:9]).max() < 1e-4          # m, over 400 s and 80 km
    assert np.abs(dx[:, 3:6]).max() < 1e-7          # m/s
    assert np.abs(dx[:, 0:3]).max() < 1e-10         # rad


def test_ideal_imu_is_earth_and_transport_rate_plus_gravity():
    sc = bs.Paper002Scenario()
    gyro, accel = bs.ideal_imu(sc)
    lat = math.radians(sc.lat_deg)
    # nose east, level: body x = E, y = N, z = U
    assert gyro[0] == pytest.approx(0.0, abs=1e-15)
    assert gyro[1] == pytest.approx(7.2921151467e-5 * math.cos(lat) + 200.0 / (6386e3 + 1000.0), rel=2e-3)
    w_n = 7.2921151467e-5 * math.cos(lat) + 200.0 / (6386.6e3 + 1000.0)
    assert accel[2] == pytest.approx(geodesy.gravity(lat, 1000.0) - 200.0 * (w_n + 7.2921151467e-5 * math.cos(lat)),
                                     rel=1e-6)
    assert accel[1] == pytest.approx(2 * 7.2921151467e-5 * math.sin(lat) * 200.0 + 200.0 ** 2 * math.tan(lat)
                                     / 6.387e6, rel=2e-3)


def test_start_state_is_truth_minus_the_drawn_error():
    sim = bs.simulate_run(SHORT, np.random.default_rng(3))
    x_true = bs.truth_states(SHORT, np.zeros(1))[0]
    x_true[10:13], x_true[13:16] = sim.gyro_bias, sim.accel_bias
    dx = minus(x_true, sim.x0)
    assert np.allclose(plus(sim.x0, dx), x_true, rtol=0, atol=1e-12)
    assert np.all(np.abs(dx) <= 6 * np.sqrt(np.diag(sim.P0)))


def _meas(x: np.ndarray) -> bs.GnssPositionVelocity:
    return bs.GnssPositionVelocity(0.0, x[7] + 1e-6, x[8] - 2e-6, x[9] + 3.0, x[4:7] + [0.1, -0.2, 0.3],
                                   np.eye(6))


def test_measurement_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    x = bs.truth_states(bs.Paper002Scenario(), np.array([123.4]))[0]
    x = plus(x, rng.normal(0.0, [1e-3] * 3 + [0.5] * 3 + [5.0] * 3 + [1e-5] * 3 + [1e-3] * 3))
    meas = _meas(x)
    H = meas.jacobian(x)
    eps = np.array([1e-6] * 3 + [1e-3] * 3 + [1e-2] * 3 + [1e-6] * 6)
    J = np.empty((6, 15))
    for i in range(15):
        e = np.zeros(15)
        e[i] = eps[i]
        J[:, i] = -(meas.innovation_at(plus(x, e)) - meas.innovation_at(plus(x, -e))) / (2 * eps[i])
    assert np.allclose(J, H, atol=1e-5)   # neglected terms ~ innovation / Earth radius
    # sigma points: h(x ⊞ dX) ⊟ h(x) is H dX to first order
    dX = rng.normal(0.0, eps * 10, (5, 15))
    assert np.allclose(meas.predict_points(x, dX), dX @ H.T, atol=1e-6)


def test_ekf_stays_at_the_truth_without_sensor_errors():
    sc = replace(SHORT, gyro_bias_deg_per_h=0.0, accel_bias_g=0.0, gyro_arw_deg_per_sqrt_h=0.0,
                 accel_vrw_ug_per_sqrt_hz=0.0, gps_pos_std_m=1e-3, gps_vel_std_mps=1e-4,
                 init_att_std_arcmin=(0.0, 0.0, 0.0), init_vel_std_mps=0.0, init_pos_std_m=0.0)
    sim = bs.simulate_run(sc, np.random.default_rng(1))
    # the filter starts exactly at the truth but believes the paper-reading P0
    sim = replace(sim, P0=np.diag(bs.Paper002Scenario().p0_std() ** 2))
    fr = bs.run_filter("ekf", sc, sim)
    assert not fr.diverged
    assert np.abs(fr.err[:, 0:3]).max() < 5e-3
    assert np.abs(fr.err[:, 3:6]).max() < 5e-4


def test_short_run_gives_finite_rows_and_series():
    res = bs.run_scenario(SHORT, 1, 5, ("ekf", "aekf"))
    assert res.name == "paper002-sins" and res.runs == 1 and res.seed == 5
    # per case: 6 RMS rows per filter, 6 learnt-R rows for the AEKF
    assert len(res.rows) == 2 * (6 + 6 + 6)
    assert all(math.isfinite(r.ours) and r.ours > 0 for r in res.rows)
    paper = {(r.quantity, r.filter): r.paper for r in res.rows}
    assert paper[("position RMS U", "ekf")] == pytest.approx(24.2267)
    assert paper[("velocity RMS E", "aekf")] == pytest.approx(0.2318)
    assert res.series["a/aekf/err_rms"].shape == (600, 6)
    assert np.all(np.isfinite(res.series["b/aekf/r_std"]))
    assert "position RMS U (a: filter R = true R)" in benchmarks.format_result(res)


def test_same_seed_repeats_exactly():
    a = bs.run_scenario(SHORT, 2, 11, ("ekf", "aekf"))
    b = bs.run_scenario(SHORT, 2, 11, ("ekf", "aekf"))
    c = bs.run_scenario(SHORT, 2, 12, ("ekf", "aekf"))
    assert a.rows == b.rows
    assert a.rows != c.rows


def test_filter_r_equal_to_true_r_beats_the_raw_gps_and_is_consistent():
    sc = bs.Paper002Scenario()
    norm = []
    for i in range(2):
        sim = bs.simulate_run(sc, np.random.default_rng(20 + i))
        for f in ("ekf", "aekf"):
            fr = bs.run_filter(f, sc, sim)
            rms = np.sqrt(np.mean(fr.err ** 2, axis=0))
            assert np.all(rms[0:3] < sc.gps_pos_std_m)
            assert np.all(rms[3:6] < sc.gps_vel_std_mps)
            if f == "ekf":
                norm.append(fr.err / fr.std)
    # the EKF's own sigma describes its errors (errors are time-correlated: loose bounds)
    ratio = np.sqrt(np.mean(np.concatenate(norm) ** 2, axis=0))
    assert np.all((ratio > 0.5) & (ratio < 1.6)), ratio


def test_aekf_learns_r_from_a_wrong_start():
    sc = replace(bs.Paper002Scenario(), duration_s=200.0, r_std_scale=0.25)
    sim = bs.simulate_run(sc, np.random.default_rng(7))
    fr = bs.run_filter("aekf", sc, sim)
    learnt = np.sqrt(np.diag(fr.r_final))
    assert np.allclose(learnt, sc.meas_std(), rtol=0.4)
    assert fr.r_std[0, 0] == pytest.approx(0.25 * 6.5)


def test_registered_with_the_papers_filters():
    bench = benchmarks.BENCHMARKS["paper002-sins"]
    assert bench.filters == ("ekf", "aekf")
    assert bench.default_runs == 20
    assert bench.run is bs.run


def test_bad_scenario_is_a_config_error():
    with pytest.raises(ConfigError, match="bias_draw"):
        bs.Paper002Scenario(bias_draw="sometimes")
    with pytest.raises(ConfigError, match="gps_period_s"):
        bs.Paper002Scenario(gps_period_s=0.0)


@pytest.mark.slow
def test_default_benchmark_runs():
    res = bs.run(20, 0, ("ekf", "aekf"))
    assert len(res.rows) == 36
    rows = {(r.quantity, r.filter, r.note): r.ours for r in res.rows}
    for case in bs.CASES:
        for f in ("ekf", "aekf"):
            for ax in bs.AXES:
                assert rows[(f"position RMS {ax}", f, case.label)] < 6.5
    learnt = [r.ours for r in res.rows if r.quantity.startswith("learnt R std, position")]
    assert np.allclose(learnt, 6.5, rtol=0.1)
