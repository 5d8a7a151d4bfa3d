"""Land-vehicle aiding (issue 8): GNSS velocity, ZUPT, ZARU, NHC and the standstill detector.

Oracles: finite differences through the model's ⊞ for every Jacobian; the simulator's truth
(its speed says when the car stands, its errors and trajectory score every run); the same run
with the aid turned off.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scenarios import load_benchmark
from typer.testing import CliRunner

from navpp import api, engine
from navpp.aiding import ZUPT_RUN, Aiding, StillRuns, ZuptCheck, vehicle_matrix
from navpp.cli import app
from navpp.config import config_from_dict
from navpp.errors import ConfigError
from navpp.filters import FILTERS
from navpp.ins.aids import GnssVelocity, NonHolonomic, ZeroRate, ZeroVelocity
from navpp.ins.aids.standstill import StandstillSettings, speed_allows, still_mask
from navpp.ins.model import plus
from navpp.metrics import compute_metrics
from navpp.simulate import SimulationSpec, simulate


def _nominal(seed=0):
    rng = np.random.default_rng(seed)
    x = np.zeros(16)
    q = rng.normal(size=4)
    x[0:4] = q / np.linalg.norm(q)
    x[4:7] = [8.0, -5.0, 0.3]
    x[7], x[8], x[9] = 0.7, 0.1, 300.0
    x[10:13] = [1e-3, -2e-3, 5e-4]
    x[13:16] = 0.01
    return x


AIDS = [
    GnssVelocity.at(0.0, np.zeros(3), np.ones(3), np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.3, 1.2])),
    NonHolonomic.at(0.0, (0.1, 0.1), vehicle_matrix((1.0, 2.0, 3.0)), np.array([0.1, -0.2, 0.3]),
                    np.array([-1.0, 0.2, -0.3])),
    ZeroRate.at(0.0, np.zeros(3), 0.2, 1e-3, 0.0),
    ZeroVelocity.at(0.0, 0.1),
]


@pytest.mark.parametrize("meas", AIDS, ids=lambda m: m.kind)
def test_jacobian_is_the_derivative_through_plus(meas):
    x = _nominal()
    H = meas.jacobian(x)
    Hn = np.zeros_like(H)
    eps = 1e-6
    for i in range(15):
        d = np.zeros(15)
        d[i] = eps
        Hn[:, i] = (meas.model(plus(x, d), meas.p) - meas.model(plus(x, -d), meas.p)) / (2 * eps)
    np.testing.assert_allclose(H, Hn, rtol=0, atol=1e-8 * max(1.0, np.abs(H).max()))
    assert H.shape == (len(meas.axes), 15) and meas.R.shape == (len(meas.axes),) * 2
    # sigma points: small points map through the Jacobian
    dX = 1e-4 * np.random.default_rng(1).normal(size=(30, 15))
    np.testing.assert_allclose(meas.predict_points(x, dX), dX @ H.T, rtol=0, atol=1e-6)


def test_models_by_hand():
    """Closed-form values: a level car heading north at 10 m/s."""
    x = np.zeros(16)
    x[0] = 1.0                                   # body = ENU: x forward = east
    x[4:7] = [10.0, 0.0, 0.0]                    # moving along body x
    x[7] = np.radians(45.0)
    nhc = NonHolonomic.at(0.0, (0.1, 0.1), np.eye(3), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(nhc.innovation_at(x), [0.0, 0.0], atol=1e-12)
    x[4:7] = [10.0, 1.0, -0.5]                   # sliding left 1 m/s, sinking 0.5 m/s
    np.testing.assert_allclose(nhc.innovation_at(x), [-1.0, 0.5], atol=1e-12)
    # a turn at 0.5 rad/s with the antenna 2 m ahead: 1 m/s to the left (north) at the antenna
    vel = GnssVelocity.at(0.0, np.array([10.0, 1.0, -0.5]), np.ones(3), np.array([0.0, 0.0, 0.5]),
                          np.array([2.0, 0.0, 0.0]))
    np.testing.assert_allclose(vel.model(x, vel.p), [10.0, 2.0, -0.5], atol=1e-12)
    # at rest the gyro measures its bias plus the Earth rate, [0, W cos 45, W sin 45] in ENU
    x[10:13] = [1e-4, 0.0, -1e-4]
    zaru = ZeroRate.at(0.0, np.zeros(3), 1.0, 0.0, 0.0)
    w = 7.2921151467e-5 * np.sqrt(0.5)
    np.testing.assert_allclose(zaru.model(x, zaru.p), [1e-4, w, w - 1e-4], atol=1e-15)


@pytest.fixture(scope="module")
def drive():
    """A 300 s automotive drive (still 30 s) with GNSS velocity (0.02 m/s): stops at 220-230 s."""
    return simulate(SimulationSpec(duration_s=300.0, still_s=30.0, seed=2, gnss_velocity=True,
                                   gnss_std_vel_mps=0.02))


def _run(rec, name="ekf", **sections):
    cfg = config_from_dict({"imu": {"preset": "automotive"}, **sections}, "test")
    res = engine.run(rec, cfg, api.make_filter(name, cfg))
    m = compute_metrics(res.solution, rec.reference, filter_name=name, log="sim", reference="truth",
                        runtime_s=res.runtime_s, imu_samples=len(rec.imu), gnss_epochs=res.gnss_epochs,
                        gnss_rejected=res.gnss_rejected, updates=res.updates)
    return res, m


def test_zupt_check_vetoes_a_run_whose_innovations_keep_one_direction():
    """The mean of the last ZUPT_RUN normalised innovations beyond ZUPT_Z sigmas vetoes the run;
    a new run starts an empty ring, and a vetoed run's ring is emptied."""
    check = ZuptCheck()
    drift = np.array([0.0, 2.0, 0.0])                   # 2 sigma each: mean 2 * sqrt(10) = 6.3 sigma
    assert not any(check.add(4, drift) for _ in range(ZUPT_RUN - 1))
    assert not check.add(5, drift) and check.run == 5 and len(check.z) == 1       # another run
    assert not any(check.add(5, drift) for _ in range(ZUPT_RUN - 2))
    assert check.add(5, drift) and check.vetoed_run == 5 and check.z == []
    white = ZuptCheck()
    assert not any(white.add(1, np.array([1.0, -1.0, 0.5]) * (-1) ** k) for k in range(3 * ZUPT_RUN))
    assert white.vetoed_run == -1 and len(white.z) == ZUPT_RUN


