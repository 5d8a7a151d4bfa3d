"""Checks of a run's filter state and finished result, and the refusal they lead to.

During the run, :func:`state_fault` says what is wrong with a filter state.  After it,
:func:`velocity_sigma_checks` (the GNSS velocity innovations against ``[gnss]
default_vel_std_mps``), :func:`consistency_checks` (the share of fixes the gate rejected, the
innovations' size), :func:`plausibility_checks` (the solution against the prior GNSS sigma and
the vehicle, :mod:`navpp.plausibility`) and :func:`aid_checks` (aids the gate rejected often)
return :class:`~navpp.findings.Finding` warnings for a doubtful run; a run that is wrong becomes a
:func:`refusal`: a :class:`~navpp.errors.RunRefused` of one line naming the likely cause, with
the other causes among its warnings.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config
from ..errors import RunRefused
from ..filters.base import GaussianState
from ..filters.linalg import finite_with_positive_variances
from ..findings import Finding, code_of
from ..recording import Recording, Solution
from .results import SmoothedRun


def state_fault(state: GaussianState) -> str | None:
    """What is wrong with a filter state (non-finite state or covariance, a covariance that is
    not positive definite on its diagonal), or None."""
    if finite_with_positive_variances(state.x, state.P):
        return None                     # the common case, in one compiled pass
    if not np.all(np.isfinite(state.x)):
        return "the state became non-finite (NaN or inf)"
    if not np.all(np.isfinite(state.P)):
        return "the covariance became non-finite (NaN or inf)"
    if not np.all(np.diagonal(state.P) > 0.0):
        return "the covariance lost positive definiteness (a variance <= 0)"
    return None


def causes_text(vehicle_mounting: bool = False, imu: bool = True) -> str:
    """The usual causes of a filter and GNSS that disagree, as one clause: the IMU's units and
    axes (with ``imu``), the vehicle mounting (with ``vehicle_mounting``), the lever arm, the time
    bases and the GNSS standard deviations."""
    parts = ["the IMU units and axes ([imu] mounting_rpy_deg)"] if imu else []
    if vehicle_mounting:
        parts.append('the vehicle mounting ([vehicle] mounting_rpy_deg = "auto" estimates it)')
    parts += ["the lever arm", "the time bases ([gnss] time_offset_s)"]
    return "check " + ", ".join(parts) + " and the GNSS standard deviations"


def causes(config: Config, imu: bool = True) -> str:
    """:func:`causes_text`, with the vehicle mounting when the non-holonomic constraint holds
    the IMU's lateral velocity to zero on a configured mounting (a degree of yaw is 0.3 m/s of
    side-slip at 60 km/h)."""
    v = config.vehicle
    return causes_text(v.type == "car" and v.nhc and not isinstance(v.mounting_rpy_deg, str), imu)


CHI2_3_MEDIAN = 2.365973884375338     # median of the chi-square distribution with 3 dof

#: What a warning the run gave says about the likely cause of a divergence, in the order tried:
#: (the warning's finding code, the short cause with its setting).
NOTICED_CAUSES = (
    ("gyro-scale", "the gyro's unit or axes ([imu] gyro_units, mounting_rpy_deg)"),
    ("gross-mounting", "the IMU's axes ([imu] mounting_rpy_deg)"),
    ("imu-tilted", "the IMU's axes ([imu] mounting_rpy_deg)"),
    ("clock-offset-applied", "the time bases ([gnss] time_offset_s)"),
    ("imu-saturated", "a saturated IMU"),
    ("gyro-rate-high", 'the gyro\'s unit ([imu] gyro_units = "deg/s"?)'),
    ("imu-gap", "the IMU's gaps"),
    ("gnss-velocity-sigma", "the GNSS velocity's 1-sigma ([gnss] default_vel_std_mps; see the warning)"),
)


def likely_cause(recording: Recording, config: Config, noticed: list[str],
                 measured: str | None = None) -> tuple[str, list[str]]:
    """The single most likely cause of a filter and GNSS that disagree, and the rest (for a
    warning line): first the fixes themselves (all identical, radians), then what the run
    noticed (the codes of its warnings), then ``measured`` (a cause the run's innovations show,
    e.g. :func:`gate_refusal_cause`), then the IMU's units and axes."""
    from ..plausibility import fix_suspect

    g = recording.gnss
    std = None if g.std_enu is None else np.asarray(g.std_enu, dtype=float) * config.gnss.std_scale
    suspect = fix_suspect(recording.source, g.lat_deg, g.lon_deg, g.alt, g.t, std, config.vehicle.type)
    if suspect is not None:
        return suspect, [causes(config)]
    codes = {code_of(w) for w in noticed}
    for code, cause in NOTICED_CAUSES:
        if code in codes:
            return f"check {cause}", [causes(config)]
    if measured is not None:
        return measured, [causes(config)]
    return "check the IMU's units and axes ([imu] mounting_rpy_deg)", [causes(config, imu=False)]


