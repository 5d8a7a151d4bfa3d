"""CSV logs: a directory holding ``imu.csv`` and ``gnss.csv`` (optionally ``reference.csv``, ``odometry.csv``).

Schemas (header row required, comma separated, extra columns ignored and named once in a
warning; see README.md, "Input: a CSV log"):

- ``imu.csv``: ``t, gx, gy, gz, ax, ay, az``: angular rate (rad/s) and specific force (m/s^2)
  sampled at ``t``, body FLU; or increments ``t, dthx, dthy, dthz, dvx, dvy, dvz`` (rad, m/s)
  accumulated over the interval ending at ``t`` (converted to rates by
  :func:`increments_to_rates`).
- ``gnss.csv``: ``t, lat, lon, alt`` (deg, deg, m ellipsoidal); optional ``std_e, std_n, std_u``
  (m, 1-sigma); optional ``ve, vn, vu`` (m/s) with optional ``std_ve, std_vn, std_vu``; optional
  ``fix``, ``num_sats``.  Each triple is all or none.
- ``reference.csv``: ``t, lat, lon, alt``; optional ``ve, vn, vu``; optional
  ``roll, pitch, heading`` (deg).
- ``odometry.csv`` (optional, read when present): ``t, speed`` (m/s, forward along the vehicle's
  x axis); optional ``yaw_rate`` (rad/s about the vehicle's z axis, up), ``std_speed`` (m/s) and
  ``std_yaw_rate`` (rad/s), 1-sigma.  Its stamps are on the IMU's clock (same time base, same
  ``t0_ns``; ``time_offset_s`` is not added to them).

Time: ``t`` is float seconds on the log's time base (``unix``, ``gpst`` or ``relative``), in
any float form (plain, e-notation, ``+``, blanks).  Stamps are read as the exact integer
nanoseconds the text says (:func:`_stamps_ns`); the recording's ``t0_ns`` is the first IMU
stamp; every relative time is ``t - t_imu[0]`` in float64 (the reference, read on its own,
uses ``t0_ns``).

Validation happens before any array is handed out.  Every failure is an ``InputError`` whose
one-line message names the file, the column and the line (header = line 1, first data row =
line 2) or the time.  What is accepted but worth knowing (dropped duplicate stamps, gaps, ignored
columns, GNSS fixes outside the IMU span) becomes a line in ``Recording.warnings``.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from itertools import islice
from pathlib import Path
from typing import BinaryIO, cast

import numpy as np

from navpp import jitmode, spill
from navpp.errors import ConfigError, InputError
from navpp.recording import GnssData, ImuData, OdometryData, Recording, ReferenceData, lone_stamp

__all__ = ["increments_to_rates", "is_csv_log", "read_csv_log", "read_reference_csv"]

IMU_FILE = "imu.csv"
GNSS_FILE = "gnss.csv"
REFERENCE_FILE = "reference.csv"
ODOMETRY_FILE = "odometry.csv"

TIME_BASES = ("unix", "gpst", "relative")
GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
ACCEL_UNITS = {"m/s^2": 1.0, "g": 9.80665}

GAP_FACTOR = 2.5
"""A sample interval longer than this times the median interval is reported as a gap."""

_IMU_RATE_COLS = ("gx", "gy", "gz", "ax", "ay", "az")
_IMU_INCREMENT_COLS = ("dthx", "dthy", "dthz", "dvx", "dvy", "dvz")
_GNSS_REQUIRED = ("t", "lat", "lon", "alt")
_GNSS_GROUPS = (("std_e", "std_n", "std_u"), ("ve", "vn", "vu"), ("std_ve", "std_vn", "std_vu"))
_GNSS_SINGLES = ("fix", "num_sats")
_ODO_REQUIRED = ("t", "speed")
_ODO_SINGLES = ("yaw_rate", "std_speed", "std_yaw_rate")
#: A wheel speed above this (m/s, 360 km/h) is not a ground vehicle's speed in m/s (km/h? mm/s?).
MAX_ODOMETRY_SPEED_MPS = 100.0
_REF_REQUIRED = ("t", "lat", "lon", "alt")
_REF_GROUPS = (("ve", "vn", "vu"), ("roll", "pitch", "heading"))
_MAX_NAMES_SHOWN = 20

MAX_LINE_BYTES = 1 << 20
"""A CSV line longer than this (1 MiB) is refused before parsing.  A row of navpp's widest
schema (gnss.csv, 16 columns) written at full float precision is under 500 bytes; 1 MiB leaves
room for thousands of extra columns, and keeps a run's memory bounded whatever the file holds."""
_SCAN_BLOCK = MAX_LINE_BYTES // 2   # a longer line spans a whole block holding no newline


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def is_csv_log(path: str | Path) -> bool:
    """True if ``path`` is a directory holding ``imu.csv`` and ``gnss.csv``."""
    p = Path(path)
    return p.is_dir() and (p / IMU_FILE).is_file() and (p / GNSS_FILE).is_file()


def read_csv_log(
    path: str | Path,
    *,
    reference: str | Path | None = None,
    time_base: str = "unix",
    gyro_units: str = "rad/s",
    accel_units: str = "m/s^2",
    time_offset_s: float = 0.0,
    progress: Callable[[float], None] | None = None,
    memory: int | None = None,
) -> Recording:
    """Read and validate a CSV log directory (``progress(fraction)`` follows imu.csv's bytes).

    Parameters
    ----------
    path : directory holding ``imu.csv`` and ``gnss.csv``.  A ``reference.csv`` in it is read
        too unless ``reference`` names another file; an ``odometry.csv`` in it becomes
        ``Recording.odometry``.
    reference : reference trajectory CSV to use instead of ``path/reference.csv``.
    time_base : ``"unix"``, ``"gpst"`` or ``"relative"``: what the ``t`` columns count.
    gyro_units : ``"rad/s"`` or ``"deg/s"`` (for increments: rad or deg).
    accel_units : ``"m/s^2"`` or ``"g"`` (for increments: m/s or g*s).
    time_offset_s : s, added to every GNSS stamp (receiver latency correction); not to the
        odometry, which is on the IMU's clock.
    memory : bytes, ``[output] memory``: IMU samples (as parsed, then as kept) holding more go
        to a spill file (:mod:`navpp.spill`) as they are read; None: they stay in memory.

    Returns
    -------
    Recording
        ``t0_ns`` = the first IMU stamp in integer ns on ``time_base``; all ``t`` arrays are
        float seconds relative to it.  ``warnings`` holds what validation accepted but noticed.

    Raises
    ------
    InputError
        A file is missing or unusable; the message names the file, column and line or time.
    ConfigError
        ``time_base`` or a unit is not one of the accepted values.

    Notes
    -----
    IMU increments (``dthx .. dvz``) become rates sampled at the stamps as described in
    :func:`increments_to_rates`; the first IMU row is then dropped (its increment covers time
    before the log starts), so ``t0_ns`` is the second stamp of the file.
    """
    gyro_scale, accel_scale = _check_options(time_base, gyro_units, accel_units)
    log_dir = Path(path)
    if not log_dir.is_dir():
        raise InputError(
            f"{log_dir}: not a directory; a CSV log is a directory holding {IMU_FILE} and {GNSS_FILE}"
        )
    warnings: list[str] = []
    imu_data, t0_ns, imu_span = _read_imu(log_dir / IMU_FILE, gyro_scale, accel_scale, warnings, progress,
                                         memory)
    gnss_data = _read_gnss(log_dir / GNSS_FILE, t0_ns, imu_span, time_offset_s, warnings)
    odo_data = None
    if (log_dir / ODOMETRY_FILE).exists():
        odo_data = _read_odometry(log_dir / ODOMETRY_FILE, t0_ns, imu_span, warnings)
    ref_data: ReferenceData | None = None
    if reference is not None:
        ref_data = read_reference_csv(reference, t0_ns, warnings_out=warnings)
    elif (log_dir / REFERENCE_FILE).exists():
        ref_data = read_reference_csv(log_dir / REFERENCE_FILE, t0_ns, warnings_out=warnings)

    return Recording(
        imu=imu_data,
        gnss=gnss_data,
        t0_ns=t0_ns,
        time_base=time_base,
        reference=ref_data,
        source=str(path),
        warnings=tuple(warnings),
        odometry=odo_data,
    )


