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
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .config import Config
from .errors import FilterDivergedError, InputError
from .filters.base import Filter, GaussianState
from .ins.alignment import Alignment, AlignmentSettings, align
from numba import njit

from .ins.model import BA, BG, POS, GnssPosition, InsModel, NoiseModel
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
class RunResult:
    solution: Solution
    biases: BiasHistory
    alignment: Alignment
    diagnostics: Diagnostics
    gnss_epochs: int
    gnss_rejected: int
    runtime_s: float                  # processing wall time, s, without kernel compilation
    compile_s: float = 0.0            # one-off numba compilation on a cold cache, s
    warnings: tuple[str, ...] = ()    # what the run noticed about the data (units, tilt, gating)


def mounting_matrix(rpy_deg: tuple[float, float, float]) -> np.ndarray:
    """Sensor -> body rotation from the mounting roll/pitch/yaw (deg, about x, y, z; ROS rpy)."""
    r, p, y = (math.radians(a) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def alignment_settings(config: Config) -> AlignmentSettings:
    noise = config.imu.noise()
    ini = config.init
    rad = lambda v: None if v is None else math.radians(v)  # noqa: E731
    return AlignmentSettings(
        method=ini.method, roll=rad(ini.roll_deg), pitch=rad(ini.pitch_deg), heading=rad(ini.heading_deg),
        still_min_s=ini.still_min_s, gyrocompass_max_heading_std=math.radians(ini.gyrocompass_max_heading_std_deg),
        min_speed_mps=ini.min_speed_mps, gyro_bias_sigma=math.hypot(noise.gyro_bias_sigma, noise.gyro_bias_instability),
        gyro_arw=noise.gyro_arw, accel_bias_sigma=math.hypot(noise.accel_bias_sigma, noise.accel_bias_instability),
        accel_vrw=noise.accel_vrw, lever_arm_b=config.gnss.lever_arm_m)


def noise_model(config: Config) -> NoiseModel:
    n = config.imu.noise()
    return NoiseModel.from_datasheet(n.gyro_arw, n.accel_vrw, n.gyro_bias_sigma, n.gyro_bias_instability,
                                     n.gyro_bias_tau, n.accel_bias_sigma, n.accel_bias_instability, n.accel_bias_tau)


def run(recording: Recording, config: Config, filt: Filter, *, progress: ProgressFn | None = None,
        cov_step_s: float = 0.05) -> RunResult:
    """Process one recording with one filter; returns the IMU-rate solution and diagnostics.

    ``runtime_s`` excludes the one-off compilation of navpp's kernels on a cold cache, which
    is reported as ``compile_s``.
    """
    from numba.core import event as numba_event

    t_wall = time.perf_counter()
    with numba_event.install_recorder("numba:compile") as rec:
        result = _run(recording, config, filt, progress, cov_step_s)
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


_CAUSES = ("check the IMU units and axes ([imu] mounting_rpy_deg), the lever arm, the time bases "
           "([gnss] time_offset_s) and the GNSS standard deviations")
_CHI2_3_MEDIAN = 2.365973884375338     # median of the chi-square distribution with 3 dof


def _consistency_checks(source: str, name: str, config: Config, tg: np.ndarray, nis: np.ndarray,
                        accepted: np.ndarray, noticed: list[str]) -> list[str]:
    """After the run: stop a diverged filter, warn about a doubtful one.

    More than ``[gnss] max_rejected_fraction`` of the fixes failing the gate means the filter
    and the GNSS disagree for good (wrong units, axes, lever arm, time base or standard
    deviations): FilterDivergedError, whose message carries what the run ``noticed`` before
    (a likely cause).  Above 5 %, or with the median NIS far above the
    chi-square median (innovations larger than the filter predicts), a warning.
    """
    m = tg.shape[0]
    rejected = int(np.count_nonzero(~accepted))
    finite = nis[np.isfinite(nis)]
    scale = math.sqrt(float(np.median(finite)) / _CHI2_3_MEDIAN) if finite.size else 1.0
    what = f"{rejected} of {m} GNSS fixes ({100.0 * rejected / max(m, 1):.0f}%) failed the innovation gate"
    if m >= 20 and rejected > config.gnss.max_rejected_fraction * m:
        first = float(tg[np.argmax(~accepted)])
        raise FilterDivergedError(
            f"{source}: {name} diverged: {what}, the first at t = {first:.1f} s, and the GNSS innovations are "
            f"{scale:.1f} times larger than predicted; "
            + ("; ".join(w.removeprefix(f"{source}: ") for w in noticed) + "; otherwise " if noticed else "")
            + f"{_CAUSES} (set [gnss] max_rejected_fraction = 1 to write the trajectory anyway)")
    warnings = []
    if rejected > 0.05 * m:
        warnings.append(f"{source}: {what}: the IMU and GNSS disagree; {_CAUSES}")
    elif m >= 20 and scale > 1.5:
        warnings.append(f"{source}: the GNSS innovations are {scale:.1f} times larger than the filter predicts: the "
                        "GNSS standard deviations (or the IMU noise) are too optimistic")
    return warnings


def _run(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
         cov_step_s: float) -> RunResult:
    t_wall = time.perf_counter()
    warnings = check_imu_plausible(recording)
    imu, gnss = recording.imu, recording.gnss
    gyro, accel = imu.gyro, imu.accel
    if any(a != 0.0 for a in config.imu.mounting_rpy_deg):
        m = mounting_matrix(config.imu.mounting_rpy_deg)
        gyro, accel = gyro @ m.T, accel @ m.T
    model = InsModel(imu.t, gyro, accel, noise_model(config), cov_step_s=cov_step_s)
    try:
        al = align(model.t, model.gyro, model.accel, gnss, alignment_settings(config))
    except InputError as exc:  # alignment knows the data, not where it came from
        raise InputError(f"{recording.source}: {exc}") from None
    model.path[al.index] = al.x[:model.path.shape[1]]

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

    def coast_to(t_end: float) -> None:
        nonlocal state
        while t_end - state.t > 1.5 * KNOT_S:
            state = filt.predict(state, model, (state.t, state.t + KNOT_S))
            knot()

    knot()
    tick = max(1, m_ep // 200)
    n_path = model.path.shape[1]
    idx = np.minimum(np.searchsorted(imu.t, tg), len(imu) - 1)
    k_sample = np.where(imu.t[idx] == tg, idx, -1)
    for k in range(m_ep):
        coast_to(float(tg[k]))
        state = filt.predict(state, model, (state.t, float(tg[k])))
        prior = state.P.diagonal()[POS].copy()
        meas = GnssPosition(float(tg[k]), float(lat[k]), float(lon[k]), float(alt[k]), np.diag(var[k]), lever)
        state, inn = filt.update(state, model, meas)
        if inn.accepted and k_sample[k] >= 0:
            model.path[k_sample[k]] = state.x[:n_path]     # the epoch's own sample shows the posterior
        knot(prior)
        bias[k, :3] = state.x[NOMINAL_BG]
        bias[k, 3:] = state.x[NOMINAL_BA]
        bias_var[k, :3] = state.P.diagonal()[BG]
        bias_var[k, 3:] = state.P.diagonal()[BA]
        nu[k] = inn.nu
        nis[k] = inn.nis
        accepted[k] = inn.accepted
        forced[k] = inn.forced
        r_std[k] = np.sqrt(np.diagonal(inn.R))
        for name, value in filt.noise_report().items():
            if name not in adaptive:
                adaptive[name] = np.full((m_ep, np.size(value)), np.nan)
            adaptive[name][k] = value
        if progress is not None and k % tick == 0:
            progress(k / m_ep)
    # after the last fix the uncertainty keeps growing to the end of the log
    coast_to(float(imu.t[-1]))
    if state.t < imu.t[-1]:
        state = filt.predict(state, model, (state.t, float(imu.t[-1])))
        knot()
    if not np.all(np.isfinite(state.P)):
        raise FilterDivergedError(f"{filt.name}: covariance became non-finite by t = {state.t:.2f} s")
    if progress is not None:
        progress(1.0)

    path = model.path[al.index:]
    model.path = None
    t_out = imu.t[al.index:]
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
    diag = Diagnostics(tg, nu, nis, accepted, forced, r_std, named)
    bias_std = np.sqrt(np.maximum(bias_var, 0.0))     # a diverged run is reported by the checks below
    biases = BiasHistory(tg, bias[:, :3], bias[:, 3:], bias_std[:, :3], bias_std[:, 3:])
    rejected = int((~accepted).sum())
    warnings += list(al.warnings)
    warnings += _consistency_checks(recording.source, filt.name, config, tg, nis, accepted, list(warnings))
    return RunResult(solution, biases, al, diag, m_ep, rejected, time.perf_counter() - t_wall, 0.0,
                     tuple(warnings))


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


__all__ = ["Diagnostics", "RunResult", "run", "solution_from_path", "mounting_matrix"]
