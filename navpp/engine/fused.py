"""The loop's compiled path for the common epochs of a plain EKF run: many epochs per call.

A run of the plain EKF (:class:`~navpp.filters.ekf.EKF` with the no-op adaptation) on the
15-state INS (:class:`~navpp.ins.model.InsModel`), with the run's own measurement source and
recorder (:class:`~navpp.engine.measurements.RunMeasurements`,
:class:`~navpp.engine.recorder.RunRecorder` without smoothing or extra states), spends most
of its epochs on one GNSS position fix that passes the gate, or on a coasting stop, and when
the only constraints are ZUPT and ZARU (no NHC, odometer or GNSS velocity), on the still epochs'
ZUPT and ZARU (with or without a fix).  Such epochs go through :func:`ekf_epochs`, one compiled
call for a stretch of them, which does what the generic loop does for them
(:func:`navpp.engine.loop.run_epochs`: time update, the state check, measurement prediction,
gate, gain, Joseph correction, the check again; for a still epoch the speed gate, the veto and
ZUPT's consistency check of :class:`~navpp.aiding.Aiding`) with the same kernels in the same
order, so the figures are the same bits, and writes what the recorder would write; a fix the
gate rejects it records as rejected, as the generic loop does.  Any other epoch, and any epoch
whose fix the filter would force through the gate, whose aid the gate rejects, whose state
fails the check, whose update fails or whose ZUPT check vetoes its still run (the kernel stops
before it), goes through the generic loop; so do filters, models, sources and recorders of any
other kind (:func:`fused_runner` returns None).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import aiding as aid_rules
from ..aiding import ZUPT_RUN, Aiding
from ..filters.adaptation import Adaptation
from ..filters.base import Filter, GaussianState
from ..filters.ekf import EKF
from ..filters.linalg import (
    compiled,
    finite_with_positive_variances,
    innovation_gain,
    joseph_correction,
    linear_moments,
    propagated_covariance,
)
from ..ins.aids import zero_rate, zero_velocity
from ..ins.model import (
    GnssPosition,
    InsModel,
    antenna_offset_enu,
    gnss_innovation_offset,
    gnss_jacobian_offset,
    integrate_with_jacobian,
    plus,
)
from ..ins.state import DX_ATT, DX_BG, DX_VEL, NOMINAL_SIZE, X_BG, X_VE
from ..jitmode import interpreted
from .measurements import RunMeasurements
from .recorder import KNOT, RunRecorder
from .schedule import Epoch, Schedule

#: Whether :func:`navpp.engine.loop.run_epochs` takes the compiled path where it applies
#: (the tests switch it off to compare with the generic loop).
ENABLED = True

#: the filter steps the compiled path stands in for, as the EKF had them when this module was
#: imported: a filter class whose steps are these (none overridden or replaced since) and that
#: runs the no-op adaptation is the plain EKF
_EKF_STEPS = {name: getattr(EKF, name) for name in ("predict", "update", "time_update", "predict_measurement",
                                                    "apply_measurement", "accepted", "_moments", "_correct",
                                                    "noise_report", "gate_threshold")}
KNOT_START = KNOT.start
_KNOT_N = KNOT.stop - KNOT.start
#: doubles per knot record: the time, the prior and the posterior variances
KNOT_RECORD = 1 + 2 * _KNOT_N
#: the longest stretch of epochs one kernel call runs (its knot buffer: 152 bytes per epoch), and
#: when the smoother's store takes its states (its buffers: about 5 kB more per epoch)
STRETCH = 1024
STORE_STRETCH = 512


@compiled
def _profile_psd(psd: np.ndarray, prof_t: np.ndarray, prof_g: np.ndarray, prof_a: np.ndarray, white_g: float,
                 white_a: float, t0: float, t1: float) -> np.ndarray:
    """:meth:`~navpp.ins.model.InsModel.psd_over` with a noise profile (block edges ``prof_t`` s,
    white-noise densities ``prof_g`` rad/sqrt(s), ``prof_a`` m/s/sqrt(s)), with Python's ``max``
    semantics: the configured ``psd`` (15,) itself, or a copy with the white noise raised."""
    k_n = prof_g.shape[0]
    k0 = min(max(int(np.searchsorted(prof_t, t0, side="right")) - 1, 0), k_n - 1)
    k1 = min(max(int(np.searchsorted(prof_t, t1, side="left")), k0 + 1), k_n)
    g, a = prof_g[k0], prof_a[k0]
    for k in range(k0 + 1, k1):
        if prof_g[k] > g:
            g = prof_g[k]
        if prof_a[k] > a:
            a = prof_a[k]
    gg, aa = g * g, a * a
    if gg <= white_g and aa <= white_a:
        return psd
    out = psd.copy()
    pg = gg if gg > white_g else white_g
    pa = aa if aa > white_a else white_a
    for k in range(3):
        out[DX_ATT + k] = pg
        out[DX_VEL + k] = pa
    return out


@compiled
def _gap_inside(gaps: np.ndarray, t0: float, t1: float) -> bool:
    """Whether a long IMU gap (``gaps`` (G, 2) start, end s, sorted, disjoint) overlaps
    ``(t0, t1)``: :meth:`~navpp.ins.model.InsModel.gap_noise` is not None there."""
    if gaps.shape[0] == 0:
        return False
    first = int(np.searchsorted(gaps[:, 1], t0, side="right"))
    last = int(np.searchsorted(gaps[:, 0], t1, side="left"))
    overlap = False
    for j in range(first, last):
        overlap = overlap or min(gaps[j, 1], t1) > max(gaps[j, 0], t0)
    return overlap


@compiled
def _knot_row(row: np.ndarray, t: float, P_prior: np.ndarray, P_post: np.ndarray) -> None:
    """One knot record (:data:`KNOT_RECORD`) into ``row``: the time ``t`` s, the variances of
    :data:`KNOT` before and after (:meth:`~navpp.engine.recorder.RunRecorder.knot`)."""
    row[0] = t
    for e in range(_KNOT_N):
        row[1 + e] = P_prior[KNOT_START + e, KNOT_START + e]
        row[1 + _KNOT_N + e] = P_post[KNOT_START + e, KNOT_START + e]


#: the measurement kind of a GNSS position fix
FIX_KIND = GnssPosition.kind
#: what :func:`_fix_update` did with a fix: passed the gate and corrected the state, failed the gate
#: (not forced), or neither (the generic loop redoes the epoch: a forced fix, divergence)
FIX_ACCEPTED, FIX_REJECTED, FIX_GENERIC = 0, 1, 2


@compiled
def _fix_update(x: np.ndarray, P: np.ndarray, lat: float, lon: float, alt: float, var: np.ndarray,
                lever: np.ndarray, gate: float
                ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    """The generic update of one GNSS position fix (``lat``, ``lon`` rad, ``alt`` m; R's diagonal
    ``var`` ENU m^2; antenna ``lever`` body FLU m) on the prior (``x``, ``P``):
    ``(status, nu, S, R, nis, x+, P+)``, ``status`` :data:`FIX_ACCEPTED` when it passes the gate
    ``gate`` and leaves a sound state, :data:`FIX_REJECTED` (the prior returned) when it fails the
    gate, else :data:`FIX_GENERIC` (S not positive definite, an unsound posterior)."""
    offset = antenna_offset_enu(x, lever)       # once for both (gnss_jacobian, gnss_innovation)
    H = gnss_jacobian_offset(offset)
    PHt, Pzz = linear_moments(P, H)
    nu = gnss_innovation_offset(x, lat, lon, alt, offset)
    R = np.zeros((3, 3))
    for e in range(3):
        R[e, e] = var[e]
    S, K, nis, ok = innovation_gain(Pzz, R, PHt, nu)
    if not ok:
        return FIX_GENERIC, nu, S, R, nis, x, P
    if not nis <= gate:
        return FIX_REJECTED, nu, S, R, nis, x, P
    dx, Pn = joseph_correction(P, K, H, R, nu)
    xp = plus(x, dx)
    ok = finite_with_positive_variances(xp, Pn)     # all_finite (the filter's own test) too
    return (FIX_ACCEPTED if ok else FIX_GENERIC), nu, S, R, nis, xp, Pn


@compiled
def _aid_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, h: np.ndarray, H: np.ndarray, var: float, gate: float
                ) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The generic update of a three-element aid (value ``z``, its model's ``h`` and ``H`` at ``x``,
    R ``var`` times the identity) on (``x``, ``P``) when it passes the ``gate`` and leaves a sound
    state: ``(True, nu, S, x+, P+)``; else ``ok`` is False (the generic loop redoes the epoch)."""
    nu = z - h
    PHt, Pzz = linear_moments(P, H)
    R = np.zeros((3, 3))
    for e in range(3):
        R[e, e] = var
    S, K, nis, ok = innovation_gain(Pzz, R, PHt, nu)
    if not ok or not nis <= gate:
        return False, nu, S, x, P
    dx, Pn = joseph_correction(P, K, H, R, nu)
    xp = plus(x, dx)
    return finite_with_positive_variances(xp, Pn), nu, S, xp, Pn


