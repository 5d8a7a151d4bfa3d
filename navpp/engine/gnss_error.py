"""The run's GNSS error model (``[gnss] error_model``): its parameters from the configuration or
estimated from the log, and what the run says when the fixes' errors turn out to be correlated
(:mod:`navpp.ins.gnss_error` holds the model itself).

Estimation (``corr_time_s`` / ``correlated_share = "auto"``): maximum likelihood of the GNSS
position innovations.  Each candidate (tau, share) is one pass of the plain EKF over the run's
epochs with the Gauss-Markov model, scoring ``-2 log L = sum(nis + log det S)`` over the fixes
(a fix's NIS capped at the gate, so that an outlier the gate rejects counts the same under every
candidate).  The search starts at 60 s and 0.8, walks tau by factors of 2 while the score
improves, then the share over :data:`SHARES`, then tau once more, and takes the vertex of the
parabola in log tau through the best point and its neighbours.  On simulated drives the score's
minimum sits at the simulator's tau and share (tau 60 s: 60; tau 120 s: 120; share 0.8 against
0.5 and 0.95); docs/ins.md gives the figures.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import spill
from ..chi2 import chdtri
from ..config import Config
from ..findings import Finding
from ..ins.gnss_error import Correlation, GnssErrorSettings
from .schedule import GnssFixes

#: fixes per block of :func:`innovation_score` (its (M, 3, 3) temporaries a block long)
SCORE_ROWS = 1 << 14
#: where the search starts when ``corr_time_s`` / ``correlated_share`` are "auto"
PRIOR_TAU_S = 60.0
PRIOR_SHARE = 0.8
#: the correlation times the search may reach, s
TAU_RANGE_S = (2.0, 3600.0)
#: the correlated shares the search tries
SHARES = (0.5, 0.65, 0.8, 0.9, 0.95)

#: -2 log-likelihood of the fixes under one candidate: (settings, share) -> score
Scorer = Callable[[GnssErrorSettings, float], float]


def settings_for(fixes: GnssFixes, tau_s: float, share: float) -> GnssErrorSettings:
    """The Gauss-Markov error of correlation time ``tau_s`` whose stationary 1-sigma per ENU
    axis is ``sqrt(share)`` times the median 1-sigma of the run's fixes."""
    std = np.sqrt(np.median(np.asarray(fixes.var, dtype=float), axis=0))
    sigma = math.sqrt(share) * std
    return GnssErrorSettings(float(tau_s), (float(sigma[0]), float(sigma[1]), float(sigma[2])))


@dataclass(frozen=True)
class GnssErrorChoice:
    """The run's Gauss-Markov GNSS error: ``settings``, the correlated ``share`` of each fix's
    variance, and (when estimated) the scores ``tried``: ((tau s, share, -2 log L), ...)."""

    settings: GnssErrorSettings
    share: float
    tried: tuple[tuple[float, float, float], ...] = ()

    def report(self) -> dict[str, Any]:
        """Plain numbers for metrics.json."""
        out: dict[str, Any] = {"model": "gauss-markov", "corr_time_s": round(self.settings.tau_s, 3),
                               "correlated_share": self.share,
                               "sigma_enu_m": [round(v, 4) for v in self.settings.sigma_enu],
                               "estimated": bool(self.tried)}
        if self.tried:
            out["tried"] = [{"corr_time_s": t, "correlated_share": sh, "minus_2_log_likelihood": round(v, 2)}
                            for t, sh, v in self.tried]
        return out

    def note(self) -> str:
        s = self.settings
        text = (f"GNSS errors modelled as Gauss-Markov (tau {s.tau_s:.0f} s, 1-sigma "
                + " / ".join(f"{v:.2f}" for v in s.sigma_enu)
                + f" m ENU) plus white noise ({1.0 - self.share:.0%} of each fix's variance)")
        if self.tried:
            text += (f"; tau and share estimated from the innovations (maximum likelihood, {len(self.tried)} EKF "
                     "passes; set [gnss] corr_time_s / correlated_share to fix them)")
        return text


