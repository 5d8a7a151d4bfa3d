"""Timing diagnostics of a log: stale IMU rows and the IMU-to-GNSS clock offset.

Pure functions, no I/O and no configuration: the caller passes arrays (as held by
:class:`navpp.recording.ImuData` / :class:`navpp.recording.GnssData`) and decides what to do
with the answers.  numpy, and of scipy only LAPACK's tridiagonal solve (``dgtsv`` of ``scipy.linalg._flapack``,
loaded without the rest of scipy.linalg: :mod:`navpp.scipy_parts`) or what it needs rarely (``scipy.special`` when
rows repeat, ``scipy.interpolate`` for a spline of fewer than 4 points): the spline's
evaluation (:class:`Cubic`) is scipy's to the bit without importing scipy.interpolate (0.3 s
and more of every run's start); the bounded lag refinement is a golden-section search
(:func:`_golden_section_min`), not scipy.optimize (which loads scipy.special too: about 0.4 s).

Conventions: times are float seconds (any common origin, e.g. relative to the log's first
IMU stamp); body frame FLU, navigation frame ENU; gyro in rad/s, specific force in m/s^2.

- :func:`find_stale_rows` finds IMU rows that repeat the previous row's six values bitwise
  under a new stamp (a logger polling faster than the sensor updates).
- :func:`estimate_clock_offset` finds the delay of the IMU stamps against the GNSS stamps by
  matching the vertical angular rate from the gyro with the course rate of the GNSS
  velocity; :func:`velocity_from_positions` turns GNSS positions into that velocity.
- :func:`yaw_scale_from_track` compares the gyro's turns with the GNSS track's over a few
  seconds (robust to metre-level fix noise): a gyro read in the wrong unit shows as a scale
  of 1/57.3 or 57.3.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np

from navpp.kernel import njit

from ..intervals import interval_median
from ..spill import Behind, like, release, release_all
from .calibrate import BLOCK_ROWS, trapezoid_integral, trapezoid_integral_at

__all__ = [
    "ClockOffset",
    "StaleRows",
    "YawScale",
    "estimate_clock_offset",
    "find_stale_rows",
    "fresh_count_dispersion",
    "velocity_from_positions",
    "yaw_scale_from_track",
]


# --------------------------------------------------------------------------------------------
# Stale rows
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StaleRows:
    """Result of :func:`find_stale_rows`.

    Attributes
    ----------
    mask : (N,) bool, True = stale row, drop it.  All False when the repeats are not judged
        stale.  The first row is never stale.
    count : int, number of True entries in ``mask``.
    fraction : float, ``count / N``.
    fresh_rate_hz : float, Hz, rate of the kept (fresh) samples: ``(n_kept - 1) / (time span
        of the kept samples)``.  Robust to a jittery polling clock, where the fresh intervals
        scatter over a few poll periods.
    n_repeats : int, rows whose six values bitwise equal the previous row's (stale or not).
    expected_by_chance : float, number of such all-six repeats expected if every channel
        repeated independently at its own rate (estimated in windows, from the rows that are
        not all-six repeats).
    dispersion : float, variance of the number of non-repeated rows per 1-s window divided by
        the binomial variance expected if the repeats fell at random (NaN when not testable).
        A sensor sampled at a fixed rate and polled faster gives ~0 (the fresh count per
        second is fixed); random coincident repeats give ~1.
    confident : bool, whether the evidence is clear-cut (see :func:`find_stale_rows`).
    reason : str, one line saying why.
    """

    mask: np.ndarray
    count: int
    fraction: float
    fresh_rate_hz: float
    n_repeats: int
    expected_by_chance: float
    dispersion: float
    confident: bool
    reason: str


def _chance_all_repeat(q: np.ndarray) -> float:
    """Probability that all channels repeat at once under independence.

    ``q`` (C,) are the per-channel repeat rates measured on the rows that are *not* all-C
    repeats.  Those rows are the independent model truncated to exclude the joint event, so
    the unconditional channel rates are ``p_c = q_c (1 - P) + P`` with ``P = prod(p_c)``: the
    smallest fixed point of ``P = prod(q_c + P (1 - q_c))`` in [0, 1) (the map is convex and
    increasing, so iterating from ``prod(q_c)`` climbs monotonically onto it).
    """
    p = float(np.prod(q))
    for _ in range(500):
        new = float(np.prod(q + p * (1.0 - q)))
        if new >= 0.999:
            return 0.999                    # no fixed point below 1: every row may repeat
        if abs(new - p) < 1e-12:
            return new
        p = new
    return p


def find_stale_rows(
    t: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    *,
    window_rows: int = 500,
    excess_factor: float = 3.0,
    alpha: float = 1e-6,
    min_fraction: float = 0.05,
    regular_dispersion: float = 0.3,
) -> StaleRows:
    """Find IMU rows that are stale copies of the previous sample.

    A row whose six values (gyro and accel) bitwise equal the previous row's while its stamp
    is new is either a *stale* sample (the logger polled faster than the sensor updated) or a
    legitimate coincidence (a coarsely quantised, quiet sensor repeating its reading).  The
    repeats are judged stale as a whole, from two independent signatures:

    1. **Excess over chance.**  In windows of ``window_rows`` rows, each channel's repeat
       rate is measured on the rows that are not all-six repeats, and the chance of all six
       repeating together is derived from them assuming independent channels (see
       ``expected_by_chance``).  The repeats are in *excess* when the observed count is more
       than ``excess_factor`` times the expected one and its Poisson upper-tail probability
       is below ``alpha``.
    2. **Polling signature.**  After removing the repeats, the number of fresh samples per
       1-s window is far steadier than random removals would leave it: ``dispersion <
       regular_dispersion`` (testable when the repeats are frequent enough that a binomial
       count would scatter by more than ~1.4 samples per window, over >= 5 windows).

    The repeats are declared stale if they are in excess, or if they make up at least
    ``min_fraction`` of the rows *and* show the polling signature.  ``confident`` is True
    when both signatures agree (both present: stale; excess absent and either no repeat at
    all or a count consistent with chance and no polling signature: not stale), False
    otherwise (e.g. an excess without a testable polling signature).  Every all-six repeat
    is flagged when the repeats are declared stale: a chance repeat among stale ones cannot
    be told apart, and dropping it only merges two equal readings.

    The kept rows keep their stamps: an integrator then uses the true interval between fresh
    samples.  (If the sensor's own sampling instant matters, note a stale-prone logger
    stamps each fresh sample at the poll that first saw it: up to one poll period late.)

    Parameters
    ----------
    t : (N,) float, s, strictly increasing sample stamps.
    gyro : (N, 3) float, rad/s, body FLU angular rate.
    accel : (N, 3) float, m/s^2, body FLU specific force.
    window_rows : rows per window for the chance estimate (handles a sensor that is quiet at
        times only).
    excess_factor, alpha : thresholds of signature 1 (ratio observed / expected, Poisson
        upper-tail probability).
    min_fraction : minimal fraction of repeated rows for signature 2 alone to decide.
    regular_dispersion : signature 2 threshold on ``dispersion``.

    Returns
    -------
    StaleRows
    """
    t = np.asarray(t, dtype=float)
    gyro, accel = np.asarray(gyro), np.asarray(accel)
    n = t.shape[0]
    if gyro.shape[0] != n or accel.shape[0] != n:
        raise ValueError(f"find_stale_rows: t has {n} rows, gyro/accel {gyro.shape[0]}/{accel.shape[0]}")
    nan = float("nan")
    if n < 3:
        mask = np.zeros(n, dtype=bool)
        return StaleRows(mask, 0, 0.0, _rate(t), 0, 0.0, nan, False,
                         f"only {n} rows: nothing to judge")

    # bitwise comparison: -0.0 vs +0.0 and NaN payloads count as different / equal by bits;
    # block by block (whole windows each): per window its fresh rows and their per-channel repeats
    repeats = np.zeros(n, dtype=bool)                   # (N,) row k repeats row k-1
    rep = repeats[1:]                                   # (N-1,) view
    starts = np.arange(0, n - 1, window_rows)
    sizes = np.diff(np.append(starts, n - 1))
    n_fresh = np.zeros(starts.shape[0], dtype=np.int64)
    n_same = np.zeros((starts.shape[0], 6), dtype=np.int64)
    block = max(1, BLOCK_ROWS // window_rows) * window_rows
    for lo in range(0, n - 1, block):
        hi = min(lo + block, n - 1)
        win = slice(lo // window_rows, lo // window_rows + -(-(hi - lo) // window_rows))
        _repeat_counts(_bits(gyro[lo:hi + 1]), _bits(accel[lo:hi + 1]), window_rows, rep[lo:hi], n_fresh[win],
                       n_same[win])
        release((gyro, accel), lo, hi)                  # a spilled IMU's rows read: out of memory
    k_obs = int(np.count_nonzero(rep))

    # 1. excess over chance, window by window: each window's channel rates from its counts (each
    # channel's repeat rate over the window's fresh rows), the chance once per distinct rates;
    # the global rates from the sums of the counts
    expected = 0.0
    n_fresh_all = int(n_fresh.sum())
    global_q = n_same.sum(axis=0) / n_fresh_all if n_fresh_all else np.zeros(6)
    chance: dict[bytes, float] = {}
    for w in range(starts.shape[0]):
        if sizes[w] < window_rows // 2 and w > 0:       # a short tail joins the global rates
            q = global_q
        else:
            q = n_same[w] / n_fresh[w] if n_fresh[w] >= 20 else global_q
        key = q.tobytes()
        if key not in chance:
            chance[key] = _chance_all_repeat(q)
        expected += int(sizes[w]) * chance[key]
    # P(Poisson(expected) >= k_obs): special.pdtrc is what stats.poisson.sf evaluates, without
    # importing scipy.stats; scipy.special itself (0.3 s) only when a row repeats
    p_tail = 1.0
    if k_obs > 0:
        from scipy import special

        p_tail = float(special.pdtrc(k_obs - 1, expected))
    excess = k_obs > 0 and k_obs > excess_factor * expected and p_tail < alpha

    # 2. polling signature: the fresh count per 1-s window
    dispersion = fresh_count_dispersion(t, repeats, k_obs / n)
    regular = bool(np.isfinite(dispersion) and dispersion < regular_dispersion)
    fraction_rep = k_obs / n

    stale = excess or (regular and fraction_rep >= min_fraction)
    msg = (f"{k_obs} all-six repeats ({100 * fraction_rep:.2f} %), {expected:.3g} expected by chance"
           f" (Poisson tail {p_tail:.2g}), fresh-count dispersion "
           + ("untestable" if not np.isfinite(dispersion) else f"{dispersion:.2f}"))
    if k_obs == 0:
        confident, reason = True, "no row repeats the previous row's six values"
    elif stale and excess and regular:
        confident, reason = True, "stale: " + msg + ": excess over chance and a regular fresh stream"
    elif stale:
        confident = False
        reason = ("stale (excess over chance, but no polling signature): " if excess else
                  "stale (polling signature, but no excess over chance): ") + msg
    elif k_obs <= expected + 3.0 * np.sqrt(expected) + 1.0 and not regular:
        confident, reason = True, "not stale: " + msg + ": consistent with chance"
    else:
        confident, reason = False, "not stale, ambiguous: " + msg

    mask = repeats if stale else np.zeros(n, dtype=bool)
    kept = t[~mask] if stale else t
    count = int(mask.sum())
    return StaleRows(mask=mask, count=count, fraction=count / n, fresh_rate_hz=_rate(kept),
                     n_repeats=k_obs,
                     expected_by_chance=float(expected), dispersion=float(dispersion),
                     confident=bool(confident), reason=reason)


@njit(cache=True)
def _repeat_counts(gyro: np.ndarray, accel: np.ndarray, window_rows: int, rep: np.ndarray, n_fresh: np.ndarray,
                   n_same: np.ndarray) -> None:
    """For the rows ``gyro``, ``accel`` (B + 1, 3) int64 (the bits of the values, :func:`_bits`):
    ``rep`` (B,) bool, row k + 1 repeats row k in all six channels; per window of
    ``window_rows`` of those B rows, its rows that do not (``n_fresh`` (W,), added to) and among
    them the ones repeating each channel (``n_same`` (W, 6), added to)."""
    for k in range(rep.shape[0]):
        w = k // window_rows
        all6 = True
        for c in range(3):
            if gyro[k + 1, c] != gyro[k, c] or accel[k + 1, c] != accel[k, c]:
                all6 = False
        rep[k] = all6
        if not all6:
            n_fresh[w] += 1
            for c in range(3):
                if gyro[k + 1, c] == gyro[k, c]:
                    n_same[w, c] += 1
                if accel[k + 1, c] == accel[k, c]:
                    n_same[w, 3 + c] += 1


def _bits(x: np.ndarray) -> np.ndarray:
    """The rows ``x`` (R, 3) as float64, their bits as int64 (R, 3)."""
    bits: np.ndarray = np.ascontiguousarray(x, dtype=float).reshape(-1, 3).view(np.int64)
    return bits


def _rate(t: np.ndarray) -> float:
    if t.shape[0] < 2 or t[-1] <= t[0]:
        return float("nan")
    return float((t.shape[0] - 1) / (t[-1] - t[0]))


def fresh_count_dispersion(t: np.ndarray, repeats: np.ndarray, f: float, window_s: float = 1.0) -> float:
    """The fresh-count dispersion of :func:`find_stale_rows`: over windows of ``window_s`` s of the
    stamps ``t`` (N,) s, the variance of the rows that are not ``repeats`` (N,) bool, divided by
    the binomial variance they would have if a fraction ``f`` of the rows repeated at random.

    NaN when the log has fewer samples than windows (its time is mostly gaps): the windows are
    never more than the samples, so the cost stays O(N) whatever the stamps span."""
    if not (t[-1] - t[0]) / window_s <= t.shape[0]:
        return float("nan")
    edges = np.arange(t[0], t[-1], window_s)
    if edges.shape[0] < 7:                      # >= 5 complete windows once the ends are cut
        return float("nan")
    # the rows and fresh rows per window, counted block by block (exact sums of 1s)
    rows = np.zeros(edges.shape[0], dtype=np.int64)
    fresh = np.zeros(edges.shape[0])
    for lo in range(0, t.shape[0], BLOCK_ROWS):
        _window_counts(edges, np.asarray(t[lo:lo + BLOCK_ROWS], dtype=float),
                       np.asarray(repeats[lo:lo + BLOCK_ROWS], dtype=np.bool_), rows, fresh)
        release((t,), lo, lo + BLOCK_ROWS)
    rows, fresh = rows[1:-1], fresh[1:-1]       # drop the partial ends
    binom = float(np.mean(rows * f * (1.0 - f)))
    if binom < 2.0:
        return float("nan")
    # remove what the changing row count explains: compare with the expected fresh count
    # random removals scatter both the fresh count and its difference to the expected count
    # by at least the binomial variance; a fixed-rate sensor keeps the fresh count steady
    resid = fresh - rows * (1.0 - f)
    return float(min(np.var(fresh), np.var(resid)) / binom)


@njit(cache=True)
def _window_counts(edges: np.ndarray, t: np.ndarray, repeats: np.ndarray, rows: np.ndarray,
                   fresh: np.ndarray) -> None:
    """Add to ``rows`` (W,) int64 and ``fresh`` (W,) float the rows among the stamps ``t`` (K,) in
    each window ``edges[w] <= t < edges[w + 1]`` (the last one unbounded) and those that are not
    ``repeats`` (K,) bool: ``np.bincount`` of ``np.searchsorted(edges, t, "right") - 1`` (a NaN
    stamp in the last window), the search started from the previous stamp's window."""
    last = edges.shape[0] - 1
    j = 0
    for k in range(t.shape[0]):
        tk = t[k]
        if tk != tk:
            j = last
        elif not (edges[j] <= tk and (j == last or tk < edges[j + 1])):
            lo, hi = 0, last + 1                    # the first edge > tk, binary search
            while lo < hi:
                mid = (lo + hi) // 2
                if tk < edges[mid]:
                    hi = mid
                else:
                    lo = mid + 1
            j = lo - 1
            if j < 0:
                raise ValueError("fresh_count_dispersion: a stamp before the first window")
        rows[j] += 1
        if not repeats[k]:
            fresh[j] += 1.0


