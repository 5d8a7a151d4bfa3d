"""Stale IMU rows and the IMU-GNSS clock offset: synthetic oracles, plus the shared real logs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navpp.geodesy import geodetic_to_enu
from navpp.ins.timing_estimates import (
    ClockOffset,
    estimate_clock_offset,
    find_stale_rows,
    velocity_from_positions,
)

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _real(name: str) -> Path:
    d = REAL / name
    if not (d / "imu.csv").is_file():
        pytest.skip(f"shared real data absent: {d}")
    return d


def _load(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1)


# ------------------------------------------------------------------------------------------
# synthetic streams
# ------------------------------------------------------------------------------------------

def _polled_stream(seed: int, duration: float = 60.0, sensor_hz: float = 100.0,
                   step: float | None = None, sigma: float = 1.0):
    """A sensor at ``sensor_hz`` read by a logger polling every 6..9 ms.

    Returns t (polls), gyro, accel (the latest sensor sample at each poll) and the true
    stale mask (polls that saw no new sample).  ``step`` quantises the values.
    """
    rng = np.random.default_rng(seed)
    t_s = np.arange(0.0, duration, 1.0 / sensor_hz) + 0.0003
    vals = sigma * rng.standard_normal((t_s.size, 6)) + np.array([0, 0, 0, 0, 0, 9.8])
    if step is not None:
        vals = np.round(vals / step) * step
    polls = np.cumsum(rng.integers(6, 10, size=int(duration / 0.006) + 10) * 1e-3)
    polls = polls[(polls > t_s[0]) & (polls < duration)]
    idx = np.searchsorted(t_s, polls, side="right") - 1
    stale = np.concatenate([[False], idx[1:] == idx[:-1]])
    return polls, vals[idx, :3], vals[idx, 3:], stale


def _quantised_quiet(seed: int, n: int = 20000, rate: float = 100.0, ratio=(0.3, 0.4, 0.5, 0.35, 0.45, 0.6)):
    """A coarse sensor at rest: each channel N(0, ratio * step) quantised to ``step``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    step = 0.01
    vals = np.round(np.asarray(ratio) * rng.standard_normal((n, 6))) * step + 0.0    # no -0.0
    return t, vals[:, :3], vals[:, 3:] + 9.81


def test_stale_rows_polled_stream_found_exactly() -> None:
    t, gyro, accel, truth = _polled_stream(seed=1)
    res = find_stale_rows(t, gyro, accel)
    assert truth.mean() > 0.2                                  # the oracle is a real polling case
    np.testing.assert_array_equal(res.mask, truth)
    assert res.count == int(truth.sum())
    assert res.fraction == pytest.approx(truth.mean())
    assert res.fresh_rate_hz == pytest.approx(100.0, rel=0.01)
    assert res.confident, res.reason
    assert res.reason.startswith("stale")


def test_stale_rows_quantised_quiet_sensor_not_flagged() -> None:
    t, gyro, accel = _quantised_quiet(seed=2)
    res = find_stale_rows(t, gyro, accel)
    assert res.n_repeats > 20                   # the chance repeats really happen
    assert res.count == 0 and not res.mask.any()
    assert res.expected_by_chance == pytest.approx(res.n_repeats, rel=0.5)
    assert res.confident, res.reason


def test_stale_rows_very_quiet_sensor_not_flagged() -> None:
    # most readings repeat per channel; all six repeat ~30 % of the time by chance alone
    t, gyro, accel = _quantised_quiet(seed=3, ratio=(0.3,) * 6)
    res = find_stale_rows(t, gyro, accel)
    assert res.n_repeats > 0.2 * t.size
    assert res.expected_by_chance == pytest.approx(res.n_repeats, rel=0.1)
    assert res.count == 0, res.reason
    assert res.confident, res.reason


