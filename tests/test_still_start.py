"""A long still start: the still period found whole, the start position the mean of its fixes
with an honest 1-sigma, no jump when the filter starts (against the simulator's truth)."""

import math

import numpy as np
import pytest

from navpp import api, engine, geodesy
from navpp.config import config_from_dict
from navpp.ins.alignment import AlignmentSettings, align, bridged, effective_count
from navpp.ins.calibrate import spans
from navpp.ins.state import POS
from navpp.metrics import interpolate_solution, position_errors_enu
from navpp.simulate import SimulationSpec, simulate


def test_bridged_fills_short_breaks_only():
    t = np.arange(0.0, 20.0, 0.5)
    mask = np.ones(t.size, bool)
    mask[4:6] = False          # 1.0 s of False: 1.5 s from the last True before to the first after
    mask[20:32] = False        # 6.0 s: 6.5 s across
    out = bridged(t, mask, 5.0)
    assert out[:20].all()                      # the short break is filled
    assert not out[20:32].any() and out[32:].all()
    # a leading or trailing False run is no break between two rests
    m2 = np.r_[np.zeros(3, bool), np.ones(5, bool), np.zeros(3, bool)]
    assert np.array_equal(bridged(np.arange(11.0), m2, 5.0), m2)


def test_a_long_rest_is_one_still_period_for_the_alignment():
    # 200 s at rest: calibration's mask breaks it where a +-1 s GNSS speed fit passes 3 sigma by
    # chance; the alignment still takes the whole rest (the truth: 0 .. 200 s)
    from navpp.ins.calibrate import calibrate

    sim = simulate(SimulationSpec(duration_s=400.0, still_s=200.0, seed=1))
    imu = sim.imu
    st = _settings()
    cal = calibrate(imu.t, imu.gyro, imu.accel, sim.gnss, gyro_arw=st.gyro_arw, accel_vrw=st.accel_vrw,
                    gyro_bias_sigma=st.gyro_bias_sigma, accel_bias_sigma=st.accel_bias_sigma)
    al = align(imu.t, imu.gyro, imu.accel, sim.gnss, AlignmentSettings(**{**st.__dict__, "still_mask": cal.still}))
    t0 = float(imu.t[0])
    assert al.still is not None and al.still[0] == t0 and al.still[1] - t0 > 190.0
    # the detector itself keeps the rest whole (a 2-D speed tested at 3 sigma broke it into 4
    # pieces here) and marks no moving sample still (against the truth's velocity)
    ref = sim.reference
    speed = np.hypot(np.interp(imu.t, ref.t, ref.vel_enu[:, 0]), np.interp(imu.t, ref.t, ref.vel_enu[:, 1]))
    moving = (speed > 1e-3) | (np.abs(np.interp(imu.t, ref.t, ref.vel_enu[:, 2])) > 1e-3)
    rest_end = float(imu.t[np.argmax(moving)])
    pieces = [(a, b) for a, b in spans(imu.t, cal.still, 0.0) if imu.t[a] < rest_end]
    assert len(pieces) == 1 and imu.t[pieces[0][1] - 1] > rest_end - 2.0
    assert not np.any(cal.still & moving)


def test_the_start_and_the_filter_share_the_still_fixes_information():
    # white fixes: the start holds START_SHARE of the mean's information and each still fix is
    # taken with its variance times N / (N_eff (1 - share)); a scalar Kalman filter run over them
    # (no process noise) ends at the mean with the mean's variance sigma^2 / N_eff (closed form),
    # not half of it, and never leaves the mean by more than the fixes' share moves it
    from navpp.engine.prepare import start_covariance, start_fixes
    from navpp.engine.schedule import GnssFixes
    from navpp.ins.alignment import START_SHARE

    sim = simulate(SimulationSpec(duration_s=60.0, still_s=30.0, seed=5, gnss_std_h_m=1.8, gnss_std_u_m=2.5))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings())
    g = sim.gnss
    m = len(g)
    fixes = GnssFixes(np.arange(m), g.t, np.radians(g.lat_deg), np.radians(g.lon_deg), g.alt,
                      np.tile(np.square(g.std_enu[0]), (m, 1)))
    shared = start_fixes(fixes, al)
    inside = (g.t >= al.start_fixes[0]) & (g.t <= al.start_fixes[1])
    assert np.count_nonzero(inside) == al.start_count > 100
    np.testing.assert_allclose(shared.r_scale[~inside], 1.0)
    scale = al.start_count / (al.start_n_eff * (1 - START_SHARE))
    np.testing.assert_allclose(shared.r_scale[inside], np.broadcast_to(scale, (int(inside.sum()), 3)))
    P0 = start_covariance(al)[POS, POS]
    np.testing.assert_allclose(np.diag(P0), np.diag(al.P[POS, POS]) / START_SHARE)
    # the east axis as a scalar: start at the mean, the still fixes one by one
    lat0, lon0 = math.radians(g.lat_deg[inside].mean()), math.radians(g.lon_deg[inside].mean())
    east = geodesy.geodetic_to_enu(np.radians(g.lat_deg[inside]), np.radians(g.lon_deg[inside]), g.alt[inside],
                                   lat0, lon0, float(g.alt[inside].mean()))[:, 0]
    x, p = 0.0, float(P0[0, 0])
    r = shared.var[inside, 0] * shared.r_scale[inside, 0]
    path = []
    for z, rk in zip(east, r):
        k = p / (p + rk)
        x, p = x + k * (z - x), (1 - k) * p
        path.append(x)
    var_mean = float(al.P[POS, POS][0, 0])
    assert p == pytest.approx(1.0 / (START_SHARE / var_mean + float(np.sum(1.0 / r))), rel=1e-9)   # information adds
    # ... to the mean's (within the fixes' scatter against their logged sigma), not twice it
    assert p == pytest.approx(var_mean, rel=0.25)
    assert abs(x) < 1e-9 + 3.0 * math.sqrt(var_mean)                 # back near the mean
    assert np.max(np.abs(path)) < 3.0 * math.sqrt(var_mean)          # no jump towards the first fixes