# --------------------------------------------------------------------------------------------
# Clock offset IMU vs GNSS
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ClockOffset:
    """Result of :func:`estimate_clock_offset`.

    Sign: ``offset_s > 0`` means the IMU stamps are LATE by ``offset_s``: an event stamped
    ``t`` by the IMU is stamped ``t - offset_s`` by the GNSS, i.e.
    ``t_gnss = t_imu - offset_s``.  To put the IMU on the GNSS time base subtract
    ``offset_s`` from the IMU stamps (or add it to the GNSS stamps to put the GNSS on the
    IMU's).  GNSS fixes that come out late against the IMU (receiver latency) give a
    negative ``offset_s``.

    Attributes
    ----------
    offset_s : float, s, the estimate (NaN when nothing could be estimated).
    sigma_s : float, s, its 1-sigma: a delete-one-block jackknife, see
        :func:`estimate_clock_offset`.
    correlation : float, correlation coefficient between the GNSS yaw rate and the shifted,
        interval-averaged gyro rate at ``offset_s``.
    n_samples : int, number of GNSS course-rate samples used.
    turn_deg : float, deg, integrated |yaw rate| (from the gyro, bias removed) over the
        samples used: how much turning the estimate rests on.
    scale : float, fitted ratio GNSS yaw rate / gyro rate (1 for a vertical gyro axis;
        cos(tilt) for a tilted one).
    bias_rad_s : float, rad/s, fitted gyro bias, as in ``rate_gnss = scale * (gyro - bias)``.
    at_edge : bool, whether the best lag lies at the edge of the search window.
    confident : bool, see :func:`estimate_clock_offset`.
    reason : str, one line saying why.
    consistent : bool, whether the two halves of the turning agree on the lag (within
        ``max_split_sigmas``); False also makes ``confident`` False.
    split_sigmas : float, their disagreement in sigmas (NaN when nothing was estimated).
    n_outliers : int, course-rate samples dropped as outliers.
    """

    offset_s: float
    sigma_s: float
    correlation: float
    n_samples: int
    turn_deg: float
    scale: float
    bias_rad_s: float
    at_edge: bool
    confident: bool
    reason: str
    consistent: bool = False
    split_sigmas: float = float("nan")
    n_outliers: int = 0


