"""Trajectory exports (TUM, GeoJSON, KML, pandas), ``--format`` and the Python API.

Oracles: an independent TUM reader that follows evo's ``file_interface.read_tum_trajectory_file``
rules (``#`` comment lines skipped, single-space separated rows of exactly 8 numbers, no
trailing delimiter); ``geodesy.geodetic_to_enu`` for positions; the navigation-convention
rotation ``Rz(pi/2 - heading) Ry(-pitch) Rx(roll)`` written out here for orientations;
``json`` / ``xml.etree`` parse-back for the map files; ``trajectory.csv`` and
``diagnostics.csv`` read by pandas for the DataFrames.
"""

from __future__ import annotations

import json
import math
import sys
import types
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import navpp
from navpp import api, geodesy
from navpp.cli import app
from navpp.config import Config, OutputConfig
from navpp.errors import ConfigError, InputError
from navpp.io import exports, frames, writers
from navpp.outdir import MANIFEST_NAME as MANIFEST
from navpp.recording import GnssData, ImuData, Recording, Solution

T0_NS = 1_700_000_000_123_456_789          # a unix stamp with a fraction: exercises the time digits
KML = "{http://www.opengis.net/kml/2.2}"
ALL = ("trajectory.tum", "trajectory.geojson", "trajectory.kml")


# --------------------------------------------------------------------------------- helpers


def drive(n_still: int = 250, n_move: int = 1250, rate_hz: float = 50.0) -> Solution:
    """5 s still then 25 s of a 10 m/s arc about (45 N, 7 E, 300 m), with attitude."""
    n = n_still + n_move
    t = 2.5 + np.arange(n) / rate_hz
    s = np.r_[np.zeros(n_still), np.arange(1, n_move + 1) * 10.0 / rate_hz]          # path length, m
    yaw = np.radians(30.0) + s / 400.0                                                 # ccw from east
    step = np.diff(s, prepend=0.0)
    east, north = np.cumsum(step * np.cos(yaw)), np.cumsum(step * np.sin(yaw))
    up = 0.01 * s
    lat, lon, alt = geodesy.enu_to_geodetic(np.column_stack([east, north, up]), np.radians(45.0), np.radians(7.0),
                                            300.0)
    heading = (90.0 - np.degrees(yaw)) % 360.0
    rph = np.column_stack([2.0 * np.sin(s / 50.0), -1.5 + 0.01 * s, heading])
    vel = np.column_stack([10 * np.cos(yaw), 10 * np.sin(yaw), np.full(n, 0.1)]) * (s > 0)[:, None]
    return Solution(t=t, lat_deg=np.degrees(lat), lon_deg=np.degrees(lon), alt=alt, vel_enu=vel, rph_deg=rph,
                    std_enu=np.full((n, 3), 0.5), t0_ns=T0_NS)


def recording_for(sol: Solution, time_base: str = "unix") -> Recording:
    """A minimal recording on ``time_base`` with IMU at the solution's epochs and three fixes:
    one before the span, then two inside it (the anchor is the first of those)."""
    n = len(sol)
    imu = ImuData(t=np.array(sol.t, dtype=float), gyro=np.zeros((n, 3)), accel=np.zeros((n, 3)))
    t = np.array([sol.t[0] - 1.0, sol.t[0] + 0.5, sol.t[0] + 1.0])
    gnss = GnssData(t=t, lat_deg=np.array([44.0, 45.0001, 45.0002]), lon_deg=np.array([6.0, 7.0001, 7.0002]),
                    alt=np.array([0.0, 310.0, 311.0]))
    return Recording(imu=imu, gnss=gnss, t0_ns=sol.t0_ns, time_base=time_base)


def read_tum(path: Path) -> np.ndarray:
    """An independent TUM reader with evo's rules; raises on anything evo would reject."""
    rows = []
    for line in path.read_text().split("\n"):
        if line.startswith("#"):
            continue
        if line == "":
            continue                     # only the file's final newline may give an empty piece
        fields = line.split(" ")         # evo: csv.reader(delimiter=" "): "a  b" or "a b " add empty fields
        assert len(fields) == 8, f"TUM rows need 8 entries and no trailing delimiter: {line!r}"
        rows.append([float(f) for f in fields])
    text = path.read_text()
    assert text.endswith("\n") and "\n\n" not in text
    return np.array(rows)


