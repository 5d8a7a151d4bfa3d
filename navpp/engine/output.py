"""From a finished forward run to the outputs: the IMU-rate solution, its position 1-sigma, the
smoothed run.

The recorded path rows are ``(q_nb, vel_enu, lat, lon, h)`` (quaternion body FLU -> nav ENU,
m/s, rad, rad, m); :func:`solution_from_path` converts them in place to degrees.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from ..filters.protocols import SmoothableModel
from ..filters.smoother import ForwardStore, smooth_arrays
from ..ins.model import BA, BG, POS, apply_node_corrections
from ..ins.strapdown import NOMINAL_BA, NOMINAL_BG
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
                 epoch_node: np.ndarray, tg: np.ndarray, t0_ns: int) -> SmoothedRun:
    """Smooth the stored forward run and bring it to the IMU rate.

    Between two nodes the forward path is the strapdown from the earlier node's posterior; the
    smoothed correction relative to it runs linearly from ``x_k^s ⊟ x_k^+`` at the start to
    ``x_k+1^s ⊟ x_ref,k+1`` at the end (nodes are at most 1.5 :data:`~navpp.engine.schedule.KNOT_S`
    apart, over which the error dynamics are linear to well below the errors themselves); a
    sample exactly at a node
    takes the node's smoothed state.  The smoothed position 1-sigma interpolates the smoothed
    variance between nodes.
    """
    t_start = time.perf_counter()
    nodes = store.arrays()
    mb = sum(a.nbytes for a in nodes.values()) / 1e6
    x_post, x_ref = nodes["x_post"], nodes["x_ref"]
    sm = smooth_arrays(nodes, model)
    spath = path.copy()
    apply_node_corrections(spath, t_out, sm.t, sm.x, x_post, x_ref)
    var = np.ascontiguousarray(np.diagonal(sm.P, axis1=1, axis2=2))
    vpos = np.ascontiguousarray(var[:, POS])
    std = interpolated_std(t_out, sm.t[0], vpos[0], sm.t[1:], vpos[1:], vpos[1:])
    solution = solution_from_path(t_out, spath, std, t0_ns)
    xs = sm.x[epoch_node]
    bstd = np.sqrt(np.maximum(var[epoch_node], 0.0))
    biases = BiasHistory(tg, xs[:, NOMINAL_BG].copy(), xs[:, NOMINAL_BA].copy(), bstd[:, BG].copy(),
                         bstd[:, BA].copy())
    return SmoothedRun(solution, biases, time.perf_counter() - t_start, int(sm.t.shape[0]),
                       int(sm.breaks + sm.repaired), mb)


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
        for j in range(3):
            va = var0[j] if k == 0 else var_post[k - 1, j]
            if k < m and tg[k] > ta:
                w = (t[i] - ta) / (tg[k] - ta)
                w = min(max(w, 0.0), 1.0)
                v = (1.0 - w) * va + w * var_prior[k, j]
            else:
                v = va
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


def solution_from_path(t: np.ndarray, path: np.ndarray, std_enu: np.ndarray, t0_ns: int) -> Solution:
    """Recorded rows (N, 10: q_nb, vel_enu, lat, lon, h) -> :class:`Solution`, converting ``path``
    IN PLACE: the solution's arrays are views of it, so an hour at 125 Hz costs no second copy."""
    path_to_output_columns(path)
    return Solution(t=np.asarray(t, dtype=float), lat_deg=path[:, 7], lon_deg=path[:, 8], alt=path[:, 9],
                    vel_enu=path[:, 4:7], rph_deg=path[:, 0:3], std_enu=std_enu, t0_ns=t0_ns)