def velocity_from_positions(t: np.ndarray, east_m: np.ndarray,
                            north_m: np.ndarray, *, max_gap_factor: float = 1.5) -> np.ndarray:
    """Horizontal velocity from positions: the derivative at ``t_k`` of the parabola through
    three neighbouring fixes, never across a gap.

    The log is cut into runs of fixes at most ``max_gap_factor`` median intervals apart.
    Inside a run, ``v_k`` is the derivative at ``t_k`` of the quadratic through epochs
    ``k - 1, k, k + 1`` (for uniform stamps the central difference ``(p_{k+1} - p_{k-1}) /
    (t_{k+1} - t_{k-1})``); at the first / last epoch of a run the quadratic through that
    epoch and its next two (previous two) neighbours, differentiated at the epoch itself.
    So every ``v_k`` belongs to ``t_k`` and is exact for a locally quadratic track,
    whatever the spacing.  A run of two fixes gets their difference quotient, a lone fix NaN.
    (Differencing across a gap would give the chord over the gap: in a turn, a course tens of
    degrees off at the fixes either side of it.)

    Parameters
    ----------
    t : (M,) float, s, strictly increasing, M >= 2.
    east_m, north_m : (M,) float, m, local east / north (e.g. from
        :func:`navpp.geodesy.geodetic_to_enu` about a fixed origin).
    max_gap_factor : an interval longer than this many median intervals is a gap.

    Returns
    -------
    (M, 2) float, m/s, (v_east, v_north) at ``t``; NaN for a fix alone between two gaps.
    """
    t = np.asarray(t, dtype=float)
    p = np.stack([np.asarray(east_m, dtype=float), np.asarray(north_m, dtype=float)], axis=1)
    if t.shape[0] < 2 or p.shape[0] != t.shape[0]:
        raise ValueError(f"velocity_from_positions: need >= 2 epochs of equal length, got t {t.shape}, "
                         f"positions {p.shape}")
    dt = np.diff(t)
    if not np.all(dt > 0):
        raise ValueError("velocity_from_positions: stamps must be strictly increasing")
    cut = np.nonzero(dt > max_gap_factor * float(np.median(dt)))[0] + 1
    v = np.full_like(p, np.nan)
    for lo, hi in zip(np.concatenate([[0], cut]), np.concatenate([cut, [t.shape[0]]])):
        ts, ps, n = t[lo:hi], p[lo:hi], hi - lo
        if n == 2:
            v[lo:hi] = (ps[1] - ps[0]) / (ts[1] - ts[0])
        if n < 3:
            continue
        h1, h2 = np.diff(ts)[:-1], np.diff(ts)[1:]                  # t_k - t_{k-1}, t_{k+1} - t_k
        v[lo + 1:hi - 1] = ((-h2 / (h1 * (h1 + h2)))[:, None] * ps[:-2]
                            + ((h2 - h1) / (h1 * h2))[:, None] * ps[1:-1]
                            + (h1 / (h2 * (h1 + h2)))[:, None] * ps[2:])
        for k, j1, j2 in ((0, 1, 2), (n - 1, n - 2, n - 3)):        # one-sided, at the epoch itself
            d1, d2 = ts[j1] - ts[k], ts[j2] - ts[k]
            v[lo + k] = (-(d1 + d2) / (d1 * d2) * ps[k] + d2 / (d1 * (d2 - d1)) * ps[j1]
                         - d1 / (d2 * (d2 - d1)) * ps[j2])
    return v


