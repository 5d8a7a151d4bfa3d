"""What the CLI and Python users call: :func:`process` and :func:`simulate_log`.

:func:`process` reads a log, runs one filter and writes the trajectory, the per-GNSS-epoch
diagnostics and, with a reference, the metrics; the helpers it is made of (filter
construction, output rate, output files, metrics of a run, warnings after a run) are public
for ``navpp compare`` and the benchmarks.  Reading a log is :mod:`navpp.reading`, simulated
outages :mod:`navpp.outages`, ``navpp inspect`` :mod:`navpp.inspection`; their entry points
are importable from here too.

These functions return result objects and raise :class:`navpp.errors.NavppError` subclasses
with one-line messages; they never print or exit.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .config import Config, check_outages, parse_formats, with_memory
from .errors import ConfigError, InputError, NavppError
from .findings import with_code
from .inspection import StreamSummary, inspect
from .outdir import input_files, refuse_overwriting_inputs
from .outfiles import claimed_out_dir, os_reason
from .reading import CONFIG_IN_LOG_DIR, companion, read_log, resolve_config

if TYPE_CHECKING:
    import numpy as np

    from .outages import apply_outages
    from .recording import Recording, Solution

__all__ = ["CONFIG_IN_LOG_DIR", "FORMAT_FILES", "FORWARD_OUTPUTS", "OUTPUT_FILES", "ProcessResult", "StreamSummary",
           "apply_outages", "check_formats", "check_output_rate", "companion", "default_out_dir",
           "forced_fix_warnings", "forward_outputs_note", "inspect", "make_filter", "mcap_writer", "process",
           "read_log", "reference_checks", "resample_solution", "resolve_config", "run_inputs", "run_metrics",
           "simulate_log", "smoothing_metrics", "write_outputs"]


def __getattr__(name: str) -> Any:
    """:func:`navpp.outages.apply_outages`, importable from here, imported on first use (with
    numpy: ``import navpp.api`` itself loads none of the numerical modules)."""
    if name == "apply_outages":
        from .outages import apply_outages

        return apply_outages
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Files navpp writes into an output directory.  After a successful run, any of these that the
#: run did not write (e.g. metrics from an earlier run with a reference, or a trajectory.kml
#: from a run with ``--format kml``) are removed, so the directory never mixes results of
#: different runs.  Only these exact names are touched.
OUTPUT_FILES = ("trajectory.csv", "trajectory_forward.csv", "diagnostics.csv", "metrics.json", "metrics.md",
                "trajectory.mcap", "trajectory.tum", "trajectory.geojson", "trajectory.kml", "trajectory_forward.tum",
                "reference.tum", "navpp.layout.json")
#: Besides :data:`OUTPUT_FILES`, the labelled TUM copy (``<log>-<filter>.tum``,
#: :func:`navpp.io.exports.labelled_tum_name`) an earlier run listed in the manifest is stale too
#: when this run did not write it: names with this suffix.  So are the figures of ``--plot``
#: (:data:`navpp.outdir.FIGURE_SUFFIXES`).
LABELLED_OUTPUT_SUFFIX = ".tum"
#: The file each ``--format`` / ``[output] formats`` name writes.
FORMAT_FILES = {"csv": "trajectory.csv", "mcap": "trajectory.mcap", "tum": "trajectory.tum",
                "geojson": "trajectory.geojson", "kml": "trajectory.kml"}


@dataclass(frozen=True)
class ProcessResult:
    """Outcome of :func:`process`.

    Attributes
    ----------
    filter_name : the filter's registry name.
    recording : the log as read (:class:`~navpp.recording.Recording`).
    solution : the solution as written (at the output rate), ``t`` in s relative to
        ``solution.t0_ns``: the smoothed one when ``smoothed``, else the forward filter's.
    run : the engine's ``RunResult`` (full-rate forward solution, biases, alignment,
        diagnostics; ``run.smoothed`` the full-rate smoothed run).
    metrics : the content of ``metrics.json`` (dict), None without a reference.  For a smoothed
        run its figures are the smoothed solution's and ``metrics["forward"]`` holds the
        forward filter's (:func:`smoothing_metrics`).
    forward : the forward filter's solution at the output rate when ``smoothed`` (what
        ``trajectory_forward.csv`` holds), else None (``solution`` is the forward one).
    out_dir, files : the output directory and the files written (empty with ``write=False``).
    config : the configuration used.
    notes, warnings : lines for the user.
    outages : one dict per simulated GNSS outage window: ``start_s``, ``duration_s``,
        ``end_s`` (s from the log start) and ``gnss_removed`` (fixes removed); empty without.
    trajectory : pandas.DataFrame (property) with exactly ``trajectory.csv``'s columns.
    diagnostics : pandas.DataFrame (property) with exactly ``diagnostics.csv``'s columns.
    """

    filter_name: str
    recording: Recording
    solution: Solution
    run: Any                       # engine.RunResult
    metrics: dict | None
    out_dir: Path
    files: tuple[Path, ...]
    config: Config
    notes: tuple[str, ...] = field(default_factory=tuple)      # what was chosen (config, alignment)
    warnings: tuple[str, ...] = field(default_factory=tuple)   # what the data made us do
    outages: tuple[dict, ...] = field(default_factory=tuple)   # simulated GNSS outage windows
    forward: Solution | None = None                            # with smoothing: the forward solution

    @property
    def smoothed(self) -> bool:
        """True when ``solution`` is the RTS-smoothed trajectory."""
        return self.forward is not None

    @cached_property
    def forward_trajectory(self):
        """The forward filter's solution as a DataFrame (``trajectory.csv``'s columns): that of
        ``trajectory_forward.csv`` for a smoothed run, else the same as :attr:`trajectory`."""
        if self.forward is None:
            return self.trajectory
        from .io.exports import trajectory_frame

        return trajectory_frame(self.forward)

    @cached_property
    def trajectory(self):
        """The solution as a ``pandas.DataFrame`` with ``trajectory.csv``'s columns.

        ``t, lat, lon, alt, ve, vn, vu, roll, pitch, heading, std_e, std_n, std_u``, all
        float64: ``t`` in s on the log's own time base (absolute, as in the CSV), lat/lon deg,
        alt m above the WGS-84 ellipsoid, velocity m/s ENU, roll/pitch/heading deg (navigation
        convention, heading clockwise from north), position 1-sigma m.  One row per row of
        ``trajectory.csv`` (the output rate), at full precision (the CSV rounds to 1 us,
        1e-9 deg and 1e-4).  Available with ``write=False`` too; built once per result.
        """
        from .io.exports import trajectory_frame

        return trajectory_frame(self.solution)

    @cached_property
    def diagnostics(self):
        """The filter's per-GNSS-epoch record as a ``pandas.DataFrame`` with
        ``diagnostics.csv``'s columns: ``t`` (s on the log's time base), innovation
        ``nu_e, nu_n, nu_u`` (m, ENU), ``nis``, ``accepted``, ``forced`` (0/1), ``r_std_e,
        r_std_n, r_std_u`` (m) and the filter's adaptive quantities."""
        from .io.exports import diagnostics_frame

        return diagnostics_frame(self.run.diagnostics, self.recording.t0_ns)

