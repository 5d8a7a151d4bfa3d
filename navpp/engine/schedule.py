"""The event schedule of a run: the GNSS fixes it uses and the epochs the filter stops at.

An :class:`Epoch` is a time the filter predicts to: a GNSS epoch (its fix, perhaps with the
constraint aids), an aid epoch between fixes (constraints only, :meth:`navpp.aiding.Aiding.schedule`),
or a coasting stop, which only splits a long time update so that the output's 1-sigma and the
smoother have a node at least every :data:`KNOT_S`.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import overload

import numpy as np

from ..config import Config
from ..errors import InputError
from ..recording import GnssData, Recording

#: Longest stretch without a covariance knot (a stop of the filter) for the output sigma, s.
KNOT_S = 1.0


@dataclass(frozen=True)
class GnssFixes:
    """The GNSS fixes a run uses, in time order: those after the alignment inside the IMU span.

    index : (M,) their rows in the recording's GNSS; t : (M,) s; lat, lon : (M,) rad;
    alt : (M,) m (ellipsoidal); var : (M, 3) prior variance ENU, m^2: the log's per-fix 1-sigma
    times ``[gnss] std_scale``, else ``[gnss] default_std_m`` (never scaled), squared.  Every
    check against "the prior R" uses ``var``.  notes : what the run notes about how ``var`` was
    formed (:func:`std_scale_notes`).  r_scale : (M, 3) factor on ``var`` for the filter's R
    (a still start's averaged fixes, :data:`navpp.ins.alignment.START_SHARE`), None: ones.
    """

    index: np.ndarray
    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    var: np.ndarray
    notes: tuple[str, ...] = ()
    r_scale: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])


def prior_std_enu(std_enu: np.ndarray | None, config: Config, n: int) -> np.ndarray:
    """The position 1-sigma (n, 3) ENU m the filter's prior R is made of: the log's ``std_enu``
    (n, 3) m times ``[gnss] std_scale``, or, when the log has none (None), ``[gnss] default_std_m``
    as configured (std_scale does not apply to it: it is the user's own figure)."""
    if std_enu is None:
        return np.tile(np.asarray(config.gnss.default_std_m, dtype=float), (n, 1))
    return np.asarray(std_enu, dtype=float) * config.gnss.std_scale


def with_prior_std(gnss: GnssData, config: Config) -> GnssData:
    """``gnss`` with the sigmas the filter uses, for the readers of a whole
    :class:`~navpp.recording.GnssData` (the alignment's initial position covariance and heading
    from the track, the calibration's GNSS speed): the position 1-sigma times ``[gnss]
    std_scale``, and a velocity 1-sigma of ``[gnss] default_vel_std_mps`` where the log has
    velocity without one (``gnss`` itself when nothing changes)."""
    changes: dict = {}
    if gnss.std_enu is not None and config.gnss.std_scale != 1.0:
        changes["std_enu"] = np.asarray(gnss.std_enu, dtype=float) * config.gnss.std_scale
    if gnss.vel_enu is not None and gnss.std_vel_enu is None:
        changes["std_vel_enu"] = np.full(np.shape(gnss.vel_enu), config.gnss.default_vel_std_mps)
    return replace(gnss, **changes) if changes else gnss


def std_scale_notes(recording: Recording, config: Config, std_enu: np.ndarray | None) -> tuple[str, ...]:
    """The run's note when ``[gnss] std_scale`` is not 1: the log's position sigmas scaled (with
    their medians before and after, ENU m, of the fixes ``std_enu`` (n, 3) m the run uses), or not
    applied because the log has none."""
    scale = config.gnss.std_scale
    if scale == 1.0:
        return ()
    from ..plausibility import std_name

    if std_enu is None or std_enu.shape[0] == 0:
        return (f"[gnss] std_scale = {scale:g} not applied: the log has no position sigmas, and "
                f"[gnss] default_std_m = {list(config.gnss.default_std_m)} m is used as configured",)
    med = np.nanmedian(np.asarray(std_enu, dtype=float), axis=0)
    was = ", ".join(f"{v:.3g}" for v in med)
    now = ", ".join(f"{v:.3g}" for v in med * scale)
    return (f"GNSS position sigmas scaled by {scale:g} ([gnss] std_scale): {std_name(recording.source, True)} "
            f"(median E, N, U {was} m) used as {now} m",)


def gnss_fixes(recording: Recording, config: Config, t_start: float) -> GnssFixes:
    """The fixes in ``(t_start, last IMU stamp]`` (s); InputError when there is none.  Their
    variances are :func:`prior_std_enu` squared: the log's sigmas times ``[gnss] std_scale``, else
    ``[gnss] default_std_m`` unscaled."""
    gnss, imu = recording.gnss, recording.imu
    sel = np.nonzero((gnss.t > t_start) & (gnss.t <= imu.t[-1]))[0]
    if sel.size == 0:
        raise InputError(f"{recording.source}: no GNSS fix inside the IMU span after alignment "
                         f"(t = {t_start:.2f} .. {imu.t[-1]:.2f} s)")
    logged = None if gnss.std_enu is None else np.asarray(gnss.std_enu[sel], dtype=float)
    std = prior_std_enu(logged, config, sel.size)
    return GnssFixes(sel, gnss.t[sel], np.radians(gnss.lat_deg[sel]), np.radians(gnss.lon_deg[sel]),
                     np.asarray(gnss.alt[sel], dtype=float), std ** 2, std_scale_notes(recording, config, logged))


@dataclass(frozen=True)
class Epoch:
    """A time the filter stops at.

    t : s.  index : the epoch's number among the measurement epochs (-1 for a coasting stop).
    fix : index of the GNSS fix at ``t`` into :class:`GnssFixes` (-1: none).  constraints :
    whether the constraint aids apply at ``t``.  sample : the IMU sample exactly at ``t`` (-1:
    none).  coast : a coasting stop (no measurement).
    """

    t: float
    index: int = -1
    fix: int = -1
    constraints: bool = False
    sample: int = -1
    coast: bool = False


def coast_stops(t_from: float, t_to: float, knot_s: float = KNOT_S) -> list[Epoch]:
    """Coasting stops from ``t_from`` towards ``t_to`` (s): one every ``knot_s`` while more than
    ``1.5 knot_s`` remain."""
    return [Epoch(t, coast=True) for t in _coast_times(t_from, t_to, knot_s)]


def _coast_times(t_from: float, t_to: float, knot_s: float) -> list[float]:
    """The times (s) of :func:`coast_stops`."""
    out = []
    while t_to - t_from > 1.5 * knot_s:
        t_from = t_from + knot_s
        out.append(t_from)
    return out


class Schedule(Sequence[Epoch]):
    """A run's epochs (what :func:`epochs` returns) as columns, 26 bytes per stop where a list of
    :class:`Epoch` objects holds about 230 (a float and three ints boxed each): ``t`` (n,)
    float64 s, ``index``, ``fix`` (n,) int32 (epochs and fixes: 2**31 at 10 Hz is 6.8 years),
    ``sample`` (n,) int64 (IMU rows: 2**31 at 1 kHz would be only 25 days), ``constraints``,
    ``coast`` (n,) bool, the fields of :class:`Epoch`.  An item (or each item of an iteration) is made as an
    :class:`Epoch` when asked for; a slice is a Schedule."""

    #: stops made into Epochs at a time by an iteration
    BLOCK = 4096

    def __init__(self, t: np.ndarray, index: np.ndarray, fix: np.ndarray, constraints: np.ndarray,
                 sample: np.ndarray, coast: np.ndarray) -> None:
        self.t, self.index, self.fix, self.constraints, self.sample, self.coast = (
            t, index, fix, constraints, sample, coast)

    def _columns(self) -> tuple[np.ndarray, ...]:
        return self.t, self.index, self.fix, self.constraints, self.sample, self.coast

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @overload
    def __getitem__(self, k: int) -> Epoch: ...

    @overload
    def __getitem__(self, k: slice) -> Schedule: ...

    def __getitem__(self, k: int | slice) -> Epoch | Schedule:
        if isinstance(k, slice):
            return Schedule(*(c[k] for c in self._columns()))
        return Epoch(float(self.t[k]), int(self.index[k]), int(self.fix[k]), bool(self.constraints[k]),
                     int(self.sample[k]), bool(self.coast[k]))

    @staticmethod
    def columns(stops: Sequence[Epoch]) -> tuple[np.ndarray, ...]:
        """``t`` (float64), ``index``, ``fix``, ``sample`` (int64), ``constraints`` and ``coast``
        (bool) of ``stops``: a Schedule's own columns (converted), else read from each Epoch."""
        if isinstance(stops, Schedule):
            return (stops.t, stops.index.astype(np.int64), stops.fix.astype(np.int64),
                    stops.sample.astype(np.int64), stops.constraints, stops.coast)
        n = len(stops)
        return (np.fromiter((e.t for e in stops), float, n), np.fromiter((e.index for e in stops), np.int64, n),
                np.fromiter((e.fix for e in stops), np.int64, n), np.fromiter((e.sample for e in stops), np.int64, n),
                np.fromiter((e.constraints for e in stops), bool, n), np.fromiter((e.coast for e in stops), bool, n))

    def __iter__(self) -> Iterator[Epoch]:
        for lo in range(0, len(self), self.BLOCK):
            for row in zip(*(c[lo:lo + self.BLOCK].tolist() for c in self._columns())):
                yield Epoch(*row)


def epochs(t_start: float, t_end: float, times: np.ndarray, fix: np.ndarray, constraints: np.ndarray,
           imu_t: np.ndarray, knot_s: float = KNOT_S) -> Schedule:
    """The run's stops from the start state at ``t_start`` to the last IMU stamp ``t_end`` (s):
    the measurement epochs (``times``, their fix index and constraint flag, as
    :meth:`navpp.aiding.Aiding.schedule` gives them) with coasting stops between them and after
    the last (a final stop at ``t_end`` when the last one is earlier).  ``imu_t`` are the IMU
    stamps (s), to find the sample at each epoch."""
    times = np.asarray(times, dtype=float)
    n = times.shape[0]
    idx = np.minimum(np.searchsorted(imu_t, times), imu_t.shape[0] - 1)
    sample = np.where(imu_t[idx] == times, idx, -1)
    t_prev = np.concatenate(([t_start], times[:-1])) if n else np.zeros(0)
    gaps = np.nonzero(times - t_prev > 1.5 * knot_s)[0]         # the epochs with coasting stops before them
    before = [_coast_times(float(t_prev[e]), float(times[e]), knot_s) for e in gaps]
    counts = np.zeros(n, np.int64)
    counts[gaps] = [len(c) for c in before]
    at = np.arange(n) + np.cumsum(counts)                         # each measurement epoch's row
    tail = _coast_times(float(times[-1]) if n else t_start, t_end, knot_s)
    if (tail[-1] if tail else float(times[-1]) if n else t_start) < t_end:
        tail.append(t_end)
    total = n + int(counts.sum()) + len(tail)
    out = Schedule(np.empty(total), np.full(total, -1, np.int32), np.full(total, -1, np.int32),
                   np.zeros(total, bool), np.full(total, -1, np.int64), np.ones(total, bool))
    out.t[at], out.index[at], out.fix[at], out.sample[at] = times, np.arange(n), fix, sample
    out.constraints[at], out.coast[at] = constraints, False
    for e, stops in zip(gaps, before):
        out.t[at[e] - len(stops):at[e]] = stops
    out.t[total - len(tail):] = tail
    return out
