"""The replay engine: the only code that knows time.

Merges IMU and GNSS on the recording's relative time axis, aligns, then for every GNSS
epoch inside the IMU span: predicts through the IMU samples up to the exact epoch (the IMU
is interpolated to it), builds the GNSS measurement (lever arm, per-epoch std or the config
default), and lets the filter gate and apply it.  Closed-loop feedback happens inside the
filter's ``correct`` (``x ⊞ K nu``).  The nominal state at every IMU sample is recorded by the
model; position 1-sigma at each sample interpolates the variance between the posterior of the
previous epoch and the prior of the next.
"""

from __future__ import annotations

import math
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from .aiding import Aiding
from .config import DEG_PER_H_TO_RAD_PER_S, MG_TO_MPS2, PRESETS, Config
from .errors import FilterDivergedError, InputError
from .filters.base import Filter, GaussianState
from .filters.smoother import ForwardStore, smooth_arrays
from .gnss_jumps import check_gnss_jumps
from .ins.alignment import Alignment, AlignmentSettings, align
from .ins.attitude import rpy_deg_to_dcm
from .ins.model import (
    ATT,
    BA,
    BG,
    LONG_GAP_PERIODS,
    POS,
    VEL,
    GnssPosition,
    InsModel,
    NoiseModel,
    apply_node_corrections,
)
from .ins.strapdown import NOMINAL_BA, NOMINAL_BG
from .recording import Recording, Solution

ProgressFn = Callable[[float], None]   # called with the fraction done, 0..1
KNOT_S = 1.0    # longest stretch without a covariance knot for the output sigma, s


@dataclass(frozen=True)
class Diagnostics:
    """Per-GNSS-epoch record of what the filter saw: t (s), innovation nu (M, 3) ENU m,
    NIS, accepted flag, forced flag (accepted after a run of rejections), and the 1-sigma of the
    measurement noise the filter used, r_std (M, 3) m (what an adaptive filter decided).
    ``adaptive`` holds the rest of what an adaptive filter decided after each epoch (its
    :meth:`~navpp.filters.base.Filter.noise_report`, e.g. VCE's process-noise group factors):
    name -> (M, k) array."""

    t: np.ndarray
    nu: np.ndarray
    nis: np.ndarray
    accepted: np.ndarray
    forced: np.ndarray
    r_std: np.ndarray
    adaptive: dict[str, np.ndarray] = field(default_factory=dict)
    vel_nu: np.ndarray | None = None          # (M, 3) GNSS velocity innovation, ENU m/s (NaN: none)
    vel_nis: np.ndarray | None = None         # (M,) its NIS
    vel_accepted: np.ndarray | None = None    # (M,) 1 applied, 0 rejected, NaN no velocity


