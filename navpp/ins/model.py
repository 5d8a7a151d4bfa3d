"""The INS as a state-space model for the filters: 15-element error space around a nominal.

The error state ``dx`` (``true = nominal ⊞ dx``: attitude, velocity, position, gyro bias,
accelerometer bias; docs/algorithms.md) and the 16-element nominal state of
:mod:`navpp.ins.strapdown` are laid out in :mod:`navpp.ins.state`.  Filters see only
``plus``/``minus`` (⊞/⊟), ``transition`` (EKF: nominal propagation + Phi, Qd) and
``propagate_points`` (sigma-point filters: every point through the real strapdown).

Continuous error dynamics (psi-angle form, ENU; Groves 2013 eqs 14.64-14.72, paper 002 eqs 1-3):
``phi' = -[w_in x] phi - M_v dv - C dbg``;
``dv' = [f_n x]^T phi + ([v x] M_v - [(2 w_ie + w_en) x]) dv + dgamma/dh e_U dp_U - C dba``;
``dp' = dv``; ``dbg' = -dbg / tau_g + w``; ``dba' = -dba / tau_a + w`` (see
:meth:`NoiseModel.bias_process` for how tau and the drive follow from the datasheet).
Per covariance step of length T (<= ``cov_step_s``): ``Phi = I + F T + (F T)^2 / 2``,
``Qd = (Phi G Qc G^T Phi^T + G Qc G^T) T / 2`` (docs/algorithms.md), accumulated over the interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from navpp.kernel import njit

from ..geodesy import GRAVITY_H1, GRAVITY_H1_LAT, GRAVITY_H2, OMEGA_E
from ..intervals import interval_median, long_intervals
from ..recording import LONG_GAP_PERIODS
from .attitude import (
    quat_conj,
    quat_mul,
    quat_to_dcm,
    quat_to_rotvec,
    rotvec_quat_coeffs,
    rotvec_to_quat,
)
from .state import (
    ATT,
    BA,
    BG,
    DP_E,
    DP_N,
    DP_U,
    DX_ATT,
    DX_BA,
    DX_BG,
    DX_POS,
    DX_VEL,
    N_ERR,
    NOMINAL_Q,
    NOMINAL_SIZE,
    PATH_SIZE,
    POS,
    VEL,
    X_BA,
    X_BG,
    X_H,
    X_LAT,
    X_LON,
    X_QW,
    X_QX,
    X_QY,
    X_QZ,
    X_VE,
    X_VN,
    X_VU,
)
from .strapdown import integrate as integrate_nominal
from .strapdown import radii

if TYPE_CHECKING:
    from .calibrate import NoiseProfile

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
#: holds, and propagating through it writes free-inertial nonsense (the gap length:
#: :func:`max_bridgeable_gap_s`).
GAP_MAX_ATT_STD = math.pi / 3.0     # rad


def max_bridgeable_gap_s() -> float:
    """The longest IMU gap (s) whose unseen-rotation 1-sigma stays within :data:`GAP_MAX_ATT_STD`."""
    t = math.sqrt(GAP_MAX_ATT_STD / GAP_ANG_ACCEL)         # while the rate is still growing
    return t if GAP_ANG_ACCEL * t <= GAP_RATE else GAP_MAX_ATT_STD / GAP_RATE


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
        """Diagonal of G Qc G^T (the noise enters isotropically), (15,): gyro white noise on the
        attitude error, accelerometer white noise on the velocity error, the bias drives on the
        bias errors, (rad/s)^2/s ... in the units of each block per second."""
        psd = np.zeros(N_ERR)
        psd[ATT] = self.gyro_arw ** 2
        psd[VEL] = self.accel_vrw ** 2
        psd[BG] = self.gyro_bias_psd
        psd[BA] = self.accel_bias_psd
        return psd

    def inv_tau(self) -> tuple[float, float]:
        """(1 / gyro_bias_tau, 1 / accel_bias_tau), 1/s; 0 for an infinite correlation time."""
        g = 0.0 if math.isinf(self.gyro_bias_tau) else 1.0 / self.gyro_bias_tau
        a = 0.0 if math.isinf(self.accel_bias_tau) else 1.0 / self.accel_bias_tau
        return g, a


@njit(cache=True, inline="always")
def _set_neg_skew(M: np.ndarray, r0: int, c0: int, w: np.ndarray) -> None:
    """Write the off-diagonal elements of ``-[w x]`` into the 3x3 block of ``M`` at (r0, c0)
    (its diagonal is left as it is)."""
    M[r0, c0 + 1], M[r0, c0 + 2] = w[2], -w[1]
    M[r0 + 1, c0], M[r0 + 1, c0 + 2] = -w[2], w[0]
    M[r0 + 2, c0], M[r0 + 2, c0 + 1] = w[1], -w[0]


@njit(cache=True, inline="always")
def error_dynamics(x: np.ndarray, fn: np.ndarray, inv_tau_g: float, inv_tau_a: float) -> np.ndarray:
    """Continuous error-state matrix F (15, 15) at nominal ``x`` with ENU specific force ``fn``
    (m/s^2) and bias correlation rates ``inv_tau_g``, ``inv_tau_a`` (1/s); equations in the
    module docstring."""
    F = _error_dynamics_state(x, inv_tau_g, inv_tau_a)
    _set_neg_skew(F, DX_VEL, DX_ATT, fn)
    return F


@njit(cache=True, inline="always")
def _error_dynamics_state(x: np.ndarray, inv_tau_g: float, inv_tau_a: float) -> np.ndarray:
    """:func:`error_dynamics` without the specific force's block (velocity rows, attitude
    columns: its off-diagonal elements are left zero), the part that depends on ``x`` alone."""
    F = np.zeros((N_ERR, N_ERR))
    _error_dynamics_into(x, inv_tau_g, inv_tau_a, F)
    return F


@njit(cache=True, inline="always")
def _error_dynamics_into(x: np.ndarray, inv_tau_g: float, inv_tau_a: float, F: np.ndarray) -> None:
    """:func:`_error_dynamics_state` into ``F`` (15, 15), whose other elements (those this never
    writes) must be zero, without temporaries (the transition calls it once per segment)."""
    ve, vn, vu = x[X_VE], x[X_VN], x[X_VU]
    lat, h = x[X_LAT], x[X_H]
    rm, rn = radii(lat)
    wie_n, wie_u = OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)
    tl = np.tan(lat)
    wen_e, wen_n, wen_u = -vn / (rm + h), ve / (rn + h), ve * tl / (rn + h)
    # d(w_en)/d(dv), its non-zero elements (row, column)
    mv01, mv10, mv20 = -1.0 / (rm + h), 1.0 / (rn + h), tl / (rn + h)
    # attitude rows: -[w_in x] phi - M_v dv - C dbg
    win_e, win_n, win_u = wen_e, wie_n + wen_n, wie_u + wen_u
    a = DX_ATT
    F[a, a + 1], F[a, a + 2] = win_u, -win_n
    F[a + 1, a], F[a + 1, a + 2] = -win_u, win_e
    F[a + 2, a], F[a + 2, a + 1] = win_n, -win_e
    F[a, DX_VEL + 1], F[a + 1, DX_VEL], F[a + 2, DX_VEL] = -mv01, -mv10, -mv20
    qw, qx, qy, qz = x[X_QW], x[X_QX], x[X_QY], x[X_QZ]     # C = quat_to_dcm(q), element by element
    c00, c01, c02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)
    c10, c11, c12 = 2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)
    c20, c21, c22 = 2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)
    for blk_r, blk_c in ((DX_ATT, DX_BG), (DX_VEL, DX_BA)):
        F[blk_r, blk_c], F[blk_r, blk_c + 1], F[blk_r, blk_c + 2] = -c00, -c01, -c02
        F[blk_r + 1, blk_c], F[blk_r + 1, blk_c + 1], F[blk_r + 1, blk_c + 2] = -c10, -c11, -c12
        F[blk_r + 2, blk_c], F[blk_r + 2, blk_c + 1], F[blk_r + 2, blk_c + 2] = -c20, -c21, -c22
    # velocity rows: phi x f_n = -[f_n x] phi (set by error_dynamics), ([v x] M_v - [(2 w_ie + w_en) x]) dv,
    # gravity's height gradient; [v x] M_v has five non-zero elements
    w2e, w2n, w2u = wen_e, 2.0 * wie_n + wen_n, 2.0 * wie_u + wen_u
    v = DX_VEL
    F[v, v], F[v, v + 1], F[v, v + 2] = -vu * mv10 + vn * mv20, w2u, -w2n
    F[v + 1, v], F[v + 1, v + 1], F[v + 1, v + 2] = -ve * mv20 - w2u, vu * mv01, w2e
    F[v + 2, v], F[v + 2, v + 1] = ve * mv10 + w2n, -vn * mv01 - w2e
    s2 = np.sin(lat) ** 2
    F[DX_VEL + 2, DP_U] = GRAVITY_H1 - GRAVITY_H1_LAT * s2 - 2.0 * GRAVITY_H2 * h   # -d(gravity)/dh
    # position rows: dp' = dv;  bias rows: first-order Gauss-Markov
    F[DP_E, DX_VEL] = F[DP_N, DX_VEL + 1] = F[DP_U, DX_VEL + 2] = 1.0
    for k in range(3):
        F[DX_BG + k, DX_BG + k] = -inv_tau_g
        F[DX_BA + k, DX_BA + k] = -inv_tau_a


#: the rows and columns of the navigation errors (attitude, velocity, position): F, each segment's
#: Phi and their products are block upper-triangular, a dense navigation block, its coupling to
#: the biases (columns ``_NAV:``) and a diagonal bias block (rows and columns ``_NAV:``)
_NAV = DX_BG


@njit(cache=True, inline="always")
def _segment_phi_blocks(F_start: np.ndarray, F_end: np.ndarray, fn: np.ndarray, T: float, FT: np.ndarray,
                        FT2: np.ndarray, Phi_j: np.ndarray) -> None:
    """Phi (15, 15) of one segment of ``T`` s, ``I + FT + (FT)^2/2 + (FT)^3/6`` with F the mean of
    the x-dependent parts of F at its two ends (:func:`_error_dynamics_into`) and its mean specific
    force ``fn``, written for the block structure into ``Phi_j`` (its zero block below the bias
    columns left as it is: zero), ``FT`` and ``FT2`` (15, 15) scratch.  With
    ``FT = [[X, Y], [0, diag d]]`` (X the navigation block), the powers are
    ``FT^2 = [[X X, X Y + Y d], [0, d^2]]`` and ``FT^3 = FT FT^2``, so every product has the
    sparse X (about 28 of 81 elements non-zero) on the left and skips its zeros."""
    for r in range(N_ERR):
        for c in range(N_ERR):
            FT[r, c] = 0.5 * (F_start[r, c] + F_end[r, c])
    _set_neg_skew(FT, DX_VEL, DX_ATT, fn)
    for r in range(N_ERR):
        for c in range(N_ERR):
            FT[r, c] *= T
    # FT^2 (navigation rows; its bias block is d^2)
    _nav_left_product(FT, FT, FT2)
    for r in range(_NAV):
        for c in range(_NAV, N_ERR):
            FT2[r, c] += FT[r, c] * FT[c, c]
    for c in range(_NAV, N_ERR):
        FT2[c, c] = FT[c, c] * FT[c, c]
    # Phi_j = I + FT + FT^2 / 2 + FT FT^2 / 6, the navigation rows from X FT^2 + [0, Y d^2]
    _nav_left_product(FT, FT2, Phi_j)
    for r in range(_NAV):
        for c in range(N_ERR):
            third = Phi_j[r, c] + (FT[r, c] * FT2[c, c] if c >= _NAV else 0.0)
            Phi_j[r, c] = FT[r, c] + 0.5 * FT2[r, c] + third / 6.0
        Phi_j[r, r] += 1.0
    for c in range(_NAV, N_ERR):
        Phi_j[c, c] = 1.0 + FT[c, c] + 0.5 * FT2[c, c] + (FT[c, c] * FT2[c, c]) / 6.0


@njit(cache=True, inline="always")
def _nav_left_product(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """``out[:_NAV] = A[:_NAV, :_NAV] @ B[:_NAV]`` (the navigation rows of a block upper-triangular
    product's first term), skipping the zeros of ``A``; rows ``_NAV:`` of ``out`` untouched."""
    for r in range(_NAV):
        for c in range(N_ERR):
            out[r, c] = 0.0
        for k in range(_NAV):
            a = A[r, k]
            if a != 0.0:
                for c in range(N_ERR):
                    out[r, c] += a * B[k, c]


@njit(cache=True, inline="always")
def _block_product(Phi_j: np.ndarray, Phi: np.ndarray, out: np.ndarray) -> None:
    """``out = Phi_j @ Phi`` (15, 15) for two block upper-triangular transitions (diagonal bias
    blocks): the navigation rows from the dense navigation block and the bias coupling, the bias
    block element by element."""
    for r in range(_NAV):
        for c in range(N_ERR):
            s = 0.0
            for k in range(_NAV):
                s += Phi_j[r, k] * Phi[k, c]
            if c >= _NAV:
                s += Phi_j[r, c] * Phi[c, c]
            out[r, c] = s
    for r in range(_NAV, N_ERR):
        for c in range(N_ERR):
            out[r, c] = 0.0
        out[r, r] = Phi_j[r, r] * Phi[r, r]


@njit(cache=True, inline="always")
def _trapezoid_blocks(Q: np.ndarray, Phi_j: np.ndarray, psd: np.ndarray, T: float, W: np.ndarray) -> None:
    """``Q`` (15, 15) carried over one segment of ``T`` s with its trapezoid noise, in place and
    written for the block structure: ``Q <- Phi_j (Q + D) Phi_j^T + D``,
    ``D = diag(psd) T / 2``, for a block upper-triangular ``Phi_j`` and a symmetric ``Q`` whose bias
    block is diagonal (so is the result's, and it is exactly symmetric: the upper triangle is
    computed and mirrored); ``W`` (15, 15) scratch."""
    for k in range(N_ERR):
        Q[k, k] += 0.5 * T * psd[k]
    # W = Phi_j (Q + D), navigation rows (the bias rows are Q's scaled by the bias block)
    for r in range(_NAV):
        for c in range(N_ERR):
            s = 0.0
            for k in range(N_ERR):
                s += Phi_j[r, k] * Q[k, c]
            W[r, c] = s
    # (W Phi_j^T): navigation block (upper triangle), its bias columns, the bias block
    for r in range(_NAV):
        for c in range(r, _NAV):
            s = 0.0
            for k in range(N_ERR):
                s += W[r, k] * Phi_j[c, k]
            Q[r, c] = s
        for c in range(_NAV, N_ERR):
            Q[r, c] = W[r, c] * Phi_j[c, c]
    for r in range(_NAV, N_ERR):
        Q[r, r] *= Phi_j[r, r] * Phi_j[r, r]
    for r in range(N_ERR):
        for c in range(r + 1, N_ERR):
            Q[c, r] = Q[r, c]
        Q[r, r] += 0.5 * T * psd[r]


@njit(cache=True, inline="always")
def transition_from_segments(x_start: np.ndarray, seg_x: np.ndarray, seg_fn: np.ndarray, seg_T: np.ndarray,
                             n_seg: int, psd: np.ndarray, inv_tau_g: float, inv_tau_a: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Qd), each (15, 15), accumulated over the strapdown's ``n_seg`` segments (nominal
    ``seg_x[j]`` (16,) at the end of segment j, its mean ENU specific force ``seg_fn[j]`` m/s^2
    and length ``seg_T[j]`` s) from the nominal ``x_start``; ``psd`` (15,) the diagonal of
    G Qc G^T.  Per segment: ``Phi_j = I + FT + (FT)^2/2 + (FT)^3/6`` with F the mean of F at the segment's
    start and end states (its mean specific force ``fn`` in both; the third-order term carries
    gyro bias -> attitude -> velocity -> position within one step) and the trapezoid Qd,
    ``(Phi_j GQG Phi_j^T + GQG) T / 2`` with GQG = diag(psd).

    The x-dependent part of F at each node is computed once and shared by the two segments
    that meet there, and the trapezoid's two sandwiches are one:
    ``Phi_j Qd Phi_j^T + Phi_j D Phi_j^T + D = Phi_j (Qd + D) Phi_j^T + D`` with
    ``D = diag(psd) T / 2``.  F and every Phi are block upper-triangular (the bias errors drive the
    navigation errors, not the reverse; the bias block is diagonal), and the products are written
    for that structure (:func:`_segment_phi_blocks`, :func:`_block_product`,
    :func:`_trapezoid_blocks`): about a third of the dense products' work, in preallocated
    buffers.  The same figures as the dense products up to rounding.
    """
    Phi = np.eye(N_ERR)
    Qd = np.zeros((N_ERR, N_ERR))
    Phi_j = np.zeros((N_ERR, N_ERR))
    product = np.empty((N_ERR, N_ERR))
    work = np.zeros((2, N_ERR, N_ERR))
    F_prev = np.zeros((N_ERR, N_ERR))
    F_next = np.zeros((N_ERR, N_ERR))
    _error_dynamics_into(x_start, inv_tau_g, inv_tau_a, F_prev)
    for j in range(n_seg):
        T = seg_T[j]
        _error_dynamics_into(seg_x[j], inv_tau_g, inv_tau_a, F_next)
        _segment_phi_blocks(F_prev, F_next, seg_fn[j], T, work[0], work[1], Phi_j)
        _block_product(Phi_j, Phi, product)
        Phi, product = product, Phi
        _trapezoid_blocks(Qd, Phi_j, psd, T, work[0])
        F_prev, F_next = F_next, F_prev
    return Phi, Qd


@njit(cache=True)
def integrate_with_jacobian(x: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, t_start: float,
                            t_end: float, out: np.ndarray, record: bool, psd: np.ndarray, inv_tau_g: float,
                            inv_tau_a: float, cov_step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Propagate nominal ``x`` (in place) from ``t_start`` to ``t_end`` (s) through the IMU
    samples (``t`` s, ``gyro`` rad/s, ``accel`` m/s^2; recording into ``out`` when ``record``,
    :func:`navpp.ins.strapdown.integrate`) and return the interval's (Phi, Qd), accumulated over
    segments of about ``cov_step_s`` s (:func:`transition_from_segments`).
    """
    m = int((t_end - t_start) / cov_step_s) + 2
    # the segments' buffers and the start state: contiguous pieces of one allocation
    buf = np.empty(m * (NOMINAL_SIZE + 4) + x.shape[0])
    seg_x = buf[:m * NOMINAL_SIZE].reshape((m, NOMINAL_SIZE))
    seg_fn = buf[m * NOMINAL_SIZE:m * (NOMINAL_SIZE + 3)].reshape((m, 3))
    seg_T = buf[m * (NOMINAL_SIZE + 3):m * (NOMINAL_SIZE + 4)]
    x_start = buf[m * (NOMINAL_SIZE + 4):]
    for k in range(x.shape[0]):
        x_start[k] = x[k]
    n_seg = integrate_nominal(x, t, gyro, accel, t_start, t_end, out, record, cov_step_s, seg_x, seg_fn, seg_T)
    return transition_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd, inv_tau_g, inv_tau_a)