def estimate_clock_offset(
    t_imu: np.ndarray,
    gyro_z_up: np.ndarray,
    t_gnss: np.ndarray,
    vel_en: np.ndarray,
    *,
    max_lag_s: float = 1.0,
    min_speed: float = 2.0,
    baseline_s: float = 1.0,
    lag_step_s: float = 0.05,
    smooth_s: float = 0.25,
    n_blocks: int = 12,
    outlier_sigmas: float = 12.0,
    max_split_sigmas: float = 3.0,
    min_turn_deg: float = 90.0,
    min_correlation: float = 0.7,
    max_sigma_s: float = 0.02,
    up: np.ndarray | None = None,
) -> ClockOffset:
    """Delay of the IMU stamps against the GNSS stamps, from turns.

    The GNSS yaw rate is the rate of the course ``atan2(v_E, v_N)`` (clockwise from north),
    sign-flipped to counter-clockwise (about up, like the gyro): over each GNSS baseline
    ``[a, b]`` (consecutive epochs ``baseline_s`` apart, rounded to whole GNSS intervals,
    consecutive baselines overlapping), ``r_k = -(course(b) - course(a)) / (b - a)`` with the
    course unwrapped.  The gyro is averaged over the same span shifted by the candidate lag,
    through its integral: ``g_k(dt) = (Θ(b + dt) - Θ(a + dt)) / (b - a)``, ``Θ`` the
    integral of ``gyro_z_up`` after a centred moving average over ``smooth_s``, interpolated
    by a cubic spline (a cost smooth in ``dt``).  The moving average (symmetric, so it moves
    no peak) keeps the gyro's sample-to-sample noise -- vibration: several deg/s per sample
    in a car -- from making the cost rough in ``dt``: unsmoothed, each lag step swaps single
    noisy samples in and out at the window ends.  The model is ``r_k = scale * g_k(dt) +
    c`` (scale and constant ``c`` absorb a tilted axis and the gyro bias); ``offset_s``
    maximises the correlation of ``r`` and ``g(dt)`` (equivalently minimises the residual of
    that linear fit) over a grid of ``lag_step_s`` within ``+-max_lag_s``, refined
    continuously (bounded scalar minimisation between the grid neighbours).  Only baselines
    whose every epoch moves faster than ``min_speed`` (m/s, so that the course is defined),
    with no gap inside, and whose shifted span stays inside the IMU data for every lag
    searched are used.  Samples whose residual at the first fit exceeds ``outlier_sigmas``
    robust (MAD) sigmas -- a glitch in the course, e.g. a velocity differenced across a GNSS
    gap -- are dropped and the lag searched again.

    Sign: ``offset_s > 0`` means the IMU stamps are late: ``t_gnss = t_imu - offset_s`` for
    the same physical instant (see :class:`ClockOffset`).

    ``sigma_s`` is a delete-one-block jackknife over ``n_blocks`` contiguous blocks of the
    samples (each block far longer than the residuals' correlation span): model-free, it
    counts the gyro noise that enters the lag through the shifted window's ends, which a
    linearised least-squares sigma misses, and it is not inflated by the telescoping course
    noise of overlapping baselines (docs/ins.md compares the two).

    ``split_sigmas``: the lag is also searched (whole window) on the two halves of the
    samples that hold equal shares of the turning; ``split_sigmas = |lag_1 - lag_2| /
    hypot(sigma_1, sigma_2)``, each half's sigma its own jackknife.  More than
    ``max_split_sigmas`` says the two halves see different delays (or a fit fooled by one
    part of the log): ``consistent`` is False.

    ``confident`` is True when all of: ``turn_deg >= min_turn_deg``, ``correlation >=
    min_correlation``, ``sigma_s <= max_sigma_s``, the peak is not at the edge of the search
    window, ``consistent`` (and at least 40 samples were used, else nothing is estimated).

    Parameters
    ----------
    t_imu : (N,) float, s, strictly increasing IMU stamps.
    gyro_z_up : (N,) float, rad/s, body angular rate projected on the local vertical (up
        positive, i.e. counter-clockwise seen from above).  For a roughly level vehicle the
        body-z (FLU) gyro is adequate: a tilt ``theta`` of that axis scales the yaw rate by
        ``cos(theta)`` (absorbed by ``scale``) and leaks roll/pitch rates and their biases
        (a constant bias is absorbed by ``c``).  For a strongly tilted mount, project with
        the attitude (``(mat_nb @ gyro)[2]``) first.
    t_gnss : (M,) float, s, strictly increasing GNSS stamps on the same nominal time base.
    vel_en : (M, 2) float, m/s, horizontal velocity (east, north) at ``t_gnss`` (an (M, 3)
        ENU array is accepted: the third column is ignored).  From positions, see
        :func:`velocity_from_positions`.
    max_lag_s : s, half-width of the lag search.
    min_speed : m/s, minimal horizontal speed for a course sample.
    baseline_s : s, span of a course-rate sample (low-pass; longer suppresses position
        noise, shorter keeps faster turns).
    lag_step_s : s, grid step of the coarse search.
    smooth_s : s, width of the gyro's centred moving average (0: none).
    n_blocks : number of jackknife blocks for ``sigma_s``.
    outlier_sigmas : residual beyond which a sample is dropped, in robust sigmas.
    max_split_sigmas : the consistency rule above.
    min_turn_deg, min_correlation, max_sigma_s : the confidence rule above.
    up : (3,) unit vector: ``gyro_z_up`` is then the (N, 3) gyro, rad/s, and its rate about ``up``
        is taken block by block (no IMU-length copy, a spilled gyro's pages released behind), as
        ``gyro_z_up @ up`` gives it.

    Returns
    -------
    ClockOffset
    """
    t_imu = np.asarray(t_imu, dtype=float)
    w = np.asarray(gyro_z_up, dtype=float)
    t_g = np.asarray(t_gnss, dtype=float)
    v = np.asarray(vel_en, dtype=float)
    w_shape = t_imu.shape if up is None else (t_imu.shape[0], 3)
    if v.ndim != 2 or v.shape[0] != t_g.shape[0] or v.shape[1] < 2 or w.shape != w_shape:
        raise ValueError(f"estimate_clock_offset: shapes t_imu {t_imu.shape}, gyro_z_up {w.shape}, "
                         f"t_gnss {t_g.shape}, vel_en {v.shape}; expected (N,), {w_shape}, (M,), (M, 2)")
    fine = np.isfinite(t_g) & np.all(np.isfinite(v[:, :2]), axis=1)     # e.g. a lone fix's NaN velocity
    t_g, v = t_g[fine], v[fine]
    if t_g.shape[0] < 3 or t_imu.shape[0] < 3:
        return _failed("too few samples")
    theta_at, t_lo, t_hi = _gyro_angle(t_imu, _vertical_rate(w, up), smooth_s)
    samples = _course_rate_samples(t_g, v, baseline_s, min_speed, max_lag_s, t_lo, t_hi)
    if isinstance(samples, str):
        return _failed(samples)
    a, b, r, m = samples
    n = int(r.shape[0])
    if n < _MIN_SAMPLES:
        return _failed(f"only {n} course-rate samples at speed > {min_speed:g} m/s (need {_MIN_SAMPLES})", n)
    lags = np.arange(-max_lag_s, max_lag_s + 0.5 * lag_step_s, lag_step_s)
    fit = _LagFit(theta_at, a, b, r, lags)
    offset, corr, at_edge = fit.best_lag()
    # glitches in the course (a velocity across a gap, a receiver jump): drop, search again
    g = fit.gyro_mean(offset)
    scale, c0 = np.polyfit(g, r, 1)
    e = r - scale * g - c0
    mad = 1.4826 * float(np.median(np.abs(e - np.median(e))))
    keep = np.abs(e - np.median(e)) <= outlier_sigmas * mad if mad > 0 else np.ones(n, bool)
    n_out = int(n - np.count_nonzero(keep))
    if n_out:
        a, b, r = a[keep], b[keep], r[keep]
        n = int(r.shape[0])
        if n < _MIN_SAMPLES:
            return _failed(f"only {n} course-rate samples left after {n_out} outliers (need {_MIN_SAMPLES})", n)
        fit = _LagFit(theta_at, a, b, r, lags)
        offset, corr, at_edge = fit.best_lag()
        g = fit.gyro_mean(offset)
        scale, c0 = np.polyfit(g, r, 1)
    bias = -c0 / scale if scale != 0 else float("nan")
    # how much turning: the gyro over the samples used, bias removed, each sample weighted
    # by its share of time (overlapping baselines count once: divide by m)
    turn = np.abs(g - bias) * (b - a) / m
    turn_deg = float(np.degrees(np.sum(turn)))

    # the two halves of the turning, each searched over the whole window, each with its own
    # jackknife sigma (the whole log's would grow with their disagreement)
    half = np.cumsum(turn) <= 0.5 * np.sum(turn)
    lag_1, _, _ = fit.best_lag(half)
    lag_2, _, _ = fit.best_lag(~half)
    # the gyro means of every sample at every lag of a fine grid, once: the jackknife's many
    # block-deleted fits are then a few matrix products each (no spline evaluations); only the
    # lags some jackknife looks at (within max_lag_s / 2 of its centre) are evaluated
    grid = np.arange(-max_lag_s, max_lag_s + 0.5 * _JACK_STEP_S, _JACK_STEP_S)
    grid = grid[np.any(np.abs(grid[:, None] - np.array([offset, lag_1, lag_2])) <= 0.5 * max_lag_s, axis=1)]
    table = fit.gyro_means(grid)                                            # (L, n)
    sigma = _jackknife_sigma(grid, table, r, offset, np.ones(n, bool), n_blocks, max_lag_s)
    sig_12 = math.hypot(_jackknife_sigma(grid, table, r, lag_1, half, n_blocks, max_lag_s),
                        _jackknife_sigma(grid, table, r, lag_2, ~half, n_blocks, max_lag_s))
    split = abs(lag_1 - lag_2) / sig_12 if sig_12 > 0 else float("inf")
    consistent = bool(split <= max_split_sigmas)

    checks = []
    if turn_deg < min_turn_deg:
        checks.append(f"turn {turn_deg:.0f} deg < {min_turn_deg:g}")
    if corr < min_correlation:
        checks.append(f"correlation {corr:.2f} < {min_correlation:g}")
    if not sigma <= max_sigma_s:
        checks.append(f"sigma {sigma * 1e3:.1f} ms > {max_sigma_s * 1e3:g}")
    if at_edge:
        checks.append(f"peak at the search edge (+-{max_lag_s:g} s)")
    if not consistent:
        checks.append(f"the two halves of the turns disagree: {lag_1 * 1e3:+.0f} vs {lag_2 * 1e3:+.0f} ms "
                      f"({split:.1f} sigma)")
    summary = (f"offset {offset * 1e3:+.1f} +- {sigma * 1e3:.1f} ms (IMU late if > 0), corr {corr:.3f}, "
               f"{n} samples" + (f" ({n_out} outliers dropped)" if n_out else "") + f", turn {turn_deg:.0f} deg, "
               f"halves {lag_1 * 1e3:+.0f} / {lag_2 * 1e3:+.0f} ms")
    confident = not checks
    reason = summary + ("" if confident else ": not confident: " + "; ".join(checks))
    return ClockOffset(offset_s=offset, sigma_s=sigma, correlation=corr, n_samples=n,
                       turn_deg=turn_deg, scale=float(scale), bias_rad_s=float(bias),
                       at_edge=bool(at_edge), confident=bool(confident), reason=reason,
                       consistent=consistent, split_sigmas=float(split), n_outliers=n_out)


def _failed(reason: str, n_used: int = 0) -> ClockOffset:
    """A :class:`ClockOffset` that estimates nothing (NaN figures), saying why."""
    nan = float("nan")
    return ClockOffset(nan, nan, nan, n_used, nan, nan, nan, False, False, reason)


#: ``theta_at(t)``: the integral of the (smoothed) vertical gyro rate at times ``t`` (s), rad
AngleAt = Callable[[np.ndarray], np.ndarray]


def _spline(x: np.ndarray | _Grid, y: np.ndarray) -> AngleAt:
    """``scipy.interpolate.CubicSpline(x, y, extrapolate=False)`` (not-a-knot ends) for (N,) float
    ``x`` (strictly increasing) and ``y``, its values to the bit: the first derivatives at ``x``
    from the same tridiagonal system and solver (LAPACK ``gtsv``, as ``solve_banded`` calls it),
    solved a block of :data:`BLOCK_ROWS` rows at a time (:func:`_spline_derivatives`); the
    interpolant (:class:`Cubic`) keeps ``x`` and ``y`` themselves (not copies) and the derivatives,
    and forms the coefficients of the intervals it evaluates.  Fewer than 4 points: CubicSpline."""
    n = x.shape[0]
    spline: AngleAt
    if n < 4:
        from scipy import interpolate

        spline = interpolate.CubicSpline(x, y, extrapolate=False)
        return spline
    xs = x if isinstance(x, np.ndarray) else None  # (a _Grid holds no rows)
    for lo in range(0, n, BLOCK_ROWS):             # block by block: no IMU-length temporaries
        xb, yb = x[lo:lo + BLOCK_ROWS + 1], y[lo:lo + BLOCK_ROWS]
        if not (np.all(np.isfinite(xb)) and np.all(np.isfinite(yb))):
            raise ValueError("_spline: x and y must be finite")
        if not np.all(xb[1:] > xb[:-1]):
            raise ValueError("_spline: x must be strictly increasing")
        release((xs, y), lo, lo + BLOCK_ROWS)
    return Cubic(x, y, _spline_derivatives(x, y))


#: Rows solved on either side of a block of the spline's system and dropped: a row's influence
#: on its neighbours shrinks at least twofold per row (the system is diagonally dominant by a
#: factor of 2), so 2**-128 of a derivative, far below its last bit, reaches across them.
SPLINE_MARGIN_ROWS = 128