@dataclass(frozen=True)
class BiasHistory:
    """Estimated sensor biases after each GNSS epoch and their 1-sigma: t (M,) s; gyro and
    gyro_std (M, 3) rad/s; accel and accel_std (M, 3) m/s^2; body FLU.  Constant between epochs."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    gyro_std: np.ndarray
    accel_std: np.ndarray


@dataclass(frozen=True)
class SmoothedRun:
    """The forward run smoothed backwards (Rauch-Tung-Striebel, :mod:`navpp.filters.smoother`).

    solution : IMU-rate smoothed solution with smoothed position 1-sigma.
    biases : smoothed sensor biases at the GNSS epochs (same epochs as the forward history).
    runtime_s : wall time of the backward pass and the IMU-rate corrections, s.
    nodes : forward nodes stored (GNSS epochs plus coast knots plus the start and end).
    breaks : forced (re-anchored) fixes the smoother did not carry information back across,
        plus steps whose prior covariance was not positive definite.
    store_mb : memory the stored forward run took, MB.
    """

    solution: Solution
    biases: BiasHistory
    runtime_s: float
    nodes: int
    breaks: int
    store_mb: float


@dataclass(frozen=True)
class RunResult:
    solution: Solution
    biases: BiasHistory
    alignment: Alignment
    diagnostics: Diagnostics
    gnss_epochs: int
    gnss_rejected: int
    runtime_s: float                  # processing wall time, s, without kernel compilation (smoothing included)
    compile_s: float = 0.0            # one-off numba compilation on a cold cache, s
    warnings: tuple[str, ...] = ()    # what the run noticed about the data (units, tilt, gating)
    smoothed: SmoothedRun | None = None   # with smooth=True: the RTS-smoothed run
    notes: tuple[str, ...] = ()       # what the run decided (e.g. the estimated vehicle mounting)
    #: updates applied / rejected by the gate per kind: gnss_position, gnss_velocity, zupt, zaru, nhc
    updates: dict[str, dict[str, int]] = field(default_factory=dict)
    #: what the run measured from the log itself (``[auto]``), plain numbers for metrics.json:
    #: standstill, biases, noise, gravity axis, mounting, stale rows, clock offset, recoveries
    calibration: dict = field(default_factory=dict)

    @property
    def forward_runtime_s(self) -> float:
        """Processing time of the forward filter alone, s (``runtime_s`` without the smoothing)."""
        return self.runtime_s - (self.smoothed.runtime_s if self.smoothed is not None else 0.0)


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


#: Floor of the initial heading's 1-sigma from the GNSS track, deg: the body's x axis may not point
#: along the motion (side slip; a hand-held or robot-mounted IMU turned on its mount).
HEADING_FLOOR_DEG = {"car": 1.0, "none": 5.0}


def noise_model(config: Config, noise=None) -> NoiseModel:
    n = config.imu.noise() if noise is None else noise
    return NoiseModel.from_datasheet(n.gyro_arw, n.accel_vrw, n.gyro_bias_sigma, n.gyro_bias_instability,
                                     n.gyro_bias_tau, n.accel_bias_sigma, n.accel_bias_instability, n.accel_bias_tau)


def _calibrated(recording: Recording, config: Config, gyro: np.ndarray, accel: np.ndarray, info: dict | None = None):
    """Measure the log (:func:`navpp.ins.calibrate.calibrate`) and apply what ``[auto]`` allows:
    a gross mounting (gravity not on +z) rotates the IMU; a turn-on bias prior the data
    contradict is widened (its instability with it).  Returns (gyro, accel, noise, calibration
    or None, notes, warnings)."""
    from dataclasses import replace as dc_replace

    from .ins.calibrate import PRIOR_CONFLICT, calibrate, gross_mounting, matrix_to_rpy_deg

    auto = config.auto
    noise = config.imu.noise()
    if not (auto.standstill or auto.noise or auto.biases or auto.mounting):
        return gyro, accel, noise, None, [], []
    imu, gnss = recording.imu, recording.gnss

    def measure(g, a):
        return calibrate(imu.t, g, a, gnss, gyro_arw=noise.gyro_arw, accel_vrw=noise.accel_vrw,
                         gyro_bias_sigma=math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability),
                         accel_bias_sigma=math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability),
                         min_still_s=config.init.still_min_s)

    notes: list[str] = []
    warnings: list[str] = []
    cal = measure(gyro, accel)
    rot = gross_mounting(cal.up_b) if auto.mounting else None
    if rot is not None:
        gyro, accel = gyro @ rot.T, accel @ rot.T
        total = rot @ mounting_matrix(config.imu.mounting_rpy_deg)
        up = cal.up_b
        axis = "xyz"[int(np.argmax(np.abs(up)))]
        sign = "+" if up[int(np.argmax(np.abs(up)))] > 0 else "-"
        warnings.append(f"{recording.source}: gravity is on the IMU's {sign}{axis} axis ({cal.up_from}), not +z: "
                        f"the IMU is rotated so that it is; write [imu] mounting_rpy_deg = "
                        f"{list(matrix_to_rpy_deg(total))} to say so (yaw is not known from gravity: check it)")
        cal = measure(gyro, accel)
        if info is not None:
            info["gross_mounting_rpy_deg"] = [round(float(v), 3) for v in matrix_to_rpy_deg(total)]
    notes += list(cal.notes)
    if auto.biases:
        wide_g = float(np.max(np.abs(cal.gyro_bias)))
        prior_g = math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability)
        # the test calibrate's note makes: an axis beyond PRIOR_CONFLICT sigmas of prior and estimate
        if cal.bias_from != "none" and np.any(np.abs(cal.gyro_bias)
                                              > PRIOR_CONFLICT * np.hypot(prior_g, cal.gyro_bias_std)):
            f = wide_g / max(prior_g, 1e-12)
            noise = dc_replace(noise, gyro_bias_sigma=max(noise.gyro_bias_sigma, wide_g),
                               gyro_bias_instability=noise.gyro_bias_instability * f)
        wide_a = float(np.max(np.abs(cal.accel_bias)))
        prior_a = math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability)
        if cal.bias_from == "still" and wide_a > 3.0 * max(prior_a, float(np.min(cal.accel_bias_std))):
            f = wide_a / max(prior_a, 1e-12)
            noise = dc_replace(noise, accel_bias_sigma=max(noise.accel_bias_sigma, wide_a),
                               accel_bias_instability=noise.accel_bias_instability * f)
        elif cal.bias_from != "still" and noise.gyro_bias_sigma > prior_g:
            # no still stretch to measure the accelerometers on, but the gyros say the IMU is of a
            # lower grade than the preset: its accelerometers are no better than that grade's
            grade = _grade_for_gyro_bias(noise.gyro_bias_sigma)
            a_sigma = PRESETS[grade]["accel_bias_mg"] * MG_TO_MPS2
            if a_sigma > noise.accel_bias_sigma:
                f = a_sigma / max(noise.accel_bias_sigma, 1e-12)
                noise = dc_replace(noise, accel_bias_sigma=a_sigma,
                                   accel_bias_instability=noise.accel_bias_instability * f)
                # the filter starts its accelerometer-bias states from the calibration's 1-sigma
                cal = dc_replace(cal, accel_bias_std=np.maximum(cal.accel_bias_std, a_sigma))
                notes.append(f"no still stretch to measure the accelerometer biases on: their prior is widened to the "
                             f"{grade} grade the gyro biases show ({PRESETS[grade]['accel_bias_mg']:g} mg 1-sigma)")
    if info is not None:
        info.update(cal.report())
        info["bias_prior"] = {"gyro_deg_per_h": round(noise.gyro_bias_sigma / DEG_PER_H_TO_RAD_PER_S, 3),
                              "accel_mg": round(noise.accel_bias_sigma / MG_TO_MPS2, 3)}
    return gyro, accel, noise, cal, notes, warnings


def _grade_for_gyro_bias(sigma_rad_s: float) -> str:
    """The best preset whose gyro turn-on 3-sigma covers ``sigma_rad_s`` (else the lowest grade)."""
    order = sorted(PRESETS, key=lambda k: PRESETS[k]["gyro_bias_deg_per_h"])
    for name in order:
        if 3.0 * PRESETS[name]["gyro_bias_deg_per_h"] * DEG_PER_H_TO_RAD_PER_S >= sigma_rad_s:
            return name
    return order[-1]


def run(recording: Recording, config: Config, filt: Filter, *, progress: ProgressFn | None = None,
        cov_step_s: float = 0.05, smooth: bool = False) -> RunResult:
    """Process one recording with one filter; returns the IMU-rate solution and diagnostics.

    With ``smooth``, the forward run is also smoothed backwards (Rauch-Tung-Striebel over the
    stored forward run): ``RunResult.smoothed``; ``solution`` stays the forward solution.
    ``runtime_s`` excludes the one-off compilation of navpp's kernels on a cold cache, which
    is reported as ``compile_s``.
    """
    from numba.core import event as numba_event

    t_wall = time.perf_counter()
    with numba_event.install_recorder("numba:compile") as rec:
        segments = imu_segments(recording)
        if len(segments) > 1:
            result = _run_segments(recording, segments, config, filt, progress, cov_step_s, smooth)
        else:
            result = _run(recording, config, filt, progress, cov_step_s, smooth)
    compile_s = _top_level_duration(rec.buffer)
    return replace(result, runtime_s=time.perf_counter() - t_wall - compile_s, compile_s=compile_s)


def _top_level_duration(events) -> float:
    """Seconds covered by outermost START..END pairs of numba compile events."""
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


def check_imu_plausible(recording: Recording) -> list[str]:
    """Catch unit and column mistakes before they become a wrong trajectory.

    Raises InputError when the median specific force is far from gravity (e.g. an
    accelerometer in g read as m/s^2); returns warnings for gyro rates no land vehicle turns at
    (e.g. deg/s read as rad/s).
    """
    imu = recording.imu
    step = max(1, len(imu) // 20000)          # a subsample says as much, without full-length temporaries
    f = float(np.median(np.linalg.norm(imu.accel[::step], axis=1)))
    if not 3.0 < f < 30.0:
        hint = ('are the accelerometer values in g? set [imu] accel_units = "g"' if 0.3 < f < 3.0
                else "check the accelerometer columns and their units")
        raise InputError(f"{recording.source}: the median specific force is {f:.3g} m/s^2, not about 9.8: {hint}")
    w = float(np.percentile(np.linalg.norm(imu.gyro[::step], axis=1), 99.0))
    warnings = []
    if w > 5.0:
        warnings.append(f"{recording.source}: gyro rates reach {w:.1f} rad/s ({np.degrees(w):.0f} deg/s) in the top "
                        'percentile: if the gyro is in deg/s, set [imu] gyro_units = "deg/s"')
    return warnings


#: Saturation: a channel whose extreme value is held for this many consecutive samples.
SATURATION_RUN = 3
#: ... and only when that extreme is physically large (rad/s, m/s^2): a noise-free or coarse
#: IMU at rest legitimately repeats small values.
SATURATION_FLOOR = {"gyro": 1.0, "accel": 15.0}


def _t_text(t: float) -> str:
    return f"t = {t:.3f} s"


def _imu_gaps(source: str, t: np.ndarray) -> list[str]:
    """One warning line for IMU intervals longer than
    :data:`navpp.ins.model.LONG_GAP_PERIODS` nominal periods: the strapdown integrates across
    them with their true length and the model adds the unseen motion to the covariance
    (:meth:`navpp.ins.model.InsModel.gap_noise`), but the user must know where they are."""
    if t.shape[0] < 3:
        return []
    dt = np.diff(t)
    nominal = float(np.median(dt))
    long_ = np.nonzero(dt > LONG_GAP_PERIODS * nominal)[0]
    if long_.size == 0:
        return []
    k0, kmax = int(long_[0]), int(long_[np.argmax(dt[long_])])
    n = long_.size
    line = (f"{source}: IMU: {n} gap{'s' if n > 1 else ''} longer than {LONG_GAP_PERIODS:g} periods "
            f"({LONG_GAP_PERIODS * nominal:.3g} s), {float(dt[long_].sum()):.3g} s in all: first at "
            f"{_t_text(float(t[k0]))} ({float(dt[k0]):.3g} s), longest at {_t_text(float(t[kmax]))} "
            f"({float(dt[kmax]):.3g} s); integrated across with the true interval, the unseen motion added to "
            "the uncertainty")
    return [line]


def imu_segments(recording: Recording) -> list[tuple[int, int]]:
    """The IMU rows cut at every gap longer than the INS can bridge
    (:func:`navpp.ins.model.max_bridgeable_gap_s`, 10.5 s: the motion unseen over it leaves the
    attitude unknown, and integrating across it would write a free-inertial stretch, an hour's
    gap thousands of km off).  Returns ``[(i0, i1), ...]``, half-open row ranges in time order;
    one range covering every row when there is no such gap.

    Each range is processed as a log of its own (:func:`run`): aligned afresh from its own data,
    no row written inside a gap.  Inside a range the IMU's time span is bounded by its sample
    count (at most one bridgeable gap per sample), so no loop over time can run away.
    """
    from .ins.model import max_bridgeable_gap_s

    t = recording.imu.t
    n = int(t.shape[0])
    if n < 2:
        return [(0, n)]
    cuts = np.flatnonzero(np.diff(t) > max_bridgeable_gap_s()) + 1
    edges = [0, *cuts.tolist(), n]
    return [(edges[k], edges[k + 1]) for k in range(len(edges) - 1)]


def _rows(obj, keep: np.ndarray):
    """A copy of the dataclass ``obj`` with the rows ``keep`` (bool mask or indices) of every array
    field whose first dimension is the length of ``obj.t`` (None fields stay None)."""
    from dataclasses import fields

    n = obj.t.shape[0]
    out = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
            out[f.name] = v[keep]
    return replace(obj, **out)


def _segment(recording: Recording, i0: int, i1: int) -> Recording:
    """The recording restricted to IMU rows ``[i0, i1)`` and the fixes and reference epochs inside
    their time span (same time base, same ``t0_ns``)."""
    t = recording.imu.t
    a, b = float(t[i0]), float(t[i1 - 1])
    imu = _rows(recording.imu, slice(i0, i1))
    gnss = _rows(recording.gnss, (recording.gnss.t >= a) & (recording.gnss.t <= b))
    ref = recording.reference
    if ref is not None:
        ref = _rows(ref, (ref.t >= a) & (ref.t <= b))
    return replace(recording, imu=imu, gnss=gnss, reference=ref)


def _concat(parts: list, cls):
    """One ``cls`` dataclass from ``parts`` of it, row-wise: array fields concatenated (a field
    None in some parts and not in others is filled with NaN rows there), dict-of-array fields
    concatenated per key, other fields taken from the first part."""
    from dataclasses import fields

    out = {}
    for f in fields(cls):
        vals = [getattr(p, f.name) for p in parts]
        ref = next((v for v in vals if v is not None), None)
        if isinstance(ref, np.ndarray):
            rows = [p.t.shape[0] for p in parts]
            out[f.name] = np.concatenate([v if v is not None else np.full((r, *ref.shape[1:]), np.nan)
                                          for v, r in zip(vals, rows)])
        elif isinstance(ref, dict) and all(isinstance(v, dict) for v in vals) and \
                all(isinstance(x, np.ndarray) for v in vals for x in v.values()):
            keys = [k for k in ref if all(k in v for v in vals)]
            out[f.name] = {k: np.concatenate([v[k] for v in vals]) for k in keys}
        else:
            out[f.name] = ref
    return cls(**out)


def _run_segments(recording: Recording, segments: list[tuple[int, int]], config: Config, filt: Filter,
                  progress: ProgressFn | None, cov_step_s: float, smooth: bool) -> RunResult:
    """Process each IMU segment (:func:`imu_segments`) as a log of its own and join the results in
    time order: the trajectory has no row inside a gap, the metrics skip the gaps
    (:func:`navpp.metrics.associate`).  A segment that cannot be processed on its own (too short to
    align, no fix in it) is left out with a warning naming its span; a divergence stops the run.
    Every segment starts from a fresh copy of ``filt``."""
    import copy

    from .ins.model import max_bridgeable_gap_s

    t = recording.imu.t
    n = float(t.shape[0])
    gaps = [(float(t[i0 - 1]), float(t[i0] - t[i0 - 1])) for i0, _ in segments[1:]]
    shown = ", ".join(f"{g:.4g} s after t = {a:.3f} s" for a, g in gaps[:3]) + (
        f" and {len(gaps) - 3} more" if len(gaps) > 3 else "")
    head = (f"{recording.source}: IMU gap{'s' if len(gaps) > 1 else ''} of {shown}: longer than the INS can "
            f"bridge ({max_bridgeable_gap_s():.3g} s, the unseen motion leaves the attitude unknown): "
            f"the log is processed as {len(segments)} segments, each aligned afresh; no trajectory inside the gaps")
    results: list[RunResult] = []
    spans: list[tuple[float, float]] = []
    skipped: list[str] = []
    first_error: Exception | None = None
    done = 0
    for i0, i1 in segments:
        a, b = float(t[i0]), float(t[i1 - 1])
        sub = _segment(recording, i0, i1)
        share = (i1 - i0) / n
        prog = None if progress is None else (lambda f, d=done, s=share: progress(min(1.0, (d + f * s * n) / n)))
        try:
            results.append(_run(sub, config, copy.deepcopy(filt), prog, cov_step_s, smooth))
            spans.append((a, b))
        except FilterDivergedError:
            raise
        except InputError as exc:
            first_error = first_error or exc
            why = str(exc).splitlines()[0]
            why = why.split(": ", 1)[1] if why.startswith(f"{recording.source}: ") else why
            skipped.append(f"{recording.source}: IMU segment t = {a:.3f} .. {b:.3f} s ({b - a:.1f} s) left out: "
                           f"{why[:160]}")
        done += i1 - i0
    if not results:
        raise first_error
    notes: list[str] = []
    for k, (r, (a, b)) in enumerate(zip(results, spans)):
        tag = f"segment {k + 1} of {len(results)} (t = {a:.1f} .. {b:.1f} s): "
        notes += [tag + x for x in r.notes]
    updates: dict[str, dict[str, int]] = {}
    for r in results:
        for kind, counts in r.updates.items():
            u = updates.setdefault(kind, {})
            for key, v in counts.items():
                u[key] = u.get(key, 0) + v
    smoothed = None
    if all(r.smoothed is not None for r in results) and results[0].smoothed is not None:
        sm = [r.smoothed for r in results]
        smoothed = SmoothedRun(solution=_concat([x.solution for x in sm], Solution),
                               biases=_concat([x.biases for x in sm], BiasHistory),
                               runtime_s=sum(x.runtime_s for x in sm), nodes=sum(x.nodes for x in sm),
                               breaks=sum(x.breaks for x in sm), store_mb=max(x.store_mb for x in sm))
    calibration = dict(results[0].calibration)
    calibration["segments"] = [{"t_start_s": a, "t_end_s": b, **r.calibration} for r, (a, b) in zip(results, spans)]
    return RunResult(
        solution=_concat([r.solution for r in results], Solution),
        biases=_concat([r.biases for r in results], BiasHistory),
        alignment=results[0].alignment,
        diagnostics=_concat([r.diagnostics for r in results], Diagnostics),
        gnss_epochs=sum(r.gnss_epochs for r in results),
        gnss_rejected=sum(r.gnss_rejected for r in results),
        runtime_s=sum(r.runtime_s for r in results),
        warnings=tuple(dict.fromkeys([head, *skipped, *(w for r in results for w in r.warnings)])),
        smoothed=smoothed,
        notes=tuple(notes),
        updates=updates,
        calibration=calibration,
    )


def _saturation(source: str, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                gyro_range: float | None, accel_range: float | None) -> list[str]:
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
        flag = np.zeros(data.shape[0], bool)
        for axis in range(3):
            v = data[:, axis]
            for ext in (float(v.max()), float(v.min())):
                if abs(ext) < SATURATION_FLOOR[name]:
                    continue
                at = v == ext
                # runs of >= SATURATION_RUN: a sample and its SATURATION_RUN - 1 successors all at ext
                run = at.copy()
                for j in range(1, SATURATION_RUN):
                    run[:-j] &= at[j:]
                    run[-j:] = False
                if run.any():
                    for j in range(SATURATION_RUN):     # mark the whole run, not only its starts
                        flag[j:] |= run[:data.shape[0] - j]
            if rng is not None:
                flag |= np.abs(v) >= rng
        if flag.any():
            idx = np.nonzero(flag)[0]
            unit = "rad/s" if name == "gyro" else "m/s^2"
            out.append(f"{source}: IMU {name}: {idx.size} sample{'s' if idx.size > 1 else ''} look saturated "
                       f"(held at the extreme value{' or beyond the configured range' if rng is not None else ''}, "
                       f"up to {float(np.abs(data[idx]).max()):.4g} {unit}) from {_t_text(float(t[idx[0]]))} to "
                       f"{_t_text(float(t[idx[-1]]))}: the solution around them is not to be trusted")
    return out


def _overlap(source: str, t_imu: np.ndarray, t_gnss: np.ndarray) -> list[str]:
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
    return [f"{source}: the IMU ({_t_text(i0)} .. {i1:.3f} s) and GNSS ({_t_text(g0)} .. {g1:.3f} s) only partly "
            f"overlap: GNSS-aided {lo:.3f} .. {hi:.3f} s; " + "; ".join(notes)]


def check_data(recording: Recording, config: Config | None = None) -> list[str]:
    """Data faults the engine copes with but the user must hear of, one line each, with times.

    IMU gaps longer than :data:`~navpp.ins.model.LONG_GAP_PERIODS` periods, saturated IMU channels (see
    :func:`_saturation`; ranges from ``[imu] gyro_range_rps`` / ``accel_range_mps2`` when the
    configuration has them), and IMU / GNSS spans that only partly overlap.  Times are s
    relative to the recording's first IMU stamp.
    """
    imu = recording.imu
    src = recording.source
    imu_cfg = getattr(config, "imu", None)
    out = _imu_gaps(src, imu.t)
    out += _saturation(src, imu.t, imu.gyro, imu.accel, getattr(imu_cfg, "gyro_range_rps", None),
                       getattr(imu_cfg, "accel_range_mps2", None))
    out += _overlap(src, imu.t, recording.gnss.t)
    return out


def _state_fault(state: GaussianState) -> str | None:
    """What is wrong with a filter state (non-finite state or covariance, a covariance that is
    not positive definite on its diagonal), or None."""
    if math.isfinite(float(state.x.sum()) + float(state.P.sum())) and float(np.diagonal(state.P).min()) > 0.0:
        return None                     # the common case, in two reductions
    if not np.all(np.isfinite(state.x)):
        return "the state became non-finite (NaN or inf)"
    if not np.all(np.isfinite(state.P)):
        return "the covariance became non-finite (NaN or inf)"
    if not np.all(np.diagonal(state.P) > 0.0):
        return "the covariance lost positive definiteness (a variance <= 0)"
    return None


def _causes_text(vehicle_mounting: bool = False) -> str:
    """The usual causes of a filter and GNSS that disagree, as one clause."""
    imu = "check the IMU units and axes ([imu] mounting_rpy_deg)"
    if vehicle_mounting:
        imu += ', the vehicle mounting ([vehicle] mounting_rpy_deg = "auto" estimates it)'
    return f"{imu}, the lever arm, the time bases ([gnss] time_offset_s) and the GNSS standard deviations"


_CAUSES = _causes_text()


def _causes(config: Config) -> str:
    """:data:`_CAUSES`, with the vehicle mounting when the non-holonomic constraint holds the
    IMU's lateral velocity to zero on a configured mounting (a degree of yaw is 0.3 m/s of
    side-slip at 60 km/h)."""
    v = config.vehicle
    return _causes_text(v.type == "car" and v.nhc and not isinstance(v.mounting_rpy_deg, str))


_CHI2_3_MEDIAN = 2.365973884375338     # median of the chi-square distribution with 3 dof

#: What a warning the run printed says about the likely cause of a divergence, in the order tried:
#: (text in the warning, the short cause with its setting).
_NOTICED_CAUSES = (
    ("GNSS track turns", "the gyro's unit or axes ([imu] gyro_units, mounting_rpy_deg)"),
    ("gravity is on", "the IMU's axes ([imu] mounting_rpy_deg)"),
    ("tilted by", "the IMU's axes ([imu] mounting_rpy_deg)"),
    ("clock offset", "the time bases ([gnss] time_offset_s)"),
    ("look saturated", "a saturated IMU"),
    ("gyro rates reach", 'the gyro\'s unit ([imu] gyro_units = "deg/s"?)'),
    ("periods (", "the IMU's gaps"),
)


def _likely_cause(recording: Recording, config: Config, noticed: list[str]) -> tuple[str, list[str]]:
    """The single most likely cause of a filter and GNSS that disagree, and the rest (for a
    warning line): first the fixes themselves (all identical, radians), then what the run
    noticed (its warnings), then the IMU's units and axes."""
    from .plausibility import fix_suspect

    g = recording.gnss
    suspect = fix_suspect(recording.source, g.lat_deg, g.lon_deg, g.alt, g.t, g.std_enu, config.vehicle.type)
    if suspect is not None:
        return suspect, [_causes(config)]
    for key, cause in _NOTICED_CAUSES:
        if any(key in w for w in noticed):
            return f"check {cause}", [_causes(config)]
    imu = "the IMU's units and axes ([imu] mounting_rpy_deg)"
    causes = _causes(config).replace("check the IMU units and axes ([imu] mounting_rpy_deg), ", "check ")
    return f"check {imu}", [causes]