def test_stale_rows_coarse_sensor_polled_is_flagged() -> None:
    # a coarse sensor (chance repeats) read by a polling logger: the polling signature decides
    t, gyro, accel, truth = _polled_stream(seed=4, step=0.5, sigma=0.5)
    res = find_stale_rows(t, gyro, accel)
    assert res.count >= truth.sum()
    assert res.mask[truth].all()
    assert res.dispersion < 0.3, res.reason


def test_stale_rows_no_repeats() -> None:
    rng = np.random.default_rng(5)
    t = np.arange(1000) * 0.01
    res = find_stale_rows(t, rng.standard_normal((1000, 3)), rng.standard_normal((1000, 3)))
    assert res.count == 0 and res.n_repeats == 0 and res.confident
    assert res.fresh_rate_hz == pytest.approx(100.0)


def test_stale_rows_real_walk() -> None:
    d = _load(_real("walk_0827") / "imu.csv")
    res = find_stale_rows(d[:, 0] - d[0, 0], d[:, 1:4], d[:, 4:7])
    assert res.count == 6958 and d.shape[0] == 20455             # the log's README
    assert res.fraction == pytest.approx(0.340, abs=0.001)
    assert res.fresh_rate_hz == pytest.approx(100.5, abs=0.1)
    assert res.confident, res.reason


def test_stale_rows_real_car_not_flagged() -> None:
    d = _load(_real("car_balzer82") / "imu.csv")
    res = find_stale_rows(d[:, 0] - d[0, 0], d[:, 1:4], d[:, 4:7])
    assert res.count == 0, res.reason
    assert res.fresh_rate_hz == pytest.approx(50.0, abs=0.1)


# ------------------------------------------------------------------------------------------
# clock offset
# ------------------------------------------------------------------------------------------

def _drive(offset: float, seed: int, duration: float = 200.0, straight: bool = False,
           speed: float = 10.0, gyro_bias: float = 0.01, pos_noise: float = 0.05):
    """A car at constant speed with smooth random turns; IMU stamps late by ``offset``.

    IMU 100 Hz (yaw rate + bias + 0.01 rad/s white noise), GNSS 10 Hz positions with
    ``pos_noise`` m white noise.  Returns t_imu, gz, t_gnss, east, north.
    """
    rng = np.random.default_rng(seed)
    fine = 1000.0
    tt = np.arange(0.0, duration + 4.0, 1.0 / fine) - 2.0
    rate = np.zeros_like(tt)
    if not straight:
        for _ in range(4):
            rate += 0.1 * np.sin(2 * np.pi * rng.uniform(0.02, 0.15) * tt + rng.uniform(0, 2 * np.pi))
    course = -np.cumsum(rate) / fine + rng.uniform(0, 2 * np.pi)       # clockwise from north
    east = np.cumsum(speed * np.sin(course)) / fine
    north = np.cumsum(speed * np.cos(course)) / fine
    t_imu = np.arange(0.0, duration, 0.01)
    gz = np.interp(t_imu - offset, tt, rate) + gyro_bias + 0.01 * rng.standard_normal(t_imu.size)
    t_g = np.arange(0.05, duration, 0.1)
    e = np.interp(t_g, tt, east) + pos_noise * rng.standard_normal(t_g.size)
    n = np.interp(t_g, tt, north) + pos_noise * rng.standard_normal(t_g.size)
    return t_imu, gz, t_g, e, n


def _estimate(offset: float, seed: int, **kw) -> ClockOffset:
    t_imu, gz, t_g, e, n = _drive(offset, seed, **kw)
    return estimate_clock_offset(t_imu, gz, t_g, velocity_from_positions(t_g, e, n))


def test_velocity_from_positions_exact_for_quadratic() -> None:
    t = np.arange(0.0, 5.0, 0.1)
    v = velocity_from_positions(t, 3.0 * t + 0.5 * t**2, -2.0 * t)
    np.testing.assert_allclose(v[1:-1, 0], 3.0 + t[1:-1], atol=1e-9)
    np.testing.assert_allclose(v[:, 1], -2.0, atol=1e-9)


