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
from .attitude import quat_mul, quat_normalize, rotvec_to_quat

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


@njit(cache=True)
def step(x, w0, w1, f0, f1, dt, fn_out):
    """Advance the nominal state ``x`` (in place) over one interval of ``dt`` seconds.

    ``w0, w1`` (rad/s) and ``f0, f1`` (m/s^2) are the bias-corrected body rates and specific
    forces at the start and end of the interval.  ``fn_out`` (3,) receives the interval's
    velocity increment from specific force, resolved in ENU (m/s), for the error model.
    """
    dw = w1 - w0
    df = f1 - f0
    dt2 = dt * dt
    # attitude increment with the exact second-order coning term for linear rates
    phi = 0.5 * (w0 + w1) * dt + _cross(w0, w1) * (dt2 / 12.0)
    # velocity increment in the start body frame: int f dt + int (alpha x f) dt
    dvb = 0.5 * (f0 + f1) * dt + dt2 * (0.5 * _cross(w0, f0) + _cross(w0, df) / 3.0
                                        + _cross(dw, f0) / 6.0 + 0.125 * _cross(dw, df))
    q = x[0:4]
    v0 = x[4:7].copy()
    lat, lon, h = x[7], x[8], x[9]
    dv_n = _quat_rotate(q, dvb)

    # predictor: rates at the start, then re-evaluate at the mid-point
    wie, wen, g, rm, rn = _nav_rates(lat, h, v0)
    zeta = (wie + wen) * dt
    v1 = v0 + dv_n - 0.5 * _cross(zeta, dv_n) - _cross(2.0 * wie + wen, v0) * dt
    v1[2] -= g * dt
    vm = 0.5 * (v0 + v1)
    hm = h + 0.5 * vm[2] * dt
    latm = lat + 0.5 * vm[1] / (rm + h) * dt
    wie, wen, g, rm, rn = _nav_rates(latm, hm, vm)
    zeta = (wie + wen) * dt
    v1 = v0 + dv_n - 0.5 * _cross(zeta, dv_n) - _cross(2.0 * wie + wen, vm) * dt
    v1[2] -= g * dt
    vm = 0.5 * (v0 + v1)

    x[9] = h + vm[2] * dt
    x[7] = lat + vm[1] / (rm + hm) * dt
    x[8] = lon + vm[0] / ((rn + hm) * np.cos(latm)) * dt
    x[4:7] = v1
    # C(k) = exp(-zeta x) C(k-1) exp(phi x)
    qn = quat_mul(rotvec_to_quat(-zeta), quat_mul(q, rotvec_to_quat(phi)))
    x[0:4] = quat_normalize(qn)
    fn_out[:] = dv_n


@njit(cache=True)
def _interp_row(t, a, i, tq):
    """Linear interpolation of row data ``a`` at ``tq`` with ``t[i-1] <= tq <= t[i]``."""
    if i <= 0:
        return a[0].copy()
    if i >= t.shape[0]:
        return a[t.shape[0] - 1].copy()
    w = (tq - t[i - 1]) / (t[i] - t[i - 1])
    return a[i - 1] + w * (a[i] - a[i - 1])


@njit(cache=True)
def integrate(x, t, gyro, accel, t_start, t_end, out, record):
    """Propagate nominal ``x`` (in place) from ``t_start`` to ``t_end`` (s) through IMU samples.

    Nodes are ``t_start``, every sample with ``t_start < t[i] < t_end``, and ``t_end``; rates at
    ``t_start``/``t_end`` are linearly interpolated between the neighbouring samples, so an
    epoch between samples is reached exactly.  When ``record`` is true, the first
    ``out.shape[1]`` elements of the state reached at each sample time ``t[i]`` in
    ``(t_start, t_end]`` are written to ``out[i]``.
    """
    n = t.shape[0]
    i = np.searchsorted(t, t_start, side="right")
    bg = x[10:13].copy()
    ba = x[13:16].copy()
    wc = _interp_row(t, gyro, i, t_start) - bg
    fc = _interp_row(t, accel, i, t_start) - ba
    tc = t_start
    fn = np.zeros(3)
    while tc < t_end:
        if i < n and t[i] < t_end:
            tn = t[i]
            wn = gyro[i] - bg
            fnb = accel[i] - ba
            rec = i
        else:
            tn = t_end
            wn = _interp_row(t, gyro, i, t_end) - bg
            fnb = _interp_row(t, accel, i, t_end) - ba
            rec = i if (i < n and t[i] == t_end) else -1
        step(x, wc, wn, fc, fnb, tn - tc, fn)
        if record and rec >= 0:
            out[rec, :] = x[:out.shape[1]]
        tc, wc, fc = tn, wn, fnb
        i += 1
    return x


def free_inertial(x0: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Free-inertial solution at every sample from ``x0`` at ``t[0]``; (N, 16) nominal rows
    (the biases stay those of ``x0``)."""
    out = np.empty((t.shape[0], NOMINAL_SIZE))
    x = np.array(x0, dtype=float)
    out[0] = x
    integrate(x, np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(gyro, dtype=float),
              np.ascontiguousarray(accel, dtype=float), float(t[0]), float(t[-1]), out, True)
    return out