@compiled
def _standstill(x: np.ndarray, P: np.ndarray, run: int, zupt_var: float, zaru: bool, zaru_z: np.ndarray,
                zaru_var: float, max_speed: float, gate: float, aid_state: np.ndarray, ring: np.ndarray,
                z_limit: float, aid_counts: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, int]:
    """The ZUPT and ZARU of a still epoch as :meth:`~navpp.aiding.Aiding.constraint_measurements`
    gives them and the generic loop applies them, from the state (``x``, ``P``) the fix left: none
    in a vetoed still run (``run``, ``aid_state[0]``) or when the speed gate
    (:func:`~navpp.ins.aids.standstill.speed_allows`, ``max_speed`` m/s) refuses; the ZUPT with R
    ``zupt_var`` (m/s)^2 (NaN: no ZUPT), then, with ``zaru``, the ZARU of the mean gyro ``zaru_z``
    (rad/s) with R ``zaru_var``.  ZUPT's consistency check (:meth:`~navpp.aiding.Aiding.observed`)
    runs on ``aid_state`` ``(vetoed run, run of the ring, innovations in the ring)`` and ``ring``
    (``ZUPT_RUN``, 3) (oldest first), which are updated, with the limit ``z_limit``
    (:data:`~navpp.aiding.ZUPT_Z`); the ZUPT and ZARU applied are added to ``aid_counts`` (2,).
    Returns ``(ok, x, P, number of aids applied)``; ``ok`` is False when an update is rejected or
    fails, or the check vetoes the run (the generic loop redoes the epoch; ``aid_state``, ``ring``
    and ``aid_counts`` are then left as they were)."""
    if run == aid_state[0]:
        return True, x, P, 0
    ve, vn, vu = x[X_VE], x[X_VE + 1], x[X_VE + 2]
    speed = np.sqrt(ve * ve + vn * vn + vu * vu)
    trace = P[DX_VEL, DX_VEL] + P[DX_VEL + 1, DX_VEL + 1] + P[DX_VEL + 2, DX_VEL + 2]
    speed_std = np.sqrt(max(trace, 0.0))
    if not (speed <= max_speed and speed_std <= 2.0 * max_speed):
        return True, x, P, 0
    no_p = np.zeros(0)
    n_zupt = n_zaru = 0
    count = aid_state[2] if aid_state[1] == run else 0
    new_ring = ring.copy()
    if zupt_var == zupt_var:
        ok, nu, S, x, P = _aid_update(x, P, np.zeros(3), zero_velocity._h(x, no_p), zero_velocity._H(x, no_p),
                                      zupt_var, gate)
        if not ok:
            return False, x, P, 0
        n_zupt = 1
        if count == ZUPT_RUN:
            for r in range(ZUPT_RUN - 1):
                for e in range(3):
                    new_ring[r, e] = new_ring[r + 1, e]
            count -= 1
        for e in range(3):
            new_ring[count, e] = nu[e] / np.sqrt(max(S[e, e], 1e-30))
        count += 1
        if count == ZUPT_RUN:
            for e in range(3):
                total = 0.0
                for r in range(ZUPT_RUN):
                    total += new_ring[r, e]
                if abs(total / ZUPT_RUN * np.sqrt(ZUPT_RUN)) > z_limit:
                    return False, x, P, 0
    if zaru:
        ok, nu, S, x, P = _aid_update(x, P, zaru_z, zero_rate._h(x, no_p), zero_rate._H(x, no_p), zaru_var, gate)
        if not ok:
            return False, x, P, 0
        n_zaru = 1
    if n_zupt:
        aid_state[1], aid_state[2] = run, count
        for r in range(ZUPT_RUN):
            for e in range(3):
                ring[r, e] = new_ring[r, e]
    aid_counts[0] += n_zupt
    aid_counts[1] += n_zaru
    return True, x, P, n_zupt + n_zaru


