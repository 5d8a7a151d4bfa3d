"""What the CLI and Python users call: :func:`process` and :func:`simulate_log`.

These functions return result objects and raise :class:`navpp.errors.NavppError` subclasses
with one-line messages; they never print or exit.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .config import Config, check_outages, load_config, parse_formats
from .errors import ConfigError, InputError, NavppError
from .outdir import OutDirLock, input_files, refuse_overwriting_inputs
from .recording import Recording, Solution

CONFIG_IN_LOG_DIR = "navpp.toml"
#: Files navpp writes into an output directory.  After a successful run, any of these that the
#: run did not write (e.g. metrics from an earlier run with a reference, or a trajectory.kml
#: from a run with ``--format kml``) are removed, so the directory never mixes results of
#: different runs.  Only these exact names are touched.
OUTPUT_FILES = ("trajectory.csv", "trajectory_forward.csv", "diagnostics.csv", "metrics.json", "metrics.md",
                "trajectory.mcap", "trajectory.tum", "trajectory.geojson", "trajectory.kml")
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


def companion(log: Path, name: str) -> Path | None:
    """A file that goes with a log: ``name`` inside a log directory; else ``<stem>.<name>``
    beside the log; else ``name`` in the log's directory (shared by the logs there)."""
    candidates = [log / name] if log.is_dir() else []
    candidates += [log.parent / f"{log.stem if log.is_file() else log.name}.{name}", log.parent / name]
    return next((c for c in candidates if c.is_file()), None)


def resolve_config(log: Path, config_path: str | Path | None) -> Config:
    """Explicit ``--config``; else the log's ``navpp.toml`` (:func:`companion`); else defaults."""
    if config_path is not None:
        return load_config(config_path)
    found = companion(log, CONFIG_IN_LOG_DIR)
    return load_config(found)


def read_log(log: str | Path, config: Config, *, reference: str | Path | None = None,
             progress: Callable[[float], None] | None = None, imu_topic: str | None = None,
             gnss_topic: str | None = None, reference_topic: str | None = None,
             gnss_file: str | Path | None = None) -> Recording:
    """Read any supported log into a validated :class:`Recording`.

    CSV log directories, MCAP files (ROS 2 or ROS 1 encoded), ROS 1 bags and ROS 2 bag
    directories; the reader is chosen by content.  ``gnss_file`` (an RTKLIB .pos) replaces or
    supplies the log's GNSS; ``reference`` (a CSV) or ``reference_topic`` gives the reference.
    """
    from dataclasses import replace

    from .io import csv as csv_io
    from .io.detect import log_kind

    path = Path(log)
    kind, where = log_kind(path)
    if kind == "csv":
        if imu_topic or gnss_topic or reference_topic:
            raise ConfigError(f"{path}: --imu-topic, --gnss-topic and --reference-topic apply to ROS logs, "
                              "not to a CSV log")
        rec = csv_io.read_csv_log(where, reference=reference, time_base=config.time.base,
                                  gyro_units=config.imu.gyro_units, accel_units=config.imu.accel_units,
                                  time_offset_s=config.gnss.time_offset_s, progress=progress)
    else:
        rec = _read_ros_log(kind, where, config, imu_topic, gnss_topic, reference_topic, gnss_file is not None)
        if reference is None and reference_topic is None:
            reference = companion(path, csv_io.REFERENCE_FILE)       # e.g. drive.reference.csv
        if reference is not None:
            rec = replace(rec, reference=csv_io.read_reference_csv(reference, rec.t0_ns))
    if gnss_file is not None:
        from .io.rtklib import read_pos

        gnss, warnings, _ = read_pos(gnss_file, time_base=config.time.base, t0_ns=rec.t0_ns)
        if config.gnss.time_offset_s:
            gnss = replace(gnss, t=gnss.t + config.gnss.time_offset_s)
        rec = replace(rec, gnss=gnss, warnings=tuple(rec.warnings) + tuple(warnings))
    return rec


