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
    gnss_lat_deg: np.ndarray | None = None      # the same fixes, geodetic WGS-84 (deg), for the map
    gnss_lon_deg: np.ndarray | None = None
    ref_lat_deg: np.ndarray | None = None       # the same reference points, geodetic WGS-84 (deg)
    ref_lon_deg: np.ndarray | None = None
    gaps_s: tuple[tuple[float, float], ...] = ()   # GNSS outages (start, end), s since log start (:func:`gnss_gaps`)


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
    lat_deg: np.ndarray | None = None           # the trajectory points of east_m/north_m, WGS-84 deg
    lon_deg: np.ndarray | None = None
    band: ErrorBand | None = None               # per-axis error with the 3-sigma band (reference needed)
    innovations: InnovationBand | None = None   # GNSS innovations with their 3 sqrt(S) band
    rejected_t_s: np.ndarray | None = None      # fixes the gate rejected, s since log start
    forced_t_s: np.ndarray | None = None        # fixes forced in after a run of rejections, s
    track_t_s: np.ndarray | None = None         # times of the trajectory points, s since log start
    rejected_lat_deg: np.ndarray | None = None  # where the rejected fixes were (the fixes' WGS-84 deg)
    rejected_lon_deg: np.ndarray | None = None


@dataclass(frozen=True)
class ErrorBand:
    """Position error of a solution against the reference, per ENU axis, with the solution's own
    1-sigma at the same epochs (decimated: every bin's extremes of each axis are kept).

    t_s : (K,) reference epochs, s since log start.
    err_enu_m : (K, 3) estimate minus reference, local ENU of the reference point, m.
    std_enu_m : (K, 3) the solution's position 1-sigma (std_e/std_n/std_u) interpolated to
        ``t_s`` (linear, :func:`navpp.metrics.interpolate_solution`), m.
    """

    t_s: np.ndarray
    err_enu_m: np.ndarray
    std_enu_m: np.ndarray

    @property
    def band_enu_m(self) -> np.ndarray:
        """(K, 3) the half-width of the +-3-sigma band per axis, m: ``3 * std_enu_m``."""
        return 3.0 * self.std_enu_m

    @property
    def err_h_m(self) -> np.ndarray:
        """(K,) horizontal error ``hypot(east, north)``, m."""
        import numpy as np

        return np.hypot(self.err_enu_m[:, 0], self.err_enu_m[:, 1])

    @property
    def band_h_m(self) -> np.ndarray:
        """(K,) the 3-sigma bound of the horizontal error, m: ``3 * hypot(std_e, std_n)``."""
        import numpy as np

        return 3.0 * np.hypot(self.std_enu_m[:, 0], self.std_enu_m[:, 1])


@dataclass(frozen=True)
class InnovationBand:
    """GNSS position innovations (fix minus prediction, ENU m) at the GNSS epochs with their
    predicted 1-sigma per axis, ``sqrt(S_ii)`` with ``S_ii ~ P_ii + R_ii``: P the solution's
    position variance just before the fix (the last solution row before it), R the measurement
    noise the filter used (the lever arm's attitude term and the cross terms are left out).

    t_s : (M,) s since log start; nu_enu_m : (M, 3) m; s_std_enu_m : (M, 3) m;
    accepted : (M,) bool, the gate's decision."""

    t_s: np.ndarray
    nu_enu_m: np.ndarray
    s_std_enu_m: np.ndarray
    accepted: np.ndarray


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


def minmax_indices(y: np.ndarray, bins: int) -> np.ndarray:
    """Indices of the minimum and maximum of each of ``bins`` equal runs of ``y`` (NaNs never
    chosen unless a run is all NaN), in increasing order; every index when ``len(y) <= 2 bins``."""
    import numpy as np

    y = np.asarray(y, dtype=float)
    n = y.size
    if n <= 2 * bins:
        return np.arange(n)
    edges = np.linspace(0, n, bins + 1).astype(int)
    keep: set[int] = set()
    for a, b in itertools.pairwise(edges):
        seg = y[a:b]
        if np.isfinite(seg).any():
            keep.update((a + int(np.nanargmin(seg)), a + int(np.nanargmax(seg))))
    return np.asarray(sorted(keep), dtype=int)


def error_band_of(rec, sol, bins: int = _ERROR_BINS) -> ErrorBand | None:
    """The per-axis error of ``sol`` against ``rec.reference`` with the solution's 1-sigma at the
    same epochs (the association and the errors of :func:`navpp.metrics.compute_metrics`);
    decimated to the extremes of each axis and of the horizontal error per bin.  None without a
    reference or without a reference epoch inside the solution's span."""
    import numpy as np

    from ..metrics import associate, interpolate_solution, position_errors_enu

    if rec.reference is None:
        return None
    ref = rec.reference
    ref_ok = np.isfinite(ref.lat_deg) & np.isfinite(ref.lon_deg) & np.isfinite(ref.alt)
    assoc = associate(np.asarray(sol.t, dtype=float), np.where(ref_ok, np.asarray(ref.t, dtype=float), np.nan),
                      skip_holes=True)
    if not assoc.idx_ref.size:
        return None
    i = assoc.idx_ref
    est = interpolate_solution(sol, assoc.t)
    err = position_errors_enu(est["lat_deg"], est["lon_deg"], est["alt"], ref.lat_deg[i], ref.lon_deg[i], ref.alt[i])
    std = np.asarray(est["std_enu"], dtype=float).reshape(-1, 3)
    keep = set()
    for y in (err[:, 0], err[:, 1], err[:, 2], np.hypot(err[:, 0], err[:, 1])):
        keep.update(minmax_indices(y, bins).tolist())
    k = np.asarray(sorted(keep), dtype=int)
    return ErrorBand(np.asarray(assoc.t, dtype=float)[k], err[k], std[k])