def make_filter(name: str, config: Config, *, seed: int | None = None):
    """Instantiate a registered filter with its ``[filter.<name>]`` options and the GNSS gate."""
    import numpy as np

    from .filters import FILTERS, get_filter

    for key in config.filters:
        if key not in FILTERS:
            import difflib
            near = difflib.get_close_matches(key, list(FILTERS), n=1)
            hint = f"; did you mean [filter.{near[0]}]?" if near else f"; filters: {', '.join(sorted(FILTERS))}"
            raise ConfigError(f"{config.source}: unknown section [filter.{key}]{hint}")
    cls = get_filter(name)
    opts = dict(config.filters.get(name, {}))
    opt_seed = opts.get("seed")
    options = cls.options_from_mapping(opts, config.source)
    rng = np.random.default_rng(seed if seed is not None else (opt_seed if isinstance(opt_seed, int) else 0))
    return cls(options, gate_probability=config.gnss.gate_probability,
               reanchor_after_s=config.gnss.reanchor_after_s, rng=rng)


def check_output_rate(rate_hz: object, what: str = "--output-rate") -> float:
    """``rate_hz`` as a float if it is a finite number > 0 Hz; :class:`ConfigError` naming ``what``."""
    import numpy as np

    ok = isinstance(rate_hz, (int, float, np.integer, np.floating)) and not isinstance(rate_hz, (bool, np.bool_))
    if not ok or not math.isfinite(float(rate_hz)) or float(rate_hz) <= 0.0:
        raise ConfigError(f"{what} must be a finite number of Hz > 0, got {rate_hz!r}")
    return float(rate_hz)


def resample_solution(sol: Solution, rate_hz: float) -> Solution:
    """The solution at ``rate_hz`` on whole multiples of the period (interpolated).

    Raises :class:`ConfigError` if ``rate_hz`` is not a finite number > 0, or so low that no
    whole multiple of the period falls within the solution's time span.
    """
    import numpy as np

    from .metrics import interpolate_solution
    from .recording import Solution
    from .spill import release

    rate_hz = check_output_rate(rate_hz, "output rate")
    period = 1.0 / rate_hz
    t0_abs = sol.t0_ns * 1e-9
    k0 = np.ceil((t0_abs + sol.t[0]) / period - 1e-9)
    k1 = np.floor((t0_abs + sol.t[-1]) / period + 1e-9)
    t = np.arange(k0, max(k1, k0 - 1.0) + 1) * period - t0_abs
    t = t[(t >= sol.t[0]) & (t <= sol.t[-1])]
    if t.size == 0:
        raise ConfigError(f"output rate {rate_hz:g} Hz: no output epoch falls within the solution's "
                          f"{sol.t[-1] - sol.t[0]:.3f} s span; use a higher rate")
    it = interpolate_solution(sol, t)

    def interp3(a: np.ndarray | None) -> np.ndarray | None:
        """``a`` (N, 3) at ``t``; a spilled ``a``'s pages released after (:mod:`navpp.spill`)."""
        if a is None:
            return None
        out = np.column_stack([np.interp(t, sol.t, a[:, i]) for i in range(3)])
        release([a], 0, a.shape[0])
        return out

    return Solution(t=t, lat_deg=it["lat_deg"], lon_deg=it["lon_deg"], alt=it["alt"], vel_enu=it["vel_enu"],
                    rph_deg=it["rph_deg"], std_enu=interp3(sol.std_enu), t0_ns=sol.t0_ns, std_att=interp3(sol.std_att),
                    std_vel_enu=interp3(sol.std_vel_enu), rate_body=interp3(sol.rate_body))


def reference_checks(rec: Recording, cfg: Config, metrics: dict | None) -> list[str]:
    """Warn when the raw GNSS disagrees with the reference far beyond its stated sigma: the
    reference is then on another time base or datum, and every figure against it misleads."""
    import numpy as np

    if metrics is None:
        return []
    raw = metrics.get("gnss_position_m", {}).get("horizontal")
    if not raw:
        return []
    std = (rec.gnss.std_enu[:, :2] if rec.gnss.std_enu is not None
           else np.asarray(cfg.gnss.default_std_m[:2])[None, :])
    expected = float(np.sqrt(np.mean(np.sum(std ** 2, axis=1))))
    if raw["rmse"] > max(5.0 * expected, 10.0):
        return [(f"{metrics['reference']}: the raw GNSS fixes are {raw['rmse']:.1f} m (horizontal RMSE) from the "
                 f"reference, {raw['rmse'] / expected:.0f} times their stated 1-sigma: the reference is probably on "
                 "another time base or datum, and the figures against it mislead")]
    return []


