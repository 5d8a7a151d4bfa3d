"""What the CLI and Python users call: :func:`process` and :func:`simulate_log`.

These functions return result objects and raise :class:`navpp.errors.NavppError` subclasses
with one-line messages; they never print or exit.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .config import Config, load_config
from .errors import ConfigError, InputError
from .recording import Recording, Solution

CONFIG_IN_LOG_DIR = "navpp.toml"
#: Files navpp writes into an output directory.  After a successful run, any of these that the
#: run did not write (e.g. metrics from an earlier run with a reference) are removed, so the
#: directory never mixes results of different runs.  Only these exact names are touched.
OUTPUT_FILES = ("trajectory.csv", "metrics.json", "metrics.md")


@dataclass(frozen=True)
class ProcessResult:
    """Outcome of :func:`process`: the solution, metrics (None without a reference), files."""

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


def resolve_config(log: Path, config_path: str | Path | None) -> Config:
    """Explicit ``--config``; else ``navpp.toml`` beside/inside the log; else built-in defaults."""
    if config_path is not None:
        return load_config(config_path)
    base = log if log.is_dir() else log.parent
    candidate = base / CONFIG_IN_LOG_DIR
    if candidate.is_file():
        cfg = load_config(candidate)
        return cfg
    return load_config(None)


def read_log(log: str | Path, config: Config, *, reference: str | Path | None = None,
             progress: Callable[[float], None] | None = None) -> Recording:
    """Read any supported log into a validated :class:`Recording`."""
    from .io import csv as csv_io

    path = Path(log)
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    if csv_io.is_csv_log(path):
        return csv_io.read_csv_log(path, reference=reference, time_base=config.time.base,
                                   gyro_units=config.imu.gyro_units, accel_units=config.imu.accel_units,
                                   time_offset_s=config.gnss.time_offset_s, progress=progress)
    if path.is_dir():
        present = [name for name in (csv_io.IMU_FILE, csv_io.GNSS_FILE) if (path / name).is_file()]
        if len(present) == 1:  # half a CSV log: name the file that is missing
            missing = csv_io.GNSS_FILE if present[0] == csv_io.IMU_FILE else csv_io.IMU_FILE
            raise InputError(f"{path / missing}: file not found (a CSV log needs {csv_io.IMU_FILE} and "
                             f"{csv_io.GNSS_FILE})")
        raise InputError(f"{path}: not a navpp log directory (expected imu.csv and gnss.csv inside)")
    raise InputError(f"{path}: unsupported log format {path.suffix or '(no suffix)'!r}; this version reads "
                     "CSV log directories (imu.csv + gnss.csv)")


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
        return [f"{metrics['reference']}: the raw GNSS fixes are {raw['rmse']:.1f} m (horizontal RMSE) from the "
                f"reference, {raw['rmse'] / expected:.0f} times their stated 1-sigma: the reference is probably on "
                "another time base or datum, and the figures against it mislead"]
    return []


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


def process(log: str | Path, *, filter_name: str = "ekf", config: str | Path | Config | None = None,
            reference: str | Path | None = None, out_dir: str | Path | None = None,
            output_rate_hz: float | None = None, progress: Callable[[str, float], None] | None = None,
            write: bool = True) -> ProcessResult:
    """Read a log, run one filter, write trajectory (and metrics with a reference).

    Parameters
    ----------
    log : a CSV log directory (imu.csv, gnss.csv, optional reference.csv).
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
    """
    from . import engine
    from .io import writers
    from .metrics import compute_metrics

    log = Path(log)
    cfg = config if isinstance(config, Config) else resolve_config(log, config)
    if output_rate_hz is not None:
        rate, rate_what = check_output_rate(output_rate_hz), "--output-rate"
    else:
        rate, rate_what = cfg.output.rate_hz, f"{cfg.source}: [output] rate_hz"
        if rate is not None:
            rate = check_output_rate(rate, rate_what)
    filt = make_filter(filter_name, cfg)
    out = Path(out_dir) if out_dir is not None else default_out_dir(log, filter_name)
    created = prepare_out_dir(out, "--out" if out_dir is not None else "output directory") if write else []
    try:
        if progress:
            progress("reading", 0.0)
        rec = read_log(log, cfg, reference=reference,
                       progress=(lambda f: progress("reading", f)) if progress else None)
        if progress:
            progress("reading", 1.0)
        imu_rate = rec.imu.rate_hz
        # 0.1 % slack: the IMU rate is a median of stamp differences (jitter, stamp rounding)
        if rate is not None and rate > imu_rate * 1.001:
            raise ConfigError(f"{rate_what} {rate:g} Hz is above the IMU rate of {log} ({imu_rate:.1f} Hz); "
                              "the trajectory cannot be finer than the IMU")
        result = engine.run(rec, cfg, filt, progress=(lambda f: progress("filtering", f)) if progress else None)
        runtime = result.runtime_s        # without the one-off kernel compilation of a first run
        sol = result.solution
        sol_out = resample_solution(sol, rate) if rate is not None else sol

        metrics = None
        if rec.reference is not None:
            metrics = compute_metrics(
                sol, rec.reference, filter_name=filter_name, log=str(log), reference=rec.reference.source or "",
                runtime_s=runtime, imu_samples=len(rec.imu), gnss_epochs=result.gnss_epochs,
                gnss_rejected=result.gnss_rejected, gnss=rec.gnss, lever_arm_m=cfg.gnss.lever_arm_m)

        files: list[Path] = []
        if write:
            files.append(_write_file(out / "trajectory.csv", lambda: writers.write_trajectory_csv(
                out / "trajectory.csv", sol_out, t0_s=rec.t0_ns * 1e-9)))
            if metrics is not None:
                files.append(_write_file(out / "metrics.json",
                                         lambda: writers.write_metrics_json(out / "metrics.json", metrics)))
                files.append(_write_file(out / "metrics.md",
                                         lambda: writers.write_metrics_md(out / "metrics.md", metrics)))
            for name in OUTPUT_FILES:          # stale results of an earlier run: not ours any more
                stale = out / name
                if stale not in files and stale.is_file():
                    try:
                        stale.unlink()
                    except OSError as exc:
                        raise InputError(f"{stale}: cannot remove this output of an earlier run "
                                         f"({_os_reason(exc)})") from None
    except BaseException:
        remove_created_dirs(created)
        raise
    notes = tuple(cfg.notes) + tuple(result.alignment.lines)
    warnings = tuple(rec.warnings) + tuple(result.warnings) + tuple(reference_checks(rec, cfg, metrics))
    return ProcessResult(filter_name, rec, sol_out, result, metrics, out, tuple(files), cfg, notes, warnings)


def simulate_log(out: str | Path, **spec: Any) -> Path:
    """Simulate a drive and write it as a CSV log directory (see :mod:`navpp.simulate`)."""
    from .simulate import SimulationSpec, simulate, write_csv_log

    sim = simulate(SimulationSpec(**spec))
    write_csv_log(sim, out)
    return Path(out)