class _Search:
    """The candidates scored so far (see the module docstring)."""

    def __init__(self, fixes: GnssFixes, score: Scorer) -> None:
        self.fixes, self.score = fixes, score
        self.seen: dict[tuple[float, float], float] = {}

    def __call__(self, tau: float, share: float) -> float:
        key = (round(float(np.clip(tau, *TAU_RANGE_S)), 3), share)
        if key not in self.seen:
            value = self.score(settings_for(self.fixes, key[0], share), share)
            self.seen[key] = value if math.isfinite(value) else math.inf
        return self.seen[key]

    def walk_tau(self, tau: float, share: float) -> float:
        best = tau
        for step in (2.0, 0.5):
            while TAU_RANGE_S[0] <= best * step <= TAU_RANGE_S[1] and self(best * step, share) < self(best, share):
                best *= step
        return best

    def walk_share(self, tau: float, share: float) -> float:
        i = SHARES.index(share)
        for step in (1, -1):
            while 0 <= i + step < len(SHARES) and self(tau, SHARES[i + step]) < self(tau, SHARES[i]):
                i += step
        return SHARES[i]

    def refined_tau(self, tau: float, share: float) -> float:
        """The vertex of the parabola in log tau through ``tau`` and its neighbours by 2x (when
        ``tau`` is the lowest of the three)."""
        lo, hi = tau / 2.0, tau * 2.0
        if not (TAU_RANGE_S[0] <= lo and hi <= TAU_RANGE_S[1]):
            return tau
        f0, f1, f2 = self(lo, share), self(tau, share), self(hi, share)
        curv = f0 - 2.0 * f1 + f2
        if not (math.isfinite(curv) and curv > 0.0 and f1 <= min(f0, f2)):
            return tau
        return tau * 2.0 ** (0.5 * (f0 - f2) / curv)


def estimate(fixes: GnssFixes, score: Scorer, tau0: float | None, share0: float | None) -> GnssErrorChoice:
    """Maximum-likelihood tau and share (module docstring); a value given (not None) is kept."""
    search = _Search(fixes, score)
    tau = PRIOR_TAU_S if tau0 is None else tau0
    share = PRIOR_SHARE if share0 is None else share0
    if tau0 is None:
        tau = search.walk_tau(tau, share)
    if share0 is None:
        share = search.walk_share(tau, share)
        if tau0 is None:
            tau = search.walk_tau(tau, share)
    if tau0 is None:
        tau = search.refined_tau(tau, share)     # the vertex is not scored: one pass less
    tried = tuple((k[0], k[1], v) for k, v in search.seen.items())
    return GnssErrorChoice(settings_for(fixes, tau, share), share, tried)


def gnss_error_choice(config: Config, fixes: GnssFixes, score: Scorer) -> GnssErrorChoice | None:
    """The run's Gauss-Markov GNSS error (None: the fixes' errors are taken as white): the
    configured ``corr_time_s`` and ``correlated_share``, each estimated when "auto"."""
    g = config.gnss
    if g.error_model != "gauss-markov":
        return None
    tau0 = None if g.corr_time_s == "auto" else float(g.corr_time_s)
    share0 = None if g.correlated_share == "auto" else float(g.correlated_share)
    if tau0 is not None and share0 is not None:
        return GnssErrorChoice(settings_for(fixes, tau0, share0), share0)
    return estimate(fixes, score, tau0, share0)


def gate_cap(gate_probability: float) -> float:
    """The NIS cap of the score: the 3-dof gate quantile (inf without a gate)."""
    return float(chdtri(3, 1.0 - gate_probability)) if gate_probability > 0.0 else math.inf


def fix_score(nis: float, S: np.ndarray, cap: float) -> float:
    """One fix's share of ``-2 log L`` (without the constant): ``min(nis, cap) + log det S``."""
    sign, logdet = np.linalg.slogdet(S)
    return min(float(nis), cap) + (float(logdet) if sign > 0 else math.inf)


def innovation_score(nis: np.ndarray, S: np.ndarray, gate_probability: float) -> float:
    """``-2 log L`` of a run's GNSS position innovations (NIS (M,), innovation covariances
    (M, 3, 3); fixes without one skipped): how likely the fixes were under the filter's own
    predictions.  Two runs over the same fixes compare by it: the lower explains them better."""
    cap = gate_cap(gate_probability)
    scores = np.empty(nis.shape[0])
    n = 0
    for a, b in spill.windows(nis.shape[0], S, rows=SCORE_ROWS):    # a spilled S released behind
        Sb = S[a:b]
        ok = np.isfinite(nis[a:b]) & np.all(np.isfinite(Sb), axis=(1, 2))
        sign, logdet = np.linalg.slogdet(Sb[ok])    # fix_score's, each fix on its own
        m = int(np.count_nonzero(ok))
        scores[n:n + m] = np.minimum(nis[a:b][ok], cap) + np.where(sign > 0, logdet, math.inf)
        n += m
    return float(sum(scores[:n].tolist()))          # in fix order, as fix_score's would add up


