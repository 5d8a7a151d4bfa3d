"""When the engine applies which aid (part of the engine: the only code that knows time).

The measurement models live in :mod:`navpp.ins.aids`, one per file; this module decides, from
the configuration and the data, at which times they apply:

- **GNSS velocity** at every GNSS epoch whose fix carries a velocity (``[gnss] use_velocity``),
  with the log's velocity sigma or ``[gnss] default_vel_std_mps``, after the position update
  (when the default is used, :func:`navpp.engine.verdict.velocity_sigma_checks` warns if the
  velocity innovations show it far off, with the value they suggest).
- **Constraints** (NHC for ``[vehicle] type = "car"``; ZUPT and ZARU while still) on a grid at
  ``[vehicle] rate_hz``: a grid time within half a period of a GNSS epoch rides on that epoch;
  the others are epochs of their own, so the constraints keep working through GNSS outages.
- **Odometer** (the log's odometry, ``[odometry] use``) at every constraint epoch, its speed
  interpolated between the two samples around the epoch; with ``[odometry] use_yaw_rate`` its yaw
  rate too, against the mean gyro over one odometry interval centred on the epoch.
- **Standstill**: :func:`navpp.ins.aids.standstill.still_mask` on the IMU, or odometry that reads
  zero (at most ``[odometry] still_speed_mps``) over a whole detector window on either side, and
  the speed gate on the filter's speed (and the GNSS speed when the log has velocity, and the
  odometer's) at the epoch.  ZARU measures the mean gyro output since the previous constraint
  epoch, when every sample in between is still.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .config import Config
from .geodesy import gravity
from .ins.aids import GnssVelocity, NonHolonomic, ZeroRate, ZeroVelocity
from .ins.aids.odometer import OdometerSpeed
from .ins.aids.standstill import StandstillSettings, speed_allows, still_mask
from .ins.aids.yaw_rate import OdometerYawRate
from .ins.attitude import quat_to_dcm, rpy_deg_to_dcm
from .ins.model import VEL
from .ins.state import NOMINAL_Q, X_H, X_LAT
from .intervals import interval_median
from .spill import Behind
from .units import STANDARD_GRAVITY

#: Aid kinds in the order they are reported (the GNSS position first).
KINDS = ("gnss_position", "gnss_velocity", "zupt", "zaru", "nhc", "odometer", "odometer_yaw")

#: ZUPT's consistency check (:meth:`Aiding.observed`): the last this many innovations, and the
#: sigmas their mean may reach on an axis (white innovations: false alarm ~1e-6 per test).
ZUPT_RUN = 10
ZUPT_Z = 5.0
#: constraint epochs whose gyro samples :meth:`Aiding.zero_rates` gathers at a time
ZARU_GATHER = 256


def vehicle_matrix(rpy_deg: tuple[float, float, float]) -> np.ndarray:
    """Body -> vehicle rotation ``C_vb`` for the vehicle frame's roll, pitch, yaw (deg) relative to
    the body: the vehicle axes are the body axes rotated by ``R = Rz Ry Rx``, so a body vector has
    vehicle coordinates ``R^T v``."""
    return rpy_deg_to_dcm(rpy_deg).T


@dataclass
class AidCounts:
    """Updates applied and rejected by the innovation gate, per kind (:data:`KINDS`)."""

    applied: dict[str, int]
    rejected: dict[str, int]

    @classmethod
    def empty(cls) -> AidCounts:
        return cls({k: 0 for k in KINDS}, {k: 0 for k in KINDS})

    def add(self, kind: str, accepted: bool) -> None:
        (self.applied if accepted else self.rejected)[kind] += 1

    def as_dict(self) -> dict[str, dict[str, int]]:
        """``{kind: {"applied": n, "rejected": n}}`` for the kinds that were tried."""
        return {k: {"applied": self.applied[k], "rejected": self.rejected[k]} for k in KINDS
                if self.applied[k] or self.rejected[k]}


@dataclass
class ZuptCheck:
    """ZUPT's consistency check (:meth:`Aiding.observed`) as it stands: ``z``, the last normalised
    innovations (each (3,), oldest first, at most :data:`ZUPT_RUN`) of still run ``run`` (-1:
    none); ``vetoed_run``, the still run it has stopped (-1: none)."""

    run: int = -1
    z: list[np.ndarray] = field(default_factory=list)
    vetoed_run: int = -1

    def add(self, run: int, z: np.ndarray) -> bool:
        """ZUPT's normalised innovation ``z`` (3,) in still run ``run``; True when the mean of the
        last :data:`ZUPT_RUN` is beyond :data:`ZUPT_Z` sigmas on an axis (``run`` is then vetoed)."""
        if self.run != run:
            self.z = []
        self.run = run
        self.z.append(z)
        if len(self.z) > ZUPT_RUN:
            self.z.pop(0)
        if len(self.z) == ZUPT_RUN:
            mean = np.mean(self.z, axis=0) * math.sqrt(ZUPT_RUN)
            if np.any(np.abs(mean) > ZUPT_Z):
                self.vetoed_run = run
                self.z = []
                return True
        return False


class StillRuns:
    """The still runs of an IMU-rate mask ``still`` (N,) bool, numbered as ``np.cumsum(~still)``
    numbers the samples (:class:`ZuptCheck`: a still sample's number is its run's; a moving
    sample's, the moving samples up to it), kept as the runs' bounds alone: O(runs) memory, not
    the 8 bytes per IMU sample of the cumulative sum (29 MB for an 8-hour 125 Hz log).

    ``start``, ``stop`` (R,) the sample ranges ``start:stop`` of the R runs; ``before`` (R,) the
    still samples before each run."""

    def __init__(self, still: np.ndarray) -> None:
        edge = np.diff(still.view(np.int8), prepend=np.int8(0), append=np.int8(0))   # +1 a run starts, -1 ends
        self.start = np.flatnonzero(edge == 1)
        self.stop = np.flatnonzero(edge == -1)
        self.before = np.concatenate([[0], np.cumsum(self.stop - self.start)[:-1]]).astype(np.int64)
        self._from, self._to, self._run = 0, 0, (0, 0)      # number_at's last run: samples from:to

    def number(self, i: np.ndarray | int) -> np.ndarray:
        """``np.cumsum(~still)[i]`` for sample indices ``i`` (int or (K,) int, in ``0 .. N-1``):
        ``i + 1`` less the still samples up to ``i``."""
        i = np.asarray(i, dtype=np.int64)
        j = np.searchsorted(self.start, i, side="right") - 1          # the last run starting at or before i
        jc = np.maximum(j, 0)
        still_upto = np.where(j >= 0, self.before[jc] + np.minimum(i + 1, self.stop[jc]) - self.start[jc], 0) \
            if self.start.size else np.zeros(i.shape, np.int64)
        out: np.ndarray = i + 1 - still_upto
        return out

    def number_at(self, i: int) -> int:
        """:meth:`number` of the one sample ``i`` (a Python int: the per-epoch loop's, whose
        consecutive calls mostly fall between the same two run starts: those are kept)."""
        if not self._from <= i < self._to:
            j = int(np.searchsorted(self.start, i, side="right")) - 1
            self._from = int(self.start[j]) if j >= 0 else -1
            self._to = int(self.start[j + 1]) if j + 1 < self.start.shape[0] else 2 ** 62
            self._run = (int(self.stop[j]), int(self.before[j]) - self._from) if j >= 0 else (0, 0)
        stop, base = self._run           # the run's end; still samples before it less its start (0, 0: none)
        return i + 1 - base - min(i + 1, stop)


class Aiding:
    """The aids of one run (see the module docstring).

    Parameters
    ----------
    config : the run's configuration.
    t, gyro, accel : the IMU as the model sees it (s; rad/s and m/s^2, body FLU, mounting applied).
    gyro_arw, accel_vrw : white noise of the configured IMU (rad/sqrt(s), m/s/sqrt(s)).
    gnss : the recording's GNSS; ``sel`` the indices of the fixes the engine uses, in order.
    mounting_rpy_deg : the vehicle frame's roll, pitch, yaw relative to the body (deg), overriding
        ``[vehicle] mounting_rpy_deg`` (the engine's estimate when that is ``"auto"``).
    still : (N,) bool, the still samples as calibration found them
        (:func:`navpp.ins.calibrate.standstill`); None: the fixed-threshold detector of
        :func:`navpp.ins.aids.standstill.still_mask` with the ``[vehicle]`` thresholds.
    profile : :class:`navpp.ins.calibrate.NoiseProfile` or None, the data's noise per second: ZARU's
        mean-rate 1-sigma uses the larger of it and ``gyro_arw``.
    gaps : (K, 2) s, the long IMU gaps (:attr:`navpp.ins.model.InsModel.gaps`): no constraint
        epoch is placed inside one (there is no IMU to say whether the vehicle is still, and the
        model's unseen-motion noise of a gap must not be cut into pieces).
    """

    def __init__(self, config: Config, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gyro_arw: float,
                 accel_vrw: float, gnss, sel: np.ndarray, gaps: np.ndarray | None = None,
                 mounting_rpy_deg: tuple[float, float, float] | None = None, still: np.ndarray | None = None,
                 profile=None, odometry=None) -> None:
        veh = config.vehicle
        self.profile = profile            # the data's noise (navpp.ins.calibrate.NoiseProfile) or None
        self.t, self.gyro, self.accel = t, gyro, accel
        self.imu_period = max(interval_median(t), 1e-9) if t.shape[0] > 1 else 1.0   # s
        self.gaps = np.zeros((0, 2)) if gaps is None else np.asarray(gaps, dtype=float).reshape(-1, 2)
        self.gyro_arw = gyro_arw
        self.nhc = veh.type == "car" and veh.nhc
        self.zupt, self.zaru = veh.zupt, veh.zaru
        self.settings = StandstillSettings(window_s=veh.still_window_s, accel_floor=veh.still_accel_std_mps2,
                                           gyro_floor=math.radians(veh.still_gyro_std_dps),
                                           max_speed=veh.still_max_speed_mps)
        # the odometer: the log's speed (m/s, vehicle x) and its 1-sigma, when [odometry] use
        self.odo = odometry if (odometry is not None and config.odometry.use and len(odometry) >= 2) else None
        self.odo_yaw = False
        if self.odo is not None:
            o, oc = self.odo, config.odometry
            self.odo_std = (np.asarray(o.std_speed, dtype=float) if o.std_speed is not None
                            else np.full(len(o), oc.std_mps))
            self.odo_point = np.asarray(oc.lever_arm_m, dtype=float)
            self.odo_period = float(np.median(np.diff(o.t)))
            self.odo_gap = 2.0 * self.odo_period     # longest interval read across, s
            self.odo_yaw = oc.use_yaw_rate and o.yaw_rate is not None
            self.odo_slip = oc.slip_per_g
            if self.odo_yaw:
                self.odo_yaw_std = (np.asarray(o.std_yaw_rate, dtype=float) if o.std_yaw_rate is not None
                                    else np.full(len(o), math.radians(oc.yaw_rate_std_dps)))
        if not (self.zupt or self.zaru):
            self.still = np.zeros(t.shape[0], bool)
        else:
            self.still = still if still is not None else still_mask(t, gyro, accel, gyro_arw, accel_vrw, self.settings)
            if self.odo is not None and config.odometry.still_speed_mps > 0.0:
                self.still = self.still | odometry_zero(t, self.odo.t, self.odo.speed, config.odometry.still_speed_mps,
                                                        veh.still_window_s, self.odo_gap)
        self.rate_hz = veh.rate_hz
        self.nhc_std = veh.nhc_std_mps
        mounting = mounting_rpy_deg if mounting_rpy_deg is not None else veh.mounting_rpy_deg
        self.c_vb = vehicle_matrix(mounting if mounting != "auto" else (0.0, 0.0, 0.0))
        self.nhc_point = np.asarray(veh.nhc_point_m, dtype=float)
        self.zupt_std = veh.zupt_std_mps
        self.zaru_floor = math.radians(veh.zaru_std_dps)
        self.lever = np.asarray(config.gnss.lever_arm_m, dtype=float)
        self.vel = self.vel_var = None
        if config.gnss.use_velocity and gnss.vel_enu is not None:
            v = np.asarray(gnss.vel_enu, dtype=float)[sel]
            if gnss.std_vel_enu is not None:
                var = np.square(np.asarray(gnss.std_vel_enu, dtype=float)[sel])
            else:
                var = np.full(v.shape, config.gnss.default_vel_std_mps ** 2)
            ok = np.all(np.isfinite(v), axis=1) & np.all(np.isfinite(var) & (var > 0.0), axis=1)
            self.vel, self.vel_var, self.vel_ok = v, var, ok
            self.vel_t = np.asarray(gnss.t, dtype=float)[sel]
        self.counts = AidCounts.empty()
        #: the time of the last constraint epoch (s; None before the first): ZARU's mean gyro starts there
        self.last_constraint_t: float | None = None
        # the still runs, numbered (ZUPT's own consistency check stops a run that is not still)
        self._runs = StillRuns(self.still) if (self.zupt or self.zaru) else None
        self.zupt_check = ZuptCheck()
        self.vetoes: list[float] = []

    @property
    def constraints(self) -> bool:
        return self.nhc or self.zupt or self.zaru or self.odo is not None

    @property
    def recorded_kinds(self) -> tuple[str, ...]:
        """The one-element aids of this run whose updates the diagnostics record per GNSS epoch."""
        return (("odometer",) if self.odo is not None else ()) + (("odometer_yaw",) if self.odo_yaw else ())

    @property
    def has_velocity(self) -> bool:
        return self.vel is not None

    def schedule(self, t_start: float, t_end: float, tg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Epochs in ``(t_start, t_end]``: times (s), the GNSS fix index at each (-1: none) and
        whether the constraints apply there.  ``tg`` are the GNSS epochs (increasing)."""
        m = tg.shape[0]
        if not self.constraints:
            return tg.copy(), np.arange(m), np.zeros(m, bool)
        period = 1.0 / self.rate_hz
        grid = np.arange(math.floor(t_start / period) + 1, math.floor(t_end / period) + 1) * period
        grid = grid[(grid > t_start) & (grid <= t_end)]
        for a, b in self.gaps:
            grid = grid[(grid <= a) | (grid >= b)]
        # each grid time rides on the nearest GNSS epoch when that is within half a period
        on_fix = np.zeros(m, bool)
        alone = np.ones(grid.shape, bool)
        if m:
            after = np.searchsorted(tg, grid)
            lo, hi = np.clip(after - 1, 0, m - 1), np.clip(after, 0, m - 1)     # the epochs either side
            near = np.where(np.abs(tg[lo] - grid) <= np.abs(tg[hi] - grid), lo, hi)
            close = np.abs(tg[near] - grid) <= 0.5 * period
            on_fix[near[close]] = True
            alone = ~close
        times = np.concatenate([tg, grid[alone]])
        fix = np.concatenate([np.arange(m), np.full(int(alone.sum()), -1)])
        cons = np.concatenate([on_fix, np.ones(int(alone.sum()), bool)])
        order = np.argsort(times, kind="stable")
        times, fix, cons = times[order], fix[order], cons[order]
        if not (self.nhc or self.odo is not None):   # ZUPT / ZARU only: none where the IMU is not still
            i = np.clip(np.searchsorted(self.t, times), 0, self.t.shape[0] - 1)
            cons &= self.still[i]
            keep = (fix >= 0) | cons
            times, fix, cons = times[keep], fix[keep], cons[keep]
        return times, fix, cons

    def still_runs(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At each epoch time ``t`` (s): whether the IMU sample :meth:`constraint_measurements`
        reads there is still, and the number of its still run (:class:`ZuptCheck`; 0 without ZUPT
        or ZARU)."""
        i = np.clip(np.searchsorted(self.t, t), 0, self.t.shape[0] - 1)
        runs = self._runs.number(i) if self._runs is not None else np.zeros(i.shape, np.int64)
        return self.still[i], runs

    def _gyro_at(self, t: float) -> np.ndarray:
        i = int(np.searchsorted(self.t, t))
        if i <= 0:
            return self.gyro[0].copy()
        if i >= self.t.shape[0]:
            return self.gyro[-1].copy()
        w = (t - self.t[i - 1]) / (self.t[i] - self.t[i - 1])
        return (1.0 - w) * self.gyro[i - 1] + w * self.gyro[i]

    def velocity(self, k: int, t: float) -> GnssVelocity | None:
        """The GNSS velocity measurement of fix ``k`` (None without one)."""
        if self.vel is None or not self.vel_ok[k]:
            return None
        return GnssVelocity.at(t, self.vel[k], self.vel_var[k], self._gyro_at(t), self.lever)

    def _gnss_still(self, t: float) -> bool:
        """The GNSS speed nearest ``t`` (within 1 s) allows standing still; True without velocity."""
        if self.vel is None:
            return True
        i = int(np.clip(np.searchsorted(self.vel_t, t), 0, self.vel_t.shape[0] - 1))
        for j in (i - 1, i):
            if 0 <= j < self.vel_t.shape[0] and abs(self.vel_t[j] - t) <= 1.0 and self.vel_ok[j]:
                speed = float(np.linalg.norm(self.vel[j]))
                return speed_allows(speed, float(np.sqrt(self.vel_var[j].sum())), self.settings)
        return True

    def _odometer_still(self, t: float) -> bool:
        """The odometer's speed at ``t`` allows standing still (as the GNSS speed must,
        :func:`~navpp.ins.aids.standstill.speed_allows`); True without an odometer reading: a
        turning wheel vetoes a standstill the IMU's quiet would otherwise declare (a smooth
        glide, a vehicle on a ferry)."""
        odo = self.odometer(t)
        if odo is None:
            return True
        return speed_allows(abs(float(odo.z[0])), float(np.sqrt(odo.R[0, 0])), self.settings)

    def observed(self, meas, inn) -> None:
        """What an applied constraint saw.  ZUPT's innovations at rest are white; a run of them
        that keeps one direction (the mean of the last ``ZUPT_RUN`` normalised innovations beyond
        ``ZUPT_Z`` sigmas on an axis) is velocity building up: the vehicle is pulling away gently
        (too smoothly for the standstill detector), and the rest of this still run gets no ZUPT or
        ZARU (``vetoes`` records when)."""
        if meas.kind != "zupt" or self._runs is None:
            return
        i = int(np.clip(np.searchsorted(self.t, inn.t), 0, self.t.shape[0] - 1))
        sd = np.sqrt(np.maximum(np.diagonal(inn.S), 1e-30))
        if self.zupt_check.add(self._runs.number_at(i), np.asarray(inn.nu, dtype=float) / sd):
            self.vetoes.append(float(inn.t))

    def _odometry_at(self, t: float, values: np.ndarray, std: np.ndarray) -> tuple[float, float] | None:
        """An odometry quantity at ``t`` and its 1-sigma: linear between the two samples around ``t``
        when they are at most two median periods apart (the larger sigma), None otherwise."""
        o = self.odo
        j = int(np.searchsorted(o.t, t))
        if j <= 0 or j >= len(o) or o.t[j] - o.t[j - 1] > self.odo_gap:
            if 0 <= j < len(o) and o.t[j] == t:
                value, sd = float(values[j]), float(std[j])
            else:
                return None
        else:
            w = (t - o.t[j - 1]) / (o.t[j] - o.t[j - 1])
            value = float((1.0 - w) * values[j - 1] + w * values[j])
            sd = float(max(std[j - 1], std[j]))
        if not (math.isfinite(value) and math.isfinite(sd) and sd > 0.0):
            return None
        return value, sd

    def _imu_window(self, t: float) -> tuple[int, int]:
        """IMU samples ``lo:hi`` within one odometry interval centred on ``t`` (at least one)."""
        half = 0.5 * self.odo_period
        lo = int(np.searchsorted(self.t, t - half))
        hi = int(np.searchsorted(self.t, t + half, side="right"))
        if hi <= lo:
            lo = int(np.clip(np.searchsorted(self.t, t), 0, self.t.shape[0] - 1))
            hi = lo + 1
        return lo, hi

    def forward_acceleration(self, t: float, x: np.ndarray) -> float:
        """The vehicle's forward acceleration (m/s^2, vehicle x) around ``t``: the mean specific
        force over one odometry interval plus gravity, rotated by the nominal ``x``'s attitude."""
        lo, hi = self._imu_window(t)
        g_n = np.array([0.0, 0.0, -float(gravity(float(x[X_LAT]), float(x[X_H])))])
        a_b = self.accel[lo:hi].mean(axis=0) + quat_to_dcm(np.ascontiguousarray(x[NOMINAL_Q])).T @ g_n
        return float((self.c_vb @ a_b)[0])

    def odometer(self, t: float, x: np.ndarray | None = None) -> OdometerSpeed | None:
        """The odometer's speed at ``t`` (:meth:`_odometry_at`), None without one.  Given the
        nominal ``x``, its 1-sigma grows with the forward acceleration, for wheels slip when they
        drive or brake hard: ``sigma^2 = sigma_0^2 + (slip_per_g |a| / g |speed|)^2``
        (``[odometry] slip_per_g``)."""
        if self.odo is None:
            return None
        got = self._odometry_at(t, self.odo.speed, self.odo_std)
        if got is None:
            return None
        speed, sd = got
        if x is not None and self.odo_slip > 0.0 and speed != 0.0:
            slip = self.odo_slip * abs(self.forward_acceleration(t, x)) / STANDARD_GRAVITY * abs(speed)
            sd = math.hypot(sd, slip)
        return OdometerSpeed.at(t, speed, sd, self.c_vb, self._gyro_at(t), self.odo_point)

    def odometer_yaw(self, t: float) -> OdometerYawRate | None:
        """The odometry's yaw rate at ``t`` (``[odometry] use_yaw_rate``), None without one: against
        the mean gyro over one odometry interval centred on ``t``."""
        if not self.odo_yaw:
            return None
        got = self._odometry_at(t, self.odo.yaw_rate, self.odo_yaw_std)
        if got is None:
            return None
        lo, hi = self._imu_window(t)
        if hi - lo < 2:                          # the IMU is no faster than the odometry
            gyro, n = self._gyro_at(t), 1
        else:
            gyro, n = self.gyro[lo:hi].mean(axis=0), hi - lo
        var = self.gyro_arw ** 2 / (n * self.imu_period)      # the mean's white noise, (rad/s)^2
        return OdometerYawRate.at(t, got[0], got[1], self.c_vb, gyro, var)

    def constraint_measurements(self, t: float, x: np.ndarray, P: np.ndarray) -> list:
        """The constraints that apply at epoch ``t`` given the prior (nominal ``x``, covariance
        ``P``): NHC for a car; ZUPT and ZARU when the IMU around ``t`` is still and the speeds
        allow it."""
        out: list = []
        t_prev, self.last_constraint_t = self.last_constraint_t, t
        if self.nhc:
            out.append(NonHolonomic.at(t, self.nhc_std, self.c_vb, self._gyro_at(t), self.nhc_point))
        odo = self.odometer(t, x)
        if odo is not None:
            out.append(odo)
        yaw = self.odometer_yaw(t)
        if yaw is not None:
            out.append(yaw)
        if not (self.zupt or self.zaru):
            return out
        i = int(np.clip(np.searchsorted(self.t, t), 0, self.t.shape[0] - 1))
        if not self.still[i]:
            return out
        if self._runs is not None and self._runs.number_at(i) == self.zupt_check.vetoed_run:
            return out
        speed = float(np.linalg.norm(x[4:7]))
        speed_std = float(np.sqrt(max(np.trace(P[VEL, VEL]), 0.0)))
        if not (speed_allows(speed, speed_std, self.settings) and self._gnss_still(t) and self._odometer_still(t)):
            return out
        if self.zupt:
            out.append(ZeroVelocity.at(t, self.zupt_std))
        if self.zaru:
            zaru = self.zero_rate(t_prev, t)
            if zaru is not None:
                out.append(zaru)
        return out

    def zero_rate(self, t_prev: float | None, t: float) -> ZeroRate | None:
        """The ZARU at ``t`` s: the mean gyro (rad/s, body FLU) since the previous constraint epoch
        ``t_prev`` s, when every IMU sample between them is still (None otherwise, or without a
        previous epoch)."""
        if t_prev is None:
            return None
        lo, hi = np.searchsorted(self.t, t_prev, side="right"), np.searchsorted(self.t, t, side="right")
        if not (hi - lo >= 2 and self.still[lo:hi].all()):
            return None
        arw = self.gyro_arw
        if self.profile is not None:          # an idling engine shakes the mean rate too
            arw = max(arw, self.profile.over(t_prev, t)[0])
        return ZeroRate.at(t, self.gyro[lo:hi].mean(axis=0), t - t_prev, arw, self.zaru_floor)

    def zero_rates(self, t_prev: float | None, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`zero_rate` at each of the constraint epochs ``t`` (E,) s in turn, each since the
        one before it (the first since ``t_prev``): whether there is one (E,) bool, its value
        (E, 3) rad/s body FLU and its R's diagonal (E,) (rad/s)^2, the same figures.  The mean
        rates of the epochs with as many samples are taken together; a spilled gyro's rows
        leave memory behind the epochs (:class:`~navpp.spill.Behind`)."""
        n = t.shape[0]
        ok, z, var = np.zeros(n, bool), np.zeros((n, 3)), np.zeros(n)
        if n == 0:
            return ok, z, var
        since = np.concatenate([[t[0] if t_prev is None else t_prev], t[:-1]])
        lo, hi = np.searchsorted(self.t, since, side="right"), np.searchsorted(self.t, t, side="right")
        ok = hi - lo >= 2       # without t_prev the first epoch spans no samples
        for e in np.flatnonzero(ok):
            ok[e] = self.still[lo[e]:hi[e]].all()
        behind = Behind(self.t, self.gyro)
        size = hi - lo
        for m in np.unique(size[ok]):
            at = np.flatnonzero(ok & (size == m))
            for part in np.array_split(at, max(1, at.size // ZARU_GATHER)):
                z[part] = self.gyro[lo[part, None] + np.arange(m)].mean(axis=1)
                behind(float(t[part[-1]]))
        for e in np.flatnonzero(ok):
            t0, t1 = float(since[e]), float(t[e])
            arw = self.gyro_arw if self.profile is None else max(self.gyro_arw, self.profile.over(t0, t1)[0])
            var[e] = ZeroRate.variance(t1 - t0, arw, self.zaru_floor)
        return ok, z, var


def odometry_zero(t: np.ndarray, odo_t: np.ndarray, speed: np.ndarray, max_speed: float, window_s: float,
                  max_gap: float) -> np.ndarray:
    """(N,) bool at the IMU times ``t`` (s): the odometry (times ``odo_t`` s, ``speed`` m/s) reads at
    most ``max_speed`` at every sample within ``window_s`` on either side of the sample, and covers
    that span (a sample within ``max_gap`` s of each end, none further apart than ``max_gap``):
    wheels that count no ticks, evidence of standing still of its own."""
    zero = np.abs(np.asarray(speed, dtype=float)) <= max_speed      # NaN reads as moving
    odo_t = np.asarray(odo_t, dtype=float)
    moving = np.concatenate([[0], np.cumsum(~zero)])
    gap_after = np.concatenate([[0], np.cumsum(np.diff(odo_t) > max_gap)])   # gaps before sample j
    lo = np.searchsorted(odo_t, t - window_s, side="left")
    hi = np.searchsorted(odo_t, t + window_s, side="right")            # samples lo .. hi-1
    n = odo_t.shape[0]
    ok = hi - lo >= 2
    lo_c, hi_c = np.clip(lo, 0, n - 1), np.clip(hi - 1, 0, n - 1)
    ok &= moving[hi] - moving[lo] == 0
    ok &= gap_after[hi_c] - gap_after[lo_c] == 0
    ok &= (odo_t[lo_c] - (t - window_s) <= max_gap) & ((t + window_s) - odo_t[hi_c] <= max_gap)
    return ok


__all__ = ["KINDS", "AidCounts", "Aiding", "StillRuns", "ZuptCheck", "odometry_zero", "vehicle_matrix"]
