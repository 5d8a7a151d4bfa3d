"""The vehicle mounting's first pass (``[vehicle] mounting_rpy_deg = "auto"`` with the NHC on).

The log is run once without the non-holonomic constraint, with a plain EKF, and the vehicle
frame's pitch and yaw relative to the body are estimated from that solution
(:func:`navpp.ins.aids.mounting.estimate_mounting`); the real run then constrains the vehicle
frame's lateral and vertical velocity.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from ..config import Config
from ..filters.base import Filter
from ..findings import Finding
from ..recording import Recording
from .results import RunResult

#: Runs the first pass: (recording, config, filter, progress, cov_step_s, smooth) -> RunResult.
PassRunner = Callable[[Recording, Config, Filter, None, float, bool], RunResult]


def first_pass_filter(config: Config) -> Filter:
    """The first pass's filter: the EKF with the run's gate, without adaptation."""
    from ..filters.ekf import EKF

    return EKF(gate_probability=config.gnss.gate_probability, reanchor_after_s=config.gnss.reanchor_after_s)


def vehicle_mounting(recording: Recording, config: Config, cov_step_s: float, run_pass: PassRunner
                     ) -> tuple[tuple[float, float, float] | None, list[str], list[Finding]]:
    """The vehicle frame's roll, pitch, yaw relative to the body (deg) from a first pass
    ``run_pass`` without the constraint (None: as configured, no first pass), and a note or a
    warning for the user."""
    veh = config.vehicle
    if not (veh.type == "car" and veh.nhc and veh.mounting_rpy_deg == "auto"):
        return None, [], []
    from ..ins.aids.mounting import estimate_mounting

    gnss = config.gnss   # the first pass only needs the attitude: no second pass for correlated fixes
    first = replace(config, vehicle=replace(veh, nhc=False),
                    gnss=replace(gnss, error_model="white") if gnss.error_model == "auto" else gnss)
    pre = run_pass(recording, first, first_pass_filter(config), None, cov_step_s, False)
    sol = pre.solution
    est = estimate_mounting(sol.t, sol.vel_enu, sol.rph_deg)
    if est is None:
        why = Finding("vehicle-mounting-unknown",
                      f"{recording.source}: [vehicle] mounting_rpy_deg = \"auto\": less than 10 s of fast straight "
                      "driving to estimate it from; the constraint assumes the IMU aligned with the vehicle")
        return (0.0, 0.0, 0.0), [], [why]
    note = (f"vehicle mounting estimated (first pass without the constraint, {est.seconds:.0f} s of straight "
            f"driving): pitch {est.pitch_deg:+.2f} deg, yaw {est.yaw_deg:+.2f} deg (spread "
            f"{est.spread_deg[0]:.2f} / {est.spread_deg[1]:.2f} deg)")
    return (0.0, est.pitch_deg, est.yaw_deg), [note], []
