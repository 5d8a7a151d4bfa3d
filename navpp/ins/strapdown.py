"""Strapdown mechanisation in the local-level ENU frame (numba kernels + thin wrappers).

Nominal navigation state, a flat float64 vector of length 16 (``NOMINAL_*`` slices):
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

import numpy as np
from numba import njit

from .. import geodesy

NOMINAL_SIZE = 16
NOMINAL_Q = slice(0, 4)
NOMINAL_VEL = slice(4, 7)
NOMINAL_POS = slice(7, 10)
NOMINAL_BG = slice(10, 13)
NOMINAL_BA = slice(13, 16)
PATH_SIZE = 10   #: recorded columns per IMU sample: q_nb, vel_enu, lat, lon, h (biases change only at updates)

radii = njit(cache=True)(geodesy.radii)
gravity = njit(cache=True)(geodesy.gravity)
_OMEGA_E = geodesy.OMEGA_E
_A = geodesy.A
_E2 = geodesy.E2


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _quat_rotate(q, v):
    """``quat_to_dcm(q) @ v`` without forming the matrix."""
    w = q[0]
    u = q[1:4]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


@njit(cache=True)
def _nav_rates(lat, h, vel):
    """Earth rate, transport rate (ENU, rad/s) and gravity magnitude at a point."""
    rm, rn = radii(lat)
    wie = np.array([0.0, _OMEGA_E * np.cos(lat), _OMEGA_E * np.sin(lat)])
    wen = np.array([-vel[1] / (rm + h), vel[0] / (rn + h), vel[0] * np.tan(lat) / (rn + h)])
    return wie, wen, gravity(lat, h), rm, rn


@njit(cache=True, inline="always")
def _qmul(a0, a1, a2, a3, b0, b1, b2, b3):
    """Hamilton product of two quaternions given as scalars."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, inline="always")
def _rv2q(x, y, z):
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
def step(x, w0, w1, f0, f1, dt, fn_out):
    """Advance the nominal state ``x`` (in place) over one interval of ``dt`` seconds.

    ``w0, w1`` (rad/s) and ``f0, f1`` (m/s^2) are the bias-corrected body rates and specific
    forces at the start and end of the interval.  ``fn_out`` (3,) receives the interval's
    velocity increment from specific force, resolved in ENU (m/s), for the error model.

    Written with scalars only (no temporary arrays): this is the innermost loop of every
    filter.
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
    qw, qx, qy, qz = x[0], x[1], x[2], x[3]
    t0 = 2.0 * (qy * v2b - qz * v1b)
    t1 = 2.0 * (qz * v0b - qx * v2b)
    t2 = 2.0 * (qx * v1b - qy * v0b)
    n0 = v0b + qw * t0 + (qy * t2 - qz * t1)
    n1 = v1b + qw * t1 + (qz * t0 - qx * t2)
    n2 = v2b + qw * t2 + (qx * t1 - qy * t0)

    ve, vn, vu = x[4], x[5], x[6]
    lat, lon, h = x[7], x[8], x[9]
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
    x[9] = h + vmu * dt
    x[7] = lat + vmn / (rm + h_m) * dt
    lon = lon + vme / ((rn + h_m) * cl) * dt
    if lon >= np.pi:          # keep longitude in [-pi, pi) across the antimeridian
        lon -= 2.0 * np.pi
    elif lon < -np.pi:
        lon += 2.0 * np.pi
    x[8] = lon
    x[4], x[5], x[6] = ne, nn, nu
    # C(k) = exp(-zeta x) C(k-1) exp(phi x)
    r0, r1, r2, r3 = _rv2q(p0, p1, p2)
    s0, s1, s2, s3 = _qmul(qw, qx, qy, qz, r0, r1, r2, r3)
    m0, m1, m2, m3 = _rv2q(-z0, -z1, -z2)
    o0, o1, o2, o3 = _qmul(m0, m1, m2, m3, s0, s1, s2, s3)
    inv = 1.0 / np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    x[0], x[1], x[2], x[3] = o0 * inv, o1 * inv, o2 * inv, o3 * inv
    fn_out[0], fn_out[1], fn_out[2] = n0, n1, n2


@njit(cache=True, inline="always")
def _sample_at(t, a, i, tq, bias, out):
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
def integrate(x, t, gyro, accel, t_start, t_end, out, record, seg_dt, seg_x, seg_fn, seg_T):
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
    i = np.searchsorted(t, t_start, side="right")
    bg = x[10:13].copy()
    ba = x[13:16].copy()
    w0 = np.empty(3)
    f0 = np.empty(3)
    w1 = np.empty(3)
    f1 = np.empty(3)
    dv_n = np.empty(3)
    acc = np.zeros(3)
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
        step(x, w0, w1, f0, f1, dt, dv_n)
        if seg_dt > 0.0:
            acc += dv_n
            t_acc += dt
            if t_acc >= seg_dt or tn >= t_end:
                seg_x[n_seg, :] = x
                seg_fn[n_seg, :] = acc / t_acc
                seg_T[n_seg] = t_acc
                n_seg += 1
                acc[:] = 0.0
                t_acc = 0.0
        if record and rec >= 0:
            out[rec, :] = x[:out.shape[1]]
        tc = tn
        w0[:] = w1
        f0[:] = f1
        i += 1
    return n_seg


_NO_SEG = np.empty((0, NOMINAL_SIZE))
_NO_SEG3 = np.empty((0, 3))
_NO_T = np.empty(0)


def free_inertial(x0: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Free-inertial solution at every sample from ``x0`` at ``t[0]``; (N, 16) nominal rows
    (the biases stay those of ``x0``)."""
    out = np.empty((t.shape[0], NOMINAL_SIZE))
    x = np.array(x0, dtype=float)
    out[0] = x
    integrate(x, np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(gyro, dtype=float),
              np.ascontiguousarray(accel, dtype=float), float(t[0]), float(t[-1]), out, True,
              0.0, _NO_SEG, _NO_SEG3, _NO_T)
    return out
