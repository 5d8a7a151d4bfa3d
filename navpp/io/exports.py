"""Trajectory exports for other tools: TUM (evo), GeoJSON and KML (maps), pandas tables.

Every file is written through :func:`navpp.io.writers.atomic_write`, so it appears complete or
not at all.  Rows whose position or attitude is not finite are left out of the files (no
tool reads them); a finished run has none.

``trajectory.tum`` (:func:`write_tum`)
    The format of the TUM RGB-D benchmark as ``evo`` reads it (``evo_traj tum``,
    ``evo_ape tum``): ``#`` comment lines first, then one pose per line, eight numbers
    separated by single spaces, no trailing space::

        t x y z qx qy qz qw

    ``t``: seconds on the log's own time base, 6 decimals, the same digits as the ``t`` of
    ``trajectory.csv``.  ``x y z``: position of the body (IMU) origin in metres, local ENU
    (east, north, up) about the anchor of :func:`navpp.io.frames.anchor_for` (the first GNSS
    fix in the solution's span), 4 decimals.  ``qx qy qz qw``: unit quaternion, 9 decimals,
    ``w >= 0``, of the rotation taking body FLU vectors into the anchor's ENU axes
    (:func:`navpp.io.frames.body_to_map`).  The comment lines name the anchor (lat, lon in
    degrees, WGS-84 ellipsoidal height in metres), the filter and the log.

``<log>-<filter>.tum`` (:func:`labelled_tum_name`)
    The same bytes as ``trajectory.tum`` under a name that carries the log and the filter,
    because ``evo`` labels a trajectory by its file name: ``evo_traj tum a/drive-ekf.tum
    b/drive-aekf.tum`` tells the runs apart, two ``trajectory.tum`` would both be
    "trajectory".  ``trajectory.tum`` stays for scripts that read it.

``reference.tum`` (:func:`write_reference_tum`)
    The run's reference trajectory in the same format, frame and anchor as
    ``trajectory.tum`` (the anchor convention above is the one every navpp TUM file shares,
    and the one a TUM reference read back is expected to use), so ``evo_ape tum
    reference.tum trajectory.tum`` needs no script of one's own.  Its rows are the reference
    epochs navpp's metrics compare (:func:`navpp.metrics.associate`: the reference rows with
    a position inside the solution's span, not inside a hole of it).  evo associates each
    with the nearest ``trajectory.tum`` row within 0.01 s where navpp interpolates the
    solution, so ``evo_ape``'s translation RMSE is ``metrics.json``'s ``position_m.3d.rmse``
    exactly (to the 0.1 mm of the files) when the output rows fall on the reference epochs
    (e.g. ``--output-rate`` = the reference's rate on its grid), and within the distance
    travelled in half an output interval otherwise.  Orientation: the reference's
    roll / pitch / heading when it has them, else ``0 0 0 1`` (identity), which evo's default
    ``evo_ape`` (translation part) does not use; the comment lines say which.

``trajectory.geojson`` (:func:`write_geojson`)
    RFC 7946: a ``FeatureCollection`` holding one ``Feature`` whose geometry is a
    ``LineString`` of ``[lon, lat, alt]`` positions (degrees with 9 decimals, metres above
    the WGS-84 ellipsoid with 4), decimated for maps by :func:`map_rows`, and whose
    properties say what it is: ``name``, ``filter``, ``log``, ``time_base``, ``t_start``,
    ``t_end`` (s on the log's time base), ``duration_s``, ``start_utc`` / ``end_utc``
    (ISO 8601, unix and gpst bases only), ``solution_rows``, ``points``, ``decimation``,
    ``altitude`` and, with a reference, ``metrics`` (the content of ``metrics.json``).
    A one-row solution gives a ``Point``.  Compact JSON, UTF-8.

``trajectory.kml`` (:func:`write_kml`)
    KML 2.2: a ``Document`` with one line ``Style`` and one ``Placemark`` whose
    ``LineString`` holds ``lon,lat,alt`` tuples (same decimals and rows as the GeoJSON),
    ``tessellate`` 1 and an ``altitudeMode`` (default ``clampToGround``: KML's absolute
    altitudes are above mean sea level, navpp's heights above the ellipsoid, so an
    ``absolute`` track would float or sink by the geoid undulation, up to 100 m).  The
    Placemark's ``ExtendedData`` carries the GeoJSON's scalar properties and, with a
    reference, the position RMSE; a ``TimeSpan`` is given on the unix and gpst bases.

Decimation for maps (:func:`map_rows`): a row is kept when it is the first of its 0.1 s
time slot (slots counted from the first row) and the horizontal path has grown by at least
0.1 m since the previous kept row; the last row is always kept.  A 125 Hz drive thus keeps
at most 10 points per second, and a standstill only the slots in which the solution moved.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from collections.abc import Mapping
from typing import IO, TYPE_CHECKING, Any
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from .. import timebase
from ..recording import Recording, Solution
from ..spill import release
from . import frames, writers
from .csvformat import BlockFormatter

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "GEOJSON_FILE",
    "KML_FILE",
    "MAP_MIN_INTERVAL_S",
    "MAP_MIN_STEP_M",
    "REFERENCE_TUM_FILE",
    "TUM_FILE",
    "absolute_time",
    "diagnostics_frame",
    "labelled_tum_name",
    "map_rows",
    "reference_solution",
    "trajectory_frame",
    "write_geojson",
    "write_kml",
    "write_reference_tum",
    "write_tum",
]

TUM_FILE = "trajectory.tum"
REFERENCE_TUM_FILE = "reference.tum"
GEOJSON_FILE = "trajectory.geojson"
KML_FILE = "trajectory.kml"

#: Map decimation: at most one point per this many seconds (slots from the first row).
MAP_MIN_INTERVAL_S = 0.1
#: Map decimation: a new point only once the horizontal path has grown by this many metres.
MAP_MIN_STEP_M = 0.1

_POSITION_DECIMALS = 4      # m: 0.1 mm, as the heights of trajectory.csv
_QUATERNION_DECIMALS = 9
_DEGREE_DECIMALS = 9        # deg: ~0.1 mm, as trajectory.csv
KML_NAMESPACE = "http://www.opengis.net/kml/2.2"
KML_ALTITUDE_MODES = ("clampToGround", "relativeToGround", "absolute")
_KML_LINE_COLOR = "ff1e69ff"  # aabbggrr: opaque orange
_KML_LINE_WIDTH = 3


# --------------------------------------------------------------------------- time and rows


def absolute_time(t_rel: np.ndarray, t0_ns: int) -> np.ndarray:
    """Seconds on the log's time base (float64) of times ``t_rel`` (s) relative to ``t0_ns``.

    The whole seconds of ``t0_ns`` are added last, so the result is as exact as float64 allows
    (0.24 us at unix times of ~1.7e9 s) rather than carrying the rounding of ``t0_ns * 1e-9``.
    """
    whole, frac_ns = divmod(int(t0_ns), 1_000_000_000)
    return float(whole) + (frac_ns * 1e-9 + np.asarray(t_rel, dtype=np.float64))


def _finite_rows(solution: Solution, with_attitude: bool) -> np.ndarray:
    ok = np.isfinite(solution.t) & np.isfinite(solution.lat_deg) & np.isfinite(solution.lon_deg)
    ok &= np.isfinite(solution.alt)
    if with_attitude:
        ok &= np.isfinite(np.asarray(solution.rph_deg, dtype=float)).all(axis=1)
    return np.flatnonzero(ok)


def _subset(solution: Solution, rows: np.ndarray | slice) -> Solution:
    """The solution at ``rows``: an index array (copies; the solution itself when it takes every
    row) or a slice (views)."""
    if isinstance(rows, np.ndarray) and rows.size == len(solution):
        return solution
    return Solution(t=solution.t[rows], lat_deg=solution.lat_deg[rows], lon_deg=solution.lon_deg[rows],
                    alt=solution.alt[rows], vel_enu=np.asarray(solution.vel_enu)[rows],
                    rph_deg=np.asarray(solution.rph_deg)[rows], std_enu=np.asarray(solution.std_enu)[rows],
                    t0_ns=solution.t0_ns, **{name: None if getattr(solution, name) is None
                                             else np.asarray(getattr(solution, name))[rows]
                                             for name in ("std_att", "std_vel_enu", "rate_body")})


def map_rows(solution: Solution, *, min_interval_s: float = MAP_MIN_INTERVAL_S,
             min_step_m: float = MAP_MIN_STEP_M) -> np.ndarray:
    """Indices of the rows a map shows (see the module docstring), ascending.

    Parameters
    ----------
    solution : the solution; rows with a non-finite position are skipped.
    min_interval_s : s, > 0. At most one point per slot of this length, counted from the
        first row.
    min_step_m : m, >= 0. A slot's first row is kept only if the horizontal path (summed
        over every row, local ENU about the first row) has grown by at least this much
        since the previous kept row: a standstill collapses to one point.

    Returns
    -------
    (K,) int array: always the first and last finite rows; every row when K <= 2.
    """
    if not (min_interval_s > 0.0 and min_step_m >= 0.0):
        raise ValueError(f"need min_interval_s > 0 and min_step_m >= 0, got {min_interval_s!r}, {min_step_m!r}")
    idx = _finite_rows(solution, with_attitude=False)
    if idx.size <= 2:
        return idx
    t = np.asarray(solution.t, dtype=float)[idx]
    slot = np.floor((t - t[0]) / min_interval_s)
    candidates = np.flatnonzero(np.r_[True, slot[1:] != slot[:-1]])
    if min_step_m > 0.0:
        origin = frames.Anchor(float(solution.lat_deg[idx[0]]), float(solution.lon_deg[idx[0]]),
                               float(solution.alt[idx[0]]))
        en = origin.enu(solution.lat_deg[idx], solution.lon_deg[idx], solution.alt[idx])[:, :2]
        path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(en, axis=0).T))][candidates]
        keep = np.zeros(candidates.size, dtype=bool)
        keep[0] = True
        last = path[0]
        for k in range(1, candidates.size):      # at most one per slot: 10 per second of log
            if path[k] - last >= min_step_m:
                keep[k] = True
                last = path[k]
        candidates = candidates[keep]
    if candidates[-1] != idx.size - 1:
        candidates = np.r_[candidates, idx.size - 1]
    return idx[candidates]


def _decimation_text(min_interval_s: float, min_step_m: float) -> str:
    return (f"at most one point per {min_interval_s:g} s, and only after {min_step_m:g} m of horizontal path; "
            "first and last rows always kept")


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


# --------------------------------------------------------------------------- TUM


def write_tum(path: str | os.PathLike[str], solution: Solution, recording: Recording | None = None, *,
              filter_name: str = "", log: str = "") -> None:
    """Write ``trajectory.tum``: ``t x y z qx qy qz qw`` per row, for ``evo`` (module docstring).

    Parameters
    ----------
    path : output file (written atomically).
    solution : the solution, every finite row is written; ``t`` relative to ``solution.t0_ns``.
    recording : the log, for the anchor (first GNSS fix in the span); None anchors the
        frame at the solution's first row.
    filter_name, log : named in the comment lines.
    """
    rows = _finite_rows(solution, with_attitude=True)
    sol = _subset(solution, rows)
    anchor = frames.anchor_for(sol, recording) if len(sol) else frames.Anchor(0.0, 0.0, 0.0)
    _write_tum_rows(path, sol, anchor, recording, [
        "# navpp trajectory, TUM format: t x y z qx qy qz qw",
        f"# filter: {_one_line(filter_name) or '-'}; log: {_one_line(log) or '-'}",
    ], True, None)


def labelled_tum_name(log: str | os.PathLike[str], filter_name: str) -> str:
    """``<log>-<filter>.tum``: the TUM file name evo shows as the run's label.  ``<log>`` is the
    log's file name without its extension (a directory log: its name), ``<filter>`` the
    filter's name; characters other than letters, digits, ``.``, ``_`` and ``-`` become ``_``."""
    import re

    p = os.fspath(log).rstrip("/\\")
    base = os.path.basename(p) or "log"
    stem = base if os.path.isdir(p) else (os.path.splitext(base)[0] or base)
    label = f"{stem}-{filter_name}" if filter_name else stem
    return re.sub(r"[^A-Za-z0-9._-]", "_", label) + ".tum"


