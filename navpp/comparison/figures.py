"""The figures of a comparison report, drawn per log with matplotlib's object API.

- ``<log>_trajectory.png``: the filters' trajectories, the GNSS fixes and the reference in the
  log's local ENU frame (m, equal axes; origin: the first GNSS fix);
- ``<log>_error_time.png``: horizontal position error (m) versus time since log start (s);
- ``<log>_error_cdf.png``: the cumulative distribution of the horizontal error;
- ``<log>_adaptive.png`` (filters that adapt their noise only): the measurement-noise 1-sigma
  the filter used (E/N/U, m) and its adaptive scale factors (VCE ``q_factor_*``/``r_factor_*``,
  the AUKF fading factor; dimensionless, 1 = as configured) versus time.

A :class:`FigureJob` is plain data (it pickles), so a worker process or a Dask worker can draw
a log's figures as soon as that log's runs are done.  Figures are drawn with ``Figure`` +
Agg, so the caller's pyplot backend is never touched; matplotlib is imported when a figure is
drawn.
"""

from __future__ import annotations

import io
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .rows import SMOOTHED_SUFFIX, smoothed_name

if TYPE_CHECKING:
    from .runs import RunOutcome, RunTask
    from .series import LogSeries, RunSeries

#: File-name endings of the figures; files with these endings that a run did not write are
#: removed from the output directory (they belong to an earlier comparison).
FIGURE_SUFFIXES = ("_trajectory.png", "_error_time.png", "_error_cdf.png", "_adaptive.png")
_DPI = 110


@dataclass(frozen=True)
class Plot:
    """One figure: its file name, a caption, and the PNG bytes."""

    name: str
    caption: str
    png: bytes


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
    for name, s in runs.items():
        ax.plot(s.east_m, s.north_m, _line(name, runs), lw=1.0, color=colors[name], label=name)
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
    for name, s in with_err.items():
        ax.plot(s.err_t_s, s.err_h_m, _line(name, runs), lw=0.8, color=colors[name], label=name)
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
    for name, s in with_err.items():
        ax.plot(s.cdf_m, np.linspace(0.0, 1.0, len(s.cdf_m)), _line(name, runs), lw=1.2, color=colors[name],
                label=name)
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
    for name, s in adapt.items():
        for j, (axis, ls) in enumerate((("E", "-"), ("N", "--"), ("U", ":"))):
            axes[0].plot(s.diag_t_s, s.r_std_m[:, j], ls, lw=1.0, color=colors[name], label=f"{name} R {axis}")
    axes[0].set_ylabel("measurement noise R, 1σ, m")
    axes[0].set_title(f"{label}: adaptive noise (R 1σ per axis: E solid, N dashed, U dotted)", fontsize=10)
    axes[0].grid(True, lw=0.4, alpha=0.6)
    axes[0].legend(fontsize=7, ncol=3, loc="upper right")
    if with_factors:
        styles = ["-", "--", ":", "-."]
        for name, s in adapt.items():
            for k, (key, values) in enumerate(s.factors.items()):
                axes[1].plot(s.diag_t_s, values, styles[k % len(styles)], lw=1.0, color=colors[name],
                             label=f"{name} {key}")
        axes[1].axhline(1.0, color="0.5", lw=0.6)
        axes[1].set_ylabel("adaptive scale factor, - (1 = as configured)")
        axes[1].set_yscale("log")
        axes[1].grid(True, lw=0.4, alpha=0.6)
        axes[1].legend(fontsize=7, ncol=2, loc="upper right")
    axes[-1].set_xlabel("time since log start, s")
    return Plot(f"{slug}_adaptive.png", f"{label}: adaptive R (m) and Q/R scale factors versus time (s)", _png(fig))


#: The figures of a log, in report order.
FIGURE_KINDS = ("trajectory", "error_time", "error_cdf", "adaptive")


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

    def job(self, log: str, outcomes: Sequence[RunOutcome]) -> FigureJob:
        """Every figure of ``log`` from the outcomes of its runs (only ok runs are drawn)."""
        log_series = next((o.log_series for o in outcomes if o.log_series is not None), None)
        runs = {row.filter: series for o in outcomes for row, series in o.rows() if row.ok and series is not None}
        return FigureJob(log, self.slugs[log], log_series, runs, self.colors)


def plots_by_log(tasks: Sequence[RunTask], drawn: Mapping[tuple[str, str], list[Plot]]) -> dict[str, list[Plot]]:
    """The figures drawn per (log, figure kind) as each log's list, in report order."""
    return {log: [p for kind in FIGURE_KINDS for p in drawn.get((log, kind), [])]
            for log in dict.fromkeys(t.log for t in tasks)}
