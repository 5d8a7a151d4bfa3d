"""The 15-state error model against oracles: the error-state transition Phi against a
finite-difference Jacobian of the real strapdown, Qd against Van Loan's matrix exponential,
⊞/⊟ round trips, and the GNSS Jacobian against finite differences."""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from navpp.ins import model as M
from navpp.ins import strapdown as S
from navpp.ins.attitude import dcm_to_quat, rph_to_dcm
from navpp.simulate import SimulationSpec, simulate

BLOCKS = {"ATT": M.ATT, "VEL": M.VEL, "POS": M.POS, "BG": M.BG, "BA": M.BA}
EPS = np.array([1e-4] * 3 + [1e-2] * 3 + [1.0] * 3 + [1e-4] * 3 + [1e-2] * 3)
NOISE = M.NoiseModel(gyro_arw=1e-4, accel_vrw=1e-3, gyro_bias_psd=1e-12, gyro_bias_tau=math.inf,
                     accel_bias_psd=1e-8, accel_bias_tau=math.inf)


@pytest.fixture(scope="module")
def drive():
    sim = simulate(SimulationSpec(duration_s=120.0, preset="ideal", still_s=60.0))
    return sim, np.ascontiguousarray(sim.imu.t), np.ascontiguousarray(sim.imu.gyro), np.ascontiguousarray(sim.imu.accel)


def _truth_state(sim, t):
    st = sim.trajectory.state(np.array([t]))
    x = np.zeros(16)
    x[0:4] = dcm_to_quat(rph_to_dcm(*st["rph"][0]))
    x[4:7] = st["vel_enu"][0]
    x[7], x[8], x[9] = st["lat"][0], st["lon"][0], st["h"][0]
    x[10:13] = np.radians([0.01, -0.02, 0.015])
    x[13:16] = [0.02, -0.01, 0.03]
    return x


def _fd_jacobian(x0, t, gyro, accel, ta, tb):
    """d(end error)/d(start error) by central differences through the real strapdown."""
    x_end = x0.copy()
    no = np.empty((1, S.PATH_SIZE))
    S.integrate(x_end, t, gyro, accel, ta, tb, no, False, 0.0, S.NO_SEG_X, S.NO_SEG_FN, S.NO_SEG_T)
    J = np.zeros((15, 15))
    for i in range(15):
        cols = []
        for sgn in (1.0, -1.0):
            e = np.zeros(15)
            e[i] = sgn * EPS[i]
            xp = M.plus(x0, e)
            S.integrate(xp, t, gyro, accel, ta, tb, no, False, 0.0, S.NO_SEG_X, S.NO_SEG_FN, S.NO_SEG_T)
            cols.append(M.minus(xp, x_end))
        J[:, i] = (cols[0] - cols[1]) / (2 * EPS[i])
    return J, x_end


# (interval start in the drive: turning at 78 s, accelerating straight at 64 s, climbing at 104 s)
@pytest.mark.parametrize("ta,length", [(78.0, 0.2), (64.0, 0.2), (104.0, 0.2), (78.0, 0.1), (78.0, 1.0)])
def test_transition_matches_finite_difference_jacobian(drive, ta, length):
    sim, t, gyro, accel = drive
    x0 = _truth_state(sim, ta)
    mdl = M.InsModel(t, gyro, accel, NOISE, cov_step_s=0.05)
    x_end, Phi, _ = mdl.transition(x0, (ta, ta + length))
    J, x_ref = _fd_jacobian(x0, t, gyro, accel, ta, ta + length)
    np.testing.assert_allclose(x_end, x_ref, rtol=0, atol=1e-12)
    worst = {}
    for rn, r in BLOCKS.items():
        for cn, c in BLOCKS.items():
            mag = np.abs(J[r, c]).max()
            if mag < 1e-9:
                assert np.abs(Phi[r, c]).max() < 1e-8, (rn, cn)
                continue
            worst[(rn, cn)] = np.abs(Phi[r, c] - J[r, c]).max() / mag
    # the bias-driven blocks carry the covariance-step discretisation; VEL<-POS holds only the
    # tiny gravity-gradient and Earth-rate terms (|block| ~ 1e-6); all else is near exact
    for key, rel in worst.items():
        limit = 0.01 if ("BG" in key or "BA" in key or key == ("VEL", "POS")) else 2e-3
        assert rel < limit, (key, rel)


