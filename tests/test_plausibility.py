"""The plausibility checks of a finished run (navpp/plausibility.py, issue 15): no false alarm on
clean runs of every filter (the simulated drive and the real RTK walk), and each check fires on
synthetic innovations built to fail it (so the clean runs' silence means something)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from navpp import api
from navpp import plausibility as pl
from navpp.filters import FILTERS

SAMPLE = Path(__file__).resolve().parent.parent / "sample_data"
#: words only the plausibility checks and the fix checks of issue 15 write
NEW_WORDS = ("configured GNSS sigma", "GNSS noise", "radians", "identical", "swapped", "a jump no vehicle",
             "altitude leaves", "speed exceeds", "cannot tell whether those sigmas")


#: the drive with the slower filters runs with the slow tests
FAST_ON_DRIVE = ("ekf", "aekf", "sage-husa")
#: the walk (real data) runs every filter in the default run but its two costliest (7 s of CPU),
#: which run with the slow tests; its UKF, CKF and AEKF keep sigma-point and adaptive filters there
SLOW_ON_WALK = ("aukf", "vce-ckf")


@pytest.mark.parametrize(("name", "log"), [
    pytest.param(n, log, id=f"{n}-{log}", marks=[pytest.mark.slow] if (log == "drive" and n not in FAST_ON_DRIVE)
                 or (log == "walk_0827" and n in SLOW_ON_WALK) else [])
    for log in ("drive", "walk_0827") for n in sorted(FILTERS)])
def test_clean_logs_pass_every_filter_without_new_warnings(name, log, tmp_path):
    res = api.process(SAMPLE / log, filter_name=name, out_dir=tmp_path / "out")
    said = [w for w in res.warnings if any(word in w for word in NEW_WORDS)]
    assert said == [], said
    assert (tmp_path / "out" / "trajectory.csv").is_file()


def _white(m=600, sigma=(1.8, 1.8, 2.5), scale=1.0, seed=1):
    rng = np.random.default_rng(seed)
    var0 = np.tile(np.square(sigma), (m, 1)) * scale ** 2      # what the log declares
    nu = rng.normal(size=(m, 3)) * np.sqrt(np.square(sigma))   # what the GNSS does
    S = np.einsum("ki,ij->kij", var0, np.eye(3))
    return np.arange(m) * 0.2, nu, S, S.copy(), var0, np.ones(m, bool)


def test_consistent_innovations_raise_nothing():
    t, nu, S, R, var0, acc = _white()
    assert pl.innovation_findings("ekf", "std", t, nu, S, R, var0, acc, 0.9999, 0.25) == []


def test_sigmas_far_too_large_are_refused_naming_them():
    t, nu, S, R, var0, acc = _white(scale=100.0)
    (f,) = pl.innovation_findings("ekf", "std_e, std_n, std_u of gnss.csv", t, nu, S, R, var0, acc, 0.9999, 0.25)
    assert f.fatal and "std_e, std_n, std_u of gnss.csv" in f.headline and "too large" in f.cause
    # twice too large is not refused (real receivers' fixes are time-correlated)
    t, nu, S, R, var0, acc = _white(scale=2.0)
    assert pl.innovation_findings("ekf", "std", t, nu, S, R, var0, acc, 0.9999, 0.25) == []
    # max_rejected_fraction = 1 lets it through as a warning
    t, nu, S, R, var0, acc = _white(scale=100.0)
    (f,) = pl.innovation_findings("ekf", "std", t, nu, S, R, var0, acc, 0.9999, 1.0)
    assert not f.fatal


def test_fix_to_fix_correlated_errors_only_warn_that_navpp_cannot_tell():
    """Oracle: the model's own numbers.  Errors of honest sigma but correlated 0.9999 from fix to fix
    (a receiver that smooths; consecutive differences correlate -(1 - rho) / 2, about 0) move
    ~70x less per fix than the sigma: the run is not refused, it says it cannot tell.  The same
    small differences from white errors (rho = 0, differences correlate -0.5) are refused."""
    t, nu, S, R, var0, acc = _white(m=2000)
    rng = np.random.default_rng(7)
    rho = 0.9999
    e = np.zeros_like(nu)
    w = rng.normal(size=nu.shape) * np.sqrt(var0) * np.sqrt(1.0 - rho ** 2)
    e[0] = rng.normal(size=3) * np.sqrt(var0[0])
    for k in range(1, e.shape[0]):
        e[k] = rho * e[k - 1] + w[k]
    (f,) = pl.innovation_findings("ekf", "std", t, e, S, R, var0, acc, 0.9999, 0.25)
    assert not f.fatal and "cannot tell" in f.headline, f
    small_white = rng.normal(size=nu.shape) * np.sqrt(var0) * math.sqrt(1.0 - rho ** 2) / math.sqrt(2.0)
    (g,) = pl.innovation_findings("ekf", "std", t, small_white, S, R, var0, acc, 0.9999, 0.25)
    assert g.fatal and "smaller than std say" in g.headline, g


def _drift(t, var0, sigmas):
    """A lost filter's error in its innovations: ``sigmas`` prior sigmas on every axis, moving
    slowly (a 40-s period: the INS drifts, it does not jump from fix to fix)."""
    return sigmas * np.sqrt(var0) * (1.0 + 0.5 * np.sin(2.0 * np.pi * t / 40.0))[:, None]


def test_a_learnt_r_hiding_large_innovations_is_a_divergence():
    t, nu, S, R, var0, acc = _white()
    nu = nu + _drift(t, var0, 30.0)                 # innovations 30 sigma of the configured R ...
    R = R * 900.0                                   # ... which the filter learnt away
    S = S * 900.0
    (f,) = pl.innovation_findings("sage-husa", "std", t, nu, S, R, var0, acc, 0.9999, 0.25)
    assert f.fatal and "sage-husa diverged" in f.headline and "configured GNSS sigma" in f.headline
    # the same with fixes 4x noisier than their sigmas: judged against their own scatter, still lost
    t, nu, S, R, var0, acc = _white()
    nu = 4.0 * nu + _drift(t, var0, 120.0)
    (f,) = pl.innovation_findings("sage-husa", "std", t, nu, S * 16.0 ** 2, R * 16.0 ** 2, var0, acc, 0.9999, 0.25)
    assert f.fatal and "sage-husa diverged" in f.headline and "configured GNSS sigma" in f.headline, f


@pytest.mark.parametrize("case", ["diverged", "noisier", "singular prior"])
def test_innovation_checks_in_windows_find_what_one_pass_finds(case, monkeypatch):
    """Oracle: the same checks in one window (the arrays as one stacked pass saw them).  Windows
    of 7 fixes, with non-finite innovations and covariances among them and a rejected fix: the
    same findings, counts and factors (the per-fix figures are the same bits)."""
    t, nu, S, R, var0, acc = _white(m=400)
    if case == "diverged":
        nu, R, S = nu + _drift(t, var0, 30.0), R * 900.0, S * 900.0
    elif case == "noisier":
        nu, S, R = 4.0 * nu, S * 16.0, R * 16.0
    else:                                   # S - R + var0 singular at one fix: no prior gate at all
        nu, R, S = nu + _drift(t, var0, 30.0), R * 900.0, S * 900.0
        S[100] = R[100] - np.diag(var0[100])
    nu[[3, 50, 51]] = np.nan
    S[[10, 200], 1, 2] = np.inf
    acc[7] = False
    monkeypatch.setattr(pl, "WINDOW_FIXES", 1 << 20)
    whole = pl.innovation_findings("aekf", "std", t, nu, S, R, var0, acc, 0.9999, 0.25)
    monkeypatch.setattr(pl, "WINDOW_FIXES", 7)
    assert pl.innovation_findings("aekf", "std", t, nu, S, R, var0, acc, 0.9999, 0.25) == whole
    if case == "singular prior":            # no prior gate, no judgement: nothing found
        assert whole == []
    else:
        assert whole and whole[0].fatal == (case == "diverged")


def test_fixes_noisier_than_their_sigmas_learnt_by_the_filter_only_warn():
    """Oracle: the model's own numbers.  White fix errors 4x their declared sigma (R 16x too
    small) that an adaptive filter learnt (R and S 16x): the innovations are what the fixes'
    real noise makes them, so the run is not refused; the warning gives the factor, about 4 per
    axis, and names the sigmas.  Without the learnt R (the filter told the prior), the same."""
    t, nu, S, R, var0, acc = _white(m=2000)
    nu = 4.0 * nu
    (f,) = pl.innovation_findings("aekf", "std", t, nu, S * 16.0, R * 16.0, var0, acc, 0.9999, 0.25)
    assert not f.fatal and "larger than std say" in f.headline and "too small" in f.cause, f
    by = [float(v) for v in f.headline.split("GNSS noise ")[1].split("x")[0].split("/")]
    assert all(3.6 < v < 4.4 for v in by), f
    assert "used R 4.0/4.0/4.0x" in f.headline
    assert pl.sigmas_too_small(t, nu, var0, "std", 0.9999).startswith("std ")
    # the sigmas right: no finding, no cause
    t, nu, S, R, var0, acc = _white(m=2000)
    assert pl.innovation_findings("aekf", "std", t, nu, S, R, var0, acc, 0.9999, 0.25) == []
    assert pl.sigmas_too_small(t, nu, var0, "std", 0.9999) is None
    # a learnt R alone, with innovations the prior explains (AEKF's R holds the prediction error)
    t, nu, S, R, var0, acc = _white()
    assert pl.innovation_findings("aekf", "std", t, nu, S * 9.0, R * 9.0, var0, acc, 0.9999, 0.25) == []


def test_solution_bounds():
    n = 1000
    t = np.arange(n) * 0.01
    alt = np.full(n, 300.0)
    vel = np.zeros((n, 3))
    vel[:, 0] = 20.0
    std = np.ones((n, 3))
    fix_alt, fix_su = np.full(10, 300.0), np.full(10, 2.5)
    assert pl.solution_findings("ekf", "car", t, alt, vel, std, fix_alt, fix_su, 0.9999) == []
    low = alt.copy()
    low[500:] = -15865.0
    (f,) = pl.solution_findings("ekf", "car", t, low, vel, std, fix_alt, fix_su, 0.9999)
    assert f.fatal and "altitude" in f.headline and "t = 5.0 s" in f.headline
    fast = vel.copy()
    fast[700:, 1] = 3e5
    (f,) = pl.solution_findings("ekf", "car", t, alt, fast, std, fix_alt, fix_su, 0.9999)
    assert "speed exceeds 150 m/s" in f.headline and "t = 7.0 s" in f.headline
    assert pl.solution_findings("ekf", "none", t, alt, vel * 10.0, std, fix_alt, fix_su, 0.9999) == []
    for bad_alt, bad_std in ((np.nan, 1.0), (300.0, np.inf), (np.inf, np.nan)):   # the first row not finite
        a, s = alt.copy(), std.copy()
        a[612], s[612, 2] = bad_alt, bad_std
        a[800] = np.nan
        (f,) = pl.solution_findings("ekf", "car", t, a, vel, s.astype(np.float32), fix_alt, fix_su, 0.9999)
        assert f.fatal and f.headline == "ekf diverged: its solution is not finite from t = 6.120 s"


def test_fix_suspects(tmp_path):
    (tmp_path / "gnss.csv").write_text("")
    lat = 45.0 + np.linspace(0, 0.01, 50)
    lon = 7.0 + np.linspace(0, 0.01, 50)
    alt = np.full(50, 300.0)
    t = np.arange(50) * 0.2
    src = str(tmp_path)
    assert pl.fix_suspect(src, lat, lon, alt, t, None, "car") is None
    assert "identical" in pl.fix_suspect(src, np.full(50, 45.0), np.full(50, 7.0), alt)
    assert "radians" in pl.fix_suspect(src, np.radians(lat), np.radians(lon), alt)
    far = lat.copy()
    far[0] = -33.9
    msg = pl.fix_suspect(src, far, lon, alt, t, None, "car")
    assert "gnss.csv's fix at t = 0.000 s" in msg and "jump" in msg
