"""The INS as a state-space model for the filters: 15-element error space around a nominal.

Error state (``true = nominal ⊞ dx``), in this order (ALGORITHMS.md):

=========  =====  =========================================================
block      slice  meaning
=========  =====  =========================================================
``ATT``    0:3    attitude error phi, ENU, rad: ``C_true = exp([phi x]) C_est``
``VEL``    3:6    velocity error, ENU, m/s
``POS``    6:9    position error, local ENU metres
``BG``     9:12   gyro bias error, body FLU, rad/s
``BA``     12:15  accelerometer bias error, body FLU, m/s^2
=========  =====  =========================================================

The nominal state is the 16-vector of :mod:`navpp.ins.strapdown`.  Filters see only
``plus``/``minus`` (⊞/⊟), ``transition`` (EKF: nominal propagation + Phi, Qd) and
``propagate_points`` (sigma-point filters: every point through the real strapdown).

Continuous error dynamics (psi-angle form, ENU; Groves 2013 eqs 14.64-14.72, paper 002 eqs 1-3):
``phi' = -[w_in x] phi - M_v dv - C dbg``;
``dv' = [f_n x]^T phi + ([v x] M_v - [(2 w_ie + w_en) x]) dv + dgamma/dh e_U dp_U - C dba``;
``dp' = dv``; ``dbg' = -dbg / tau_g + w``; ``dba' = -dba / tau_a + w`` (see
:meth:`NoiseModel.bias_process` for how tau and the drive follow from the datasheet).
Per covariance step of length T (<= ``cov_step_s``): ``Phi = I + F T + (F T)^2 / 2``,
``Qd = (Phi G Qc G^T Phi^T + G Qc G^T) T / 2`` (ALGORITHMS.md), accumulated over the interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numba import njit

from .. import geodesy
from .attitude import (
    quat_conj,
    quat_mul,
    quat_to_dcm,
    quat_to_rotvec,
    rotvec_quat_coeffs,
    rotvec_to_quat,
)
from .strapdown import PATH_SIZE, _nav_rates, radii
from .strapdown import integrate as _integrate_nominal

N_ERR = 15
ATT = slice(0, 3)
VEL = slice(3, 6)
POS = slice(6, 9)
BG = slice(9, 12)
BA = slice(12, 15)

#: An IMU interval longer than this many nominal sample periods is a long gap (dropped
#: messages, a logger stall).  The strapdown integrates across any gap with its true length,
#: interpolating the rates linearly; across a long gap the motion it cannot see is added to the
#: covariance (:meth:`InsModel.gap_noise`).  Shorter gaps (a few dropped samples) cost nothing
#: measurable at vehicle dynamics and are integrated silently.
LONG_GAP_PERIODS = 5.0
#: Unseen motion across a long gap of length T (s): the true specific force and rate depart
#: from the linear interpolation by a 1-sigma of ``min(JERK * T, ACCEL)`` (m/s^2, per ENU axis)
#: and ``min(ANG_ACCEL * T, RATE)`` (rad/s, per axis), constant over the gap: typical land
#: vehicle dynamics (braking / cornering), conservative for slower platforms.
GAP_JERK = 2.0              # m/s^3
GAP_ACCEL = 1.0             # m/s^2
GAP_ANG_ACCEL = 0.2         # rad/s^2
GAP_RATE = 0.1              # rad/s
#: The longest IMU gap the INS bridges: the gap whose unseen rotation (1-sigma
#: ``min(GAP_ANG_ACCEL * T, GAP_RATE) * T``, :meth:`InsModel.gap_noise`) reaches pi/3 rad, where
#: the 3-sigma attitude interval spans the whole circle: after a longer gap the heading is
#: unknown, not uncertain, the small-angle error model (sin x = x: 17 % off at pi/3) no longer
#: holds, and propagating through it writes free-inertial nonsense (10.5 s with the constants
#: above; a 10 s stall in motion is bridged, tests/test_faults.py, a 20 s one is not).
GAP_MAX_ATT_STD = math.pi / 3.0     # rad


def max_bridgeable_gap_s() -> float:
    """The longest IMU gap (s) whose unseen-rotation 1-sigma stays within :data:`GAP_MAX_ATT_STD`."""
    t = math.sqrt(GAP_MAX_ATT_STD / GAP_ANG_ACCEL)         # while the rate is still growing
    return t if GAP_ANG_ACCEL * t <= GAP_RATE else GAP_MAX_ATT_STD / GAP_RATE

_DGDH_H1 = geodesy._H1
_DGDH_H1_LAT = geodesy._H1_LAT
_DGDH_H2 = geodesy._H2


@dataclass(frozen=True)
class NoiseModel:
    """Continuous-time noise of the 15-state model, SI units.

    gyro_arw : rad/sqrt(s); accel_vrw : m/s/sqrt(s) (white noise densities).
    gyro_bias_psd, accel_bias_psd : drive of the bias states, (rad/s)^2/s and (m/s^2)^2/s.
    gyro_bias_tau, accel_bias_tau : correlation time of the bias states, s (``inf``: no decay).
    Build it from datasheet figures with :meth:`from_datasheet`.
    """

    gyro_arw: float
    accel_vrw: float
    gyro_bias_psd: float
    gyro_bias_tau: float
    accel_bias_psd: float
    accel_bias_tau: float

    @staticmethod
    def bias_process(turn_on: float, instability: float, tau: float) -> tuple[float, float]:
        """(drive psd, correlation time) of one bias state for a sensor whose bias is a random
        constant (1-sigma ``turn_on``) plus a Gauss-Markov process (``instability``, ``tau``).

        One first-order state cannot hold both, and a Gauss-Markov state with the
        instability's own (sigma, tau) forgets, within a few tau, that the constant part is
        unknown: its covariance collapses to the instability whether the bias was observed or
        not.  navpp keeps the instability's drive ``2 instability^2 / tau`` (how fast the bias
        really wanders) and stretches the correlation time so that the stationary variance is the
        sum, ``tau_eff = tau (turn_on^2 + instability^2) / instability^2``.  ``tau = inf`` is a
        random walk reaching the instability in one hour; no instability is a random constant.
        """
        if instability <= 0.0:
            return 0.0, math.inf
        if math.isinf(tau):
            return instability ** 2 / 3600.0, math.inf
        total = turn_on ** 2 + instability ** 2
        return 2.0 * instability ** 2 / tau, tau * total / instability ** 2

    @classmethod
    def from_datasheet(cls, gyro_arw: float, accel_vrw: float, gyro_bias_sigma: float,
                       gyro_bias_instability: float, gyro_bias_tau: float, accel_bias_sigma: float,
                       accel_bias_instability: float, accel_bias_tau: float) -> NoiseModel:
        """From SI datasheet figures (:class:`navpp.config.ImuNoise` fields)."""
        qg, tg = cls.bias_process(gyro_bias_sigma, gyro_bias_instability, gyro_bias_tau)
        qa, ta = cls.bias_process(accel_bias_sigma, accel_bias_instability, accel_bias_tau)
        return cls(gyro_arw, accel_vrw, qg, tg, qa, ta)

    def psd(self) -> np.ndarray:
        """Diagonal of G Qc G^T (the noise enters isotropically), (15,)."""
        return np.concatenate([np.full(3, self.gyro_arw ** 2), np.full(3, self.accel_vrw ** 2), np.zeros(3),
                               np.full(3, self.gyro_bias_psd), np.full(3, self.accel_bias_psd)])

    def inv_tau(self) -> tuple[float, float]:
        g = 0.0 if math.isinf(self.gyro_bias_tau) else 1.0 / self.gyro_bias_tau
        a = 0.0 if math.isinf(self.accel_bias_tau) else 1.0 / self.accel_bias_tau
        return g, a


@njit(cache=True)
def error_dynamics(x, fn, inv_tau_g, inv_tau_a):
    """Continuous error-state matrix F (15, 15) at nominal ``x`` with ENU specific force ``fn``."""
    F = np.zeros((15, 15))
    vel = x[4:7]
    lat, h = x[7], x[9]
    wie, wen, _g, rm, rn = _nav_rates(lat, h, vel)
    win = wie + wen
    C = quat_to_dcm(x[0:4])
    mv = np.zeros((3, 3))
    mv[0, 1] = -1.0 / (rm + h)
    mv[1, 0] = 1.0 / (rn + h)
    mv[2, 0] = np.tan(lat) / (rn + h)
    # attitude rows
    F[0, 1], F[0, 2] = win[2], -win[1]
    F[1, 0], F[1, 2] = -win[2], win[0]
    F[2, 0], F[2, 1] = win[1], -win[0]
    for r in range(3):
        for c in range(3):
            F[r, 3 + c] = -mv[r, c]
            F[r, 9 + c] = -C[r, c]
            F[3 + r, 12 + c] = -C[r, c]
    # velocity rows: phi x f_n = -[f_n x] phi
    F[3, 1], F[3, 2] = fn[2], -fn[1]
    F[4, 0], F[4, 2] = -fn[2], fn[0]
    F[5, 0], F[5, 1] = fn[1], -fn[0]
    w2 = 2.0 * wie + wen
    sk_v = np.array([[0.0, -vel[2], vel[1]], [vel[2], 0.0, -vel[0]], [-vel[1], vel[0], 0.0]])
    vm = sk_v @ mv
    F[3, 3], F[3, 4], F[3, 5] = vm[0, 0], vm[0, 1] + w2[2], vm[0, 2] - w2[1]
    F[4, 3], F[4, 4], F[4, 5] = vm[1, 0] - w2[2], vm[1, 1], vm[1, 2] + w2[0]
    F[5, 3], F[5, 4], F[5, 5] = vm[2, 0] + w2[1], vm[2, 1] - w2[0], vm[2, 2]
    s2 = np.sin(lat) ** 2
    F[5, 8] = _DGDH_H1 - _DGDH_H1_LAT * s2 - 2.0 * _DGDH_H2 * h   # -d(gravity)/dh
    # position rows
    F[6, 3] = F[7, 4] = F[8, 5] = 1.0
    for k in range(3):
        F[9 + k, 9 + k] = -inv_tau_g
        F[12 + k, 12 + k] = -inv_tau_a
    return F


@njit(cache=True)
def _transition_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd, inv_tau_g, inv_tau_a):
    """Accumulate Phi and Qd over the strapdown's segments (module docstring).

    F of a segment is the mean of F at its start and end states (with the segment's mean
    specific force), and Phi_j = I + FT + (FT)^2/2 + (FT)^3/6: the third-order term carries
    gyro bias -> attitude -> velocity -> position within one step.
    """
    Phi = np.eye(15)
    Qd = np.zeros((15, 15))
    F_prev_state = x_start
    for j in range(n_seg):
        T = seg_T[j]
        Phi_j = _segment_phi(F_prev_state, seg_x[j], seg_fn[j], T, inv_tau_g, inv_tau_a)
        Phi = Phi_j @ Phi
        Qd = Phi_j @ Qd @ Phi_j.T + _segment_qd(Phi_j, psd, T)
        F_prev_state = seg_x[j]
    return Phi, Qd


@njit(cache=True)
def _segment_phi(x_start, x_end, fn, T, inv_tau_g, inv_tau_a):
    """Phi of one segment: F the mean of F at its start and end states, to third order in FT."""
    F = 0.5 * (error_dynamics(x_start, fn, inv_tau_g, inv_tau_a) + error_dynamics(x_end, fn, inv_tau_g, inv_tau_a))
    FT = F * T
    FT2 = FT @ FT
    return np.eye(15) + FT + 0.5 * FT2 + (FT2 @ FT) / 6.0


@njit(cache=True)
def _segment_qd(Phi_j, psd, T):
    """Qd of one segment by the trapezoid: (Phi_j GQG Phi_j^T + GQG) T / 2 with GQG = diag(psd)."""
    Qd_j = Phi_j * (psd * (0.5 * T)) @ Phi_j.T
    for k in range(15):
        Qd_j[k, k] += 0.5 * T * psd[k]
    return Qd_j


@njit(cache=True)
def integrate_with_jacobian(x, t, gyro, accel, t_start, t_end, out, record, psd,
                            inv_tau_g, inv_tau_a, cov_step_s):
    """Propagate nominal ``x`` (in place) and return the interval's (Phi, Qd).

    The error-state transition is accumulated over the strapdown's segments of about
    ``cov_step_s``.
    """
    m = int((t_end - t_start) / cov_step_s) + 2
    seg_x = np.empty((m, 16))
    seg_fn = np.empty((m, 3))
    seg_T = np.empty(m)
    x_start = x.copy()
    n_seg = _integrate_nominal(x, t, gyro, accel, t_start, t_end, out, record, cov_step_s, seg_x, seg_fn, seg_T)
    return _transition_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd, inv_tau_g, inv_tau_a)


#: process-noise groups of the 15-state model (VCE): name -> error-state indices driven by it.
#: White noise enters the attitude and velocity errors in ENU (``G Qc G^T`` is diagonal and
#: isotropic, :meth:`NoiseModel.psd`); the bias drives act on the body-FLU bias states.
NOISE_GROUPS_TRIAD: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("gyro_white", (0, 1, 2)), ("accel_white", (3, 4, 5)), ("gyro_bias", (9, 10, 11)), ("accel_bias", (12, 13, 14)))
NOISE_GROUPS_AXIS: tuple[tuple[str, tuple[int, ...]], ...] = tuple(
    (f"{name}_{axis}", (idx,))
    for name, first, axes in (("gyro_white", 0, "enu"), ("accel_white", 3, "enu"),
                              ("gyro_bias", 9, "xyz"), ("accel_bias", 12, "xyz"))
    for idx, axis in zip(range(first, first + 3), axes))


@njit(cache=True)
def _noise_groups_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd_groups, inv_tau_g, inv_tau_a):
    """Qd of every noise group over the strapdown's segments, in one pass, (G, 15, 15).

    Same discretisation as :func:`_transition_from_segments` (Phi_j to third order, Qd_j by the
    trapezoid), with the psd masked to one group at a time: Qd is linear in the psd, so the
    groups sum to the interval's Qd.
    """
    G = psd_groups.shape[0]
    Qg = np.zeros((G, 15, 15))
    F_prev_state = x_start
    for j in range(n_seg):
        T = seg_T[j]
        Phi_j = _segment_phi(F_prev_state, seg_x[j], seg_fn[j], T, inv_tau_g, inv_tau_a)
        for g in range(G):
            Qg[g] = Phi_j @ Qg[g] @ Phi_j.T + _segment_qd(Phi_j, psd_groups[g], T)
        F_prev_state = seg_x[j]
    return Qg


@njit(cache=True)
def integrate_noise_groups(x, t, gyro, accel, t_start, t_end, psd_groups, inv_tau_g, inv_tau_a, cov_step_s):
    """Propagate nominal ``x`` (in place, nothing recorded) and return the interval's Qd per
    noise group, (G, 15, 15), the psd of group g being ``psd_groups[g]`` (15,)."""
    m = int((t_end - t_start) / cov_step_s) + 2
    seg_x = np.empty((m, 16))
    seg_fn = np.empty((m, 3))
    seg_T = np.empty(m)
    x_start = x.copy()
    unused = np.empty((1, PATH_SIZE))
    n_seg = _integrate_nominal(x, t, gyro, accel, t_start, t_end, unused, False, cov_step_s, seg_x, seg_fn, seg_T)
    return _noise_groups_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd_groups, inv_tau_g, inv_tau_a)


@njit(cache=True, inline="always")
def _wrap_pi(a):
    """Angle difference wrapped to [-pi, pi) (longitude across the antimeridian)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def plus(x, dx):
    """Nominal ⊞ error: ``x`` (16,) and ``dx`` (15,) -> (16,)."""
    y = x.copy()
    y[0:4] = quat_mul(rotvec_to_quat(dx[0:3]), x[0:4])
    y[4:7] = x[4:7] + dx[3:6]
    rm, rn = radii(x[7])
    h = x[9]
    y[7] = x[7] + dx[7] / (rm + h)
    y[8] = _wrap_pi(x[8] + dx[6] / ((rn + h) * np.cos(x[7])))
    y[9] = h + dx[8]
    y[10:13] = x[10:13] + dx[9:12]
    y[13:16] = x[13:16] + dx[12:15]
    return y