def test_standstill_detector_finds_the_stops(drive):
    rec = drive.recording()
    speed = np.linalg.norm(drive.trajectory.state(rec.imu.t)["vel_enu"], axis=1)
    mask = still_mask(rec.imu.t, rec.imu.gyro, rec.imu.accel, np.radians(1.0) / 60.0, 0.05 / 60.0,
                      StandstillSettings())
    stopped = speed < 1e-6
    inner = stopped & np.roll(stopped, 125) & np.roll(stopped, -125)      # 1 s inside a stop
    assert mask[inner].mean() > 0.9
    # never while turning; smooth straight motion can be as quiet as a stop for a simulated IMU
    # (no engine vibration): the engine's speed gate handles that (next test)
    turning = np.abs(rec.imu.gyro[:, 2]) > np.radians(2.0)
    assert turning.any() and not mask[turning].any()


def test_zupt_only_where_the_car_stands(drive):
    """The engine's speed gate keeps constant-speed cruising (as quiet as a stop for a simulated
    IMU) out: the ZUPTs applied match the constraint epochs the truth says are at rest."""
    rec = drive.recording()
    res, _ = _run(rec)
    al_t = res.alignment.t
    grid = np.arange(np.floor(al_t / 0.2) + 1, 300.0 / 0.2 + 1) * 0.2
    speed = np.linalg.norm(drive.trajectory.state(grid)["vel_enu"], axis=1)
    at_rest = int(np.count_nonzero(speed < 1e-6))
    applied = res.updates["zupt"]["applied"]
    assert 0.8 * at_rest <= applied <= at_rest, (applied, at_rest)
    assert res.updates["zaru"]["applied"] >= 0.8 * at_rest - 5