@compiled
def _record_fix(k: int, accepted: bool, nu: np.ndarray, nis: float, S: np.ndarray, R: np.ndarray, x: np.ndarray,
                P: np.ndarray, nu_out: np.ndarray, nis_out: np.ndarray, accepted_out: np.ndarray,
                forced_out: np.ndarray, s_out: np.ndarray, r_out: np.ndarray, bias_out: np.ndarray,
                bias_var_out: np.ndarray) -> None:
    """What the recorder keeps of fix ``k``, ``accepted`` or rejected by the gate (not forced), with
    innovation ``nu``, ``nis``, ``S`` and ``R``, the epoch's posterior (``x``, ``P``) giving the
    biases and their variance."""
    nu_out[k] = nu
    nis_out[k] = nis
    accepted_out[k] = accepted
    forced_out[k] = False
    s_out[k] = S
    r_out[k] = R
    for e in range(6):
        bias_out[k, e] = x[X_BG + e]
        bias_var_out[k, e] = P[DX_BG + e, DX_BG + e]


@compiled
def _path_row(path: np.ndarray, sample: int, x: np.ndarray) -> None:
    """The recorded ``path``'s row of IMU ``sample`` (-1: none) from the posterior nominal ``x``."""
    if sample >= 0:
        row = path[sample]
        for e in range(row.shape[0]):
            row[e] = x[e]