@njit(cache=True)
def minus(x1, x0):
    """Error taking ``x0`` to ``x1``: ``x1 = x0 ⊞ minus(x1, x0)``, (15,)."""
    dx = np.empty(15)
    dx[0:3] = quat_to_rotvec(quat_mul(x1[0:4], quat_conj(x0[0:4])))
    dx[3:6] = x1[4:7] - x0[4:7]
    rm, rn = radii(x0[7])
    h = x0[9]
    dx[6] = _wrap_pi(x1[8] - x0[8]) * (rn + h) * np.cos(x0[7])
    dx[7] = (x1[7] - x0[7]) * (rm + h)
    dx[8] = x1[9] - h
    dx[9:12] = x1[10:13] - x0[10:13]
    dx[12:15] = x1[13:16] - x0[13:16]
    return dx


@njit(cache=True)
def _propagate_points(x, dX, t, gyro, accel, t_start, t_end, out, record):
    no_seg = np.empty((0, 16))      # (module-level empty arrays would be read-only constants here)
    no_seg3 = np.empty((0, 3))
    no_t = np.empty(0)
    xn = x.copy()
    _integrate_nominal(xn, t, gyro, accel, t_start, t_end, out, record, 0.0, no_seg, no_seg3, no_t)
    dX_new = np.empty_like(dX)
    unused = np.empty((1, PATH_SIZE))
    for k in range(dX.shape[0]):
        xk = plus(x, dX[k])
        _integrate_nominal(xk, t, gyro, accel, t_start, t_end, unused, False, 0.0, no_seg, no_seg3, no_t)
        dX_new[k] = minus(xk, xn)
    return xn, dX_new



