"""Output files: ``trajectory.csv``, ``metrics.json``, ``metrics.md`` (README.md, "Outputs").

Every file is written through :func:`atomic_write`: the bytes go to a temporary name in the
target directory, are flushed to disk, and the temporary file is renamed over the target only
when complete, so a failed or interrupted run never leaves a half-written file that looks
finished.

``trajectory.csv`` is formatted block by block by a compiled fixed-point formatter
(:mod:`navpp.io.csvformat`, with a vectorised exact path for values too large for it) rather
than ``pandas.to_csv`` or ``numpy.savetxt``, which format value by value (README, "Speed", has
the times).  Its text is identical to Python's ``format(x, ".Nf")`` for every value (correct
rounding of the exact binary value, ties to even, ``"nan"``, ``"inf"``, ``"-inf"``, and
``"-0.0000"`` for negative values that round to zero, as C's ``printf`` and pandas also write
them).  The one exception is the ``t`` column, which is computed more precisely than
``format(t0_s + t, ".6f")`` would (see :func:`write_trajectory_csv`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from navpp.recording import Solution
from navpp.spill import release

if TYPE_CHECKING:
    from .csvformat import BlockFormatter

__all__ = [
    "TRAJECTORY_COLUMNS",
    "TRAJECTORY_DECIMALS",
    "atomic_write",
    "format_fixed_columns",
    "write_diagnostics_csv",
    "write_metrics_json",
    "write_metrics_md",
    "write_trajectory_csv",
]

#: Column names of ``trajectory.csv``, in order (README.md, "Outputs").
TRAJECTORY_COLUMNS: tuple[str, ...] = (
    "t", "lat", "lon", "alt", "ve", "vn", "vu", "roll", "pitch", "heading",
    "std_e", "std_n", "std_u",
)
#: Decimals written per column: t 1 us, lat/lon 1e-9 deg (~0.1 mm), alt/velocities/angles/std 1e-4.
TRAJECTORY_DECIMALS: tuple[int, ...] = (6, 9, 9, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4)

_CHUNK_ROWS = 16_384  # rows formatted per pass: bounds memory to a few MB whatever the length


# --------------------------------------------------------------------------- atomic write


def _default_file_mode() -> int:
    """Permissions an ordinary ``open(path, "w")`` would give a new file (0o666 & ~umask)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return 0o644


def atomic_write(path: str | os.PathLike[str], writer: Callable[[IO[Any]], object],
                 mode: str = "w") -> None:
    """Write a file so that it appears complete or not at all.

    ``writer`` receives an open file (text, UTF-8 with ``"\\n"`` line ends, for ``mode="w"``;
    binary for ``mode="wb"``) on a temporary name in the target's directory.  When it returns,
    the data are flushed and fsynced and the temporary file is renamed over ``path``
    (``os.replace``, atomic on POSIX and Windows).  If ``writer`` raises (or the run is
    interrupted), the temporary file is removed, ``path`` is left as it was, and the exception
    propagates.

    Parameters
    ----------
    path : target file; its directory must exist.
    writer : callable that writes the whole content to the file it is given.
    mode : ``"w"`` (text) or ``"wb"`` (binary).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{path.name}.", suffix=".tmp")
    try:
        if mode == "w":
            f: IO[Any] = os.fdopen(fd, "w", encoding="utf-8", newline="\n")
        else:
            f = os.fdopen(fd, "wb")
        with f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        try:
            target_mode = path.stat().st_mode & 0o7777
        except FileNotFoundError:
            target_mode = _default_file_mode()
        os.chmod(tmp_name, target_mode)
        os.replace(tmp_name, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_name)
        raise
    _fsync_directory(directory)


def _fsync_directory(directory: Path) -> None:
    """Make the rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        dfd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


# --------------------------------------------------------------------------- fixed-point formatting


def _block_formatter(decimals: Sequence[int], t0_s: float | None) -> BlockFormatter:
    """The formatter of rows of these columns (:class:`navpp.io.csvformat.BlockFormatter`),
    imported here so that importing the writers does not load numba."""
    from .csvformat import BlockFormatter

    return BlockFormatter(decimals, t0_s=t0_s)