def run_inputs(log: Path, config: str | Path | Config | None, reference: str | Path | None,
               gnss_file: str | Path | None) -> set[tuple[int, int]]:
    """(device, inode) of every file a run of :func:`process` reads (:func:`navpp.outdir.input_files`):
    the log (a file, or the files in its directory), the config, the reference and the GNSS file."""
    cfg_path = config if isinstance(config, (str, Path)) else companion(log, CONFIG_IN_LOG_DIR)
    ref_path = reference if reference is not None else (companion(log, "reference.csv")
                                                        or companion(log, "reference.tum"))
    return input_files(log, cfg_path, ref_path, gnss_file, not_in_dirs=OUTPUT_FILES)


def default_out_dir(log: Path, filter_name: str) -> Path:
    stem = log.name if log.is_dir() else log.stem
    return Path("navpp-out") / f"{stem}-{filter_name}"

def _write_file(path: Path, write: Callable[[], None]) -> Path:
    try:
        write()
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({os_reason(exc)})") from None
    return path


def write_outputs(out: Path, outputs: Sequence[tuple[str, Callable[[Path], None]]],
                  inputs: set[tuple[int, int]] = frozenset()) -> list[Path]:
    """Write a run's files into ``out`` all together, then remove its stale :data:`OUTPUT_FILES`.

    Each ``(name, write)`` is called as ``write(path)`` on a path inside a hidden staging
    directory in ``out``; only when every writer has succeeded are the files renamed to
    ``out / name`` (keeping the permissions of a file they replace).  If any writer fails or
    the run is interrupted, nothing in ``out`` changes: the previous run's outputs stay whole
    and consistent with each other.  The staging directory is always removed.

    Stale outputs are the :data:`OUTPUT_FILES`, labelled TUM copies and figures
    (:data:`navpp.outdir.FIGURE_SUFFIXES`) of an earlier run that this one did not write;
    only those the directory's manifest (:mod:`navpp.outdir`) lists as written by navpp are
    removed, and never one of the run's ``inputs`` (``(device, inode)`` pairs,
    :func:`navpp.outdir.input_files`), which are never replaced either.  The manifest is then
    updated.

    Returns the paths written, in the order given.  Raises :class:`InputError` naming the
    file (``out / name``) that could not be written or the stale output that could not be
    removed; other exceptions of a writer propagate unchanged.
    """
    from . import interrupts, outdir

    outdir.refuse_overwriting_inputs(out, [name for name, _ in outputs], inputs)
    try:
        staging = Path(tempfile.mkdtemp(dir=out, prefix=outdir.STAGING_PREFIX))
    except OSError as exc:
        raise InputError(f"{out}: cannot write there ({os_reason(exc)})") from None
    written: list[Path] = []
    try:
        for name, write in outputs:
            _write_file(out / name, lambda write=write, name=name: write(staging / name))
        with interrupts.commit():
            for name, _ in outputs:
                staged, target = staging / name, out / name
                try:
                    if target.is_file():
                        os.chmod(staged, target.stat().st_mode & 0o7777)
                    os.replace(staged, target)
                except OSError as exc:
                    raise InputError(f"{target}: cannot write ({os_reason(exc)})") from None
                written.append(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    ours = outdir.read_manifest(out)
    labelled = sorted(n for n in ours if n.endswith((LABELLED_OUTPUT_SUFFIX, *outdir.FIGURE_SUFFIXES))
                      and n not in OUTPUT_FILES and os.sep not in n and "/" not in n)
    for name in (*OUTPUT_FILES, *labelled):   # stale results of an earlier navpp run: not ours any more
        stale = out / name
        if (stale not in written and name in ours and stale.is_file() and not stale.is_symlink()
                and not outdir.is_input(stale, inputs)):
            try:
                stale.unlink()
            except OSError as exc:
                raise InputError(f"{stale}: cannot remove this output of an earlier run "
                                 f"({os_reason(exc)})") from None
    try:
        outdir.write_manifest(out, {p.name for p in written} | {n for n in ours if (out / n).exists()})
    except OSError as exc:
        raise InputError(f"{out / outdir.MANIFEST_NAME}: cannot write ({os_reason(exc)})") from None
    return written


def check_formats(formats: str | Sequence[str] | None, embed_input: bool, cfg: Config) -> tuple[str, ...]:
    """The output formats of a run: ``formats`` if given (``--format``), else the config's.

    Raises :class:`ConfigError` for an unknown name and for ``embed_input`` without ``mcap``.
    """
    if formats is not None:
        chosen, what = parse_formats(formats, "formats"), "--format"
    else:
        chosen, what = cfg.output.formats, f"{cfg.source}: [output] formats"
    if embed_input and "mcap" not in chosen:
        raise ConfigError(f"--embed-input copies the input log into trajectory.mcap, but {what} is "
                          f"{','.join(chosen)}: add mcap (e.g. --format {','.join((*chosen, 'mcap'))})")
    return chosen


def mcap_writer() -> Callable[..., None]:
    try:
        from .io.mcap_out import write_trajectory_mcap
    except ImportError as exc:
        raise ConfigError(f"the mcap output format is not available ({exc})") from None
    return write_trajectory_mcap


def process(log: str | Path, *, filter_name: str = "ekf", config: str | Path | Config | None = None,
            reference: str | Path | None = None, out_dir: str | Path | None = None,
            output_rate_hz: float | None = None, progress: Callable[[str, float], None] | None = None,
            write: bool = True, imu_topic: str | None = None, gnss_topic: str | None = None,
            reference_topic: str | None = None, gnss_file: str | Path | None = None,
            formats: str | Sequence[str] | None = None, embed_input: bool = False,
            gnss_outages: Sequence[tuple[float, float]] | None = None,
            smooth: bool | None = None, odometry_topic: str | None = None,
            reference_anchor: str | Sequence[float] | None = None, plot: bool = False,
            jit: str | None = None, memory: str | int | None = None) -> ProcessResult:
    """Read a log, run one filter, write trajectory (and metrics with a reference).

    ``navpp.process`` is this function.  Example::

        res = navpp.process("drive.mcap", filter_name="aekf", formats=["csv", "tum"])
        res.trajectory          # pandas.DataFrame, trajectory.csv's columns
        res.metrics             # dict as metrics.json, or None without a reference

    Parameters
    ----------
    log : a CSV log directory (imu.csv, gnss.csv, optional reference.csv), an MCAP file, a
        ROS 1 bag or a ROS 2 bag directory.
    imu_topic, gnss_topic, reference_topic : topic choices for ROS logs (see :func:`read_log`);
        the reference topic may be a NavSatFix, a ``nav_msgs/Odometry`` or a
        ``geometry_msgs/PoseStamped`` (poses in a local ENU frame: see ``reference_anchor``).
    odometry_topic : the wheel odometry topic of a ROS log (``nav_msgs/Odometry``, ``TwistStamped``
        or ``TwistWithCovarianceStamped`` in the vehicle frame); None chooses automatically
        (:func:`navpp.io.detect.choose_odometry_topic`; the run's notes say which), ``"none"``
        leaves the log's odometry out (any log kind).
    gnss_file : an RTKLIB .pos file replacing or supplying the log's GNSS.
    filter_name : registry name (``navpp filters``).
    config : a TOML path or a :class:`Config`; None looks for ``navpp.toml`` in the log
        directory, then uses the defaults (automotive preset).
    reference : reference CSV or TUM file overriding ``reference.csv`` in the log directory
        (``reference.csv`` / ``reference.tum`` beside a ROS log); the run's notes say which
        reference was used and how it was found.
    reference_anchor : origin of a local-frame reference (TUM file, Odometry / PoseStamped
        topic) as ``(lat_deg, lon_deg, alt_m)`` or ``"LAT,LON,ALT"`` (WGS-84 ellipsoidal height;
        ENU axes); None uses the anchor its file names (navpp's own trajectory.tum and
        trajectory.mcap record theirs; :mod:`navpp.io.refposes`).
    out_dir : output directory; default ``navpp-out/<log>-<filter>``.  With ``write=True`` it is
        created and checked writable before anything is read (:class:`InputError` if not).
        After a successful run, navpp's own output files (:data:`OUTPUT_FILES`) that this run
        did not write are removed from it.
    output_rate_hz : trajectory rate, Hz (finite, > 0, at most the IMU rate); overrides
        ``[output] rate_hz``; None and no config rate: one row per IMU sample.
    progress : ``progress(stage, fraction)`` for progress bars.
    write : False computes everything and writes nothing.
    formats : output formats (a list or a comma-separated string) among ``csv`` (trajectory.csv),
        ``mcap`` (trajectory.mcap), ``tum`` (trajectory.tum), ``geojson`` (trajectory.geojson),
        ``kml`` (trajectory.kml); see :mod:`navpp.io.exports`.  Overrides ``[output]
        formats``; None uses it (default ``csv``).  ``diagnostics.csv`` and, with a
        reference, ``metrics.json`` and ``metrics.md`` are always written.  All files of a
        run appear together: if one cannot be written, the directory keeps the previous
        run's files unchanged (:func:`write_outputs`).
    embed_input : copy the input log's messages into trajectory.mcap (needs ``mcap``).
    gnss_outages : simulated GNSS outages, ``[(start_s, duration_s), ...]``: seconds from the
        log start (its first IMU sample), ``start >= 0``, ``duration > 0``, each window inside
        the log (:class:`InputError` otherwise).  The fixes with ``start <= t <= start +
        duration`` are removed before filtering (the INS coasts through), and the metrics
        report each window (``metrics["outages"]``).  Overrides ``[gnss] outages``; None uses it.
    smooth : smooth the forward run backwards (Rauch-Tung-Striebel, :mod:`navpp.filters.smoother`):
        ``trajectory.csv`` and the other trajectory formats hold the smoothed solution (with
        smoothed 1-sigma), ``trajectory_forward.csv`` (with ``csv``) and the MCAP's
        ``/navpp/forward/*`` topics the forward one, and the metrics show both.  Overrides
        ``[output] smooth``; None uses it (default off).
    memory : memory the smoother's stored forward run and the IMU-rate output may each hold
        before they spill to a temporary file in ``$TMPDIR``, bytes or text (``"500MB"``, ``"1GB"``,
        ``"2G"``); overrides ``[output] memory`` (default 64 MB); None uses it.
    plot : also write the run's figures beside the outputs (:mod:`navpp.plots`: the error per
        axis with its +-3-sigma band, the trajectory, the adaptive noise, an HTML overview map);
        ignored with ``write=False``.

    Returns
    -------
    ProcessResult : with ``trajectory`` and ``diagnostics`` as pandas DataFrames and
        ``metrics`` as a dict (None without a reference).

    jit : ``"on"`` (compiled; the default unless ``$NAVPP_JIT`` says otherwise), ``"off"``
        (interpreted) or ``"auto"`` (by the job's size and what is cached): navpp's kernels in
        this process (:mod:`navpp.jitmode`; decided at the first run, fixed after it).

    Raises
    ------
    NavppError : ConfigError for bad options or config (unknown formats, ``embed_input``
        without ``mcap``), InputError for unreadable input or unwritable output,
        FilterDivergedError when the filter diverges; each with a one-line message.
    """
    from . import jitmode

    with cycles_after():
        cfg = config if isinstance(config, Config) else resolve_config(Path(log), config)
        if memory is not None:
            cfg = with_memory(cfg, memory)
        choice = jitmode.choose(jit, [Path(log)], [filter_name], cfg.output.smooth if smooth is None else bool(smooth))
        plan = _plan(Path(log), filter_name=filter_name, config=config, resolved=cfg, reference=reference,
                     out_dir=out_dir, output_rate_hz=output_rate_hz, write=write, gnss_file=gnss_file, formats=formats,
                     embed_input=embed_input, gnss_outages=gnss_outages, smooth=smooth,
                     topics=(imu_topic, gnss_topic, reference_topic, odometry_topic),
                     reference_anchor=_anchor_arg(reference_anchor))
        if plot:
            plan = replace(plan, plot=True)
        with claimed_out_dir(plan.out, plan.out_label, OUTPUT_FILES) if write else nullcontext():
            res = _run(plan, progress)
    line = jitmode.note(choice)
    return replace(res, notes=(*res.notes, line)) if line else res


@contextmanager
def cycles_after() -> Iterator[None]:
    """Python's cyclic garbage collector paused for a run, and left after it as it was.

    A run makes few reference cycles, but its imports and the kernels' loading leave hundreds of
    thousands of objects, which the collector walks again each time its counts trip: about 130
    collections and 0.1-0.15 s of a one-hour log's 2 s (the peak memory of an eight-hour log 0.3 MB
    higher).  Cycles made during the run are collected after it, as the collector's counts next
    trip."""
    import gc

    from .kernel import CollectorOnCompile

    paused = gc.isenabled()
    gc.disable()
    try:
        with CollectorOnCompile():      # on again if numba compiles (its garbage is cyclic)
            yield
    finally:
        if paused:
            gc.enable()


@dataclass(frozen=True)
class _Plan:
    """A :func:`process` run with every option checked, before anything is read or created.

    ``rate_hz`` the output rate (Hz, None: every IMU sample) and ``rate_what`` where it came
    from (for messages); ``windows`` the simulated GNSS outages ``(start_s, duration_s)``;
    ``out_label`` how the output directory is named in messages; ``inputs`` the (device,
    inode) of every file the run reads (empty without ``write``); ``topics`` the IMU, GNSS,
    reference and odometry topic choices.
    """

    log: Path
    cfg: Config
    config_arg: str | Path | Config | None
    filter_name: str
    filt: Any
    reference: str | Path | None
    gnss_file: str | Path | None
    topics: tuple[str | None, str | None, str | None, str | None]
    rate_hz: float | None
    rate_what: str
    formats: tuple[str, ...]
    embed_input: bool
    windows: tuple[tuple[float, float], ...]
    smooth: bool
    write: bool
    out: Path
    out_label: str
    inputs: set[tuple[int, int]]
    reference_anchor: str | None = None
    plot: bool = False            # also write the figures (navpp.plots)


def _anchor_arg(anchor: str | Sequence[float] | None) -> str | None:
    """``reference_anchor`` as the ``"LAT,LON,ALT"`` text :func:`read_log` takes."""
    if anchor is None or isinstance(anchor, str):
        return anchor
    return ",".join(repr(float(v)) for v in anchor)


def _plan(log: Path, *, filter_name: str, config: str | Path | Config | None, reference: str | Path | None,
          resolved: Config | None = None,
          out_dir: str | Path | None, output_rate_hz: float | None, write: bool, gnss_file: str | Path | None,
          formats: str | Sequence[str] | None, embed_input: bool, gnss_outages: Sequence[tuple[float, float]] | None,
          smooth: bool | None, topics: tuple[str | None, str | None, str | None, str | None],
          reference_anchor: str | None = None) -> _Plan:
    """Check every option of :func:`process` (in this order: config, output rate, formats,
    outages, filter, output directory against the inputs); the first problem raises."""
    cfg = resolved or (config if isinstance(config, Config) else resolve_config(log, config))
    if output_rate_hz is not None:
        rate, rate_what = check_output_rate(output_rate_hz), "--output-rate"
    else:
        rate, rate_what = cfg.output.rate_hz, f"{cfg.source}: [output] rate_hz"
        if rate is not None:
            rate = check_output_rate(rate, rate_what)
    chosen_formats = check_formats(formats, embed_input, cfg)
    if write and "mcap" in chosen_formats:
        mcap_writer()                 # before the run: not available is a ConfigError now, not after it
    windows = (check_outages(gnss_outages, "gnss_outages") if gnss_outages is not None
               else cfg.gnss.outages)
    smooth = cfg.output.smooth if smooth is None else bool(smooth)
    filt = make_filter(filter_name, cfg)
    out = Path(out_dir) if out_dir is not None else default_out_dir(log, filter_name)
    label = "--out" if out_dir is not None else "output directory"
    inputs: set[tuple[int, int]] = set()
    if write:        # before anything is created or read: a run whose result would replace its own input
        inputs = run_inputs(log, config, reference, gnss_file)
        forward_tum = [FORWARD_OUTPUTS["tum"]] if smooth and "tum" in chosen_formats else []
        refuse_overwriting_inputs(out, [FORMAT_FILES[f] for f in chosen_formats] + list(OUTPUT_FILES[1:5])
                                  + forward_tum, inputs, label)
    return _Plan(log, cfg, config, filter_name, filt, reference, gnss_file, topics, rate, rate_what,
                 tuple(chosen_formats), embed_input, tuple(windows), smooth, write, out, label, inputs,
                 reference_anchor)


def _read(plan: _Plan, progress: Callable[[str, float], None] | None) -> tuple[Recording, list[dict]]:
    """The log as the run uses it: read, its simulated outages removed, its IMU rate checked
    against the output rate.  Returns the recording and one dict per outage window."""
    if progress:
        progress("reading", 0.0)
    imu_topic, gnss_topic, reference_topic, odometry_topic = plan.topics
    rec = read_log(plan.log, plan.cfg, reference=plan.reference,
                   progress=(lambda f: progress("reading", f)) if progress else None, imu_topic=imu_topic,
                   gnss_topic=gnss_topic, reference_topic=reference_topic, gnss_file=plan.gnss_file,
                   odometry_topic=odometry_topic, reference_anchor=plan.reference_anchor)
    if progress:
        progress("reading", 1.0)
    from .outages import apply_outages

    rec, outages = apply_outages(rec, plan.windows, str(plan.log))
    imu_rate = rec.imu.rate_hz
    # 0.1 % slack: the IMU rate is a median of stamp differences (jitter, stamp rounding)
    if plan.rate_hz is not None and plan.rate_hz > imu_rate * 1.001:
        raise ConfigError(f"{plan.rate_what} {plan.rate_hz:g} Hz is above the IMU rate of {plan.log} "
                          f"({imu_rate:.1f} Hz); the trajectory cannot be finer than the IMU")
    return rec, outages


def _filter(plan: _Plan, rec: Recording, progress: Callable[[str, float], None] | None) -> Any:
    """The engine run (``engine.RunResult``); a failure on a log the reader found cut off
    names the cut in its one line (the likely reason)."""
    from . import engine

    try:
        return engine.run(rec, plan.cfg, plan.filt,
                          progress=(lambda f: progress("filtering", f)) if progress else None, smooth=plan.smooth)
    except NavppError as exc:
        cut = with_code(rec.warnings, "recording-cut-off")
        if cut:
            raise type(exc)(f"{exc} ({cut[0]})") from None
        raise


def _run(plan: _Plan, progress: Callable[[str, float], None] | None) -> ProcessResult:
    """Read, filter, measure and (with ``plan.write``) write: the body of :func:`process`."""
    rec, outages = _read(plan, progress)
    result = _filter(plan, rec, progress)
    runtime = result.runtime_s        # without the one-off kernel compilation of a first run
    sol = result.smoothed.solution if plan.smooth else result.solution
    sol_out = resample_solution(sol, plan.rate_hz) if plan.rate_hz is not None else sol
    fwd_out = None
    if plan.smooth:
        fwd_out = resample_solution(result.solution, plan.rate_hz) if plan.rate_hz is not None else result.solution
    removed = [o["gnss_removed"] for o in outages]
    named = {"filter_name": plan.filter_name, "log": str(plan.log), "windows": plan.windows, "removed": removed}
    metrics = run_metrics(rec, plan.cfg, result, sol, runtime_s=runtime, **named)
    if metrics is not None and result.calibration:
        metrics["calibration"] = result.calibration
    if metrics is not None and plan.smooth:
        forward = run_metrics(rec, plan.cfg, result, result.solution, runtime_s=result.forward_runtime_s, **named)
        metrics = smoothing_metrics(metrics, forward, result.smoothed)
    files: list[Path] = []
    written_notes: list[str] = []        # what a writer has to say (the embedded input's left-out topics)
    if plan.write:
        outputs = _outputs(plan.formats, log=plan.log, rec=rec, sol_out=sol_out, result=result, metrics=metrics,
                           filter_name=plan.filter_name, embed_input=plan.embed_input, forward_out=fwd_out,
                           compared=sol, cfg=plan.cfg, notes=written_notes)
        if plan.plot:
            from .plots import plot_outputs

            outputs += plot_outputs(plan.log, rec, result, plan.filt, plan.filter_name, plan.windows)
        files = write_outputs(plan.out, outputs, plan.inputs)
    cfg = plan.cfg
    notes = tuple(rec.notes) + tuple(cfg.notes) + tuple(result.notes) + tuple(result.alignment.lines) + tuple(
        f"GNSS outage {o['start_s']:g}-{o['end_s']:g} s ({o['duration_s']:g} s from the log start): "
        f"{o['gnss_removed']} fixes removed, the INS coasts" for o in outages) + odometry_note(rec, cfg) + tuple(
        written_notes)
    warnings = (tuple(rec.warnings) + tuple(result.warnings) + tuple(forced_fix_warnings(rec, cfg, result))
                + tuple(reference_checks(rec, cfg, metrics)))
    if plan.smooth:
        notes += (f"smoothed backwards (Rauch-Tung-Striebel) over {result.smoothed.nodes} forward nodes in "
                  f"{result.smoothed.runtime_s:.2f} s; {forward_outputs_note(plan.formats, plan.write)}",)
    return ProcessResult(plan.filter_name, rec, sol_out, result, metrics, plan.out, tuple(files), cfg, notes,
                         warnings, tuple(outages), fwd_out)


#: Where a smoothed run keeps the forward filter's solution, per output format (``--format``).
FORWARD_OUTPUTS = {"csv": "trajectory_forward.csv", "tum": "trajectory_forward.tum",
                   "mcap": "the /navpp/forward/fix and /navpp/forward/odometry topics of trajectory.mcap"}


def forward_outputs_note(formats: Sequence[str], write: bool = True) -> str:
    """Where a smoothed run's forward solution went, by the formats written (:data:`FORWARD_OUTPUTS`;
    geojson and kml hold the smoothed trajectory only)."""
    where = [FORWARD_OUTPUTS[f] for f in formats if f in FORWARD_OUTPUTS]
    if not write:
        return "the forward solution is ProcessResult.forward (nothing written)"
    if not where:
        verb = "holds" if len(formats) == 1 else "hold"
        return (f"the forward solution is not written ({', '.join(formats)} {verb} the smoothed one only; "
                "--format csv, tum or mcap keeps it)")
    return ("the forward solution is in " + ", ".join(where[:-1]) + (" and " if len(where) > 1 else "")
            + where[-1])


def odometry_note(rec: Recording, cfg: Config) -> tuple[str, ...]:
    """The run's note on its odometry input: which stream (topic or file), samples and rate, and
    what of it the run used (``[odometry] use``, ``use_yaw_rate``)."""
    import numpy as np

    od = rec.odometry
    if od is None or len(od) == 0:
        return ()
    dt = np.diff(od.t)
    rate = f", {1.0 / float(np.median(dt)):.3g} Hz" if dt.size and float(np.median(dt)) > 0 else ""
    head = f"odometry: {od.source} ({len(od)} samples{rate})"
    if not cfg.odometry.use:
        return (f"{head}, not used ([odometry] use = false)",)
    if od.yaw_rate is None:
        used = "speed used" + ("; it has no yaw rate for [odometry] use_yaw_rate" if cfg.odometry.use_yaw_rate else "")
    elif cfg.odometry.use_yaw_rate:
        used = "speed and yaw rate used"
    else:
        used = "speed used; its yaw rate is not ([odometry] use_yaw_rate = true fuses it)"
    return (f"{head}: {used}",)


def run_metrics(rec: Recording, cfg: Config, result: Any, solution: Solution, *, filter_name: str, log: str,
                runtime_s: float, windows: Sequence[tuple[float, float]], removed: Sequence[int]) -> dict | None:
    """:func:`navpp.metrics.compute_metrics` of one solution of an engine run (``result``, the
    forward or the smoothed solution) against the recording's reference; None without one.
    ``windows`` are the simulated outages and ``removed`` the fixes each removed."""
    from .metrics import compute_metrics

    if rec.reference is None:
        return None
    return compute_metrics(solution, rec.reference, filter_name=filter_name, log=log,
                           reference=rec.reference.source or "", runtime_s=runtime_s, imu_samples=len(rec.imu),
                           gnss_epochs=result.gnss_epochs, gnss_rejected=result.gnss_rejected, gnss=rec.gnss,
                           lever_arm_m=cfg.gnss.lever_arm_m, outages=windows, outages_removed=removed,
                           updates=result.updates)


#: The figures of the forward filter kept in ``metrics["forward"]`` of a smoothed run.
FORWARD_METRIC_KEYS = ("position_m", "velocity_mps", "attitude_deg", "outages", "runtime_s")


def smoothing_metrics(smoothed: dict, forward: dict, run: Any) -> dict:
    """``metrics.json`` of a smoothed run: the smoothed solution's figures at the top level (as
    for any run), ``"solution": "smoothed"``, ``"smoothing_s"`` (the backward pass, s, part of
    ``runtime_s``), ``"smoother_nodes"``, and ``"forward"``: the forward filter's
    :data:`FORWARD_METRIC_KEYS` (its ``runtime_s`` without the smoothing)."""
    out = dict(smoothed)
    out["solution"] = "smoothed"
    out["smoothing_s"] = float(run.runtime_s)
    out["smoother_nodes"] = int(run.nodes)
    out["forward"] = {k: forward[k] for k in FORWARD_METRIC_KEYS if k in forward}
    return out


#: At most this many times are named in the forced-fix warning.
FORCED_TIMES_SHOWN = 8


def forced_fix_warnings(rec: Recording, cfg: Config, result: Any) -> list[str]:
    """A warning when fixes were forced through the gate after a long run of rejections.

    The filter then re-anchors its position covariance on the fix (it takes itself, not the
    GNSS, to be wrong), and the trajectory may jump there: the user should know when.
    """
    import numpy as np

    diag = getattr(result, "diagnostics", None)
    forced = np.asarray(getattr(diag, "forced", ()), dtype=bool)
    if not forced.any():
        return []
    times = np.asarray(diag.t, dtype=float)[forced]
    shown = ", ".join(f"{x:.1f}" for x in times[:FORCED_TIMES_SHOWN])
    more = f" and {times.size - FORCED_TIMES_SHOWN} more" if times.size > FORCED_TIMES_SHOWN else ""
    n = int(times.size)
    line = (f"{rec.source}: {n} GNSS fix{'es' if n > 1 else ''} force-admitted after "
            f"{cfg.gnss.reanchor_after_s:g} s of gate rejections, with the position covariance re-anchored "
            f"(the solution may jump there), at t = {shown}{more} s from the log start")
    return [line]


def _outputs(formats: Sequence[str], *, log: Path, rec: Recording, sol_out: Solution, result: Any,
             metrics: dict | None, filter_name: str, embed_input: bool,
             forward_out: Solution | None = None, compared: Solution | None = None,
             cfg: Config | None = None, notes: list[str] | None = None) -> list[tuple[str, Callable[[Path], None]]]:
    """``(file name, writer(path))`` for every file of a run, in the order they are listed.
    ``forward_out``: the forward solution of a smoothed run (``sol_out`` is then the smoothed one).
    ``compared``: the (full-rate) solution the metrics were computed on; its span picks the rows
    of ``reference.tum``.  ``notes``: the writers append their lines for the run's notes there
    (:func:`embed_note`)."""
    from .io import writers

    cfg = Config() if cfg is None else cfg
    t0_s = rec.t0_ns * 1e-9
    biases = result.smoothed.biases if forward_out is not None else result.biases
    outputs: list[tuple[str, Callable[[Path], None]]] = []
    if "csv" in formats:
        outputs.append(("trajectory.csv", lambda p: writers.write_trajectory_csv(p, sol_out, t0_s=t0_s)))
        if forward_out is not None:
            outputs.append(("trajectory_forward.csv",
                            lambda p: writers.write_trajectory_csv(p, forward_out, t0_s=t0_s)))
    outputs.append(("diagnostics.csv", lambda p: writers.write_diagnostics_csv(p, result.diagnostics, t0_s=t0_s)))
    if metrics is not None:
        outputs.append(("metrics.json", lambda p: writers.write_metrics_json(p, metrics)))
        outputs.append(("metrics.md", lambda p: writers.write_metrics_md(p, metrics)))
    named = {"filter_name": filter_name, "log": str(log)}
    if any(fmt in ("tum", "geojson", "kml") for fmt in formats):
        # with xml.sax (and urllib): imported only for the formats it writes
        from .io import exports
    for fmt in formats:
        if fmt == "tum":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_tum(p, sol_out, rec, **named)))
            if forward_out is not None:
                outputs.append((FORWARD_OUTPUTS["tum"], lambda p: exports.write_tum(
                    p, forward_out, rec, filter_name=f"{filter_name} (forward, not smoothed)", log=str(log))))
            outputs.append((exports.labelled_tum_name(log, filter_name),
                            lambda p: exports.write_tum(p, sol_out, rec, **named)))
            if rec.reference is not None and metrics is not None:
                outputs.append((exports.REFERENCE_TUM_FILE, lambda p: exports.write_reference_tum(
                    p, rec.reference, sol_out, rec, compared=compared, **named)))
        elif fmt == "geojson":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_geojson(p, sol_out, rec, metrics=metrics,
                                                                              **named)))
        elif fmt == "kml":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_kml(p, sol_out, rec, metrics=metrics,
                                                                          **named)))
        elif fmt == "mcap":
            from .io.foxglove import LAYOUT_FILE, write_layout

            mounting = (result.calibration or {}).get("gross_mounting_rpy_deg", cfg.imu.mounting_rpy_deg)
            rate_hz = rec.imu.rate_hz
            rate_noise = cfg.imu.noise().gyro_arw * math.sqrt(rate_hz) if math.isfinite(rate_hz) else 0.0
            def write_mcap(p: Path, mounting: Any = mounting, rate_noise: float = rate_noise) -> None:
                skipped = mcap_writer()(
                    p, solution=sol_out, recording=rec, diagnostics=result.diagnostics, biases=biases,
                    embed_input=embed_input, input_log=log, filter_name=filter_name,
                    imu_mounting_rpy_deg=mounting, gnss_lever_arm_m=cfg.gnss.lever_arm_m, rate_noise_std=rate_noise,
                    **({"forward": forward_out} if forward_out is not None else {}))
                if skipped and notes is not None:
                    notes.append(embed_note(skipped))

            outputs.append((FORMAT_FILES[fmt], write_mcap))
            outputs.append((LAYOUT_FILE, lambda p: write_layout(p, result.diagnostics)))
    return outputs


