"""Output writers: exact CSV text, atomic writes, metrics files."""

from __future__ import annotations

import json
import math
import os
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pandas as pd
import pytest

from navpp.io.writers import (
    TRAJECTORY_COLUMNS,
    TRAJECTORY_DECIMALS,
    atomic_write,
    format_fixed_columns,
    write_diagnostics_csv,
    write_metrics_json,
    write_metrics_md,
    write_trajectory_csv,
)
from navpp.recording import Solution

HEADER = "t,lat,lon,alt,ve,vn,vu,roll,pitch,heading,std_e,std_n,std_u"

EDGE_VALUES = [0.0, -0.0, 0.5, -0.5, 1.5, 2.5, -2.5, 0.125, -0.375, 0.00005, -0.00004, -0.00005,
               0.99995, -0.99995, 9.99995, 123456.5, 1e-300, -5e-324, 12345678.123456789,
               1e17, -1e300, np.nan, np.inf, -np.inf, 359.99996, -179.9999999995]


def _random_solution(n: int, seed: int = 0) -> Solution:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.uniform(0, 1e-3, n)
    return Solution(
        t=t,
        lat_deg=rng.uniform(-90, 90, n),
        lon_deg=rng.uniform(-180, 180, n),
        alt=rng.normal(100, 500, n),
        vel_enu=rng.normal(0, 10, (n, 3)) * rng.choice([1e-5, 1.0], (n, 3)),
        rph_deg=np.stack([rng.normal(0, 3, n), rng.normal(0, 3, n), rng.uniform(0, 360, n)], -1),
        std_enu=np.abs(rng.normal(0, 2, (n, 3))),

    )


def _solution_columns(sol: Solution) -> list[np.ndarray]:
    return [sol.lat_deg, sol.lon_deg, sol.alt, *sol.vel_enu.T, *sol.rph_deg.T, *sol.std_enu.T]


# --------------------------------------------------------------------------- formatting


@pytest.mark.parametrize("decimals", [0, 1, 4, 6, 9])
def test_fixed_formatting_matches_python_format(decimals):
    rng = np.random.default_rng(decimals)
    x = np.concatenate([
        EDGE_VALUES,
        rng.normal(0, 1, 3000), rng.normal(0, 1e4, 3000), rng.uniform(-1e-3, 1e-3, 3000),
        # values on or next to decimal ties, where a naive x * 10**d rounding goes wrong
        (rng.integers(-10**6, 10**6, 3000) + 0.5) / 10.0 ** decimals,
        np.nextafter((rng.integers(-10**6, 10**6, 3000) + 0.5) / 10.0 ** decimals, np.inf),
    ])
    text = format_fixed_columns([x, -x], [decimals, decimals]).decode("ascii")
    lines = text.split("\n")
    assert lines[-1] == ""
    for v, line in zip(x, lines[:-1]):
        assert line == f"{format(float(v), f'.{decimals}f')},{format(float(-v), f'.{decimals}f')}"


def test_small_negative_numbers_keep_their_sign():
    text = format_fixed_columns([np.array([-0.5, -0.00004, -0.0, 0.00004, np.nan, -np.inf])], [4])
    assert text.decode().split("\n")[:-1] == ["-0.5000", "-0.0000", "-0.0000", "0.0000", "nan", "-inf"]


def test_multiple_chunks_join_seamlessly(monkeypatch):
    import navpp.io.writers as w

    monkeypatch.setattr(w, "_CHUNK_ROWS", 7)
    x = np.arange(30) - 15.25
    lines = format_fixed_columns([x], [2]).decode().split("\n")[:-1]
    assert lines == [f"{v:.2f}" for v in x]


# --------------------------------------------------------------------------- trajectory.csv


def test_trajectory_csv_reads_back(tmp_path):
    sol = _random_solution(5000)
    path = tmp_path / "trajectory.csv"
    t0_s = 1_700_000_000.123456789
    write_trajectory_csv(path, sol, t0_s=t0_s)
    with open(path) as f:
        assert f.readline().rstrip("\n") == HEADER
    assert ",".join(TRAJECTORY_COLUMNS) == HEADER
    df = pd.read_csv(path)
    assert list(df.columns) == list(TRAJECTORY_COLUMNS)
    assert len(df) == len(sol)
    for name, values, decimals in zip(TRAJECTORY_COLUMNS[1:], _solution_columns(sol),
                                      TRAJECTORY_DECIMALS[1:]):
        half = 0.5 * 10.0 ** -decimals
        np.testing.assert_array_less(np.abs(df[name].to_numpy() - values), half * (1 + 1e-6) + 1e-12,
                                     err_msg=name)
    # t: every cell is t0_s + t rounded to 1 us, checked in exact arithmetic
    cells = [line.split(",", 1)[0] for line in path.read_text().splitlines()[1:]]
    for cell, t in zip(cells[::97], sol.t[::97]):
        exact = Fraction(t0_s) + Fraction(float(t))
        assert abs(Fraction(Decimal(cell)) - exact) <= Fraction(1, 2 * 10**6) + Fraction(1, 10**11)
        assert len(cell.split(".")[1]) == 6


