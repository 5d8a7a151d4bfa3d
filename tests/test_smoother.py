"""RTS smoothing: every registered filter's stored forward run against a textbook RTS smoother
on a linear model (the oracle); rejected fixes, re-anchored fixes; the IMU-rate corrections."""

import numpy as np
import pytest
from scenarios import linear_problem

from navpp.filters import FILTERS, GaussianState, Prediction
from navpp.filters.linear import LinearMeasurement, LinearModel
from navpp.filters.smoother import ForwardStore, rts_smooth


def _problem(seed=3, n=4, m=2, steps=12):
    return linear_problem(seed, n, m, steps)


def _textbook_rts(x0, P0, Phi, Q, H, R, zs, skip=()):
    """Kalman filter then RTS, with explicit inverses (written independently of navpp).
    Steps in ``skip`` have no measurement.  Returns smoothed means and covariances of the
    initial state and every step."""
    xf, Pf, xp, Pp = [x0], [P0], [x0], [P0]
    x, P = x0, P0
    for k, z in enumerate(zs):
        x, P = Phi @ x, Phi @ P @ Phi.T + Q
        xp.append(x)
        Pp.append(P)
        if k not in skip:
            K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
            x, P = x + K @ (z - H @ x), (np.eye(len(x)) - K @ H) @ P
        xf.append(x)
        Pf.append(P)
    xs, Ps = [xf[-1]], [Pf[-1]]
    for k in range(len(zs) - 1, -1, -1):
        C = Pf[k] @ Phi.T @ np.linalg.inv(Pp[k + 1])
        xs.insert(0, xf[k] + C @ (xs[0] - xp[k + 1]))
        Ps.insert(0, Pf[k] + C @ (Ps[0] - Pp[k + 1]) @ C.T)
    return np.array(xs), np.array(Ps)