@compiled
def ekf_epochs(x: np.ndarray, P: np.ndarray, t_prev: float, ep_t: np.ndarray, ep_fix: np.ndarray,
               ep_sample: np.ndarray, ep_coast: np.ndarray, ep_generic: np.ndarray, first: int, stop: int,
               fix_lat: np.ndarray, fix_lon: np.ndarray, fix_alt: np.ndarray, fix_var: np.ndarray,
               lever: np.ndarray, gate: float, rejecting_since: float, reanchor_after_s: float, nu_out: np.ndarray,
               nis_out: np.ndarray, accepted_out: np.ndarray, forced_out: np.ndarray, s_out: np.ndarray,
               r_out: np.ndarray, bias_out: np.ndarray, bias_var_out: np.ndarray, knots_out: np.ndarray, keep: bool,
               nodes_x: np.ndarray, nodes_P: np.ndarray, imu_t: np.ndarray, gyro: np.ndarray,
               accel: np.ndarray, path: np.ndarray, psd: np.ndarray, has_profile: bool, prof_t: np.ndarray,
               prof_g: np.ndarray, prof_a: np.ndarray, white_g: float, white_a: float, inv_tau_g: float,
               inv_tau_a: float, cov_step_s: float, gaps: np.ndarray, ep_cons: np.ndarray, ep_run: np.ndarray,
               zupt_var: float, zaru_ok: np.ndarray, zaru_z: np.ndarray, zaru_var: np.ndarray, max_speed: float,
               aid_state: np.ndarray, ring: np.ndarray, z_limit: float, aid_counts: np.ndarray
               ) -> tuple[int, np.ndarray, np.ndarray, float, int]:
    """The plain EKF over epochs ``first`` .. ``stop - 1`` from the state (``x`` (16,), ``P``
    (15, 15)) at ``t_prev`` (s), as the generic loop runs them (module docstring).

    Epochs: ``ep_t`` s, fix ``ep_fix``, IMU sample ``ep_sample`` (-1: none), ``ep_coast``,
    ``ep_generic``.  Fixes (rad, rad, m), R's diagonal ENU m^2, ``lever`` body FLU m, NIS ``gate``;
    the run of rejections began at ``rejecting_since`` s (NaN: none), forced in after
    ``reanchor_after_s``.  Writes the per-fix arrays (rejected fixes too), ``knots_out``, the
    ``path``; with ``keep`` ``nodes_x`` (L, 2, 16) propagated and posterior nominal, ``nodes_P``
    (L, 3, 15, 15) prior, posterior, ``P Phi^T``.  Then the model's arrays and the still epochs'
    (:func:`_standstill`).  Returns the first epoch not run (``stop``, or the generic loop's: see
    the module docstring), the state before it (x, P, t) and the knot rows written.
    """
    n_knots = 0
    i = first
    while i < stop:
        if ep_generic[i]:
            break
        t1 = ep_t[i]
        if _gap_inside(gaps, t_prev, t1):
            break
        psd_i = _profile_psd(psd, prof_t, prof_g, prof_a, white_g, white_a, t_prev, t1) if has_profile else psd
        xn = x.copy()
        Phi, Qd = integrate_with_jacobian(xn, imu_t, gyro, accel, t_prev, t1, path, True, psd_i, inv_tau_g,
                                          inv_tau_a, cov_step_s)
        Pp, PPhit = propagated_covariance(P, Phi, Qd)
        if keep:
            nodes_x[i - first, 0], nodes_P[i - first, 0], nodes_P[i - first, 2] = xn, Pp, PPhit
        if ep_coast[i]:
            _knot_row(knots_out[n_knots], t1, Pp, Pp)
            n_knots += 1
            x, P, t_prev = xn, Pp, t1
            i += 1
            continue
        if not finite_with_positive_variances(xn, Pp):
            break
        k = ep_fix[i]
        xp, Pn, applied = xn, Pp, False
        if k >= 0:
            status, nu, S, R, nis, xp, Pn = _fix_update(xn, Pp, fix_lat[k], fix_lon[k], fix_alt[k], fix_var[k],
                                                        lever, gate)
            if status == FIX_GENERIC:
                break
            applied = status == FIX_ACCEPTED
            if applied:
                rejecting_since = np.nan
            elif rejecting_since != rejecting_since:        # NaN: the first rejection of a run
                rejecting_since = t1
            elif t1 - rejecting_since >= reanchor_after_s:  # the filter forces this fix in
                break
        if ep_cons[i]:
            ok, xp, Pn, n_aids = _standstill(xp, Pn, ep_run[i], zupt_var, zaru_ok[i], zaru_z[i], zaru_var[i],
                                             max_speed, gate, aid_state, ring, z_limit, aid_counts)
            if not ok or not (applied or n_aids):
                break
            applied = True
        if keep:
            nodes_x[i - first, 1], nodes_P[i - first, 1] = xp, Pn
        if k >= 0:
            _record_fix(k, status == FIX_ACCEPTED, nu, nis, S, R, xp, Pn, nu_out, nis_out, accepted_out, forced_out,
                        s_out, r_out, bias_out, bias_var_out)
        if applied:
            _path_row(path, ep_sample[i], xp)
        _knot_row(knots_out[n_knots], t1, Pp, Pn)
        n_knots += 1
        x, P, t_prev = xp, Pn, t1
        i += 1
    return i, x, P, t_prev, n_knots


