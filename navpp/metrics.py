"""Accuracy of a solution against a reference: association, errors in local ENU metres, statistics.

Steps, each a tested function of its own:

1. :func:`associate` picks the reference epochs inside the solution's time span (no
   extrapolation).
2. :func:`interpolate_solution` brings the solution to those epochs (linear; heading on the
   unwrapped angle).
3. :func:`position_errors_enu` expresses estimate minus reference in the local ENU frame of
   each reference point (exact, through ECEF): east = longitude error, north = latitude error,
   up = height error, metres.
4. :func:`error_stats` reduces errors to MAE / RMSE / max / p95 per axis, horizontally and in 3-D.

:func:`compute_metrics` chains them into the ``metrics.json`` structure of README.md ("Outputs") and,
when given the raw GNSS fixes, adds their own accuracy against the reference antenna position;
with simulated GNSS outages, :func:`outage_metrics` adds the errors inside each window.

All angles here are in degrees, navigation convention (heading clockwise from north, pitch
nose up, roll right side down); body frame FLU, navigation frame ENU.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from typing import Any, NamedTuple

import numpy as np

from navpp import geodesy, spill
from navpp.errors import InputError
from navpp.ins.attitude import rph_deg_to_dcm
from navpp.intervals import interval_median, long_intervals
from navpp.recording import GnssData, ReferenceData, Solution

__all__ = [
    "Association",
    "associate",
    "compute_metrics",
    "error_stats",
    "interpolate_solution",
    "outage_metrics",
    "position_errors_enu",
    "wrap_deg",
]

#: Below this horizontal speed (m/s) the reference velocity does not define a heading.
MIN_SPEED_FOR_HEADING = 0.5


class Association(NamedTuple):
    """Reference epochs matched to an estimate.

    Attributes
    ----------
    idx_ref : (K,) int, indices into the reference arrays, increasing.
    t : (K,) float, s, the reference times ``t_ref[idx_ref]`` (where the estimate is evaluated).
    """

    idx_ref: np.ndarray
    t: np.ndarray


def associate(t_est: np.ndarray, t_ref: np.ndarray, skip_holes: bool = False) -> Association:
    """Reference epochs at which the estimate can be interpolated.

    Keeps the reference epochs with ``t_est[0] <= t_ref <= t_est[-1]`` (the span's ends
    included: the estimate is known there without extrapolation); with ``skip_holes``, not those
    inside a hole of the estimate (an interval longer than the INS bridges,
    :func:`navpp.ins.model.max_bridgeable_gap_s`, and than 3 of its median intervals: the gap
    between two segments of a run, navpp.engine.imu_segments);
    non-finite reference times are dropped.

    Parameters
    ----------
    t_est : (N,) float, s, non-decreasing estimate times.
    t_ref : (K,) float, s, reference times (same time base).

    Returns
    -------
    Association ``(idx_ref, t)``; empty when the spans do not overlap or ``t_est`` is empty.
    """
    t_est = np.asarray(t_est, dtype=float)
    t_ref = np.asarray(t_ref, dtype=float)
    if t_est.size == 0:
        idx = np.empty(0, dtype=np.int64)
        return Association(idx, t_ref[idx])
    inside = np.isfinite(t_ref) & (t_ref >= t_est[0]) & (t_ref <= t_est[-1])
    if skip_holes and t_est.size > 2:
        # a hole in the estimate (the IMU gap between two segments of a run, navpp.engine.imu_segments)
        # is not interpolated across: longer than the INS bridges and 3 of the estimate's own intervals
        from .ins.model import max_bridgeable_gap_s

        limit = max(max_bridgeable_gap_s(), 3.0 * interval_median(t_est))
        holes = long_intervals(t_est, limit)        # np.diff(t_est) > limit, a spilled t_est window by window
        for k in holes:
            inside &= ~((t_ref > t_est[k]) & (t_ref < t_est[k + 1]))
    idx = np.flatnonzero(inside).astype(np.int64)
    return Association(idx, t_ref[idx])


def wrap_deg(angle: np.ndarray | float, low: float = -180.0) -> np.ndarray:
    """Wrap degrees into ``[low, low + 360)``."""
    return np.mod(np.asarray(angle, dtype=float) - low, 360.0) + low


def _by_source_window(rows: np.ndarray) -> Iterator[slice | np.ndarray]:
    """The positions in ``rows`` (K,) (indices of source rows) grouped by the window of
    :data:`~navpp.spill.WINDOW_ROWS` source rows each falls in, window after window: slices of
    ``rows`` when they are non-decreasing (times in order, the usual case), index arrays otherwise."""
    win = rows // spill.WINDOW_ROWS
    if win.size == 0:
        return
    ordered = bool(np.all(win[1:] >= win[:-1]))
    order = None if ordered else np.argsort(win, kind="stable")
    win = win if order is None else win[order]
    bounds = [0, *(np.flatnonzero(win[1:] != win[:-1]) + 1).tolist(), win.size]
    for a, b in itertools.pairwise(bounds):
        yield slice(a, b) if order is None else order[a:b]


class _Bracket(NamedTuple):
    """Indices and weights that interpolate a source series at new times: ``y[i0] + w (y[i1] - y[i0])``."""

    i0: np.ndarray
    i1: np.ndarray
    w: np.ndarray

    @classmethod
    def of(cls, t_src: np.ndarray, t: np.ndarray) -> _Bracket:
        """The bracket of each time ``t`` (K,) s in the non-decreasing source times ``t_src`` (N,) s;
        a spilled ``t_src`` is searched and indexed one window of source rows at a time
        (:func:`_by_source_window`), its rows released behind each, so that the pages it touches
        stay a window's worth whatever the number of times."""
        n = t_src.shape[0]
        if n == 1:
            return cls(np.zeros(t.shape, int), np.zeros(t.shape, int), np.zeros(t.shape))
        if not spill.spilled(t_src):
            i1 = np.clip(np.searchsorted(t_src, t, side="right"), 1, max(n - 1, 1))
            i0 = i1 - 1
            span = t_src[i1] - t_src[i0]
            return cls(i0, i1, np.clip((t - t_src[i0]) / np.where(span > 0, span, 1.0), 0.0, 1.0))
        step = spill.WINDOW_ROWS
        # the window of each time from every window's first stamp (a strided read of N / step rows):
        # t_src[j * step] <= t < t_src[(j + 1) * step], so its place is inside window j
        first = np.array(t_src[::step])
        spill.release_all(t_src)
        win = np.maximum(np.searchsorted(first, t, side="right") - 1, 0)
        i0, i1, w = np.empty(t.shape, np.int64), np.empty(t.shape, np.int64), np.empty(t.shape)
        for sel in _by_source_window(win * step):
            start = int(win[sel][0]) * step
            lo = max(start - 1, 0)                  # a bracket's rows lie in start - 1 .. start + step
            seg = t_src[lo:start + step + 1]
            tk = t[sel]
            k1 = np.clip(start + np.searchsorted(seg[start - lo:start - lo + step], tk, side="right"), 1, n - 1)
            a, b = seg[k1 - 1 - lo], seg[k1 - lo]
            span = b - a
            i0[sel], i1[sel] = k1 - 1, k1
            w[sel] = np.clip((tk - a) / np.where(span > 0, span, 1.0), 0.0, 1.0)
            spill.release([t_src], lo, start + step + 1)
        return cls(i0, i1, w)

    def pair(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``y[i0]``, ``y[i1]`` as float: indexed first, converted after (no full-length copy); a
        spilled ``y`` (:mod:`navpp.spill`) one window of :data:`~navpp.spill.WINDOW_ROWS` source
        rows at a time (:func:`_by_source_window`), its rows released behind each."""
        y = np.asarray(y)
        if not spill.spilled(y):
            return y[self.i0].astype(float), y[self.i1].astype(float)
        a, b = np.empty((self.i0.shape[0], *y.shape[1:])), np.empty((self.i0.shape[0], *y.shape[1:]))
        for sel in _by_source_window(self.i0):
            i0, i1 = self.i0[sel], self.i1[sel]
            a[sel], b[sel] = y[i0], y[i1]
            spill.release([y], int(i0.min()), int(i1.max()) + 1)
        return a, b

    def linear(self, y: np.ndarray) -> np.ndarray:
        a, b = self.pair(y)
        w = self.w if a.ndim == 1 else self.w[:, None]
        return a + w * (b - a)

    def angle_deg(self, y: np.ndarray) -> np.ndarray:
        """Angles (deg) along the shorter arc between the two samples (crossing 0/360 or +-180)."""
        a, b = self.pair(y)
        return a + self.w * wrap_deg(b - a)


def _interp(t_src: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N,) or (N, m) ``y`` at ``t``; one-sample sources are constant."""
    return _Bracket.of(np.asarray(t_src, dtype=float), np.asarray(t, dtype=float)).linear(y)


def _decreasing(t: np.ndarray) -> bool:
    """Whether the times ``t`` (N,) s ever decrease; a spilled ``t`` window by window, its pages
    released behind (:func:`navpp.spill.windows`)."""
    for a, b in spill.windows(t.shape[0], t):
        seg = t[max(a - 1, 0):b]            # with the window's first pair across its start
        if np.any(seg[1:] < seg[:-1]):
            return True
    return False


def _interp_track(t_src: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray,
                  vel_enu: np.ndarray | None, rph_deg: np.ndarray | None,
                  t: np.ndarray) -> dict[str, np.ndarray]:
    """Interpolate a trajectory: positions, velocity and roll/pitch linearly; longitude and
    heading along the shorter arc between neighbouring samples (across +-180 deg and 0/360 deg).

    Only the two samples around each requested time are touched, so interpolating an
    IMU-rate solution at reference epochs costs no full-length temporaries.
    """
    t_src = np.asarray(t_src, dtype=float)
    t = np.asarray(t, dtype=float)
    if t_src.size == 0:
        raise ValueError("cannot interpolate a trajectory with no epochs")
    if _decreasing(t_src):
        raise InputError("trajectory times are not increasing; cannot interpolate")
    return _track_at(_Bracket.of(t_src, t), lat_deg, lon_deg, alt, vel_enu, rph_deg, t)


def _track_at(br: _Bracket, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray,
              vel_enu: np.ndarray | None, rph_deg: np.ndarray | None, t: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`_interp_track`'s values at the times ``t`` (K,) s bracketed by ``br`` in its source."""
    out = {
        "t": t,
        "lat_deg": br.linear(lat_deg),
        "lon_deg": wrap_deg(br.angle_deg(lon_deg)),
        "alt": br.linear(alt),
    }
    if vel_enu is not None:
        out["vel_enu"] = br.linear(vel_enu)
    if rph_deg is not None:
        rph = np.asarray(rph_deg)
        out["rph_deg"] = np.stack([br.linear(rph[:, 0]), br.linear(rph[:, 1]),
                                   wrap_deg(br.angle_deg(rph[:, 2]), 0.0)], axis=-1)
    return out


def interpolate_solution(sol: Solution, t: np.ndarray) -> dict[str, np.ndarray]:
    """Solution values at times ``t`` (s, relative to ``sol.t0_ns``) by linear interpolation.

    Latitude, altitude, velocity, roll, pitch and position std are linear in time; longitude
    is interpolated on its unwrapped value (so a crossing of +-180 deg is handled) and wrapped
    to [-180, 180); heading is interpolated on the unwrapped angle and wrapped to [0, 360).
    Times outside ``[sol.t[0], sol.t[-1]]`` get the end values (use :func:`associate` first).

    Returns
    -------
    dict with ``t`` (K,), ``lat_deg`` (K,) deg, ``lon_deg`` (K,) deg, ``alt`` (K,) m,
    ``vel_enu`` (K, 3) m/s, ``rph_deg`` (K, 3) deg, ``std_enu`` (K, 3) m.
    """
    out = _interp_track(sol.t, sol.lat_deg, sol.lon_deg, sol.alt, sol.vel_enu, sol.rph_deg, t)
    out["std_enu"] = _interp(np.asarray(sol.t, dtype=float), sol.std_enu, np.asarray(t, dtype=float))
    return out


#: Points per block of :func:`position_errors_enu`: its ECEF differences and rotations are (K, 3)
#: and (K, 3, 3) temporaries, which for an 8-hour reference at 10 Hz were about 66 MB at once.
ENU_BLOCK = 1 << 15


def position_errors_enu(lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray,
                        ref_lat_deg: np.ndarray, ref_lon_deg: np.ndarray,
                        ref_alt: np.ndarray) -> np.ndarray:
    """Estimate minus reference position in the local ENU frame of each reference point.

    Exact (through ECEF, :func:`navpp.geodesy.geodetic_to_enu`), so it holds at any latitude and
    any error size.

    Parameters
    ----------
    lat_deg, lon_deg, alt : (K,) estimate, deg / deg / m (WGS-84 ellipsoidal height).
    ref_lat_deg, ref_lon_deg, ref_alt : (K,) reference, same units.

    Returns
    -------
    (K, 3) float, m: east (longitude error), north (latitude error), up (height error).
    """
    cols = [np.atleast_1d(np.asarray(a, dtype=float)) for a in (lat_deg, lon_deg, alt, ref_lat_deg, ref_lon_deg,
                                                                  ref_alt)]
    k = max(c.shape[0] for c in cols)
    cols = [np.broadcast_to(c, (k,)) for c in cols]
    out = np.empty((k, 3))
    for a in range(0, k, ENU_BLOCK):     # point by point, so blocks give the same bits as one call
        la, lo, h, rla, rlo, rh = (c[a:a + ENU_BLOCK] for c in cols)
        out[a:a + ENU_BLOCK] = geodesy.geodetic_to_enu(np.radians(la), np.radians(lo), h, np.radians(rla),
                                                       np.radians(rlo), rh)
    return out


def _abs_stats(a: np.ndarray) -> dict[str, float]:
    """MAE, RMSE, max and 95th percentile (numpy's linear method) of non-negative values."""
    return {
        "mae": float(np.mean(a)),
        "rmse": float(np.sqrt(np.mean(a * a))),
        "max": float(np.max(a)),
        "p95": float(np.percentile(a, 95.0)),
    }


def error_stats(err: np.ndarray) -> dict[str, dict[str, float]]:
    """Statistics of ENU errors.

    Parameters
    ----------
    err : (K, 3) float, errors east / north / up (m, or m/s for velocities), K >= 1.

    Returns
    -------
    ``{"east", "north", "up", "horizontal", "3d"}``, each ``{"mae", "rmse", "max", "p95"}`` of
    the absolute error: ``mae = mean|e|``, ``rmse = sqrt(mean e^2)``, ``max = max|e|``,
    ``p95`` = 95th percentile of ``|e|`` (linear interpolation between order statistics);
    horizontal uses ``hypot(east, north)``, 3d the Euclidean norm.
    """
    err = np.asarray(err, dtype=float)
    if err.ndim != 2 or err.shape[1] != 3 or err.shape[0] == 0:
        raise ValueError(f"error_stats needs a (K, 3) array with K >= 1, got shape {err.shape}")
    # one column's or one norm's temporaries at a time (the norms row by row in blocks of
    # ENU_BLOCK: the same bits as at once), not the (K, 3) ones
    stats = {name: _abs_stats(np.abs(err[:, j])) for j, name in enumerate(("east", "north", "up"))}
    norm = np.empty(err.shape[0])
    for name in ("horizontal", "3d"):
        for a in range(0, err.shape[0], ENU_BLOCK):
            e = err[a:a + ENU_BLOCK]
            norm[a:a + ENU_BLOCK] = np.hypot(e[:, 0], e[:, 1]) if name == "horizontal" else np.linalg.norm(e, axis=1)
        stats[name] = _abs_stats(norm)
    return stats


def _heading_from_velocity(vel_enu: np.ndarray) -> np.ndarray | None:
    """Heading (deg) of the horizontal velocity, held across slow epochs; None if never moving."""
    speed = np.hypot(vel_enu[:, 0], vel_enu[:, 1])
    moving = np.isfinite(speed) & (speed >= MIN_SPEED_FOR_HEADING)
    if not moving.any():
        return None
    idx = np.flatnonzero(moving)
    # index of the nearest preceding moving epoch (or the first one, before it)
    pos = np.maximum(np.searchsorted(idx, np.arange(len(speed)), side="right") - 1, 0)
    src = idx[pos]
    return np.degrees(np.arctan2(vel_enu[src, 0], vel_enu[src, 1]))


def _gnss_position_metrics(gnss: GnssData, ref: ReferenceData,
                           lever_arm_m: Sequence[float]) -> dict[str, Any]:
    """Accuracy of the raw GNSS fixes against the reference antenna position."""
    lever = np.asarray(lever_arm_m, dtype=float).reshape(3)
    t_g = np.asarray(gnss.t, dtype=float)
    ok = (np.isfinite(t_g) & np.isfinite(gnss.lat_deg) & np.isfinite(gnss.lon_deg)
          & np.isfinite(gnss.alt))
    assoc = associate(np.asarray(ref.t, dtype=float), np.where(ok, t_g, np.nan))
    if assoc.idx_ref.size == 0:
        return {"epochs": 0, "note": "no GNSS fix inside the reference time span"}
    i = assoc.idx_ref
    r = _interp_track(ref.t, ref.lat_deg, ref.lon_deg, ref.alt, ref.vel_enu, ref.rph_deg, assoc.t)
    err = position_errors_enu(gnss.lat_deg[i], gnss.lon_deg[i], gnss.alt[i],
                              r["lat_deg"], r["lon_deg"], r["alt"])
    note = None
    if np.any(lever != 0.0):
        if "rph_deg" in r:
            rph_nb = r["rph_deg"]       # deg: C_b^n's angles (the DCMs formed block by block below)
        else:
            heading = _heading_from_velocity(r["vel_enu"]) if "vel_enu" in r else None
            if heading is None:
                # no heading: only the vertical part of the lever arm is known (roll = pitch = 0)
                rph_nb = None
                err = err - np.array([0.0, 0.0, lever[2]])
                note = ("only the vertical part of the lever arm applied: the reference has no attitude and "
                        "no velocity to take a heading from")
            else:
                rph_nb = np.stack([np.zeros_like(heading), np.zeros_like(heading), heading], axis=-1)
                note = ("lever arm rotated with the heading of the reference velocity "
                        "(roll and pitch taken as zero): the reference has no attitude")
        if rph_nb is not None:
            # antenna = body + C_b^n l; in the ENU frame of the body point (the frame of the
            # antenna point differs by |l| / R ~ 1e-7 rad); the (K, 3, 3) DCMs in blocks of
            # ENU_BLOCK fixes (each fix's product does not depend on the block)
            for a in range(0, err.shape[0], ENU_BLOCK):
                err[a:a + ENU_BLOCK] -= rph_deg_to_dcm(rph_nb[a:a + ENU_BLOCK]) @ lever
    out: dict[str, Any] = {"epochs": int(i.size)}
    out.update(error_stats(err))
    if note is not None:
        out["note"] = note
    return out


def outage_metrics(t: np.ndarray, err: np.ndarray, windows: Sequence[tuple[float, float]],
                   removed: Sequence[int] | None = None) -> list[dict[str, Any]]:
    """Position errors inside GNSS outage windows, one dict per window.

    Parameters
    ----------
    t : (K,) float, s, times of the compared reference epochs (relative to the log start),
        increasing.
    err : (K, 3) float, m, estimate minus reference at ``t``, ENU.
    windows : ``(start_s, duration_s)`` pairs; a window holds the epochs with
        ``start <= t <= start + duration`` (both ends included, as the removed fixes).
    removed : GNSS fixes removed per window (reported as ``gnss_removed``), optional.

    Returns
    -------
    list of dicts: ``start_s``, ``duration_s``, ``end_s`` (s), ``epochs`` (reference epochs
    inside), ``gnss_removed`` (if given), and when ``epochs > 0``: ``end_epoch_s`` (time of the
    last reference epoch inside the window, where the "end" errors are taken), ``horizontal_m``
    (``hypot(east, north)``) and ``vertical_m`` (``|up|``), each ``{"end", "max", "rmse"}`` in m.
    """
    t = np.asarray(t, dtype=float)
    err = np.asarray(err, dtype=float).reshape(-1, 3)
    out: list[dict[str, Any]] = []
    for k, (start, dur) in enumerate(windows):
        start, dur = float(start), float(dur)
        end = start + dur
        inside = np.flatnonzero((t >= start) & (t <= end))
        w: dict[str, Any] = {"start_s": start, "duration_s": dur, "end_s": end, "epochs": int(inside.size)}
        if removed is not None:
            w["gnss_removed"] = int(removed[k])
        if inside.size:
            e = err[inside]
            for name, a in (("horizontal_m", np.hypot(e[:, 0], e[:, 1])), ("vertical_m", np.abs(e[:, 2]))):
                w[name] = {"end": float(a[-1]), "max": float(a.max()), "rmse": float(np.sqrt(np.mean(a * a)))}
            w["end_epoch_s"] = float(t[inside[-1]])
        out.append(w)
    return out


def compute_metrics(sol: Solution, ref: ReferenceData, *, filter_name: str, log: str,
                    reference: str, runtime_s: float, imu_samples: int, gnss_epochs: int,
                    gnss_rejected: int, gnss: GnssData | None = None,
                    lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0),
                    outages: Sequence[tuple[float, float]] = (),
                    outages_removed: Sequence[int] | None = None,
                    updates: dict[str, dict[str, int]] | None = None) -> dict[str, Any]:
    """The ``metrics.json`` structure (README.md, "Outputs") of a solution against a reference.

    Keys: ``filter``, ``log``, ``reference``, ``epochs`` (reference epochs inside the solution
    span), ``position_m`` (:func:`error_stats` of the ENU position errors, m), ``velocity_mps``
    (same over ENU velocity errors, only if the reference has velocity), ``attitude_deg``
    (``roll``, ``pitch``, ``heading``: each ``{"mae", "rmse", "max", "p95"}`` of the error
    wrapped to [-180, 180), only if the reference has attitude), ``runtime_s``,
    ``imu_samples``, ``gnss_epochs``, ``gnss_rejected``.

    With ``gnss``, also ``gnss_position_m``: the raw fixes against the reference antenna
    position (reference interpolated to the GNSS epochs inside its span; antenna = reference
    body position + ``C_b^n @ lever_arm_m``, ``C_b^n`` from the reference attitude, else from
    the heading of the reference velocity with zero roll and pitch, else the lever arm is
    ignored).  It holds :func:`error_stats` plus ``epochs`` (fixes compared) and, when the lever
    arm could not be applied in full, a ``note``.

    With ``outages`` (``(start_s, duration_s)`` windows of removed GNSS, s from the log start),
    also ``outages``: :func:`outage_metrics` of the position errors, one dict per window (the
    other figures stay over the whole run); ``outages_removed`` gives the fixes removed per
    window.

    With ``updates`` (the engine's ``RunResult.updates``), also ``updates``: per measurement kind
    (``gnss_position``, ``gnss_velocity``, ``zupt``, ``zaru``, ``nhc``) the updates applied and
    rejected by the innovation gate.

    Parameters
    ----------
    sol : the solution (body origin).
    ref : the reference (body origin), same relative time base as ``sol``.
    lever_arm_m : (3,) m, GNSS antenna position in the body frame (FLU).

    Raises
    ------
    InputError
        When no reference epoch falls inside the solution's time span.

    Returns
    -------
    dict of plain Python ``str`` / ``int`` / ``float`` values (JSON serialisable).
    """
    t_sol = np.asarray(sol.t, dtype=float)
    t_ref = np.asarray(ref.t, dtype=float)
    # reference rows without a position cannot be compared: drop them (time -> NaN)
    ref_ok = np.isfinite(ref.lat_deg) & np.isfinite(ref.lon_deg) & np.isfinite(ref.alt)
    assoc = associate(t_sol, np.where(ref_ok, t_ref, np.nan), skip_holes=True)
    if assoc.idx_ref.size == 0:
        sol_span = f"[{t_sol[0]:.3f}, {t_sol[-1]:.3f}] s" if t_sol.size else "empty"
        ref_span = f"[{np.nanmin(t_ref):.3f}, {np.nanmax(t_ref):.3f}] s" if t_ref.size else "empty"
        raise InputError(
            f"reference {reference or ref.source!r}: no epoch inside the solution's time span "
            f"(solution {sol_span}, reference {ref_span}, relative to the log start)"
        )
    i = assoc.idx_ref
    if _decreasing(t_sol):
        raise InputError("trajectory times are not increasing; cannot interpolate")
    # interpolate_solution's values but the 1-sigma (unused here) and their errors in blocks of
    # ENU_BLOCK reference points, so that no reference-length temporaries pile up (the errors of
    # each point do not depend on the block: the same bits as at once)
    n_ref = i.size
    pos_err = np.empty((n_ref, 3))
    vel_err, vel_rows = (np.empty((n_ref, 3)), np.empty(n_ref, bool)) if ref.vel_enu is not None else (None, None)
    att_err, att_rows = (np.empty((n_ref, 3)), np.empty(n_ref, bool)) if ref.rph_deg is not None else (None, None)
    for a in range(0, n_ref, ENU_BLOCK):
        b = min(n_ref, a + ENU_BLOCK)
        ib, tb = i[a:b], assoc.t[a:b]
        est = _track_at(_Bracket.of(t_sol, tb), sol.lat_deg, sol.lon_deg, sol.alt, sol.vel_enu, sol.rph_deg, tb)
        pos_err[a:b] = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"],
                                           ref.lat_deg[ib], ref.lon_deg[ib], ref.alt[ib])
        if vel_err is not None and vel_rows is not None:
            ref_vel = np.asarray(ref.vel_enu, dtype=float)[ib]
            vel_err[a:b] = est["vel_enu"] - ref_vel
            vel_rows[a:b] = np.all(np.isfinite(ref_vel), axis=1)
        if att_err is not None and att_rows is not None:
            ref_rph = np.asarray(ref.rph_deg, dtype=float)[ib]
            att_err[a:b] = np.abs(wrap_deg(est["rph_deg"] - ref_rph))
            att_rows[a:b] = np.all(np.isfinite(ref_rph), axis=1)
    metrics: dict[str, Any] = {
        "filter": str(filter_name),
        "log": str(log),
        "reference": str(reference),
        "epochs": int(n_ref),
        "position_m": error_stats(pos_err),
    }
    if vel_err is not None and vel_rows is not None and vel_rows.any():
        metrics["velocity_mps"] = error_stats(vel_err if vel_rows.all() else vel_err[vel_rows])
    del vel_err
    if att_err is not None and att_rows is not None and att_rows.any():
        att = att_err if att_rows.all() else att_err[att_rows]
        metrics["attitude_deg"] = {name: _abs_stats(att[:, j]) for j, name in enumerate(("roll", "pitch", "heading"))}
        del att
    del att_err
    metrics["runtime_s"] = float(runtime_s)
    metrics["imu_samples"] = int(imu_samples)
    metrics["gnss_epochs"] = int(gnss_epochs)
    metrics["gnss_rejected"] = int(gnss_rejected)
    if gnss is not None:
        metrics["gnss_position_m"] = _gnss_position_metrics(gnss, ref, lever_arm_m)
    if len(outages):
        metrics["outages"] = outage_metrics(assoc.t, pos_err, outages, outages_removed)
    if updates:
        metrics["updates"] = {k: {"applied": int(v["applied"]), "rejected": int(v["rejected"])}
                              for k, v in updates.items()}
    del pos_err
    spill.trim_heap()       # the reference-length errors' pages back to the system before the writers
    return metrics
