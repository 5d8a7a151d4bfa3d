"""GNSS faults (issue 6): simulated outages (``--gnss-outage``, ``gnss_outages=``, ``[gnss]
outages``) and their metrics, the innovation gate against outliers, forced re-admission, and
adaptive filters that must not learn outliers into R.

Oracles: the simulator's truth, windows and counts computed by hand, and a flat-earth error
computation independent of navpp's exact ECEF one (errors of a few metres: agreement to mm).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scenarios import gnss_jump_recording, load_benchmark
from typer.testing import CliRunner

from navpp import api, engine
from navpp.cli import app
from navpp.config import config_from_dict
from navpp.errors import ConfigError, InputError
from navpp.metrics import outage_metrics
from navpp.simulate import SimulationSpec, simulate

WINDOWS = [(60.0, 10.0), (90.0, 5.0)]          # inside the session log (120 s, still until 30 s)


bench = load_benchmark("bench_faults")


@pytest.fixture(scope="module")
def runs(sim_log_dir):
    base = api.process(sim_log_dir, write=False)
    cut = api.process(sim_log_dir, write=False, gnss_outages=WINDOWS)
    return base, cut


# --------------------------------------------------------------------------- removal

def test_outage_fixes_are_removed(runs):
    base, cut = runs
    t = np.asarray(base.recording.gnss.t)
    expected = [int(np.count_nonzero((t >= s - 1e-9) & (t <= s + d + 1e-9))) for s, d in WINDOWS]
    assert expected == [51, 26]                      # 5 Hz, both ends included
    assert [w["gnss_removed"] for w in cut.outages] == expected
    assert base.run.gnss_epochs - cut.run.gnss_epochs == sum(expected)
    used = np.asarray(cut.run.diagnostics.t)
    for s, d in WINDOWS:
        assert not np.any((used >= s) & (used <= s + d))
    assert len(cut.recording.gnss) == len(base.recording.gnss) - sum(expected)
    assert len(cut.recording.imu) == len(base.recording.imu)          # the IMU is untouched
    assert any("60-70 s" in n and "51 fixes removed" in n for n in cut.notes)


def test_ins_coasts_through_the_outage(runs):
    base, cut = runs
    s, d = WINDOWS[0]
    k = np.searchsorted(cut.solution.t, s + d)
    # the 1-sigma grows through 10 s of free inertial and exceeds the run with GNSS
    assert cut.solution.std_enu[k, 0] > 2.0 * base.solution.std_enu[k, 0]
    assert cut.solution.std_enu[k, 0] > cut.solution.std_enu[np.searchsorted(cut.solution.t, s), 0]


def test_outages_from_the_config(sim_log_dir):
    cfg = config_from_dict({"gnss": {"outages": [list(w) for w in WINDOWS]}}, "test")
    res = api.process(sim_log_dir, write=False, config=cfg)
    assert [(w["start_s"], w["duration_s"]) for w in res.outages] == WINDOWS
    assert [w["gnss_removed"] for w in res.metrics["outages"]] == [51, 26]
    # the keyword overrides the config's windows
    res2 = api.process(sim_log_dir, write=False, config=cfg, gnss_outages=[(40.0, 2.0)])
    assert [w["gnss_removed"] for w in res2.outages] == [11]


@pytest.mark.parametrize("bad", [[(10.0, 0.0)], [(-1.0, 5.0)], [(10.0, float("nan"))], [(10.0,)], ["10:5"]])
def test_invalid_windows_are_config_errors(sim_log_dir, bad):
    with pytest.raises(ConfigError, match="gnss_outages"):
        api.process(sim_log_dir, write=False, gnss_outages=bad)


def test_window_outside_the_log_is_an_input_error(sim_log_dir):
    """A window running past the end is said as such, with the longest window that fits (the
    log spans 0-120 s); one starting after the end is said as that."""
    with pytest.raises(InputError, match=r"GNSS outage 100:50 \(100-150 s\) runs past the end of the log at "
                                         r"120.000 s .* the longest outage from 100 s is 100:20$"):
        api.process(sim_log_dir, write=False, gnss_outages=[(100.0, 50.0)])
    with pytest.raises(InputError, match=r"GNSS outage 130:5 \(130-135 s\) starts after the log ends"):
        api.process(sim_log_dir, write=False, gnss_outages=[(130.0, 5.0)])


# --------------------------------------------------------------------------- metrics

def test_outage_metrics_by_hand():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    err = np.array([[9, 9, 9], [3, 4, -1], [0, 1, 2], [6, 8, -3], [9, 9, 9]], dtype=float)
    (w,) = outage_metrics(t, err, [(1.0, 2.0)], [7])
    assert w["epochs"] == 3 and w["gnss_removed"] == 7 and w["end_s"] == 3.0 and w["end_epoch_s"] == 3.0
    assert w["horizontal_m"] == pytest.approx({"end": 10.0, "max": 10.0, "rmse": np.sqrt((25 + 1 + 100) / 3)})
    assert w["vertical_m"] == pytest.approx({"end": 3.0, "max": 3.0, "rmse": np.sqrt((1 + 4 + 9) / 3)})
    (empty,) = outage_metrics(t, err, [(4.5, 1.0)])
    assert empty["epochs"] == 0 and "horizontal_m" not in empty and "gnss_removed" not in empty


def _flat_earth_errors(sol, ref, t):
    """Estimate minus reference (E, N, U m) at reference times ``t``: np.interp and the local
    radii of curvature (independent of navpp.metrics)."""
    a, e2 = 6378137.0, 6.69437999014e-3
    k = np.searchsorted(ref.t, t)
    lat = np.radians(ref.lat_deg[k])
    w = np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    rn, rm = a / w, a * (1.0 - e2) / w ** 3
    de = np.radians(np.interp(t, sol.t, sol.lon_deg) - ref.lon_deg[k]) * (rn + ref.alt[k]) * np.cos(lat)
    dn = np.radians(np.interp(t, sol.t, sol.lat_deg) - ref.lat_deg[k]) * (rm + ref.alt[k])
    du = np.interp(t, sol.t, sol.alt) - ref.alt[k]
    return np.column_stack([de, dn, du])


def test_outage_metrics_equal_a_direct_computation(runs):
    _, cut = runs
    ref, sol = cut.recording.reference, cut.solution
    for (s, d), w in zip(WINDOWS, cut.metrics["outages"]):
        t = ref.t[(ref.t >= s) & (ref.t <= s + d)]
        e = _flat_earth_errors(sol, ref, t)
        h, v = np.hypot(e[:, 0], e[:, 1]), np.abs(e[:, 2])
        assert w["epochs"] == t.size == round(d * 10) + 1           # 10 Hz reference, both ends
        assert w["end_epoch_s"] == pytest.approx(s + d)
        for got, a in ((w["horizontal_m"], h), (w["vertical_m"], v)):
            assert got["end"] == pytest.approx(a[-1], abs=2e-3)
            assert got["max"] == pytest.approx(a.max(), abs=2e-3)
            assert got["rmse"] == pytest.approx(np.sqrt(np.mean(a ** 2)), abs=2e-3)
    # the overall figures stay over the whole run
    assert cut.metrics["epochs"] == runs[0].metrics["epochs"]


# --------------------------------------------------------------------------- CLI

def test_cli_outages_in_summary_json_and_md(sim_log_dir, tmp_path):
    out = tmp_path / "o"
    r = CliRunner().invoke(app, ["process", str(sim_log_dir), "--out", str(out), "--gnss-outage", "60:10",
                                 "--gnss-outage", "90:5"])
    assert r.exit_code == 0, r.output
    assert "GNSS outage 60-70 s (10 s, 51 fixes removed): at its end horizontal" in r.stdout
    assert "GNSS outage 90-95 s (5 s, 26 fixes removed)" in r.stdout
    m = json.loads((out / "metrics.json").read_text())
    assert [w["start_s"] for w in m["outages"]] == [60.0, 90.0]
    md = (out / "metrics.md").read_text()
    assert "## Simulated GNSS outages" in md and "| 60-70 | 51 | 101 |" in md
    assert "over the whole run" in md


@pytest.mark.parametrize("value", ["abc", "60", "60:10:5", "60:0", "60:-5", "-1:5", "60:nan", "x:5"])
def test_cli_unparseable_or_invalid_outage_is_a_usage_error(sim_log_dir, value, tmp_path):
    r = CliRunner().invoke(app, ["process", str(sim_log_dir), "--out", str(tmp_path / "o"), "--gnss-outage", value])
    assert r.exit_code == 2, r.output
    assert "--gnss-outage" in r.output


def test_cli_outage_outside_the_log_exits_1(sim_log_dir, tmp_path):
    r = CliRunner().invoke(app, ["process", str(sim_log_dir), "--out", str(tmp_path / "o"),
                                 "--gnss-outage", "110:30"])
    assert r.exit_code == 1, r.output
    assert "runs past the end of the log" in r.output and "Traceback" not in r.output


# --------------------------------------------------------------------------- gate and outliers

@pytest.fixture(scope="module")
def outlier_drive():
    """A 300 s automotive drive and the same with 2 % of its fixes displaced by 15-60 m."""
    sim = simulate(SimulationSpec(duration_s=300.0, still_s=30.0, seed=21))
    rec = sim.recording()
    gnss, idx = bench.with_outliers(rec.gnss, 0.02, seed=7, after_s=50.0)
    return rec, replace(rec, gnss=gnss), idx


def test_outliers_are_really_displaced(outlier_drive):
    rec, bad, idx = outlier_drive
    from navpp.metrics import position_errors_enu

    d = position_errors_enu(bad.gnss.lat_deg, bad.gnss.lon_deg, bad.gnss.alt,
                            rec.gnss.lat_deg, rec.gnss.lon_deg, rec.gnss.alt)
    dist = np.linalg.norm(d, axis=1)
    assert idx.size == round(0.02 * np.count_nonzero(rec.gnss.t > 50.0))
    assert np.all((dist[idx] > 15.0 - 1e-6) & (dist[idx] < 60.0 + 1e-6))
    assert np.count_nonzero(dist > 1e-6) == idx.size


@pytest.mark.parametrize("name", ["ekf", "aekf"])
def test_gate_keeps_outliers_out(outlier_drive, name):
    rec, bad, idx = outlier_drive
    clean = bench.run_filter(rec, name)[0]["position_m"]["horizontal"]["rmse"]
    m, res = bench.run_filter(bad, name)
    gated = m["position_m"]["horizontal"]["rmse"]
    off = bench.run_filter(bad, name, gate_probability=0.0)[0]["position_m"]["horizontal"]["rmse"]
    assert gated <= 1.2 * clean, (gated, clean)
    assert off >= 1.4 * clean, (off, clean)                      # without the gate: much worse
    rejected_t = np.asarray(res.diagnostics.t)[~np.asarray(res.diagnostics.accepted)]
    assert np.isin(rec.gnss.t[idx], rejected_t).mean() > 0.9       # the outliers are what was rejected
    assert not res.diagnostics.forced.any()


# the VCE-CKF's pair of runs (2.8 s CPU, four times the AEKF's) with the slow statistical tests
@pytest.mark.parametrize("name", ["aekf", pytest.param("vce-ckf", marks=pytest.mark.slow)])
def test_adaptive_r_is_not_polluted_by_outliers(outlier_drive, name):
    _, bad, _ = outlier_drive
    _, res = bench.run_filter(bad, name)
    r_std = np.asarray(res.diagnostics.r_std)
    late = np.asarray(res.diagnostics.t) > 150.0
    learnt_h = np.sqrt(np.mean(r_std[late, :2] ** 2))
    assert learnt_h == pytest.approx(1.8, rel=0.25), learnt_h        # the simulator's 1.8 m
    # the contrast: without the gate the outliers are learnt into R
    _, res_off = bench.run_filter(bad, name, gate_probability=0.0)
    off_h = np.sqrt(np.mean(np.asarray(res_off.diagnostics.r_std)[late, :2] ** 2))
    assert off_h > 1.5 * learnt_h, (off_h, learnt_h)


@pytest.fixture(scope="module")
def jump_drive():
    """A 240 s drive whose GNSS jumps 20 m east for good at t = 150 s: fixes are rejected for
    ``reanchor_after_s`` and then forced through the gate."""
    return gnss_jump_recording()


def test_forced_admission_is_reported(jump_drive):
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    res = engine.run(jump_drive, cfg, api.make_filter("ekf", cfg))
    forced_t = np.asarray(res.diagnostics.t)[np.asarray(res.diagnostics.forced)]
    assert forced_t.size >= 1 and forced_t[0] >= 160.0 - 1e-9          # after 10 s of rejections
    (line,) = api.forced_fix_warnings(jump_drive, cfg, res)
    assert f"{forced_t.size} GNSS fix" in line and "force-admitted after 10 s" in line
    assert f"t = {forced_t[0]:.1f}" in line and "re-anchored" in line


def test_aekf_does_not_learn_a_forced_fix(jump_drive):
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    res = engine.run(jump_drive, cfg, api.make_filter("aekf", cfg))
    d = res.diagnostics
    k = int(np.flatnonzero(np.asarray(d.forced))[0])
    before, after = np.asarray(d.r_std)[k - 1, :2], np.asarray(d.r_std)[k + 1, :2]
    # a 20 m innovation learnt with weight d ~ 0.02 would lift R's std from ~2 m to ~3.5 m
    assert np.all(after < 1.05 * before), (before, after)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ekf", "aekf", "ckf", "vce-ckf"])
def test_15_minute_drive_with_outliers_meets_the_target(name):
    sim = simulate(SimulationSpec(duration_s=900.0, seed=0))
    rec = sim.recording()
    gnss, _ = bench.with_outliers(rec.gnss, 0.02, seed=1000, after_s=sim.spec.still_effective_s + 20.0)
    clean = bench.run_filter(rec, name)[0]["position_m"]["horizontal"]["rmse"]
    gated = bench.run_filter(replace(rec, gnss=gnss), name)[0]["position_m"]["horizontal"]["rmse"]
    assert gated <= 1.2 * clean, (gated, clean)


def test_config_outages_are_validated(tmp_path):
    from navpp.config import load_config

    f = tmp_path / "navpp.toml"
    f.write_text("[gnss]\noutages = [[100, 0]]\n")
    with pytest.raises(ConfigError, match=r"navpp.toml: \[gnss\] outages: duration must be .* > 0"):
        load_config(f)
    f.write_text("[gnss]\noutages = [100, 30]\n")
    with pytest.raises(ConfigError, match=r"\[gnss\] outages: each window must be \[start, duration\]"):
        load_config(f)


def test_cli_outage_without_reference(log_copy, tmp_path):
    (log_copy / "reference.csv").unlink()
    r = CliRunner().invoke(app, ["process", str(log_copy), "--out", str(tmp_path / "o"), "--gnss-outage", "60:10"])
    assert r.exit_code == 0, r.output
    assert "GNSS outage 60-70 s (10 s, 51 fixes removed)" in r.stdout
    assert not (tmp_path / "o" / "metrics.json").exists()