def quat_to_mat(q_xyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = np.moveaxis(np.asarray(q_xyzw, dtype=float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def nav_rotation(roll_deg: float, pitch_deg: float, heading_deg: float) -> np.ndarray:
    """Body FLU -> local ENU: Rz(pi/2 - heading) Ry(-pitch) Rx(roll) (navpp/__init__ contract)."""
    r, p, y = math.radians(roll_deg), -math.radians(pitch_deg), math.pi / 2 - math.radians(heading_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def csv_t_strings(path: Path) -> list[str]:
    return [line.split(",", 1)[0] for line in path.read_text().splitlines()[1:]]


def tree(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def greedy_map_rows(sol: Solution, interval: float, step: float) -> list[int]:
    """The decimation rule written as a plain loop over every row (the oracle of map_rows)."""
    a = frames.Anchor(float(sol.lat_deg[0]), float(sol.lon_deg[0]), float(sol.alt[0]))
    en = a.enu(sol.lat_deg, sol.lon_deg, sol.alt)[:, :2]
    path, kept, last_slot, last_path = 0.0, [0], 0, 0.0
    for i in range(1, len(sol)):
        path += float(np.hypot(*(en[i] - en[i - 1])))
        slot = math.floor((sol.t[i] - sol.t[0]) / interval)
        first_of_slot = math.floor((sol.t[i - 1] - sol.t[0]) / interval) != slot
        if first_of_slot and slot != last_slot and path - last_path >= step:
            kept.append(i)
            last_slot, last_path = slot, path
    if kept[-1] != len(sol) - 1:
        kept.append(len(sol) - 1)
    return kept


# --------------------------------------------------------------------------------- TUM


def test_tum_reads_like_evo_and_matches_csv_time_enu_and_attitude(tmp_path: Path) -> None:
    sol = drive()
    tum, csv = tmp_path / "trajectory.tum", tmp_path / "trajectory.csv"
    exports.write_tum(tum, sol, filter_name="ekf", log="drive")
    writers.write_trajectory_csv(csv, sol, t0_s=T0_NS * 1e-9)
    rows = read_tum(tum)
    assert rows.shape == (len(sol), 8)
    # t: the same digits as trajectory.csv's t
    tum_t = [line.split(" ", 1)[0] for line in tum.read_text().splitlines() if not line.startswith("#")]
    assert tum_t == csv_t_strings(csv)
    assert tum_t[0] == "1700000002.623457"            # 1700000000.123456789 + 2.5, to the microsecond
    # x y z: ENU about the anchor (no recording: the first row), 4 decimals
    a = frames.anchor_for(sol)
    enu = geodesy.geodetic_to_enu(np.radians(sol.lat_deg), np.radians(sol.lon_deg), sol.alt,
                                  np.radians(a.lat_deg), np.radians(a.lon_deg), a.alt)
    np.testing.assert_allclose(rows[:, 1:4], enu, rtol=0, atol=0.5e-4 + 1e-9)
    # quaternion: unit, w >= 0, body FLU -> anchor ENU
    q = rows[:, 4:8]
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=3e-9)
    assert (q[:, 3] >= 0).all()
    np.testing.assert_allclose(quat_to_mat(q), frames.body_to_map(sol, a), atol=5e-9)
    # at the anchor itself the map axes are the local ENU axes: the navigation-convention rotation
    np.testing.assert_allclose(quat_to_mat(q[0]), nav_rotation(*sol.rph_deg[0]), atol=5e-9)
    comments = [line for line in tum.read_text().splitlines() if line.startswith("#")]
    assert "filter: ekf; log: drive" in comments[1]
    assert f"lat {a.lat_deg:.9f} deg" in comments[3] and f"lon {a.lon_deg:.9f} deg" in comments[3]


def test_tum_anchor_is_the_first_fix_in_the_span(tmp_path: Path) -> None:
    sol = drive(10, 40)
    exports.write_tum(tmp_path / "a.tum", sol, recording_for(sol))
    rows = read_tum(tmp_path / "a.tum")
    enu = geodesy.geodetic_to_enu(np.radians(sol.lat_deg), np.radians(sol.lon_deg), sol.alt,
                                  np.radians(45.0001), np.radians(7.0001), 310.0)
    np.testing.assert_allclose(rows[:, 1:4], enu, rtol=0, atol=0.5e-4 + 1e-9)
    assert "lat 45.000100000 deg, lon 7.000100000 deg, height 310.0000 m" in (tmp_path / "a.tum").read_text()


def test_tum_positions_about_the_first_gnss_fix(sim_log_dir: Path, tmp_path: Path) -> None:
    """With the recording, the anchor is the first fix in the span (shared with the MCAP map frame)."""
    res = api.process(sim_log_dir, write=False, output_rate_hz=25.0)
    exports.write_tum(tmp_path / "a.tum", res.solution, res.recording)
    rows = read_tum(tmp_path / "a.tum")
    sol, g = res.solution, res.recording.gnss
    i = int(np.nonzero(g.t >= sol.t[0])[0][0])
    enu = geodesy.geodetic_to_enu(np.radians(sol.lat_deg), np.radians(sol.lon_deg), sol.alt,
                                  np.radians(g.lat_deg[i]), np.radians(g.lon_deg[i]), g.alt[i])
    np.testing.assert_allclose(rows[:, 1:4], enu, rtol=0, atol=0.5e-4 + 1e-9)


def test_tum_skips_non_finite_rows_and_failure_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sol = drive(10, 40)
    lat = sol.lat_deg.copy()
    lat[7] = np.nan
    rph = sol.rph_deg.copy()
    rph[9, 2] = np.inf
    bad = Solution(t=sol.t, lat_deg=lat, lon_deg=sol.lon_deg, alt=sol.alt, vel_enu=sol.vel_enu, rph_deg=rph,
                   std_enu=sol.std_enu, t0_ns=sol.t0_ns)
    exports.write_tum(tmp_path / "a.tum", bad)
    rows = read_tum(tmp_path / "a.tum")
    assert len(rows) == len(sol) - 2 and np.isfinite(rows).all()

    (tmp_path / "b.tum").write_text("previous\n")

    def broken(*args, **kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(frames, "quat_xyzw", broken)        # fails after the header was written
    with pytest.raises(RuntimeError):
        exports.write_tum(tmp_path / "b.tum", sol)
    assert (tmp_path / "b.tum").read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tum", "b.tum"]


# --------------------------------------------------------------------------------- maps


def test_map_rows_follow_the_rule() -> None:
    sol = drive()
    rows = exports.map_rows(sol)
    assert rows.tolist() == greedy_map_rows(sol, exports.MAP_MIN_INTERVAL_S, exports.MAP_MIN_STEP_M)
    # the still part collapses to its first row; moving at 10 m/s at 50 Hz: one point per 0.1 s
    assert rows[0] == 0 and rows[1] >= 250 and rows[-1] == len(sol) - 1
    slots = np.floor((sol.t[rows[:-1]] - sol.t[0]) / 0.1)
    assert (np.diff(slots) >= 1).all()
    assert 240 <= rows.size <= 252
    assert exports.map_rows(sol, min_step_m=0.0).size == 300 + 1   # every 0.1 s slot of 30 s, and the last row
    with pytest.raises(ValueError):
        exports.map_rows(sol, min_interval_s=0.0)


def test_geojson_is_rfc7946_and_holds_the_kept_rows(tmp_path: Path) -> None:
    sol = drive()
    metrics = {"filter": "ekf", "position_m": {"horizontal": {"rmse": 0.5, "mae": float("nan")}}}
    path = tmp_path / "trajectory.geojson"
    exports.write_geojson(path, sol, recording_for(sol), filter_name="ekf", log="logs/drive.mcap", metrics=metrics)

    def no_constants(name: str):
        raise AssertionError(f"not JSON: {name}")

    doc = json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constants)
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == 1
    feature = doc["features"][0]
    assert feature["type"] == "Feature" and feature["geometry"]["type"] == "LineString"
    coords = np.array(feature["geometry"]["coordinates"])
    rows = exports.map_rows(sol)
    assert coords.shape == (rows.size, 3)
    # RFC 7946 order: longitude, latitude, altitude (7 E, 45 N here)
    assert np.all(np.abs(coords[:, 0] - 7.0) < 0.1) and np.all(np.abs(coords[:, 1] - 45.0) < 0.1)
    np.testing.assert_allclose(coords[:, 0], sol.lon_deg[rows], rtol=0, atol=1e-9)
    np.testing.assert_allclose(coords[:, 1], sol.lat_deg[rows], rtol=0, atol=1e-9)
    np.testing.assert_allclose(coords[:, 2], sol.alt[rows], rtol=0, atol=0.5e-4 + 1e-9)
    p = feature["properties"]
    assert p["filter"] == "ekf" and p["log"] == "logs/drive.mcap" and p["name"] == "navpp ekf: drive.mcap"
    assert p["t_start"] == pytest.approx(1700000002.623457, abs=1e-6)
    assert p["t_end"] == pytest.approx(1700000002.623457 + 29.98, abs=1e-6)
    assert p["points"] == rows.size and p["solution_rows"] == len(sol)
    assert p["start_utc"] == "2023-11-14T22:13:22.623Z"
    assert "0.1 s" in p["decimation"] and "0.1 m" in p["decimation"]
    assert p["metrics"] == {"filter": "ekf", "position_m": {"horizontal": {"rmse": 0.5, "mae": None}}}


def test_geojson_of_one_row_is_a_point(tmp_path: Path) -> None:
    sol = drive(1, 0)
    exports.write_geojson(tmp_path / "one.geojson", sol)
    geometry = json.loads((tmp_path / "one.geojson").read_text())["features"][0]["geometry"]
    assert geometry["type"] == "Point" and len(geometry["coordinates"]) == 3


def test_kml_parses_and_holds_the_kept_rows(tmp_path: Path) -> None:
    sol = drive()
    path = tmp_path / "trajectory.kml"
    metrics = {"reference": "ref <&> .csv", "position_m": {"horizontal": {"rmse": 0.61}, "up": {"rmse": 0.4}}}
    exports.write_kml(path, sol, recording_for(sol), filter_name="aekf", log="a&b.mcap", metrics=metrics)
    root = ET.parse(path).getroot()
    assert root.tag == f"{KML}kml"
    doc = root.find(f"{KML}Document")
    style = doc.find(f"{KML}Style")
    assert style is not None and style.find(f"{KML}LineStyle/{KML}width").text == "3"
    placemark = doc.find(f"{KML}Placemark")
    assert placemark.find(f"{KML}styleUrl").text == "#" + style.get("id")
    assert placemark.find(f"{KML}name").text == "navpp aekf: a&b.mcap"
    line = placemark.find(f"{KML}LineString")
    assert line.find(f"{KML}altitudeMode").text == "clampToGround"
    tuples = line.find(f"{KML}coordinates").text.split()
    coords = np.array([[float(v) for v in item.split(",")] for item in tuples])
    rows = exports.map_rows(sol)
    assert coords.shape == (rows.size, 3)
    np.testing.assert_allclose(coords[:, 0], sol.lon_deg[rows], rtol=0, atol=1e-9)
    np.testing.assert_allclose(coords[:, 1], sol.lat_deg[rows], rtol=0, atol=1e-9)
    np.testing.assert_allclose(coords[:, 2], sol.alt[rows], rtol=0, atol=0.5e-4 + 1e-9)
    data = {d.get("name"): d.find(f"{KML}value").text for d in placemark.iter(f"{KML}Data")}
    assert data["filter"] == "aekf" and data["reference"] == "ref <&> .csv"
    assert float(data["horizontal_rmse_m"]) == 0.61 and float(data["points"]) == rows.size
    span = placemark.find(f"{KML}TimeSpan")
    assert span.find(f"{KML}begin").text == "2023-11-14T22:13:22.623Z"
    exports.write_kml(tmp_path / "abs.kml", sol, altitude_mode="absolute")
    assert ET.parse(tmp_path / "abs.kml").getroot().find(f".//{KML}altitudeMode").text == "absolute"
    with pytest.raises(ValueError, match="altitude_mode"):
        exports.write_kml(tmp_path / "x.kml", sol, altitude_mode="floating")


def test_gpst_times_are_named_in_utc(tmp_path: Path) -> None:
    sol = drive(5, 20)
    exports.write_geojson(tmp_path / "g.geojson", sol, recording_for(sol, "gpst"))
    p = json.loads((tmp_path / "g.geojson").read_text())["features"][0]["properties"]
    assert p["time_base"] == "gpst"
    assert p["start_utc"] == "2023-11-14T22:13:04.623Z"      # GPS - UTC = 18 s in 2023
    for rec in (recording_for(sol, "relative"), None):
        exports.write_geojson(tmp_path / "r.geojson", sol, rec)
        assert "start_utc" not in json.loads((tmp_path / "r.geojson").read_text())["features"][0]["properties"]
    exports.write_kml(tmp_path / "r.kml", sol)
    assert ET.parse(tmp_path / "r.kml").getroot().find(f".//{KML}TimeSpan") is None


def test_absolute_time_keeps_the_nanoseconds_of_t0() -> None:
    t = exports.absolute_time(np.array([0.0, 0.5]), T0_NS)
    assert t.dtype == np.float64
    np.testing.assert_allclose(t - 1_700_000_000, [0.123456789, 0.623456789], rtol=0, atol=3e-7)


# --------------------------------------------------------------------------------- process


@pytest.fixture(scope="module")
def every_format(sim_log_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("exports") / "run"
    res = api.process(sim_log_dir, out_dir=out, formats="csv,tum,geojson,kml")
    return res, out


def test_process_writes_every_asked_format(every_format) -> None:
    res, out = every_format
    names = ["trajectory.csv", "diagnostics.csv", "metrics.json", "metrics.md", "trajectory.tum", "drive-ekf.tum",
             "reference.tum", "trajectory.geojson", "trajectory.kml"]
    assert [p.name for p in res.files] == names
    assert (out / "drive-ekf.tum").read_bytes() == (out / "trajectory.tum").read_bytes()
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == sorted(names)  # no staging directory left
    assert csv_t_strings(out / "trajectory.csv") == [
        line.split(" ", 1)[0] for line in (out / "trajectory.tum").read_text().splitlines() if line[0] != "#"]
    props = json.loads((out / "trajectory.geojson").read_text())["features"][0]["properties"]
    assert props["metrics"] == json.loads((out / "metrics.json").read_text())
    assert props["filter"] == "ekf"
    ET.parse(out / "trajectory.kml")


def test_trajectory_dataframe_equals_the_csv(every_format) -> None:
    res, out = every_format
    df = res.trajectory
    csv = pd.read_csv(out / "trajectory.csv")
    assert list(df.columns) == list(csv.columns) == list(writers.TRAJECTORY_COLUMNS)
    assert (df.dtypes == np.float64).all() and len(df) == len(csv)
    np.testing.assert_allclose(df["t"], csv["t"], rtol=0, atol=1e-6)
    for name, decimals in zip(writers.TRAJECTORY_COLUMNS[1:], writers.TRAJECTORY_DECIMALS[1:]):
        # a value on a rounding half may go either way; the difference then carries the values' ulp
        ulp = float(np.spacing(np.abs(csv[name]).max()))
        np.testing.assert_allclose(df[name], csv[name], rtol=0, atol=0.5 * 10.0 ** -decimals + 8.0 * ulp,
                                   err_msg=name)
    assert res.trajectory is df                        # built once per result


def test_diagnostics_dataframe_equals_the_csv(every_format) -> None:
    res, out = every_format
    df = res.diagnostics
    csv = pd.read_csv(out / "diagnostics.csv")
    assert list(df.columns) == list(csv.columns) and len(df) == len(csv) > 100
    np.testing.assert_allclose(df["t"], csv["t"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(df.drop(columns="t"), csv.drop(columns="t"), rtol=0, atol=0.5e-4 * (1 + 1e-6))


def test_top_level_api(sim_log_dir: Path) -> None:
    assert navpp.process is api.process
    assert "compare" in navpp.__all__ and callable(navpp.compare)
    from navpp import comparison

    assert navpp.compare is comparison.compare
    res = navpp.process(sim_log_dir, write=False, output_rate_hz=10.0)
    assert res.files == () and list(res.trajectory.columns) == list(writers.TRAJECTORY_COLUMNS)
    assert set(res.metrics) >= {"position_m", "filter"}
    np.testing.assert_allclose(np.diff(res.trajectory["t"]), 0.1, atol=1e-6)


def test_top_level_compare_resolves_at_call_time(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = types.ModuleType("navpp.comparison")
    fake.compare = lambda *args, **kwargs: ("called", args, kwargs)
    monkeypatch.setitem(sys.modules, "navpp.comparison", fake)
    assert navpp.__getattr__("compare")(["a"], ["ekf"], jobs=2) == ("called", (["a"], ["ekf"]), {"jobs": 2})
    assert navpp._compare(["a"], ["ekf"]) == ("called", (["a"], ["ekf"]), {})


def test_config_formats_apply_and_the_argument_overrides(sim_log_dir: Path, tmp_path: Path) -> None:
    cfg = Config(output=OutputConfig(formats=("tum",)))
    res = api.process(sim_log_dir, config=cfg, out_dir=tmp_path / "a", output_rate_hz=5.0)
    assert [p.name for p in res.files] == ["diagnostics.csv", "metrics.json", "metrics.md", "trajectory.tum",
                                           "drive-ekf.tum", "reference.tum"]
    res = api.process(sim_log_dir, config=cfg, out_dir=tmp_path / "b", output_rate_hz=5.0, formats=["kml"])
    assert [p.name for p in res.files][-1] == "trajectory.kml" and not (tmp_path / "b" / "trajectory.tum").exists()


def test_rerun_removes_stale_exports(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="csv,tum,geojson,kml")
    (out / "trajectory.tum.bak").write_text("mine\n")
    res = api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="geojson")
    assert [p.name for p in res.files] == ["diagnostics.csv", "metrics.json", "metrics.md", "trajectory.geojson"]
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == sorted(
        ["diagnostics.csv", "metrics.json", "metrics.md", "trajectory.geojson", "trajectory.tum.bak"])


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), RuntimeError("bug")])
def test_failing_writer_keeps_the_previous_run_whole(sim_log_dir: Path, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch, error: Exception) -> None:
    out = tmp_path / "out"
    api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="csv,tum")
    before = tree(out)

    def half_written(path, *args, **kwargs):
        Path(path).write_text("<?xml half")
        raise error

    monkeypatch.setattr(exports, "write_kml", half_written)
    with pytest.raises(InputError if isinstance(error, OSError) else RuntimeError) as exc:
        api.process(sim_log_dir, out_dir=out, output_rate_hz=10.0, formats="csv,kml")
    if isinstance(error, OSError):
        assert str(exc.value) == f"{out / 'trajectory.kml'}: cannot write (no space left on device)"
    assert tree(out) == before                       # trajectory.csv not replaced, trajectory.tum kept
    assert sorted(p.name for p in out.iterdir()) == sorted(before)

    new = tmp_path / "new" / "dir"
    with pytest.raises(InputError if isinstance(error, OSError) else RuntimeError):
        api.process(sim_log_dir, out_dir=new, output_rate_hz=10.0, formats="kml")
    assert not (tmp_path / "new").exists()


def test_format_errors_come_before_reading(sim_log_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def read_log(*args, **kwargs):
        raise AssertionError("the log was read before the formats were checked")

    monkeypatch.setattr(api, "read_log", read_log)
    with pytest.raises(ConfigError, match=r"formats: unknown format 'gpx'; valid formats: 'csv', 'mcap'"):
        api.process(sim_log_dir, out_dir=tmp_path / "o", formats="csv,gpx")
    with pytest.raises(ConfigError, match=r"--embed-input .* add mcap"):
        api.process(sim_log_dir, out_dir=tmp_path / "o", formats="csv", embed_input=True)
    with pytest.raises(ConfigError, match=r"\[output\] formats is csv"):
        api.process(sim_log_dir, out_dir=tmp_path / "o", embed_input=True)
    assert not (tmp_path / "o").exists()


def test_mcap_writer_is_called_with_its_contract(sim_log_dir: Path, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    fake = types.ModuleType("navpp.io.mcap_out")

    def write_trajectory_mcap(path, *, solution, recording, diagnostics=None, biases=None, embed_input=False,
                              input_log=None, filter_name="", imu_mounting_rpy_deg=(0.0, 0.0, 0.0),
                              gnss_lever_arm_m=(0.0, 0.0, 0.0), rate_noise_std=0.0):
        calls.append({"solution": solution, "recording": recording, "diagnostics": diagnostics, "biases": biases,
                      "embed_input": embed_input, "input_log": input_log, "filter_name": filter_name})
        Path(path).write_bytes(b"\x89MCAP0\r\n")

    fake.write_trajectory_mcap = write_trajectory_mcap
    monkeypatch.setitem(sys.modules, "navpp.io.mcap_out", fake)
    out = tmp_path / "out"
    res = api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="mcap", embed_input=True,
                      filter_name="aekf")
    assert [p.name for p in res.files] == ["diagnostics.csv", "metrics.json", "metrics.md", "trajectory.mcap",
                                           "navpp.layout.json"]
    assert (out / "trajectory.mcap").read_bytes() == b"\x89MCAP0\r\n"
    (call,) = calls
    assert call["solution"] is res.solution and call["recording"] is res.recording
    assert call["diagnostics"] is res.run.diagnostics and call["biases"] is res.run.biases
    assert call["embed_input"] is True and call["input_log"] == sim_log_dir and call["filter_name"] == "aekf"


# --------------------------------------------------------------------------------- CLI

runner = CliRunner()


def invoke(*args: str | Path):
    return runner.invoke(app, [str(a) for a in args])


def test_cli_format_combination(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = invoke("process", sim_log_dir, "--out", out, "--output-rate", "5", "--format", "tum, kml,tum", "-q")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "diagnostics.csv", "drive-ekf.tum", "metrics.json", "metrics.md", "reference.tum", "trajectory.kml",
        "trajectory.tum"]


def test_cli_format_overrides_the_config(log_copy: Path, tmp_path: Path) -> None:
    cfg = (log_copy / "navpp.toml").read_text() if (log_copy / "navpp.toml").exists() else ""
    (log_copy / "navpp.toml").write_text(cfg + '\n[output]\nformats = ["geojson"]\n')
    out = tmp_path / "out"
    assert invoke("process", log_copy, "--out", out, "--output-rate", "5", "-q").exit_code == 0
    assert (out / "trajectory.geojson").is_file() and not (out / "trajectory.csv").exists()
    assert invoke("process", log_copy, "--out", out, "--output-rate", "5", "--format", "csv", "-q").exit_code == 0
    assert (out / "trajectory.csv").is_file() and not (out / "trajectory.geojson").exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--format", "csv,gpx"], ("Invalid value for '--format': unknown format 'gpx'; valid formats: 'csv', 'mcap', "
                              "'tum', 'geojson', 'kml'")),
    (["--format", "kmz"], "(did you mean 'kml'?)"),
    (["--format", ","], "Invalid value for '--format': must be a non-empty list of format names"),
    (["--format", "csv,tum", "--embed-input"], "Invalid value for '--embed-input': needs mcap among --format"),
])
def test_cli_format_usage_errors(sim_log_dir: Path, tmp_path: Path, args: list[str], message: str) -> None:
    res = invoke("process", sim_log_dir, "--out", tmp_path / "out", *args)
    assert res.exit_code == 2, res.output
    assert message in " ".join(res.stderr.split())
    assert not (tmp_path / "out").exists()