def _read_imu(imu_path: Path, gyro_scale: float, accel_scale: float, warnings: list[str],
              progress: Callable[[float], None] | None,
              memory: int | None = None) -> tuple[ImuData, int, tuple[float, float]]:
    """``imu.csv`` (rates or increments) as :class:`ImuData` in rad/s and m/s^2, its ``t``
    relative to the first kept stamp; that stamp (int ns on the log's time base) and the first
    and last stamp as read (float s, the span the GNSS fixes are checked against).  Beyond
    ``memory`` bytes (None: never) the samples live on a spill file, each check's pages released
    after it."""
    header = _read_header(imu_path)
    imu_format, imu_cols = _imu_format(imu_path, header)
    imu = _read_table(imu_path, header, imu_cols, warnings, progress, (1, 3, 3), memory)
    _check_lone_stamp(imu)
    _released(imu)
    imu = _with_ns(imu, header)
    _released(imu)
    imu = _check_time(imu, warnings)
    _released(imu)
    if imu_format == "increments":
        if imu.n < 3:
            raise _need_more(imu, "at least 3 rows are needed for IMU increments (the first row is dropped)")
        t_imu, rates = increments_to_rates(imu.col("t"), imu.block(_IMU_INCREMENT_COLS))
        imu_lines = imu.lines[1:]
    else:
        if imu.n < 2:
            raise _need_more(imu, "at least 2 IMU samples are needed")
        t_imu, rates = imu.col("t"), None
        imu_lines = imu.lines
    nominal = _check_rate(imu, t_imu, "an IMU", 1.0, 100_000.0)     # the median interval, once
    rate = 1.0 / nominal
    if rate < 50.0:
        warnings.append(f"{imu.path.name}: IMU rate {rate:.1f} Hz is low for strapdown navigation "
                        "(100-200 Hz expected); processed anyway")
    _gap_warning(imu.path.name, t_imu, imu_lines, warnings, nominal)
    _released(imu)
    span = (float(t_imu[0]), float(t_imu[-1]))
    imu_ns = imu.data["t_ns"]
    if imu_format == "increments":
        imu_ns = imu_ns[1:]
    t0_ns = int(imu_ns[0])
    if rates is None:       # straight from the parsed columns: no (N, 6) intermediate copy
        gyro = imu.vectors(_IMU_RATE_COLS[0:3], gyro_scale)
        accel = imu.vectors(_IMU_RATE_COLS[3:6], accel_scale)
    else:
        gyro = np.ascontiguousarray(rates[:, 0:3] * gyro_scale)
        accel = np.ascontiguousarray(rates[:, 3:6] * accel_scale)
    del imu, rates
    # t = (imu_ns - t0_ns) * 1e-9 in the stamps' own memory (the table that held them is gone)
    t = imu_ns.view(np.float64)
    for a, b in spill.windows(imu_ns.shape[0], imu_ns):
        np.subtract(imu_ns[a:b], t0_ns, out=imu_ns[a:b])
        np.multiply(imu_ns[a:b], 1e-9, out=t[a:b])
    return ImuData(t=t, gyro=gyro, accel=accel), t0_ns, span


def _released(table: _Table) -> None:
    """The pages of ``table``'s spilled columns out of memory (:func:`navpp.spill.release`), after
    a pass over them: the next pass reads them back from the spill file."""
    spill.release([*table.data.values(), *table.groups.values(), table.stamps_ns, table.lines], 0, table.n)


def _read_gnss(gnss_path: Path, t0_ns: int, imu_span: tuple[float, float], time_offset_s: float,
               warnings: list[str]) -> GnssData:
    """``gnss.csv`` as :class:`GnssData`, ``t`` relative to ``t0_ns`` after adding ``time_offset_s``
    (s); invalid fixes dropped, fixes outside ``imu_span`` (first and last IMU stamp as read, s)
    kept with a warning, none inside it an error."""
    header = _read_header(gnss_path)
    gnss_cols = _select_columns(gnss_path, header, _GNSS_REQUIRED, _GNSS_GROUPS, _GNSS_SINGLES)
    if "std_ve" in gnss_cols and "ve" not in gnss_cols:
        raise InputError(
            f"{gnss_path}: line 1 (header), columns 'std_ve', 'std_vn', 'std_vu' given without "
            "'ve', 'vn', 'vu'"
        )
    gnss = _read_table(gnss_path, header, gnss_cols, warnings)
    _check_lat_lon(gnss)
    _check_positive(gnss, [c for g in (_GNSS_GROUPS[0], _GNSS_GROUPS[2]) for c in g])
    _check_integral(gnss, _GNSS_SINGLES)
    gnss = _check_time(_with_ns(gnss, header), warnings)
    gnss = _drop_invalid_fixes(gnss, warnings)
    _check_rate(gnss, gnss.data["t"], "GNSS", 0.01, 1000.0)
    if gnss.n < 1:  # cannot happen after _read_table's row check; kept as the contract
        raise _need_more(gnss, "at least 1 GNSS fix is needed")
    t_gnss = gnss.col("t") + float(time_offset_s)
    _gap_warning(gnss.path.name, t_gnss, gnss.lines, warnings)
    _check_span(gnss, t_gnss, imu_span, time_offset_s, warnings)
    return GnssData(
        t=(gnss.data["t_ns"] + round(float(time_offset_s) * 1e9) - t0_ns) * 1e-9,
        lat_deg=gnss.col("lat"),
        lon_deg=gnss.col("lon"),
        alt=gnss.col("alt"),
        std_enu=gnss.block(_GNSS_GROUPS[0]) if "std_e" in gnss_cols else None,
        vel_enu=gnss.block(_GNSS_GROUPS[1]) if "ve" in gnss_cols else None,
        std_vel_enu=gnss.block(_GNSS_GROUPS[2]) if "std_ve" in gnss_cols else None,
        fix=gnss.col("fix").astype(np.int64) if "fix" in gnss_cols else None,
        num_sats=gnss.col("num_sats").astype(np.int64) if "num_sats" in gnss_cols else None,
    )


