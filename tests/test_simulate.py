"""Tests of navpp.simulate: each against an oracle independent of the code under test."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pandas as pd
import pytest

from navpp.errors import ConfigError
from navpp.geodesy import OMEGA_E, geodetic_to_ecef, geodetic_to_enu, gravity, mat_enu_from_ecef, radii
from navpp.ins.attitude import rph_to_dcm
from navpp.simulate import (
    IMU_GRADES,
    SimulationSpec,
    Trajectory,
    body_rate_from_rph,
    draw_imu_errors,
    gauss_markov,
    simulate,
    write_csv_log,
)


@pytest.fixture(scope="module")
def trajectory() -> Trajectory:
    return Trajectory.from_spec(SimulationSpec(duration_s=500.0, preset="ideal"))


@pytest.fixture(scope="module")
def moving_times() -> np.ndarray:
    # random times in the first drive cycle and a half (still period is 0-60 s), plus
    # times inside the turn + dip overlap and at a U-turn
    rng = np.random.default_rng(1)
    t = np.concatenate([rng.uniform(61.0, 499.0, 2000), 60.0 + np.array([20.0, 50.0, 120.0, 150.0, 152.5, 165.0])])
    return np.sort(t)


def _skew_vector(w: np.ndarray) -> np.ndarray:
    return np.stack([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]], axis=-1)


def _mat(state: dict) -> np.ndarray:
    rph = state["rph"]
    return rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])


# (1) body rate --------------------------------------------------------------------------


def test_body_rate_equals_finite_difference_of_dcm(trajectory, moving_times):
    h = 1e-4
    t = moving_times
    s, sp, sm = trajectory.state(t), trajectory.state(t + h), trajectory.state(t - h)
    c = _mat(s)
    c_dot = (_mat(sp) - _mat(sm)) / (2.0 * h)
    w_mat = np.einsum("nji,njk->nik", c, c_dot)  # C^T C_dot
    assert np.abs(w_mat + w_mat.transpose(0, 2, 1)).max() < 1e-8  # skew-symmetric
    w_fd = _skew_vector(w_mat)
    w = body_rate_from_rph(s["rph"], s["rph_dot"])
    assert np.abs(w - w_fd).max() < 1e-8
    # the drive actually rotates the body about all three axes
    assert np.all(np.abs(w).max(axis=0) > [1e-3, 1e-2, 0.2])


def test_body_rate_signs():
    # level right turn: yaw rate about body z (up) is negative; nose-up pitching is negative
    # about body y (left); roll to the right is positive about body x (forward)
    w = body_rate_from_rph(np.zeros((3, 3)), np.diag([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(w, [[0.1, 0, 0], [0, -0.2, 0], [0, 0, -0.3]], atol=1e-15)


# (2) velocity, acceleration, position -----------------------------------------------------


def test_accel_and_rates_are_derivatives(trajectory, moving_times):
    h = 1e-4
    t = moving_times
    s, sp, sm = trajectory.state(t), trajectory.state(t + h), trajectory.state(t - h)
    acc_fd = (sp["vel_enu"] - sm["vel_enu"]) / (2.0 * h)
    assert np.abs(acc_fd - s["accel_enu"]).max() < 1e-7
    rph_fd = (sp["rph"] - sm["rph"]) / (2.0 * h)
    assert np.abs(rph_fd - s["rph_dot"]).max() < 1e-8


def test_position_derivative_matches_velocity(trajectory, moving_times):
    h = 1e-2  # five-point stencil: truncation ~1e-10, round-off of lat/lon ~1e-7 m/s
    t = moving_times
    st = [trajectory.state(t + k * h) for k in (-2, -1, 1, 2)]

    def d(key):
        return (st[0][key] - 8.0 * st[1][key] + 8.0 * st[2][key] - st[3][key]) / (12.0 * h)

    s = trajectory.state(t)
    rm, rn = radii(s["lat"])
    v = s["vel_enu"]
    assert np.abs(d("lat") * (rm + s["h"]) - v[:, 1]).max() < 5e-7
    assert np.abs(d("lon") * (rn + s["h"]) * np.cos(s["lat"]) - v[:, 0]).max() < 5e-7
    assert np.abs(d("h") - v[:, 2]).max() < 1e-7


def test_drive_shape(trajectory):
    t = np.arange(0.0, 500.0, 0.05)
    s = trajectory.state(t)
    speed = np.linalg.norm(s["vel_enu"], axis=1)
    assert speed.min() >= 0.0 and 15.0 < speed.max() <= 25.0
    assert np.all(speed[t < 60.0] == 0.0)
    climb = s["h"].max() - 300.0
    assert 10.0 <= climb <= 30.0
    # hills come back: the height at the end of each cycle equals the start height
    np.testing.assert_allclose(trajectory.position(np.array([260.0, 460.0]))[:, 2], 300.0, atol=1e-6)
    # lean outward: in a right turn (heading rate > 0) roll < 0 (left side down)
    right = s["rph_dot"][:, 2] > 0.1
    assert np.all(s["rph"][right, 0] < 0.0)
    assert np.degrees(np.abs(s["rph"][:, 0]).max()) < 3.0


# (3) ideal IMU at rest ---------------------------------------------------------------------


def test_ideal_imu_at_rest_is_closed_form(trajectory):
    t = np.concatenate([np.linspace(0.0, 59.9, 300), 60.0 + np.linspace(190.5, 199.5, 50)])
    s = trajectory.state(t)
    assert np.all(s["vel_enu"] == 0.0)
    gyro, accel = trajectory.ideal_imu(t)
    c = _mat(s)
    lat, h = s["lat"], s["h"]
    w_ie = np.stack([np.zeros_like(lat), OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)], axis=-1)
    g_up = np.stack([np.zeros_like(lat), np.zeros_like(lat), gravity(lat, h)], axis=-1)
    np.testing.assert_allclose(gyro, np.einsum("nji,nj->ni", c, w_ie), rtol=0, atol=1e-12 * OMEGA_E)
    np.testing.assert_allclose(accel, np.einsum("nji,nj->ni", c, g_up), rtol=0, atol=1e-12 * 9.81)
    # heading 30 deg, level: forward (x) sees cos 30 and left (y) sin 30 of the north Earth rate
    w_north = OMEGA_E * math.cos(math.radians(45.0))
    np.testing.assert_allclose(gyro[0, :2], [w_north * math.cos(math.radians(30.0)),
                                             w_north * math.sin(math.radians(30.0))], rtol=1e-12)


def test_ideal_imu_on_the_move_matches_mechanisation_identity(trajectory, moving_times):
    """Feed the ideal IMU back through the ENU velocity equation: v_dot = C f - (2w_ie+w_en) x v + g."""
    t = moving_times
    s = trajectory.state(t)
    _gyro, accel = trajectory.ideal_imu(t)
    c = _mat(s)
    lat, h, v = s["lat"], s["h"], s["vel_enu"]
    rm, rn = radii(lat)
    w_ie = np.stack([np.zeros_like(lat), OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)], axis=-1)
    w_en = np.stack([-v[:, 1] / (rm + h), v[:, 0] / (rn + h), v[:, 0] * np.tan(lat) / (rn + h)], axis=-1)
    g_n = np.stack([np.zeros_like(lat), np.zeros_like(lat), -gravity(lat, h)], axis=-1)
    v_dot = np.einsum("nij,nj->ni", c, accel) - np.cross(2 * w_ie + w_en, v) + g_n
    np.testing.assert_allclose(v_dot, s["accel_enu"], rtol=0, atol=1e-12)


# (4) sensor errors -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def noisy() -> object:
    return simulate(SimulationSpec(duration_s=600.0, preset="automotive", seed=7))


def test_imu_white_noise_and_bias_statistics(noisy):
    e = noisy.sensor_errors
    n = len(noisy.imu)
    for kind in ("gyro", "accel"):
        meas = getattr(noisy.imu, kind)
        true = getattr(noisy.truth_imu, kind)
        white = meas - (1.0 + e[f"{kind}_scale_factor"]) * true - e[f"{kind}_bias"] - e[f"{kind}_gauss_markov"]
        sigma = e[f"{kind}_white_sigma"]
        np.testing.assert_allclose(white.std(axis=0), sigma, rtol=0.03)
        # the recorded turn-on bias is what the data carry: mean residual within 5 sigma
        resid = meas - (1.0 + e[f"{kind}_scale_factor"]) * true - e[f"{kind}_gauss_markov"]
        assert np.all(np.abs(resid.mean(axis=0) - e[f"{kind}_bias"]) < 5.0 * sigma / math.sqrt(n))
        assert np.all(e[f"{kind}_bias"] != 0.0)
    g = IMU_GRADES["automotive"]
    dt = 1.0 / 125.0
    assert e["gyro_white_sigma"] == pytest.approx(g.gyro_arw_deg_per_sqrt_h * math.pi / 180 / 60 / math.sqrt(dt))
    assert e["accel_white_sigma"] == pytest.approx(g.accel_vrw_mps_per_sqrt_h / 60 / math.sqrt(dt))


def test_imu_error_draw_distributions():
    grade = IMU_GRADES["consumer"]
    draws = [draw_imu_errors(np.random.default_rng(seed), 2, 0.01, grade) for seed in range(400)]
    gb = np.concatenate([d["gyro_bias"] for d in draws])
    ab = np.concatenate([d["accel_bias"] for d in draws])
    sf = np.concatenate([d["gyro_scale_factor"] for d in draws])
    assert gb.std() == pytest.approx(grade.gyro_bias_deg_per_h * math.pi / 180 / 3600, rel=0.1)
    assert ab.std() == pytest.approx(grade.accel_bias_mg * 9.80665e-3, rel=0.1)
    assert sf.std() == pytest.approx(grade.scale_factor_ppm * 1e-6, rel=0.1)


def test_gauss_markov_is_stationary_with_the_right_correlation():
    rng = np.random.default_rng(3)
    sigma, tau, dt = 2.0, 20.0, 0.5
    x = gauss_markov(rng, 100, dt, sigma, tau, axes=4000)  # 4000 independent realisations
    assert x[0].std() == pytest.approx(sigma, rel=0.05)
    assert x[-1].std() == pytest.approx(sigma, rel=0.05)
    rho = np.mean(x[1:] * x[:-1]) / np.mean(x[:-1] ** 2)
    assert rho == pytest.approx(math.exp(-dt / tau), abs=0.01)
    lag10 = np.mean(x[10:] * x[:-10]) / np.mean(x[:-10] ** 2)
    assert lag10 == pytest.approx(math.exp(-10 * dt / tau), abs=0.02)


def test_seed_reproducibility():
    spec = SimulationSpec(duration_s=40.0, imu_rate_hz=50.0, seed=5)
    a, b = simulate(spec), simulate(spec)
    c = simulate(SimulationSpec(duration_s=40.0, imu_rate_hz=50.0, seed=6))
    for x, y in ((a.imu.gyro, b.imu.gyro), (a.imu.accel, b.imu.accel), (a.gnss.lat_deg, b.gnss.lat_deg)):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.imu.gyro, c.imu.gyro)
    assert not np.array_equal(a.gnss.lat_deg, c.gnss.lat_deg)
    np.testing.assert_array_equal(a.truth_imu.gyro, c.truth_imu.gyro)


@pytest.mark.parametrize("spec", [SimulationSpec(duration_s=40.0, imu_rate_hz=50.0, preset="ideal"),
                                  SimulationSpec(duration_s=40.0, imu_rate_hz=50.0, errors=False)])
def test_ideal_imu_is_exact(spec):
    sim = simulate(spec)
    np.testing.assert_array_equal(sim.imu.gyro, sim.truth_imu.gyro)
    np.testing.assert_array_equal(sim.imu.accel, sim.truth_imu.accel)


def test_short_run_shortens_the_still_period():
    sim = simulate(SimulationSpec(duration_s=40.0, imu_rate_hz=20.0, preset="ideal"))
    speed = np.linalg.norm(sim.reference.vel_enu, axis=1)
    assert np.all(speed[sim.reference.t < 20.0] == 0.0) and speed.max() > 1.0
    assert sim.imu.t[0] == 0.0 and sim.imu.t[-1] == pytest.approx(40.0)


def test_invalid_specs_are_config_errors():
    for kw in (dict(duration_s=10.0), dict(gnss_rate_hz=20.0), dict(preset="cheap"),
               dict(gnss_error="pink"), dict(lever_arm_m=(1.0, 2.0))):
        with pytest.raises(ConfigError):
            SimulationSpec(**kw)


@pytest.mark.parametrize("kw, message", [
    (dict(seed=-1), "simulate: seed must be a non-negative integer, got -1"),
    (dict(seed=1.5), "simulate: seed must be a non-negative integer, got 1.5"),
    (dict(duration_s=math.inf), "simulate: duration_s must be a finite number, got inf"),
    (dict(imu_rate_hz=math.inf), "simulate: imu_rate_hz must be a finite number, got inf"),
    (dict(still_s=math.nan), "simulate: still_s must be a finite number, got nan"),
    (dict(gnss_std_h_m=math.inf), "simulate: gnss_std_h_m must be a finite number, got inf"),
    (dict(lever_arm_m=(0.0, math.nan, 0.0)), "simulate: lever_arm_m must be finite, got (0.0, nan, 0.0)"),
])
def test_invalid_specs_name_the_field(kw, message) -> None:
    with pytest.raises(ConfigError) as exc:
        SimulationSpec(**kw)
    assert str(exc.value) == message


def test_still_effective_is_at_most_half_the_duration() -> None:
    assert SimulationSpec(duration_s=50.0, still_s=100.0).still_effective_s == 25.0
    assert SimulationSpec(duration_s=50.0, still_s=20.0).still_effective_s == 20.0


# (5) GNSS ----------------------------------------------------------------------------------


def _gnss_error_enu(sim) -> np.ndarray:
    """GNSS minus reference (zero lever arm) in local ENU metres, exact through ECEF."""
    ref = sim.reference
    k = np.searchsorted(ref.t, sim.gnss.t)
    np.testing.assert_allclose(ref.t[k], sim.gnss.t, atol=1e-9)
    g = sim.gnss
    return geodetic_to_enu(np.radians(g.lat_deg), np.radians(g.lon_deg), g.alt,
                           np.radians(ref.lat_deg[k]), np.radians(ref.lon_deg[k]), ref.alt[k])


def test_gnss_white_noise_statistics():
    sim = simulate(SimulationSpec(duration_s=3600.0, imu_rate_hz=10.0, preset="ideal", seed=2))
    np.testing.assert_allclose(sim.gnss.t * 5.0, np.round(sim.gnss.t * 5.0), atol=1e-9)  # whole multiples
    err = _gnss_error_enu(sim)
    np.testing.assert_allclose(err.std(axis=0), [1.8, 1.8, 2.5], rtol=0.1)
    assert np.all(np.abs(err.mean(axis=0)) < 0.1)
    np.testing.assert_allclose(sim.gnss.std_enu, np.tile([1.8, 1.8, 2.5], (len(sim.gnss), 1)))
    # the recorded error, applied to first order through the radii (second order ~ e^2/R)
    np.testing.assert_allclose(err, sim.sensor_errors["gnss_error_enu"], atol=1e-4)


def test_gnss_correlated_noise_statistics():
    sim = simulate(SimulationSpec(duration_s=3600.0, imu_rate_hz=10.0, preset="ideal", seed=4,
                                  gnss_error="correlated", gnss_corr_time_s=5.0))
    err = _gnss_error_enu(sim)
    stated = np.array([1.8, 1.8, 2.5]) * math.sqrt(1.25)
    np.testing.assert_allclose(sim.gnss.std_enu[0], stated)
    np.testing.assert_allclose(err.std(axis=0), stated, rtol=0.1)
    # lag-1 correlation of the total error: (sigma^2 exp(-dt/tau)) / (1.25 sigma^2)
    rho = np.mean(err[1:] * err[:-1], axis=0) / np.mean(err**2, axis=0)
    np.testing.assert_allclose(rho, math.exp(-0.2 / 5.0) / 1.25, atol=0.05)


def test_gnss_lever_arm_position_and_velocity():
    lever = (1.5, -0.7, 1.1)
    spec = SimulationSpec(duration_s=300.0, imu_rate_hz=10.0, preset="ideal", lever_arm_m=lever,
                          gnss_std_h_m=0.0, gnss_std_u_m=0.0, gnss_velocity=True, gnss_std_vel_mps=0.0)
    sim = simulate(spec)
    traj = sim.trajectory
    g = sim.gnss
    s = traj.state(g.t)
    c = _mat(s)
    # antenna offset from the body origin, exact through ECEF, equals C * lever arm
    d = geodetic_to_enu(np.radians(g.lat_deg), np.radians(g.lon_deg), g.alt, s["lat"], s["lon"], s["h"])
    np.testing.assert_allclose(d, c @ np.array(lever), atol=2e-6)  # radii: first order in |l|/R
    # antenna velocity equals the time derivative of the antenna's ECEF position, in ENU
    t = g.t[(g.t > 1.0) & (g.t < 299.0)]
    h = 1e-3

    def antenna_ecef(tt):
        st = traj.state(tt)
        off = _mat(st) @ np.array(lever)
        r = geodetic_to_ecef(st["lat"], st["lon"], st["h"])
        return r + np.einsum("nji,nj->ni", mat_enu_from_ecef(st["lat"], st["lon"]), off)

    v_ecef = (antenna_ecef(t + h) - antenna_ecef(t - h)) / (2.0 * h)
    s = traj.state(t)
    v_fd = np.einsum("nij,nj->ni", mat_enu_from_ecef(s["lat"], s["lon"]), v_ecef)
    k = np.searchsorted(g.t, t)
    np.testing.assert_allclose(g.vel_enu[k], v_fd, atol=1e-5)
    assert np.abs(g.vel_enu[k] - s["vel_enu"]).max() > 0.1  # the lever-arm term is exercised


def test_reference_is_the_truth():
    sim = simulate(SimulationSpec(duration_s=400.0, imu_rate_hz=10.0, preset="ideal", heading0_deg=350.0))
    ref = sim.reference
    s = sim.trajectory.state(ref.t)
    np.testing.assert_allclose(ref.lat_deg, np.degrees(s["lat"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(ref.vel_enu, s["vel_enu"], atol=1e-12)
    h = ref.rph_deg[:, 2]
    assert h.min() >= 0.0 and h.max() < 360.0 and h.max() - h.min() > 300.0  # wraps through north
    np.testing.assert_allclose(np.radians(h), np.mod(s["rph"][:, 2], 2 * np.pi), atol=1e-12)
    np.testing.assert_allclose(ref.t * 10.0, np.round(ref.t * 10.0), atol=1e-9)


# (6) CSV round trip -------------------------------------------------------------------------


def test_write_csv_log_round_trip(tmp_path):
    spec = SimulationSpec(duration_s=60.0, imu_rate_hz=50.0, still_s=20.0, gnss_velocity=True,
                          lever_arm_m=(0.5, 0.0, 1.0), preset="tactical", t0_unix=1_700_000_000.25)
    sim = simulate(spec)
    write_csv_log(sim, tmp_path / "log")
    out = tmp_path / "log"
    assert sorted(p.name for p in out.iterdir()) == ["gnss.csv", "imu.csv", "navpp.toml", "reference.csv"]

    imu = pd.read_csv(out / "imu.csv", dtype={"t": str})
    assert list(imu.columns) == ["t", "gx", "gy", "gz", "ax", "ay", "az"]
    us = imu["t"].str.replace(".", "", regex=False).astype(np.int64).to_numpy()
    np.testing.assert_array_equal(us - 1_700_000_000_250_000, np.round(sim.imu.t * 1e6).astype(np.int64))
    assert all(len(x.split(".")[1]) == 6 for x in imu["t"].head())
    np.testing.assert_array_equal(imu[["gx", "gy", "gz"]].to_numpy(), sim.imu.gyro)
    np.testing.assert_array_equal(imu[["ax", "ay", "az"]].to_numpy(), sim.imu.accel)

    gnss = pd.read_csv(out / "gnss.csv")
    assert list(gnss.columns) == ["t", "lat", "lon", "alt", "std_e", "std_n", "std_u",
                                  "ve", "vn", "vu", "std_ve", "std_vn", "std_vu"]
    np.testing.assert_allclose(gnss["t"] - spec.t0_unix, sim.gnss.t, atol=1e-6)
    np.testing.assert_allclose(gnss["lat"], sim.gnss.lat_deg, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gnss["lon"], sim.gnss.lon_deg, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gnss["alt"], sim.gnss.alt, rtol=0, atol=1e-9)
    np.testing.assert_allclose(gnss[["std_e", "std_n", "std_u"]], sim.gnss.std_enu)
    np.testing.assert_allclose(gnss[["ve", "vn", "vu"]], sim.gnss.vel_enu, atol=1e-9)

    ref = pd.read_csv(out / "reference.csv")
    assert list(ref.columns) == ["t", "lat", "lon", "alt", "ve", "vn", "vu", "roll", "pitch", "heading"]
    np.testing.assert_allclose(ref["t"] - spec.t0_unix, sim.reference.t, atol=1e-6)
    np.testing.assert_allclose(ref[["roll", "pitch", "heading"]], sim.reference.rph_deg, atol=1e-9)
    np.testing.assert_allclose(ref[["ve", "vn", "vu"]], sim.reference.vel_enu, atol=1e-9)

    cfg = tomllib.loads((out / "navpp.toml").read_text())
    assert cfg == {"imu": {"preset": "tactical"}, "gnss": {"lever_arm_m": [0.5, 0.0, 1.0]}}
    assert (out / "navpp.toml").read_text().startswith("#")
    assert sim.t0_ns == 1_700_000_000_250_000_000
    rec = sim.recording()
    assert rec.t0_ns == sim.t0_ns and rec.reference is sim.reference


def test_write_csv_log_ideal_omits_imu_preset(tmp_path):
    sim = simulate(SimulationSpec(duration_s=30.0, imu_rate_hz=20.0, preset="ideal"))
    write_csv_log(sim, tmp_path)
    cfg = tomllib.loads((tmp_path / "navpp.toml").read_text())
    assert "imu" not in cfg and cfg["gnss"]["lever_arm_m"] == [0.0, 0.0, 0.0]
    gnss = pd.read_csv(tmp_path / "gnss.csv")
    assert list(gnss.columns) == ["t", "lat", "lon", "alt", "std_e", "std_n", "std_u"]


def test_csv_blocks_join_seamlessly():
    from navpp.simulate import _table

    t = np.arange(10) * 0.125
    cols = [(np.linspace(-1.0, 1.0, 10), "%.17g"), (-np.zeros(10), "%.3f")]
    one = "".join(_table(100.5, t, ["t", "a", "b"], cols))
    many = "".join(_table(100.5, t, ["t", "a", "b"], cols, rows_per_block=3))
    assert one == many
    lines = one.splitlines()
    assert lines[0] == "t,a,b" and len(lines) == 11
    assert lines[2] == "100.625000,-0.77777777777777779,0.000"  # no "-0.000"