def test_gnss_velocity_is_used_when_present_and_improves_the_solution(drive):
    rec = drive.recording()
    with_v, m_v = _run(rec)
    _, m_p = _run(rec, gnss={"use_velocity": False})
    assert m_v["updates"]["gnss_velocity"]["applied"] == with_v.gnss_epochs
    assert "gnss_velocity" not in m_p["updates"]
    def h(m):
        return m["position_m"]["horizontal"]["rmse"]
    assert h(m_v) < 0.5 * h(m_p), (h(m_v), h(m_p))
    assert m_v["velocity_mps"]["horizontal"]["rmse"] < 0.3 * m_p["velocity_mps"]["horizontal"]["rmse"]
    d = with_v.diagnostics
    assert np.all(d.vel_accepted == 1.0) and np.all(np.isfinite(d.vel_nu))
    # the velocity innovations are consistent: NIS near its 3 dof mean
    assert 1.5 < np.mean(d.vel_nis) < 4.5


@pytest.mark.slow     # a 760-s drive run twice; the quick run keeps NHC and ZUPT across 30-s outages in
#                       test_mounting_is_estimated_and_a_wrong_one_is_warned (their effect: here)
def test_nhc_and_zupt_bridge_outages():
    """A 15-minute drive, outages at 200, 450 and 700 s (a turn and a dip; a stop; a hill):
    the error at each outage's end with NHC + ZUPT against the same run without them."""
    rec = simulate(SimulationSpec(duration_s=760.0, seed=2)).recording()
    rec, _ = api.apply_outages(rec, [(200.0, 30.0), (450.0, 30.0), (700.0, 30.0)], "sim")
    outs = [(200.0, 30.0), (450.0, 30.0), (700.0, 30.0)]
    ends = []
    for veh in ({"type": "none", "zupt": False, "zaru": False}, {"type": "car"}):
        cfg = config_from_dict({"imu": {"preset": "automotive"}, "vehicle": veh}, "test")
        res = engine.run(rec, cfg, api.make_filter("ekf", cfg))
        m = compute_metrics(res.solution, rec.reference, filter_name="ekf", log="", reference="", runtime_s=0,
                            imu_samples=0, gnss_epochs=0, gnss_rejected=0, outages=outs)
        ends.append([w["horizontal_m"]["end"] for w in m["outages"]])
    ratio = np.median(ends[1]) / np.median(ends[0])
    assert ratio <= 0.4, ends


#: the default run's CPU budget: the EKF checks the aids' plumbing and the UKF the sigma-point one
#: (the adaptive filters with aids: test_adaptive_filters_learn_r_from_gnss_position_only); the
#: other filters run with the slow tests
QUICK_FILTERS = ("ekf", "ukf")


@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n in QUICK_FILTERS else [pytest.mark.slow])
                                  for n in sorted(FILTERS)])
def test_every_filter_applies_every_aid(drive, name):
    rec = drive.recording()
    res, m = _run(rec, name, vehicle={"type": "car"})
    for kind in ("gnss_position", "gnss_velocity", "zupt", "zaru", "nhc"):
        assert res.updates[kind]["applied"] > 0, (name, kind, res.updates)
    # the RWCKF's random weights cost it accuracy (README, Filters); it must still run and converge
    assert m["position_m"]["horizontal"]["rmse"] < (1.5 if name == "rwckf" else 0.5), name


def test_adaptive_filters_learn_r_from_gnss_position_only(drive):
    """The AEKF's learnt GNSS R is the same whether or not NHC updates run in between (they
    are applied with their own R and never learnt from)."""
    rec = drive.recording()
    a, _ = _run(rec, "aekf", vehicle={"type": "car", "zupt": False, "zaru": False}, gnss={"use_velocity": False})
    b, _ = _run(rec, "aekf", vehicle={"type": "none", "zupt": False, "zaru": False}, gnss={"use_velocity": False})
    ra, rb = a.diagnostics.r_std, b.diagnostics.r_std
    assert ra.shape == rb.shape
    assert np.median(np.abs(ra - rb) / rb) < 0.05


