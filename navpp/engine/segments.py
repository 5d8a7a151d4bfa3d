"""A log cut at IMU gaps the INS cannot bridge, processed segment by segment and joined.

:func:`imu_segments` finds the cuts; :func:`run_segments` runs each segment as a log of its
own (aligned afresh from its own data, no row written inside a gap) and joins the results in
time order.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import fields, replace
from typing import Any

import numpy as np

from ..config import Config
from ..errors import FilterDivergedError, InputError
from ..filters.base import Filter
from ..findings import Finding
from ..recording import Recording, Solution
from .results import BiasHistory, Diagnostics, RunResult, SmoothedRun

ProgressFn = Callable[[float], None]   # called with the fraction done, 0..1
#: Runs one segment: (recording, config, filter, progress, cov_step_s, smooth) -> RunResult.
SegmentRunner = Callable[[Recording, Config, Filter, "ProgressFn | None", float, bool], RunResult]


def imu_segments(recording: Recording) -> list[tuple[int, int]]:
    """The IMU rows cut at every gap longer than the INS can bridge
    (:func:`navpp.ins.model.max_bridgeable_gap_s`, 10.5 s: the motion unseen over it leaves the
    attitude unknown, and integrating across it would write a free-inertial stretch, an hour's
    gap thousands of km off).  Returns ``[(i0, i1), ...]``, half-open row ranges in time order;
    one range covering every row when there is no such gap.

    Each range is processed as a log of its own (:func:`run_segments`): aligned afresh from its
    own data, no row written inside a gap.  Inside a range the IMU's time span is bounded by its
    sample count (at most one bridgeable gap per sample), so no loop over time can run away.
    """
    from ..ins.model import max_bridgeable_gap_s
    from ..intervals import long_intervals

    t = recording.imu.t
    n = int(t.shape[0])
    if n < 2:
        return [(0, n)]
    cuts = long_intervals(t, max_bridgeable_gap_s()) + 1          # a spilled t window by window
    edges = [0, *cuts.tolist(), n]
    return [(edges[k], edges[k + 1]) for k in range(len(edges) - 1)]


def rows(obj: Any, keep: np.ndarray | slice) -> Any:
    """A copy of the dataclass ``obj`` with the rows ``keep`` (bool mask or indices) of every array
    field whose first dimension is the length of ``obj.t`` (None fields stay None)."""
    n = obj.t.shape[0]
    out = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
            out[f.name] = v[keep]
    return replace(obj, **out)


def segment(recording: Recording, i0: int, i1: int) -> Recording:
    """The recording restricted to IMU rows ``[i0, i1)`` and the fixes, odometry rows and reference
    epochs inside their time span ``t[i0] <= t <= t[i1 - 1]`` s (same time base, same ``t0_ns``)."""
    t = recording.imu.t
    a, b = float(t[i0]), float(t[i1 - 1])
    imu = rows(recording.imu, slice(i0, i1))
    gnss = rows(recording.gnss, (recording.gnss.t >= a) & (recording.gnss.t <= b))
    ref, odo = recording.reference, recording.odometry
    if ref is not None:
        ref = rows(ref, (ref.t >= a) & (ref.t <= b))
    if odo is not None:
        odo = rows(odo, (odo.t >= a) & (odo.t <= b))
    return replace(recording, imu=imu, gnss=gnss, reference=ref, odometry=odo)


def concat(parts: list, cls: type) -> Any:
    """One ``cls`` dataclass from ``parts`` of it, row-wise: array fields concatenated (a field
    None in some parts and not in others is filled with NaN rows there), dict-of-array fields
    concatenated per key, other fields taken from the first part."""
    out: dict[str, Any] = {}
    for f in fields(cls):
        vals = [getattr(p, f.name) for p in parts]
        ref = next((v for v in vals if v is not None), None)
        if isinstance(ref, np.ndarray):
            n_rows = [p.t.shape[0] for p in parts]
            out[f.name] = np.concatenate([v if v is not None else np.full((r, *ref.shape[1:]), np.nan)
                                          for v, r in zip(vals, n_rows)])
        elif isinstance(ref, dict) and all(isinstance(v, dict) for v in vals) and \
                all(isinstance(x, np.ndarray) for v in vals for x in v.values()):
            keys = [k for k in ref if all(k in v for v in vals)]
            out[f.name] = {k: np.concatenate([v[k] for v in vals]) for k in keys}
        else:
            out[f.name] = ref
    return cls(**out)


def run_segments(recording: Recording, segments: list[tuple[int, int]], config: Config, filt: Filter,
                 progress: ProgressFn | None, cov_step_s: float, smooth: bool, run_one: SegmentRunner) -> RunResult:
    """Process each IMU segment (:func:`imu_segments`) with ``run_one`` as a log of its own and
    join the results in time order: the trajectory has no row inside a gap, the metrics skip the
    gaps (:func:`navpp.metrics.associate`).  A segment that cannot be processed on its own (too
    short to align, no fix in it) is left out with a warning naming its span; a divergence stops
    the run.  Every segment starts from a fresh copy of ``filt``."""
    from ..ins.model import max_bridgeable_gap_s

    t = recording.imu.t
    n = float(t.shape[0])
    gaps = [(float(t[i0 - 1]), float(t[i0] - t[i0 - 1])) for i0, _ in segments[1:]]
    shown = ", ".join(f"{g:.4g} s after t = {a:.3f} s" for a, g in gaps[:3]) + (
        f" and {len(gaps) - 3} more" if len(gaps) > 3 else "")
    head = Finding("imu-segments",
                   f"{recording.source}: IMU gap{'s' if len(gaps) > 1 else ''} of {shown}: longer than the INS can "
                   f"bridge ({max_bridgeable_gap_s():.3g} s, the unseen motion leaves the attitude unknown): the log "
                   f"is processed as {len(segments)} segments, each aligned afresh; no trajectory inside the gaps")
    results: list[RunResult] = []
    spans: list[tuple[float, float]] = []
    skipped: list[Finding] = []
    first_error: Exception | None = None
    done = 0
    for i0, i1 in segments:
        a, b = float(t[i0]), float(t[i1 - 1])
        sub = segment(recording, i0, i1)
        share = (i1 - i0) / n
        prog = None if progress is None else (lambda f, d=done, s=share: progress(min(1.0, (d + f * s * n) / n)))
        try:
            results.append(run_one(sub, config, copy.deepcopy(filt), prog, cov_step_s, smooth))
            spans.append((a, b))
        except FilterDivergedError:
            raise
        except InputError as exc:
            first_error = first_error or exc
            why = str(exc).splitlines()[0]
            why = why.split(": ", 1)[1] if why.startswith(f"{recording.source}: ") else why
            skipped.append(Finding("imu-segment-left-out", f"{recording.source}: IMU segment t = {a:.3f} .. "
                                   f"{b:.3f} s ({b - a:.1f} s) left out: {why[:160]}"))
        done += i1 - i0
    if not results:
        assert first_error is not None
        raise first_error
    return joined(results, spans, [head, *skipped])


def joined(results: list[RunResult], spans: list[tuple[float, float]], head: list[Finding]) -> RunResult:
    """One result from the results of segments spanning ``spans`` (t_start, t_end) s, in time
    order: rows concatenated, counts added, notes tagged with their segment; the warnings
    ``head`` first, then the segments' (each line once)."""
    notes: list[str] = []
    for k, (r, (a, b)) in enumerate(zip(results, spans)):
        tag = f"segment {k + 1} of {len(results)} (t = {a:.1f} .. {b:.1f} s): "
        notes += [tag + x for x in r.notes]
    updates: dict[str, dict[str, int]] = {}
    for r in results:
        for kind, counts in r.updates.items():
            u = updates.setdefault(kind, {})
            for key, v in counts.items():
                u[key] = u.get(key, 0) + v
    smoothed = None
    sm = [r.smoothed for r in results if r.smoothed is not None]
    if len(sm) == len(results):
        smoothed = SmoothedRun(solution=concat([x.solution for x in sm], Solution),
                               biases=concat([x.biases for x in sm], BiasHistory),
                               runtime_s=sum(x.runtime_s for x in sm), nodes=sum(x.nodes for x in sm),
                               breaks=sum(x.breaks for x in sm), store_mb=max(x.store_mb for x in sm))
    calibration = dict(results[0].calibration)
    calibration["segments"] = [{"t_start_s": a, "t_end_s": b, **r.calibration} for r, (a, b) in zip(results, spans)]
    return RunResult(
        solution=concat([r.solution for r in results], Solution),
        biases=concat([r.biases for r in results], BiasHistory),
        alignment=results[0].alignment,
        diagnostics=concat([r.diagnostics for r in results], Diagnostics),
        gnss_epochs=sum(r.gnss_epochs for r in results),
        gnss_rejected=sum(r.gnss_rejected for r in results),
        runtime_s=sum(r.runtime_s for r in results),
        warnings=tuple(dict.fromkeys([*head, *(w for r in results for w in r.warnings)])),
        smoothed=smoothed,
        notes=tuple(notes),
        updates=updates,
        calibration=calibration,
    )
