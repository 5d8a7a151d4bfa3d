"""Bad inputs, round two (issue 15), timing and jumps: lone bad stamps (t = 0 among unix stamps,
a header stamp of 0), an IMU gap longer than the INS can bridge, GNSS fixes displaced for good,
and the compare watchdog.  Rows for the harness (tests/badinputs.py) first, then plain tests of
what must keep working (a lone outlier fix is still the gate's, a short gap is still bridged)."""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import numpy as np
import pytest
from badinputs import DRIVE, Case, copy_drive, edit_csv, params, run_case, run_in_process, run_navpp

from navpp.recording import lone_stamp

T0 = 1_700_000_000.0


def _set_t(line: str, t: float) -> str:
    return f"{t:.6f}," + line.split(",", 1)[1]


def _shift_from(lines: list[str], t_from: float, shift: float) -> list[str]:
    """Every row at or after ``t_from`` (s from the log start) ``shift`` s later."""
    out = lines[:1]
    for ln in lines[1:]:
        t = float(ln.split(",", 1)[0])
        out.append(_set_t(ln, t + shift) if t - T0 >= t_from else ln)
    return out


def _move_lon(line: str, dlon: float) -> str:
    c = line.split(",")
    c[2] = f"{(float(c[2]) + dlon + 180.0) % 360.0 - 180.0:.9f}"
    return ",".join(c)


#: 16,000 km along the parallel at 45 deg N, in degrees of longitude
DLON_16000_KM = 16_000e3 / (111_320.0 * math.cos(math.radians(45.0)))


def _t0_first_row(work):
    log = copy_drive(work)
    edit_csv(log / "imu.csv", lambda ls: [ls[0], _set_t(ls[1], 0.0), *ls[2:]])
    return ["process", str(log), "--out", str(work / "out")]


def _far_stamp_in_the_middle(work):
    log = copy_drive(work)
    # line 5002 (row 5001) stamped 1000 s late: the old check blamed line 5003 ("time goes backwards")
    edit_csv(log / "imu.csv", lambda ls: [*ls[:5001], _set_t(ls[5001], float(ls[5001].split(",")[0]) + 1000.0),
                                          *ls[5002:]])
    return ["process", str(log), "--out", str(work / "out")]


def _mcap_with_stamp(work, k: int) -> Path:
    """sample_data/drive as a ROS 2 MCAP whose IMU message ``k`` has header stamp 0 (log time kept)."""
    from test_formats import FIX_TYPE_ROS2, IMU_TYPE_ROS2, write_mcap

    from navpp.io import roswrite
    from navpp.io.csv import read_csv_log

    rec = read_csv_log(DRIVE)
    imu_ns = rec.t0_ns + np.round(rec.imu.t * 1e9).astype(np.int64)
    g_ns = rec.t0_ns + np.round(rec.gnss.t * 1e9).astype(np.int64)
    header = imu_ns.copy()
    header[k] = 0
    g = rec.gnss
    streams = [("/imu/data", IMU_TYPE_ROS2, imu_ns,
                roswrite.encode_imu(header, rec.imu.gyro, rec.imu.accel, encoding="cdr")),
               ("/gnss/fix", FIX_TYPE_ROS2, g_ns,
                roswrite.encode_navsatfix(g_ns, g.lat_deg, g.lon_deg, g.alt, encoding="cdr", cov_diag=g.std_enu ** 2))]
    (work / "navpp.toml").write_text((DRIVE / "navpp.toml").read_text())
    return write_mcap(work / "drive.mcap", streams)


def _mcap_stamp_zero(k: int):
    def build(work):
        path = _mcap_with_stamp(work, k)
        return ["process", str(path), "--config", str(work / "navpp.toml"), "--out", str(work / "out")]
    return build


def _hour_gap(work):
    log = copy_drive(work)
    for name in ("imu.csv", "gnss.csv", "reference.csv"):     # the logger paused for an hour
        edit_csv(log / name, lambda ls: _shift_from(ls, 150.0, 3600.0))
    return ["process", str(log), "--out", str(work / "out")]


def _half_the_fixes_moved(work):
    log = copy_drive(work)
    edit_csv(log / "gnss.csv", lambda ls: ls[:751] + [_move_lon(x, DLON_16000_KM) for x in ls[751:]])
    return ["process", str(log), "--out", str(work / "out")]