def _spline_derivatives(x: np.ndarray | _Grid, y: np.ndarray) -> np.ndarray:
    """The first derivatives (N,) at ``x`` (N >= 4, strictly increasing) of the not-a-knot cubic
    spline through ``y``, block by block: each block's rows solved with
    :data:`SPLINE_MARGIN_ROWS` more on either side (the rows beyond left out), the margins
    dropped.  The margins' solves start and end elsewhere than the whole system's, but what that
    changes dies out across them: the derivatives are the whole solve's (checked to the bit in
    tests/test_prep_blocks.py), without its IMU-length diagonals and right-hand side."""
    from ..scipy_parts import extension

    n = x.shape[0]
    d = like(y, n, (), np.float64)          # spilled as y is: rows released behind the solve
    xs = x if isinstance(x, np.ndarray) else None
    try:
        gtsv = extension("scipy.linalg._flapack").dgtsv     # get_lapack_funcs("gtsv") for float64
    except (ImportError, AttributeError):                   # a scipy laid out otherwise: its public way
        from scipy.linalg import get_lapack_funcs

        gtsv = get_lapack_funcs("gtsv", (np.empty(0), np.empty((0, 1))))
    for lo in range(0, n, BLOCK_ROWS):
        hi = min(lo + BLOCK_ROWS, n)
        a, b = max(lo - SPLINE_MARGIN_ROWS, 0), min(hi + SPLINE_MARGIN_ROWS, n)
        lower, main, upper, rhs = _spline_rows(x, y, a, b)
        sol, info = gtsv(lower, main, upper, rhs, True, True, True, True)[3:]     # (b - a, 1), int
        if info != 0:
            raise ValueError(f"_spline: the tridiagonal solve failed (info {info})")
        d[lo:hi] = sol[lo - a:hi - a, 0]
        release((xs, y, d), max(lo - BLOCK_ROWS - SPLINE_MARGIN_ROWS, 0), a)
    release_all(xs, y, d)
    return d


def _spline_rows(x: np.ndarray | _Grid, y: np.ndarray, a: int, b: int) -> tuple[np.ndarray, ...]:
    """Rows ``a .. b - 1`` of the not-a-knot spline's system for the first derivatives ``d`` at
    ``x`` (N,) through ``y`` (N,), as ``gtsv`` takes them: (lower (b-a-1), main (b-a), upper
    (b-a-1), right-hand side (b-a, 1)); their couplings to rows outside are left out.  Row k
    (0 < k < N - 1): ``dx[k] d[k-1] + 2 (dx[k-1] + dx[k]) d[k] + dx[k-1] d[k+1] = 3 (dx[k]
    slope[k-1] + dx[k-1] slope[k])``, ``dx`` and ``slope`` the intervals' widths and chord slopes;
    rows 0 and N - 1: the third derivative continuous across x[1] and x[N-2]."""
    n = x.shape[0]
    lower, main, upper = np.empty(b - a - 1), np.empty(b - a), np.empty(b - a - 1)
    rhs = np.empty((b - a, 1))
    lo, hi = max(a, 1), min(b, n - 1)               # the inner rows
    h = x[lo:hi + 1] - x[lo - 1:hi]                 # dx[lo - 1:hi]
    m = y[lo:hi + 1] - y[lo - 1:hi]
    m /= h                                          # slope[lo - 1:hi]
    main[lo - a:hi - a] = 2 * (h[:-1] + h[1:])
    rhs[lo - a:hi - a, 0] = 3 * (h[1:] * m[:-1] + h[:-1] * m[1:])
    top = min(hi, b - 1)                            # inner rows with an upper coupling inside
    upper[lo - a:top - a] = h[:top - lo]
    first = max(lo, a + 1)                          # ... with a lower coupling inside
    lower[first - a - 1:hi - a - 1] = h[first - lo + 1:]
    if a == 0:
        h0, h1 = x[1] - x[0], x[2] - x[1]
        main[0] = h1
        upper[0] = w = x[2] - x[0]
        rhs[0] = ((h0 + 2 * w) * h1 * ((y[1] - y[0]) / h0) + h0 ** 2 * ((y[2] - y[1]) / h1)) / w
    if b == n:
        g1, g0 = x[-2] - x[-3], x[-1] - x[-2]
        main[-1] = g1
        lower[-1] = w = x[-1] - x[-3]
        rhs[-1] = (g0 ** 2 * ((y[-2] - y[-3]) / g1) + (2 * w + g0) * g1 * ((y[-1] - y[-2]) / g0)) / w
    return lower, main, upper, rhs


#: No shift at all: :func:`_cubic_means` evaluates the spline itself.
_NO_LAGS = np.zeros(0)


class Cubic:
    """The piecewise cubic Hermite interpolant over the breakpoints ``x`` (N,) s, strictly
    increasing, of the values ``y`` (N,) and first derivatives ``d`` (N,) at them (the last
    interval closed): ``scipy.interpolate.PPoly`` of the coefficients CubicSpline forms from
    them, its values to the bit (NaN outside ``[x[0], x[-1]]``), without importing
    scipy.interpolate and without an (4, N - 1) coefficient array: each evaluation forms the
    coefficients of the intervals it needs with the same operations."""

    #: steps of one interval from the first guess before the binary search takes over
    STEPS = 3

    def __init__(self, x: np.ndarray | _Grid, y: np.ndarray, d: np.ndarray) -> None:
        self.x = x
        self.y = y
        self.d = d

    def interval(self, t: np.ndarray) -> np.ndarray:
        """The interval ``i`` (as ``t``, intp) with ``x[i] <= t < x[i + 1]``, clipped to
        ``[0, N - 2]`` (so ``t == x[-1]`` is in the last one; NaN anywhere): a binary search's
        answer.  First guessed from ``t``'s offset at the mean breakpoint spacing and stepped
        towards it (a grid, an IMU's stamps: there in a step or two); the times still off after
        :attr:`STEPS` steps (after a gap in the stamps) are searched."""
        x = self.x
        last = x.shape[0] - 2
        guess = (t - x[0]) * ((last + 1) / (x[-1] - x[0]))
        np.fmax(guess, 0.0, out=guess)                 # NaN -> 0
        np.fmin(guess, last, out=guess)
        i: np.ndarray = guess.astype(np.intp)
        for _ in range(self.STEPS):
            down = (t < x[i]) & (i > 0)
            up = (t >= x[i + 1]) & (i < last)
            if not (down.any() or up.any()):
                return i
            i -= down
            i += up
        off = ((t < x[i]) & (i > 0)) | ((t >= x[i + 1]) & (i < last))
        if off.any():
            found = x.searchsorted(t[off], side="right")
            found -= 1
            i[off] = np.clip(found, 0, last)
        return i

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """The values at the times ``t`` (an array, any shape), evaluated as scipy's
        ``evaluate_poly1`` does: ``c3 + c2 s + c1 (s s) + c0 ((s s) s)`` summed in that order,
        ``s = t - x[i]``, ``i`` the interval holding ``t``, with CubicSpline's coefficients of
        that interval: ``c3 = y[i]``, ``c2 = d[i]``, ``c1 = (m - d[i]) / h - q``, ``c0 = q / h``,
        ``h`` its width, ``m`` its chord slope, ``q = (d[i] + d[i + 1] - 2 m) / h``."""
        t = np.asarray(t, dtype=float)
        if t.ndim == 0:
            return self(t[None]).reshape(())
        flat = np.ascontiguousarray(t).reshape(-1)
        out = np.empty((1, flat.shape[0]))
        _cubic_means(*self._kernel_args(), flat, flat, _NO_LAGS, out)
        return out.reshape(t.shape)

    def _kernel_args(self) -> tuple[np.ndarray, bool, float, float, int, np.ndarray, np.ndarray]:
        """The breakpoints, values and derivatives as the kernels (:func:`_cubic_at`) take them."""
        x = self.x
        xs = np.empty(0) if isinstance(x, _Grid) else np.asarray(x, dtype=float)
        start, step = (x.start, x.step) if isinstance(x, _Grid) else (0.0, 0.0)
        return (xs, isinstance(x, _Grid), float(start), float(step), int(x.shape[0]), np.asarray(self.y, dtype=float),
                np.asarray(self.d, dtype=float))

    def means(self, a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
        """``(self(b + lags[:, None]) - self(a + lags[:, None])) / (b - a)``, (L, K) for the spans
        ``a``, ``b`` (K,) s and the shifts ``lags`` (L,) s: the same bits, without the (L, K)
        temporaries."""
        out = np.empty((lags.shape[0], a.shape[0]))
        _cubic_means(*self._kernel_args(), np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float),
                     np.ascontiguousarray(lags, dtype=float), out)
        return out