class LikelihoodRecorder:
    """A loop recorder that only scores the GNSS position innovations: ``total`` = the sum of
    :func:`fix_score` over the fixes (``cap`` the gate's NIS threshold, :func:`gate_cap`)."""

    def __init__(self, cap: float) -> None:
        self.cap, self.total, self.n = cap, 0.0, 0

    def predicted(self, epoch: Any, prediction: Any) -> None:
        pass

    def updated(self, epoch: Any, meas: Any, update: Any) -> None:
        if meas.kind != "gnss_position":
            return
        self.total += fix_score(update.innovation.nis, update.innovation.S, self.cap)
        self.n += 1

    def epoch_done(self, epoch: Any, outcome: Any) -> None:
        pass


def _measured(corr: Correlation) -> str:
    return (f"the GNSS innovations {corr.lag_s:g} s apart correlate at {corr.rho:.2f} ({corr.pairs} pairs of fixes; "
            f"white fix errors give about 0, the test is {corr.threshold:.2f})")


def correlation_note(corr: Correlation) -> str:
    """The note of an ``"auto"`` run that switched the Gauss-Markov model on."""
    return (f"{_measured(corr)}: the fixes' errors last longer than one fix, so the run was repeated with "
            "Gauss-Markov GNSS error states ([gnss] error_model = \"auto\"; \"white\" keeps them white)")


def kept_white_finding(source: str, corr: Correlation, filter_name: str, white: float, gm: float) -> Finding:
    """The warning of an ``"auto"`` run whose Gauss-Markov repeat explained the fixes worse: the
    white run is kept, and its sigma is too small."""
    return Finding("gnss-errors-correlated",
                   f"{source}: {_measured(corr)}; the run was repeated with Gauss-Markov GNSS error states, but "
                   f"{filter_name} explained the fixes worse with them (-2 log-likelihood of the innovations "
                   f"{gm:.0f} against {white:.0f} white), so the white run is kept: it follows the slow GNSS error "
                   "and its sigma is too small (error_model = \"gauss-markov\" forces the states)")


def correlation_finding(source: str, corr: Correlation, r_ratio: float | None = None,
                        random_filter: str | None = None) -> Finding:
    """The warning of a run that takes the fixes as white while its innovations say otherwise:
    told so (``error_model = "white"``), or ``random_filter``, a filter whose random mean shifts
    the Gauss-Markov states would accumulate; ``r_ratio``: the median R an adaptive filter learnt
    over the log's, when below 1."""
    shrunk = ""
    if r_ratio is not None and r_ratio < 0.9:
        shrunk = (f"; the adaptive filter learnt an R of {r_ratio:.2f} times the fixes' sigma from those nearly equal "
                  "innovations, so it follows them even more closely")
    if random_filter is not None:
        why = (f"{random_filter} moves its mean by random amounts its covariance does not carry, which the "
               "Gauss-Markov GNSS error states would accumulate, so they are not added ([gnss] error_model = "
               "\"gauss-markov\" forces them; a filter without random weights, e.g. ekf or ckf, models the error)")
    else:
        why = "[gnss] error_model = \"white\" takes them as independent; set error_model = \"auto\" or \"gauss-markov\""
    return Finding("gnss-errors-correlated",
                   f"{source}: {_measured(corr)}: the filter follows the slow GNSS error and its sigma is too "
                   f"small{shrunk}; {why}")


def residual_finding(source: str, corr: Correlation, tau_s: float) -> Finding:
    """The warning of a Gauss-Markov run (correlation time ``tau_s``) whose innovations are still
    correlated."""
    return Finding("gnss-errors-correlated",
                   f"{source}: with the Gauss-Markov GNSS error (tau {tau_s:.0f} s) {_measured(corr)}: "
                   "the fixes' errors do not follow the model (a longer [gnss] corr_time_s, or a larger "
                   "correlated_share?)")


__all__ = ["PRIOR_SHARE", "PRIOR_TAU_S", "SHARES", "TAU_RANGE_S", "GnssErrorChoice", "LikelihoodRecorder",
           "correlation_finding", "correlation_note", "estimate", "fix_score", "gate_cap", "gnss_error_choice",
           "innovation_score", "kept_white_finding", "residual_finding", "settings_for"]
