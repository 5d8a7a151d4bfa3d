"""Pictures (issue 19, point 9): the series behind the figures against closed forms, the raw-GNSS
row against the metrics, the map's embedded coordinates against the trajectory, coincidence
detection on synthetic series, and ``process --plot`` writing readable figures."""

from __future__ import annotations

import csv
import io
import json
import math
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from navpp.comparison.figures import coincident_groups, identical_label, max_difference
from navpp.comparison.rows import RAW_GNSS, CompareRow, summary_csv, with_raw_gnss
from navpp.comparison.series import error_band_of, gnss_gaps, innovation_band_of, minmax_indices
from navpp.mapview import COORD_DECIMALS, MapLayer, decimate_track, map_html
from navpp.recording import ReferenceData, Solution

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3


def _solution(t: np.ndarray, lat0: float = 48.1, lon0: float = 11.5) -> Solution:
    n = t.size
    lat = lat0 + 1e-6 * t                  # ~0.11 m/s north
    lon = lon0 + 2e-6 * np.sin(0.1 * t)
    std = np.stack([0.5 + 0.01 * t, 0.7 + 0.02 * t, 1.0 + 0.005 * t], axis=1)   # linear in t
    return Solution(t, lat, lon, np.full(n, 500.0), np.zeros((n, 3)), np.zeros((n, 3)), std)


def test_error_band_is_three_times_the_solution_sigma_and_the_error_is_closed_form():
    t = np.arange(0.0, 400.0, 0.01)                        # 40,000 solution rows
    sol = _solution(t)
    t_ref = np.arange(0.05, 399.0, 0.1)                    # between solution rows: interpolated
    dlat = 1e-5                                            # reference 1e-5 deg north of the solution
    lat_ref = 48.1 + 1e-6 * t_ref + dlat
    lon_ref = 11.5 + 2e-6 * np.sin(0.1 * t_ref)
    alt_ref = np.full(t_ref.size, 500.0)
    alt_ref[1234] += 7.0                                   # one spike in up: decimation must keep it
    ref = ReferenceData(t_ref, lat_ref, lon_ref, alt_ref)
    band = error_band_of(SimpleNamespace(reference=ref), sol, bins=100)
    assert band is not None and band.t_s.size < t_ref.size  # decimated ...
    assert t_ref[1234] in band.t_s                           # ... extremes kept
    # the band: 3 x the solution's std (linear in t, so the linear interpolation is exact)
    expect_std = np.stack([0.5 + 0.01 * band.t_s, 0.7 + 0.02 * band.t_s, 1.0 + 0.005 * band.t_s], axis=1)
    np.testing.assert_allclose(band.band_enu_m, 3.0 * expect_std, rtol=1e-9)
    np.testing.assert_allclose(band.band_h_m, 3.0 * np.hypot(expect_std[:, 0], expect_std[:, 1]), rtol=1e-9)
    # the error: estimate - reference = -dlat along north, M the meridian radius of curvature
    lat = np.radians(48.1 + 1e-6 * band.t_s)
    m_radius = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * np.sin(lat) ** 2) ** 1.5
    np.testing.assert_allclose(band.err_enu_m[:, 1], -np.radians(dlat) * m_radius, atol=2e-4)
    assert np.abs(band.err_enu_m[:, 0]).max() < 2e-4
    k = int(np.flatnonzero(band.t_s == t_ref[1234])[0])
    assert band.err_enu_m[k, 2] == pytest.approx(-7.0, abs=1e-3)
    np.testing.assert_allclose(band.err_h_m, np.hypot(band.err_enu_m[:, 0], band.err_enu_m[:, 1]))
    assert error_band_of(SimpleNamespace(reference=None), sol) is None


def test_innovation_band_uses_the_prior_sigma_and_r():
    t = np.arange(0.0, 10.0, 0.01)
    sol = _solution(t)
    fix_t = np.arange(0.2, 9.9, 0.2)
    r_std = np.tile([1.5, 2.0, 3.0], (fix_t.size, 1))
    accepted = np.ones(fix_t.size, bool)
    accepted[7] = False
    diag = SimpleNamespace(t=fix_t, nu=np.ones((fix_t.size, 3)), r_std=r_std, accepted=accepted)
    inno = innovation_band_of(sol, diag)
    before = np.searchsorted(t, fix_t) - 1            # the last row strictly before each fix
    assert np.all(t[before] < fix_t) and np.all(t[before + 1] >= fix_t - 1e-12)
    np.testing.assert_allclose(inno.s_std_enu_m, np.sqrt(sol.std_enu[before] ** 2 + r_std ** 2))
    assert inno.accepted.tolist() == accepted.tolist()


def test_gnss_gaps_merge_windows_and_long_intervals():
    fixes = np.concatenate([np.arange(0, 10, 0.2), np.arange(15, 20, 0.2), np.arange(20.5, 30, 0.2)])
    gaps = gnss_gaps(fixes, windows=((12.0, 5.0),))
    # 9.8 -> 15.0 (a natural gap) merged with the window 12 .. 17; 19.8 -> 20.5 is < 1 s: no gap
    assert gaps == (pytest.approx((9.8, 17.0)),)
    assert gnss_gaps(np.arange(0, 10, 0.2)) == ()


