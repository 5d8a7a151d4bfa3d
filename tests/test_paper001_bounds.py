"""Paper 001 tracking's bounds (navpp/papers/bounds.py, tracking.py): the PCRB against the
Kalman filter's Riccati covariance on a linear-Gaussian model, the information blocks against
second implementations (linear closed form, finite-difference scores), and the bootstrap particle
filter against the Kalman filter on a linear-Gaussian model."""

from __future__ import annotations

import numpy as np
import pytest

from navpp.papers import bounds, tracking


def _riccati(Phi, Q, H, R, P0, steps):
    """The oracle: the Kalman filter's posterior covariances, predict then update, (steps, n, n)."""
    P, out = P0, []
    for _ in range(steps):
        P = Phi @ P @ Phi.T + Q
        K = np.linalg.solve(H @ P @ H.T + R, H @ P).T
        P = (np.eye(len(P)) - K @ H) @ P
        out.append(P)
    return np.array(out)


def test_pcrb_on_a_linear_gaussian_model_is_the_kalman_covariance():
    Phi, _, Q, H = tracking.tracking_matrices()
    R = np.diag([1.0, 0.5])
    steps = 30
    got = bounds.pcrb_recursion(np.linalg.inv(tracking.TRACK_P0), *bounds.linear_blocks(Phi, Q, H, R, steps))
    np.testing.assert_allclose(got, _riccati(Phi, Q, H, R, tracking.TRACK_P0, steps), rtol=1e-9, atol=1e-12)


def test_tracking_blocks_at_standstill_are_the_linear_blocks():
    """g and its Jacobian vanish at zero speed, so the previous-reading blocks are the linear ones."""
    Phi, _, Q, H = tracking.tracking_matrices()
    truths = np.zeros((3, 6, 4))
    truths[..., 0] = np.arange(6.0)                 # positions anywhere, speeds zero
    for got, want in zip(tracking.tracking_blocks(truths, "previous"), bounds.linear_blocks(Phi, Q, H, np.eye(2), 5)):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_additive_and_score_blocks_agree_on_a_linear_model():
    """Two forms of the information (Jacobian and score outer product) on ``x_k = Phi x + w``: the
    score form is a Monte Carlo mean, 20,000 draws, so a relative tolerance of about 5 sigma."""
    Phi, _, Q, H = tracking.tracking_matrices()
    rng = np.random.default_rng(3)
    Qi = np.linalg.inv(Q)
    w = rng.standard_normal((20_000, 1, 4)) @ np.linalg.cholesky(Q).T
    s1, s2 = (w @ Qi) @ Phi, -(w @ Qi)
    A = np.broadcast_to(Phi, (2, 1, 4, 4))
    for got, want in zip(bounds.score_blocks(s1, s2, H, np.eye(2)), bounds.additive_blocks(A, Q, H, np.eye(2))):
        scale = np.max(np.abs(want))
        np.testing.assert_allclose(got / scale, want / scale, atol=0.05)


def _log_density(prev, cur):
    """Second implementation of the implicit reading's log p(x_k | x_{k-1}) (up to a constant):
    the Gaussian of ``w = x_k - F g(x_k) - Phi x_{k-1}`` and the finite-difference log-Jacobian."""
    Phi, F, Q, _ = tracking.tracking_matrices()

    def h(x):
        return x - F @ tracking.systematic_error(x)

    w = h(cur) - Phi @ prev
    eps = 1e-6
    Dh = np.column_stack([(h(cur + eps * e) - h(cur - eps * e)) / (2 * eps) for e in np.eye(4)])
    return -0.5 * w @ np.linalg.solve(Q, w) + np.log(abs(np.linalg.det(Dh)))


