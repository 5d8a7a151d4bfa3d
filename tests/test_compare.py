"""``navpp compare``: every row's figures are those of ``navpp process`` with the same filter
(the second path is the oracle); ``--jobs 2`` gives exactly the figures of a serial run;
failures become rows and exit code 1; the CI gates (exit 3) on hand-made summaries and on the
sample logs against the committed baseline; bad arguments fail with exit 2.

The committed baseline ``tests/data/compare_baseline_summary.csv`` was written by
``navpp compare sample_data/drive sample_data/drive.mcap --filters ekf,aekf --out DIR``
(run from the repository root); regenerate it the same way when a change is meant to move
the figures.
"""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp import api
from navpp.cli import app
from navpp.comparison import (
    SUMMARY_COLUMNS,
    CompareRow,
    check_baseline,
    check_limits,
    compare,
    parse_limits,
    parse_tolerance,
    read_baseline,
)
from navpp.errors import ConfigError

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_data"
BASELINE = Path(__file__).parent / "data" / "compare_baseline_summary.csv"


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line(text: str) -> str:
    return " ".join(text.split())


def read_summary(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# --------------------------------------------------------------------------- figures and parallel runs


def test_rows_equal_process_figures(sim_log_dir: Path):
    rows = compare([sim_log_dir], ["ekf", "ckf"]).rows
    assert [(r.filter, r.status) for r in rows] == [("ekf", "ok"), ("ckf", "ok")]
    for r in rows:
        single = api.process(sim_log_dir, filter_name=r.filter, write=False)
        assert r.metrics["position_m"] == single.metrics["position_m"]
        assert r.gnss_rejected == single.run.gnss_rejected and r.gnss_epochs == single.run.gnss_epochs
        assert r.imu_samples == len(single.recording.imu)


def untimed(r: CompareRow) -> CompareRow:
    """The row without its measured run time (in the row and in its metrics)."""
    metrics = None if r.metrics is None else {k: v for k, v in r.metrics.items() if k != "runtime_s"}
    return replace(r, runtime_s=0.0, metrics=metrics)


def _same_series(a, b) -> None:
    for name in a.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if hasattr(x, "__dataclass_fields__"):      # a band of the series (ErrorBand, InnovationBand)
            assert type(x) is type(y), name
            _same_series(x, y)
        elif isinstance(x, dict):
            assert x.keys() == y.keys()
            for k in x:
                np.testing.assert_array_equal(x[k], y[k])
        elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y, name


def test_jobs_2_equals_serial_exactly_and_reports_progress(sim_log_dir: Path, tmp_path: Path):
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "imu.csv").write_text("t,gx\n0,1\n")
    (broken / "gnss.csv").write_text("t,lat,lon,alt\n0,45,7,300\n")
    # the adaptive AEKF as the second filter: its learnt R is state the workers must not share
    # (the VCE-CKF, four times its CPU, checks nothing more here)
    logs, filters = [sim_log_dir, broken, SAMPLES / "drive"], ["ekf", "aekf"]
    serial = compare(logs, filters, jobs=1)
    events: list[tuple[str, float]] = []
    parallel = compare(logs, filters, jobs=2, progress=lambda s, f: events.append((s, f)))
    assert parallel.jobs == 2
    assert [untimed(r) for r in parallel.rows] == [untimed(r) for r in serial.rows]
    assert [r.status == "ok" for r in serial.rows] == [True, True, False, False, True, True]
    assert "imu.csv" in serial.rows[2].status and serial.rows[2].status == serial.rows[3].status
    a, b = serial.summary.drop(columns="runtime_s"), parallel.summary.drop(columns="runtime_s")
    assert a.equals(b)
    assert serial.run_series.keys() == parallel.run_series.keys() and len(serial.run_series) == 4
    for key in serial.run_series:
        _same_series(serial.run_series[key], parallel.run_series[key])
    for log in serial.log_series:
        if serial.log_series[log] is not None:
            _same_series(serial.log_series[log], parallel.log_series[log])
    done = {s: f for s, f in events}             # the last fraction of each stage
    assert done["all runs"] == 1.0
    assert done[f"{sim_log_dir.name} aekf"] == 1.0 and done["reading drive"] == 1.0