def _refusal(recording: Recording, config: Config, headline: str, notes: list[str], warnings: list[str],
             cause: str | None = None, anyway: bool = True) -> FilterDivergedError:
    """A FilterDivergedError as one short line (source, what was seen, the likely cause) with the
    run's warnings, the other causes and the way to write the trajectory anyway as warnings
    before it (the CLI prints them first), and the run's notes."""
    if cause is None:
        cause, others = _likely_cause(recording, config, warnings)
    else:
        others = [_causes(config)]
    extra = [f"{recording.source}: other causes to check: {'; '.join(others)}"
             + (" ([gnss] max_rejected_fraction = 1 writes the trajectory anyway)" if anyway else "")]
    exc = FilterDivergedError(f"{recording.source}: {headline}; likely: {cause}")
    exc.warnings = tuple(warnings) + tuple(extra)
    exc.notes = tuple(notes)
    return exc


def _consistency_checks(source: str, name: str, config: Config, tg: np.ndarray, nis: np.ndarray,
                        accepted: np.ndarray, noticed: list[str]) -> list[str]:
    """After the run: stop a diverged filter, warn about a doubtful one.

    More than ``[gnss] max_rejected_fraction`` of the fixes failing the gate means the filter
    and the GNSS disagree for good (wrong units, axes, lever arm, time base or standard
    deviations): FilterDivergedError, one short line with the likely cause (see
    :func:`_refusal`; the other causes and what the run ``noticed`` go in its warnings).  Above
    5 %, or with the median NIS far above the chi-square median (innovations larger than the
    filter predicts), a warning.
    """
    m = tg.shape[0]
    rejected = int(np.count_nonzero(~accepted))
    finite = nis[np.isfinite(nis)]
    scale = math.sqrt(float(np.median(finite)) / _CHI2_3_MEDIAN) if finite.size else 1.0
    what = f"{rejected} of {m} GNSS fixes ({100.0 * rejected / max(m, 1):.0f}%) failed the innovation gate"
    if m >= 20 and rejected > config.gnss.max_rejected_fraction * m:
        first = float(tg[np.argmax(~accepted)])
        raise FilterDivergedError(
            f"{name} diverged: {what} (first at t = {first:.1f} s; innovations {scale:.1f}x predicted)")
    warnings = []
    if rejected > 0.05 * m:
        warnings.append(f"{source}: {what}: the IMU and GNSS disagree; {_causes(config)}")
    elif m >= 20 and scale > 1.5:
        warnings.append(f"{source}: the GNSS innovations are {scale:.1f} times larger than the filter predicts: the "
                        "GNSS standard deviations (or the IMU noise) are too optimistic")
    return warnings


