"""The engine's loop, schedule, checks' findings and refusals, against oracles: the loop over a
linear model against the closed-form Kalman filter, the coasting stops against hand-placed
times, the findings' codes against navpp.findings.CODES."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from navpp import api
from navpp.engine import check_data
from navpp.engine.loop import EpochOutcome, run_epochs
from navpp.engine.schedule import Epoch, coast_stops, epochs
from navpp.engine.verdict import likely_cause, refusal
from navpp.errors import FilterDivergedError, RunRefused
from navpp.filters.base import GaussianState
from navpp.filters.ekf import EKF
from navpp.filters.linear import LinearMeasurement, LinearModel
from navpp.findings import CODES, Finding, code_of

PHI = np.array([[1.0, 1.0], [0.0, 1.0]])        # constant velocity, 1 s steps
Q = np.diag([0.01, 0.04])
H = np.array([[1.0, 0.0]])
R = np.array([[0.25]])


def _measurements(n: int) -> list[LinearMeasurement]:
    rng = np.random.default_rng(7)
    return [LinearMeasurement(float(k + 1), np.array([0.5 * (k + 1) + rng.normal(0.0, 0.5)]), H, R)
            for k in range(n)]


def _kalman(x, P, meas):
    """The closed-form Kalman filter (the oracle): x, P after each measurement."""
    out = []
    for m in meas:
        x, P = PHI @ x, PHI @ P @ PHI.T + Q
        S = H @ P @ H.T + m.R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (m.z - H @ x)
        P = (np.eye(2) - K @ H) @ P
        out.append((x, P))
    return out


class OneStage:
    """A source with the epoch's one measurement in stage 0."""

    def __init__(self, meas):
        self.meas = meas
        self.seen: list[tuple[int, int, np.ndarray]] = []

    def measurements(self, epoch, stage, state):
        self.seen.append((epoch.index, stage, state.x.copy()))
        return (self.meas[epoch.index],) if stage == 0 else None

    def observed(self, epoch, meas, update):
        return update.state


class Keep:
    """A recorder that keeps everything."""

    def __init__(self):
        self.predictions, self.updates, self.outcomes = [], [], []

    def predicted(self, epoch, prediction):
        self.predictions.append((epoch, prediction))

    def updated(self, epoch, meas, update):
        self.updates.append(update)

    def epoch_done(self, epoch, outcome: EpochOutcome):
        self.outcomes.append(outcome)


def test_loop_runs_the_kalman_filter_over_a_schedule():
    meas = _measurements(20)
    start = GaussianState(0.0, np.zeros(2), np.eye(2))
    rec = Keep()
    last = run_epochs(EKF(), LinearModel(PHI, Q), start, [Epoch(m.t, k) for k, m in enumerate(meas)],
                      OneStage(meas), rec)
    oracle = _kalman(start.x, start.P, meas)
    assert len(rec.outcomes) == len(rec.predictions) == len(rec.updates) == 20
    for out, (x, P) in zip(rec.outcomes, oracle):
        assert out.applied and not out.reset and out.prior_used is out.prior
        np.testing.assert_allclose(out.state.x, x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.state.P, P, rtol=0, atol=1e-12)
    assert last is rec.outcomes[-1].state and last.t == 20.0


def test_coasting_stops_only_predict_and_the_check_skips_them():
    meas = _measurements(3)
    schedule = [Epoch(0.5, coast=True), Epoch(1.0, 0), Epoch(2.0, 1), Epoch(2.5, coast=True), Epoch(3.0, 2)]
    checked = []
    rec, src = Keep(), OneStage(meas)
    run_epochs(EKF(), LinearModel(PHI, Q), GaussianState(0.0, np.zeros(2), np.eye(2)), schedule, src, rec,
               lambda state, t: checked.append(t))
    assert [e.t for e, _ in rec.predictions] == [0.5, 1.0, 2.0, 2.5, 3.0]
    assert [s[:2] for s in src.seen] == [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)]
    # after each measurement epoch's time update and after each update; never at a coasting stop
    assert checked == [1.0, 1.0, 2.0, 2.0, 3.0, 3.0]


def test_a_stage_sees_the_state_the_previous_stage_and_the_source_left():
    meas = _measurements(1)

    class TwoStages(OneStage):
        def measurements(self, epoch, stage, state):
            self.seen.append((epoch.index, stage, state.x.copy()))
            return (self.meas[0],) if stage < 2 else None

        def observed(self, epoch, meas, update):          # a reset of the source's own
            return GaussianState(update.state.t, update.state.x + 100.0, update.state.P)

    rec, src = Keep(), TwoStages(meas)
    run_epochs(EKF(), LinearModel(PHI, Q), GaussianState(0.0, np.zeros(2), np.eye(2)), [Epoch(1.0, 0)], src, rec)
    np.testing.assert_array_equal(src.seen[1][2], rec.updates[0].state.x + 100.0)
    np.testing.assert_array_equal(rec.outcomes[0].state.x, rec.updates[1].state.x + 100.0)
    assert rec.outcomes[0].prior_used is rec.outcomes[0].prior       # the first applied update's prior


