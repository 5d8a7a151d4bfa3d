"""The figures ``navpp process --plot`` writes beside a run's outputs.

The same figures as a ``navpp compare`` report draws for each log (:mod:`navpp.comparison.figures`),
for the one run (and, with ``--smooth``, its smoothed solution as ``<filter>+rts`` beside it):

- ``<log>_<filter>_errors.png``: the E, N, U and horizontal position error (m) against the
  reference with the solution's +-3-sigma band, GNSS outages shaded, the fixes the gate
  rejected and the forced ones marked; without a reference ``<log>_<filter>_innovations.png``
  instead: the GNSS innovations with their +-3 sqrt(S) band (the title says so);
- ``<log>_trajectory.png``: the track in the log's local ENU frame (m) with the GNSS fixes and
  the reference;
- ``<log>_adaptive.png`` (filters that adapt their noise): the measurement noise used and the
  adaptive scale factors;
- ``<log>_map.html``: a self-contained, zoomable overview map (:mod:`navpp.mapview`).

``<log>`` is the log's file or directory name with anything but ``A-Za-z0-9._-`` replaced.
PNGs are drawn with matplotlib's Agg canvas (the caller's pyplot backend is not touched).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

__all__ = ["PLOT_KINDS", "plot_outputs", "process_plots"]

#: The figure kinds of :mod:`navpp.comparison.figures` that ``process --plot`` draws, in order.
PLOT_KINDS = ("run_errors", "trajectory", "adaptive", "map")


def process_plots(log: str | Path, rec: Any, result: Any, filt: Any, filter_name: str,
                  windows: Sequence[tuple[float, float]] = ()) -> list[Any]:
    """The figures of one ``process`` run (:class:`~navpp.comparison.figures.Plot` list).

    rec : the recording the run used (simulated outages removed); result : the engine's
    ``RunResult`` (full-rate solutions, diagnostics; ``result.smoothed`` when smoothed);
    filt : the filter instance; windows : the simulated GNSS outages ``(start_s, duration_s)``.
    """
    from .comparison.figures import FigureJob, figure_colors, figure_slugs, render_figures
    from .comparison.rows import smoothed_name
    from .comparison.series import log_series_of, run_series_of

    runs = {filter_name: run_series_of(rec, result.solution, result.diagnostics, filt)}
    if result.smoothed is not None:   # the diagnostics are the forward filter's: drawn once, with it
        runs[smoothed_name(filter_name)] = replace(
            run_series_of(rec, result.smoothed.solution, result.diagnostics, filt), adaptive=False,
            diag_t_s=None, r_std_m=None, factors={}, innovations=None)
    slug = figure_slugs([str(log)])[str(log)]
    job = FigureJob(str(log), slug, log_series_of(rec, tuple(windows)), runs, figure_colors(list(runs)),
                    kinds=PLOT_KINDS)
    plots = render_figures(job)
    order = {k: i for i, k in enumerate(PLOT_KINDS)}

    def kind(p: Any) -> int:
        if p.name.endswith(("_errors.png", "_innovations.png")):
            return order["run_errors"]
        return next((order[k] for k in PLOT_KINDS if p.name.endswith(f"_{k}.png") or p.name.endswith(f"_{k}.html")),
                    len(order))

    return sorted(plots, key=kind)


def plot_outputs(log: str | Path, rec: Any, result: Any, filt: Any, filter_name: str,
                 windows: Sequence[tuple[float, float]] = ()) -> list[tuple[str, Callable[[Path], None]]]:
    """``(file name, writer(path))`` of every figure of the run, for
    :func:`navpp.api.write_outputs` (the figures are drawn here, before anything is written)."""
    def writer(data: bytes) -> Callable[[Path], None]:
        def write(path: Path) -> None:
            Path(path).write_bytes(data)
        return write

    return [(str(p.name), writer(p.png)) for p in process_plots(log, rec, result, filt, filter_name, windows)]
