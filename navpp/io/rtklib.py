"""RTKLIB solution files (``.pos``, as written by rtkpost / rnx2rtkp / rtknavi).

Format (RTKLIB ``outsolheads`` / ``outsols``)
---------------------------------------------
Header lines start with ``%``.  The last of them is the column header, e.g.::

    %  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio

Its first word is the time system of the data lines: ``GPST``, ``UTC`` or ``JST`` (UTC+9 h).
It is read from there and never guessed: a file without it raises ``InputError`` (or pass
``time_system=``).  Data lines hold, separated by spaces (or RTKLIB's configured separator):

- time: ``yyyy/mm/dd hh:mm:ss.sss`` (any number of decimals) or ``week tow`` (GPS week and
  seconds of week; with ``UTC``/``JST`` RTKLIB counts weeks of that scale from 1980-01-06).
- position: ``latitude(deg) longitude(deg) height(m)``; or ``latitude(d'")`` /
  ``longitude(d'")`` as three fields each (degrees, minutes, seconds; the sign is on the
  degrees field, ``-0`` included); or ``x-ecef(m) y-ecef(m) z-ecef(m)`` (converted with
  :func:`navpp.geodesy.ecef_to_geodetic`).  ``e/n/u-baseline`` output is refused (no absolute
  position), as are geoid ("geodetic") heights and the Tokyo datum.
- ``Q`` (1 fix, 2 float, 3 sbas, 4 dgps, 5 single, 6 ppp; RTKLIB demo5 adds 7 dead
  reckoning), ``ns`` (satellites), ``sdn sde sdu sdne sdeu sdun`` (m; for xyz output
  ``sdx sdy sdz sdxy sdyz sdzx``; RTKLIB writes the cross terms as sign(c) * sqrt(|c|)),
  ``age(s) ratio`` (ignored), and with "output velocity" on ``vn ve vu sdvn sdve sdvu sdvne
  sdveu sdvun`` (``vx vy vz sdvx ...`` for xyz).

Mapping to :class:`~navpp.recording.GnssData`
---------------------------------------------
- ``fix`` = RTKLIB's ``Q`` value as it is (see ``Q_NAMES``); epochs with ``Q = 0`` (no
  solution) are dropped with a warning.  ``num_sats`` = ``ns``.
- ``std_enu`` = (sde, sdn, sdu): note RTKLIB's column order is north, east, up.  For xyz files
  the full ECEF covariance is rotated to ENU.
- ``vel_enu`` = (ve, vn, vu) and ``std_vel_enu`` = (sdve, sdvn, sdvu) when present (rotated from
  ECEF for xyz files).
- time: converted from the file's time system to ``time_base`` (``"unix"`` or ``"gpst"``, see
  :mod:`navpp.timebase`) exactly in integer nanoseconds with the leap-second table; ``t`` is
  float seconds relative to ``t0_ns`` (given, or the first epoch's stamp, returned).
"""  # noqa: E501  (RTKLIB's column header above, quoted as rtkpost writes it)

from __future__ import annotations

import datetime as _dt
import io
from pathlib import Path

import numpy as np
import pandas as pd

from navpp import timebase
from navpp.errors import ConfigError, InputError
from navpp.geodesy import ecef_to_geodetic, mat_enu_from_ecef
from navpp.recording import GnssData

__all__ = ["Q_NAMES", "TIME_SYSTEMS", "read_pos"]

Q_NAMES = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp", 7: "dr"}
"""RTKLIB solution quality flag ``Q`` -> name (7 = dead reckoning, RTKLIB demo5 only)."""

TIME_SYSTEMS = ("GPST", "UTC", "JST")

_NS = timebase.NS
_JST_OFFSET_NS = 9 * 3600 * _NS
_WEEK_NS = timebase.SECONDS_PER_WEEK * _NS
_GPS_EPOCH_NS = timebase.GPS_EPOCH_UNIX * _NS
#: The last GPS week whose times (with a day to spare for time-system shifts) fit int64 ns.
_MAX_WEEK = (np.iinfo(np.int64).max - _GPS_EPOCH_NS) // _WEEK_NS - 1

