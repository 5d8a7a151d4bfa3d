"""What the engine does to the data and the configuration before the filter runs.

The mounting rotation, the noise model and the alignment's settings from the configuration;
what the log says about its own timing (stale rows, the IMU-GNSS clock offset) and sensors
(:func:`calibrated`: a gross mounting, turn-on biases the prior does not cover).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..config import DEG_PER_H_TO_RAD_PER_S, MG_TO_MPS2, PRESETS, Config
from ..findings import Finding
from ..ins.alignment import START_SHARE, Alignment, AlignmentSettings
from ..ins.attitude import rpy_deg_to_dcm
from ..ins.calibrate import rows_mean
from ..ins.model import NoiseModel
from ..ins.state import POS
from ..recording import Recording
from ..spill import like, release, windows
from .checks import check_gyro_scale
from .schedule import GnssFixes, with_prior_std


def mounting_matrix(rpy_deg: tuple[float, float, float]) -> np.ndarray:
    """Sensor -> body rotation from the mounting roll/pitch/yaw (deg, about x, y, z; ROS rpy)."""
    return rpy_deg_to_dcm(rpy_deg)


def alignment_settings(config: Config, noise=None, cal=None) -> AlignmentSettings:
    """The alignment's settings from the config, the noise in use (``noise``, an
    :class:`~navpp.config.ImuNoise`; default the config's) and what calibration measured."""
    noise = config.imu.noise() if noise is None else noise
    ini = config.init
    rad = lambda v: None if v is None else math.radians(v)  # noqa: E731
    extra = {}
    if cal is not None:
        auto = config.auto
        if auto.standstill:
            extra["still_mask"] = cal.still
        if auto.biases:
            extra.update(gyro_bias=cal.gyro_bias, gyro_bias_std=cal.gyro_bias_std, accel_bias=cal.accel_bias,
                         accel_bias_std=cal.accel_bias_std, up_b=cal.up_b)
    return AlignmentSettings(
        method=ini.method, roll=rad(ini.roll_deg), pitch=rad(ini.pitch_deg), heading=rad(ini.heading_deg),
        still_min_s=ini.still_min_s, gyrocompass_max_heading_std=math.radians(ini.gyrocompass_max_heading_std_deg),
        min_speed_mps=ini.min_speed_mps, gyro_bias_sigma=math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability),
        gyro_arw=noise.gyro_arw, accel_bias_sigma=math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability),
        accel_vrw=noise.accel_vrw, lever_arm_b=config.gnss.lever_arm_m,
        first_motion=config.auto.heading,
        heading_floor=math.radians(HEADING_FLOOR_DEG["car" if config.vehicle.type == "car" else "none"]),
        **extra)


def start_fixes(fixes: GnssFixes, al: Alignment) -> GnssFixes:
    """``fixes`` with the filter's R of a still start's averaged fixes (those at the times
    ``al.start_fixes``) scaled by ``N / (N_eff (1 - START_SHARE))`` per ENU axis: the start
    (:func:`start_covariance`) holds :data:`~navpp.ins.alignment.START_SHARE` of their
    information, the filter takes the rest; ``fixes`` itself when the start is not such a mean.
    With the Gauss-Markov GNSS error model as well: N_eff then counts the fixes' correlated
    error, which the start's tie to the error states carries
    (:meth:`navpp.ins.gnss_error.GnssErrorModel.start`)."""
    if al.start_fixes is None:
        return fixes
    t0, t1 = al.start_fixes
    inside = (fixes.t >= t0 - 1e-6) & (fixes.t <= t1 + 1e-6)
    if not inside.any():
        return fixes
    scale = np.ones((len(fixes), 3))
    scale[inside] = al.start_count / (np.asarray(al.start_n_eff, dtype=float) * (1.0 - START_SHARE))
    return replace(fixes, r_scale=scale)