#: process-noise groups of the 15-state model (VCE): name -> error-state indices driven by it.
#: White noise enters the attitude and velocity errors in ENU (``G Qc G^T`` is diagonal and
#: isotropic, :meth:`NoiseModel.psd`); the bias drives act on the body-FLU bias states.
NOISE_GROUPS_TRIAD: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("gyro_white", tuple(range(DX_ATT, DX_ATT + 3))), ("accel_white", tuple(range(DX_VEL, DX_VEL + 3))),
    ("gyro_bias", tuple(range(DX_BG, DX_BG + 3))), ("accel_bias", tuple(range(DX_BA, DX_BA + 3))))
NOISE_GROUPS_AXIS: tuple[tuple[str, tuple[int, ...]], ...] = tuple(
    (f"{name}_{axis}", (idx,))
    for name, first, axes in (("gyro_white", DX_ATT, "enu"), ("accel_white", DX_VEL, "enu"),
                              ("gyro_bias", DX_BG, "xyz"), ("accel_bias", DX_BA, "xyz"))
    for idx, axis in zip(range(first, first + 3), axes))


@njit(cache=True)
def _noise_groups_from_segments(x_start: np.ndarray, seg_x: np.ndarray, seg_fn: np.ndarray, seg_T: np.ndarray,
                                n_seg: int, psd_groups: np.ndarray, inv_tau_g: float, inv_tau_a: float
                                ) -> np.ndarray:
    """Qd of every noise group over the strapdown's segments, in one pass, (G, 15, 15).

    Same discretisation as :func:`transition_from_segments`, on the same block structure
    (:func:`_segment_phi_blocks`, :func:`_trapezoid_blocks`), with the psd masked to one group
    at a time: Qd is linear in the psd, so the groups sum to the interval's Qd.
    """
    G = psd_groups.shape[0]
    Qg = np.zeros((G, N_ERR, N_ERR))
    Phi_j = np.zeros((N_ERR, N_ERR))
    work = np.zeros((2, N_ERR, N_ERR))
    F_prev = np.zeros((N_ERR, N_ERR))
    F_next = np.zeros((N_ERR, N_ERR))
    _error_dynamics_into(x_start, inv_tau_g, inv_tau_a, F_prev)
    for j in range(n_seg):
        T = seg_T[j]
        _error_dynamics_into(seg_x[j], inv_tau_g, inv_tau_a, F_next)
        _segment_phi_blocks(F_prev, F_next, seg_fn[j], T, work[0], work[1], Phi_j)
        for g in range(G):
            _trapezoid_blocks(Qg[g], Phi_j, psd_groups[g], T, work[0])
        F_prev, F_next = F_next, F_prev
    return Qg