def refusal(recording: Recording, config: Config, headline: str, notes: list[str], warnings: list[str],
            cause: str | None = None, anyway: bool = True, measured: str | None = None) -> RunRefused:
    """A :class:`~navpp.errors.RunRefused` as one short line (source, what was seen, the likely
    cause) with the run's warnings, the other causes and the way to write the trajectory anyway
    as warnings after them (the CLI prints them first), and the run's notes.  ``cause``: the
    cause to name; else :func:`likely_cause` ranks the usual ones with ``measured``."""
    if cause is None:
        cause, others = likely_cause(recording, config, warnings, measured)
    else:
        others = [causes(config)]
    extra = Finding("refusal-causes", f"{recording.source}: other causes to check: {'; '.join(others)}"
                    + (" ([gnss] max_rejected_fraction = 1 writes the trajectory anyway)" if anyway else ""))
    exc = RunRefused(f"{recording.source}: {headline}; likely: {cause}")
    exc.warnings = (*warnings, extra)
    exc.notes = tuple(notes)
    return exc


def consistency_checks(source: str, name: str, config: Config, tg: np.ndarray, nis: np.ndarray,
                       accepted: np.ndarray) -> tuple[str | None, list[Finding]]:
    """After the run: is the filter diverged, is it doubtful?

    More than ``[gnss] max_rejected_fraction`` of the fixes failing the gate means the filter
    and the GNSS disagree for good (wrong units, axes, lever arm, time base or standard
    deviations): the returned headline (else None) is what the caller refuses the run with
    (:func:`refusal`).  Above 5 %, or with the median NIS far above the chi-square median
    (innovations larger than the filter predicts), a warning.
    """
    m = tg.shape[0]
    rejected = int(np.count_nonzero(~accepted))
    finite = nis[np.isfinite(nis)]
    scale = math.sqrt(float(np.median(finite)) / CHI2_3_MEDIAN) if finite.size else 1.0
    what = f"{rejected} of {m} GNSS fixes ({100.0 * rejected / max(m, 1):.0f}%) failed the innovation gate"
    if m >= 20 and rejected > config.gnss.max_rejected_fraction * m:
        first = float(tg[np.argmax(~accepted)])
        return f"{name} diverged: {what} (first at t = {first:.1f} s; innovations {scale:.1f}x predicted)", []
    warnings = []
    if rejected > 0.05 * m:
        warnings.append(Finding("gnss-rejected", f"{source}: {what}: the IMU and GNSS disagree; {causes(config)}"))
    elif m >= 20 and scale > 1.5:
        warnings.append(Finding("innovations-large",
                                f"{source}: the GNSS innovations are {scale:.1f} times larger than the filter "
                                "predicts: the GNSS standard deviations (or the IMU noise) are too optimistic"))
    return None, warnings