def test_trajectory_csv_text_of_one_row(tmp_path):
    sol = Solution(t=np.array([0.25]), lat_deg=np.array([-0.5]), lon_deg=np.array([114.123456789]),
                   alt=np.array([-12.34567]), vel_enu=np.array([[-0.00004, 1.0, np.nan]]),
                   rph_deg=np.array([[-0.5, 2.0, 359.99999]]), std_enu=np.array([[0.1, 0.2, 0.3]]))
    path = tmp_path / "trajectory.csv"
    write_trajectory_csv(path, sol, t0_s=1_600_000_000.5)
    assert path.read_text() == (
        HEADER + "\n"
        "1600000000.750000,-0.500000000,114.123456789,-12.3457,-0.0000,1.0000,nan,"
        "-0.5000,2.0000,360.0000,0.1000,0.2000,0.3000\n"
    )


def test_trajectory_csv_relative_time_and_empty(tmp_path):
    sol = _random_solution(3)
    write_trajectory_csv(tmp_path / "a.csv", sol, t0_s=0.0)
    df = pd.read_csv(tmp_path / "a.csv")
    np.testing.assert_allclose(df["t"], sol.t, atol=5e-7)
    empty = _random_solution(0)
    write_trajectory_csv(tmp_path / "b.csv", empty, t0_s=0.0)
    assert (tmp_path / "b.csv").read_text() == HEADER + "\n"


# --------------------------------------------------------------------------- atomic writes


def test_atomic_write_leaves_nothing_when_the_writer_raises(tmp_path):
    def failing(f):
        f.write("half a file")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        atomic_write(tmp_path / "out.txt", failing)
    assert os.listdir(tmp_path) == []

    (tmp_path / "out.txt").write_text("previous run")
    with pytest.raises(RuntimeError):
        atomic_write(tmp_path / "out.txt", failing, mode="w")
    assert os.listdir(tmp_path) == ["out.txt"]
    assert (tmp_path / "out.txt").read_text() == "previous run"


def test_atomic_write_replaces_and_keeps_no_temp(tmp_path):
    (tmp_path / "out.bin").write_bytes(b"old")
    atomic_write(tmp_path / "out.bin", lambda f: f.write(b"new\n"), mode="wb")
    assert (tmp_path / "out.bin").read_bytes() == b"new\n"
    atomic_write(tmp_path / "out.txt", lambda f: f.write("text\n"))
    assert sorted(os.listdir(tmp_path)) == ["out.bin", "out.txt"]
    with pytest.raises(ValueError):
        atomic_write(tmp_path / "x", lambda f: None, mode="a")


def test_trajectory_csv_failure_keeps_previous_file(tmp_path, monkeypatch):
    from navpp.io.csvformat import BlockFormatter

    path = tmp_path / "trajectory.csv"
    path.write_text("finished earlier\n")

    def broken(*args, **kwargs):
        raise MemoryError("simulated")

    monkeypatch.setattr(BlockFormatter, "text", broken)
    with pytest.raises(MemoryError):
        write_trajectory_csv(path, _random_solution(10), t0_s=0.0)
    assert os.listdir(tmp_path) == ["trajectory.csv"]
    assert path.read_text() == "finished earlier\n"


# --------------------------------------------------------------------------- metrics files


