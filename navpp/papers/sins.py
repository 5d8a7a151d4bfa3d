"""Paper 002's SINS/GPS simulation (section 4, Tables 1-6): EKF against the improved AEKF.

A 400-s straight and level flight at 200 m/s east from 39 deg N, 116 deg E, 1000 m; gyro
constant drift 0.1 deg/h, accelerometer constant bias 1e-4 g; GPS position and velocity with
white noise 6.5 m and 0.46 m/s; forgetting factor 0.978; filter period 0.1 s.  The filters
are the registry's (``ekf``, ``aekf``) with their default options, driven directly
(``predict`` to each GPS epoch, ``update``) on :class:`~navpp.ins.model.InsModel` with the
position + velocity measurement :class:`GnssPositionVelocity` defined here.

Truth.  Constant velocity in the ENU frame means constant latitude and height and a longitude
growing at ``v_E / ((R_N + h) cos L)``; the body keeps a constant attitude to the local level
frame (heading 90 deg, level), so the exact IMU is constant in time:
``w_ib_b = C^T (w_ie + w_en)`` and ``f_b = C^T ((2 w_ie + w_en) x v + g e_U)`` with navpp's own
Earth model (:mod:`navpp.geodesy`), the inverse of the strapdown's ENU mechanisation.  Fed
to navpp's strapdown this IMU reproduces the truth to micrometres over 400 s (the tests'
oracle).

Readings of the paper (it gives no more than the figures above; docs/algorithms.md, "The papers'
benchmarks: readings") are the fields of :class:`Paper002Scenario`, each documented there,
and are repeated in the benchmark's notes.

References: paper 002 section 4 and Tables 1-6; Groves (2013) eqs 5.53-5.54 (the ENU
mechanisation whose inverse gives the ideal IMU).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .. import geodesy
from ..engine.loop import EpochOutcome, run_epochs
from ..engine.schedule import Epoch
from ..errors import ConfigError, FilterDivergedError
from ..filters import GaussianState, Update
from ..filters.noise import SageHusaAdapter
from ..filters.protocols import MeasurementBase
from ..ins.attitude import dcm_to_quat, rph_to_dcm
from ..ins.model import POS, VEL, InsModel, NoiseModel, gnss_innovation, minus, plus
from ..ins.state import (
    NOMINAL_BA,
    NOMINAL_BG,
    NOMINAL_Q,
    NOMINAL_SIZE,
    NOMINAL_VEL,
    X_H,
    X_LAT,
    X_LON,
    X_VE,
)
from ..units import DEG_PER_H_TO_RAD_PER_S, DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S, DEG_TO_RAD, STANDARD_GRAVITY
from .filter_spec import make_bench_filter
from .registry import BenchResult, Row, register_benchmark
from .simulated import OneMeasurementPerEpoch, Recorder, measurement_epochs

AXES = ("E", "N", "U")

#: Paper 002, Tables 5 (velocity RMS, m/s) and 6 (position RMS, m): filter -> (E, N, U).
PAPER_VEL_RMS = {"ekf": (0.5217, 0.4071, 0.9369), "aekf": (0.2318, 0.2180, 0.2870)}
PAPER_POS_RMS = {"ekf": (9.8577, 8.3439, 24.2267), "aekf": (6.2181, 8.1796, 6.7595)}

TITLE = "Paper 002 SINS/GPS simulation (400 s, 200 m/s east, GPS 6.5 m / 0.46 m/s): EKF vs improved AEKF"

STEADY_AFTER_S = 100.0   #: start of the "steady state" figures in the notes, s

ARCMIN_TO_RAD = DEG_TO_RAD / 60.0              #: arcmin -> rad
UG_PER_SQRT_HZ_TO_MPS_PER_SQRT_S = STANDARD_GRAVITY * 1e-6   #: VRW, ug/sqrt(Hz) -> m/s^2/sqrt(Hz) = m/s/sqrt(s)


@dataclass(frozen=True)
class Paper002Scenario:
    """The simulation of paper 002 section 4, with navpp's readings where the paper is silent.

    Stated by the paper: ``duration_s``, ``lat_deg``, ``lon_deg``, ``h_m``, ``speed_east_mps``
    (north and up 0), roll and pitch 0 and yaw 90 deg (``heading_deg``), ``gyro_bias_deg_per_h``
    ("gyro random constant drift"), ``accel_bias_g`` ("accelerometer random constant zero
    bias"), ``gps_pos_std_m``, ``gps_vel_std_mps``, ``filter_period_s`` (the forgetting factor
    0.978 is the AEKF's default).

    Readings (the paper does not say):

    heading_deg : navpp's heading, clockwise from north (body FLU, ENU), so 90 deg is nose
        east, along the velocity: the paper's yaw 90 deg with v_E = 200 m/s read as a
        north-clockwise heading.  (navpp's internal ENU yaw, counter-clockwise from east, is 0.)
    gps_period_s : the GPS fix period; the paper names one period, the filter's 0.1 s, and
        navpp reads it as a GPS position + velocity update every 0.1 s (10 Hz).
    imu_rate_hz : not stated; 100 Hz.
    bias_draw : "random" (default): each run draws every axis' bias from N(0, sigma^2) with
        the paper's figures as sigma (a "random constant", also the filter's prior);
        "fixed": +sigma on every axis (a single deterministic bias).
    gyro_arw_deg_per_sqrt_h, accel_vrw_ug_per_sqrt_hz : white sensor noise, not stated by the
        paper; assumed values for a 0.1 deg/h-class IMU (0 turns it off).  The filter's Q uses
        the same densities (no bias drive: the biases are random constants).
    init_att_std_arcmin, init_vel_std_mps, init_pos_std_m : initial errors, not stated; each
        run draws them from N(0, P0) and the filter starts with that P0.  Level 1 arcmin
        (about what a 100 ug accelerometer bias allows), heading 30 arcmin (about what a
        0.1 deg/h gyro allows by gyrocompassing at 39 deg N), velocity and position from one
        GPS fix (0.46 m/s, 6.5 m); bias P0 is the bias sigma above.
    r_std_scale : the filter's assumed measurement std over the true one (1: filter R = true R).
    """

    duration_s: float = 400.0
    lat_deg: float = 39.0
    lon_deg: float = 116.0
    h_m: float = 1000.0
    speed_east_mps: float = 200.0
    heading_deg: float = 90.0
    gyro_bias_deg_per_h: float = 0.1
    accel_bias_g: float = 1e-4
    gps_pos_std_m: float = 6.5
    gps_vel_std_mps: float = 0.46
    filter_period_s: float = 0.1
    gps_period_s: float = 0.1
    imu_rate_hz: float = 100.0
    bias_draw: str = "random"
    gyro_arw_deg_per_sqrt_h: float = 0.01
    accel_vrw_ug_per_sqrt_hz: float = 10.0
    init_att_std_arcmin: tuple[float, float, float] = (1.0, 1.0, 30.0)
    init_vel_std_mps: float = 0.46
    init_pos_std_m: float = 6.5
    r_std_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.bias_draw not in ("random", "fixed"):
            raise ConfigError(f"paper002-sins: bias_draw must be 'random' or 'fixed', got {self.bias_draw!r}")
        for name in ("duration_s", "gps_period_s", "imu_rate_hz", "r_std_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"paper002-sins: {name} must be a finite number > 0, got {value!r}")
        if self.gps_period_s * self.imu_rate_hz < 1.0 - 1e-9:
            raise ConfigError("paper002-sins: the GPS period must span at least one IMU interval")

    # derived quantities ---------------------------------------------------------------------
    @property
    def gyro_bias_sigma(self) -> float:
        """rad/s."""
        return self.gyro_bias_deg_per_h * DEG_PER_H_TO_RAD_PER_S

    @property
    def accel_bias_sigma(self) -> float:
        """m/s^2."""
        return self.accel_bias_g * STANDARD_GRAVITY

    @property
    def gyro_arw(self) -> float:
        """rad/sqrt(s)."""
        return self.gyro_arw_deg_per_sqrt_h * DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S

    @property
    def accel_vrw(self) -> float:
        """m/s/sqrt(s)."""
        return self.accel_vrw_ug_per_sqrt_hz * UG_PER_SQRT_HZ_TO_MPS_PER_SQRT_S

    def noise_model(self) -> NoiseModel:
        """The filter's continuous noise: the true white-noise densities, constant biases."""
        return NoiseModel(self.gyro_arw, self.accel_vrw, 0.0, math.inf, 0.0, math.inf)

    def p0_std(self) -> np.ndarray:
        """(15,) initial 1-sigma in the error-state order of :mod:`navpp.ins.model`."""
        return np.concatenate([np.asarray(self.init_att_std_arcmin, dtype=float) * ARCMIN_TO_RAD,
                               np.full(3, self.init_vel_std_mps), np.full(3, self.init_pos_std_m),
                               np.full(3, self.gyro_bias_sigma), np.full(3, self.accel_bias_sigma)])

    def meas_std(self) -> np.ndarray:
        """(6,) true GPS 1-sigma: position E, N, U (m), velocity E, N, U (m/s)."""
        return np.array([self.gps_pos_std_m] * 3 + [self.gps_vel_std_mps] * 3)


# --------------------------------------------------------------------------- truth and IMU


def truth_states(sc: Paper002Scenario, t: np.ndarray) -> np.ndarray:
    """Exact nominal states (N, 16) of the straight and level flight at times ``t`` (s), biases 0.

    Constant ENU velocity and attitude, constant latitude and height, longitude linear in time.
    """
    t = np.asarray(t, dtype=float)
    lat, lon0, h = sc.lat_deg * DEG_TO_RAD, sc.lon_deg * DEG_TO_RAD, sc.h_m
    _, rn = geodesy.radii(lat)
    q = dcm_to_quat(rph_to_dcm(0.0, 0.0, sc.heading_deg * DEG_TO_RAD))
    x = np.zeros((t.size, NOMINAL_SIZE))
    x[:, NOMINAL_Q] = q
    x[:, X_VE] = sc.speed_east_mps
    x[:, X_LAT] = lat
    lon = lon0 + sc.speed_east_mps / ((rn + h) * math.cos(lat)) * t
    x[:, X_LON] = (lon + math.pi) % (2.0 * math.pi) - math.pi
    x[:, X_H] = h
    return x


def ideal_imu(sc: Paper002Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The exact, constant body rate (rad/s) and specific force (m/s^2), body FLU, (3,) each."""
    lat, h = sc.lat_deg * DEG_TO_RAD, sc.h_m
    vel = np.array([sc.speed_east_mps, 0.0, 0.0])
    mat_nb = rph_to_dcm(0.0, 0.0, sc.heading_deg * DEG_TO_RAD)
    w_ie = geodesy.earth_rate_enu(lat)
    w_en = geodesy.transport_rate_enu(lat, h, vel)
    f_n = np.cross(2.0 * w_ie + w_en, vel) + np.array([0.0, 0.0, geodesy.gravity(lat, h)])
    return mat_nb.T @ (w_ie + w_en), mat_nb.T @ f_n


def imu_times(sc: Paper002Scenario) -> np.ndarray:
    n = round(sc.duration_s * sc.imu_rate_hz)
    return np.arange(n + 1) / sc.imu_rate_hz


def gps_times(sc: Paper002Scenario) -> np.ndarray:
    n = math.floor(sc.duration_s / sc.gps_period_s + 1e-9)
    return np.arange(1, n + 1) * sc.gps_period_s


# --------------------------------------------------------------------------- measurement


@dataclass(frozen=True)
class GnssPositionVelocity(MeasurementBase):
    """GNSS position and velocity fix (antenna at the IMU) as a measurement of the 15-state model.

    Residual (6,): position fix minus INS position in local ENU metres about the nominal
    position (as :class:`~navpp.ins.model.GnssPosition`), then velocity fix minus INS
    velocity, ENU m/s.  ``R`` (6, 6): m^2 and (m/s)^2.  ``H = [[0, 0, I, 0, 0], [0, I, 0, 0, 0]]``.
    """

    t: float
    lat: float        # rad
    lon: float        # rad
    h: float          # m
    vel_enu: np.ndarray
    R: np.ndarray

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        d = np.empty(6)
        d[0:3] = gnss_innovation(x, self.lat, self.lon, self.h, np.zeros(3))
        d[3:6] = self.vel_enu - x[NOMINAL_VEL]
        return d

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        H = np.zeros((6, 15))
        H[0:3, POS] = np.eye(3)
        H[3:6, VEL] = np.eye(3)
        return H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) ⊟ h(x)``, (m, 6)."""
        dX = np.ascontiguousarray(dX, dtype=float)
        Z = np.empty((dX.shape[0], 6))
        for k in range(dX.shape[0]):
            Z[k, 0:3] = minus(plus(x, dX[k]), x)[POS]
        Z[:, 3:6] = dX[:, VEL]
        return Z


# --------------------------------------------------------------------------- one run


@dataclass(frozen=True, eq=False)
class SinsRun:
    """One Monte Carlo draw: the measured IMU, the GPS fixes, the truth and the initial state.

    t_imu (N,), gyro, accel (N, 3) body FLU measured; t_gps (M,); z_pos (M, 3) lat, lon (rad),
    h (m); z_vel (M, 3) ENU m/s; truth (M, 16) at the fixes; x0 (16,) and P0 (15, 15) the
    filter's start at t = 0; gyro_bias, accel_bias (3,) the true biases.
    """

    t_imu: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    t_gps: np.ndarray
    z_pos: np.ndarray
    z_vel: np.ndarray
    truth: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray


def simulate_run(sc: Paper002Scenario, rng: np.random.Generator) -> SinsRun:
    """Draw one run (order of draws fixed: biases, IMU white noise, initial error, GPS noise)."""
    t = imu_times(sc)
    n = t.size
    w, f = ideal_imu(sc)
    if sc.bias_draw == "random":
        bg = rng.normal(0.0, sc.gyro_bias_sigma, 3)
        ba = rng.normal(0.0, sc.accel_bias_sigma, 3)
    else:
        bg = np.full(3, sc.gyro_bias_sigma)
        ba = np.full(3, sc.accel_bias_sigma)
    dt = 1.0 / sc.imu_rate_hz
    gyro = w + bg + rng.standard_normal((n, 3)) * (sc.gyro_arw / math.sqrt(dt))
    accel = f + ba + rng.standard_normal((n, 3)) * (sc.accel_vrw / math.sqrt(dt))

    p0_std = sc.p0_std()
    x_true0 = truth_states(sc, np.zeros(1))[0]
    x_true0[NOMINAL_BG], x_true0[NOMINAL_BA] = bg, ba
    # the filter starts at truth ⊟ dx0 so that truth = x0 ⊞ dx0 with dx0 ~ N(0, P0)
    dx0 = rng.standard_normal(15) * p0_std
    x0 = _start_from(x_true0, dx0)

    tg = gps_times(sc)
    truth = truth_states(sc, tg)
    truth[:, NOMINAL_BG], truth[:, NOMINAL_BA] = bg, ba
    e_pos = rng.standard_normal((tg.size, 3)) * sc.gps_pos_std_m
    e_vel = rng.standard_normal((tg.size, 3)) * sc.gps_vel_std_mps
    rm, rn = geodesy.radii(truth[:, X_LAT])
    h = truth[:, X_H]
    z_pos = np.column_stack([truth[:, X_LAT] + e_pos[:, 1] / (rm + h),
                             truth[:, X_LON] + e_pos[:, 0] / ((rn + h) * np.cos(truth[:, X_LAT])),
                             h + e_pos[:, 2]])
    z_vel = truth[:, NOMINAL_VEL] + e_vel
    return SinsRun(t, gyro, accel, tg, z_pos, z_vel, truth, x0, np.diag(p0_std ** 2), bg, ba)


def _start_from(x_true: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """``x0`` with ``x0 ⊞ dx = x_true`` (Newton on ⊟; one step is exact to rounding for
    every block but the position scale, two settle it)."""
    x0 = plus(x_true, -dx)
    for _ in range(3):
        x0 = plus(x0, dx - minus(x_true, x0))
    return x0


@dataclass(frozen=True, eq=False)
class FilterRun:
    """What one filter did on one run: err (M, 6) truth ⊟ estimate after each update
    (position E, N, U m; velocity E, N, U m/s); std (M, 6) the filter's own 1-sigma of those;
    r_std (M, 6) sqrt(diag R) used at each update; r_final (6, 6) the filter's measurement
    noise after the last epoch (an adaptive filter's learnt R; the configured R otherwise);
    diverged: the error message, or ''."""

    err: np.ndarray
    std: np.ndarray
    r_std: np.ndarray
    r_final: np.ndarray
    diverged: str = ""


class SinsRecorder(Recorder):
    """Keeps what a :class:`FilterRun` holds: after each fix's update the error truth ⊟ estimate
    and the filter's 1-sigma (position E, N, U m; velocity E, N, U m/s) and the 1-sigma of the
    R used, (M, 6) each; ``r_last`` the last R used (6, 6)."""

    #: the position and velocity blocks of the error state, in that order
    IDX = np.r_[6:9, 3:6]

    def __init__(self, truth: np.ndarray, R: np.ndarray) -> None:
        m = truth.shape[0]
        self.truth = truth
        self.err, self.std, self.r_std = np.full((m, 6), np.nan), np.full((m, 6), np.nan), np.full((m, 6), np.nan)
        self.r_last = R

    def updated(self, epoch: Epoch, meas: Any, update: Update) -> None:
        self.r_std[epoch.index] = np.sqrt(np.diag(update.innovation.R))
        self.r_last = update.innovation.R

    def epoch_done(self, epoch: Epoch, outcome: EpochOutcome) -> None:
        k, state = epoch.index, outcome.state
        dx = minus(self.truth[k], state.x)
        self.err[k, 0:3], self.err[k, 3:6] = dx[POS], dx[VEL]
        self.std[k] = np.sqrt(state.P.diagonal()[self.IDX])


def run_filter(name: str, sc: Paper002Scenario, sim: SinsRun, seed: int = 0) -> FilterRun:
    """Drive filter ``name`` (default options, no gate) over ``sim`` on the engine's loop:
    predict to each fix, update."""
    filt = make_bench_filter(name, seed)
    model = InsModel(sim.t_imu, sim.gyro, sim.accel, sc.noise_model())
    R = np.diag((sc.meas_std() * sc.r_std_scale) ** 2)
    fixes = [GnssPositionVelocity(float(t), lat, lon, h, vel, R)
             for t, (lat, lon, h), vel in zip(sim.t_gps, sim.z_pos, sim.z_vel)]
    rec = SinsRecorder(sim.truth, R)
    state = GaussianState(float(sim.t_imu[0]), sim.x0.copy(), sim.P0.copy())
    try:
        run_epochs(filt, model, state, measurement_epochs(sim.t_gps), OneMeasurementPerEpoch(fixes), rec)
    except FilterDivergedError as exc:
        return FilterRun(rec.err, rec.std, rec.r_std, rec.r_last, str(exc))
    r_final = filt.adapter.R if isinstance(filt.adapter, SageHusaAdapter) else None
    return FilterRun(rec.err, rec.std, rec.r_std, np.array(rec.r_last if r_final is None else r_final))


# --------------------------------------------------------------------------- the benchmark


@dataclass(frozen=True)
class _Case:
    key: str
    label: str
    r_std_scale: float


CASES = (
    _Case("a", "a: filter R = true R", 1.0),
    _Case("b", "b: filter R std = true/4", 0.25),
)


@dataclass
class _Acc:
    """Per-filter accumulator over runs."""

    rms: list[np.ndarray] = field(default_factory=list)          # (6,) per run
    r_final_std: list[np.ndarray] = field(default_factory=list)  # (6,) per run
    sq_sum: np.ndarray | None = None                 # (M, 6) sum over runs of err^2
    r_sum: np.ndarray | None = None                  # (M, 6) sum over runs of r_std
    diverged: int = 0
    first_failure: str = ""

    def add(self, fr: FilterRun) -> None:
        """Count one filter run: a divergence, or its figures."""
        if fr.diverged:
            self.diverged += 1
            self.first_failure = self.first_failure or fr.diverged
            return
        self.rms.append(np.sqrt(np.mean(fr.err ** 2, axis=0)))
        self.r_final_std.append(np.sqrt(np.diag(fr.r_final)))
        self.sq_sum = fr.err ** 2 if self.sq_sum is None else self.sq_sum + fr.err ** 2
        self.r_sum = fr.r_std if self.r_sum is None else self.r_sum + fr.r_std


@register_benchmark("paper002-sins", TITLE, 20, ("ekf", "aekf"))
def run(runs: int, seed: int, filters: Sequence[str]) -> BenchResult:
    """Paper 002 section 4 over ``runs`` Monte Carlo runs (:func:`run_scenario` on the defaults)."""
    return run_scenario(Paper002Scenario(), runs, seed, filters)


def run_scenario(base: Paper002Scenario, runs: int, seed: int, filters: Sequence[str]) -> BenchResult:
    """Both cases (:data:`CASES`) on ``base`` over ``runs`` runs; every filter and both cases
    see the same draws (run i uses the i-th child of ``SeedSequence(seed)``).

    Rows per case and filter: position and velocity RMS per axis (mean over runs of each run's
    RMS over all fixes) next to the paper's Tables 6 and 5, and, for a filter whose R moved
    (the AEKF), its learnt R as 1-sigma per axis.  Series: ``t`` (M,), and per
    ``"{case}/{filter}"``: ``err_rms`` (M, 6) RMS over runs at each fix and ``r_std`` (M, 6)
    the mean over runs of the R 1-sigma used at each fix.
    """
    acc = _monte_carlo(base, runs, seed, filters)
    t_gps = gps_times(base)
    rows: list[Row] = []
    series: dict[str, np.ndarray] = {"t": t_gps}
    notes = _notes(base)
    steady = []
    for c in CASES:
        for f in filters:
            a = acc[(c.key, f)]
            tag = c.label + ("" if not a.diverged else f", {a.diverged}/{runs} diverged")
            if a.diverged:
                notes.append(f"case {c.key}, {f}: {a.diverged} of {runs} runs diverged and are left out "
                             f"(first: {a.first_failure})")
            if not a.rms:
                continue
            rows += _case_rows(base, c, f, a, tag)
            err_rms = np.sqrt(_summed(a.sq_sum) / len(a.rms))
            series[f"{c.key}/{f}/err_rms"] = err_rms
            series[f"{c.key}/{f}/r_std"] = _summed(a.r_sum) / len(a.rms)
            late = t_gps > STEADY_AFTER_S
            if late.any():
                pos = np.sqrt(np.mean(err_rms[late, 0:3] ** 2, axis=0))
                steady.append(f"{c.key} {f} {'/'.join(f'{v:.2f}' for v in pos)}")
    if steady:
        notes.append(_steady_note(steady))
    notes.append(_spread_note(acc, filters, runs))
    return BenchResult("paper002-sins", TITLE, rows, notes, runs, seed, series=series)


def _spread_note(acc: dict[tuple[str, str], _Acc], filters: Sequence[str], runs: int) -> str:
    """Per case and filter: the position RMS E/N/U (mean over runs) ± the sd of the per-run RMS,
    and the paired difference to the EKF (same draws; only when neither diverged in any run) ±
    the half-width of its 95 % t interval."""
    from scipy.stats import t as student_t

    parts = []
    for c in CASES:
        for f in filters:
            a = acc[(c.key, f)]
            if not a.rms:
                continue
            r = np.array(a.rms)[:, 0:3]
            sd = np.std(r, axis=0, ddof=1) if len(r) > 1 else np.zeros(3)
            text = f"{c.key} {f} {'/'.join(f'{m:.2f}±{e:.2f}' for m, e in zip(r.mean(axis=0), sd))}"
            ref = acc.get((c.key, "ekf"))
            if f != "ekf" and ref is not None and len(ref.rms) == len(a.rms) == runs and runs > 1:
                d = r - np.array(ref.rms)[:, 0:3]
                half = student_t.ppf(0.975, runs - 1) * np.std(d, axis=0, ddof=1) / np.sqrt(runs)
                text += f" (vs ekf {'/'.join(f'{m:+.2f}±{e:.2f}' for m, e in zip(d.mean(axis=0), half))})"
            parts.append(text)
    return ("Spread over runs, position RMS E/N/U in m: mean ± the sd of the per-run RMS, and the paired "
            "difference to the EKF ± the half-width of its 95 % interval (t over the runs): " + "; ".join(parts)
            + ".")


def _monte_carlo(base: Paper002Scenario, runs: int, seed: int, filters: Sequence[str]
                 ) -> dict[tuple[str, str], _Acc]:
    """Every filter on every case over ``runs`` simulated runs: (case key, filter) -> figures."""
    seeds = np.random.SeedSequence(seed).spawn(runs)
    acc = {(c.key, f): _Acc() for c in CASES for f in filters}
    for i in range(runs):
        sim = simulate_run(base, np.random.default_rng(seeds[i]))
        for c in CASES:
            sc = replace(base, r_std_scale=c.r_std_scale)
            for f in filters:
                acc[(c.key, f)].add(run_filter(f, sc, sim, seed=100_003 * seed + i))
    return acc


def _summed(total: np.ndarray | None) -> np.ndarray:
    """An accumulator's sum over runs (set once a run completed)."""
    assert total is not None
    return total


def _case_rows(base: Paper002Scenario, c: _Case, f: str, a: _Acc, tag: str) -> list[Row]:
    """Position and velocity RMS per axis of filter ``f`` on case ``c``, and its learnt R when
    it moved away from the configured one."""
    rows = []
    rms = np.mean(a.rms, axis=0)
    for j, ax in enumerate(AXES):
        rows.append(Row(f"position RMS {ax}", f, float(rms[j]), _paper(PAPER_POS_RMS, f, j), "m", tag))
    for j, ax in enumerate(AXES):
        rows.append(Row(f"velocity RMS {ax}", f, float(rms[3 + j]), _paper(PAPER_VEL_RMS, f, j), "m/s",
                        tag))
    true_std = base.meas_std()
    r_std = np.mean(a.r_final_std, axis=0)
    if not np.allclose(r_std, true_std * c.r_std_scale, rtol=1e-12, atol=0.0):
        for j, ax in enumerate(AXES):
            rows.append(Row(f"learnt R std, position {ax} (true {true_std[j]:g})", f, float(r_std[j]),
                            None, "m", tag))
        for j, ax in enumerate(AXES):
            rows.append(Row(f"learnt R std, velocity {ax} (true {true_std[3 + j]:g})", f,
                            float(r_std[3 + j]), None, "m/s", tag))
    return rows


def _steady_note(steady: list[str]) -> str:
    """The note on the position RMS after :data:`STEADY_AFTER_S` (one entry per case and filter)."""
    return (f"Position RMS E/N/U (m) after t = {STEADY_AFTER_S:g} s, pooled over runs: "
            + "; ".join(steady) + ". The cases and filters differ mostly in the first tens of "
            "seconds: with a Q this small the EKF is close to weighted least squares, whose "
            "estimate does not change when every R is scaled alike, so case b costs the EKF "
            "little; the AEKF starts case b with the small R (high gain, P shrinks), then "
            "learns the true R within seconds while P stays over-confident, so it weights "
            "the first fixes more than the later ones and converges more slowly.")


def _paper(table: dict, f: str, j: int) -> float | None:
    return table[f][j] if f in table else None


def _notes(sc: Paper002Scenario) -> list[str]:
    att = "/".join(f"{v:g}" for v in sc.init_att_std_arcmin)
    return [
        ("Paper 002 gives one run; ours: mean over runs of each run's RMS over all fixes "
         f"({sc.gps_period_s:g}-{sc.duration_s:g} s, after each update), error = truth ⊟ estimate. "
         "The same draws feed every filter and both cases."),
        (f"Truth: {sc.speed_east_mps:g} m/s east at {sc.lat_deg:g}N {sc.lon_deg:g}E {sc.h_m:g} m on WGS-84 "
         "(constant latitude and height), level, heading 90 deg clockwise from north = nose east: the "
         "paper's 'yaw angle is 90°' with 'velocity of east ... 200m/s' read as a north-clockwise "
         "heading (navpp's convention; a counter-clockwise yaw would fly tail first, and with random "
         "biases it is statistically the same flight). The exact IMU is constant (body rate = Earth + "
         "transport rate, specific force = Coriolis + gravity) and integrates back to the truth."),
        (f"Sensors: biases are random constants, N(0, sigma^2) per axis and run with the paper's "
         f"{sc.gyro_bias_deg_per_h:g} deg/h and {sc.accel_bias_g:g} g as sigma (reading of 'random "
         "constant'; bias_draw='fixed' puts +sigma on every axis). White noise, not stated by the "
         f"paper: assumed ARW {sc.gyro_arw_deg_per_sqrt_h:g} deg/sqrt(h), VRW "
         f"{sc.accel_vrw_ug_per_sqrt_hz:g} ug/sqrt(Hz); IMU at {sc.imu_rate_hz:g} Hz (not stated). The "
         "filter's Q has the same densities and no bias drive."),
        (f"GPS: position and velocity fixes every {sc.gps_period_s:g} s (the paper's only period, "
         "'filter period is 0.1s', read as one fix per filter step), white noise "
         f"{sc.gps_pos_std_m:g} m / {sc.gps_vel_std_mps:g} m/s per ENU axis, antenna at the IMU. "
         "No innovation gate (the paper has none)."),
        (f"Initial errors (not stated): drawn per run from N(0, P0), P0 1-sigma attitude {att} arcmin "
         f"(E/N/U), velocity {sc.init_vel_std_mps:g} m/s, position {sc.init_pos_std_m:g} m (one GPS fix), "
         "biases at their sigma."),
        ("Filters: registry defaults (aekf: forgetting factor 0.978 = the paper's b, prior_epochs 20, "
         "estimate_mean off). The paper does not say how its true GPS noise differs from the "
         "filters' R. Case a: filter R = true R. Case b: the filters assume a std 4x too small "
         "(R/16), read from the paper's 'the error curves calculated by EKF are rough' and 'oscillate "
         "hundreds of seconds' against the AEKF's 'smooth and convergent' curves: what a filter that "
         "trusts the GPS too much (too small an R) shows, and what learning R repairs."),
        ("Learnt R (AEKF): sqrt(diag) of the adapter's R after the last fix, mean over runs. The "
         "improved recursion R = (1-d) R + d e e' tracks the innovation covariance H P- H' + R_true, "
         "so it sits at or slightly above the true R by construction."),
        ("Where we differ: the paper's EKF position RMS (9.9/8.3/24.2 m) exceeds its own GPS noise "
         "(6.5 m) and its AEKF's (6.2/8.2/6.8 m) is about that noise, i.e. neither filter averages the "
         "GPS down; on this reading a 10 Hz position + velocity filter does, by an order of "
         "magnitude, in both cases and for both filters, and the AEKF is not better than the EKF. "
         "Other readings (fixed biases, no or 10x white noise, nose west) move our figures by tens of "
         "percent, GPS at 1 Hz by about 3x, none toward the paper's. Its Q, P0, initial errors and "
         "noise mismatch are unstated and its Figs 3-4 are lost; nothing here is tuned toward its "
         "numbers."),
    ]
