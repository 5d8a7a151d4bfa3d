"""Self-calibration from the log (issue 14): navpp/ins/calibrate.py and what the engine does with it.

Oracles: the simulator's truth (its speed says when the vehicle stands; its drawn turn-on biases;
its white-noise sigmas), closed-form rotations for the gravity axis, and the same run with the
automatic step turned off.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from navpp import api, engine
from navpp.config import config_from_dict
from navpp.errors import FilterDivergedError, InputError
from navpp.ins.attitude import rpy_deg_to_dcm
from navpp.ins.calibrate import calibrate, gross_mounting, matrix_to_rpy_deg, noise_profile
from navpp.metrics import compute_metrics
from navpp.recording import ImuData
from navpp.simulate import SimulationSpec, simulate


@pytest.fixture(scope="module")
def consumer_drive():
    """A 300-s consumer-grade drive with a 30-s standstill at the start and a stop mid-way."""
    return simulate(SimulationSpec(duration_s=300.0, still_s=30.0, seed=5, preset="consumer"))


#: every automatic step on (they are opt-in: [auto] in the config)
ON = {"auto": {k: True for k in ("standstill", "noise", "biases", "mounting", "heading", "recovery", "stale_rows",
                                 "clock_offset")}}


def _on(raw=None):
    raw = dict(raw or {})
    raw.update(ON)
    return config_from_dict(raw, "t")


def _cal(sim, **kw):
    rec = sim.recording()
    noise = config_from_dict({"imu": {"preset": "automotive"}}, "t").imu.noise()
    args = dict(gyro_arw=noise.gyro_arw, accel_vrw=noise.accel_vrw, gyro_bias_sigma=noise.gyro_bias_sigma,
                accel_bias_sigma=noise.accel_bias_sigma)
    args.update(kw)
    return calibrate(rec.imu.t, rec.imu.gyro, rec.imu.accel, rec.gnss, **args)


def _metrics(sol, ref):
    return compute_metrics(sol, ref, filter_name="ekf", log="", reference="", runtime_s=0, imu_samples=0,
                           gnss_epochs=0, gnss_rejected=0)["position_m"]["horizontal"]["rmse"]


def test_standstill_agrees_with_the_truth_speed(consumer_drive):
    cal = _cal(consumer_drive)
    ref = consumer_drive.reference
    speed = np.interp(consumer_drive.imu.t, ref.t, np.linalg.norm(ref.vel_enu, axis=1))
    # never still while moving: no ZUPT while driving
    assert np.all(speed[cal.still] < 0.05), float(speed[cal.still].max())
    # the 30-s standstill at the start is found (all but the confirmation blocks at its end)
    start = consumer_drive.imu.t < 29.0
    assert cal.still[start].mean() > 0.95
    assert cal.still_spans[0][0] < 0.6


def test_turn_on_gyro_bias_from_the_still_start(consumer_drive):
    """The consumer turn-on bias (200 deg/h, 1 sigma) against an automotive prior (10 deg/h):
    the prior is rejected and the estimate is within 3 sigma of the drawn bias (the Gauss-Markov
    part at the start included)."""
    cal = _cal(consumer_drive)
    err = consumer_drive.sensor_errors
    truth = err["gyro_bias"] + err["gyro_gauss_markov"][:100].mean(axis=0)
    assert cal.bias_from == "still"
    z = (cal.gyro_bias - truth) / cal.gyro_bias_std
    assert np.all(np.abs(z) < 3.0), z
    assert np.all(cal.gyro_bias_std < math.radians(0.01))


def test_noise_profile_reads_white_noise(consumer_drive):
    """White noise of known density comes back from the 0.1-s means within 10 %, a slow motion
    (a smooth turn) adds nothing, and a fast oscillation of the mount (27.3 Hz, 100 times the
    white noise's per-sample spread), which does not drift, is mostly averaged out (the per-sample
    scatter would read all of it)."""
    t = np.arange(0, 60.0, 0.01)
    rng = np.random.default_rng(0)
    arw, vrw = 0.002, 0.003
    gyro = rng.normal(0, arw / math.sqrt(0.01), (t.size, 3)) + np.sin(0.5 * t)[:, None]
    accel = rng.normal(0, vrw / math.sqrt(0.01), (t.size, 3)) + np.array([0, 0, 9.8])
    prof = noise_profile(t, gyro, accel)
    assert abs(np.median(prof.gyro_arw) / arw - 1.0) < 0.1
    assert abs(np.median(prof.accel_vrw) / vrw - 1.0) < 0.1
    shake = 100.0 * arw / math.sqrt(0.01) * np.sin(2 * math.pi * 27.3 * t + 0.3)[:, None] * np.ones(3)
    shaken = noise_profile(t, gyro + shake, accel)
    per_sample = np.std(shake[:, 0]) * math.sqrt(0.01)          # what the per-sample scatter would read
    assert per_sample > 50 * arw
    assert np.median(shaken.gyro_arw) < per_sample / 3.0


@pytest.mark.parametrize("rpy", [(90.0, 0.0, 0.0), (-90.0, 0.0, 0.0), (180.0, 0.0, 0.0), (0.0, 90.0, 0.0)])
def test_gross_mounting_puts_gravity_on_z(rpy):
    """A sensor whose gravity axis is y, -y, -z (FRD written as FLU) or x: the rotation found
    maps the sensor's up onto +z, and the rpy it reports rebuilds the same matrix."""
    m = rpy_deg_to_dcm(rpy)                      # sensor -> body
    up_sensor = m.T @ np.array([0.0, 0.0, 1.0])
    rot = gross_mounting(up_sensor)
    assert rot is not None
    np.testing.assert_allclose(rot @ up_sensor, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(rpy_deg_to_dcm(matrix_to_rpy_deg(rot)), rot, atol=1e-4)
    assert gross_mounting(np.array([0.1, -0.2, 0.97])) is None       # a tilt, not a mounting


def _rotated(sim, rpy):
    """The recording as a sensor mounted with ``rpy`` (sensor -> body) would log it."""
    rec = sim.recording()
    m = rpy_deg_to_dcm(rpy)
    imu = ImuData(rec.imu.t, rec.imu.gyro @ m, rec.imu.accel @ m)       # body -> sensor: m^T v
    return replace(rec, imu=imu)


@pytest.fixture(scope="module")
def drive():
    return simulate(SimulationSpec(duration_s=180.0, still_s=20.0, seed=11))


@pytest.mark.parametrize("rpy", [(90.0, 0.0, 0.0), (180.0, 0.0, 0.0)])
def test_y_up_or_upside_down_imu_works_and_names_the_setting(drive, rpy):
    rec = _rotated(drive, rpy)
    cfg = _on()
    res = engine.run(rec, cfg, api.make_filter("ekf", cfg))
    h = _metrics(res.solution, rec.reference)
    base = engine.run(drive.recording(), cfg, api.make_filter("ekf", cfg))
    assert h < 1.2 * _metrics(base.solution, rec.reference) + 0.05, h
    assert any("mounting_rpy_deg" in w and "not +z" in w for w in res.warnings), res.warnings
    # off: levelled at 90 deg of roll with a line naming the setting; upside down (180 deg) is
    # refused naming it (issue 15: the roll of 180 deg and a lever arm turned down were written)
    off = replace(cfg, auto=replace(cfg.auto, mounting=False))
    if rpy[0] == 180.0:
        with pytest.raises(InputError, match=r"mounting_rpy_deg = \[180, 0, 0\]"):
            engine.run(rec, off, api.make_filter("ekf", off))
        return
    res_off = engine.run(rec, off, api.make_filter("ekf", off))
    assert any("mounting_rpy_deg" in w and "tilted" in w for w in res_off.warnings), res_off.warnings


def test_stale_rows_are_dropped(drive):
    """Every fifth row repeated under a new stamp (a logger polling faster than the sensor): the
    rows are dropped, counted, and the solution equals the run on the fresh rows alone."""
    rec = drive.recording()
    imu = rec.imu
    keep = np.ones(len(imu), bool)
    keep[::2] = False
    keep[0] = True
    t_all = imu.t
    src = np.maximum.accumulate(np.where(keep, np.arange(len(imu)), 0))       # stale rows copy the last fresh
    stale = replace(rec, imu=ImuData(t_all, imu.gyro[src], imu.accel[src]))
    fresh = replace(rec, imu=ImuData(t_all[keep], imu.gyro[keep], imu.accel[keep]))
    cfg = _on()
    a = engine.run(stale, cfg, api.make_filter("ekf", cfg))
    b = engine.run(fresh, cfg, api.make_filter("ekf", cfg))
    assert any("stale rows" in w for w in a.warnings), a.warnings
    np.testing.assert_array_equal(a.solution.lat_deg, b.solution.lat_deg)


def test_clock_offset_is_found_and_applied():
    """GNSS stamps 0.3 s late (receiver latency) on an RTK-grade drive: the run estimates it,
    applies it, says so, and does about as well as with the true offset configured."""
    rec = simulate(SimulationSpec(duration_s=180.0, still_s=20.0, seed=11, gnss_std_h_m=0.05,
                                  gnss_std_u_m=0.1)).recording()
    late = replace(rec, gnss=replace(rec.gnss, t=rec.gnss.t + 0.3))
    cfg = _on()
    res = engine.run(late, cfg, api.make_filter("ekf", cfg))
    line = next(w for w in res.warnings if "clock offset" in w)
    est = float(line.split("the GNSS is ")[1].split(" s")[0])
    assert abs(est - 0.3) < 0.05, line
    told = _on({"gnss": {"time_offset_s": -0.3}})
    ref = engine.run(replace(late, gnss=replace(late.gnss, t=late.gnss.t - 0.3)), told,
                     api.make_filter("ekf", told))
    assert _metrics(res.solution, rec.reference) < 1.3 * _metrics(ref.solution, rec.reference) + 0.05


def test_a_diverging_run_prints_its_notes_first(drive, tmp_path):
    """An error carries what the run measured before it failed (the CLI prints it first)."""
    rec = drive.recording()
    bad = replace(rec, gnss=replace(rec.gnss, lat_deg=rec.gnss.lat_deg + np.where(rec.gnss.t > 60, 0.01, 0.0)))
    cfg = _on({"gnss": {"reanchor_after_s": 1e9}})
    cfg = replace(cfg, auto=replace(cfg.auto, recovery=False))
    with pytest.raises(FilterDivergedError) as info:
        engine.run(bad, cfg, api.make_filter("ekf", cfg))
    assert any("still" in n for n in info.value.notes), info.value.notes


def test_recovery_after_drift(drive):
    """A wrong initial heading (90 deg off, configured with a tight sigma): the gate rejects the
    fixes; the forced fix re-aligns the velocity and re-opens attitude, so the run recovers
    (re-opening only the position leaves it far worse)."""
    rec = drive.recording()
    true_heading = float(rec.reference.rph_deg[0, 2])
    raw = {"init": {"heading_deg": (true_heading + 90.0) % 360.0}, "gnss": {"max_rejected_fraction": 1.0}}
    on = _on(raw)
    off = replace(on, auto=replace(on.auto, recovery=False))
    a = engine.run(rec, on, api.make_filter("ekf", on))
    b = engine.run(rec, off, api.make_filter("ekf", off))
    ha, hb = _metrics(a.solution, rec.reference), _metrics(b.solution, rec.reference)
    assert any("drifted from the GNSS" in w for w in a.warnings), a.warnings
    assert ha < 0.5 * hb, (ha, hb)


@pytest.mark.parametrize("shape", [(40, 360), (40, 30), (40, 15), (7, 1), (7, 2), (3, 5)])
def test_row_sums_match_the_median_rule_to_the_bit(shape):
    """The noise profile's per-row sums (one in-place partition for the median) give what
    ``np.median`` and the plain rule give, bit for bit, with glitches (NaN, inf, huge values)."""
    from navpp.ins.calibrate import OUTLIER_K, _row_medians, _row_sums

    rng = np.random.default_rng(sum(shape))
    v = rng.standard_normal(shape) * np.exp(3.0 * rng.standard_normal(shape))
    for bad, value in ((0.02, np.nan), (0.02, np.inf), (0.02, -np.inf), (0.01, 1e200)):
        v[rng.random(shape) < bad] = value
    v[0] = np.nan                                   # a row of nothing but glitches
    for x in (v, np.nan_to_num(v, nan=1.0, posinf=2.0, neginf=-3.0)):
        av = np.abs(x)
        finite = np.isfinite(av)
        with np.errstate(invalid="ignore", over="ignore"):
            med = np.median(np.where(finite, av, np.inf), axis=1)
            keep = finite & (av <= OUTLIER_K * med[:, None])
            ssq = (np.where(keep, av, 0.0) ** 2).sum(axis=1)
        assert np.array_equal(_row_medians(np.where(finite, av, np.inf)), med)
        got_ssq, got_cnt = _row_sums(x)
        assert np.array_equal(got_ssq, ssq, equal_nan=True)
        assert np.array_equal(got_cnt, keep.sum(axis=1).astype(float))


@pytest.mark.parametrize("size", [1, 2, 7, 8, 12, 24, 60, 129])
def test_group_means_are_numpys_to_the_bit(size):
    """The noise profile's means of consecutive groups of rows add in numpy's order."""
    from navpp.ins.calibrate import _group_means

    rng = np.random.default_rng(size)
    x = (rng.standard_normal((50 * size, 3)) * np.exp(5.0 * rng.standard_normal((50 * size, 3)))).reshape(50, size, 3)
    assert np.array_equal(_group_means(x), x.mean(axis=1))