# Column names that make a '%' line the column header, and the position format they imply.
_POS_FORMATS = {
    "latitude(deg)": "llh",
    "latitude(d'\")": "dms",
    "x-ecef(m)": "xyz",
    "e-baseline(m)": "enu",
}
_DMS_NAMES = ("latitude(d'\")", "longitude(d'\")")
_REQUIRED = {
    "llh": ("latitude(deg)", "longitude(deg)", "height(m)"),
    "dms": ("latitude(d'\")", "longitude(d'\")", "height(m)"),
    "xyz": ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)"),
}
_STD_NAMES = {
    "llh": ("sdn(m)", "sde(m)", "sdu(m)"),
    "dms": ("sdn(m)", "sde(m)", "sdu(m)"),
    "xyz": ("sdx(m)", "sdy(m)", "sdz(m)", "sdxy(m)", "sdyz(m)", "sdzx(m)"),
}
_VEL_NAMES = {
    "llh": ("vn(m/s)", "ve(m/s)", "vu(m/s)"),
    "dms": ("vn(m/s)", "ve(m/s)", "vu(m/s)"),
    "xyz": ("vx(m/s)", "vy(m/s)", "vz(m/s)"),
}
_VEL_STD_NAMES = {
    "llh": ("sdvn", "sdve", "sdvu"),
    "dms": ("sdvn", "sdve", "sdvu"),
    "xyz": ("sdvx", "sdvy", "sdvz", "sdvxy", "sdvyz", "sdvzx"),
}
_MAX_LINES_SHOWN = 5
_FAST_PATH = True
"""Parse with pandas' C reader first; the line-by-line parser runs when that fails (to name the
bad line).  Tests switch it off to check both give the same result."""


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def read_pos(
    path: str | Path,
    *,
    time_base: str = "unix",
    t0_ns: int | None = None,
    time_system: str | None = None,
) -> tuple[GnssData, list[str], int]:
    """Read an RTKLIB solution file into ``GnssData`` on ``time_base``.

    Parameters
    ----------
    path : the ``.pos`` file.
    time_base : ``"unix"`` (UTC seconds since 1970) or ``"gpst"`` (GPS time as seconds since
        1970 on the GPS scale, = unix + GPS-UTC; see :mod:`navpp.timebase`): the base of the
        log this GNSS will be fused with.  ``"relative"`` cannot hold absolute times.
    t0_ns : integer ns on ``time_base`` that the returned ``t`` is relative to (normally the
        recording's ``t0_ns``); default: the first epoch of this file.
    time_system : ``"GPST"``, ``"UTC"`` or ``"JST"``, only for files whose column header does
        not name it; when the header names one, a different value here is an error.

    Returns
    -------
    gnss : ``GnssData`` (``fix`` = RTKLIB ``Q``, ``num_sats`` = ``ns``, ``std_enu`` from
        sde/sdn/sdu, velocities when the file has them).
    warnings : readable lines about what was accepted but worth knowing (dropped epochs, ...).
    t0_ns : the origin used for ``gnss.t`` (int ns on ``time_base``).

    Raises
    ------
    InputError
        Unreadable file, no column header / time system, unsupported format, or a bad data
        line (the message names the file and the line number).
    ConfigError
        ``time_base`` is not ``"unix"`` or ``"gpst"``.
    """
    path = Path(path)
    name = path.name
    _check_time_base(name, time_base)
    lines = _read_lines(path)
    warnings: list[str] = []
    layout = _parse_header(name, lines, time_system, warnings)
    data = _data_lines(lines, layout)
    if not data:
        raise InputError(f"{name}: no solution lines after the header (an empty RTKLIB solution)")
    parsed = _parse_fast(data, layout) if _FAST_PATH else None
    if parsed is None:  # the line-by-line parser finds and names the bad line
        parsed = _parse_slow(name, data, layout)
    linenos, t_src, numeric = parsed
    abs_ns, numeric, linenos, q, ns = _usable_epochs(name, linenos, t_src, numeric, layout, time_base, warnings)
    lat, lon, h, std_enu, vel_enu, std_vel = _positions(name, numeric, layout, linenos)
    _late_and_zero_std_warnings(name, abs_ns, time_base, std_enu, warnings)

    t0 = int(abs_ns[0]) if t0_ns is None else int(t0_ns)
    whole, frac = np.divmod(abs_ns - np.int64(t0), _NS)
    t_rel = whole.astype(np.float64) + frac.astype(np.float64) / 1e9
    gnss = GnssData(
        t=t_rel,
        lat_deg=lat,
        lon_deg=lon,
        alt=h,
        std_enu=std_enu,
        vel_enu=vel_enu,
        std_vel_enu=std_vel,
        fix=q,
        num_sats=ns,
    )
    return gnss, warnings, t0