def _navpp_forward(filt, model, x0, P0, zs, H, R, skip=(), reset_at=None, **store_options):
    """The engine's protocol on a linear model: a node per time update, the update recorded
    (the one of node ``reset_at`` as if its fix had been forced).  A float64 store unless
    ``store_options`` say otherwise."""
    state = GaussianState(0.0, x0, P0)
    store = ForwardStore(len(x0), len(x0), **{"dtype": np.float64, **store_options})
    store.start(state)
    innovations = []
    for k, z in enumerate(zs, start=1):
        pred = filt.predict(state, model, (k - 1.0, float(k)))
        state = pred.state
        store.predicted(pred)
        if k - 1 in skip:
            continue
        up = filt.update(state, model, LinearMeasurement(float(k), z, H, R))
        state, inn = up.state, up.innovation
        store.updated(up.prior_used, state, inn.forced or k == reset_at)
        innovations.append(inn)
    return store, innovations


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_every_filter_smooths_like_textbook_rts_on_a_linear_model(name):
    Phi, Q, H, R, x0, P0, zs = _problem()
    skip = {4, 5, 6}                             # an outage: three steps without a measurement
    model = LinearModel(Phi, Q)
    cls = FILTERS[name]
    filt = cls(cls.options_from_mapping(cls.oracle_options))
    store, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip)
    sm = rts_smooth(store, model)
    xs, Ps = _textbook_rts(x0, P0, Phi, Q, H, R, zs, skip)
    np.testing.assert_allclose(sm.x, xs, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(sm.var, np.diagonal(Ps, axis1=1, axis2=2), rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(sm.t, np.arange(len(zs) + 1.0))
    assert sm.breaks == 0 and sm.repaired == 0


def test_smoothed_variance_is_below_the_filtered_one():
    Phi, Q, H, R, x0, P0, zs = _problem(seed=5)
    model = LinearModel(Phi, Q)
    filt = FILTERS["ekf"]()
    state, filtered = GaussianState(0.0, x0, P0), [np.diag(P0)]
    for k, z in enumerate(zs, start=1):
        state = filt.predict(state, model, (k - 1.0, float(k))).state
        if k - 1 not in {3, 4, 5, 6}:
            state = filt.update(state, model, LinearMeasurement(float(k), z, H, R)).state
        filtered.append(np.diag(state.P))
    store, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={3, 4, 5, 6})
    sm = rts_smooth(store, model)
    assert np.all(sm.var <= np.array(filtered) + 1e-12)
    np.testing.assert_array_equal(sm.var[-1], filtered[-1])       # the last node is the filter's


def test_a_rejected_measurement_smooths_as_if_it_were_absent():
    Phi, Q, H, R, x0, P0, _ = _problem(seed=7)
    rng = np.random.default_rng(8)          # measurements of a simulated truth, so the gate passes them
    truth, zs = rng.multivariate_normal(x0, P0), []
    for _ in range(12):
        truth = Phi @ truth + rng.multivariate_normal(np.zeros(len(x0)), Q)
        zs.append(H @ truth + rng.multivariate_normal(np.zeros(len(R)), R))
    zs[5] = zs[5] + 1e4                                               # an outlier the gate rejects
    model = LinearModel(Phi, Q)
    gated = FILTERS["ekf"](gate_probability=0.999)
    store, inns = _navpp_forward(gated, model, x0, P0, zs, H, R)
    assert [i.accepted for i in inns].count(False) == 1 and not inns[5].accepted
    sm = rts_smooth(store, model)
    xs, Ps = _textbook_rts(x0, P0, Phi, Q, H, R, zs, skip={5})
    np.testing.assert_allclose(sm.x, xs, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(sm.var, np.diagonal(Ps, axis1=1, axis2=2), rtol=1e-7, atol=1e-10)


def test_no_information_is_carried_back_across_a_reanchored_fix():
    Phi, Q, H, R, x0, P0, zs = _problem(seed=11)
    model = LinearModel(Phi, Q)
    store, _ = _navpp_forward(FILTERS["ekf"](), model, x0, P0, zs, H, R, reset_at=7)
    plain, _ = _navpp_forward(FILTERS["ekf"](), model, x0, P0, zs, H, R)
    x_post = rts_smooth(plain, model).x_post                  # the forward posteriors (no reset)
    sm = rts_smooth(store, model)
    # before the reset: exactly the smoothing of the run that ends at node 6
    xs, Ps = _textbook_rts(x0, P0, Phi, Q, H, R, zs[:6])
    np.testing.assert_allclose(sm.x[:7], xs, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(sm.var[:7], np.diagonal(Ps, axis1=1, axis2=2), rtol=1e-7, atol=1e-10)
    assert sm.breaks == 1
    np.testing.assert_array_equal(sm.x[6], x_post[6])          # node 6 keeps its forward posterior


def test_blocks_and_spilling_change_nothing(tmp_path):
    """Blocks of 3 nodes against one block; a budget below one block (every full block spilled
    to a temporary file in ``tmp_path``, deleted when the store closes): the same bytes."""
    Phi, Q, H, R, x0, P0, zs = _problem(seed=13, steps=40)
    model = LinearModel(Phi, Q)
    filt = FILTERS["ekf"]()
    one, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={10, 11}, dtype=np.float32)
    small, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={10, 11}, dtype=np.float32, block_nodes=3)
    spilled, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={10, 11}, dtype=np.float32, block_nodes=3,
                                budget_bytes=1, spill_dir=str(tmp_path))
    assert spilled.spilled_blocks == 12 and list(tmp_path.iterdir()) == []    # unlinked at once
    a, b, c = (rts_smooth(s, model) for s in (one, small, spilled))
    for field in ("t", "x", "var", "x_post", "x_ref"):
        np.testing.assert_array_equal(getattr(b, field), getattr(a, field))
        np.testing.assert_array_equal(getattr(c, field), getattr(a, field))
    assert spilled.n == 0 and spilled.spilled_blocks == 0


def test_float32_storage_changes_the_smoothing_by_rounding_only():
    Phi, Q, H, R, x0, P0, zs = _problem(seed=17, steps=40)
    model = LinearModel(Phi, Q)
    filt = FILTERS["ekf"]()
    f8, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={20, 21, 22})
    f4, _ = _navpp_forward(filt, model, x0, P0, zs, H, R, skip={20, 21, 22}, dtype=np.float32)
    a, b = rts_smooth(f8, model), rts_smooth(f4, model)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-6 * np.abs(a.x).max())
    np.testing.assert_allclose(b.var, a.var, rtol=1e-5)