def start_covariance(al: Alignment) -> np.ndarray:
    """The start covariance (15, 15): the alignment's, with a still start's position variance
    (that of the mean of the still fixes) over :data:`~navpp.ins.alignment.START_SHARE`
    (:func:`start_fixes` gives the fixes the rest)."""
    if al.start_fixes is None:
        return al.P
    P = al.P.copy()
    P[POS, POS] /= START_SHARE
    return P


def averaged_start(al: Alignment) -> tuple[float, int] | None:
    """(span s, count) of the fixes a still start's position is the mean of (None: one fix), for
    :meth:`navpp.ins.gnss_error.GnssErrorModel.start`."""
    if al.start_fixes is None:
        return None
    return al.start_fixes[1] - al.start_fixes[0], al.start_count


#: Floor of the initial heading's 1-sigma from the GNSS track, deg: the body's x axis may not point
#: along the motion (side slip; a hand-held or robot-mounted IMU turned on its mount).
HEADING_FLOOR_DEG = {"car": 1.0, "none": 5.0}


def noise_model(config: Config, noise=None) -> NoiseModel:
    """The INS's continuous noise model from the datasheet figures in ``noise`` (an
    :class:`~navpp.config.ImuNoise`; default the config's ``[imu]``)."""
    n = config.imu.noise() if noise is None else noise
    return NoiseModel.from_datasheet(n.gyro_arw, n.accel_vrw, n.gyro_bias_sigma, n.gyro_bias_instability,
                                     n.gyro_bias_tau, n.accel_bias_sigma, n.accel_bias_instability, n.accel_bias_tau)


def calibrated(recording: Recording, config: Config, gyro: np.ndarray, accel: np.ndarray, info: dict | None = None):
    """Measure the log (:func:`navpp.ins.calibrate.calibrate`) and apply what ``[auto]`` allows:
    a gross mounting (gravity not on +z) rotates the IMU; a turn-on bias prior the data
    contradict is widened (its instability with it).  Returns (gyro, accel, noise, calibration
    or None, notes, warnings)."""
    from ..ins.calibrate import calibrate, gross_mounting, matrix_to_rpy_deg

    auto = config.auto
    noise = config.imu.noise()
    if not (auto.standstill or auto.noise or auto.biases or auto.mounting):
        return gyro, accel, noise, None, [], []
    imu, gnss = recording.imu, with_prior_std(recording.gnss, config)

    def measure(g, a):
        return calibrate(imu.t, g, a, gnss, gyro_arw=noise.gyro_arw, accel_vrw=noise.accel_vrw,
                         gyro_bias_sigma=math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability),
                         accel_bias_sigma=math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability),
                         min_still_s=config.init.still_min_s)

    notes: list[str] = []
    warnings: list[Finding] = []
    cal = measure(gyro, accel)
    rot = gross_mounting(cal.up_b) if auto.mounting else None
    if rot is not None:
        gyro, accel = rotated_rows(gyro, rot), rotated_rows(accel, rot)
        total = rot @ mounting_matrix(config.imu.mounting_rpy_deg)
        up = cal.up_b
        axis = "xyz"[int(np.argmax(np.abs(up)))]
        sign = "+" if up[int(np.argmax(np.abs(up)))] > 0 else "-"
        warnings.append(Finding("gross-mounting",
                                f"{recording.source}: gravity is on the IMU's {sign}{axis} axis ({cal.up_from}), "
                                f"not +z: the IMU is rotated so that it is; write [imu] mounting_rpy_deg = "
                                f"{list(matrix_to_rpy_deg(total))} to say so (yaw is not known from gravity: "
                                "check it)"))
        cal = measure(gyro, accel)
        if info is not None:
            info["gross_mounting_rpy_deg"] = [round(float(v), 3) for v in matrix_to_rpy_deg(total)]
    notes += list(cal.notes)
    if auto.biases:
        noise, cal = widened_bias_prior(noise, cal, notes)
    if info is not None:
        info.update(cal.report())
        info["bias_prior"] = {"gyro_deg_per_h": round(noise.gyro_bias_sigma / DEG_PER_H_TO_RAD_PER_S, 3),
                              "accel_mg": round(noise.accel_bias_sigma / MG_TO_MPS2, 3)}
    return gyro, accel, noise, cal, notes, warnings