def _metrics() -> dict:
    stats = {"mae": 0.123456, "rmse": 0.234567, "max": 1.5, "p95": 0.9}
    pos = {k: dict(stats) for k in ("east", "north", "up", "horizontal", "3d")}
    pos["north"]["mae"] = 0.654321
    return {
        "filter": "rwckf", "log": "drive.mcap", "reference": "ref.csv", "epochs": 5731,
        "position_m": pos,
        "velocity_mps": {k: {"mae": 0.0111, "rmse": 0.0222, "max": 0.0333, "p95": 0.0444}
                         for k in pos},
        "attitude_deg": {k: {"mae": 0.5, "rmse": 0.6, "max": 2.25, "p95": 1.125}
                         for k in ("roll", "pitch", "heading")},
        "runtime_s": 12.5, "imu_samples": 573100, "gnss_epochs": 5731, "gnss_rejected": 17,
        "gnss_position_m": {"epochs": 5700, **{k: {"mae": 1.0101, "rmse": 2.0202, "max": 3.0303,
                                                    "p95": 4.0404} for k in pos}},
    }


def test_metrics_json_round_trip(tmp_path):
    m = _metrics()
    write_metrics_json(tmp_path / "metrics.json", m)
    assert json.loads((tmp_path / "metrics.json").read_text()) == m
    assert os.listdir(tmp_path) == ["metrics.json"]


def test_metrics_json_is_valid_with_non_finite_and_numpy_values(tmp_path):
    m = {"a": float("nan"), "b": np.float64(1.25), "c": np.int64(3), "d": {"e": float("inf")}}
    write_metrics_json(tmp_path / "m.json", m)
    text = (tmp_path / "m.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"a": None, "b": 1.25, "c": 3, "d": {"e": None}}


def test_metrics_md_contains_the_numbers(tmp_path):
    m = _metrics()
    write_metrics_md(tmp_path / "metrics.md", m)
    text = (tmp_path / "metrics.md").read_text()
    for word in ("rwckf", "drive.mcap", "ref.csv", "5731", "12.5", "573100", "17",
                 "east = longitude error", "north = latitude error"):
        assert word in text
    for section in ("position_m", "velocity_mps", "attitude_deg", "gnss_position_m"):
        for row, stats in m[section].items():
            if not isinstance(stats, dict):
                continue
            line = next(ln for ln in text[text.index(_TITLES[section]):].splitlines()
                        if ln.startswith(f"| {row} |"))
            for key in ("mae", "rmse", "max", "p95"):
                assert f"{stats[key]:.4f}" in line, (section, row, key)
    assert "| north | 0.6543 | 0.2346 | 1.5000 | 0.9000 |" in text


_TITLES = {"position_m": "## Position", "velocity_mps": "## Velocity",
           "attitude_deg": "## Attitude", "gnss_position_m": "## Raw GNSS"}


def test_metrics_md_without_optional_sections(tmp_path):
    m = _metrics()
    for key in ("velocity_mps", "attitude_deg", "gnss_position_m"):
        del m[key]
    write_metrics_md(tmp_path / "metrics.md", m)
    text = (tmp_path / "metrics.md").read_text()
    assert "## Position" in text and "## Velocity" not in text and "## Raw GNSS" not in text
    assert math.isclose(m["runtime_s"], 12.5)


def test_diagnostics_csv_round_trips_every_epoch(tmp_path):
    from navpp.engine import Diagnostics

    rng = np.random.default_rng(3)
    m = 40
    diag = Diagnostics(t=np.arange(m) * 0.2 + 0.2, nu=rng.normal(size=(m, 3)), nis=rng.chisquare(3, m),
                       accepted=rng.uniform(size=m) > 0.1, forced=np.zeros(m, bool),
                       r_std=rng.uniform(1, 3, (m, 3)),
                       adaptive={"q_factor": rng.uniform(0.1, 10, (m, 4)), "fading": rng.uniform(1, 2, (m, 1))})
    path = tmp_path / "diagnostics.csv"
    write_diagnostics_csv(path, diag, t0_s=1700000000.0)
    df = pd.read_csv(path)
    assert list(df.columns) == ["t", "nu_e", "nu_n", "nu_u", "nis", "accepted", "forced", "r_std_e", "r_std_n",
                                "r_std_u", "q_factor_0", "q_factor_1", "q_factor_2", "q_factor_3", "fading"]
    np.testing.assert_allclose(df["t"] - 1700000000.0, diag.t, atol=1e-6)
    np.testing.assert_allclose(df[["nu_e", "nu_n", "nu_u"]], diag.nu, atol=5e-5)
    np.testing.assert_array_equal(df["accepted"].to_numpy(bool), diag.accepted)
    np.testing.assert_allclose(df[["q_factor_0", "q_factor_1", "q_factor_2", "q_factor_3"]],
                               diag.adaptive["q_factor"], atol=5e-7)
    np.testing.assert_allclose(df["fading"], diag.adaptive["fading"][:, 0], atol=5e-7)