@pytest.mark.parametrize("offset,seed", [(0.010, 11), (-0.3, 12), (0.25, 13)])
def test_clock_offset_synthetic(offset: float, seed: int) -> None:
    res = _estimate(offset, seed)
    assert res.confident, res.reason
    assert abs(res.offset_s - offset) < 3.0 * res.sigma_s, res.reason
    assert res.sigma_s < 0.02                      # and so an error beyond 60 ms fails
    assert res.bias_rad_s == pytest.approx(0.01, abs=0.005)


def test_clock_offset_velocity_input_and_sign() -> None:
    # noise-free ENU velocities: a sharp answer, and the sign of the documented convention
    t_imu, gz, t_g, e, n = _drive(0.12, 21, pos_noise=0.0)
    res = estimate_clock_offset(t_imu, gz, t_g, velocity_from_positions(t_g, e, n))
    assert res.offset_s == pytest.approx(0.12, abs=0.005), res.reason
    # GNSS stamps shifted later by 0.1 s = IMU comparatively 0.1 s earlier
    res2 = estimate_clock_offset(t_imu, gz, t_g + 0.1, velocity_from_positions(t_g, e, n))
    assert res2.offset_s == pytest.approx(0.02, abs=0.005), res2.reason


def test_clock_offset_straight_drive_not_confident() -> None:
    res = _estimate(0.1, 31, straight=True)
    assert not res.confident
    assert "turn" in res.reason


def test_clock_offset_too_slow_gives_nan() -> None:
    res = _estimate(0.1, 32, speed=1.0)
    assert not res.confident and np.isnan(res.offset_s) and res.n_samples == 0


@pytest.mark.slow
@pytest.mark.parametrize("offset", [0.010, -0.3])
def test_clock_offset_sigma_is_honest(offset: float) -> None:
    z = []
    for seed in range(100, 120):
        res = _estimate(offset, seed)
        z.append((res.offset_s - offset) / res.sigma_s)
    z = np.asarray(z)
    assert np.all(np.abs(z) < 3.5), z
    # not over-confident; in these simulations sigma is ~2x conservative (documented)
    assert 0.3 < np.sqrt(np.mean(z**2)) < 1.2, z


def test_clock_offset_real_car() -> None:
    d = _real("car_balzer82")
    imu, gnss = _load(d / "imu.csv"), _load(d / "gnss.csv")
    t0 = imu[0, 0]
    lat, lon = np.radians(gnss[:, 1]), np.radians(gnss[:, 2])
    enu = geodetic_to_enu(lat, lon, gnss[:, 3], lat[0], lon[0], gnss[0, 3])
    t_g = gnss[:, 0] - t0
    res = estimate_clock_offset(imu[:, 0] - t0, imu[:, 3], t_g,
                                velocity_from_positions(t_g, enu[:, 0], enu[:, 1]))
    # README: positions ~0.51 s late against the IMU (-0.42 s from 1-s courses), i.e. IMU early
    assert -0.7 < res.offset_s < -0.2, res.reason
    assert abs(res.offset_s + 0.51) < 3.0 * res.sigma_s, res.reason
    assert res.n_samples > 1000


# ------------------------------------------------------------------------------------------
# clock offset against the simulator's truth (navpp.simulate, realism "consumer-car")
# ------------------------------------------------------------------------------------------

def _sim_estimate(seed: int, duration: float = 300.0, **spec_kw) -> tuple[ClockOffset, float]:
    """As the engine's timing_fixes: stale rows dropped, gyro on the mean specific force,
    velocity from the positions.  Returns the estimate and the true offset."""
    from navpp.simulate import SimulationSpec, simulate

    spec = SimulationSpec(duration_s=duration, seed=seed, **spec_kw)
    sim = simulate(spec)
    t, gyro, accel = sim.imu.t, sim.imu.gyro, sim.imu.accel
    stale = find_stale_rows(t, gyro, accel)
    if stale.count:
        t, gyro, accel = t[~stale.mask], gyro[~stale.mask], accel[~stale.mask]
    up = accel.mean(axis=0) / np.linalg.norm(accel.mean(axis=0))
    g = sim.gnss
    lat, lon = np.radians(g.lat_deg), np.radians(g.lon_deg)
    enu = geodetic_to_enu(lat, lon, g.alt, lat[0], lon[0], g.alt[0])
    vel = velocity_from_positions(g.t, enu[:, 0], enu[:, 1])
    return estimate_clock_offset(t, gyro @ up, g.t, vel), float(spec.imu_time_offset_s or 0.0)


