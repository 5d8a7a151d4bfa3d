"""``navpp compare``: every row's figures are those of ``navpp process`` with the same filter
(the second path is the oracle); failures become rows and exit code 1; bad arguments fail."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from navpp import api
from navpp.cli import app
from navpp.compare import SUMMARY_COLUMNS, compare

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_rows_equal_process_figures(sim_log_dir: Path):
    rows = compare([sim_log_dir], ["ekf", "ckf"])
    assert [(r.filter, r.status) for r in rows] == [("ekf", "ok"), ("ckf", "ok")]
    for r in rows:
        single = api.process(sim_log_dir, filter_name=r.filter, write=False)
        assert r.metrics["position_m"] == single.metrics["position_m"]
        assert r.gnss_rejected == single.run.gnss_rejected and r.gnss_epochs == single.run.gnss_epochs


def test_cli_table_summary_and_json(sim_log_dir: Path, tmp_path: Path):
    out = tmp_path / "cmp"
    res = invoke("compare", sim_log_dir, "--filters", "ekf,aekf", "--out", out, "-q")
    assert res.exit_code == 0, res.output
    assert "H RMSE" in res.stdout and "aekf" in res.stdout
    with open(out / "summary.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert tuple(table[0]) == SUMMARY_COLUMNS
    assert [t["filter"] for t in table] == ["ekf", "aekf"]
    ekf = api.process(sim_log_dir, filter_name="ekf", write=False).metrics["position_m"]
    assert float(table[0]["horizontal_rmse"]) == pytest.approx(ekf["horizontal"]["rmse"], abs=6e-5)
    assert float(table[0]["up_mae"]) == pytest.approx(ekf["up"]["mae"], abs=6e-5)

    res = invoke("compare", sim_log_dir, "--filters", "ekf", "--out", out, "--json")
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)
    assert rows[0]["filter"] == "ekf" and rows[0]["status"] == "ok"
    assert rows[0]["horizontal_rmse"] == pytest.approx(ekf["horizontal"]["rmse"], abs=6e-5)


def test_a_failing_filter_is_a_row_and_exit_1(log_copy: Path, tmp_path: Path):
    # the paper's random covariance weights collapse the INS covariance (rwckf.py): a real divergence
    (log_copy / "navpp.toml").write_text((log_copy / "navpp.toml").read_text()
                                         + '\n[filter.rwckf]\ncovariance = "random"\nselect = "none"\n')
    out = tmp_path / "cmp"
    res = invoke("compare", log_copy, "--filters", "ekf,rwckf", "--out", out, "-q")
    assert res.exit_code == 1
    assert "1 of 2 runs failed: rwckf on" in " ".join(res.stderr.split())
    assert "Traceback" not in res.output
    with open(out / "summary.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert table[0]["status"] == "ok" and table[0]["horizontal_rmse"]
    assert "diverged" in table[1]["status"] and table[1]["horizontal_rmse"] == ""


def test_without_reference_rows_have_status_only(log_copy: Path, tmp_path: Path):
    (log_copy / "reference.csv").unlink()
    res = invoke("compare", log_copy, "--filters", "ekf", "--out", tmp_path / "c", "-q")
    assert res.exit_code == 0, res.output
    assert "no reference" in res.stdout
    with open(tmp_path / "c" / "summary.csv", newline="") as f:
        row = next(csv.DictReader(f))
    assert row["status"] == "ok" and row["horizontal_rmse"] == "" and float(row["runtime_s"]) > 0


@pytest.mark.parametrize("args, message", [
    (["--filters", "ekf,nope"], "unknown filter 'nope'"),
    (["--filters", "ekf,ekf"], "ekf given more than once"),
    (["--filters", " , "], "at least one filter"),
])
def test_bad_filter_lists(sim_log_dir: Path, tmp_path: Path, args, message):
    res = invoke("compare", sim_log_dir, *args, "--out", tmp_path / "c")
    assert res.exit_code == 1
    assert message in " ".join(res.stderr.split())
    assert not (tmp_path / "c").exists()


def test_one_reference_for_several_logs_is_refused(sim_log_dir: Path, tmp_path: Path):
    other = tmp_path / "other"
    shutil.copytree(sim_log_dir, other)
    res = invoke("compare", sim_log_dir, other, "--reference", sim_log_dir / "reference.csv", "--out", tmp_path / "c")
    assert res.exit_code == 1
    assert "beside each log" in " ".join(res.stderr.split())


def test_bench_lists_runs_and_refuses_bad_arguments():
    res = invoke("bench")
    assert res.exit_code == 0, res.output
    for name in ("paper001-tracking", "paper002-sins", "paper003-bearing", "paper003-turn"):
        assert name in res.stdout
    res = invoke("bench", "paper003-turn", "--runs", "1", "--seed", "3")
    assert res.exit_code == 0, res.output
    assert "(1 run, seed 3" in res.stdout and "vce-ckf" in res.stdout and "VCE r_factor range" in res.stdout
    res = invoke("bench", "paper003-tunr")
    assert res.exit_code == 1 and "unknown benchmark 'paper003-tunr'" in " ".join(res.stderr.split())
    res = invoke("bench", "paper003-turn", "--runs", "0")
    assert res.exit_code == 2
    res = invoke("bench", "paper003-turn", "--runs", "1", "--filters", "ckf,vce-ckf[windw=10]")
    assert res.exit_code == 1 and "did you mean 'window'" in " ".join(res.stderr.split())