def test_zaru_makes_the_vertical_gyro_bias_observable_at_a_stop():
    """Consumer IMU, GNSS removed over the stop at 220-230 s (a car park): at the stop's end the
    vertical gyro bias's 1-sigma with ZARU is a fraction of that without (the heading is then
    unobservable from anything else)."""
    sim = simulate(SimulationSpec(duration_s=240.0, still_s=30.0, seed=5, preset="consumer"))
    rec, _ = api.apply_outages(sim.recording(), [(212.0, 20.0)], "sim")
    out = {}
    for zaru in (False, True):
        cfg = config_from_dict({"imu": {"preset": "consumer"}, "vehicle": {"zaru": zaru}}, "test")
        res = engine.run(rec, cfg, api.make_filter("ekf", cfg))
        k = int(np.searchsorted(res.biases.t, 232.0))
        out[zaru] = (res.biases.gyro_std[k, 2], res.biases.gyro[k, 2], res.updates.get("zaru", {}).get("applied", 0))
    assert out[False][2] == 0 and out[True][2] > 30
    # measured 0.59: a 10 s stop with a consumer gyro (ARW 0.5 deg/sqrt(h)) averages the rate to ~10 deg/h
    assert out[True][0] < 0.7 * out[False][0], out
    truth = sim.sensor_errors["gyro_bias"][2] + sim.sensor_errors["gyro_gauss_markov"][
        np.searchsorted(sim.imu.t, 230.0), 2]
    assert abs(out[True][1] - truth) < 3.0 * out[True][0] + 1e-5


def test_each_aid_can_be_turned_off(drive):
    rec = drive.recording()
    res, _ = _run(rec, vehicle={"type": "car", "nhc": False, "zupt": False, "zaru": False},
                  gnss={"use_velocity": False})
    assert set(res.updates) == {"gnss_position"}
    assert res.diagnostics.vel_nu is None


def test_constraints_ride_on_gnss_epochs_and_fill_outages():
    cfg = config_from_dict({"vehicle": {"type": "car", "rate_hz": 5.0}}, "test")
    t = np.arange(0.0, 20.0, 0.01)
    z = np.zeros((t.size, 3))
    a = Aiding(cfg, t, z, z + [0, 0, 9.8], 0.0, 0.0, type("G", (), {"vel_enu": None})(), np.arange(0))
    tg = np.concatenate([np.arange(1.0, 5.0, 0.2), np.arange(10.0, 12.0, 1.0)])
    times, fix, cons = a.schedule(0.5, 12.0, tg)
    assert np.all(np.diff(times) > 0)
    assert set(fix[fix >= 0]) == set(range(tg.size))
    own = times[fix < 0]
    # no extra epoch where 5 Hz GNSS carries the constraints; 5 Hz epochs in the gaps
    assert not np.any((own > 1.0) & (own < 4.8 - 1e-9))
    assert np.allclose(np.diff(own[(own > 5.0) & (own < 9.9)]), 0.2)
    assert cons[fix >= 0].sum() >= 20


def test_config_validation():
    with pytest.raises(ConfigError, match=r"\[vehicle\] nhc_std_mps must be > 0"):
        config_from_dict({"vehicle": {"nhc_std_mps": [0.1, 0.0]}}, "x")
    with pytest.raises(ConfigError, match=r"\[vehicle\] zaru must be true or false"):
        config_from_dict({"vehicle": {"zaru": 1}}, "x")
    with pytest.raises(ConfigError, match=r"\[gnss\] use_velocity must be true or false"):
        config_from_dict({"gnss": {"use_velocity": "no"}}, "x")
    with pytest.raises(ConfigError, match="rate_hz"):
        config_from_dict({"vehicle": {"rate_hz": 0}}, "x")


def test_counts_in_metrics_diagnostics_and_cli(tmp_path, drive):
    from navpp.simulate import write_csv_log

    log = tmp_path / "log"
    write_csv_log(drive, log)
    (log / "navpp.toml").write_text('[imu]\npreset = "automotive"\n[vehicle]\ntype = "car"\n')
    r = CliRunner().invoke(app, ["process", str(log), "--out", str(tmp_path / "o"), "--format", "csv,mcap"])
    assert r.exit_code == 0, r.output
    assert "aiding updates applied (rejected): gnss_velocity" in r.output and "nhc" in r.output
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert set(m["updates"]) == {"gnss_position", "gnss_velocity", "zupt", "zaru", "nhc"}
    assert "## Measurement updates" in (tmp_path / "o" / "metrics.md").read_text()
    head = (tmp_path / "o" / "diagnostics.csv").read_text().splitlines()[0].split(",")
    assert head[10:15] == ["nu_ve", "nu_vn", "nu_vu", "nis_vel", "vel_accepted"]
    # the MCAP diagnostics carry them too, by name, for Foxglove
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(tmp_path / "o" / "trajectory.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msg = next(m for _, ch, _, m in reader.iter_decoded_messages(topics=["/navpp/diagnostics"])
                   if ch.topic == "/navpp/diagnostics")
    assert list(msg.names[:5]) == ["nu_ve", "nu_vn", "nu_vu", "nis_vel", "vel_accepted"]