def _read_ros_log(kind: str, path: Path, config: Config, imu_topic: str | None, gnss_topic: str | None,
                  reference_topic: str | None, gnss_from_file: bool) -> Recording:
    from .io.assemble import choose_topic, recording_from_log
    from .io.detect import list_topics, read_topics
    from .io.ros import FIX_TYPE, IMU_TYPE, TWIST_COV_TYPE, TWIST_TYPE, LogContents

    topics = list_topics(kind, path)
    index = LogContents(str(path), topics)
    wanted = [choose_topic(index, IMU_TYPE, "IMU", "--imu-topic", imu_topic)]
    if not gnss_from_file:
        wanted.append(choose_topic(index, FIX_TYPE, "GNSS", "--gnss-topic", gnss_topic,
                                   (reference_topic,) if reference_topic else ()))
        twists = [t.topic for t in topics if t.msgtype in (TWIST_COV_TYPE, TWIST_TYPE)]
        if len(twists) == 1:
            wanted.append(twists[0])
    if reference_topic:
        wanted.append(choose_topic(index, FIX_TYPE, "reference", "--reference-topic", reference_topic))
    contents = read_topics(kind, path, [w for w in wanted if w])
    if gnss_from_file and not any(t.msgtype == FIX_TYPE for t in contents.topics):
        contents = _with_placeholder_fix(contents)
    return recording_from_log(contents, imu_topic=imu_topic, gnss_topic=gnss_topic, reference_topic=reference_topic,
                              time_source=config.time.source, time_base=config.time.base,
                              default_std_m=config.gnss.default_std_m, gyro_scale=config.imu.gyro_scale,
                              accel_scale=config.imu.accel_scale, time_offset_s=config.gnss.time_offset_s)


def _with_placeholder_fix(contents):
    """A log without GNSS whose GNSS comes from --gnss: give the assembler one IMU-timed fix
    so it can build the Recording; the engine then uses the file's fixes."""
    import numpy as np

    from .io.ros import FIX_TYPE, FixMessages, TopicInfo

    imu = next(iter(contents.imu.values()))
    ns = imu.stamp_ns[:1]
    fix = FixMessages("(--gnss)", ns, ns, np.zeros(1, np.int8), np.zeros(1), np.zeros(1), np.zeros(1),
                      np.zeros((1, 9)), np.zeros(1, np.uint8))
    return type(contents)(contents.source, contents.topics + (TopicInfo("(--gnss)", FIX_TYPE, 1),),
                          contents.imu, {"(--gnss)": fix}, contents.twist, contents.warnings)


def make_filter(name: str, config: Config, *, seed: int | None = None):
    """Instantiate a registered filter with its ``[filter.<name>]`` options and the GNSS gate."""
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
    ok = isinstance(rate_hz, (int, float, np.integer, np.floating)) and not isinstance(rate_hz, (bool, np.bool_))
    if not ok or not math.isfinite(float(rate_hz)) or float(rate_hz) <= 0.0:
        raise ConfigError(f"{what} must be a finite number of Hz > 0, got {rate_hz!r}")
    return float(rate_hz)


def resample_solution(sol: Solution, rate_hz: float) -> Solution:
    """The solution at ``rate_hz`` on whole multiples of the period (interpolated).

    Raises :class:`ConfigError` if ``rate_hz`` is not a finite number > 0, or so low that no
    whole multiple of the period falls within the solution's time span.
    """
    from .metrics import interpolate_solution

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
    std = np.column_stack([np.interp(t, sol.t, sol.std_enu[:, i]) for i in range(3)])
    return Solution(t=t, lat_deg=it["lat_deg"], lon_deg=it["lon_deg"], alt=it["alt"], vel_enu=it["vel_enu"],
                    rph_deg=it["rph_deg"], std_enu=std, t0_ns=sol.t0_ns)


def reference_checks(rec: Recording, cfg: Config, metrics: dict | None) -> list[str]:
    """Warn when the raw GNSS disagrees with the reference far beyond its stated sigma: the
    reference is then on another time base or datum, and every figure against it misleads."""
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
    ref_path = reference if reference is not None else companion(log, "reference.csv")
    return input_files(log, cfg_path, ref_path, gnss_file, not_in_dirs=OUTPUT_FILES)


def default_out_dir(log: Path, filter_name: str) -> Path:
    stem = log.name if log.is_dir() else log.stem
    return Path("navpp-out") / f"{stem}-{filter_name}"


def _os_reason(exc: OSError) -> str:
    """An OSError as a short lower-case reason ("permission denied"), without the path."""
    return (exc.strerror or str(exc) or type(exc).__name__).lower()


def _first_non_directory(path: Path) -> Path | None:
    """``path`` or its nearest ancestor that exists but is not a directory, if any."""
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return None if p.is_dir() else p
    return None


