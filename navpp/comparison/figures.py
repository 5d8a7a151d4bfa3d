"""The figures of a comparison report, drawn per log with matplotlib's object API.

- ``<log>_trajectory.png``: the filters' trajectories, the GNSS fixes and the reference in the
  log's local ENU frame (m, equal axes; origin: the first GNSS fix);
- ``<log>_error_time.png``: horizontal position error (m) versus time since log start (s);
- ``<log>_error_cdf.png``: the cumulative distribution of the horizontal error;
- ``<log>_adaptive.png`` (filters that adapt their noise only): the measurement-noise 1-sigma
  the filter used (E/N/U, m) and its adaptive scale factors (VCE ``q_factor_*``/``r_factor_*``,
  the AUKF fading factor; dimensionless, 1 = as configured; a colour per factor) versus time;
- ``<log>_<filter>_errors.png`` per run: the E, N, U and horizontal position error (m) against
  the reference with the solution's +-3-sigma band, GNSS outages shaded, rejected and forced
  fixes marked (:func:`run_error_figure`); without a reference ``<log>_<filter>_innovations.png``,
  the GNSS innovations with their +-3 sqrt(S) band, instead;
- ``<log>_map.html``: an overview map of the log (:mod:`navpp.mapview`): the tracks, the GNSS
  fixes, the reference and the GNSS outages.

Runs whose positions coincide (:func:`position_groups`: within 1 mm, or closer than about two
pixels of the error axis) are drawn once, labelled ``"ckf = ukf (identical)"`` or ``"ckf ≈ ukf
(lines coincide, differ ≤ 4.4 mm)"``, so no line hides another unsaid.

A :class:`FigureJob` is plain data (it pickles), so a worker process or a Dask worker can draw
a log's figures as soon as that log's runs are done.  Figures are drawn with ``Figure`` +
Agg, so the caller's pyplot backend is never touched; matplotlib is imported when a figure is
drawn.
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .rows import SMOOTHED_SUFFIX, smoothed_name

if TYPE_CHECKING:       # (not .runs: it imports navpp.api, which imports navpp.plots, which imports this)
    from .series import LogSeries, RunSeries

_DPI = 110
#: Two runs' plotted values within this (m, or the unit of the series) are "identical".
COINCIDE_TOL = 1e-3


@dataclass(frozen=True)
class Plot:
    """One figure: its file name, a caption, and the file's bytes (PNG; HTML for a map)."""

    name: str
    caption: str
    png: bytes

    @property
    def is_page(self) -> bool:
        """True for an HTML page (the map), False for a PNG figure."""
        return self.name.endswith(".html")


def _spans(series: Mapping[str, Sequence]) -> list[float]:
    """Per array position, the range of the finite values over every series (0 if none)."""
    import numpy as np

    spans: list[float] = []
    for arrays in series.values():
        for k, x in enumerate(arrays):
            if len(spans) <= k:
                spans.append(0.0)
            if x is None:
                continue
            v = np.asarray(x, dtype=float)
            v = v[np.isfinite(v)]
            if v.size:
                spans[k] = max(spans[k], float(v.max() - v.min()))
    return spans


def max_difference(a: Sequence, b: Sequence) -> float:
    """The largest absolute difference between two series of arrays of the same shapes (NaN
    against NaN counts 0, NaN against a number inf; shapes that differ: inf)."""
    import numpy as np

    if len(a) != len(b):
        return math.inf
    worst = 0.0
    for x, y in zip(a, b):
        if x is None or y is None:
            if (x is None) != (y is None):
                return math.inf
            continue
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        if x.shape != y.shape:
            return math.inf
        nan = np.isnan(x)
        if not np.array_equal(nan, np.isnan(y)):
            return math.inf
        if x.size and (~nan).any():
            worst = max(worst, float(np.max(np.abs(x[~nan] - y[~nan]))))
    return worst


def coincident_groups(series: Mapping[str, Sequence], tol: float = COINCIDE_TOL,
                      rel: float = 0.0) -> list[tuple[str, ...]]:
    """Group names whose series coincide: every array of the one has the same shape as the
    other's and differs from it by at most ``max(tol, rel * span)`` everywhere, ``span`` the
    range of that array over all the series (``rel`` ~ 2e-3: closer than a line's width on a
    500-pixel axis; NaN equals NaN).  Groups in first-seen order, each in the order given; a
    name that coincides with none is a group of its own."""
    limits = [max(tol, rel * sp) for sp in _spans(series)]

    def same(a: Sequence, b: Sequence) -> bool:
        if len(a) != len(b):
            return False
        return all(max_difference((x,), (y,)) <= limits[k] for k, (x, y) in enumerate(zip(a, b)))

    groups: list[list[str]] = []
    for name, arrays in series.items():
        for g in groups:
            if same(series[g[0]], arrays):
                g.append(name)
                break
        else:
            groups.append([name])
    return [tuple(g) for g in groups]


