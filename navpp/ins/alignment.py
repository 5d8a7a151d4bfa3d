"""Initial alignment: still-period detection, static levelling, gyrocompassing, GNSS heading.

- The first still period is *detected* from the IMU (windowed spread of specific force and
  angular rate), confirmed by GNSS velocity when the log has it; never assumed from a fixed
  time.
- Levelling: roll and pitch from the mean specific force of the still period.
- Heading: from the config when given; by gyrocompassing when the gyro grade makes it
  accurate enough (predicted 1-sigma below ``[init] gyrocompass_max_heading_std_deg``);
  otherwise from the GNSS track of the first 150 m of driving, each displacement rotated back
  by the turn the gyro measured since the start (a still car does not turn, but this does not
  assume it).

References: Groves (2013) section 5.6 (levelling, gyrocompassing); Titterton & Weston (2004)
ch. 10.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..findings import Finding
from ..intervals import interval_median
from ..spill import release
from .aids.standstill import quiet_blocks
from .attitude import dcm_to_quat, rph_to_dcm
from .calibrate import MOVING_K, gnss_scatter_h, gnss_speed_at, spans, trapezoid_integral_at
from .state import (
    ATT,
    BA,
    BG,
    N_ERR,
    NOMINAL_BA,
    NOMINAL_BG,
    NOMINAL_Q,
    NOMINAL_SIZE,
    NOMINAL_VEL,
    POS,
    VEL,
    X_H,
    X_LAT,
    X_LON,
)

if TYPE_CHECKING:
    from ..recording import GnssData


@dataclass(frozen=True)
class AlignmentSettings:
    """What alignment needs to know (SI units; taken from the config by the engine)."""

    method: str = "auto"                     # auto | gyrocompass | gnss | config
    roll: float | None = None                # rad, given by the user
    pitch: float | None = None
    heading: float | None = None
    still_min_s: float = 2.0
    gyrocompass_max_heading_std: float = math.radians(2.0)
    min_speed_mps: float = 3.0
    gyro_bias_sigma: float = 0.0             # rad/s (turn-on)
    gyro_arw: float = 0.0                    # rad/sqrt(s)
    accel_bias_sigma: float = 0.0            # m/s^2
    accel_vrw: float = 0.0                   # m/s/sqrt(s)
    lever_arm_b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # what calibration measured (navpp.ins.calibrate); None: not measured
    still_mask: np.ndarray | None = None     # (N,) bool still samples: replaces the own detector
    gyro_bias: np.ndarray | None = None      # (3,) rad/s, with its 1-sigma (3,)
    gyro_bias_std: np.ndarray | None = None
    accel_bias: np.ndarray | None = None     # (3,) m/s^2, with its 1-sigma (3,)
    accel_bias_std: np.ndarray | None = None
    up_b: np.ndarray | None = None           # (3,) the body's up from gravity: levelling in motion
    first_motion: bool = False               # heading from the first motion only (no gap, no big turn)
    heading_floor: float = 0.0               # rad, floor of the GNSS-track heading's 1-sigma


@dataclass(frozen=True)
class Alignment:
    """Result: start time, nominal state and covariance, and a readable account of the method."""

    t: float
    index: int                   # IMU sample index of ``t``
    x: np.ndarray                # (16,) nominal
    P: np.ndarray                # (15, 15)
    still: tuple[float, float] | None
    lines: tuple[str, ...] = field(default_factory=tuple)
    warnings: tuple[str, ...] = field(default_factory=tuple)
    #: a still start's averaged fixes: the times of the first and last (s; None in motion or from
    #: one fix), how many and as how many independent ones per ENU axis (3,)
    start_fixes: tuple[float, float] | None = None
    start_count: int = 1
    start_n_eff: np.ndarray = field(default_factory=lambda: np.ones(3))


#: A still start's position is the mean of the still period's fixes (``P`` holds that mean's
#: variance), and the filter takes those fixes again (they tie the INS across the rest and give
#: the adaptive filters innovations).  So that their information counts once, the filter's start
#: holds this share of it (the mean with its variance over the share) and the fixes the rest (each
#: fix's variance times ``N / (N_eff (1 - share))``, N_eff per axis from :func:`effective_count`;
#: :func:`navpp.engine.prepare.start_fixes`): both parts are means of the same fixes, so the output
#: does not jump when the filter starts, and at the end of the rest the filter's variance is the
#: mean's (not half of it).  With the Gauss-Markov GNSS error model the start is also tied to the
#: error states (:meth:`navpp.ins.gnss_error.GnssErrorModel.start`).
START_SHARE = 0.5


#: A still IMU tilted by more than this (deg) is warned about (axes not forward-left-up?); one
#: tilted beyond 90 deg plus this (its z axis closer to down) is refused as upside down.
TILT_WARN_DEG = 30.0


def still_runs(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, *, min_duration: float,
               gyro_arw: float = 0.0, accel_vrw: float = 0.0, window_s: float = 0.5) -> list[tuple[int, int]]:
    """Runs of still IMU windows lasting at least ``min_duration`` s: sample index ranges [i0, i1).

    A window is still when the standard deviation of every specific-force axis is below
    ``max(0.4 m/s^2, 4 x white-noise sigma)`` and of every rate axis below
    ``max(2 deg/s, 4 x sigma)`` (an idling engine's vibration passes), and the mean rate is
    below 1 deg/s.  Smooth motion passes this test too: :func:`align` confirms a run with
    gravity and the GNSS track.
    """
    n = t.shape[0]
    dt = interval_median(t) if n > 1 else 1.0
    sig_a = accel_vrw / math.sqrt(dt)
    sig_g = gyro_arw / math.sqrt(dt)
    # generous: an idling engine shakes the IMU; align() confirms every run with gravity and GNSS
    thr_a = max(0.4, 4.0 * sig_a)
    thr_g = max(math.radians(2.0), 4.0 * sig_g)
    w, still = quiet_blocks(t, gyro, accel, window_s, thr_a, thr_g, math.radians(1.0))
    nw = still.shape[0]
    if nw == 0:
        return []
    need = max(1, int(math.ceil(min_duration / (w * dt))))
    runs = []
    k = 0
    while k < nw:
        if still[k]:
            j = k
            while j < nw and still[j]:
                j += 1
            if j - k >= need:
                runs.append((k * w, j * w))
            k = j
        else:
            k += 1
    return runs


def _first_gnss_motion(gnss: GnssData, speed: float = 0.5) -> float:
    """Time (s) of the first GNSS epoch whose speed (velocity, or a fit of the fixes within
    +-1 s) exceeds ``speed`` m/s and :data:`~navpp.ins.calibrate.MOVING_K` sigma; inf when the
    GNSS never moves."""
    tg = np.asarray(gnss.t, dtype=float)
    v, sv = gnss_speed_at(gnss, tg)
    moving = np.nonzero(np.isfinite(v) & (v > speed) & (v > MOVING_K * np.nan_to_num(sv, nan=np.inf)))[0]
    return float(tg[moving[0]]) if moving.size else math.inf


def detect_still(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, *, min_duration: float,
                 gyro_arw: float = 0.0, accel_vrw: float = 0.0, window_s: float = 0.5
                 ) -> tuple[int, int] | None:
    """The first of :func:`still_runs`, or None."""
    runs = still_runs(t, gyro, accel, min_duration=min_duration, gyro_arw=gyro_arw, accel_vrw=accel_vrw,
                      window_s=window_s)
    return runs[0] if runs else None


def gnss_speed_bound(gnss: GnssData, sel: np.ndarray, lat: float, lon: float, h: float,
                     std_floor: float = 0.0) -> tuple[float, float]:
    """Horizontal speed (m/s) of the GNSS track over the fixes ``sel`` and its 1-sigma.

    From GNSS velocity when the log has it (median), else from a straight-line fit of the
    positions against time, one fix's horizontal 1-sigma the larger of the log's and
    ``std_floor`` (m: the fixes' own scatter, :func:`~navpp.ins.calibrate.gnss_scatter_h`, for
    std columns that are optimistic).  With fewer than 3 fixes and no velocity: (0, inf).
    """
    if gnss.vel_enu is not None and sel.any():
        v = np.hypot(gnss.vel_enu[sel, 0], gnss.vel_enu[sel, 1])
        sv = float(np.mean(gnss.std_vel_enu[sel][:, :2])) if gnss.std_vel_enu is not None else 0.1
        return float(np.median(v)), sv
    idx = np.nonzero(sel)[0]
    if idx.size < 3:
        return 0.0, math.inf
    enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg[idx]), np.radians(gnss.lon_deg[idx]), gnss.alt[idx],
                                  lat, lon, h)
    tt = gnss.t[idx] - gnss.t[idx].mean()
    stt = float(np.sum(tt * tt))
    if stt <= 0:
        return 0.0, math.inf
    ve = float(np.sum(tt * enu[:, 0]) / stt)
    vn = float(np.sum(tt * enu[:, 1]) / stt)
    sp = (float(np.mean(gnss.std_enu[idx][:, :2])) if gnss.std_enu is not None else 2.0)
    return math.hypot(ve, vn), max(sp, std_floor) / math.sqrt(stt)


def _not_still(t: np.ndarray, accel: np.ndarray, gnss: GnssData, i0: int, i1: int, window_s: float = 1.0,
               max_change: float = 0.15) -> str:
    """Why samples [i0, i1) are not a still period ('' when they are).

    The mean specific force must be gravity, its 1-s means must not drift from the run's
    median by more than ``max_change`` m/s^2 (vibration averages out, a pull-away does not),
    and the GNSS fixes of every 5-s stretch must not move (speed above 0.5 m/s and
    :data:`~navpp.ins.calibrate.MOVING_K` sigma; one fix's sigma at least the scatter of the fixes
    near the run, as :func:`~navpp.ins.calibrate.gnss_speed_at` takes it: with std columns too
    small, the noise of a resting receiver's fixes would read as motion).
    """
    t0, t1 = float(t[i0]), float(t[i1 - 1])
    near = (gnss.t >= t0 - 0.5) & (gnss.t <= t1 + 0.5)
    f_mean = accel[i0:i1].mean(axis=0)
    if near.any():
        lat, lon, h = (math.radians(float(np.mean(gnss.lat_deg[near]))),
                       math.radians(float(np.mean(gnss.lon_deg[near]))), float(np.mean(gnss.alt[near])))
    else:
        lat, lon, h = math.radians(float(gnss.lat_deg[0])), 0.0, 0.0
    scatter = 0.0
    if gnss.vel_enu is None and np.count_nonzero(near) >= 12:
        enu_near = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg[near]), np.radians(gnss.lon_deg[near]),
                                           gnss.alt[near], lat, lon, h)
        scatter = gnss_scatter_h(gnss.t[near], enu_near)
    f_norm = float(np.linalg.norm(f_mean))
    if abs(f_norm - float(geodesy.gravity(lat, h))) > 0.5:
        return f"specific force {f_norm:.2f} m/s^2, not gravity"
    dt = float(np.median(np.diff(t[i0:min(i1, i0 + 1000)]))) if i1 - i0 > 1 else 1.0
    w = max(1, int(round(window_s / dt)))
    nw = (i1 - i0) // w
    if nw >= 2:
        means = accel[i0:i0 + nw * w].reshape(nw, w, 3).mean(axis=1)
        change = float(np.max(np.linalg.norm(means - np.median(means, axis=0), axis=1)))
        if change > max_change:
            return f"the specific force changes by {change:.2f} m/s^2"
    # 5 s windows from t0; only those holding a fix can show motion, so the loop visits the
    # windows of the fixes near the run (at most two each), not every window of its time span
    n_win = int(math.floor((max(t1 - 5.0, t0) + 1e-9 - t0) / 5.0)) + 1
    g = gnss.t[near]
    lo = np.clip(np.ceil((g - 5.5 - t0) / 5.0) - 1, 0, n_win - 1).astype(np.int64)
    hi = np.clip(np.floor((g + 0.5 - t0) / 5.0) + 1, 0, n_win - 1).astype(np.int64)
    cand = lo[:, None] + np.arange(4)[None, :]             # hi - lo <= 3 for a window of 6 s
    wins = np.unique(cand[cand <= hi[:, None]])
    for a in t0 + 5.0 * wins.astype(float):
        sel = near & (gnss.t >= a - 0.5) & (gnss.t <= min(a + 5.0, t1) + 0.5)
        speed, speed_std = gnss_speed_bound(gnss, sel, lat, lon, h, scatter)
        if speed > max(0.5, MOVING_K * speed_std):      # a 2-D speed: calibrate.MOVING_K
            return f"the GNSS track moves at {speed:.1f} m/s"
    return ""


def level(f_mean: np.ndarray) -> tuple[float, float]:
    """Roll and pitch (rad) from the mean specific force (body FLU) of a still period."""
    roll = math.atan2(f_mean[1], f_mean[2])
    pitch = math.atan2(f_mean[0], math.hypot(f_mean[1], f_mean[2]))
    return roll, pitch


def gyrocompass(w_mean: np.ndarray, roll: float, pitch: float) -> float:
    """Heading (rad, clockwise from north) from the mean body rate of a still period."""
    m = rph_to_dcm(roll, pitch, 0.0)       # body -> a frame levelled and pointing north
    w_l = m @ w_mean                       # Earth rate in that frame: [0, W cos L, W sin L]
    # rotating the levelled frame by heading psi: the body sees north at angle -psi
    return float(np.mod(-math.atan2(w_l[0], w_l[1]), 2 * math.pi))


def _gnss_enu(gnss: GnssData, lat0: float, lon0: float, h0: float) -> np.ndarray:
    return geodesy.geodetic_to_enu(np.radians(gnss.lat_deg), np.radians(gnss.lon_deg), gnss.alt,
                                   lat0, lon0, h0)


@dataclass(frozen=True)
class _Levelling:
    """Where the run starts and how roll and pitch were found (a step of :func:`align`).

    ``start`` the IMU sample of the start; ``still`` the still period's samples [i0, i1) (None:
    starting in motion); ``t_s0, t_s1`` its first and last sample times, s (the start time twice
    in motion); ``roll, pitch`` rad with the 1-sigma ``att_std`` rad, found by ``how``; ``w_mean``
    the still period's mean body rate, rad/s (None in motion).
    """

    start: int
    still: tuple[int, int] | None
    t_s0: float
    t_s1: float
    roll: float
    pitch: float
    att_std: float
    how: str
    w_mean: np.ndarray | None

    @property
    def moving(self) -> bool:
        return self.still is None


def _still_period(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gnss: GnssData, settings: AlignmentSettings,
                  lines: list[str]) -> tuple[int, int] | None:
    """The first still period with GNSS before the first motion, as IMU samples [i0, i1): the
    quiet runs (calibration's mask, else :func:`still_runs`), each cut to the longest prefix that
    gravity and the GNSS track confirm (:func:`_not_still`).  What was skipped goes to ``lines``."""
    first_fix = float(gnss.t[0])
    if settings.still_mask is not None:
        runs = spans(t, bridged(t, settings.still_mask, STILL_GAP_S), settings.still_min_s)
        first_motion = _first_gnss_motion(gnss)
    else:
        runs = still_runs(t, gyro, accel, min_duration=settings.still_min_s, gyro_arw=settings.gyro_arw,
                          accel_vrw=settings.accel_vrw)
        first_motion = max(float(t[0]), first_fix) + 5.0
    for i0, i1 in runs:
        t_s0, t_s1 = float(t[i0]), float(t[i1 - 1])
        if t_s1 < first_fix:
            lines.append(f"still period t = {t_s0:.2f} .. {t_s1:.2f} s not used: no GNSS fix yet")
            continue
        if t_s0 > first_motion:
            break      # the log starts in motion: a later stop would throw away all that came before
        # the IMU test is generous (vibration): a quiet run may end in a smooth pull-away.
        # Keep the longest prefix that gravity and the GNSS track confirm as still.
        why = ""
        i_end = i1
        while True:
            why = _not_still(t, accel, gnss, i0, i_end)
            if not why:
                break
            i_end = int(np.searchsorted(t, float(t[i_end - 1]) - 1.0))      # one second shorter
            if i_end <= i0 or t[i_end - 1] - t_s0 < settings.still_min_s:
                break
        if why:
            lines.append(f"quiet IMU at t = {t_s0:.2f} .. {t_s1:.2f} s is not a still period ({why})")
            continue
        if i_end < i1:
            lines.append(f"quiet IMU until t = {t_s1:.2f} s, but the vehicle moves after "
                         f"t = {float(t[i_end - 1]):.2f} s")
        if t_s0 < first_fix - 0.5:
            # GNSS starts during the still period: still fine, the vehicle has not moved
            lines.append(f"GNSS starts at t = {first_fix:.2f} s, inside the still period")
        return i0, i_end
    return None


#: Breaks in calibration's still mask up to this long (s) are bridged for the alignment: a block
#: whose +-1 s GNSS speed fit passes :data:`~navpp.ins.calibrate.MOVING_K` sigma by chance (about
#: one still block in 3000 with metre-level fixes) would break a long rest into pieces;
#: :func:`_not_still` (gravity, 5-s GNSS windows) then confirms the bridged run.
STILL_GAP_S = 5.0


def bridged(t: np.ndarray, mask: np.ndarray, max_gap_s: float) -> np.ndarray:
    """``mask`` (N,) bool with its runs of False between two True runs filled when they last at
    most ``max_gap_s`` s (from the last True sample before to the first after)."""
    out = mask.copy()
    d = np.diff(mask.astype(np.int8))
    ends = np.nonzero(d == -1)[0]          # last True sample before a break
    starts = np.nonzero(d == 1)[0] + 1     # first True sample after one
    for e in ends:
        k = int(np.searchsorted(starts, e))
        if k < starts.size and t[starts[k]] - t[e] <= max_gap_s:
            out[e:starts[k]] = True
    return out


def _levelling(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, first_fix: float, settings: AlignmentSettings,
               still: tuple[int, int] | None, lines: list[str], warnings: list[str]) -> _Levelling:
    """Roll and pitch: static levelling on the still period, else the log's mean gravity
    direction (``settings.up_b``) or level, starting in motion at the first fix; the config's
    roll and pitch when given.  Refuses a body whose z axis points down (InputError)."""
    w_mean = None
    if still is not None:
        i0, i1 = still
        t_s0, t_s1 = float(t[i0]), float(t[i1 - 1])
        lines.append(f"still period detected: t = {t_s0:.2f} .. {t_s1:.2f} s ({t_s1 - t_s0:.1f} s)")
        if i0 > 0:
            lines.append(f"IMU data before the still period (t < {t_s0:.2f} s) is not used")
        f_mean = accel[i0:i1].mean(axis=0)
        w_mean = gyro[i0:i1].mean(axis=0)
        roll, pitch = level(f_mean)
        g_est = float(np.linalg.norm(f_mean))
        att_std = math.hypot(settings.accel_bias_sigma / max(g_est, 1.0), math.radians(0.05))
        level_how = "static levelling"
        start = i0
        if max(abs(roll), abs(pitch)) > math.radians(TILT_WARN_DEG):
            warnings.append(Finding("imu-tilted", f"the IMU is tilted by roll {math.degrees(roll):+.1f} deg, "
                                    f"pitch {math.degrees(pitch):+.1f} deg at rest: "
                                    "if its axes are not forward-left-up (e.g. FRD), set [imu] mounting_rpy_deg"))
    else:
        start = min(int(np.searchsorted(t, first_fix)), len(t) - 1)
        if settings.up_b is not None:
            roll, pitch = level(np.asarray(settings.up_b, dtype=float))
            level_how = "mean gravity direction of the log"
            lines.append(f"no still period of {settings.still_min_s:.1f} s with GNSS before the first motion: "
                         f"starting in motion at t = {float(t[start]):.2f} s, levelled on the log's mean "
                         f"gravity direction (+-3 deg)")
        else:
            lines.append(f"no still period of {settings.still_min_s:.1f} s with GNSS found: starting in motion at "
                         f"t = {float(t[start]):.2f} s with roll = pitch = 0 (+-3 deg)")
            roll = pitch = 0.0
            level_how = "assumed level"
        att_std = math.radians(3.0)
        t_s0 = t_s1 = float(t[start])
    if settings.roll is not None and settings.pitch is not None:
        roll, pitch = settings.roll, settings.pitch
        level_how = "config"
        att_std = math.radians(0.5)
    elif math.cos(roll) * math.cos(pitch) < -math.sin(math.radians(TILT_WARN_DEG)):
        # the body's z axis points down (tilted beyond 90 deg plus the tilt warning's 30 deg, so a
        # y-up mounting near 90 deg stays a warning): no land vehicle runs upside down, but
        # forward-right-down axes read as forward-left-up do; the strapdown would carry the roll of
        # 180 deg and the lever arm's up component would become down (a vertical bias of twice it)
        where = (f"at rest, t = {t_s0:.1f} .. {t_s1:.1f} s" if still is not None else "on the log's mean")
        raise InputError(f"gravity is measured along -z of the declared forward-left-up body ({where}, roll "
                         f"{math.degrees(roll):+.0f} deg): the axes look forward-right-down; set [imu] "
                         f"mounting_rpy_deg = [180, 0, 0]")
    return _Levelling(start, still, t_s0, t_s1, roll, pitch, att_std, level_how, w_mean)


@dataclass(frozen=True)
class _StartFix:
    """The antenna position at the start (a step of :func:`align`): ``lat``, ``lon`` rad, ``h`` m,
    the mean of ``count`` fixes (times ``t_first .. t_last``, s), with the ENU 1-sigma of that mean
    ``std_enu`` (3,) m, one fix's 1-sigma ``fix_std`` (3,) m and the effective number of
    independent fixes per axis ``n_eff`` (3,)."""

    lat: float
    lon: float
    h: float
    std_enu: np.ndarray
    count: int
    fix_std: np.ndarray
    n_eff: np.ndarray
    t_first: float = math.nan
    t_last: float = math.nan


def effective_count(x: np.ndarray) -> float:
    """The effective number of independent samples in the evenly spaced series ``x`` (N,): N over
    the integrated autocorrelation time ``1 + 2 sum(rho_k)`` of its deviations from their mean,
    the sum cut by Geyer's (1992) initial positive sequence (pairs ``rho_2m + rho_2m+1`` summed
    while positive and decreasing); in [1, N].  White errors give about N; errors correlated over
    ``tau`` samples about ``N / (2 tau)``; errors correlated over more than the series (an offset
    the series cannot show) are caught only as far as their wander within it shows."""
    n = x.shape[0]
    if n < 4:
        return float(max(n, 1))
    d = x - x.mean()
    var = float(d @ d)
    if var <= 0.0:
        return float(n)
    m = 1 << int(2 * n - 1).bit_length()
    f = np.fft.rfft(d, m)
    rho = np.fft.irfft(f * np.conj(f), m)[:n] / var
    pairs = rho[0:n - 1:2] + rho[1:n:2]
    tau = -1.0
    prev = math.inf
    for g in pairs:
        if not g > 0.0:
            break
        g = min(float(g), prev)
        tau += 2.0 * g
        prev = g
    return float(min(max(n / max(tau, 1.0), 1.0), n))


def _start_fix(gnss: GnssData, lv: _Levelling, t_start: float) -> _StartFix:
    """The GNSS fixes of the still period averaged, else the first fix at or after the start.

    At rest every fix measures the same antenna position: the mean's 1-sigma per axis is one
    fix's (the larger of the log's sigma and the fixes' own scatter) over the square root of
    the effective number of independent fixes (:func:`effective_count`), not of their number:
    a receiver's errors are correlated over seconds to minutes."""
    if lv.moving:
        in_still = np.zeros(len(gnss), bool)
    else:
        in_still = (gnss.t >= lv.t_s0 - 1e-6) & (gnss.t <= lv.t_s1 + 1e-6)
        if not in_still.any():     # a slow receiver: the fixes just around the still period
            in_still = (gnss.t >= lv.t_s0 - 0.5) & (gnss.t <= lv.t_s1 + 0.5)
    after = np.nonzero(gnss.t >= t_start)[0]
    if not in_still.any() and after.size == 0:
        raise InputError("no GNSS fix at or after the alignment start: cannot initialise the position")
    idx = np.nonzero(in_still)[0] if in_still.any() else after[:1]
    fix_std = (np.mean(gnss.std_enu[idx], axis=0) if gnss.std_enu is not None else np.array([2.0, 2.0, 4.0]))
    lat, lon, h = (math.radians(float(np.mean(gnss.lat_deg[idx]))), math.radians(float(np.mean(gnss.lon_deg[idx]))),
                   float(np.mean(gnss.alt[idx])))
    n_eff = np.ones(3)
    std = np.asarray(fix_std, dtype=float)
    if idx.size > 1:
        enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg[idx]), np.radians(gnss.lon_deg[idx]), gnss.alt[idx],
                                      lat, lon, h)
        n_eff = np.array([effective_count(enu[:, a]) for a in range(3)])
        std = np.maximum(std, enu.std(axis=0, ddof=1)) / np.sqrt(n_eff)
    return _StartFix(lat, lon, h, std, len(idx), np.asarray(fix_std, dtype=float), n_eff, float(gnss.t[idx[0]]),
                     float(gnss.t[idx[-1]]))


