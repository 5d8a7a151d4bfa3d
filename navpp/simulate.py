"""Simulated INS/GNSS logs whose truth is known exactly: the oracle for navpp's tests.

The trajectory is defined first, as smooth analytic controls of time; the ideal IMU is
derived from it in closed form with the Earth model of :mod:`navpp.geodesy`.  Nothing here
integrates IMU data with a strapdown, so a strapdown tested against this module is tested
against an independent truth.

Trajectory (a car-like drive)
-----------------------------
Controls, each an analytic function of time with analytic derivatives:

- speed ``s(t) >= 0`` (m/s) along body x (no side slip),
- heading ``psi(t)`` (rad, clockwise from north),
- path angle ``theta(t)`` (rad, nose up); body pitch equals the path angle (no angle of attack),
- roll ``phi(t) = -k * s * psi_dot / G0`` with ``k = LEAN_GAIN`` and ``G0 = 9.80665``: in a
  right turn (``psi_dot > 0``) the roll is negative (left side down), i.e. the car leans
  outward, by about 1.7 mrad per m/s^2 of lateral acceleration.

Steps (speed changes, turns of +-90 deg, a U-turn) are quintic smootherstep
``S(x) = 6x^5 - 15x^4 + 10x^3``; hills are the C2 bump ``B(x) = 64 x^3 (1 - x)^3`` in theta,
always as a +bump followed by an equal -bump at constant speed, so the road climbs and comes
back to the same height exactly.  The run starts with a still period (``still_s``, shortened
to ``duration_s / 2`` for short runs), then a 200-s drive cycle (start, turns, hill, U-turn,
a dip inside two turns, stop, 10 s standstill) repeats until ``duration_s``.  The net heading
change of a cycle is zero.

Velocity ENU is ``v = s [cos(theta) sin(psi), cos(theta) cos(psi), sin(theta)]``; position is
integrated from it (``lat_dot = vN / (RM + h)``, ``lon_dot = vE / ((RN + h) cos lat)``,
``h_dot = vU``) with scipy's DOP853 (rtol 1e-12, atol 1e-13) in chunks between the controls'
breakpoints, so every chunk is analytic (C-infinity).

Ideal IMU (instantaneous values at the sample times, not averages), ``C = mat_nb``::

    f_b    = C^T (v_dot + (2 w_ie + w_en) x v - g_n),   g_n = [0, 0, -gravity(lat, h)]
    w_ib_b = w_nb_b + C^T (w_ie + w_en)

with ``skew(w_nb_b) = C^T C_dot`` written out from the Euler-angle rates
(:func:`body_rate_from_rph`).

Sensor errors
-------------
Per axis: measured = (1 + sf) * true + turn-on bias + Gauss-Markov bias instability + white
noise.  sf ~ N(0, ppm * 1e-6), bias ~ N(0, bias 1-sigma), Gauss-Markov with stationary sigma
= instability and correlation time tau (exact discretisation, started from its stationary
distribution), white noise per-sample sigma = ARW / sqrt(dt) (VRW likewise).  Datasheet
numbers per grade are in :data:`IMU_GRADES` (the same numbers as the ``[imu]`` presets).

GNSS: antenna at ``lever_arm_m`` (body FLU), position = body position + C * lever arm.
``gnss_error="white"``: white noise ``gnss_std_h_m`` per horizontal axis and ``gnss_std_u_m``
vertical.  ``gnss_error="correlated"``: a first-order Gauss-Markov error (tau =
``gnss_corr_time_s``, sigma = those stds) plus white noise of half those stds; the written
``std_e/std_n/std_u`` are then the total 1-sigma, ``sqrt(1.25)`` times the stds.

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns independent streams for the IMU
and the GNSS, so changing the IMU preset does not change the GNSS noise (and vice versa); a
third stream draws the real-world effects below (vibration, stale rows), so turning them on
leaves the other two streams as they were.

Real-world effects (consumer car logs)
--------------------------------------
All off by default; with every one off the third stream is not drawn from.
``realism="consumer-car"`` turns on the bundle :data:`REALISM_BUNDLES` at once; a field given
explicitly overrides the bundle's value (0 turns an effect off).  ``imu_rate_hz``,
``gnss_rate_hz``, ``preset``, ``still_s``, ``gnss_std_h_m`` and ``gnss_std_u_m`` default to None:
the bundle's value with one, else 125 Hz, 5 Hz, automotive, 60 s, 1.8 m, 2.5 m.

- Mounting ``mounting_rpy_deg`` (deg, roll/pitch/yaw about x, y, z, ROS rpy): the IMU is rotated
  against the body (vehicle, FLU); with ``C_bs = rpy_deg_to_dcm(mounting_rpy_deg)`` (sensor -> body,
  the convention of navpp's ``[imu] mounting_rpy_deg``) it reads ``w_s = C_bs^T w_b`` and
  ``f_s = C_bs^T f_b``, so ``[imu] mounting_rpy_deg`` = the same angles undoes it exactly.  Roll
  90 deg: the IMU's +y is up.  All sensor errors below are in the sensor axes.
- Turn-on biases ``gyro_bias_dps`` (deg/s) and ``accel_bias_mg`` (mg), and scale factors
  ``gyro_scale_factor_pct``, ``accel_scale_factor_pct`` (%), per sensor axis, replace the
  preset's drawn ones; the preset's Gauss-Markov instability and white noise stay.
- Axis non-orthogonality ``gyro_misalignment_deg``, ``accel_misalignment_deg`` = (yx, zx, zy)
  deg: ``measured = (I + diag(sf) + N) true + ...`` with ``N[1,0] = yx, N[2,0] = zx,
  N[2,1] = zy`` (rad): the y axis senses some x, the z axis some x and y.
- Vibration ``vibration_gyro_dps = (a, b)`` (deg/s, deg/s per m/s), ``vibration_accel_mps2 =
  (a, b)`` (m/s^2, m/s^2 per m/s): added to each sensor axis with sample std ``a + b * speed``
  (true speed of the body, m/s), the engine running for the whole log (idling while still).
  The mount shakes: most of it (``1 - VIBRATION_WHITE_SHARE`` of the variance) is the sampled
  rate of change of a damped oscillation (:data:`VIBRATION_HZ`, damping
  :data:`VIBRATION_DAMPING`), whose integral stays bounded (the mount's angle and velocity
  oscillate, they do not wander); the rest is white (broadband shaking aliased into the
  samples), an angle random walk of ``sqrt(share) * std * sqrt(dt)``: about 9 deg/sqrt(h) at
  16 m/s for the consumer-car bundle at 100 Hz.  The oscillation's frequency is physical; at a
  low IMU rate it aliases.
- Stale rows ``stale_fraction``: each IMU row after the first is, independently with this
  probability, a copy of the previous row's six values under its own (new) stamp.
- Clock offset ``imu_time_offset_s`` (s): the IMU row's written stamp = true sample time +
  offset (> 0: the IMU stamps are late against the GNSS); ``[gnss] time_offset_s`` = offset puts
  the GNSS on the IMU's time base.  The reference and the GNSS stay at true times.
- ``start_in_motion``: no still period; the log starts on the first pull-away where the speed
  is :data:`START_SPEED_MPS` (accelerating); heading and position at t = 0 are the spec's.
- GNSS gap ``gnss_gap_s``: the fixes of ``[start, start + gnss_gap_s)`` (true time) are
  missing; the start is ``gnss_gap_start_s`` or the start of the first turn at least
  :data:`GAP_EARLIEST_S` into the log and after the still period.

Odometry
--------
``odometry=True`` writes a wheel odometer (``odometry.csv``) at ``odometry_rate_hz``: the true
forward speed ``v`` of the body origin along the vehicle x axis (the vehicle frame is the body
frame here: a simulated mounting rotates the IMU only; with no side slip ``v = s``), read as::

    speed = (1 + e) * (v + slip) + n,   e = odometry_scale_error_pct / 100,  n ~ N(0, odometry_std_mps)

then rounded to multiples of ``odometry_quantum_mps`` (0: not quantised).  Slip: under hard
forward acceleration ``a = dv/dt`` the wheels spin (braking: they skid),
``slip = odometry_slip * sign(a) * max(0, |a| - 2 m/s^2)`` m/s (:data:`ODOMETRY_SLIP_THRESHOLD_MPS2`),
never below ``-v`` (a locked wheel stops).  The drive cycle reaches 2.25 m/s^2 pulling away and
3.3 m/s^2 braking from 20 m/s.  ``odometry_yaw_rate=True`` adds the true yaw rate of the vehicle
w.r.t. the Earth about its z axis (rad/s, up; negative in a right turn) plus white noise
``odometry_yaw_rate_std_rps``.  The written ``std_speed`` is ``hypot(std, quantum / sqrt(12))``
(left out when 0), ``std_yaw_rate`` the yaw-rate noise.  Stamps are on the IMU's clock (true time
+ ``imu_time_offset_s``).  A wheel that does not turn (``v + slip = 0``: standing still, or a
locked wheel) reads exactly 0 for the speed and the yaw rate, as encoders that count no ticks do;
the noise is drawn for every sample all the same.  The noise is drawn from a fourth stream of the seed (speed, then yaw
rate), so turning odometry on leaves the IMU, GNSS and effects exactly as they were; the truth
is in :attr:`Simulation.sensor_errors` (``odometry_*``), the scale error also in ``navpp.toml``'s
comment and ``realism.json``.

Order: ideal IMU -> mounting -> sensor errors and vibration -> stale rows -> stamps.  With
``errors=False`` the sensor errors and the vibration are off; mounting, stale rows, clock offset,
start and gap still apply.  :func:`write_csv_log` writes what was applied (the true biases,
scale factors, error matrices, vibration model, stale rows, clock offset, mounting, gap window)
to ``realism.json``; its ``navpp.toml`` for a bundle holds only what a user would write (the
lever arm and ``[vehicle] type = "car"``).

References: Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., eqs 5.53-5.54 (ENU mechanisation, whose inverse gives the ideal IMU),
eq 2.56 (Euler-rate kinematics) and section 14.2.6 (Gauss-Markov processes).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from functools import cached_property
from itertools import pairwise
from pathlib import Path
from typing import TypeVar

import numpy as np
from scipy.integrate import solve_ivp
from scipy.signal import lfilter

from navpp.errors import ConfigError
from navpp.geodesy import E2, OMEGA_E, A, gravity, radii
from navpp.ins.attitude import rph_to_dcm, rpy_deg_to_dcm
from navpp.recording import GnssData, ImuData, OdometryData, Recording, ReferenceData

G0 = 9.80665  #: standard gravity, m/s^2 (mg conversion and the roll lean law)
LEAN_GAIN = 0.03  #: roll = -LEAN_GAIN * lateral acceleration / G0 (rad); leans outward
CYCLE_S = 200.0  #: length of one drive cycle, s
_MAX_STEP_S = 1.0  # keeps the dense output (7th order) accurate between steps

_DEG_PER_H = math.pi / 180.0 / 3600.0  # deg/h -> rad/s
_DEG_PER_SQRT_H = math.pi / 180.0 / 60.0  # deg/sqrt(h) -> rad/sqrt(s)
_MPS_PER_SQRT_H = 1.0 / 60.0  # m/s/sqrt(h) -> m/s/sqrt(s)
_MG = 9.80665e-3  # mg -> m/s^2

_T = TypeVar("_T")


def _resolved(value: _T | None) -> _T:
    """A spec field that :meth:`SimulationSpec.__post_init__` has filled in (never None after it)."""
    if value is None:  # pragma: no cover - __post_init__ resolves every default
        raise AssertionError("a SimulationSpec field was left unresolved")
    return value


# --------------------------------------------------------------------------- IMU grades


@dataclass(frozen=True)
class ImuGrade:
    """Sensor error budget of one IMU grade, in datasheet units (as the ``[imu]`` keys)."""

    gyro_arw_deg_per_sqrt_h: float
    gyro_bias_deg_per_h: float
    gyro_bias_instability_deg_per_h: float
    gyro_bias_corr_time_s: float
    accel_vrw_mps_per_sqrt_h: float
    accel_bias_mg: float
    accel_bias_instability_mg: float
    accel_bias_corr_time_s: float
    scale_factor_ppm: float  #: gyro and accel alike, 1-sigma per axis


#: The ``[imu]`` presets of navpp.config.PRESETS plus a scale-factor error per grade, and "ideal".
IMU_GRADES: dict[str, ImuGrade] = {
    "consumer": ImuGrade(0.5, 200.0, 10.0, 100.0, 0.1, 20.0, 1.0, 100.0, 3000.0),
    "automotive": ImuGrade(1.0, 10.0, 1.0, 300.0, 0.05, 2.0, 0.1, 300.0, 500.0),
    "tactical": ImuGrade(0.1, 1.0, 0.1, 600.0, 0.03, 0.3, 0.02, 600.0, 100.0),
    "navigation": ImuGrade(0.003, 0.03, 0.01, 3600.0, 0.03, 0.025, 0.01, 3600.0, 10.0),
    "ideal": ImuGrade(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
}


# --------------------------------------------------------------------------- real-world effects

#: Values of the fields left at None when no realism bundle is chosen.
_PLAIN_DEFAULTS: dict[str, object] = {
    "imu_rate_hz": 125.0, "gnss_rate_hz": 5.0, "preset": "automotive", "still_s": 60.0,
    "gnss_std_h_m": 1.8, "gnss_std_u_m": 2.5,
}

#: The real-world effects' own fields (None: off).
_EFFECT_FIELDS = (
    "vibration_gyro_dps", "vibration_accel_mps2", "gyro_bias_dps", "accel_bias_mg", "gyro_scale_factor_pct",
    "accel_scale_factor_pct", "gyro_misalignment_deg", "accel_misalignment_deg", "stale_fraction",
    "imu_time_offset_s", "mounting_rpy_deg", "gnss_gap_s",
)

#: ``SimulationSpec.realism`` bundles: field values used where the spec leaves a field at None.
REALISM_BUNDLES: dict[str, dict[str, object]] = {
    "consumer-car": {
        "imu_rate_hz": 100.0, "gnss_rate_hz": 4.0, "gnss_std_h_m": 0.05, "gnss_std_u_m": 0.05,
        "preset": "consumer", "still_s": 35.0,
        "vibration_gyro_dps": (2.0, 0.5), "vibration_accel_mps2": (0.13, 0.0325),
        "gyro_bias_dps": (0.25, -0.30, 0.17), "accel_bias_mg": (30.0, -25.0, 40.0),
        "gyro_scale_factor_pct": (1.0, -0.8, 1.2), "accel_scale_factor_pct": (-0.7, 1.0, 0.6),
        "gyro_misalignment_deg": (0.5, -0.4, 0.3), "accel_misalignment_deg": (-0.3, 0.5, 0.4),
        "stale_fraction": 0.02, "imu_time_offset_s": 0.010, "gnss_gap_s": 15.0,
    },
}

GAP_EARLIEST_S = 20.0  #: the default GNSS gap starts in the first turn at least this far into the log, s
START_SPEED_MPS = 8.0  #: speed at the first sample with ``start_in_motion`` (on the first pull-away), m/s


def _start_cut_s() -> float:
    """Time into a drive cycle where the first pull-away (0 -> 12 m/s in 10 s) reaches
    :data:`START_SPEED_MPS`: ``12 S(x) = 8`` solved for x by bisection (S is increasing)."""
    start, length, delta = _CYCLE_SPEED[0]
    target = START_SPEED_MPS / delta
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _scalar_shape(mid, True) < target:
            lo = mid
        else:
            hi = mid
    return start + length * 0.5 * (lo + hi)


# --------------------------------------------------------------------------- the spec


@dataclass(frozen=True)
class SimulationSpec:
    """Everything that defines a simulated log; the same spec and seed give the same log.

    Times in s, rates in Hz, angles in degrees where the name says ``_deg``, lengths in m.
    ``errors=False`` makes the IMU exact whatever the preset (GNSS noise is controlled by
    its stds; set them to 0 for exact GNSS).  The fields after ``errors`` are the real-world
    effects (module docstring, "Real-world effects"): None / False is off.
    """

    duration_s: float = 900.0
    imu_rate_hz: float | None = None  #: None: 125 Hz (the realism bundle's rate with one)
    gnss_rate_hz: float | None = None  #: None: 5 Hz (or the bundle's)
    reference_rate_hz: float = 10.0
    preset: str | None = None  #: None: "automotive" (or the bundle's)
    seed: int = 0
    still_s: float | None = None  #: None: 60 s (or the bundle's)
    lat0_deg: float = 45.0
    lon0_deg: float = 7.0
    alt0_m: float = 300.0
    heading0_deg: float = 30.0
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gnss_std_h_m: float | None = None  #: None: 1.8 m (or the bundle's)
    gnss_std_u_m: float | None = None  #: None: 2.5 m (or the bundle's)
    gnss_error: str = "white"
    gnss_corr_time_s: float = 120.0
    gnss_velocity: bool = False
    t0_unix: float = 1_700_000_000.0
    gnss_std_vel_mps: float = 0.05
    errors: bool = True
    # -- real-world effects (module docstring, "Real-world effects"); None / False: off ------
    realism: str | None = None
    vibration_gyro_dps: tuple[float, float] | None = None
    vibration_accel_mps2: tuple[float, float] | None = None
    gyro_bias_dps: tuple[float, float, float] | None = None
    accel_bias_mg: tuple[float, float, float] | None = None
    gyro_scale_factor_pct: tuple[float, float, float] | None = None
    accel_scale_factor_pct: tuple[float, float, float] | None = None
    gyro_misalignment_deg: tuple[float, float, float] | None = None
    accel_misalignment_deg: tuple[float, float, float] | None = None
    stale_fraction: float | None = None
    imu_time_offset_s: float | None = None
    mounting_rpy_deg: tuple[float, float, float] | None = None
    start_in_motion: bool = False
    gnss_gap_s: float | None = None
    gnss_gap_start_s: float | None = None
    # -- wheel odometry (module docstring, "Odometry"); off by default ----------------------
    odometry: bool = False
    odometry_rate_hz: float = 10.0
    odometry_scale_error_pct: float = 0.0
    odometry_std_mps: float = 0.02
    odometry_quantum_mps: float = 0.0
    odometry_slip: float = 0.0
    odometry_yaw_rate: bool = False
    odometry_yaw_rate_std_rps: float = 0.002

    def __post_init__(self) -> None:
        if self.realism is not None and self.realism not in REALISM_BUNDLES:
            raise ConfigError(f"simulate: unknown realism {self.realism!r}; choose one of {', '.join(REALISM_BUNDLES)}")
        bundle = REALISM_BUNDLES[self.realism] if self.realism is not None else {}
        for name, plain in _PLAIN_DEFAULTS.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, bundle.get(name, plain))
        for name, value in bundle.items():
            if name not in _PLAIN_DEFAULTS and getattr(self, name) is None:
                object.__setattr__(self, name, value)
        self._check_realism()
        self._check_odometry()
        lever = tuple(float(x) for x in self.lever_arm_m)
        if len(lever) != 3:
            raise ConfigError(f"simulate: lever_arm_m needs 3 numbers (body FLU, m), got {self.lever_arm_m!r}")
        object.__setattr__(self, "lever_arm_m", lever)
        if not all(math.isfinite(x) for x in lever):
            raise ConfigError(f"simulate: lever_arm_m must be finite, got {self.lever_arm_m!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ConfigError(f"simulate: seed must be a non-negative integer, got {self.seed!r}")
        for name in ("duration_s", "imu_rate_hz", "gnss_rate_hz", "reference_rate_hz", "still_s", "gnss_std_h_m",
                     "gnss_std_u_m", "gnss_std_vel_mps", "gnss_corr_time_s", "lat0_deg", "lon0_deg", "alt0_m",
                     "heading0_deg", "t0_unix"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value):
                raise ConfigError(f"simulate: {name} must be a finite number, got {value!r}")
        if not self.duration_s >= 30.0:
            raise ConfigError(f"simulate: duration must be >= 30 s, got {self.duration_s!r}")
        if not _resolved(self.imu_rate_hz) > 0.0:
            raise ConfigError(f"simulate: IMU rate must be > 0 Hz, got {self.imu_rate_hz!r}")
        if not 1.0 <= _resolved(self.gnss_rate_hz) <= 10.0:
            raise ConfigError(f"simulate: GNSS rate must be within 1-10 Hz, got {self.gnss_rate_hz!r}")
        if not self.reference_rate_hz > 0.0:
            raise ConfigError(f"simulate: reference rate must be > 0 Hz, got {self.reference_rate_hz!r}")
        if self.preset not in IMU_GRADES:
            raise ConfigError(
                f"simulate: unknown IMU preset {self.preset!r}; choose one of {', '.join(IMU_GRADES)}"
            )
        if self.gnss_error not in ("white", "correlated"):
            raise ConfigError(f"simulate: gnss_error must be 'white' or 'correlated', got {self.gnss_error!r}")
        if not _resolved(self.still_s) >= 0.0:
            raise ConfigError(f"simulate: still_s must be >= 0 s, got {self.still_s!r}")
        for name in ("gnss_std_h_m", "gnss_std_u_m", "gnss_std_vel_mps"):
            if not getattr(self, name) >= 0.0:
                raise ConfigError(f"simulate: {name} must be >= 0, got {getattr(self, name)!r}")
        if not self.gnss_corr_time_s > 0.0:
            raise ConfigError(f"simulate: gnss_corr_time_s must be > 0 s, got {self.gnss_corr_time_s!r}")
        if not -85.0 <= self.lat0_deg <= 85.0:
            raise ConfigError(f"simulate: lat0_deg must be within +-85 deg, got {self.lat0_deg!r}")

    def _check_realism(self) -> None:
        """Validate the real-world effects' fields (tuples become tuples of floats)."""
        def number(name: str, value: object) -> float:
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value):
                raise ConfigError(f"simulate: {name} must be a finite number, got {value!r}")
            return float(value)

        for name, size, limit in (("vibration_gyro_dps", 2, None), ("vibration_accel_mps2", 2, None),
                                  ("gyro_bias_dps", 3, None), ("accel_bias_mg", 3, None),
                                  ("gyro_scale_factor_pct", 3, 50.0), ("accel_scale_factor_pct", 3, 50.0),
                                  ("gyro_misalignment_deg", 3, 10.0), ("accel_misalignment_deg", 3, 10.0),
                                  ("mounting_rpy_deg", 3, None)):
            value = getattr(self, name)
            if value is None:
                continue
            try:
                vec = tuple(float(x) for x in value)
            except (TypeError, ValueError):
                vec = ()
            if len(vec) != size or not all(math.isfinite(x) for x in vec):
                raise ConfigError(f"simulate: {name} needs {size} finite numbers, got {value!r}")
            if name.startswith("vibration") and min(vec) < 0.0:
                raise ConfigError(f"simulate: {name} (a, b) must be >= 0, got {value!r}")
            if limit is not None and max(abs(x) for x in vec) > limit:
                raise ConfigError(f"simulate: {name} must be within +-{limit:g}, got {value!r}")
            object.__setattr__(self, name, vec)
        if self.stale_fraction is not None and not 0.0 <= number("stale_fraction", self.stale_fraction) <= 0.5:
            raise ConfigError(f"simulate: stale_fraction must be within 0-0.5, got {self.stale_fraction!r}")
        if self.imu_time_offset_s is not None and not abs(number("imu_time_offset_s", self.imu_time_offset_s)) <= 1.0:
            raise ConfigError(f"simulate: imu_time_offset_s must be within +-1 s, got {self.imu_time_offset_s!r}")
        if not isinstance(self.start_in_motion, (bool, np.bool_)):
            raise ConfigError(f"simulate: start_in_motion must be true or false, got {self.start_in_motion!r}")
        if self.gnss_gap_s is not None and not number("gnss_gap_s", self.gnss_gap_s) >= 0.0:
            raise ConfigError(f"simulate: gnss_gap_s must be >= 0 s, got {self.gnss_gap_s!r}")
        if self.gnss_gap_start_s is not None and not number("gnss_gap_start_s", self.gnss_gap_start_s) >= 0.0:
            raise ConfigError(f"simulate: gnss_gap_start_s must be >= 0 s, got {self.gnss_gap_start_s!r}")

    def _check_odometry(self) -> None:
        """Validate the odometry fields (module docstring, "Odometry")."""
        for name in ("odometry", "odometry_yaw_rate"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ConfigError(f"simulate: {name} must be true or false, got {getattr(self, name)!r}")
        for name, lo, hi, strict in (("odometry_rate_hz", 0.0, 1000.0, True),
                                     ("odometry_scale_error_pct", -50.0, 50.0, False),
                                     ("odometry_std_mps", 0.0, 10.0, False),
                                     ("odometry_quantum_mps", 0.0, 10.0, False), ("odometry_slip", 0.0, 10.0, False),
                                     ("odometry_yaw_rate_std_rps", 0.0, 10.0, False)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or not lo <= value <= hi or (strict and value == lo):
                within = f"within {'(' if strict else '['}{lo:g}, {hi:g}]"
                raise ConfigError(f"simulate: {name} must be a finite number {within}, got {value!r}")

    @property
    def still_effective_s(self) -> float:
        """Still period actually used: ``min(still_s, duration_s / 2)``; 0 with ``start_in_motion``."""
        if self.start_in_motion:
            return 0.0
        return min(_resolved(self.still_s), 0.5 * self.duration_s)

    @property
    def start_cut_s(self) -> float:
        """Time into the first drive cycle at which the log starts: 0, or with ``start_in_motion``
        the moment the first pull-away passes :data:`START_SPEED_MPS`."""
        return _start_cut_s() if self.start_in_motion else 0.0

    @property
    def realistic(self) -> bool:
        """Whether any real-world effect is on (then ``realism.json`` is written)."""
        return self.realism is not None or self.start_in_motion or any(
            getattr(self, name) is not None for name in _EFFECT_FIELDS)


# --------------------------------------------------------------------------- smooth pieces


def smootherstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic smootherstep ``S(x) = 6x^5 - 15x^4 + 10x^3`` on clipped x and its derivatives.

    Returns ``S, dS/dx, d2S/dx2``; constant 0 before x = 0 and 1 after x = 1 (C2).
    """
    x = np.clip(x, 0.0, 1.0)
    x2 = x * x
    s = x2 * x * (10.0 + x * (-15.0 + 6.0 * x))
    d1 = 30.0 * x2 * (1.0 - x) ** 2
    d2 = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return s, d1, d2


def bump(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """C2 bump ``B(x) = 64 x^3 (1 - x)^3`` (peak 1 at x = 1/2, zero outside [0, 1]) and derivatives."""
    x = np.clip(x, 0.0, 1.0)
    u = 1.0 - x
    b = 64.0 * x**3 * u**3
    d1 = 192.0 * x * x * u * u * (u - x)
    d2 = 384.0 * x * u * ((u - x) ** 2 - x * u)
    return b, d1, d2


@dataclass(frozen=True)
class _Channel:
    """One control as a sequence of non-overlapping smooth events.

    ``kind == "step"``: value = base + sum of ``delta * S((t - start) / T)``;
    ``kind == "bump"``: value = sum of ``delta * B((t - start) / T)`` (returns to ``base``).
    """

    kind: str
    base: float
    start: np.ndarray
    length: np.ndarray
    delta: np.ndarray

    def __post_init__(self) -> None:
        if np.any(self.start[1:] < self.start[:-1] + self.length[:-1] - 1e-9):
            raise ValueError(f"{self.kind} channel: events overlap")

    @property
    def _before(self) -> np.ndarray:
        # value accumulated before event i (steps only)
        if self.kind == "bump":
            return np.zeros(self.start.size + 1)
        return np.concatenate([[0.0], np.cumsum(self.delta)])

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value and first two time derivatives at ``t`` (vectorised)."""
        t = np.asarray(t, dtype=float)
        if self.start.size == 0:
            z = np.zeros_like(t)
            return z + self.base, z, z.copy()
        i = np.searchsorted(self.start, t, side="right") - 1
        active = i >= 0
        j = np.where(active, i, 0)
        x = np.where(active, (t - self.start[j]) / self.length[j], 0.0)
        f, d1, d2 = (smootherstep if self.kind == "step" else bump)(x)
        amp = np.where(active, self.delta[j], 0.0)
        t_scale = self.length[j]
        before = np.where(active, self._before[j], 0.0)
        return (self.base + before + amp * f, amp * d1 / t_scale, amp * d2 / (t_scale * t_scale))

    def breakpoints(self) -> np.ndarray:
        """Start and end times (s) of every event, unsorted."""
        return np.concatenate([self.start, self.start + self.length])

    def piece(self, t_mid: float) -> tuple[float, float, float, float, bool]:
        """Scalar description on a breakpoint-free interval containing ``t_mid``.

        Returns ``(offset, amplitude, start, length, is_step)`` so that the value is
        ``offset + amplitude * shape((t - start) / length)``; amplitude 0 when no event runs.
        """
        before = self._before
        i = int(np.searchsorted(self.start, t_mid, side="right")) - 1
        if i >= 0 and t_mid < self.start[i] + self.length[i]:
            return (self.base + before[i], float(self.delta[i]), float(self.start[i]),
                    float(self.length[i]), self.kind == "step")
        offset = self.base + (before[i + 1] if i >= 0 else 0.0)
        return offset, 0.0, 0.0, 1.0, self.kind == "step"


def _scalar_shape(x: float, is_step: bool) -> float:
    x = 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)
    if is_step:
        return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
    u = 1.0 - x
    return 64.0 * x * x * x * u * u * u


# --------------------------------------------------------------------------- controls


# One drive cycle, times relative to the cycle start: (start s, length s, change)
_CYCLE_SPEED = (  # m/s
    (0.0, 10.0, 12.0),  # pull away to 12 m/s
    (28.0, 8.0, 8.0),  # to 20 m/s
    (100.0, 8.0, -14.0),  # brake to 6 m/s
    (132.0, 10.0, 9.0),  # to 15 m/s
    (178.0, 12.0, -15.0),  # stop; standstill 190-200
)
_CYCLE_HEADING = (  # rad, positive = right turn
    (14.0, 10.0, 0.5 * math.pi),  # right turn at 12 m/s
    (80.0, 14.0, -0.5 * math.pi),  # left turn at 20 m/s
    (112.0, 16.0, math.pi),  # U-turn at 6 m/s
    (146.0, 12.0, -0.5 * math.pi),  # left turn at 15 m/s (inside a dip)
    (162.0, 12.0, -0.5 * math.pi),  # left turn at 15 m/s
)
_CYCLE_PITCH = (  # rad, bump amplitudes; +bump then -bump at constant speed
    (40.0, 20.0, math.radians(4.0)),  # hill at 20 m/s: climbs ~12.8 m and comes back
    (60.0, 20.0, -math.radians(4.0)),
    (146.0, 12.0, -math.radians(3.0)),  # dip at 15 m/s during two left turns: ~4.3 m
    (158.0, 12.0, math.radians(3.0)),
)


@dataclass(frozen=True)
class DriveControls:
    """Speed, heading and path-angle controls of the scripted drive, and the roll law.

    Build with :meth:`scripted`; evaluate with :meth:`evaluate`.
    """

    speed: _Channel
    heading: _Channel
    pitch: _Channel
    lean_gain: float = LEAN_GAIN

    @classmethod
    def scripted(cls, duration_s: float, still_s: float, heading0_rad: float) -> DriveControls:
        """Still for ``still_s``, then 200-s drive cycles until past ``duration_s``.

        A negative ``still_s`` starts the first cycle that long before t = 0 (a log that
        starts in motion).
        """
        n_cycles = max(1, int(math.ceil((duration_s - still_s) / CYCLE_S)) + 1)
        offsets = still_s + CYCLE_S * np.arange(n_cycles)

        def channel(kind: str, base: float, table: tuple[tuple[float, float, float], ...]) -> _Channel:
            ev = np.array(table, dtype=float)
            start = (offsets[:, None] + ev[None, :, 0]).ravel()
            length = np.tile(ev[:, 1], n_cycles)
            delta = np.tile(ev[:, 2], n_cycles)
            return _Channel(kind, base, start, length, delta)

        return cls(
            speed=channel("step", 0.0, _CYCLE_SPEED),
            heading=channel("step", heading0_rad, _CYCLE_HEADING),
            pitch=channel("bump", 0.0, _CYCLE_PITCH),
        )

    def evaluate(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Controls at ``t`` (s): ``s, s_dot, psi, psi_dot, psi_ddot, theta, theta_dot, phi, phi_dot``."""
        s, s_dot, _ = self.speed.evaluate(t)
        psi, psi_dot, psi_ddot = self.heading.evaluate(t)
        theta, theta_dot, _ = self.pitch.evaluate(t)
        k = self.lean_gain / G0
        phi = -k * s * psi_dot
        phi_dot = -k * (s_dot * psi_dot + s * psi_ddot)
        return dict(s=s, s_dot=s_dot, psi=psi, psi_dot=psi_dot, psi_ddot=psi_ddot,
                    theta=theta, theta_dot=theta_dot, phi=phi, phi_dot=phi_dot)

    def breakpoints(self) -> np.ndarray:
        """Sorted times (s) where any control's event starts or ends: between two, all are analytic."""
        return np.unique(np.concatenate([c.breakpoints() for c in (self.speed, self.heading, self.pitch)]))


# --------------------------------------------------------------------------- kinematics


def body_rate_from_rph(rph: np.ndarray, rph_dot: np.ndarray) -> np.ndarray:
    """Body rate w.r.t. the navigation frame, ``w_nb_b`` (..., 3) rad/s, body FLU.

    From ``C^T C_dot = skew(w_nb_b)`` with ``C = Rz(pi/2 - heading) Ry(-pitch) Rx(roll)``
    (:func:`navpp.ins.attitude.rph_to_dcm`)::

        w_nb_b = [roll_dot - heading_dot sin(pitch),
                  -pitch_dot cos(roll) - heading_dot cos(pitch) sin(roll),
                  pitch_dot sin(roll) - heading_dot cos(pitch) cos(roll)]

    Parameters
    ----------
    rph, rph_dot : (..., 3) roll, pitch, heading (rad) and their rates (rad/s).
    """
    rph = np.asarray(rph, dtype=float)
    rph_dot = np.asarray(rph_dot, dtype=float)
    sr, cr = np.sin(rph[..., 0]), np.cos(rph[..., 0])
    sp, cp = np.sin(rph[..., 1]), np.cos(rph[..., 1])
    dr, dp, dh = rph_dot[..., 0], rph_dot[..., 1], rph_dot[..., 2]
    return np.stack([
        dr - dh * sp,
        -dp * cr - dh * cp * sr,
        dp * sr - dh * cp * cr,
    ], axis=-1)


def earth_rate_enu_batch(lat: np.ndarray) -> np.ndarray:
    """Earth rotation rate in ENU, (N, 3) rad/s, for latitudes (N,) rad."""
    lat = np.asarray(lat, dtype=float)
    return np.stack([np.zeros_like(lat), OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)], axis=-1)


def transport_rate_enu_batch(lat: np.ndarray, h: np.ndarray, vel_enu: np.ndarray) -> np.ndarray:
    """Transport rate of ENU w.r.t. the Earth, (N, 3) rad/s, as ``geodesy.transport_rate_enu``."""
    rm, rn = radii(lat)
    ve, vn = vel_enu[..., 0], vel_enu[..., 1]
    return np.stack([-vn / (rm + h), ve / (rn + h), ve * np.tan(lat) / (rn + h)], axis=-1)


def _rotate_t(mat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """``mat^T @ vec`` for stacks (N, 3, 3), (N, 3)."""
    return np.einsum("nji,nj->ni", mat, vec)


def _rotate(mat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", mat, vec)


def _offset_geodetic(lat: np.ndarray, lon: np.ndarray, h: np.ndarray,
                     d_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Small ENU offsets (N, 3) m -> geodetic, first order through the radii at (lat, h)."""
    rm, rn = radii(lat)
    return (lat + d_enu[:, 1] / (rm + h),
            lon + d_enu[:, 0] / ((rn + h) * np.cos(lat)),
            h + d_enu[:, 2])


# --------------------------------------------------------------------------- trajectory


class Trajectory:
    """Analytic truth of the body (IMU) origin: controls + integrated geodetic position.

    Valid on ``[0, t_end]`` s.  The position ODE is solved on first use and cached.

    Parameters
    ----------
    controls : the drive controls.
    lat0, lon0 : rad; h0 : m -- position at t = 0.
    t_end : s, end of the valid interval.
    """

    def __init__(self, controls: DriveControls, lat0: float, lon0: float, h0: float, t_end: float):
        self.controls = controls
        self.lat0 = float(lat0)
        self.lon0 = float(lon0)
        self.h0 = float(h0)
        self.t_end = float(t_end)

    @classmethod
    def from_spec(cls, spec: SimulationSpec) -> Trajectory:
        """The scripted drive of ``spec`` (valid to ``duration_s + 1`` s for finite differences).

        With ``start_in_motion`` the first cycle starts ``start_cut_s`` before t = 0 (the car is
        already pulling away at ``START_SPEED_MPS``); ``heading0_deg`` and the start position
        are then those at t = 0.
        """
        offset = spec.still_effective_s - spec.start_cut_s if spec.start_in_motion else spec.still_effective_s
        controls = DriveControls.scripted(spec.duration_s + 1.0, offset, math.radians(spec.heading0_deg))
        return cls(controls, math.radians(spec.lat0_deg), math.radians(spec.lon0_deg),
                   spec.alt0_m, spec.duration_s + 1.0)

    # -- position ------------------------------------------------------------------------

    @cached_property
    def _chunks(self) -> tuple[np.ndarray, list]:
        """Position over [0, t_end]: chunk starts and, per chunk, a dense output or a constant."""
        bp = self.controls.breakpoints()
        edges = np.unique(np.concatenate([[0.0], bp[(bp > 0.0) & (bp < self.t_end)], [self.t_end]]))
        y = np.array([self.lat0, self.lon0, self.h0])
        pieces: list = []
        for ta, tb in pairwise(edges):
            tm = 0.5 * (ta + tb)
            sp = self.controls.speed.piece(tm)
            if sp[1] == 0.0 and sp[0] == 0.0:  # standing still
                pieces.append(y.copy())
                continue
            sol = solve_ivp(_position_rhs(sp, self.controls.heading.piece(tm), self.controls.pitch.piece(tm)),
                            (ta, tb), y, method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True,
                            max_step=_MAX_STEP_S)
            if not sol.success:  # pragma: no cover - the right-hand side is analytic
                raise RuntimeError(f"position integration failed on [{ta}, {tb}] s: {sol.message}")
            pieces.append(sol.sol)
            y = sol.y[:, -1].copy()
        return edges[:-1], pieces

    def position(self, t: np.ndarray) -> np.ndarray:
        """Geodetic position (N, 3): lat (rad), lon (rad), h (m) at times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if t.size and (t.min() < 0.0 or t.max() > self.t_end):
            raise ValueError(f"trajectory is defined on [0, {self.t_end}] s, got times in "
                             f"[{t.min()}, {t.max()}]")
        starts, pieces = self._chunks
        order = np.argsort(t, kind="stable")
        ts = t[order]
        out = np.empty((t.size, 3))
        lo = np.searchsorted(ts, starts, side="left")
        hi = np.append(lo[1:], ts.size)
        res = np.empty((ts.size, 3))
        for a, b, piece in zip(lo, hi, pieces):
            if a == b:
                continue
            if isinstance(piece, np.ndarray):
                res[a:b] = piece
            else:
                res[a:b] = piece(ts[a:b]).T
        out[order] = res
        return out

    # -- state ---------------------------------------------------------------------------

    def state(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Truth at times ``t`` (N,) s.

        Returns
        -------
        dict with ``lat, lon`` (N,) rad, ``h`` (N,) m, ``vel_enu`` (N, 3) m/s, ``accel_enu``
        (N, 3) m/s^2 (time derivative of the ENU velocity components), ``rph`` (N, 3) rad
        (roll, pitch, heading; heading unwrapped) and ``rph_dot`` (N, 3) rad/s.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pos = self.position(t)
        c = self.controls.evaluate(t)
        s, th, ps = c["s"], c["theta"], c["psi"]
        cth, sth, cps, sps = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
        u = np.stack([cth * sps, cth * cps, sth], axis=-1)
        du_dth = np.stack([-sth * sps, -sth * cps, cth], axis=-1)
        du_dps = np.stack([cth * cps, -cth * sps, np.zeros_like(th)], axis=-1)
        vel = s[:, None] * u
        acc = (c["s_dot"][:, None] * u
               + s[:, None] * (c["theta_dot"][:, None] * du_dth + c["psi_dot"][:, None] * du_dps))
        return dict(
            lat=pos[:, 0], lon=pos[:, 1], h=pos[:, 2], vel_enu=vel, accel_enu=acc,
            rph=np.stack([c["phi"], th, ps], axis=-1),
            rph_dot=np.stack([c["phi_dot"], c["theta_dot"], c["psi_dot"]], axis=-1),
        )

    def ideal_imu(self, t: np.ndarray, state: dict[str, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Error-free IMU at ``t``: gyro (N, 3) rad/s and specific force (N, 3) m/s^2, body FLU.

        ``state`` may pass ``self.state(t)`` when already computed.
        """
        st = self.state(t) if state is None else state
        lat, h, vel = st["lat"], st["h"], st["vel_enu"]
        rph = st["rph"]
        mat_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
        w_ie = earth_rate_enu_batch(lat)
        w_en = transport_rate_enu_batch(lat, h, vel)
        f_n = st["accel_enu"] + np.cross(2.0 * w_ie + w_en, vel)
        f_n[:, 2] += gravity(lat, h)  # - g_n
        accel = _rotate_t(mat_nb, f_n)
        gyro = body_rate_from_rph(rph, st["rph_dot"]) + _rotate_t(mat_nb, w_ie + w_en)
        return gyro, accel


def _position_rhs(speed_piece: tuple, heading_piece: tuple,
                  pitch_piece: tuple) -> Callable[[float, np.ndarray], list[float]]:
    """Scalar right-hand side of the position ODE on one breakpoint-free chunk."""
    s_off, s_amp, s_t0, s_len, _ = speed_piece
    p_off, p_amp, p_t0, p_len, _ = heading_piece
    q_off, q_amp, q_t0, q_len, _ = pitch_piece
    one_minus_e2 = 1.0 - E2
    sin, cos, sqrt = math.sin, math.cos, math.sqrt

    def rhs(t: float, y: np.ndarray) -> list[float]:
        s = s_off + s_amp * _scalar_shape((t - s_t0) / s_len, True)
        psi = p_off + p_amp * _scalar_shape((t - p_t0) / p_len, True)
        th = q_off + q_amp * _scalar_shape((t - q_t0) / q_len, False)
        ch = cos(th)
        ve, vn, vu = s * ch * sin(psi), s * ch * cos(psi), s * sin(th)
        lat, h = y[0], y[2]
        sl = sin(lat)
        w2 = 1.0 - E2 * sl * sl
        w = sqrt(w2)
        rn = A / w
        rm = A * one_minus_e2 / (w2 * w)
        return [vn / (rm + h), ve / ((rn + h) * cos(lat)), vu]

    return rhs


# --------------------------------------------------------------------------- random errors


def gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma: np.ndarray | float,
                 tau: float, axes: int = 3) -> np.ndarray:
    """First-order Gauss-Markov samples (n, axes), stationary from the first sample.

    ``b[k+1] = exp(-dt/tau) b[k] + sqrt(1 - exp(-2 dt/tau)) sigma w[k]``, ``b[0] ~ N(0, sigma^2)``.
    """
    sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (axes,))
    a = math.exp(-dt / tau)
    x = rng.standard_normal((n, axes))
    x[1:] *= math.sqrt(-math.expm1(-2.0 * dt / tau))
    x *= sigma
    return lfilter([1.0], [1.0, -a], x, axis=0)


def draw_imu_errors(rng: np.random.Generator, n: int, dt: float, grade: ImuGrade) -> dict[str, np.ndarray | float]:
    """Draw one IMU's errors for ``n`` samples at interval ``dt`` (SI units, body FLU).

    Order of draws (fixed, so a seed reproduces): scale factors, turn-on biases, Gauss-Markov
    processes (gyro, accel), white noise (gyro, accel).
    """
    sf = grade.scale_factor_ppm * 1e-6
    gyro_sf = rng.normal(0.0, sf, 3)
    accel_sf = rng.normal(0.0, sf, 3)
    gyro_bias = rng.normal(0.0, grade.gyro_bias_deg_per_h * _DEG_PER_H, 3)
    accel_bias = rng.normal(0.0, grade.accel_bias_mg * _MG, 3)
    gyro_gm = gauss_markov(rng, n, dt, grade.gyro_bias_instability_deg_per_h * _DEG_PER_H,
                           grade.gyro_bias_corr_time_s)
    accel_gm = gauss_markov(rng, n, dt, grade.accel_bias_instability_mg * _MG,
                            grade.accel_bias_corr_time_s)
    gyro_sigma = grade.gyro_arw_deg_per_sqrt_h * _DEG_PER_SQRT_H / math.sqrt(dt)
    accel_sigma = grade.accel_vrw_mps_per_sqrt_h * _MPS_PER_SQRT_H / math.sqrt(dt)
    gyro_white = rng.standard_normal((n, 3)) * gyro_sigma
    accel_white = rng.standard_normal((n, 3)) * accel_sigma
    return dict(
        gyro_scale_factor=gyro_sf, accel_scale_factor=accel_sf,
        gyro_bias=gyro_bias, accel_bias=accel_bias,
        gyro_gauss_markov=gyro_gm, accel_gauss_markov=accel_gm,
        gyro_white_sigma=gyro_sigma, accel_white_sigma=accel_sigma,
        gyro_bias_instability=grade.gyro_bias_instability_deg_per_h * _DEG_PER_H,
        accel_bias_instability=grade.accel_bias_instability_mg * _MG,
        gyro_bias_corr_time_s=grade.gyro_bias_corr_time_s,
        accel_bias_corr_time_s=grade.accel_bias_corr_time_s,
        _gyro_white=gyro_white, _accel_white=accel_white,
    )


# --------------------------------------------------------------------------- simulation


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated log and its truth.

    Times are float seconds relative to the first IMU sample; ``t0_ns`` is that sample's unix
    time in integer ns.  ``sensor_errors`` holds the drawn errors (SI units, body FLU /
    ENU): ``gyro_bias``, ``accel_bias`` (3,) turn-on biases; ``gyro_scale_factor``,
    ``accel_scale_factor`` (3,); ``gyro_gauss_markov``, ``accel_gauss_markov`` (N, 3);
    ``gyro_white_sigma``, ``accel_white_sigma`` per-sample sigmas; ``gnss_error_enu`` (M, 3) m;
    ``gnss_true_lat_deg``, ``gnss_true_lon_deg``, ``gnss_true_alt`` (antenna truth);
    ``gnss_true_vel_enu`` (M, 3) when GNSS velocity is simulated.

    ``truth_imu`` is the error-free IMU of the body (FLU) at the true sample times; with a
    mounting the logged ``imu`` is in the sensor axes and its errors (``sensor_errors``) too.
    ``imu.t`` are the written stamps (true time + ``imu_time_offset_s``).  ``realism``: the
    real-world effects applied (see :func:`realism_json`), None when none is on.

    ``odometry`` is the logged wheel odometry (``spec.odometry``; module docstring, "Odometry"),
    stamped like ``imu``; its truth is in ``sensor_errors``: ``odometry_scale_error`` (ratio, the
    odometer reads ``1 + e`` times the wheel speed), ``odometry_true_speed`` (K,) m/s forward speed
    of the body origin along the vehicle (body) x axis, ``odometry_true_yaw_rate`` (K,) rad/s about
    the vehicle z axis (w.r.t. the Earth), ``odometry_slip_mps`` (K,) m/s, at the true times
    ``odometry_true_t`` (K,) s.
    """

    imu: ImuData
    gnss: GnssData
    reference: ReferenceData
    truth_imu: ImuData
    t0_ns: int
    spec: SimulationSpec
    sensor_errors: dict = field(repr=False)
    trajectory: Trajectory | None = field(default=None, repr=False, compare=False)
    realism: dict | None = field(default=None, repr=False)
    odometry: OdometryData | None = None

    def recording(self) -> Recording:
        """The simulated log as a :class:`~navpp.recording.Recording` (unix time base)."""
        sp = self.spec
        return Recording(imu=self.imu, gnss=self.gnss, t0_ns=self.t0_ns, time_base="unix",
                         reference=self.reference, odometry=self.odometry,
                         source=f"navpp.simulate(duration={sp.duration_s:g} s, preset={sp.preset}, seed={sp.seed})")


def _sample_times(duration: float, rate: float) -> np.ndarray:
    n = int(math.floor(duration * rate + 1e-9)) + 1
    return np.arange(n) / rate


def simulate(spec: SimulationSpec) -> Simulation:
    """Simulate a drive: IMU (with errors of ``spec.preset``), GNSS and reference.

    Parameters
    ----------
    spec : what to simulate; the same spec gives bit-identical output.

    Returns
    -------
    Simulation
    """
    traj = Trajectory.from_spec(spec)
    # IMU (0,), GNSS (1,), real-world effects (2,), odometry (3,): spawn keys are fixed, so the
    # fourth child leaves the first three (and every log without odometry) as they were
    streams = np.random.SeedSequence(spec.seed).spawn(4)
    imu_rng, gnss_rng = (np.random.default_rng(s) for s in streams[:2])
    imu, truth_imu, err, applied = _simulate_imu(spec, traj, imu_rng, streams[2])
    gnss, errors = _simulate_gnss(spec, traj, gnss_rng, err)
    odometry, odo_truth = _simulate_odometry(spec, traj, np.random.default_rng(streams[3]))
    errors.update(odo_truth)
    if applied is not None:
        gnss, applied["gnss_gap"] = _gnss_gap(spec, traj, gnss)
        if applied["gnss_gap"] is not None:
            keep = applied["gnss_gap"].pop("_keep")
            for key in ("gnss_error_enu", "gnss_true_lat_deg", "gnss_true_lon_deg", "gnss_true_alt",
                        "gnss_true_vel_enu"):
                if key in errors:
                    errors[key] = errors[key][keep]
    return Simulation(
        imu=imu,
        gnss=gnss,
        reference=_simulate_reference(spec, traj),
        truth_imu=truth_imu,
        t0_ns=int(round(spec.t0_unix * 1e6)) * 1000,  # the microsecond the CSV times are written to
        spec=spec,
        sensor_errors=errors,
        trajectory=traj,
        realism=applied,
        odometry=odometry,
    )


def _simulate_imu(spec: SimulationSpec, traj: Trajectory, imu_rng: np.random.Generator,
                  effects_seed: np.random.SeedSequence) -> tuple[ImuData, ImuData, dict, dict | None]:
    """The logged IMU (written stamps, sensor axes, with errors), the error-free IMU of the body at
    the true sample times, the drawn errors (:attr:`Simulation.sensor_errors`) and the applied
    real-world effects (None when none is on; ``effects_seed`` seeds their draws)."""
    dt = 1.0 / _resolved(spec.imu_rate_hz)
    t_imu = _sample_times(spec.duration_s, _resolved(spec.imu_rate_hz))
    st_imu = traj.state(t_imu) if spec.realistic else None
    gyro_true, accel_true = traj.ideal_imu(t_imu, st_imu)
    gyro_in, accel_in = gyro_true, accel_true
    mount = None
    if spec.mounting_rpy_deg is not None:
        mount = rpy_deg_to_dcm(spec.mounting_rpy_deg)  # sensor -> body, as navpp's [imu] mounting_rpy_deg
        gyro_in, accel_in = gyro_true @ mount, accel_true @ mount  # rows: C_bs^T w_b, C_bs^T f_b
    grade = IMU_GRADES[_resolved(spec.preset)] if spec.errors else IMU_GRADES["ideal"]
    err = draw_imu_errors(imu_rng, t_imu.size, dt, grade)
    gyro_white = err.pop("_gyro_white")
    accel_white = err.pop("_accel_white")
    if spec.realistic and spec.errors:
        _override_turn_on(spec, err)
    if spec.preset == "ideal" or not spec.errors:
        gyro, accel = gyro_in.copy(), accel_in.copy()
    else:
        # measured = (1 + sf) * true + turn-on bias + Gauss-Markov + white, per axis
        gyro = ((1.0 + err["gyro_scale_factor"]) * gyro_in + err["gyro_bias"]
                + err["gyro_gauss_markov"] + gyro_white)
        accel = ((1.0 + err["accel_scale_factor"]) * accel_in + err["accel_bias"]
                 + err["accel_gauss_markov"] + accel_white)
    del gyro_white, accel_white
    applied = None
    t_imu_written = t_imu
    if st_imu is not None:
        gyro, accel, t_imu_written, applied = _real_world_imu(
            spec, np.random.default_rng(effects_seed), t_imu, st_imu, gyro_in, accel_in, gyro, accel, err, mount)
    return (ImuData(t=t_imu_written, gyro=gyro, accel=accel),
            ImuData(t=t_imu.copy(), gyro=gyro_true, accel=accel_true), err, applied)


def _simulate_gnss(spec: SimulationSpec, traj: Trajectory, gnss_rng: np.random.Generator,
                   imu_errors: dict) -> tuple[GnssData, dict]:
    """The GNSS fixes of the antenna (all of them: the gap is cut by :func:`_gnss_gap`) and the
    sensor errors: ``imu_errors`` plus the GNSS errors and antenna truth."""
    t_gnss = _sample_times(spec.duration_s, _resolved(spec.gnss_rate_hz))
    st = traj.state(t_gnss)
    mat_nb = rph_to_dcm(st["rph"][:, 0], st["rph"][:, 1], st["rph"][:, 2])
    lever = np.asarray(spec.lever_arm_m, dtype=float)
    lat_a, lon_a, h_a = _offset_geodetic(st["lat"], st["lon"], st["h"], mat_nb @ lever)
    std = np.array([spec.gnss_std_h_m, spec.gnss_std_h_m, spec.gnss_std_u_m])
    m = t_gnss.size
    if spec.gnss_error == "white":
        e_gnss = gnss_rng.standard_normal((m, 3)) * std
        std_total = std
    else:
        gm = gauss_markov(gnss_rng, m, 1.0 / _resolved(spec.gnss_rate_hz), std, spec.gnss_corr_time_s)
        e_gnss = gm + gnss_rng.standard_normal((m, 3)) * (0.5 * std)
        std_total = std * math.sqrt(1.25)
    lat_m, lon_m, h_m = _offset_geodetic(lat_a, lon_a, h_a, e_gnss)
    errors = dict(imu_errors, gnss_error_enu=e_gnss, gnss_true_lat_deg=np.degrees(lat_a),
                  gnss_true_lon_deg=np.degrees(lon_a), gnss_true_alt=h_a)
    vel_m = std_vel = None
    if spec.gnss_velocity:
        w_en = transport_rate_enu_batch(st["lat"], st["h"], st["vel_enu"])
        w_eb_b = body_rate_from_rph(st["rph"], st["rph_dot"]) + _rotate_t(mat_nb, w_en)
        vel_a = st["vel_enu"] + _rotate(mat_nb, np.cross(w_eb_b, lever))
        vel_m = vel_a + gnss_rng.standard_normal((m, 3)) * spec.gnss_std_vel_mps
        std_vel = np.full((m, 3), spec.gnss_std_vel_mps)
        errors["gnss_true_vel_enu"] = vel_a
    gnss = GnssData(t=t_gnss, lat_deg=np.degrees(lat_m), lon_deg=np.degrees(lon_m), alt=h_m,
                    std_enu=np.tile(std_total, (m, 1)), vel_enu=vel_m, std_vel_enu=std_vel)
    return gnss, errors


def _simulate_reference(spec: SimulationSpec, traj: Trajectory) -> ReferenceData:
    """The exact truth of the body origin at ``reference_rate_hz`` (heading in [0, 360) deg)."""
    t_ref = _sample_times(spec.duration_s, spec.reference_rate_hz)
    sr = traj.state(t_ref)
    rph_deg = np.degrees(sr["rph"])
    rph_deg[:, 2] = np.mod(rph_deg[:, 2], 360.0)
    rph_deg[:, 2] = np.where(rph_deg[:, 2] >= 360.0, 0.0, rph_deg[:, 2])
    return ReferenceData(t=t_ref, lat_deg=np.degrees(sr["lat"]), lon_deg=np.degrees(sr["lon"]),
                         alt=sr["h"], vel_enu=sr["vel_enu"], rph_deg=rph_deg,
                         source="navpp.simulate truth (body origin)")


#: Odometry slip (module docstring, "Odometry"): beyond this forward acceleration the wheels slip, m/s^2.
ODOMETRY_SLIP_THRESHOLD_MPS2 = 2.0


def _simulate_odometry(spec: SimulationSpec, traj: Trajectory,
                       rng: np.random.Generator) -> tuple[OdometryData | None, dict]:
    """The wheel odometry of ``spec`` (None when off) and its truth for ``sensor_errors``
    (:class:`Simulation`).  Draws from ``rng`` in a fixed order: speed noise, yaw-rate noise."""
    if not spec.odometry:
        return None, {}
    t = _sample_times(spec.duration_s, spec.odometry_rate_hz)
    st = traj.state(t)
    rph = st["rph"]
    mat_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
    speed = _rotate_t(mat_nb, st["vel_enu"])[:, 0]             # body (= vehicle) x, m/s
    a_fwd = _rotate_t(mat_nb, st["accel_enu"])[:, 0]           # d speed / dt, m/s^2
    w_en = transport_rate_enu_batch(st["lat"], st["h"], st["vel_enu"])
    yaw_rate = (body_rate_from_rph(rph, st["rph_dot"]) + _rotate_t(mat_nb, w_en))[:, 2]   # w_eb_b z, rad/s
    excess = np.maximum(0.0, np.abs(a_fwd) - ODOMETRY_SLIP_THRESHOLD_MPS2)
    slip = np.maximum(spec.odometry_slip * np.sign(a_fwd) * excess, -speed)   # a locked wheel stops
    scale = spec.odometry_scale_error_pct * 1e-2
    measured = (1.0 + scale) * (speed + slip) + rng.standard_normal(t.size) * spec.odometry_std_mps
    q = spec.odometry_quantum_mps
    if q > 0.0:
        measured = q * np.round(measured / q)
    turning = speed + slip != 0.0                                  # a wheel at rest counts no ticks
    measured = np.where(turning, measured, 0.0)
    yaw = std_yaw = None
    if spec.odometry_yaw_rate:
        yaw = np.where(turning, yaw_rate + rng.standard_normal(t.size) * spec.odometry_yaw_rate_std_rps, 0.0)
        if spec.odometry_yaw_rate_std_rps > 0.0:
            std_yaw = np.full(t.size, spec.odometry_yaw_rate_std_rps)
    sigma = math.hypot(spec.odometry_std_mps, q / math.sqrt(12.0))   # white noise and quantisation
    offset = spec.imu_time_offset_s or 0.0                            # on the IMU's clock
    odo = OdometryData(t=t + offset if offset else t, speed=measured, yaw_rate=yaw,
                       std_speed=np.full(t.size, sigma) if sigma > 0.0 else None, std_yaw_rate=std_yaw,
                       source="navpp.simulate odometry")
    return odo, {"odometry_scale_error": scale, "odometry_true_speed": speed, "odometry_true_yaw_rate": yaw_rate,
                 "odometry_slip_mps": slip, "odometry_true_t": t}


#: Vibration (module docstring): the mount's oscillation, Hz, its damping ratio, and the share of
#: the vibration's variance that is white.
VIBRATION_HZ = 30.0
VIBRATION_DAMPING = 0.1
VIBRATION_WHITE_SHARE = 0.02


def _oscillation(rng: np.random.Generator, t: np.ndarray, k: int) -> np.ndarray:
    """(N, k) unit-std samples of the rate of change of a damped oscillator driven by white
    noise (its exact sampling at ``t``'s median interval): the running sum stays bounded."""
    n = t.shape[0]
    if n < 3:
        return np.zeros((n, k))
    dt = float(np.median(np.diff(t)))
    w = 2.0 * math.pi * VIBRATION_HZ
    r = math.exp(-VIBRATION_DAMPING * w * dt)
    th = w * math.sqrt(1.0 - VIBRATION_DAMPING ** 2) * dt
    warm = int(20.0 / max(1e-9, VIBRATION_DAMPING * w * dt)) + 10        # start from steady state
    e = rng.standard_normal((n + warm + 1, k))
    x = lfilter([1.0], [1.0, -2.0 * r * math.cos(th), r * r], e, axis=0)[warm:]
    d = np.diff(x, axis=0)
    return d / d.std(axis=0)


def _real_world_imu(spec: SimulationSpec, rng: np.random.Generator, t: np.ndarray, state: dict,
                    gyro_s: np.ndarray, accel_s: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                    err: dict, mount: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """The real-world effects on the IMU (module docstring, "Real-world effects").

    ``gyro_s, accel_s`` are the error-free readings in the sensor frame, ``gyro, accel`` the
    readings with the preset's errors; returns the readings with the effects, the written
    stamps (s from ``t0_unix``) and the applied effects (``realism.json``).  Draws from
    ``rng`` in a fixed order: gyro vibration, accel vibration, stale rows.
    """
    speed = np.linalg.norm(state["vel_enu"], axis=1)
    applied: dict = {"realism": spec.realism}
    meas = {"gyro": gyro, "accel": accel}
    true_s = {"gyro": gyro_s, "accel": accel_s}
    for kind, unit, mis_deg in (("gyro", math.radians(1.0), spec.gyro_misalignment_deg),
                                ("accel", _MG, spec.accel_misalignment_deg)):
        meas[kind], applied[kind] = _axis_errors(spec, kind, unit, mis_deg, meas[kind], true_s[kind], err)
    applied["vibration"] = _add_vibration(spec, rng, t, speed, meas)
    gyro, accel, applied["stale_rows"] = _stale_rows(spec, rng, meas["gyro"], meas["accel"])
    offset = spec.imu_time_offset_s or 0.0
    applied["imu_time_offset_s"] = spec.imu_time_offset_s
    applied["imu_time_offset_meaning"] = ("written IMU stamp = true time + offset (the IMU is late for > 0); "
                                          "[gnss] time_offset_s = offset puts the GNSS on the IMU's time base")
    applied["mounting_rpy_deg"] = None if spec.mounting_rpy_deg is None else list(spec.mounting_rpy_deg)
    applied["mounting_matrix"] = None if mount is None else mount.tolist()
    applied["mounting_meaning"] = ("sensor -> body rotation (as [imu] mounting_rpy_deg, rpy_matrix): the IMU "
                                   "reads w_s = C^T w_b, f_s = C^T f_b")
    applied["start_in_motion"] = bool(spec.start_in_motion)
    applied["start_speed_mps"] = float(speed[0])
    applied["start_cut_s"] = spec.start_cut_s
    applied["still_s"] = spec.still_effective_s
    t_written = t + offset if offset else t
    return gyro, accel, t_written, applied


def _axis_errors(spec: SimulationSpec, kind: str, unit: float, mis_deg: tuple[float, float, float] | None,
                 meas: np.ndarray, true_s: np.ndarray, err: dict) -> tuple[np.ndarray, dict]:
    """The ``kind`` ("gyro" / "accel") readings with the axis non-orthogonality (and, for an ideal
    IMU, the spec's own scale factors and biases) added, and their entry of ``realism.json``
    (biases in ``unit``: rad/s per deg/s, m/s^2 per mg)."""
    on = spec.errors
    mis = np.zeros(3) if mis_deg is None or not on else np.radians(mis_deg)
    n = np.zeros((3, 3))
    n[1, 0], n[2, 0], n[2, 1] = mis  # axis y senses x, z senses x, z senses y (rad)
    if n.any():
        meas = meas + true_s @ n.T
    real = on and spec.preset != "ideal"  # the preset's errors are in (or the extras alone)
    sf = err[f"{kind}_scale_factor"] if real else np.zeros(3)
    bias = err[f"{kind}_bias"] if real else np.zeros(3)
    if not real and on and spec.preset == "ideal":  # an ideal IMU with explicit extras
        sf, bias = _extras_alone(spec, kind)
        meas = meas + sf * true_s + bias
    return meas, {
        "turn_on_bias": (bias / unit).tolist(),
        "turn_on_bias_units": "deg/s" if kind == "gyro" else "mg",
        "scale_factor": np.asarray(sf, dtype=float).tolist(),
        "misalignment_deg": np.degrees(mis).tolist(),
        "error_matrix": (np.eye(3) + np.diag(sf) + n).tolist(),
        "model": "measured = error_matrix @ true (sensor axes) + turn_on_bias + Gauss-Markov + white "
                 "+ vibration",
    }


def _add_vibration(spec: SimulationSpec, rng: np.random.Generator, t: np.ndarray, speed: np.ndarray,
                   meas: dict[str, np.ndarray]) -> dict:
    """Add the vibration to the readings of ``meas`` ("gyro", "accel": each entry replaced) and
    return its model for ``realism.json``; ``speed`` (N,) m/s is the body's true speed."""
    on = spec.errors
    vib_model = {"model": "per sensor axis, sample std = a + b * speed (true speed, m/s); engine on for the "
                          "whole log; variance share 1 - white_share: sampled rate of a damped oscillation "
                          "(bounded integral), white_share: white",
                 "oscillation_hz": VIBRATION_HZ, "damping": VIBRATION_DAMPING, "white_share": VIBRATION_WHITE_SHARE}
    for kind, pair, unit in (("gyro", spec.vibration_gyro_dps, math.radians(1.0)),
                             ("accel", spec.vibration_accel_mps2, 1.0)):
        if pair is None or not on:
            vib_model[f"{kind}_{'dps' if kind == 'gyro' else 'mps2'}"] = None
            continue
        sigma = (pair[0] + pair[1] * speed) * unit
        shake = _oscillation(rng, t, 3)
        white = rng.standard_normal((t.size, 3))
        unit_std = math.sqrt(1.0 - VIBRATION_WHITE_SHARE) * shake + math.sqrt(VIBRATION_WHITE_SHARE) * white
        meas[kind] = meas[kind] + unit_std * sigma[:, None]
        vib_model[f"{kind}_{'dps' if kind == 'gyro' else 'mps2'}"] = {"a": pair[0], "b": pair[1]}
    return vib_model


def _stale_rows(spec: SimulationSpec, rng: np.random.Generator, gyro: np.ndarray,
                accel: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """The readings with ``stale_fraction`` of the rows after the first replaced by the previous
    row's values, and the ``realism.json`` entry listing them."""
    n = int(gyro.shape[0])
    stale_idx = np.zeros(0, dtype=np.int64)
    if spec.stale_fraction:
        stale = rng.random(n) < spec.stale_fraction
        stale[0] = False
        src = np.maximum.accumulate(np.where(stale, 0, np.arange(n)))  # the last fresh row
        gyro, accel = gyro[src], accel[src]
        stale_idx = np.nonzero(stale)[0]
    return gyro, accel, {"fraction": spec.stale_fraction, "count": int(stale_idx.size), "rows": stale_idx.tolist(),
                         "meaning": "0-based IMU rows (after the header) that repeat the previous row's six "
                                    "values under their own stamp"}


def _override_turn_on(spec: SimulationSpec, err: dict) -> None:
    """The spec's turn-on biases and scale factors replace the preset's drawn ones (in ``err``)."""
    for kind, bias, sf in (("gyro", spec.gyro_bias_dps, spec.gyro_scale_factor_pct),
                           ("accel", spec.accel_bias_mg, spec.accel_scale_factor_pct)):
        extra_sf, extra_bias = _extras_alone(spec, kind)
        if bias is not None:
            err[f"{kind}_bias"] = extra_bias
        if sf is not None:
            err[f"{kind}_scale_factor"] = extra_sf


def _extras_alone(spec: SimulationSpec, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """The spec's own scale factor (ratio) and turn-on bias (SI) of ``kind``; zeros where None."""
    if kind == "gyro":
        sf, bias, unit = spec.gyro_scale_factor_pct, spec.gyro_bias_dps, math.radians(1.0)
    else:
        sf, bias, unit = spec.accel_scale_factor_pct, spec.accel_bias_mg, _MG
    return (np.zeros(3) if sf is None else np.asarray(sf) * 1e-2,
            np.zeros(3) if bias is None else np.asarray(bias) * unit)


def _gnss_gap(spec: SimulationSpec, traj: Trajectory, gnss: GnssData) -> tuple[GnssData, dict | None]:
    """GNSS without the fixes of ``[start, start + gnss_gap_s)`` (true time, s from ``t0_unix``).

    The start is ``gnss_gap_start_s``, or the start of the first turn (heading step) that
    begins at least :data:`GAP_EARLIEST_S` after the first sample and after the still period.
    """
    if not spec.gnss_gap_s:
        return gnss, None
    start = spec.gnss_gap_start_s
    if start is None:
        hd = traj.controls.heading
        ok = hd.start >= max(GAP_EARLIEST_S, spec.still_effective_s)
        if not ok.any():
            raise ConfigError("simulate: no turn to put the GNSS gap in; give gnss_gap_start_s")
        start = float(hd.start[np.argmax(ok)])
    end = start + spec.gnss_gap_s
    if end > spec.duration_s:
        raise ConfigError(f"simulate: the GNSS gap ({start:g}-{end:g} s) ends after the log "
                          f"({spec.duration_s:g} s); shorten gnss_gap_s or make the log longer")
    keep = ~((gnss.t >= start) & (gnss.t < end))
    sel = lambda a: None if a is None else a[keep]  # noqa: E731
    out = GnssData(t=gnss.t[keep], lat_deg=gnss.lat_deg[keep], lon_deg=gnss.lon_deg[keep], alt=gnss.alt[keep],
                   std_enu=sel(gnss.std_enu), vel_enu=sel(gnss.vel_enu), std_vel_enu=sel(gnss.std_vel_enu))
    return out, {"start_s": start, "end_s": end, "removed_fixes": int(np.count_nonzero(~keep)), "_keep": keep,
                 "meaning": "GNSS fixes with start_s <= true time < end_s (s from t0_unix) are missing"}


# --------------------------------------------------------------------------- CSV output


def _write_atomic(path: Path, parts: Iterable[str]) -> None:
    """Write the text ``parts`` to a temporary name beside ``path``, then rename it into place."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            for part in parts:
                fh.write(part)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _table(t0_unix: float, t: np.ndarray, header: list[str], columns: list[tuple[np.ndarray, str]],
           rows_per_block: int = 50_000) -> Iterator[str]:
    """CSV text in blocks: header, then rows whose first column is the absolute time.

    The time is exact to the microsecond (integer seconds and microseconds, 6 decimals); each
    block is formatted by one ``%`` operation on a repeated row format (no per-row Python).
    """
    yield ",".join(header) + "\n"
    us = int(round(t0_unix * 1e6)) + np.round(np.asarray(t) * 1e6).astype(np.int64)
    row = "%d.%06d," + ",".join(f for _, f in columns) + "\n"
    for a in range(0, us.size, rows_per_block):
        b = min(a + rows_per_block, us.size)
        data = np.empty((b - a, 2 + len(columns)), dtype=object)
        data[:, 0] = (us[a:b] // 1_000_000).tolist()
        data[:, 1] = (us[a:b] % 1_000_000).tolist()
        for j, (col, _) in enumerate(columns):
            data[:, 2 + j] = (np.asarray(col[a:b], dtype=float) + 0.0).tolist()  # + 0.0: no "-0.0"
        yield (row * (b - a)) % tuple(data.ravel().tolist())


def _odometry_table(t0_unix: float, odo: OdometryData) -> Iterator[str]:
    """``odometry.csv``: ``t, speed[, yaw_rate][, std_speed][, std_yaw_rate]``, t as in imu.csv."""
    header, cols = ["t", "speed"], [(odo.speed, "%.17g")]
    for name in ("yaw_rate", "std_speed", "std_yaw_rate"):
        col = getattr(odo, name)
        if col is not None:
            header.append(name)
            cols.append((col, "%.17g"))
    return _table(t0_unix, odo.t, header, cols)


def _odometry_comment(sp: SimulationSpec) -> list[str]:
    """navpp.toml comment lines describing the simulated odometry (its truth included), or []."""
    if not sp.odometry:
        return []
    return [f"# odometry.csv: forward speed along the vehicle x axis at {sp.odometry_rate_hz:g} Hz on the IMU clock, "
            f"scale error {sp.odometry_scale_error_pct:+g} % (truth), noise {sp.odometry_std_mps:g} m/s, "
            f"quantum {sp.odometry_quantum_mps:g} m/s, slip {sp.odometry_slip:g} s"
            + (f", yaw rate {sp.odometry_yaw_rate_std_rps:g} rad/s noise" if sp.odometry_yaw_rate else "") + "."]


def _toml(sim: Simulation) -> str:
    sp = sim.spec
    if sp.realism is not None:
        return _toml_realism(sim)
    lines = [
        "# navpp.toml -- generated by navpp.simulate (navpp simulate): a simulated car drive.",
        f"# duration {sp.duration_s:g} s (still {sp.still_effective_s:g} s first), start "
        f"{sp.lat0_deg:g} deg N {sp.lon0_deg:g} deg E {sp.alt0_m:g} m, heading {sp.heading0_deg:g} deg.",
        f"# IMU {sp.imu_rate_hz:g} Hz, preset {sp.preset}, errors {'on' if sp.errors else 'off'}, "
        f"seed {sp.seed}; GNSS {sp.gnss_rate_hz:g} Hz, {sp.gnss_error} noise "
        f"({sp.gnss_std_h_m:g} m horizontal, {sp.gnss_std_u_m:g} m vertical)"
        + (f", velocity {sp.gnss_std_vel_mps:g} m/s" if sp.gnss_velocity else "") + ".",
        f"# imu.csv, gnss.csv, reference.csv: t in unix seconds (first IMU sample {sp.t0_unix:.6f});",
        "# reference.csv is the exact truth of the body (IMU) origin.",
        *_odometry_comment(sp),
        "",
    ]
    if sp.preset != "ideal":
        lines += ["[imu]", f'preset = "{sp.preset}"', ""]
    else:
        lines += ["# [imu] preset omitted: the IMU is error-free (preset 'ideal').", ""]
    lever = ", ".join(repr(float(x)) for x in sp.lever_arm_m)
    lines += ["[gnss]", f"lever_arm_m = [{lever}]", ""]
    return "\n".join(lines)


def _toml_realism(sim: Simulation) -> str:
    """What a user of a real car log would write: the lever arm (measured on the car) and the
    vehicle type; no IMU preset or noise figures, no mounting, no clock offset (those are the
    truth the run has to find; they are in ``realism.json``)."""
    sp = sim.spec
    lever = ", ".join(repr(float(x)) for x in sp.lever_arm_m)
    return "\n".join([
        f"# navpp.toml -- generated by navpp.simulate (navpp simulate --realism {sp.realism}): a simulated",
        "# car drive with the effects of a real log; what the run has to find is in realism.json.",
        "# imu.csv, gnss.csv, reference.csv: t in unix seconds; reference.csv is the exact truth of the",
        "# body (vehicle) origin at true times.",
        *_odometry_comment(sp),
        "",
        "[gnss]",
        f"lever_arm_m = [{lever}]",
        "",
        "[vehicle]",
        'type = "car"',
        "",
    ])


def realism_json(sim: Simulation) -> dict:
    """The real-world effects applied to ``sim`` (the content of ``realism.json``), or {}."""
    if sim.realism is None:
        return {}
    sp = sim.spec
    out = {
        "note": "truth of the simulated log (navpp.simulate): frames body FLU (vehicle), sensor = the IMU's "
                "axes; times s from t0_unix (true time); do not give these to the run",
        "t0_unix": sp.t0_unix, "duration_s": sp.duration_s, "seed": sp.seed, "preset": sp.preset,
        "errors": bool(sp.errors), "imu_rate_hz": sp.imu_rate_hz, "gnss_rate_hz": sp.gnss_rate_hz,
        "gnss_std_h_m": sp.gnss_std_h_m, "gnss_std_u_m": sp.gnss_std_u_m, "lever_arm_m": list(sp.lever_arm_m),
    }
    out.update(sim.realism)
    if sp.odometry:
        out["odometry"] = {"scale_error_pct": sp.odometry_scale_error_pct, "rate_hz": sp.odometry_rate_hz,
                           "std_mps": sp.odometry_std_mps, "quantum_mps": sp.odometry_quantum_mps,
                           "slip_s": sp.odometry_slip, "slip_threshold_mps2": ODOMETRY_SLIP_THRESHOLD_MPS2,
                           "yaw_rate_std_rps": sp.odometry_yaw_rate_std_rps if sp.odometry_yaw_rate else None,
                           "model": "speed = (1 + scale_error) * (forward speed + slip) + white noise, then "
                                    "quantised; stamps on the IMU clock (imu_time_offset_s applies)"}
    return out


def write_csv_log(sim: Simulation, out_dir: str | os.PathLike) -> None:
    """Write ``imu.csv``, ``gnss.csv``, ``reference.csv`` and ``navpp.toml`` into ``out_dir``,
    ``odometry.csv`` when the spec has odometry, and ``realism.json`` (:func:`realism_json`) when
    a real-world effect is on.

    Times are absolute (``spec.t0_unix + t``, 6 decimals, exact to the microsecond); IMU
    values are written with 17 significant digits (round-trip exact).  Each file is written
    to a temporary name and renamed when complete.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = sim.spec.t0_unix
    imu = sim.imu
    g17 = "%.17g"
    _write_atomic(out / "imu.csv", _table(
        t0, imu.t, ["t", "gx", "gy", "gz", "ax", "ay", "az"],
        [(imu.gyro[:, i], g17) for i in range(3)] + [(imu.accel[:, i], g17) for i in range(3)]))

    g = sim.gnss
    header = ["t", "lat", "lon", "alt", "std_e", "std_n", "std_u"]
    cols = [(g.lat_deg, "%.12f"), (g.lon_deg, "%.12f"), (g.alt, "%.9f")]
    std_enu = _resolved(g.std_enu)
    cols += [(std_enu[:, i], "%.6g") for i in range(3)]
    if g.vel_enu is not None:
        header += ["ve", "vn", "vu", "std_ve", "std_vn", "std_vu"]
        std_vel = _resolved(g.std_vel_enu)
        cols += [(g.vel_enu[:, i], "%.9f") for i in range(3)]
        cols += [(std_vel[:, i], "%.6g") for i in range(3)]
    _write_atomic(out / "gnss.csv", _table(t0, g.t, header, cols))

    r = sim.reference
    cols = [(r.lat_deg, "%.12f"), (r.lon_deg, "%.12f"), (r.alt, "%.9f")]
    vel_ref, rph_deg = _resolved(r.vel_enu), _resolved(r.rph_deg)
    cols += [(vel_ref[:, i], "%.9f") for i in range(3)]
    heading = np.round(rph_deg[:, 2], 9)
    heading = np.where(heading >= 360.0, 0.0, heading)  # [0, 360) after rounding too
    cols += [(rph_deg[:, 0], "%.9f"), (rph_deg[:, 1], "%.9f"), (heading, "%.9f")]
    _write_atomic(out / "reference.csv", _table(
        t0, r.t, ["t", "lat", "lon", "alt", "ve", "vn", "vu", "roll", "pitch", "heading"], cols))

    if sim.odometry is not None:
        _write_atomic(out / "odometry.csv", _odometry_table(t0, sim.odometry))
    _write_atomic(out / "navpp.toml", [_toml(sim)])
    if sim.realism is not None:
        _write_atomic(out / "realism.json", [json.dumps(realism_json(sim), indent=1) + "\n"])