def test_minmax_indices_keep_each_bins_extremes():
    y = np.zeros(10_000)
    y[4321], y[777] = 5.0, -2.0
    idx = minmax_indices(y, 50)
    assert 4321 in idx and 777 in idx and idx.size <= 100 and np.all(np.diff(idx) > 0)


def test_coincident_groups_on_synthetic_series():
    t = np.linspace(0, 10, 200)
    a = np.sin(t)
    series = {"ekf": (t, a), "ckf": (t, a + 1e-5), "ukf": (t, a + 0.5 * 1e-3), "aekf": (t, a + 0.01),
              "short": (t[:-1], a[:-1])}
    groups = coincident_groups(series, tol=1e-3)
    assert groups == [("ekf", "ckf", "ukf"), ("aekf",), ("short",)]
    assert identical_label(groups[0]) == "ekf = ckf = ukf (identical)" and identical_label(("aekf",)) == "aekf"
    with_nan = {"x": (np.array([1.0, np.nan]),), "y": (np.array([1.0, np.nan]),), "z": (np.array([1.0, 2.0]),)}
    assert coincident_groups(with_nan) == [("x", "y"), ("z",)]
    # closer than rel x the data range (2 here, so 0.012 m) per array; the time
    # array (range 10) does not widen the tolerance of the values
    assert coincident_groups(series, rel=6e-3) == [("ekf", "ckf", "ukf", "aekf"), ("short",)]
    assert coincident_groups({"a": (t, a), "b": (t, a + 0.005)}, rel=2e-3) == [("a",), ("b",)]
    assert max_difference(series["ekf"], series["aekf"]) == pytest.approx(0.01)
    assert identical_label(("ckf", "ukf"), 0.0044) == "ckf ≈ ukf (lines coincide, differ ≤ 4.4 mm)"


def _metrics(h: float, raw: dict | None) -> dict:
    stats = {"mae": h, "rmse": h, "max": h, "p95": h}
    m = {"epochs": 10, "position_m": {k: dict(stats) for k in ("east", "north", "up", "horizontal", "3d")}}
    if raw is not None:
        m["gnss_position_m"] = raw
    return m


def test_raw_gnss_row_is_the_metrics_raw_gnss_once_per_log():
    raw = {"epochs": 42}
    for j, axis in enumerate(("east", "north", "up", "horizontal", "3d")):
        raw[axis] = {"mae": 1.0 + j + 0.123456, "rmse": 2.0 + j + 0.654321, "max": 9.0 + j, "p95": 5.0 + j}
    rows = [CompareRow("a", "ekf", "ok", _metrics(0.5, raw), 100, 2, 1.0, 1000, "ref.csv"),
            CompareRow("a", "ckf", "ok", _metrics(0.6, raw), 100, 2, 1.0, 1000, "ref.csv"),
            CompareRow("b", "ekf", "failed", None),
            CompareRow("c", "ekf", "ok", None, 100, 0, 1.0, 1000)]           # no reference: no raw row
    out = with_raw_gnss(rows)
    assert [(r.log, r.filter) for r in out] == [("a", "ekf"), ("a", "ckf"), ("a", RAW_GNSS), ("b", "ekf"),
                                                ("c", "ekf")]
    table = list(csv.DictReader(io.StringIO(summary_csv(rows))))
    rec = table[2]
    assert rec["filter"] == RAW_GNSS and rec["epochs"] == rec["gnss_epochs"] == "42"
    for axis in ("east", "north", "up", "horizontal"):
        assert float(rec[f"{axis}_mae"]) == round(raw[axis]["mae"], 4)
        assert float(rec[f"{axis}_rmse"]) == round(raw[axis]["rmse"], 4)
    assert float(rec["3d_rmse"]) == round(raw["3d"]["rmse"], 4)
    assert float(rec["horizontal_p95"]) == raw["horizontal"]["p95"]
    assert rec["runtime_s"] == rec["gnss_rejected"] == rec["imu_samples"] == ""
    assert rec["reference"] == "ref.csv"