def test_phi_qd_match_van_loan_for_frozen_dynamics(drive):
    sim, _t, _gyro, _accel = drive
    x = _truth_state(sim, 78.0)
    fn = np.array([0.8, -2.0, 9.81])
    F = M.error_dynamics(x, fn, 1.0 / 300.0, 1.0 / 300.0)
    psd = M.NoiseModel(1e-3, 1e-2, 1e-9, 300.0, 1e-7, 300.0).psd()
    total, n_seg = 0.2, 20
    # Van Loan: expm([[-F, GQG], [0, F^T]] T) -> Phi = B22^T, Qd = Phi B12 (exact for frozen F)
    n = 15
    A = np.zeros((2 * n, 2 * n))
    A[:n, :n] = -F
    A[:n, n:] = np.diag(psd)
    A[n:, n:] = F.T
    B = expm(A * total)
    Phi_ex = B[n:, n:].T
    Qd_ex = Phi_ex @ B[:n, n:]
    seg_x = np.tile(x, (n_seg, 1))
    seg_fn = np.tile(fn, (n_seg, 1))
    Phi, Qd = M.transition_from_segments(x, seg_x, seg_fn, np.full(n_seg, total / n_seg), n_seg, psd,
                                          1.0 / 300.0, 1.0 / 300.0)
    assert np.max(np.abs(Phi - Phi_ex)) < 1e-8
    # trapezoidal Qd per step (ALGORITHMS.md): relative error ~ 1/n_seg^2 in the position block
    scale = np.sqrt(np.outer(np.diag(Qd_ex), np.diag(Qd_ex)))
    assert np.max(np.abs(Qd - Qd_ex) / np.where(scale > 0, scale, 1.0)) < 5e-3
    assert np.all(np.linalg.eigvalsh(Qd) > -1e-20)


def test_plus_minus_round_trip():
    rng = np.random.default_rng(3)
    x = np.zeros(16)
    x[0:4] = dcm_to_quat(rph_to_dcm(0.1, -0.2, 2.0))
    x[4:7] = [3.0, -4.0, 0.2]
    x[7], x[8], x[9] = math.radians(45.0), math.radians(179.9999), 300.0
    for _ in range(20):
        dx = rng.normal(size=15) * np.array([1e-2] * 3 + [1.0] * 3 + [10.0] * 3 + [1e-4] * 3 + [1e-2] * 3)
        y = M.plus(x, dx)
        assert -math.pi <= y[8] < math.pi                    # longitude wrapped across 180 deg
        np.testing.assert_allclose(M.minus(y, x), dx, rtol=1e-6, atol=1e-9)


def test_gnss_jacobian_matches_finite_differences(drive):
    sim, *_ = drive
    x = _truth_state(sim, 78.0)
    lever = np.array([0.5, -0.3, 1.2])
    meas = M.GnssPosition(78.0, x[7] + 1e-6, x[8] - 2e-6, x[9] + 1.0, np.eye(3), lever)
    H = meas.jacobian(x)
    Hfd = np.zeros((3, 15))
    for i in range(15):
        e = np.zeros(15)
        e[i] = EPS[i]
        # the innovation is z - h(x): its derivative is -H
        Hfd[:, i] = -(meas.innovation_at(M.plus(x, e)) - meas.innovation_at(M.plus(x, -e))) / (2 * EPS[i])
    np.testing.assert_allclose(H, Hfd, atol=1e-5)      # curvature terms ~ offset / R
    dX = np.random.default_rng(1).normal(size=(5, 15)) * EPS
    np.testing.assert_allclose(meas.predict_points(x, dX), dX @ H.T, atol=1e-3 * np.abs(dX @ H.T).max())


@pytest.mark.parametrize("lever", [(0.5, -0.3, 1.2), (0.0, 0.0, 0.0)])
def test_gnss_points_equal_the_measurement_of_each_point(drive, lever):
    """predict_points = innovation difference of every perturbed state, h(x ⊞ dX) - h(x),
    computed point by point through ⊞ and the innovation (the definition, as the oracle)."""
    sim, *_ = drive
    x = _truth_state(sim, 78.0)
    lever = np.array(lever)
    meas = M.GnssPosition(78.0, x[7], x[8], x[9], np.eye(3), lever)
    dX = np.random.default_rng(4).normal(size=(31, 15)) * np.array([3e-2] * 3 + [1.0] * 3 + [5.0] * 3
                                                                    + [1e-4] * 3 + [1e-2] * 3)
    expected = np.array([meas.innovation_at(x) - meas.innovation_at(M.plus(x, d)) for d in dX])
    # the innovation of a perturbed state uses that state's radii: curvature terms ~ |d|^2 / R ~ 4e-6 m
    np.testing.assert_allclose(meas.predict_points(x, dX), expected, rtol=0, atol=2e-5)