def plain_ekf(filt: Filter) -> bool:
    """Whether ``filt`` is the plain EKF: an :class:`~navpp.filters.ekf.EKF` with the no-op
    adaptation whose steps are the ones the compiled path stands in for (:data:`_EKF_STEPS`)."""
    cls = type(filt)
    return (isinstance(filt, EKF) and type(filt.adapter) is Adaptation
            and all(getattr(cls, name) is step for name, step in _EKF_STEPS.items()))


def standstill_only(aiding: Aiding) -> bool:
    """Whether ``aiding``'s constraints are ZUPT and ZARU alone (no NHC, odometer or GNSS
    velocity): then its constraint epochs are the compiled path's too (:func:`_standstill`)."""
    return (aiding.zupt or aiding.zaru) and not aiding.nhc and aiding.odo is None and aiding.vel is None


class _StandstillInputs:
    """What :func:`_standstill` needs of a run's still epochs (``cons`` (L,) bool, the epochs it may
    run, at times ``t`` (L,) s; :attr:`cons` those whose IMU sample is still), taken from
    ``aiding`` as :meth:`~navpp.aiding.Aiding.constraint_measurements` takes it, and its state (the
    ZUPT check's ring and veto, the counts), which :meth:`load` takes before a stretch and
    :meth:`ran` hands back after it."""

    def __init__(self, aiding: Aiding, t: np.ndarray, cons: np.ndarray) -> None:
        n = t.shape[0]
        self.cons = cons.copy()
        self.run = np.zeros(n, np.int64)
        self.zaru_ok = np.zeros(n, bool)
        self.zaru_z = np.zeros((n, 3))
        self.zaru_var = np.zeros(n)
        self.zupt_var = aiding.zupt_std ** 2 if aiding.zupt else np.nan
        self.max_speed = aiding.settings.max_speed
        self.z_limit = aid_rules.ZUPT_Z
        self.aid_state = np.zeros(3, np.int64)
        self.ring = np.zeros((ZUPT_RUN, 3))
        self.counts = np.zeros(2, np.int64)
        if not cons.any():
            return
        at = np.flatnonzero(cons)
        self.cons[at], self.run[at] = aiding.still_runs(t[at])
        at = at[self.cons[at]]
        if aiding.zaru:     # the mean gyro since the previous constraint epoch when every sample in between is still
            self.zaru_ok[at], self.zaru_z[at], self.zaru_var[at] = aiding.zero_rates(aiding.last_constraint_t, t[at])

    def arguments(self) -> tuple[Any, ...]:
        """:func:`ekf_epochs`'s still-epoch arguments, ``ep_cons`` (:attr:`cons`) on."""
        return (self.cons, self.run, self.zupt_var, self.zaru_ok, self.zaru_z, self.zaru_var, self.max_speed,
                self.aid_state, self.ring, self.z_limit, self.counts)

    def load(self, aiding: Aiding) -> None:
        """The ZUPT check's state as ``aiding`` has it (the generic loop's epochs change it)."""
        check = aiding.zupt_check
        self.aid_state[:] = (check.vetoed_run, check.run, len(check.z))
        for r, z in enumerate(check.z):
            self.ring[r] = z

    def ran(self, aiding: Aiding, filt: Filter, t_last: float) -> None:
        """After a stretch whose last still epoch was at ``t_last`` s: ``aiding`` and ``filt`` as the
        generic loop would leave them (the ZUPT check's ring, the counts, the last constraint time,
        the accepted kinds)."""
        aiding.last_constraint_t = t_last
        aiding.zupt_check.run = int(self.aid_state[1])
        aiding.zupt_check.z = [self.ring[r].copy() for r in range(int(self.aid_state[2]))]
        for kind, n in zip(("zupt", "zaru"), self.counts):
            if n:
                aiding.counts.applied[kind] += int(n)
                filt.accepted(kind)
        self.counts[:] = 0