@njit(cache=True)
def integrate_noise_groups(x: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, t_start: float,
                           t_end: float, psd_groups: np.ndarray, inv_tau_g: float, inv_tau_a: float,
                           cov_step_s: float) -> np.ndarray:
    """Propagate nominal ``x`` (in place, nothing recorded) and return the interval's Qd per
    noise group, (G, 15, 15), the psd of group g being ``psd_groups[g]`` (15,)."""
    m = int((t_end - t_start) / cov_step_s) + 2
    seg_x = np.empty((m, NOMINAL_SIZE))
    seg_fn = np.empty((m, 3))
    seg_T = np.empty(m)
    x_start = x.copy()
    unused = np.empty((1, PATH_SIZE))
    n_seg = integrate_nominal(x, t, gyro, accel, t_start, t_end, unused, False, cov_step_s, seg_x, seg_fn, seg_T)
    return _noise_groups_from_segments(x_start, seg_x, seg_fn, seg_T, n_seg, psd_groups, inv_tau_g, inv_tau_a)


@njit(cache=True, inline="always")
def _wrap_pi(a: float) -> float:
    """Angle difference wrapped to [-pi, pi) (longitude across the antimeridian)."""
    wrapped: float = (a + np.pi) % (2.0 * np.pi) - np.pi
    return wrapped


