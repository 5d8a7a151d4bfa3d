"""What the report plots of a log and of each run, decimated where the run is (a worker).

Positions are in the log's local ENU frame (m) about its first GNSS fix; times in s since the
log start.  A series holds a few thousand numbers at most, so it travels cheaply from a worker
process (or a Dask worker) back to the process that draws the figures.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

#: Probabilities at which the horizontal-error CDF is sampled for the report.
CDF_POINTS = 201
# Points kept for the plots, about one per pixel column of a figure (or finer):
_TRACK_POINTS = 2000      # trajectory points per run (stride decimation)
_ERROR_BINS = 500         # error-vs-time bins; each keeps its minimum and maximum (spikes survive)
_DIAG_POINTS = 1000       # diagnostics points per run (stride)


@dataclass(frozen=True)
class LogSeries:
    """What the report plots of a log itself, in the log's local ENU frame (m) about ``anchor``
    (lat deg, lon deg, alt m: the first GNSS fix): the GNSS fixes and the reference track
    (None without a reference)."""

    anchor: tuple[float, float, float]
    gnss_east_m: np.ndarray
    gnss_north_m: np.ndarray
    ref_east_m: np.ndarray | None = None
    ref_north_m: np.ndarray | None = None


@dataclass(frozen=True)
class RunSeries:
    """What the report plots of one run, decimated.

    east_m, north_m : (K,) trajectory in the log's local ENU frame (m, see :class:`LogSeries`).
    err_t_s, err_h_m : (L,) horizontal position error (m) against the reference at reference
        epochs, time since log start (s); the minimum and maximum of each of up to 500 bins;
        None without a reference.
    cdf_m : (CDF_POINTS,) horizontal error (m) at probabilities ``linspace(0, 1, CDF_POINTS)``
        (linear quantiles of all reference epochs); None without a reference.
    adaptive : True for filters that adapt their noise (a noise adapter or adaptive factors).
    diag_t_s : (M,) GNSS epochs (s since log start); r_std_m : (M, 3) the measurement noise
        1-sigma used, E/N/U (m); factors : name -> (M,) adaptive scale factors (dimensionless,
        1 = as configured: VCE ``q_factor_*`` / ``r_factor_*``, the AUKF ``fading``).
    """

    east_m: np.ndarray
    north_m: np.ndarray
    err_t_s: np.ndarray | None = None
    err_h_m: np.ndarray | None = None
    cdf_m: np.ndarray | None = None
    adaptive: bool = False
    diag_t_s: np.ndarray | None = None
    r_std_m: np.ndarray | None = None
    factors: dict[str, np.ndarray] = field(default_factory=dict)


def stride_indices(n: int, keep: int) -> np.ndarray:
    """Indices of about ``keep`` evenly strided samples of ``n``, the last one always included."""
    import numpy as np

    if n <= keep:
        return np.arange(n)
    idx = np.arange(0, n, math.ceil(n / keep))
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def minmax_decimate(t: np.ndarray, y: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep, of each of ``bins`` equal runs of samples, its minimum and its maximum in time order:
    a line plot of the result shows every peak of the original.  NaNs are dropped first."""
    import numpy as np

    ok = np.isfinite(y)
    t, y = np.asarray(t, dtype=float)[ok], np.asarray(y, dtype=float)[ok]
    n = y.size
    if n <= 2 * bins:
        return t, y
    edges = np.linspace(0, n, bins + 1).astype(int)
    keep = []
    for a, b in itertools.pairwise(edges):
        i, j = a + int(np.argmin(y[a:b])), a + int(np.argmax(y[a:b]))
        keep += sorted({i, j})
    idx = np.asarray(keep)
    return t[idx], y[idx]