def format_fixed_columns(columns: Sequence[np.ndarray], decimals: Sequence[int]) -> bytes:
    """CSV text (no header) of equal-length float columns with fixed decimals per column.

    Every value is written exactly as ``format(v, f".{d}f")`` writes it (see the module
    docstring); rows end with ``"\\n"``.  Block by block (:mod:`navpp.io.csvformat`).
    """
    if len(columns) != len(decimals) or not columns:
        raise ValueError("format_fixed_columns needs one decimals entry per column")
    columns = [np.asarray(c) for c in columns]
    formatter = _block_formatter(decimals, None)
    n = int(columns[0].shape[0])
    return b"".join(bytes(formatter.text([c[start:start + _CHUNK_ROWS] for c in columns]))
                    for start in range(0, n, _CHUNK_ROWS))


def write_trajectory_csv(path: str | os.PathLike[str], sol: Solution, *, t0_s: float) -> None:
    """Write ``trajectory.csv`` (README.md, "Outputs"): one row per solution epoch.

    Columns ``t, lat, lon, alt, ve, vn, vu, roll, pitch, heading, std_e, std_n, std_u``:
    ``t`` in seconds on the log's own time base (``t0_s + sol.t``, 6 decimals), latitude and
    longitude in degrees (9 decimals, ~0.1 mm), altitude m, velocity ENU m/s, roll/pitch/heading
    deg (navigation convention), position 1-sigma m (4 decimals each).  Non-finite values are
    written ``nan`` / ``inf`` / ``-inf``.

    ``t`` is ``t0_s + sol.t`` rounded once to the microsecond: the float sum (which at unix
    times of ~1.7e9 s has a resolution of 0.24 us) is never formed.  It is still only as exact
    as ``t0_s`` itself.

    Parameters
    ----------
    path : output file (written atomically).
    sol : the solution.
    t0_s : seconds on the log's time base of ``sol.t == 0`` (e.g. ``recording.t0_ns * 1e-9``).
    """
    if not math.isfinite(t0_s) or abs(t0_s) >= 1.0e12:
        raise ValueError(f"t0_s must be finite and below 1e12 s in magnitude, got {t0_s!r}")
    n = len(sol)
    # in their own dtype (the 1-sigma is float32): each block is made float64 as it is formatted
    vel = np.asarray(sol.vel_enu).reshape(n, 3)
    rph = np.asarray(sol.rph_deg).reshape(n, 3)
    std = np.asarray(sol.std_enu).reshape(n, 3)
    columns = [np.asarray(c) for c in (sol.t, sol.lat_deg, sol.lon_deg, sol.alt, vel[:, 0], vel[:, 1], vel[:, 2],
                                       rph[:, 0], rph[:, 1], rph[:, 2], std[:, 0], std[:, 1], std[:, 2])]
    header = (",".join(TRAJECTORY_COLUMNS) + "\n").encode("ascii")
    formatter = _block_formatter(TRAJECTORY_DECIMALS, t0_s)

    def write(f: IO[bytes]) -> None:
        f.write(header)
        for start in range(0, n, _CHUNK_ROWS):
            stop = min(n, start + _CHUNK_ROWS)
            f.write(formatter.text([c[start:stop] for c in columns]))
            release(columns, start, stop)      # the rows written leave memory (a spilled solution)

    atomic_write(path, write, mode="wb")


