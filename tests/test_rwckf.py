"""RWCKF (paper 001 eqs 22-32): Dirichlet weights against the paper's own sampler, the
epoch's weights against hand-computed moments, uniform weights against the CKF, selection."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from navpp import api
from navpp.config import config_from_dict
from navpp.errors import ConfigError
from navpp.filters import GaussianState, get_filter
from navpp.filters.linear import LinearMeasurement, LinearModel
from navpp.filters.rules import DirichletWeights
from navpp.simulate import SimulationSpec, simulate


def _paper_sampler(rng, m, size):
    """Paper 001's construction: gaps between sorted uniforms (the second implementation)."""
    u = np.sort(rng.uniform(size=(size, m - 1)), axis=1)
    edges = np.hstack([np.zeros((size, 1)), u, np.ones((size, 1))])
    return np.diff(edges, axis=1)


def test_dirichlet_weights_match_the_papers_sampler():
    m, size = 30, 20000
    ours = DirichletWeights().draw(np.random.default_rng(1), m, size)
    paper = _paper_sampler(np.random.default_rng(2), m, size)
    assert ours.shape == (size, m)
    assert np.all(ours >= 0)
    np.testing.assert_allclose(ours.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    # the marginal of D(1..1) is Beta(1, m-1); both samplers against it and against each other
    for sample in (ours[:, 0], paper[:, 0], ours[:, 17]):
        assert stats.kstest(sample, stats.beta(1, m - 1).cdf).pvalue > 1e-3
    assert stats.ks_2samp(ours[:, 3], paper[:, 3]).pvalue > 1e-3


def _linear_problem(seed=3, n=4):
    rng = np.random.default_rng(seed)
    Phi = np.eye(n) + np.diag(np.full(n - 1, 0.5), 1)
    A = rng.normal(size=(n, n))
    Q = 0.05 * A @ A.T + 0.01 * np.eye(n)
    H = np.eye(2, n)
    R = np.diag([0.7, 1.3])
    return LinearModel(Phi, Q), H, R, rng.normal(size=n), np.eye(n) * 2.0, rng


def _filter(**options):
    cls = get_filter("rwckf")
    return cls(cls.options_from_mapping(options), rng=np.random.default_rng(options.get("seed", 0)))


@pytest.mark.parametrize("covariance", ["random", "uniform"])
def test_epoch_weights_give_the_papers_moments(covariance, monkeypatch):
    """With a fixed weight vector beta, the prior and the measurement moments are eqs 24-28,
    written here directly from the cubature points: the means beta-weighted; the covariances
    beta-weighted about the beta means ("random", the paper's literal reading) or uniform about
    the uniform means ("uniform": the CKF's covariances)."""
    model, H, R, x0, P0, _ = _linear_problem()
    n, m = 4, 8
    beta = DirichletWeights().draw(np.random.default_rng(9), m)
    monkeypatch.setattr(DirichletWeights, "draw", lambda self, rng, m_, size=None: beta.copy())
    filt = _filter(select="none", covariance=covariance)
    state = GaussianState(0.0, x0, P0)
    prior = filt.predict(state, model, (0.0, 1.0)).state
    z = np.array([0.3, -0.2])
    up = filt.update(prior, model, LinearMeasurement(1.0, z, H, R))
    post, inn = up.state, up.innovation

    uni = np.full(m, 1 / m)
    wc = beta if covariance == "random" else uni         # the covariance weights and their centre
    S0 = np.linalg.cholesky(P0)
    X = np.vstack([x0 + np.sqrt(n) * S0[:, i] for i in range(n)] + [x0 - np.sqrt(n) * S0[:, i] for i in range(n)])
    Xs = X @ model.Phi.T
    x_pred = beta @ Xs                                                  # eq 24
    P_pred = (Xs - wc @ Xs).T @ np.diag(wc) @ (Xs - wc @ Xs) + model.Q  # eq 25 (centred)
    S1 = np.linalg.cholesky(P_pred)
    X1 = np.vstack([x_pred + np.sqrt(n) * S1[:, i] for i in range(n)]
                   + [x_pred - np.sqrt(n) * S1[:, i] for i in range(n)])
    Z = X1 @ H.T
    z_hat = beta @ Z                                                    # eq 26
    Pzz = (Z - wc @ Z).T @ np.diag(wc) @ (Z - wc @ Z) + R               # eq 27
    Pxz = (X1 - wc @ X1).T @ np.diag(wc) @ (Z - wc @ Z)                 # eq 28
    K = Pxz @ np.linalg.inv(Pzz)                                        # eq 29
    np.testing.assert_allclose(inn.nu, z - z_hat, atol=1e-12)
    np.testing.assert_allclose(inn.S, Pzz, atol=1e-12)
    np.testing.assert_allclose(post.x, x_pred + K @ (z - z_hat), atol=1e-12)     # eq 30
    np.testing.assert_allclose(post.P, P_pred - K @ Pzz @ K.T, atol=1e-12)       # eq 32


def test_uniform_weights_are_the_ckf_on_the_ins():
    sim = simulate(SimulationSpec(duration_s=120.0, seed=4))
    rec = sim.recording()
    cfg = config_from_dict({"filter": {"rwckf": {"weights": "uniform"}}}, "test")
    from navpp import engine
    a = engine.run(rec, cfg, api.make_filter("rwckf", cfg))
    b = engine.run(rec, cfg, api.make_filter("ckf", cfg))
    np.testing.assert_allclose(a.solution.lat_deg, b.solution.lat_deg, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.solution.std_enu, b.solution.std_enu, rtol=1e-9)


def _update_with_weights(beta, posterior, model, interval, meas, monkeypatch):
    """The predict and update of an RWCKF whose epoch weights are ``beta`` (None: uniform, the
    CKF) from ``posterior``, through the public interface: its one draw returns ``beta``."""
    if beta is None:
        filt = get_filter("ckf")()
        prior = filt.predict(posterior, model, interval).state
        return filt.update(prior, model, meas)
    filt = _filter(select="none")
    with monkeypatch.context() as mp:
        mp.setattr(DirichletWeights, "draw", lambda self, rng, m_, size=None: np.array(beta, dtype=float))
        prior = filt.predict(posterior, model, interval).state
        return filt.update(prior, model, meas)


def _likelihood_score(inn):
    """Paper 001's selection score of an update: ``nuᵀ S⁻¹ nu + ln det S``."""
    return float(inn.nu @ np.linalg.solve(inn.S, inn.nu) + np.linalg.slogdet(inn.S)[1])


def test_likelihood_selection_never_explains_the_fix_worse_than_the_ckf(monkeypatch):
    """The chosen candidate minimises the score over the candidates, which include the uniform
    vector; every candidate is replayed on its own (a filter whose only weights are that
    candidate's, from the same posterior) as the oracle for the selection."""
    model, H, R, x0, P0, rng = _linear_problem(seed=5)
    filt = _filter(candidates=8, seed=2)
    twin = np.random.default_rng(2)                 # replays the filter's draws
    state = GaussianState(0.0, x0, P0)
    for k in range(1, 30):
        interval = (k - 1.0, float(k))
        meas = LinearMeasurement(float(k), rng.normal(size=2) * 2, H, R)
        cands = [None, *DirichletWeights().draw(twin, 8, 8)]
        one_by_one = np.array([_likelihood_score(_update_with_weights(b, state, model, interval, meas,
                                                                        monkeypatch).innovation) for b in cands])
        up = filt.update(filt.predict(state, model, interval).state, model, meas)
        state, inn = up.state, up.innovation
        score = _likelihood_score(inn)
        assert score == pytest.approx(one_by_one.min(), rel=1e-9, abs=1e-9)
        assert score <= one_by_one[0] + 1e-9
        chosen = filt.noise_report()["weights"]
        best = cands[int(np.argmin(one_by_one))]
        np.testing.assert_array_equal(chosen, np.full(8, 1 / 8) if best is None else best)


def test_batched_scores_match_the_template_path_on_the_ins(monkeypatch):
    """On the INS the batched scoring composes attitude errors to first order only: the chosen
    candidate is the best one by the exact score, to well below the candidates' spread. The
    oracle replays every candidate of the filter's own draws through the public interface (a
    ``select = "none"`` RWCKF whose one draw is that candidate, the CKF for the uniform one)
    from the state before the last time update; the replay of the chosen candidate must give
    the filter's own update (the replay is faithful)."""
    from navpp import engine
    from navpp.ins.model import GnssPosition

    sim = simulate(SimulationSpec(duration_s=90.0, seed=5))
    rec = sim.recording()
    cfg = config_from_dict({}, "test")
    filt = api.make_filter("rwckf", cfg)
    draws, captured, last = [], [], {}
    real_draw, real_predict, real_update = DirichletWeights.draw, filt.predict, filt.update

    def draw(self, rng, m, size=None):
        out = real_draw(self, rng, m, size)
        draws.append(out)
        return out

    def predict(state, model, interval):
        out = real_predict(state, model, interval)
        last.update(before=state, model=model, interval=interval, after=out.state)
        return out

    def update(state, model, meas):
        out = real_update(state, model, meas)
        inn = out.innovation
        if len(captured) < 5 and isinstance(meas, GnssPosition) and state is last.get("after"):
            captured.append((last["before"], last["model"], last["interval"], meas, draws[-1],
                             filt.noise_report()["weights"], _likelihood_score(inn)))
        return out

    monkeypatch.setattr(DirichletWeights, "draw", draw)
    monkeypatch.setattr(filt, "predict", predict)
    monkeypatch.setattr(filt, "update", update)
    engine.run(rec, cfg, filt)
    monkeypatch.setattr(DirichletWeights, "draw", real_draw)
    assert len(captured) == 5
    one = config_from_dict({"filter": {"rwckf": {"select": "none"}}}, "test")
    for before, model, interval, meas, cands, chosen, score in captured:
        model = replace(model, path=None)                 # the run's path is released: a scratch one
        exact = []
        for beta in [None, *cands]:
            replay = api.make_filter("ckf" if beta is None else "rwckf", one)
            with monkeypatch.context() as mp:
                mp.setattr(DirichletWeights, "draw", lambda self, rng, m_, size=None, b=beta: np.array(b, dtype=float))
                prior = replay.predict(before, model, interval).state
                exact.append(_likelihood_score(replay.update(prior, model, meas).innovation))
        exact = np.array(exact)
        i = next(i for i, b in enumerate([np.full(chosen.size, 1 / chosen.size), *cands]) if np.array_equal(b, chosen))
        assert exact[i] == pytest.approx(score, rel=1e-9, abs=1e-9)          # the replay is faithful
        assert exact[i] - exact.min() < 1e-6 * max(1.0, np.ptp(exact)), (i, exact)


def test_residual_selection_picks_the_smallest_innovation(monkeypatch):
    model, H, R, x0, P0, _ = _linear_problem(seed=6)
    filt = _filter(select="residual", candidates=6, seed=4)
    start = GaussianState(0.0, x0, P0)
    meas = LinearMeasurement(1.0, np.array([2.0, -1.0]), H, R)
    # every candidate's innovation, each candidate replayed on its own with the same draws
    betas = [None, *DirichletWeights().draw(np.random.default_rng(4), 8, 6)]
    norms = [np.linalg.norm(_update_with_weights(b, start, model, (0.0, 1.0), meas, monkeypatch).innovation.nu)
             for b in betas]
    inn = filt.update(filt.predict(start, model, (0.0, 1.0)).state, model, meas).innovation
    assert np.linalg.norm(inn.nu) == pytest.approx(min(norms), rel=1e-12)
    assert len(set(np.round(norms, 9))) == len(norms)          # the candidates do differ


def test_runs_repeat_with_the_seed_and_differ_across_seeds():
    model, H, R, x0, P0, rng = _linear_problem(seed=7)
    zs = [rng.normal(size=2) for _ in range(10)]

    def run(seed):
        filt = _filter(seed=seed)
        state = GaussianState(0.0, x0, P0)
        for k, z in enumerate(zs, start=1):
            state = filt.predict(state, model, (k - 1.0, float(k))).state
            state = filt.update(state, model, LinearMeasurement(float(k), z, H, R)).state
        return state.x

    np.testing.assert_array_equal(run(1), run(1))
    assert not np.allclose(run(1), run(2))


def test_time_updates_between_fixes_use_uniform_weights():
    """Coasting steps are the CKF's; only the last step before a fix is re-weighted."""
    model, _, _, x0, P0, _ = _linear_problem(seed=8)
    rw, ckf = _filter(select="none", seed=3), get_filter("ckf")()
    a = b = GaussianState(0.0, x0, P0)
    for k in range(1, 5):
        a = rw.predict(a, model, (k - 1.0, float(k))).state
        b = ckf.predict(b, model, (k - 1.0, float(k))).state
        np.testing.assert_allclose(a.x, b.x, atol=1e-12)
        np.testing.assert_allclose(a.P, b.P, atol=1e-12)


@pytest.mark.parametrize("bad, match", [({"select": "best"}, "select"), ({"candidates": 0}, "candidates"),
                                        ({"covariance": "x"}, "covariance"), ({"seed": -1}, "seed"),
                                        ({"weights": "gauss"}, "weights")])
def test_bad_options_are_config_errors(bad, match):
    with pytest.raises(ConfigError, match=match):
        get_filter("rwckf").options_from_mapping(bad)
