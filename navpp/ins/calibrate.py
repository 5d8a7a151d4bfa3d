"""What the data can tell before filtering: standstill, biases, noise levels, gravity axis.

A preset (``[imu] preset``) is a prior; this module measures the log itself and says how the
two compare.  Everything here is plain numpy over blocks of the IMU stream, in one pass:

- **Blocks.**  The IMU is cut into blocks of ``BLOCK_S`` (0.5 s); each block into sub-blocks
  of about ``SUB_S`` (0.05 s).  Per block: the mean, the per-sample spread (white noise plus
  vibration) and the *low-passed spread*, the standard deviation of the sub-block means, which
  an engine's or a hand's high-frequency shaking barely moves but real motion does.
- **Standstill** (one detector for the alignment and for ZUPT/ZARU).  A block is quiet when
  its low-passed spreads are within ``K_QUIET`` times the log's own quietest level (the
  ``QUIET_PERCENTILE`` percentile of all blocks) or within the configured IMU's white noise
  floor.  Where GNSS covers the block its speed must be small; a block whose GNSS speed says
  still may be as shaky as halfway (geometrically) between the quietest and the median block
  (a hand-held rest with tremor, an idling engine).  Inside a run of quiet blocks the block
  means must agree (a slow turn or a crawl is smooth, but its mean rate or force changes).  A block
  is still when it and both neighbours are quiet (stops are confirmed from both sides).  No time
  rule: a still stretch may be anywhere in the log.
- **Noise for Q.**  Per second of log, the white-noise density the data show: the quieter of
  two bands, the second differences of 0.1-s means (``NOISE_TAU_S``; a mount's fast shaking,
  which the strapdown integrates to an oscillation rather than a drift, averages out) and each
  sample against its ``NOISE_SPAN`` neighbours (a walker's steps do not reach it), in
  rad/sqrt(s) and m/s/sqrt(s).  Vibration that grows with speed raises it; the engine takes the
  larger of it and the preset, interval by interval.
- **Biases.**  Gyro: the mean rate of the first still stretch, less the vertical Earth rate
  (its horizontal part, unknown without a heading, is in the 1-sigma).  Without any still
  stretch, the mean rate over the log across the vertical (a land vehicle or a walker does
  not keep rolling or pitching) and the vertical bias from the GNSS course.  Accelerometer:
  along the gravity axis only, ``|f| - g``.  Each estimate with its 1-sigma; an estimate far
  outside the preset's turn-on 1-sigma (more than 3 sigma) says the preset is wrong for this
  IMU, and the bias prior is widened to what the data show.
- **Gravity axis.**  The mean specific force of the still stretches (else of the whole log):
  the sensor's "up".  More than ``GROSS_TILT_DEG`` from +z is a mounting, not a slope: the
  engine rotates the IMU so that gravity is on +z and says which setting to write.

References: Groves (2013) section 14.2 (noise), 5.6 (levelling); Allan variance (IEEE Std
952-1997) for the noise reading of averaged data; Skog et al. (2010) for standstill detection
with thresholds relative to the sensor.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from navpp.kernel import njit

from .. import geodesy
from ..intervals import interval_median, mean_interval, pairwise_sum
from ..recording import BLOCK_ROWS as BLOCK_ROWS  # re-exported for .alignment, .timing_estimates
from ..spill import WINDOW_ROWS, like, release, release_all
from .attitude import rpy_to_dcm

if TYPE_CHECKING:
    from ..recording import GnssData

BLOCK_S = 0.5            #: standstill block, s
SUB_S = 0.05             #: sub-block for the low-passed spread, s
NOISE_BLOCK_S = 1.0      #: block of the noise profile, s
OUTLIER_K = 10.0  #: departures beyond this many block medians are glitches, not noise
NOISE_TAU_S = 0.1        #: averaging time of the noise reading, s
NOISE_TAU_STEPS = (1, 2, 5)  #: ... and its multiples read too (the quietest band is the white floor)
NOISE_SPAN = 5           #: samples of the local mean the top band is read against
_TOP_CHUNK_BLOCKS = 512   #: noise-profile blocks whose top-band residuals are formed at a time
_STAT_CHUNK_BLOCKS = 1024  #: standstill blocks whose statistics are taken at a time
QUIET_PERCENTILE = 5.0   #: the log's quietest level: this percentile of the block spreads
K_QUIET = 3.0            #: quiet = within this factor of the quietest level (no GNSS to confirm)
K_WHITE = 4.0            #: or within this many white-noise sigmas of the configured IMU
GNSS_STILL_SPEED = 0.2   #: m/s: below this (or 3 sigma of it) the GNSS says still ...
GNSS_STILL_SPEED_MAX = 0.5  #: ... but never above this, m/s
#: GNSS says moving when its horizontal speed exceeds this many times its 1-sigma per axis.  A
#: still track's 2-D speed is Rayleigh distributed: beyond k sigma with probability exp(-k^2 / 2),
#: 1.1 % at k = 3 (not the 0.27 % of a 1-D 3-sigma test), which broke every 200 s simulated rest
#: with 1.8 m fixes into 3 to 6 pieces; at 4.0 one block in 3000 (0.5 s each) passes by chance,
#: and no simulated rest broke (a moving block still needs the IMU quiet to be taken as still)
MOVING_K = 4.0
GROSS_TILT_DEG = 45.0    #: gravity further than this from body +z: a mounting, not a slope
PRIOR_CONFLICT = 3.0     #: an estimate beyond this many sigmas of the prior rejects the prior


@dataclass(frozen=True)
class NoiseProfile:
    """White-noise densities the data show, per ``NOISE_BLOCK_S`` of log.

    t : (K + 1,) s, block edges; gyro_arw (K,) rad/sqrt(s); accel_vrw (K,) m/s/sqrt(s).
    """

    t: np.ndarray
    gyro_arw: np.ndarray
    accel_vrw: np.ndarray

    def over(self, t0: float, t1: float) -> tuple[float, float]:
        """The largest densities of the blocks that ``[t0, t1]`` touches (gyro, accel).

        Called once per filter interval: plain Python on cached lists (bisect), no numpy
        scalar overhead."""
        edges, g, a = self._lists
        k0 = min(max(bisect.bisect_right(edges, t0) - 1, 0), len(g) - 1)
        k1 = min(max(bisect.bisect_left(edges, t1), k0 + 1), len(g))
        if k1 == k0 + 1:
            return g[k0], a[k0]
        return max(g[k0:k1]), max(a[k0:k1])

    @cached_property
    def _lists(self) -> tuple[list[float], list[float], list[float]]:
        return ([float(v) for v in self.t], [float(v) for v in self.gyro_arw], [float(v) for v in self.accel_vrw])


@dataclass(frozen=True)
class Calibration:
    """What :func:`calibrate` found (SI units, body FLU of the IMU as given).

    still : (N,) bool, still samples (the one standstill detector).
    still_spans : ((t0, t1), ...) s, the still stretches of at least ``min_still_s``.
    up_b : (3,) unit vector, the sensor's up (mean specific force direction); up_from: where from.
    gyro_bias, gyro_bias_std : (3,) rad/s; accel_bias, accel_bias_std : (3,) m/s^2 (along up only).
    bias_from : "still" | "motion" | "none".
    still_arw, still_vrw : white-noise densities in the still stretches (None without one).
    profile : the noise profile for Q.
    notes : lines for the user.
    """

    still: np.ndarray
    still_spans: tuple[tuple[float, float], ...]
    up_b: np.ndarray
    up_from: str
    gyro_bias: np.ndarray
    gyro_bias_std: np.ndarray
    accel_bias: np.ndarray
    accel_bias_std: np.ndarray
    bias_from: str
    still_arw: float | None
    still_vrw: float | None
    profile: NoiseProfile
    notes: tuple[str, ...] = field(default_factory=tuple)

    def report(self) -> dict[str, object]:
        """The estimates as plain numbers (datasheet units) for metrics.json."""
        rad2deg = 180.0 / math.pi
        out: dict[str, object] = {
            "still_spans_s": [[round(a, 3), round(b, 3)] for a, b in self.still_spans],
            "still_fraction": round(float(self.still.mean()) if self.still.size else 0.0, 4),
            "gravity_up_body": [round(float(v), 5) for v in self.up_b],
            "gravity_from": self.up_from,
            "bias_from": self.bias_from,
            "gyro_bias_dps": [round(float(v) * rad2deg, 5) for v in self.gyro_bias],
            "gyro_bias_std_dps": [round(float(v) * rad2deg, 5) for v in self.gyro_bias_std],
            "accel_bias_mg": [round(float(v) / 9.80665e-3, 3) for v in self.accel_bias],
            "accel_bias_std_mg": [round(float(v) / 9.80665e-3, 3) for v in self.accel_bias_std],
            "gyro_arw_deg_per_sqrt_h_median": round(float(np.median(self.profile.gyro_arw)) * rad2deg * 60.0, 3),
            "gyro_arw_deg_per_sqrt_h_p90": round(float(np.percentile(self.profile.gyro_arw, 90)) * rad2deg * 60.0, 3),
            "accel_vrw_mps_per_sqrt_h_median": round(float(np.median(self.profile.accel_vrw)) * 60.0, 4),
            "accel_vrw_mps_per_sqrt_h_p90": round(float(np.percentile(self.profile.accel_vrw, 90)) * 60.0, 4),
        }
        if self.still_arw is not None and self.still_vrw is not None:      # measured together
            out["gyro_arw_deg_per_sqrt_h_still"] = round(self.still_arw * rad2deg * 60.0, 4)
            out["accel_vrw_mps_per_sqrt_h_still"] = round(float(self.still_vrw) * 60.0, 5)
        return out




def trapezoid_integral(t: np.ndarray | float, w: np.ndarray | Callable[[int, int], np.ndarray],
                       n: int | None = None) -> np.ndarray:
    """The trapezoidal integral of the rate ``w`` (N,) at the stamps ``t`` (N,) s (or at a
    constant step ``t`` s) from 0 at the first, (N,): ``concatenate([[0], cumsum(0.5 * (w[1:] +
    w[:-1]) * diff(t))])`` to the bit, block by block (:func:`trapezoid_blocks`); ``[0]`` for
    N = 0, as that concatenation gives.  ``w`` may be given block by block instead, as
    :func:`trapezoid_blocks` takes it, with ``n`` = N: then no N-long rate is held.  Spilled
    stamps: the integral is spilled too (:func:`navpp.spill.like`), its rows released once written."""
    rate = w if callable(w) else (lambda lo, hi: w[lo:hi])
    n = w.shape[0] if n is None and not callable(w) else n
    assert n is not None, "trapezoid_integral: a rate given block by block needs n"
    theta = np.empty(max(n, 1)) if isinstance(t, float) else like(t, max(n, 1), (), np.float64)
    theta[0] = 0.0
    for lo, _, part in trapezoid_blocks(t, rate, n):
        theta[lo:lo + part.shape[0]] = part
        release((theta,), lo, lo + part.shape[0])
    return theta


def trapezoid_blocks(t: np.ndarray | float, rate: Callable[[int, int], np.ndarray], n: int
                     ) -> Iterator[tuple[int, np.ndarray | float, np.ndarray]]:
    """:func:`trapezoid_integral` of a rate given block by block, ``rate(lo, hi)`` its rows
    ``lo:hi`` (hi - lo,), rad/s, at the stamps ``t`` (N,) s (or a constant step ``t`` s), ``n``
    rows: yields for each block of :data:`BLOCK_ROWS` rows ``(lo, stamps, theta)``, ``theta``
    the integral's rows ``lo:lo + len(theta)`` (the same bits: the running sum carried from block
    to block, in the same order, as one cumsum adds) and ``stamps`` the stamps from the row before
    ``lo`` (from ``lo`` in the first block) to the block's last (``t`` itself for a constant
    step).  Neither the rate nor the integral is held whole; the rows of spilled stamps are
    released once their block is done."""
    w_last = theta_last = 0.0
    for lo in range(0, n, BLOCK_ROWS):
        hi = min(lo + BLOCK_ROWS, n)
        w = rate(lo, hi)
        first = lo == 0
        ww = w if first else np.concatenate([[w_last], w])
        stamps = t if isinstance(t, float) else t[max(lo - 1, 0):hi]
        inc = 0.5 * (ww[1:] + ww[:-1]) * (stamps if isinstance(stamps, float) else stamps[1:] - stamps[:-1])
        theta = np.empty(hi - lo)
        if first:
            theta[0] = 0.0
            np.cumsum(inc, out=theta[1:])
        else:           # the carry first: the same sequence of additions as one cumsum
            inc[0] = theta_last + inc[0]
            np.cumsum(inc, out=theta)
        yield lo, stamps, theta
        w_last, theta_last = w[-1], theta[-1]
        if not isinstance(t, float):
            release((t,), max(lo - 1, 0), hi - 1)     # the next block starts from row hi - 1


def trapezoid_integral_at(t: np.ndarray, rate: Callable[[int, int], np.ndarray], n: int,
                          tq: np.ndarray) -> np.ndarray:
    """``np.interp(tq, t, trapezoid_integral(t, w))`` to the bit, the rate ``w`` given block by
    block as :func:`trapezoid_blocks` takes it (``t`` (N,) s, ``n`` = N >= 2): the integral, rad,
    at the times ``tq`` (K,) s (the first or last value beyond the stamps, NaN at NaN) without an
    N-long rate or integral."""
    out = np.full(tq.shape, np.nan)
    last = 0.0
    for lo, stamps, theta in trapezoid_blocks(t, rate, n):
        assert not isinstance(stamps, float)
        fp = theta if lo == 0 else np.concatenate([[last], theta])
        inside = (tq >= stamps[0]) & (tq <= stamps[-1])
        out[inside] = np.interp(tq[inside], stamps, fp)
        last = theta[-1]
    out[tq < t[0]] = 0.0
    out[tq > t[n - 1]] = last
    return out


def sample_period(t: np.ndarray) -> float:
    """The IMU's sample period, s: the mean interval without the gaps (intervals over 5 times
    the median), so that a jittery polled stream gets its real rate, not its commonest interval.
    A spilled ``t`` is read window by window (:mod:`navpp.intervals`)."""
    if t.shape[0] < 2:
        return 1.0
    med = interval_median(t)
    mean = mean_interval(t, 5.0 * med)
    return med if mean is None else mean


@dataclass(frozen=True)
class BlockStatistics:
    """The IMU cut into ``nb`` blocks of ``w`` samples, each into sub-blocks of ``m`` samples
    (``dt`` the sample period, s).  Per block and axis, (nb, 3): the mean, the per-sample spread
    (standard deviation) and the low-passed spread (standard deviation of the sub-block means)
    of the rate (``gyro_*``, rad/s) and of the specific force (``accel_*``, m/s^2)."""

    w: int
    m: int
    nb: int
    dt: float
    gyro_mean: np.ndarray
    gyro_std: np.ndarray
    gyro_lp: np.ndarray
    accel_mean: np.ndarray
    accel_std: np.ndarray
    accel_lp: np.ndarray


def block_statistics(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, block_s: float = BLOCK_S,
                     sub_s: float = SUB_S, dt: float | None = None) -> BlockStatistics:
    """:class:`BlockStatistics` over blocks of about ``block_s`` and sub-blocks of about ``sub_s`` s
    (``dt``: the :func:`sample_period` of ``t`` when known)."""
    n = t.shape[0]
    dt = sample_period(t) if dt is None else dt
    m = max(1, int(round(sub_s / dt)))
    w = max(2 * m, int(round(block_s / dt / m)) * m)
    nb = n // w
    per_sensor: list[np.ndarray] = []
    for x in (gyro, accel):
        mean, std, lp = np.empty((nb, 3)), np.empty((nb, 3)), np.empty((nb, 3))
        # _STAT_CHUNK_BLOCKS blocks at a time: a spilled IMU's rows leave memory once read
        for b0 in range(0, nb, _STAT_CHUNK_BLOCKS):
            b1 = min(nb, b0 + _STAT_CHUNK_BLOCKS)
            _block_moments(x[b0 * w:b1 * w], w, m, mean[b0:b1], std[b0:b1], lp[b0:b1])
            release((x,), b0 * w, b1 * w)
        per_sensor += [mean, std, lp]
    return BlockStatistics(w, m, nb, dt, *per_sensor)


@njit(cache=True)
def _block_moments(x: np.ndarray, w: int, m: int, mean: np.ndarray, std: np.ndarray, lp: np.ndarray) -> None:
    """Per block of ``w`` rows of ``x`` (nb * w, 3) and axis, into (nb, 3) each: the ``mean``, the
    standard deviation ``std`` and ``lp``, the standard deviation of the means of the block's
    sub-blocks of ``m`` rows.  One pass over ``x``, the same bits as numpy's ``mean`` and ``std``
    over the blocks (each sum in row order from the first row, divided by the count; the
    deviations from the mean squared and summed likewise)."""
    per = w // m
    sub = np.empty(per)
    for b in range(mean.shape[0]):
        r0 = b * w
        for j in range(3):
            total = x[r0, j]
            for r in range(r0 + 1, r0 + w):
                total += x[r, j]
            mu = total / w
            d = x[r0, j] - mu
            sq = d * d
            for r in range(r0 + 1, r0 + w):
                d = x[r, j] - mu
                sq += d * d
            mean[b, j] = mu
            std[b, j] = np.sqrt(sq / w)
            for k in range(per):
                s0 = r0 + k * m
                total = x[s0, j]
                for r in range(s0 + 1, s0 + m):
                    total += x[r, j]
                sub[k] = total / m
            total = sub[0]
            for k in range(1, per):
                total += sub[k]
            mu = total / per
            d = sub[0] - mu
            sq = d * d
            for k in range(1, per):
                d = sub[k] - mu
                sq += d * d
            lp[b, j] = np.sqrt(sq / per)


def gnss_scatter_h(tg: np.ndarray, enu: np.ndarray) -> float:
    """Horizontal scatter of the fixes (m, 1-sigma per axis) from their second differences over
    evenly spaced triplets: ``p[k+1] - 2 p[k] + p[k-1]`` has variance ``6 sigma^2`` for white
    noise, and motion adds only ``a dt^2`` (8 cm at 2 m/s^2 and 5 Hz).  Robust (median of the
    absolute values); 0 with fewer than 10 triplets.  Correlated errors are under-read: a floor."""
    if tg.shape[0] < 12:
        return 0.0
    d1 = np.diff(tg)
    even = np.abs(d1[1:] - d1[:-1]) <= 0.1 * np.minimum(d1[1:], d1[:-1])
    if int(even.sum()) < 10:
        return 0.0
    d2 = (enu[2:, :2] - 2.0 * enu[1:-1, :2] + enu[:-2, :2])[even]
    return float(1.4826 * np.median(np.abs(d2)) / math.sqrt(6.0))


def gnss_speed_at(gnss: GnssData, times: np.ndarray, half_window: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal GNSS speed (m/s) and its 1-sigma near each of ``times`` (NaN: no GNSS there).

    From the log's velocity where it has one (the nearest within ``half_window``), else a
    straight-line fit of the fixes within ``+-half_window`` (at least 3)."""
    k = times.shape[0]
    speed = np.full(k, np.nan)
    sigma = np.full(k, np.nan)
    if len(gnss) == 0:
        return speed, sigma
    tg = np.asarray(gnss.t, dtype=float)
    lo = np.searchsorted(tg, times - half_window)
    hi = np.searchsorted(tg, times + half_window, side="right")
    if gnss.vel_enu is not None:
        v = np.hypot(gnss.vel_enu[:, 0], gnss.vel_enu[:, 1])
        sv = (np.hypot(gnss.std_vel_enu[:, 0], gnss.std_vel_enu[:, 1]) if gnss.std_vel_enu is not None
              else np.full(v.shape, 0.1))
        for i in np.nonzero(hi > lo)[0]:
            j = lo[i] + int(np.argmin(np.abs(tg[lo[i]:hi[i]] - times[i])))
            if np.isfinite(v[j]):
                speed[i], sigma[i] = v[j], sv[j] if np.isfinite(sv[j]) else 0.1
        return speed, sigma
    lat0, lon0, h0 = math.radians(float(gnss.lat_deg[0])), math.radians(float(gnss.lon_deg[0])), float(gnss.alt[0])
    enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg), np.radians(gnss.lon_deg), gnss.alt, lat0, lon0, h0)
    std_h = (np.mean(gnss.std_enu[:, :2], axis=1) if gnss.std_enu is not None else np.full(tg.shape, 2.0))
    # the log's std columns may be optimistic: the fixes' own scatter is a floor
    std_h = np.maximum(np.nan_to_num(std_h, nan=2.0), gnss_scatter_h(tg, enu))
    # straight-line fits over every window at once, from prefix sums (times relative to the
    # first fix: no cancellation worth the name over windows of seconds)
    tr = tg - tg[0]

    def csum(x: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(x)])

    c1, ct, ctt = csum(np.ones_like(tr)), csum(tr), csum(tr * tr)
    ce, cn, cte, ctn, cs = csum(enu[:, 0]), csum(enu[:, 1]), csum(tr * enu[:, 0]), csum(tr * enu[:, 1]), csum(std_h)
    n = c1[hi] - c1[lo]
    ok = n >= 3
    nn = np.where(ok, n, 1.0)
    st, stt_raw = ct[hi] - ct[lo], ctt[hi] - ctt[lo]
    stt = stt_raw - st * st / nn                       # sum of (t - mean t)^2
    good = ok & (stt > 1e-12)
    sden = np.where(good, stt, 1.0)
    ve = ((cte[hi] - cte[lo]) - st * (ce[hi] - ce[lo]) / nn) / sden
    vn = ((ctn[hi] - ctn[lo]) - st * (cn[hi] - cn[lo]) / nn) / sden
    speed = np.where(good, np.hypot(ve, vn), np.nan)
    sigma = np.where(good, (cs[hi] - cs[lo]) / nn / np.sqrt(sden), np.nan)
    return speed, sigma