@pytest.mark.slow
def test_issue_targets_velocity_and_outages():
    """The issue's measured targets (benchmarks/bench_aiding.py, three 15-minute drives): GNSS
    velocity at 0.02 m/s brings the horizontal RMSE to <= 0.25 x positions only (0.244); NHC +
    ZUPT bring the median outage-end error to <= 0.4 x (0.09 over a turn, a stop and a hill)."""
    bench = load_benchmark("bench_aiding")
    assert bench.velocity(3, "ekf") <= 0.25
    assert bench.outages(3, "ekf")["turn-stop-hill"] <= 0.4


def test_an_uncertain_speed_allows_no_zupt():
    s = StandstillSettings(max_speed=0.2)
    assert speed_allows(0.05, 0.05, s)
    assert not speed_allows(0.3, 0.05, s)          # moving
    assert not speed_allows(0.05, 0.5, s)          # not known to be still: an inflated covariance


@pytest.mark.slow
def test_a_fading_filter_with_zupt_stays_sane():
    """The AUKF inflates its covariance when it fades; with a lenient speed gate (speed below
    3 sigma) that let ZUPTs in while cruising and the filter broke down (726 m horizontal RMSE on
    this 15-minute drive); the gate now needs a small sigma too (2.3 m with the outages)."""
    rec = simulate(SimulationSpec(duration_s=900.0, seed=2)).recording()
    rec, _ = api.apply_outages(rec, [(200.0, 30.0), (450.0, 30.0), (700.0, 30.0)], "sim")
    res, m = _run(rec, "aukf")
    assert res.gnss_rejected < 10 and m["position_m"]["horizontal"]["rmse"] < 3.0, m["position_m"]["horizontal"]


def test_smoothing_with_every_aid(drive):
    """Several updates at one node (GNSS position and velocity, NHC, ZUPT, ZARU): the smoother
    takes the node's first prior and last posterior, and still improves on the forward run."""
    rec = drive.recording()
    cfg = config_from_dict({"imu": {"preset": "automotive"}, "vehicle": {"type": "car"}}, "test")
    res = engine.run(rec, cfg, api.make_filter("ekf", cfg), smooth=True)
    assert res.smoothed.breaks == 0
    out = []
    for sol in (res.solution, res.smoothed.solution):
        m = compute_metrics(sol, rec.reference, filter_name="ekf", log="", reference="", runtime_s=0, imu_samples=0,
                            gnss_epochs=0, gnss_rejected=0)
        out.append((m["position_m"]["horizontal"]["rmse"], m["velocity_mps"]["horizontal"]["rmse"]))
    assert out[1][0] < 0.8 * out[0][0] and out[1][1] < out[0][1], out


@pytest.fixture(scope="module")
def misaligned():
    """A 600 s drive whose IMU is turned against the vehicle: its axes are the vehicle's rotated
    by pitch -1.5 deg and yaw +2 deg, so the vehicle frame is, relative to the IMU body frame,
    pitch +1.5 and yaw -2 deg (to first order); two 30 s outages."""
    from dataclasses import replace

    from navpp.ins.attitude import rpy_deg_to_dcm
    from navpp.recording import ImuData

    rec = simulate(SimulationSpec(duration_s=600.0, seed=3)).recording()
    R = rpy_deg_to_dcm((0.0, -1.5, 2.0))
    rec = replace(rec, imu=ImuData(rec.imu.t, rec.imu.gyro @ R, rec.imu.accel @ R))
    return rec


