"""Checks of the input data, before the filter runs.

Each returns :class:`~navpp.findings.Finding` warnings (a code and the line the user reads) for
faults the engine copes with, or raises :class:`~navpp.errors.InputError` for data that cannot
be processed as configured (a unit or axis mistake that would become a wrong trajectory).
Times in messages are s relative to the recording's first IMU stamp.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config
from ..errors import InputError
from ..findings import Finding
from ..ins.model import LONG_GAP_PERIODS
from ..intervals import interval_median, long_intervals
from ..recording import Recording
from ..spill import windows


def check_imu_plausible(recording: Recording) -> list[Finding]:
    """Catch unit and column mistakes before they become a wrong trajectory.

    Raises InputError when the median specific force is far from gravity (e.g. an
    accelerometer in g read as m/s^2); returns warnings for gyro rates no land vehicle turns at
    (e.g. deg/s read as rad/s).
    """
    imu = recording.imu
    step = max(1, len(imu) // 20000)          # a subsample says as much, without full-length temporaries
    f = float(np.median(np.linalg.norm(every(imu.accel, step), axis=1)))
    if not 3.0 < f < 30.0:
        hint = ('are the accelerometer values in g? set [imu] accel_units = "g"' if 0.3 < f < 3.0
                else "check the accelerometer columns and their units")
        raise InputError(f"{recording.source}: the median specific force is {f:.3g} m/s^2, not about 9.8: {hint}")
    w = float(np.percentile(np.linalg.norm(every(imu.gyro, step), axis=1), 99.0))
    warnings = []
    if w > 5.0:
        warnings.append(Finding("gyro-rate-high",
                                f"{recording.source}: gyro rates reach {w:.1f} rad/s ({np.degrees(w):.0f} deg/s) "
                                'in the top percentile: if the gyro is in deg/s, set [imu] gyro_units = "deg/s"'))
    return warnings


def every(rows: np.ndarray, step: int) -> np.ndarray:
    """A copy of ``rows[::step]`` (``rows`` (N, ...)), taken window by window
    (:func:`navpp.spill.windows`): of a spilled ``rows`` only a window's pages are resident at a
    time (a subsample's rows further apart than a page touch every page of the whole)."""
    parts = [rows[lo + (-lo) % step:hi:step].copy() for lo, hi in windows(rows.shape[0], rows)]
    return np.concatenate(parts) if parts else rows[:0].copy()


#: Saturation: a channel whose extreme value is held for this many consecutive samples.
SATURATION_RUN = 3
#: ... and only when that extreme is physically large (rad/s, m/s^2): a noise-free or coarse
#: IMU at rest legitimately repeats small values.
SATURATION_FLOOR = {"gyro": 1.0, "accel": 15.0}


def t_text(t: float) -> str:
    """A time for a message: ``t = 12.345 s``."""
    return f"t = {t:.3f} s"


def imu_gaps(source: str, t: np.ndarray) -> list[Finding]:
    """One warning line for IMU intervals longer than
    :data:`navpp.ins.model.LONG_GAP_PERIODS` nominal periods: the strapdown integrates across
    them with their true length and the model adds the unseen motion to the covariance
    (:meth:`navpp.ins.model.InsModel.gap_noise`), but the user must know where they are."""
    if t.shape[0] < 3:
        return []
    nominal = interval_median(t)
    long_ = long_intervals(t, LONG_GAP_PERIODS * nominal)
    if long_.size == 0:
        return []
    gap = t[long_ + 1] - t[long_]           # the long intervals, s
    k0, kmax = int(long_[0]), int(long_[np.argmax(gap)])
    n = long_.size
    line = (f"{source}: IMU: {n} gap{'s' if n > 1 else ''} longer than {LONG_GAP_PERIODS:g} periods "
            f"({LONG_GAP_PERIODS * nominal:.3g} s), {float(gap.sum()):.3g} s in all: first at "
            f"{t_text(float(t[k0]))} ({float(gap[0]):.3g} s), longest at {t_text(float(t[kmax]))} "
            f"({float(gap.max()):.3g} s); integrated across with the true interval, the unseen motion added to "
            "the uncertainty")
    return [Finding("imu-gap", line)]



def saturation(source: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
               gyro_range: float | None, accel_range: float | None) -> list[Finding]:
    """Warn about IMU channels that look clipped.

    A sample is suspect when its channel sits at the channel's extreme value (max or min over
    the log, at least :data:`SATURATION_FLOOR` in magnitude) for at least
    :data:`SATURATION_RUN` consecutive samples, or when ``|value|`` reaches a configured range
    (rad/s for the gyro, m/s^2 for the accelerometer; None: not checked).  The filter still
    uses those samples (there is nothing better to use), so the warning says where the
    solution is not to be trusted.
    """
    out = []
    for name, data, rng in (("gyro", gyro, gyro_range), ("accel", accel, accel_range)):
        n = data.shape[0]
        flag = np.zeros(n, bool)
        for axis in range(3):       # window by window: a spilled IMU's pages released behind
            v = data[:, axis]
            ends = np.array([(v[a:b].max(), v[a:b].min()) for a, b in windows(n, data)]).reshape(-1, 2)
            for ext in (float(ends[:, 0].max()), float(ends[:, 1].min())):
                if abs(ext) < SATURATION_FLOOR[name]:
                    continue
                at = np.empty(n, bool)
                for a, b in windows(n, data):
                    np.equal(v[a:b], ext, out=at[a:b])
                # runs of >= SATURATION_RUN: a sample and its SATURATION_RUN - 1 successors all at ext
                run = at.copy()
                for j in range(1, SATURATION_RUN):
                    run[:-j] &= at[j:]
                    run[-j:] = False
                if run.any():
                    for j in range(SATURATION_RUN):     # mark the whole run, not only its starts
                        flag[j:] |= run[:data.shape[0] - j]
            if rng is not None:
                for a, b in windows(n, data):
                    flag[a:b] |= np.abs(v[a:b]) >= rng
        if flag.any():
            idx = np.nonzero(flag)[0]
            unit = "rad/s" if name == "gyro" else "m/s^2"
            out.append(Finding(
                "imu-saturated",
                f"{source}: IMU {name}: {idx.size} sample{'s' if idx.size > 1 else ''} look saturated "
                f"(held at the extreme value{' or beyond the configured range' if rng is not None else ''}, "
                f"up to {float(np.abs(data[idx]).max()):.4g} {unit}) from {t_text(float(t[idx[0]]))} to "
                f"{t_text(float(t[idx[-1]]))}: the solution around them is not to be trusted"))
    return out


def overlap(source: str, t_imu: np.ndarray, t_gnss: np.ndarray) -> list[Finding]:
    """One line when the IMU and GNSS spans only partly overlap: only the overlap is GNSS-aided;
    IMU time before the first fix waits for it (alignment), IMU time after the last fix is
    free inertial (its uncertainty grows), fixes outside the IMU span are ignored."""
    if t_gnss.size == 0:
        return []
    i0, i1, g0, g1 = float(t_imu[0]), float(t_imu[-1]), float(t_gnss[0]), float(t_gnss[-1])
    nominal = float(np.median(np.diff(t_gnss))) if t_gnss.size > 1 else 1.0
    tol = max(2.0 * nominal, 1.0)           # a fix or two missing at either end is not worth a line
    if abs(g0 - i0) <= tol and abs(g1 - i1) <= tol:
        return []
    lo, hi = max(i0, g0), min(i1, g1)
    notes = []
    if lo - i0 > tol:
        notes.append(f"no fix for the first {lo - i0:.1f} s of IMU")
    if i1 - hi > tol:
        notes.append(f"the last {i1 - hi:.1f} s of IMU are free inertial")
    outside = int(np.count_nonzero((t_gnss < i0) | (t_gnss > i1)))
    if outside:
        notes.append(f"{outside} fix{'es' if outside > 1 else ''} outside the IMU span ignored")
    if not notes:
        return []
    return [Finding("spans-partly-overlap",
                    f"{source}: the IMU ({t_text(i0)} .. {i1:.3f} s) and GNSS ({t_text(g0)} .. {g1:.3f} s) only "
                    f"partly overlap: GNSS-aided {lo:.3f} .. {hi:.3f} s; " + "; ".join(notes))]


def check_data(recording: Recording, config: Config | None = None) -> list[Finding]:
    """Data faults the engine copes with but the user must hear of, one line each, with times.

    IMU gaps longer than :data:`~navpp.ins.model.LONG_GAP_PERIODS` periods, saturated IMU channels (see
    :func:`saturation`; ranges from ``[imu] gyro_range_rps`` / ``accel_range_mps2`` when the
    configuration has them), and IMU / GNSS spans that only partly overlap.  Times are s
    relative to the recording's first IMU stamp.
    """
    imu = recording.imu
    src = recording.source
    gyro_range = None if config is None else config.imu.gyro_range_rps
    accel_range = None if config is None else config.imu.accel_range_mps2
    out = imu_gaps(src, imu.t)
    out += saturation(src, imu.t, imu.gyro, imu.accel, gyro_range, accel_range)
    out += overlap(src, imu.t, recording.gnss.t)
    return out




#: The gyro's yaw rate against the GNSS course rate: a fit this well correlated over this many
#: degrees of GNSS turning measures the gyro's scale; outside these bounds it is not a tilt
#: (cos 53 deg = 0.6; the chord courses read about 0.9 on a steady drive) but the wrong unit
#: or axis.
GYRO_SCALE_CORRELATION = 0.7
GYRO_SCALE_TURN_DEG = 90.0
GYRO_SCALE_BOUNDS = (0.6, 1.6)
#: beyond this factor either way a gyro scale is refused: every turn's heading would be off by at
#: least three times the turn itself, which no filter corrects into a right trajectory (between
#: the warning bounds and this, the filter's gate and divergence checks decide)
GYRO_SCALE_REFUSE = 4.0


def check_gyro_scale(recording: Recording, config: Config, up_s: np.ndarray, enu: np.ndarray) -> list[Finding]:
    """The gyro's turns against the GNSS track's (:func:`navpp.ins.timing_estimates.yaw_scale_from_track`):
    raise InputError when the ratio says the gyro's values are in the wrong unit (1/57.3: deg/s
    read as rad/s) or are off by more than :data:`GYRO_SCALE_REFUSE` either way; warn when it is
    otherwise far from 1 (a wrong axis, a bad scale)."""
    from ..ins.timing_estimates import yaw_scale_from_track

    imu, gnss, source = recording.imu, recording.gnss, recording.source
    std_h = np.hypot(gnss.std_enu[:, 0], gnss.std_enu[:, 1]) / math.sqrt(2.0) if gnss.std_enu is not None else 0.0
    est = yaw_scale_from_track(imu.t, imu.gyro, gnss.t, enu[:, 0], enu[:, 1], std_h, up=up_s)
    lo, hi = GYRO_SCALE_BOUNDS
    if (math.isfinite(est.scale) and -hi <= est.scale <= -lo and est.correlation <= -GYRO_SCALE_CORRELATION
            and est.gnss_turn_deg >= GYRO_SCALE_TURN_DEG):
        # the track turns the other way at the gyro's rate: a mirror image, as lat and lon swapped
        # make it (east and north exchanged); the gyro's up is measured from the accelerometers,
        # so an IMU that is upside down or forward-right-down does not do this
        from ..plausibility import gnss_name

        raise InputError(f"{source}: the GNSS track turns the other way from the gyro (ratio {est.scale:.2f}, "
                         f"correlation {est.correlation:.2f} over {est.gnss_turn_deg:.0f} deg): are lat and lon "
                         f"swapped in {gnss_name(source)}? (else a reversed gyro axis)")
    scale = abs(est.scale) if math.isfinite(est.scale) else float("nan")
    if not (math.isfinite(scale) and scale > 0 and math.isfinite(est.correlation)
            and est.correlation >= GYRO_SCALE_CORRELATION and est.gnss_turn_deg >= GYRO_SCALE_TURN_DEG):
        return []
    if lo <= scale <= hi:
        return []
    what = (f"the GNSS track turns {scale:.3g} x as much as the gyro measures about the vertical "
            f"(correlation {est.correlation:.2f} over {est.gnss_turn_deg:.0f} deg of turns)")
    deg = math.degrees(1.0)
    unit = config.imu.gyro_units
    if abs(math.log(scale * deg)) < math.log(1.2):
        hint = ('the gyro is in deg/s: set [imu] gyro_units = "deg/s"' if unit != "deg/s"
                else "check [imu] gyro_units")
    elif abs(math.log(scale / deg)) < math.log(1.2):
        hint = ('the gyro is in rad/s: set [imu] gyro_units = "rad/s"' if unit == "deg/s"
                else "check [imu] gyro_units")
    elif 1.0 / GYRO_SCALE_REFUSE <= scale <= GYRO_SCALE_REFUSE:
        return [Finding("gyro-scale",
                        f"{source}: {what}: check the gyro columns and their axes ([imu] mounting_rpy_deg)")]
    else:       # the short form: the message stays one line
        what = f"the GNSS track turns {scale:.3g} x as much as the gyro measures (correlation {est.correlation:.2f})"
        hint = (f"the gyro reads {1.0 / scale:.3g} x the turns: check the gyro columns' unit and scale "
                "([imu] gyro_units)")
    raise InputError(f"{source}: {what}: {hint}")



def alignment_findings(warnings: tuple[str, ...] | list[str]) -> list[Finding]:
    """The alignment's warnings (:attr:`navpp.ins.alignment.Alignment.warnings`) as findings: a
    :class:`~navpp.findings.Finding` (e.g. ``"imu-tilted"``) passes as it is; a plain line gets the
    code ``""``."""
    return [w if isinstance(w, Finding) else Finding("", w) for w in warnings]
