"""Smoothing end to end (issue 7): ``smooth=True`` / ``--smooth`` on simulated drives, against
the simulator's truth (the reference), the forward run of the same filter, and the outputs'
own contract (trajectory_forward.csv, metrics["forward"], MCAP forward topics, compare rows)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scenarios import gnss_jump_recording
from typer.testing import CliRunner

from navpp import api, engine
from navpp.cli import app
from navpp.comparison import compare
from navpp.config import config_from_dict
from navpp.errors import ConfigError
from navpp.filters import FILTERS
from navpp.metrics import interpolate_solution, position_errors_enu
from navpp.simulate import SimulationSpec, simulate

OUTAGE = (60.0, 20.0)           # inside the session log (120 s, still until 30 s)


@pytest.fixture(scope="module")
def drive300(tmp_path_factory):
    """A 300 s automotive drive (still 30 s) with a 30 s GNSS outage at 150 s."""
    from navpp.simulate import write_csv_log

    d = tmp_path_factory.mktemp("drive300") / "drive"
    write_csv_log(simulate(SimulationSpec(duration_s=300.0, still_s=30.0, seed=0)), d)
    fwd = api.process(d, write=False, gnss_outages=[(150.0, 30.0)])
    sm = api.process(d, write=False, gnss_outages=[(150.0, 30.0)], smooth=True)
    return fwd, sm


@pytest.fixture(scope="module")
def pair(sim_log_dir):
    fwd = api.process(sim_log_dir, write=False, gnss_outages=[OUTAGE])
    sm = api.process(sim_log_dir, write=False, gnss_outages=[OUTAGE], smooth=True)
    return fwd, sm


def _errors(res, sol):
    ref = res.recording.reference
    inside = (ref.t >= sol.t[0]) & (ref.t <= sol.t[-1])
    est = interpolate_solution(sol, ref.t[inside])
    err = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"], ref.lat_deg[inside],
                              ref.lon_deg[inside], ref.alt[inside])
    std = np.column_stack([np.interp(ref.t[inside], sol.t, sol.std_enu[:, i]) for i in range(3)])
    return ref.t[inside], err, std


def test_the_forward_solution_is_untouched_by_smoothing(pair):
    fwd, sm = pair
    assert sm.smoothed and not fwd.smoothed
    for name in ("t", "lat_deg", "lon_deg", "alt", "vel_enu", "rph_deg", "std_enu"):
        np.testing.assert_array_equal(getattr(sm.forward, name), getattr(fwd.solution, name), err_msg=name)


def test_smoothing_bridges_the_outage(drive300):
    """The simulator's truth is the oracle; the figures on this drive (seed 0): outage RMSE
    6.2 m forward, 0.8 m smoothed; over the whole drive 2.1 m and 0.4 m."""
    fwd, sm = drive300
    t, e_f, _ = _errors(fwd, fwd.solution)
    _, e_s, _ = _errors(sm, sm.solution)
    h_f, h_s = np.hypot(e_f[:, 0], e_f[:, 1]), np.hypot(e_s[:, 0], e_s[:, 1])
    w = (t >= 150.0) & (t <= 180.0)
    def rms(a):
        return float(np.sqrt(np.mean(a * a)))
    assert rms(h_s[w]) <= 0.3 * rms(h_f[w]), (rms(h_s[w]), rms(h_f[w]))
    assert rms(h_s) < 0.8 * rms(h_f)
    assert rms(e_s[:, 2]) < rms(e_f[:, 2])
    # the metrics say the same, side by side
    m = sm.metrics
    assert m["solution"] == "smoothed" and m["smoother_nodes"] > 0 and m["smoothing_s"] >= 0.0
    assert m["forward"]["position_m"]["horizontal"]["rmse"] == pytest.approx(
        fwd.metrics["position_m"]["horizontal"]["rmse"], rel=1e-12)
    assert m["position_m"]["horizontal"]["rmse"] == pytest.approx(rms(h_s), rel=1e-6)
    assert m["outages"][0]["horizontal_m"]["rmse"] < 0.3 * m["forward"]["outages"][0]["horizontal_m"]["rmse"]


def test_smoothed_sigma_is_smaller_and_honest(pair):
    fwd, sm = pair
    t, e_s, std_s = _errors(sm, sm.solution)
    _, _, std_f = _errors(fwd, fwd.solution)
    moving = t > 35.0
    assert np.all(std_s[moving] <= std_f[moving] * (1 + 1e-5) + 1e-6)
    w = (t >= OUTAGE[0]) & (t <= sum(OUTAGE))
    assert np.median(std_s[w, :2]) < 0.5 * np.median(std_f[w, :2])
    # consistent with the truth: |error| within 3 sigma on (nearly) every epoch, per axis
    assert np.mean(np.abs(e_s[moving]) <= 3.0 * std_s[moving]) > 0.97


def test_the_end_of_the_log_is_the_forward_filters(pair):
    _, sm = pair
    f, s = sm.forward, sm.solution
    for name in ("lat_deg", "lon_deg", "alt"):
        assert getattr(s, name)[-1] == getattr(f, name)[-1]


#: the three costliest runs (2.6 s of CPU) go with the slow tests: the default run keeps every
#: filter's smoother in test_smoother.py (a linear model) and its six others on this log
SLOW_SMOOTHED = ("rwckf", "sif", "vce-ckf")


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW_SMOOTHED else [])
                                  for n in sorted(FILTERS)])
def test_every_filter_smooths(sim_log_dir, name):
    res = api.process(sim_log_dir, filter_name=name, write=False, smooth=True)
    f = res.metrics["forward"]["position_m"]["horizontal"]["rmse"]
    s = res.metrics["position_m"]["horizontal"]["rmse"]
    # the RWCKF's random-weight jitter is not in its covariance, so smoothing removes little of it
    assert s < (1.0 if name == "rwckf" else 0.8) * f, (name, s, f)
    assert res.run.smoothed.breaks == 0


def test_no_information_is_carried_back_across_a_forced_fix():
    """GNSS jumps 20 m east for good at t = 150 s; after 10 s of rejections the fix is forced.
    Carrying that jump back would drag the trajectory before 150 s east; it must not."""
    rec = gnss_jump_recording(20.0, at_s=150.0)
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    res = engine.run(rec, cfg, api.make_filter("ekf", cfg), smooth=True)
    assert res.diagnostics.forced.any() and res.smoothed.breaks >= 1
    assert any("smoothing:" in w and "forced through the gate" in w for w in res.warnings)
    ref = rec.reference
    sel = (ref.t > 100.0) & (ref.t < 149.0)
    est = interpolate_solution(res.smoothed.solution, ref.t[sel])
    err = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"], ref.lat_deg[sel], ref.lon_deg[sel],
                              ref.alt[sel])
    assert np.abs(err[:, 0]).max() < 2.0


def test_written_files(sim_log_dir, tmp_path):
    out = tmp_path / "o"
    res = api.process(sim_log_dir, out_dir=out, smooth=True, formats="csv,mcap", gnss_outages=[OUTAGE])
    names = sorted(p.name for p in res.files)
    assert names == sorted(["trajectory.csv", "trajectory_forward.csv", "diagnostics.csv", "metrics.json",
                            "metrics.md", "trajectory.mcap", "navpp.layout.json"])
    written = pd.read_csv(out / "trajectory.csv")
    np.testing.assert_allclose(written["lat"], res.trajectory["lat"], rtol=0, atol=2e-9)
    np.testing.assert_allclose(written["alt"], res.trajectory["alt"], rtol=0, atol=1e-4)
    fwd = pd.read_csv(out / "trajectory_forward.csv")
    np.testing.assert_allclose(fwd["lat"], res.forward_trajectory["lat"], atol=1e-9)
    assert not np.allclose(fwd["lat"], pd.read_csv(out / "trajectory.csv")["lat"], atol=1e-9, rtol=0)
    m = json.loads((out / "metrics.json").read_text())
    assert m["solution"] == "smoothed" and "forward" in m
    md = (out / "metrics.md").read_text()
    assert "## Forward and smoothed" in md and "outage 60-80 s: horizontal RMSE (m)" in md

    from mcap.reader import make_reader

    with open(out / "trajectory.mcap", "rb") as f:
        reader = make_reader(f)
        counts = {c.topic: 0 for c in reader.get_summary().channels.values()}
        for _, ch, _ in reader.iter_messages():
            counts[ch.topic] += 1
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
    assert counts["/navpp/forward/odometry"] == counts["/navpp/odometry"] == len(res.solution.t)
    assert counts["/navpp/forward/fix"] == len(res.solution.t)
    assert meta["navpp"]["solution"].startswith("smoothed")
    # a later run without smoothing removes the stale forward file
    again = api.process(sim_log_dir, out_dir=out)
    assert not (out / "trajectory_forward.csv").exists() and again.forward is None


def test_config_turns_smoothing_on_and_is_validated(log_copy):
    (log_copy / "navpp.toml").write_text('[imu]\npreset = "automotive"\n[output]\nsmooth = true\n')
    res = api.process(log_copy, write=False)
    assert res.smoothed
    assert not api.process(log_copy, write=False, smooth=False).smoothed
    (log_copy / "navpp.toml").write_text('[output]\nsmooth = "yes"\n')
    with pytest.raises(ConfigError, match=r"\[output\] smooth must be true or false"):
        api.process(log_copy, write=False)


def test_cli_smooth(sim_log_dir, tmp_path):
    r = CliRunner().invoke(app, ["process", str(sim_log_dir), "--smooth", "--gnss-outage", "60:20",
                                 "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    assert "smoothed vs forward filter: horizontal RMSE" in r.output
    assert "; forward filter: end" in r.output
    assert (tmp_path / "o" / "trajectory_forward.csv").is_file()


@pytest.mark.slow     # compare --smooth in worker processes; test_written_files covers the smoothed files
def test_compare_smooth_rows(sim_log_dir, tmp_path):
    res = compare([sim_log_dir], ["ekf", "ckf"], smooth=True, out_dir=tmp_path)
    assert [r.filter for r in res.rows] == ["ekf", "ekf+rts", "ckf", "ckf+rts"]
    assert all(r.ok for r in res.rows)
    by = {r.filter: r for r in res.rows}
    for name in ("ekf", "ckf"):
        assert by[name + "+rts"].runtime_s > by[name].runtime_s
        assert (by[name + "+rts"].metrics["position_m"]["horizontal"]["rmse"]
                < by[name].metrics["position_m"]["horizontal"]["rmse"])
    summary = pd.read_csv(tmp_path / "summary.csv")
    assert list(summary["filter"]) == ["ekf", "ekf+rts", "ckf", "ckf+rts", "raw GNSS"]
    assert "ekf+rts" in (tmp_path / "report.md").read_text()
    assert set(res.run_series) == {(str(sim_log_dir), f) for f in ("ekf", "ekf+rts", "ckf", "ckf+rts")}
    parallel = compare([sim_log_dir], ["ekf", "ckf"], smooth=True, jobs=2, report=False)
    for a, b in zip(res.rows, parallel.rows):
        assert (a.filter, a.metrics["position_m"]) == (b.filter, b.metrics["position_m"])


def test_a_spilled_store_smooths_to_the_same_bytes(sim_log_dir, monkeypatch, tmp_path):
    """Blocks of 64 nodes and a budget of one byte: every full block goes to a temporary file
    (in $TMPDIR, gone afterwards) and the smoothed solution is the in-memory one, bit for bit."""
    import tempfile

    from navpp.filters import smoother

    monkeypatch.setattr(smoother, "BLOCK_NODES", 64)
    kept = api.process(sim_log_dir, write=False, gnss_outages=[OUTAGE], smooth=True)
    opened, temporary_file = [], tempfile.TemporaryFile
    monkeypatch.setattr(tempfile, "TemporaryFile", lambda **kw: opened.append(kw) or temporary_file(**kw))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    spilled = api.process(sim_log_dir, write=False, gnss_outages=[OUTAGE], smooth=True, memory=1)
    # one file for the store; the IMU-rate output (beyond the same budget) has its own (navpp.spill)
    assert [kw["prefix"] for kw in opened].count("navpp-smoother-") == 1 and list(tmp_path.iterdir()) == []
    for name in ("t", "lat_deg", "lon_deg", "alt", "vel_enu", "rph_deg", "std_enu", "std_att", "std_vel_enu",
                 "rate_body"):
        np.testing.assert_array_equal(getattr(spilled.solution, name), getattr(kept.solution, name), err_msg=name)


def test_memory_option_and_config_are_validated(log_copy, tmp_path):
    r = CliRunner().invoke(app, ["process", str(log_copy), "--smooth", "--memory", "12XB", "--out", str(tmp_path)])
    assert r.exit_code == 1
    assert "--memory: expected a memory size such as 500MB, 1GB or 2G, got '12XB'" in r.output
    assert config_from_dict({"output": {"memory": "1.5GB"}}, "t.toml").output.memory == 3 << 29
    assert config_from_dict({"output": {"memory": "500MB"}}, "t.toml").output.memory == 500 << 20
    with pytest.raises(ConfigError, match=r"\[output\] memory: expected a memory size"):
        config_from_dict({"output": {"memory": 0}}, "t.toml")
