"""Filter core: every registered filter against the closed-form Kalman filter on a linear
model; gating; options validation."""

import numpy as np
import pytest
from scenarios import linear_problem

from navpp.errors import ConfigError, FilterDivergedError
from navpp.filters import FILTERS, GaussianState, get_filter
from navpp.filters.linear import LinearMeasurement, LinearModel


def _kalman_reference(x, P, Phi, Q, z, H, R):
    """Textbook Kalman filter, written independently with explicit inverses (the oracle)."""
    x = Phi @ x
    P = Phi @ P @ Phi.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    x = x + K @ (z - H @ x)
    P = (np.eye(len(x)) - K @ H) @ P
    return x, P


def _problem(seed=1, n=4, m=2):
    return linear_problem(seed, n, m, steps=8)


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_every_filter_equals_kalman_on_linear_model(name):
    Phi, Q, H, R, x0, P0, zs = _problem()
    model = LinearModel(Phi, Q)
    cls = FILTERS[name]
    filt = cls(cls.options_from_mapping(cls.oracle_options))      # adaptation off
    state = GaussianState(0.0, x0, P0)
    x_ref, P_ref = x0, P0
    for k, z in enumerate(zs, start=1):
        state = filt.predict(state, model, (k - 1.0, float(k))).state
        up = filt.update(state, model, LinearMeasurement(float(k), z, H, R))
        state, inn = up.state, up.innovation
        assert inn.accepted
        x_ref, P_ref = _kalman_reference(x_ref, P_ref, Phi, Q, z, H, R)
        np.testing.assert_allclose(state.x, x_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(state.P, P_ref, rtol=1e-8, atol=1e-10)
        np.testing.assert_array_equal(state.P, state.P.T)


def test_innovation_record_and_nis():
    Phi, Q, H, R, x0, P0, zs = _problem()
    filt = get_filter("ekf")()
    model = LinearModel(Phi, Q)
    state = filt.predict(GaussianState(0.0, x0, P0), model, (0.0, 1.0)).state
    inn = filt.update(state, model, LinearMeasurement(1.0, zs[0], H, R)).innovation
    nu = zs[0] - H @ state.x
    S = H @ state.P @ H.T + R
    np.testing.assert_allclose(inn.nu, nu)
    np.testing.assert_allclose(inn.S, S)
    assert inn.nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-10)


def test_gate_rejects_outlier_then_forces_acceptance():
    n = 2
    model = LinearModel(np.eye(n), 1e-4 * np.eye(n))
    H = np.eye(n)
    R = np.eye(n)
    filt = get_filter("ekf")(gate_probability=0.999, reanchor_after_s=1.5)
    state = GaussianState(0.0, np.zeros(n), np.eye(n))
    outlier = LinearMeasurement(1.0, np.array([100.0, 0.0]), H, R)
    results = []
    for k in range(3):
        state = filt.predict(state, model, (float(k), k + 1.0)).state
        before = state.x.copy()
        up = filt.update(state, model, outlier)
        state, inn = up.state, up.innovation
        results.append(inn.accepted)
        if not inn.accepted:
            np.testing.assert_array_equal(state.x, before)   # a rejected fix changes nothing
    # chi2(2) 99.9 % = 13.8: the 100 m outlier is rejected at t = 1 and 2, forced in at t = 3
    assert results == [False, False, True]
    assert filt.rejected == 2


def test_gate_threshold_is_chi_square_quantile():
    filt = get_filter("ekf")(gate_probability=0.99)
    assert filt.gate_threshold(1) == pytest.approx(6.634896601, rel=1e-8)
    assert filt.gate_threshold(3) == pytest.approx(11.34486673, rel=1e-8)
    assert get_filter("ekf")(gate_probability=0.0).gate_threshold(3) == np.inf


def test_unknown_filter_lists_choices():
    with pytest.raises(ConfigError, match="ekf"):
        get_filter("ekff")


def test_filter_without_options_rejects_keys():
    with pytest.raises(ConfigError, match=r"\[filter.ekf\]"):
        get_filter("ekf").options_from_mapping({"alpha": 1.0}, "cfg.toml")


def test_divergence_is_reported_not_propagated():
    from navpp.errors import FilterDivergedError

    n = 2
    Q = np.eye(n)
    Q[0, 1] = Q[1, 0] = np.nan
    model = LinearModel(np.eye(n), Q)
    filt = get_filter("ekf")()
    state = filt.predict(GaussianState(0.0, np.zeros(n), np.eye(n)), model, (0.0, 1.0)).state
    with pytest.raises(FilterDivergedError, match=r"t=1\.000"):
        filt.update(state, model, LinearMeasurement(1.0, np.ones(n), np.eye(n), np.eye(n)))


def test_sigma_point_filter_repairs_a_slightly_indefinite_covariance():
    n = 3
    model = LinearModel(np.eye(n), 1e-3 * np.eye(n))
    P = np.diag([1.0, 1.0, -1e-9])                       # lost definiteness by round-off
    filt = get_filter("ckf")()
    state = filt.predict(GaussianState(0.0, np.zeros(n), P), model, (0.0, 1.0)).state
    assert filt.repairs == 1
    assert np.all(np.linalg.eigvalsh(state.P) > 0)
    with pytest.raises(FilterDivergedError, match=r"ckf: covariance is not finite at t=0\.000 s"):
        filt.predict(GaussianState(0.0, np.zeros(n), np.full((n, n), np.nan)), model, (0.0, 1.0))


def test_gain_and_nis_same_bits_as_chol_solve():
    """gain_and_nis solves row by row without transposed copies: the same bits as chol_solve on
    Pxz^T and on nu (the form it had), and nis by the same dot product."""
    from navpp.filters.linalg import chol_solve, cholesky, gain_and_nis
    from navpp.kernel import njit

    dot = njit()(lambda a, b: a @ b)    # the compiled dot product gain_and_nis uses
    rng = np.random.default_rng(11)
    for m in (1, 2, 3, 6):
        for _ in range(10):
            A = rng.normal(size=(m, m))
            S = A @ A.T + m * np.eye(m)
            Pxz = rng.normal(size=(15, m))
            nu = rng.normal(size=m)
            K, nis, ok = gain_and_nis(Pxz, S, nu)
            L, ok_ref = cholesky(S)
            assert ok and ok_ref
            K_ref = chol_solve(L, np.ascontiguousarray(Pxz.T)).T.copy()
            w = chol_solve(L, nu.reshape(-1, 1))[:, 0].copy()
            assert K.tobytes() == K_ref.tobytes()
            assert nis == dot(nu, w)
    K, nis, ok = gain_and_nis(np.ones((15, 3)), -np.eye(3), np.ones(3))
    assert not ok and nis == np.inf