def identical_label(group: Sequence[str], difference: float = 0.0, unit: str = "m") -> str:
    """The legend text of a group of coinciding runs: ``"ckf = ukf (identical)"`` when they differ
    by at most :data:`COINCIDE_TOL`, else ``"ckf ≈ ukf (lines coincide, differ ≤ 4.4 mm)"``; a
    group of one: the name."""
    if len(group) == 1:
        return group[0]
    if difference <= COINCIDE_TOL:
        return " = ".join(group) + " (identical)"
    size = f"{difference * 1000:.1f} mm" if unit == "m" and difference < 1 else f"{difference:.3g} {unit}".strip()
    return " ≈ ".join(group) + f" (lines coincide, differ ≤ {size})"


def _drawn(runs: Mapping[str, RunSeries], arrays, rel: float = 0.0, tol: float = COINCIDE_TOL
           ) -> list[tuple[str, str]]:
    """(name drawn, legend label) per group of runs whose ``arrays(series)`` coincide
    (:func:`coincident_groups` with ``tol`` and ``rel``)."""
    series = {n: arrays(s) for n, s in runs.items()}
    out = []
    for g in coincident_groups(series, tol=tol, rel=rel):
        diff = max((max_difference(series[g[0]], series[n]) for n in g[1:]), default=0.0)
        out.append((g[0], identical_label(g, diff)))
    return out


#: Runs whose positions differ by less than this fraction of the error axis (the range of their
#: error CDFs) coincide on the error figures: about 2 pixels of an 800-pixel axis.
POSITION_COINCIDE_REL = 5e-3


def position_groups(runs: Mapping[str, RunSeries]) -> list[tuple[str, str]]:
    """(name drawn, legend label) per group of runs whose positions coincide on the figures: the
    same trajectory points (E, N, m; strided alike, so point for point) and error quantiles
    within ``max(COINCIDE_TOL, POSITION_COINCIDE_REL x the error range)`` m (identical within
    :data:`COINCIDE_TOL` without a reference).  Every position figure of a log uses these."""
    import numpy as np

    spans = [float(np.nanmax(s.cdf_m) - np.nanmin(s.cdf_m)) for s in runs.values()
             if s.cdf_m is not None and np.isfinite(s.cdf_m).any()]
    tol = max([COINCIDE_TOL] + [POSITION_COINCIDE_REL * sp for sp in spans])
    return _drawn(runs, lambda s: (s.east_m, s.north_m, s.cdf_m), tol=tol)


def log_label(log: str) -> str:
    """How a log is named in the report: its last path component."""
    return Path(log).name or log


def figure_slugs(logs: Sequence[str]) -> dict[str, str]:
    """A file-name stem per log: its label with anything but ``A-Za-z0-9._-`` replaced, made
    unique with ``-2``, ``-3``, ... ."""
    out: dict[str, str] = {}
    used: set[str] = set()
    for log in logs:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", log_label(log)).strip("._") or "log"
        slug, k = base, 2
        while slug in used:
            slug, k = f"{base}-{k}", k + 1
        used.add(slug)
        out[log] = slug
    return out


