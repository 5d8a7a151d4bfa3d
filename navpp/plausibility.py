"""Is the finished solution plausible?  Checked after the run, before anything is written.

Adaptive filters learn the GNSS noise R from the innovations (Sage-Husa, AEKF, VCE) or inflate
the prediction (AUKF's fading): a filter that has lost the GNSS then accepts every fix with a
normal-looking NIS, and the gate never fires.  So every filter is judged here against the
PRIOR R: the 1-sigma the log declares per fix (``std_e, std_n, std_u`` of ``gnss.csv``, the
NavSatFix covariance) or ``[gnss] default_std_m``, widened only where the fixes' own scatter
shows more noise than that (below).  All thresholds are chi-square quantiles at
the configured gate probability (``[gnss] gate_probability``, 0.9999 by default) and shares of
the fixes against ``[gnss] max_rejected_fraction``, as for the gate:

- innovations far beyond the prior R: more than the allowed share of fixes whose NIS with
  the prior R, ``nu' (S - R_used + R_prior)^-1 nu``, exceeds the 3-dof gate quantile;
  together with R grown far beyond the prior (the learnt 1-sigma above ``sqrt(chi2_1(p))``
  times the prior's: no single consistent innovation makes R that large) or the solution away
  from the accepted fixes (the post-fit residual ``R_used S^-1 nu`` normalised by the prior R
  beyond the 3-dof gate quantile), each at more than that share (a learnt R alone is not
  wrong: AEKF's holds the prediction error by design).  Where the fixes' own scatter is larger
  than the prior R says (the second differences of consecutive innovations, normalised by the
  prior R: the INS's smooth drift cancels, the fixes' noise stays; correlated fix errors only
  lower them), the prior R is widened to that scatter per ENU axis first: an adaptive filter
  that learnt the noise the fixes really have is right to, and the run only warns that the
  sigmas are too small; a filter whose innovations lie beyond even the widened gate is refused.
  A run the gate refused (``[gnss] max_rejected_fraction``) names those sigmas as the likely
  cause when more than half of those normalised second differences lie beyond the 3-dof gate
  quantile (sigmas at least 3x too small at the default p);
- GNSS noise far SMALLER than the prior R says (standard deviations in cm read as m): the
  difference of consecutive innovations (the INS's drift cancels, the fixes' noise stays),
  normalised by the two fixes' prior R, below the lower chi-square quantile ``chi2_3(1 - p)``
  at more than half the fixes (a consistent filter puts about ``1 - p`` of them there; a
  real receiver's time-correlated fixes put more, but far from half), i.e. the
  sigmas at least ``sqrt(chi2_3 median / chi2_3(1 - p))`` = 12x too large at the default p;
  only when those differences look white (lag-1 correlation at most
  :data:`WHITE_DIFFERENCE_CORRELATION`): a receiver's smoothed or time-correlated fixes also
  move little from fix to fix with an honest sigma, and then the run only warns that it cannot
  tell;
- the solution's altitude beyond the fixes' altitude range by more than the 1-dof gate
  quantile of the fixes' and the solution's vertical sigma, its speed beyond the vehicle
  type's (:data:`MAX_SPEED_MPS`), a non-finite position or sigma.

Speeds m/s, distances m, ENU axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .chi2 import chdtri
from .spill import windows

#: The highest speed the solution may show per ``[vehicle] type``, m/s: a road car's top speed
#: is below 150 m/s (540 km/h); with no vehicle model the speed of sound (no platform navpp's
#: loosely coupled land/walk/robot aiding is meant for flies faster).
MAX_SPEED_MPS = {"car": 150.0, "none": 343.0}

#: The "sigma too large" test needs fix errors that are white from fix to fix: the consecutive
#: differences of white errors correlate -0.5 at lag 1; of errors with fix-to-fix correlation rho,
#: -(1 - rho) / 2.  Above this value (rho > 0.5: a receiver that smooths its fixes, multipath,
#: atmosphere) small differences say nothing about the sigma, and the test only warns.
WHITE_DIFFERENCE_CORRELATION = -0.25

#: Altitude departures from the fixes' band below this, m, are left to the innovation checks and
#: the consistency warnings: the bound is for gross failures (an altitude kilometres or more off),
#: not for an overconfident filter a few metres off the fixes' band.
ALTITUDE_FLOOR_M = 100.0

#: Fixes per window of the innovation checks' passes over the (M, 3, 3) covariances (1.2 MB each).
WINDOW_FIXES = 1 << 14

#: The gate probability the checks use when gating is off (``gate_probability = 0``).
DEFAULT_GATE_PROBABILITY = 0.9999


@dataclass(frozen=True)
class Verdict:
    """One thing wrong with a run: ``fatal`` refuses the run; ``headline`` is what was seen
    (short, for the one error line); ``cause`` the single most likely cause with its setting
    (or None: the caller ranks the usual ones)."""

    fatal: bool
    headline: str
    cause: str | None = None


def gnss_name(source: str) -> str:
    """How the user knows the GNSS stream: ``gnss.csv`` for a CSV log directory, else 'the GNSS fixes'."""
    try:
        if Path(source).is_dir():
            return "gnss.csv"
    except OSError:
        pass
    return "the GNSS fixes"


def std_name(source: str, has_std: bool) -> str:
    """The setting or columns the GNSS 1-sigma came from."""
    if not has_std:
        return "[gnss] default_std_m"
    if gnss_name(source) == "gnss.csv":
        return "std_e, std_n, std_u of gnss.csv"
    return "the NavSatFix position_covariance"


def fix_suspect(source: str, lat_deg: np.ndarray, lon_deg: np.ndarray, alt: np.ndarray,
                t: np.ndarray | None = None, std_enu: np.ndarray | None = None,
                vehicle_type: str = "none") -> str | None:
    """What is wrong with the fixes themselves, before blaming the IMU: all identical, a whole
    track of latitudes and longitudes inside +-pi/2 and +-pi (radians read as degrees: a track
    that stays within 1.6 deg of the equator and 3.2 deg of Greenwich, in the Gulf of Guinea),
    or (given the times ``t``, s) a step between consecutive fixes longer than the vehicle
    type's :data:`MAX_SPEED_MPS` covers in the interval plus the gate quantile of the two fixes'
    sigmas (``std_enu``, m).  Returns a short clause naming the file, or None."""
    n = int(lat_deg.shape[0])
    if n < 2:
        return None
    name = gnss_name(source)
    if np.ptp(lat_deg) == 0.0 and np.ptp(lon_deg) == 0.0 and np.ptp(alt) == 0.0:
        return (f"all {n} fixes of {name} are identical ({float(lat_deg[0]):.6f}, {float(lon_deg[0]):.6f}, "
                f"{float(alt[0]):.1f} m)")
    if float(np.max(np.abs(lat_deg))) <= 0.5 * math.pi and float(np.max(np.abs(lon_deg))) <= math.pi \
            and np.ptp(lat_deg) + np.ptp(lon_deg) > 0.0:
        return f"{name}'s {n} lat/lon lie within +-1.571/+-3.142: radians? (degrees expected)"
    if t is not None:
        from .geodesy import geodetic_to_ecef

        xyz = geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), np.asarray(alt, float))
        step = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
        sig = (np.linalg.norm(std_enu, axis=1) if std_enu is not None else np.zeros(n))
        k = math.sqrt(gate_quantiles(DEFAULT_GATE_PROBABILITY)[0])
        reach = MAX_SPEED_MPS.get(vehicle_type, MAX_SPEED_MPS["none"]) * np.abs(np.diff(t)) \
            + k * np.hypot(sig[1:], sig[:-1])
        jump = ~(step <= reach)
        if jump.any():
            i = int(np.argmax(jump))
            return (f"{name}'s fix at t = {float(t[i]):.3f} s is {float(step[i]) / 1000.0:.4g} km from the next: "
                    "a jump no vehicle makes")
    return None


def _difference_lag1_correlation(z: np.ndarray, index: np.ndarray) -> float:
    """Lag-1 correlation of the normalised consecutive-innovation differences ``z`` (K, 3), pooled
    over the axes from centred deviations; ``index`` (K,) their positions in the fix sequence
    (only neighbours one fix apart are paired).  NaN-free; 0 when nothing pairs."""
    z = z - z.mean(axis=0)
    nb = np.flatnonzero(np.diff(index) == 1)
    den = float(np.sum(z * z))
    if nb.size < 10 or den <= 0.0:
        return 0.0
    return float(np.sum(z[nb] * z[nb + 1])) / den


def gate_quantiles(gate_probability: float) -> tuple[float, float, float]:
    """(3-dof upper, 3-dof lower, 1-dof upper) chi-square quantiles at the gate probability."""
    p = gate_probability if 0.0 < gate_probability < 1.0 else DEFAULT_GATE_PROBABILITY
    return float(chdtri(3, 1.0 - p)), float(chdtri(3, p)), float(chdtri(1, 1.0 - p))


def innovation_findings(name: str, std_label: str, t: np.ndarray, nu: np.ndarray, S: np.ndarray,
                        R_used: np.ndarray, var0: np.ndarray, accepted: np.ndarray, gate_probability: float,
                        max_fraction: float) -> list[Verdict]:
    """The innovation checks against the prior R (module docstring).

    t : (M,) s, the fixes' times; nu : (M, 3) innovations, ENU m (NaN rows: no update); S : (M, 3, 3) their
    covariance as the filter computed it; R_used : (M, 3, 3) the R it used; var0 : (M, 3) the prior R's
    diagonal, m^2; accepted : (M,) bool.  M fixes; nothing is checked below 20.
    """
    ok = np.all(np.isfinite(nu), axis=1) & np.all(var0 > 0.0, axis=1)
    for a, b in windows(ok.shape[0], S, rows=WINDOW_FIXES):
        ok[a:b] &= np.all(np.isfinite(S[a:b]), axis=(1, 2))
    m = int(np.count_nonzero(ok))
    if m < 20:
        return []
    hi3, lo3, hi1 = gate_quantiles(gate_probability)
    out: list[Verdict] = []

    # far smaller than predicted: the declared sigma is too large.  The innovation carries the
    # INS's drift as well as the GNSS noise, and a filter that trusts a too-large sigma little
    # drifts until the two match; between consecutive fixes the drift hardly changes, so the
    # difference of consecutive innovations is the GNSS noise R claims to describe.
    z_d, r1, white = consecutive_differences(t, nu, var0, ok)
    q_d = np.sum(z_d * z_d, axis=1)
    n_d = int(q_d.shape[0])
    low = int(np.count_nonzero(q_d < lo3))
    if n_d >= 20 and low > 0.5 * n_d:
        scale = math.sqrt(_CHI2_3_MEDIAN / max(float(np.median(q_d)), 1e-300))
        if white:
            what = (f"GNSS noise {scale:.3g}x smaller than {std_label} say ({_share(low, n_d)} below "
                    f"the chi-square {100.0 * _tail(gate_probability):.2g}% bound)")
            out.append(Verdict(max_fraction < 1.0, what, "those sigmas are too large (cm read as m?)"))
        else:
            out.append(Verdict(False, f"the fixes move {scale:.3g}x less from one to the next than {std_label} "
                                      f"say, but their errors are correlated from fix to fix (consecutive "
                                      f"differences correlate {r1:+.2f}, white noise: -0.5): navpp cannot tell "
                                      "whether those sigmas are too large or the receiver smooths its fixes"))
    # far larger than the prior says: the fixes' own scatter, the R the data support
    z2 = second_differences(t, nu, var0, ok)
    spread = fix_spread(z2)
    failed = _beyond_prior(nu, S, R_used, var0, ok, accepted, hi3, hi1, max_fraction)
    # judged against the fixes' own scatter where it is larger: a filter that learnt it (AEKF,
    # Sage-Husa, VCE) is right to; one whose innovations lie beyond even that has lost the GNSS
    # (and lies beyond the prior's gate all the more: the headline gives that one)
    if failed is not None and (not np.any(spread > 1.0)
                               or _beyond_prior(nu, S, R_used, var0 * spread ** 2, ok, accepted, hi3, hi1,
                                                max_fraction) is not None):
        beyond, how = failed
        out.append(Verdict(True, f"{name} diverged: {_share(beyond, m)} fail the configured GNSS sigma's gate ({how})"))
    elif np.any(spread > 1.0) and (failed is not None or far_too_small(z2, gate_probability)):
        by = "/".join(f"{v:.1f}" for v in spread)
        r_ratio = np.sqrt(np.median(np.diagonal(R_used, axis1=1, axis2=2)[ok] / var0[ok], axis=0))
        learnt = (f"; {name} used R {'/'.join(f'{v:.1f}' for v in r_ratio)}x them" if np.any(r_ratio > 1.5)
                  else "")
        out.append(Verdict(False, f"GNSS noise {by}x (E/N/U) larger than {std_label} say (second differences of "
                                  f"consecutive innovations){learnt}: judged against the fixes' own scatter",
                           "those sigmas are too small"))
    return out


def consecutive_differences(t: np.ndarray, nu: np.ndarray, var0: np.ndarray,
                            ok: np.ndarray | None = None) -> tuple[np.ndarray, float, bool]:
    """The differences of consecutive innovations normalised by the two fixes' prior R.

    Between consecutive fixes the INS's drift hardly changes, so ``nu[k] - nu[k-1]`` is the
    difference of the two fixes' noise, which the prior R claims to describe: ``z`` (K, 3) is
    N(0, 1) per axis when the sigmas are right and the errors white.  t (M,) s; nu (M, 3) m;
    var0 (M, 3) m^2; ok (M,) bool, the fixes to use (default: finite ones).  Only fixes at most
    1.5 median intervals apart pair up.  Returns (z, their lag-1 correlation (0 below 20 pairs),
    white: at least 20 pairs correlated at most :data:`WHITE_DIFFERENCE_CORRELATION`)."""
    ok, close = _paired(t, nu, var0, ok)
    pair = ok[1:] & ok[:-1] & close
    z = (nu[1:] - nu[:-1])[pair] / np.sqrt((var0[1:] + var0[:-1])[pair])
    n = int(z.shape[0])
    r1 = _difference_lag1_correlation(z, np.flatnonzero(pair)) if n >= 20 else 0.0
    return z, r1, n >= 20 and r1 <= WHITE_DIFFERENCE_CORRELATION


def second_differences(t: np.ndarray, nu: np.ndarray, var: np.ndarray,
                       ok: np.ndarray | None = None) -> np.ndarray:
    """The second differences of the innovations ``nu[k+1] - 2 nu[k] + nu[k-1]`` normalised by
    the three fixes' prior R, ``var[k+1] + 4 var[k] + var[k-1]``: (K, 3), N(0, 1) per axis for
    white fix errors with the prior sigmas.  The INS's error between fixes (a drift) is smooth
    and cancels; what remains of the filter's own prediction error adds at most its share
    ``H P H'`` of the innovation variance (the innovations of a consistent filter are white with
    variance ``H P H' + R``), small beside R at metre-level fixes; fix errors correlated from fix
    to fix make them smaller, never larger.  t (M,) s; nu (M, 3) m; var (M, 3) m^2; ok (M,)
    bool, the fixes to use (default: finite ones); only triplets at most 1.5 median intervals
    apart."""
    ok, close = _paired(t, nu, var, ok)
    tri = ok[2:] & ok[1:-1] & ok[:-2] & close[1:] & close[:-1]
    z: np.ndarray = ((nu[2:] - 2.0 * nu[1:-1] + nu[:-2])[tri]
                     / np.sqrt((var[2:] + 4.0 * var[1:-1] + var[:-2])[tri]))
    return z


def fix_spread(z: np.ndarray) -> np.ndarray:
    """The fixes' own scatter over their prior sigma per ENU axis (3,), at least 1, from the
    normalised second differences ``z`` (K, 3) of :func:`second_differences` (robust: the median
    of ``z^2`` over the chi-square(1) median); ones below 20 of them."""
    if z.shape[0] < 20:
        return np.ones(3)
    spread: np.ndarray = np.sqrt(np.maximum(np.median(z * z, axis=0) / _CHI2_1_MEDIAN, 1.0))
    return spread


def far_too_small(z: np.ndarray, gate_probability: float) -> bool:
    """Whether the normalised second differences ``z`` (K, 3) say the prior sigmas are far too
    small: at least 20 of them, more than half beyond the 3-dof gate quantile (the sigmas at
    least ``sqrt(chi2_3(p) / chi2_3 median)`` = 3x too small at the default p)."""
    hi3 = gate_quantiles(gate_probability)[0]
    return bool(z.shape[0] >= 20 and int(np.count_nonzero(np.sum(z * z, axis=1) > hi3)) > 0.5 * z.shape[0])


def sigmas_too_small(t: np.ndarray, nu: np.ndarray, var: np.ndarray, std_label: str,
                     gate_probability: float) -> str | None:
    """The likely cause of a refusal when the fixes' own scatter is far larger than their prior
    sigma says (:func:`far_too_small` on the innovations' :func:`second_differences`, ``var``
    the prior R's diagonal): a short clause naming ``std_label``, or None."""
    z = second_differences(t, nu, var)
    if not far_too_small(z, gate_probability):
        return None
    by = "/".join(f"{v:.1f}" for v in fix_spread(z))
    return f"{std_label} {by}x (E/N/U) too small by the fixes' own scatter"


def _beyond_prior(nu: np.ndarray, S: np.ndarray, R_used: np.ndarray, var: np.ndarray, ok: np.ndarray,
                  accepted: np.ndarray, hi3: float, hi1: float, max_fraction: float) -> tuple[int, str] | None:
    """The divergence test of :func:`innovation_findings` against the GNSS variance ``var`` (M, 3),
    m^2, over the fixes ``ok`` (M,) bool: (fixes beyond its gate, what else shows it) when it
    fails, else None.  nu (M, 3) m; S, R_used (M, 3, 3) m^2 as the filter used them; accepted
    (M,) bool.  In windows of :data:`WINDOW_FIXES` fixes (the (M, 3, 3) temporaries of the
    stacked solves stay a window's; spilled records are released as they pass), each fix's
    figures the bits of one stacked pass."""
    m = int(np.count_nonzero(ok))
    acc = accepted[ok]
    nis0, r_ratio, q_post = np.empty(m), np.empty(m), np.empty(m)
    singular = False                             # the prior S of some fix is not solvable
    row = 0
    for a, b in windows(ok.shape[0], nu, S, R_used, rows=WINDOW_FIXES):
        sel = ok[a:b]
        k = int(np.count_nonzero(sel))
        if k == 0:
            continue
        nu_w, S_w, R_w, var_w = nu[a:b][sel], S[a:b][sel], R_used[a:b][sel], var[a:b][sel]
        # far beyond the prior R (what a learnt R or an inflated P let through)
        S0 = S_w - R_w + var_w[:, :, None] * np.eye(3)
        if not singular:
            try:
                nis0[row:row + k] = np.einsum("ki,ki->k", nu_w, np.linalg.solve(S0, nu_w[:, :, None])[:, :, 0])
            except np.linalg.LinAlgError:
                singular = True
        r_ratio[row:row + k] = np.sqrt(np.diagonal(R_w, axis1=1, axis2=2) / var_w).max(axis=1)
        S_inv_nu = np.linalg.solve(S_w, nu_w[:, :, None])
        post = np.einsum("kij,kjl->kil", R_w, S_inv_nu)[:, :, 0]
        q_post[row:row + k] = np.sum(post * post / var_w, axis=1)
        row += k
    if singular:
        nis0 = np.zeros(m)                       # no judgement without a solvable prior S
    beyond = int(np.count_nonzero(~(nis0 <= hi3)))
    grown = int(np.count_nonzero(r_ratio > math.sqrt(hi1)))
    far = int(np.count_nonzero(acc & ~(q_post <= hi3)))
    n_acc = int(np.count_nonzero(acc))
    # a learnt R (or an inflated P) alone is no divergence: AEKF's R holds the prediction error by
    # design; it is one when the fixes it let through lie beyond the gate of the prior R
    if beyond > max_fraction * m and (grown > max_fraction * m or far > max_fraction * max(n_acc, 1)):
        how = (f"learnt R {float(np.median(r_ratio)):.3g}x it" if grown > max_fraction * m
               else f"solution off {_share(far, n_acc)} it took")
        return beyond, how
    return None


def _share(n: int, of: int) -> str:
    """``n of OF fixes (P%)`` for a message."""
    return f"{n} of {of} fixes ({100.0 * n / max(of, 1):.0f}%)"


def _paired(t: np.ndarray, nu: np.ndarray, var: np.ndarray, ok: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The fixes to use (``ok``, default: finite innovations and positive prior variances) and,
    per consecutive pair, whether the two are at most 1.5 median intervals apart."""
    if ok is None:
        ok = np.all(np.isfinite(nu), axis=1) & np.all(var > 0.0, axis=1)
    dt = np.diff(t)
    step = float(np.median(dt)) if dt.size else 0.0
    return ok, dt <= 1.5 * step


def _tail(gate_probability: float) -> float:
    """The gate's tail probability 1 - p (the lower bound's, mirrored)."""
    p = gate_probability if 0.0 < gate_probability < 1.0 else DEFAULT_GATE_PROBABILITY
    return 1.0 - p


_CHI2_3_MEDIAN = 2.365973884375338     # median of the chi-square distribution with 3 dof
_CHI2_1_MEDIAN = 0.454936423119572     # ... with 1 dof


def solution_findings(name: str, vehicle_type: str, t: np.ndarray, alt: np.ndarray, vel_enu: np.ndarray,
                      std_enu: np.ndarray, fix_alt: np.ndarray, fix_std_u: np.ndarray,
                      gate_probability: float, fatal: bool = True) -> list[Verdict]:
    """The solution's own bounds (O(n), vectorised), for gross failures the innovation checks
    may miss: finite; altitude within the fixes' altitude band widened on each side by the
    band's own height, :data:`ALTITUDE_FLOOR_M`, and the 1-dof gate quantile of the fixes' and
    the solution's vertical sigma (an overconfident filter a few metres off is the consistency
    warnings' business, not this check's); speed within
    the vehicle type's :data:`MAX_SPEED_MPS`.  t (N,) s; alt (N,) m; vel_enu (N, 3) m/s;
    std_enu (N, 3) m; fix_alt, fix_std_u (M,) m.  ``fatal`` False: findings are warnings
    (``[gnss] max_rejected_fraction = 1``: write anyway).  In windows of rows
    (:func:`navpp.spill.windows`: a spilled solution's rows leave memory behind the pass), with
    the findings and figures of the whole arrays."""
    if t.shape[0] == 0 or fix_alt.shape[0] == 0:
        return []
    k = math.sqrt(gate_quantiles(gate_probability)[2])
    su = float(np.max(fix_std_u)) if np.all(np.isfinite(fix_std_u)) else 0.0
    band = float(np.max(fix_alt)) - float(np.min(fix_alt))
    margin = band + k * su + ALTITUDE_FLOOR_M
    lo, hi = float(np.min(fix_alt)) - margin, float(np.max(fix_alt)) + margin
    vmax = MAX_SPEED_MPS.get(vehicle_type, MAX_SPEED_MPS["none"])
    first_alt = first_fast = far = fastest = -1      # first row out of the band / too fast; argmax rows
    far_v = fast_v = -1.0
    for a, b in windows(t.shape[0], alt, vel_enu, std_enu):
        alt_w, std_w, vel_w = alt[a:b], std_enu[a:b], vel_enu[a:b]
        if not (np.isfinite(alt_w).all() and np.isfinite(std_w).all()):     # (the per-row test costs 20x)
            bad = ~(np.isfinite(alt_w) & np.isfinite(std_w).all(axis=1))
            i = a + int(np.argmax(bad))
            return [Verdict(fatal, f"{name} diverged: its solution is not finite from t = {float(t[i]):.3f} s")]
        slack = k * std_w[:, 2]
        out_alt = (alt_w < lo - slack) | (alt_w > hi + slack)
        if first_alt < 0 and out_alt.any():
            first_alt = a + int(np.argmax(out_alt))
        off = np.abs(alt_w - 0.5 * (lo + hi))
        j = int(np.argmax(off))
        if off[j] > far_v:                      # the first maximum, as over the whole
            far, far_v = a + j, float(off[j])
        speed2 = np.einsum("ij,ij->i", vel_w, vel_w)
        fast = speed2 > vmax * vmax
        if first_fast < 0 and fast.any():
            first_fast = a + int(np.argmax(fast))
        j = int(np.argmax(speed2))              # the first NaN, else the first maximum, as over the whole
        if fastest < 0 or (not math.isnan(fast_v) and (math.isnan(speed2[j]) or speed2[j] > fast_v)):
            fastest, fast_v = a + j, float(speed2[j])
    if first_alt >= 0:
        return [Verdict(fatal, f"{name} diverged: its altitude leaves the fixes' {lo:.0f} .. {hi:.0f} m at "
                              f"t = {float(t[first_alt]):.1f} s (reaching {float(alt[far]):.4g} m)")]
    if first_fast >= 0:
        return [Verdict(fatal, f"{name} diverged: its speed exceeds {vmax:.0f} m/s (the most a [vehicle] type = "
                              f"\"{vehicle_type}\" goes) at t = {float(t[first_fast]):.1f} s, reaching "
                              f"{math.sqrt(fast_v):.4g} m/s")]
    return []
