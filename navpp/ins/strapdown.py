"""Strapdown mechanisation in the local-level ENU frame (numba kernels + thin wrappers).

Nominal navigation state, a flat float64 vector of length 16 (layout in :mod:`navpp.ins.state`):
``q_nb`` (4, scalar-first quaternion body FLU -> nav ENU), ``vel_enu`` (3, m/s), ``lat, lon``
(rad), ``h`` (m, WGS-84 ellipsoidal), ``gyro_bias`` (3, rad/s, body), ``accel_bias`` (3, m/s^2,
body).  Sensor model: true rate = measured - gyro_bias, true specific force = measured -
accel_bias.

Integration between two nodes (IMU sample times, or a sample interpolated to an exact epoch)
uses the rates at both ends under a linear-in-time model: the attitude increment carries the
exact second-order coning term ``(w0 x w1) T^2 / 12`` and the velocity increment the exact
first-order rotation/sculling integral ``int(alpha x f) dt``; the navigation-frame rotation,
gravity and Coriolis terms are evaluated at the interval mid-point (one predictor pass).

References: Savage, *Strapdown Analytics* (2000), ch. 7 and 19 (coning / sculling);
Groves (2013) eqs 5.54-5.56 (local-navigation-frame mechanisation); Shin (2005) and KF-GINS
``insmech.cpp`` for the mid-point scheme.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import numpy as np

from navpp.kernel import njit

from .. import geodesy
from .state import (
    NOMINAL_BA,
    NOMINAL_BG,
    NOMINAL_POS,
    NOMINAL_Q,
    NOMINAL_SIZE,
    NOMINAL_VEL,
    PATH_SIZE,
    X_BA,
    X_BG,
    X_H,
    X_LAT,
    X_LON,
    X_QW,
    X_QX,
    X_QY,
    X_QZ,
    X_VE,
    X_VN,
    X_VU,
)

# the scalar geodesy functions compiled for the kernels (typed for scalars: numba specialises per call)
#: :func:`navpp.geodesy.radii`, compiled: (meridian, prime-vertical) radius of curvature, m, at a latitude (rad)
radii = cast(Callable[[float], tuple[float, float]], njit(cache=True)(geodesy.radii))
#: :func:`navpp.geodesy.gravity`, compiled: normal gravity, m/s^2, at (lat rad, h m)
gravity = cast(Callable[[float, float], float], njit(cache=True)(geodesy.gravity))
_OMEGA_E = geodesy.OMEGA_E
_A = geodesy.A
_E2 = geodesy.E2


@njit(cache=True)
def nav_rates(lat: float, h: float, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """At (``lat`` rad, ``h`` m) with ENU velocity ``vel`` (m/s): the Earth rate and the transport
    rate (ENU, rad/s), the normal gravity (m/s^2) and the meridian and prime-vertical radii (m)."""
    rm, rn = radii(lat)
    wie = np.array([0.0, _OMEGA_E * np.cos(lat), _OMEGA_E * np.sin(lat)])
    wen = np.array([-vel[1] / (rm + h), vel[0] / (rn + h), vel[0] * np.tan(lat) / (rn + h)])
    return wie, wen, gravity(lat, h), rm, rn


@njit(cache=True, inline="always")
def _qmul(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float
          ) -> tuple[float, float, float, float]:
    """Hamilton product of two quaternions given as scalars."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, inline="always")