def test_reanchor_restarts_position_block():
    P = np.full((15, 15), 0.01) + np.eye(15)
    nu = np.array([20.0, -1.0, 0.5])
    R = np.diag([1.0, 1.0, 4.0])
    meas = M.GnssPosition(0.0, 0.7, 0.1, 300.0, R, np.zeros(3))
    Pn = meas.reanchor(P, nu, R)
    np.testing.assert_allclose(Pn[M.POS, M.POS], np.diag(nu ** 2) + R)
    assert np.all(Pn[M.POS, :3] == 0) and np.all(Pn[M.VEL, M.POS] == 0)
    np.testing.assert_array_equal(Pn[M.VEL, M.VEL], P[M.VEL, M.VEL])
    # recovery: velocity, attitude and gyro bias re-opened to their floors, uncorrelated
    floors = np.zeros(15)
    floors[M.VEL] = 3.0
    floors[M.ATT] = 0.1
    Pr = M.GnssPosition(0.0, 0.7, 0.1, 300.0, R, np.zeros(3), floors).reanchor(P, nu, R)
    np.testing.assert_allclose(np.diagonal(Pr)[M.VEL], 9.0)
    np.testing.assert_allclose(np.diagonal(Pr)[M.ATT], 1.01)       # the larger of the old 1.01 and 0.01
    assert np.all(Pr[M.VEL, M.BA] == 0) and np.all(Pr[M.ATT, M.VEL] == 0)
    np.testing.assert_array_equal(Pr[M.BA, M.BA], P[M.BA, M.BA])


def test_propagate_points_is_the_strapdown_in_error_space(drive):
    # the sigma-point interface: each point goes through the real strapdown and comes back as an
    # error about the propagated nominal; small points must follow Phi, and the nominal must be
    # the same one the EKF's transition produces (and records)
    sim, t, gyro, accel = drive
    x0 = _truth_state(sim, 78.0)
    mdl = M.InsModel(t, gyro, accel, NOISE)
    x_ekf, Phi, _ = mdl.transition(x0, (78.0, 78.2))
    dX = np.random.default_rng(2).normal(size=(6, 15)) * EPS * 1e-2
    x_new, dX_new = mdl.propagate_points(x0, dX, (78.0, 78.2))
    np.testing.assert_array_equal(x_new, x_ekf)
    np.testing.assert_allclose(dX_new, dX @ Phi.T, rtol=0, atol=2e-2 * np.abs(dX @ Phi.T).max())
    i = int(np.searchsorted(t, 78.2))
    np.testing.assert_array_equal(mdl.path[i], x_new[: S.PATH_SIZE])


def test_bias_process_keeps_turn_on_uncertainty():
    # the stationary variance q tau / 2 is turn-on^2 + instability^2, the drive the instability's
    q, tau = M.NoiseModel.bias_process(10.0, 1.0, 300.0)
    assert q == pytest.approx(2.0 / 300.0)
    assert q * tau / 2 == pytest.approx(101.0)
    assert M.NoiseModel.bias_process(10.0, 0.0, 300.0) == (0.0, math.inf)        # a random constant
    q, tau = M.NoiseModel.bias_process(10.0, 1.0, math.inf)
    assert tau == math.inf and q * 3600.0 == pytest.approx(1.0)                 # random walk


def test_gnss_offset_forms_are_the_same_bits():
    """The fused fix update computes the antenna offset once (gnss_*_offset): the same bits as
    gnss_innovation and gnss_jacobian, which compute it each."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        x = np.zeros(16)
        q = rng.normal(size=4)
        x[0:4] = q / np.linalg.norm(q)
        x[4:7] = rng.normal(scale=10.0, size=3)
        x[7], x[8], x[9] = rng.uniform(-1.2, 1.2), rng.uniform(-3.0, 3.0), rng.uniform(-50.0, 3000.0)
        lever = rng.normal(size=3)
        lat, lon, h = x[7] + rng.normal(scale=1e-6), x[8] + rng.normal(scale=1e-6), x[9] + rng.normal()
        offset = M.antenna_offset_enu(x, lever)
        assert M.gnss_innovation_offset(x, lat, lon, h, offset).tobytes() == \
            M.gnss_innovation(x, lat, lon, h, lever).tobytes()
        assert M.gnss_jacobian_offset(offset).tobytes() == M.gnss_jacobian(x, lever).tobytes()