def adaptive_columns(diagnostics: Any) -> tuple[list[str], np.ndarray]:
    """Names and (M, K) values of every per-epoch quantity beyond the fixed GNSS-position fields:
    the GNSS velocity update of the epoch when the run had one (``nu_ve, nu_vn, nu_vu`` m/s,
    ``nis_vel``, ``vel_accepted``; nan where a fix had no velocity), the odometer's update at the
    epoch when the run had one (``nu_odo`` m/s, ``nis_odo``, ``odo_accepted``) and the odometry's yaw rate
    with ``[odometry] use_yaw_rate`` (``nu_yaw`` rad/s, ``nis_yaw``, ``yaw_accepted``), then the extra filter states
    of ``diagnostics.states`` (the GNSS error states ``gnss_error_e/n/u`` and their 1-sigma, ENU m,
    with the Gauss-Markov GNSS error model), then every adaptive quantity in
    ``diagnostics.adaptive``.

    An adaptive entry ``name -> (M, k)`` gives ``name`` when k is 1, else ``name_0 ..
    name_<k-1>``: the column names of ``diagnostics.csv`` (and of the MCAP diagnostics' ``names``).
    """
    m = len(diagnostics.t)
    names: list[str] = []
    cols: list[np.ndarray] = []
    vel_nu = getattr(diagnostics, "vel_nu", None)
    if vel_nu is not None:
        names += ["nu_ve", "nu_vn", "nu_vu", "nis_vel", "vel_accepted"]
        cols.append(np.column_stack([np.asarray(vel_nu, dtype=np.float64).reshape(m, 3),
                                     np.asarray(diagnostics.vel_nis, dtype=np.float64).reshape(m),
                                     np.asarray(diagnostics.vel_accepted, dtype=np.float64).reshape(m)]))
    for short, values in getattr(diagnostics, "aids", {}).items():
        names += [f"nu_{short}", f"nis_{short}", f"{short}_accepted"]
        cols.append(np.column_stack([np.asarray(v, dtype=np.float64).reshape(m) for v in values]))
    for key, values in [*getattr(diagnostics, "states", {}).items(), *getattr(diagnostics, "adaptive", {}).items()]:
        v = np.asarray(values, dtype=np.float64).reshape(m, -1)
        names += [key] if v.shape[1] == 1 else [f"{key}_{i}" for i in range(v.shape[1])]
        cols.append(v)
    return names, (np.concatenate(cols, axis=1) if cols else np.zeros((m, 0)))


def diagnostics_columns(diag: Any) -> tuple[list[str], list[np.ndarray], list[int]]:
    """Column names, (M,) value arrays and decimals of ``diagnostics.csv`` (after ``t``).

    ``nu_e, nu_n, nu_u`` GNSS innovation (ENU m), ``nis``, ``accepted``, ``forced`` (0/1),
    ``r_std_e, r_std_n, r_std_u`` the measurement 1-sigma the filter used (m); when the run used
    GNSS velocity, ``nu_ve, nu_vn, nu_vu`` (m/s), ``nis_vel`` and ``vel_accepted`` (nan where a
    fix had no velocity); then each entry of the filter's noise report (``name`` when it has
    one value, ``name_<i>`` otherwise).
    """
    nu = np.asarray(diag.nu, dtype=np.float64)
    r = np.asarray(diag.r_std, dtype=np.float64)
    names = ["nu_e", "nu_n", "nu_u", "nis", "accepted", "forced", "r_std_e", "r_std_n", "r_std_u"]
    cols = [nu[:, 0], nu[:, 1], nu[:, 2], np.asarray(diag.nis, dtype=np.float64),
            np.asarray(diag.accepted, dtype=np.float64), np.asarray(diag.forced, dtype=np.float64),
            r[:, 0], r[:, 1], r[:, 2]]
    decimals = [4, 4, 4, 4, 0, 0, 4, 4, 4]
    extra_names, values = adaptive_columns(diag)
    names += extra_names
    cols += list(values.T)
    n_vel = 5 if getattr(diag, "vel_nu", None) is not None else 0
    aid_decimals = [d for short in getattr(diag, "aids", {}) for d in ([6, 4, 0] if short == "yaw" else [4, 4, 0])]
    decimals += [4, 4, 4, 4, 0][:n_vel] + aid_decimals + [6] * (len(extra_names) - n_vel - len(aid_decimals))
    return names, cols, decimals


def write_diagnostics_csv(path: str | os.PathLike[str], diag: Any, *, t0_s: float) -> None:
    """Write ``diagnostics.csv``: one row per GNSS epoch the filter saw (:func:`diagnostics_columns`),
    ``t`` in seconds on the log's time base (``t0_s + diag.t``).  Written atomically."""
    names, cols, decimals = diagnostics_columns(diag)
    header = (",".join(["t", *names]) + "\n").encode("ascii")
    columns = [np.asarray(diag.t, dtype=np.float64), *cols]
    decimals = [6, *decimals]
    n = columns[0].shape[0]
    formatter = _block_formatter(decimals, t0_s)

    def write(f: IO[bytes]) -> None:
        f.write(header)
        for start in range(0, n, _CHUNK_ROWS):
            block = [c[start:start + _CHUNK_ROWS] for c in columns]
            f.write(formatter.text(block))

    atomic_write(path, write, mode="wb")