def reference_solution(reference: Any, solution: Solution) -> Solution:
    """The reference rows navpp's metrics compare (see ``reference.tum`` in the module docstring)
    as a :class:`Solution` on ``solution.t0_ns`` (zero velocity where the reference has none;
    NaN attitude where it has none; zero sigmas)."""
    from ..metrics import associate

    ref = reference
    ok = np.isfinite(ref.lat_deg) & np.isfinite(ref.lon_deg) & np.isfinite(ref.alt)
    i = associate(np.asarray(solution.t, dtype=float), np.where(ok, np.asarray(ref.t, dtype=float), np.nan),
                  skip_holes=True).idx_ref
    n = int(i.size)
    vel = (np.asarray(ref.vel_enu, dtype=float)[i] if ref.vel_enu is not None else np.zeros((n, 3)))
    rph = (np.asarray(ref.rph_deg, dtype=float)[i] if ref.rph_deg is not None else np.full((n, 3), np.nan))
    return Solution(t=np.asarray(ref.t, dtype=float)[i], lat_deg=np.asarray(ref.lat_deg, dtype=float)[i],
                    lon_deg=np.asarray(ref.lon_deg, dtype=float)[i], alt=np.asarray(ref.alt, dtype=float)[i],
                    vel_enu=vel, rph_deg=rph, std_enu=np.zeros((n, 3)), t0_ns=solution.t0_ns)