def _heading(t: np.ndarray, gyro: np.ndarray, gnss: GnssData, settings: AlignmentSettings, lv: _Levelling,
             t_start: float, fix: _StartFix, lines: list[str], warnings: list[str]) -> tuple[float, float, str]:
    """(heading rad, 1-sigma rad, how it was found): the config's heading (cross-checked with the
    GNSS track), gyrocompassing when the gyro grade allows it at rest, else the GNSS track
    (:func:`_heading_from_gnss` / :func:`_heading_first_motion`; GNSS velocity checked against the
    positions)."""
    method = settings.method
    g_sigma = math.sqrt(settings.gyro_bias_sigma ** 2 + (settings.gyro_arw ** 2 / max(lv.t_s1 - lv.t_s0, 1e-3)))
    gc_std = g_sigma / (geodesy.OMEGA_E * max(math.cos(fix.lat), 1e-3))
    bias_g = np.zeros(3) if settings.gyro_bias is None else np.asarray(settings.gyro_bias, dtype=float)
    bias_g_std = (settings.gyro_bias_sigma if settings.gyro_bias_std is None
                  else float(np.max(settings.gyro_bias_std)))

    def track_heading(use_velocity: bool) -> tuple[float, float, float]:
        if settings.first_motion:
            return _heading_first_motion(t, gyro, gnss, t_start, lv.t_s1, lv.roll, lv.pitch, fix.lat,
                                         fix.lon, fix.h, fix.fix_std, settings.min_speed_mps, bias_g_std,
                                         settings.heading_floor, use_velocity=use_velocity, gyro_bias=bias_g)
        return _heading_from_gnss(t, gyro, gnss, t_start, lv.t_s1, lv.roll, lv.pitch, fix.lat, fix.lon, fix.h,
                                  fix.fix_std, settings.min_speed_mps, use_velocity=use_velocity)

    if settings.heading is not None and method in ("auto", "config"):
        heading = settings.heading
        head_std = math.radians(1.0)
        head_how = "config"
        try:      # a cross-check, not a requirement: the track may be too short
            h_trk: float | None
            h_trk, s_trk, _ = track_heading(use_velocity=False)
        except InputError:
            h_trk = None
        if h_trk is not None:
            diff = math.degrees(math.remainder(h_trk - heading, 2 * math.pi))
            if abs(diff) > max(10.0, 3.0 * math.degrees(s_trk)):
                warnings.append(f"[init] heading_deg = {math.degrees(heading):.1f} differs by {diff:+.1f} deg from the "
                                f"heading of the GNSS track ({math.degrees(h_trk):.1f} +- {math.degrees(s_trk):.1f}): "
                                "heading is clockwise from north, not a ROS yaw")
        return heading, head_std, head_how
    if method == "config":
        raise InputError("[init] method = 'config' needs heading_deg")
    if lv.w_mean is not None and (method == "gyrocompass"
                                  or (method == "auto" and gc_std < settings.gyrocompass_max_heading_std)):
        return (gyrocompass(lv.w_mean, lv.roll, lv.pitch), max(gc_std, math.radians(0.1)),
                f"gyrocompassing (predicted 1-sigma {math.degrees(gc_std):.2f} deg)")
    if method == "auto" and not lv.moving:
        lines.append(f"gyrocompassing not possible with this gyro (predicted 1-sigma "
                     f"{math.degrees(gc_std):.1f} deg): heading from the GNSS track")
    heading, head_std, t_course = track_heading(use_velocity=gnss.vel_enu is not None)
    head_how = (f"GNSS track of the first motion up to t = {t_course:.2f} s, gyro bias removed"
                if settings.first_motion
                else f"GNSS track up to t = {t_course:.2f} s, turns taken out with the gyro")
    if gnss.vel_enu is not None:
        # the velocity columns are easy to get wrong (NED, swapped, sign): check them against
        # the positions, which cannot be
        try:
            h_pos: float | None
            h_pos, s_pos, _ = track_heading(use_velocity=False)
        except InputError:
            h_pos = None
        if h_pos is not None:
            diff = math.degrees(math.remainder(heading - h_pos, 2 * math.pi))
            if abs(diff) > max(5.0, 3.0 * math.degrees(math.hypot(head_std, s_pos))):
                warnings.append(f"the course of the GNSS velocity differs by {diff:+.1f} deg from the GNSS "
                                "positions' track (are ve, vn swapped, NED or of the wrong sign?): heading "
                                "taken from the positions")
                heading, head_std = h_pos, s_pos
                head_how = "GNSS position track, turns taken out with the gyro"
    return heading, head_std, head_how


