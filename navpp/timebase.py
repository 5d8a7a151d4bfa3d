"""Time scales: UTC/unix, GPS time (GPST) and the GPS-UTC leap-second table.

Definitions used throughout navpp
---------------------------------
``unix``
    UTC seconds since 1970-01-01 00:00:00 UTC, POSIX style (every day has 86400 s, leap
    seconds are not counted).  ROS stamps are on this base.
``gpst`` (the ``[time] base = "gpst"`` of the config (README.md, "Configuration file"))
    GPS time expressed as seconds since 1970-01-01 00:00:00 *on the GPS time scale*, i.e. the
    GPS calendar date and time of day converted the POSIX way.  Numerically
    ``gpst = unix + (GPS - UTC)``: 18 s ahead of ``unix`` since 2017-01-01, equal to it before
    1981-07-01.  This is what users of ROS/MCAP "GPS time" stamps usually mean, and a GPST
    calendar time ``2024/01/01 00:00:00`` from RTKLIB becomes ``gpst = 1704067200`` exactly as
    the same calendar time in UTC becomes ``unix = 1704067200``.
    The GPS epoch 1980-01-06 00:00:00 GPST is ``gpst = GPS_EPOCH_UNIX = 315964800``.
``relative``
    Seconds from an arbitrary origin; it cannot be converted to or from the other two.

"Seconds since the GPS epoch" (``gps_seconds``: GPS week * 604800 + time of week) is a third
numeric form of GPS time; ``gpst_to_unix`` / ``unix_to_gpst`` take / return it, as the names
of those conventional functions suggest.  ``gpst`` base value = ``gps_seconds + GPS_EPOCH_UNIX``.

Leap seconds
------------
A leap second inserted at the end of a UTC day (23:59:60) has no unix value of its own.  This
module follows the POSIX formula: 23:59:60.x UTC maps to the unix value of the following
00:00:00.x, so ``gpst_to_unix`` repeats one unix second there, and ``unix_to_gpst`` reads an
ambiguous unix second as the one *after* the leap second.  Everywhere else the conversions are
exact inverses; the ``*_ns`` variants work in int64 nanoseconds and are exact.

Times before the GPS epoch are converted with GPS-UTC = 0 (GPS time did not exist then).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "GPS_EPOCH_UNIX",
    "LEAP_SECONDS",
    "LEAP_STARTS_UNIX_NS",
    "LEAP_TABLE_VALID_UNTIL_UNIX",
    "SECONDS_PER_WEEK",
    "TIME_BASES",
    "FloatSeconds",
    "convert",
    "convert_ns",
    "gps_week_tow_to_unix",
    "gps_week_tow_to_unix_ns",
    "gpst_to_unix",
    "gpst_to_unix_ns",
    "in_leap_second_gpst_base_ns",
    "leap_seconds_at_gpst_base_ns",
    "leap_seconds_at_unix_ns",
    "unix_to_gps_week_tow",
    "unix_to_gpst",
    "unix_to_gpst_ns",
]

TIME_BASES = ("unix", "gpst", "relative")

FloatSeconds = np.ndarray | np.float64
"""What the float-second converters return: a numpy float64 for a scalar input, else an array."""

NS = 1_000_000_000
SECONDS_PER_DAY = 86_400
SECONDS_PER_WEEK = 604_800
GPS_EPOCH_UNIX = 315_964_800
"""Unix time of the GPS epoch 1980-01-06 00:00:00 UTC (where GPS-UTC = 0)."""

# --------------------------------------------------------------------------------------------
# GPS-UTC leap-second table.
#
# Source: IERS Bulletin C / the IERS leap-second history (hpiers.obspm.fr/iers/bul/bulc/
# Leap_Second.dat; also the IANA tz "leap-seconds.list"), where TAI-UTC = 19 s at the GPS
# epoch and GPS-UTC = (TAI-UTC) - 19 s.  Each row is the UTC date at whose 00:00:00 the new
# GPS-UTC value starts (the leap second was inserted as 23:59:60 of the day before) and that
# value.  Checked against the IERS list updated through Bulletin C of July 2025, which announced
# no leap second at the end of December 2025; the table is therefore known to be complete for
# dates before 2026-07-01 (LEAP_TABLE_VALID_UNTIL_UNIX).
#
# MUST BE UPDATED when IERS announces a new leap second (Bulletin C, published each January and
# July): add a row here and move LEAP_TABLE_VALID_UNTIL_UNIX to the end of the period the new
# bulletin covers.  tests/test_rtklib.py cross-checks this table against the system's
# /usr/share/zoneinfo/leap-seconds.list when that file exists.
# --------------------------------------------------------------------------------------------
LEAP_SECONDS: tuple[tuple[str, int], ...] = (
    ("1981-07-01", 1),
    ("1982-07-01", 2),
    ("1983-07-01", 3),
    ("1985-07-01", 4),
    ("1988-01-01", 5),
    ("1990-01-01", 6),
    ("1991-01-01", 7),
    ("1992-07-01", 8),
    ("1993-07-01", 9),
    ("1994-07-01", 10),
    ("1996-01-01", 11),
    ("1997-07-01", 12),
    ("1999-01-01", 13),
    ("2006-01-01", 14),
    ("2009-01-01", 15),
    ("2012-07-01", 16),
    ("2015-07-01", 17),
    ("2017-01-01", 18),
)

LEAP_TABLE_VALID_UNTIL_UNIX = 1_782_864_000
"""Unix time of 2026-07-01 00:00:00 UTC: the table is known complete for earlier instants."""


def _date_to_unix(date: str) -> int:
    return int(np.datetime64(date, "s").astype(np.int64))


# Thresholds in int64 ns: on the unix scale (UTC instant the new value starts) and on the gpst
# base (the same instant in GPS time, i.e. unix threshold + new value).
_LEAP_UNIX_NS = np.array([_date_to_unix(d) * NS for d, _ in LEAP_SECONDS], dtype=np.int64)
_LEAP_VALUES = np.array([v for _, v in LEAP_SECONDS], dtype=np.int64)
_LEAP_GPST_NS = _LEAP_UNIX_NS + _LEAP_VALUES * NS
_LEAP_LOOKUP = np.concatenate([[0], _LEAP_VALUES]).astype(np.int64)
for _a in (_LEAP_UNIX_NS, _LEAP_VALUES, _LEAP_GPST_NS, _LEAP_LOOKUP):
    _a.flags.writeable = False
LEAP_STARTS_UNIX_NS = _LEAP_UNIX_NS
"""Read-only int64 ns: unix instants (00:00:00 UTC) at which each new GPS-UTC value starts."""
_LEAP_UNIX_S = (_LEAP_UNIX_NS // NS).astype(np.float64)
_LEAP_GPST_S = (_LEAP_GPST_NS // NS).astype(np.float64)


def _as_int_ns(t_ns: npt.ArrayLike) -> np.ndarray:
    a = np.asarray(t_ns)
    if a.dtype.kind not in "iu":
        raise TypeError(f"nanosecond times must be integers, got dtype {a.dtype}")
    return a.astype(np.int64)


def _seconds_to_ns(t: npt.ArrayLike) -> np.ndarray:
    """Float seconds -> int64 ns, whole seconds split off first so the fraction keeps its digits."""
    t = np.asarray(t, dtype=np.float64)
    s = np.floor(t)
    return s.astype(np.int64) * NS + np.round((t - s) * NS).astype(np.int64)


def leap_seconds_at_unix_ns(unix_ns: npt.ArrayLike) -> np.ndarray:
    """GPS-UTC in whole seconds (int64) at the given unix instants (int64 ns)."""
    t = _as_int_ns(unix_ns)
    return _LEAP_LOOKUP[np.searchsorted(_LEAP_UNIX_NS, t, side="right")]


def leap_seconds_at_gpst_base_ns(gpst_ns: npt.ArrayLike) -> np.ndarray:
    """GPS-UTC in whole seconds (int64) at instants given on the ``gpst`` base (int64 ns)."""
    t = _as_int_ns(gpst_ns)
    return _LEAP_LOOKUP[np.searchsorted(_LEAP_GPST_NS, t, side="right")]


def in_leap_second_gpst_base_ns(gpst_ns: npt.ArrayLike) -> np.ndarray:
    """True where a ``gpst`` base instant (int64 ns) falls inside an inserted leap second.

    Those instants are 23:59:60.x UTC, which has no unix value of its own (see the module
    docstring): converted to unix they land on the following second's values.
    """
    t = _as_int_ns(gpst_ns)
    i = np.searchsorted(_LEAP_GPST_NS, t, side="right")  # first threshold > t
    nxt = np.concatenate([_LEAP_GPST_NS, [np.iinfo(np.int64).max]])[i]
    return t >= nxt - NS


# --------------------------------------------------------------------------------------------
# seconds since the GPS epoch <-> unix
# --------------------------------------------------------------------------------------------


def gpst_to_unix_ns(gps_ns: npt.ArrayLike) -> np.ndarray:
    """GPS time as int64 ns since the GPS epoch (1980-01-06) -> unix int64 ns (exact)."""
    base = _as_int_ns(gps_ns) + GPS_EPOCH_UNIX * NS
    return base - leap_seconds_at_gpst_base_ns(base) * NS


def unix_to_gpst_ns(unix_ns: npt.ArrayLike) -> np.ndarray:
    """Unix int64 ns -> GPS time as int64 ns since the GPS epoch (exact)."""
    t = _as_int_ns(unix_ns)
    return t + leap_seconds_at_unix_ns(t) * NS - GPS_EPOCH_UNIX * NS


def _float_out(a: np.ndarray) -> FloatSeconds:
    return a[()] if a.ndim == 0 else a


def _unix_to_gpst_base_s(t: np.ndarray) -> np.ndarray:
    return t + _LEAP_LOOKUP[np.searchsorted(_LEAP_UNIX_S, t, side="right")]


def _gpst_base_to_unix_s(t: np.ndarray) -> np.ndarray:
    return t - _LEAP_LOOKUP[np.searchsorted(_LEAP_GPST_S, t, side="right")]


def gpst_to_unix(gps_seconds: npt.ArrayLike) -> FloatSeconds:
    """GPS time in seconds since the GPS epoch (week * 604800 + tow) -> unix seconds (float).

    Vectorised; scalars give a numpy float.  Only whole seconds are added or subtracted, so the
    result is as exact as float64 allows; use ``gpst_to_unix_ns`` for exact nanoseconds.
    """
    t = np.asarray(gps_seconds, dtype=np.float64) + float(GPS_EPOCH_UNIX)
    return _float_out(_gpst_base_to_unix_s(t))


def unix_to_gpst(unix_seconds: npt.ArrayLike) -> FloatSeconds:
    """Unix seconds -> GPS time in seconds since the GPS epoch (float, vectorised)."""
    t = np.asarray(unix_seconds, dtype=np.float64)
    return _float_out(_unix_to_gpst_base_s(t) - float(GPS_EPOCH_UNIX))


def gps_week_tow_to_unix_ns(week: npt.ArrayLike, tow: npt.ArrayLike) -> np.ndarray:
    """GPS week number (full, not modulo 1024) and time of week (s) -> unix int64 ns."""
    week = np.asarray(week)
    if week.dtype.kind not in "iu":
        if not np.all(week == np.floor(week)):
            raise ValueError("GPS week numbers must be whole")
        week = week.astype(np.int64)
    gps_ns = week.astype(np.int64) * (SECONDS_PER_WEEK * NS) + _seconds_to_ns(tow)
    return gpst_to_unix_ns(gps_ns)


def gps_week_tow_to_unix(week: npt.ArrayLike, tow: npt.ArrayLike) -> FloatSeconds:
    """GPS week number (full) and time of week (s) -> unix seconds (float, vectorised)."""
    week = np.asarray(week, dtype=np.float64)
    if not np.all(week == np.floor(week)):
        raise ValueError("GPS week numbers must be whole")
    base = (week * SECONDS_PER_WEEK + float(GPS_EPOCH_UNIX)) + np.asarray(tow, dtype=np.float64)
    return _float_out(_gpst_base_to_unix_s(base))


def unix_to_gps_week_tow(unix_seconds: npt.ArrayLike) -> tuple[np.ndarray, FloatSeconds]:
    """Unix seconds -> (GPS week int64, time of week float seconds)."""
    gps = unix_to_gpst(unix_seconds)
    week = np.floor_divide(gps, SECONDS_PER_WEEK)
    return week.astype(np.int64), _float_out(np.asarray(gps - week * SECONDS_PER_WEEK))


# --------------------------------------------------------------------------------------------
# between the time bases of ``[time] base``
# --------------------------------------------------------------------------------------------


def _check_base(name: str, what: str) -> None:
    if name not in TIME_BASES:
        raise ValueError(f"unknown {what} time base {name!r}; expected one of {', '.join(TIME_BASES)}")


def convert_ns(t_ns: npt.ArrayLike, from_base: str, to_base: str) -> np.ndarray:
    """Convert int64 ns between the ``"unix"`` and ``"gpst"`` bases (see the module docstring).

    ``"relative"`` converts only to itself; anything else raises ``ValueError``.
    """
    _check_base(from_base, "source")
    _check_base(to_base, "target")
    t = _as_int_ns(t_ns)
    if from_base == to_base:
        return t
    if "relative" in (from_base, to_base):
        raise ValueError("relative times have no absolute origin and cannot be converted to "
                         f"{to_base!r} from {from_base!r}")
    if from_base == "unix":  # -> gpst
        return t + leap_seconds_at_unix_ns(t) * NS
    return t - leap_seconds_at_gpst_base_ns(t) * NS  # gpst -> unix


def convert(t: npt.ArrayLike, from_base: str, to_base: str) -> FloatSeconds:
    """Convert float seconds between the ``"unix"`` and ``"gpst"`` bases (vectorised).

    ``gpst = unix + (GPS - UTC)``; see the module docstring for the definitions.
    """
    _check_base(from_base, "source")
    _check_base(to_base, "target")
    t = np.asarray(t, dtype=np.float64)
    if from_base == to_base:
        return _float_out(t)
    if "relative" in (from_base, to_base):
        raise ValueError("relative times have no absolute origin and cannot be converted to "
                         f"{to_base!r} from {from_base!r}")
    if from_base == "unix":
        return _float_out(_unix_to_gpst_base_s(t))
    return _float_out(_gpst_base_to_unix_s(t))