@njit(cache=True)
def plus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Nominal ⊞ error: ``x`` (16,) and ``dx`` (15,) -> (16,).  The attitude error rotates
    ``q_nb`` in the navigation frame; the position error (ENU m) moves lat, lon, h with the
    radii of curvature at ``x``.  Elements beyond the INS's (an augmented state,
    :mod:`navpp.ins.augmented`: ``x`` (16 + k,), ``dx`` (15 + k,)) add."""
    y = x.copy()
    q = quat_mul(rotvec_to_quat(dx[ATT]), x[NOMINAL_Q])
    for k in range(4):                  # element loops, not slice assignment (see jitcache.py)
        y[X_QW + k] = q[k]
    for k in range(3):
        y[X_VE + k] = x[X_VE + k] + dx[DX_VEL + k]
    rm, rn = radii(x[X_LAT])
    h = x[X_H]
    y[X_LAT] = x[X_LAT] + dx[DP_N] / (rm + h)
    y[X_LON] = _wrap_pi(x[X_LON] + dx[DP_E] / ((rn + h) * np.cos(x[X_LAT])))
    y[X_H] = h + dx[DP_U]
    for k in range(3):
        y[X_BG + k] = x[X_BG + k] + dx[DX_BG + k]
        y[X_BA + k] = x[X_BA + k] + dx[DX_BA + k]
    for i in range(x.shape[0] - NOMINAL_SIZE):
        y[NOMINAL_SIZE + i] = x[NOMINAL_SIZE + i] + dx[N_ERR + i]
    return y


@njit(cache=True)
def minus(x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Error taking ``x0`` to ``x1``: ``x1 = x0 ⊞ minus(x1, x0)``, (15,) (15 + k, for augmented
    states of 16 + k elements)."""
    k = x1.shape[0] - NOMINAL_SIZE
    dx = np.empty(N_ERR + k)
    rv = quat_to_rotvec(quat_mul(x1[NOMINAL_Q], quat_conj(x0[NOMINAL_Q])))
    for j in range(3):                  # element loops, not slice assignment (see jitcache.py)
        dx[DX_ATT + j] = rv[j]
        dx[DX_VEL + j] = x1[X_VE + j] - x0[X_VE + j]
    rm, rn = radii(x0[X_LAT])
    h = x0[X_H]
    dx[DP_E] = _wrap_pi(x1[X_LON] - x0[X_LON]) * (rn + h) * np.cos(x0[X_LAT])
    dx[DP_N] = (x1[X_LAT] - x0[X_LAT]) * (rm + h)
    dx[DP_U] = x1[X_H] - h
    for j in range(3):
        dx[DX_BG + j] = x1[X_BG + j] - x0[X_BG + j]
        dx[DX_BA + j] = x1[X_BA + j] - x0[X_BA + j]
    for i in range(k):
        dx[N_ERR + i] = x1[NOMINAL_SIZE + i] - x0[NOMINAL_SIZE + i]
    return dx