CASES = [
    Case("imu-t0-first-csv-row", _t0_first_row, ("imu.csv", "line 2", "t=0.0", "lone bad stamp")),
    Case("imu-stamp-far-ahead-mid-log", _far_stamp_in_the_middle, ("imu.csv", "line 5002", "lone bad stamp")),
    Case("mcap-header-stamp-0-first", _mcap_stamp_zero(0),
         ("drive.mcap", "'/imu/data'", "message 0 (t = 0.000000000 s)", "lone bad stamp", '[time] source = "log"')),
    Case("mcap-header-stamp-0-mid-log", _mcap_stamp_zero(9000),
         ("drive.mcap", "'/imu/data'", "message 9000 (t = 0.000000000 s)", "lone bad stamp"), slow=True),
    Case("half-the-fixes-moved-16000-km", _half_the_fixes_moved,
         ("GNSS", "t = 150.000 s", "stay displaced", "inconsistent")),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


# --------------------------------------------------------------------------- compare


def test_compare_with_a_t0_log_finishes_and_keeps_the_good_log(tmp_path):
    bad = tmp_path / "bad"
    _t0_first_row(tmp_path / "b")
    (tmp_path / "b" / "log").rename(bad)
    out = tmp_path / "out"
    code, _, stderr, wall = run_in_process(["compare", str(bad), str(DRIVE), "--filters", "ekf", "--out", str(out),
                                            "--quiet"], tmp_path)
    assert code == 1 and wall < 60.0, stderr
    last = [ln for ln in stderr.splitlines() if ln.strip()][-1]
    assert last.startswith("navpp:") and "1 of 2 runs failed" in last and len(last) < 300, stderr
    assert any(ln.startswith("warning: ekf on") and "imu.csv: line 2" in ln for ln in stderr.splitlines()), stderr
    rows = {r["log"]: r for r in csv.DictReader((out / "summary.csv").open())}
    assert rows[str(DRIVE)]["status"] == "ok" and rows[str(bad)]["status"] != "ok"


def test_the_compare_watchdog_stops_a_hung_run_and_the_rest_go_on(tmp_path, monkeypatch):
    """A run that does not finish within its limit is a failed row naming the log; the next
    log's run still happens (serial, in this process: engine.run made to hang or fail fast)."""
    from navpp import comparison, engine
    from navpp.errors import InputError

    hung = tmp_path / "hung"
    copy_drive(tmp_path, "hung")
    fine = copy_drive(tmp_path, "fine")

    def fake_run(rec, cfg, filt, **kw):
        if Path(rec.source).name == "hung":
            time.sleep(60.0)
        raise InputError(f"{rec.source}: reached the filter")

    monkeypatch.setattr(engine, "run", fake_run)
    monkeypatch.setattr(comparison.watchdog, "WATCHDOG_MIN_S", 1.0)
    t = time.monotonic()
    res = comparison.compare([hung, fine], ["ekf"], time_limit_s=1e-6, report=False)
    assert time.monotonic() - t < 30.0
    status = {Path(r.log).name: r.status for r in res.rows}
    assert status["hung"].startswith(f"{hung}: stopped by the watchdog after 1 s (the limit for 37501 IMU samples")
    assert status["fine"] == f"{fine}: reached the filter"


def test_watchdog_limit_scales_with_the_log():
    from navpp.comparison import DEFAULT_TIME_LIMIT_S, WATCHDOG_MIN_S, watchdog_limit_s

    assert watchdog_limit_s(DEFAULT_TIME_LIMIT_S, 10_000) == WATCHDOG_MIN_S          # a short log
    assert watchdog_limit_s(DEFAULT_TIME_LIMIT_S, 37_501) == pytest.approx(225.0, abs=0.01)   # the 300 s drive
    assert watchdog_limit_s(DEFAULT_TIME_LIMIT_S, 360_000) == pytest.approx(2160.0)   # an hour at 100 Hz
    assert watchdog_limit_s(0.0, 1e9) == 0.0


def test_compare_time_limit_must_be_a_number_of_seconds(tmp_path):
    code, _, stderr, _ = run_navpp(["compare", str(DRIVE), "--time-limit", "-1", "--out", str(tmp_path / "o")])
    assert code == 2 and "--time-limit" in stderr


# --------------------------------------------------------------------------- what must keep working


def test_lone_stamp_finds_only_lone_stamps():
    t = T0 + np.arange(2000) * 0.008
    assert lone_stamp(t) is None
    for k, v in ((0, 0.0), (1000, 0.0), (1000, t[1000] + 50.0), (1999, t[-1] + 1e6)):
        a = t.copy()
        a[k] = v
        assert lone_stamp(a)[0] == k
    a = t.copy()
    a[1000:] += 3600.0                  # a gap between two runs of samples: not a lone stamp
    assert lone_stamp(a) is None
    a = t.copy()
    a[-1] += 5.0                        # one sample a short gap after the rest (16 s long): a gap
    assert lone_stamp(a) is None
    a = t.copy()
    a[1000] -= 0.5                      # within the reordering tolerance: sorted by the reader
    assert lone_stamp(a) is None
    ns = (t * 1e9).astype(np.int64)
    ns[0] = 0
    assert lone_stamp(ns) == (0, pytest.approx(T0 + 0.008))


def test_the_bridgeable_gap_follows_the_unseen_motion_model():
    from navpp.ins import model

    T = model.max_bridgeable_gap_s()
    att = min(model.GAP_ANG_ACCEL * T, model.GAP_RATE) * T
    assert att == pytest.approx(model.GAP_MAX_ATT_STD) and pytest.approx(10.47, abs=0.01) == T


def _recording_with_gap(gap_s: float):
    from navpp.recording import GnssData, ImuData, Recording

    t = np.arange(2000) * 0.01
    t[1000:] += gap_s
    imu = ImuData(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.8], (t.size, 1)))
    tg = np.arange(0.0, t[-1], 0.2)
    gnss = GnssData(tg, np.full(tg.size, 45.0), np.full(tg.size, 7.0), np.full(tg.size, 300.0))
    return Recording(imu, gnss, int(T0 * 1e9), source="synthetic")