def _rv2q(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """Quaternion of the rotation vector (x, y, z), exact (series below 1e-8 rad)."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-16:
        s = 0.5 - a2 / 48.0
        c = 1.0 - a2 / 8.0
    else:
        a = np.sqrt(a2)
        s = np.sin(0.5 * a) / a
        c = np.cos(0.5 * a)
    return c, s * x, s * y, s * z


@njit(cache=True)
def step(x: np.ndarray, w0: np.ndarray, w1: np.ndarray, f0: np.ndarray, f1: np.ndarray, dt: float,
         fn_out: np.ndarray) -> None:
    """Advance the nominal state ``x`` (in place) over one interval of ``dt`` seconds
    (:func:`_step`: its docstring)."""
    _step(x, w0, w1, f0, f1, dt, fn_out)


@njit(cache=True, inline="always")
def _step(x: np.ndarray, w0: np.ndarray, w1: np.ndarray, f0: np.ndarray, f1: np.ndarray, dt: float,
          fn_out: np.ndarray) -> None:
    """Advance the nominal state ``x`` (in place) over one interval of ``dt`` seconds.

    ``w0, w1`` (rad/s) and ``f0, f1`` (m/s^2) are the bias-corrected body rates and specific
    forces at the start and end of the interval.  ``fn_out`` (3,) receives the interval's
    velocity increment from specific force, resolved in ENU (m/s), for the error model.

    Written with scalars only (no temporary arrays): this is the innermost loop of every filter.
    """
    dt2 = dt * dt
    a0, a1, a2 = w0[0], w0[1], w0[2]
    b0, b1, b2 = w1[0], w1[1], w1[2]
    d0, d1, d2 = b0 - a0, b1 - a1, b2 - a2                      # rate change
    g0, g1, g2 = f0[0], f0[1], f0[2]
    e0, e1, e2 = f1[0] - g0, f1[1] - g1, f1[2] - g2             # specific-force change
    # attitude increment with the exact second-order coning term for linear rates:
    # phi = (w0 + w1) T / 2 + (w0 x w1) T^2 / 12
    k = dt2 / 12.0
    p0 = 0.5 * (a0 + b0) * dt + (a1 * b2 - a2 * b1) * k
    p1 = 0.5 * (a1 + b1) * dt + (a2 * b0 - a0 * b2) * k
    p2 = 0.5 * (a2 + b2) * dt + (a0 * b1 - a1 * b0) * k
    # velocity increment in the start body frame: int f dt + int (alpha x f) dt, where
    # int (alpha x f) = T^2 [w0 x f0 / 2 + w0 x df / 3 + dw x f0 / 6 + dw x df / 8]
    u0 = 0.5 * (a1 * g2 - a2 * g1) + (a1 * e2 - a2 * e1) / 3.0 + (d1 * g2 - d2 * g1) / 6.0 + 0.125 * (d1 * e2 - d2 * e1)
    u1 = 0.5 * (a2 * g0 - a0 * g2) + (a2 * e0 - a0 * e2) / 3.0 + (d2 * g0 - d0 * g2) / 6.0 + 0.125 * (d2 * e0 - d0 * e2)
    u2 = 0.5 * (a0 * g1 - a1 * g0) + (a0 * e1 - a1 * e0) / 3.0 + (d0 * g1 - d1 * g0) / 6.0 + 0.125 * (d0 * e1 - d1 * e0)
    v0b = (g0 + 0.5 * e0) * dt + u0 * dt2
    v1b = (g1 + 0.5 * e1) * dt + u1 * dt2
    v2b = (g2 + 0.5 * e2) * dt + u2 * dt2
    # rotate into the start navigation frame: v_n = q v_b q*
    qw, qx, qy, qz = x[X_QW], x[X_QX], x[X_QY], x[X_QZ]
    t0 = 2.0 * (qy * v2b - qz * v1b)
    t1 = 2.0 * (qz * v0b - qx * v2b)
    t2 = 2.0 * (qx * v1b - qy * v0b)
    n0 = v0b + qw * t0 + (qy * t2 - qz * t1)
    n1 = v1b + qw * t1 + (qz * t0 - qx * t2)
    n2 = v2b + qw * t2 + (qx * t1 - qy * t0)

    ve, vn, vu = x[X_VE], x[X_VN], x[X_VU]
    lat, lon, h = x[X_LAT], x[X_LON], x[X_H]
    # predictor with the start values, then the mid-point values
    lat_m, h_m = lat, h
    vme, vmn, vmu = ve, vn, vu
    for it in range(2):
        sl = np.sin(lat_m)
        cl = np.cos(lat_m)
        w2 = 1.0 - _E2 * sl * sl
        rn = _A / np.sqrt(w2)
        rm = rn * (1.0 - _E2) / w2
        wie_n = _OMEGA_E * cl
        wie_u = _OMEGA_E * sl
        wen_e = -vmn / (rm + h_m)
        wen_n = vme / (rn + h_m)
        wen_u = vme * sl / cl / (rn + h_m)
        g = gravity(lat_m, h_m)
        # navigation-frame rotation over the interval and the Coriolis/gravity increment
        z0 = wen_e * dt
        z1 = (wie_n + wen_n) * dt
        z2 = (wie_u + wen_u) * dt
        c0 = wen_e
        c1 = 2.0 * wie_n + wen_n
        c2 = 2.0 * wie_u + wen_u
        # v1 = v0 + dv_n - (zeta x dv_n) / 2 - (c x v_m) dt - g e_U dt
        ne = ve + n0 - 0.5 * (z1 * n2 - z2 * n1) - (c1 * vmu - c2 * vmn) * dt
        nn = vn + n1 - 0.5 * (z2 * n0 - z0 * n2) - (c2 * vme - c0 * vmu) * dt
        nu = vu + n2 - 0.5 * (z0 * n1 - z1 * n0) - (c0 * vmn - c1 * vme) * dt - g * dt
        vme, vmn, vmu = 0.5 * (ve + ne), 0.5 * (vn + nn), 0.5 * (vu + nu)
        if it == 0:
            h_m = h + 0.5 * vmu * dt
            lat_m = lat + 0.5 * vmn / (rm + h) * dt
    x[X_H] = h + vmu * dt
    x[X_LAT] = lat + vmn / (rm + h_m) * dt
    lon = lon + vme / ((rn + h_m) * cl) * dt
    if lon >= np.pi:          # keep longitude in [-pi, pi) across the antimeridian
        lon -= 2.0 * np.pi
    elif lon < -np.pi:
        lon += 2.0 * np.pi
    x[X_LON] = lon
    x[X_VE], x[X_VN], x[X_VU] = ne, nn, nu
    # C(k) = exp(-zeta x) C(k-1) exp(phi x)
    r0, r1, r2, r3 = _rv2q(p0, p1, p2)
    s0, s1, s2, s3 = _qmul(qw, qx, qy, qz, r0, r1, r2, r3)
    m0, m1, m2, m3 = _rv2q(-z0, -z1, -z2)
    o0, o1, o2, o3 = _qmul(m0, m1, m2, m3, s0, s1, s2, s3)
    inv = 1.0 / np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    x[X_QW], x[X_QX], x[X_QY], x[X_QZ] = o0 * inv, o1 * inv, o2 * inv, o3 * inv
    fn_out[0], fn_out[1], fn_out[2] = n0, n1, n2


@njit(cache=True, inline="always")
def _sample_at(t: np.ndarray, a: np.ndarray, i: int, tq: float, bias: np.ndarray, out: np.ndarray) -> None:
    """``out = a(tq) - bias``, linear between rows ``i-1`` and ``i`` (``t[i-1] <= tq <= t[i]``)."""
    n = t.shape[0]
    if i <= 0:
        for k in range(3):
            out[k] = a[0, k] - bias[k]
    elif i >= n:
        for k in range(3):
            out[k] = a[n - 1, k] - bias[k]
    else:
        w = (tq - t[i - 1]) / (t[i] - t[i - 1])
        for k in range(3):
            out[k] = a[i - 1, k] + w * (a[i, k] - a[i - 1, k]) - bias[k]


@njit(cache=True)
def integrate(x: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, t_start: float, t_end: float,
              out: np.ndarray, record: bool, seg_dt: float, seg_x: np.ndarray, seg_fn: np.ndarray,
              seg_T: np.ndarray) -> int:
    """Propagate nominal ``x`` (in place) from ``t_start`` to ``t_end`` (s) through IMU samples.

    Nodes are ``t_start``, every sample with ``t_start < t[i] < t_end``, and ``t_end``; rates at
    ``t_start``/``t_end`` are linearly interpolated between the neighbouring samples, so an
    epoch between samples is reached exactly.

    Outputs
    -------
    out : when ``record``, the first ``out.shape[1]`` elements of the state reached at each
        sample time ``t[i]`` in ``(t_start, t_end]`` are written to ``out[i]``.
    seg_x, seg_fn, seg_T : when ``seg_dt > 0``, the interval is cut into segments of at least
        ``seg_dt`` s (the last one ends at ``t_end``); segment j reports the state at its end
        ``seg_x[j]``, its mean ENU specific force ``seg_fn[j]`` (m/s^2) and length ``seg_T[j]``
        (s), which is what the error model needs.  Returns the number of segments.
    """
    n = t.shape[0]
    i = int(np.searchsorted(t, t_start, side="right"))
    # the biases (copied: x changes in place), the rates and forces at both ends of a step, its
    # velocity increment and the segment's sum: rows of one scratch array, not eight arrays
    scratch = np.empty((8, 3))
    bg, ba, w0, f0, w1, f1, dv_n, acc = (scratch[0], scratch[1], scratch[2], scratch[3], scratch[4], scratch[5],
                                         scratch[6], scratch[7])
    for k in range(3):
        bg[k] = x[X_BG + k]
        ba[k] = x[X_BA + k]
        acc[k] = 0.0
    t_acc = 0.0
    n_seg = 0
    _sample_at(t, gyro, i, t_start, bg, w0)
    _sample_at(t, accel, i, t_start, ba, f0)
    tc = t_start
    while tc < t_end:
        if i < n and t[i] < t_end:
            tn = t[i]
            for k in range(3):
                w1[k] = gyro[i, k] - bg[k]
                f1[k] = accel[i, k] - ba[k]
            rec = i
        else:
            tn = t_end
            _sample_at(t, gyro, i, t_end, bg, w1)
            _sample_at(t, accel, i, t_end, ba, f1)
            rec = i if (i < n and t[i] == t_end) else -1
        dt = tn - tc
        _step(x, w0, w1, f0, f1, dt, dv_n)
        # (element loops, not slice assignment from arrays: see navpp/jitcache.py)
        if seg_dt > 0.0:
            for k in range(3):
                acc[k] += dv_n[k]
            t_acc += dt
            if t_acc >= seg_dt or tn >= t_end:
                for k in range(seg_x.shape[1]):
                    seg_x[n_seg, k] = x[k]
                for k in range(3):
                    seg_fn[n_seg, k] = acc[k] / t_acc
                seg_T[n_seg] = t_acc
                n_seg += 1
                for k in range(3):
                    acc[k] = 0.0
                t_acc = 0.0
        if record and rec >= 0:
            for k in range(out.shape[1]):
                out[rec, k] = x[k]
        tc = tn
        for k in range(3):
            w0[k] = w1[k]
            f0[k] = f1[k]
        i += 1
    return n_seg


#: empty segment buffers (``seg_x``, ``seg_fn``, ``seg_T``) for :func:`integrate` with ``seg_dt = 0``
NO_SEG_X = np.empty((0, NOMINAL_SIZE))
NO_SEG_FN = np.empty((0, 3))
NO_SEG_T = np.empty(0)


def free_inertial(x0: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Free-inertial solution at every sample from ``x0`` at ``t[0]``; (N, 16) nominal rows
    (the biases stay those of ``x0``)."""
    out = np.empty((t.shape[0], NOMINAL_SIZE))
    x = np.array(x0, dtype=float)
    out[0] = x
    integrate(x, np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(gyro, dtype=float),
              np.ascontiguousarray(accel, dtype=float), float(t[0]), float(t[-1]), out, True,
              0.0, NO_SEG_X, NO_SEG_FN, NO_SEG_T)
    return out


__all__ = ["NOMINAL_BA", "NOMINAL_BG", "NOMINAL_POS", "NOMINAL_Q", "NOMINAL_SIZE", "NOMINAL_VEL", "NO_SEG_FN",
           "NO_SEG_T", "NO_SEG_X", "PATH_SIZE", "free_inertial", "gravity", "integrate", "nav_rates", "radii", "step"]