@njit(cache=True)
def _propagate_points(x: np.ndarray, dX: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                      t_start: float, t_end: float, out: np.ndarray, record: bool) -> tuple[np.ndarray, np.ndarray]:
    """The nominal ``x`` and the points ``x ⊞ dX[k]`` through the strapdown (recording the
    nominal's path into ``out`` when ``record``): ``f(x)`` and ``f(x ⊞ dX[k]) ⊟ f(x)``."""
    no_seg = np.empty((0, NOMINAL_SIZE))    # (module-level empty arrays would be read-only constants here)
    no_seg3 = np.empty((0, 3))
    no_t = np.empty(0)
    xn = x.copy()
    integrate_nominal(xn, t, gyro, accel, t_start, t_end, out, record, 0.0, no_seg, no_seg3, no_t)
    dX_new = np.empty_like(dX)
    unused = np.empty((1, PATH_SIZE))
    for k in range(dX.shape[0]):
        xk = plus(x, dX[k])
        integrate_nominal(xk, t, gyro, accel, t_start, t_end, unused, False, 0.0, no_seg, no_seg3, no_t)
        dX_new[k] = minus(xk, xn)
    return xn, dX_new


@njit(cache=True, inline="always")
def _plus_row(row: np.ndarray, c: np.ndarray) -> None:
    """``row ⊞ c`` in place for a recorded path row (q_nb, vel_enu, lat, lon, h): the same
    arithmetic as :func:`plus`, without temporaries (it runs once per IMU sample)."""
    w, s = rotvec_quat_coeffs(c[DX_ATT], c[DX_ATT + 1], c[DX_ATT + 2])
    p0, p1, p2, p3 = w, s * c[DX_ATT], s * c[DX_ATT + 1], s * c[DX_ATT + 2]
    q0, q1, q2, q3 = row[X_QW], row[X_QX], row[X_QY], row[X_QZ]
    row[X_QW] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    row[X_QX] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    row[X_QY] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    row[X_QZ] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    row[X_VE] += c[DX_VEL]
    row[X_VN] += c[DX_VEL + 1]
    row[X_VU] += c[DX_VEL + 2]
    lat, h = row[X_LAT], row[X_H]
    rm, rn = radii(lat)
    row[X_LAT] = lat + c[DP_N] / (rm + h)
    row[X_LON] = _wrap_pi(row[X_LON] + c[DP_E] / ((rn + h) * np.cos(lat)))
    row[X_H] = h + c[DP_U]