def test_the_fast_path_is_asked_once_for_an_epoch_it_leaves():
    """A fast path that runs epochs two at a time but leaves epoch 3 (and cuts a stretch short at
    epoch 6): the generic loop takes epoch 3 at once, the fast path goes on at epochs 4 and 6, and
    the run is the generic loop's."""
    meas = _measurements(8)
    schedule = [Epoch(m.t, k) for k, m in enumerate(meas)]
    generic = Keep()
    oracle = run_epochs(EKF(), LinearModel(PHI, Q), GaussianState(0.0, np.zeros(2), np.eye(2)), schedule,
                        OneStage(meas), generic)

    class TwoAtATime:
        def __init__(self) -> None:
            self.asked: list[int] = []

        def run(self, i, state, stop):
            self.asked.append(i)
            if i == 3:
                return i, state, True
            j = min(i + 2, 3 if i < 3 else stop, stop)
            return j, generic.outcomes[j - 1].state, j == 3

    fast, rec = TwoAtATime(), Keep()
    last = run_epochs(EKF(), LinearModel(PHI, Q), GaussianState(0.0, np.zeros(2), np.eye(2)), schedule,
                      OneStage(meas), rec, fast=fast)
    assert fast.asked == [0, 2, 4, 6]
    assert [e.index for e, _ in rec.predictions] == [3]
    np.testing.assert_array_equal(last.x, oracle.x)


def test_a_rejected_measurement_applies_nothing():
    far = [LinearMeasurement(1.0, np.array([1e6]), H, R)]
    rec = Keep()
    run_epochs(EKF(gate_probability=0.999), LinearModel(PHI, Q), GaussianState(0.0, np.zeros(2), np.eye(2)),
               [Epoch(1.0, 0)], OneStage(far), rec)
    (out,) = rec.outcomes
    assert not out.applied and out.prior_used is None and out.state is out.prior


def test_coasting_stops_every_knot_until_the_next_epoch():
    assert [e.t for e in coast_stops(0.0, 3.2)] == [1.0, 2.0]          # 1.2 s left: no stop
    imu_t = np.array([0.0, 1.6, 3.2, 5.0])
    stops = epochs(0.0, 5.0, np.array([3.2]), np.array([0]), np.array([True]), imu_t)
    assert [(e.t, e.coast) for e in stops] == [(1.0, True), (2.0, True), (3.2, False), (4.2, True), (5.0, True)]
    (fix,) = [e for e in stops if not e.coast]
    assert (fix.index, fix.fix, fix.constraints, fix.sample) == (0, 0, True, 2)
    # no final stop when the last epoch is at the end; a sample only where a stamp equals the time
    stops = epochs(0.0, 1.0, np.array([0.5, 1.0]), np.array([-1, 0]), np.array([True, False]), np.array([0.0, 1.0]))
    assert [(e.t, e.sample) for e in stops] == [(0.5, -1), (1.0, 1)]


def test_every_finding_code_in_navpp_is_listed():
    used = set()
    for p in Path(api.__file__).parent.rglob("*.py"):
        used |= set(re.findall(r'Finding\(\s*"([a-z0-9-]+)"', p.read_text()))
    assert used and not used - set(CODES), used - set(CODES)


def test_data_checks_carry_codes():
    t = np.arange(0.0, 10.0, 0.01)
    accel = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    accel[500:506, 2] = 19.6                             # clipped
    t[700:] += 0.5                                       # a gap of 50 periods
    rec = SimpleNamespace(source="log", imu=SimpleNamespace(t=t, gyro=np.zeros((t.size, 3)), accel=accel),
                          gnss=SimpleNamespace(t=np.arange(0.0, 10.5, 1.0)))
    assert sorted(code_of(w) for w in check_data(rec)) == ["imu-gap", "imu-saturated"]


def _gnss_track():
    t = np.arange(0.0, 30.0, 1.0)
    return SimpleNamespace(t=t, lat_deg=48.0 + 1e-5 * t, lon_deg=11.0 + 1e-5 * t, alt=500.0 + 0 * t, std_enu=None)


def test_the_likely_cause_is_found_by_code_not_by_text():
    from navpp.config import Config

    cfg = Config()
    rec = SimpleNamespace(source="log", gnss=_gnss_track())
    cause, _ = likely_cause(rec, cfg, [Finding("imu-saturated", "anything at all")])
    assert cause == "check a saturated IMU"
    cause, others = likely_cause(rec, cfg, ["log: IMU gyro: 3 samples look saturated"])   # a plain line
    assert cause == "check the IMU's units and axes ([imu] mounting_rpy_deg)"
    assert others[0].startswith("check the lever arm")


def test_a_refusal_is_a_run_refused_with_the_other_causes_last():
    from navpp.config import Config

    exc = refusal(SimpleNamespace(source="log", gnss=_gnss_track()), Config(), "ekf diverged: x", ["a note"],
                  [Finding("imu-gap", "log: a gap")], cause="check y")
    assert isinstance(exc, RunRefused) and isinstance(exc, FilterDivergedError)
    assert str(exc) == "log: ekf diverged: x; likely: check y"
    assert [code_of(w) for w in exc.warnings] == ["imu-gap", "refusal-causes"] and exc.notes == ("a note",)


def test_a_filter_divergence_keeps_its_reason_apart():
    exc = FilterDivergedError.in_filter("ckf", "covariance is not positive definite at t=1.000 s")
    assert str(exc) == "ckf: covariance is not positive definite at t=1.000 s"
    assert exc.why == "covariance is not positive definite at t=1.000 s"
    with pytest.raises(FilterDivergedError):
        raise exc
