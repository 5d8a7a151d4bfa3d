"""From a finished forward run to the outputs: the IMU-rate solution, its 1-sigma (position,
velocity, attitude), its body rate, the smoothed run.

The recorded path rows are ``(q_nb, vel_enu, lat, lon, h)`` (quaternion body FLU -> nav ENU,
m/s, rad, rad, m); :func:`solution_from_path` converts them in place to degrees.  A path on a
spill file (:mod:`navpp.spill`) gives its outputs on spill files too, and every pass here
goes over it window by window, releasing the rows behind it.
"""

from __future__ import annotations

import math
import time

import numpy as np

from navpp.kernel import njit

from .. import spill
from ..filters.protocols import SmoothableModel
from ..filters.smoother import ForwardStore, rts_smooth
from ..geodesy import OMEGA_E
from ..ins.model import ATT, BA, BG, POS, VEL, apply_node_corrections
from ..ins.strapdown import NOMINAL_BA, NOMINAL_BG, radii
from ..recording import Solution
from .results import BiasHistory, SmoothedRun


def compile_seconds(events) -> float:
    """Seconds covered by the outermost START..END pairs of numba compile ``events`` (as a
    ``numba.core.event`` recorder's buffer holds them)."""
    depth, start, total = 0, 0.0, 0.0
    for ts, ev in events:
        if ev.is_start:
            if depth == 0:
                start = ts
            depth += 1
        else:
            depth -= 1
            if depth == 0:
                total += ts - start
    return total


def smoothed_run(store: ForwardStore, model: SmoothableModel, t_out: np.ndarray, path: np.ndarray,
                 epoch_node: np.ndarray, tg: np.ndarray, t0_ns: int, gyro: np.ndarray | None = None) -> SmoothedRun:
    """Smooth the stored forward run and bring it to the IMU rate.

    Between two nodes the forward path is the strapdown from the earlier node's posterior; the
    smoothed correction relative to it runs linearly from ``x_k^s ⊟ x_k^+`` at the start to
    ``x_k+1^s ⊟ x_ref,k+1`` at the end (nodes are at most 1.5 :data:`~navpp.engine.schedule.KNOT_S`
    apart, over which the error dynamics are linear to well below the errors themselves); a
    sample exactly at a node
    takes the node's smoothed state.  The smoothed position, velocity and attitude 1-sigma
    interpolate the smoothed variances between nodes.  ``gyro`` (N, 3) rad/s, body FLU, at
    ``t_out``: the gyro the model used, for the body rate (:func:`body_rate`, with the smoothed
    gyro bias); None: no body rate.
    """
    t_start = time.perf_counter()
    mb = store.nbytes / 1e6
    sm = rts_smooth(store, model)
    spath = spill.copy_rows(path)
    for a, b in spill.windows(len(spath), spath):      # row by row: a window's rows are the same bits
        apply_node_corrections(spath[a:b], t_out[a:b], sm.t, sm.x, sm.x_post, sm.x_ref)
    var = sm.var
    std = {}
    for name, block in (("pos", POS), ("vel", VEL), ("att", ATT)):
        v = np.ascontiguousarray(var[:, block])
        std[name] = interpolated_std_rows(t_out, sm.t[0], v[0], sm.t[1:], v[1:], v[1:], like=spath)
    xs = sm.x[epoch_node]
    rate = None
    if gyro is not None:
        rate = body_rate(t_out, spath, gyro, tg, xs[:, NOMINAL_BG], sm.x[0, NOMINAL_BG])
    solution = solution_from_path(t_out, spath, std["pos"], t0_ns, std_att=std["att"], std_vel_enu=std["vel"],
                                  rate_body=rate)
    bstd = np.sqrt(np.maximum(var[epoch_node], 0.0))
    biases = BiasHistory(tg, xs[:, NOMINAL_BG].copy(), xs[:, NOMINAL_BA].copy(), bstd[:, BG].copy(),
                         bstd[:, BA].copy())
    return SmoothedRun(solution, biases, time.perf_counter() - t_start, int(sm.t.shape[0]),
                       int(sm.breaks + sm.repaired), mb)