@njit(cache=True)
def apply_node_corrections(path: np.ndarray, t: np.ndarray, node_t: np.ndarray, xs: np.ndarray, x_post: np.ndarray,
                           x_ref: np.ndarray) -> None:
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
    cl = np.zeros(N_ERR)
    cr = np.zeros(N_ERR)
    c = np.zeros(N_ERR)
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
        for e in range(N_ERR):
            c[e] = (1.0 - w) * cl[e] + w * cr[e]
        _plus_row(path[i], c)


@njit(cache=True)
def rts_means(x_post: np.ndarray, x_prior: np.ndarray, gains: np.ndarray, reset: np.ndarray) -> np.ndarray:
    """The smoother's mean recursion on the INS nominal (:func:`navpp.filters.smoother.smooth_arrays`):
    ``xs[k] = x_post[k] ⊞ gains[k+1] (xs[k+1] ⊟ x_prior[k+1])`` backwards from the last node,
    ``xs[k] = x_post[k]`` where ``reset[k+1]``.  (M, 16) arrays, gains (M, 15, 15); augmented
    states too ((M, 16 + k), gains (M, 15 + k, 15 + k), :mod:`navpp.ins.augmented`)."""
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
    profile: NoiseProfile | None = None

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.gyro = np.ascontiguousarray(self.gyro, dtype=float)
        self.accel = np.ascontiguousarray(self.accel, dtype=float)
        self._psd = self.noise.psd()
        # the configured white-noise densities squared (gyro, accel) as Python floats: psd_over's
        # comparison once per interval without numpy scalars
        self._white_psd = (float(self._psd[DX_ATT]), float(self._psd[DX_VEL]))
        self._inv_tau = self.noise.inv_tau()
        if self.path is None:
            self.path = np.full((self.t.shape[0], PATH_SIZE), np.nan)
        # long gaps: (start, end) times of IMU intervals over LONG_GAP_PERIODS nominal periods
        k = long_intervals(self.t, LONG_GAP_PERIODS * interval_median(self.t)) if self.t.shape[0] > 2 \
            else np.zeros(0, int)
        self.gaps = np.column_stack([self.t[k], self.t[k + 1]]) if k.size else np.zeros((0, 2))

    def psd_over(self, interval: tuple[float, float]) -> np.ndarray:
        """Diagonal of G Qc G^T (15,) over ``interval``: the configured noise, with the white noise
        raised to the measured profile where the data shake more (vibration, steps)."""
        if self.profile is None:
            return self._psd
        g, a = self.profile.over(interval[0], interval[1])
        white_g, white_a = self._white_psd
        if g * g <= white_g and a * a <= white_a:
            return self._psd
        psd = self._psd.copy()
        psd[ATT] = max(white_g, g * g)
        psd[VEL] = max(white_a, a * a)
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
                att, vel, pos = DX_ATT + i, DX_VEL + i, DX_POS + i
                Q[att, att] += (sw * T) ** 2
                Q[vel, vel] += (sf * T) ** 2
                Q[pos, pos] += (sf * sp) ** 2
                Q[vel, pos] += sf * sf * T * sp
                Q[pos, vel] += sf * sf * T * sp
        return Q

    #: the smoother's mean recursion, compiled (:func:`rts_means`)
    rts_means = staticmethod(rts_means)
    #: VCE's process-noise groups reach the fixes through many time updates (filters.protocols)
    noise_share: ClassVar[str] = "propagated"

    def _path_out(self) -> np.ndarray:
        """The (N, PATH_SIZE) array the strapdown records the nominal into."""
        if self.path is None:
            raise ValueError("InsModel.path was released (set to None): the model cannot propagate any more")
        return self.path

    def propagation_arrays(self) -> tuple[Any, ...]:
        """What :meth:`transition` propagates with, for a compiled caller that runs many
        intervals (:func:`navpp.engine.fused.ekf_epochs`): IMU ``t`` s, ``gyro`` rad/s, ``accel``
        m/s^2, the recorded path, the configured psd (15,), whether there is a noise profile,
        its block edges (s) and white-noise densities (gyro rad/sqrt(s), accel m/s/sqrt(s); empty
        without one), the configured white psd (gyro, accel), the bias correlation rates (1/s),
        ``cov_step_s`` and the long gaps (G, 2) s."""
        p = self.profile
        prof = (np.ascontiguousarray(p.t, dtype=float), np.ascontiguousarray(p.gyro_arw, dtype=float),
                np.ascontiguousarray(p.accel_vrw, dtype=float)) if p is not None else (np.zeros(1), np.zeros(0),
                                                                                        np.zeros(0))
        return (self.t, self.gyro, self.accel, self._path_out(), self._psd, p is not None, *prof, *self._white_psd,
                *self._inv_tau, float(self.cov_step_s), np.ascontiguousarray(self.gaps, dtype=float))

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
                                          self._path_out(), True, self.psd_over(interval), self._inv_tau[0],
                                          self._inv_tau[1], self.cov_step_s)
        Qg = self.gap_noise(interval)
        return xn, Phi, (Qd if Qg is None else Qd + Qg)

    def process_noise(self, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        """Qd over the interval (additive noise for sigma-point filters)."""
        xn = x.copy()
        _, Qd = integrate_with_jacobian(xn, self.t, self.gyro, self.accel, interval[0], interval[1],
                                        self._path_out(), False, self.psd_over(interval), self._inv_tau[0],
                                        self._inv_tau[1], self.cov_step_s)
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
        names: list[str] = []
        rows: list[np.ndarray] = []
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
                                 interval[0], interval[1], self._path_out(), True)


