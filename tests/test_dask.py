"""``navpp compare --executor dask`` (issue 9) on a real ``distributed.LocalCluster`` of worker
processes (two for the full comparison and the local cluster, one for the quicker checks).
Oracle: the local executor's rows, which must be equal bit for bit (every figure; the run times
are measurements and differ)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from navpp.cli import app
from navpp.comparison import compare
from navpp.errors import ConfigError

distributed = pytest.importorskip("distributed")

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data"


def _cluster(n_workers: int):
    """The address of a LocalCluster of ``n_workers`` worker processes, closed afterwards."""
    cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


@pytest.fixture(scope="module")
def scheduler():
    """One worker process: each worker imports navpp and loads its kernels (2-3 s of CPU), and
    the checks that use it need no second one."""
    yield from _cluster(1)


@pytest.fixture(scope="module")
def scheduler_2():
    yield from _cluster(2)


def _comparable(row) -> str:
    """Everything of a row except the run time (metrics included, as JSON: exact float text)."""
    m = dict(row.metrics or {})
    m.pop("runtime_s", None)
    return json.dumps([row.log, row.filter, row.status, row.gnss_epochs, row.gnss_rejected, row.imu_samples,
                       row.reference, list(row.warnings), m], sort_keys=True)


@pytest.mark.slow     # the heaviest default test (two clusters' runs); the default run keeps test_local_cluster_*
def test_dask_rows_equal_the_local_executors_bit_for_bit(scheduler_2, sim_log_dir, tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "gnss.csv").write_text("t,lat,lon,alt\n")            # no imu.csv: a row, not a crash
    logs = [str(sim_log_dir), str(SAMPLES / "drive.mcap"), str(broken)]
    filters = ["ekf", "ckf", "aekf"]
    local = compare(logs, filters, jobs=1, out_dir=tmp_path / "local")
    remote = compare(logs, filters, executor="dask", scheduler=scheduler_2, out_dir=tmp_path / "out")
    assert [_comparable(r) for r in remote.rows] == [_comparable(r) for r in local.rows]
    assert remote.jobs == 2
    assert [r.ok for r in remote.rows] == [True] * 6 + [False] * 3
    assert "imu.csv" in remote.rows[-1].status
    # the plot series travel back as well, and the report is drawn
    assert set(remote.run_series) == set(local.run_series)
    names = {p.name for p in remote.files}
    assert {"summary.csv", "report.md", "report.html"} <= names and any(n.endswith("_trajectory.png") for n in names)


@pytest.mark.slow     # two worker processes of its own (4 s of CPU); the default run keeps the dask executor
#                       on the module's one-worker cluster (test_smoothed_rows_on_dask, test_cli)
def test_local_cluster_when_no_scheduler_is_given(sim_log_dir):
    res = compare([sim_log_dir], ["ekf"], executor="dask", jobs=2, report=False)
    assert res.jobs == 2 and res.rows[0].ok


def test_smoothed_rows_on_dask(scheduler, sim_log_dir):
    local = compare([sim_log_dir], ["ekf"], smooth=True, report=False)
    remote = compare([sim_log_dir], ["ekf"], smooth=True, executor="dask", scheduler=scheduler, report=False)
    assert [r.filter for r in remote.rows] == ["ekf", "ekf+rts"]
    assert [_comparable(r) for r in remote.rows] == [_comparable(r) for r in local.rows]


def test_cli(scheduler, sim_log_dir, tmp_path):
    r = CliRunner().invoke(app, ["compare", str(sim_log_dir), "--filters", "ekf,aekf", "--executor", "dask",
                                 "--scheduler", scheduler, "--out", str(tmp_path / "c"), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert [row["filter"] for row in doc["rows"]] == ["ekf", "aekf"]
    r = CliRunner().invoke(app, ["compare", str(sim_log_dir), "--scheduler", scheduler, "--out", str(tmp_path / "d")])
    assert r.exit_code == 2 and "--executor dask" in r.output


def test_bad_executor_arguments():
    with pytest.raises(ConfigError, match="--executor must be one of local, dask"):
        compare(["x"], ["ekf"], executor="spark")
    with pytest.raises(ConfigError, match="use it with --executor dask"):
        compare(["x"], ["ekf"], scheduler="tcp://h:8786")