def std_label(recording: Recording, config: Config) -> str:
    """Where the fixes' prior 1-sigma came from, for a message (the log's columns or the setting,
    with ``[gnss] std_scale`` when it is not 1)."""
    from ..plausibility import std_name

    has_std = recording.gnss.std_enu is not None
    label = std_name(recording.source, has_std)
    if has_std and config.gnss.std_scale != 1.0:
        label += f" times [gnss] std_scale = {config.gnss.std_scale:g}"
    return label


def gate_refusal_cause(recording: Recording, config: Config, t: np.ndarray, nu: np.ndarray,
                       var0: np.ndarray) -> str | None:
    """A cause of a run the gate refused when the fixes' own scatter says their sigmas are far
    too small (:func:`navpp.plausibility.sigmas_too_small`: fixes t (M,) s, innovations nu (M, 3)
    m, prior R var0 (M, 3) m^2), with the setting that fixes it, for :func:`likely_cause` to rank
    after the fixes themselves and what the run noticed; None otherwise."""
    from ..plausibility import sigmas_too_small

    clause = sigmas_too_small(t, nu, var0, std_label(recording, config), config.gnss.gate_probability)
    if clause is None:
        return None
    return f"{clause} ([gnss] std_scale; aekf, sage-husa learn it)"


def plausibility_checks(recording: Recording, config: Config, name: str, solution: Solution,
                        smoothed: SmoothedRun | None, fixes, nu: np.ndarray, s_used: np.ndarray,
                        r_used: np.ndarray, accepted: np.ndarray, notes: list[str],
                        warnings: list[str]) -> list[Finding]:
    """Every filter's finished solution judged against the prior GNSS sigma and the vehicle
    (:mod:`navpp.plausibility`), before anything is written: a refusal (one short line) for a
    run that is wrong, warnings for a doubtful one.  ``fixes`` are the run's GNSS fixes
    (:class:`~navpp.engine.schedule.GnssFixes`: their ``var`` is the prior R, the log's sigmas
    already times ``[gnss] std_scale``); ``nu``, ``s_used``, ``r_used``, ``accepted`` what the
    filter saw and did at each."""
    from .. import plausibility as pl

    src = recording.source
    label = std_label(recording, config)
    found = pl.innovation_findings(name, label, fixes.t, nu, s_used, r_used, fixes.var, accepted,
                                   config.gnss.gate_probability, config.gnss.max_rejected_fraction)
    sols = [solution] + ([smoothed.solution] if smoothed is not None else [])
    for sol in sols:
        found += pl.solution_findings(name, config.vehicle.type, sol.t, sol.alt, sol.vel_enu, sol.std_enu, fixes.alt,
                                      np.sqrt(fixes.var[:, 2]), config.gnss.gate_probability,
                                      config.gnss.max_rejected_fraction < 1.0)
    out: list[Finding] = []
    for f in found:
        if f.fatal:
            raise refusal(recording, config, f.headline, notes, [*warnings, *out], f.cause)
        line = f"{src}: {f.headline}: {f.cause}" if f.cause else f"{src}: {f.headline}"
        out.append(Finding("solution-doubtful", line))
    return out


#: How far the GNSS velocity innovations may be from what ``[gnss] default_vel_std_mps`` predicts
#: (a factor on the 1-sigma, either way) before :func:`velocity_sigma_checks` warns.  A factor of
#: 3 is a 9x wrong weight on the velocity; within it, a receiver's Doppler velocity (typically
#: 0.03-0.3 m/s) is left alone, and so are the INS's own velocity error in S (the innovations of
#: a consistent run read somewhat below 1) and time-correlated velocity errors.  The statistic's
#: own scatter is far smaller: ~10 % at :data:`VEL_SIGMA_MIN_UPDATES` updates.
VEL_SIGMA_FACTOR = 3.0
#: Fewest GNSS velocity updates (accepted or rejected) :func:`velocity_sigma_checks` judges.
VEL_SIGMA_MIN_UPDATES = 30