def interpolated_std_rows(t: np.ndarray, t0: float, var0: np.ndarray, tg: np.ndarray, var_prior: np.ndarray,
                          var_post: np.ndarray, *, like: np.ndarray) -> np.ndarray:
    """:func:`interpolated_std` (N, 3) float32, spilled like the path ``like`` (then computed
    window by window: a window's rows are the same bits, ``t`` increasing)."""
    if not spill.spilled(like):
        return interpolated_std(t, t0, var0, tg, var_prior, var_post)
    out = spill.like(like, t.shape[0], (3,), np.float32)
    for a, b in spill.windows(t.shape[0], out, t):         # a spilled t's pages released too
        out[a:b] = interpolated_std(t[a:b], t0, var0, tg, var_prior, var_post)
    return out


@njit(cache=True)
def interpolated_std(t, t0, var0, tg, var_prior, var_post):
    """Position 1-sigma (m) at times ``t``: the variance runs linearly from one epoch's posterior
    to the next epoch's prior (growth between fixes is close to linear at GNSS rates; over a
    long outage, where it grows faster, this is conservative).  At an epoch: the posterior."""
    n = t.shape[0]
    m = tg.shape[0]
    out = np.empty((n, 3), dtype=np.float32)     # a 1-sigma needs no more than 7 digits
    k = 0                       # next epoch index: tg[k-1] <= t < tg[k]
    for i in range(n):
        while k < m and tg[k] <= t[i]:
            k += 1
        ta = t0 if k == 0 else tg[k - 1]
        between = k < m and tg[k] > ta
        w = 0.0
        if between:             # the weight of the next epoch's prior, the same for the three axes
            w = (t[i] - ta) / (tg[k] - ta)
            w = min(max(w, 0.0), 1.0)
        for j in range(3):
            va = var0[j] if k == 0 else var_post[k - 1, j]
            v = (1.0 - w) * va + w * var_prior[k, j] if between else va
            out[i, j] = np.sqrt(max(v, 0.0))
    return out


@njit(cache=True)
def path_to_output_columns(path):
    """Convert recorded rows (N, 10) in place into output units: columns 0-2 become roll, pitch,
    heading in degrees (navigation convention), 7-8 latitude and longitude in degrees."""
    r2d = 180.0 / np.pi
    for i in range(path.shape[0]):
        w, x, y, z = path[i, 0], path[i, 1], path[i, 2], path[i, 3]
        c20 = 2.0 * (x * z - w * y)
        c21 = 2.0 * (y * z + w * x)
        c22 = 1.0 - 2.0 * (x * x + y * y)
        c00 = 1.0 - 2.0 * (y * y + z * z)
        c10 = 2.0 * (x * y + w * z)
        pitch = np.arcsin(min(max(c20, -1.0), 1.0))
        roll = np.arctan2(c21, c22)
        heading = (0.5 * np.pi - np.arctan2(c10, c00)) % (2.0 * np.pi)
        path[i, 0] = roll * r2d
        path[i, 1] = pitch * r2d
        path[i, 2] = heading * r2d
        path[i, 3] = np.nan
        path[i, 7] *= r2d
        path[i, 8] *= r2d


def body_rate(t: np.ndarray, path: np.ndarray, gyro: np.ndarray, bias_t: np.ndarray, bias_gyro: np.ndarray,
              bias0: np.ndarray) -> np.ndarray:
    """Angular velocity of the body relative to the local ENU frame, body FLU, rad/s, (N, 3).

    ``w_nb^b = w_ib^b - b_g - C_bn (w_ie^n + w_en^n)``: ``gyro`` (N, 3) the measured rate the
    model integrated (mounting applied), ``b_g`` the gyro bias estimate after the last fix at or
    before each time (``bias_t`` (M,) s, ``bias_gyro`` (M, 3)), ``bias0`` before the first fix;
    the attitude ``C_nb``, velocity and position from the recorded ``path`` rows (N, 10: q_nb,
    vel_enu, lat rad, lon rad, h m; read before :func:`solution_from_path` converts them).
    One compiled pass (:func:`_body_rate_into`): the result is the only IMU-rate array made
    (spilled like ``path``, and then made window by window, the pages of every spilled input
    released behind the window)."""
    out = spill.like(path, path.shape[0], (3,), np.float64)
    t, gyro = np.asarray(t, dtype=float), np.asarray(gyro, dtype=float)
    bias_t, bias_gyro, bias0 = (np.asarray(a, dtype=float) for a in (bias_t, bias_gyro, bias0))
    for a, b in spill.windows(path.shape[0], path, out, t, gyro):     # every spilled input released behind
        _body_rate_into(out[a:b], t[a:b], path[a:b], gyro[a:b], bias_t, bias_gyro, bias0)
    return out