class FusedRunner:
    """Runs stretches of a run's epochs through :func:`ekf_epochs` and keeps the filter, the
    source and the recorder as the generic loop would leave them (see :func:`fused_runner`)."""

    def __init__(self, filt: Filter, model: InsModel, source: RunMeasurements, recorder: RunRecorder,
                 epochs: Sequence[Epoch]) -> None:
        self.filt, self.source, self.recorder = filt, source, recorder
        n = len(epochs)
        self.t, index, self.fix, self.sample, constraints, self.coast = Schedule.columns(epochs)
        self.aiding = aid = source.aiding
        self.standstill = _StandstillInputs(aid, self.t, ~self.coast & constraints & standstill_only(aid))
        self.cons = self.standstill.cons
        self.generic = ~self.coast & (((self.fix < 0) & ~self.cons) | (constraints & ~self.cons))
        has_vel = source.velocity_mask()
        if has_vel is not None and has_vel.size:
            self.generic |= ~self.coast & (self.fix >= 0) & has_vel[np.maximum(self.fix, 0)]
        # the recorder's progress: stretches end after each epoch it reports
        self.report = np.zeros(n, bool)
        if recorder.progress is not None:
            self.report = ~self.coast & (index % recorder.tick == 0)
        self.index = index
        f = source.fixes
        self.fix_lat, self.fix_lon, self.fix_alt = (np.ascontiguousarray(a, dtype=float) for a in (f.lat, f.lon, f.alt))
        self.fix_var = np.ascontiguousarray(source.r_var, dtype=float)
        self.knots = np.empty((min(n, STRETCH), KNOT_RECORD))
        self.prop = model.propagation_arrays()
        self.x_size, self.n_err = NOMINAL_SIZE, model.dim
        self.no_nodes = (np.empty((0, 2, self.x_size)), np.empty((0, 3, self.n_err, self.n_err)))

    def run(self, i: int, state: GaussianState, stop: int) -> tuple[int, GaussianState, bool]:
        """Epochs ``i`` .. at most ``stop - 1`` from ``state``; returns the first epoch not run,
        the state before it and whether the generic loop must run that epoch
        (:meth:`~navpp.engine.loop.FastPath.run`)."""
        if self.generic[i]:
            return i, state, True
        rec = self.recorder
        if self.report[i:stop].any():
            stop = i + int(np.argmax(self.report[i:stop])) + 1
        keep = rec.store is not None
        stop = min(stop, i + (STORE_STRETCH if keep else STRETCH))
        if keep:            # fresh buffers: the store keeps views of the last nodes
            nodes_x, nodes_P = np.empty((stop - i, 2, self.x_size)), np.empty((stop - i, 3, self.n_err, self.n_err))
        else:
            nodes_x, nodes_P = self.no_nodes
        st = self.standstill
        st.load(self.aiding)
        since = self.filt.rejecting_since(FIX_KIND)
        since = np.nan if since is None else since
        j, x, P, t, n_knots = ekf_epochs(
            state.x, state.P, state.t, self.t, self.fix, self.sample, self.coast, self.generic, i, stop,
            self.fix_lat, self.fix_lon, self.fix_alt, self.fix_var, self.source.lever, self.filt.gate_threshold(3),
            since, self.filt.reanchor_after_s,
            rec.nu, rec.nis, rec.accepted, rec.forced, rec.s_used, rec.r_used, rec.bias, rec.bias_var, self.knots,
            keep, nodes_x, nodes_P, *self.prop, *st.arguments())
        leaves = j < stop           # the kernel stopped before an epoch it does not run
        if j == i:
            return i, state, leaves
        if keep:
            rec.fused_nodes(self.t[i:j], self.fix[i:j], self.coast[i:j], nodes_x, nodes_P)
        rec.fused_epochs(self.knots[:n_knots], t, int(self.sample[i:j].max()))
        with_fix = i + np.flatnonzero(self.fix[i:j] >= 0)
        if with_fix.size:
            self._fixes_gated(with_fix)
        cons = self.cons[i:j]
        if cons.any():
            st.ran(self.aiding, self.filt, float(self.t[i:j][cons][-1]))
        if self.report[j - 1] and rec.progress is not None:
            rec.progress(int(self.index[j - 1]) / rec.n_epochs)
        return j, GaussianState(t, x, P), leaves

    def _fixes_gated(self, epochs: np.ndarray) -> None:
        """The filter and the source as the generic loop leaves them after the kernel gated the
        fixes of ``epochs`` (indices of epochs with a fix, in order; none forced): the counts, the
        last accepted fix and the current run of rejections."""
        k = self.fix[epochs]
        ok = self.recorder.accepted[k]
        passed = np.flatnonzero(ok)
        n_ok = int(passed.size)
        tail = epochs[passed[-1] + 1:] if n_ok else epochs      # the rejected fixes after the last accepted one
        t_good = float(self.t[epochs[passed[-1]]]) if n_ok else None
        self.source.fixes_gated(n_ok, k.size - n_ok, t_good, self.recorder.nis[self.fix[tail]])
        since = None if n_ok else self.filt.rejecting_since(FIX_KIND)
        if tail.size and since is None:
            since = float(self.t[tail[0]])
        self.filt.gated(FIX_KIND, k.size - n_ok, since)


