"""The papers' package (navpp/papers): its layering (no application layer, no import of an
experiment by the registry, no private name across modules) and the engine's loop driving a
simulated run exactly as a hand-written predict / update sequence does."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from navpp import papers
from navpp.engine.schedule import Epoch
from navpp.filters import GaussianState
from navpp.papers import montecarlo, sins, tracking, turn
from navpp.papers.simulated import OneMeasurementPerEpoch, measurement_epochs

PACKAGE = Path(papers.__file__).parent
EXPERIMENTS = {"tracking", "sins", "bearing", "turn", "table5_real", "xpn"}


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names) of every import in ``path`` (function-level too), resolved to absolute
    module names of navpp.papers."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = "navpp.papers" if node.level == 1 else "navpp" if node.level == 2 else ""
            mod = ".".join(x for x in (base, node.module or "") if x)
            out.append((mod, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
    return out


@pytest.mark.parametrize("path", sorted(PACKAGE.glob("*.py")), ids=lambda p: p.name)
def test_papers_import_no_application_layer_and_no_private_name(path):
    # table5_real scores real logs, so it runs them as the application does (navpp.api, config);
    # it still stays out of the command line
    app_layer = ("navpp.cli",) if path.name == "table5_real.py" else ("navpp.api", "navpp.config", "navpp.cli")
    for mod, names in _imports(path):
        assert mod not in app_layer, (path.name, mod)
        # the package's own modules: no private name; elsewhere: only the listed leftover
        private = [n for n in names if n.startswith("_") and n != "__future__"]
        allowed: set[tuple[str, str]] = set()
        assert all((mod, n) in allowed for n in private), (path.name, mod, private)


def test_only_the_package_init_imports_the_experiments():
    for path in PACKAGE.glob("*.py"):
        if path.name == "__init__.py":
            continue
        imported = {mod.rsplit(".", 1)[-1] for mod, names in _imports(path) if mod.startswith("navpp.papers")}
        imported |= {n for mod, names in _imports(path) if mod == "navpp.papers" for n in names}
        assert not imported & EXPERIMENTS, (path.name, imported & EXPERIMENTS)
    assert set(papers.BENCHMARKS) == {"paper001-tracking", "paper001-xpn", "paper002-sins", "paper003-bearing",
                                      "paper003-turn", "paper001-table5-real"}


def test_one_measurement_per_epoch_source():
    epochs = measurement_epochs(np.array([1.0, 2.5, 4.0]))
    assert [(e.t, e.index, e.coast) for e in epochs] == [(1.0, 0, False), (2.5, 1, False), (4.0, 2, False)]
    source = OneMeasurementPerEpoch(["a", "b", "c"])
    state = GaussianState(0.0, np.zeros(1), np.eye(1))
    assert source.measurements(Epoch(2.5, index=1), 0, state) == ["b"]
    assert source.measurements(Epoch(2.5, index=1), 1, state) is None


def _by_hand(filt, case):
    """The oracle: predict to each measurement time, update, keep the posterior."""
    state = GaussianState(float(case.times[0]), np.array(case.x0, dtype=float), np.array(case.P0, dtype=float))
    xs, Ps = [], []
    for k, meas in enumerate(case.measurements):
        state = filt.predict(state, case.model, (state.t, float(case.times[k + 1]))).state
        state = filt.update(state, case.model, meas).state
        xs.append(state.x)
        Ps.append(state.P)
    return np.array(xs), np.array(Ps)


@pytest.mark.parametrize("name, make_case", [("ekf", tracking.tracking_case), ("rwckf", tracking.tracking_case),
                                             ("vce-ckf", turn.turn_case)])
def test_run_filter_on_the_loop_equals_the_hand_written_sequence(name, make_case):
    case = make_case(montecarlo.truth_rng(3, 0))
    track = montecarlo.run_filter(papers.make_bench_filter(name, 7), case)
    x, P = _by_hand(papers.make_bench_filter(name, 7), case)
    assert track.error is None
    np.testing.assert_array_equal(track.x, x)
    np.testing.assert_array_equal(track.P, P)


def test_sins_run_filter_on_the_loop_equals_the_hand_written_sequence():
    from dataclasses import replace

    from navpp.ins.model import POS, VEL, InsModel, minus

    sc = replace(sins.Paper002Scenario(), duration_s=5.0)
    sim = sins.simulate_run(sc, np.random.default_rng(4))
    fr = sins.run_filter("aekf", sc, sim, seed=2)
    filt = papers.make_bench_filter("aekf", 2)
    model = InsModel(sim.t_imu, sim.gyro, sim.accel, sc.noise_model())
    R = np.diag(sc.meas_std() ** 2)
    state = GaussianState(float(sim.t_imu[0]), sim.x0.copy(), sim.P0.copy())
    for k, t in enumerate(sim.t_gps):
        meas = sins.GnssPositionVelocity(float(t), *sim.z_pos[k], sim.z_vel[k], R)
        state = filt.predict(state, model, (state.t, float(t))).state
        up = filt.update(state, model, meas)
        state = up.state
        dx = minus(sim.truth[k], state.x)
        np.testing.assert_array_equal(fr.err[k], np.r_[dx[POS], dx[VEL]])
        np.testing.assert_array_equal(fr.r_std[k], np.sqrt(np.diag(up.innovation.R)))
    assert fr.diverged == ""
    np.testing.assert_array_equal(fr.r_final, filt.adapter.R)