@njit(cache=True)
def _body_rate_into(out, t, path, gyro, bias_t, bias_gyro, bias0):
    """:func:`body_rate` row by row into ``out`` (N, 3) rad/s, body FLU; the sums in the order
    numpy's vectorised form took them, so the figures are the same to the last bit.  The bias
    in force (the last at or before ``t[i]``) is searched for at the first row and followed from
    row to row after it (afresh where ``t`` goes back)."""
    m = bias_t.shape[0]
    k = -1              # the last bias time at or before the row's time (-1: none)
    for i in range(path.shape[0]):
        if i == 0 or (k >= 0 and t[i] < bias_t[k]):
            k = np.searchsorted(bias_t, t[i], side="right") - 1
        while k + 1 < m and bias_t[k + 1] <= t[i]:
            k += 1
        bg = bias_gyro[k] if k >= 0 else bias0
        w, x, y, z = path[i, 0], path[i, 1], path[i, 2], path[i, 3]
        ve, vn, lat, h = path[i, 4], path[i, 5], path[i, 7], path[i, 9]
        rm, rn = radii(lat)
        # w_in^n = w_ie^n + w_en^n, ENU, rad/s
        w_e = -vn / (rm + h)
        w_n = OMEGA_E * math.cos(lat) + ve / (rn + h)
        w_u = OMEGA_E * math.sin(lat) + ve * math.tan(lat) / (rn + h)
        # C_bn w_in^n: the columns of C_nb (the rotation body FLU -> nav ENU) against w_in^n
        r0 = (1.0 - 2.0 * (y * y + z * z)) * w_e + 2.0 * (x * y + w * z) * w_n + 2.0 * (x * z - w * y) * w_u
        r1 = 2.0 * (x * y - w * z) * w_e + (1.0 - 2.0 * (x * x + z * z)) * w_n + 2.0 * (y * z + w * x) * w_u
        r2 = 2.0 * (x * z + w * y) * w_e + 2.0 * (y * z - w * x) * w_n + (1.0 - 2.0 * (x * x + y * y)) * w_u
        out[i, 0] = gyro[i, 0] - bg[0] - r0
        out[i, 1] = gyro[i, 1] - bg[1] - r1
        out[i, 2] = gyro[i, 2] - bg[2] - r2


def solution_from_path(t: np.ndarray, path: np.ndarray, std_enu: np.ndarray, t0_ns: int, *,
                       std_att: np.ndarray | None = None, std_vel_enu: np.ndarray | None = None,
                       rate_body: np.ndarray | None = None) -> Solution:
    """Recorded rows (N, 10: q_nb, vel_enu, lat, lon, h) -> :class:`Solution`, converting ``path``
    IN PLACE: the solution's arrays are views of it, so an hour at 125 Hz costs no second copy.
    ``std_att`` (rad), ``std_vel_enu`` (m/s), ``rate_body`` (rad/s): see :class:`Solution`."""
    for a, b in spill.windows(path.shape[0], path):
        path_to_output_columns(path[a:b])
    return Solution(t=np.asarray(t, dtype=float), lat_deg=path[:, 7], lon_deg=path[:, 8], alt=path[:, 9],
                    vel_enu=path[:, 4:7], rph_deg=path[:, 0:3], std_enu=std_enu, t0_ns=t0_ns, std_att=std_att,
                    std_vel_enu=std_vel_enu, rate_body=rate_body)