def prepare_out_dir(out: Path, label: str) -> list[Path]:
    """Create ``out`` (with parents) and prove it is writable by creating and removing a file.

    Returns the directories this call created (outermost first), so that a run that fails
    later can remove them again.  Raises :class:`InputError` ``"<label> <out>: cannot write
    there (<reason>)"``.
    """
    missing = [p for p in (out, *out.parents) if not (p.exists() or p.is_symlink())][::-1]
    try:
        blocker = _first_non_directory(out)
        if blocker is not None:
            what = "it is" if blocker == out else f"{blocker} is"
            kind = "a broken symbolic link" if not blocker.exists() else "a file, not a directory"
            raise InputError(f"{label} {out}: cannot write there ({what} {kind})")
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".navpp-write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        remove_created_dirs(missing)
        raise InputError(f"{label} {out}: cannot write there ({_os_reason(exc)})") from None
    return missing


def remove_created_dirs(created: list[Path]) -> None:
    """Remove the (still empty) directories :func:`prepare_out_dir` created, innermost first."""
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            break


def _write_file(path: Path, write: Callable[[], None]) -> Path:
    try:
        write()
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({_os_reason(exc)})") from None
    return path


def write_outputs(out: Path, outputs: Sequence[tuple[str, Callable[[Path], None]]],
                  inputs: set[tuple[int, int]] = frozenset()) -> list[Path]:
    """Write a run's files into ``out`` all together, then remove its stale :data:`OUTPUT_FILES`.

    Each ``(name, write)`` is called as ``write(path)`` on a path inside a hidden staging
    directory in ``out``; only when every writer has succeeded are the files renamed to
    ``out / name`` (keeping the permissions of a file they replace).  If any writer fails or
    the run is interrupted, nothing in ``out`` changes: the previous run's outputs stay whole
    and consistent with each other.  The staging directory is always removed.

    Stale outputs are the :data:`OUTPUT_FILES` of an earlier run that this one did not write;
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
        raise InputError(f"{out}: cannot write there ({_os_reason(exc)})") from None
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
                    raise InputError(f"{target}: cannot write ({_os_reason(exc)})") from None
                written.append(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    ours = outdir.read_manifest(out)
    for name in OUTPUT_FILES:          # stale results of an earlier navpp run: not ours any more
        stale = out / name
        if (stale not in written and name in ours and stale.is_file() and not stale.is_symlink()
                and not outdir.is_input(stale, inputs)):
            try:
                stale.unlink()
            except OSError as exc:
                raise InputError(f"{stale}: cannot remove this output of an earlier run "
                                 f"({_os_reason(exc)})") from None
    try:
        outdir.write_manifest(out, {p.name for p in written} | {n for n in ours if (out / n).exists()})
    except OSError as exc:
        raise InputError(f"{out / outdir.MANIFEST_NAME}: cannot write ({_os_reason(exc)})") from None
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


def _mcap_writer() -> Callable[..., None]:
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
            smooth: bool | None = None) -> ProcessResult:
    """Read a log, run one filter, write trajectory (and metrics with a reference).

    ``navpp.process`` is this function.  Example::

        res = navpp.process("drive.mcap", filter_name="aekf", formats=["csv", "tum"])
        res.trajectory          # pandas.DataFrame, trajectory.csv's columns
        res.metrics             # dict as metrics.json, or None without a reference

    Parameters
    ----------
    log : a CSV log directory (imu.csv, gnss.csv, optional reference.csv), an MCAP file, a
        ROS 1 bag or a ROS 2 bag directory.
    imu_topic, gnss_topic, reference_topic : topic choices for ROS logs (see :func:`read_log`).
    gnss_file : an RTKLIB .pos file replacing or supplying the log's GNSS.
    filter_name : registry name (``navpp filters``).
    config : a TOML path or a :class:`Config`; None looks for ``navpp.toml`` in the log
        directory, then uses the defaults (automotive preset).
    reference : reference CSV overriding ``reference.csv`` in the log directory.
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

    Returns
    -------
    ProcessResult : with ``trajectory`` and ``diagnostics`` as pandas DataFrames and
        ``metrics`` as a dict (None without a reference).

    Raises
    ------
    NavppError : ConfigError for bad options or config (unknown formats, ``embed_input``
        without ``mcap``), InputError for unreadable input or unwritable output,
        FilterDivergedError when the filter diverges; each with a one-line message.
    """
    from . import engine

    log = Path(log)
    cfg = config if isinstance(config, Config) else resolve_config(log, config)
    if output_rate_hz is not None:
        rate, rate_what = check_output_rate(output_rate_hz), "--output-rate"
    else:
        rate, rate_what = cfg.output.rate_hz, f"{cfg.source}: [output] rate_hz"
        if rate is not None:
            rate = check_output_rate(rate, rate_what)
    chosen_formats = check_formats(formats, embed_input, cfg)
    if write and "mcap" in chosen_formats:
        _mcap_writer()                # before the run: not available is a ConfigError now, not after it
    windows = (check_outages(gnss_outages, "gnss_outages") if gnss_outages is not None
               else cfg.gnss.outages)
    smooth = cfg.output.smooth if smooth is None else bool(smooth)
    filt = make_filter(filter_name, cfg)
    out = Path(out_dir) if out_dir is not None else default_out_dir(log, filter_name)
    label = "--out" if out_dir is not None else "output directory"
    inputs: set[tuple[int, int]] = set()
    if write:        # before anything is created or read: a run whose result would replace its own input
        inputs = run_inputs(log, config, reference, gnss_file)
        refuse_overwriting_inputs(out, [FORMAT_FILES[f] for f in chosen_formats] + list(OUTPUT_FILES[1:5]),
                                  inputs, label)
    created = prepare_out_dir(out, label) if write else []
    lock = OutDirLock(out, label, extra_leftovers=OUTPUT_FILES) if write else None
    try:
        if lock is not None:          # held until the files are written: a second run into out fails at once
            lock.acquire()
        if progress:
            progress("reading", 0.0)
        rec = read_log(log, cfg, reference=reference,
                       progress=(lambda f: progress("reading", f)) if progress else None, imu_topic=imu_topic,
                       gnss_topic=gnss_topic, reference_topic=reference_topic, gnss_file=gnss_file)
        if progress:
            progress("reading", 1.0)
        rec, outages = apply_outages(rec, windows, str(log))
        imu_rate = rec.imu.rate_hz
        # 0.1 % slack: the IMU rate is a median of stamp differences (jitter, stamp rounding)
        if rate is not None and rate > imu_rate * 1.001:
            raise ConfigError(f"{rate_what} {rate:g} Hz is above the IMU rate of {log} ({imu_rate:.1f} Hz); "
                              "the trajectory cannot be finer than the IMU")
        try:
            result = engine.run(rec, cfg, filt, progress=(lambda f: progress("filtering", f)) if progress else None,
                                smooth=smooth)
        except NavppError as exc:
            cut = [w for w in rec.warnings if "the recording is cut off" in w]
            if cut:       # the likely reason: say it in the one line
                raise type(exc)(f"{exc} ({cut[0]})") from None
            raise
        runtime = result.runtime_s        # without the one-off kernel compilation of a first run
        sol = result.smoothed.solution if smooth else result.solution
        sol_out = resample_solution(sol, rate) if rate is not None else sol
        fwd_out = None
        if smooth:
            fwd_out = resample_solution(result.solution, rate) if rate is not None else result.solution

        removed = [o["gnss_removed"] for o in outages]
        metrics = run_metrics(rec, cfg, result, sol, filter_name=filter_name, log=str(log), runtime_s=runtime,
                              windows=windows, removed=removed)
        if metrics is not None and result.calibration:
            metrics["calibration"] = result.calibration
        if metrics is not None and smooth:
            forward = run_metrics(rec, cfg, result, result.solution, filter_name=filter_name, log=str(log),
                                  runtime_s=result.forward_runtime_s, windows=windows, removed=removed)
            metrics = smoothing_metrics(metrics, forward, result.smoothed)

        files: list[Path] = []
        if write:
            outputs = _outputs(chosen_formats, log=log, rec=rec, sol_out=sol_out, result=result, metrics=metrics,
                               filter_name=filter_name, embed_input=embed_input, forward_out=fwd_out)
            files = write_outputs(out, outputs, inputs)
    except BaseException:
        if lock is not None:
            lock.release()
        remove_created_dirs(created)
        raise
    if lock is not None:
        lock.release()
    notes = tuple(cfg.notes) + tuple(result.notes) + tuple(result.alignment.lines) + tuple(
        f"GNSS outage {o['start_s']:g}-{o['end_s']:g} s ({o['duration_s']:g} s from the log start): "
        f"{o['gnss_removed']} fixes removed, the INS coasts" for o in outages)
    warnings = (tuple(rec.warnings) + tuple(result.warnings) + tuple(forced_fix_warnings(rec, cfg, result))
                + tuple(reference_checks(rec, cfg, metrics)))
    if smooth:
        notes += (f"smoothed backwards (Rauch-Tung-Striebel) over {result.smoothed.nodes} forward nodes in "
                  f"{result.smoothed.runtime_s:.2f} s; trajectory_forward.csv holds the forward solution",)
    return ProcessResult(filter_name, rec, sol_out, result, metrics, out, tuple(files), cfg, notes, warnings,
                         tuple(outages), fwd_out)


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


def apply_outages(rec: Recording, windows: Sequence[tuple[float, float]],
                  label: str) -> tuple[Recording, list[dict]]:
    """Remove the GNSS fixes inside simulated outage windows.

    Parameters
    ----------
    rec : the recording; its times are s from the log start (the first IMU sample).
    windows : validated ``(start_s, duration_s)`` pairs (:func:`navpp.config.check_outages`).
    label : how the log is named in error messages.

    Returns
    -------
    The recording without the fixes at ``start <= t <= start + duration`` of any window (its
    IMU and reference untouched), and one dict per window: ``start_s``, ``duration_s``,
    ``end_s``, ``gnss_removed`` (fixes inside that window; overlapping windows count a fix in each).

    Raises
    ------
    InputError
        A window that does not lie inside the log's IMU span: one starting after the log's end,
        or one running past it (not clipped: the outage metrics are read as the error after
        ``duration`` s without GNSS; the message gives the longest window that fits).
    """
    from dataclasses import fields, replace

    if not windows:
        return rec, []
    t_end = float(rec.imu.t[-1]) if len(rec.imu) else 0.0
    t = np.asarray(rec.gnss.t, dtype=float)
    drop = np.zeros(t.shape, bool)
    info = []
    for start, dur in windows:
        end = start + dur
        if start >= t_end:
            raise InputError(f"{label}: GNSS outage {start:g}:{dur:g} ({start:g}-{end:g} s) starts after the log "
                             f"ends: it spans 0-{t_end:.3f} s from its first IMU sample")
        if end > t_end + 1e-9:
            # not clipped: the outage metrics are read as "error after DUR s without GNSS"
            raise InputError(f"{label}: GNSS outage {start:g}:{dur:g} ({start:g}-{end:g} s) runs past the end of "
                             f"the log at {t_end:.3f} s (from its first IMU sample); the longest outage from "
                             f"{start:g} s is {start:g}:{math.floor((t_end - start) * 1000) / 1000:g}")
        inside = (t >= start) & (t <= end)
        drop |= inside
        info.append({"start_s": float(start), "duration_s": float(dur), "end_s": float(end),
                     "gnss_removed": int(np.count_nonzero(inside))})
    if drop.any():
        keep = ~drop
        g = rec.gnss
        cut = {f.name: np.asarray(getattr(g, f.name))[keep] for f in fields(g)
               if isinstance(getattr(g, f.name), np.ndarray) and getattr(g, f.name).shape[:1] == t.shape}
        rec = replace(rec, gnss=replace(g, **cut))
    return rec, info


#: At most this many times are named in the forced-fix warning.
FORCED_TIMES_SHOWN = 8


def forced_fix_warnings(rec: Recording, cfg: Config, result: Any) -> list[str]:
    """A warning when fixes were forced through the gate after a long run of rejections.

    The filter then re-anchors its position covariance on the fix (it takes itself, not the
    GNSS, to be wrong), and the trajectory may jump there: the user should know when.
    """
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
             forward_out: Solution | None = None) -> list[tuple[str, Callable[[Path], None]]]:
    """``(file name, writer(path))`` for every file of a run, in the order they are listed.
    ``forward_out``: the forward solution of a smoothed run (``sol_out`` is then the smoothed one)."""
    from .io import exports, writers

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
    for fmt in formats:
        if fmt == "tum":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_tum(p, sol_out, rec, **named)))
        elif fmt == "geojson":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_geojson(p, sol_out, rec, metrics=metrics,
                                                                              **named)))
        elif fmt == "kml":
            outputs.append((FORMAT_FILES[fmt], lambda p: exports.write_kml(p, sol_out, rec, metrics=metrics,
                                                                          **named)))
        elif fmt == "mcap":
            outputs.append((FORMAT_FILES[fmt], lambda p: _mcap_writer()(
                p, solution=sol_out, recording=rec, diagnostics=result.diagnostics, biases=biases,
                embed_input=embed_input, input_log=log, filter_name=filter_name,
                **({"forward": forward_out} if forward_out is not None else {}))))
    return outputs


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


@dataclass(frozen=True)
class StreamSummary:
    """One row of ``navpp inspect``: a topic (ROS logs) or a file (CSV logs)."""

    name: str
    msgtype: str
    count: int
    rate_hz: float | None
    first_s: float | None            # absolute stamps, s on the log's time base
    last_s: float | None
    gaps: int                        # intervals longer than 3 nominal periods
    largest_gap_s: float | None
    duplicates: int                  # repeated stamps
    role: str


def _stream_stats(stamps_ns) -> tuple[float | None, float | None, float | None, int, float | None, int]:
    import numpy as np

    t = np.asarray(stamps_ns, dtype=np.int64)
    if t.size == 0:
        return None, None, None, 0, None, 0
    first, last = t[0] * 1e-9, t[-1] * 1e-9
    if t.size < 2:
        return None, first, last, 0, None, 0
    d = np.diff(t) * 1e-9
    dup = int(np.count_nonzero(d == 0))
    pos = d[d > 0]
    if pos.size == 0:
        return None, first, last, 0, None, dup
    nominal = float(np.median(pos))
    gaps = d > 3.0 * nominal
    return (1.0 / nominal, first, last, int(np.count_nonzero(gaps)),
            float(d[gaps].max()) if gaps.any() else None, dup)


def inspect(log: str | Path, *, config: str | Path | Config | None = None
            ) -> tuple[str, list[StreamSummary], tuple[str, ...]]:
    """What a log holds and the role navpp would give each stream: (kind, rows, reader warnings)."""
    import numpy as np
    import pandas as pd

    from .io.detect import list_topics, log_kind, read_topics
    from .io.ros import FIX_TYPE, IMU_TYPE, SUPPORTED_TYPES, TWIST_COV_TYPE, TWIST_TYPE

    path = Path(log)
    kind, where = log_kind(path)
    rows: list[StreamSummary] = []
    if kind == "csv":
        roles = {"imu.csv": "IMU", "gnss.csv": "GNSS", "reference.csv": "reference"}
        for name, role in roles.items():
            f = where / name
            if not f.is_file():
                continue
            from .io.csv import prescan
            prescan(f)      # NUL bytes, overlong lines: refused before pandas holds them in memory
            try:
                t = pd.read_csv(f, usecols=["t"], dtype={"t": float}, engine="c")["t"].to_numpy()
                ns = np.round(t * 1e9).astype(np.int64)
            except (ValueError, KeyError) as exc:
                raise InputError(f"{f}: cannot read column 't': {exc}") from None
            columns = ", ".join(pd.read_csv(f, nrows=0).columns)
            rate, first, last, gaps, largest, dup = _stream_stats(ns)
            rows.append(StreamSummary(name, columns, int(ns.size), rate, first, last, gaps, largest, dup, role))
        return kind, rows, ()
    topics = list_topics(kind, where)
    wanted = [t.topic for t in topics if t.msgtype in SUPPORTED_TYPES]
    contents = read_topics(kind, where, wanted)
    n_imu = sum(t.msgtype == IMU_TYPE for t in topics)
    n_fix = sum(t.msgtype == FIX_TYPE for t in topics)
    n_twist = sum(t.msgtype in (TWIST_COV_TYPE, TWIST_TYPE) for t in topics)
    for t in topics:
        msgs = contents.imu.get(t.topic) or contents.fix.get(t.topic) or contents.twist.get(t.topic)
        if msgs is not None:
            rate, first, last, gaps, largest, dup = _stream_stats(msgs.stamp_ns)
        else:
            rate = (t.count - 1) / ((t.last_ns - t.first_ns) * 1e-9) if (t.first_ns is not None and t.last_ns
                                                                          and t.last_ns > t.first_ns) else None
            first = t.first_ns * 1e-9 if t.first_ns is not None else None
            last = t.last_ns * 1e-9 if t.last_ns is not None else None
            gaps, largest, dup = 0, None, 0
        if t.msgtype == IMU_TYPE:
            role = "IMU" if n_imu == 1 else "IMU? (choose with --imu-topic)"
        elif t.msgtype == FIX_TYPE:
            role = "GNSS" if n_fix == 1 else "GNSS or reference? (--gnss-topic / --reference-topic)"
        elif t.msgtype in (TWIST_COV_TYPE, TWIST_TYPE):
            role = "GNSS velocity" if n_twist == 1 else "not used (several velocity topics)"
        else:
            role = ""
        rows.append(StreamSummary(t.topic, t.msgtype, t.count, rate, first, last, gaps, largest, dup, role))
    return kind, rows, tuple(contents.warnings)