def write_reference_tum(path: str | os.PathLike[str], reference: Any, solution: Solution,
                        recording: Recording | None = None, *, filter_name: str = "", log: str = "",
                        compared: Solution | None = None) -> None:
    """Write ``reference.tum``: the reference (a :class:`~navpp.recording.ReferenceData`, ``t``
    relative to ``solution.t0_ns``) at the epochs the metrics compare, in ``trajectory.tum``'s
    frame and anchor (that of ``solution`` and ``recording``; module docstring).
    ``compared``: the solution the metrics were computed on, when not ``solution`` itself (the
    full-rate one of a run written at ``--output-rate``): its span picks the rows.

    Raises ValueError when no reference epoch falls inside the solution's span.
    """
    rows = _finite_rows(solution, with_attitude=True)
    sol = _subset(solution, rows)
    if len(sol) == 0:
        raise ValueError("the solution has no finite row: no anchor for reference.tum")
    anchor = frames.anchor_for(sol, recording)
    ref = reference_solution(reference, solution if compared is None else compared)
    if len(ref) == 0:
        raise ValueError("no reference epoch inside the solution's span: nothing to write to reference.tum")
    rph = np.asarray(ref.rph_deg, dtype=float)
    has_att = bool(np.isfinite(rph).all())
    src = getattr(reference, "source", "") or "-"
    _write_tum_rows(path, ref, anchor, recording, [
        "# navpp reference, TUM format: t x y z qx qy qz qw",
        f"# reference: {_one_line(src)}; compared with filter: {_one_line(filter_name) or '-'}; "
        f"log: {_one_line(log) or '-'}",
    ], has_att, "the reference epochs navpp's metrics compare (inside the solution's span)")


