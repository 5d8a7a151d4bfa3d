"""``navpp bench paper001-table5-real``: paper 001 Table 5's protocol on the real logs.

Oracle: ``benchmarks/bench_real.py`` (a second implementation of the walk's scoring, through
``navpp.metrics``) on the same data, laid out as ``../shared/data/real`` lays it out, built from
the repository's copy of walk_0827.
"""

from __future__ import annotations

import importlib.util
import math
import re
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from navpp.cli import app
from navpp.errors import ConfigError
from navpp.papers import table5_real

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT / "sample_data" / "walk_0827"


def _bench_real():
    spec = importlib.util.spec_from_file_location("bench_real", ROOT / "benchmarks" / "bench_real.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture
def real_layout(tmp_path: Path) -> Path:
    """The shipped walk laid out as the real-logs folder holds it (mounting.toml,
    reference_outages.csv), with no car_balzer82."""
    d = tmp_path / "real" / "walk_0827"
    d.mkdir(parents=True)
    for name in ("imu.csv", "gnss.csv", "outages.csv"):
        shutil.copy(WALK / name, d / name)
    shutil.copy(WALK / "navpp.toml", d / "mounting.toml")
    shutil.copy(WALK / "reference.csv", d / "reference_outages.csv")
    return d.parent


def _row(result, filt: str, quantity: str) -> float:
    (row,) = [r for r in result.rows if r.filter == filt and r.quantity == f"walk_0827 {quantity}"]
    return row.ours


def test_the_walk_gives_bench_reals_figures_for_the_ekf(real_layout: Path, monkeypatch):
    monkeypatch.delenv(table5_real.ENV, raising=False)
    result = table5_real.run_table5_real(1, 0, ["ekf"], data=real_layout)
    assert any("no car_balzer82/" in n for n in result.notes)
    line = _bench_real()._walk(real_layout, "ekf", None)
    h_rmse, held = (float(v) for v in re.search(r"H RMSE in outages\s+([\d.]+) m \(last fix held: ([\d.]+)\)",
                                                 line).groups())
    ours = math.hypot(_row(result, "ekf", "longitude (east) RMSE"), _row(result, "ekf", "latitude (north) RMSE"))
    ours_held = math.hypot(_row(result, "gnss-held", "longitude (east) RMSE"),
                           _row(result, "gnss-held", "latitude (north) RMSE"))
    # bench_real prints two decimals; its metrics interpolate through ECEF with heights (mm apart)
    assert ours == pytest.approx(h_rmse, abs=0.007), (ours, line)
    assert ours_held == pytest.approx(held, abs=0.006), (ours_held, line)
    held_exact = _bench_real().held_fix_rmse(WALK / "gnss.csv", WALK / "reference.csv")
    assert ours_held == pytest.approx(held_exact, rel=1e-9)
    # MAE <= RMSE per axis, and the filter beats holding the last fix on both axes
    for axis in ("longitude (east)", "latitude (north)"):
        assert _row(result, "ekf", f"{axis} MAE") <= _row(result, "ekf", f"{axis} RMSE")
    assert ours < 0.7 * ours_held


def test_missing_data_is_one_line_and_exit_1(tmp_path: Path, monkeypatch):
    monkeypatch.setenv(table5_real.ENV, str(tmp_path / "nowhere"))
    res = CliRunner().invoke(app, ["bench", "paper001-table5-real", "--filters", "ekf"])
    assert res.exit_code == 1, res.output
    out = res.output.strip()
    assert len(out.splitlines()) == 1 and "NAVPP_REAL_DATA" in out and "nowhere" in out, out
    assert "Traceback" not in out
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match="neither walk_0827/ nor car_balzer82/"):
        table5_real.find_logs(tmp_path / "empty")
    assert table5_real.main(["--data", str(tmp_path / "nowhere")]) == 1


def test_without_a_data_path_the_shipped_walk_is_used(monkeypatch):
    monkeypatch.delenv(table5_real.ENV, raising=False)
    logs, notes = table5_real.find_logs()
    assert [log.folder for log in logs] == [WALK] and logs[0].reference == WALK / "reference.csv"
    assert any(table5_real.ENV in n for n in notes)


@pytest.mark.slow
@pytest.mark.skipif(not (ROOT.parent / "shared" / "data" / "real" / "car_balzer82").is_dir(),
                    reason="needs ../shared/data/real/car_balzer82 (not shipped)")
def test_the_car_gives_bench_reals_figure_for_the_ekf(monkeypatch):
    real = ROOT.parent / "shared" / "data" / "real"
    monkeypatch.setenv(table5_real.ENV, str(real))
    logs, _ = table5_real.find_logs()
    (car,) = [log for log in logs if log.name == "car_balzer82"]
    ours = table5_real.figures(table5_real._car_errors(car, "ekf", 0))["h_rmse"]
    line = _bench_real()._car(real, "ekf", None)
    h_rmse = float(re.search(r"H RMSE vs withheld fixes\s+([\d.]+) m", line).group(1))
    assert ours == pytest.approx(h_rmse, abs=0.02), (ours, line)