class _MapParser(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.data: str | None = None
        self.scripts = 0
        self._in = False

    def handle_starttag(self, tag, attrs):
        if tag == "script":
            self.scripts += 1
            self._in = dict(attrs).get("id") == "navpp-map-data"

    def handle_endtag(self, tag):
        self._in = False

    def handle_data(self, data):
        if self._in:
            self.data = (self.data or "") + data


def map_document(text: str) -> dict:
    """The JSON data of a map page, found with html.parser (the page must parse)."""
    p = _MapParser()
    p.feed(text)
    p.close()
    assert p.data is not None and p.scripts == 2
    return json.loads(p.data)


def test_map_page_embeds_the_layers_rounded():
    lat = 48.0 + np.linspace(0, 0.01, 10_001) + 1.23456789e-9
    lon = 11.0 + np.linspace(0, 0.02, 10_001)
    dlat, dlon = decimate_track(lat, lon, keep=1000)
    assert dlat.size <= 1001 and dlat[-1] == lat[-1] and dlat[0] == lat[0]
    page = map_html("t </script>", [MapLayer("track", "line", "#123456", ((dlat, dlon),)),
                                    MapLayer("fixes", "points", "#777", ((lat[:5], lon[:5]),))])
    doc = map_document(page)
    seg = np.asarray(doc["layers"][0]["segments"][0])
    np.testing.assert_allclose(seg[:, 0], dlat, atol=0.5 * 10.0 ** -COORD_DECIMALS)
    np.testing.assert_allclose(seg[:, 1], dlon, atol=0.5 * 10.0 ** -COORD_DECIMALS)
    assert doc["layers"][1]["kind"] == "points" and len(doc["layers"][1]["segments"][0]) == 5
    assert "t &lt;/script&gt;" in page


@pytest.fixture(scope="module")
def plotted(sim_log_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    """``navpp.process(..., plot=True)`` on the session log with a simulated outage."""
    from navpp import api

    out = tmp_path_factory.mktemp("plots")
    res = api.process(sim_log_dir, filter_name="ekf", out_dir=out, gnss_outages=[(60.0, 10.0)], plot=True)
    return res, out


def test_process_plot_writes_readable_figures_and_a_map(plotted):
    from matplotlib.image import imread

    res, out = plotted
    label = Path(res.recording.source or "drive").name
    names = {p.name for p in res.files}
    pngs = sorted(n for n in names if n.endswith(".png"))
    assert pngs == ["drive_ekf_errors.png", "drive_trajectory.png"], (label, names)
    for n in pngs:
        data = (out / n).read_bytes()
        assert data.startswith(PNG_SIGNATURE) and imread(io.BytesIO(data), format="png").shape[0] > 300
    assert "drive_map.html" in names


def test_map_track_is_the_trajectory_decimated(plotted):
    res, out = plotted
    doc = map_document((out / "drive_map.html").read_text(encoding="utf-8"))
    layers = {ly["name"]: ly for ly in doc["layers"]}
    assert set(layers) >= {"GNSS fixes", "reference", "ekf"}
    track = np.asarray(layers["ekf"]["segments"][0])
    traj = res.trajectory          # the written trajectory, full precision (one row per IMU sample here)
    lat, lon = traj["lat"].to_numpy(), traj["lon"].to_numpy()
    assert track[0] == pytest.approx([lat[0], lon[0]], abs=1e-7) and track[-1] == pytest.approx([lat[-1], lon[-1]],
                                                                                               abs=1e-7)
    # every point of the map is a trajectory row, in time order, within the rounding of 1e-7 deg
    prev = 0
    for la, lo in track:
        rows = np.flatnonzero((np.abs(lat - la) <= 0.51e-7) & (np.abs(lon - lo) <= 0.51e-7))
        later = rows[rows >= prev]
        assert later.size, (la, lo)
        prev = int(later[0])
    assert 500 <= len(track) <= 4001
    # the outage: the simulated window is one of the outage segments, on the track
    assert any(name.startswith("GNSS outages") for name in layers)


def test_errors_figure_band_is_the_solution_sigma(plotted):
    """The series the error figure draws, from the run: 3 x std of trajectory.csv at the epochs."""
    from navpp.comparison.series import error_band_of as band_of

    res, _ = plotted
    band = band_of(res.recording, res.solution)
    traj = res.trajectory
    t = traj["t"].to_numpy() - res.recording.t0_ns * 1e-9
    for j, col in enumerate(("std_e", "std_n", "std_u")):
        np.testing.assert_allclose(band.band_enu_m[:, j], 3.0 * np.interp(band.t_s, t, traj[col].to_numpy()),
                                   rtol=0, atol=1e-4)     # 0.1 mm: the steps at the fixes, t rounded to 1 us
    assert math.isfinite(float(band.err_h_m.max()))


def test_position_groups_name_runs_whose_lines_coincide():
    from navpp.comparison.figures import position_groups
    from navpp.comparison.series import RunSeries

    k = np.arange(500.0)
    east, north = 10.0 * np.cos(k / 50), 10.0 * np.sin(k / 50)
    cdf = np.linspace(0.0, 1.5, 201)                       # an error axis of 1.5 m: 7.5 mm coincide
    runs = {"ckf": RunSeries(east, north, cdf_m=cdf),
            "ukf": RunSeries(east + 0.0044, north, cdf_m=cdf + 0.001),
            "ekf": RunSeries(east + 0.02, north, cdf_m=cdf),
            "aekf": RunSeries(east + 0.02, north + 0.0005, cdf_m=cdf)}
    assert position_groups(runs) == [("ckf", "ckf ≈ ukf (lines coincide, differ ≤ 4.4 mm)"),
                                     ("ekf", "ekf = aekf (identical)")]
    # without a reference (no error axis): identical within 1 mm only
    bare = {n: RunSeries(s.east_m, s.north_m) for n, s in runs.items()}
    assert [label for _, label in position_groups(bare)] == ["ckf", "ukf", "ekf = aekf (identical)"]