def test_velocity_from_positions_gap_and_uneven_stamps() -> None:
    # jittered stamps, a gap, a lone fix: exact for a quadratic track, nothing across a gap
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 10.0, 0.25) + rng.uniform(-0.05, 0.05, 40)
    t = np.concatenate([t, t[-1] + 15.0 + 0.25 * np.arange(6), [60.0]])
    east, north = 3.0 * t + 0.4 * t**2, -2.0 * t + 0.1 * t**2
    v = velocity_from_positions(t, east, north)
    np.testing.assert_allclose(v[:-1, 0], 3.0 + 0.8 * t[:-1], atol=1e-8)
    np.testing.assert_allclose(v[:-1, 1], -2.0 + 0.2 * t[:-1], atol=1e-8)
    assert np.all(np.isnan(v[-1]))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_clock_offset_consumer_car_not_confidently_wrong(seed: int) -> None:
    # seed 1 was "-0.167 s +- 0.006, confident" against a truth of +0.010: velocities
    # differenced across the GNSS gap (course 30-60 deg off at its edges) times the gyro's
    # vibration (7 deg/s per sample) made a false peak, and a Gauss-Newton sigma ~10x small
    res, truth = _sim_estimate(seed, realism="consumer-car")
    assert res.n_samples > 800, res.reason
    assert abs(res.offset_s - truth) < 3.0 * res.sigma_s, res.reason
    assert res.sigma_s < 0.3, res.reason
    if res.confident:
        assert abs(res.offset_s - truth) < 0.03, res.reason


@pytest.mark.parametrize("seed", [1, 2])
def test_clock_offset_consumer_car_without_vibration(seed: int) -> None:
    # the same drive (gap, stale rows, biases, scale factors, misalignment) minus the
    # vibration: a sharp, confident estimate of the +10 ms
    res, truth = _sim_estimate(seed, realism="consumer-car", vibration_gyro_dps=(0.0, 0.0))
    assert res.confident, res.reason
    assert res.consistent, res.reason
    assert abs(res.offset_s - truth) < max(3.0 * res.sigma_s, 0.005), res.reason
    assert res.sigma_s < 0.02, res.reason


def test_clock_offset_gap_glitch_dropped() -> None:
    # velocities differenced across the gap (what velocity_from_positions did): the two
    # glitches at its edges are dropped as outliers, not fitted
    from navpp.simulate import SimulationSpec, simulate

    sim = simulate(SimulationSpec(duration_s=300.0, seed=1, realism="consumer-car", vibration_gyro_dps=(0.0, 0.0)))
    g = sim.gnss
    lat, lon = np.radians(g.lat_deg), np.radians(g.lon_deg)
    enu = geodetic_to_enu(lat, lon, g.alt, lat[0], lon[0], g.alt[0])
    p = enu[:, :2]
    vel = np.empty_like(p)
    vel[1:-1] = (p[2:] - p[:-2]) / (g.t[2:] - g.t[:-2])[:, None]
    vel[0], vel[-1] = (p[1] - p[0]) / (g.t[1] - g.t[0]), (p[-1] - p[-2]) / (g.t[-1] - g.t[-2])
    up = sim.imu.accel.mean(axis=0) / np.linalg.norm(sim.imu.accel.mean(axis=0))
    res = estimate_clock_offset(sim.imu.t, sim.imu.gyro @ up, g.t, vel)
    assert res.n_outliers >= 1, res.reason
    assert abs(res.offset_s - 0.010) < max(3.0 * res.sigma_s, 0.005), res.reason