def _write_tum_rows(path: str | os.PathLike[str], sol: Solution, anchor: frames.Anchor,
                    recording: Recording | None, head: list[str], attitude: bool, rows_text: str | None) -> None:
    t0_s = sol.t0_ns * 1e-9
    time_base = f" ({recording.time_base})" if recording is not None else ""
    header = head + [
        f"# t: s on the log's time base{time_base}, as trajectory.csv" + (f"; rows: {rows_text}" if rows_text else ""),
        (f"# x y z: m, local ENU (east, north, up) about lat {anchor.lat_deg:.9f} deg, "
         f"lon {anchor.lon_deg:.9f} deg, height {anchor.alt:.4f} m (WGS-84 ellipsoid)"),
        ("# qx qy qz qw: rotation body FLU (x forward, y left, z up) -> that ENU frame" if attitude else
         "# qx qy qz qw: 0 0 0 1 (the reference has no attitude; evo_ape's default translation part ignores it)"),
    ]
    text_header = ("\n".join(header) + "\n").encode("utf-8")
    n = len(sol)
    decimals = (6, *[_POSITION_DECIMALS] * 3, *[_QUATERNION_DECIMALS] * 4)
    formatter = BlockFormatter(decimals, t0_s=t0_s, sep=b" ")

    def write(f: IO[bytes]) -> None:
        f.write(text_header)
        for start in range(0, n, writers._CHUNK_ROWS):
            stop = min(n, start + writers._CHUNK_ROWS)
            part = _subset(sol, slice(start, stop))
            xyz = anchor.enu(part.lat_deg, part.lon_deg, part.alt)
            if attitude:
                q = frames.quat_xyzw(frames.body_to_map(part, anchor))
            else:
                q = np.zeros((stop - start, 4))
                q[:, 3] = 1.0
            block = [np.asarray(part.t), *xyz.T, *q.T]
            f.write(formatter.text(block))
            release([sol.t, sol.lat_deg, sol.lon_deg, sol.alt, sol.rph_deg], start, stop)   # a spilled solution

    writers.atomic_write(path, write, mode="wb")


