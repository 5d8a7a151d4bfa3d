"""Validated numpy containers: what readers produce and what the engine and writers consume.

Time: ``t0_ns`` is the log's first IMU stamp as integer nanoseconds on the log's own time
base (unix, gpst or relative seconds, as declared by ``[time] base``); every ``t`` array is
float seconds relative to ``t0_ns``.  Frames: body FLU, navigation ENU, positions geodetic
WGS-84 (latitude/longitude in degrees where the name says ``_deg``, radians otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .spill import windows

#: A stamp may step back by at most this much (s) and still be taken for a reordered message
#: (sorted into place); a larger step back is a clock jump or a concatenated log: an error.
MAX_REORDER_S = 1.0
#: An IMU interval longer than this many nominal sample periods is a long gap (dropped
#: messages, a logger stall).  The strapdown integrates across any gap with its true length,
#: interpolating the rates linearly; across a long gap the motion it cannot see is added to the
#: covariance (:meth:`navpp.ins.model.InsModel.gap_noise`).  Shorter gaps (a few dropped samples) cost nothing
#: measurable at vehicle dynamics and are integrated silently.
LONG_GAP_PERIODS = 5.0
#: Rows per block of the block-wise passes over the IMU (the reader's checks, the calibration,
#: the timing estimates): a few MB of temporaries whatever the log's length.
BLOCK_ROWS = 1 << 16


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

    A CSV log's samples beyond ``[output] memory`` live on a spill file (:mod:`navpp.spill`,
    written by the reader as it parses): the same values, but a pass over the whole log should
    release the pages behind it (:func:`navpp.spill.windows`, :class:`navpp.spill.Behind`) or
    after it (:func:`navpp.spill.release_all`), else every page it touched stays resident.
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
        for a, b in windows(n - 1, self.t):          # a spilled t a window at a time
            bad = ~(np.diff(self.t[a:b + 1]) > 0.0)          # also catches NaN stamps
            if bad.any():
                k = a + int(np.argmax(bad))
                raise ValueError(f"ImuData.t must be strictly increasing: t[{k + 1}] = {float(self.t[k + 1])!r} "
                                 f"after t[{k}] = {float(self.t[k])!r} (readers sort and drop duplicates)")
        _readonly(self.t, self.gyro, self.accel)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def rate_hz(self) -> float:
        """Nominal rate from the median sample interval."""
        if len(self) < 2:
            return float("nan")
        from .intervals import interval_median

        return float(1.0 / interval_median(self.t))      # a spilled t window by window


def lone_stamp(t: np.ndarray, reorder_s: float = MAX_REORDER_S) -> tuple[int, float] | None:
    """A lone outlier stamp in log order: ``(index, distance s)`` or None.

    One sample whose stamp is far from both neighbours while the neighbours agree with each
    other (a clock not yet set, a header stamp of 0, a corrupted field) -- the samples around
    it are regular, so the stamp is what is wrong, not the stream.  "Far" is decided from the
    stream itself, in seconds:

    - inside the stream (``0 < k < N-1``): the two neighbours are at most two long-gap spans
      apart (``2 * 5`` median intervals, :data:`LONG_GAP_PERIODS`) and stamp
      ``k`` lies outside their interval by more than that span and more than ``reorder_s``
      (a smaller step back is a reordering, sorted by :func:`order_samples`);
    - at either end: the step to the neighbour is longer than the whole rest of the stream
      lasts (and than the long-gap span and ``reorder_s``), while the neighbour's next step is
      regular (a stamp 0 before a unix-time log: 1.7e9 s against the log's minutes).

    A long gap between two runs of samples is not a lone stamp (the samples on both sides are
    many); nor is one sample at either end a short gap away from the rest.

    Parameters
    ----------
    t : (N,) stamps in log order, s (float) or ns (int64; the distance is then returned in s).
    reorder_s : the largest step back, s, that is a reordering rather than a bad stamp.

    Returns
    -------
    (k, d) with ``k`` the index in ``t`` and ``d`` how far (s) stamp k lies from its nearest
    neighbour; None when there is no such stamp.  O(N).
    """
    n = t.shape[0]
    if n < 4:
        return None
    scale = 1e-9 if np.issubdtype(np.asarray(t).dtype, np.integer) else 1.0
    d = np.diff(np.asarray(t)).astype(float, copy=False)      # exact int differences before scaling
    if scale != 1.0:
        d *= scale
    pos = d[d > 0]
    if pos.size == 0:
        return None
    span = LONG_GAP_PERIODS * float(np.median(pos, overwrite_input=True))   # the longest regular step, s
    del pos
    floor = max(span, reorder_s)
    # inside: both steps irregular, the neighbours regular with each other, stamp k outside them;
    # a block of stamps at a time (no full-length temporaries)
    for lo in range(0, n - 2, BLOCK_ROWS):
        before, after = d[lo:lo + BLOCK_ROWS], d[lo + 1:lo + 1 + BLOCK_ROWS]
        before = before[:after.shape[0]]
        skip = before + after                                   # t[k+1] - t[k-1], k = lo + 1 ..
        out = np.maximum(-before, -after)       # how far t[k] lies before t[k-1] or after t[k+1]
        bad = (skip > 0) & (skip <= 2.0 * span) & (out > floor)
        if bad.any():
            j = int(np.argmax(bad))
            return lo + j + 1, float(out[j])
    # the first sample: a step longer than the rest of the stream lasts, the next step regular
    rest0 = float(np.asarray(t[-1] - t[1]).astype(float)) * scale
    if 0 < d[1] <= span and abs(d[0]) > max(rest0, floor):
        return 0, abs(float(d[0]))
    rest1 = float(np.asarray(t[-2] - t[0]).astype(float)) * scale
    if 0 < d[-2] <= span and abs(d[-1]) > max(rest1, floor):
        return n - 1, abs(float(d[-1]))
    return None


def _stamp_s(ns: int) -> str:
    sec, frac = divmod(int(ns), 1_000_000_000)
    return f"{sec}.{frac:09d} s"


def order_samples(stamps_ns: np.ndarray, values: np.ndarray, what: str,
                  warnings: list[str]) -> np.ndarray:
    """Indices that put a stream's samples in strictly increasing stamp order, deterministically.

    The policy every reader shares (one warning line per kind, naming ``what``, the count and
    the first stamp concerned):

    - out-of-order samples (a stamp earlier than the one before, by at most
      :data:`MAX_REORDER_S`) are sorted into place (stable sort: equal stamps keep their order
      in the log);
    - exact duplicates (same stamp, same values) are dropped;
    - conflicting duplicates (same stamp, different values) keep the first in log order and
      drop the others: one stamp can carry one measurement only, and the first is what a
      real-time system would have used;
    - a step back of more than :data:`MAX_REORDER_S` is a clock jump, not a reordering:
      :class:`~navpp.errors.InputError`.

    Parameters
    ----------
    stamps_ns : (N,) int64, absolute stamps in ns, in log order.
    values : (N, k) float, the sample's values (compared for duplicates); (N,) accepted.
    what : the stream, as it should appear in messages (file and topic / column).
    warnings : list the warnings are appended to.

    Returns
    -------
    (M,) int index into the inputs, M <= N, giving strictly increasing stamps.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    vals = np.asarray(values, dtype=float).reshape(stamps.shape[0], -1)
    d = np.diff(stamps)
    back = np.nonzero(d < 0)[0]
    if back.size:
        worst = int(back[np.argmin(d[back])])
        if -int(d[worst]) > MAX_REORDER_S * 1e9:
            k = worst + 1
            raise InputError(
                f"{what}: sample {k} has stamp {_stamp_s(stamps[k])}, {-int(d[worst]) * 1e-9:.3f} s before sample "
                f"{k - 1} ({_stamp_s(stamps[k - 1])}): a clock jump (more than {MAX_REORDER_S:g} s back), not a "
                "reordering; split the log or check its time source")
        k = int(back[0]) + 1
        warnings.append(f"{what}: {back.size} sample{'s' if back.size > 1 else ''} out of stamp order, sorted "
                        f"(first: sample {k} at {_stamp_s(stamps[k])})")
        order = np.argsort(stamps, kind="stable")
    else:
        order = np.arange(stamps.shape[0])
    s = stamps[order]
    same = np.concatenate([[False], s[1:] == s[:-1]])
    if not same.any():
        return order
    # a duplicate is compared with the first sample of its stamp (NaN == NaN counts as equal)
    first = np.maximum.accumulate(np.where(same, 0, np.arange(s.shape[0])))
    v, v0 = vals[order], vals[order[first]]
    equal = np.all((v == v0) | (np.isnan(v) & np.isnan(v0)), axis=1)
    exact, conflict = same & equal, same & ~equal
    for mask, kind, action in ((exact, "exact duplicate", "dropped"),
                               (conflict, "conflicting duplicate", "dropped, the first sample of each stamp kept")):
        n = int(np.count_nonzero(mask))
        if n:
            j = int(np.argmax(mask))
            warnings.append(f"{what}: {n} {kind}{'s' if n > 1 else ''} (a stamp repeated"
                            + (" with different values" if mask is conflict else "")
                            + f") {action} (first at {_stamp_s(s[j])}, sample {int(order[j])})")
    return order[~same]


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
class OdometryData:
    """The vehicle's own speed: wheel odometry (ROS ``nav_msgs/Odometry``, ``TwistStamped``), CAN
    wheel speeds, ``odometry.csv``.

    Attributes
    ----------
    t : (K,) float, s relative to ``t0_ns``.
    speed : (K,) float, m/s, forward speed along the vehicle's x axis (FLU) at the odometry point.
    yaw_rate : (K,) float or None, rad/s, about the vehicle's z axis (up).
    std_speed : (K,) float or None, m/s, 1-sigma of ``speed`` as given by the log.
    std_yaw_rate : (K,) float or None, rad/s, 1-sigma of ``yaw_rate`` as given by the log.
    source : where it came from (a topic name, a file), for messages.
    """

    t: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray | None = None
    std_speed: np.ndarray | None = None
    std_yaw_rate: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        k = self.t.shape[0]
        for name in ("speed", "yaw_rate", "std_speed", "std_yaw_rate"):
            a = getattr(self, name)
            if a is not None and a.shape != (k,):
                raise ValueError(f"OdometryData.{name} has shape {a.shape}, expected ({k},)")
        _readonly(self.t, self.speed, self.yaw_rate, self.std_speed, self.std_yaw_rate)

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
    #: wheel odometry / vehicle speed when the log has it (:class:`OdometryData`)
    odometry: OdometryData | None = None
    #: what reading chose, one line each (which reference and how it was found, a GNSS file
    #: replacing the log's GNSS); printed with the run's notes
    notes: tuple[str, ...] = field(default_factory=tuple)

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
    std_att : (N, 3) float or None, rad, 1-sigma of the attitude error: the small rotation
        about the local ENU axes (east, north, up) between the true and the estimated attitude
        (the filter's error state; the up element is the heading's 1-sigma).  None: not carried.
    std_vel_enu : (N, 3) float or None, m/s, 1-sigma of ``vel_enu`` per ENU axis.
    rate_body : (N, 3) float or None, rad/s, angular velocity of the body relative to the local
        ENU frame, body FLU: the gyro (mounting applied) minus the estimated gyro bias, the
        Earth rate and the transport rate.
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt: np.ndarray
    vel_enu: np.ndarray
    rph_deg: np.ndarray
    std_enu: np.ndarray
    t0_ns: int = 0
    std_att: np.ndarray | None = None
    std_vel_enu: np.ndarray | None = None
    rate_body: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])
