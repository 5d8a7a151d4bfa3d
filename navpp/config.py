"""Run configuration: TOML loading, validation, IMU presets and datasheet-unit conversion.

One TOML file, every field optional (README.md, "Configuration file"; `navpp config` prints every key)::

    [imu]      preset, noise in datasheet units, mounting_rpy_deg, gyro_units, accel_units
    [gnss]     lever_arm_m, default_std_m, default_vel_std_mps, gate_probability, ...
    [time]     base, source
    [init]     method, roll_deg, pitch_deg, heading_deg, ...
    [vehicle]  type, nhc, zupt, zaru and their noise, rate and standstill-detector keys
    [output]   rate_hz, formats, smooth, memory
    [auto]     which self-calibration steps run (standstill, noise, biases, mounting, ...)
    [filter.<name>]  each filter's own options, kept raw and validated by that filter

This module is the only place where datasheet units (deg/sqrt(h), deg/h, m/s/sqrt(h), mg)
are converted to SI: ``ImuConfig.noise()`` returns an :class:`ImuNoise` in rad, m and s.

Every dataclass validates and normalises its own fields in ``__post_init__`` (ints become
floats, lists become tuples, ``"inf"`` becomes ``math.inf``), so a config built in Python is
checked exactly like one read from TOML.  ``config_from_dict`` adds what only a file can get
wrong (unknown sections and keys, with the nearest valid key) and prefixes every message
with the file name.  All failures raise :class:`navpp.errors.ConfigError`.
"""

from __future__ import annotations

import difflib
import math
import numbers
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final

from navpp.errors import ConfigError
from navpp.units import (  # the datasheet-unit factors the config converts with, re-exported
    DEG_PER_H_TO_RAD_PER_S,
    DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S,
    DEG_TO_RAD,
    MG_TO_MPS2,
    MPS_PER_SQRT_H_TO_MPS_PER_SQRT_S,
    STANDARD_GRAVITY,
)

__all__ = [
    "ACCEL_UNITS",
    "DEG_PER_H_TO_RAD_PER_S",
    "DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S",
    "DEG_TO_RAD",
    "GYRO_UNITS",
    "INIT_METHODS",
    "MG_TO_MPS2",
    "MPS_PER_SQRT_H_TO_MPS_PER_SQRT_S",
    "NOISE_KEYS",
    "OUTPUT_FORMATS",
    "PRESETS",
    "PRESET_NAMES",
    "STANDARD_GRAVITY",
    "TIME_BASES",
    "TIME_SOURCES",
    "VEHICLE_TYPES",
    "Config",
    "GnssConfig",
    "ImuConfig",
    "ImuNoise",
    "InitConfig",
    "OdometryConfig",
    "OutputConfig",
    "TimeConfig",
    "VehicleConfig",
    "check_outages",
    "config_from_dict",
    "load_config",
    "parse_formats",
]

MAX_LEVER_ARM_M: Final[float] = 100.0
"""Longest plausible IMU-to-antenna lever arm (large ships); longer ones are unit mistakes."""

# --------------------------------------------------------------------------- presets

NOISE_KEYS: Final[tuple[str, ...]] = (
    "gyro_arw_deg_per_sqrt_h",
    "gyro_bias_deg_per_h",
    "gyro_bias_instability_deg_per_h",
    "gyro_bias_corr_time_s",
    "accel_vrw_mps_per_sqrt_h",
    "accel_bias_mg",
    "accel_bias_instability_mg",
    "accel_bias_corr_time_s",
)
"""The ``[imu]`` keys a preset fills, in datasheet units."""


def _preset(values: tuple[float, ...]) -> dict[str, float]:
    return dict(zip(NOISE_KEYS, values, strict=True))


PRESETS: dict[str, dict[str, float]] = {
    # name:          ARW    bias   instab  tau     VRW   bias    instab  tau
    "consumer": _preset((0.5, 200.0, 10.0, 100.0, 0.1, 20.0, 1.0, 100.0)),
    "automotive": _preset((1.0, 10.0, 1.0, 300.0, 0.05, 2.0, 0.1, 300.0)),
    "tactical": _preset((0.1, 1.0, 0.1, 600.0, 0.03, 0.3, 0.02, 600.0)),
    "navigation": _preset((0.003, 0.03, 0.01, 3600.0, 0.03, 0.025, 0.01, 3600.0)),
}
"""IMU noise presets in datasheet units (README.md, "Configuration file"), keyed by ``NOISE_KEYS``."""

PRESET_NAMES: Final[tuple[str, ...]] = tuple(PRESETS)
DEFAULT_PRESET: Final[str] = "automotive"

GYRO_UNITS: Final[tuple[str, ...]] = ("rad/s", "deg/s")
ACCEL_UNITS: Final[tuple[str, ...]] = ("m/s^2", "g")
TIME_BASES: Final[tuple[str, ...]] = ("unix", "gpst", "relative")
TIME_SOURCES: Final[tuple[str, ...]] = ("header", "log")
INIT_METHODS: Final[tuple[str, ...]] = ("auto", "gyrocompass", "gnss", "config")
VEHICLE_TYPES: Final[tuple[str, ...]] = ("auto", "car", "none")
OUTPUT_FORMATS: Final[tuple[str, ...]] = ("csv", "mcap", "tum", "geojson", "kml")

# Default of the eight noise fields: "take this value from the preset".  Identified by
# identity, so a NaN a user writes is still rejected as not finite.
_FROM_PRESET: Final[float] = float("nan")

_INF_WORDS: Final[frozenset[str]] = frozenset({"inf", "+inf", "infinity", "+infinity"})

# --------------------------------------------------------------------------- field checks


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _nearest(word: str, candidates: Sequence[str]) -> str | None:
    """The candidate closest to ``word`` (difflib ratio, then prefix/substring), or None."""
    lowered = {c.lower(): c for c in candidates}
    w = word.lower()
    match = difflib.get_close_matches(w, list(lowered), n=1, cutoff=0.6)
    if match:
        return lowered[match[0]]
    containing = [c for low, c in lowered.items() if w and (w in low or low in w)]
    if containing:
        return min(containing, key=len)
    match = difflib.get_close_matches(w, list(lowered), n=1, cutoff=0.4)
    return lowered[match[0]] if match else None


