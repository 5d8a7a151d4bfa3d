"""Validated numpy containers: what readers produce and what the engine and writers consume.

Time: ``t0_ns`` is the log's first IMU stamp as integer nanoseconds on the log's own time
base (unix, gpst or relative seconds, as declared by ``[time] base``); every ``t`` array is
float seconds relative to ``t0_ns``.  Frames: body FLU, navigation ENU, positions geodetic
WGS-84 (latitude/longitude in degrees where the name says ``_deg``, radians otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _readonly(*arrays: np.ndarray | None) -> None:
    for a in arrays:
        if a is not None:
            a.flags.writeable = False


@dataclass(frozen=True)
class ImuData:
    """IMU samples.

    Attributes
    ----------
    t : (N,) float, s relative to the recording's ``t0_ns``, strictly increasing.
    gyro : (N, 3) float, rad/s, angular rate of the body w.r.t. inertial space, body FLU,
        sampled at ``t``.
    accel : (N, 3) float, m/s^2, specific force, body FLU, sampled at ``t``.
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray

    def __post_init__(self) -> None:
        n = self.t.shape[0]
        if self.t.ndim != 1 or self.gyro.shape != (n, 3) or self.accel.shape != (n, 3):
            raise ValueError(
                f"ImuData shapes: t {self.t.shape}, gyro {self.gyro.shape}, accel {self.accel.shape}; "
                "expected (N,), (N, 3), (N, 3)"
            )
        _readonly(self.t, self.gyro, self.accel)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def rate_hz(self) -> float:
        """Nominal rate from the median sample interval."""
        if len(self) < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.t)))


@dataclass(frozen=True)
class GnssData:
    """GNSS position (and optionally velocity) fixes of the antenna.

    Attributes
    ----------
    t : (M,) float, s relative to ``t0_ns``.
    lat_deg, lon_deg : (M,) float, degrees, WGS-84 geodetic.
    alt : (M,) float, m above the WGS-84 ellipsoid.
    std_enu : (M, 3) float or None, m, 1-sigma of the position per ENU axis as given by the log.
    vel_enu : (M, 3) float or None, m/s, antenna velocity in ENU.
    std_vel_enu : (M, 3) float or None, m/s, 1-sigma of ``vel_enu``.
    fix : (M,) int or None, fix status / quality flag as given by the log.
    num_sats : (M,) int or None.
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt: np.ndarray
    std_enu: np.ndarray | None = None
    vel_enu: np.ndarray | None = None
    std_vel_enu: np.ndarray | None = None
    fix: np.ndarray | None = None
    num_sats: np.ndarray | None = None

    def __post_init__(self) -> None:
        m = self.t.shape[0]
        for name in ("lat_deg", "lon_deg", "alt"):
            if getattr(self, name).shape != (m,):
                raise ValueError(f"GnssData.{name} has shape {getattr(self, name).shape}, expected ({m},)")
        for name in ("std_enu", "vel_enu", "std_vel_enu"):
            a = getattr(self, name)
            if a is not None and a.shape != (m, 3):
                raise ValueError(f"GnssData.{name} has shape {a.shape}, expected ({m}, 3)")
        _readonly(self.t, self.lat_deg, self.lon_deg, self.alt, self.std_enu, self.vel_enu,
                  self.std_vel_enu, self.fix, self.num_sats)

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class ReferenceData:
    """Reference trajectory (e.g. DGPS/RTK or simulated truth) of the body origin.

    Attributes
    ----------
    t : (K,) float, s relative to the recording's ``t0_ns``.
    lat_deg, lon_deg, alt : (K,) float, degrees / degrees / m (WGS-84 ellipsoidal).
    vel_enu : (K, 3) float or None, m/s.
    rph_deg : (K, 3) float or None, roll, pitch, heading in degrees (navigation convention:
        roll right side down, pitch nose up, heading clockwise from north).
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt: np.ndarray
    vel_enu: np.ndarray | None = None
    rph_deg: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        _readonly(self.t, self.lat_deg, self.lon_deg, self.alt, self.vel_enu, self.rph_deg)

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class Recording:
    """One validated log: IMU, GNSS and optionally a reference, on one time base.

    ``t0_ns`` is the absolute stamp (integer ns on ``time_base``) that every relative ``t`` is
    measured from.  ``warnings`` lists what validation noticed but accepted (dropped duplicate
    stamps, gaps, ignored columns), one readable line each.
    """

    imu: ImuData
    gnss: GnssData
    t0_ns: int
    time_base: str = "unix"
    reference: ReferenceData | None = None
    source: str = ""
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def absolute_time(self, t_rel: np.ndarray) -> np.ndarray:
        """Relative seconds -> float seconds on the log's own time base."""
        return self.t0_ns * 1e-9 + np.asarray(t_rel, dtype=float)


@dataclass(frozen=True)
class Solution:
    """A navigation solution, one row per output epoch.

    Attributes
    ----------
    t : (N,) float, s relative to ``t0_ns``.
    lat_deg, lon_deg, alt : (N,) float, WGS-84 position of the body (IMU) origin.
    vel_enu : (N, 3) float, m/s.
    rph_deg : (N, 3) float, roll / pitch / heading in degrees (navigation convention).
    std_enu : (N, 3) float, m, 1-sigma position uncertainty per ENU axis.
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt: np.ndarray
    vel_enu: np.ndarray
    rph_deg: np.ndarray
    std_enu: np.ndarray
    t0_ns: int = 0

    def __len__(self) -> int:
        return int(self.t.shape[0])