def test_implicit_scores_are_the_gradients_of_the_log_density():
    rng = np.random.default_rng(5)
    for _ in range(4):
        prev = tracking.TRACK_X0 + rng.standard_normal(4)
        cur = tracking.tracking_step(prev, rng.standard_normal(4), g_at="current")
        s1, s2 = tracking.implicit_scores(prev, cur)
        eps = 1e-5
        fd1 = [(_log_density(prev + eps * e, cur) - _log_density(prev - eps * e, cur)) / (2 * eps) for e in np.eye(4)]
        fd2 = [(_log_density(prev, cur + eps * e) - _log_density(prev, cur - eps * e)) / (2 * eps) for e in np.eye(4)]
        np.testing.assert_allclose(s1, fd1, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(s2, fd2, rtol=1e-5, atol=1e-5)


def test_tracking_pcrb_lies_between_the_one_step_bound_and_the_kalman_filter():
    """A few hundred truths: the PCRB must sit above the one-step bound sqrt(0.5) (it knows less)
    and below the Kalman filter's 1.23 m (docs/papers.md); near the 4,000-truth 1.040 / 1.008 m."""
    for g_at, full in (("previous", 1.040), ("current", 1.008)):
        bound, se, curve, kept = tracking.tracking_pcrb(np.random.default_rng(1), g_at, truths=400)
        assert kept > 250 and curve.shape == (tracking.TRACK_STEPS,)
        assert np.sqrt(0.5) < bound < 1.2 and bound == pytest.approx(full, abs=0.02), (g_at, bound)
        assert 0 < se < 0.01


def test_particle_filter_matches_the_kalman_filter_on_a_linear_gaussian_model():
    """On ``x_k = Phi x + w`` the Kalman filter is the optimal filter; a 2,000-particle PF must
    reach its RMSE.  Paired over 8 runs x 30 steps the PF - KF differences are PF sampling error
    (a few per cent of the error); a PF without the weighting would be at the prior's spread
    (several times worse)."""
    Phi, _, Q, H = tracking.tracking_matrices()
    R = np.eye(2)
    P0 = tracking.TRACK_P0
    rng = np.random.default_rng(8)
    pf_err, kf_err = [], []
    for run in range(8):
        x = tracking.TRACK_X0 + np.sqrt(np.diag(P0)) * rng.standard_normal(4)
        X, Z = [], []
        for _ in range(30):
            x = Phi @ x + np.linalg.cholesky(Q) @ rng.standard_normal(4)
            X.append(x)
            Z.append(H @ x + rng.standard_normal(2))
        X, Z = np.array(X), np.array(Z)
        m, P, kf = tracking.TRACK_X0.copy(), P0.copy(), []
        for z in Z:
            m, P = Phi @ m, Phi @ P @ Phi.T + Q
            K = np.linalg.solve(H @ P @ H.T + R, H @ P).T
            m, P = m + K @ (z - H @ m), (np.eye(4) - K @ H) @ P
            kf.append(m)
        pf = bounds.bootstrap_pf(Z, np.random.default_rng(100 + run), lambda x, w: x @ Phi.T + w, Q, H, R,
                                 tracking.TRACK_X0, P0, particles=2000)
        pf_err.append(pf - X)
        kf_err.append(np.array(kf) - X)
    pf_err, kf_err = np.array(pf_err), np.array(kf_err)
    ratio = np.sqrt(np.mean(pf_err[..., [0, 2]] ** 2) / np.mean(kf_err[..., [0, 2]] ** 2))
    assert ratio == pytest.approx(1.0, abs=0.03), ratio
    # and the PF's estimate sits near the KF's own (sampling error small against the KF's error)
    assert np.sqrt(np.mean((pf_err - kf_err)[..., [0, 2]] ** 2)) < 0.2 * np.sqrt(np.mean(kf_err[..., [0, 2]] ** 2))


def test_rmse_intervals_cover_the_pooled_rmse():
    err = np.random.default_rng(2).standard_normal((40, 10, 4))
    lo, hi = bounds.rmse_interval(err)
    pooled = np.sqrt(np.mean(np.sum(err[..., [0, 2]] ** 2, axis=-1)))
    assert lo < pooled < hi and hi - lo < 0.2 * pooled
    lo, hi = bounds.ratio_interval(err, err)
    assert lo == pytest.approx(1.0) and hi == pytest.approx(1.0)