def _vehicle_mounting(recording: Recording, config: Config, cov_step_s: float
                      ) -> tuple[tuple[float, float, float] | None, list[str], list[str]]:
    """``[vehicle] mounting_rpy_deg = "auto"`` with the NHC on: a first EKF pass without the
    constraint, and the vehicle frame's pitch and yaw estimated from its solution
    (:func:`navpp.ins.aids.mounting.estimate_mounting`).  Returns the angles (None: as
    configured), and a note or a warning for the user."""
    veh = config.vehicle
    if not (veh.type == "car" and veh.nhc and veh.mounting_rpy_deg == "auto"):
        return None, [], []
    from dataclasses import replace as dc_replace

    from .filters.ekf import EKF
    from .ins.aids.mounting import estimate_mounting

    first = dc_replace(config, vehicle=dc_replace(veh, nhc=False))
    pre = _run(recording, first, EKF(gate_probability=config.gnss.gate_probability,
                                     reanchor_after_s=config.gnss.reanchor_after_s), None, cov_step_s)
    sol = pre.solution
    est = estimate_mounting(sol.t, sol.vel_enu, sol.rph_deg)
    if est is None:
        why = (f"{recording.source}: [vehicle] mounting_rpy_deg = \"auto\": less than 10 s of fast straight "
               "driving to estimate it from; the constraint assumes the IMU aligned with the vehicle")
        return (0.0, 0.0, 0.0), [], [why]
    note = (f"vehicle mounting estimated (first pass without the constraint, {est.seconds:.0f} s of straight "
            f"driving): pitch {est.pitch_deg:+.2f} deg, yaw {est.yaw_deg:+.2f} deg (spread "
            f"{est.spread_deg[0]:.2f} / {est.spread_deg[1]:.2f} deg)")
    return (0.0, est.pitch_deg, est.yaw_deg), [note], []


