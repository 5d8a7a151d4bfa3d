"""The local ENU frame of the exports: anchor choice, positions, orientation in the anchor's axes."""

import numpy as np

from navpp import geodesy
from navpp.ins.attitude import rph_to_dcm
from navpp.io import frames
from navpp.recording import Solution


def _solution(lat, lon, alt, rph, vel):
    n = len(lat)
    return Solution(t=np.arange(n, dtype=float), lat_deg=np.asarray(lat, float), lon_deg=np.asarray(lon, float),
                    alt=np.asarray(alt, float), vel_enu=np.asarray(vel, float).reshape(n, 3),
                    rph_deg=np.asarray(rph, float).reshape(n, 3), std_enu=np.ones((n, 3)))


def test_positions_are_exact_enu_about_the_anchor():
    a = frames.Anchor(45.0, 7.0, 300.0)
    # 1 km north, 2 km east, 10 m up, by the inverse conversion (the oracle)
    lat, lon, h = geodesy.enu_to_geodetic(np.array([2000.0, 1000.0, 10.0]), np.radians(45.0), np.radians(7.0), 300.0)
    np.testing.assert_allclose(a.enu(np.degrees(lat), np.degrees(lon), h), [2000.0, 1000.0, 10.0], atol=1e-6)


def test_orientation_at_the_anchor_is_the_attitude_and_rotates_with_the_earth_elsewhere():
    a = frames.Anchor(45.0, 7.0, 300.0)
    # heading 30 deg at the anchor: yaw 60 deg counter-clockwise from east, in the map
    sol = _solution([45.0, 45.0], [7.0, 8.0], [300.0, 300.0], [[0, 0, 30], [0, 0, 30]], np.zeros(6))
    R = frames.body_to_map(sol, a)
    np.testing.assert_allclose(R[0], rph_to_dcm(0.0, 0.0, np.radians(30.0)), atol=1e-12)
    q = frames.quat_xyzw(R[:1])[0]
    np.testing.assert_allclose(q, [0.0, 0.0, np.sin(np.radians(30.0)), np.cos(np.radians(30.0))], atol=1e-12)
    # 1 deg of longitude east (~79 km): the local vertical there is tilted by 1 deg * sin(lat) about
    # north-ish, so the body "up" axis seen in the anchor's frame leans east by ~0.7 deg
    up_in_map = R[1] @ np.array([0.0, 0.0, 1.0])
    lean = np.degrees(np.arctan2(up_in_map[0], up_in_map[2]))
    assert abs(lean - np.cos(np.radians(45.0)) * 1.0) < 0.01


def test_body_velocity_of_a_car_driving_north():
    sol = _solution([45.0], [7.0], [300.0], [[0, 0, 0]], [[0.0, 10.0, 0.0]])
    np.testing.assert_allclose(frames.velocity_body(sol), [[10.0, 0.0, 0.0]], atol=1e-12)
    sol = _solution([45.0], [7.0], [300.0], [[0, 0, 90]], [[0.0, 10.0, 0.0]])     # facing east, moving north
    np.testing.assert_allclose(frames.velocity_body(sol), [[0.0, 10.0, 0.0]], atol=1e-12)  # to its left


def test_anchor_is_the_first_fix_in_the_solution_span(sim_log_dir):
    from navpp import api

    res = api.process(sim_log_dir, write=False)
    a = frames.anchor_for(res.solution, res.recording)
    g = res.recording.gnss
    i = int(np.nonzero(g.t >= res.solution.t[0])[0][0])
    assert (a.lat_deg, a.lon_deg, a.alt) == (g.lat_deg[i], g.lon_deg[i], g.alt[i])
    assert frames.anchor_for(res.solution).lat_deg == res.solution.lat_deg[0]