# --------------------------------------------------------------------------- maps


def _span_properties(solution: Solution, rows: np.ndarray, recording: Recording | None) -> dict[str, Any]:
    time_base = recording.time_base if recording is not None else "unknown"
    props: dict[str, Any] = {"time_base": time_base}
    if rows.size:
        t = absolute_time(np.asarray(solution.t)[[rows[0], rows[-1]]], solution.t0_ns)
        props.update(t_start=round(float(t[0]), 6), t_end=round(float(t[1]), 6),
                     duration_s=round(float(solution.t[rows[-1]] - solution.t[rows[0]]), 6))
        if time_base in ("unix", "gpst"):
            utc = timebase.convert(t, time_base, "unix") if time_base == "gpst" else t
            iso = [_dt.datetime.fromtimestamp(float(v), _dt.UTC).isoformat(timespec="milliseconds")
                   .replace("+00:00", "Z") for v in np.atleast_1d(utc)]
            props.update(start_utc=iso[0], end_utc=iso[1])
    return props


def _map_properties(solution: Solution, rows: np.ndarray, recording: Recording | None, filter_name: str,
                    log: str, min_interval_s: float, min_step_m: float) -> dict[str, Any]:
    name = "navpp" + (f" {filter_name}" if filter_name else "") + (f": {os.path.basename(str(log))}" if log else "")
    props: dict[str, Any] = {"name": _one_line(name), "filter": filter_name, "log": str(log)}
    props.update(_span_properties(solution, rows, recording))
    props.update(solution_rows=len(solution), points=int(rows.size),
                 decimation=_decimation_text(min_interval_s, min_step_m),
                 altitude="m above the WGS-84 ellipsoid")
    return props


