"""GNSS position sigmas 4x too small (R 16x too small: the "sigma /4" case of
benchmarks/bench_filters.py) on a simulated 300-s drive, the simulator's truth the oracle.

- AEKF and Sage-Husa learn R from the innovations: they must finish, say that the sigmas are too
  small, and end with the error of the same filter told the true sigmas (within 10 % per axis
  group).  Before, the plausibility check judged them against the wrong prior R and refused them
  ("aekf diverged: 864 of 1500 fixes (58%) fail the configured GNSS sigma's gate (learnt R 4.45x
  it)"), and the alignment read the 60-s rest as motion (0.7 m/s of fix noise against a quarter
  of its sigma), so that every filter started in motion from one fix.
- The EKF, told the wrong R, must still be refused (its gate rejects most fixes), and the refusal
  names the sigmas as the likely cause, with the measured factor near 4.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from navpp import api, engine
from navpp.config import config_from_dict
from navpp.errors import RunRefused
from navpp.metrics import interpolate_solution, position_errors_enu
from navpp.simulate import SimulationSpec, simulate

DURATION_S = 300.0
STILL_S = 60.0
FACTOR = 0.25                  # on the simulated fixes' true 1-sigma


@pytest.fixture(scope="module")
def drive():
    return simulate(SimulationSpec(duration_s=DURATION_S, still_s=STILL_S, seed=0)).recording()


def _small(rec):
    return replace(rec, gnss=replace(rec.gnss, std_enu=np.asarray(rec.gnss.std_enu, dtype=float) * FACTOR))


def _run(rec, name):
    cfg = config_from_dict({}, "test")
    return engine.run(rec, cfg, api.make_filter(name, cfg))


def _rmse_hu(rec, sol) -> tuple[float, float]:
    """Horizontal and vertical RMSE against the simulator's truth, m."""
    ref = rec.reference
    sel = (ref.t >= sol.t[0]) & (ref.t <= sol.t[-1])
    it = interpolate_solution(sol, ref.t[sel])
    e = position_errors_enu(it["lat_deg"], it["lon_deg"], it["alt"], ref.lat_deg[sel], ref.lon_deg[sel], ref.alt[sel])
    r = np.sqrt(np.mean(e ** 2, axis=0))
    return float(np.hypot(r[0], r[1])), float(r[2])


@pytest.mark.parametrize("name", ["aekf", "sage-husa"])
def test_adaptive_filter_told_sigmas_4x_too_small_matches_the_true_sigma_run(drive, name):
    truth = _run(drive, name)
    small = _run(_small(drive), name)        # refused before: RunRefused
    h0, u0 = _rmse_hu(drive, truth.solution)
    h1, u1 = _rmse_hu(drive, small.solution)
    assert abs(h1 - h0) <= 0.1 * h0 and abs(u1 - u0) <= 0.1 * u0, (h0, u0, h1, u1)
    # the still start is found although the fixes' noise is 4x their sigma
    t0, t1 = small.alignment.start_fixes
    assert t1 - t0 > 0.9 * STILL_S
    # one warning says what is wrong with the log, with the factor the fixes show
    (w,) = [w for w in small.warnings if "too small" in w]
    factors = [float(v) for v in re.search(r"GNSS noise ([0-9./]+)x \(E/N/U\) larger", w).group(1).split("/")]
    assert all(3.0 < f < 5.0 for f in factors), w
    assert not any("too small" in w for w in truth.warnings)


def test_ekf_told_sigmas_4x_too_small_is_refused_naming_them(drive):
    with pytest.raises(RunRefused) as info:
        _run(_small(drive), "ekf")
    msg = str(info.value)
    assert "ekf diverged" in msg and "failed the innovation gate" in msg
    likely = msg.split("likely: ", 1)[1]
    assert "too small by the fixes' own scatter" in likely and "std_scale" in likely, msg
    factors = [float(v) for v in re.search(r"([0-9./]+)x \(E/N/U\) too small", likely).group(1).split("/")]
    assert all(3.0 < f < 5.0 for f in factors), msg