def _check_time_base(name: str, time_base: str) -> None:
    """:class:`ConfigError` unless ``time_base`` can hold RTKLIB's absolute times."""
    if time_base not in ("unix", "gpst"):
        if time_base == "relative":
            raise ConfigError(
                f"{name}: RTKLIB times are absolute (GPST/UTC) and cannot be aligned with a log on "
                "[time] base = \"relative\"; set base to \"unix\" or \"gpst\""
            )
        raise ConfigError(f"time base {time_base!r} is not one of 'unix', 'gpst' for {name}")


def _usable_epochs(name: str, linenos: np.ndarray, t_src: np.ndarray, numeric: np.ndarray, layout: dict,
                   time_base: str, warnings: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                              np.ndarray | None, np.ndarray | None]:
    """The epochs kept: not ``Q = 0``, in strictly increasing time, not inside a leap second.

    Returns their times (int64 ns on ``time_base``), numeric columns, line numbers, ``Q`` and
    ``ns`` (None when the file has no such column); each dropped kind is a warning.
    """
    cols = layout["numeric_index"]
    keep = np.ones(len(linenos), dtype=bool)
    q = None
    if "Q" in cols:
        q = _integers(name, numeric[:, cols["Q"]], linenos, "Q")
        no_sol = q == 0
        if no_sol.any():
            keep &= ~no_sol
            warnings.append(f"{name}: {_epochs(int(no_sol.sum()))} with Q = 0 (no solution) dropped"
                            f"{_lines_note(linenos[no_sol])}")
    ns = _integers(name, numeric[:, cols["ns"]], linenos, "ns") if "ns" in cols else None

    keep &= _order_times(name, t_src, linenos, layout["time_system"], keep, warnings)
    abs_ns, keep = _to_base(name, t_src, linenos, layout["time_system"], time_base, keep, warnings)

    idx = np.flatnonzero(keep)
    if idx.size == 0:
        raise InputError(f"{name}: no usable solution epochs: every epoch has Q = 0 (no "
                         "solution), repeats a time or falls inside a leap second")
    return (abs_ns[idx], numeric[idx], linenos[idx], None if q is None else q[idx],
            None if ns is None else ns[idx])


def _late_and_zero_std_warnings(name: str, abs_ns: np.ndarray, time_base: str, std_enu: np.ndarray | None,
                                warnings: list[str]) -> None:
    """Warn about epochs after the leap-second table's end and about zero standard deviations."""
    last_unix_s = (abs_ns[-1] if time_base == "unix"
                   else int(timebase.convert_ns(abs_ns[-1:], "gpst", "unix")[0])) // _NS
    if last_unix_s >= timebase.LEAP_TABLE_VALID_UNTIL_UNIX:
        until = _dt.datetime.fromtimestamp(timebase.LEAP_TABLE_VALID_UNTIL_UNIX, _dt.UTC).date()
        warnings.append(
            f"{name}: epochs after {until}, the date up to which navpp's leap-second table is known "
            "complete; if IERS has announced a leap second since, update navpp.timebase"
        )
    if std_enu is not None and np.any(std_enu <= 0.0):
        n_bad = int(np.any(std_enu <= 0.0, axis=1).sum())
        warnings.append(f"{name}: {_epochs(n_bad)} with a zero standard deviation in sdn/sde/sdu")


# --------------------------------------------------------------------------------------------
# header
# --------------------------------------------------------------------------------------------


def _read_lines(path: Path) -> list[str]:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: RTKLIB solution file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected an RTKLIB .pos file") from None
    except OSError as e:
        raise InputError(f"{path}: cannot be read ({e.strerror or e})") from None
    if not data.strip():
        raise InputError(f"{path.name}: empty file, expected an RTKLIB solution (.pos)")
    if b"\x00" in data[:4096]:
        raise InputError(f"{path.name}: binary data, not an RTKLIB solution text file (.pos)")
    text = data.decode("utf-8", errors="replace")
    return [ln.rstrip("\r") for ln in text.split("\n")]