def widened_bias_prior(noise, cal, notes: list[str]):
    """The turn-on bias prior (``noise``, an :class:`~navpp.config.ImuNoise`) widened where the
    calibration ``cal`` contradicts it: the gyro's when an axis lies beyond
    :data:`~navpp.ins.calibrate.PRIOR_CONFLICT` sigmas; the accelerometers' from a still stretch,
    else to the grade the gyro biases show.  Returns (noise, cal); appends a note to ``notes``."""
    from ..ins.calibrate import PRIOR_CONFLICT

    wide_g = float(np.max(np.abs(cal.gyro_bias)))
    prior_g = math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability)
    # the test calibrate's note makes: an axis beyond PRIOR_CONFLICT sigmas of prior and estimate
    if cal.bias_from != "none" and np.any(np.abs(cal.gyro_bias)
                                          > PRIOR_CONFLICT * np.hypot(prior_g, cal.gyro_bias_std)):
        f = wide_g / max(prior_g, 1e-12)
        noise = replace(noise, gyro_bias_sigma=max(noise.gyro_bias_sigma, wide_g),
                        gyro_bias_instability=noise.gyro_bias_instability * f)
    wide_a = float(np.max(np.abs(cal.accel_bias)))
    prior_a = math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability)
    if cal.bias_from == "still" and wide_a > 3.0 * max(prior_a, float(np.min(cal.accel_bias_std))):
        f = wide_a / max(prior_a, 1e-12)
        noise = replace(noise, accel_bias_sigma=max(noise.accel_bias_sigma, wide_a),
                        accel_bias_instability=noise.accel_bias_instability * f)
    elif cal.bias_from != "still" and noise.gyro_bias_sigma > prior_g:
        # no still stretch to measure the accelerometers on, but the gyros say the IMU is of a
        # lower grade than the preset: its accelerometers are no better than that grade's
        grade = grade_for_gyro_bias(noise.gyro_bias_sigma)
        a_sigma = PRESETS[grade]["accel_bias_mg"] * MG_TO_MPS2
        if a_sigma > noise.accel_bias_sigma:
            f = a_sigma / max(noise.accel_bias_sigma, 1e-12)
            noise = replace(noise, accel_bias_sigma=a_sigma,
                            accel_bias_instability=noise.accel_bias_instability * f)
            # the filter starts its accelerometer-bias states from the calibration's 1-sigma
            cal = replace(cal, accel_bias_std=np.maximum(cal.accel_bias_std, a_sigma))
            notes.append(f"no still stretch to measure the accelerometer biases on: their prior is widened to the "
                         f"{grade} grade the gyro biases show ({PRESETS[grade]['accel_bias_mg']:g} mg 1-sigma)")
    return noise, cal


def grade_for_gyro_bias(sigma_rad_s: float) -> str:
    """The best preset whose gyro turn-on 3-sigma covers ``sigma_rad_s`` (else the lowest grade)."""
    order = sorted(PRESETS, key=lambda k: PRESETS[k]["gyro_bias_deg_per_h"])
    for name in order:
        if 3.0 * PRESETS[name]["gyro_bias_deg_per_h"] * DEG_PER_H_TO_RAD_PER_S >= sigma_rad_s:
            return name
    return order[-1]


#: A clock offset estimate is applied when it is confident, or when it departs from zero by
#: this many sigmas (the data reject "no offset" at about 99 %) with a sigma below
#: CLOCK_MAX_SIGMA_S: a latency of tenths of a second is worth metres at speed.
CLOCK_SIGMAS = 2.5
CLOCK_MAX_SIGMA_S = 0.2
#: ... and only where the gyro and the course rate agree this well (the sigma of a weak fit is not
#: to be trusted)
CLOCK_MIN_CORRELATION = 0.5


