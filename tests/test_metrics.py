"""Metrics against closed-form oracles: known offsets, hand-computed statistics, wraps."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from navpp import geodesy
from navpp.errors import InputError
from navpp.ins.attitude import rph_deg_to_dcm
from navpp.metrics import (
    associate,
    compute_metrics,
    error_stats,
    interpolate_solution,
    position_errors_enu,
    wrap_deg,
)
from navpp.recording import GnssData, ReferenceData, Solution

LATITUDES = [-89.0, -60.0, -33.9, 0.0, 30.5, 52.2, 75.0, 89.5]


def _offset(lat_deg, lon_deg, alt, enu):
    """Positions displaced by ``enu`` (m) in the local ENU frame of each point."""
    lat, lon, h = geodesy.enu_to_geodetic(np.broadcast_to(enu, (len(lat_deg), 3)),
                                          np.radians(lat_deg), np.radians(lon_deg), alt)
    return np.degrees(lat), np.degrees(lon), h


def _solution(t, lat, lon, alt, vel=None, rph=None):
    n = len(t)
    z = np.zeros((n, 3))
    return Solution(t=np.asarray(t, float), lat_deg=np.asarray(lat, float),
                    lon_deg=np.asarray(lon, float), alt=np.asarray(alt, float),
                    vel_enu=z.copy() if vel is None else np.asarray(vel, float),
                    rph_deg=z.copy() if rph is None else np.asarray(rph, float),
                    std_enu=np.full((n, 3), 0.1))


def _reference(lat0=30.5, n=50, rate=10.0, vel=None, rph=None):
    t = np.arange(n) / rate
    # a straight-ish drive north-east at ~14 m/s
    lat = lat0 + 1e-4 * t
    lon = 114.3 + 1e-4 * t
    alt = 20.0 + 0.1 * t
    return ReferenceData(t=t, lat_deg=lat, lon_deg=lon, alt=alt, vel_enu=vel, rph_deg=rph,
                         source="ref.csv")


def _kwargs():
    return dict(filter_name="ekf", log="drive.mcap", reference="ref.csv", runtime_s=1.5,
                imu_samples=1000, gnss_epochs=10, gnss_rejected=1)


# --------------------------------------------------------------------------- position errors


@pytest.mark.parametrize("lat0", LATITUDES)
def test_known_enu_offset_is_recovered(lat0):
    ref_lat = lat0 + np.linspace(-0.2, 0.2, 7)
    ref_lat = np.clip(ref_lat, -89.9, 89.9)
    ref_lon = np.linspace(-179.9, 179.9, 7)
    ref_alt = np.linspace(-50.0, 3000.0, 7)
    lat, lon, alt = _offset(ref_lat, ref_lon, ref_alt, [1.0, -2.0, 0.5])
    err = position_errors_enu(lat, lon, alt, ref_lat, ref_lon, ref_alt)
    assert err.shape == (7, 3)
    np.testing.assert_allclose(err, np.tile([1.0, -2.0, 0.5], (7, 1)), atol=1e-3)


def test_east_is_longitude_and_north_is_latitude():
    # +1e-5 deg of latitude at the equator is ~1.106 m north; +1e-5 deg of longitude ~1.113 m east
    err = position_errors_enu([1e-5, 0.0], [0.0, 1e-5], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    rm, rn = geodesy.radii(0.0)
    np.testing.assert_allclose(err[0], [0.0, rm * math.radians(1e-5), 0.0], atol=1e-6)
    np.testing.assert_allclose(err[1], [rn * math.radians(1e-5), 0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("lat0", [-60.0, 0.0, 30.5, 75.0])
def test_compute_metrics_on_offset_solution(lat0):
    ref = _reference(lat0)
    lat, lon, alt = _offset(ref.lat_deg, ref.lon_deg, ref.alt, [1.0, -2.0, 0.5])
    sol = _solution(ref.t, lat, lon, alt)
    m = compute_metrics(sol, ref, **_kwargs())
    pos = m["position_m"]
    for axis, value in (("east", 1.0), ("north", 2.0), ("up", 0.5),
                        ("horizontal", math.sqrt(5.0)), ("3d", math.sqrt(5.25))):
        for stat in ("mae", "rmse", "max", "p95"):
            assert pos[axis][stat] == pytest.approx(value, abs=1e-3), (axis, stat)
    assert m["epochs"] == len(ref)


# --------------------------------------------------------------------------- statistics


def test_error_stats_hand_computed():
    err = np.array([[1.0, 0.0, 2.0], [-2.0, 0.0, -2.0], [3.0, 0.0, 2.0],
                    [-4.0, 0.0, -2.0], [10.0, 0.0, 2.0]])
    s = error_stats(err)
    assert s["east"] == pytest.approx({"mae": 4.0, "rmse": math.sqrt(26.0), "max": 10.0,
                                       "p95": 4.0 + 0.8 * 6.0})
    assert s["north"] == pytest.approx({"mae": 0.0, "rmse": 0.0, "max": 0.0, "p95": 0.0})
    assert s["up"] == pytest.approx({"mae": 2.0, "rmse": 2.0, "max": 2.0, "p95": 2.0})
    assert s["horizontal"] == pytest.approx(s["east"])
    d3 = [math.sqrt(5.0), math.sqrt(8.0), math.sqrt(13.0), math.sqrt(20.0), math.sqrt(104.0)]
    assert s["3d"] == pytest.approx({"mae": sum(d3) / 5, "rmse": math.sqrt(sum(v * v for v in d3) / 5),
                                     "max": math.sqrt(104.0), "p95": d3[3] + 0.8 * (d3[4] - d3[3])})
    for axis in s.values():
        assert all(type(v) is float for v in axis.values())


def test_error_stats_horizontal_uses_hypot():
    s = error_stats(np.array([[3.0, 4.0, 0.0], [-3.0, -4.0, 12.0]]))
    assert s["horizontal"]["mae"] == pytest.approx(5.0)
    assert s["3d"]["max"] == pytest.approx(13.0)


def test_error_stats_rejects_bad_shape():
    with pytest.raises(ValueError):
        error_stats(np.zeros((0, 3)))
    with pytest.raises(ValueError):
        error_stats(np.zeros((4, 2)))


# --------------------------------------------------------------------------- association, interpolation


def test_association_keeps_only_epochs_inside_the_span():
    t_est = np.array([1.0, 2.0, 3.0, 4.0])
    t_ref = np.array([0.0, 0.5, 1.0, 1.7, 2.5, 4.0, 4.01, 10.0, np.nan])
    a = associate(t_est, t_ref)
    np.testing.assert_array_equal(a.idx_ref, [2, 3, 4, 5])
    np.testing.assert_array_equal(a.t, [1.0, 1.7, 2.5, 4.0])
    assert associate(t_est, np.array([5.0, 6.0])).idx_ref.size == 0
    assert associate(np.array([]), t_ref).idx_ref.size == 0


def test_interpolation_of_linear_trajectory_is_exact():
    t = np.array([0.0, 0.1, 0.25, 0.4, 1.0, 2.0])
    rate = np.array([1e-5, -2e-5, 0.3])
    sol = _solution(t, 30.0 + rate[0] * t, 114.0 + rate[1] * t, 10.0 + rate[2] * t,
                    vel=np.stack([t, -2 * t, 0.5 + t], -1),
                    rph=np.stack([1.0 + t, -2.0 + 3 * t, 10.0 + 20 * t], -1))
    tq = np.array([0.0, 0.05, 0.33, 0.7, 1.5, 2.0])
    out = interpolate_solution(sol, tq)
    np.testing.assert_allclose(out["lat_deg"], 30.0 + rate[0] * tq, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["lon_deg"], 114.0 + rate[1] * tq, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["alt"], 10.0 + rate[2] * tq, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["vel_enu"], np.stack([tq, -2 * tq, 0.5 + tq], -1), atol=1e-12)
    np.testing.assert_allclose(out["rph_deg"], np.stack([1.0 + tq, -2.0 + 3 * tq, 10.0 + 20 * tq], -1),
                               atol=1e-12)
    np.testing.assert_allclose(out["std_enu"], 0.1, atol=1e-15)


def test_heading_and_longitude_interpolate_across_the_wrap():
    t = np.array([0.0, 2.0])
    sol = _solution(t, [0.0, 0.0], [179.9999, -179.9999], [0.0, 0.0],
                    rph=np.array([[0.0, 0.0, 359.0], [0.0, 0.0, 1.0]]))
    out = interpolate_solution(sol, np.array([0.5, 1.0, 1.5]))
    np.testing.assert_allclose(out["rph_deg"][:, 2], [359.5, 0.0, 0.5], atol=1e-9)
    assert np.all((out["rph_deg"][:, 2] >= 0.0) & (out["rph_deg"][:, 2] < 360.0))
    np.testing.assert_allclose(out["lon_deg"][[0, 2]], [179.99995, -179.99995], atol=1e-9)
    assert abs(abs(out["lon_deg"][1]) - 180.0) < 1e-9


def test_heading_error_wraps():
    assert wrap_deg(359.0 - 1.0) == pytest.approx(-2.0)
    assert wrap_deg(1.0 - 359.0) == pytest.approx(2.0)
    assert wrap_deg(180.0) == pytest.approx(-180.0)
    ref = _reference(n=5, vel=np.zeros((5, 3)),
                     rph=np.tile([0.0, 0.0, 1.0], (5, 1)))
    sol = _solution(ref.t, ref.lat_deg, ref.lon_deg, ref.alt, rph=np.tile([0.5, -0.25, 359.0], (5, 1)))
    m = compute_metrics(sol, ref, **_kwargs())
    assert m["attitude_deg"]["heading"] == pytest.approx({"mae": 2.0, "rmse": 2.0, "max": 2.0, "p95": 2.0})
    assert m["attitude_deg"]["roll"]["max"] == pytest.approx(0.5)
    assert m["attitude_deg"]["pitch"]["rmse"] == pytest.approx(0.25)
    assert m["velocity_mps"]["3d"]["max"] == 0.0


# --------------------------------------------------------------------------- compute_metrics structure


def test_metrics_structure_and_types():
    ref = _reference(n=20)
    sol = _solution(ref.t[2:15], ref.lat_deg[2:15], ref.lon_deg[2:15], ref.alt[2:15])
    m = compute_metrics(sol, ref, **_kwargs())
    assert list(m) == ["filter", "log", "reference", "epochs", "position_m", "runtime_s",
                       "imu_samples", "gnss_epochs", "gnss_rejected"]
    assert m["epochs"] == 13
    assert (m["filter"], m["log"], m["reference"]) == ("ekf", "drive.mcap", "ref.csv")
    assert set(m["position_m"]) == {"east", "north", "up", "horizontal", "3d"}
    for stats in m["position_m"].values():
        assert set(stats) == {"mae", "rmse", "max", "p95"}
    assert type(m["runtime_s"]) is float and type(m["imu_samples"]) is int
    assert json.loads(json.dumps(m, allow_nan=False)) == m


def test_no_overlap_raises_one_line_input_error():
    ref = _reference(n=10)  # t in [0, 0.9]
    sol = _solution(ref.t + 5.0, ref.lat_deg, ref.lon_deg, ref.alt)
    with pytest.raises(InputError) as info:
        compute_metrics(sol, ref, **_kwargs())
    msg = str(info.value)
    assert "\n" not in msg
    assert "5.000" in msg and "5.900" in msg and "0.000" in msg and "0.900" in msg


# --------------------------------------------------------------------------- rotations, raw GNSS


def _gnss_at_antenna(ref, antenna_enu, fix_error_enu, t):
    """GNSS fixes at ``antenna + fix_error`` (ENU about the reference body point) at times t."""
    lat = np.interp(t, ref.t, ref.lat_deg)
    lon = np.interp(t, ref.t, ref.lon_deg)
    alt = np.interp(t, ref.t, ref.alt)
    g_lat, g_lon, g_alt = _offset(lat, lon, alt, np.asarray(antenna_enu) + fix_error_enu)
    return GnssData(t=t, lat_deg=g_lat, lon_deg=g_lon, alt=g_alt)


def test_raw_gnss_stats_with_lever_arm_and_attitude():
    n = 40
    rph = np.tile([20.0, -5.0, 135.0], (n, 1))
    ref = _reference(n=n, rph=rph)
    lever = (0.5, -0.3, 1.2)
    antenna = rph_deg_to_dcm(rph[0]) @ lever
    t_g = np.array([-1.0, 0.05, 0.5, 1.25, 2.0, 3.9, 4.5])  # -1.0 and 4.5 lie outside the reference
    gnss = _gnss_at_antenna(ref, antenna, [0.3, -0.2, 0.1], t_g)
    sol = _solution(ref.t, ref.lat_deg, ref.lon_deg, ref.alt, rph=rph)
    m = compute_metrics(sol, ref, gnss=gnss, lever_arm_m=lever, **_kwargs())
    g = m["gnss_position_m"]
    assert g["epochs"] == 5
    assert "note" not in g
    for axis, value in (("east", 0.3), ("north", 0.2), ("up", 0.1),
                        ("horizontal", math.hypot(0.3, 0.2)), ("3d", math.sqrt(0.14))):
        assert g[axis]["rmse"] == pytest.approx(value, abs=1e-3)
        assert g[axis]["max"] == pytest.approx(value, abs=1e-3)
    # ignoring the lever arm would be wrong by |lever| ~ 1.3 m
    m0 = compute_metrics(sol, ref, gnss=gnss, **_kwargs())
    assert m0["gnss_position_m"]["3d"]["mae"] > 1.0


def test_raw_gnss_lever_arm_from_velocity_heading_or_vertical_only():
    n = 30
    vel = np.tile([5.0, 0.0, 0.0], (n, 1))  # due east: heading 90 deg
    ref = _reference(n=n, vel=vel)
    lever = (1.0, 0.0, 0.0)  # 1 m forward -> 1 m east
    t_g = np.array([0.2, 1.0, 2.0])
    gnss = _gnss_at_antenna(ref, [1.0, 0.0, 0.0], [0.0, 0.4, 0.0], t_g)
    sol = _solution(ref.t, ref.lat_deg, ref.lon_deg, ref.alt)
    g = compute_metrics(sol, ref, gnss=gnss, lever_arm_m=lever, **_kwargs())["gnss_position_m"]
    assert g["east"]["max"] == pytest.approx(0.0, abs=1e-3)
    assert g["north"]["mae"] == pytest.approx(0.4, abs=1e-3)
    assert "velocity" in g["note"]

    ref_bare = _reference(n=n)
    g = compute_metrics(sol, ref_bare, gnss=gnss, lever_arm_m=lever, **_kwargs())["gnss_position_m"]
    assert g["east"]["mae"] == pytest.approx(1.0, abs=1e-3)  # horizontal lever arm not removed
    assert "only the vertical part" in g["note"]


def test_raw_gnss_outside_reference_span():
    ref = _reference(n=10)
    gnss = GnssData(t=np.array([50.0, 60.0]), lat_deg=np.array([30.0, 30.0]),
                    lon_deg=np.array([114.0, 114.0]), alt=np.array([0.0, 0.0]))
    sol = _solution(ref.t, ref.lat_deg, ref.lon_deg, ref.alt)
    g = compute_metrics(sol, ref, gnss=gnss, **_kwargs())["gnss_position_m"]
    assert g["epochs"] == 0 and "note" in g


def test_raw_gnss_vertical_lever_arm_without_reference_heading():
    n = 20
    t = np.arange(n, dtype=float)
    ref = ReferenceData(t, np.full(n, 45.0), np.full(n, 7.0), np.full(n, 100.0))
    sol = _solution(t, ref.lat_deg, ref.lon_deg, ref.alt)
    gnss = GnssData(t, ref.lat_deg.copy(), ref.lon_deg.copy(), ref.alt + 1.5)   # antenna 1.5 m up
    g = compute_metrics(sol, ref, gnss=gnss, lever_arm_m=(0.3, 0.0, 1.5), **_kwargs())["gnss_position_m"]
    assert g["up"]["max"] == pytest.approx(0.0, abs=1e-6)


def test_decreasing_times_found_across_the_windows_of_a_spilled_series() -> None:
    """metrics._decreasing on a spilled series (window by window) agrees with the whole-array check,
    also for a decrease between the last row of one window and the first of the next."""
    from navpp import spill
    from navpp.metrics import _decreasing

    n = 2 * spill.WINDOW_ROWS + 3
    t = spill.empty_rows(n, (), np.float64, True)
    t[:] = np.arange(n, dtype=float)
    assert spill.spilled(t) and not _decreasing(t)
    for k in (1, spill.WINDOW_ROWS, spill.WINDOW_ROWS + 1, n - 1):       # t[k] < t[k - 1]
        t[:] = np.arange(n, dtype=float)
        t[k] = t[k - 1] - 0.5
        assert _decreasing(t) == bool(np.any(np.asarray(t)[1:] < np.asarray(t)[:-1])) is True
    assert not _decreasing(np.array([3.0]))
