"""``[gnss] std_scale`` and the GNSS velocity 1-sigma (issue 17, point 3).

std_scale: a simulated log whose written position sigmas are 3x too small, run with std_scale = 3,
must be the run with the true sigmas (the oracle): the same R, the same solution.  The velocity
sigma: with GNSS velocity and no velocity sigma in the log, ``[gnss] default_vel_std_mps`` (0.1 m/s)
is used, and :func:`navpp.engine.verdict.velocity_sigma_checks` warns when the velocity innovations
show it far off: simulated velocity noise of 1.0 m/s (10x) warns and suggests about 1 m/s, 0.1 m/s
does not.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from navpp import api, engine
from navpp.config import config_from_dict
from navpp.engine.schedule import gnss_fixes
from navpp.metrics import interpolate_solution, position_errors_enu
from navpp.simulate import SimulationSpec, simulate

DURATION_S = 200.0

#: The run's notes, the alignment's sigmas and the velocity check reach a run through three lines in
#: navpp/engine/run.py, which the lead owns (patch handed over with issue 17's report): until they
#: are in, these tests fail as expected; strict, so that they say when the marks can go.
needs_wiring = pytest.mark.xfail(strict=True, reason="needs the navpp/engine/run.py wiring of issue 17 point 3")


def _recording(seed: int = 0, **spec):
    return simulate(SimulationSpec(duration_s=DURATION_S, still_s=30.0, seed=seed, **spec)).recording()


def _config(**gnss):
    return config_from_dict({"gnss": gnss}, "test")


def _run(rec, cfg):
    return engine.run(rec, cfg, api.make_filter("ekf", cfg))


def _rmse_enu(rec, sol) -> np.ndarray:
    """RMSE of the solution against the simulator's truth per ENU axis, m."""
    ref = rec.reference
    sel = (ref.t >= sol.t[0]) & (ref.t <= sol.t[-1])
    it = interpolate_solution(sol, ref.t[sel])
    e = position_errors_enu(it["lat_deg"], it["lon_deg"], it["alt"], ref.lat_deg[sel], ref.lon_deg[sel], ref.alt[sel])
    return np.sqrt(np.mean(e ** 2, axis=0))


# ----------------------------------------------------------------------------------- std_scale


def test_std_scale_multiplies_the_logs_sigmas_only():
    rec = _recording()
    std = np.asarray(rec.gnss.std_enu, dtype=float)
    fixes = gnss_fixes(rec, _config(std_scale=3.0), 30.0)
    np.testing.assert_allclose(fixes.var, (3.0 * std[fixes.index]) ** 2, rtol=1e-15)
    assert len(fixes.notes) == 1 and fixes.notes[0].startswith("GNSS position sigmas scaled by 3 ([gnss] std_scale)")
    assert gnss_fixes(rec, _config(), 30.0).notes == ()
    # a log without sigmas: default_std_m as configured, not scaled, and the note says so
    bare = replace(rec, gnss=replace(rec.gnss, std_enu=None))
    fixes = gnss_fixes(bare, _config(std_scale=3.0, default_std_m=[1.5, 3.0]), 30.0)
    np.testing.assert_array_equal(fixes.var, np.tile([1.5 ** 2, 1.5 ** 2, 3.0 ** 2], (len(fixes), 1)))
    assert "std_scale = 3 not applied" in fixes.notes[0] and "default_std_m" in fixes.notes[0]


@pytest.fixture(scope="module")
def scale_runs():
    """The oracle (true sigmas), the same log with sigmas written 3x too small run with std_scale = 3,
    and without it (the control: what std_scale is for)."""
    rec = _recording(seed=0)
    small = replace(rec, gnss=replace(rec.gnss, std_enu=np.asarray(rec.gnss.std_enu, dtype=float) / 3.0))
    anyway = {"max_rejected_fraction": 1.0}      # the control run is wrong, and must still finish
    return (rec, _run(rec, _config(**anyway)), _run(small, _config(std_scale=3.0, **anyway)),
            _run(small, _config(**anyway)))


def test_std_scale_gives_the_filter_the_true_r(scale_runs):
    rec, truth, scaled, _ = scale_runs
    np.testing.assert_array_equal(scaled.diagnostics.t, truth.diagnostics.t)
    np.testing.assert_allclose(scaled.diagnostics.r_std, truth.diagnostics.r_std, rtol=1e-12)
    np.testing.assert_allclose(truth.diagnostics.r_std[0], rec.gnss.std_enu[0], rtol=1e-12)


def test_without_std_scale_the_small_sigmas_ruin_the_run(scale_runs):
    rec, truth, _, small = scale_runs
    assert small.gnss_rejected > 0.2 * small.gnss_epochs
    assert np.linalg.norm(_rmse_enu(rec, small.solution)) > 3.0 * np.linalg.norm(_rmse_enu(rec, truth.solution))


@needs_wiring
def test_std_scale_run_is_the_true_sigma_run(scale_runs):
    # the alignment's initial position covariance must take the scaled sigmas too (without them the
    # altitude of this drive differs by up to 9 m from the oracle's)
    rec, truth, scaled, _ = scale_runs
    np.testing.assert_allclose(_rmse_enu(rec, scaled.solution), _rmse_enu(rec, truth.solution), rtol=1e-6)
    assert float(np.max(np.abs(scaled.solution.alt - truth.solution.alt))) < 1e-6
    assert any(n.startswith("GNSS position sigmas scaled by 3") for n in scaled.notes)
    assert not any("std_scale" in n for n in truth.notes)