def timing_fixes(recording: Recording, config: Config,
                 info: dict | None = None) -> tuple[Recording, list[str], list[Finding]]:
    """What the IMU stamps and values say about timing (:mod:`navpp.ins.timing_estimates`):
    stale IMU rows (a logger polling faster than the sensor) are dropped; the IMU's turns are
    checked against the GNSS track's (:func:`~navpp.engine.checks.check_gyro_scale`); the
    IMU-GNSS clock offset is estimated from the gyro's yaw rate and the GNSS course rate and
    applied to the GNSS stamps when the data are sure of it (unless ``[gnss] time_offset_s`` is
    set).  Returns the recording to process, notes and warnings; ``info`` (when given) receives
    the figures for metrics.json."""
    from .. import geodesy

    notes: list[str] = []
    warnings: list[Finding] = []
    if config.auto.stale_rows and len(recording.imu) > 10:
        recording = dropped_stale_rows(recording, notes, warnings, info)
    imu, gnss = recording.imu, recording.gnss
    if len(gnss) < 20 or len(imu) < 20:
        return recording, notes, warnings
    up = rows_mean(imu.accel, [(0, len(imu))], len(imu))     # the sensor's up, as logged, block by block
    up = up / max(float(np.linalg.norm(up)), 1e-9)
    # origin at the middle fix, not the first: a first fix on the far side of the globe would mirror
    # the track in the tangent plane (the yaw-scale check would read it as lat/lon swapped)
    mid = int(np.argsort(gnss.lat_deg, kind="stable")[len(gnss) // 2])
    lat0, lon0 = math.radians(float(gnss.lat_deg[mid])), math.radians(float(gnss.lon_deg[mid]))
    enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg), np.radians(gnss.lon_deg), gnss.alt, lat0, lon0,
                                  float(gnss.alt[mid]))
    warnings += check_gyro_scale(recording, config, up, enu)
    if config.auto.clock_offset and config.gnss.time_offset_s == 0.0:
        recording = clock_offset_fixed(recording, up, enu, notes, warnings, info)
    return recording, notes, warnings


def dropped_stale_rows(recording: Recording, notes: list[str], warnings: list[Finding],
                       info: dict | None) -> Recording:
    """The recording without its stale IMU rows (:func:`navpp.ins.timing_estimates.find_stale_rows`);
    a warning when rows are dropped, a note when repeats are no more than chance.  The odometry
    and GNSS are untouched (the kept IMU rows keep their stamps)."""
    from ..ins.timing_estimates import find_stale_rows
    from ..recording import ImuData

    imu, src = recording.imu, recording.source
    stale = find_stale_rows(imu.t, imu.gyro, imu.accel)
    if info is not None:
        info["stale_rows"] = {"dropped": int(stale.count), "fraction": round(float(stale.fraction), 5),
                              "fresh_rate_hz": round(float(stale.fresh_rate_hz), 3) if stale.count else None}
    if stale.count:
        recording = replace(recording, imu=ImuData(*kept_rows(~stale.mask, imu.t, imu.gyro, imu.accel)))
        warnings.append(Finding("stale-rows-dropped",
                                f"{src}: IMU: {stale.count} stale rows ({100.0 * stale.fraction:.1f} %) repeat the "
                                f"previous row's six values under a new stamp (a logger polling faster than the "
                                f"sensor): dropped; fresh samples at {stale.fresh_rate_hz:.1f} Hz ([auto] stale_rows = "
                                f"false keeps them)"))
    elif stale.n_repeats:
        notes.append(f"IMU: {stale.n_repeats} rows repeat the previous row's values, no more than chance: kept "
                     f"({stale.reason})")
    return recording