def plot_anchor(rec) -> Any:
    import numpy as np

    from ..io.frames import Anchor

    g = rec.gnss
    ok = np.flatnonzero(np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg) & np.isfinite(g.alt))
    if ok.size:
        i = int(ok[0])
        return Anchor(float(g.lat_deg[i]), float(g.lon_deg[i]), float(g.alt[i]))
    if rec.reference is not None and len(rec.reference.t):
        r = rec.reference
        return Anchor(float(r.lat_deg[0]), float(r.lon_deg[0]), float(r.alt[0]))
    return None


def log_series_of(rec) -> LogSeries | None:
    import numpy as np

    anchor = plot_anchor(rec)
    if anchor is None:
        return None
    g = rec.gnss
    ok = np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg) & np.isfinite(g.alt)
    gi = np.flatnonzero(ok)[stride_indices(int(ok.sum()), 2 * _TRACK_POINTS)]
    genu = anchor.enu(g.lat_deg[gi], g.lon_deg[gi], g.alt[gi]).reshape(-1, 3)
    ref_e = ref_n = None
    if rec.reference is not None:
        r = rec.reference
        rok = np.flatnonzero(np.isfinite(r.lat_deg) & np.isfinite(r.lon_deg) & np.isfinite(r.alt))
        ri = rok[stride_indices(rok.size, _TRACK_POINTS)]
        renu = anchor.enu(r.lat_deg[ri], r.lon_deg[ri], r.alt[ri]).reshape(-1, 3)
        ref_e, ref_n = renu[:, 0], renu[:, 1]
    return LogSeries((anchor.lat_deg, anchor.lon_deg, anchor.alt), genu[:, 0], genu[:, 1], ref_e, ref_n)


#: Adaptive entries plotted as scale factors (prefixes of the Diagnostics ``adaptive`` names).
FACTOR_PREFIXES = ("q_factor", "r_factor", "fading")


def run_series_of(rec, sol, diag, filt) -> RunSeries:
    """The plot series of one solution (forward or smoothed) with the run's diagnostics."""
    import numpy as np

    from ..metrics import associate, interpolate_solution, position_errors_enu

    anchor = plot_anchor(rec)
    si = stride_indices(len(sol.t), _TRACK_POINTS)
    if anchor is not None:
        enu = anchor.enu(sol.lat_deg[si], sol.lon_deg[si], sol.alt[si]).reshape(-1, 3)
        east, north = enu[:, 0], enu[:, 1]
    else:
        east = north = np.zeros(0)
    err_t = err_h = cdf = None
    if rec.reference is not None:
        ref = rec.reference
        ref_ok = np.isfinite(ref.lat_deg) & np.isfinite(ref.lon_deg) & np.isfinite(ref.alt)
        assoc = associate(np.asarray(sol.t, dtype=float), np.where(ref_ok, np.asarray(ref.t, dtype=float), np.nan),
                          skip_holes=True)
        if assoc.idx_ref.size:
            i = assoc.idx_ref
            est = interpolate_solution(sol, assoc.t)
            err = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"],
                                      ref.lat_deg[i], ref.lon_deg[i], ref.alt[i])
            h = np.hypot(err[:, 0], err[:, 1])
            err_t, err_h = minmax_decimate(assoc.t, h, _ERROR_BINS)
            cdf = np.quantile(h, np.linspace(0.0, 1.0, CDF_POINTS))
    factors = {k: np.asarray(v, dtype=float).reshape(len(diag.t), -1)[:, 0]
               for k, v in diag.adaptive.items()
               if k.startswith(FACTOR_PREFIXES) and np.asarray(v).reshape(len(diag.t), -1).shape[1] == 1}
    adaptive = filt.adapts_noise or bool(factors)
    di = stride_indices(len(diag.t), _DIAG_POINTS)
    return RunSeries(east, north, err_t, err_h, cdf, adaptive,
                     np.asarray(diag.t, dtype=float)[di] if adaptive else None,
                     np.asarray(diag.r_std, dtype=float)[di] if adaptive else None,
                     {k: v[di] for k, v in factors.items()} if adaptive else {})