def test_api_result_summary_and_files(sim_log_dir: Path, tmp_path: Path):
    res = compare([sim_log_dir], ["ekf"], out_dir=tmp_path)
    assert [p.name for p in res.files][:1] == ["summary.csv"]
    assert {"report.md", "report.html", "drive_trajectory.png"} <= {p.name for p in res.files}
    import pandas as pd

    on_disk = pd.read_csv(tmp_path / "summary.csv", keep_default_na=False, na_values=[""])
    assert list(res.summary.columns) == list(SUMMARY_COLUMNS)
    assert res.summary.astype(str).equals(on_disk.astype(str))
    assert compare([sim_log_dir], ["ekf"], report=False).files == ()
    with pytest.raises(ConfigError, match="jobs"):
        compare([sim_log_dir], ["ekf"], jobs=0)
    with pytest.raises(ConfigError, match="more than once"):
        compare([sim_log_dir, sim_log_dir], ["ekf"])


# --------------------------------------------------------------------------- command line


def test_cli_table_summary_and_json(sim_log_dir: Path, tmp_path: Path):
    out = tmp_path / "cmp"
    res = invoke("compare", sim_log_dir, "--filters", "ekf,aekf", "--out", out, "-q")
    assert res.exit_code == 0, res.output
    assert "H RMSE" in res.stdout and "aekf" in res.stdout
    table = read_summary(out / "summary.csv")
    assert tuple(table[0]) == SUMMARY_COLUMNS
    assert [t["filter"] for t in table] == ["ekf", "aekf", "raw GNSS"]
    metrics = api.process(sim_log_dir, filter_name="ekf", write=False).metrics
    ekf = metrics["position_m"]
    assert float(table[0]["horizontal_rmse"]) == pytest.approx(ekf["horizontal"]["rmse"], abs=6e-5)
    assert float(table[0]["up_mae"]) == pytest.approx(ekf["up"]["mae"], abs=6e-5)
    raw = metrics["gnss_position_m"]           # the raw-GNSS row: the fixes against the reference, as process has it
    assert int(table[2]["epochs"]) == raw["epochs"] and table[2]["runtime_s"] == ""
    for axis in ("east", "north", "up", "horizontal"):
        for stat in ("mae", "rmse"):
            assert float(table[2][f"{axis}_{stat}"]) == pytest.approx(raw[axis][stat], abs=6e-5)
    assert (out / "report.md").is_file() and (out / "report.html").is_file()

    res = invoke("compare", sim_log_dir, "--filters", "ekf", "--out", out, "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["exit_code"] == 0 and doc["gate"] is None and doc["failed"] == 0
    row = doc["rows"][0]
    assert tuple(row) == SUMMARY_COLUMNS
    assert row["filter"] == "ekf" and row["status"] == "ok"
    assert row["horizontal_rmse"] == pytest.approx(ekf["horizontal"]["rmse"], abs=6e-5)


def test_a_failing_filter_is_a_row_and_exit_1(log_copy: Path, tmp_path: Path):
    # the paper's random covariance weights collapse the INS covariance (rwckf.py): a real divergence
    (log_copy / "navpp.toml").write_text((log_copy / "navpp.toml").read_text()
                                         + '\n[filter.rwckf]\ncovariance = "random"\nselect = "none"\n')
    out = tmp_path / "cmp"
    res = invoke("compare", log_copy, "--filters", "ekf,rwckf", "--out", out, "-q")
    assert res.exit_code == 1
    last = res.stderr.strip().splitlines()[-1]
    assert "1 of 2 runs failed" in last and "rwckf on" in last and len(last) < 300, res.stderr
    assert "warning: rwckf on" in one_line(res.stderr) and "diverged" in one_line(res.stderr)   # the reason
    assert "Traceback" not in res.output
    table = read_summary(out / "summary.csv")
    assert table[0]["status"] == "ok" and table[0]["horizontal_rmse"]
    assert "diverged" in table[1]["status"] and table[1]["horizontal_rmse"] == ""
    assert "diverged" in (out / "report.md").read_text()


def test_an_unreadable_log_is_rows_and_the_others_run(sim_log_dir: Path, tmp_path: Path):
    missing = tmp_path / "nowhere.mcap"
    res = invoke("compare", missing, sim_log_dir, "--filters", "ekf,aekf", "--out", tmp_path / "c", "-q")
    assert res.exit_code == 1
    err = one_line(res.stderr)
    last = res.stderr.strip().splitlines()[-1]
    assert "2 of 4 runs failed" in last and "ekf, aekf on nowhere.mcap" in last and len(last) < 300, res.stderr
    assert "warning: ekf, aekf on" in err and "Traceback" not in res.output
    table = read_summary(tmp_path / "c" / "summary.csv")
    assert [t["status"] == "ok" for t in table] == [False, False, True, True, True]     # + the raw GNSS row
    assert (tmp_path / "c" / "report.html").is_file()


def test_without_reference_rows_have_status_only(log_copy: Path, tmp_path: Path):
    (log_copy / "reference.csv").unlink()
    res = invoke("compare", log_copy, "--filters", "ekf", "--out", tmp_path / "c", "-q")
    assert res.exit_code == 0, res.output
    assert "no reference" in res.stdout
    row = read_summary(tmp_path / "c" / "summary.csv")[0]
    assert row["status"] == "ok" and row["horizontal_rmse"] == "" and float(row["runtime_s"]) > 0


@pytest.mark.parametrize("args, message", [
    (["--filters", "ekf,nope"], "unknown filter 'nope'"),
    (["--filters", "ekf,ekf"], "ekf given more than once"),
    (["--filters", " , "], "at least one filter"),
])
def test_bad_filter_lists(sim_log_dir: Path, tmp_path: Path, args, message):
    res = invoke("compare", sim_log_dir, *args, "--out", tmp_path / "c")
    assert res.exit_code == 1
    assert message in one_line(res.stderr)
    assert not (tmp_path / "c").exists()


def test_one_reference_for_several_logs_is_refused(sim_log_dir: Path, tmp_path: Path):
    other = tmp_path / "other"
    shutil.copytree(sim_log_dir, other)
    res = invoke("compare", sim_log_dir, other, "--reference", sim_log_dir / "reference.csv", "--out", tmp_path / "c")
    assert res.exit_code == 1
    assert "beside each log" in one_line(res.stderr)
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("args, message", [
    (["--jobs", "0"], "must be an integer >= 1"),
    (["--tolerance", "5%"], "--tolerance applies to --baseline"),
    (["--baseline", "BASE", "--tolerance", "abc"], "--tolerance must be a percentage"),
    (["--baseline", "BASE", "--tolerance", "-1%"], "--tolerance must be a percentage"),
    (["--baseline", "BASE", "--tolerance", "nan"], "--tolerance must be a percentage"),
    (["--max-rmse", "X=1"], "'X=1' is not KEY=METRES"),
    (["--max-rmse", "H"], "'H' is not KEY=METRES"),
    (["--max-rmse", "H=-1"], "finite number of metres >= 0"),
    (["--max-rmse", "H=1,horizontal=2"], "given more than once"),
    (["--max-rmse", ","], "give limits such as H=1.0,U=1.5"),
    (["--baseline", "MISSING"], "cannot read"),
    (["--baseline", "NOT_A_SUMMARY"], "not a navpp compare summary.csv"),
    (["--baseline", "BAD_NUMBER"], "line 2: horizontal_rmse = 'abc' is not a number"),
])
def test_bad_gate_arguments_are_usage_errors(sim_log_dir: Path, tmp_path: Path, args, message):
    files = {"BASE": BASELINE, "MISSING": tmp_path / "missing.csv", "NOT_A_SUMMARY": tmp_path / "x.csv",
             "BAD_NUMBER": tmp_path / "bad.csv"}
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    (tmp_path / "bad.csv").write_text("log,filter,horizontal_rmse\ndrive,ekf,abc\n")
    res = invoke("compare", sim_log_dir, "--filters", "ekf", "--out", tmp_path / "c",
                 *[files.get(a, a) for a in args])
    assert res.exit_code == 2, res.output
    assert message in one_line(res.output)
    assert "Traceback" not in res.output
    assert not (tmp_path / "c").exists()


# --------------------------------------------------------------------------- CI gates on the sample logs


def test_gate_on_the_sample_logs_against_the_committed_baseline(tmp_path: Path, monkeypatch):
    # the second command runs the same tasks (logs, filters, report) as the first: it replays the
    # first's outcomes and figures, so that what it checks, the gates, costs no second set of runs
    from navpp.comparison import runner as compare_runner

    run_tasks, done = compare_runner._run_tasks, []

    def once(tasks, *args):
        if not done:
            done.append((tasks, run_tasks(tasks, *args)))
        assert tasks == done[0][0]
        return done[0][1]

    monkeypatch.setattr(compare_runner, "_run_tasks", once)
    res = invoke("compare", SAMPLES / "drive", SAMPLES / "drive.mcap", "--filters", "ekf,aekf",
                 "--out", tmp_path / "c", "-q", "--baseline", BASELINE, "--tolerance", "5%",
                 "--max-rmse", "H=1.0,U=1.0")
    assert res.exit_code == 0, res.output
    assert "not in the baseline" not in res.stderr          # every row matched by log name and filter

    # the same run against a baseline 10 % better for one row: exit 3 naming row, metric, values
    rows = read_summary(BASELINE)
    rows[1]["horizontal_rmse"] = f"{float(rows[1]['horizontal_rmse']) * 0.9:.4f}"
    rows = [r for r in rows if r["filter"] != "ekf" or r["log"] != "sample_data/drive.mcap"]   # a new row
    tight = tmp_path / "tight.csv"
    with open(tight, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    # a vertical limit between the two filters' vertical RMSE: the worse one fails it on both logs
    up = {r["filter"]: float(r["up_rmse"]) for r in read_summary(BASELINE) if r["log"] == "sample_data/drive"}
    worse = max(up, key=up.__getitem__)
    res = invoke("compare", SAMPLES / "drive", SAMPLES / "drive.mcap", "--filters", "ekf,aekf",
                 "--out", tmp_path / "c", "-q", "--baseline", tight, "--max-rmse", f"U={sum(up.values()) / 2:.5f}",
                 "--json")
    assert res.exit_code == 3, res.output
    err = one_line(res.stderr)
    assert "CI gate failed: 3 of" in err
    assert "drive aekf horizontal_rmse baseline" in err and "+11.1" in err
    assert "ekf on " in err and "drive.mcap: not in the baseline" in err
    doc = json.loads(res.stdout)
    assert doc["exit_code"] == 3 and doc["gate"]["passed"] is False
    failures = {(Path(f["log"]).name, f["filter"], f["metric"], f["gate"]) for f in doc["gate"]["failures"]}
    assert failures == {("drive", "aekf", "horizontal_rmse", "baseline"), ("drive", worse, "up_rmse", "max-rmse"),
                        ("drive.mcap", worse, "up_rmse", "max-rmse")}


def test_a_failed_run_wins_over_the_gate(log_copy: Path, tmp_path: Path):
    (log_copy / "navpp.toml").write_text((log_copy / "navpp.toml").read_text()
                                         + '\n[filter.rwckf]\ncovariance = "random"\nselect = "none"\n')
    res = invoke("compare", log_copy, "--filters", "ekf,rwckf", "--out", tmp_path / "c", "-q",
                 "--max-rmse", "H=0.001")
    assert res.exit_code == 1
    assert "CI gate: regressions" in res.stderr and "runs failed" in one_line(res.stderr)


# --------------------------------------------------------------------------- gate logic on hand-made rows


def row(log: str = "a/drive", filt: str = "ekf", h: float | None = 1.0, u: float = 1.0, status: str = "ok"
        ) -> CompareRow:
    if h is None or status != "ok":
        return CompareRow(log, filt, status, None, 10, 0, 0.1)
    stats = {"mae": 0.5, "rmse": 0.5, "max": 2.0, "p95": 1.5}
    pos = {k: dict(stats) for k in ("east", "north", "3d")}
    pos["horizontal"] = dict(stats, rmse=h)
    pos["up"] = dict(stats, rmse=u)
    return CompareRow(log, filt, status, {"epochs": 100, "position_m": pos}, 10, 0, 0.1)


def base(log: str = "a/drive", filt: str = "ekf", h: float | None = 1.0, u: float | None = 1.0) -> dict:
    return {"log": log, "filter": filt, "status": "ok", "horizontal_rmse": h, "up_rmse": u}


@pytest.mark.parametrize("b, value, tol, ok", [
    (1.0, 1.05, 5.0, True), (1.0, 1.0501, 5.0, False), (0.64, 0.672, 5.0, True), (0.64, 0.6721, 5.0, False),
    (0.6433, 0.6433, 0.0, True), (0.6433, 0.6434, 0.0, False), (2.0, 1.0, 0.0, True),
    (0.0, 0.0, 5.0, True), (0.0, 0.0001, 5.0, False), (0.3, 0.33, 10.0, True),
])
def test_baseline_tolerance_boundary(b, value, tol, ok):
    v = check_baseline([row(h=value)], [base(h=b)], tol)
    assert v.passed is ok and v.checks == 2
    if not ok:
        (f,) = v.failures
        assert (f.metric, f.gate, f.reference, f.value) == ("horizontal_rmse", "baseline", b, value)
        assert f.allowed == pytest.approx(b * (1 + tol / 100))
        assert f.worse_pct == (pytest.approx((value - b) / b * 100) if b else float("inf"))


def test_baseline_matching_and_notes():
    rows = [row("/ci/tmp/drive", "ekf"), row("/ci/tmp/drive", "ckf"), row("/ci/tmp/city", "ekf", h=9.0),
            row("/ci/tmp/drive", "aekf", status="failed: diverged")]
    baseline = [base("sample_data/drive", "ekf"), base("sample_data/drive", "aekf"), base("x/gone", "ekf"),
                base("city", "ekf", h=None)]
    v = check_baseline(rows, baseline, 5.0)
    assert v.passed and v.checks == 3             # drive ekf (2 metrics) + city ekf (up only)
    notes = " | ".join(v.notes)
    assert "ckf on /ci/tmp/drive: not in the baseline" in notes
    assert "aekf on /ci/tmp/drive: the run failed" in notes
    assert "ekf on x/gone: in the baseline but not run" in notes
    assert "ekf on /ci/tmp/city: the baseline has no horizontal_rmse" in notes
    # a name shared by two baseline logs is ambiguous: no match by name
    v = check_baseline([row("/ci/drive")], [base("a/drive"), base("b/drive")], 5.0)
    assert v.checks == 0 and "not in the baseline" in v.notes[0]
    # the exact log text wins over the name
    v = check_baseline([row("a/drive", h=1.0)], [base("a/drive", h=1.0), base("b/drive", h=0.1)], 5.0)
    assert v.passed and v.checks == 2


def test_a_row_without_reference_fails_the_gates():
    v = check_baseline([row(h=None)], [base()], 5.0)
    assert not v.passed and {f.value for f in v.failures} == {None}
    v = check_limits([row(h=None)], {"horizontal_rmse": 1.0})
    assert not v.passed and "no reference" in v.failures[0].reason


def test_limits():
    rows = [row("d", "ekf", h=1.0, u=1.5), row("d", "ckf", h=1.2, u=1.0), row("d", "x", status="failed")]
    v = check_limits(rows, parse_limits("H=1.0,u=1.5"))
    assert v.checks == 4 and [(f.filter, f.metric) for f in v.failures] == [("ckf", "horizontal_rmse")]
    assert v.failures[0].worse_pct == pytest.approx(20.0) and "x on d: the run failed" in v.notes[0]
    assert check_limits(rows[:1], {"horizontal_rmse": 0.0}).failures[0].worse_pct == float("inf")
    as_json = json.loads(json.dumps(v.as_dict()))
    assert as_json["passed"] is False and as_json["failures"][0]["allowed"] == 1.0


def test_gate_argument_parsing(tmp_path: Path):
    assert parse_tolerance("5%") == parse_tolerance("5") == parse_tolerance(" 5 % ") == 5.0
    assert parse_tolerance(0) == 0.0
    for bad in ("", "%", "-1", "inf", "five"):
        with pytest.raises(ConfigError):
            parse_tolerance(bad)
    assert parse_limits("H=1, E=0.5,N=0.5,Up=2,3d=3") == {
        "horizontal_rmse": 1.0, "east_rmse": 0.5, "north_rmse": 0.5, "up_rmse": 2.0, "3d_rmse": 3.0}
    rows = read_baseline(BASELINE)
    assert len(rows) == 4 and rows[0]["log"] == "sample_data/drive" and isinstance(rows[0]["horizontal_rmse"], float)
    dup = tmp_path / "dup.csv"
    dup.write_text("log,filter,up_rmse\nd,ekf,1\nd,ekf,2\n")
    with pytest.raises(ConfigError, match="line 3: ekf on d appears twice"):
        read_baseline(dup)


def test_bench_lists_runs_and_refuses_bad_arguments():
    res = invoke("bench")
    assert res.exit_code == 0, res.output
    for name in ("paper001-tracking", "paper002-sins", "paper003-bearing", "paper003-turn"):
        assert name in res.stdout
    res = invoke("bench", "paper003-turn", "--runs", "1", "--seed", "3")
    assert res.exit_code == 0, res.output
    assert "(1 run, seed 3" in res.stdout and "vce-ckf" in res.stdout and "VCE r_factor range" in res.stdout
    res = invoke("bench", "paper003-tunr")
    assert res.exit_code == 1 and "unknown benchmark 'paper003-tunr'" in one_line(res.stderr)
    res = invoke("bench", "paper003-turn", "--runs", "0")
    assert res.exit_code == 2
    res = invoke("bench", "paper003-turn", "--runs", "1", "--filters", "ckf,vce-ckf[windw=10]")
    assert res.exit_code == 1 and "did you mean 'window'" in one_line(res.stderr)


def test_parallel_schedule_is_log_by_log_costliest_first():
    from navpp.comparison.runs import RunTask
    from navpp.comparison.schedule import submission_order

    tasks = [RunTask(i * 3 + j, log, f, None, None, None, None, None, False, False)
             for i, log in enumerate(["b", "a"]) for j, f in enumerate(["ekf", "ckf", "rwckf"])]
    assert [(t.log, t.filter) for t in submission_order(tasks)] == [
        ("b", "rwckf"), ("b", "ckf"), ("b", "ekf"), ("a", "rwckf"), ("a", "ckf"), ("a", "ekf")]


def test_python_api_creates_the_output_directory(sim_log_dir, tmp_path):
    import navpp

    out = tmp_path / "new" / "cmp"
    res = navpp.compare([sim_log_dir], ["ekf"], out_dir=out, report=False)
    assert (out / "summary.csv").is_file() and res.summary["filter"].tolist() == ["ekf", "raw GNSS"]


def test_config_outages_apply_to_compare_as_to_process(log_copy):
    toml = log_copy / "navpp.toml"
    text = toml.read_text()
    text = text.replace("[gnss]", "[gnss]\noutages = [[60.0, 20.0]]", 1) if "[gnss]" in text \
        else text + "\n[gnss]\noutages = [[60.0, 20.0]]\n"
    toml.write_text(text)
    from navpp.comparison import compare as run_compare

    row = run_compare([log_copy], ["ekf"], report=False).rows[0]
    single = api.process(log_copy, filter_name="ekf", write=False)
    assert row.metrics["outages"] == single.metrics["outages"] and len(row.metrics["outages"]) == 1
    assert row.gnss_epochs == single.run.gnss_epochs
