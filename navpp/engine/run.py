"""One run of one filter over one recording: the steps from the data to the result.

:func:`run` cuts the log at IMU gaps the INS cannot bridge (:mod:`navpp.engine.segments`) and
runs each piece with :func:`run_one`: check and fix the data (:mod:`navpp.engine.checks`,
:mod:`navpp.engine.prepare`), build the INS model and align, estimate the vehicle mounting
(:mod:`navpp.engine.mounting`), schedule the epochs (:mod:`navpp.engine.schedule`), run the
loop (:mod:`navpp.engine.loop`) with the run's measurements and recorder, then smooth, convert
and judge the result (:mod:`navpp.engine.output`, :mod:`navpp.engine.verdict`).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..aiding import Aiding
from ..config import Config
from ..errors import FilterDivergedError, InputError, NavppError, RunRefused
from ..filters.base import Filter, GaussianState
from ..findings import Finding
from ..gnss_jumps import check_gnss_jumps
from ..ins.aids.odometer import scale_block
from ..ins.alignment import START_SHARE, Alignment, align
from ..ins.augmented import AugmentedInsModel, StateBlock
from ..ins.gnss_error import Correlation, GnssErrorModel, GnssErrorSettings, innovation_correlation
from ..ins.model import InsModel
from ..ins.strapdown import NOMINAL_BG
from ..kernel import CompileEvents
from ..recording import ImuData, Recording
from ..spill import map_large_blocks, release_all, spilled, trim_heap
from .checks import alignment_findings, check_data, check_imu_plausible
from .fused import fused_runner
from .gnss_error import (
    LikelihoodRecorder,
    correlation_finding,
    correlation_note,
    gate_cap,
    gnss_error_choice,
    innovation_score,
    kept_white_finding,
    residual_finding,
)
from .loop import run_epochs
from .measurements import RunMeasurements, recovery_reopening
from .mounting import first_pass_filter, vehicle_mounting
from .output import body_rate, compile_seconds, interpolated_std_rows, smoothed_run, solution_from_path
from .prepare import (
    alignment_settings,
    averaged_start,
    calibrated,
    mounting_matrix,
    noise_model,
    rotated_rows,
    start_covariance,
    start_fixes,
    timing_fixes,
)
from .recorder import KNOT, OUTPUT_ROW_BYTES, RunRecorder, new_path
from .results import RunResult, SmoothedRun
from .schedule import GnssFixes, epochs, gnss_fixes, with_prior_std
from .segments import ProgressFn, imu_segments, run_segments
from .verdict import (
    aid_checks,
    consistency_checks,
    gate_refusal_cause,
    plausibility_checks,
    refusal,
    state_fault,
    velocity_sigma_checks,
)


def run(recording: Recording, config: Config, filt: Filter, *, progress: ProgressFn | None = None,
        cov_step_s: float = 0.05, smooth: bool = False) -> RunResult:
    """Process one recording with one filter; returns the IMU-rate solution and diagnostics.

    With ``smooth``, the forward run is also smoothed backwards (Rauch-Tung-Striebel over the
    stored forward run): ``RunResult.smoothed``; ``solution`` stays the forward solution.
    ``runtime_s`` excludes the one-off compilation of navpp's kernels on a cold cache, which
    is reported as ``compile_s``.
    """
    t_wall = time.perf_counter()
    config, vehicle_note = resolved_vehicle(recording, config)
    if spilled(recording.imu.t) or len(recording.imu) * OUTPUT_ROW_BYTES > config.output.memory:
        map_large_blocks()      # a long run: its large temporaries' memory back to the system when freed
        trim_heap()             # and the reader's, freed on the heap before
    with CompileEvents() as rec:
        segments = imu_segments(recording)
        if len(segments) > 1:
            result = run_segments(recording, segments, config, filt, progress, cov_step_s, smooth, run_one)
        else:
            result = run_one(recording, config, filt, progress, cov_step_s, smooth)
    compile_s = compile_seconds(rec.buffer)
    trim_heap()         # the run's transients out of memory before the caller's writers
    if vehicle_note is not None:
        result = replace(result, notes=(vehicle_note, *result.notes))
    return replace(result, runtime_s=time.perf_counter() - t_wall - compile_s, compile_s=compile_s)


def resolved_vehicle(recording: Recording, config: Config) -> tuple[Config, str | None]:
    """``config`` with ``[vehicle] type = "auto"`` made ``"car"`` when the run uses wheel odometry
    (``[odometry] use`` and a log with odometry: only a wheeled vehicle has it), else ``"none"``;
    and the note saying so (None when nothing was decided here)."""
    if config.vehicle.type != "auto":
        return config, None
    od = recording.odometry
    wheeled = od is not None and len(od) >= 2 and config.odometry.use
    resolved = replace(config, vehicle=replace(config.vehicle, type="car" if wheeled else "none"))
    if not wheeled:
        return resolved, None
    nhc = "the non-holonomic constraint applies" if config.vehicle.nhc else "[vehicle] nhc = false keeps the NHC off"
    return resolved, (f"vehicle: a wheeled vehicle, for the log has wheel odometry ({od.source}): {nhc} "
                      '([vehicle] type = "none" says otherwise)')


@dataclass
class Journal:
    """What a run has noted (decisions, measurements) and warned about so far."""

    notes: list[str]
    warnings: list[str]


@dataclass(frozen=True)
class Prepared:
    """A recording ready for the loop: the recording as processed (timing fixed), the INS model
    over it (its path is the recorder's), the path, the calibration (or None) and its figures
    for metrics.json, the alignment and the GNSS fixes after it."""

    recording: Recording
    model: InsModel
    path: np.ndarray
    cal: Any
    calibration: dict
    alignment: Alignment
    fixes: GnssFixes


def run_one(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
            cov_step_s: float, smooth: bool = False) -> RunResult:
    """One run over a recording without unbridgeable gaps; a failure carries what the run had
    noted and warned about so far (:meth:`navpp.errors.NavppError.with_context`), so the user
    sees the likely cause first.

    ``[gnss] error_model = "auto"``: the run takes the fixes' errors as white; when its
    innovations are correlated over several seconds (:func:`~navpp.ins.gnss_error.innovation_correlation`)
    it is run again, from the start and with a fresh copy of the filter, with the Gauss-Markov
    GNSS error states, and the notes say so.  ``"white"``: the same measurement gives a warning
    naming the setting."""
    mode = config.gnss.error_model
    spare = copy.deepcopy(filt) if mode == "auto" else None
    first_config = replace(config, gnss=replace(config.gnss, error_model="white")) if mode == "auto" else config
    result = _run_logged(recording, first_config, filt, progress, cov_step_s, smooth)
    d = result.diagnostics
    corr = innovation_correlation(d.t, d.nu, d.accepted)
    result = _with_correlation(result, corr)
    if mode == "gauss-markov":
        if corr.correlated:
            tau = result.calibration.get("gnss_error", {}).get("corr_time_s", float("nan"))
            result = replace(result, warnings=(*result.warnings, residual_finding(recording.source, corr, tau)))
        return result
    if not corr.correlated:
        return result
    if spare is None or filt.random_mean:
        return replace(result, warnings=(*result.warnings, correlation_finding(
            recording.source, corr, learnt_r_ratio(d.r_std, recording, config) if filt.adapts_noise else None,
            filt.name if filt.random_mean else None)))
    gm_config = replace(config, gnss=replace(config.gnss, error_model="gauss-markov"))
    again = _run_logged(recording, gm_config, spare, progress, cov_step_s, smooth)
    d2 = again.diagnostics
    after = innovation_correlation(d2.t, d2.nu, d2.accepted)
    again = replace(_with_correlation(again, after), notes=(correlation_note(corr), *again.notes))
    again.calibration["gnss_error"]["detected_by"] = {"lag_s": corr.lag_s, "rho": round(corr.rho, 4),
                                                      "pairs": corr.pairs}
    white_score, gm_score = result.calibration["gnss_innovation_score"], again.calibration["gnss_innovation_score"]
    if not gm_score < white_score:
        # the filter explains the fixes no better with the model (its own adaptation fights it)
        return replace(result, warnings=(*result.warnings, kept_white_finding(recording.source, corr, filt.name,
                                                                                 white_score, gm_score)))
    if after.correlated:
        tau = again.calibration["gnss_error"]["corr_time_s"]
        again = replace(again, warnings=(*again.warnings, residual_finding(recording.source, after, tau)))
    return again


def _with_correlation(result: RunResult, corr: Correlation) -> RunResult:
    """``result`` with the innovations' lag correlation in its calibration figures (metrics.json)."""
    return replace(result, calibration={**result.calibration, "gnss_innovation_correlation": {
        "lag_s": corr.lag_s, "rho": round(corr.rho, 4), "pairs": corr.pairs, "threshold": round(corr.threshold, 4)}})


def learnt_r_ratio(r_std: np.ndarray, recording: Recording, config: Config) -> float | None:
    """The median 1-sigma an adaptive filter used for the fixes over the median the log (or
    ``[gnss] default_std_m``) gives, horizontal axes; None when it cannot be told."""
    gnss = recording.gnss
    prior = (np.asarray(gnss.std_enu, dtype=float)[:, :2] if gnss.std_enu is not None
             else np.asarray(config.gnss.default_std_m, dtype=float)[None, :2])
    used = np.asarray(r_std, dtype=float)[:, :2]
    if not (np.any(np.isfinite(used)) and np.any(np.isfinite(prior))):
        return None
    return float(np.nanmedian(used) / (np.nanmedian(prior) * config.gnss.std_scale))


def _run_logged(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
                cov_step_s: float, smooth: bool) -> RunResult:
    log = Journal([], [])
    try:
        return processed(recording, config, filt, progress, cov_step_s, smooth, log)
    except NavppError as exc:
        exc.with_context(log.notes, log.warnings)
        raise


def prepared(recording: Recording, config: Config, cov_step_s: float, log: Journal) -> Prepared:
    """Check the data, fix its timing, rotate and calibrate the IMU, build the model, align.
    After each pass over the IMU its spilled pages are released (:func:`released_imu`)."""
    check_gnss_jumps(recording, config.vehicle.type, config.gnss.default_std_m, config.gnss.reanchor_after_s,
                     config.gnss.std_scale)
    log.warnings += check_imu_plausible(recording)
    released_imu(recording.imu)
    calibration: dict = {}
    recording, t_notes, t_warnings = timing_fixes(recording, config, calibration)
    released_imu(recording.imu)
    log.notes += t_notes
    log.warnings += t_warnings
    log.warnings += check_data(recording, config)
    released_imu(recording.imu)
    imu, gnss = recording.imu, recording.gnss
    gyro, accel = imu.gyro, imu.accel
    if any(a != 0.0 for a in config.imu.mounting_rpy_deg):
        m = mounting_matrix(config.imu.mounting_rpy_deg)
        gyro, accel = rotated_rows(gyro, m), rotated_rows(accel, m)     # spilled as read, window by window
    gyro, accel, noise, cal, cal_notes, cal_warnings = calibrated(recording, config, gyro, accel, calibration)
    log.notes += cal_notes
    log.warnings += cal_warnings
    released_imu(imu, gyro, accel)
    profile = cal.profile if (cal is not None and config.auto.noise) else None
    path = new_path(imu.t.shape[0], config.output.memory)
    model = InsModel(imu.t, gyro, accel, noise_model(config, noise), cov_step_s=cov_step_s, path=path,
                     profile=profile)
    released_imu(imu)
    try:
        al = align(model.t, model.gyro, model.accel, with_prior_std(gnss, config),
                   alignment_settings(config, noise, cal))
    except InputError as exc:  # alignment knows the data, not where it came from
        from ..plausibility import fix_suspect

        suspect = fix_suspect(recording.source, gnss.lat_deg, gnss.lon_deg, gnss.alt)
        if suspect is not None:     # the fixes themselves first: the alignment only saw their symptom
            both = f"{recording.source}: {suspect}; {exc}"
            raise InputError(both if len(both) < 285 else f"{recording.source}: {suspect}") from None
        raise InputError(f"{recording.source}: {exc}") from None
    log.notes[:0] = list(al.lines)          # for an error's context; the result carries them apart
    released_imu(imu, model.gyro, model.accel)
    return Prepared(recording, model, path, cal, calibration, al, gnss_fixes(recording, config, al.t))


def released_imu(imu: ImuData, *arrays: np.ndarray) -> None:
    """The pages of the IMU's spilled arrays (``imu``'s and the calibrated ``arrays``) out of
    memory after a pass over them (:func:`navpp.spill.release_all`): a pass that reads the
    whole log touches every page, and they would otherwise stay resident until the run ends."""
    release_all(imu.t, imu.gyro, imu.accel, *arrays)


def processed(recording: Recording, config: Config, filt: Filter, progress: ProgressFn | None,
              cov_step_s: float, smooth: bool, log: Journal) -> RunResult:
    """The steps of :func:`run_one`; ``log`` collects the notes and warnings as they come."""
    t_wall = time.perf_counter()
    prep = prepared(recording, config, cov_step_s, log)
    trim_heap()         # the prepare stage's IMU-length transients
    recording, model, al, fixes = prep.recording, prep.model, prep.alignment, prep.fixes
    n_al = len(al.lines)
    log.notes += fixes.notes
    mounting, m_notes, m_warnings = vehicle_mounting(recording, config, cov_step_s, run_one)
    released_imu(recording.imu, model.gyro, model.accel)
    log.notes += m_notes
    log.warnings += m_warnings
    cal = prep.cal

    def new_aiding(sel: np.ndarray = fixes.index) -> Aiding:
        return Aiding(config, model.t, model.gyro, model.accel, model.noise.gyro_arw, model.noise.accel_vrw,
                      recording.gnss, sel, model.gaps, mounting,
                      still=cal.still if (cal is not None and config.auto.standstill) else None,
                      profile=model.profile, odometry=recording.odometry)

    aiding = new_aiding()
    imu_t = recording.imu.t
    schedule = epochs(al.t, float(imu_t[-1]), *aiding.schedule(al.t, float(imu_t[-1]), fixes.t), imu_t)
    n_epochs = int(np.count_nonzero(~schedule.coast)) if progress is not None else 1
    reopen = recovery_reopening(config, al.P)
    lever = np.asarray(config.gnss.lever_arm_m, dtype=float)
    more = (scale_block(config.odometry.scale_sigma, config.odometry.scale_walk_per_sqrt_h),) \
        if aiding.odo is not None else ()
    score = estimation_scorer(config, model, recording, al, fixes, new_aiding, reopen, lever, more)
    choice = gnss_error_choice(config, fixes, score)
    released_imu(recording.imu, model.gyro, model.accel)
    fmodel: InsModel | AugmentedInsModel = model
    fixes = start_fixes(fixes, al)      # a still start shares its averaged fixes with the filter
    start = GaussianState(al.t, al.x, start_covariance(al))
    if choice is not None:
        fmodel = GnssErrorModel(model, choice.settings, more)
        log.notes.append(choice.note())
        prep.calibration["gnss_error"] = choice.report()
    elif more:
        fmodel = AugmentedInsModel(model, more)
    if isinstance(fmodel, GnssErrorModel):
        start = GaussianState(al.t, *fmodel.start(al.x, al.P, averaged_start(al), START_SHARE))
    elif isinstance(fmodel, AugmentedInsModel):
        start = GaussianState(al.t, *fmodel.start(al.x, start.P))
    recorder = RunRecorder(fixes, prep.path, start, al.index, filt.noise_report, velocity=aiding.has_velocity,
                           smooth=smooth, store_bytes=config.output.memory, progress=progress, n_epochs=n_epochs,
                           extra_states=fmodel.state_labels() if isinstance(fmodel, AugmentedInsModel) else None,
                           aids=aiding.recorded_kinds)
    source = RunMeasurements(fixes, recording.gnss, lever, reopen, aiding, model=fmodel,
                             r_share=1.0 if choice is None else 1.0 - choice.share)
    check = DivergenceCheck(recording, config, filt.name, al.t, log, source)
    fast = fused_runner(filt, fmodel, source, recorder, schedule)
    released_imu(recording.imu, model.gyro, model.accel)    # its still epochs' ZARU read the whole gyro
    try:
        state = run_epochs(filt, fmodel, start, schedule, source, recorder, check, fast)
        del fast, schedule
        check(state, state.t)
    except RunRefused:
        raise
    except FilterDivergedError as exc:
        raise check.diverged(recorder.t, exc.why or str(exc)) from None
    released_imu(recording.imu, model.gyro, model.accel)
    trim_heap()
    if progress is not None:
        progress(1.0)
    result = finished(recording, config, filt, prep, recorder, source, smooth, log, fmodel)
    return replace(result, runtime_s=time.perf_counter() - t_wall, notes=tuple(log.notes[n_al:]))


#: The GNSS error model's estimation passes use one fix per this many seconds at most: the
#: errors they weigh last tens of seconds, and a pass over 1 Hz fixes costs a fraction of one over
#: 5-10 Hz (measured in docs/ins.md).
ESTIMATION_FIX_INTERVAL_S = 1.0


def estimation_scorer(config: Config, model: InsModel, recording: Recording, al: Alignment, fixes: GnssFixes,
                      new_aiding: Any, reopen: np.ndarray | None, lever: np.ndarray,
                      more: tuple[StateBlock, ...] = ()) -> Any:
    """The score of a Gauss-Markov candidate (:mod:`navpp.engine.gnss_error`): ``-2 log L`` of
    the fixes' innovations in one pass of the plain EKF over the run's epochs, with the fixes thinned
    to one per :data:`ESTIMATION_FIX_INTERVAL_S` (``new_aiding(sel)``: the run's aids over the fixes
    ``sel``)."""
    dt = float(np.median(np.diff(fixes.t))) if len(fixes) > 1 else ESTIMATION_FIX_INTERVAL_S
    k = max(1, int(round(ESTIMATION_FIX_INTERVAL_S / dt))) if dt > 0.0 else 1
    sub = GnssFixes(fixes.index[::k], fixes.t[::k], fixes.lat[::k], fixes.lon[::k], fixes.alt[::k], fixes.var[::k])
    t_end = float(recording.imu.t[-1])
    schedule = epochs(al.t, t_end, *new_aiding(sub.index).schedule(al.t, t_end, sub.t), recording.imu.t)

    def score(settings: GnssErrorSettings, share: float) -> float:
        fm = GnssErrorModel(model, settings, more)
        scorer = LikelihoodRecorder(gate_cap(config.gnss.gate_probability))
        src = RunMeasurements(sub, recording.gnss, lever, reopen, new_aiding(sub.index), model=fm,
                              r_share=1.0 - share)
        try:
            run_epochs(first_pass_filter(config), fm, GaussianState(al.t, *fm.start(al.x, al.P, averaged_start(al))),
                       schedule, src,
                       scorer)
        except FilterDivergedError:
            return math.inf
        return scorer.total
    return score


class DivergenceCheck:
    """The loop's :class:`~navpp.engine.loop.StateCheck`: a state that is not finite or whose
    covariance lost positive definiteness stops the run with a refusal naming the time, the fault
    and the last good epoch (``source.last_good``, else the alignment's time ``t_align``, s)."""

    def __init__(self, recording: Recording, config: Config, filter_name: str, t_align: float, log: Journal,
                 source: RunMeasurements) -> None:
        self.recording, self.config, self.filter_name = recording, config, filter_name
        self.t_align, self.log, self.source = t_align, log, source

    def __call__(self, state: GaussianState, t: float) -> None:
        fault = state_fault(state)
        if fault is not None:
            raise self.diverged(t, fault)

    def diverged(self, t: float, why: str) -> RunRefused:
        """The refusal of a filter that diverged at ``t`` (s) for the reason ``why``."""
        last_good = self.source.last_good
        good = (f"the last good epoch (accepted GNSS update) was t = {last_good:.3f} s" if last_good is not None
                else f"no GNSS update had been accepted yet (alignment at t = {self.t_align:.3f} s)")
        return refusal(self.recording, self.config, f"{self.filter_name} diverged at t = {t:.3f} s: {why}; {good}",
                       self.log.notes, self.log.warnings, anyway=False)


def finished(recording: Recording, config: Config, filt: Filter, prep: Prepared, recorder: RunRecorder,
             source: RunMeasurements, smooth: bool, log: Journal, fmodel: Any = None) -> RunResult:
    """The result of a finished forward run: smoothed (with ``smooth``) on the filter's model
    ``fmodel`` (default the INS), converted to the output's units, and judged
    (:mod:`navpp.engine.verdict`); a refusal for a run that is wrong."""
    al, fixes = prep.alignment, prep.fixes
    path = recorder.path[al.index:]
    t_out = recording.imu.t[al.index:]
    gyro = np.asarray(prep.model.gyro)[al.index:]
    smoothed = None
    if smooth:
        smoothed = smoothed_output(recorder, prep.model if fmodel is None else fmodel, t_out, path, fixes.t,
                                   recording.t0_ns, gyro)
    std_out = output_std(recorder, t_out, path)
    rate = body_rate(t_out, path, gyro, fixes.t, recorder.bias[:, :3], al.x[NOMINAL_BG])
    released_imu(recording.imu, prep.model.gyro, prep.model.accel)
    trim_heap()         # the output step's transients, before the checks' own
    solution = solution_from_path(t_out, path, std_out["pos"], recording.t0_ns, std_att=std_out["att"],
                                  std_vel_enu=std_out["vel"], rate_body=rate)
    diag = recorder.diagnostics(fixes.t, filt.noise_report_labels())
    log.warnings += alignment_findings(al.warnings)
    aiding = source.aiding
    log.warnings += recovery_warnings(recording.source, source.recoveries)
    log.notes += veto_notes(aiding.vetoes)
    log.warnings += velocity_sigma_checks(recording.source, config, recording.gnss.std_vel_enu is not None,
                                          diag.vel_nis)
    headline, c_warnings = consistency_checks(recording.source, filt.name, config, fixes.t, recorder.nis,
                                              recorder.accepted)
    if headline is not None:
        raise refusal(recording, config, headline, log.notes, log.warnings,
                      measured=gate_refusal_cause(recording, config, fixes.t, recorder.nu, fixes.var))
    log.warnings += c_warnings
    log.warnings += plausibility_checks(recording, config, filt.name, solution, smoothed, fixes, recorder.nu,
                                        recorder.s_used, recorder.r_used, recorder.accepted, log.notes,
                                        log.warnings)
    log.warnings += aid_checks(recording.source, aiding.counts.as_dict())
    if smoothed is not None and smoothed.breaks:
        n = smoothed.breaks
        log.warnings.append(Finding(
            "smoothing-breaks",
            f"{recording.source}: smoothing: {n} step{'s' if n > 1 else ''} the smoother carries no information "
            "back across (a fix forced through the gate with the covariance re-anchored, or a prior covariance "
            "that was not positive definite): the smoothed trajectory keeps the forward filter's jump there"))
    return RunResult(solution, recorder.bias_history(fixes.t), al, diag, len(fixes), int((~recorder.accepted).sum()),
                     0.0, 0.0, tuple(log.warnings), smoothed, (), aiding.counts.as_dict(),
                     {**prep.calibration, "recoveries_s": [round(v, 3) for v in source.recoveries],
                      "standstill_ended_early_s": [round(v, 3) for v in aiding.vetoes],
                      "gnss_innovation_score": round(innovation_score(recorder.nis, recorder.s_used,
                                                                      config.gnss.gate_probability), 2)})


def output_std(recorder: RunRecorder, t_out: np.ndarray, path: np.ndarray) -> dict[str, np.ndarray]:
    """The output's 1-sigma at ``t_out`` (s): ``"att"`` (rad, about the ENU axes), ``"vel"``
    (ENU m/s), ``"pos"`` (ENU m), (N, 3) float32 each, spilled like ``path``
    (:func:`~navpp.engine.output.interpolated_std_rows` between the recorder's knots).  Each
    block's columns are copied from the recorded knots in turn, and the knots are dropped after:
    nothing later reads them."""
    kt = recorder.knot_values(slice(0, 1))[:, 0]
    t0, kt = float(kt[0]), kt[1:]
    std_out = {}
    for name, j in (("att", 0), ("vel", 3), ("pos", 6)):     # the KNOT layout of the recorder
        prior, post = 1 + j, 1 + KNOT.stop - KNOT.start + j
        kp, kq = recorder.knot_values(slice(prior, prior + 3)), recorder.knot_values(slice(post, post + 3))
        std_out[name] = interpolated_std_rows(t_out, t0, kq[0], kt, kp[1:], kq[1:], like=path)
        del kp, kq
    recorder.drop_knots()
    return std_out


def smoothed_output(recorder: RunRecorder, model: Any, t_out: np.ndarray, path: np.ndarray,
                    tg: np.ndarray, t0_ns: int, gyro: np.ndarray | None = None) -> SmoothedRun:
    """The recorder's forward run smoothed (:func:`~navpp.engine.output.smoothed_run`), its
    runtime without the compilation of kernels on a cold cache; the recorder's store is emptied."""
    assert recorder.store is not None
    with CompileEvents() as compiling:
        smoothed = smoothed_run(recorder.store, model, t_out, path, recorder.epoch_node, tg, t0_ns, gyro)
    recorder.store = None
    return replace(smoothed, runtime_s=smoothed.runtime_s - compile_seconds(compiling.buffer))


def recovery_warnings(source: str, recoveries: list[float]) -> list[Finding]:
    """A warning when the INS had drifted from the GNSS and was re-aligned at ``recoveries`` (s)."""
    if not recoveries:
        return []
    n = len(recoveries)
    return [Finding("ins-recovered",
                    f"{source}: the INS had drifted from the GNSS (a run of rejected fixes) {n} "
                    f"time{'s' if n > 1 else ''}, at t = " + ", ".join(f"{v:.1f}" for v in recoveries[:10])
                    + (" ..." if n > 10 else "") + " s: velocity re-aligned on the GNSS, attitude and gyro-bias "
                    "uncertainty re-opened ([auto] recovery = false re-opens the position only)")]


def veto_notes(vetoes: list[float]) -> list[str]:
    """A note when ZUPT's consistency check ended standstills early, at ``vetoes`` (s)."""
    if not vetoes:
        return []
    n = len(vetoes)
    return [f"standstill ended early {n} time{'s' if n > 1 else ''}, at t = "
            + ", ".join(f"{x:.1f}" for x in vetoes[:10]) + (" ..." if n > 10 else "")
            + " s: ZUPT's velocity corrections kept one direction (a gentle start the IMU's spreads did not "
            "show), so no more ZUPT or ZARU until the next stop"]