def _row_sums(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nb,) sum of squares and (nb,) count of the values kept per row of ``v`` (nb, k): those
    within ``OUTLIER_K`` times the row's median |v| (each row on its own: rows may come in parts)."""
    av = np.abs(v)
    finite = np.isfinite(av)
    every = bool(finite.all())
    with np.errstate(invalid="ignore", over="ignore"):
        keep = av <= OUTLIER_K * _row_medians(av.copy() if every else np.where(finite, av, np.inf))[:, None]
        if not every:
            keep &= finite
        sq = np.where(keep, av, 0.0)
        np.square(sq, out=sq)
    return sq.sum(axis=1), np.count_nonzero(keep, axis=1).astype(float)


def _row_medians(work: np.ndarray) -> np.ndarray:
    """``np.median(work, axis=1)`` of (nb, k) float ``work`` without NaN, to the bit, ``work``
    partitioned in place: one partition at ``k // 2`` (np.median partitions at both middle
    indices of an even row, on a copy), the lower middle value the largest of the row's lower part,
    and the mean of the two middle values formed as np.median forms it, ``(a + b) / 2``."""
    k = work.shape[1]
    half = k // 2
    work.partition(half, axis=1)
    upper = work[:, half]
    if k % 2:
        return upper.copy()
    lower: np.ndarray = work[:, :half].max(axis=1)
    lower += upper
    lower /= 2.0
    return lower