def _outage_run(rec, mounting):
    """The EKF with two 30 s outages and the vehicle mounting ``mounting``.  The GNSS errors are
    taken as white: the wrong mounting's correlated innovations would otherwise repeat that run
    with Gauss-Markov states and their 10-pass search (test_gnss_error.py's subject), 9 s of CPU;
    the runs with the right mounting are the same either way."""
    outs = [(200.0, 30.0), (450.0, 30.0)]
    cut, _ = api.apply_outages(rec, outs, "sim")
    cfg = config_from_dict({"imu": {"preset": "automotive"}, "gnss": {"error_model": "white"},
                            "vehicle": {"type": "car", "mounting_rpy_deg": mounting}}, "test")
    res = engine.run(cut, cfg, api.make_filter("ekf", cfg))
    m = compute_metrics(res.solution, rec.reference, filter_name="ekf", log="", reference="", runtime_s=0,
                        imu_samples=0, gnss_epochs=0, gnss_rejected=0, outages=outs)
    return res, m


def test_mounting_is_estimated_and_a_wrong_one_is_warned(misaligned):
    from navpp.ins.aids.mounting import estimate_mounting

    auto, m_auto = _outage_run(misaligned, "auto")
    (note,) = [n for n in auto.notes if "vehicle mounting estimated" in n]
    assert "pitch +1.5" in note and "yaw -2.0" in note, note
    known, m_known = _outage_run(misaligned, (0.0, 1.5, -2.0))
    wrong, m_wrong = _outage_run(misaligned, (0.0, 0.0, 0.0))
    h = lambda m: m["position_m"]["horizontal"]["rmse"]  # noqa: E731
    assert h(m_auto) < 1.2 * h(m_known) and h(m_wrong) > 5.0 * h(m_known), (h(m_auto), h(m_known), h(m_wrong))
    # the constraint on the wrong mounting and the GNSS disagree: the warning names the vehicle
    # mounting (NHC's own gate, or the GNSS's when the recovery lets NHC hold)
    assert any(("nhc updates" in w or "GNSS fixes" in w) and '[vehicle] mounting_rpy_deg = "auto"' in w
               for w in wrong.warnings), wrong.warnings
    assert not any("nhc updates" in w for w in auto.warnings)
    # the estimator itself, on the forward solution of the known-mounting run
    est = estimate_mounting(known.solution.t, known.solution.vel_enu, known.solution.rph_deg)
    assert abs(est.pitch_deg - 1.5) < 0.2 and abs(est.yaw_deg + 2.0) < 0.2 and est.seconds > 100.0


def test_mounting_auto_without_enough_motion_is_warned(sim_log_dir, monkeypatch):
    from navpp.ins.aids import mounting

    t = np.arange(0.0, 30.0, 0.1)                     # 30 s, but only 8 s faster than 5 m/s
    vel = np.zeros((t.size, 3))
    vel[:, 1] = np.where(t > 22.0, 8.0, 2.0)
    assert mounting.estimate_mounting(t, vel, np.zeros((t.size, 3))) is None
    monkeypatch.setattr(mounting, "estimate_mounting", lambda *a, **k: None)
    cfg = config_from_dict({"vehicle": {"type": "car", "mounting_rpy_deg": "auto"}}, "test")
    res = engine.run(api.read_log(sim_log_dir, cfg), cfg, api.make_filter("ekf", cfg))
    assert not any("estimated" in n for n in res.notes)
    assert any('mounting_rpy_deg = "auto": less than 10 s of fast straight driving' in w for w in res.warnings)


@pytest.mark.parametrize("mask", ["runs", "alternating", "all still", "none still", "edges"])
def test_still_run_numbers_are_the_cumulative_sum_of_moving_samples(mask):
    """Oracle: ``np.cumsum(~still)``, the numbering the runs' bounds stand for, at every sample,
    as arrays and one at a time (in order, backwards and shuffled)."""
    rng = np.random.default_rng(4)
    still = {"runs": np.repeat(rng.random(300) < 0.4, 11), "alternating": np.arange(501) % 2 == 0,
             "all still": np.ones(9, bool), "none still": np.zeros(9, bool),
             "edges": np.array([True, True, False, False, True, False, True, True])}[mask]
    want = np.cumsum(~still)
    runs = StillRuns(still)
    got = runs.number(np.arange(still.size))
    assert got.dtype == want.dtype and np.array_equal(got, want)
    for order in (np.arange(still.size), np.arange(still.size)[::-1], rng.permutation(still.size)):
        assert [runs.number_at(int(i)) for i in order] == [int(v) for v in want[order]]