def test_the_log_is_cut_only_at_gaps_beyond_the_limit():
    from navpp.engine import imu_segments

    assert imu_segments(_recording_with_gap(10.4)) == [(0, 2000)]     # a 10.41 s interval: bridged
    assert imu_segments(_recording_with_gap(10.5)) == [(0, 1000), (1000, 2000)]


def test_an_hour_long_imu_gap_splits_the_run_into_segments_each_aligned_afresh(tmp_path):
    """Oracle: the reference (exact truth).  The logger paused for an hour 150 s into the drive:
    no row inside the gap, each side as accurate as a log of its own, the metrics skip the gap."""
    import json

    argv = _hour_gap(tmp_path)
    code, _, err, _ = run_in_process(argv + ["--reference", str(tmp_path / "log" / "reference.csv")], tmp_path)
    assert code == 0, err
    assert "IMU gap of 3600 s after t = 149.992 s" in err and "2 segments" in err, err
    traj = np.genfromtxt(tmp_path / "out" / "trajectory.csv", delimiter=",", names=True)
    t = traj["t"] - traj["t"][0]
    assert not ((t > 150.0) & (t < 3750.0)).any()               # nothing written inside the gap
    assert (t <= 150.0).sum() > 1000 and (t >= 3750.0).sum() > 1000
    assert np.all(np.abs(traj["alt"] - 300.0) < 50.0)           # no free-inertial stretch anywhere
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["position_m"]["horizontal"]["rmse"] < 1.0, m["position_m"]      # 0.60 m without the gap
    assert m["position_m"]["up"]["rmse"] < 2.5, m["position_m"]


@pytest.fixture(scope="module")
def drive_config():
    from navpp import api

    return api.resolve_config(DRIVE, None)


def _run_with_gnss(tmp_path, drive_config, edit):
    from navpp import api, engine

    log = copy_drive(tmp_path)
    edit_csv(log / "gnss.csv", edit)
    rec = api.read_log(log, drive_config)
    return rec, engine.run(rec, drive_config, api.make_filter("ekf", drive_config))


def test_one_outlier_fix_is_still_the_gates(tmp_path, drive_config):
    """One fix 790 m off (and a burst of ten 16,000 km off): no refusal, the gate rejects them and
    the trajectory stays as accurate as the clean log's (0.60 m horizontal RMSE)."""
    def edit(ls):
        ls = list(ls)
        ls[751] = _move_lon(ls[751], 0.01)
        ls[1001:1011] = [_move_lon(x, DLON_16000_KM) for x in ls[1001:1011]]
        return ls

    rec, res = _run_with_gnss(tmp_path, drive_config, edit)
    d = res.diagnostics
    bad = np.isin(np.round(d.t, 3), np.round([150.0, *(200.0 + 0.2 * np.arange(10))], 3))
    assert bad.sum() == 11 and not d.accepted[bad].any()
    assert d.accepted[~bad].mean() > 0.99
    assert _horizontal_rmse(res.solution, rec.reference) < 0.8


def _horizontal_rmse(sol, ref) -> float:
    from navpp import geodesy

    lat = np.interp(sol.t, ref.t, ref.lat_deg)
    lon = np.interp(sol.t, ref.t, ref.lon_deg)
    enu = geodesy.geodetic_to_enu(np.radians(sol.lat_deg), np.radians(sol.lon_deg), sol.alt,
                                  math.radians(45.0), math.radians(7.0), 300.0)
    ref_enu = geodesy.geodetic_to_enu(np.radians(lat), np.radians(lon), sol.alt, math.radians(45.0),
                                      math.radians(7.0), 300.0)
    return float(np.sqrt(np.mean(np.sum((enu - ref_enu)[:, :2] ** 2, axis=1))))


def test_the_alignment_and_stale_row_loops_do_not_step_over_empty_time():
    """The loops that stepped over time now step over samples: a log whose stamps span 1.7e9 s
    with a handful of samples costs nothing there."""
    from navpp.ins.timing_estimates import fresh_count_dispersion

    t = np.concatenate([[0.0], T0 + np.arange(50) * 0.008])
    start = time.monotonic()
    assert math.isnan(fresh_count_dispersion(t, np.zeros(t.size, bool), 0.1))
    assert time.monotonic() - start < 1.0