def _pooled(ssq: np.ndarray, cnt: np.ndarray) -> np.ndarray:
    """(nb,) mean square from the per-row sums of squares ``ssq`` and counts ``cnt`` (:func:`_row_sums`),
    each row pooled with its neighbours (a 3-row window)."""
    ssq3, cnt3 = ssq.copy(), cnt.copy()
    ssq3[1:] += ssq[:-1]
    cnt3[1:] += cnt[:-1]
    ssq3[:-1] += ssq[1:]
    cnt3[:-1] += cnt[1:]
    pooled: np.ndarray = ssq3 / np.maximum(cnt3, 1.0)
    return pooled


def _top_row_sums(xb: np.ndarray, w: int, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_row_sums` of the top band's residuals (each sample of ``xb`` (nb * w, 3) against the
    mean of the ``NOISE_SPAN`` samples around it, ``np.convolve``'s ``"same"`` window) per block of
    ``w`` samples, :data:`_TOP_CHUNK_BLOCKS` blocks at a time: no residual array as long as the log.
    Each part is convolved with ``NOISE_SPAN`` samples either side of it, so every residual is the
    one the whole log's convolution gives, to the last bit."""
    kernel = np.ones(NOISE_SPAN) / NOISE_SPAN
    n = nb * w
    ssq, cnt = np.empty(nb), np.empty(nb)
    for b0 in range(0, nb, _TOP_CHUNK_BLOCKS):
        b1 = min(nb, b0 + _TOP_CHUNK_BLOCKS)
        s, e = b0 * w, b1 * w
        lo, hi = max(0, s - NOISE_SPAN), min(n, e + NOISE_SPAN)
        res = np.empty((e - s, 3))
        for j in range(3):
            res[:, j] = xb[s:e, j] - np.convolve(xb[lo:hi, j], kernel, mode="same")[s - lo:e - lo]
        ssq[b0:b1], cnt[b0:b1] = _row_sums(res.reshape(b1 - b0, w * 3))
        release((xb,), lo, hi)                  # a spilled IMU's rows read: out of memory
    return ssq, cnt


def _band_row_sums(xb: np.ndarray, size: int, w: int, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_row_sums` per block of ``w`` rows of the second differences ``d[k] = a[k+1] - 2 a[k]
    + a[k-1]`` of the means ``a`` of consecutive groups of ``size`` rows of ``xb`` (nb * w, 3), ``w``
    a multiple of ``size`` and at least 3 groups (the first and last ``d`` those next to them),
    :data:`_STAT_CHUNK_BLOCKS` blocks at a time with a group either side (each group's mean and each
    difference on its own: the same bits as over the whole log), a spilled ``xb``'s rows released
    after each part: no array of the means or differences as long as the log."""
    per = w // size
    k_all = nb * per
    ssq, cnt = np.empty(nb), np.empty(nb)
    for b0 in range(0, nb, _STAT_CHUNK_BLOCKS):
        b1 = min(nb, b0 + _STAT_CHUNK_BLOCKS)
        k0, k1 = b0 * per, b1 * per                     # the part's groups
        g0, g1 = max(k0 - 1, 0), min(k1 + 1, k_all)     # ... and their neighbours
        a = _group_means(xb[g0 * size:g1 * size].reshape(g1 - g0, size, 3))
        d = np.zeros((k1 - k0, 3))
        lo, hi = max(k0, 1), min(k1, k_all - 1)         # the differences with both neighbours
        d[lo - k0:hi - k0] = a[lo + 1 - g0:hi + 1 - g0] - 2.0 * a[lo - g0:hi - g0] + a[lo - 1 - g0:hi - 1 - g0]
        if k0 == 0:
            d[0] = d[1]
        if k1 == k_all:
            d[-1] = d[-2]
        ssq[b0:b1], cnt[b0:b1] = _row_sums(d.reshape(b1 - b0, per * 3))
        release((xb,), g0 * size, g1 * size)
    return ssq, cnt


def _group_means(x: np.ndarray) -> np.ndarray:
    """``x.mean(axis=1)`` of (g, s, 3) float ``x``, the same bits: numpy adds along that axis in
    order, row after row (it is not the contiguous one), and so does this, a (g, 3) row at a
    time, which for groups of tens of rows costs a third of the strided reduction
    (tests/test_calibrate.py checks the bits against numpy)."""
    acc = x[:, 0, :].copy()
    for k in range(1, x.shape[1]):
        acc += x[:, k, :]
    acc /= x.shape[1]
    return acc


def noise_profile(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, block_s: float = NOISE_BLOCK_S,
                  tau_s: float = NOISE_TAU_S, dt: float | None = None) -> NoiseProfile:
    """White-noise densities per block of ``block_s`` (see the module docstring; ``dt``: the
    :func:`sample_period` of ``t`` when known).

    White noise is flat across the spectrum, so any band's level bounds it from above; the
    reading is the quieter of two bands:

    - around ``1 / tau_s``: the samples averaged over ``tau_s`` (m samples); the second
      difference of consecutive means, ``d = a[k+1] - 2 a[k] + a[k-1]``, has variance
      ``6 N^2 / tau`` for white noise of density ``N``, and removes motion that changes slowly
      over ``3 tau`` (a turn, a brake).  A mount's shaking, faster than ``1 / tau``, averages out
      of the means (it oscillates; the strapdown does not drift on it).
    - the top: each sample against the mean of the ``NOISE_SPAN`` samples around it,
      ``N^2 = dt * mean(r^2) * span / (span - 1)``.  A walker's steps (1-5 Hz) barely reach it.

    Each band's mean square is taken over the three axes of a block, departures beyond
    ``OUTLIER_K`` times the block's median left out (glitches), pooled with the neighbouring
    blocks (a 3-block window, so an interval's Q also covers the shaking just before and after
    it)."""
    n = t.shape[0]
    dt = sample_period(t) if dt is None else dt
    m = max(1, int(round(tau_s / dt)))
    tau = m * dt
    per = max(3, int(round(block_s / tau)))         # means per block
    w = per * m
    nb = n // w
    if nb < 1 or n < 3 * m:
        zero = np.zeros(1)
        return NoiseProfile(np.array([float(t[0]), float(t[-1])]), zero, zero)
    dens = []
    for x in (gyro, accel):
        xb = x[: nb * w]
        # the bands around 1 / tau, 1 / (2 tau), 1 / (4 tau): second differences of the means
        # (variance 6 N^2 / tau each)
        band = np.full(nb, np.inf)
        for mult in NOISE_TAU_STEPS:
            mm = m * mult
            if per % mult or per // mult < 3:
                continue
            band = np.minimum(band, _pooled(*_band_row_sums(xb, mm, w, nb)) / 6.0 * (tau * mult))
        # the top of the band: each sample against the mean of the NOISE_SPAN around it
        top = _pooled(*_top_row_sums(xb, w, nb)) * NOISE_SPAN / (NOISE_SPAN - 1.0) * dt
        # white noise is flat: the quieter band bounds it (a mount's shaking fills the top, a
        # walker's steps the band around 1 / tau)
        dens.append(np.sqrt(np.minimum(band, top)))
        release_all(x)                          # a spilled IMU's pages this sensor's passes read
    edges = np.concatenate([t[0: nb * w: w], [t[min(nb * w, n - 1)]]])
    edges[-1] = max(edges[-1], float(t[-1]))
    release_all(t)
    return NoiseProfile(edges.astype(float), dens[0], dens[1])


def standstill(t: np.ndarray, stats: BlockStatistics, gnss: GnssData, gyro_arw: float, accel_vrw: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool still samples and (nb,) bool still blocks (see the module docstring)."""
    n = t.shape[0]
    nb, w, m, dt = stats.nb, stats.w, stats.m, stats.dt
    mask = np.zeros(n, bool)
    if nb < 3:
        return mask, np.zeros(nb, bool)
    lp_g = stats.gyro_lp.max(axis=1)
    lp_a = stats.accel_lp.max(axis=1)
    q_g = float(np.percentile(lp_g, QUIET_PERCENTILE))
    q_a = float(np.percentile(lp_a, QUIET_PERCENTILE))
    # with the GNSS speed to confirm, quiet reaches halfway (geometrically) from the quietest
    # blocks to the typical one: a hand's tremor or an idling engine, not a walk or a drive
    mid_g = math.sqrt(q_g * float(np.median(lp_g)))
    mid_a = math.sqrt(q_a * float(np.median(lp_a)))
    floor_g = max(K_WHITE * gyro_arw / math.sqrt(m * dt), math.radians(0.02))
    floor_a = max(K_WHITE * accel_vrw / math.sqrt(m * dt), 0.005)
    centres = t[np.minimum(np.arange(nb) * w + w // 2, n - 1)]
    release_all(t)                              # a spilled t's pages the gather read
    speed, speed_std = gnss_speed_at(gnss, centres)
    has = np.isfinite(speed)
    limit = np.maximum(GNSS_STILL_SPEED, np.minimum(3.0 * np.nan_to_num(speed_std, nan=0.0), GNSS_STILL_SPEED_MAX))
    gnss_still = has & (speed <= limit)
    # moving only when the speed is beyond its own noise: a noisy fix says nothing either way
    gnss_moving = has & ~gnss_still & (speed > MOVING_K * np.nan_to_num(speed_std, nan=0.0))
    thr_g = np.where(gnss_still, max(K_QUIET * q_g, mid_g), K_QUIET * q_g)
    thr_a = np.where(gnss_still, max(K_QUIET * q_a, mid_a), K_QUIET * q_a)
    quiet = (lp_g <= np.maximum(thr_g, floor_g)) & (lp_a <= np.maximum(thr_a, floor_a)) & ~gnss_moving
    # a slow turn or a crawl is as smooth as a rest: inside a run of quiet blocks, the block means
    # must agree with the run's median within what the shaking allows
    sub_n = math.sqrt(w / m)
    for i0, i1 in spans(np.arange(nb, dtype=float), quiet, 1.0):
        # the rate only: a hand-held IMU tilts slowly at rest, which moves the mean force, not the rate
        lp = stats.gyro_lp
        dev = np.abs(stats.gyro_mean[i0:i1] - np.median(stats.gyro_mean[i0:i1], axis=0))
        allowed = np.maximum(3.0 * lp[i0:i1] / sub_n + 2.0 * np.median(lp[i0:i1], axis=0), floor_g)
        quiet[i0:i1] &= np.all(dev <= allowed, axis=1)
    confirmed = quiet.copy()
    confirmed[1:] &= quiet[:-1]
    confirmed[:-1] &= quiet[1:]
    confirmed[0] &= quiet[0]
    mask[: nb * w] = np.repeat(confirmed, w)
    return mask, confirmed


def spans(t: np.ndarray, mask: np.ndarray, min_s: float) -> list[tuple[int, int]]:
    """Index ranges [i0, i1) of runs of ``mask`` lasting at least ``min_s``."""
    edge = np.zeros(1, dtype=np.int8)      # int8 throughout: no int64 copy of the mask
    d = np.diff(np.concatenate([edge, mask.astype(np.int8), edge]))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    return [(int(a), int(b)) for a, b in zip(starts, ends) if b - a >= 2 and t[b - 1] - t[a] >= min_s]


def _vertical_bias_from_course(t: np.ndarray, gyro: np.ndarray, up: np.ndarray, gnss: GnssData,
                               min_speed: float = 3.0) -> tuple[float, float, float] | None:
    """Vertical gyro bias (rad/s) from the GNSS course: over every stretch driven faster than
    ``min_speed`` without a gap, the integrated vertical rate (``gyro`` (N, 3) rad/s about ``up``
    (3,), taken block by block: no IMU-length rate or integral) minus the course change.
    Returns (bias, 1-sigma, seconds used) or None."""
    if len(gnss) < 10:
        return None
    tg = np.asarray(gnss.t, dtype=float)
    if gnss.vel_enu is not None:
        ve, vn = gnss.vel_enu[:, 0], gnss.vel_enu[:, 1]
        tc = tg
        course_sd = np.full(tg.shape, math.radians(3.0))
    else:
        lat0, lon0 = math.radians(float(gnss.lat_deg[0])), math.radians(float(gnss.lon_deg[0]))
        enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg), np.radians(gnss.lon_deg), gnss.alt, lat0, lon0,
                                      float(gnss.alt[0]))
        std_h = float(np.nanmedian(gnss.std_enu[:, :2])) if gnss.std_enu is not None else 2.0
        std_h = max(std_h if math.isfinite(std_h) else 2.0, gnss_scatter_h(tg, enu))
        # chords long enough that the fixes' noise moves their course by a few degrees at most:
        # 0.5 s for RTK, up to 5 s for metre-level fixes (20 sigma at ~10 m/s)
        span_s = min(5.0, max(0.5, 2.0 * std_h))
        step = max(1, int(round(span_s / max(float(np.median(np.diff(tg))), 1e-3))))
        d = enu[step:] - enu[:-step]
        dtc = tg[step:] - tg[:-step]
        ve, vn = d[:, 0] / dtc, d[:, 1] / dtc
        tc = 0.5 * (tg[step:] + tg[:-step])
        length = np.hypot(d[:, 0], d[:, 1])
        course_sd = math.sqrt(2.0) * std_h / np.maximum(length, 1e-9)
    ok = (np.hypot(ve, vn) > min_speed) & (course_sd < math.radians(5.0))
    ok &= (tc >= t[0]) & (tc <= t[-1])
    if np.count_nonzero(ok) < 10:
        return None
    yaw = -np.arctan2(ve, vn)        # counter-clockwise from north... as a rate only
    nominal = float(np.median(np.diff(tc)))
    # stretches: consecutive ok epochs without a gap over 3 nominal intervals, and without a course
    # step the unwrap could take either way
    idx = np.nonzero(ok)[0]
    jump = np.abs(np.angle(np.exp(1j * np.diff(yaw[idx])))) > 0.5 * math.pi
    breaks = np.nonzero((np.diff(idx) > 1) | (np.diff(tc[idx]) > 3.0 * nominal) | jump)[0]
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [idx.size - 1]])

    def rate(lo: int, hi: int) -> np.ndarray:
        """Rows ``lo:hi`` of the rate about up, rad/s (a spilled gyro's rows released once read)."""
        w: np.ndarray = gyro[lo:hi] @ up
        release((gyro,), lo, hi)
        return w

    # the integrated rate at both ends of each stretch (rad)
    turned = trapezoid_integral_at(t, rate, t.shape[0], np.concatenate([tc[idx[starts]], tc[idx[ends]]]))
    turned_start, turned_end = turned[:starts.size], turned[starts.size:]
    num = tot = var = 0.0
    for s, (a, b) in enumerate(zip(starts, ends)):
        i, j = idx[a], idx[b]
        T = float(tc[j] - tc[i])
        if T < 5.0:
            continue
        gyro_turn = float(turned_end[s] - turned_start[s])
        course = np.unwrap(yaw[idx[a:b + 1]])
        num += gyro_turn - float(course[-1] - course[0])
        tot += T
        var += float(course_sd[i]) ** 2 + float(course_sd[j]) ** 2
    if tot < 20.0:
        return None
    # the chords' course noise at the ends of each stretch
    return num / tot, math.sqrt(var) / tot, tot


