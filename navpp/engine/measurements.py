"""The measurements of a run's epochs, as the loop asks for them (a
:class:`~navpp.engine.loop.MeasurementSource` of :class:`~navpp.engine.schedule.Epoch`).

Stage 0 at a GNSS epoch: the position fix (:class:`~navpp.ins.model.GnssPosition`), then its
velocity when the log has one.  Stage 1 where the constraints apply: NHC, ZUPT, ZARU as
:class:`~navpp.aiding.Aiding` decides from the state the fixes left.

Recovery: when the fixes have been rejected for a while and their innovations grow (the INS
drifting away, :func:`drifting`, rather than a GNSS jump), the fix is built to re-open
velocity, attitude and gyro bias as well as the position if it is forced through the gate,
and after a forced fix the velocity is re-aligned on the GNSS (:func:`realigned_velocity`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..aiding import Aiding
from ..config import Config
from ..filters.base import GaussianState, Update
from ..ins.model import ATT, BG, VEL, GnssPosition
from ..ins.state import N_ERR, NOMINAL_SIZE
from ..ins.strapdown import NOMINAL_VEL
from ..recording import GnssData
from .schedule import Epoch, GnssFixes

#: What a forced fix re-opens (1-sigma floors): velocity m/s per axis, attitude deg per axis.
RECOVER_VEL_STD = 1.0
RECOVER_ATT_STD_DEG = (2.0, 2.0, 20.0)


def recovery_reopening(config: Config, P0: np.ndarray) -> np.ndarray | None:
    """The 1-sigma floors (per error state) a forced fix re-opens when the INS drifted
    (``[auto] recovery``; None: the position only): velocity and attitude
    (:data:`RECOVER_VEL_STD`, :data:`RECOVER_ATT_STD_DEG`), the gyro bias to its initial
    1-sigma (from the start covariance ``P0``)."""
    if not config.auto.recovery:
        return None
    reopen = np.zeros(P0.shape[0])
    reopen[VEL] = RECOVER_VEL_STD
    reopen[ATT] = np.radians(RECOVER_ATT_STD_DEG)
    reopen[BG] = np.sqrt(np.diagonal(P0)[BG])
    return reopen


def drifting(run_nis: np.ndarray) -> bool:
    """Whether the NIS of the current run of rejected fixes (in time order) show INS drift:
    innovations that grow (the last quarter's median NIS over twice the first quarter's), rather
    than a GNSS jump, whose innovations stay the same size."""
    if run_nis.size < 4:
        return False
    run = run_nis[np.isfinite(run_nis)]
    if run.size < 4:
        return False
    q = max(1, run.size // 4)
    return float(np.median(run[-q:])) > 2.0 * float(np.median(run[:q]))


def realigned_velocity(state: GaussianState, gnss: GnssData, fixes: GnssFixes, k: int) -> GaussianState:
    """After a forced fix ``k``: the velocity from the GNSS (its velocity, else a straight line
    through the fixes within 1 s either side), when there is one; the covariance is already
    re-opened."""
    from .. import geodesy

    sel, lat, lon, alt = fixes.index, fixes.lat, fixes.lon, fixes.alt
    idx = sel[k]
    if gnss.vel_enu is not None and np.all(np.isfinite(gnss.vel_enu[idx])):
        v = np.asarray(gnss.vel_enu[idx], dtype=float)
    else:
        near = np.nonzero(np.abs(gnss.t[sel] - gnss.t[idx]) <= 1.0)[0]
        if near.size < 3:
            return state
        enu = geodesy.geodetic_to_enu(lat[near], lon[near], alt[near], float(lat[k]), float(lon[k]), float(alt[k]))
        tt = gnss.t[sel][near] - gnss.t[sel][near].mean()
        stt = float(tt @ tt)
        if stt <= 0.0:
            return state
        v = (tt @ (enu - enu.mean(axis=0))) / stt
    x = state.x.copy()
    x[NOMINAL_VEL] = v
    return GaussianState(state.t, x, state.P)


class RunMeasurements:
    """The measurements of one run (see the module docstring).

    Parameters
    ----------
    fixes : the run's GNSS fixes; gnss : the recording's GNSS (velocities, for the recovery).
    lever_arm_b : GNSS antenna lever arm, body FLU, m.
    reopen : :func:`recovery_reopening` (None: no recovery).
    aiding : the run's aids (their counts and consistency checks are kept up to date here).
    model : the filter's model when it is not the 15-state INS (the INS with the GNSS error states,
        :class:`~navpp.ins.gnss_error.GnssErrorModel`): every measurement is carried to it with
        its ``measurement`` and the aids see the INS part of the state.
    r_share : the share of each fix's variance that is white (its R): 1 with white fix errors.

    ``last_good`` is the time (s) of the last accepted fix (None: none yet); ``recoveries`` the
    times of the forced fixes that re-aligned a drifted INS.
    """

    def __init__(self, fixes: GnssFixes, gnss: GnssData, lever_arm_b: np.ndarray, reopen: np.ndarray | None,
                 aiding: Aiding, *, model: Any = None, r_share: float = 1.0) -> None:
        self.fixes, self.gnss, self.lever, self.reopen, self.aiding = fixes, gnss, lever_arm_b, reopen, aiding
        self.wrap = getattr(model, "measurement", None)
        self.r_share = float(r_share)
        # the diagonal of each fix's R (M, 3) ENU m^2: the white share of its variance
        self.r_var = fixes.var * self.r_share if fixes.r_scale is None else fixes.var * self.r_share * fixes.r_scale
        self.last_good: float | None = None
        self.recoveries: list[float] = []
        self._rejected_nis: list[float] = []    # NIS of the fixes rejected since the last accepted one
        self._drift = False                     # the current fix was built to re-open (INS drift)

    def measurements(self, epoch: Epoch, stage: int, state: GaussianState) -> Sequence[Any] | None:
        if stage == 0:
            out = self.fix_measurements(epoch) if epoch.fix >= 0 else []
        elif stage == 1:
            out = (self.aiding.constraint_measurements(epoch.t, state.x[:NOMINAL_SIZE],
                                                              np.ascontiguousarray(state.P[:N_ERR, :N_ERR]))
                   if epoch.constraints else [])
        else:
            return None
        return out if self.wrap is None else [self.wrap(m) for m in out]

    def fix_measurements(self, epoch: Epoch) -> list[Any]:
        """The position fix of ``epoch`` and its velocity (when there is one)."""
        k, f = epoch.fix, self.fixes
        self._drift = (self.reopen is not None and len(self._rejected_nis) >= 4
                       and drifting(np.asarray(self._rejected_nis, dtype=float)))
        R = np.zeros((3, 3))
        R.ravel()[::4] = self.r_var[k]      # diag, ENU m^2, without np.diag's Python wrapper
        out: list[Any] = [GnssPosition(epoch.t, float(f.lat[k]), float(f.lon[k]), float(f.alt[k]), R, self.lever,
                                       self.reopen if self._drift else None)]
        vmeas = self.aiding.velocity(k, epoch.t)
        if vmeas is not None:
            out.append(vmeas)
        return out

    def velocity_mask(self) -> np.ndarray | None:
        """Which fixes come with a GNSS velocity measurement (M,) (None: none does)."""
        return None if self.aiding.vel is None else np.asarray(self.aiding.vel_ok, dtype=bool)

    def fixes_gated(self, n_accepted: int, n_rejected: int, t_good: float | None, rejected_nis: np.ndarray) -> None:
        """What :meth:`observed` keeps after position fixes the gate passed (``n_accepted``, the
        last at ``t_good`` s; None: none) or rejected (``n_rejected``, none forced; the NIS of
        those after the last accepted one ``rejected_nis``), whose epochs had no other measurement
        than a still epoch's aids (the loop's compiled path, :mod:`navpp.engine.fused`)."""
        self.aiding.counts.applied["gnss_position"] += n_accepted
        self.aiding.counts.rejected["gnss_position"] += n_rejected
        if t_good is not None:
            self.last_good = t_good
            self._rejected_nis = []
        self._rejected_nis.extend(rejected_nis.tolist())

    def observed(self, epoch: Epoch, meas: Any, update: Update) -> GaussianState:
        inn, state = update.innovation, update.state
        self.aiding.counts.add(meas.kind, inn.accepted)
        if meas.kind != "gnss_position":
            self.aiding.observed(getattr(meas, "inner", meas), inn)
            return state
        if inn.accepted:
            self.last_good = epoch.t
            self._rejected_nis = []
        else:
            self._rejected_nis.append(inn.nis)
        if inn.forced and self._drift:
            state = realigned_velocity(state, self.gnss, self.fixes, epoch.fix)
            self.recoveries.append(epoch.t)
        return state