def test_clock_offset_halves_disagree_not_confident() -> None:
    # the IMU clock jumps by 0.3 s halfway (a logger restart): each half has its own lag,
    # the fit is some compromise: reported not consistent, not confident (the engine's
    # 2.5-sigma rule would otherwise apply it)
    t_imu, gz, t_g, e, n = _drive(0.0, 41, duration=300.0)
    _t1, gz1, _, _, _ = _drive(0.3, 41, duration=300.0)
    half = t_imu > 150.0
    gz = np.where(half, gz1, gz)
    res = estimate_clock_offset(t_imu, gz, t_g, velocity_from_positions(t_g, e, n))
    assert not res.consistent and not res.confident, res.reason
    assert "halves" in res.reason


@pytest.mark.slow
@pytest.mark.parametrize("kw", [dict(realism="consumer-car", vibration_gyro_dps=(0.0, 0.0)),
                                dict(gnss_std_h_m=0.05, gnss_std_u_m=0.05, imu_time_offset_s=0.05),
                                dict(realism="consumer-car")])
def test_clock_offset_simulated_sigma_is_honest(kw: dict) -> None:
    z, conf_err = [], []
    for seed in range(1, 13):
        res, truth = _sim_estimate(seed, **kw)
        z.append((res.offset_s - truth) / res.sigma_s)
        if res.confident:
            conf_err.append(abs(res.offset_s - truth) / res.sigma_s)
    z = np.asarray(z)
    assert np.all(np.abs(z) < 4.0), z
    assert 0.3 < np.sqrt(np.mean(z**2)) < 1.6, z          # neither >3x conservative nor optimistic
    assert all(x < 4.0 for x in conf_err), conf_err


# ---------------------------------------------------------------- the kernels against numpy


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_repeat_counts_are_numpys(seed):
    """_repeat_counts: the all-six repeats and each window's fresh and per-channel counts, as the
    numpy expressions (bitwise equality of each channel, np.add.reduceat per window) give them."""
    from navpp.ins.timing_estimates import _bits, _repeat_counts

    rng = np.random.default_rng(seed)
    n, w = 2345, 100
    gyro = np.round(rng.normal(size=(n, 3)), 1)
    accel = np.round(rng.normal(size=(n, 3)), 1)
    again = rng.random(n) < 0.3
    for k in np.nonzero(again)[0][1:]:
        gyro[k], accel[k] = gyro[k - 1], accel[k - 1]
    gyro[5, 0], gyro[4, 0] = 0.0, -0.0              # equal values, different bits: not a repeat
    bits = np.concatenate([_bits(gyro), _bits(accel)], axis=1)
    same = bits[1:] == bits[:-1]
    rep_ref = same.all(axis=1)
    starts = np.arange(0, n - 1, w)
    fresh_ref = np.add.reduceat((~rep_ref).astype(np.int64), starts)
    same_ref = np.add.reduceat((same & ~rep_ref[:, None]).astype(np.int64), starts, axis=0)
    rep = np.zeros(n - 1, dtype=bool)
    n_fresh, n_same = np.zeros(starts.shape[0], np.int64), np.zeros((starts.shape[0], 6), np.int64)
    _repeat_counts(_bits(gyro), _bits(accel), w, rep, n_fresh, n_same)
    np.testing.assert_array_equal(rep, rep_ref)
    np.testing.assert_array_equal(n_fresh, fresh_ref)
    np.testing.assert_array_equal(n_same, same_ref)