def _read_odometry(odo_path: Path, t0_ns: int, imu_span: tuple[float, float], warnings: list[str]) -> OdometryData:
    """``odometry.csv`` as :class:`OdometryData`, ``t`` relative to ``t0_ns`` (the first IMU stamp).

    The stamps are taken to be on the IMU's clock: ``[gnss] time_offset_s`` (a GNSS latency) is
    not added to them.  Validated like ``gnss.csv``: non-numeric, NaN or infinite cells, stamps
    going backwards, stamps not in seconds, standard deviations <= 0, ``std_yaw_rate`` without
    ``yaw_rate``, a speed over :data:`MAX_ODOMETRY_SPEED_MPS` and every row outside the IMU span
    are errors naming the line and column; duplicate stamps (dropped), gaps, rows outside the IMU
    span and extra columns are warnings."""
    header = _read_header(odo_path)
    cols = _select_columns(odo_path, header, _ODO_REQUIRED, (), _ODO_SINGLES)
    if "std_yaw_rate" in cols and "yaw_rate" not in cols:
        raise InputError(f"{odo_path}: line 1 (header), column 'std_yaw_rate' given without 'yaw_rate'")
    odo = _read_table(odo_path, header, cols, warnings)
    _check_positive(odo, ("std_speed", "std_yaw_rate"), "[odometry] std_mps")
    fast = np.abs(odo.data["speed"]) > MAX_ODOMETRY_SPEED_MPS
    if fast.any():
        k = int(np.argmax(fast))
        raise InputError(f"{odo_path}: line {odo.lines[k]}, column 'speed': {float(odo.data['speed'][k])!r} m/s is "
                         f"over {MAX_ODOMETRY_SPEED_MPS:g} m/s: not a vehicle speed in m/s (km/h?)")
    _check_lone_stamp(odo)
    odo = _check_time(_with_ns(odo, header), warnings)
    _check_rate(odo, odo.data["t"], "odometry", 0.2, 10_000.0)
    _gap_warning(odo.path.name, odo.data["t"], odo.lines, warnings)
    _check_span(odo, odo.data["t"], imu_span, 0.0, warnings, "odometry rows")
    return OdometryData(
        t=(odo.data["t_ns"] - t0_ns) * 1e-9,
        speed=odo.col("speed"),
        yaw_rate=odo.col("yaw_rate") if "yaw_rate" in cols else None,
        std_speed=odo.col("std_speed") if "std_speed" in cols else None,
        std_yaw_rate=odo.col("std_yaw_rate") if "std_yaw_rate" in cols else None,
        source=str(odo_path),
    )


def _check_span(table: _Table, t: np.ndarray, imu_span: tuple[float, float], time_offset_s: float,
                warnings: list[str], rows: str = "fixes") -> None:
    """Rows (``t``, s, offset applied) outside the IMU's first..last stamp: a warning; all of them
    outside: an error (the time bases of the two files disagree).  ``rows`` names them."""
    t_first, t_last = imu_span
    n_before = int(np.count_nonzero(t < t_first))
    n_after = int(np.count_nonzero(t > t_last))
    if n_before + n_after == table.n:
        raise InputError(
            f"{table.path}: column 't': all {table.n} {rows} (t={float(t[0])!r}..{float(t[-1])!r}"
            + (f", after adding time_offset_s={time_offset_s!r}" if time_offset_s else "")
            + f") lie outside the IMU time span t={t_first!r}..{t_last!r}; check the time bases of "
            f"{IMU_FILE} and {table.path.name}"
        )
    if n_before or n_after:
        warnings.append(
            f"{table.path.name}: {n_before + n_after} of {table.n} {rows} lie outside the IMU time span "
            f"t={t_first!r}..{t_last!r} ({n_before} before, {n_after} after"
            + (f", after adding time_offset_s={time_offset_s!r}" if time_offset_s else "")
            + "); kept, but the engine ignores them"
        )


def read_reference_csv(
    path: str | Path, t0_ns: int, *, warnings_out: list[str] | None = None
) -> ReferenceData:
    """Read and validate a reference trajectory CSV.

    Parameters
    ----------
    path : CSV file with ``t, lat, lon, alt`` and optionally ``ve, vn, vu`` and
        ``roll, pitch, heading`` (deg).
    t0_ns : int, ns on the log's time base: the stamp the relative times are measured from
        (``Recording.t0_ns``).
    warnings_out : if given, validation warnings (ignored columns, duplicate stamps) are
        appended to it.

    Returns
    -------
    ReferenceData
        ``t`` in s relative to ``t0_ns``; ``source`` is ``str(path)``.

    Raises
    ------
    InputError
        As :func:`read_csv_log`.
    """
    ref_path = Path(path)
    warnings: list[str] = []
    header = _read_header(ref_path)
    cols = _select_columns(ref_path, header, _REF_REQUIRED, _REF_GROUPS, ())
    ref = _read_table(ref_path, header, cols, warnings)
    _check_lat_lon(ref)
    ref = _check_time(_with_ns(ref, header), warnings)
    if warnings_out is not None:
        warnings_out.extend(warnings)
    t_rel = (ref.data["t_ns"] - int(t0_ns)) * 1e-9
    return ReferenceData(
        t=t_rel,
        lat_deg=ref.col("lat"),
        lon_deg=ref.col("lon"),
        alt=ref.col("alt"),
        vel_enu=ref.block(_REF_GROUPS[0]) if "ve" in cols else None,
        rph_deg=ref.block(_REF_GROUPS[1]) if "roll" in cols else None,
        source=str(path),
    )