@njit(cache=True)
def antenna_offset_enu(x: np.ndarray, lever_arm_b: np.ndarray) -> np.ndarray:
    """ENU offset (m) of an antenna at ``lever_arm_b`` (body FLU, m) from the nominal position."""
    offset: np.ndarray = quat_to_dcm(x[NOMINAL_Q]) @ lever_arm_b
    return offset


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
        """Fix minus predicted antenna position at nominal ``x``, local ENU m (3,)."""
        return gnss_innovation(x, self.lat, self.lon, self.h, self.lever_arm_b)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """H (3, 15) at nominal ``x``."""
        return gnss_jacobian(x, self.lever_arm_b)

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) ⊟ h(x)`` in ENU metres, (m, 3)."""
        return gnss_points(x, np.ascontiguousarray(dX, dtype=float), self.lever_arm_b)

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
def gnss_innovation(x: np.ndarray, lat: float, lon: float, h: float, lever: np.ndarray) -> np.ndarray:
    """GNSS fix (``lat``, ``lon`` rad, ``h`` m) minus the antenna position predicted from the
    nominal ``x`` with the lever arm ``lever`` (body FLU, m): local ENU m about the nominal (3,)."""
    return gnss_innovation_offset(x, lat, lon, h, antenna_offset_enu(x, lever))


@njit(cache=True, inline="always")
def gnss_innovation_offset(x: np.ndarray, lat: float, lon: float, h: float, offset: np.ndarray) -> np.ndarray:
    """:func:`gnss_innovation` with the antenna's ENU ``offset`` (m) from the nominal position
    given (:func:`antenna_offset_enu`: a caller that also needs the Jacobian computes it once)."""
    rm, rn = radii(x[X_LAT])
    hx = x[X_H]
    d = np.empty(3)
    d[0] = _wrap_pi(lon - x[X_LON]) * (rn + hx) * np.cos(x[X_LAT])
    d[1] = (lat - x[X_LAT]) * (rm + hx)
    d[2] = h - hx
    nu: np.ndarray = d - offset
    return nu


@njit(cache=True)
def gnss_jacobian(x: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """H (3, 15) of :func:`gnss_innovation`'s prediction: ``[-[(C l) x], 0, I, 0, 0]``."""
    return gnss_jacobian_offset(antenna_offset_enu(x, lever))