@pytest.mark.parametrize("order", ["increasing", "shuffled"])
def test_window_counts_are_searchsorted_bincount(order):
    """_window_counts: rows and fresh rows per window as np.searchsorted(edges, t, "right") - 1 and
    np.bincount count them, stamps on an edge and a NaN stamp included."""
    from navpp.ins.timing_estimates import _window_counts

    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 50.0, 3000))
    t[0] = 0.0
    edges = np.arange(t[0], t[-1], 1.0)
    t[10:13] = edges[3:6]                                   # on an edge: the window it opens
    t = np.sort(t)
    t = np.append(t, np.nan)
    if order == "shuffled":
        t = rng.permutation(t)
    repeats = rng.random(t.shape[0]) < 0.4
    idx = np.searchsorted(edges, t, side="right") - 1
    rows_ref = np.bincount(idx, minlength=edges.shape[0])
    fresh_ref = np.bincount(idx, weights=~repeats, minlength=edges.shape[0])
    rows, fresh = np.zeros(edges.shape[0], np.int64), np.zeros(edges.shape[0])
    _window_counts(edges, t, repeats, rows, fresh)
    np.testing.assert_array_equal(rows, rows_ref)
    np.testing.assert_array_equal(fresh, fresh_ref)


@pytest.mark.parametrize("grid", [False, True])
def test_cubic_means_are_the_numpy_expression(grid):
    """Cubic.means (one kernel) against the spline's values at the shifted span ends, differenced
    and divided as numpy does it: the same bits, spans running off the ends (NaN) included."""
    from navpp.ins import timing_estimates as te

    rng = np.random.default_rng(4)
    n = 3000
    x = te._Grid(12.5, 0.01, n) if grid else 12.5 + np.cumsum(rng.uniform(0.008, 0.012, n))
    y = np.cumsum(rng.standard_normal(n))
    spline = te._spline(x, y)
    xn = float(x[n - 1])
    a = np.sort(rng.uniform(12.0, xn - 0.5, 400))
    b = a + rng.uniform(0.2, 1.5, 400)
    lags = np.arange(-1.0, 1.0001, 0.05)
    ref = (spline(b + lags[:, None]) - spline(a + lags[:, None])) / (b - a)
    assert spline.means(a, b, lags).tobytes() == ref.tobytes()


def test_chord_courses_are_the_scalar_ones():
    """yaw_scale_from_track forms its chords' courses and lengths over arrays: numpy's arctan2 and
    hypot give each element the bits they give it alone (as the chord-by-chord loop formed them)."""
    rng = np.random.default_rng(9)
    de = rng.standard_normal(2001) * rng.choice([1e-3, 1.0, 1e3], 2001)
    dn = rng.standard_normal(2001) * rng.choice([1e-3, 1.0, 1e3], 2001)
    de[:3], dn[:3] = [0.0, -0.0, np.nan], [-0.0, 0.0, 1.0]
    courses, lengths = np.arctan2(dn, de), np.hypot(de, dn)
    for k in range(de.shape[0]):
        assert np.float64(courses[k]).tobytes() == np.float64(float(np.arctan2(dn[k], de[k]))).tobytes()
        assert np.float64(lengths[k]).tobytes() == np.float64(float(np.hypot(de[k], dn[k]))).tobytes()


def test_cubic_means_unshifted_are_the_value_difference():
    """Cubic.means at a zero shift is (f(b) - f(a)) / (b - a) to the bit, spans ending at -0.0 and
    +0.0 on a breakpoint at 0 included (as the gyro's moving average uses it)."""
    from navpp.ins import timing_estimates as te

    rng = np.random.default_rng(8)
    for x in (te._Grid(0.0, 0.01, 500), np.r_[0.0, np.cumsum(rng.uniform(0.005, 0.015, 499))]):
        y = np.cumsum(rng.standard_normal(500))
        y[0] = 0.0
        spline = te._spline(x, y)
        a = np.r_[-0.0, 0.0, -0.0, rng.uniform(0.0, 4.0, 300)]
        b = np.r_[0.5, 0.25, 1.0, a[3:] + rng.uniform(0.1, 0.6, 300)]
        ref = (spline(b) - spline(a)) / (b - a)
        assert spline.means(a, b, np.zeros(1))[0].tobytes() == ref.tobytes()