def _png(fig) -> bytes:
    """The figure as PNG bytes (no software tag: the same figure gives the same bytes)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata={"Software": None})
    return buf.getvalue()


def figure_colors(filters: Sequence[str]) -> dict[str, str]:
    """A colour per filter; a smoothed run (``<filter>+rts``) shares its forward filter's colour
    (:func:`_line` tells them apart by the line style)."""
    palette = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
               "tab:olive", "tab:cyan"]
    bases = list(dict.fromkeys(f.removesuffix(SMOOTHED_SUFFIX) for f in filters))
    return {f: palette[bases.index(f.removesuffix(SMOOTHED_SUFFIX)) % len(palette)] for f in filters}


def _line(name: str, runs: Mapping[str, RunSeries]) -> str:
    """Line style: dashed for a forward run whose smoothed run is plotted too, else solid."""
    return "--" if smoothed_name(name) in runs else "-"


def _trajectory_figure(label: str, slug: str, log_series: LogSeries | None, runs: Mapping[str, RunSeries],
                       colors: Mapping[str, str]) -> Plot | None:
    from matplotlib.figure import Figure

    if log_series is None and not runs:
        return None
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    ax = fig.add_subplot()
    if log_series is not None:
        ax.plot(log_series.gnss_east_m, log_series.gnss_north_m, ".", ms=2.5, color="0.6", label="GNSS fixes")
        if log_series.ref_east_m is not None:
            ax.plot(log_series.ref_east_m, log_series.ref_north_m, "-", color="black", lw=1.8, label="reference")
        lat, lon, alt = log_series.anchor
        ax.set_title(f"{label}: trajectories, local ENU about the first GNSS fix\n"
                     f"({lat:.6f}°, {lon:.6f}°, {alt:.1f} m)", fontsize=10)
    for name, legend in position_groups(runs):
        s = runs[name]
        ax.plot(s.east_m, s.north_m, _line(name, runs), lw=1.0, color=colors[name], label=legend)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.legend(fontsize=8, loc="best")
    return Plot(f"{slug}_trajectory.png", f"{label}: trajectories in local ENU (m) with the GNSS fixes", _png(fig))


def _error_time_figure(label: str, slug: str, runs: Mapping[str, RunSeries], colors: Mapping[str, str]
                       ) -> Plot | None:
    from matplotlib.figure import Figure

    with_err = {n: s for n, s in runs.items() if s.err_h_m is not None}
    if not with_err:
        return None
    fig = Figure(figsize=(8.5, 4.2), layout="constrained")
    ax = fig.add_subplot()
    for name, legend in position_groups(with_err):
        s = with_err[name]
        ax.plot(s.err_t_s, s.err_h_m, _line(name, runs), lw=0.8, color=colors[name], label=legend)
    ax.set_xlabel("time since log start, s")
    ax.set_ylabel("horizontal position error, m")
    ax.set_title(f"{label}: horizontal error against the reference", fontsize=10)
    ax.set_ylim(bottom=0.0)
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.legend(fontsize=8, loc="upper right")
    return Plot(f"{slug}_error_time.png", f"{label}: horizontal position error (m) versus time (s)", _png(fig))


def _error_cdf_figure(label: str, slug: str, runs: Mapping[str, RunSeries], colors: Mapping[str, str]
                      ) -> Plot | None:
    import numpy as np
    from matplotlib.figure import Figure

    with_err = {n: s for n, s in runs.items() if s.cdf_m is not None}
    if not with_err:
        return None
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.add_subplot()
    for name, legend in position_groups(with_err):
        s = with_err[name]
        ax.plot(s.cdf_m, np.linspace(0.0, 1.0, len(s.cdf_m)), _line(name, runs), lw=1.2, color=colors[name],
                label=legend)
    ax.axhline(0.95, color="0.5", lw=0.6, ls="--", label="95 %")
    ax.set_xlabel("horizontal position error, m")
    ax.set_ylabel("fraction of reference epochs, -")
    ax.set_ylim(0.0, 1.0)
    ax.set_xlim(left=0.0)
    ax.set_title(f"{label}: cumulative distribution of the horizontal error", fontsize=10)
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.legend(fontsize=8, loc="lower right")
    return Plot(f"{slug}_error_cdf.png", f"{label}: horizontal error CDF (m)", _png(fig))


def _adaptive_figure(label: str, slug: str, runs: Mapping[str, RunSeries], colors: Mapping[str, str]
                     ) -> Plot | None:
    from matplotlib.figure import Figure

    adapt = {n: s for n, s in runs.items() if s.adaptive and s.diag_t_s is not None and len(s.diag_t_s)}
    if not adapt:
        return None
    with_factors = any(s.factors for s in adapt.values())
    fig = Figure(figsize=(8.5, 6.5 if with_factors else 4.2), layout="constrained")
    axes = fig.subplots(2 if with_factors else 1, 1, sharex=True, squeeze=False)[:, 0]
    for name, legend in _drawn(adapt, lambda s: (s.diag_t_s, s.r_std_m)):
        s = adapt[name]
        for j, (axis, ls) in enumerate((("E", "-"), ("N", "--"), ("U", ":"))):
            axes[0].plot(s.diag_t_s, s.r_std_m[:, j], ls, lw=1.0, color=colors[name], label=f"{legend} R {axis}")
    axes[0].set_ylabel("measurement noise R, 1σ, m")
    axes[0].set_title(f"{label}: adaptive noise (R 1σ per axis: E solid, N dashed, U dotted)", fontsize=10)
    axes[0].grid(True, lw=0.4, alpha=0.6)
    axes[0].legend(fontsize=7, ncol=3, loc="upper right")
    if with_factors:
        # a colour per factor (qualitative colormap), a line style per filter
        styles = ["-", "--", ":", "-."]
        keys = list(dict.fromkeys(k for s in adapt.values() for k in s.factors))
        fcolors = factor_colors(keys)
        with_f = {n: s for n, s in adapt.items() if s.factors}
        drawn = _drawn(with_f, lambda s: (s.diag_t_s, *(s.factors.get(k) for k in keys)))
        for j, (name, legend) in enumerate(drawn):
            s = with_f[name]
            # factors of one run that coincide (e.g. several left at 1) are drawn once, named together
            for group in coincident_groups({k: (v,) for k, v in s.factors.items()}):
                text = identical_label(group)
                axes[1].plot(s.diag_t_s, s.factors[group[0]], styles[j % len(styles)], lw=1.0,
                             color=fcolors[group[0]], label=f"{legend}: {text}" if len(drawn) > 1 else text)
        if len(drawn) == 1:
            axes[1].set_title(f"adaptive scale factors of {drawn[0][1]}", fontsize=9)
        axes[1].axhline(1.0, color="0.5", lw=0.6)
        axes[1].set_ylabel("adaptive scale factor, - (1 = as configured)")
        axes[1].set_yscale("log")
        axes[1].grid(True, lw=0.4, alpha=0.6)
        axes[1].legend(fontsize=7, ncol=2, loc="upper right")
    axes[-1].set_xlabel("time since log start, s")
    return Plot(f"{slug}_adaptive.png", f"{label}: adaptive R (m) and Q/R scale factors versus time (s)", _png(fig))


def factor_colors(keys: Sequence[str]) -> dict[str, tuple[float, ...]]:
    """A distinct colour per adaptive factor name (matplotlib's qualitative ``tab10``, then
    ``tab20`` for more than ten)."""
    from matplotlib import colormaps

    cmap = colormaps["tab10" if len(keys) <= 10 else "tab20"]
    return {k: tuple(cmap(i % cmap.N)) for i, k in enumerate(keys)}


def _shade_gaps(ax, gaps: Sequence[tuple[float, float]], label: bool) -> None:
    for k, (a, b) in enumerate(gaps):
        ax.axvspan(a, b, color="tab:orange", alpha=0.15, lw=0, label="GNSS outage" if label and k == 0 else None)


def _mark_fixes(ax, s: RunSeries, label: bool) -> None:
    """Rejected (red down triangles) and forced (purple up triangles) fixes along the axis bottom."""
    for t, marker, color, what in ((s.rejected_t_s, "v", "tab:red", "rejected fix"),
                                   (s.forced_t_s, "^", "tab:purple", "forced fix")):
        if t is not None and len(t):
            ax.plot(t, [0.03] * len(t), marker, ms=4, color=color, transform=ax.get_xaxis_transform(),
                    clip_on=True, label=f"{what} ({len(t)})" if label else None, ls="none")


def run_error_figure(label: str, slug: str, name: str, s: RunSeries, gaps: Sequence[tuple[float, float]] = (),
                     color: str = "tab:blue", legend: str | None = None) -> Plot | None:
    """One run's position error per axis (E, N, U, horizontal; m) against the reference with the
    solution's +-3-sigma band (:class:`~navpp.comparison.series.ErrorBand`: ``3 std_e/n/u``; the
    horizontal bound ``3 hypot(std_e, std_n)``), GNSS outages shaded, rejected and forced fixes
    marked.  Without a reference: the GNSS innovations (E, N, U) with +-3 sqrt(S).  None when
    there is neither."""
    from matplotlib.figure import Figure

    band, inno = s.band, s.innovations
    if band is None and inno is None:
        return None
    fname = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "run"
    name = legend or name
    rows = 4 if band is not None else 3
    height = 8.0 if rows == 4 else 6.4
    fig = Figure(figsize=(8.5, height))       # fixed margins: a constrained layout doubles the drawing time
    fig.subplots_adjust(left=0.085, right=0.985, top=1 - 0.35 / height, bottom=0.5 / height, hspace=0.12)
    axes = fig.subplots(rows, 1, sharex=True)
    if band is not None:
        t = band.t_s
        panels = [(band.err_enu_m[:, j], band.band_enu_m[:, j], f"{axis} error, m", True)
                  for j, axis in enumerate("ENU")]
        panels.append((band.err_h_m, band.band_h_m, "horizontal error, m", False))
        title = f"{label}, {name}: position error against the reference with the ±3σ band of the solution"
    else:
        assert inno is not None
        t = inno.t_s
        panels = [(inno.nu_enu_m[:, j], 3.0 * inno.s_std_enu_m[:, j], f"{axis} innovation, m", True)
                  for j, axis in enumerate("ENU")]
        title = (f"{label}, {name}: no reference, so GNSS innovations (fix - prediction) with ±3√S, "
                 f"S ≈ P + R per axis")
    for k, (ax, (y, b, ylabel, two_sided)) in enumerate(zip(axes, panels)):
        _shade_gaps(ax, gaps, k == 0)
        ax.fill_between(t, -b if two_sided else 0.0 * b, b, color=color, alpha=0.18, lw=0,
                        label="±3σ" if k == 0 and band is not None else "±3√S" if k == 0 else None)
        ax.plot(t, y, "-", lw=0.7, color=color, label=name if k == 0 else None)
        _mark_fixes(ax, s, k == 0)
        ax.set_ylabel(ylabel)
        ax.grid(True, lw=0.4, alpha=0.6)
        if not two_sided:
            ax.set_ylim(bottom=0.0)
    axes[0].set_title(title, fontsize=9.5)
    axes[0].legend(fontsize=7, ncol=5, loc="upper right")
    axes[-1].set_xlabel("time since log start, s")
    what = "position error (m) with ±3σ" if band is not None else "GNSS innovations (m) with ±3√S"
    kind = "errors" if band is not None else "innovations"
    return Plot(f"{slug}_{fname}_{kind}.png", f"{label}, {name}: {what} versus time (s); GNSS outages shaded, "
                f"rejected and forced fixes marked", _png(fig))


def _run_errors(label: str, slug: str, log_series: LogSeries | None, runs: Mapping[str, RunSeries],
                colors: Mapping[str, str]) -> list[Plot]:
    gaps = log_series.gaps_s if log_series is not None else ()
    plots = []
    # a figure per run; runs whose positions coincide (position_groups) share one
    for name, legend in position_groups(runs):
        p = run_error_figure(label, slug, name, runs[name], gaps, colors.get(name, "tab:blue"), legend)
        if p is not None:
            plots.append(p)
    return plots


def log_map(label: str, slug: str, log_series: LogSeries | None, runs: Mapping[str, RunSeries],
            colors: Mapping[str, str]) -> Plot | None:
    """The log's overview map (:mod:`navpp.mapview`) as ``<slug>_map.html``: each run's track
    (coinciding ones once), the reference, the GNSS fixes (rejected ones of the first run
    crossed) and the GNSS outages (the first run's track inside them)."""
    from matplotlib.colors import to_hex

    from ..mapview import MapLayer, decimate_track, map_html

    layers = []
    first = next((s for s in runs.values() if s.lat_deg is not None and s.track_t_s is not None), None)
    if log_series is not None and log_series.gnss_lat_deg is not None:
        layers.append(MapLayer("GNSS fixes", "points", "#777777",
                               ((log_series.gnss_lat_deg, log_series.gnss_lon_deg),), width=4.0))
    if log_series is not None and log_series.ref_lat_deg is not None:
        layers.append(MapLayer("reference", "line", "#000000",
                               (decimate_track(log_series.ref_lat_deg, log_series.ref_lon_deg),), width=3.0))
    with_track = {n: s for n, s in runs.items() if s.lat_deg is not None}

    for name, legend in position_groups(with_track):
        s = with_track[name]
        layers.append(MapLayer(legend, "line", to_hex(colors.get(name, "tab:blue")),
                               (decimate_track(s.lat_deg, s.lon_deg),), width=2.0))
    if (log_series is not None and log_series.gaps_s and first is not None and first.lat_deg is not None
            and first.lon_deg is not None and first.track_t_s is not None):
        segs = []
        for a, b in log_series.gaps_s:
            inside = (first.track_t_s >= a) & (first.track_t_s <= b)
            if inside.sum() >= 2:
                segs.append((first.lat_deg[inside], first.lon_deg[inside]))
        if segs:
            layers.append(MapLayer(f"GNSS outages ({len(log_series.gaps_s)})", "line", "#ff8c00", tuple(segs),
                                   width=6.0))
    if (first is not None and first.rejected_lat_deg is not None and first.rejected_lon_deg is not None
            and len(first.rejected_lat_deg)):
        layers.append(MapLayer(f"rejected fixes ({len(first.rejected_lat_deg)})", "points", "#d62728",
                               ((first.rejected_lat_deg, first.rejected_lon_deg),), width=5.0, marker="cross"))
    if not layers or not any(len(seg[0]) for ly in layers for seg in ly.segments):
        return None
    notes = []
    if log_series is not None:
        lat, lon, alt = log_series.anchor
        notes.append(f"First GNSS fix: {lat:.6f}°, {lon:.6f}°, {alt:.1f} m.")
    return Plot(f"{slug}_map.html", f"{label}: overview map (tracks, GNSS fixes, outages; zoom and pan)",
                map_html(f"{label}: overview map", layers, notes).encode("utf-8"))


#: The figures of a log, in report order.
FIGURE_KINDS = ("trajectory", "error_time", "error_cdf", "adaptive", "run_errors", "map")


@dataclass(frozen=True)
class FigureJob:
    """What :func:`render_figures` needs to draw figures of one log (plain data: it pickles, so
    a worker process can draw them): ``runs`` maps filter -> series of the log's ok runs;
    ``kinds`` the figures to draw (:data:`FIGURE_KINDS`)."""

    log: str
    slug: str
    log_series: LogSeries | None
    runs: dict[str, RunSeries]
    colors: dict[str, str]
    kinds: tuple[str, ...] = FIGURE_KINDS


def render_figures(job: FigureJob) -> list[Plot]:
    """Draw the job's figures (those that have something to show), in :data:`FIGURE_KINDS` order."""
    label = log_label(job.log)
    plots = []
    for kind in FIGURE_KINDS:
        if kind not in job.kinds:
            continue
        if kind == "trajectory":
            p = _trajectory_figure(label, job.slug, job.log_series, job.runs, job.colors)
        elif kind == "run_errors":
            plots += _run_errors(label, job.slug, job.log_series, job.runs, job.colors)
            continue
        elif kind == "map":
            p = log_map(label, job.slug, job.log_series, job.runs, job.colors)
        else:
            draw = {"error_time": _error_time_figure, "error_cdf": _error_cdf_figure, "adaptive": _adaptive_figure}
            p = draw[kind](label, job.slug, job.runs, job.colors)
        if p is not None:
            plots.append(p)
    return plots


def figure_names(logs: Sequence[str], filters: Sequence[str]) -> tuple[dict[str, str], dict[str, str]]:
    """File-name stems per log (unique, file-system safe) and a colour per filter, shared by
    every figure of a comparison."""
    return figure_slugs(logs), figure_colors(filters)


class FigurePlan:
    """Which figures to draw: file stems per log and a colour per filter, fixed before any run
    finishes so that a log's figures can be drawn as soon as its own runs are done."""

    def __init__(self, logs: Sequence[str], filters: Sequence[str]) -> None:
        self.slugs, self.colors = figure_names(logs, filters)

    def job(self, log: str, outcomes: Sequence[Any]) -> FigureJob:
        """Every figure of ``log`` from the outcomes of its runs (:class:`~navpp.comparison.runs.RunOutcome`;
        only ok runs are drawn)."""
        log_series = next((o.log_series for o in outcomes if o.log_series is not None), None)
        runs = {row.filter: series for o in outcomes for row, series in o.rows() if row.ok and series is not None}
        return FigureJob(log, self.slugs[log], log_series, runs, self.colors)


def plots_by_log(tasks: Sequence[Any], drawn: Mapping[tuple[str, str], list[Plot]]) -> dict[str, list[Plot]]:
    """The figures drawn per (log, figure kind) as each log's list, in report order (``tasks``:
    the :class:`~navpp.comparison.runs.RunTask` of the comparison)."""
    return {log: [p for kind in FIGURE_KINDS for p in drawn.get((log, kind), [])]
            for log in dict.fromkeys(t.log for t in tasks)}