def test_cli_embed_input_without_mcap_in_the_config_is_exit_1(sim_log_dir: Path, tmp_path: Path) -> None:
    res = invoke("process", sim_log_dir, "--out", tmp_path / "out", "--embed-input")
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "--embed-input" in lines[0] and "add mcap" in lines[0]
    assert not (tmp_path / "out").exists()


def test_mcap_format_writes_a_readable_mcap(sim_log_dir: Path, tmp_path: Path) -> None:
    """Wiring with the real writer (navpp.io.mcap_out), once it is there."""
    pytest.importorskip("navpp.io.mcap_out")
    from mcap.reader import make_reader

    out = tmp_path / "out"
    res = api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="csv,mcap")
    assert [p.name for p in res.files][-2:] == ["trajectory.mcap", "navpp.layout.json"]
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "diagnostics.csv", "metrics.json", "metrics.md", "navpp.layout.json", "trajectory.csv", "trajectory.mcap"]
    with open(out / "trajectory.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {c.topic for c in summary.channels.values()}
    assert {"/navpp/fix", "/navpp/odometry", "/navpp/diagnostics"} <= topics      # diagnostics were passed
    api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0, formats="mcap", embed_input=True)
    with open(out / "trajectory.mcap", "rb") as f:
        embedded = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert topics < embedded                                # --embed-input adds the input's topics
    api.process(sim_log_dir, out_dir=out, output_rate_hz=5.0)
    assert not (out / "trajectory.mcap").exists()          # stale: removed by a run without mcap