def calibrate(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gnss: GnssData, *, gyro_arw: float, accel_vrw: float,
              gyro_bias_sigma: float, accel_bias_sigma: float, min_still_s: float = 2.0) -> Calibration:
    """Measure the log (see the module docstring).

    Parameters
    ----------
    t : (N,) s; gyro (N, 3) rad/s; accel (N, 3) m/s^2: body FLU (the configured mounting applied).
    gnss : the recording's GNSS (:class:`navpp.recording.GnssData`).
    gyro_arw, accel_vrw : the configured white noise (rad/sqrt(s), m/s/sqrt(s)): the detector's floor.
    gyro_bias_sigma, accel_bias_sigma : the configured turn-on bias 1-sigma (rad/s, m/s^2): the prior.
    min_still_s : shortest still stretch used for the biases and the gravity axis, s.
    """
    notes: list[str] = []
    dt = sample_period(t)
    stats = block_statistics(t, gyro, accel, dt=dt)
    still, _ = standstill(t, stats, gnss, gyro_arw, accel_vrw)
    runs = spans(t, still, min_still_s)
    profile = noise_profile(t, gyro, accel, dt=dt)
    lat = math.radians(float(np.median(gnss.lat_deg))) if len(gnss) else 0.0
    h = float(np.median(gnss.alt)) if len(gnss) else 0.0
    if runs:
        est = _biases_at_rest(gyro, accel, runs, dt, lat, h, gyro_bias_sigma, accel_bias_sigma)
        a, b = runs[0]
        n_still = sum(b1 - a1 for a1, b1 in runs)
        notes.append(
            f"still: {len(runs)} stretch{'es' if len(runs) > 1 else ''} of {n_still * dt:.1f} s in all "
            f"(first t = {t[a]:.2f} .. {t[b - 1]:.2f} s), found relative to the log's quietest blocks"
            + (" and confirmed by the GNSS speed" if len(gnss) else ""))
        still_arw, still_vrw = float(est.still_arw or 0.0), float(est.still_vrw or 0.0)
        notes.append(
            f"IMU noise in the still stretches (vibration included): gyro {math.degrees(still_arw) * 60.0:.3g} "
            f"deg/sqrt(h) ({math.degrees(still_arw / math.sqrt(dt)):.3g} deg/s per sample), accel "
            f"{still_vrw * 60.0:.3g} m/s/sqrt(h) ({still_vrw / math.sqrt(dt):.3g} m/s^2 per sample)")
    else:
        est = _biases_in_motion(t, gyro, accel, gnss, gyro_bias_sigma, accel_bias_sigma, notes)
    up, gyro_bias, gyro_bias_std = est.up, est.gyro_bias, est.gyro_bias_std
    tilt = math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0))))
    deg = np.degrees(gyro_bias)
    notes.append(f"gyro bias ({'from ' + est.bias_from if est.bias_from != 'none' else 'prior only'}): "
                 f"{deg[0]:+.3f} {deg[1]:+.3f} {deg[2]:+.3f} deg/s +- "
                 f"{' '.join(f'{v:.3f}' for v in np.degrees(gyro_bias_std))}; accel bias along up "
                 f"{float(est.accel_bias @ up) / 9.80665e-3:+.1f} mg")
    if (np.any(np.abs(gyro_bias) > PRIOR_CONFLICT * np.hypot(gyro_bias_sigma, gyro_bias_std))
            and est.bias_from != "none"):
        notes.append("the gyro biases are beyond the configured turn-on 1-sigma "
                     f"({math.degrees(gyro_bias_sigma) * 3600:.3g} deg/h): "
                     "the IMU is of a lower grade than the preset says; the bias prior is widened")
    mp = profile
    notes.append(f"IMU noise for Q from the data (quietest band of each second of log): gyro median "
                 f"{math.degrees(float(np.median(mp.gyro_arw))) * 60:.3g}, 90 % "
                 f"{math.degrees(float(np.percentile(mp.gyro_arw, 90))) * 60:.3g} deg/sqrt(h); accel median "
                 f"{float(np.median(mp.accel_vrw)) * 60:.3g}, 90 % {float(np.percentile(mp.accel_vrw, 90)) * 60:.3g} "
                 f"m/s/sqrt(h) (configured {math.degrees(gyro_arw) * 60:.3g} and {accel_vrw * 60:.3g}: "
                 "the larger is used)")
    if tilt > 1.0:
        notes.append(f"gravity in body axes ({est.up_from}): ({up[0]:+.3f}, {up[1]:+.3f}, {up[2]:+.3f}), "
                     f"{tilt:.1f} deg from +z")
    return Calibration(still, tuple((float(t[a]), float(t[b - 1])) for a, b in runs), up, est.up_from, gyro_bias,
                       gyro_bias_std, est.accel_bias, est.accel_bias_std, est.bias_from, est.still_arw,
                       est.still_vrw, profile, tuple(notes))