def rotated_rows(x: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """``x @ rot.T``: the rows of ``x`` (N, 3) rotated by ``rot`` (3, 3), window by window
    (:func:`navpp.spill.windows`, the same bits), spilled as ``x`` is, the rows of both released
    as the windows pass."""
    out = like(x, x.shape[0], (3,), np.float64)
    for a, b in windows(x.shape[0], x, out):
        out[a:b] = x[a:b] @ rot.T
    return out


def kept_rows(keep: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """``[a[keep] for a in arrays]`` (``keep`` (N,) bool over the arrays' rows), window by window
    (:func:`navpp.spill.windows`): each result spilled as its array is (:func:`navpp.spill.like`),
    the rows of both released as the windows pass."""
    n_keep = int(np.count_nonzero(keep))
    out = [like(a, n_keep, a.shape[1:], a.dtype) for a in arrays]
    row = 0
    for a, b in windows(keep.shape[0], *arrays):
        sel = keep[a:b]
        k = int(np.count_nonzero(sel))
        for src, dst in zip(arrays, out):
            dst[row:row + k] = src[a:b][sel]
        release(out, row, row + k)
        row += k
    return out


def clock_offset_fixed(recording: Recording, up: np.ndarray, enu: np.ndarray, notes: list[str],
                       warnings: list[Finding], info: dict | None) -> Recording:
    """The recording with the IMU-GNSS clock offset applied to the GNSS stamps when the estimate
    (:func:`navpp.ins.timing_estimates.estimate_clock_offset`, the gyro about the sensor's ``up``
    against the course rate of the GNSS track ``enu`` (M, 3) m) is sure of it; a note otherwise.
    The odometry is on the IMU's clock (the same logger): the offset is not applied to it."""
    from ..ins.timing_estimates import estimate_clock_offset, velocity_from_positions

    imu, gnss, src = recording.imu, recording.gnss, recording.source
    if gnss.vel_enu is not None:
        vel = np.asarray(gnss.vel_enu[:, :2], dtype=float)
    else:
        vel = velocity_from_positions(gnss.t, enu[:, 0], enu[:, 1])
    ok = np.all(np.isfinite(vel), axis=1)
    try:
        est = estimate_clock_offset(imu.t, imu.gyro, gnss.t[ok], vel[ok], up=up)
    except ValueError:
        est = None
    if est is None or not math.isfinite(est.offset_s):
        notes.append("IMU-GNSS clock offset: not estimated (too little turning at speed)")
        if info is not None:
            info["clock_offset"] = {"estimated": False, "reason": "too little turning at speed"}
        return recording
    sure = est.confident or (not est.at_edge and est.consistent and est.sigma_s < CLOCK_MAX_SIGMA_S
                             and est.correlation >= CLOCK_MIN_CORRELATION
                             and abs(est.offset_s) > CLOCK_SIGMAS * est.sigma_s)
    what = (f"IMU-GNSS clock offset from the gyro's yaw rate against the GNSS course rate: the GNSS is "
            f"{-est.offset_s:+.3f} s +- {est.sigma_s:.3f} late against the IMU (correlation "
            f"{est.correlation:.2f}, {est.turn_deg:.0f} deg of turns)")
    applied = bool(sure and abs(est.offset_s) > 0.5 * est.sigma_s)
    if info is not None:
        info["clock_offset"] = {"imu_late_s": round(float(est.offset_s), 4),
                                "sigma_s": round(float(est.sigma_s), 4),
                                "correlation": round(float(est.correlation), 3),
                                "turn_deg": round(float(est.turn_deg), 1), "confident": bool(est.confident),
                                "applied": applied}
    if not applied:
        notes.append(f"{what}: not applied ({est.reason})")
        return recording
    warnings.append(Finding("clock-offset-applied",
                            f"{src}: {what}: applied to the GNSS stamps (write [gnss] time_offset_s = "
                            f"{est.offset_s:.2f} to fix it, or [auto] clock_offset = false)"))
    return replace(recording, gnss=replace(gnss, t=gnss.t + est.offset_s))