def test_effective_count_against_closed_form():
    rng = np.random.default_rng(3)
    n = 4000
    assert effective_count(rng.standard_normal(n)) == pytest.approx(n, rel=0.2)
    # AR(1) with coefficient phi: N (1 - phi) / (1 + phi) independent samples
    phi = 0.9
    x = np.zeros(n)
    e = rng.standard_normal(n)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    assert effective_count(x) == pytest.approx(n * (1 - phi) / (1 + phi), rel=0.35)
    assert effective_count(np.ones(10)) == 10.0 and effective_count(np.arange(2.0)) == 2.0


def _settings():
    return AlignmentSettings(gyro_bias_sigma=math.radians(10) / 3600, gyro_arw=math.radians(1) / 60,
                             accel_bias_sigma=2e-3 * 9.80665, accel_vrw=0.05 / 60)


def _start_error(sim, al):
    """(3,) start position error ENU m of the alignment against the truth, and its 1-sigma (3,) m."""
    ref = sim.reference
    e = geodesy.geodetic_to_enu(al.x[7], al.x[8], al.x[9], math.radians(ref.lat_deg[0]),
                                math.radians(ref.lon_deg[0]), ref.alt[0])
    return np.asarray(e, dtype=float).ravel(), np.sqrt(np.diag(al.P[POS, POS]))


def test_still_start_position_sigma_is_the_mean_of_the_fixes_and_honest():
    # 60 s at rest with white 1.8 / 2.5 m fixes at 5 Hz: the start is the mean of about 300 fixes;
    # its 1-sigma is one fix's over sqrt(N) (not one fix's), and the errors agree with it
    z = []
    for seed in range(6):
        sim = simulate(SimulationSpec(duration_s=100.0, still_s=60.0, seed=seed, gnss_std_h_m=1.8, gnss_std_u_m=2.5))
        al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings())
        e, s = _start_error(sim, al)
        n = int(np.count_nonzero((sim.gnss.t >= al.still[0]) & (sim.gnss.t <= al.still[1])))
        assert n > 250
        # the effective count from ~300 white fixes is at most a little low (Geyer's sequence cut)
        ratio = s / (np.array([1.8, 1.8, 2.5]) / math.sqrt(n))
        assert np.all((ratio > 0.95) & (ratio < 1.6)), ratio
        z.append(e / s)
    # 18 normalised errors: their RMS within the 99.9 % band of sqrt(chi2_18 / 18)
    assert 0.45 <= float(np.sqrt(np.mean(np.square(z)))) <= 1.6


def test_correlated_fixes_are_not_averaged_as_independent():
    # Gauss-Markov fix errors (tau 20 s) over a 60 s rest: far fewer independent fixes than fixes
    sim = simulate(SimulationSpec(duration_s=100.0, still_s=60.0, seed=2, gnss_error="correlated",
                                  gnss_corr_time_s=20.0))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings())
    e, s = _start_error(sim, al)
    n = int(np.count_nonzero((sim.gnss.t >= al.still[0]) & (sim.gnss.t <= al.still[1])))
    # white averaging would claim 1.8 / sqrt(n) ~ 0.1 m; 2 tau per independent fix gives ~0.7 m
    assert np.all(s[:2] > 3.0 * 1.8 / math.sqrt(n))
    assert np.all(np.abs(e) < 4.0 * s)


def test_filter_output_does_not_jump_at_a_still_start():
    # the filter starts at the still period's start from the mean of its fixes: the output
    # barely moves in the first second and stays in the start's 1-sigma band (the old start, one
    # fix's 1-sigma, pulled it about a metre towards the first fixes)
    sim = simulate(SimulationSpec(duration_s=60.0, still_s=30.0, seed=7, gnss_std_h_m=1.8, gnss_std_u_m=2.5))
    rec = sim.recording()
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    res = engine.run(rec, cfg, api.make_filter("ekf", cfg))
    sol = res.solution
    assert sol.t[0] == pytest.approx(rec.imu.t[0])          # the still period is in the output
    ref = rec.reference
    sel = (ref.t >= sol.t[0]) & (ref.t <= sol.t[0] + 1.0)
    it = interpolate_solution(sol, ref.t[sel])
    e = position_errors_enu(it["lat_deg"], it["lon_deg"], it["alt"], ref.lat_deg[sel], ref.lon_deg[sel], ref.alt[sel])
    s0 = it["std_enu"][0]
    n = int(np.count_nonzero(rec.gnss.t <= 30.0 + rec.imu.t[0]))
    assert np.all(s0 < 2.0 * np.array([1.8, 1.8, 2.5]) / math.sqrt(n))
    assert np.all(np.abs(e[0]) < 4.0 * s0)                  # error / sigma at the start
    # over the first second the output moves only as far as k more fixes move a mean of n:
    # k / (n + k) times their mean's error, below 3 sqrt(k) sigma / n (plus a centimetre of INS)
    k = int(np.count_nonzero((rec.gnss.t > sol.t[0]) & (rec.gnss.t <= sol.t[0] + 1.0)))
    assert np.all(np.ptp(e, axis=0) < 3.0 * math.sqrt(k) * np.array([1.8, 1.8, 2.5]) / n + 0.01)
