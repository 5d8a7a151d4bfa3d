"""The local frame of navpp's exports: ENU metres on the tangent plane of one anchor point.

Every export that needs Cartesian coordinates (TUM files, the MCAP ``map`` frame) uses the
same anchor, so they line up with each other: the first GNSS fix inside the solution's span
(the user's first known position), else the solution's first row.

Positions are exact (through ECEF).  Orientations are expressed in the anchor's ENU axes:
the local-level ENU frame at a point ``p`` is rotated from the anchor's by about
``distance / R_earth`` (0.009 deg per km), and :func:`body_to_map` applies that rotation, so
a vehicle driving in a straight line keeps a constant orientation in the map only where
the Earth is flat.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import geodesy
from ..ins.attitude import dcm_to_quat, rph_to_dcm
from ..recording import Recording, Solution


@dataclass(frozen=True)
class Anchor:
    """Origin of the local ENU frame: latitude, longitude (deg) and ellipsoidal height (m)."""

    lat_deg: float
    lon_deg: float
    alt: float

    def enu(self, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray) -> np.ndarray:
        """Geodetic positions -> (N, 3) ENU metres about the anchor."""
        return geodesy.geodetic_to_enu(np.radians(lat_deg), np.radians(lon_deg), np.asarray(alt, dtype=float),
                                       np.radians(self.lat_deg), np.radians(self.lon_deg), self.alt)


def anchor_for(solution: Solution, recording: Recording | None = None) -> Anchor:
    """The first GNSS fix at or after the solution's first epoch; else the solution's first row."""
    if recording is not None and recording.gnss is not None and len(recording.gnss.t):
        g = recording.gnss
        idx = np.nonzero(g.t >= solution.t[0])[0]
        if idx.size:
            i = int(idx[0])
            return Anchor(float(g.lat_deg[i]), float(g.lon_deg[i]), float(g.alt[i]))
    return Anchor(float(solution.lat_deg[0]), float(solution.lon_deg[0]), float(solution.alt[0]))


def body_to_map(solution: Solution, anchor: Anchor) -> np.ndarray:
    """Rotation matrices (N, 3, 3) taking body-FLU vectors into the anchor's ENU axes.

    ``C_map_body = M_anchor M_p^T C_enu(p)_body`` with ``M`` the ECEF-to-ENU rotation at the
    anchor and at each position ``p``, and ``C_enu(p)_body`` from the solution's roll, pitch,
    heading (navigation convention).
    """
    rph = np.radians(np.asarray(solution.rph_deg, dtype=float))
    c_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
    m_p = geodesy.mat_enu_from_ecef(np.radians(solution.lat_deg), np.radians(solution.lon_deg))
    m_a = geodesy.mat_enu_from_ecef(np.radians(anchor.lat_deg), np.radians(anchor.lon_deg))
    return np.einsum("ij,nkj,nkl->nil", m_a, m_p, c_nb, optimize=True)


def quat_xyzw(mats: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) in ROS/TUM order ``x, y, z, w`` (w >= 0) of rotations (N, 3, 3)."""
    q = dcm_to_quat(mats)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def velocity_body(solution: Solution) -> np.ndarray:
    """Velocity in body FLU (N, 3), m/s, from the ENU velocity and the attitude."""
    rph = np.radians(np.asarray(solution.rph_deg, dtype=float))
    c_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
    return np.einsum("nji,nj->ni", c_nb, np.asarray(solution.vel_enu, dtype=float))