def _parse_header(name: str, lines: list[str], time_system: str | None,
                  warnings: list[str]) -> dict:
    """The layout the column header describes: ``time_system``, ``pos_format`` (llh, dms, xyz),
    ``sep`` (RTKLIB's field separator, None for blanks), ``n_fields`` per data line,
    ``numeric_index`` (column name -> numeric column), ``numeric_fields`` (numeric column -> first
    field of the line) and ``header_lineno``."""
    col_line, col_lineno, legend = _header_lines(name, lines)
    pos_format, sep = _position_format(name, col_line, col_lineno, legend, warnings)
    body = col_line[1:]
    if sep is not None:
        body = body.replace(sep, " ")
    names = body.split()
    if names and names[0] in _POS_FORMATS:  # no time label at all
        names = ["<time>"] + names
    header_ts = _time_system(name, names[0], col_lineno, time_system)

    # Map column names to data-field positions (time = 2 fields, d'" = 3 fields).
    field = 2
    numeric_index: dict[str, int] = {}
    numeric_fields: list[int] = []
    for nm in names[1:]:
        width = 3 if nm in _DMS_NAMES else 1
        if nm in numeric_index:
            raise InputError(f"{name}: line {col_lineno}: column {nm!r} appears twice")
        numeric_index[nm] = len(numeric_fields)
        numeric_fields.append(field)
        field += width
    for need in _REQUIRED[pos_format]:
        if need not in numeric_index:
            raise InputError(f"{name}: line {col_lineno}: column header lacks {need!r}")
    return {
        "time_system": header_ts,
        "pos_format": pos_format,
        "sep": sep,
        "n_fields": field,
        "numeric_index": numeric_index,
        "numeric_fields": numeric_fields,
        "header_lineno": col_lineno,
    }


def _header_lines(name: str, lines: list[str]) -> tuple[str, int, str | None]:
    """The column header line (stripped) and its line number, and the legend line saying the
    position format (``lat/lon/height=...``) or None, from the ``%`` lines before the data."""
    col_line = None
    col_lineno = 0
    legend = None
    first_data = None
    for i, ln in enumerate(lines, start=1):
        s = ln.strip()
        if not s:
            continue
        if not s.startswith("%"):
            first_data = (i, s)
            break
        if any(k in s for k in _POS_FORMATS):
            col_line, col_lineno = s, i
        elif "lat/lon/height=" in s or "x/y/z-ecef=" in s or "e/n/u-baseline=" in s:
            legend = s
    if first_data is not None and first_data[1].startswith("$"):
        raise InputError(f"{name}: line {first_data[0]} is an NMEA / solution-status record; navpp "
                         "reads RTKLIB's lat/lon/height or x/y/z-ecef solution format")
    if col_line is None:
        raise InputError(
            f"{name}: no RTKLIB column header line (e.g. '%  GPST  latitude(deg) longitude(deg) "
            "height(m)  Q  ns  sdn(m) ...') before the data, so the time system (GPST or UTC) and "
            "the columns are unknown; re-export with RTKLIB or add that line"
        )
    return col_line, col_lineno, legend


def _position_format(name: str, col_line: str, col_lineno: int, legend: str | None,
                     warnings: list[str]) -> tuple[str, str | None]:
    """The position format the column header names (``llh``, ``dms`` or ``xyz``; baselines, geoid
    heights and the Tokyo datum refused) and RTKLIB's field separator (None: blanks)."""
    sep = None
    pos_format = ""
    for key, fmt in _POS_FORMATS.items():
        p = col_line.find(key)
        if p >= 0:
            pos_format = fmt
            nxt = col_line[p + len(key): p + len(key) + 1]
            if nxt and not nxt.isspace():
                sep = nxt
            break
    if pos_format == "enu":
        raise InputError(f"{name}: line {col_lineno}: e/n/u-baseline solutions carry no absolute "
                         "position; re-export with RTKLIB as lat/lon/height or x/y/z-ecef")
    if legend is not None:
        if "geodetic" in legend:
            raise InputError(f"{name}: heights are geodetic (above the geoid); navpp needs "
                             "ellipsoidal heights: re-export with RTKLIB output height = ellipsoidal")
        if "Tokyo" in legend:
            raise InputError(f"{name}: positions are on the Tokyo datum; navpp needs WGS84: "
                             "re-export with RTKLIB output datum = WGS84")
    elif pos_format != "xyz":
        warnings.append(f"{name}: the header does not say the height type; read as ellipsoidal "
                        "(RTKLIB's default)")
    return pos_format, sep


def _time_system(name: str, label: str, col_lineno: int, time_system: str | None) -> str:
    """The data lines' time system: the column header's first word (``label``), or
    ``time_system`` when the header names none; the two must agree when both are given."""
    header_ts = label.upper() if label.upper() in TIME_SYSTEMS else None
    if time_system is None:
        if header_ts is None:
            raise InputError(
                f"{name}: line {col_lineno}: the column header does not name the time system "
                "(it should start '%  GPST' or '%  UTC'); add it so GPS time and UTC are not confused"
            )
        return header_ts
    ts = time_system.upper()
    if ts not in TIME_SYSTEMS:
        raise ConfigError(f"time system {time_system!r} is not one of {', '.join(TIME_SYSTEMS)}")
    if header_ts is not None and ts != header_ts:
        raise InputError(f"{name}: line {col_lineno}: the header says {header_ts} but "
                         f"{ts} was requested")
    return ts