def write_geojson(path: str | os.PathLike[str], solution: Solution, recording: Recording | None = None, *,
                  filter_name: str = "", log: str = "", metrics: Mapping[str, Any] | None = None,
                  min_interval_s: float = MAP_MIN_INTERVAL_S, min_step_m: float = MAP_MIN_STEP_M) -> None:
    """Write ``trajectory.geojson`` (RFC 7946; layout in the module docstring).

    Parameters
    ----------
    path : output file (written atomically).
    solution : the solution; the rows of :func:`map_rows` are written.
    recording : the log (its time base names the times); optional.
    filter_name, log : properties of the feature.
    metrics : ``metrics.json``'s content, stored under ``properties.metrics`` when given.
    min_interval_s, min_step_m : decimation, see :func:`map_rows`.
    """
    rows = map_rows(solution, min_interval_s=min_interval_s, min_step_m=min_step_m)
    props = _map_properties(solution, rows, recording, filter_name, log, min_interval_s, min_step_m)
    if metrics is not None:
        props["metrics"] = writers._json_ready(metrics)
    coords = [[round(float(lon), _DEGREE_DECIMALS), round(float(lat), _DEGREE_DECIMALS),
               round(float(alt), _POSITION_DECIMALS)]
              for lon, lat, alt in zip(solution.lon_deg[rows], solution.lat_deg[rows], solution.alt[rows])]
    if len(coords) >= 2:
        geometry: dict[str, Any] | None = {"type": "LineString", "coordinates": coords}
    elif coords:
        geometry = {"type": "Point", "coordinates": coords[0]}
    else:
        geometry = None
    doc = {"type": "FeatureCollection",
           "features": [{"type": "Feature", "geometry": geometry, "properties": props}]}
    text = _json_dumps(doc) + "\n"
    writers.atomic_write(path, lambda f: f.write(text), mode="w")