def fused_runner(filt: Filter, model: Any, source: Any, recorder: Any, epochs: Sequence[Any]) -> FusedRunner | None:
    """The compiled path's runner for a run over ``epochs``
    (:meth:`~navpp.engine.loop.FastPath`, :class:`FusedRunner`), or None when it does not apply:
    not :data:`ENABLED`, kernels interpreted (``--jit off``: the kernel's loops as Python are no
    faster than the generic loop, sample drive 5.0-5.4 s against 5.0-5.1 s CPU), not the plain
    EKF (:func:`plain_ekf`) on the 15-state :class:`~navpp.ins.model.InsModel`, or a source or
    recorder of another kind (or one that carries measurements to another model or records
    extra states).  The loop's check
    must raise only on the faults of :func:`~navpp.engine.verdict.state_fault` (the kernel
    leaves every state that has one to the generic loop)."""
    if not (ENABLED and not interpreted() and type(model) is InsModel and type(source) is RunMeasurements
            and source.wrap is None
            and type(recorder) is RunRecorder and recorder.extra_values is None
            and plain_ekf(filt)):
        return None
    return FusedRunner(filt, model, source, recorder, epochs)


__all__ = ["ENABLED", "KNOT_RECORD", "FusedRunner", "ekf_epochs", "fused_runner", "plain_ekf"]