@dataclass(frozen=True)
class _Biases:
    """What :func:`calibrate` reads from the still stretches or, without one, from the motion:
    the sensor's up (unit, body FLU) and where from; the biases with their 1-sigma (rad/s,
    m/s^2) and where from ("still" | "motion" | "none"); the white noise of the still stretches
    (rad/sqrt(s), m/s/sqrt(s); None in motion)."""

    up: np.ndarray
    up_from: str
    gyro_bias: np.ndarray
    gyro_bias_std: np.ndarray
    accel_bias: np.ndarray
    accel_bias_std: np.ndarray
    bias_from: str
    still_arw: float | None = None
    still_vrw: float | None = None


def _biases_at_rest(gyro: np.ndarray, accel: np.ndarray, runs: list[tuple[int, int]], dt: float, lat: float,
                    h: float, gyro_bias_sigma: float, accel_bias_sigma: float) -> _Biases:
    """Up from the mean specific force of all still stretches (samples ``runs``, ``dt`` the sample
    period, s); the biases from
    the first one: gyro = mean rate less the vertical Earth rate at ``lat`` (rad), the horizontal
    Earth rate (unknown heading) in its 1-sigma; accelerometer along up only, ``|f| - g(lat, h)``;
    each combined with the zero-mean prior (:func:`_with_prior`)."""
    g_local = float(geodesy.gravity(lat, h))
    w_e = geodesy.OMEGA_E
    n_still = sum(b - a for a, b in runs)
    f_all = rows_mean(accel, runs, n_still)
    up = f_all / np.linalg.norm(f_all)
    up_from = f"{len(runs)} still stretch{'es' if len(runs) > 1 else ''}, {n_still * dt:.0f} s"
    a, b = runs[0]
    n = b - a
    w_mean = gyro[a:b].mean(axis=0)
    f_mean = accel[a:b].mean(axis=0)
    # the 1-sigma of a mean: from the scatter of 0.5-s means (vibration is not white)
    wb = max(2, int(round(0.5 / dt)))
    nblk = max(1, n // wb)
    gm = gyro[a:a + nblk * wb].reshape(nblk, wb, 3).mean(axis=1) if nblk >= 2 else gyro[a:b]
    fm = accel[a:a + nblk * wb].reshape(nblk, wb, 3).mean(axis=1) if nblk >= 2 else accel[a:b]
    g_sd = gm.std(axis=0, ddof=1) / math.sqrt(gm.shape[0]) if gm.shape[0] > 1 else np.full(3, gyro_bias_sigma)
    f_sd = fm.std(axis=0, ddof=1) / math.sqrt(fm.shape[0]) if fm.shape[0] > 1 else np.full(3, accel_bias_sigma)
    up1 = f_mean / np.linalg.norm(f_mean)
    est_g = w_mean - w_e * math.sin(lat) * up1
    # the horizontal Earth rate (unknown heading) is part of the error on the axes across up
    sd_g = np.sqrt(g_sd ** 2 + (w_e * math.cos(lat)) ** 2 * np.clip(1.0 - up1 ** 2, 0.0, 1.0))
    est_a = (float(np.linalg.norm(f_mean)) - g_local) * up1
    sd_a = np.sqrt(f_sd ** 2 + (3e-4 * g_local) ** 2) * np.abs(up1) + 1e-9   # gravity model, 30 ug
    gyro_bias, gyro_bias_std = _with_prior(est_g, sd_g, gyro_bias_sigma)
    # only the component along up is observed; across it the prior stays
    accel_bias, accel_bias_std = _with_prior(est_a, np.where(np.abs(up1) > 0.5, sd_a, np.inf), accel_bias_sigma)
    still_arw = _runs_rms(gyro, runs, n_still, rows_mean(gyro, runs, n_still)) * math.sqrt(dt)
    still_vrw = _runs_rms(accel, runs, n_still, f_all) * math.sqrt(dt)
    return _Biases(up, up_from, gyro_bias, gyro_bias_std, accel_bias, accel_bias_std, "still", still_arw, still_vrw)


def _runs_rows(x: np.ndarray, runs: list[tuple[int, int]]) -> Iterator[np.ndarray]:
    """The rows of ``x`` (N, 3) in the index ranges ``runs`` ([a, b), in order) as contiguous parts
    of at most :data:`~navpp.spill.WINDOW_ROWS` rows; a spilled ``x``'s rows released after each."""
    for a, b in runs:
        for lo in range(a, b, WINDOW_ROWS):
            hi = min(b, lo + WINDOW_ROWS)
            yield np.ascontiguousarray(x[lo:hi])
            release((x,), lo, hi)


def rows_mean(x: np.ndarray, runs: list[tuple[int, int]], n: int) -> np.ndarray:
    """(3,) mean of the ``n`` rows of ``x`` (N, 3) in ``runs``: ``x[sel].mean(axis=0)`` to the bit
    (numpy adds the rows of an axis-0 sum one after the other; each part continues the sum)."""
    acc: np.ndarray | None = None
    for part in _runs_rows(x, runs):
        acc = np.add.reduce(part if acc is None else np.vstack([acc[None], part]), axis=0)
    assert acc is not None
    mean: np.ndarray = acc / n
    return mean


def _runs_rms(x: np.ndarray, runs: list[tuple[int, int]], n: int, mean: np.ndarray) -> float:
    """The root mean square of the ``n`` rows of ``x`` (N, 3) in ``runs`` less ``mean`` (3,) over all
    three axes: ``np.sqrt(np.mean((x[sel] - mean) ** 2))`` to the bit (:func:`navpp.intervals.pairwise_sum`)."""
    ssq = pairwise_sum((((part - mean) ** 2).ravel() for part in _runs_rows(x, runs)), 3 * n)
    return float(np.sqrt(ssq / (3 * n)))


def _biases_in_motion(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gnss: GnssData, gyro_bias_sigma: float,
                      accel_bias_sigma: float, notes: list[str]) -> _Biases:
    """Without a still stretch: up from the mean specific force of the whole log; over more than
    30 s, the gyro biases across up from the mean rate (a land vehicle or a walker does not keep
    rolling or pitching) and the vertical one from the GNSS course
    (:func:`_vertical_bias_from_course`); else the priors alone."""
    whole = [(0, t.shape[0])]
    f_all = rows_mean(accel, whole, t.shape[0])
    up = f_all / np.linalg.norm(f_all)
    gyro_bias, gyro_bias_std = np.zeros(3), np.full(3, gyro_bias_sigma)
    bias_from = "none"
    w_all = rows_mean(gyro, whole, t.shape[0])
    T = float(t[-1] - t[0])
    if T > 30.0:
        # across up: a land vehicle or a walker does not keep rolling or pitching
        across = w_all - float(w_all @ up) * up
        sd_across = math.radians(5.0) / T              # a few degrees of net roll/pitch change
        est = across.copy()
        sd = np.full(3, sd_across)
        vert = _vertical_bias_from_course(t, gyro, up, gnss)
        if vert is not None:
            est = est + vert[0] * up
            sd = np.sqrt(sd ** 2 + (vert[1] * up) ** 2)
        else:
            sd = np.sqrt(sd ** 2 + (gyro_bias_sigma * up) ** 2)
        gyro_bias, gyro_bias_std = _with_prior(est, sd, gyro_bias_sigma)
        bias_from = "motion"
        notes.append(f"no still stretch: gyro biases from the mean rate over the {T:.0f} s log (across the "
                     "vertical)" + (f" and from the GNSS course over {vert[2]:.0f} s of driving (vertical)"
                                    if vert is not None else "; the vertical bias stays unknown"))
    return _Biases(up, "the whole log (no still stretch)", gyro_bias, gyro_bias_std, np.zeros(3),
                   np.full(3, accel_bias_sigma), bias_from)


def _with_prior(est: np.ndarray, sd: np.ndarray, prior_sd: float) -> tuple[np.ndarray, np.ndarray]:
    """Combine per-axis estimates (``sd`` may be inf: not observed) with a zero-mean prior of
    ``prior_sd``.  When any axis is more than :data:`PRIOR_CONFLICT` sigmas from the prior, the
    prior is wrong for this sensor: the estimates stand alone, and the unobserved axes get a
    prior as wide as the largest bias seen."""
    est = np.asarray(est, dtype=float)
    sd = np.asarray(sd, dtype=float)
    obs = np.isfinite(sd)
    conflict = obs & (np.abs(est) > PRIOR_CONFLICT * np.hypot(prior_sd, np.where(obs, sd, 0.0)))
    if conflict.any():
        wide = max(prior_sd, float(np.abs(est[obs]).max()))
        return np.where(obs, est, 0.0), np.where(obs, np.maximum(sd, 1e-12), wide)
    if prior_sd <= 0.0:
        return np.zeros(3), np.zeros(3)
    w_p = 1.0 / prior_sd ** 2
    w_e = np.where(obs, 1.0 / np.maximum(sd, 1e-15) ** 2, 0.0)
    mean = w_e * np.where(obs, est, 0.0) / (w_p + w_e)
    return mean, 1.0 / np.sqrt(w_p + w_e)


def gross_mounting(up_b: np.ndarray) -> np.ndarray | None:
    """Sensor -> body rotation (3, 3) that puts the sensor's up on +z, when up is more than
    :data:`GROSS_TILT_DEG` from +z (None otherwise).

    A roll about x then a pitch about y, as levelling does: the sensor's x axis stays the
    body's forward as far as gravity allows (y up becomes a roll of 90 deg; FRD written as FLU,
    a roll of 180 deg).  Yaw is not observable from gravity."""
    up = np.asarray(up_b, dtype=float) / np.linalg.norm(up_b)
    if math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0)))) <= GROSS_TILT_DEG:
        return None
    phi = math.atan2(up[1], up[2])
    r = math.hypot(up[1], up[2])
    theta = math.atan2(-up[0], r)
    return rpy_to_dcm(phi, theta, 0.0)          # Ry(theta) Rx(phi)


def matrix_to_rpy_deg(mat: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw (deg) with ``mat = Rz(yaw) Ry(pitch) Rx(roll)`` (``[imu] mounting_rpy_deg``)."""
    pitch = -math.asin(float(np.clip(mat[2, 0], -1.0, 1.0)))
    roll = math.atan2(float(mat[2, 1]), float(mat[2, 2]))
    yaw = math.atan2(float(mat[1, 0]), float(mat[0, 0]))
    return tuple(round(math.degrees(a), 2) + 0.0 for a in (roll, pitch, yaw))  # type: ignore[return-value]


__all__ = ["Calibration", "NoiseProfile", "block_statistics", "calibrate", "gnss_speed_at", "gross_mounting",
           "matrix_to_rpy_deg", "noise_profile", "spans", "standstill"]