def increments_to_rates(t: np.ndarray, increments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convert increments accumulated over the interval ending at each stamp to rates at the stamps.

    Parameters
    ----------
    t : (N,) float, s, strictly increasing stamps, N >= 3.
    increments : (N, K) float, quantity accumulated over ``(t[k-1], t[k]]`` (e.g. rad and m/s);
        row 0 covers time before ``t[0]`` and is not used.

    Returns
    -------
    t_out : (N-1,) float, s, ``t[1:]``.
    rates : (N-1, K) float, quantity per second, sampled at ``t_out``.

    Notes
    -----
    The mean rate of interval k is ``r_k = increments[k] / dt_k`` with ``dt_k = t[k] - t[k-1]``;
    it is the rate at the interval's midpoint if the rate varies linearly.  The rate at ``t[k]``
    interpolates linearly between the midpoints of intervals k and k+1:
    ``(dt_{k+1} r_k + dt_k r_{k+1}) / (dt_k + dt_{k+1})``, which is the plain average
    ``(r_k + r_{k+1}) / 2`` when the sampling is uniform, and exact for a linearly varying rate
    at any spacing (a long gap after ``t[k]`` barely weighs in).  The last sample takes its own
    interval's mean rate.  The first sample is dropped: its increment covers time before the log.
    """
    t = np.asarray(t, dtype=np.float64)
    inc = np.asarray(increments, dtype=np.float64)
    if t.ndim != 1 or inc.ndim != 2 or inc.shape[0] != t.shape[0] or t.shape[0] < 3:
        raise ValueError(
            f"increments_to_rates: t {t.shape}, increments {inc.shape}; expected (N,), (N, K), N >= 3"
        )
    dt = np.diff(t)  # dt[k-1] = t[k] - t[k-1], k = 1..N-1
    mean_rate = inc[1:] / dt[:, None]  # r_k, k = 1..N-1
    rates = np.empty_like(mean_rate)
    w_next = (dt[:-1] / (dt[:-1] + dt[1:]))[:, None]
    rates[:-1] = (1.0 - w_next) * mean_rate[:-1] + w_next * mean_rate[1:]
    rates[-1] = mean_rate[-1]
    return t[1:].copy(), rates


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Table:
    """Validated numeric columns of one CSV file, with the file line number of every row."""

    path: Path
    data: dict[str, np.ndarray]
    lines: np.ndarray  # (n,) int64, line number in the file (header = 1)
    stamps_ns: np.ndarray | None = None  # (n,) int64, the ``t`` text's exact ns, when the parser gave them
    # (n, k) C-contiguous arrays the fast parser wrote columns into, by their names (those
    # columns of ``data`` are views of them)
    groups: dict[tuple[str, ...], np.ndarray] = field(default_factory=dict)
    # the most decimals a ``t`` cell's text carries over the file's first _STAMP_DECIMAL_LINES
    # data lines and over all of its rows, when the fast parser read the file (see _stamps_ns)
    stamp_decimals: tuple[int, int] | None = None

    @property
    def n(self) -> int:
        """Number of rows."""
        return int(self.lines.shape[0])

    def col(self, name: str) -> np.ndarray:
        """(n,) C-contiguous column ``name``."""
        return np.ascontiguousarray(self.data[name])

    def block(self, names: Sequence[str]) -> np.ndarray:
        """(n, len(names)) array of the columns."""
        return np.column_stack([self.data[c] for c in names])

    def vectors(self, names: Sequence[str], scale: float = 1.0) -> np.ndarray:
        """(n, len(names)) C-contiguous array of the columns times ``scale``: the parser's own
        array when it wrote them as one group, scaled in place (the table's columns with it)."""
        group = self.groups.get(tuple(names))
        if group is not None:
            if scale != 1.0:
                np.multiply(group, scale, out=group)
            return group
        out = np.empty((self.n, len(names)))
        for j, c in enumerate(names):
            np.multiply(self.data[c], scale, out=out[:, j])
        return out

    def take(self, keep: np.ndarray) -> _Table:
        """The rows selected by ``keep`` (a boolean mask or indices)."""
        groups = {names: g[keep] for names, g in self.groups.items()}
        grouped = {name: g[:, j] for names, g in groups.items() for j, name in enumerate(names)}
        return _Table(self.path, {k: grouped[k] if k in grouped else v[keep] for k, v in self.data.items()},
                      self.lines[keep], None if self.stamps_ns is None else self.stamps_ns[keep], groups,
                      self.stamp_decimals)


def _check_options(time_base: str, gyro_units: str, accel_units: str) -> tuple[float, float]:
    if time_base not in TIME_BASES:
        raise ConfigError(f"time base {time_base!r} is not one of {', '.join(map(repr, TIME_BASES))}")
    if gyro_units not in GYRO_UNITS:
        raise ConfigError(f"gyro units {gyro_units!r} are not one of {', '.join(map(repr, GYRO_UNITS))}")
    if accel_units not in ACCEL_UNITS:
        raise ConfigError(
            f"accel units {accel_units!r} are not one of {', '.join(map(repr, ACCEL_UNITS))}"
        )
    return GYRO_UNITS[gyro_units], ACCEL_UNITS[accel_units]


def _cell_decimals(cell: str) -> int:
    """Decimal places a number written as text carries, in any float form: ``1700000000.123``,
    ``+1.700000000123E+09``, ``1.7e9`` (-8: none), with blanks or quotes around it.  0 if the
    cell is not a number (the float parse reports those)."""
    s = cell.strip().strip('"').strip().lstrip("+-")
    mantissa, _, exponent = s.lower().partition("e")
    try:
        shift = int(exponent) if exponent else 0
    except ValueError:
        return 0
    return len(mantissa.partition(".")[2]) - shift


_STAMP_DECIMAL_LINES = 2000
"""Data lines over which :func:`_stamps_ns` takes the most decimals a stamp is written with."""


def _stamp_decimals(path: Path, header: list[str], max_lines: int = _STAMP_DECIMAL_LINES) -> int:
    """Most decimals written in the ``t`` column over the first data lines (any float form)."""
    j = header.index("t")
    d = 0
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        next(f, None)
        for _, line in zip(range(max_lines), f):
            cells = line.split(",")
            if len(cells) > j:
                d = max(d, _cell_decimals(cells[j]))
    return d


def _stamps_ns(table: _Table, header: list[str]) -> np.ndarray:
    """The ``t`` column as exact integer nanoseconds (what the file says, not float64's nearest
    value), whatever the float form (plain, e-notation, ``+`` sign, blanks).

    Fast path: with ``d`` the most decimals written over the first 2000 lines (for e-notation
    the mantissa's decimals minus the exponent), ``round(t 10^d)`` recovers the text exactly
    while ``|t| 10^d < 2^51``, and the residual ``|t 10^d - round(t 10^d)|`` stays within
    float64's error (4 eps |t| 10^d).  A larger residual means a later row carries more
    decimals: then, as when ``|t| 10^d >= 2^51`` (e.g. unix stamps with 7+ decimals), the
    column is converted exactly from its text (half-even at 1 ns; by the fast parser when it
    read the file, ``table.stamps_ns``, else re-read).  A later row whose extra decimals lie
    below float64's resolution of ``t`` is rounded to ``d`` decimals.  When the fast parser read
    the file it counted the decimals itself (``table.stamp_decimals``: no text scan), and when
    no row carries more than ``d`` its exact ns are the fast path's result, taken as they are."""
    t = table.data["t"]
    if table.stamp_decimals is None:
        d = min(_stamp_decimals(table.path, header), 9)
    else:       # the fast parser's count over the same lines
        d = min(max(table.stamp_decimals[0], 0), 9)
    if t.size == 0:
        return np.zeros(0, dtype=np.int64)
    t_max = max(float(np.max(t)), -float(np.min(t)))
    scale = 10.0 ** d
    if (table.stamps_ns is not None and table.stamp_decimals is not None and table.stamp_decimals[1] <= d
            and t_max * scale < 2.0 ** 51):
        # no row carries more than d decimals: each stamp is k / 10^d (|k| < 2^51) and round(t 10^d)
        # is k (errors < 0.5), so the fast path below would give the parser's exact ns
        return table.stamps_ns
    tolerance = 4.0 * np.finfo(np.float64).eps * t_max * scale
    # a block of rows at a time: the residuals first, then the ns (no full-length temporaries)
    if t_max * scale < 2.0 ** 51 and all(
            float(np.max(np.abs(scaled - np.round(scaled)))) <= tolerance
            for scaled in (t[a:b] * scale for a, b in spill.windows(t.shape[0], t))):
        ns = spill.like(t, t.shape[0], (), np.int64)
        for a, b in spill.windows(t.shape[0], t, ns):
            np.multiply(np.round(t[a:b] * scale).astype(np.int64), 10 ** (9 - d), out=ns[a:b])
        return ns
    if table.stamps_ns is not None:     # the exact path's result, from the fast parser
        return table.stamps_ns
    return _stamps_ns_text(table, header)


def _stamps_ns_text(table: _Table, header: list[str]) -> np.ndarray:
    """Slow exact path of :func:`_stamps_ns`: the ``t`` cells of ``table``'s rows as text,
    converted with :class:`decimal.Decimal` (any float form), a chunk at a time."""
    from decimal import Decimal, InvalidOperation

    import pandas as pd

    want = table.lines - 2          # data row index of every kept row, increasing
    out = np.empty(want.shape[0], dtype=np.int64)
    j = header.index("t")
    k = 0
    start = 0
    with open(table.path, "rb") as fh:
        reader = pd.read_csv(fh, engine="c", header=0, usecols=[j], dtype=str, keep_default_na=False,
                             skip_blank_lines=False, encoding="utf-8-sig", chunksize=_CHUNK_ROWS)
        with reader:
            for chunk in reader:
                cells = chunk.iloc[:, 0].to_numpy()
                stop = start + cells.shape[0]
                while k < want.shape[0] and want[k] < stop:
                    cell = cells[want[k] - start]
                    try:
                        out[k] = int(Decimal(cell.strip().strip('"')).scaleb(9).to_integral_value())
                    except (InvalidOperation, ValueError, OverflowError) as e:
                        raise InputError(f"{table.path}: line {table.lines[k]}, column 't': cannot read "
                                         f"{_echo(cell)} as seconds") from e
                    k += 1
                start = stop
    return out


def _echo(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters: a bad cell may be megabytes long."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(str(value)):,} characters)"


def _names(names: Sequence[str], limit: int = 120) -> str:
    """The names quoted, at most ``_MAX_NAMES_SHOWN`` of them and about ``limit`` characters."""
    shown = ", ".join(_echo(n, 30) for n in names[:_MAX_NAMES_SHOWN])
    if len(shown) > limit:
        shown = shown[:limit].rsplit(", ", 1)[0] + ", ..."
    if len(names) > _MAX_NAMES_SHOWN or shown.endswith("..."):
        shown += f" ({len(names)} columns)"
    return shown


def prescan(path: Path) -> None:
    """Refuse a file holding NUL bytes or a line longer than :data:`MAX_LINE_BYTES` before any
    parser sees it (a pre-allocated or crash-truncated log ends in NULs; a parser would hold the
    whole "line" in memory and echo it).  One pass of memchr over 512 KiB blocks; the line number
    is counted only when something is found."""
    buf = bytearray(_SCAN_BLOCK)
    view = memoryview(buf)
    offset = 0          # file offset of buf[0]
    line_start = 0      # file offset where the current line starts
    try:
        with open(path, "rb", buffering=0) as f:
            while True:
                n = f.readinto(buf)
                if not n:
                    return
                block = buf if n == _SCAN_BLOCK else view[:n].tobytes()
                z = block.find(b"\0")
                end = z if z >= 0 else n
                i = block.find(b"\n", 0, end)
                if (i if i >= 0 else end) + offset - line_start > MAX_LINE_BYTES:
                    raise _long_line(path, f, line_start)
                if i >= 0:
                    line_start = offset + block.rfind(b"\n", 0, end) + 1
                if z >= 0:
                    line = _line_number(f, offset + z)
                    raise InputError(
                        f"{path}: line {line}: NUL byte (\\0) at byte {offset + z:,} of "
                        f"{path.stat().st_size:,}: not text from there (pre-allocated or cut short while "
                        "logging?); cut the file before it")
                offset += n
    except OSError as e:
        raise InputError(f"{path}: cannot read: {e.strerror or e}") from e


def _line_number(f: BinaryIO, at: int) -> int:
    """1-based number of the line holding byte ``at`` of the open binary file ``f``."""
    f.seek(0)
    count = 1
    remaining = at
    while remaining > 0:
        block = f.read(min(_SCAN_BLOCK, remaining))
        if not block:
            break
        count += block.count(b"\n")
        remaining -= len(block)
    return count


def _long_line(path: Path, f: BinaryIO, start: int) -> InputError:
    line = _line_number(f, start)
    f.seek(start)
    head = f.read(40).decode("utf-8", errors="replace")
    return InputError(f"{path}: line {line}: longer than {MAX_LINE_BYTES // (1 << 20)} MiB (starts {head!r}...); "
                      "a CSV row is a few hundred bytes")


def _read_header(path: Path) -> list[str]:
    """The header's column names, stripped of surrounding blanks; checks the file is usable
    (:func:`prescan`) and comma separated."""
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    prescan(path)
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            row = next(csv.reader(f), None)
    except UnicodeDecodeError as e:      # decoded a block at a time: the bad byte may be on a later line
        raise _utf8_error(path, e) from e
    except (OSError, csv.Error) as e:
        raise InputError(f"{path}: line 1: cannot read the header: {e}") from e
    if row is None:
        raise InputError(f"{path}: empty file; expected a header row (line 1) and data rows")
    names = [c.strip() for c in row]
    if len(names) == 1:
        for sep, what in ((";", "semicolons (';')"), ("\t", "tabs"), ("|", "bars ('|')")):
            if len(names[0].split(sep)) > 1:
                raise InputError(
                    f"{path}: line 1 (header): columns separated by {what}, not commas ({_echo(names[0], 30)}); "
                    "save it with ',' between columns and '.' as the decimal point")
    if not any(names):
        raise InputError(f"{path}: line 1: empty header; expected column names (a header row is required)")
    seen: set[str] = set()
    for name in names:
        if name and name in seen:
            raise InputError(f"{path}: line 1 (header), column {name!r}: appears more than once")
        seen.add(name)
    return names


def _missing_columns_error(path: Path, missing: Sequence[str], header: list[str], expected: str) -> InputError:
    return InputError(
        f"{path}: line 1 (header): missing required column(s) {_names(missing)}; expected {expected}; "
        f"found {_names(header)}"
    )


def _imu_format(path: Path, header: list[str]) -> tuple[str, list[str]]:
    present = set(header)
    rates = ("t", *_IMU_RATE_COLS)
    increments = ("t", *_IMU_INCREMENT_COLS)
    if all(c in present for c in rates):
        return "rates", list(rates)
    if all(c in present for c in increments):
        return "increments", list(increments)
    n_rates = sum(c in present for c in _IMU_RATE_COLS)
    n_inc = sum(c in present for c in _IMU_INCREMENT_COLS)
    chosen = increments if n_inc > n_rates else rates
    missing = [c for c in chosen if c not in present]
    raise _missing_columns_error(
        path, missing, header, f"{', '.join(rates)} (rates) or {', '.join(increments)} (increments)"
    )


def _select_columns(
    path: Path,
    header: list[str],
    required: Sequence[str],
    groups: Sequence[Sequence[str]],
    singles: Sequence[str],
) -> list[str]:
    present = set(header)
    missing = [c for c in required if c not in present]
    if missing:
        raise _missing_columns_error(path, missing, header, ", ".join(required))
    cols = list(required)
    for group in groups:
        have = [c for c in group if c in present]
        if have and len(have) < len(group):
            lacking = [c for c in group if c not in present]
            raise InputError(
                f"{path}: line 1 (header): missing column(s) {_names(lacking)}: {_names(list(group))} "
                "go together, all or none"
            )
        cols.extend(have)
    cols.extend(c for c in singles if c in present)
    return cols


_CHUNK_ROWS = 65536


def _read_table(path: Path, header: list[str], wanted: list[str], warnings: list[str],
                progress: Callable[[float], None] | None = None, widths: Sequence[int] | None = None,
                memory: int | None = None) -> _Table:
    """Parse ``wanted`` columns as float64 and check every cell is a finite number.

    A plain file goes through the numba kernel of :mod:`navpp.io.csvparse` (same values, no
    pandas), which writes ``wanted`` split in consecutive groups of ``widths`` (default one
    each) into arrays the table keeps (:attr:`_Table.groups`); any other file (or when kernels
    run interpreted) through pandas, whose errors locate the faulty line and cell.  The kernel's
    arrays go to a spill file beyond ``memory`` bytes (None: never; pandas's stay in memory)."""
    # Unnamed columns (trailing commas) are ignored silently: there is nothing to name.
    extra = [name for name in header if name and name not in wanted]
    if extra:
        warnings.append(f"{path.name}: ignoring extra column(s) {_names(extra)}")
    positions = [header.index(c) for c in wanted]
    decimals: list[int] = []
    parsed = None if jitmode.interpreted() else _parse_plain(path, len(header), positions, header.index("t"),
                                                             progress, widths, memory, decimals)
    if parsed is not None:      # the kernel takes only finite numbers and no blank line: nothing to check
        values, stamps_ns = parsed
        names = iter(wanted)
        data: dict[str, np.ndarray] = {}
        groups: dict[tuple[str, ...], np.ndarray] = {}
        for v in values:
            if v.ndim == 1:
                data[next(names)] = v
            else:
                group = tuple(islice(names, v.shape[1]))
                groups[group] = v
                data.update({name: v[:, j] for j, name in enumerate(group)})
        n = values[0].shape[0]
        lines = spill.like(values[0], n, (), np.int64)        # on the spill file with the values
        for a, b in spill.windows(n, lines):
            lines[a:b] = np.arange(a + 2, b + 2, dtype=np.int64)
        return _Table(path, data, lines, stamps_ns, groups, (decimals[0], decimals[1]) if decimals else None)
    block = _parse_with_pandas(path, header, wanted, positions, progress)
    finite = np.isfinite(block)
    n = block.shape[1]
    # Blank lines at the end of the file are harmless: drop them.
    row_empty = cast(np.ndarray, np.isnan(block).all(axis=0))      # (n,) bool, for every (k, n) block
    while n > 0 and row_empty[n - 1]:
        n -= 1
    if n == 0:
        raise InputError(f"{path}: line 1 (header) is not followed by any data row; expected at least one")
    block, finite = block[:, :n], finite[:, :n]
    if not finite.all():
        row, j = _first_true((~finite).T)
        value = block[j, row]
        if row_empty[row]:
            what = "blank line"
        elif np.isnan(value):
            what = "missing value (empty cell or NaN)"
        else:
            what = f"non-finite value {float(value)!r}"
        raise InputError(f"{path}: line {row + 2}, column {wanted[j]!r}: {what}")
    data = {name: block[j] for j, name in enumerate(wanted)}
    return _Table(path, data, np.arange(2, n + 2, dtype=np.int64))


def _parse_plain(path: Path, n_fields: int, positions: list[int], stamp_position: int,
                 progress: Callable[[float], None] | None, widths: Sequence[int] | None,
                 memory: int | None = None,
                 decimals: list[int] | None = None) -> tuple[list[np.ndarray], np.ndarray | None] | None:
    """The float64 columns in groups of ``widths`` and the exact ns of field ``stamp_position``
    (or None) by :func:`navpp.io.csvparse.parse_columns` (spilled beyond ``memory`` bytes; the
    stamps' decimals appended to ``decimals`` as there); None when the file is not plain (then
    :func:`_parse_with_pandas` reads it and names the fault)."""
    from navpp.io.csvparse import parse_columns

    try:
        return parse_columns(path, n_fields, positions, stamp_position, progress, widths, memory, decimals,
                             _STAMP_DECIMAL_LINES)
    except OSError as e:
        raise InputError(f"{path}: cannot read: {e}") from e


def _parse_with_pandas(path: Path, header: list[str], wanted: list[str], positions: list[int],
                       progress: Callable[[float], None] | None) -> np.ndarray:
    """(len(wanted), n) float64 columns parsed by pandas, NaN for empty cells; an InputError
    naming the line (and the cell when one is not a number) for a file pandas cannot read."""
    import pandas as pd

    size = max(path.stat().st_size, 1)
    try:
        # Chunked parsing keeps the peak memory near the size of the data itself (a one-shot
        # read_csv holds several times the table in parser buffers).
        with open(path, "rb") as fh:
            reader = pd.read_csv(
                fh,
                engine="c",
                header=0,
                dtype={i: np.float64 for i in positions},
                skip_blank_lines=False,
                encoding="utf-8-sig",
                chunksize=_CHUNK_ROWS,
            )
            parts: list[np.ndarray] = []
            with reader:
                for chunk in reader:
                    parts.append(chunk.iloc[:, positions].to_numpy(dtype=np.float64))
                    if progress is not None:
                        progress(min(fh.tell() / size, 1.0))
    except pd.errors.ParserError as e:
        raise InputError(f"{path}: {_parser_message(e, len(header))}") from e
    except UnicodeDecodeError as e:       # a ValueError too: catch it first
        raise _utf8_error(path, e) from e
    except ValueError as e:
        raise _locate_non_numeric(path, wanted, positions, e) from e
    except OSError as e:
        raise InputError(f"{path}: cannot read: {e}") from e
    # assemble chunk by chunk, releasing each one: the peak is the table plus one chunk
    block = np.empty((len(wanted), sum(p.shape[0] for p in parts)))
    row = 0
    parts.reverse()
    while parts:
        part = parts.pop()
        block[:, row:row + part.shape[0]] = part.T
        row += part.shape[0]
        del part
    return block


def _first_true(mask: np.ndarray) -> tuple[int, int]:
    """(row, column) of the first True in row-major order (the first offending line)."""
    flat = int(np.argmax(mask.ravel()))
    return divmod(flat, mask.shape[1])


def _parser_message(e: Exception, n_header: int) -> str:
    m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(e))
    if m:
        return f"line {m.group(2)}: {m.group(3)} fields, but the header (line 1) has {n_header} columns"
    m = re.search(r"EOF inside string starting at row (\d+)", str(e))
    if m:      # the parser counts rows from 0 at the header
        return f"line {int(m.group(1)) + 1}: a quote (\") opens a field that is never closed"
    return f"cannot parse as CSV: {str(e).strip().splitlines()[-1]}"


def _utf8_error(path: Path, cause: UnicodeDecodeError) -> InputError:
    """The first line of ``path`` that is not valid UTF-8, as an InputError naming it."""
    try:
        with open(path, "rb") as f:
            for number, line in enumerate(f, start=1):
                try:
                    line.decode("utf-8")
                except UnicodeDecodeError as e:
                    return InputError(f"{path}: line {number}: not a UTF-8 text file ({e.reason} at byte {e.start} "
                                      "of the line)")
    except OSError as e:
        return InputError(f"{path}: cannot read: {e.strerror or e}")
    return InputError(f"{path}: not a UTF-8 text file ({cause.reason})")


def _locate_non_numeric(path: Path, wanted: list[str], positions: list[int], cause: Exception) -> InputError:
    """Slow path, only after the fast parse failed: find the first cell that is not a number
    (read as text a chunk at a time, so memory stays bounded)."""
    # usecols returns columns in file order; map back to names by position.
    import pandas as pd

    by_position = dict(zip(positions, wanted))
    start = 0
    try:
        with open(path, "rb") as fh:
            reader = pd.read_csv(fh, engine="c", header=0, usecols=positions, dtype=object,
                                 skip_blank_lines=False, encoding="utf-8-sig", chunksize=_CHUNK_ROWS)
            with reader:
                for raw in reader:
                    best: tuple[int, str, object] | None = None
                    for k, pos in enumerate(sorted(positions)):
                        s = raw.iloc[:, k]
                        bad = pd.to_numeric(s, errors="coerce").isna().to_numpy() & s.notna().to_numpy()
                        if bad.any():
                            row = int(np.argmax(bad))
                            if best is None or row < best[0]:
                                best = (row, by_position[pos], s.iloc[row])
                    if best is not None:
                        row, name, value = best
                        return InputError(f"{path}: line {start + row + 2}, column {name!r}: non-numeric value "
                                          f"{_echo(value)}")
                    start += raw.shape[0]
    except Exception:  # noqa: BLE001 - fall back to the fast parser's own message
        pass
    return InputError(f"{path}: non-numeric value: {_echo(str(cause))}")


def _check_lat_lon(table: _Table) -> None:
    _check_range(table, "lat", -90.0, 90.0, "[-90, 90] deg", upper_open=False)
    _check_range(table, "lon", -180.0, 360.0, "[-180, 360) deg", upper_open=True)


def _check_range(table: _Table, name: str, lo: float, hi: float, text: str, *, upper_open: bool) -> None:
    v = table.data[name]
    bad = (v < lo) | ((v >= hi) if upper_open else (v > hi))
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(
            f"{table.path}: line {table.lines[k]}, column {name!r}: {float(v[k])!r} is outside {text}"
        )


def _check_positive(table: _Table, names: Sequence[str], default: str = "[gnss] default_std_m") -> None:
    """Standard deviations must be > 0: a zero claims a perfect fix and breaks the filter.
    ``default`` names what is used when the column is left out."""
    names = [c for c in names if c in table.data]
    if not names:
        return
    bad = np.column_stack([table.data[c] <= 0 for c in names])
    if bad.any():
        row, j = _first_true(bad)
        value = float(table.data[names[j]][row])
        what = "negative" if value < 0 else "zero"
        raise InputError(
            f"{table.path}: line {table.lines[row]}, column {names[j]!r}: {what} standard deviation "
            f"{value!r}; it must be > 0 (leave the column out to use {default})"
        )


def _drop_invalid_fixes(table: _Table, warnings: list[str]) -> _Table:
    """Drop fixes flagged invalid (``fix`` = 0, the NMEA GGA 'no fix' quality) and fixes at
    exactly lat = lon = 0 (a receiver's placeholder for 'no position'), with a count."""
    bad = (table.data["lat"] == 0.0) & (table.data["lon"] == 0.0)
    n_null = int(np.count_nonzero(bad))
    n_nofix = 0
    if "fix" in table.data:
        nofix = table.data["fix"] == 0
        n_nofix = int(np.count_nonzero(nofix & ~bad))
        bad |= nofix
    if not bad.any():
        return table
    first = int(table.lines[int(np.argmax(bad))])
    parts = []
    if n_nofix:
        parts.append(f"{n_nofix} fix{'es' if n_nofix > 1 else ''} with fix = 0 (no fix)")
    if n_null:
        parts.append(f"{n_null} fix{'es' if n_null > 1 else ''} at lat = lon = 0")
    warnings.append(f"{table.path.name}: dropped {' and '.join(parts)} (first at line {first})")
    kept = table.take(~bad)
    if kept.n == 0:
        raise InputError(f"{table.path}: no valid fix: every row has fix = 0 or lat = lon = 0")
    return kept


def _check_rate(table: _Table, t: np.ndarray, what: str, low: float, high: float) -> float:
    """A median sample interval far outside ``[1/high, 1/low]`` s means ``t`` is not in seconds.
    Returns that median (s; NaN for fewer than 2 stamps)."""
    if t.shape[0] < 2:
        return float("nan")
    dt = float(np.median(np.diff(t), overwrite_input=True))
    if dt <= 0:
        return dt
    rate = 1.0 / dt
    if low <= rate <= high:
        return dt
    hint = ""
    for factor, unit in ((1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds")):
        if low <= rate * factor <= high:
            hint = f"; are the stamps in {unit}? t must be in seconds"
            break
    raise InputError(
        f"{table.path}: column 't': median sample interval {dt:.6g} s ({rate:.6g} Hz) is not plausible for "
        f"{what} ({low:g}..{high:g} Hz){hint}"
    )


def _check_integral(table: _Table, names: Sequence[str]) -> None:
    for name in names:
        if name in table.data:
            v = table.data[name]
            bad = v != np.round(v)
            if bad.any():
                k = int(np.argmax(bad))
                raise InputError(
                    f"{table.path}: line {table.lines[k]}, column {name!r}: {float(v[k])!r} is not an integer"
                )


def _with_ns(table: _Table, header: list[str]) -> _Table:
    """``table`` with its stamps as exact integer ns in ``data["t_ns"]`` (see :func:`_stamps_ns`)."""
    return replace(table, data={**table.data, "t_ns": _stamps_ns(table, header)}, stamps_ns=None)


def _check_lone_stamp(table: _Table) -> None:
    """One row whose stamp is far from its regular neighbours (:func:`navpp.recording.lone_stamp`:
    a clock not yet set, t = 0 before unix time): an error naming the row.  Not dropped: the
    row's values may be as wrong as its stamp, and deleting one line is the user's call."""
    t = table.data["t"]
    hit = lone_stamp(t, reorder_s=0.0)
    if hit is None:
        return
    k, dist = hit
    j = k + 1 if k + 1 < t.shape[0] else k - 1
    raise InputError(
        f"{table.path}: line {table.lines[k]}, column 't': t={float(t[k])!r} lies {dist:.4g} s from its "
        f"neighbours (line {table.lines[j]}: t={float(t[j])!r}) while the rows around it are regular: a lone bad "
        "stamp (a clock not yet set?); delete or correct that row"
    )


def _check_time(table: _Table, warnings: list[str]) -> _Table:
    """Stamps must not decrease; equal consecutive stamps: the later row is dropped (warned).

    Compares the exact ns stamps (``data["t_ns"]``, see :func:`_with_ns`) when present, the float
    seconds otherwise.  A dropped row that repeats the row before it in every column is named an
    exact duplicate row (a logger writing a row twice), not a coarse stamp."""
    t = table.data["t"]
    stamps = table.data.get("t_ns", t)
    dt = np.diff(stamps)
    back = dt < 0
    if back.any():
        k = int(np.argmax(back)) + 1
        raise InputError(
            f"{table.path}: line {table.lines[k]}, column 't': time goes backwards, t={float(t[k])!r} "
            f"after t={float(t[k - 1])!r} on line {table.lines[k - 1]}"
        )
    dup = dt == 0
    if not dup.any():
        return table
    same = dup.copy()
    for name, v in table.data.items():
        if name not in ("t", "t_ns"):
            same &= v[1:] == v[:-1]
    n_dup = int(np.count_nonzero(dup))
    n_same = int(np.count_nonzero(same))
    n_other = n_dup - n_same
    first_line = int(table.lines[int(np.argmax(dup)) + 1])
    text = (f"{table.path.name}: dropped {n_dup} duplicate timestamp{'s' if n_dup > 1 else ''} "
            f"(first at line {first_line})")
    if n_same:
        k = int(np.argmax(same)) + 1
        which = "all are" if n_same == n_dup else f"{n_same} are"
        text += (f"; {which} exact duplicate rows, the same in every column as the row before "
                 f"(e.g. line {table.lines[k]} = line {table.lines[k - 1]})")
    if n_other >= 10 and n_other > 0.01 * t.shape[0]:
        pos = dt[dt > 0]
        step = float(np.min(pos)) * (1e-9 if "t_ns" in table.data else 1.0) if pos.size else 0.0
        text += (f"; {'that many' if not n_same else f'{n_other} with other values:'} repeats mean the stamps are "
                 f"too coarse (steps of {step:.3g} s): write t with more decimals")
    warnings.append(text)
    keep = np.concatenate(([True], ~dup))
    return table.take(keep)


def _gap_warning(file_name: str, t: np.ndarray, lines: np.ndarray, warnings: list[str],
                 nominal: float | None = None) -> None:
    """Warn about intervals longer than ``GAP_FACTOR`` times the median interval (``nominal``
    when the caller has it already: that of ``t``)."""
    if t.shape[0] < 3:
        return
    dt = np.diff(t)
    if nominal is None:
        nominal = float(np.median(dt))
    gaps = dt > GAP_FACTOR * nominal
    if not gaps.any():
        return
    k = int(np.argmax(np.where(gaps, dt, -np.inf)))
    n_gaps = int(np.count_nonzero(gaps))
    warnings.append(
        f"{file_name}: {n_gaps} gap{'s' if n_gaps > 1 else ''} longer than {GAP_FACTOR} x the nominal "
        f"interval {nominal:.4g} s ({1.0 / nominal:.4g} Hz); largest {float(dt[k]):.4g} s from "
        f"t={float(t[k])!r} (line {lines[k]}) to t={float(t[k + 1])!r} (line {lines[k + 1]})"
    )


def _need_more(table: _Table, need: str) -> InputError:
    lines = table.lines
    where = f"line {lines[0]}" if table.n == 1 else f"lines {lines[0]}..{lines[-1]}"
    return InputError(
        f"{table.path}: column 't': {table.n} distinct timestamp{'s' if table.n != 1 else ''} ({where}); "
        f"{need}"
    )