def _as_float(
    section: str,
    key: str,
    value: object,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    strict_min: bool = False,
    strict_max: bool = False,
    allow_inf: bool = False,
) -> float:
    """Check that ``value`` is a real number (bool excluded) within bounds; return a float."""
    if allow_inf and isinstance(value, str) and value.strip().lower() in _INF_WORDS:
        return math.inf
    if not _is_number(value):
        what = 'a number or "inf"' if allow_inf else "a number"
        raise ConfigError(f"[{section}] {key} must be {what}, got {value!r}")
    x = float(value)  # type: ignore[arg-type]  # checked by _is_number
    if math.isnan(x) or (math.isinf(x) and not allow_inf):
        raise ConfigError(f"[{section}] {key} must be finite, got {value!r}")
    if minimum is not None and (x <= minimum if strict_min else x < minimum):
        op = ">" if strict_min else ">="
        raise ConfigError(f"[{section}] {key} must be {op} {minimum:g}, got {value!r}")
    if maximum is not None and (x >= maximum if strict_max else x > maximum):
        op = "<" if strict_max else "<="
        raise ConfigError(f"[{section}] {key} must be {op} {maximum:g}, got {value!r}")
    return x


def _as_vector(section: str, key: str, value: object, n: int) -> tuple[float, ...]:
    """Check that ``value`` is a list/tuple of ``n`` finite numbers; return a float tuple."""
    if (
        not isinstance(value, list | tuple)
        or len(value) != n
        or not all(_is_number(v) and math.isfinite(v) for v in value)
    ):
        raise ConfigError(
            f"[{section}] {key} must be a list of {n} finite numbers, got {value!r}"
        )
    return tuple(float(v) for v in value)


def _as_choice(section: str, key: str, value: object, choices: Sequence[str]) -> str:
    """Check that ``value`` is one of ``choices``; the message lists them all."""
    if isinstance(value, str) and value in choices:
        return value
    listed = ", ".join(repr(c) for c in choices)
    msg = f"[{section}] {key} must be one of {listed}; got {value!r}"
    if isinstance(value, str) and (near := _nearest(value, choices)) is not None:
        msg += f" (did you mean {near!r}?)"
    raise ConfigError(msg)


def _as_bool(section: str, key: str, value: object) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"[{section}] {key} must be true or false, got {value!r}")
    return value


