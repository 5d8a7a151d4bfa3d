"""WGS-84 geodesy against closed-form values and round trips."""

import numpy as np
import pytest

from navpp import geodesy as g


def test_radii_closed_form():
    rm, rn = g.radii(0.0)
    assert rn == pytest.approx(g.A)
    assert rm == pytest.approx(g.A * (1 - g.E2))
    rm, rn = g.radii(np.pi / 2)
    assert rm == pytest.approx(rn)                       # at the pole both equal a^2/b
    assert rn == pytest.approx(g.A ** 2 / g.B, rel=1e-12)


def test_normal_gravity_at_equator_and_pole():
    assert g.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert g.gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    # free-air gradient ~ -3.086e-6 /s^2 per metre
    gradient = (g.gravity(0.7, 100.0) - g.gravity(0.7, 0.0)) / 100.0
    assert gradient == pytest.approx(-3.0877e-6 + 4.4e-9 * np.sin(0.7) ** 2, rel=1e-3)


@pytest.mark.parametrize("lat_deg,lon_deg,h", [(0, 0, 0), (45, 7, 300), (-33.9, 151.2, -30), (89.999, 10, 1e4),
                                               (-89.9, -179.999, 5e3), (60, 180, 3e5), (0.001, -90, 8848)])
def test_ecef_round_trip(lat_deg, lon_deg, h):
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    la, lo, hh = g.ecef_to_geodetic(g.geodetic_to_ecef(lat, lon, h))
    assert abs(la - lat) * g.A < 1e-6
    assert abs(np.angle(np.exp(1j * (lo - lon)))) * g.A * np.cos(lat) < 1e-6
    assert abs(hh - h) < 1e-6


def test_ecef_known_point():
    # equator / Greenwich at h = 0 is (a, 0, 0); north pole is (0, 0, b)
    np.testing.assert_allclose(g.geodetic_to_ecef(0.0, 0.0, 0.0), [g.A, 0, 0], atol=1e-9)
    np.testing.assert_allclose(g.geodetic_to_ecef(np.pi / 2, 0.0, 0.0), [0, 0, g.B], atol=1e-6)


def test_enu_round_trip_and_small_offsets():
    lat0, lon0, h0 = np.radians(45.0), np.radians(7.0), 300.0
    enu = np.array([[10.0, -20.0, 3.0], [1500.0, 2500.0, -40.0]])
    lat, lon, h = g.enu_to_geodetic(enu, lat0, lon0, h0)
    np.testing.assert_allclose(g.geodetic_to_enu(lat, lon, h, lat0, lon0, h0), enu, atol=1e-7)
    # a small northward step equals dlat * (RM + h)
    rm, rn = g.radii(lat0)
    e = g.geodetic_to_enu(lat0 + 1e-7, lon0, h0, lat0, lon0, h0)
    assert e[1] == pytest.approx(1e-7 * (rm + h0), rel=1e-6)
    e = g.geodetic_to_enu(lat0, lon0 + 1e-7, h0, lat0, lon0, h0)
    assert e[0] == pytest.approx(1e-7 * (rn + h0) * np.cos(lat0), rel=1e-6)


def test_earth_and_transport_rate():
    w = g.earth_rate_enu(np.radians(30.0))
    np.testing.assert_allclose(w, [0, g.OMEGA_E * np.cos(np.radians(30)), g.OMEGA_E * 0.5], rtol=1e-12)
    rm, rn = g.radii(0.5)
    np.testing.assert_allclose(g.transport_rate_enu(0.5, 100.0, np.array([10.0, 20.0, 0.0])),
                               [-20 / (rm + 100), 10 / (rn + 100), 10 * np.tan(0.5) / (rn + 100)], rtol=1e-12)