def _data_lines(lines: list[str], layout: dict) -> list[tuple[int, str]]:
    """(line number, stripped text with RTKLIB's separator turned into spaces) of data lines."""
    sep = layout["sep"]
    out = []
    for i, ln in enumerate(lines, start=1):
        s = ln.strip()
        if not s or s[0] == "%":
            continue
        out.append((i, s.replace(sep, " ") if sep is not None else s))
    return out


def _parse_fast(data: list[tuple[int, str]], layout: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Vectorised parse with pandas' C reader; None when anything is off (the slow path reports)."""
    n = layout["n_fields"]
    try:
        df = pd.read_csv(io.StringIO("\n".join(s for _, s in data)), sep=r"\s+", header=None,
                         dtype={0: str, 1: str, **dict.fromkeys(range(2, n), np.float64)},
                         engine="c", na_filter=True, keep_default_na=False,
                         na_values=[""], comment=None)
    except Exception:  # noqa: BLE001 - any reader failure: let the slow path name the line
        return None
    if df.shape != (len(data), n) or df.isna().to_numpy().any():
        return None
    vals = df.iloc[:, 2:]
    if not all(dt.kind == "f" or dt.kind in "iu" for dt in vals.dtypes):
        return None
    raw = vals.to_numpy(dtype=np.float64)
    if not np.all(np.isfinite(raw)):
        return None
    d0, d1 = df[0], df[1]
    calendar = d0.str.contains("/", regex=False)
    if calendar.all():
        stamps = d0 + " " + d1
        ts = None
        for fmt in ("%Y/%m/%d %H:%M:%S.%f", "%Y/%m/%d %H:%M:%S"):
            try:
                ts = pd.to_datetime(stamps, format=fmt, exact=True)
                break
            except (ValueError, TypeError):
                continue
        if ts is None or not d0.str.fullmatch(r"\d{4}/\d{2}/\d{2}").all():
            return None
        frac = d1.str.partition(".")[2]
        if (frac.str.len() > 9).any():
            return None
        t = ts.dt.as_unit("ns").to_numpy().astype("datetime64[ns]").view(np.int64)
    elif not calendar.any():
        if not d0.str.fullmatch(r"\d+").all() or not d1.str.fullmatch(r"\d+(\.\d{0,9})?").all():
            return None
        if (d0.str.len() > 6).any():       # beyond int64 ns: the slow path names the line
            return None
        week = d0.astype(np.int64).to_numpy()
        tow_s = d1.astype(np.float64).to_numpy()
        if np.any(tow_s > _WEEK_NS / _NS) or np.any(week > _MAX_WEEK):     # before the int cast can overflow
            return None
        tow = np.round(tow_s * _NS).astype(np.int64)
        if np.any(tow > _WEEK_NS):
            return None
        t = _GPS_EPOCH_NS + week * _WEEK_NS + tow
    else:
        return None
    linenos = np.fromiter((i for i, _ in data), dtype=np.int64, count=len(data))
    return linenos, t, _collapse(raw, layout)


def _parse_slow(name: str, data: list[tuple[int, str]], layout: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = layout["n_fields"]
    rows = []
    for i, s in data:
        toks = s.split()
        if len(toks) != n:
            raise InputError(f"{name}: line {i}: {len(toks)} fields, expected {n} as the column "
                             f"header (line {layout['header_lineno']}) says: {s[:80]!r}")
        rows.append((i, toks))
    linenos = np.array([i for i, _ in rows], dtype=np.int64)
    return linenos, _parse_times(name, rows), _parse_numeric(name, rows, layout)


def _decimal_ns(s: str) -> int:
    """Non-negative decimal seconds string -> int ns, exact (rounded half up past 9 decimals)."""
    ip, dot, fp = s.partition(".")
    if not (ip.isdigit() or (ip == "" and fp)) or (dot and fp and not fp.isdigit()):
        raise ValueError(s)
    if not ip.isascii() or not fp.isascii():
        raise ValueError(s)
    ns = int(ip or "0") * _NS
    if fp:
        ns += int((fp + "000000000")[:9])
        if len(fp) > 9 and fp[9] >= "5":
            ns += 1
    return ns


def _parse_times(name: str, rows: list[tuple[int, list[str]]]) -> np.ndarray:
    """Data-line times -> int64 ns since 1970-01-01 00:00:00 *of the file's own time scale*."""
    out = np.empty(len(rows), dtype=np.int64)
    days: dict[str, int] = {}
    epoch = _dt.date(1970, 1, 1)
    for k, (lineno, toks) in enumerate(rows):
        d, tod = toks[0], toks[1]
        try:
            if "/" in d:
                day = days.get(d)
                if day is None:
                    y, m, dd = d.split("/")
                    if not (y.isdigit() and m.isdigit() and dd.isdigit()):
                        raise ValueError(d)
                    yi = int(y)
                    if len(y) <= 2:
                        yi += 2000 if yi < 80 else 1900
                    day = (_dt.date(yi, int(m), int(dd)) - epoch).days
                    days[d] = day
                hh, mm, ss = tod.split(":")
                if not (hh.isdigit() and mm.isdigit()) or int(hh) > 23 or int(mm) > 59:
                    raise ValueError(tod)
                sec = _decimal_ns(ss)
                if sec >= 61 * _NS:
                    raise ValueError(tod)
                out[k] = day * 86400 * _NS + (int(hh) * 3600 + int(mm) * 60) * _NS + sec
            else:
                if not d.isdigit():
                    raise ValueError(d)
                tow = _decimal_ns(tod)
                if tow > _WEEK_NS:
                    raise ValueError(tod)
                if int(d) > _MAX_WEEK:
                    raise OverflowError(d)
                out[k] = _GPS_EPOCH_NS + int(d) * _WEEK_NS + tow
        except ValueError:
            raise InputError(
                f"{name}: line {lineno}: bad time {d + ' ' + tod!r}, expected "
                "'yyyy/mm/dd hh:mm:ss.sss' or 'week tow'"
            ) from None
        except OverflowError:      # a year or GPS week beyond what int64 ns can hold
            raise InputError(
                f"{name}: line {lineno}: time {d + ' ' + tod!r} is out of range (after the year 2262)"
            ) from None
    return out


def _parse_numeric(name: str, rows: list[tuple[int, list[str]]], layout: dict) -> np.ndarray:
    try:
        raw = np.array([toks[2:] for _, toks in rows], dtype=np.float64)
    except ValueError:
        raw = None
    if raw is None or not np.all(np.isfinite(raw)):
        fields = layout["numeric_fields"]
        names = list(layout["numeric_index"])
        dms = _dms_columns(layout)
        for lineno, toks in rows:
            for f, tok in enumerate(toks[2:], start=2):
                try:
                    ok = np.isfinite(float(tok))
                except ValueError:
                    ok = False
                if not ok:
                    col = _column_of(f, fields, names, dms)
                    raise InputError(f"{name}: line {lineno}: {col} is {tok!r}, not a finite number")
    assert raw is not None  # numpy parses a token as float() does: a failure was raised above
    return _collapse(raw, layout)


def _dms_columns(layout: dict) -> set[int]:
    return {layout["numeric_index"][n] for n in _DMS_NAMES if n in layout["numeric_index"]}


def _collapse(raw: np.ndarray, layout: dict) -> np.ndarray:
    """Raw numeric fields (after the 2 time fields) -> one column per header name.

    A d m s triple becomes signed degrees; the sign is the degrees field's (``-0`` parses to
    -0.0, so ``signbit`` keeps the sign of latitudes between 0 and -1 degree).
    """
    dms = _dms_columns(layout)
    fields = layout["numeric_fields"]
    if not dms:
        return raw
    out = np.empty((raw.shape[0], len(fields)), dtype=np.float64)
    for j, f in enumerate(fields):
        c = f - 2
        if j in dms:
            d, m, s = raw[:, c], raw[:, c + 1], raw[:, c + 2]
            out[:, j] = np.where(np.signbit(d), -1.0, 1.0) * (np.abs(d) + m / 60.0 + s / 3600.0)
        else:
            out[:, j] = raw[:, c]
    return out


def _column_of(field: int, fields: list[int], names: list[str], dms: set[int]) -> str:
    for j, f in enumerate(fields):
        if f <= field < f + (3 if j in dms else 1):
            return names[j]
    return f"field {field + 1}"


def _integers(name: str, v: np.ndarray, linenos: np.ndarray, col: str) -> np.ndarray:
    bad = (v != np.round(v)) | (v < 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(f"{name}: line {linenos[k]}: {col} is {v[k]:g}, expected a whole number >= 0")
    return v.astype(np.int64)


def _epochs(n: int) -> str:
    return f"{n} epoch{'s' if n != 1 else ''}"


def _lines_note(linenos: np.ndarray) -> str:
    shown = ", ".join(str(int(x)) for x in linenos[:_MAX_LINES_SHOWN])
    more = " ..." if linenos.size > _MAX_LINES_SHOWN else ""
    return f" (line{'s' if linenos.size > 1 else ''} {shown}{more})"


# --------------------------------------------------------------------------------------------
# time order and time base
# --------------------------------------------------------------------------------------------


def _order_times(name: str, t: np.ndarray, linenos: np.ndarray, ts: str, keep: np.ndarray,
                 warnings: list[str]) -> np.ndarray:
    """Mask of epochs to keep so that times increase strictly.

    Exact duplicates keep the first line.  In UTC/JST files RTKLIB prints the epochs inside an
    inserted leap second (23:59:60.x) as 00:00:00.x of the next day, so time steps back by up
    to 1 s at a leap second; those leap-second epochs are dropped.  Any other backward step is
    an error naming the line.
    """
    ok = keep.copy()
    idx = np.flatnonzero(ok)
    if idx.size < 2 or np.all(np.diff(t[idx]) > 0):
        return ok
    offset = _JST_OFFSET_NS if ts == "JST" else 0
    leap_local = timebase.LEAP_STARTS_UNIX_NS + offset
    dup_lines: list[int] = []
    leap_lines: list[int] = []
    last = int(t[idx[0]])
    kept: list[int] = [int(idx[0])]
    for k in idx[1:]:
        tk = int(t[k])
        if tk > last:
            kept.append(int(k))
            last = tk
            continue
        near_leap = ts != "GPST" and last - tk < _NS and bool(
            np.any((leap_local <= tk) & (tk < leap_local + _NS)))
        if near_leap:
            # the kept epochs at or after tk were inside 23:59:60: drop them
            while kept and int(t[kept[-1]]) >= tk:
                j = kept.pop()
                ok[j] = False
                leap_lines.append(int(linenos[j]))
            kept.append(int(k))
            last = tk
        elif tk == last:
            ok[k] = False
            dup_lines.append(int(linenos[k]))
        else:
            raise InputError(
                f"{name}: line {linenos[k]}: time goes backwards by {(last - tk) / _NS:.3f} s "
                "(solution files must be in time order)"
            )
    if dup_lines:
        warnings.append(f"{name}: {_epochs(len(dup_lines))} repeating the previous time "
                        f"dropped{_lines_note(np.array(dup_lines))}")
    if leap_lines:
        warnings.append(f"{name}: {_epochs(len(leap_lines))} inside a leap second (23:59:60 UTC, "
                        f"printed as the next second by RTKLIB) were dropped"
                        f"{_lines_note(np.array(sorted(leap_lines)))}")
    return ok


def _to_base(name: str, t_src: np.ndarray, linenos: np.ndarray, ts: str, base: str,
             keep: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    keep = keep.copy()
    if ts == "GPST":
        if base == "gpst":
            return t_src, keep
        inside = timebase.in_leap_second_gpst_base_ns(t_src) & keep
        if inside.any():
            keep &= ~inside
            warnings.append(f"{name}: {_epochs(int(inside.sum()))} (GPST) inside a leap second "
                            f"(23:59:60 UTC), which has no unix time, dropped"
                            f"{_lines_note(linenos[inside])}")
        out = timebase.convert_ns(t_src, "gpst", "unix")
    else:
        unix = t_src - _JST_OFFSET_NS if ts == "JST" else t_src
        out = unix if base == "unix" else timebase.convert_ns(unix, "unix", "gpst")
    # GPS-UTC changing inside the file is worth a line: the shift is not constant.
    k = np.flatnonzero(keep)
    if k.size:
        ref = out if base == "unix" else timebase.convert_ns(out, "gpst", "unix")
        leaps = timebase.leap_seconds_at_unix_ns(ref[k])
        if (ts == "GPST") != (base == "gpst") and leaps[0] != leaps[-1]:
            warnings.append(f"{name}: the file spans a leap second (GPS-UTC {int(leaps[0])} -> "
                            f"{int(leaps[-1])} s); its times were converted epoch by epoch")
    return out, keep


# --------------------------------------------------------------------------------------------
# positions
# --------------------------------------------------------------------------------------------


def _unsqvar(v: np.ndarray) -> np.ndarray:
    """RTKLIB's sign(c) * sqrt(|c|) back to the covariance c."""
    return np.sign(v) * v * v


def _cov_from_fields(numeric: np.ndarray, cols: dict[str, int], names: tuple[str, ...]) -> np.ndarray | None:
    """(M, 3, 3) covariance from sdx sdy sdz [sdxy sdyz sdzx]; None if the stds are absent."""
    if not all(n in cols for n in names[:3]):
        return None
    sd = np.stack([numeric[:, cols[n]] for n in names[:3]], axis=1)
    m = sd.shape[0]
    cov = np.zeros((m, 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = sd[:, 0] ** 2, sd[:, 1] ** 2, sd[:, 2] ** 2
    if all(n in cols for n in names[3:6]):
        xy, yz, zx = (_unsqvar(numeric[:, cols[n]]) for n in names[3:6])
        cov[:, 0, 1] = cov[:, 1, 0] = xy
        cov[:, 1, 2] = cov[:, 2, 1] = yz
        cov[:, 2, 0] = cov[:, 0, 2] = zx
    return cov


def _rotate_std(cov: np.ndarray | None, rot: np.ndarray) -> np.ndarray | None:
    if cov is None:
        return None
    c = np.einsum("mij,mjk,mlk->mil", rot, cov, rot)
    return np.sqrt(np.clip(np.einsum("mii->mi", c), 0.0, None))


def _positions(name: str, numeric: np.ndarray, layout: dict, linenos: np.ndarray) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """lat, lon (deg), h (m, ellipsoidal), std_enu (m), vel_enu (m/s) and std_vel_enu (m/s) of the
    epochs (the last three None when the file has none), rotated from ECEF for xyz files."""
    cols = layout["numeric_index"]
    fmt = layout["pos_format"]
    std_names = _STD_NAMES[fmt]
    vel_names = _VEL_NAMES[fmt]
    vstd_names = _VEL_STD_NAMES[fmt]
    has_vel = all(n in cols for n in vel_names)

    if fmt == "xyz":
        xyz = np.stack([numeric[:, cols[n]] for n in ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)")], axis=1)
        r = np.linalg.norm(xyz, axis=1)
        bad = r < 6.0e6
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(f"{name}: line {linenos[k]}: ECEF position is {r[k]:.1f} m from the "
                             "Earth's centre, not a position near the Earth's surface")
        lat_r, lon_r, h = ecef_to_geodetic(xyz)
        rot = mat_enu_from_ecef(lat_r, lon_r)
        lat, lon = np.degrees(lat_r), np.degrees(lon_r)
        std_enu = _rotate_std(_cov_from_fields(numeric, cols, std_names), rot)
        vel_enu = std_vel = None
        if has_vel:
            v = np.stack([numeric[:, cols[n]] for n in vel_names], axis=1)
            vel_enu = np.einsum("mij,mj->mi", rot, v)
            std_vel = _rotate_std(_cov_from_fields(numeric, cols, vstd_names), rot)
    else:
        lat_name, lon_name = (("latitude(deg)", "longitude(deg)") if fmt == "llh" else _DMS_NAMES)
        lat = numeric[:, cols[lat_name]].copy()
        lon = numeric[:, cols[lon_name]].copy()
        h = numeric[:, cols["height(m)"]].copy()
        for arr, col, lim in ((lat, lat_name, 90.0), (lon, lon_name, 180.0)):
            bad = np.abs(arr) > lim
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise InputError(f"{name}: line {linenos[k]}: {col} {arr[k]:g} is out of range "
                                 f"[-{lim:g}, {lim:g}]")
        std_enu = None
        if all(n in cols for n in std_names):
            sdn, sde, sdu = (numeric[:, cols[n]] for n in std_names)
            std_enu = np.stack([sde, sdn, sdu], axis=1)
        vel_enu = std_vel = None
        if has_vel:
            vn, ve, vu = (numeric[:, cols[n]] for n in vel_names)
            vel_enu = np.stack([ve, vn, vu], axis=1)
            if all(n in cols for n in vstd_names):
                svn, sve, svu = (numeric[:, cols[n]] for n in vstd_names)
                std_vel = np.stack([sve, svn, svu], axis=1)
    if std_enu is not None and np.any(std_enu < 0.0):
        k = int(np.flatnonzero(np.any(std_enu < 0.0, axis=1))[0])
        raise InputError(f"{name}: line {linenos[k]}: negative standard deviation")
    return (np.ascontiguousarray(lat, dtype=np.float64), np.ascontiguousarray(lon, dtype=np.float64),
            np.ascontiguousarray(h, dtype=np.float64), std_enu, vel_enu, std_vel)