def _json_dumps(obj: Any) -> str:
    """Compact, strict JSON (no NaN), non-ASCII kept as UTF-8."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False, ensure_ascii=False)


def _kml_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6f}" if math.isfinite(v) else str(v)
    return str(v)


def write_kml(path: str | os.PathLike[str], solution: Solution, recording: Recording | None = None, *,
              filter_name: str = "", log: str = "", metrics: Mapping[str, Any] | None = None,
              altitude_mode: str = "clampToGround", min_interval_s: float = MAP_MIN_INTERVAL_S,
              min_step_m: float = MAP_MIN_STEP_M) -> None:
    """Write ``trajectory.kml`` (KML 2.2; layout in the module docstring).

    Parameters
    ----------
    path : output file (written atomically).
    solution : the solution; the rows of :func:`map_rows` are written as ``lon,lat,alt``
        (deg, deg, m above the WGS-84 ellipsoid).
    recording : the log (its time base names the times); optional.
    filter_name, log : the Placemark's name and data.
    metrics : ``metrics.json``'s content; its position RMSEs go into ``ExtendedData``.
    altitude_mode : one of ``KML_ALTITUDE_MODES``; see the module docstring for why the
        default is ``clampToGround``.
    min_interval_s, min_step_m : decimation, see :func:`map_rows`.
    """
    if altitude_mode not in KML_ALTITUDE_MODES:
        raise ValueError(f"altitude_mode must be one of {', '.join(KML_ALTITUDE_MODES)}, got {altitude_mode!r}")
    rows = map_rows(solution, min_interval_s=min_interval_s, min_step_m=min_step_m)
    props = _map_properties(solution, rows, recording, filter_name, log, min_interval_s, min_step_m)
    data = {k: v for k, v in props.items() if k != "name"}
    if metrics is not None:
        pos = metrics.get("position_m", {})
        for key, label in (("horizontal", "horizontal"), ("up", "up"), ("3d", "3d")):
            rmse = pos.get(key, {}).get("rmse")
            if rmse is not None:
                data[f"{label}_rmse_m"] = float(rmse)
        if metrics.get("reference"):
            data["reference"] = metrics["reference"]
    description = (f"{props['name']}. Heights are m above the WGS-84 ellipsoid (altitudeMode {altitude_mode}). "
                   f"Points: {props['decimation']}.")
    coords = writers.format_fixed_columns(
        [solution.lon_deg[rows], solution.lat_deg[rows], solution.alt[rows]],
        (_DEGREE_DECIMALS, _DEGREE_DECIMALS, _POSITION_DECIMALS)).decode("ascii")
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<kml xmlns="{KML_NAMESPACE}">',
        "<Document>",
        f"<name>{escape(props['name'])}</name>",
        f"<description>{escape(description)}</description>",
        '<Style id="navpp-trajectory">',
        f"<LineStyle><color>{_KML_LINE_COLOR}</color><width>{_KML_LINE_WIDTH}</width></LineStyle>",
        "</Style>",
        "<Placemark>",
        f"<name>{escape(props['name'])}</name>",
        f"<description>{escape(description)}</description>",
    ]
    if "start_utc" in props:
        lines.append(f"<TimeSpan><begin>{props['start_utc']}</begin><end>{props['end_utc']}</end></TimeSpan>")
    lines.append("<styleUrl>#navpp-trajectory</styleUrl>")
    lines.append("<ExtendedData>")
    lines += [f"<Data name={quoteattr(k)}><value>{escape(_kml_value(v))}</value></Data>" for k, v in data.items()]
    lines.append("</ExtendedData>")
    if rows.size >= 2:
        lines += ["<LineString>", "<tessellate>1</tessellate>", f"<altitudeMode>{altitude_mode}</altitudeMode>",
                  "<coordinates>", coords.rstrip("\n"), "</coordinates>", "</LineString>"]
    elif rows.size == 1:
        lines.append(f"<Point><altitudeMode>{altitude_mode}</altitudeMode><coordinates>{coords.strip()}"
                     "</coordinates></Point>")
    lines += ["</Placemark>", "</Document>", "</kml>"]
    text = "\n".join(lines) + "\n"
    writers.atomic_write(path, lambda f: f.write(text), mode="w")


# --------------------------------------------------------------------------- pandas


def trajectory_frame(solution: Solution) -> pd.DataFrame:
    """The solution as a ``pandas.DataFrame`` with ``trajectory.csv``'s columns.

    ``t`` is float64 seconds on the log's time base (:func:`absolute_time`); ``lat, lon``
    deg; ``alt`` m (WGS-84 ellipsoid); ``ve, vn, vu`` m/s (ENU); ``roll, pitch, heading`` deg
    (navigation convention, heading clockwise from north); ``std_e, std_n, std_u`` m (1 sigma).
    Full precision: the CSV rounds the same numbers to its decimals.
    """
    import pandas as pd

    vel = np.asarray(solution.vel_enu, dtype=np.float64).reshape(-1, 3)
    rph = np.asarray(solution.rph_deg, dtype=np.float64).reshape(-1, 3)
    std = np.asarray(solution.std_enu, dtype=np.float64).reshape(-1, 3)
    values = [absolute_time(solution.t, solution.t0_ns), solution.lat_deg, solution.lon_deg, solution.alt,
              vel[:, 0], vel[:, 1], vel[:, 2], rph[:, 0], rph[:, 1], rph[:, 2], std[:, 0], std[:, 1], std[:, 2]]
    return pd.DataFrame({name: np.array(v, dtype=np.float64) for name, v in zip(writers.TRAJECTORY_COLUMNS, values)})


def diagnostics_frame(diagnostics: Any, t0_ns: int) -> pd.DataFrame:
    """The filter's per-GNSS-epoch diagnostics as a ``pandas.DataFrame`` with
    ``diagnostics.csv``'s columns (:func:`navpp.io.writers.diagnostics_columns`); ``t`` is
    float64 seconds on the log's time base, ``diagnostics.t`` being relative to ``t0_ns``."""
    import pandas as pd

    names, cols, _ = writers.diagnostics_columns(diagnostics)
    frame = {"t": absolute_time(diagnostics.t, t0_ns)}
    frame.update({name: np.array(c, dtype=np.float64) for name, c in zip(names, cols)})
    return pd.DataFrame(frame)