def _as_int(section: str, key: str, value: object, *, minimum: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ConfigError(f"[{section}] {key} must be an integer, got {value!r}")
    if value < minimum:
        raise ConfigError(f"[{section}] {key} must be >= {minimum}, got {value!r}")
    return value


def _as_optional_float(section: str, key: str, value: object, **bounds: Any) -> float | None:
    return None if value is None else _as_float(section, key, value, **bounds)


def _fix_float(obj: object, section: str, key: str, **bounds: Any) -> None:
    """Validate ``obj.key`` with ``_as_float`` and store the float back (frozen dataclass)."""
    _set(obj, key, _as_float(section, key, getattr(obj, key), **bounds))


def _fix_optional_float(obj: object, section: str, key: str, **bounds: Any) -> None:
    """As ``_fix_float`` but None is allowed and kept."""
    _set(obj, key, _as_optional_float(section, key, getattr(obj, key), **bounds))


def _freeze(value: Any) -> Any:
    """Read-only deep copy: mappings -> MappingProxyType, lists -> tuples."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)  # normalising a frozen dataclass in __post_init__


# --------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class ImuNoise:
    """IMU error model in SI units, derived once from :class:`ImuConfig` by ``noise()``.

    Bias models are first-order Gauss-Markov: ``b_dot = -b / tau + w`` with steady-state
    standard deviation ``*_bias_instability``; ``tau = math.inf`` means a random walk.

    Attributes
    ----------
    gyro_arw : float, rad/sqrt(s). Angle random walk (white rate noise density).
    accel_vrw : float, m/s/sqrt(s). Velocity random walk (white specific-force noise density).
    gyro_bias_sigma : float, rad/s. Turn-on gyro bias, 1 sigma (initial covariance).
    gyro_bias_instability : float, rad/s. Steady-state sigma of the gyro bias process.
    gyro_bias_tau : float, s. Gyro bias correlation time, > 0, may be ``math.inf``.
    accel_bias_sigma : float, m/s^2. Turn-on accelerometer bias, 1 sigma.
    accel_bias_instability : float, m/s^2. Steady-state sigma of the accelerometer bias.
    accel_bias_tau : float, s. Accelerometer bias correlation time, > 0, may be ``math.inf``.
    """

    gyro_arw: float
    accel_vrw: float
    gyro_bias_sigma: float
    gyro_bias_instability: float
    gyro_bias_tau: float
    accel_bias_sigma: float
    accel_bias_instability: float
    accel_bias_tau: float


#: White-noise densities of ``[imu]``: must be > 0 (a noise-free IMU makes the process noise of
#: velocity or attitude zero, the filter's prediction then outweighs every fix).
WHITE_NOISE_KEYS = ("gyro_arw_deg_per_sqrt_h", "accel_vrw_mps_per_sqrt_h")


@dataclass(frozen=True)
class ImuConfig:
    """``[imu]``: noise in datasheet units, mounting rotation and sample units.

    Each of the eight noise values comes from ``preset`` unless given explicitly; explicit
    values override the preset.  Values are resolved at construction, so to switch preset
    build a new ``ImuConfig(preset=...)`` rather than ``dataclasses.replace`` the preset.

    Attributes
    ----------
    preset : str. One of ``PRESET_NAMES``; default ``"automotive"``.
    gyro_arw_deg_per_sqrt_h : float, deg/sqrt(h), > 0. Gyro angle random walk (no gyro is
        noise-free: 0 would let the filter trust the integrated IMU without limit, so it is refused).
    gyro_bias_deg_per_h : float, deg/h, >= 0. Turn-on gyro bias, 1 sigma.
    gyro_bias_instability_deg_per_h : float, deg/h, >= 0. Gyro bias instability.
    gyro_bias_corr_time_s : float, s, > 0 or ``math.inf`` (TOML ``inf`` or ``"inf"``).
    accel_vrw_mps_per_sqrt_h : float, m/s/sqrt(h), > 0. Accelerometer velocity random walk (0 refused).
    accel_bias_mg : float, mg, >= 0. Turn-on accelerometer bias, 1 sigma.
    accel_bias_instability_mg : float, mg, >= 0. Accelerometer bias instability.
    accel_bias_corr_time_s : float, s, > 0 or ``math.inf``.
    mounting_rpy_deg : (3,) float, deg. Rotation from the sensor frame to body FLU as roll,
        pitch, yaw about x, y, z.
    gyro_units : str. Units of the logged angular rate: ``"rad/s"`` or ``"deg/s"``.
    accel_units : str. Units of the logged specific force: ``"m/s^2"`` or ``"g"``.
    gyro_range_rps : float, rad/s, > 0, or None. The gyro's measurement range (datasheet full
        scale); samples reaching it are reported as saturated.  None: not checked (saturation is
        then found from values repeated at a channel's extreme only).
    accel_range_mps2 : float, m/s^2, > 0, or None. The accelerometer's range, likewise.
    """

    preset: str = DEFAULT_PRESET
    gyro_arw_deg_per_sqrt_h: float = _FROM_PRESET
    gyro_bias_deg_per_h: float = _FROM_PRESET
    gyro_bias_instability_deg_per_h: float = _FROM_PRESET
    gyro_bias_corr_time_s: float = _FROM_PRESET
    accel_vrw_mps_per_sqrt_h: float = _FROM_PRESET
    accel_bias_mg: float = _FROM_PRESET
    accel_bias_instability_mg: float = _FROM_PRESET
    accel_bias_corr_time_s: float = _FROM_PRESET
    mounting_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_units: str = "rad/s"
    accel_units: str = "m/s^2"
    gyro_range_rps: float | None = None
    accel_range_mps2: float | None = None

    def __post_init__(self) -> None:
        preset = _as_choice("imu", "preset", self.preset, PRESET_NAMES)
        for key in NOISE_KEYS:
            value = getattr(self, key)
            if value is _FROM_PRESET:
                value = PRESETS[preset][key]
            if key.endswith("_corr_time_s"):
                value = _as_float(
                    "imu", key, value, minimum=0.0, strict_min=True, allow_inf=True
                )
            else:
                value = _as_float("imu", key, value, minimum=0.0)
                if key in WHITE_NOISE_KEYS and value == 0.0:
                    raise ConfigError(
                        f"[imu] {key} = 0: no real IMU is noise-free (the filter would trust it without "
                        f"limit between fixes); give the datasheet's value or leave it out ({preset} preset: "
                        f"{PRESETS[preset][key]:g})")
            _set(self, key, value)
        mounting = _as_vector("imu", "mounting_rpy_deg", self.mounting_rpy_deg, 3)
        _set(self, "mounting_rpy_deg", mounting)
        _as_choice("imu", "gyro_units", self.gyro_units, GYRO_UNITS)
        _as_choice("imu", "accel_units", self.accel_units, ACCEL_UNITS)
        _fix_optional_float(self, "imu", "gyro_range_rps", minimum=0.0, strict_min=True)
        _fix_optional_float(self, "imu", "accel_range_mps2", minimum=0.0, strict_min=True)

    @property
    def gyro_scale(self) -> float:
        """Factor that converts logged angular rate (``gyro_units``) to rad/s."""
        return DEG_TO_RAD if self.gyro_units == "deg/s" else 1.0

    @property
    def accel_scale(self) -> float:
        """Factor that converts logged specific force (``accel_units``) to m/s^2."""
        return STANDARD_GRAVITY if self.accel_units == "g" else 1.0

    def noise(self) -> ImuNoise:
        """The noise model in SI units.

        Returns
        -------
        ImuNoise
            ARW in rad/sqrt(s), VRW in m/s/sqrt(s), gyro biases in rad/s, accelerometer
            biases in m/s^2, correlation times in s.
        """
        return ImuNoise(
            gyro_arw=self.gyro_arw_deg_per_sqrt_h * DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S,
            accel_vrw=self.accel_vrw_mps_per_sqrt_h * MPS_PER_SQRT_H_TO_MPS_PER_SQRT_S,
            gyro_bias_sigma=self.gyro_bias_deg_per_h * DEG_PER_H_TO_RAD_PER_S,
            gyro_bias_instability=self.gyro_bias_instability_deg_per_h * DEG_PER_H_TO_RAD_PER_S,
            gyro_bias_tau=self.gyro_bias_corr_time_s,
            accel_bias_sigma=self.accel_bias_mg * MG_TO_MPS2,
            accel_bias_instability=self.accel_bias_instability_mg * MG_TO_MPS2,
            accel_bias_tau=self.accel_bias_corr_time_s,
        )


def _std_triplet(value: object) -> tuple[float, float, float]:
    """``default_std_m``: scalar, [horizontal, vertical] or [east, north, up] -> ENU tuple."""
    key = "default_std_m"
    if _is_number(value):
        s = _as_float("gnss", key, value, minimum=0.0, strict_min=True)
        return (s, s, s)
    if isinstance(value, list | tuple) and len(value) in (2, 3):
        for v in value:
            if not _is_number(v) or not math.isfinite(v) or v <= 0:
                break
        else:
            if len(value) == 2:
                return (float(value[0]), float(value[0]), float(value[1]))
            return (float(value[0]), float(value[1]), float(value[2]))
    raise ConfigError(
        f"[gnss] {key} must be a positive number, a list [horizontal, vertical] or a list "
        f"[east, north, up] of positive numbers, got {value!r}"
    )


def check_outages(value: object, what: str = "[gnss] outages") -> tuple[tuple[float, float], ...]:
    """Simulated GNSS outage windows as ``((start_s, duration_s), ...)``.

    Parameters
    ----------
    value : a sequence of ``[start, duration]`` pairs, s: ``start`` from the log start (the
        first IMU sample), finite and >= 0; ``duration`` finite and > 0.
    what : how the value is named in the error message.

    Raises
    ------
    ConfigError
        Not a list of pairs of numbers, or a number out of range.
    """
    if value is None:
        return ()
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise ConfigError(f"{what} must be a list of [start, duration] pairs (s), got {value!r}")
    out = []
    for pair in value:
        ok = (not isinstance(pair, str | bytes) and isinstance(pair, Sequence) and len(pair) == 2
              and all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in pair))
        if not ok:
            raise ConfigError(f"{what}: each window must be [start, duration] in s, got {pair!r}")
        start, dur = float(pair[0]), float(pair[1])
        if not (math.isfinite(start) and start >= 0.0):
            raise ConfigError(f"{what}: start must be a finite number of s >= 0 (from the log start), got {pair[0]!r}")
        if not (math.isfinite(dur) and dur > 0.0):
            raise ConfigError(f"{what}: duration must be a finite number of s > 0, got {pair[1]!r}")
        out.append((start, dur))
    return tuple(out)


#: ``[gnss] error_model`` choices (:class:`GnssConfig`).
GNSS_ERROR_MODELS = ("auto", "white", "gauss-markov")


@dataclass(frozen=True)
class GnssConfig:
    """``[gnss]``: antenna lever arm, default measurement noise and outlier gate.

    Attributes
    ----------
    lever_arm_m : (3,) float, m. Antenna phase centre in body FLU, from the IMU.
    default_std_m : (3,) float, m, > 0. ENU position 1 sigma used when the log has none.
        Accepts a scalar (all axes) or [horizontal, vertical] and stores (e, n, u).
    default_vel_std_mps : float, m/s, > 0. Velocity 1 sigma used when the log has none.
    gate_probability : float in [0, 1). Chi-square innovation gate; 0 disables gating.
    reanchor_after_s : float, s, > 0. When every fix has failed the gate for this long, the
        next one is accepted and the position re-anchored on it (the filter, not the GNSS, is
        then taken to be wrong); shorter bursts of outliers are rejected whole.
    time_offset_s : float, s. Added to GNSS stamps to put them on the IMU's time base.
    max_rejected_fraction : float in (0, 1]. A run in which a larger share of the fixes fails
        the gate has diverged (the IMU and GNSS disagree): it stops with an error instead of
        writing a trajectory.  1 never stops.
    use_velocity : bool, default true. Use the log's GNSS velocity (CSV ``ve, vn, vu``, a Twist
        topic, RTKLIB velocity columns) as a measurement when it has one.
    outages : ((start_s, duration_s), ...). Simulated GNSS outages: the fixes inside each
        window (s from the log start, the first IMU sample) are removed before filtering and
        the metrics report each window separately; ``navpp process --gnss-outage`` replaces them.
        Applied by ``navpp process`` / :func:`navpp.api.process` and by ``navpp compare``.
    error_model : str, default ``"auto"``. How the fixes' errors behave in time: ``"white"``
        (independent from fix to fix), ``"gauss-markov"`` (a first-order Gauss-Markov error of
        correlation time ``corr_time_s`` carried as three extra filter states, ENU m, plus white
        noise) or ``"auto"`` (white, unless the innovations of the run are correlated over
        several seconds: then the run is repeated with the Gauss-Markov model and the notes say
        so).
    corr_time_s : float, s, > 0, or ``"auto"`` (default). Correlation time of the Gauss-Markov
        GNSS error; ``"auto"``: estimated from the log (the value whose innovations are most likely,
        :mod:`navpp.engine.gnss_error`), starting from 60 s.
    correlated_share : float in (0, 1) or ``"auto"`` (default). Share of each fix's variance (its
        sigma squared) that is the correlated part; the rest is white.  With the Gauss-Markov model
        the white part is the fix's R and the correlated part's stationary 1-sigma is
        ``sqrt(correlated_share)`` times the median sigma of the log's fixes (per ENU axis).
        ``"auto"``: estimated with ``corr_time_s``, starting from 0.8.
    std_scale : float, > 0, default 1. Multiplies the position 1-sigma columns of the log
        (``std_e, std_n, std_u``, a NavSatFix covariance's square roots) before use: for a
        receiver whose reported accuracy is known to be optimistic or pessimistic.
    """

    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    default_std_m: tuple[float, float, float] = (2.0, 2.0, 4.0)
    default_vel_std_mps: float = 0.1
    gate_probability: float = 0.9999
    reanchor_after_s: float = 10.0
    time_offset_s: float = 0.0
    max_rejected_fraction: float = 0.25
    outages: tuple[tuple[float, float], ...] = ()
    use_velocity: bool = True
    error_model: str = "auto"
    corr_time_s: float | str = "auto"
    correlated_share: float | str = "auto"
    std_scale: float = 1.0

    def __post_init__(self) -> None:
        _as_bool("gnss", "use_velocity", self.use_velocity)
        _as_choice("gnss", "error_model", self.error_model, GNSS_ERROR_MODELS)
        for key, what, bounds in (("corr_time_s", "a number of s > 0", dict(minimum=0.0, strict_min=True)),
                                  ("correlated_share", "a number in (0, 1)",
                                   dict(minimum=0.0, maximum=1.0, strict_min=True, strict_max=True))):
            value = getattr(self, key)
            if isinstance(value, str) and value != "auto":
                raise ConfigError(f"[gnss] {key} must be {what} or \"auto\", got {value!r}")
            if value != "auto":
                _fix_float(self, "gnss", key, **bounds)
        _fix_float(self, "gnss", "std_scale", minimum=0.0, strict_min=True)
        _set(self, "outages", check_outages(self.outages))
        _set(self, "lever_arm_m", _as_vector("gnss", "lever_arm_m", self.lever_arm_m, 3))
        if math.hypot(*self.lever_arm_m) > MAX_LEVER_ARM_M:
            raise ConfigError(f"[gnss] lever_arm_m = {list(self.lever_arm_m)!r} is "
                              f"{math.hypot(*self.lever_arm_m):.0f} m "
                              f"long (more than {MAX_LEVER_ARM_M:.0f} m): it must be in metres (millimetres?)")
        _fix_float(self, "gnss", "max_rejected_fraction", minimum=0.0, maximum=1.0, strict_min=True)
        _set(self, "default_std_m", _std_triplet(self.default_std_m))
        _fix_float(self, "gnss", "default_vel_std_mps", minimum=0.0, strict_min=True)
        _fix_float(self, "gnss", "gate_probability", minimum=0.0, maximum=1.0, strict_max=True)
        _fix_float(self, "gnss", "reanchor_after_s", minimum=0.0, strict_min=True)
        _fix_float(self, "gnss", "time_offset_s")


@dataclass(frozen=True)
class TimeConfig:
    """``[time]``: the log's time base and which stamps to use.

    Attributes
    ----------
    base : str. ``"unix"`` (UTC s since 1970), ``"gpst"`` or ``"relative"``.
    source : str. ``"header"`` (message header stamps) or ``"log"`` (record times).
    """

    base: str = "unix"
    source: str = "header"

    def __post_init__(self) -> None:
        _as_choice("time", "base", self.base, TIME_BASES)
        _as_choice("time", "source", self.source, TIME_SOURCES)


@dataclass(frozen=True)
class InitConfig:
    """``[init]``: initial alignment.

    Attributes
    ----------
    method : str. ``"auto"``, ``"gyrocompass"``, ``"gnss"`` or ``"config"`` (needs
        ``heading_deg``).
    roll_deg, pitch_deg : float or None, deg. When given they override levelling. Roll in
        [-180, 180], pitch in [-90, 90], navigation convention.
    heading_deg : float or None, deg clockwise from north.
    still_min_s : float, s, >= 0. Minimum still period for levelling / gyrocompassing.
    gyrocompass_max_heading_std_deg : float, deg, > 0. Gyrocompass heading accepted only if
        its 1 sigma is below this.
    min_speed_mps : float, m/s, >= 0. Minimum GNSS speed for heading from the velocity.
    """

    method: str = "auto"
    roll_deg: float | None = None
    pitch_deg: float | None = None
    heading_deg: float | None = None
    still_min_s: float = 2.0
    gyrocompass_max_heading_std_deg: float = 2.0
    min_speed_mps: float = 3.0

    def __post_init__(self) -> None:
        _as_choice("init", "method", self.method, INIT_METHODS)
        _fix_optional_float(self, "init", "roll_deg", minimum=-180.0, maximum=180.0)
        _fix_optional_float(self, "init", "pitch_deg", minimum=-90.0, maximum=90.0)
        _fix_optional_float(self, "init", "heading_deg")
        _fix_float(self, "init", "still_min_s", minimum=0.0)
        _fix_float(self, "init", "gyrocompass_max_heading_std_deg", minimum=0.0, strict_min=True)
        _fix_float(self, "init", "min_speed_mps", minimum=0.0)
        if self.method == "config" and self.heading_deg is None:
            raise ConfigError("[init] method = 'config' requires heading_deg")


@dataclass(frozen=True)
class VehicleConfig:
    """``[vehicle]``: what the vehicle's own motion says (:mod:`navpp.ins.aids`).

    Attributes
    ----------
    type : ``"car"`` (a wheeled vehicle: the non-holonomic constraint applies), ``"none"``, or
        ``"auto"`` (default): ``"car"`` when the run uses wheel odometry (only a wheeled vehicle
        has it; the notes say so), else ``"none"``.
    nhc : bool, default true. Apply the non-holonomic constraint (with ``type = "car"`` only).
    nhc_std_mps : (lateral, vertical) m/s, > 0. 1-sigma of the body's lateral and vertical
        velocity in the vehicle frame (side slip, suspension); a scalar sets both.
    mounting_rpy_deg : (3,) deg, or ``"auto"``. The vehicle frame's roll, pitch, yaw relative to
        the IMU body frame (after ``[imu] mounting_rpy_deg``), about x, y, z.  ``"auto"``:
        estimated (pitch and yaw; roll 0) from a first forward pass without the constraint
        (:mod:`navpp.ins.aids.mounting`), and the run says what it found.
    nhc_point_m : (3,) m. The point whose velocity has no lateral and vertical part (the rear
        axle's centre), body FLU, from the IMU.
    zupt, zaru : bool, default true. Zero-velocity and zero-rate updates while still.
    zupt_std_mps : float, m/s, > 0. 1-sigma of the zero velocity.
    zaru_std_dps : float, deg/s, >= 0. Floor on the 1-sigma of the zero rate (vibration); the
        gyro's white noise averaged over the still interval is added.
    rate_hz : float, Hz, > 0. Rate of the NHC, ZUPT and ZARU pseudo-measurements; those that fall
        within half a period of a GNSS fix ride on it.
    still_window_s : float, s, > 0. Block length of the standstill detector.
    still_accel_std_mps2, still_gyro_std_dps : floors of the detector's standard-deviation
        thresholds (m/s^2, deg/s); above them the thresholds are 4 x the configured IMU's
        white noise per sample.
    still_max_speed_mps : float, m/s, > 0. The filter's speed (and the GNSS speed, when the log
        has velocity) must be below this, with a 1-sigma below twice this, for a ZUPT or ZARU.
    """

    type: str = "auto"
    nhc: bool = True
    nhc_std_mps: tuple[float, float] = (0.1, 0.1)
    mounting_rpy_deg: tuple[float, float, float] | str = (0.0, 0.0, 0.0)
    nhc_point_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    zupt: bool = True
    zaru: bool = True
    zupt_std_mps: float = 0.02
    zaru_std_dps: float = 0.005
    rate_hz: float = 5.0
    still_window_s: float = 0.5
    still_accel_std_mps2: float = 0.05
    still_gyro_std_dps: float = 0.5
    still_max_speed_mps: float = 0.2

    def __post_init__(self) -> None:
        _as_choice("vehicle", "type", self.type, VEHICLE_TYPES)
        for key in ("nhc", "zupt", "zaru"):
            _as_bool("vehicle", key, getattr(self, key))
        std: object = self.nhc_std_mps
        if _is_number(std):
            std = (std, std)
        _set(self, "nhc_std_mps", _as_vector("vehicle", "nhc_std_mps", std, 2))
        if min(self.nhc_std_mps) <= 0.0:
            raise ConfigError(f"[vehicle] nhc_std_mps must be > 0, got {list(self.nhc_std_mps)!r}")
        if self.mounting_rpy_deg != "auto":
            _set(self, "mounting_rpy_deg", _as_vector("vehicle", "mounting_rpy_deg", self.mounting_rpy_deg, 3))
        _set(self, "nhc_point_m", _as_vector("vehicle", "nhc_point_m", self.nhc_point_m, 3))
        for key in ("zupt_std_mps", "rate_hz", "still_window_s", "still_max_speed_mps"):
            _fix_float(self, "vehicle", key, minimum=0.0, strict_min=True)
        for key in ("zaru_std_dps", "still_accel_std_mps2", "still_gyro_std_dps"):
            _fix_float(self, "vehicle", key, minimum=0.0)


@dataclass(frozen=True)
class AutoConfig:
    """``[auto]``: what navpp measures from the log itself (:mod:`navpp.ins.calibrate`).
    Every step is on by default; with one off, the configured value (a preset, a ``[vehicle]``
    threshold) is used instead, so a step's effect can be measured by turning it off.

    Attributes
    ----------
    standstill : bool. Standstill from the log's own quietest stretches, confirmed by the GNSS
        speed, for the alignment and for ZUPT/ZARU (off: fixed thresholds from ``[vehicle]``).
    noise : bool. Q's white noise is the larger of the preset and what the data show, second by
        second (vibration grows with speed).
    biases : bool. Turn-on biases from still stretches (or from motion without one) start the
        filter; a preset whose turn-on 1-sigma the data contradict is widened.
    mounting : bool. An IMU whose gravity axis is not +z (y up, upside down) is rotated so it
        is, and the run names the ``[imu] mounting_rpy_deg`` to write.
    heading : bool. Initial heading from the first motion only (no GNSS gap, no large turn,
        gyro bias removed), with a 1-sigma that includes the bias; off: the 150 m track.
    recovery : bool. A fix forced through the gate after a run of rejections re-aligns velocity
        and heading from the GNSS and re-opens attitude and gyro-bias uncertainty.
    stale_rows : bool. IMU rows that repeat the previous row's six values are dropped.
    clock_offset : bool. The IMU-GNSS clock offset is estimated from the gyro's yaw rate and the
        GNSS course rate and applied when the estimate is confident.
    """

    standstill: bool = True
    noise: bool = True
    biases: bool = True
    mounting: bool = True
    heading: bool = True
    recovery: bool = True
    stale_rows: bool = True
    clock_offset: bool = True

    def __post_init__(self) -> None:
        for f in fields(self):
            _as_bool("auto", f.name, getattr(self, f.name))


@dataclass(frozen=True)
class OutputConfig:
    """``[output]``: what to write.

    Attributes
    ----------
    rate_hz : float or None, Hz, > 0. Output rate; None writes one row per IMU sample.
    formats : tuple of str. Subset of ``OUTPUT_FORMATS``, non-empty, duplicates dropped;
        default ``("csv",)``.  ``csv`` -> trajectory.csv, ``mcap`` -> trajectory.mcap,
        ``tum`` -> trajectory.tum, ``geojson`` -> trajectory.geojson, ``kml`` ->
        trajectory.kml; diagnostics.csv (and metrics with a reference) are always written.
        TOML may give a list or one comma-separated string (``"csv,mcap"``); ``navpp
        process --format`` overrides it.
    smooth : bool, default false.  Smooth the forward run backwards (Rauch-Tung-Striebel):
        the written trajectory is the smoothed one, the forward one is kept beside it
        (``trajectory_forward.csv``, ``trajectory_forward.tum``, the MCAP's forward topics, by
        the formats written) and the metrics show both; ``--smooth`` turns it on.
    memory : int bytes, > 0, default 64 MiB; TOML may give ``"500MB"``, ``"1GB"``, ``"2G"``
        (:func:`parse_memory`).  Memory each of a run's long stores may hold: the smoother's
        stored forward run (beyond it the stored blocks go to a temporary file, deleted at the
        end, and are read back by the backward pass: :class:`navpp.filters.smoother.ForwardStore`)
        and the IMU-rate output, 140 bytes per IMU sample (beyond it the path, its 1-sigma and
        body rate live on a mapped temporary file whose pages every pass releases behind it:
        :mod:`navpp.spill`; with ``smooth`` the smoothed copy follows the path's choice, so an
        output just under the budget holds twice that in memory), and the IMU samples of a CSV
        log, 64 bytes per sample as parsed (beyond it they are written to a mapped temporary
        file as the reader parses them, and the run's passes over the IMU release their pages
        behind them).  All are in ``$TMPDIR`` and give the same bits as in memory; ``--memory``
        overrides it.  The default keeps an hour of 125 Hz IMU in memory (output 63 MB, samples
        29 MB: the fastest run) and spills longer logs, whose peak then stays flat in their length
        (a 4-hour log's 115 MB of samples held in memory had put its peak above the 8-hour one's).
    """

    rate_hz: float | None = None
    formats: tuple[str, ...] = ("csv",)
    smooth: bool = False
    memory: int = 64 << 20

    def __post_init__(self) -> None:
        _fix_optional_float(self, "output", "rate_hz", minimum=0.0, strict_min=True)
        _set(self, "formats", parse_formats(self.formats, "[output] formats"))
        _as_bool("output", "smooth", self.smooth)
        _set(self, "memory", parse_memory(self.memory, "[output] memory"))


#: multiples of a byte a memory size may name (binary: 1 GB = 1024^3 bytes)
MEMORY_UNITS: Final = {"": 1, "B": 1, "K": 1 << 10, "KB": 1 << 10, "M": 1 << 20, "MB": 1 << 20, "G": 1 << 30,
                       "GB": 1 << 30, "T": 1 << 40, "TB": 1 << 40}


def with_memory(cfg: Config, memory: object) -> Config:
    """``cfg`` with ``[output] memory`` replaced by the ``--memory`` value ``memory`` (:func:`parse_memory`)."""
    return replace(cfg, output=replace(cfg.output, memory=parse_memory(memory, "--memory")))


def parse_memory(value: object, what: str) -> int:
    """Bytes from a memory size: an int (bytes) or text such as ``"500MB"``, ``"1GB"``, ``"2G"``,
    ``"1.5 GB"`` (:data:`MEMORY_UNITS`, case-insensitive, binary).  ``what`` (``"[output]
    memory"``, ``"--memory"``) starts the message of the :class:`ConfigError` a value that is
    not a size above zero raises."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        number, unit = float(value), ""
    elif isinstance(value, str):
        text = value.strip().upper()
        digits = text.rstrip("KMGTB ")
        unit = text[len(digits):].strip()
        try:
            number = float(digits)
        except ValueError:
            number = math.nan
    else:
        number, unit = math.nan, ""
    if not (math.isfinite(number) and number > 0 and unit in MEMORY_UNITS and number * MEMORY_UNITS[unit] >= 1):
        raise ConfigError(f"{what}: expected a memory size such as 500MB, 1GB or 2G, got {value!r}")
    return int(number * MEMORY_UNITS[unit])


def parse_formats(value: object, what: str) -> tuple[str, ...]:
    """Output format names from a list or a comma-separated string, validated.

    Parameters
    ----------
    value : e.g. ``["csv", "tum"]`` or ``"csv, tum"``; each a name of ``OUTPUT_FORMATS``.
    what : where the value came from (``"[output] formats"``, ``"--format"``); every
        message starts with ``f"{what}: "``.

    Returns
    -------
    tuple of str : the names in the given order, duplicates dropped.

    Raises
    ------
    ConfigError : empty, not a list/string, or an unknown name (the message lists the valid
        names and suggests the nearest).
    """
    raw: object = value
    if isinstance(raw, str):
        raw = [part.strip() for part in raw.split(",") if part.strip()]
    if not isinstance(raw, list | tuple) or not raw:
        raise ConfigError(f"{what}: must be a non-empty list of format names, got {value!r}")
    listed = ", ".join(repr(c) for c in OUTPUT_FORMATS)
    for name in raw:
        if not (isinstance(name, str) and name in OUTPUT_FORMATS):
            msg = f"{what}: unknown format {name!r}; valid formats: {listed}"
            if isinstance(name, str) and (near := _nearest(name, OUTPUT_FORMATS)) is not None:
                msg += f" (did you mean {near!r}?)"
            raise ConfigError(msg)
    return tuple(dict.fromkeys(raw))


@dataclass(frozen=True)
class OdometryConfig:
    """``[odometry]``: the vehicle's own speed (wheel odometry, CAN wheel speed) as an aid.

    Attributes
    ----------
    use : bool, default true. Use the log's odometry (``odometry.csv``, an odometry topic) when it has one.
    lever_arm_m : (3,) float, m. The odometry point (the wheel axle's centre) in body FLU, from the IMU.
    std_mps : float, m/s, > 0, default 0.05. The speed's 1-sigma when the log has none.
    scale_sigma : float, > 0, default 0.03. Prior 1-sigma of the odometer's scale-factor error
        (0.03 = 3 %: a wheel radius or tyre pressure a little off); the filter estimates it.
    scale_walk_per_sqrt_h : float, >= 0, default 0.002. How fast the scale factor may drift, per
        square-root hour (tyres warming, load).
    use_yaw_rate : bool, default false. Also fuse the odometry's yaw rate (vehicle z axis, w.r.t. the
        Earth) when the log has one: it observes the vertical gyro bias while driving.  Off by default:
        a skid-steered robot's or a slipping car's wheel yaw rate is often worse than a MEMS gyro, and
        many Odometry messages carry a zero there; the notes say when a log has a yaw rate left unused.
    yaw_rate_std_dps : float, deg/s, > 0, default 0.2. The yaw rate's 1-sigma when the log has none.
    slip_per_g : float, >= 0, default 0.1. Wheels slip when they drive or brake hard: the speed's
        1-sigma grows by this share of the speed per g of forward acceleration (0.1: 3 % of the
        speed when braking at 0.3 g; the IMU gives the acceleration); 0 turns this off.
    still_speed_mps : float, m/s, >= 0, default 0.01. Odometry that reads at most this speed for a whole
        standstill window is evidence of standing still on its own (wheels that count no ticks), even when
        the IMU is too shaky to say so (an idling engine); 0 turns this off.  The speed gates still apply.
    """

    use: bool = True
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std_mps: float = 0.05
    scale_sigma: float = 0.03
    scale_walk_per_sqrt_h: float = 0.002
    use_yaw_rate: bool = False
    yaw_rate_std_dps: float = 0.2
    slip_per_g: float = 0.1
    still_speed_mps: float = 0.01

    def __post_init__(self) -> None:
        _as_bool("odometry", "use", self.use)
        _as_bool("odometry", "use_yaw_rate", self.use_yaw_rate)
        _fix_float(self, "odometry", "yaw_rate_std_dps", minimum=0.0, strict_min=True)
        _fix_float(self, "odometry", "still_speed_mps", minimum=0.0)
        _fix_float(self, "odometry", "slip_per_g", minimum=0.0)
        _set(self, "lever_arm_m", _as_vector("odometry", "lever_arm_m", self.lever_arm_m, 3))
        _fix_float(self, "odometry", "std_mps", minimum=0.0, strict_min=True)
        _fix_float(self, "odometry", "scale_sigma", minimum=0.0, strict_min=True)
        _fix_float(self, "odometry", "scale_walk_per_sqrt_h", minimum=0.0)


_SECTIONS: Final[dict[str, type]] = {
    "imu": ImuConfig,
    "gnss": GnssConfig,
    "time": TimeConfig,
    "init": InitConfig,
    "vehicle": VehicleConfig,
    "odometry": OdometryConfig,
    "output": OutputConfig,
    "auto": AutoConfig,
}
_FILTER_SECTION: Final[str] = "filter"
_ALL_SECTIONS: Final[tuple[str, ...]] = (*_SECTIONS, _FILTER_SECTION)


@dataclass(frozen=True)
class Config:
    """A whole, validated run configuration.

    Attributes
    ----------
    imu, gnss, time, init, vehicle, odometry, output, auto : the section dataclasses.
    filters : read-only mapping ``name -> options`` holding the raw ``[filter.<name>]``
        tables (nested tables read-only, lists as tuples); each filter validates its own.
    source : str. Where the configuration came from: a file path or ``"built-in defaults"``.
    notes : tuple of str. Lines to tell the user, e.g. which IMU preset is in use.
    """

    imu: ImuConfig = field(default_factory=ImuConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    time: TimeConfig = field(default_factory=TimeConfig)
    init: InitConfig = field(default_factory=InitConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    auto: AutoConfig = field(default_factory=AutoConfig)
    filters: Mapping[str, Mapping[str, Any]] = field(
        default_factory=lambda: MappingProxyType({})
    )
    source: str = "built-in defaults"
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name, cls in _SECTIONS.items():
            if not isinstance(getattr(self, name), cls):
                got = getattr(self, name)
                raise ConfigError(f"[{name}] must be a {cls.__name__}, got {got!r}")
        if not isinstance(self.filters, Mapping):
            raise ConfigError(
                f"[filter] must be a table of [filter.<name>] tables, got {self.filters!r}"
            )
        for name, options in self.filters.items():
            if not isinstance(options, Mapping):
                raise ConfigError(
                    f"[filter] may only hold [filter.<name>] tables; got {name!r} = {options!r}"
                )
        _set(self, "filters", _freeze(self.filters))
        _set(self, "notes", tuple(self.notes))

    @classmethod
    def default(cls) -> Config:
        """Built-in defaults: the automotive IMU preset, and a note that says so."""
        return cls(notes=(f"no config given: using the {DEFAULT_PRESET} IMU preset",))


# --------------------------------------------------------------------------- loading


def _unknown_key(key: object, section: str, valid: Sequence[str]) -> ConfigError:
    msg = f"unknown key {key!r} in [{section}]"
    near = _nearest(key, valid) if isinstance(key, str) else None
    if near is not None:
        return ConfigError(f"{msg}; did you mean {near!r}?")
    return ConfigError(f"{msg}; valid keys: {', '.join(valid)}")


def _unknown_top_level(key: object, value: object) -> ConfigError:
    sections = ", ".join(f"[{s}]" for s in _ALL_SECTIONS)
    if not isinstance(key, str):
        return ConfigError(f"unknown section {key!r}; valid sections: {sections}")
    if isinstance(value, Mapping):
        near = _nearest(key, _ALL_SECTIONS)
        hint = f"did you mean [{near}]?" if near is not None else f"valid sections: {sections}"
        return ConfigError(f"unknown section [{key}]; {hint}")
    owners = [s for s, cls in _SECTIONS.items() if key in {f.name for f in fields(cls)}]
    if owners:
        return ConfigError(
            f"key {key!r} is outside any section; did you mean to put it under [{owners[0]}]?"
        )
    return ConfigError(f"unknown top-level key {key!r}; settings go in the sections {sections}")


def _imu_note(imu_table: Mapping[str, Any], imu: ImuConfig, source: str) -> str:
    given = [k for k in NOISE_KEYS if k in imu_table]
    if "preset" not in imu_table and not given:
        return f"{source} sets no IMU noise: using the {DEFAULT_PRESET} IMU preset by default"
    if len(given) == len(NOISE_KEYS):
        return (
            f"IMU noise: all {len(given)} values from {source} "
            f"(the {imu.preset} preset is not used)"
        )
    which = f"the {imu.preset} IMU preset" + ("" if "preset" in imu_table else " (default)")
    if not given:
        return f"IMU noise: {which}, from {source}"
    return f"IMU noise: {which}, with {', '.join(given)} overridden by {source}"


def _build(data: Mapping[str, Any], source: str) -> Config:
    if not isinstance(data, Mapping):
        raise ConfigError(f"the top level must be a table, got {data!r}")
    for key, value in data.items():
        if key not in _ALL_SECTIONS:
            raise _unknown_top_level(key, value)
    sections: dict[str, Any] = {}
    for name, cls in _SECTIONS.items():
        table = data.get(name, {})
        if not isinstance(table, Mapping):
            raise ConfigError(f"[{name}] must be a table, got {table!r}")
        valid = [f.name for f in fields(cls)]
        for key in table:
            if key not in valid:
                raise _unknown_key(key, name, valid)
        sections[name] = cls(**table)
    filters = data.get(_FILTER_SECTION, {})
    if not isinstance(filters, Mapping):
        raise ConfigError(f"[filter] must be a table of [filter.<name>] tables, got {filters!r}")
    note = _imu_note(data.get("imu", {}), sections["imu"], source)
    return Config(**sections, filters=filters, source=source, notes=(note,))


def config_from_dict(data: Mapping[str, Any], source: str) -> Config:
    """Validate a parsed configuration (as ``tomllib`` returns it) and build a :class:`Config`.

    Parameters
    ----------
    data : mapping ``section -> table``; missing sections and keys take their defaults.
    source : str. Where ``data`` came from; starts every error message and is kept in
        ``Config.source``.

    Raises
    ------
    ConfigError
        Unknown section or key (with the nearest valid one), wrong type or shape, value out
        of range, unknown preset or enum value.
    """
    try:
        return _build(data, source)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def load_config(path: str | Path | None) -> Config:
    """Read and validate a TOML configuration file.

    Parameters
    ----------
    path : str, Path or None. None returns :meth:`Config.default`.

    Raises
    ------
    ConfigError
        Missing or unreadable file, invalid UTF-8 or TOML (with tomllib's line and column),
        or any error of :func:`config_from_dict`.
    """
    if path is None:
        return Config.default()
    source = str(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {source}") from None
    except OSError as exc:
        raise ConfigError(f"cannot read config file {source}: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        msg = f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start})"
        raise ConfigError(msg) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: invalid TOML: {exc}") from None
    return config_from_dict(data, source)
