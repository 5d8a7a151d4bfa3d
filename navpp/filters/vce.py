"""Helmert variance component estimation (VCE) of the process and measurement noise.

A filter's adaptation (:class:`~navpp.filters.adaptation.Adaptation`; the VCE-CKF,
:mod:`navpp.filters.vce_ckf`): it chooses the process noise of every time update and the R of
every adaptive measurement, and learns after every applied update.  It relies on nothing but
the model's noise groups (:class:`~navpp.filters.protocols.GroupedNoiseModel`; a model without
them is one group, its ``process_noise``) and the :class:`~navpp.filters.states.Innovation`
record, so the same code runs on the INS and on the papers' small benchmark models.

Per accepted epoch (paper 003 eqs 37-39; docs/algorithms.md "Helmert variance component
estimation"), with the prior covariance ``P⁻`` (n, n), ``A = (P⁻)⁻¹`` (Cholesky solves),
``S = Pzz + R`` (the innovation covariance: the papers' ``Pzz``), ``K = Pxz S⁻¹``, innovation
``d`` and ``Q = Σ_g f_g U_g`` (``U_g`` the configured, *unit* group covariance; ``f_g`` its
factor):

- residuals ``v_z = (Pxzᵀ A K - I) d``, ``v_g = Q_g A K d`` with ``Q_g = f_g U_g`` (the noise
  the filter actually used);
- redundancies ``r_zᵢ = [I - Pxzᵀ A K]ᵢᵢ``, ``r_g = tr(Q_g A Pxz S⁻¹ Pxzᵀ A)``,
  ``r_x = tr((P⁻ - Q) A Pxz S⁻¹ Pxzᵀ A)``; ``r_x + Σ r_g + Σ r_zᵢ = m`` exactly on a linear
  model (a check, not an input).

Pooled over a moving window of ``window`` accepted epochs, the factor relative to the
configured noise is ``f_g = Σ v_gᵀ U_g⁺ v_g / Σ r_g``.  Weighting with the pseudo-inverse of
the *unit* ``U_g`` while ``v_g`` and ``r_g`` carry the used ``f_g U_g`` makes the quotient the new
factor itself (``f_g`` times the Helmert correction ``vᵀ Q_g⁺ v / r``, which is 1 at
consistency), so iterating it converges to ``true / configured``.  No pseudo-inverse is
formed: ``v_g = Q_g y`` with ``y = A K d`` and ``Q Q⁺ Q = Q`` give ``v_gᵀ U_g⁺ v_g = f_g² yᵀ U_g y``
exactly, even for the rank-deficient, ill-conditioned groups of the INS's discretised Q.

The measurement noise gets one factor per axis that scales the R *given* with the measurement
(the configured GNSS std, or the log's per-epoch std): ``R_used = D R D``, ``D = diag(√f)``,
and ``f_zᵢ = Σ (v_zᵢ² / R_ii) / Σ r_zᵢ``.  With a constant R this is the paper's
``σ̂²_zᵢ = Σ v_zᵢ² / Σ r_zᵢ`` divided by R_ii; with a per-epoch R it normalises each epoch.

A group (or axis) is updated only when its pooled redundancy exceeds ``min_redundancy``, and
factors are clamped to ``[floor, ceiling]`` (1 = the configured prior).

Time update: the process noise is ``Σ_g f_g U_g(x, interval)``.  When several predicts run
between two updates (the engine's 1-s coasting steps, outages, rejected fixes) the groups of
all steps are **summed** without propagating the earlier steps' noise through the later steps'
transition (which a sigma-point filter does not have); ``P⁻ - Q`` and ``v_g``, ``r_g`` use that
sum.  At the GNSS rate (one predict per update) this is exact; over an outage it understates
the part of ``P⁻`` due to the outage's noise, which then counts towards ``r_x`` instead.  The
sum restarts after every accepted (or forced) update; forced updates are not learnt from.

Propagated shares (``q_share = "propagated"``, the default on the INS): a group's noise reaches
an innovation mostly through what it has added to ``P⁻`` over many time updates, not through the
last step's ``U_g`` (on the INS at the GNSS rate the step redundancy is tiny, so the step form
never moves Q).  Each group's share of the covariance, ``P_g``, is carried along like ``P`` itself:
``P_g ← Φ P_g Φᵀ + f_g U_g`` at every time update (``Φ = Cᵀ P⁻¹``, the statistically linearised
transition from the update's cross-covariance) and ``P_g ← L P_g Lᵀ`` at every applied update
(``L = I − Pxz S⁻¹ Pxzᵀ A``, aids included; a forced update restarts the shares).  Then
``r_g = tr(P_g M)`` and ``q_num = f_g yᵀ P_g y``: at consistency ``E[yᵀ P_g y] = tr(P_g M)``, so
the pooled quotient is again the factor itself.  When a factor changes, its share is rescaled
with it (``P_g`` is linear in ``f_g``).  Step mode remains the paper's reading (its small
benchmarks, where every step's noise reaches the measurement, keep it).

Pooling (paper 003 cites Wang 2009 for it): a single epoch's estimate is one squared residual,
far too noisy to use raw.

Identifiability (tests/test_vce.py): on one epoch VCE sees only the innovation ``d``, so it
tells the groups apart only through the different *shapes* their noise gives ``S``.  With a
scalar measurement every group's correction is the same ``d²/S`` (tested), so VCE can only
rescale Q and R together until the innovations are consistent; along the curve of consistent
(Q, R) nothing pulls it to the truth.  Measuring position and velocity separates them only
weakly; two sensors on the same position separate them well (the convergence test).  On the
INS at the GNSS rate the process-noise groups have a tiny redundancy per epoch (a short step's
noise barely reaches the position innovation directly), so ``min_redundancy`` keeps Q at its
prior and only R is learnt (docs/papers.md gives the measured figures).

References: paper 003 eqs 6-18 and 35-39; docs/algorithms.md; Wang (2009) as cited by paper 003.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from .adaptation import Adaptation
from .linalg import chol_solve, cholesky
from .protocols import GroupedNoiseModel, Interval, Measurement, Model
from .states import GaussianState, Innovation, MeasurementPrediction, Prediction

ADAPT_CHOICES = ("QR", "Q", "R", "none")
Q_GROUP_CHOICES = ("triad", "axis")
Q_SHARE_CHOICES = ("auto", "step", "propagated")


@dataclass(frozen=True)
class VCEOptions:
    """``[filter.vce-ckf]``.

    window : epochs pooled per estimate (moving window of accepted updates), >= 1.
    adapt : which noise is estimated: ``"QR"`` (the paper's), ``"Q"``, ``"R"`` or ``"none"``
        (the plain CKF: the oracle setting).
    min_redundancy : a group is updated only when its pooled redundancy exceeds this, >= 0.
    floor, ceiling : factors are clamped to ``[floor, ceiling]`` times the configured noise;
        ``0 < floor <= 1 <= ceiling``.
    q_groups : process-noise groups on the INS: ``"triad"`` (gyro white, accel white, gyro bias
        drive, accel bias drive) or ``"axis"`` (each per axis: 12 groups); models whose
        ``noise_groups`` takes no ``per`` argument use their own groups.
    q_share : what a group's redundancy is measured on: ``"step"``, the noise of the time
        update(s) since the last fix (the paper's), or ``"propagated"``, the group's whole share
        of the prior covariance, carried through every time update and measurement (see the
        module docstring); ``"auto"``: propagated on the INS (a model whose ``noise_groups``
        takes ``per``), step elsewhere.
    q_fixed : names of process-noise groups whose factor stays 1 (their noise is used and
        counted, not estimated).  Default ``("gnss_error",)``: the drive of the Gauss-Markov GNSS
        error states (``[gnss] error_model``) is part of the fixes' noise model, and one position
        innovation sees it and the white R the same way, so VCE cannot tell them apart; left free
        it runs to ``ceiling`` and the filter follows the fixes again (measured in
        docs/ins.md).  The white R keeps its factors.
    """

    window: int = 50
    adapt: str = "QR"
    min_redundancy: float = 1.0
    floor: float = 0.1
    ceiling: float = 10.0
    q_groups: str = "triad"
    q_share: str = "auto"
    q_fixed: tuple[str, ...] = ("gnss_error",)

    def __post_init__(self) -> None:
        if isinstance(self.q_fixed, str) or not all(isinstance(g, str) for g in self.q_fixed):
            raise ValueError(f"q_fixed must be a list of group names, got {self.q_fixed!r}")
        object.__setattr__(self, "q_fixed", tuple(self.q_fixed))
        if isinstance(self.window, bool) or int(self.window) != self.window or self.window < 1:
            raise ValueError(f"window must be an integer number of epochs >= 1, got {self.window!r}")
        object.__setattr__(self, "window", int(self.window))
        if self.adapt not in ADAPT_CHOICES:
            raise ValueError(f"adapt must be one of {', '.join(repr(a) for a in ADAPT_CHOICES)}, got {self.adapt!r}")
        if not (np.isfinite(self.min_redundancy) and self.min_redundancy >= 0.0):
            raise ValueError(f"min_redundancy must be a finite number >= 0, got {self.min_redundancy!r}")
        if not (np.isfinite(self.floor) and np.isfinite(self.ceiling) and 0.0 < self.floor <= 1.0 <= self.ceiling):
            raise ValueError(f"floor and ceiling must satisfy 0 < floor <= 1 <= ceiling (finite), "
                             f"got floor={self.floor!r}, ceiling={self.ceiling!r}")
        if self.q_groups not in Q_GROUP_CHOICES:
            raise ValueError(f"q_groups must be 'triad' or 'axis', got {self.q_groups!r}")
        if self.q_share not in Q_SHARE_CHOICES:
            raise ValueError(f"q_share must be one of {', '.join(repr(a) for a in Q_SHARE_CHOICES)}, "
                             f"got {self.q_share!r}")

    @property
    def adapt_q(self) -> bool:
        return "Q" in self.adapt

    @property
    def adapt_r(self) -> bool:
        return "R" in self.adapt


@dataclass(frozen=True)
class VCEEpoch:
    """One accepted epoch's VCE numbers (diagnostics and tests).

    r_x : redundancy of the propagated state; r_g : (G,) per process-noise group; r_z : (m,)
    per measurement axis; v_z : (m,) measurement residuals (measurement units); q_num : (G,)
    ``v_gᵀ U_g⁺ v_g``; z_num : (m,) ``v_zᵢ² / R_ii`` (R as given with the measurement).
    """

    r_x: float
    r_g: np.ndarray
    r_z: np.ndarray
    v_z: np.ndarray
    q_num: np.ndarray
    z_num: np.ndarray

    @property
    def total(self) -> float:
        """``r_x + Σ r_g + Σ r_z``: the measurement dimension m on a linear model."""
        return float(self.r_x + self.r_g.sum() + self.r_z.sum())


class HelmertVCE(Adaptation):
    """Helmert VCE as a filter's adaptation.  State of the estimator: configured noise groups
    accumulated since the last update, factors, and the window of per-epoch numbers (see the
    module docstring).

    Attributes
    ----------
    q_group_names : names of the process-noise groups (from the model), set at the first predict.
    q_factor : (G,) process-noise factors, relative to the configured noise.
    r_factor : (m,) measurement-noise factors per axis, relative to the R given, set at the
        first measurement.
    last : the last learnt :class:`VCEEpoch` (None before).
    skipped : epochs not learnt from because ``P⁻`` or ``S`` was not positive definite.
    r_axes : names of the measurement elements of the last adaptive measurement.
    """

    adapts_noise = True

    def __init__(self, options: VCEOptions) -> None:
        self.o = options
        self.q_group_names: list[str] | None = None
        self.q_factor = np.zeros(0)
        self._q_fixed = np.zeros(0, dtype=bool)
        self.r_factor: np.ndarray | None = None
        self.last: VCEEpoch | None = None
        self.skipped = 0
        self._U: np.ndarray | None = None         # (G, n, n) unit groups summed since the last update
        self._Q_total: np.ndarray | None = None   # (n, n) process noise used since the last update
        self._R_given: np.ndarray | None = None
        self.r_axes: tuple[str, ...] = ()
        self._grouped: bool | None = None        # the model has noise groups (decided at the first predict)
        self.propagated = options.q_share == "propagated"   # "auto" decided at the first predict
        self._Pg: np.ndarray | None = None       # (G, n, n) each group's share of P (propagated mode)
        self._step_noise: np.ndarray | None = None   # (G, n, n) f_g U_g of the running time update
        W = options.window
        self._k = 0                                # accepted epochs learnt from
        self._q_num = self._q_red = np.zeros((W, 0))
        self._z_num = self._z_red = np.zeros((W, 0))

    # time update ---------------------------------------------------------------------------
    def _groups(self, model: Model, x: np.ndarray, interval: Interval) -> tuple[list[str], np.ndarray]:
        """The model's noise groups; a model without groups is one group, its process noise."""
        if self._grouped is None:
            self._grouped = isinstance(model, GroupedNoiseModel)
            if self._grouped and self.o.q_share == "auto":
                self.propagated = cast(GroupedNoiseModel, model).noise_share == "propagated"
        if not self._grouped:
            return ["Q"], np.asarray(model.process_noise(x, interval), dtype=float)[None]
        names, Qs = cast(GroupedNoiseModel, model).noise_groups(x, interval, per=self.o.q_groups)
        return list(names), np.asarray(Qs, dtype=float)

    def process_noise(self, model: Model, x: np.ndarray, interval: Interval) -> np.ndarray:
        """Process noise (n, n) for a time update over ``interval``: ``Σ_g f_g U_g`` when Q is
        adapted, else the model's own; the groups are accumulated until the next update."""
        if not self.o.adapt_q:
            Q: np.ndarray = np.asarray(model.process_noise(x, interval), dtype=float)
            self._Q_total = Q.copy() if self._Q_total is None else self._Q_total + Q
            return Q
        names, Us = self._groups(model, x, interval)
        if self.q_group_names is None:
            self.q_group_names = names
            G = len(names)
            self.q_factor = np.ones(G)
            self._q_fixed = np.array([name in self.o.q_fixed for name in names], dtype=bool)
            self._q_num = np.zeros((self.o.window, G))
            self._q_red = np.zeros((self.o.window, G))
        elif names != self.q_group_names:
            raise ValueError(f"VCE: the model's noise groups changed from {self.q_group_names} to {names}")
        self._U = Us.copy() if self._U is None else self._U + Us
        if self.propagated:
            self._step_noise = self.q_factor[:, None, None] * Us
        Q = np.einsum("g,gij->ij", self.q_factor, Us)
        Q = 0.5 * (Q + Q.T)
        self._Q_total = Q.copy() if self._Q_total is None else self._Q_total + Q
        return Q

    def predicted(self, before: GaussianState, prediction: Prediction) -> None:
        """Propagated mode: carry the groups' shares through the time update just made."""
        self.propagate(before.P, prediction.cross_cov)

    def propagate(self, P_before: np.ndarray, cross: np.ndarray) -> None:
        """Propagated mode: carry each group's share of P through a time update,
        ``P_g <- Phi P_g Phi^T + f_g U_g``, with the statistically linearised transition
        ``Phi = C^T P^-1`` from the update's cross-covariance ``C = E[dx_k dx_k+1^T]`` and the
        covariance ``P`` before it."""
        if not self.propagated or self._step_noise is None:
            return
        pending, self._step_noise = self._step_noise, None
        L, ok = cholesky(np.ascontiguousarray(P_before, dtype=float))
        if not ok:
            self._Pg = None
            return
        phi = chol_solve(L, np.ascontiguousarray(cross, dtype=float)).T          # (n, n)
        if self._Pg is None:
            self._Pg = pending
        else:
            Pg = phi @ self._Pg @ phi.T + pending
            self._Pg = 0.5 * (Pg + np.transpose(Pg, (0, 2, 1)))

    def shrink_shares(self, P_prior: np.ndarray, Pxz: np.ndarray, S: np.ndarray, *, reset: bool = False) -> None:
        """Propagated mode: after any applied update (GNSS or an aid), each group's share of P
        shrinks like P itself, ``P_g <- L P_g L^T`` with ``L = I - Pxz S^-1 Pxz^T P^-1`` (the
        statistically linearised ``I - K H``); a re-anchored (forced) update restarts them."""
        if not self.propagated or self._Pg is None:
            return
        if reset:
            self._Pg = None
            return
        LP, okP = cholesky(np.ascontiguousarray(P_prior, dtype=float))
        LS, okS = cholesky(np.ascontiguousarray(S, dtype=float))
        if not (okP and okS):
            self._Pg = None
            return
        B = chol_solve(LP, np.ascontiguousarray(Pxz, dtype=float))                 # A Pxz (n, m)
        KH = np.ascontiguousarray(Pxz, dtype=float) @ chol_solve(LS, np.ascontiguousarray(B.T))   # (n, n)
        L = np.eye(KH.shape[0]) - KH
        Pg = L @ self._Pg @ L.T
        self._Pg = 0.5 * (Pg + np.transpose(Pg, (0, 2, 1)))

    # measurement update --------------------------------------------------------------------
    def measurement_noise(self, meas: Measurement, raw: MeasurementPrediction) -> np.ndarray:
        """R for an adaptive measurement: its R scaled per axis (:meth:`scaled_noise`)."""
        self.r_axes = meas.axes
        return self.scaled_noise(meas.R)

    def corrected(self, prior: GaussianState, raw: MeasurementPrediction, innovation: Innovation,
                  meas: Measurement) -> None:
        """After an applied update: learn from an adaptive one, then shrink the groups' shares
        (every applied update, aids included; a forced one restarts them)."""
        if meas.adaptive:
            self.learn(prior.P, innovation.nu, innovation.S, innovation.Pxz, forced=innovation.forced)
        self.shrink_shares(prior.P, innovation.Pxz, innovation.S, reset=innovation.forced)

    def labels(self) -> dict[str, list[str]]:
        """``q_factor``: the group names; ``r_factor``: the axes of the last adaptive measurement."""
        labels = {"q_factor": list(self.q_group_names or [])}
        if self.r_axes:
            labels["r_factor"] = list(self.r_axes)
        return labels

    def scaled_noise(self, R_given: np.ndarray) -> np.ndarray:
        """R (m, m) for this update: the given R scaled per axis, ``D R D``, ``D = diag(√f)``."""
        R_given = np.asarray(R_given, dtype=float)
        self._R_given = R_given
        if not self.o.adapt_r:
            return R_given
        m = R_given.shape[0]
        if self.r_factor is None:
            self.r_factor = np.ones(m)
            self._z_num = np.zeros((self.o.window, m))
            self._z_red = np.zeros((self.o.window, m))
        elif self.r_factor.shape[0] != m:
            raise ValueError(f"VCE: the measurement dimension changed from {self.r_factor.shape[0]} to {m}")
        d = np.sqrt(self.r_factor)
        return R_given * np.outer(d, d)

    def restart_interval(self) -> None:
        """Forget the noise accumulated since the last update (called after every applied update)."""
        self._U = None
        self._Q_total = None

    def epoch(self, P_prior: np.ndarray, nu: np.ndarray, S: np.ndarray, Pxz: np.ndarray,
              R_given: np.ndarray | None = None) -> VCEEpoch | None:
        """The VCE residuals and redundancies of one update (module docstring); None when
        ``P⁻`` or ``S`` is not positive definite.

        P_prior : (n, n) prior covariance; nu : (m,) innovation ``d``; S : (m, m) innovation
        covariance including the R used; Pxz : (n, m); R_given : (m, m) R before scaling
        (defaults to the one of the last :meth:`measurement_noise` call, else ``S``'s R part is
        unknown and the measurement numbers are normalised by 1).
        """
        # compiled Cholesky solves (base.py): tiny matrices, no BLAS threading in the loop
        LP, okP = cholesky(np.ascontiguousarray(P_prior, dtype=float))
        LS, okS = cholesky(np.ascontiguousarray(S, dtype=float))
        if not (okP and okS):
            return None
        n, m = Pxz.shape
        B = chol_solve(LP, np.ascontiguousarray(Pxz, dtype=float))             # A Pxz (n, m)
        w = chol_solve(LS, np.asarray(nu, dtype=float).reshape(-1, 1))[:, 0]   # S⁻¹ d
        y = B @ w                                       # A K d
        M = B @ chol_solve(LS, np.ascontiguousarray(B.T))   # A Pxz S⁻¹ Pxzᵀ A  (n, n)
        M = 0.5 * (M + M.T)
        D = Pxz.T @ B                                   # Pxzᵀ A Pxz  (m, m)
        T = chol_solve(LS, np.ascontiguousarray(0.5 * (D + D.T))).T   # Pxzᵀ A K
        v_z = T @ nu - nu
        r_z = 1.0 - np.diagonal(T)
        Q_total = self._Q_total if self._Q_total is not None else np.zeros((n, n))
        r_x = float(np.sum((P_prior - Q_total) * M))
        if self.o.adapt_q and self.propagated and self._Pg is not None:
            f = self.q_factor
            r_g = np.einsum("gij,ij->g", self._Pg, M)
            q_num = f * np.einsum("i,gij,j->g", y, self._Pg, y)
        elif self.o.adapt_q and self._U is not None:
            f = self.q_factor
            r_g = f * np.einsum("gij,ij->g", self._U, M)
            q_num = f ** 2 * np.einsum("i,gij,j->g", y, self._U, y)
        else:
            r_g = np.array([float(np.sum(Q_total * M))]) if self._Q_total is not None else np.zeros(0)
            q_num = np.array([float(y @ Q_total @ y)]) if self._Q_total is not None else np.zeros(0)
        Rd = np.diagonal(R_given if R_given is not None else (self._R_given if self._R_given is not None
                                                              else np.eye(m)))
        with np.errstate(divide="ignore", invalid="ignore"):
            z_num = np.where(Rd > 0.0, v_z ** 2 / Rd, np.nan)
        return VCEEpoch(r_x, r_g, r_z, v_z, q_num, z_num)

    def learn(self, P_prior: np.ndarray, nu: np.ndarray, S: np.ndarray, Pxz: np.ndarray, *,
              forced: bool = False) -> None:
        """After an applied update: add the epoch to the window (unless ``forced`` through the
        gate) and re-estimate the factors; restart the interval's noise sum either way."""
        try:
            if forced or self.o.adapt == "none":
                return
            e = self.epoch(P_prior, nu, S, Pxz)
            if e is None:
                self.skipped += 1
                return
            self.last = e
            slot = self._k % self.o.window
            self._k += 1
            if self.o.adapt_q and self.q_group_names is not None and e.r_g.shape == self.q_factor.shape:
                self._q_num[slot], self._q_red[slot] = e.q_num, e.r_g
                old_f = self.q_factor
                self.q_factor = self._pooled(self._q_num, self._q_red, self.q_factor)
                self.q_factor[self._q_fixed] = old_f[self._q_fixed]
                if self.propagated and self._Pg is not None:
                    # each share is linear in its factor
                    self._Pg = self._Pg * (self.q_factor / old_f)[:, None, None]
            if self.o.adapt_r and self.r_factor is not None and np.all(np.isfinite(e.z_num)):
                self._z_num[slot], self._z_red[slot] = e.z_num, e.r_z
                self.r_factor = self._pooled(self._z_num, self._z_red, self.r_factor)
        finally:
            self.restart_interval()

    def _pooled(self, num: np.ndarray, red: np.ndarray, current: np.ndarray) -> np.ndarray:
        k = min(self._k, self.o.window)
        sn, sr = num[:k].sum(axis=0), red[:k].sum(axis=0)
        ok = sr > self.o.min_redundancy
        new = current.copy()
        new[ok] = np.clip(sn[ok] / sr[ok], self.o.floor, self.o.ceiling)
        return new

    def pooled_redundancy(self) -> dict[str, np.ndarray]:
        """Σ r over the current window: ``"q"`` (G,) and ``"r"`` (m,)."""
        k = min(self._k, self.o.window)
        return {"q": self._q_red[:k].sum(axis=0), "r": self._z_red[:k].sum(axis=0)}

    def report(self) -> dict[str, np.ndarray]:
        """``q_factor`` (G,) when Q is adapted, ``r_factor`` (m,) when R is."""
        out: dict[str, np.ndarray] = {}
        if self.o.adapt_q and self.q_group_names is not None:
            out["q_factor"] = self.q_factor.copy()
        if self.o.adapt_r and self.r_factor is not None:
            out["r_factor"] = self.r_factor.copy()
        return out