def _initial_state(gnss: GnssData, settings: AlignmentSettings, lv: _Levelling, fix: _StartFix, t_start: float,
                   heading: float, head_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Nominal (16,) and covariance (15, 15) at the start: the IMU position is the antenna fix
    less the lever arm rotated by the attitude; velocity zero at rest, from GNSS in motion;
    biases from calibration when it measured them, else zero with the configured turn-on sigma."""
    C = rph_to_dcm(lv.roll, lv.pitch, heading)
    # the GNSS fixes are of the antenna: remove the lever arm to get the IMU position
    off = C @ np.asarray(settings.lever_arm_b, dtype=float)
    rm, rn = geodesy.radii(fix.lat)
    x = np.zeros(NOMINAL_SIZE)
    x[NOMINAL_Q] = dcm_to_quat(C)
    x[X_LAT] = fix.lat - off[1] / (rm + fix.h)
    x[X_LON] = fix.lon - off[0] / ((rn + fix.h) * math.cos(fix.lat))
    x[X_H] = fix.h - off[2]
    if lv.moving:
        x[NOMINAL_VEL] = _gnss_velocity_at(gnss, t_start, fix.lat, fix.lon, fix.h)
    P = np.zeros((N_ERR, N_ERR))
    P[ATT, ATT] = np.diag([lv.att_std ** 2, lv.att_std ** 2, head_std ** 2])
    vel_std = 0.05 if not lv.moving else 1.0
    P[VEL, VEL] = np.eye(3) * vel_std ** 2
    P[POS, POS] = np.diag(fix.std_enu ** 2)
    if settings.gyro_bias is not None:
        x[NOMINAL_BG] = settings.gyro_bias
        P[BG, BG] = np.diag(np.maximum(np.asarray(settings.gyro_bias_std, dtype=float), 1e-9) ** 2)
    else:
        P[BG, BG] = np.eye(3) * max(settings.gyro_bias_sigma, 1e-9) ** 2
    if settings.accel_bias is not None:
        x[NOMINAL_BA] = settings.accel_bias
        P[BA, BA] = np.diag(np.maximum(np.asarray(settings.accel_bias_std, dtype=float), 1e-9) ** 2)
    else:
        P[BA, BA] = np.eye(3) * max(settings.accel_bias_sigma, 1e-9) ** 2
    return x, P


def align(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gnss: GnssData, settings: AlignmentSettings
          ) -> Alignment:
    """Initial nominal state and covariance (see module docstring): the still period, levelling,
    the start fix, the heading, the state."""
    lines: list[str] = []
    warnings: list[str] = []
    if len(gnss) == 0:
        raise InputError("no GNSS fixes: cannot initialise the position")
    still = _still_period(t, gyro, accel, gnss, settings, lines)
    lv = _levelling(t, gyro, accel, float(gnss.t[0]), settings, still, lines, warnings)
    t_start = float(t[lv.start])
    fix = _start_fix(gnss, lv, t_start)
    heading, head_std, head_how = _heading(t, gyro, gnss, settings, lv, t_start, fix, lines, warnings)
    x, P = _initial_state(gnss, settings, lv, fix, t_start, heading, head_std)
    lines.append(f"attitude: roll {math.degrees(lv.roll):+.2f} deg, pitch {math.degrees(lv.pitch):+.2f} deg "
                 f"({lv.how}), heading {math.degrees(heading) % 360:.1f} deg +- "
                 f"{math.degrees(head_std):.1f} ({head_how})")
    if lv.moving:
        lines.append(f"position: 1 GNSS fix; start at t = {t_start:.2f} s")
    else:
        neff = "/".join(f"{v:.0f}" for v in fix.n_eff)
        sd = "/".join(f"{v:.2f}" for v in fix.std_enu)
        lines.append(f"position: the mean of the {fix.count} GNSS fix(es) of the still period (as {neff} independent "
                     f"ones E/N/U, from their autocorrelation), 1-sigma {sd} m; start at t = {t_start:.2f} s")
    span = (fix.t_first, fix.t_last) if (not lv.moving and fix.count > 1) else None
    if span is not None:
        scale = fix.count / (fix.n_eff * (1.0 - START_SHARE))
        lines.append(f"the filter takes those fixes again, each with its variance times "
                     f"{'/'.join(f'{v:.1f}' for v in scale)} E/N/U, and starts from the mean at 1-sigma "
                     f"{'/'.join(f'{v:.2f}' for v in fix.std_enu / math.sqrt(START_SHARE))} m: each holds "
                     f"{1.0 - START_SHARE:.0%} of their information")
    return Alignment(t_start, lv.start, x, P, None if lv.moving else (lv.t_s0, lv.t_s1), tuple(lines),
                     tuple(warnings), span, fix.count, fix.n_eff)


def _gnss_velocity_at(gnss: GnssData, t0: float, lat: float, lon: float, h: float, span: float = 2.0) -> np.ndarray:
    """ENU velocity (m/s) at ``t0`` for a start in motion: the GNSS velocity nearest ``t0`` when
    the log has it, else a straight-line fit of the positions over ``[t0, t0 + span]``."""
    if gnss.vel_enu is not None:
        k = int(np.argmin(np.abs(gnss.t - t0)))
        return np.array(gnss.vel_enu[k], dtype=float)
    sel = (gnss.t >= t0 - 1e-9) & (gnss.t <= t0 + span)
    if np.count_nonzero(sel) < 2:
        k = min(max(int(np.searchsorted(gnss.t, t0)), 1), len(gnss) - 1)
        sel = np.zeros(len(gnss), bool)
        sel[k - 1:k + 1] = True
    enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg[sel]), np.radians(gnss.lon_deg[sel]), gnss.alt[sel],
                                  lat, lon, h)
    tt = gnss.t[sel] - gnss.t[sel].mean()
    vel: np.ndarray = (tt @ (enu - enu.mean(axis=0))) / float(tt @ tt)
    return vel


@dataclass(frozen=True)
class _Track:
    """The GNSS track after the still period as K displacements (:func:`_rotated_track`).

    ``tg`` (K,) fix times, s; ``dt`` (K,) s since the previous fix (or the still end); ``d``
    (K, 2) east/north displacements, m; ``t_mid`` (K,) s their middles; ``rot`` (K,) rad turned
    (counter-clockwise) since the start at each displacement's middle; ``moving`` (K,) bool;
    ``step_noise`` (K,) m per displacement from velocity (None from positions: their sum
    telescopes, only the end's noise remains, the start being the mean of the still fixes).
    """

    tg: np.ndarray
    dt: np.ndarray
    d: np.ndarray
    t_mid: np.ndarray
    rot: np.ndarray
    moving: np.ndarray
    step_noise: np.ndarray | None


def _rotated_track(t: np.ndarray, gyro: np.ndarray, gnss: GnssData, t_start: float, t_still_end: float, roll: float,
                   pitch: float, lat: float, lon: float, h: float, min_speed: float, use_velocity: bool,
                   gyro_bias: np.ndarray | None = None) -> _Track:
    """The GNSS track after the still period, as displacements, with the gyro's turn since
    ``t_start`` at each of them (shared by :func:`_heading_from_gnss` and
    :func:`_heading_first_motion`).

    Displacements come from GNSS velocity x dt when the log has it and ``use_velocity`` (zero
    below ``min_speed``), else from positions, the still position as the origin.  ``gyro_bias``
    (3,) rad/s, if given, is taken off the gyro first.  The gyro's vertical rate and its integral
    are formed block by block (:func:`~navpp.ins.calibrate.trapezoid_integral_at`): neither is
    held whole, and a spilled IMU's rows are released once read."""
    C = rph_to_dcm(roll, pitch, 0.0)
    i0 = int(np.searchsorted(t, t_start))
    ts = t[i0:]
    earth = geodesy.OMEGA_E * math.sin(lat)

    def w_up(lo: int, hi: int) -> np.ndarray:
        """The gyro's rate about the levelled vertical less the earth's, rad/s, rows lo:hi of ``ts``."""
        g = gyro[i0 + lo:i0 + hi]
        w: np.ndarray = (g if gyro_bias is None else g - gyro_bias) @ C[2]
        w -= earth
        release((gyro,), i0 + lo, i0 + hi)      # a spilled gyro's rows read: out of memory
        return w

    after = gnss.t > t_still_end
    tg = gnss.t[after]
    if tg.size == 0:
        raise InputError("no GNSS fix after the still period: cannot find the heading; give [init] heading_deg "
                         "in the config")
    prev = np.concatenate([[t_still_end], tg[:-1]])
    dt = tg - prev
    if use_velocity and gnss.vel_enu is not None:
        v = gnss.vel_enu[after]
        moving = np.hypot(v[:, 0], v[:, 1]) > min_speed
        d = v[:, :2] * dt[:, None]
        d[~moving] = 0.0
        t_mid = tg - 0.5 * dt
        std_v = float(np.mean(gnss.std_vel_enu[after][:, :2])) if gnss.std_vel_enu is not None else 0.1
        step_noise = std_v * dt          # independent per displacement
    else:
        enu = _gnss_enu(gnss, lat, lon, h)[after][:, :2]
        d = np.diff(np.vstack([np.zeros((1, 2)), enu]), axis=0)
        t_mid = 0.5 * (prev + tg)
        step_noise = None
        moving = np.hypot(d[:, 0], d[:, 1]) > min_speed * dt
    return _Track(tg, dt, d, t_mid, trapezoid_integral_at(ts, w_up, ts.shape[0], t_mid), moving, step_noise)


def _heading_from_gnss(t: np.ndarray, gyro: np.ndarray, gnss: GnssData, t_start: float, t_still_end: float,
                       roll: float, pitch: float, lat: float, lon: float, h: float, fix_std: np.ndarray,
                       min_speed: float, use_velocity: bool = True, path_length: float = 150.0,
                       min_length: float = 30.0, max_window: float = 120.0,
                       gyro_bias: np.ndarray | None = None) -> tuple[float, float, float]:
    """Heading at ``t_start`` from the GNSS track once moving, referred back with the gyro.

    Every GNSS displacement after the still period (from positions, or from GNSS velocity x dt
    when the log has it) points along the vehicle's heading at that moment (no side slip).  The
    gyro says how far the vehicle has turned since ``t_start``; rotating each displacement back
    by that angle makes them all point along the start heading, and their sum (the first
    ``path_length`` metres of driving) gives it with the noise of a ``path_length`` chord, whatever
    the turns.  With positions, the start point is the mean of the still-period fixes.
    ``use_velocity`` chooses GNSS velocity (when present) over positions; ``gyro_bias`` (3,) rad/s,
    if given, is taken off ``gyro``.
    Returns (heading rad, 1-sigma rad, time the summed track ends).
    """
    tr = _rotated_track(t, gyro, gnss, t_start, t_still_end, roll, pitch, lat, lon, h, min_speed, use_velocity,
                        gyro_bias)
    tg, d, rot, step_noise = tr.tg, tr.d, tr.rot, tr.step_noise
    # rotate each displacement back to the start heading: course + turn (complex N + iE)
    z = (d[:, 1] + 1j * d[:, 0]) * np.exp(1j * rot)
    csum = np.cumsum(z)
    reach = np.nonzero((np.abs(csum) >= path_length) | (tg - t_still_end > max_window))[0]
    k = int(reach[0]) if reach.size else len(z) - 1
    total = csum[k]
    if abs(total) < min_length:
        raise InputError(f"the vehicle never moves {min_length:.0f} m from its start in the GNSS log: cannot find "
                         "the heading; give [init] heading_deg in the config")
    heading = float(np.mod(np.angle(total), 2 * math.pi))
    if step_noise is not None:
        noise = float(np.sqrt(np.sum(step_noise[: k + 1] ** 2)))
    else:
        noise = 1.1 * float(np.mean(fix_std[:2]))      # across-track error of the end point
    std = noise / abs(total) + math.radians(0.3)
    return heading, std, float(tg[k])


def _heading_first_motion(t: np.ndarray, gyro: np.ndarray, gnss: GnssData, t_start: float, t_still_end: float,
                          roll: float, pitch: float, lat: float, lon: float, h: float, fix_std: np.ndarray,
                          min_speed: float, bias_std: float, floor: float, use_velocity: bool = True,
                          path_length: float = 60.0, min_length: float = 5.0, max_turn: float = math.radians(90.0),
                          max_window: float = 60.0, gyro_bias: np.ndarray | None = None) -> tuple[float, float, float]:
    """Heading at ``t_start`` from the GNSS track of the first motion only.

    As :func:`_heading_from_gnss` (displacements rotated back by the turn the gyro measured,
    ``gyro`` less ``gyro_bias`` (3,) rad/s, its estimated bias), but the track ends at the first GNSS gap
    (more than 3 nominal intervals), once the vehicle has turned by more than ``max_turn``
    since the start, or after ``path_length`` m.  The 1-sigma adds the bias's share, ``bias_std``
    (rad/s) times the time from the start to the middle of the track, and the floor ``floor``
    (rad: the body's x axis may not point along the motion).
    Returns (heading rad, 1-sigma rad, time the summed track ends).
    """
    tr = _rotated_track(t, gyro, gnss, t_start, t_still_end, roll, pitch, lat, lon, h, min_speed, use_velocity,
                        gyro_bias)
    tg, dt, d, t_mid, rot = tr.tg, tr.dt, tr.d, tr.t_mid, tr.rot
    moving, step_noise = tr.moving, tr.step_noise
    nominal = float(np.median(np.diff(gnss.t))) if len(gnss) > 1 else 1.0
    first = np.nonzero(moving)[0]
    if first.size == 0 or float(tg[first[0]]) - t_still_end > max_window:
        # a slow platform (a walker, a robot): moving is relative to the log's own pace
        v_all, _ = gnss_speed_at(gnss, tg)
        fast = float(np.nanpercentile(v_all, 90)) if np.isfinite(v_all).any() else 0.0
        slow = max(0.3, 0.5 * fast)
        if slow < min_speed:
            return _heading_first_motion(t, gyro, gnss, t_start, t_still_end, roll, pitch, lat, lon, h, fix_std,
                                         slow, bias_std, floor, use_velocity, path_length, min_length, max_turn,
                                         max_window, gyro_bias)
    if first.size == 0:
        raise InputError(f"the vehicle never moves faster than {min_speed:.1f} m/s in the GNSS log: cannot find "
                         "the heading; give [init] heading_deg in the config")
    rot0 = rot[first[0]]
    # the track: from the start, up to a gap, a large turn (relative to the first motion), or its length
    stop = (dt > max(3.0 * nominal, 1.0)) | (np.abs(rot - rot0) > max_turn) | (tg - t_still_end > max_window)
    stop[: first[0] + 1] &= dt[: first[0] + 1] > max(3.0 * nominal, 1.0)    # a gap before the first motion counts
    z = (d[:, 1] + 1j * d[:, 0]) * np.exp(1j * rot)
    csum = np.cumsum(z)
    end = np.nonzero(stop | (np.abs(csum) >= path_length))[0]
    k = int(end[0]) if end.size else len(z) - 1
    if stop[k] and k > 0:
        k -= 1          # the displacement across the gap or past the turn is not used
    total = csum[k]
    if abs(total) < min_length:
        # too short before a gap or a turn: the whole rotated track (bias removed), whose 1-sigma
        # carries the bias over its whole length
        heading, std, t_end = _heading_from_gnss(t, gyro, gnss, t_start, t_still_end, roll, pitch, lat, lon, h,
                                                 fix_std, min_speed, use_velocity=use_velocity, gyro_bias=gyro_bias)
        std = math.sqrt(std ** 2 + (bias_std * 0.5 * (t_end - t_start)) ** 2 + floor ** 2)
        return heading, std, t_end
    heading = float(np.mod(np.angle(total), 2 * math.pi))
    if step_noise is not None:
        noise = float(np.sqrt(np.sum(step_noise[: k + 1] ** 2)))
    else:
        noise = 1.1 * float(np.mean(fix_std[:2]))
    t_mid_track = 0.5 * (float(t_mid[first[0]]) + float(tg[k])) - t_start
    std = math.sqrt((noise / abs(total)) ** 2 + (bias_std * max(t_mid_track, 0.0)) ** 2 + floor ** 2
                    + math.radians(0.3) ** 2)
    return heading, std, float(tg[k])
