"""What a run returns: the solution, the per-epoch diagnostics, the bias history, the smoothed run."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..ins.alignment import Alignment
from ..recording import Solution


@dataclass(frozen=True)
class Diagnostics:
    """Per-GNSS-epoch record of what the filter saw: t (s), innovation nu (M, 3) ENU m,
    NIS, accepted flag, forced flag (accepted after a run of rejections), and the 1-sigma of the
    measurement noise the filter used, r_std (M, 3) m (what an adaptive filter decided).
    ``adaptive`` holds the rest of what an adaptive filter decided after each epoch (its
    :meth:`~navpp.filters.base.Filter.noise_report`, e.g. VCE's process-noise group factors):
    name -> (M, k) array."""

    t: np.ndarray
    nu: np.ndarray
    nis: np.ndarray
    accepted: np.ndarray
    forced: np.ndarray
    r_std: np.ndarray
    adaptive: dict[str, np.ndarray] = field(default_factory=dict)
    vel_nu: np.ndarray | None = None          # (M, 3) GNSS velocity innovation, ENU m/s (NaN: none)
    vel_nis: np.ndarray | None = None         # (M,) its NIS
    vel_accepted: np.ndarray | None = None    # (M,) 1 applied, 0 rejected, NaN no velocity
    #: extra filter states after each fix, name -> (M, 1): with the Gauss-Markov GNSS error model
    #: ``gnss_error_e/n/u`` (ENU m) and their 1-sigma ``gnss_error_e_std`` ...
    states: dict[str, np.ndarray] = field(default_factory=dict)
    #: one-element aids at the GNSS epoch, short name -> (innovation (M,), NIS (M,), applied (M,): 1, 0,
    #: NaN where the aid had no update there): ``odo`` the odometer's speed (m/s), ``yaw`` the
    #: odometry's yaw rate (rad/s)
    aids: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)


@dataclass(frozen=True)
class BiasHistory:
    """Estimated sensor biases after each GNSS epoch and their 1-sigma: t (M,) s; gyro and
    gyro_std (M, 3) rad/s; accel and accel_std (M, 3) m/s^2; body FLU.  Constant between epochs."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    gyro_std: np.ndarray
    accel_std: np.ndarray


@dataclass(frozen=True)
class SmoothedRun:
    """The forward run smoothed backwards (Rauch-Tung-Striebel, :mod:`navpp.filters.smoother`).

    solution : IMU-rate smoothed solution with smoothed position 1-sigma.
    biases : smoothed sensor biases at the GNSS epochs (same epochs as the forward history).
    runtime_s : wall time of the backward pass and the IMU-rate corrections, s.
    nodes : forward nodes stored (GNSS epochs plus coast knots plus the start and end).
    breaks : forced (re-anchored) fixes the smoother did not carry information back across,
        plus steps whose prior covariance was not positive definite.
    store_mb : memory the stored forward run took, MB.
    """

    solution: Solution
    biases: BiasHistory
    runtime_s: float
    nodes: int
    breaks: int
    store_mb: float


@dataclass(frozen=True)
class RunResult:
    """One run of one filter over one recording: the forward IMU-rate solution and what the run
    saw, decided and measured (see the fields); ``smoothed`` with ``smooth=True``."""

    solution: Solution
    biases: BiasHistory
    alignment: Alignment
    diagnostics: Diagnostics
    gnss_epochs: int
    gnss_rejected: int
    runtime_s: float                  # processing wall time, s, without kernel compilation (smoothing included)
    compile_s: float = 0.0            # one-off numba compilation on a cold cache, s
    warnings: tuple[str, ...] = ()    # what the run noticed about the data (units, tilt, gating)
    smoothed: SmoothedRun | None = None   # with smooth=True: the RTS-smoothed run
    notes: tuple[str, ...] = ()       # what the run decided (e.g. the estimated vehicle mounting)
    #: updates applied / rejected by the gate per kind: gnss_position, gnss_velocity, zupt, zaru, nhc
    updates: dict[str, dict[str, int]] = field(default_factory=dict)
    #: what the run measured from the log itself (``[auto]``), plain numbers for metrics.json:
    #: standstill, biases, noise, gravity axis, mounting, stale rows, clock offset, recoveries
    calibration: dict = field(default_factory=dict)

    @property
    def forward_runtime_s(self) -> float:
        """Processing time of the forward filter alone, s (``runtime_s`` without the smoothing)."""
        return self.runtime_s - (self.smoothed.runtime_s if self.smoothed is not None else 0.0)