def test_store_refuses_a_cross_covariance_of_the_wrong_shape():
    store = ForwardStore(2, 2)
    store.start(GaussianState(0.0, np.zeros(2), np.eye(2)))
    with pytest.raises(ValueError, match="cross_cov has shape"):
        store.predicted(Prediction(GaussianState(1.0, np.zeros(2), np.eye(2)), np.zeros((3, 3)), np.zeros(2)))


def test_node_corrections_move_the_path_by_the_interpolated_error():
    """On the INS nominal: a sample between two nodes moves by the linearly interpolated
    correction (checked against model.plus applied row by row); a sample at a node takes the
    node's smoothed state."""
    from navpp.ins.model import apply_node_corrections, minus, plus
    from navpp.ins.strapdown import PATH_SIZE

    rng = np.random.default_rng(2)
    x = np.zeros(16)
    x[0] = 1.0                                              # identity attitude
    x[4:7] = [10.0, 5.0, 0.1]
    x[7], x[8], x[9] = np.radians(45.0), np.radians(7.0), 300.0
    node_t = np.array([0.0, 1.0, 2.5])
    x_post = np.array([plus(x, rng.normal(scale=1e-3, size=15)) for _ in node_t])
    x_ref = np.array([plus(x, rng.normal(scale=1e-3, size=15)) for _ in node_t])
    xs = np.array([plus(x, rng.normal(scale=1e-2, size=15)) for _ in node_t])
    t = np.array([0.0, 0.25, 0.5, 1.0, 1.3, 2.5])
    path = np.array([plus(x, rng.normal(scale=1e-3, size=15))[:PATH_SIZE] for _ in t])
    want = path.copy()
    for i, ti in enumerate(t):
        k = int(np.searchsorted(node_t, ti, side="right")) - 1
        if ti in node_t:
            want[i] = xs[list(node_t).index(ti), :PATH_SIZE]
            continue
        w = (ti - node_t[k]) / (node_t[k + 1] - node_t[k])
        c = (1 - w) * minus(xs[k], x_post[k]) + w * minus(xs[k + 1], x_ref[k + 1])
        full = np.zeros(16)
        full[:PATH_SIZE] = path[i]
        want[i] = plus(full, c)[:PATH_SIZE]
    apply_node_corrections(path, t, node_t, xs, x_post, x_ref)
    np.testing.assert_allclose(path, want, rtol=0, atol=1e-12)


def test_compiled_ins_mean_recursion_equals_the_generic_one():
    """InsModel.rts_means (compiled) against the recursion written out over model.plus / minus."""
    from navpp.ins.model import InsModel, NoiseModel, plus

    rng = np.random.default_rng(4)
    x = np.zeros(16)
    x[0] = 1.0
    x[7], x[8], x[9] = np.radians(45.0), np.radians(7.0), 300.0
    m = 30
    a = {"x_post": np.array([plus(x, rng.normal(scale=1e-3, size=15)) for _ in range(m)]),
         "x_prior": np.array([plus(x, rng.normal(scale=1e-3, size=15)) for _ in range(m)]),
         "gains": 0.3 * rng.normal(size=(m, 15, 15)), "reset": np.zeros(m, bool)}
    a["reset"][11] = True
    a["gains"][11] = 0.0
    ins = InsModel(np.arange(3.0), np.zeros((3, 3)), np.zeros((3, 3)), NoiseModel(0, 0, 0, np.inf, 0, np.inf))

    class Generic:                         # the recursion written out over the same plus / minus
        plus, minus = staticmethod(ins.plus), staticmethod(ins.minus)

        def rts_means(self, x_post, x_prior, gains, reset):
            xs = np.empty_like(x_post)
            xs[-1] = x_post[-1]
            for k in range(len(x_post) - 2, -1, -1):
                xs[k] = x_post[k] if reset[k + 1] else self.plus(x_post[k], gains[k + 1] @ self.minus(xs[k + 1],
                                                                                                    x_prior[k + 1]))
            return xs

    fast = ins.rts_means(a["x_post"], a["x_prior"], a["gains"], a["reset"])
    slow = Generic().rts_means(a["x_post"], a["x_prior"], a["gains"], a["reset"])
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