def velocity_sigma_checks(source: str, config: Config, has_vel_std: bool,
                          vel_nis: np.ndarray | None) -> list[Finding]:
    """A warning when the log's GNSS velocity has no 1-sigma (``has_vel_std`` False), so ``[gnss]
    default_vel_std_mps`` was used, and the velocity innovations show it far off.

    ``vel_nis`` (M,) is the NIS of every velocity update tried (NaN: none at that fix), accepted
    or rejected: the gate truncates the accepted ones at its quantile (21.1 at p = 0.9999, a
    factor sqrt(21.1 / 2.37) = 3.0 at most), so they alone cannot show a sigma 3x too small.
    ``scale = sqrt(median NIS / median of chi-square 3)`` is the innovations' size over the
    predicted ``sqrt(S)``; the median ignores outliers.  S is the velocity's R plus the INS's own
    velocity uncertainty, which GNSS velocity keeps small, so ``default_vel_std_mps * scale`` is
    the 1-sigma the innovations suggest (200-s simulated drives, 5 seeds: within 15 % of the truth
    from 0.03 to 1 m/s; 3 m/s reads 1.8-2.0, every update rejected and S holding the INS's own
    velocity uncertainty; 0.01 m/s reads 0.015, the INS's own error dominating).  Warns when ``scale``
    is beyond :data:`VEL_SIGMA_FACTOR` either way over at least :data:`VEL_SIGMA_MIN_UPDATES`
    updates.
    """
    if has_vel_std or vel_nis is None:
        return []
    nis = np.asarray(vel_nis, dtype=float)
    nis = nis[np.isfinite(nis)]
    if nis.size < VEL_SIGMA_MIN_UPDATES:
        return []
    scale = math.sqrt(float(np.median(nis)) / CHI2_3_MEDIAN)
    if 1.0 / VEL_SIGMA_FACTOR <= scale <= VEL_SIGMA_FACTOR:
        return []
    default = config.gnss.default_vel_std_mps
    return [Finding("gnss-velocity-sigma",
                    f"{source}: the GNSS velocity has no 1-sigma, and its innovations are {scale:.2g} times what "
                    f"[gnss] default_vel_std_mps = {default:g} m/s predicts (median NIS of {nis.size} velocity "
                    f"updates): they suggest default_vel_std_mps = {default * scale:.2g}")]


#: Share of an aid's updates the gate may reject before the run says the aid disagrees with the data.
AID_REJECTED_WARN = 0.05
#: What to check when an aid's updates fail the gate often, per aid kind.
AID_HINTS = {
    "nhc": "the vehicle's motion is not along its x axis: check [vehicle] mounting_rpy_deg (or set it to \"auto\") "
           "and nhc_point_m, or raise nhc_std_mps (side slip)",
    "zupt": "standstill was detected while the vehicle moved: raise [vehicle] still_accel_std_mps2 / "
            "still_gyro_std_dps or turn zupt off",
    "zaru": "standstill was detected while the vehicle turned: raise [vehicle] still_gyro_std_dps or turn zaru off",
    "gnss_velocity": "the GNSS velocity disagrees with the IMU: check the lever arm, [gnss] time_offset_s and the "
                     "velocity's standard deviations (default_vel_std_mps), or set use_velocity = false",
}


def aid_checks(source: str, updates: dict[str, dict[str, int]]) -> list[Finding]:
    """A warning per aid the innovation gate rejected often (more than
    :data:`AID_REJECTED_WARN` of its updates): the aid and the data disagree."""
    out = []
    for kind, hint in AID_HINTS.items():
        c = updates.get(kind)
        if not c:
            continue
        n = c["applied"] + c["rejected"]
        if n >= 20 and c["rejected"] > AID_REJECTED_WARN * n:
            out.append(Finding("aid-rejected", f"{source}: {c['rejected']} of {n} {kind} updates "
                               f"({100.0 * c['rejected'] / n:.0f}%) failed the innovation gate: {hint}"))
    return out