@njit(cache=True)
def _grid_row(grid: bool, xs: np.ndarray, start: float, delta: float, step: float, k: int) -> float:
    """Row ``k`` of the breakpoints: ``xs[k]``, or of ``np.arange(start, ..., step)`` (the bits of
    :func:`_arange_rows`)."""
    if not grid:
        return float(xs[k])
    if k == 0:
        return start
    if k == 1:
        return start + step
    return float(k) * delta + start


@njit(cache=True)
def _cubic_interval(xs: np.ndarray, grid: bool, start: float, delta: float, step: float, last: int, x0: float,
                    scale: float, tk: float) -> int:
    """The interval ``i`` with ``x[i] <= tk < x[i + 1]`` (clipped to ``[0, last]``) of a time ``tk``
    inside the breakpoints (:func:`_cubic_at`'s arguments): guessed from its offset, stepped."""
    g = (tk - x0) * scale
    i = min(int(g), last) if g > 0.0 else 0
    xi = _grid_row(grid, xs, start, delta, step, i)
    xj = _grid_row(grid, xs, start, delta, step, i + 1)
    while tk < xi and i > 0:
        i -= 1
        xj = xi
        xi = _grid_row(grid, xs, start, delta, step, i)
    while tk >= xj and i < last:
        i += 1
        xi = xj
        xj = _grid_row(grid, xs, start, delta, step, i + 1)
    return i


@njit(cache=True, inline="always")
def _cubic_coefficients(xs: np.ndarray, grid: bool, start: float, delta: float, step: float, y: np.ndarray,
                        d: np.ndarray, i: int) -> tuple[float, float, float, float, float]:
    """The breakpoint ``x[i]`` and CubicSpline's coefficients ``c3, c2, c1, c0`` of interval ``i``,
    formed as :meth:`Cubic.__call__` forms them."""
    xi = _grid_row(grid, xs, start, delta, step, i)
    xj = _grid_row(grid, xs, start, delta, step, i + 1)
    h = xj - xi
    m = y[i + 1] - y[i]
    m /= h
    d0 = d[i]
    q = d0 + d[i + 1]
    q -= 2 * m
    q /= h
    m -= d0
    m /= h
    m -= q
    q /= h
    return xi, y[i], d0, m, q


@njit(cache=True, inline="always")
def _cubic_sum(xi: float, c3: float, c2: float, c1: float, c0: float, tk: float) -> float:
    """The interval's polynomial at ``tk``, summed as scipy's ``evaluate_poly1``."""
    s = tk - xi
    z = s * s
    v = c3 + 0.0
    v += c2 * s
    v += c1 * z
    z *= s
    v += c0 * z
    return v


@njit(cache=True)
def _cubic_at(xs: np.ndarray, grid: bool, start: float, delta: float, step: float, last: int, x0: float,
              xn: float, scale: float, y: np.ndarray, d: np.ndarray, tk: float) -> float:
    """:meth:`Cubic.__call__` at one time ``tk``, the same operations in the same order: the
    breakpoints ``xs`` (N,), or (``grid``) the rows of ``np.arange(start, ..., step)``
    (:class:`_Grid`, ``delta`` its row spacing); ``last`` N - 2, ``x0`` and ``xn`` the first and
    last breakpoints, ``scale`` (N - 1) / (xn - x0)."""
    if not (tk >= x0 and tk <= xn):
        return np.nan
    i = _cubic_interval(xs, grid, start, delta, step, last, x0, scale, tk)
    xi, c3, c2, c1, c0 = _cubic_coefficients(xs, grid, start, delta, step, y, d, i)
    return _cubic_sum(xi, c3, c2, c1, c0, tk)


@njit(cache=True)
def _cubic_means(xs: np.ndarray, grid: bool, start: float, step: float, n: int, y: np.ndarray,
                 d: np.ndarray, a: np.ndarray, b: np.ndarray, lags: np.ndarray, out: np.ndarray) -> None:
    """:meth:`Cubic.means`: ``out[j, k] = (f(b[k] + lags[j]) - f(a[k] + lags[j])) / (b[k] - a[k])``,
    ``f`` the spline over the breakpoints ``xs`` (N,) or (``grid``) the ``n`` rows of a :class:`_Grid`
    (:func:`_cubic_at`); no ``lags`` at all: the values ``out[0, k] = f(a[k])`` (:meth:`Cubic.__call__`),
    ``b`` unused (one kernel for both: each cached kernel costs a run some milliseconds to load)."""
    delta = (start + step) - start
    x0 = _grid_row(grid, xs, start, delta, step, 0)
    xn = _grid_row(grid, xs, start, delta, step, n - 1)
    scale = (n - 1) / (xn - x0)
    last = n - 2
    if lags.shape[0] == 0:
        for k in range(a.shape[0]):
            out[0, k] = _cubic_at(xs, grid, start, delta, step, last, x0, xn, scale, y, d, a[k])
        return
    for k in range(a.shape[0]):
        # sample by sample, the lags in turn: successive lags mostly fall in the interval of the
        # previous one, whose coefficients are kept (one set per span end)
        ia, ib = -1, -1
        xa, a3, a2, a1, a0 = 0.0, 0.0, 0.0, 0.0, 0.0
        xb, b3, b2, b1, b0 = 0.0, 0.0, 0.0, 0.0, 0.0
        width = b[k] - a[k]
        for j in range(lags.shape[0]):
            ta, tb = a[k] + lags[j], b[k] + lags[j]
            fa, fb = np.nan, np.nan
            if ta >= x0 and ta <= xn:
                i = _cubic_interval(xs, grid, start, delta, step, last, x0, scale, ta)
                if i != ia:
                    ia = i
                    xa, a3, a2, a1, a0 = _cubic_coefficients(xs, grid, start, delta, step, y, d, i)
                fa = _cubic_sum(xa, a3, a2, a1, a0, ta)
            if tb >= x0 and tb <= xn:
                i = _cubic_interval(xs, grid, start, delta, step, last, x0, scale, tb)
                if i != ib:
                    ib = i
                    xb, b3, b2, b1, b0 = _cubic_coefficients(xs, grid, start, delta, step, y, d, i)
                fb = _cubic_sum(xb, b3, b2, b1, b0, tb)
            out[j, k] = (fb - fa) / width


#: One shift of nothing, s: :meth:`Cubic.means` of the spans themselves.
_NO_SHIFT = np.zeros(1)


def _gyro_angle(t_imu: np.ndarray, rate: Callable[[int, int], np.ndarray],
                smooth_s: float) -> tuple[AngleAt, float, float]:
    """The integral of the vertical rate (rad/s at ``t_imu``, its rows ``lo:hi`` from ``rate(lo,
    hi)``, :func:`_vertical_rate`) as a C2 interpolant, after a centred moving average over
    ``smooth_s`` s (0: none), with the span (s) it covers.

    A C2 interpolant: with linear interpolation the lag search's cost has kinks at every lag
    that aligns the GNSS stamps with IMU stamps, and the minimum sticks to them.  The rate, the
    moving average and the average's grid are formed block by block, and the raw integral's
    spline is freed (a spilled ``t_imu``'s pages released) before the grid of the smoothed one
    is built: at most four IMU-length arrays at a time (the stamps, the raw spline's angle and
    derivatives, the average's integral)."""
    theta_at = _spline(t_imu, trapezoid_integral(t_imu, rate, t_imu.shape[0]))
    t_lo, t_hi = float(t_imu[0]), float(t_imu[-1])
    if smooth_s > 0.0 and t_hi - t_lo > 4.0 * smooth_s:
        # the centred moving average, on a uniform grid at the IMU's median step; its integral
        step = interval_median(t_imu)
        start, stop = t_lo + 0.5 * smooth_s, t_hi - 0.5 * smooth_s

        raw = theta_at
        behind = Behind(t_imu, *((raw.y, raw.d) if isinstance(raw, Cubic) else ()))

        def averaged(lo: int, hi: int) -> np.ndarray:
            """Rows ``lo:hi`` of the moving average on the grid, rad/s (the raw spline's spilled
            rows released behind it)."""
            g = _arange_rows(start, step, lo, hi)
            a = np.clip(g - 0.5 * smooth_s, t_lo, t_hi)
            b = np.clip(g + 0.5 * smooth_s, t_lo, t_hi)
            # the same bits as the expression below (a span end of -0.0 shifted by +0.0 gives its value)
            mean: np.ndarray = (raw.means(a, b, _NO_SHIFT)[0] if isinstance(raw, Cubic)
                                else (raw(b) - raw(a)) / (b - a))
            behind(float(a[0]) - smooth_s)
            return mean

        n_grid = _arange_length(start, stop, step)
        phi = trapezoid_integral(step, averaged, n_grid)
        del theta_at, raw, behind
        release_all(t_imu)
        grid = _Grid(start, step, n_grid)
        theta_at = _spline(grid, phi)
        t_lo, t_hi = float(grid[0]), float(grid[-1])
    return theta_at, t_lo, t_hi


def _arange_length(start: float, stop: float, step: float) -> int:
    """The length of ``np.arange(start, stop, step)`` (float, ``step`` > 0)."""
    return max(math.ceil((stop - start) / step), 0)