def embed_note(skipped: Sequence[str]) -> str:
    """The run's note on the input topics ``--embed-input`` left out of trajectory.mcap (one line;
    ``skipped``: one ``"TOPIC (TYPE): reason"`` each, as the file's ``embedded_input_skipped``)."""
    n = len(skipped)
    return (f"--embed-input: {n} input topic{'s' if n != 1 else ''} not embedded in trajectory.mcap: "
            + "; ".join(skipped))


def simulate_log(out: str | Path, **spec: Any) -> Path:
    """Simulate a drive and write it as a CSV log directory (see :mod:`navpp.simulate`).

    ``spec`` are :class:`~navpp.simulate.SimulationSpec` fields, the real-world effects too
    (``realism="consumer-car"``, ``mounting_rpy_deg``, ``start_in_motion``, ``gnss_gap_s``, ...);
    with one on, ``realism.json`` (their truth) is written beside the CSV files.
    """
    from .simulate import SimulationSpec, simulate, write_csv_log

    sim = simulate(SimulationSpec(**spec))
    write_csv_log(sim, out)
    return Path(out)


def compile_kernels(filters: Sequence[str] | None = None,
                    progress: Callable[[str], None] | None = None, native: bool = True) -> list[tuple[str, float]]:
    """``navpp compile``: compile (or load from the cache) every kernel group ``filters`` (None:
    all) need, the smoother's, the wheel-odometry aids' and the MCAP/ROS readers', by running
    them on short simulated drives in a temporary directory (:mod:`navpp.jitmode`), once more
    with every long store spilled to disk (its read-only arrays are kernel signatures of their
    own); then, with ``native``, build the native module from numba's cache
    (:mod:`navpp.native`: every signature compiled on this machine, the last step).

    Returns (step, CPU seconds) per step.  Raises :class:`~navpp.errors.ConfigError` when this
    process already runs interpreted.  The native module's step names what was built, or why
    nothing was (no C compiler, say): numba's cache serves the runs then.
    """
    import time

    from . import jitmode, kernel

    if jitmode.decided() is False:
        raise jitmode.interpreted_error()
    if os.environ.get(kernel.ENV_USE, "1").strip() == "0":
        native_why = f"{kernel.ENV_USE}=0"
    else:
        native_why = "" if not native or kernel.without_native() else "this process runs on one already"
    jitmode.apply(True)                 # before the filters' modules are imported
    jitmode.CHOSEN[:] = [jitmode.Choice(True, "navpp compile")]
    filters = tuple(filters) if filters is not None else jitmode.ALL_FILTERS
    from .filters import get_filter

    for name in filters:                # an unknown name: a ConfigError naming it, before any work
        get_filter(name)

    steps: list[tuple[str, float]] = []
    built: list[Any] = []
    with tempfile.TemporaryDirectory(prefix="navpp-compile-") as tmp:
        root = Path(tmp)
        log = simulate_log(root / "drive", duration_s=90.0, still_s=30.0, seed=1)

        def step(name: str, run: Callable[[], Any]) -> None:
            if progress:
                progress(name)
            t0 = time.process_time()
            run()
            steps.append((name, time.process_time() - t0))

        step("ekf, smoother, MCAP writer", lambda: process(
            log, filter_name="ekf", smooth=True, formats="csv,mcap", embed_input=True, out_dir=root / "ekf"))
        step("MCAP and ROS readers", lambda: process(
            root / "ekf" / "trajectory.mcap", filter_name="ekf", write=False, imu_topic="/imu/data",
            gnss_topic="/gnss/fix"))
        for name in filters:
            if name != "ekf":
                step(name, lambda name=name: process(log, filter_name=name, write=False))
        odo = simulate_log(root / "odometry", duration_s=90.0, still_s=30.0, seed=2, odometry=True,
                           odometry_yaw_rate=True)
        for name in filters:
            step(f"{name} with wheel odometry", lambda name=name: process(odo, filter_name=name, write=False))
        step("ekf, smoother, stores spilled to disk", lambda: process(
            log, filter_name="ekf", smooth=True, memory=1 << 12, out_dir=root / "spilled"))
    if native and not native_why:
        from .native import NativeBuildError, build

        try:
            step("native module", lambda: built.append(build(progress)))
            r = built[0]
            native_why = (f"{r.entries} entry points of {r.kernels} kernels"
                          f"{' built' if r.built else ', up to date'}: {r.path}")
        except NativeBuildError as exc:
            steps.append(("native module", 0.0))
            native_why = f"not built: {exc}"
        steps[-1] = (f"native module ({native_why})", steps[-1][1])
    elif native:
        steps.append((f"native module (not built: {native_why})", 0.0))
    return steps