@njit(cache=True, inline="always")
def gnss_jacobian_offset(offset: np.ndarray) -> np.ndarray:
    """:func:`gnss_jacobian` with the antenna's ENU ``offset`` (m) given (:func:`gnss_innovation_offset`)."""
    H = np.zeros((3, N_ERR))
    _set_neg_skew(H, 0, DX_ATT, offset)
    H[0, DP_E] = H[1, DP_N] = H[2, DP_U] = 1.0
    return H


@njit(cache=True)
def gnss_points(x: np.ndarray, dX: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """``h(x ⊞ dX_k) ⊟ h(x)`` for error points ``dX`` (m, 15): ENU m, (m, 3).

    ``minus(plus(x, d), x)`` returns the position part of ``d`` unchanged (both use the radii
    at ``x``), so the antenna moves by the position error plus the change of the rotated lever
    arm, ``(exp([phi x]) - I) C a``: one small rotation per point instead of a quaternion round
    trip.
    """
    m = dX.shape[0]
    Z = np.empty((m, 3))
    a0 = antenna_offset_enu(x, lever)
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    for k in range(m):
        Z[k, 0] = dX[k, DP_E]
        Z[k, 1] = dX[k, DP_N]
        Z[k, 2] = dX[k, DP_U]
        if has_lever:
            Z[k] += quat_to_dcm(rotvec_to_quat(dX[k, ATT])) @ a0 - a0
    return Z


__all__ = [
    "ATT", "BA", "BG", "GAP_ACCEL", "GAP_ANG_ACCEL", "GAP_JERK", "GAP_MAX_ATT_STD", "GAP_RATE", "LONG_GAP_PERIODS",
    "NOISE_GROUPS_AXIS", "NOISE_GROUPS_TRIAD", "N_ERR", "POS", "VEL", "GnssPosition", "InsModel", "NoiseModel",
    "antenna_offset_enu", "apply_node_corrections", "error_dynamics", "gnss_innovation", "gnss_jacobian",
    "gnss_points", "integrate_noise_groups", "integrate_with_jacobian", "max_bridgeable_gap_s", "minus", "plus",
    "rts_means", "transition_from_segments",
]