def _arange_rows(start: float, step: float, lo: int, hi: int) -> np.ndarray:
    """Rows ``lo:hi`` of ``np.arange(start, stop, step)`` (float), the same bits without the
    whole array: numpy fills row ``i >= 2`` with ``start + i * delta``, ``delta = (start + step)
    - start``, row 1 with ``start + step`` and row 0 with ``start`` (tests/test_prep_blocks.py
    checks it against numpy)."""
    rows = np.arange(lo, hi, dtype=float)
    rows *= (start + step) - start
    rows += start
    if lo <= 1 < hi:
        rows[1 - lo] = start + step
    if lo == 0 < hi:
        rows[0] = start
    return rows


class _Grid:
    """``np.arange(start, stop, step)`` (float, ``n`` rows) without the array, as :func:`_spline`
    and :class:`Cubic` read their breakpoints: a slice, a row or rows by index (an int array) are
    formed when read, the same bits (:func:`_arange_rows`); ``searchsorted`` as the array's."""

    def __init__(self, start: float, step: float, n: int) -> None:
        self.start, self.step, self.shape = start, step, (n,)

    def __getitem__(self, k: Any) -> Any:
        n = self.shape[0]
        if isinstance(k, slice):
            lo, hi, stride = k.indices(n)
            assert stride == 1, "_Grid: a slice with a step"
            return _arange_rows(self.start, self.step, lo, max(hi, lo))
        if isinstance(k, (int, np.integer)):
            row = int(k) + n if k < 0 else int(k)
            if not 0 <= row < n:
                raise IndexError(f"_Grid: row {k} of {n}")
            return _arange_rows(self.start, self.step, row, row + 1)[0]
        idx = np.asarray(k)
        rows = idx.astype(float)
        rows *= (self.start + self.step) - self.start
        rows += self.start
        rows[idx == 1] = self.start + self.step
        rows[idx == 0] = self.start
        return rows

    def searchsorted(self, v: np.ndarray, side: Literal["left", "right"] = "left") -> np.ndarray:
        """``np.searchsorted(grid, v, side)``, the rows formed :data:`BLOCK_ROWS` at a time."""
        n = self.shape[0]
        found = np.zeros(np.shape(v), dtype=np.intp)
        for lo in range(0, n, BLOCK_ROWS):
            found += np.searchsorted(self[lo:lo + BLOCK_ROWS], v, side=side)
        return found


def _vertical_rate(gyro: np.ndarray, up: np.ndarray | None) -> Callable[[int, int], np.ndarray]:
    """``rate(lo, hi)``: rows ``lo:hi`` of the rate about ``up``, rad/s: ``gyro`` (N, 3) rad/s
    ``@ up`` (3,) (the same bits as the whole product), the rows of a spilled ``gyro`` released
    once read (:func:`navpp.spill.release`); ``up`` None: ``gyro`` (N,) is that rate."""
    if up is None:
        return lambda lo, hi: gyro[lo:hi]

    def rate(lo: int, hi: int) -> np.ndarray:
        w: np.ndarray = gyro[lo:hi] @ up
        release((gyro,), lo, hi)
        return w
    return rate


