"""Paper 001 section 4.2 (SINS/XPN, navpp/papers/xpn.py): the Kepler truth against the free
inertial SINS, eq 47's transition against the SINS itself, and a short run of the filters
against the Kalman filter and the fix noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navpp.errors import ConfigError
from navpp.papers import BENCHMARKS, xpn

SC = xpn.XpnScenario()


def test_kepler_truth_matches_the_elements_and_conserves_energy_and_momentum():
    t = np.array([0.0, 1234.5, 4000.0])
    r, v = xpn.kepler_state(SC, t)
    e, a = SC.ecc, SC.a_m
    nu0 = SC.nu0_deg * math.pi / 180.0
    # conic equation at t = 0 (closed form of the elements)
    assert np.linalg.norm(r[0]) == pytest.approx(a * (1 - e * e) / (1 + e * math.cos(nu0)), rel=1e-12)
    energy = 0.5 * np.sum(v * v, 1) - xpn.MU_EARTH / np.linalg.norm(r, axis=1)
    assert energy == pytest.approx(np.full(3, -xpn.MU_EARTH / (2 * a)), rel=1e-11)
    h = np.cross(r, v)
    assert h / np.linalg.norm(h[0]) == pytest.approx(np.tile(h[0] / np.linalg.norm(h[0]), (3, 1)), abs=1e-12)
    inc = math.degrees(math.acos(h[0, 2] / np.linalg.norm(h[0])))
    assert inc == pytest.approx(SC.inc_deg, abs=1e-9)


def test_free_inertial_sins_with_the_ideal_imu_reproduces_the_kepler_orbit():
    # a second implementation: RK4 on r'' = -mu r / r^3 at 10 Hz against Kepler's equation
    T = 3000.0
    K = round(T * SC.imu_rate_hz)
    gyro = np.tile([0.0, 0.0, SC.mean_motion], (K, 1))
    accel = np.zeros((K, 3))
    x0, xT = xpn.true_states(SC, np.array([0.0, T]), np.zeros(3), np.zeros(3))
    y = xpn.sins_propagate(x0, 0, K, 1.0 / SC.imu_rate_hz, gyro, accel)
    d = xpn.xpn_minus(xT, y)
    assert np.linalg.norm(d[0:3]) < 1e-3            # m, over half an orbit
    assert np.linalg.norm(d[3:6]) < 1e-6            # m/s
    assert np.linalg.norm(d[6:9]) < 1e-9            # rad: the body attitude of body_attitude()


def test_eq47_transition_matches_the_sins_on_small_errors():
    rng = np.random.default_rng(3)
    K = 10
    gyro = np.tile([0.0, 0.0, SC.mean_motion], (K, 1)) + rng.normal(0, 1e-5, (K, 3))
    accel = rng.normal(0.0, 0.5, (K, 3))           # a thrust-like specific force exercises -[f x] phi
    x = xpn.true_states(SC, np.zeros(1), np.zeros(3), np.zeros(3))[0]
    xn, Phi = xpn.xpn_transition(x, 0, K, 0.1, gyro, accel)
    dx = np.concatenate([[10.0, -5, 3], [0.05, -0.02, 0.01], [1e-4, -2e-4, 3e-4], [1e-6, -1e-6, 2e-6],
                         [1e-3, -2e-3, 5e-4]])
    moved = xpn.xpn_minus(xpn.sins_propagate(xpn.xpn_plus(x, dx), 0, K, 0.1, gyro, accel), xn)
    lin = Phi @ dx
    # the nonlinear SINS and eq 47 agree to a few per mille of each block's change
    for sl in (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 15)):
        assert np.linalg.norm(moved[sl] - lin[sl]) <= 5e-3 * np.linalg.norm(moved[sl]) + 1e-12


def test_short_run_filters_average_the_fixes_and_the_sigma_point_filters_equal_the_kalman_filter():
    sc = xpn.XpnScenario(duration_s=300.0, window_s=(100.0, 200.0))
    res = xpn.run_scenario(sc, 2, 0, ("ekf", "ckf", "rwckf"))
    get = {(r.quantity, r.filter): r.ours for r in res.rows}
    for f in ("ekf", "ckf", "rwckf"):
        # below the fix noise (25 m per axis, 43 m norm; 0.3 m/s, 0.52 m/s)
        assert get[("position RMSE, without", f)] < 25.0
        assert get[("velocity RMSE, without", f)] < 0.52
    # eq 47 is linear in the error: the CKF is the Kalman filter
    for q in ("position RMSE, with the added errors", "position RMSE, without", "velocity RMSE, without"):
        assert get[(q, "ckf")] == pytest.approx(get[(q, "ekf")], rel=1e-6)
    # error/sigma about 1 (NEES / 3 over 2 runs, over the window-free period)
    assert 0.2 < get[("ANEES position, without", "ekf")] < 3.0
    assert 0.2 < get[("ANEES velocity, without", "ekf")] < 3.0


def test_registered_with_the_papers_filters_and_runs():
    b = BENCHMARKS["paper001-xpn"]
    assert b.filters == ("ckf", "ukf", "sif", "aukf", "rwckf") and b.default_runs == 100


def test_bad_scenario_is_a_config_error():
    with pytest.raises(ConfigError, match="added"):
        xpn.XpnScenario(added="both")
    with pytest.raises(ConfigError, match="window_s"):
        xpn.XpnScenario(window_s=(200.0, 100.0))
    with pytest.raises(ConfigError, match="whole number"):
        xpn.XpnScenario(fix_period_s=0.25)


def test_worker_processes_give_the_same_table_and_the_nees_matches_a_per_fix_solve():
    """--jobs splits the runs over processes; the table is the one-process table to the bit.
    The batched NEES equals e^T P^-1 e solved fix by fix (oracle: np.linalg.solve per fix)."""
    sc = xpn.XpnScenario(duration_s=120.0, window_s=(40.0, 80.0))
    one = xpn.run_scenario(sc, 3, 5, ("ckf", "rwckf"))
    two = xpn.run_scenario(sc, 3, 5, ("ckf", "rwckf"), jobs=2)
    strip = [(r.quantity, r.filter, r.ours, r.note) for r in one.rows if r.unit != "s"]
    assert strip == [(r.quantity, r.filter, r.ours, r.note) for r in two.rows if r.unit != "s"]
    assert any("paired − ckf" in r.note for r in one.rows if r.filter == "rwckf")
    rec = xpn.XpnRecorder(np.zeros((4, 16)))
    rng = np.random.default_rng(1)
    for k in range(3):                                   # the 4th fix is never reached: NaN
        A = rng.standard_normal((6, 6))
        rec.err[k] = rng.standard_normal(6)
        rec.cov[k, 0], rec.cov[k, 1] = A[:3] @ A[:3].T + np.eye(3), A[3:] @ A[3:].T + np.eye(3)
    got = rec.nees()
    for k in range(3):
        for j in range(2):
            e = rec.err[k, 3 * j:3 * j + 3]
            assert got[k, j] == pytest.approx(e @ np.linalg.solve(rec.cov[k, j], e), rel=1e-12)
    assert np.isnan(got[3]).all()


def test_bench_cli_warns_of_a_long_run_and_passes_jobs(monkeypatch):
    """`navpp bench paper001-xpn` with the paper's 100 runs says how long it will take before it
    starts and hands --jobs to the benchmark; a benchmark that cannot split its runs says
    --jobs was ignored.  (The run function is replaced: the real one takes hours.)"""
    from dataclasses import replace

    from typer.testing import CliRunner

    from navpp import papers
    from navpp.cli import app
    from navpp.papers.registry import BenchResult

    seen = {}

    def fake(runs, seed, filters, jobs=1):
        seen.update(runs=runs, jobs=jobs, filters=filters)
        return BenchResult("paper001-xpn", xpn.TITLE, [], [], runs, seed)

    b = papers.BENCHMARKS["paper001-xpn"]
    monkeypatch.setitem(papers.BENCHMARKS, "paper001-xpn", replace(b, run=fake))
    res = CliRunner().invoke(app, ["bench", "paper001-xpn", "--jobs", "2"])
    assert res.exit_code == 0, res.output
    assert seen == {"runs": 100, "jobs": 2, "filters": b.filters}
    hours = 100 * xpn.CPU_S_PER_RUN / 3600
    assert f"about {hours:.1f} h of CPU" in res.stderr and "--runs N and --jobs N" in res.stderr
    assert papers.expected_cpu_s("paper001-xpn", 4, ["ckf"]) == pytest.approx(4 * xpn.CPU_S_PER_RUN / 5)
    res = CliRunner().invoke(app, ["bench", "paper001-xpn", "--runs", "2", "--filters", "ckf"])
    assert res.exit_code == 0 and "h of CPU" not in res.stderr and seen["jobs"] == 1
    res = CliRunner().invoke(app, ["bench", "paper003-turn", "--runs", "1", "--jobs", "2"])
    assert res.exit_code == 0, res.output
    assert "--jobs 2 ignored: paper003-turn runs in one process" in res.stdout
    res = CliRunner().invoke(app, ["bench", "paper003-turn", "--jobs", "0"])
    assert res.exit_code == 2