@njit(cache=True, inline="always")
def _plus_row(row, c):
    """``row ⊞ c`` in place for a recorded path row (q_nb, vel_enu, lat, lon, h): the same
    arithmetic as :func:`plus`, without temporaries (it runs once per IMU sample)."""
    w, s = rotvec_quat_coeffs(c[0], c[1], c[2])
    p0, p1, p2, p3 = w, s * c[0], s * c[1], s * c[2]
    q0, q1, q2, q3 = row[0], row[1], row[2], row[3]
    row[0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    row[1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    row[2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    row[3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    row[4] += c[3]
    row[5] += c[4]
    row[6] += c[5]
    lat, h = row[7], row[9]
    rm, rn = radii(lat)
    row[7] = lat + c[7] / (rm + h)
    row[8] = _wrap_pi(row[8] + c[6] / ((rn + h) * np.cos(lat)))
    row[9] = h + c[8]


@njit(cache=True)
def apply_node_corrections(path, t, node_t, xs, x_post, x_ref):
    """Move a recorded forward path (N, PATH_SIZE) onto a smoothed one, in place.

    ``t`` (N,) sample times (s, increasing); ``node_t`` (M,) the forward run's node times;
    ``xs`` (M, 16) smoothed nominal states at the nodes; ``x_post`` (M, 16) the forward
    posterior at each node (where the path between that node and the next starts); ``x_ref``
    (M, 16) the nominal the time update ending at each node reached (where that path ends).
    A sample strictly between nodes k and k+1 moves by the error correction interpolated
    linearly in time from ``xs[k] ⊟ x_post[k]`` to ``xs[k+1] ⊟ x_ref[k+1]``; a sample at a
    node's time takes that node's smoothed state.  Samples outside the node span are left.
    """
    n = t.shape[0]
    m = node_t.shape[0]
    width = path.shape[1]
    j = 0
    cl = np.zeros(15)
    cr = np.zeros(15)
    c = np.zeros(15)
    have = -1                                # the interval whose corrections are in cl, cr
    for i in range(n):
        ti = t[i]
        while j < m - 1 and node_t[j + 1] < ti:
            j += 1
        if ti < node_t[0] or ti > node_t[m - 1]:
            continue
        if ti == node_t[j] or (j + 1 < m and ti == node_t[j + 1]):
            k = j if ti == node_t[j] else j + 1
            path[i, :] = xs[k, :width]
            continue
        if have != j:
            cl = minus(xs[j], x_post[j])
            cr = minus(xs[j + 1], x_ref[j + 1])
            have = j
        span = node_t[j + 1] - node_t[j]
        w = (ti - node_t[j]) / span if span > 0.0 else 1.0
        for e in range(15):
            c[e] = (1.0 - w) * cl[e] + w * cr[e]
        _plus_row(path[i], c)


@njit(cache=True)
def rts_means(x_post, x_prior, gains, reset):
    """The smoother's mean recursion on the INS nominal (:func:`navpp.filters.smoother.smooth_arrays`):
    ``xs[k] = x_post[k] ⊞ gains[k+1] (xs[k+1] ⊟ x_prior[k+1])`` backwards from the last node,
    ``xs[k] = x_post[k]`` where ``reset[k+1]``.  (M, 16) arrays, gains (M, 15, 15)."""
    m = x_post.shape[0]
    xs = np.empty_like(x_post)
    xs[m - 1] = x_post[m - 1]
    for k in range(m - 2, -1, -1):
        if reset[k + 1]:
            xs[k] = x_post[k]
        else:
            xs[k] = plus(x_post[k], gains[k + 1] @ minus(xs[k + 1], x_prior[k + 1]))
    return xs


@dataclass
class InsModel:
    """Strapdown INS over one recording's IMU data, in 15-element error space.

    Parameters
    ----------
    t : (N,) s; gyro : (N, 3) rad/s; accel : (N, 3) m/s^2 (body FLU, mounting applied).
    noise : continuous noise model (SI).
    cov_step_s : longest covariance-propagation step, s.
    profile : optional measured white-noise profile (vibration): raises Q where the log shakes.

    ``path`` (N, PATH_SIZE) receives the attitude, velocity and position of the nominal state
    at every IMU sample a transition passes (biases change only at updates: the engine keeps
    them per epoch).
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    noise: NoiseModel
    cov_step_s: float = 0.05
    path: np.ndarray | None = None
    dim: int = N_ERR
    #: white noise the data show (:class:`navpp.ins.calibrate.NoiseProfile`): over an interval,
    #: Q's gyro and accel white noise is the larger of ``noise`` and the profile's
    profile: object | None = None

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.gyro = np.ascontiguousarray(self.gyro, dtype=float)
        self.accel = np.ascontiguousarray(self.accel, dtype=float)
        self._psd = self.noise.psd()
        self._inv_tau = self.noise.inv_tau()
        if self.path is None:
            self.path = np.full((self.t.shape[0], PATH_SIZE), np.nan)
        # long gaps: (start, end) times of IMU intervals over LONG_GAP_PERIODS nominal periods
        dt = np.diff(self.t)
        k = np.nonzero(dt > LONG_GAP_PERIODS * np.median(dt))[0] if dt.size > 1 else np.zeros(0, int)
        self.gaps = np.column_stack([self.t[k], self.t[k + 1]]) if k.size else np.zeros((0, 2))

    def psd_over(self, interval: tuple[float, float]) -> np.ndarray:
        """Diagonal of G Qc G^T (15,) over ``interval``: the configured noise, with the white noise
        raised to the measured profile where the data shake more (vibration, steps)."""
        if self.profile is None:
            return self._psd
        g, a = self.profile.over(interval[0], interval[1])
        psd = self._psd
        if g * g <= psd[0] and a * a <= psd[3]:
            return psd
        psd = psd.copy()
        psd[0:3] = max(psd[0], g * g)
        psd[3:6] = max(psd[3], a * a)
        return psd

    def gap_noise(self, interval: tuple[float, float]) -> np.ndarray | None:
        """Covariance (15, 15) of the motion the IMU did not see in the long gaps inside
        ``interval`` (None when there is none), referred to the interval's end.

        The specific force and rate depart from the strapdown's linear interpolation by
        constants ``df`` (m/s^2, ENU) and ``dw`` (rad/s) over a gap of length ``T`` ending ``r``
        seconds before the interval's end (sigmas: :data:`GAP_JERK` ... :data:`GAP_RATE`): the
        attitude error is ``dw T``, the velocity error ``df T``, the position error
        ``df (T^2 / 2 + T r)``.  Couplings through the specific force and the Earth's rotation
        over the gap are neglected (second order over a gap of seconds).
        """
        if self.gaps.shape[0] == 0:
            return None
        t0, t1 = interval
        Q = None
        first = int(np.searchsorted(self.gaps[:, 1], t0, side="right"))     # gaps are sorted and disjoint
        last = int(np.searchsorted(self.gaps[:, 0], t1, side="left"))
        for a, b in self.gaps[first:last]:
            lo, hi = max(a, t0), min(b, t1)
            if hi <= lo:
                continue
            T, r = hi - lo, t1 - hi
            sf = min(GAP_JERK * T, GAP_ACCEL)
            sw = min(GAP_ANG_ACCEL * T, GAP_RATE)
            sp = T * T / 2.0 + T * r
            if Q is None:
                Q = np.zeros((N_ERR, N_ERR))
            for i in range(3):
                Q[i, i] += (sw * T) ** 2
                Q[3 + i, 3 + i] += (sf * T) ** 2
                Q[6 + i, 6 + i] += (sf * sp) ** 2
                Q[3 + i, 6 + i] += sf * sf * T * sp
                Q[6 + i, 3 + i] += sf * sf * T * sp
        return Q

    #: the smoother's mean recursion, compiled (:func:`rts_means`)
    rts_means = staticmethod(rts_means)
    #: VCE's process-noise groups reach the fixes through many time updates (filters.protocols)
    noise_share: ClassVar[str] = "propagated"

    # ⊞ / ⊟ -----------------------------------------------------------------------------------
    @staticmethod
    def plus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return plus(x, np.ascontiguousarray(dx, dtype=float))

    @staticmethod
    def minus(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        return minus(x1, x0)

    # propagation ---------------------------------------------------------------------------
    def transition(self, x: np.ndarray, interval: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nominal propagation over ``interval = (t_start, t_end)`` with its Phi (15, 15) and Qd."""
        xn = x.copy()
        Phi, Qd = integrate_with_jacobian(xn, self.t, self.gyro, self.accel, interval[0], interval[1],
                                          self.path, True, self.psd_over(interval), self._inv_tau[0], self._inv_tau[1],
                                          self.cov_step_s)
        Qg = self.gap_noise(interval)
        return xn, Phi, (Qd if Qg is None else Qd + Qg)

    def process_noise(self, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        """Qd over the interval (additive noise for sigma-point filters)."""
        xn = x.copy()
        _, Qd = integrate_with_jacobian(xn, self.t, self.gyro, self.accel, interval[0], interval[1],
                                        self.path, False, self.psd_over(interval), self._inv_tau[0], self._inv_tau[1],
                                        self.cov_step_s)
        Qg = self.gap_noise(interval)
        return Qd if Qg is None else Qd + Qg

    def noise_groups(self, x: np.ndarray, interval: tuple[float, float], per: str = "triad"
                     ) -> tuple[list[str], np.ndarray]:
        """Qd over the interval split by noise source (for variance component estimation).

        Parameters
        ----------
        x : nominal state (16,) at ``interval[0]``.
        interval : (t_start, t_end), s.
        per : ``"triad"``: four groups ``gyro_white, accel_white, gyro_bias, accel_bias``;
            ``"axis"``: twelve, one per axis (white noise per ENU axis, ``_e/_n/_u``; bias drive
            per body FLU axis, ``_x/_y/_z``).  Groups whose psd is zero are left out.

        Returns
        -------
        names : list of G group names; Qs : (G, 15, 15), summing to :meth:`process_noise`.
        """
        table = {"triad": NOISE_GROUPS_TRIAD, "axis": NOISE_GROUPS_AXIS}.get(per)
        if table is None:
            raise ValueError(f"noise_groups: per must be 'triad' or 'axis', got {per!r}")
        names, rows = [], []
        base = self.psd_over(interval)
        for name, idx in table:
            mask = np.zeros(N_ERR)
            mask[list(idx)] = 1.0
            psd = base * mask
            if np.any(psd > 0.0):
                names.append(name)
                rows.append(psd)
        if not rows:
            return [], np.zeros((0, N_ERR, N_ERR))
        xn = x.copy()
        Qs = integrate_noise_groups(xn, self.t, self.gyro, self.accel, interval[0], interval[1],
                                    np.ascontiguousarray(np.array(rows)), self._inv_tau[0], self._inv_tau[1],
                                    self.cov_step_s)
        return names, 0.5 * (Qs + Qs.transpose(0, 2, 1))

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Push error points ``dX`` (m, 15) around ``x`` through the strapdown.

        Returns the propagated nominal ``f(x)`` and the points ``f(x ⊞ dX_i) ⊟ f(x)``.
        """
        return _propagate_points(x, np.ascontiguousarray(dX, dtype=float), self.t, self.gyro, self.accel,
                                 interval[0], interval[1], self.path, True)


@njit(cache=True)
def antenna_offset_enu(x, lever_arm_b):
    """ENU offset (m) of an antenna at ``lever_arm_b`` (body FLU, m) from the nominal position."""
    return quat_to_dcm(x[0:4]) @ lever_arm_b


@dataclass(frozen=True)
class GnssPosition:
    """GNSS antenna position fix as a measurement of the 15-state model.

    The residual is the fix minus the INS-predicted antenna position, in local ENU metres
    about the nominal position; ``R`` (3, 3) is the fix covariance, m^2.
    H = [ -[(C l) x], 0, I, 0, 0 ].
    """

    t: float
    lat: float   # rad
    lon: float   # rad
    h: float     # m
    R: np.ndarray
    lever_arm_b: np.ndarray
    #: (15,) 1-sigma floors a forced fix re-opens besides the position (velocity, attitude, gyro
    #: bias: a run of rejections is INS drift, not a GNSS jump); None: the position only
    reopen_std: np.ndarray | None = None
    axes: ClassVar[tuple[str, ...]] = ("e", "n", "u")     # names of the measurement's elements
    kind: ClassVar[str] = "gnss_position"
    adaptive: ClassVar[bool] = True       # adaptive filters learn their noise from it
    forceable: ClassVar[bool] = True      # forced in after a run of gate rejections (re-anchored)

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        return _gnss_innovation(x, self.lat, self.lon, self.h, self.lever_arm_b)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return _gnss_jacobian(x, self.lever_arm_b)

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) ⊟ h(x)`` in ENU metres, (m, 3)."""
        return _gnss_points(x, np.ascontiguousarray(dX, dtype=float), self.lever_arm_b)

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Covariance for a fix forced through the gate: the position block restarts from the
        innovation (``diag(nu^2) + R``) uncorrelated with the rest, so a GNSS jump moves the
        position without kicking velocity and attitude through stale cross-covariances.  With
        ``reopen_std``, every state with a positive floor is re-opened too (its variance at least
        the floor squared, its correlations dropped): the INS drifted, and what it was sure of
        (heading, velocity, gyro bias) is what the rejections say is wrong."""
        P = P.copy()
        P[POS, :] = 0.0
        P[:, POS] = 0.0
        P[POS, POS] = np.diag(nu ** 2) + R
        if self.reopen_std is not None:
            idx = np.nonzero(np.asarray(self.reopen_std) > 0.0)[0]
            keep = np.diagonal(P)[idx].copy()
            P[idx, :] = 0.0
            P[:, idx] = 0.0
            P[idx, idx] = np.maximum(keep, np.asarray(self.reopen_std)[idx] ** 2)
        return P


@njit(cache=True)
def _gnss_innovation(x, lat, lon, h, lever):
    rm, rn = radii(x[7])
    hx = x[9]
    d = np.empty(3)
    d[0] = _wrap_pi(lon - x[8]) * (rn + hx) * np.cos(x[7])
    d[1] = (lat - x[7]) * (rm + hx)
    d[2] = h - hx
    return d - antenna_offset_enu(x, lever)


@njit(cache=True)
def _gnss_jacobian(x, lever):
    H = np.zeros((3, 15))
    a = antenna_offset_enu(x, lever)
    # -[a x]
    H[0, 1], H[0, 2] = a[2], -a[1]
    H[1, 0], H[1, 2] = -a[2], a[0]
    H[2, 0], H[2, 1] = a[1], -a[0]
    H[0, 6] = H[1, 7] = H[2, 8] = 1.0
    return H


@njit(cache=True)
def _gnss_points(x, dX, lever):
    """``h(x ⊞ dX_k) ⊟ h(x)`` for error points ``dX`` (m, 15): ENU m, (m, 3).

    ``minus(plus(x, d), x)`` returns the position part of ``d`` unchanged (both use the radii
    at ``x``), so the antenna moves by ``d[6:9]`` plus the change of the rotated lever arm,
    ``(exp([phi x]) - I) C a``; written that way it costs one small rotation per point instead
    of a quaternion round trip (the sigma-point filters call this for every candidate point).
    """
    m = dX.shape[0]
    Z = np.empty((m, 3))
    a0 = antenna_offset_enu(x, lever)
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    for k in range(m):
        Z[k, 0] = dX[k, 6]
        Z[k, 1] = dX[k, 7]
        Z[k, 2] = dX[k, 8]
        if has_lever:
            Z[k] += quat_to_dcm(rotvec_to_quat(dX[k, 0:3])) @ a0 - a0
    return Z