# --------------------------------------------------------------------------- metrics


def _json_ready(obj: Any) -> Any:
    """Plain JSON values: numpy scalars to Python numbers, non-finite floats to ``None``."""
    if isinstance(obj, Mapping):
        return {str(k): _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_json_ready(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def write_metrics_json(path: str | os.PathLike[str], metrics: Mapping[str, Any]) -> None:
    """Write ``metrics.json`` (indented, UTF-8); NaN/inf become ``null`` so the file is valid JSON."""
    text = json.dumps(_json_ready(metrics), indent=2, allow_nan=False) + "\n"
    atomic_write(path, lambda f: f.write(text), mode="w")


_STAT_COLUMNS = (("mae", "MAE"), ("rmse", "RMSE"), ("max", "max"), ("p95", "p95"))
_POSITION_ROWS = ("east", "north", "up", "horizontal", "3d")


def _num(v: Any, decimals: int = 4) -> str:
    if v is None:
        return "-"
    v = float(v)
    return f"{v:.{decimals}f}" if math.isfinite(v) else str(v)


def _stats_table(stats: Mapping[str, Any], rows: Sequence[str], unit: str) -> list[str]:
    lines = [
        f"| | MAE ({unit}) | RMSE ({unit}) | max ({unit}) | p95 ({unit}) |",
        "|---|---:|---:|---:|---:|",
    ]
    for row in rows:
        if row not in stats:
            continue
        s = stats[row]
        lines.append(f"| {row} | " + " | ".join(_num(s.get(key)) for key, _ in _STAT_COLUMNS) + " |")
    return lines


def metrics_markdown(metrics: Mapping[str, Any]) -> str:
    """The Markdown text of ``metrics.md``: the numbers of ``metrics.json`` as tables (4 decimals)."""
    m = metrics
    out = [
        f"# navpp metrics: {m.get('filter', '?')} on {m.get('log', '?')}",
        "",
        f"- filter: `{m.get('filter', '')}`",
        f"- log: `{m.get('log', '')}`",
        f"- reference: `{m.get('reference', '')}`",
        f"- reference epochs compared: {m.get('epochs', 0)}",
        f"- runtime: {_num(m.get('runtime_s'), 3)} s",
        f"- IMU samples: {m.get('imu_samples', 0)}; GNSS epochs: {m.get('gnss_epochs', 0)}; "
        f"GNSS rejected: {m.get('gnss_rejected', 0)}",
        "",
    ]
    if m.get("forward"):
        out += _forward_smoothed_table(m)
    out += [
        "## Position error (m)" + (" of the smoothed solution" if m.get("forward") else ""),
        "",
        "Estimate minus reference in the local ENU frame of each reference point: "
        "east = longitude error, north = latitude error, up = height error, in metres; "
        "horizontal = hypot(east, north), 3d = norm of all three.",
        "",
    ]
    out += _stats_table(m.get("position_m", {}), _POSITION_ROWS, "m")
    if "velocity_mps" in m:
        out += ["", "## Velocity error (m/s)", "", "Estimate minus reference, ENU.", ""]
        out += _stats_table(m["velocity_mps"], _POSITION_ROWS, "m/s")
    if "attitude_deg" in m:
        out += ["", "## Attitude error (deg)", "",
                "Estimate minus reference, wrapped to [-180, 180).", ""]
        out += _stats_table(m["attitude_deg"], ("roll", "pitch", "heading"), "deg")
    if "gnss_position_m" in m:
        g = m["gnss_position_m"]
        out += ["", "## Raw GNSS position error (m)", "",
                "GNSS fixes minus the reference antenna position (reference interpolated to the "
                "GNSS epochs), local ENU: east = longitude error, north = latitude error.", ""]
        if "epochs" in g:
            out += [f"GNSS epochs compared: {g['epochs']}", ""]
        if "note" in g:
            out += [f"Note: {g['note']}", ""]
        if any(row in g for row in _POSITION_ROWS):
            out += _stats_table(g, _POSITION_ROWS, "m")
    if m.get("outages"):
        out += _outage_table(m["outages"])
    if m.get("updates"):
        out += ["", "## Measurement updates", "",
                "Updates the filter applied and the innovation gate rejected, per kind (gnss_position, "
                "gnss_velocity, zupt = zero velocity, zaru = zero angular rate, nhc = non-holonomic constraint).",
                "", "| kind | applied | rejected |", "|---|---:|---:|"]
        out += [f"| {k} | {v.get('applied', 0)} | {v.get('rejected', 0)} |" for k, v in m["updates"].items()]
    out += ["", f"GNSS epochs rejected by the filter: {m.get('gnss_rejected', 0)}", ""]
    return "\n".join(out)


def _forward_smoothed_table(m: Mapping[str, Any]) -> list[str]:
    """The "Forward and smoothed" section of a smoothed run's ``metrics.md``: the key RMSEs of
    both solutions side by side, with the ratio smoothed / forward."""
    f = m["forward"]
    rows: list[tuple[str, Any, Any]] = []
    for group, unit, axes in (("position_m", "m", ("east", "north", "up", "horizontal", "3d")),
                              ("velocity_mps", "m/s", ("east", "north", "up", "horizontal")),
                              ("attitude_deg", "deg", ("roll", "pitch", "heading"))):
        for axis in axes:
            a, b = (f.get(group) or {}).get(axis), (m.get(group) or {}).get(axis)
            if a is not None and b is not None:
                what = {"position_m": "position", "velocity_mps": "velocity", "attitude_deg": "attitude"}[group]
                rows.append((f"{what} {axis} RMSE ({unit})", a.get("rmse"), b.get("rmse")))
    for wf, ws in zip(f.get("outages") or [], m.get("outages") or []):
        if "horizontal_m" in wf and "horizontal_m" in ws:
            span = f"{float(wf['start_s']):g}-{float(wf['end_s']):g} s"
            rows.append((f"outage {span}: horizontal RMSE (m)", wf["horizontal_m"]["rmse"],
                         ws["horizontal_m"]["rmse"]))
            rows.append((f"outage {span}: horizontal error at end (m)", wf["horizontal_m"]["end"],
                         ws["horizontal_m"]["end"]))
    out = ["## Forward and smoothed", "",
           (f"The trajectory written is the forward filter's run smoothed backwards (Rauch-Tung-Striebel, "
            f"{m.get('smoother_nodes', '?')} nodes, {_num(m.get('smoothing_s'), 3)} s); the forward solution is in "
            "trajectory_forward.csv.  Errors against the reference; ratio = smoothed / forward."), "",
           "| | forward | smoothed | ratio |", "|---|---:|---:|---:|"]
    for name, a, b in rows:
        ratio = float(b) / float(a) if a is not None and b is not None and float(a) > 0 else None
        out.append(f"| {name} | {_num(a)} | {_num(b)} | {_num(ratio, 2)} |")
    return out + [""]


def _outage_table(windows: Any) -> list[str]:
    """The "Simulated GNSS outages" section of ``metrics.md``: one row per window."""
    out = ["", "## Simulated GNSS outages (m)", "",
           ("The GNSS fixes inside each window (s from the log start) were removed before filtering; "
            "the INS coasted.  Errors at the last reference epoch inside the window (end) and over "
            "the reference epochs inside it; horizontal = hypot(east, north), vertical = |up|.  "
            "The figures above are over the whole run, outages included."), "",
           ("| window (s) | fixes removed | epochs | horiz. end | horiz. max | horiz. RMSE "
            "| vert. end | vert. max | vert. RMSE |"),
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for w in windows:
        cells = [f"{float(w['start_s']):g}-{float(w['end_s']):g}", str(w.get("gnss_removed", "")),
                 str(w.get("epochs", 0))]
        for part in ("horizontal_m", "vertical_m"):
            s = w.get(part) or {}
            cells += [_num(s.get(k), 4) if k in s else "" for k in ("end", "max", "rmse")]
        out.append("| " + " | ".join(cells) + " |")
    return out


def write_metrics_md(path: str | os.PathLike[str], metrics: Mapping[str, Any]) -> None:
    """Write ``metrics.md``: :func:`metrics_markdown` of ``metrics``, atomically."""
    text = metrics_markdown(metrics)
    atomic_write(path, lambda f: f.write(text), mode="w")
