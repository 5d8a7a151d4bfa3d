"""WGS-84 Earth model and coordinate conversions (vectorised numpy).

Conventions: latitude/longitude in radians unless a name ends in ``_deg``; heights in metres
above the WGS-84 ellipsoid; local frames are ENU (east, north, up).  The scalar helpers
(``radii``, ``gravity``, ``earth_rate_enu``, ``transport_rate_enu``) are written in the subset
of numpy that numba compiles, so ``navpp.ins`` compiles these same functions for its kernels.

References: NIMA TR8350.2 (WGS-84 constants); Groves, *Principles of GNSS, Inertial, and
Multisensor Integrated Navigation Systems*, 2nd ed., eqs 2.105-2.106 (radii), 2.134 (normal
gravity, Somigliana) and the free-air height correction used by KF-GINS and pyins.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

#: a latitude, height, ... given as a float or an array: the result has the same kind
FloatOrArray = TypeVar("FloatOrArray", float, np.ndarray)

A = 6378137.0  #: semi-major axis, m
F = 1.0 / 298.257223563  #: flattening
E2 = F * (2.0 - F)  #: first eccentricity squared
B = A * (1.0 - F)  #: semi-minor axis, m
OMEGA_E = 7.2921151467e-5  #: Earth rotation rate, rad/s
GM = 3.986004418e14  #: m^3/s^2

# Somigliana normal gravity on the ellipsoid and a second-order free-air height correction:
# g(lat, h) = G_EQ (1 + K_SOMIGLIANA sin^2 lat) / sqrt(1 - E2 sin^2 lat)
#             - (GRAVITY_H1 - GRAVITY_H1_LAT sin^2 lat) h + GRAVITY_H2 h^2
G_EQ = 9.7803253359  #: normal gravity on the equator, m/s^2
K_SOMIGLIANA = 0.00193185265241  #: Somigliana's constant
GRAVITY_H1 = 3.0877e-6  #: free-air gradient, 1/s^2
GRAVITY_H1_LAT = 4.4e-9  #: its latitude term, 1/s^2
GRAVITY_H2 = 7.2e-14  #: second-order height term, 1/(m s^2)


def radii(lat: FloatOrArray) -> tuple[FloatOrArray, FloatOrArray]:
    """Meridian (north-south) and prime-vertical (east-west) radii of curvature, m.

    Parameters
    ----------
    lat : float or ndarray, rad.

    Returns
    -------
    rm, rn : same shape as ``lat``.
    """
    s = np.sin(lat)
    w2 = 1.0 - E2 * s * s
    w = np.sqrt(w2)
    rn = A / w
    rm = A * (1.0 - E2) / (w2 * w)
    return rm, rn


def gravity(lat: FloatOrArray, h: FloatOrArray) -> FloatOrArray:
    """Magnitude of normal gravity (gravitation + centrifugal), m/s^2, along -up.

    Parameters
    ----------
    lat : rad; h : m above the ellipsoid (scalars or equal-shape arrays).
    """
    s2 = np.sin(lat) ** 2
    g0 = G_EQ * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    g: FloatOrArray = g0 - (GRAVITY_H1 - GRAVITY_H1_LAT * s2) * h + GRAVITY_H2 * h * h
    return g


def earth_rate_enu(lat: float) -> np.ndarray:
    """Earth rotation rate resolved in ENU at latitude ``lat`` (rad), rad/s, shape (3,)."""
    return np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])


def transport_rate_enu(lat: float, h: float, vel_enu: np.ndarray) -> np.ndarray:
    """Rotation rate of the ENU frame w.r.t. the Earth for velocity ``vel_enu`` (m/s), rad/s."""
    rm, rn = radii(lat)
    return np.array([
        -vel_enu[1] / (rm + h),
        vel_enu[0] / (rn + h),
        vel_enu[0] * np.tan(lat) / (rn + h),
    ])


def geodetic_to_ecef(lat: ArrayLike, lon: ArrayLike, h: ArrayLike) -> np.ndarray:
    """Geodetic (rad, rad, m) -> ECEF (m); vectorised, returns (..., 3)."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    h = np.asarray(h, dtype=float)
    _, rn = radii(lat)
    cl = np.cos(lat)
    x = (rn + h) * cl * np.cos(lon)
    y = (rn + h) * cl * np.sin(lon)
    z = (rn * (1.0 - E2) + h) * np.sin(lat)
    return np.stack([x, y, z], axis=-1)


def ecef_to_geodetic(xyz: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF (..., 3) m -> geodetic (lat rad, lon rad, h m).

    Bowring's closed form followed by two Newton refinements: sub-millimetre everywhere
    from the Earth's centre region excluded (|r| > 100 km) to far outside the atmosphere.
    """
    xyz = np.asarray(xyz, dtype=float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    ep2 = E2 / (1.0 - E2)
    theta = np.arctan2(z * A, p * B)
    lat = np.arctan2(z + ep2 * B * np.sin(theta) ** 3, p - E2 * A * np.cos(theta) ** 3)
    for _ in range(2):
        _, rn = radii(lat)
        s = np.sin(lat)
        c = np.cos(lat)
        # h from whichever of p or z is better conditioned at this latitude
        h = np.where(np.abs(c) > 0.1, p / np.where(np.abs(c) > 0.1, c, 1.0) - rn,
                     z / np.where(np.abs(s) > 0.1, s, 1.0) - rn * (1.0 - E2))
        lat = np.arctan2(z, p * (1.0 - E2 * rn / (rn + h)))
    _, rn = radii(lat)
    s = np.sin(lat)
    c = np.cos(lat)
    h = np.where(np.abs(c) > 0.1, p / np.where(np.abs(c) > 0.1, c, 1.0) - rn,
                 z / np.where(np.abs(s) > 0.1, s, 1.0) - rn * (1.0 - E2))
    return lat, lon, h


def mat_enu_from_ecef(lat: ArrayLike, lon: ArrayLike) -> np.ndarray:
    """Rotation matrix projecting ECEF vectors into ENU at (lat, lon) rad; (..., 3, 3)."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    z = np.zeros_like(lat)
    return np.stack([
        np.stack([-so, co, z], axis=-1),
        np.stack([-sl * co, -sl * so, cl], axis=-1),
        np.stack([cl * co, cl * so, sl], axis=-1),
    ], axis=-2)


def geodetic_to_enu(lat: ArrayLike, lon: ArrayLike, h: ArrayLike, lat0: ArrayLike, lon0: ArrayLike,
                    h0: ArrayLike) -> np.ndarray:
    """Position(s) (rad, rad, m) in local ENU metres about the origin(s) (lat0, lon0, h0).

    Exact (through ECEF). Origins may be scalars or arrays broadcastable to the positions,
    so an error at each epoch can be expressed about that epoch's own reference point.
    """
    d = geodetic_to_ecef(lat, lon, h) - geodetic_to_ecef(lat0, lon0, h0)
    m = mat_enu_from_ecef(lat0, lon0)
    enu: np.ndarray = np.einsum("...ij,...j->...i", m, d)
    return enu


def enu_to_geodetic(enu: ArrayLike, lat0: ArrayLike, lon0: ArrayLike, h0: ArrayLike
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local ENU metres (..., 3) about (lat0, lon0, h0) -> geodetic (lat, lon, h)."""
    m = mat_enu_from_ecef(lat0, lon0)
    d = np.einsum("...ji,...j->...i", m, np.asarray(enu, dtype=float))
    return ecef_to_geodetic(geodetic_to_ecef(lat0, lon0, h0) + d)
