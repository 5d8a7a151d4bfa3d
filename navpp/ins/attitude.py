"""Attitude algebra: quaternions, direction cosine matrices, rotation vectors, Euler angles.

Conventions
-----------
- ``mat_nb`` (C_b^n) projects body-FLU vectors into navigation-ENU: ``v_n = mat_nb @ v_b``.
- Quaternions are scalar-first ``[w, x, y, z]`` (Hamilton), ``q_nb`` rotates body to nav, so
  that ``mat_nb == quat_to_dcm(q_nb)``.
- Euler angles: one builder, :func:`rpy_to_dcm` (``Rz(yaw) Ry(pitch) Rx(roll)``, rad, about the
  x, y, z axes: ROS ``rpy``, the convention of the mounting settings).  The angles for people
  (``rph``: roll right side down positive, pitch nose up positive, heading clockwise from north)
  are the same rotation with ``pitch -> -pitch`` and ``yaw = pi/2 - heading``:
  ``mat_nb = Rz(pi/2 - heading) @ Ry(-pitch) @ Rx(roll)`` (:func:`rph_to_dcm`).  Names without
  ``_deg`` take radians; ``*_deg_to_dcm`` take degrees in a (..., 3) array.

The scalar functions are numba-compiled (``njit``) and used inside the strapdown kernel; the
``*_batch`` and Euler-angle helpers are vectorised numpy for I/O and simulation.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from navpp.kernel import njit


@njit(cache=True)
def skew(v: np.ndarray) -> np.ndarray:
    """3x3 cross-product matrix: ``skew(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` (scalar first)."""
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ])


@njit(cache=True)
def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate ``[w, -x, -y, -z]``: the inverse of a unit quaternion."""
    return np.array([q[0], -q[1], -q[2], -q[3]])


@njit(cache=True, inline="always")
def rotvec_quat_coeffs(x: float, y: float, z: float) -> tuple[float, float]:
    """``(c, s)`` of the quaternion ``[c, s x, s y, s z]`` of the rotation vector (x, y, z) rad."""
    a = np.sqrt(x * x + y * y + z * z)
    if a < 1e-8:
        # series to 4th order keeps full double precision for tiny angles
        return 1.0 - a * a / 8.0, 0.5 - a * a / 48.0
    return np.cos(0.5 * a), np.sin(0.5 * a) / a


@njit(cache=True)
def rotvec_to_quat(phi: np.ndarray) -> np.ndarray:
    """Exact quaternion of the rotation vector ``phi`` (rad)."""
    c, s = rotvec_quat_coeffs(phi[0], phi[1], phi[2])
    return np.array([c, s * phi[0], s * phi[1], s * phi[2]])


@njit(cache=True)
def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of a unit quaternion; the shorter of the two equivalent rotations."""
    w = q[0]
    x, y, z = q[1], q[2], q[3]
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = np.sqrt(x * x + y * y + z * z)
    if n < 1e-8:  # noqa: SIM108  (the series and the exact form, each with its own line)
        k = 2.0 / w * (1.0 - n * n / (3.0 * w * w))  # 2*atan(n/w)/n to second order
    else:
        k = 2.0 * np.arctan2(n, w) / n
    return np.array([k * x, k * y, k * z])


@njit(cache=True)
def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """DCM of a unit quaternion: ``quat_to_dcm(q_nb) == mat_nb``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@njit(cache=True)
def quat_normalize(q: np.ndarray) -> np.ndarray:
    """``q`` scaled to unit norm."""
    norm: float = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q / norm


def rpy_to_dcm(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> np.ndarray:
    """The one rotation builder: ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, (..., 3, 3), angles in rad.

    Right-handed elementary rotations about the x, y, z axes (ROS ``rpy``): the matrix of a
    frame turned from a reference frame by ``yaw`` about z, then ``pitch`` about the new y, then
    ``roll`` about the new x; it takes vectors resolved in the turned frame into the reference
    frame.  With body FLU and navigation ENU this is ``mat_nb`` for ``yaw`` counter-clockwise
    from east and ``pitch`` positive nose *down* (:func:`rph_to_dcm` gives it from the
    navigation angles).  Inputs broadcast against each other; written out element by element
    (no matrix products), so the result does not depend on the BLAS build.
    """
    roll, pitch, yaw = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (roll, pitch, yaw)))
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    m = np.empty(roll.shape + (3, 3))
    m[..., 0, 0] = cy * cp
    m[..., 0, 1] = cy * sp * sr - sy * cr
    m[..., 0, 2] = cy * sp * cr + sy * sr
    m[..., 1, 0] = sy * cp
    m[..., 1, 1] = sy * sp * sr + cy * cr
    m[..., 1, 2] = sy * sp * cr - cy * sr
    m[..., 2, 0] = -sp
    m[..., 2, 1] = cp * sr
    m[..., 2, 2] = cp * cr
    return m


def rph_to_dcm(roll: ArrayLike, pitch: ArrayLike, heading: ArrayLike) -> np.ndarray:
    """``mat_nb`` (..., 3, 3), body FLU -> navigation ENU, from the navigation angles in rad:
    roll (right side down positive), pitch (nose up positive), heading (clockwise from north).

    ``mat_nb = Rz(pi/2 - heading) @ Ry(-pitch) @ Rx(roll)`` (:func:`rpy_to_dcm`).
    """
    return rpy_to_dcm(roll, -np.asarray(pitch, dtype=float), 0.5 * np.pi - np.asarray(heading, dtype=float))


def rpy_deg_to_dcm(rpy_deg: ArrayLike) -> np.ndarray:
    """:func:`rpy_to_dcm` of roll, pitch, yaw given in degrees as the last axis of ``rpy_deg``
    (..., 3); the convention of ``[imu]`` and ``[vehicle] mounting_rpy_deg`` (sensor -> body,
    vehicle -> body)."""
    rpy = np.radians(np.asarray(rpy_deg, dtype=float))
    return rpy_to_dcm(rpy[..., 0], rpy[..., 1], rpy[..., 2])


def rph_deg_to_dcm(rph_deg: ArrayLike) -> np.ndarray:
    """:func:`rph_to_dcm` of roll, pitch, heading given in degrees as the last axis of
    ``rph_deg`` (..., 3): ``mat_nb`` of the attitude columns of navpp's files."""
    rph = np.radians(np.asarray(rph_deg, dtype=float))
    return rph_to_dcm(rph[..., 0], rph[..., 1], rph[..., 2])


def dcm_to_rph(mat_nb: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(roll, pitch, heading) in rad from ``mat_nb`` (..., 3, 3); heading in [0, 2*pi)."""
    m = np.asarray(mat_nb, dtype=float)
    pitch = np.arcsin(np.clip(m[..., 2, 0], -1.0, 1.0))     # -sin(-pitch) = sin(pitch)
    roll = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    yaw = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    heading = np.mod(0.5 * np.pi - yaw, 2.0 * np.pi)
    return roll, pitch, heading


def dcm_to_quat(mat: ArrayLike) -> np.ndarray:
    """Unit quaternion(s) ``[w, x, y, z]`` (..., 4) of DCM(s) (..., 3, 3); w >= 0."""
    m = np.asarray(mat, dtype=float)
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cand = np.stack([
        1.0 + tr,
        1.0 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
        1.0 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
        1.0 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
    ], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    s = np.sqrt(np.take_along_axis(cand, k[..., None], -1)[..., 0]) * 2.0
    q0 = np.select([k == 0, k == 1, k == 2, k == 3], [
        0.25 * s,
        (m[..., 2, 1] - m[..., 1, 2]) / s,
        (m[..., 0, 2] - m[..., 2, 0]) / s,
        (m[..., 1, 0] - m[..., 0, 1]) / s])
    q1 = np.select([k == 0, k == 1, k == 2, k == 3], [
        (m[..., 2, 1] - m[..., 1, 2]) / s,
        0.25 * s,
        (m[..., 0, 1] + m[..., 1, 0]) / s,
        (m[..., 0, 2] + m[..., 2, 0]) / s])
    q2 = np.select([k == 0, k == 1, k == 2, k == 3], [
        (m[..., 0, 2] - m[..., 2, 0]) / s,
        (m[..., 0, 1] + m[..., 1, 0]) / s,
        0.25 * s,
        (m[..., 1, 2] + m[..., 2, 1]) / s])
    q3 = np.select([k == 0, k == 1, k == 2, k == 3], [
        (m[..., 1, 0] - m[..., 0, 1]) / s,
        (m[..., 0, 2] + m[..., 2, 0]) / s,
        (m[..., 1, 2] + m[..., 2, 1]) / s,
        0.25 * s])
    q[..., 0], q[..., 1], q[..., 2], q[..., 3] = q0, q1, q2, q3
    q *= np.where(q[..., :1] < 0, -1.0, 1.0)
    return q


def quat_to_dcm_batch(q: ArrayLike) -> np.ndarray:
    """DCMs (..., 3, 3) of quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m