def innovation_band_of(sol, diag, points: int = _DIAG_POINTS) -> InnovationBand | None:
    """The GNSS position innovations of ``diag`` with ``sqrt(P + R)`` per axis (see
    :class:`InnovationBand`); None without GNSS epochs.  Strided to about ``points`` epochs,
    rejected fixes always kept."""
    import numpy as np

    t = np.asarray(diag.t, dtype=float)
    if not t.size:
        return None
    st = np.asarray(sol.t, dtype=float)
    before = np.clip(np.searchsorted(st, t, side="left") - 1, 0, max(st.size - 1, 0))
    p_std = np.asarray(sol.std_enu, dtype=float).reshape(-1, 3)[before]
    r_std = np.asarray(diag.r_std, dtype=float).reshape(-1, 3)
    s_std = np.sqrt(p_std ** 2 + r_std ** 2)
    acc = np.asarray(diag.accepted).astype(bool)
    k = np.union1d(stride_indices(t.size, points), np.flatnonzero(~acc))
    return InnovationBand(t[k], np.asarray(diag.nu, dtype=float).reshape(-1, 3)[k], s_std[k], acc[k])


def gnss_gaps(t_fix_s: np.ndarray, windows: tuple[tuple[float, float], ...] = (),
              min_gap_s: float = 1.0) -> tuple[tuple[float, float], ...]:
    """GNSS outages as ``(start, end)`` s: the simulated outage windows ``(start_s, duration_s)``
    and every interval between consecutive fixes longer than ``min_gap_s`` and 3 times the median
    fix interval; overlapping ones merged, in time order."""
    import numpy as np

    t = np.sort(np.asarray(t_fix_s, dtype=float)[np.isfinite(t_fix_s)])
    spans = [(float(a), float(a) + float(d)) for a, d in windows]
    if t.size >= 2:
        dt = np.diff(t)
        limit = max(min_gap_s, 3.0 * float(np.median(dt)))
        spans += [(float(t[j]), float(t[j + 1])) for j in np.flatnonzero(dt > limit)]
    merged: list[tuple[float, float]] = []
    for a, b in sorted(spans):
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return tuple(merged)


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


def log_series_of(rec, windows: tuple[tuple[float, float], ...] = ()) -> LogSeries | None:
    """What the report plots of the log itself; ``windows``: the simulated GNSS outages
    ``(start_s, duration_s)`` removed from ``rec`` (shown among the GNSS gaps)."""
    import numpy as np

    anchor = plot_anchor(rec)
    if anchor is None:
        return None
    g = rec.gnss
    ok = np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg) & np.isfinite(g.alt)
    gi = np.flatnonzero(ok)[stride_indices(int(ok.sum()), 2 * _TRACK_POINTS)]
    genu = anchor.enu(g.lat_deg[gi], g.lon_deg[gi], g.alt[gi]).reshape(-1, 3)
    ref_e = ref_n = ref_lat = ref_lon = None
    if rec.reference is not None:
        r = rec.reference
        rok = np.flatnonzero(np.isfinite(r.lat_deg) & np.isfinite(r.lon_deg) & np.isfinite(r.alt))
        ri = rok[stride_indices(rok.size, _TRACK_POINTS)]
        renu = anchor.enu(r.lat_deg[ri], r.lon_deg[ri], r.alt[ri]).reshape(-1, 3)
        ref_e, ref_n = renu[:, 0], renu[:, 1]
        ref_lat, ref_lon = np.asarray(r.lat_deg, dtype=float)[ri], np.asarray(r.lon_deg, dtype=float)[ri]
    gaps = gnss_gaps(np.asarray(g.t, dtype=float)[ok], tuple(windows))
    return LogSeries((anchor.lat_deg, anchor.lon_deg, anchor.alt), genu[:, 0], genu[:, 1], ref_e, ref_n,
                     np.asarray(g.lat_deg, dtype=float)[gi], np.asarray(g.lon_deg, dtype=float)[gi], ref_lat, ref_lon,
                     gaps)


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
    lat, lon = np.asarray(sol.lat_deg, dtype=float)[si], np.asarray(sol.lon_deg, dtype=float)[si]
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
    dt = np.asarray(diag.t, dtype=float)
    rej_t = dt[~np.asarray(diag.accepted).astype(bool)]
    g = rec.gnss
    gt = np.asarray(g.t, dtype=float)
    rej_lat = rej_lon = None
    if gt.size and rej_t.size:      # the fix at (nearest to) each rejected epoch
        j = np.clip(np.searchsorted(gt, rej_t), 1, gt.size - 1) if gt.size > 1 else np.zeros(rej_t.size, int)
        if gt.size > 1:
            j = np.where(np.abs(gt[j - 1] - rej_t) <= np.abs(gt[j] - rej_t), j - 1, j)
        rej_lat, rej_lon = np.asarray(g.lat_deg, dtype=float)[j], np.asarray(g.lon_deg, dtype=float)[j]
    return RunSeries(east, north, err_t, err_h, cdf, adaptive,
                     dt[di] if adaptive else None,
                     np.asarray(diag.r_std, dtype=float)[di] if adaptive else None,
                     {k: v[di] for k, v in factors.items()} if adaptive else {},
                     lat, lon, error_band_of(rec, sol),
                     innovation_band_of(sol, diag) if rec.reference is None else None,
                     rej_t, dt[np.asarray(diag.forced).astype(bool)], np.asarray(sol.t, dtype=float)[si],
                     rej_lat, rej_lon)