def _course_rate_samples(t_g: np.ndarray, v: np.ndarray, baseline_s: float, min_speed: float, max_lag_s: float,
                         t_lo: float, t_hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | str:
    """GNSS yaw-rate samples over baselines of ``m`` epochs (about ``baseline_s``): their starts
    ``a``, ends ``b`` (s) and counter-clockwise course rates ``r`` (rad/s), and ``m``; or why
    there are none.  A baseline is used when every epoch of it moves faster than ``min_speed``
    (m/s), it holds no gap and no course jump beyond pi/2 between epochs, and it stays inside the
    gyro span [t_lo, t_hi] shifted by any lag within ``+-max_lag_s``; beyond :data:`MAX_SAMPLES`
    they are thinned evenly."""
    dt_med = float(np.median(np.diff(t_g)))
    m = max(1, int(round(baseline_s / dt_med)))
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.unwrap(np.arctan2(v[:, 0], v[:, 1]))
    if t_g.shape[0] <= m:
        return "fewer GNSS epochs than one baseline"
    a, b = t_g[:-m], t_g[m:]
    # every epoch of the baseline fast enough: a sliding minimum over m + 1 epochs
    fast = speed > min_speed
    run = np.convolve(fast.astype(int), np.ones(m + 1, dtype=int), mode="valid") == m + 1
    ok = (run
          & (b - a <= 1.5 * m * dt_med)                       # no gap inside the baseline
          & (a - max_lag_s >= t_lo) & (b + max_lag_s <= t_hi))
    # a course jump of more than pi between epochs is not a turn the unwrap can resolve
    step = np.abs(np.diff(course))
    big = np.convolve((step > 0.5 * np.pi).astype(int), np.ones(m, dtype=int), mode="valid") > 0
    ok &= ~big
    r = -(course[m:] - course[:-m]) / (b - a)
    a, b, r = a[ok], b[ok], r[ok]
    if r.shape[0] > MAX_SAMPLES:
        # overlapping baselines repeat each other: every k-th loses little (a long log's search
        # would otherwise cost seconds of spline evaluations per lag)
        k = -(-r.shape[0] // MAX_SAMPLES)
        a, b, r = a[::k], b[::k], r[::k]
    return a, b, r, m


@dataclass(frozen=True)
class _LagFit:
    """The lag search over the course-rate samples ``(a, b, r)`` (:func:`_course_rate_samples`)
    against the gyro angle ``theta_at`` (:func:`_gyro_angle`), on the grid ``lags`` (s)."""

    theta_at: AngleAt
    a: np.ndarray
    b: np.ndarray
    r: np.ndarray
    lags: np.ndarray

    def gyro_mean(self, dt: float, sel: slice | np.ndarray = slice(None)) -> np.ndarray:
        """The gyro's mean rate over each baseline shifted by ``dt`` s, rad/s."""
        aa, bb = self.a[sel], self.b[sel]
        if isinstance(self.theta_at, Cubic):
            shifted: np.ndarray = self.theta_at.means(aa, bb, np.array([dt], dtype=float))[0]
            return shifted
        mean: np.ndarray = (self.theta_at(bb + dt) - self.theta_at(aa + dt)) / (bb - aa)
        return mean

    def gyro_means(self, lags: np.ndarray) -> np.ndarray:
        """:meth:`gyro_mean` of every baseline at each of ``lags`` (L,) s: (L, n) rad/s, the
        same bits, evaluated for as many lags at a time as a block holds."""
        n = self.r.shape[0]
        if isinstance(self.theta_at, Cubic):
            return self.theta_at.means(self.a, self.b, lags)
        out = np.empty((lags.shape[0], n))
        step = max(1, BLOCK_ROWS // max(n, 1))
        for lo in range(0, lags.shape[0], step):
            d = lags[lo:lo + step, None]
            out[lo:lo + step] = (self.theta_at(self.b + d) - self.theta_at(self.a + d)) / (self.b - self.a)
        return out

    @cached_property
    def coarse(self) -> np.ndarray:
        """:meth:`gyro_means` at the grid ``lags``, (L, n) rad/s: every :meth:`best_lag` starts from it."""
        return self.gyro_means(self.lags)

    def neg_corr(self, dt: float, sel: slice | np.ndarray = slice(None)) -> float:
        """Minus the correlation of the course rates with the gyro means at lag ``dt``."""
        return _neg_corr(self.gyro_mean(dt, sel), self.r[sel])

    def best_lag(self, sel: slice | np.ndarray = slice(None)) -> tuple[float, float, bool]:
        """(lag s, correlation, at the grid's edge) maximising the correlation over the samples
        ``sel``: the grid's best point refined between its neighbours (bounded minimisation)."""
        lags = self.lags
        rr = self.r[sel]
        costs = np.array([_neg_corr(g[sel], rr) for g in self.coarse])
        i = int(np.argmin(costs))
        lo, hi = lags[max(i - 1, 0)], lags[min(i + 1, lags.shape[0] - 1)]
        x, fx = _golden_section_min(lambda d: self.neg_corr(d, sel), float(lo), float(hi), LAG_TOL_S)
        d, c = (x, fx) if fx <= costs[i] else (float(lags[i]), float(costs[i]))
        edge = i == 0 or i == lags.shape[0] - 1
        return d, -c, edge


#: The lag refinement's tolerance, s: far below any lag's 1-sigma (a few ms on a good log).
LAG_TOL_S = 1e-5
#: The golden ratio's reciprocal, (sqrt(5) - 1) / 2: the share of a bracket its inner points keep.
_GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


def _golden_section_min(f: Callable[[float], float], lo: float, hi: float, tol: float) -> tuple[float, float]:
    """(x, f(x)): the smallest value of ``f`` found on ``[lo, hi]`` by golden-section search, the
    bracket narrowed until it is at most ``tol`` wide (for an ``f`` with one minimum on the
    interval, ``x`` is within ``tol`` of it; at an end when ``f`` is monotonic there).

    Two inner points split the bracket in the golden ratio; the side beyond the worse of them
    cannot hold the minimum and goes, and the better one is an inner point of the narrower
    bracket, so each step costs one evaluation and keeps 0.618 of the width: about
    ``log(tol / (hi - lo)) / log(0.618)`` evaluations (20 for a 0.1 s bracket to 10 us)."""
    a, b = lo, hi
    x1, x2 = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
    f1, f2 = f(x1), f(x2)
    while b - a > tol:
        if f1 <= f2:        # the minimum is left of x2
            b, x2, f2 = x2, x1, f1
            x1 = b - _GOLDEN * (b - a)
            f1 = f(x1)
        else:               # ... right of x1
            a, x1, f1 = x1, x2, f2
            x2 = a + _GOLDEN * (b - a)
            f2 = f(x2)
    return (x1, f1) if f1 <= f2 else (x2, f2)


def _neg_corr(g: np.ndarray, r: np.ndarray) -> float:
    """Minus the correlation of the course rates ``r`` (n,) with the gyro means ``g`` (n,)."""
    gs, rs = g - g.mean(), r - r.mean()
    den = np.sqrt(np.dot(gs, gs) * np.dot(rs, rs))
    return -float(np.dot(gs, rs) / den) if den > 0 else 0.0


_MIN_SAMPLES = 40
#: At most this many course-rate samples enter the lag search (evenly thinned beyond).
MAX_SAMPLES = 2000
#: Lag grid of the jackknife's block-deleted fits, s.
_JACK_STEP_S = 0.005


def _jackknife_sigma(grid: np.ndarray, table: np.ndarray, r: np.ndarray, offset: float, use: np.ndarray,
                     n_blocks: int, max_lag_s: float) -> float:
    """Delete-one-block jackknife 1-sigma of the lag fitted on the samples ``use`` (bool mask).

    ``table`` (L, n) holds every sample's gyro mean at each lag of ``grid`` (L,) and ``r`` (n,)
    the GNSS yaw rates; the blocks are contiguous runs of the used samples; each block-deleted
    lag maximises the correlation over the grid points within ``+-max_lag_s / 2`` of ``offset``
    (a lag far off is a large deviation either way), refined by a parabola through the best grid
    point and its neighbours."""
    idx = np.nonzero(use)[0]
    k = int(min(max(n_blocks, 2), idx.shape[0] // 4))
    if k < 2:
        return float("nan")
    near = np.flatnonzero(np.abs(grid - offset) <= 0.5 * max_lag_s)    # one run of the increasing grid
    if near.shape[0] < 3:
        return float("nan")
    lg, T = grid[near[0]:near[-1] + 1], table[near[0]:near[-1] + 1]     # views: the table is not copied
    edges = np.linspace(0, idx.shape[0], k + 1).round().astype(int)
    step = float(lg[1] - lg[0])
    lags = np.empty(k)
    for i in range(k):
        sel = use.copy()
        sel[idx[edges[i]:edges[i + 1]]] = False
        gs, rr = T[:, sel], r[sel]
        gs -= gs.mean(axis=1, keepdims=True)        # in place: one (L, n) copy per block, not two
        rs = rr - rr.mean()
        den = np.sqrt(np.einsum("ij,ij->i", gs, gs) * float(rs @ rs))
        corr = np.where(den > 0.0, (gs @ rs) / np.where(den > 0.0, den, 1.0), -np.inf)
        j = int(np.argmax(corr))
        lag = float(lg[j])
        if 0 < j < lg.shape[0] - 1:
            c0, c1, c2 = corr[j - 1], corr[j], corr[j + 1]
            curv = c0 - 2.0 * c1 + c2
            if curv < 0.0:
                lag += step * 0.5 * (c0 - c2) / curv
        lags[i] = lag
    return float(np.sqrt((k - 1) / k * np.sum((lags - lags.mean()) ** 2)))


# --------------------------------------------------------------------------------------------
# Gyro scale against the GNSS track
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class YawScale:
    """Result of :func:`yaw_scale_from_track`.

    Attributes
    ----------
    scale : float, GNSS turn / gyro turn (slope of the fit with a constant for the bias);
        1 for a vertical gyro axis in rad/s, 1/57.3 for one in deg/s read as rad/s. NaN when
        there are fewer than 5 chord pairs.
    correlation : float, correlation coefficient of the two turns.
    gnss_turn_deg : float, deg, sum of |GNSS turn| over the pairs used.
    n_pairs : int.
    """

    scale: float
    correlation: float
    gnss_turn_deg: float
    n_pairs: int


def yaw_scale_from_track(t_imu: np.ndarray, gyro_z_up: np.ndarray, t_gnss: np.ndarray,
                         east_m: np.ndarray, north_m: np.ndarray, std_h_m: np.ndarray | float = 0.0,
                         *, window_s: float = 4.0, min_chord_m: float = 5.0, up: np.ndarray | None = None
                         ) -> YawScale:
    """How the gyro's turns compare with the GNSS track's.

    The track is cut into consecutive, non-overlapping chords of about ``window_s`` (from one
    GNSS epoch to the first at least ``window_s`` later); a chord's course ``atan2(dE, dN)`` is
    the heading at its middle for a steady turn, and its error is about ``sigma_h / length``
    rad, so chords shorter than ``max(min_chord_m, 20 sigma_h)`` or spanning a gap are dropped.
    For each pair of adjacent chords, the GNSS turn (course change, counter-clockwise positive,
    wrapped to +-pi) is compared with the gyro's turn between the two middles (trapezoidal
    integral of ``gyro_z_up``); the fit ``gnss = scale * gyro + c`` absorbs a constant bias.

    Parameters
    ----------
    t_imu : (N,) s, increasing; gyro_z_up : (N,) rad/s about the local vertical (up, CCW).
    t_gnss : (M,) s, increasing, the same time base; east_m, north_m : (M,) m, local ENU.
    std_h_m : scalar or (M,) m, horizontal 1-sigma per fix (0: unknown, ``min_chord_m`` rules).
    up : (3,) unit vector: ``gyro_z_up`` is then the (N, 3) gyro, rad/s, and its rate about ``up``
        is taken block by block (no IMU-length copy, a spilled gyro's pages released behind), as
        ``gyro_z_up @ up`` gives it.
    """
    nan = float("nan")
    t_imu = np.asarray(t_imu, dtype=float)
    gyro = np.asarray(gyro_z_up, dtype=float)
    rate = _vertical_rate(gyro, up)
    t_g = np.asarray(t_gnss, dtype=float)
    e, nn = np.asarray(east_m, dtype=float), np.asarray(north_m, dtype=float)
    if t_g.shape[0] < 4 or t_imu.shape[0] < 4:
        return YawScale(nan, nan, 0.0, 0)
    sig = np.broadcast_to(np.nan_to_num(np.asarray(std_h_m, dtype=float), nan=0.0), t_g.shape)
    dt_med = float(np.median(np.diff(t_g)))
    gap = np.concatenate([[0], np.cumsum(np.diff(t_g) > 3.0 * dt_med)])   # gap count up to each epoch
    starts = []
    i = 0
    m = t_g.shape[0]
    ends = np.searchsorted(t_g, t_g + window_s - 1e-9).tolist()        # each epoch's chord end
    while i < m - 1:
        j = ends[i]
        if j >= m:
            break
        starts.append((i, j))
        i = j
    if len(starts) < 2:
        return YawScale(nan, nan, 0.0, 0)
    ii, jj = np.array(starts, dtype=np.intp).T           # each chord's first and last epoch
    de, dn = e[jj] - e[ii], nn[jj] - nn[ii]
    need = np.maximum(min_chord_m, 20.0 * np.maximum(sig[ii], sig[jj]))
    ok_a = (gap[jj] == gap[ii]) & (np.hypot(de, dn) >= need) & (t_g[jj] - t_g[ii] <= 1.5 * window_s)
    mids_a = 0.5 * (t_g[ii] + t_g[jj])
    courses_a = np.arctan2(dn, de)                       # counter-clockwise from east
    pair = ok_a[1:] & ok_a[:-1] & (mids_a[:-1] >= t_imu[0]) & (mids_a[1:] <= t_imu[-1])
    y = np.angle(np.exp(1j * np.diff(courses_a)))[pair]
    th = trapezoid_integral_at(t_imu, rate, t_imu.shape[0], mids_a)
    x = np.diff(th)[pair]
    n = int(y.shape[0])
    if n < 5:
        return YawScale(nan, nan, float(np.degrees(np.abs(y).sum())) if n else 0.0, n)
    xs, ys = x - x.mean(), y - y.mean()
    sxx, syy, sxy = float(xs @ xs), float(ys @ ys), float(xs @ ys)
    if sxx <= 0.0 or syy <= 0.0:
        return YawScale(nan, nan, float(np.degrees(np.abs(y).sum())), n)
    return YawScale(scale=sxy / sxx, correlation=sxy / np.sqrt(sxx * syy),
                    gnss_turn_deg=float(np.degrees(np.abs(y).sum())), n_pairs=n)