def _drifting(nis: np.ndarray, last_accepted: int, k: int) -> bool:
    """Whether the GNSS fixes rejected before fix ``k`` since fix ``last_accepted`` (-1: none),
    the current run of rejections, show INS drift: innovations that grow (the last quarter's
    median NIS over twice the first quarter's), rather than a GNSS jump, whose innovations stay
    the same size."""
    if k - last_accepted - 1 < 4:
        return False
    run = nis[last_accepted + 1:k]
    run = run[np.isfinite(run)]
    if run.size < 4:
        return False
    q = max(1, run.size // 4)
    return float(np.median(run[-q:])) > 2.0 * float(np.median(run[:q]))


#: What a forced fix re-opens (1-sigma floors): velocity m/s per axis, attitude deg per axis.
RECOVER_VEL_STD = 1.0
RECOVER_ATT_STD_DEG = (2.0, 2.0, 20.0)


def _realigned_velocity(state: GaussianState, gnss, sel: np.ndarray, k: int, lat: np.ndarray, lon: np.ndarray,
                        alt: np.ndarray) -> GaussianState:
    """After a forced fix: the velocity from the GNSS (its velocity, else a straight line through
    the fixes within 1 s either side), when there is one; the covariance is already re-opened."""
    from . import geodesy

    idx = sel[k]
    if gnss.vel_enu is not None and np.all(np.isfinite(gnss.vel_enu[idx])):
        v = np.asarray(gnss.vel_enu[idx], dtype=float)
    else:
        near = np.nonzero(np.abs(gnss.t[sel] - gnss.t[idx]) <= 1.0)[0]
        if near.size < 3:
            return state
        enu = geodesy.geodetic_to_enu(lat[near], lon[near], alt[near], float(lat[k]), float(lon[k]), float(alt[k]))
        tt = gnss.t[sel][near] - gnss.t[sel][near].mean()
        stt = float(tt @ tt)
        if stt <= 0.0:
            return state
        v = (tt @ (enu - enu.mean(axis=0))) / stt
    x = state.x.copy()
    x[4:7] = v
    return GaussianState(state.t, x, state.P)


#: A clock offset estimate is applied when it is confident, or when it departs from zero by
#: this many sigmas (the data reject "no offset" at about 99 %) with a sigma below
#: CLOCK_MAX_SIGMA_S: a latency of tenths of a second is worth metres at speed.
CLOCK_SIGMAS = 2.5
CLOCK_MAX_SIGMA_S = 0.2
#: ... and only where the gyro and the course rate agree this well (a weak fit's sigma is not to be
#: trusted: a 2.5 Hz, 1.5 m GNSS gave 0.54 +- 0.07 s at correlation 0.18 for a true 0.01 s)
CLOCK_MIN_CORRELATION = 0.5


#: The gyro's yaw rate against the GNSS course rate: a fit this well correlated over this many
#: degrees of GNSS turning measures the gyro's scale; outside these bounds it is not a tilt
#: (cos 53 deg = 0.6; the chord courses read about 0.9 on a steady drive) but the wrong unit
#: or axis.
GYRO_SCALE_CORRELATION = 0.7
GYRO_SCALE_TURN_DEG = 90.0
GYRO_SCALE_BOUNDS = (0.6, 1.6)


def _check_gyro_scale(recording: Recording, config: Config, up_s: np.ndarray, enu: np.ndarray) -> list[str]:
    """The gyro's turns against the GNSS track's (:func:`navpp.ins.timing_estimates.yaw_scale_from_track`):
    raise InputError when the ratio says the gyro's values are in the wrong unit (1/57.3: deg/s
    read as rad/s); warn when it is otherwise far from 1 (a wrong axis, a bad scale)."""
    from .ins.timing_estimates import yaw_scale_from_track

    imu, gnss, source = recording.imu, recording.gnss, recording.source
    std_h = np.hypot(gnss.std_enu[:, 0], gnss.std_enu[:, 1]) / math.sqrt(2.0) if gnss.std_enu is not None else 0.0
    est = yaw_scale_from_track(imu.t, imu.gyro @ up_s, gnss.t, enu[:, 0], enu[:, 1], std_h)
    lo, hi = GYRO_SCALE_BOUNDS
    if (math.isfinite(est.scale) and -hi <= est.scale <= -lo and est.correlation <= -GYRO_SCALE_CORRELATION
            and est.gnss_turn_deg >= GYRO_SCALE_TURN_DEG):
        # the track turns the other way at the gyro's rate: a mirror image, as lat and lon swapped
        # make it (east and north exchanged); the gyro's up is measured from the accelerometers,
        # so an IMU that is upside down or forward-right-down does not do this
        from .plausibility import gnss_name

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
    else:
        return [f"{source}: {what}: check the gyro columns and their axes ([imu] mounting_rpy_deg)"]
    raise InputError(f"{source}: {what}: {hint}")


def timing_fixes(recording: Recording, config: Config,
                 info: dict | None = None) -> tuple[Recording, list[str], list[str]]:
    """What the IMU stamps and values say about timing (:mod:`navpp.ins.timing_estimates`):
    stale IMU rows (a logger polling faster than the sensor) are dropped; the IMU-GNSS clock
    offset is estimated from the gyro's yaw rate and the GNSS course rate and applied to the
    GNSS stamps when the data are sure of it (unless ``[gnss] time_offset_s`` is set).
    Returns the recording to process, notes and warnings; ``info`` (when given) receives the
    figures for metrics.json."""
    from dataclasses import replace as dc_replace

    from . import geodesy
    from .ins.timing_estimates import estimate_clock_offset, find_stale_rows, velocity_from_positions
    from .recording import ImuData

    auto = config.auto
    notes: list[str] = []
    warnings: list[str] = []
    imu, gnss, src = recording.imu, recording.gnss, recording.source
    if auto.stale_rows and len(imu) > 10:
        stale = find_stale_rows(imu.t, imu.gyro, imu.accel)
        if info is not None:
            info["stale_rows"] = {"dropped": int(stale.count), "fraction": round(float(stale.fraction), 5),
                                  "fresh_rate_hz": round(float(stale.fresh_rate_hz), 3) if stale.count else None}
        if stale.count:
            keep = ~stale.mask
            imu = ImuData(imu.t[keep], imu.gyro[keep], imu.accel[keep])
            recording = dc_replace(recording, imu=imu)
            warnings.append(f"{src}: IMU: {stale.count} stale rows ({100.0 * stale.fraction:.1f} %) repeat the "
                            f"previous row's six values under a new stamp (a logger polling faster than the sensor): "
                            f"dropped; "
                            f"fresh samples at {stale.fresh_rate_hz:.1f} Hz ([auto] stale_rows = false keeps them)")
        elif stale.n_repeats:
            notes.append(f"IMU: {stale.n_repeats} rows repeat the previous row's values, no more than chance: kept "
                         f"({stale.reason})")
    if len(gnss) < 20 or len(imu) < 20:
        return recording, notes, warnings
    up = imu.accel.mean(axis=0)            # the sensor's up, as logged
    up = up / max(float(np.linalg.norm(up)), 1e-9)
    # origin at the middle fix, not the first: a first fix on the far side of the globe would mirror
    # the track in the tangent plane (the yaw-scale check would read it as lat/lon swapped)
    mid = int(np.argsort(gnss.lat_deg, kind="stable")[len(gnss) // 2])
    lat0, lon0 = math.radians(float(gnss.lat_deg[mid])), math.radians(float(gnss.lon_deg[mid]))
    enu = geodesy.geodetic_to_enu(np.radians(gnss.lat_deg), np.radians(gnss.lon_deg), gnss.alt, lat0, lon0,
                                  float(gnss.alt[mid]))
    warnings += _check_gyro_scale(recording, config, up, enu)
    if auto.clock_offset and config.gnss.time_offset_s == 0.0:
        if gnss.vel_enu is not None:
            vel = np.asarray(gnss.vel_enu[:, :2], dtype=float)
        else:
            vel = velocity_from_positions(gnss.t, enu[:, 0], enu[:, 1])
        ok = np.all(np.isfinite(vel), axis=1)
        try:
            est = estimate_clock_offset(imu.t, imu.gyro @ up, gnss.t[ok], vel[ok])
        except ValueError:
            est = None
        if est is not None and math.isfinite(est.offset_s):
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
            if applied:
                gnss = dc_replace(gnss, t=gnss.t + est.offset_s)
                recording = dc_replace(recording, gnss=gnss)
                warnings.append(f"{src}: {what}: applied to the GNSS stamps (write [gnss] time_offset_s = "
                                f"{est.offset_s:.2f} to fix it, or [auto] clock_offset = false)")
            else:
                notes.append(f"{what}: not applied ({est.reason})")
        else:
            notes.append("IMU-GNSS clock offset: not estimated (too little turning at speed)")
            if info is not None:
                info["clock_offset"] = {"estimated": False, "reason": "too little turning at speed"}
    return recording, notes, warnings


def _run(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
         cov_step_s: float, smooth: bool = False) -> RunResult:
    """One run; a failure carries what the run had noted and warned about so far
    (:meth:`navpp.errors.NavppError.with_context`), so the user sees the likely cause first."""
    from .errors import NavppError

    notes: list[str] = []
    warnings: list[str] = []
    try:
        return _run_body(recording, config, filt, progress, cov_step_s, smooth, notes, warnings)
    except NavppError as exc:
        exc.with_context(notes, warnings)
        raise


def _run_body(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
              cov_step_s: float, smooth: bool, notes: list[str], warnings: list[str]) -> RunResult:
    t_wall = time.perf_counter()
    check_gnss_jumps(recording, config.vehicle.type, config.gnss.default_std_m, config.gnss.reanchor_after_s)
    warnings += check_imu_plausible(recording)
    calibration: dict = {}
    recording, t_notes, t_warnings = timing_fixes(recording, config, calibration)
    notes += t_notes
    warnings += t_warnings
    warnings += check_data(recording, config)
    imu, gnss = recording.imu, recording.gnss
    gyro, accel = imu.gyro, imu.accel
    if any(a != 0.0 for a in config.imu.mounting_rpy_deg):
        m = mounting_matrix(config.imu.mounting_rpy_deg)
        gyro, accel = gyro @ m.T, accel @ m.T
    gyro, accel, noise, cal, cal_notes, cal_warnings = _calibrated(recording, config, gyro, accel, calibration)
    notes += cal_notes
    warnings += cal_warnings
    profile = cal.profile if (cal is not None and config.auto.noise) else None
    model = InsModel(imu.t, gyro, accel, noise_model(config, noise), cov_step_s=cov_step_s, profile=profile)
    try:
        al = align(model.t, model.gyro, model.accel, gnss, alignment_settings(config, noise, cal))
    except InputError as exc:  # alignment knows the data, not where it came from
        from .plausibility import fix_suspect

        suspect = fix_suspect(recording.source, gnss.lat_deg, gnss.lon_deg, gnss.alt)
        if suspect is not None:     # the fixes themselves first: the alignment only saw their symptom
            both = f"{recording.source}: {suspect}; {exc}"
            raise InputError(both if len(both) < 285 else f"{recording.source}: {suspect}") from None
        raise InputError(f"{recording.source}: {exc}") from None
    model.path[al.index] = al.x[:model.path.shape[1]]
    notes[:0] = list(al.lines)          # for an error's context; the result carries them apart
    n_al = len(al.lines)

    lever = np.asarray(config.gnss.lever_arm_m, dtype=float)
    sel = np.nonzero((gnss.t > al.t) & (gnss.t <= imu.t[-1]))[0]
    if sel.size == 0:
        raise InputError(f"{recording.source}: no GNSS fix inside the IMU span after alignment "
                         f"(t = {al.t:.2f} .. {imu.t[-1]:.2f} s)")
    tg = gnss.t[sel]
    lat = np.radians(gnss.lat_deg[sel])
    lon = np.radians(gnss.lon_deg[sel])
    alt = np.asarray(gnss.alt[sel], dtype=float)
    std = (np.asarray(gnss.std_enu[sel], dtype=float) if gnss.std_enu is not None
           else np.tile(np.asarray(config.gnss.default_std_m, dtype=float), (sel.size, 1)))
    var = std ** 2

    m_ep = sel.size
    nu = np.full((m_ep, 3), np.nan)
    nis = np.full(m_ep, np.nan)
    accepted = np.zeros(m_ep, bool)
    forced = np.zeros(m_ep, bool)
    r_std = np.full((m_ep, 3), np.nan)
    s_used = np.full((m_ep, 3, 3), np.nan)     # each fix's innovation covariance and R as the filter had them
    r_used = np.full((m_ep, 3, 3), np.nan)
    adaptive: dict[str, np.ndarray] = {}
    bias = np.empty((m_ep, 6))
    bias_var = np.empty((m_ep, 6))
    state = GaussianState(al.t, al.x, al.P)
    # covariance knots for the output's 1-sigma: (t, variance before, variance after an update);
    # long gaps between fixes get a knot every KNOT_S so the sigma follows the real growth
    knots = array("d")          # flat (t, prior E/N/U variance, posterior E/N/U variance) records

    def knot(prior: np.ndarray | None = None) -> None:
        v = state.P.diagonal()[POS]
        knots.append(state.t)
        knots.extend(v if prior is None else prior)
        knots.extend(v)

    store = None
    epoch_node = np.zeros(m_ep, np.int64)       # the smoother's node of each GNSS epoch
    if smooth:
        store = ForwardStore(state.P.shape[0], state.x.shape[0])
        store.start(state)

    def predicted(interval: tuple[float, float]) -> None:
        nonlocal state
        state = filt.predict(state, model, interval)
        if store is not None:
            store.predicted(state, filt.last_cross, filt.last_x_ref)

    def coast_to(t_end: float) -> None:
        while t_end - state.t > 1.5 * KNOT_S:
            predicted((state.t, state.t + KNOT_S))
            knot()

    knot()
    # recovery: a forced fix re-opens velocity, attitude and gyro bias as well as the position
    reopen = None
    recoveries: list[float] = []
    if config.auto.recovery:
        reopen = np.zeros(al.P.shape[0])
        reopen[VEL] = RECOVER_VEL_STD
        reopen[ATT] = np.radians(RECOVER_ATT_STD_DEG)
        reopen[BG] = np.sqrt(np.diagonal(al.P)[BG])
    mounting, mounting_note, mounting_warning = _vehicle_mounting(recording, config, cov_step_s)
    notes += mounting_note
    warnings += mounting_warning
    aiding = Aiding(config, model.t, model.gyro, model.accel, model.noise.gyro_arw, model.noise.accel_vrw, gnss,
                    sel, model.gaps, mounting,
                    still=cal.still if (cal is not None and config.auto.standstill) else None, profile=profile)
    ev_t, ev_fix, ev_cons = aiding.schedule(al.t, float(imu.t[-1]), tg)
    n_ev = ev_t.shape[0]
    vel_nu = np.full((m_ep, 3), np.nan) if aiding.has_velocity else None
    vel_nis = np.full(m_ep, np.nan) if aiding.has_velocity else None
    vel_accepted = np.full(m_ep, np.nan) if aiding.has_velocity else None
    tick = max(1, n_ev // 200)
    n_path = model.path.shape[1]
    idx = np.minimum(np.searchsorted(imu.t, ev_t), len(imu) - 1)
    ev_sample = np.where(imu.t[idx] == ev_t, idx, -1)

    def _epochs() -> None:
        nonlocal state, last_good
        last_acc = -1                 # index of the last accepted fix (the start of a run of rejections)
        used_prior = None           # per epoch: the prior the first applied update corrected,
        reset = applied = False     # whether an update re-anchored the covariance, whether any applied

        def apply(meas, t_e: float):
            nonlocal state, used_prior, reset, applied
            filt.last_prior = None
            state, inn = filt.update(state, model, meas)
            checked(t_e)                            # the update
            aiding.counts.add(meas.kind, inn.accepted)
            if inn.accepted:
                if not applied:
                    used_prior = filt.last_prior
                applied = True
                reset |= inn.forced
            return inn

        for e in range(n_ev):
            t_e = float(ev_t[e])
            k = int(ev_fix[e])
            coast_to(t_e)
            predicted((state.t, t_e))
            prior = state.P.diagonal()[POS].copy()
            checked(t_e)                            # the prediction
            used_prior, reset, applied = None, False, False
            if k >= 0:
                drift = reopen is not None and _drifting(nis, last_acc, k)
                meas = GnssPosition(t_e, float(lat[k]), float(lon[k]), float(alt[k]), np.diag(var[k]), lever,
                                    reopen if drift else None)
                inn = apply(meas, t_e)
                if inn.accepted:
                    last_good = t_e
                if inn.forced and drift:
                    state = _realigned_velocity(state, gnss, sel, k, lat, lon, alt)
                    recoveries.append(t_e)
                nu[k] = inn.nu
                nis[k] = inn.nis
                accepted[k] = inn.accepted
                if inn.accepted:
                    last_acc = k
                forced[k] = inn.forced
                r_std[k] = np.sqrt(np.diagonal(inn.R))
                s_used[k] = inn.S
                r_used[k] = inn.R
                for name, value in filt.noise_report().items():
                    if name not in adaptive:
                        adaptive[name] = np.full((m_ep, np.size(value)), np.nan)
                    adaptive[name][k] = value
                vmeas = aiding.velocity(k, t_e)
                if vmeas is not None:
                    vinn = apply(vmeas, t_e)
                    vel_nu[k], vel_nis[k], vel_accepted[k] = vinn.nu, vinn.nis, float(vinn.accepted)
            if ev_cons[e]:
                for cmeas in aiding.constraint_measurements(t_e, state.x, state.P):
                    aiding.observed(cmeas, apply(cmeas, t_e))
            if store is not None:
                store.updated(used_prior, state, reset)
            if applied and ev_sample[e] >= 0:
                model.path[ev_sample[e]] = state.x[:n_path]     # the epoch's own sample shows the posterior
            knot(prior)
            if k >= 0:
                if store is not None:
                    epoch_node[k] = store.n - 1
                bias[k, :3] = state.x[NOMINAL_BG]
                bias[k, 3:] = state.x[NOMINAL_BA]
                bias_var[k, :3] = state.P.diagonal()[BG]
                bias_var[k, 3:] = state.P.diagonal()[BA]
            if progress is not None and e % tick == 0:
                progress(e / n_ev)
        # after the last fix the uncertainty keeps growing to the end of the log
        coast_to(float(imu.t[-1]))
        if state.t < imu.t[-1]:
            predicted((state.t, float(imu.t[-1])))
            knot()
        checked(state.t)

    last_good: float | None = None       # time of the last accepted GNSS update

    def diverged(t: float, why: str) -> FilterDivergedError:
        good = (f"the last good epoch (accepted GNSS update) was t = {last_good:.3f} s" if last_good is not None
                else f"no GNSS update had been accepted yet (alignment at t = {al.t:.3f} s)")
        return _refusal(recording, config, f"{filt.name} diverged at t = {t:.3f} s: {why}; {good}", notes,
                        warnings, anyway=False)

    def checked(t: float) -> None:
        fault = _state_fault(state)
        if fault is not None:
            raise diverged(t, fault)

    try:
        _epochs()
    except FilterDivergedError as exc:
        if str(exc).startswith(f"{recording.source}: {filt.name} diverged at"):
            raise
        raise diverged(state.t, str(exc).removeprefix(f"{filt.name}: ")) from None
    if progress is not None:
        progress(1.0)

    path = model.path[al.index:]
    model.path = None
    t_out = imu.t[al.index:]
    smoothed = None
    if store is not None:
        from numba.core import event as numba_event

        with numba_event.install_recorder("numba:compile") as compiling:
            smoothed = _smoothed_run(store, model, t_out, path, epoch_node, tg, recording.t0_ns)
        smoothed = replace(smoothed, runtime_s=smoothed.runtime_s - _top_level_duration(compiling.buffer))
        del store
    kn = np.frombuffer(knots, dtype=float).reshape(-1, 7)
    kt, k_prior, k_post = kn[:, 0].copy(), kn[:, 1:4].copy(), kn[:, 4:7].copy()
    std_out = _interpolated_std(t_out, kt[0], k_post[0], kt[1:], k_prior[1:], k_post[1:])
    solution = solution_from_path(t_out, path, std_out, recording.t0_ns)
    labels = filt.noise_report_labels()
    named: dict[str, np.ndarray] = {}
    for key, values in adaptive.items():
        lab = labels.get(key)
        if lab is not None and len(lab) == values.shape[1] and values.shape[1] > 1:
            named.update({f"{key}_{name}": values[:, [i]] for i, name in enumerate(lab)})
        else:
            named[key] = values
    diag = Diagnostics(tg, nu, nis, accepted, forced, r_std, named, vel_nu, vel_nis, vel_accepted)
    bias_std = np.sqrt(np.maximum(bias_var, 0.0))     # a diverged run is reported by the checks below
    biases = BiasHistory(tg, bias[:, :3], bias[:, 3:], bias_std[:, :3], bias_std[:, 3:])
    rejected = int((~accepted).sum())
    warnings += list(al.warnings)
    if recoveries:
        warnings.append(f"{recording.source}: the INS had drifted from the GNSS (a run of rejected fixes) "
                        f"{len(recoveries)} time{'s' if len(recoveries) > 1 else ''}, at t = "
                        + ", ".join(f"{v:.1f}" for v in recoveries[:10]) + (" ..." if len(recoveries) > 10 else "")
                        + " s: velocity re-aligned on the GNSS, attitude and gyro-bias uncertainty re-opened "
                        "([auto] recovery = false re-opens the position only)")
    if aiding.vetoes:
        v = aiding.vetoes
        notes.append(f"standstill ended early {len(v)} time{'s' if len(v) > 1 else ''}, at t = "
                     + ", ".join(f"{x:.1f}" for x in v[:10]) + (" ..." if len(v) > 10 else "")
                     + " s: ZUPT's velocity corrections kept one direction (a gentle start the IMU's spreads did not "
                     "show), so no more ZUPT or ZARU until the next stop")
    try:
        warnings += _consistency_checks(recording.source, filt.name, config, tg, nis, accepted, list(warnings))
    except FilterDivergedError as exc:
        raise _refusal(recording, config, str(exc), notes, warnings) from None
    warnings += _plausibility_checks(recording, config, filt.name, solution, smoothed, tg, nu, s_used, r_used, var,
                                     accepted, alt, notes, warnings)
    warnings += _aid_checks(recording.source, aiding.counts.as_dict())
    if smoothed is not None and smoothed.breaks:
        n = smoothed.breaks
        warnings.append(f"{recording.source}: smoothing: {n} step{'s' if n > 1 else ''} the smoother carries no "
                        "information back across (a fix forced through the gate with the covariance re-anchored, "
                        "or a prior covariance that was not positive definite): the smoothed trajectory keeps "
                        "the forward filter's jump there")
    return RunResult(solution, biases, al, diag, m_ep, rejected, time.perf_counter() - t_wall, 0.0,
                     tuple(warnings), smoothed, tuple(notes[n_al:]), aiding.counts.as_dict(),
                     {**calibration, "recoveries_s": [round(v, 3) for v in recoveries],
                      "standstill_ended_early_s": [round(v, 3) for v in aiding.vetoes]})


def _plausibility_checks(recording: Recording, config: Config, name: str, solution: Solution,
                         smoothed: SmoothedRun | None, tg: np.ndarray, nu: np.ndarray, s_used: np.ndarray,
                         r_used: np.ndarray, var0: np.ndarray, accepted: np.ndarray, fix_alt: np.ndarray,
                         notes: list[str], warnings: list[str]) -> list[str]:
    """Every filter's finished solution judged against the prior GNSS sigma and the vehicle
    (:mod:`navpp.plausibility`), before anything is written: FilterDivergedError (one short
    line) for a run that is wrong, warnings for a doubtful one."""
    from . import plausibility as pl

    src = recording.source
    label = pl.std_name(src, recording.gnss.std_enu is not None)
    found = pl.innovation_findings(name, label, tg, nu, s_used, r_used, var0, accepted, config.gnss.gate_probability,
                                   config.gnss.max_rejected_fraction)
    sols = [solution] + ([smoothed.solution] if smoothed is not None else [])
    for sol in sols:
        found += pl.solution_findings(name, config.vehicle.type, sol.t, sol.alt, sol.vel_enu, sol.std_enu, fix_alt,
                                      np.sqrt(var0[:, 2]), config.gnss.gate_probability,
                                      config.gnss.max_rejected_fraction < 1.0)
    out = []
    for f in found:
        if f.fatal:
            raise _refusal(recording, config, f.headline, notes, warnings + out, f.cause)
        out.append(f"{src}: {f.headline}: {f.cause}" if f.cause else f"{src}: {f.headline}")
    return out


#: Share of an aid's updates the gate may reject before the run says the aid disagrees with the data.
AID_REJECTED_WARN = 0.05
_AID_HINTS = {
    "nhc": "the vehicle's motion is not along its x axis: check [vehicle] mounting_rpy_deg (or set it to \"auto\") "
           "and nhc_point_m, or raise nhc_std_mps (side slip)",
    "zupt": "standstill was detected while the vehicle moved: raise [vehicle] still_accel_std_mps2 / "
            "still_gyro_std_dps or turn zupt off",
    "zaru": "standstill was detected while the vehicle turned: raise [vehicle] still_gyro_std_dps or turn zaru off",
    "gnss_velocity": "the GNSS velocity disagrees with the IMU: check the lever arm, [gnss] time_offset_s and the "
                     "velocity's standard deviations (default_vel_std_mps), or set use_velocity = false",
}


def _aid_checks(source: str, updates: dict[str, dict[str, int]]) -> list[str]:
    """A warning per aid the innovation gate rejected often (more than
    :data:`AID_REJECTED_WARN` of its updates): the aid and the data disagree."""
    out = []
    for kind, hint in _AID_HINTS.items():
        c = updates.get(kind)
        if not c:
            continue
        n = c["applied"] + c["rejected"]
        if n >= 20 and c["rejected"] > AID_REJECTED_WARN * n:
            out.append(f"{source}: {c['rejected']} of {n} {kind} updates ({100.0 * c['rejected'] / n:.0f}%) failed "
                       f"the innovation gate: {hint}")
    return out


def _smoothed_run(store: ForwardStore, model: InsModel, t_out: np.ndarray, path: np.ndarray,
                  epoch_node: np.ndarray, tg: np.ndarray, t0_ns: int) -> SmoothedRun:
    """Smooth the stored forward run and bring it to the IMU rate.

    Between two nodes the forward path is the strapdown from the earlier node's posterior; the
    smoothed correction relative to it runs linearly from ``x_k^s ⊟ x_k^+`` at the start to
    ``x_k+1^s ⊟ x_ref,k+1`` at the end (nodes are at most ``1.5 KNOT_S`` apart, over which the
    error dynamics are linear to well below the errors themselves); a sample exactly at a node
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
    std = _interpolated_std(t_out, sm.t[0], vpos[0], sm.t[1:], vpos[1:], vpos[1:])
    solution = solution_from_path(t_out, spath, std, t0_ns)
    xs = sm.x[epoch_node]
    bstd = np.sqrt(np.maximum(var[epoch_node], 0.0))
    biases = BiasHistory(tg, xs[:, NOMINAL_BG].copy(), xs[:, NOMINAL_BA].copy(), bstd[:, BG].copy(),
                         bstd[:, BA].copy())
    return SmoothedRun(solution, biases, time.perf_counter() - t_start, int(sm.t.shape[0]),
                       int(sm.breaks + sm.repaired), mb)


@njit(cache=True)
def _interpolated_std(t, t0, var0, tg, var_prior, var_post):
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
def _path_to_output_columns(path):
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
    _path_to_output_columns(path)
    return Solution(t=np.asarray(t, dtype=float), lat_deg=path[:, 7], lon_deg=path[:, 8], alt=path[:, 9],
                    vel_enu=path[:, 4:7], rph_deg=path[:, 0:3], std_enu=std_enu, t0_ns=t0_ns)


__all__ = ["Diagnostics", "RunResult", "SmoothedRun", "mounting_matrix", "run", "solution_from_path"]
