"""navpp command line: a thin Typer app over :mod:`navpp.api`.

Heavy modules (numpy, numba, pandas) are imported inside the commands so ``navpp --help``
answers at once.  Every :class:`navpp.errors.NavppError` becomes one line on stderr and exit
code 1.  Usage errors exit with 2 (Typer/Click): options that cannot be parsed, and option
values that are invalid whatever the data (``--output-rate 0``, ``--seed -1``), which the
option callbacks below reject as ``Error: Invalid value for '--option': must be ..., got ...``.
Problems that depend on the data (an ``--output-rate`` above the log's IMU rate, an ``--out``
directory that cannot be written) are processing errors: one line, exit code 1.

Help and usage errors are plain Click text (``rich_markup_mode=None``): rich markup would eat
bracketed text such as ``[default: ...]`` and ``[init]``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Annotated

import typer

from .cli_print import note, print_compare_details, print_comparison, print_process_summary, process_details
from .cli_values import install as install_plain_values


class _Group(typer.core.TyperGroup):
    """navpp's command group: it and the command about to run coerce their plain option values
    themselves (:mod:`navpp.cli_values`: no pydantic on a run's start), the rest as typer does."""

    def parse_args(self, ctx, args):
        install_plain_values(self, ctx)
        return super().parse_args(ctx, args)

    def resolve_command(self, ctx, args):
        name, command, rest = super().resolve_command(ctx, args)
        if command is not None:       # its --help option is named as the group's (ctx.help_option_names)
            install_plain_values(command, ctx)
        return name, command, rest


app = typer.Typer(
    cls=_Group, no_args_is_help=True, pretty_exceptions_enable=False, rich_markup_mode=None,
    help="Post-process inertial navigation logs: strapdown INS + loosely coupled GNSS filters.",
)


def _version(value: bool) -> None:
    """``--version``: the package version (:mod:`navpp.version`), then exit 0."""
    if value:
        from .version import __version__

        typer.echo(f"navpp {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print navpp's version and exit.")] = False,
) -> None:
    """Post-process inertial navigation logs: strapdown INS + loosely coupled GNSS filters."""


def _fail(message: str, exc: BaseException | None = None) -> None:
    """One error line and exit 1; what the run had warned about and noted before it failed
    (``exc.warnings``, ``exc.notes``) is printed first, since it often names the cause."""
    from rich.console import Console
    from rich.markup import escape

    from .interrupts import Interrupted, committed, received

    if received() is not None and not committed():   # a signal surfaced as this error (e.g. inside numba)
        raise Interrupted(received())
    err = Console(stderr=True, highlight=False, soft_wrap=True)
    for line in getattr(exc, "warnings", ()):
        err.print(f"[yellow]warning:[/] {escape(line)}")
    for line in getattr(exc, "notes", ()):
        note(err, line)
    # escape: messages name config sections such as "[init]", which rich would eat as markup
    err.print(f"[bold red]navpp: error:[/] {escape(message)}")
    raise typer.Exit(1)


def _show(value) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value)


def _require(ok: Callable[[object], bool], requirement: str) -> Callable:
    """Option callback: a usage error (exit 2) naming the option unless ``ok(value)``."""

    def callback(value):
        if value is not None and not ok(value):
            raise typer.BadParameter(f"must be {requirement}, got {_show(value)}")
        return value

    return callback


def _finite(lo: float, hi: float = math.inf, *, strict: bool = False) -> Callable[[float], bool]:
    return lambda v: math.isfinite(v) and (v > lo if strict else v >= lo) and v <= hi


class _Progress:
    """Rich progress bars on stderr, one task per stage; only on a terminal, never with --quiet."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar = None
        self.tasks: dict[str, int] = {}
        self.marks: dict[str, list[float]] = {}     # stage -> [first call, last call], perf_counter s (--verbose)

    def __enter__(self):
        if self.quiet:
            return self                 # no bars: rich is not even imported
        from rich.console import Console

        console = Console(stderr=True)
        if console.is_terminal:
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(TextColumn("{task.description:<10}"), BarColumn(),
                                TextColumn("{task.percentage:>3.0f}%"), TimeElapsedColumn(), console=console,
                                transient=True)
            self.bar.__enter__()
        return self

    def __call__(self, stage: str, fraction: float) -> None:
        import time

        now = time.perf_counter()
        self.marks.setdefault(stage, [now, now])[1] = now
        if self.bar is None:
            return
        if stage not in self.tasks:
            self.tasks[stage] = self.bar.add_task(stage, total=1.0)
        self.bar.update(self.tasks[stage], completed=fraction)

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)

    def say(self, line: str) -> None:
        """One line on stderr, above the bars when they are shown (also with --quiet)."""
        if self.bar is not None:
            from rich.markup import escape

            self.bar.console.print(f"[dim]·[/] {escape(line)}", highlight=False)
        else:
            sys.stderr.write(f"· {line}\n")
            sys.stderr.flush()


def _process_formats(value: str | None) -> tuple[str, ...] | None:
    """``--format`` callback: the names as a tuple; a usage error (exit 2) listing the valid ones."""
    if value is None:
        return None
    from .config import parse_formats
    from .errors import ConfigError

    try:
        return parse_formats(value, "--format")
    except ConfigError as exc:
        raise typer.BadParameter(str(exc).removeprefix("--format: ")) from None


def _gnss_outages(values: list[str] | None) -> tuple[tuple[float, float], ...] | None:
    """``--gnss-outage START:DUR`` callback: ``((start_s, duration_s), ...)``; a usage error (exit 2)
    unless START is a finite number >= 0 and DUR one > 0 (s)."""
    if not values:
        return None
    from .config import check_outages
    from .errors import ConfigError

    pairs = []
    for text in values:
        parts = text.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            pairs.append((float(parts[0]), float(parts[1])))
        except ValueError:
            raise typer.BadParameter(f"must be START:DURATION in seconds from the log start (e.g. 120:30), "
                                     f"got {text!r}") from None
    try:
        return check_outages(pairs, "--gnss-outage")
    except ConfigError as exc:
        raise typer.BadParameter(str(exc).removeprefix("--gnss-outage: ")) from None


def _filter_names(incomplete: str) -> list[str]:
    """Shell completion of ``--filter``: the registered filter names starting with ``incomplete``."""
    from .filters import FILTERS

    return [name for name in sorted(FILTERS) if name.startswith(incomplete)]


@app.command()
def process(
    log: Annotated[Path, typer.Argument(metavar="LOG", help="Log: an MCAP file, a ROS 1 bag, a ROS 2 bag directory, "
                                        "or a directory with imu.csv and gnss.csv (reference.csv optional).")],
    filter: Annotated[str, typer.Option("--filter", "-f", help="Filter name (see `navpp filters`).",
                                        autocompletion=_filter_names)] = "ekf",
    config: Annotated[Path | None, typer.Option(help="TOML config; default: navpp.toml in the log directory, "
                                                   "else the automotive preset.")] = None,
    reference: Annotated[Path | None, typer.Option(help="Reference CSV (t, lat, lon, alt[, ve, vn, vu, roll, "
                                                      "pitch, heading]) or TUM file (t x y z qx qy qz qw, local "
                                                      "ENU: see --reference-anchor); overrides reference.csv.")] = None,
    reference_anchor: Annotated[str | None, typer.Option(
        metavar="LAT,LON,ALT", help="Origin of a TUM or Odometry/PoseStamped reference's local ENU frame: deg, deg, "
        "m above the WGS-84 ellipsoid.  [default: the anchor navpp's own trajectory.tum / trajectory.mcap "
        "record]")] = None,
    imu_topic: Annotated[str | None, typer.Option(
        help="IMU topic (sensor_msgs/Imu) when a ROS log has several.")] = None,
    gnss_topic: Annotated[str | None, typer.Option(
        help="GNSS topic (sensor_msgs/NavSatFix) when a ROS log has several.")] = None,
    reference_topic: Annotated[str | None, typer.Option(
        help="A topic of the log to use as the reference: NavSatFix (e.g. a DGPS receiver), or nav_msgs/Odometry "
             "or geometry_msgs/PoseStamped in a local ENU frame (see --reference-anchor).")] = None,
    odometry_topic: Annotated[str | None, typer.Option(
        help="Wheel odometry topic (nav_msgs/Odometry, TwistStamped or TwistWithCovarianceStamped in the vehicle "
             "frame), or none for no odometry.  [default: chosen by frame and rate; the notes say which]")] = None,
    gnss: Annotated[Path | None, typer.Option(
        "--gnss", help="RTKLIB solution file (.pos) replacing or supplying the log's GNSS.")] = None,
    out: Annotated[Path | None, typer.Option(
        help="Output directory, created if needed.  [default: navpp-out/<log>-<filter>]")] = None,
    output_rate: Annotated[float | None, typer.Option(
        help="Trajectory rate in Hz, at most the IMU rate.  [default: every IMU sample]",
        callback=_require(_finite(0.0, strict=True), "a finite number of Hz > 0"))] = None,
    formats: Annotated[str | None, typer.Option(
        "--format", callback=_process_formats,
        help="Trajectory files, comma separated: csv (trajectory.csv), mcap, tum (for evo), geojson, kml; "
             "diagnostics.csv is always written.  [default: [output] formats of the config, else csv]")] = None,
    embed_input: Annotated[bool, typer.Option(
        "--embed-input", help="Copy the input log's messages into trajectory.mcap (needs mcap in --format).")] = False,
    gnss_outage: Annotated[list[str] | None, typer.Option(
        "--gnss-outage", metavar="START:DUR", callback=_gnss_outages,
        help="Simulate a GNSS outage: drop the fixes from START for DUR seconds (s from the log start, the "
             "first IMU sample); repeatable.  The metrics report each window.  [default: [gnss] outages]")] = None,
    smooth: Annotated[bool | None, typer.Option(
        "--smooth/--no-smooth", help="Smooth the forward run backwards (Rauch-Tung-Striebel): the trajectory files "
        "hold the smoothed trajectory, trajectory_forward.csv/.tum (and the MCAP's forward topics) the forward one, "
        "the metrics show both.  "
        "[default: [output] smooth, else off]", show_default=False)] = None,
    memory: Annotated[str | None, typer.Option(
        "--memory", metavar="SIZE", help="Memory the smoother's stored forward run and the IMU-rate output may each "
        "hold (500MB, 1GB, 2G; binary units); beyond it they go to a temporary file in $TMPDIR, deleted at the end.  "
        "[default: [output] memory, else 64MB]", show_default=False)] = None,
    plot: Annotated[bool, typer.Option(
        "--plot", help="Also write figures beside the outputs: <log>_<filter>_errors.png (error per axis with the "
                       "±3σ band, outages, rejected fixes; without a reference <log>_<filter>_innovations.png), "
                       "<log>_trajectory.png, <log>_adaptive.png and the zoomable overview map <log>_map.html.")
    ] = False,
    jit: Annotated[str | None, typer.Option(
        "--jit", metavar="auto|on|off", help="Compile navpp's kernels (on), run them as plain Python (off), or "
        "choose by the log's size and what is cached (auto: interpreted when that is cheaper than compiling; "
        "see `navpp compile`).  [default: $NAVPP_JIT, else auto]",
        callback=_require(lambda v: v is None or v.lower() in ("auto", "on", "off"), "auto, on or off"))] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars, notes or summary (warnings about "
                                        "the data are still printed).")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Also print where the config, reference and "
                                          "odometry came from, the config keys that differ from the defaults, "
                                          "the time of each stage and the size of each file written.")] = False,
) -> None:
    """Process one log with one filter; write trajectory.csv or the --format files, diagnostics.csv,
    and metrics with a reference."""
    from .errors import NavppError

    if embed_input and formats is not None and "mcap" not in formats:
        raise typer.BadParameter(f"needs mcap among --format (got {','.join(formats)}), e.g. --format "
                                 f"{','.join((*formats, 'mcap'))}", param_hint="'--embed-input'")
    import time

    t_start = time.perf_counter()
    try:
        from . import api, jitmode
        from .jitcache import CompileAnnouncer

        with _Progress(quiet) as prog, CompileAnnouncer(prog.say) as announcer:
            res = api.process(log, filter_name=filter, config=config, reference=reference, out_dir=out,
                              output_rate_hz=output_rate, progress=prog, imu_topic=imu_topic,
                              gnss_topic=gnss_topic, reference_topic=reference_topic, gnss_file=gnss,
                              formats=formats, embed_input=embed_input, gnss_outages=gnss_outage, smooth=smooth,
                              odometry_topic=odometry_topic, reference_anchor=reference_anchor,
                              plot=plot, jit=jitmode.requested(jit, "auto"), memory=memory)
    except NavppError as exc:
        _fail(str(exc), exc)
        return
    print_process_summary(res, quiet, process_details(res, prog.marks, t_start, time.perf_counter()) if verbose else [],
                          compile_s=announcer.seconds)
    from rich.console import Console

    from .kernel import native_hint
    from .native import build_due, build_in_child

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    if announcer.kernels and build_due():       # this run compiled: the native module too, once
        if not quiet:
            note(err, "building navpp's native module from the kernels now in numba's cache (once, about a minute "
                      "of CPU; later runs start without numba; NAVPP_NATIVE=0 skips this) ...")
        line = build_in_child()
        if not quiet:
            note(err, line)
    elif not quiet and (hint := native_hint()):
        note(err, hint)


DEFAULT_COMPARE = "ekf,aekf,ckf,vce-ckf,rwckf"


@app.command()
def compare(
    logs: Annotated[list[Path], typer.Argument(metavar="LOG...", help="Logs to process (any format `process` reads).")],
    filters: Annotated[str, typer.Option(help="Comma-separated filter names (see `navpp filters`).")] = DEFAULT_COMPARE,
    config: Annotated[Path | None, typer.Option(help="TOML config for every log; default: each log's navpp.toml, "
                                                   "else the automotive preset.")] = None,
    reference: Annotated[Path | None, typer.Option(help="Reference CSV or TUM file (one log only); default: each "
                                                      "log's reference.csv.")] = None,
    reference_anchor: Annotated[str | None, typer.Option(
        metavar="LAT,LON,ALT", help="Origin of a TUM or Odometry/PoseStamped reference's local ENU frame: deg, deg, "
        "m above the WGS-84 ellipsoid.  [default: the anchor navpp's own trajectory.tum / trajectory.mcap "
        "record]")] = None,
    imu_topic: Annotated[str | None, typer.Option(help="IMU topic for ROS logs with several.")] = None,
    gnss_topic: Annotated[str | None, typer.Option(help="GNSS topic for ROS logs with several.")] = None,
    reference_topic: Annotated[str | None, typer.Option(
        help="A topic to use as the reference: NavSatFix, or nav_msgs/Odometry or geometry_msgs/PoseStamped in a "
             "local ENU frame (see --reference-anchor).")] = None,
    odometry_topic: Annotated[str | None, typer.Option(
        help="Wheel odometry topic for ROS logs, or none.  [default: chosen by frame and rate]")] = None,
    out: Annotated[Path, typer.Option(help="Directory for summary.csv, report.md, report.html and the figures, "
                                      "created if needed.")] = Path("navpp-out/compare"),
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes: runs (log x filter) in parallel.",
                                      callback=_require(lambda v: v >= 1, "an integer >= 1"))] = 1,
    baseline: Annotated[Path | None, typer.Option(
        help="CI gate: an earlier summary.csv. Rows are matched by log and filter (the log's name when the "
             "path differs); exit 3 if a horizontal or up RMSE is worse by more than --tolerance. Rows missing "
             "from the baseline are listed, not failed.")] = None,
    tolerance: Annotated[str | None, typer.Option(
        metavar="PCT", help="Allowed worsening against --baseline, percent: 5% or 5 (a value exactly at the limit "
                            "passes).  [default: 5%]")] = None,
    max_rmse: Annotated[str | None, typer.Option(
        "--max-rmse", metavar="KEY=M,...", help="CI gate: RMSE limits in metres, keys H (horizontal), E, N, U, 3D, "
                                                "e.g. H=1.0,U=1.5; exit 3 if a run exceeds one (or has no reference).")
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary rows, the gate verdict and the exit "
                                           "code as JSON on stdout instead of the table.")] = False,
    smooth: Annotated[bool, typer.Option(
        "--smooth", help="Also smooth every run backwards (Rauch-Tung-Striebel): a second row per filter, "
                         "<filter>+rts, beside the forward one.")] = False,
    memory: Annotated[str | None, typer.Option(
        "--memory", metavar="SIZE", help="Memory each run's smoother store and IMU-rate output may each hold "
        "(500MB, 1GB, 2G; binary units); beyond it they go to a temporary file in $TMPDIR.  "
        "[default: [output] memory, else 64MB]",
        show_default=False)] = None,
    executor: Annotated[str, typer.Option(
        "--executor", help="Where the runs go: local (this machine, --jobs processes) or dask (a Dask cluster: "
                           "--scheduler, else a LocalCluster of --jobs workers; pip install 'navpp[dask]').",
        metavar="local|dask", callback=_require(lambda v: v in ("local", "dask"), "local or dask"))] = "local",
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", metavar="ADDR", help="Dask scheduler address (tcp://HOST:8786) for --executor dask; the "
                                            "workers must see the logs at the same paths.")] = None,
    time_limit: Annotated[float, typer.Option(
        "--time-limit", metavar="S", help="Watchdog: a run may take S seconds per 100,000 IMU samples of its log "
                                          "(at least 120 s); one that takes longer fails with a row naming the log "
                                          "and the rest go on. 0: no watchdog.",
        callback=_require(lambda v: math.isfinite(v) and v >= 0, "a number of seconds >= 0"))] = 600.0,
    jit: Annotated[str | None, typer.Option(
        "--jit", metavar="auto|on|off", help="Compile navpp's kernels (on), run them as plain Python (off), or "
        "choose by the log's size and what is cached (auto: interpreted when that is cheaper than compiling; "
        "see `navpp compile`).  [default: $NAVPP_JIT, else auto]",
        callback=_require(lambda v: v is None or v.lower() in ("auto", "on", "off"), "auto, on or off"))] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars.")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Also print each log's config and where it came "
                                          "from, each run's reference, and the wall time of each stage (reading "
                                          "a log, a filter on a log).")] = False,
) -> None:
    """Run several filters on each log; print the MAE/RMSE table; write summary.csv and the report.

    A log that cannot be read or a filter that fails is a row with the reason; the command then
    exits with 1 after writing everything else.  Exit 3: a CI gate (--baseline, --max-rmse)
    failed; the regressions are listed on stderr.  Exit 2: bad arguments.
    """
    import time

    from . import comparison as cmp
    from .errors import NavppError

    tol, base_rows, limits = _gate_options(tolerance, max_rmse, baseline, scheduler, executor)
    t_start = time.perf_counter()
    try:
        from . import jitmode
        from .outfiles import prepare_out_dir, remove_created_dirs

        # before the filters are looked up: that imports the kernels, fixing the mode
        choice = jitmode.choose(jit, list(logs), [f.strip().lower() for f in filters.split(",") if f.strip()],
                                smooth, default="auto")
        ahead = jitmode.workers_note(choice, min(jobs, len(logs) * len(filters.split(","))))
        if ahead and not (quiet or json_out):
            from rich.console import Console

            note(Console(stderr=True, highlight=False, soft_wrap=True), ahead)
        names = cmp.parse_filters(filters)
        created = prepare_out_dir(out, "--out")
        from .jitcache import CompileAnnouncer

        try:
            with _Progress(quiet or json_out) as prog, CompileAnnouncer(prog.say):
                result = cmp.compare(logs, names, config=config, reference=reference, imu_topic=imu_topic,
                                     gnss_topic=gnss_topic, reference_topic=reference_topic,
                                     odometry_topic=odometry_topic, jobs=jobs,
                                     out_dir=out, progress=prog, smooth=smooth, executor=executor,
                                     scheduler=scheduler, time_limit_s=time_limit, jit=jit,
                                     reference_anchor=reference_anchor, memory=memory)
        except BaseException:
            remove_created_dirs(created)
            raise
    except NavppError as exc:
        _fail(str(exc))
        return
    verdict = None
    if base_rows is not None or limits is not None:
        verdict = result.gate(baseline=base_rows, tolerance_pct=tol, max_rmse=limits)
    failed = result.failed
    code = 1 if failed else 3 if verdict is not None and not verdict.passed else 0
    line = jitmode.note(jitmode.CHOSEN[0]) if jitmode.CHOSEN else ""
    if line and not (quiet or json_out):
        from rich.console import Console

        note(Console(stderr=True, highlight=False, soft_wrap=True), line)
    print_comparison(result, json_out, verdict, code)
    if verbose and not json_out:
        print_compare_details(result, logs, config, prog.marks, t_start, time.perf_counter())
    if failed:
        _fail_runs(failed, len(result.rows))
    if code == 3:
        from rich.console import Console
        from rich.markup import escape

        Console(stderr=True, highlight=False, soft_wrap=True).print(
            "[bold red]navpp: error:[/] "
            f"{escape(f'CI gate failed: {len(verdict.failures)} of {verdict.checks} checks')}"
            " (listed above)")
        raise typer.Exit(3)


def _gate_options(tolerance: str | None, max_rmse: str | None, baseline: Path | None, scheduler: str | None,
                  executor: str) -> tuple[float, list | None, dict[str, float] | None]:
    """``compare``'s gate options checked: (tolerance %, baseline rows or None, RMSE limits (m) or
    None); a bad one (or --scheduler without Dask) is a usage error (exit 2)."""
    from . import comparison as cmp
    from .errors import ConfigError

    tol, base_rows, limits = cmp.DEFAULT_TOLERANCE_PCT, None, None
    try:
        if tolerance is not None:
            if baseline is None:
                raise ConfigError("--tolerance applies to --baseline; give --baseline SUMMARY.csv too")
            tol = cmp.parse_tolerance(tolerance)
        if max_rmse is not None:
            limits = cmp.parse_limits(max_rmse)
        if baseline is not None:
            base_rows = cmp.read_baseline(baseline)
        if scheduler is not None and executor != "dask":
            raise ConfigError("--scheduler names a Dask scheduler: add --executor dask")
    except ConfigError as exc:
        raise typer.BadParameter(str(exc)) from None
    return tol, base_rows, limits


def _fail_runs(failed: list, n_runs: int) -> None:
    """Exit 1 for the failed runs of a comparison: each reason on a warning line of its own, and
    one short error line naming the failed runs."""
    groups: dict[tuple[str, str], list[str]] = {}
    for r in failed:
        groups.setdefault((r.log, r.status), []).append(r.filter)
    reasons = [f"{', '.join(f)} on {log}: {status}" for (log, status), f in groups.items()]
    head = f"{len(failed)} of {n_runs} runs failed (reasons above, and in summary.csv): "
    names = [f"{', '.join(f)} on {Path(log).name or log}" for (log, _), f in groups.items()]
    shown = ""
    for k, name in enumerate(names):
        more = f"; and {len(names) - k} more" if k else ""
        if len(head) + len(shown) + len(name) + 20 > 280:
            shown += more or name[:200]
            break
        shown += ("; " if k else "") + name
    _fail(head + shown, SimpleNamespace(warnings=reasons, notes=()))


@app.command()
def bench(
    name: Annotated[str | None, typer.Argument(metavar="NAME", help="Benchmark name; omit to list them.")] = None,
    runs: Annotated[int | None, typer.Option(help="Monte Carlo runs  [default: the paper's]",
                                                callback=_require(lambda v: v >= 1, "an integer >= 1"))] = None,
    seed: Annotated[int, typer.Option(help="Seed of the simulated truth and of random filters.",
                                      callback=_require(lambda v: v >= 0, "an integer >= 0"))] = 0,
    filters: Annotated[str | None, typer.Option(help="Comma-separated filters  [default: the paper's "
                                                   "comparison]")] = None,
    jobs: Annotated[int, typer.Option("--jobs", "-j", help="Worker processes for the runs (benchmarks that "
                                                            "can split them: paper001-xpn).",
                                      callback=_require(lambda v: v >= 1, "an integer >= 1"))] = 1,
) -> None:
    """Run one of the papers' benchmarks and print our figures next to the paper's.

    Filters may carry options: --filters "rwckf,rwckf[covariance=random; candidates=32]".
    """
    from .errors import ConfigError, NavppError

    try:
        from . import papers as benchmarks

        if name is None:
            for key, b in sorted(benchmarks.BENCHMARKS.items()):
                typer.echo(f"{key:<20} {b.title}  [{b.default_runs} runs; {', '.join(b.filters)}]")
            return
        chosen = None
        if filters is not None:
            chosen = [f.strip() for f in filters.split(",") if f.strip()]
            if not chosen:
                raise ConfigError("--filters: give at least one filter, e.g. --filters ckf,vce-ckf")
            for spec in chosen:
                benchmarks.parse_filter_spec(spec)
        cpu = benchmarks.expected_cpu_s(name, runs, chosen)
        if cpu > 600:
            per = benchmarks.BENCHMARKS[name].cpu_s_per_run
            typer.echo(f"note: {name} takes about {per:.0f} s of CPU per run of the paper's filters (measured on a "
                       f"2-core x86-64 machine): about {cpu / 3600:.1f} h of CPU here; --runs N and --jobs N "
                       "shorten it", err=True)
        result = benchmarks.run_benchmark(name, runs=runs, seed=seed, filters=chosen, jobs=jobs)
    except NavppError as exc:
        _fail(str(exc))
        return
    typer.echo(benchmarks.format_result(result))


PRESETS = ("consumer", "automotive", "tactical", "navigation", "ideal")


def _triplet(value: str | None, names: str, unit: str, option: str) -> tuple[float, float, float] | None:
    """Three finite numbers written ``a,b,c`` (None stays None); else one line naming the option."""
    if value is None:
        return None
    try:
        v = tuple(float(x) for x in value.split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise typer.BadParameter(f"needs three finite numbers '{names}' ({unit}), got {value!r}", param_hint=option)
    return v  # type: ignore[return-value]


def _lever_arm(value: str | None) -> tuple[float, float, float] | None:
    return _triplet(value, "x,y,z", "m", "'--lever-arm'")


def _mounting(value: str | None) -> tuple[float, float, float] | None:
    return _triplet(value, "roll,pitch,yaw", "deg", "'--mounting'")


REALISM = ("consumer-car",)
#: options the realism bundle sets unless given: CLI parameter -> SimulationSpec field
_BUNDLE_OPTIONS = {"imu_rate": "imu_rate_hz", "gnss_rate": "gnss_rate_hz", "preset": "preset", "still": "still_s",
                   "gnss_std_h": "gnss_std_h_m", "gnss_std_u": "gnss_std_u_m"}


@app.command()
def simulate(
    ctx: typer.Context,
    out: Annotated[Path, typer.Argument(metavar="OUT", help="Output directory for the CSV log (imu.csv, gnss.csv, "
                                        "reference.csv, navpp.toml).")],
    duration: Annotated[float, typer.Option(
        help="Drive length, s, >= 30 (includes the initial still period).",
        callback=_require(_finite(30.0), "a finite number of seconds >= 30"))] = 900.0,
    imu_rate: Annotated[float, typer.Option(
        help="IMU rate, Hz.", callback=_require(_finite(0.0, strict=True), "a finite number of Hz > 0"))] = 125.0,
    gnss_rate: Annotated[float, typer.Option(
        help="GNSS rate, Hz (1-10).", callback=_require(_finite(1.0, 10.0), "a number of Hz within 1-10"))] = 5.0,
    preset: Annotated[str, typer.Option(help=f"IMU grade: {', '.join(PRESETS)}.",
                                        callback=_require(lambda v: v in PRESETS, f"one of {', '.join(PRESETS)}"))]
        = "automotive",
    seed: Annotated[int, typer.Option(help="Random seed (same seed, same log).",
                                      callback=_require(lambda v: v >= 0, "a non-negative integer"))] = 0,
    gnss_std_h: Annotated[float, typer.Option(help="GNSS horizontal noise 1-sigma per axis, m.",
                                              callback=_require(_finite(0.0), "a finite number of metres >= 0"))] = 1.8,
    gnss_std_u: Annotated[float, typer.Option(help="GNSS vertical noise 1-sigma, m.",
                                              callback=_require(_finite(0.0), "a finite number of metres >= 0"))] = 2.5,
    gnss_error: Annotated[str, typer.Option(help="GNSS error model: white or correlated.",
                                            callback=_require(lambda v: v in ("white", "correlated"),
                                                              "'white' or 'correlated'"))] = "white",
    gnss_corr_time: Annotated[float, typer.Option(
        help="Correlation time of the correlated GNSS error (--gnss-error correlated), s.",
        callback=_require(_finite(0.0, strict=True), "a finite number of seconds > 0"))] = 120.0,
    lever_arm: Annotated[str | None, typer.Option(
        help="Antenna lever arm in body FLU, m: 'x,y,z'.  [default: 0,0,0]")] = None,
    still: Annotated[float, typer.Option(help="Initial still period, s (at most half of --duration).",
                                         callback=_require(_finite(0.0), "a finite number of seconds >= 0"))] = 60.0,
    realism: Annotated[str | None, typer.Option(
        help="Real-world effects of a consumer car log at once (vibration, large turn-on biases, scale factors, "
             "non-orthogonality, stale rows, a 10 ms IMU clock offset, a GNSS gap; IMU 100 Hz, GNSS 4 Hz at 5 cm, "
             "still 35 s, preset consumer unless given); the truth goes to realism.json.",
        callback=_require(lambda v: v in REALISM, f"one of {', '.join(REALISM)}"))] = None,
    mounting: Annotated[str | None, typer.Option(
        help="IMU mounting against the vehicle, deg: 'roll,pitch,yaw' (as [imu] mounting_rpy_deg; '90,0,0': y up).  "
             "[default: none]")] = None,
    start_in_motion: Annotated[bool, typer.Option("--start-in-motion", help="Start while driving (8 m/s, no "
                                                  "still period).")] = False,
    gnss_gap: Annotated[float | None, typer.Option(
        help="GNSS gap, s, in the first turn at least 20 s into the log (0: none).  [default: none; 15 with "
             "--realism]", callback=_require(_finite(0.0), "a finite number of seconds >= 0"))] = None,
    gnss_gap_start: Annotated[float | None, typer.Option(
        help="Start of the GNSS gap, s after the first sample.  [default: the first turn]",
        callback=_require(_finite(0.0), "a finite number of seconds >= 0"))] = None,
    odometry: Annotated[bool, typer.Option("--odometry", help="Write wheel odometry (odometry.csv: forward speed, "
                                           "0.02 m/s noise).")] = False,
    odometry_scale_error: Annotated[float, typer.Option(
        help="Odometer scale error, % (it reads 1 + PCT/100 times the true speed; with --odometry).",
        callback=_require(_finite(-50.0, 50.0), "a number of % within -50..50"))] = 0.0,
    odometry_rate: Annotated[float, typer.Option(
        help="Odometry rate, Hz (with --odometry).",
        callback=_require(_finite(0.0, 1000.0, strict=True), "a number of Hz within 0..1000, > 0"))] = 10.0,
    odometry_std: Annotated[float, typer.Option(
        help="Odometry speed white noise, m/s 1-sigma (with --odometry).",
        callback=_require(_finite(0.0, 10.0), "a number of m/s within 0..10"))] = 0.02,
    odometry_quantum: Annotated[float, typer.Option(
        help="Odometry speed resolution, m/s: readings are rounded to its multiples (0: none; with --odometry).",
        callback=_require(_finite(0.0, 10.0), "a number of m/s within 0..10"))] = 0.0,
    odometry_slip: Annotated[float, typer.Option(
        help="Wheel slip under hard acceleration: SLIP m/s per m/s^2 beyond 2 m/s^2 (0: none; with --odometry).",
        callback=_require(_finite(0.0, 10.0), "a number within 0..10"))] = 0.0,
    odometry_yaw_rate: Annotated[bool, typer.Option(
        "--odometry-yaw-rate", help="Also write the vehicle's yaw rate (0.002 rad/s noise) in odometry.csv.")] = False,
) -> None:
    """Simulate a car-like drive and write it as a CSV log with its reference."""
    from rich.console import Console

    from .errors import NavppError

    la = _lever_arm(lever_arm)
    rpy = _mounting(mounting)
    try:
        from . import api

        kwargs = dict(duration_s=duration, imu_rate_hz=imu_rate, gnss_rate_hz=gnss_rate, preset=preset, seed=seed,
                      gnss_std_h_m=gnss_std_h, gnss_std_u_m=gnss_std_u, gnss_error=gnss_error, still_s=still,
                      gnss_corr_time_s=gnss_corr_time)
        if realism is not None:
            kwargs["realism"] = realism
            for option, name in _BUNDLE_OPTIONS.items():   # the bundle's value unless given
                source = ctx.get_parameter_source(option)      # Typer's own (vendored) click enum
                if source is None or source.name == "DEFAULT":
                    del kwargs[name]
        if la is not None:
            kwargs["lever_arm_m"] = la
        if rpy is not None:
            kwargs["mounting_rpy_deg"] = rpy
        if start_in_motion:
            kwargs["start_in_motion"] = True
        if gnss_gap is not None:
            kwargs["gnss_gap_s"] = gnss_gap
        if gnss_gap_start is not None:
            kwargs["gnss_gap_start_s"] = gnss_gap_start
        if odometry:
            kwargs.update(odometry=True, odometry_scale_error_pct=odometry_scale_error, odometry_rate_hz=odometry_rate,
                          odometry_std_mps=odometry_std, odometry_quantum_mps=odometry_quantum,
                          odometry_slip=odometry_slip, odometry_yaw_rate=odometry_yaw_rate)
        try:
            path = api.simulate_log(out, **kwargs)
        except ValueError as exc:
            _fail(f"simulate: {exc}")
            return
    except NavppError as exc:
        _fail(str(exc))
        return
    from .simulate import SimulationSpec

    spec = SimulationSpec(**kwargs)
    if not spec.start_in_motion and spec.still_effective_s < spec.still_s:
        note(Console(stderr=True, highlight=False, soft_wrap=True),
              f"still period shortened to {spec.still_effective_s:g} s: "
              + (f"--still {spec.still_s:g} s" if "still_s" in kwargs
                 else f"the {realism} still period {spec.still_s:g} s")
              + f" is more than half of --duration {duration:g} s")
    typer.echo(f"wrote {path}/imu.csv, gnss.csv, reference.csv, navpp.toml"
               + (", odometry.csv" if spec.odometry else "") + (", realism.json" if spec.realistic else ""))


@app.command("inspect")
def inspect_cmd(
    log: Annotated[Path, typer.Argument(metavar="LOG", help="An MCAP file, a ROS 1 bag, a ROS 2 bag directory, or a "
                                        "CSV log directory.")],
) -> None:
    """List a log's topics (or CSV files): type, count, rate, time span, gaps, repeats, role."""
    from .errors import NavppError

    try:
        from . import api

        kind, rows, warnings = api.inspect(log)
    except NavppError as exc:
        _fail(str(exc))
        return
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    tab = Table(title=f"{escape(str(log))} ({kind})")
    for col, just in (("topic / file", "left"), ("type / columns", "left"), ("count", "right"), ("rate Hz", "right"),
                      ("first t (s)", "right"), ("span s", "right"), ("gaps >3T", "right"),
                      ("repeats", "right"), ("role", "left")):
        tab.add_column(col, justify=just)
    for r in rows:
        span = f"{r.last_s - r.first_s:.1f}" if r.first_s is not None and r.last_s is not None else ""
        gaps = f"{r.gaps} (max {r.largest_gap_s:.3g} s)" if r.gaps else "0"
        tab.add_row(escape(r.name), escape(r.msgtype), str(r.count), f"{r.rate_hz:.1f}" if r.rate_hz else "",
                    f"{r.first_s:.3f}" if r.first_s is not None else "", span, gaps, str(r.duplicates), r.role)
    con = Console(highlight=False)
    if not con.is_terminal:
        con = Console(highlight=False, width=200)
    con.print(tab)
    err = Console(stderr=True, highlight=False, soft_wrap=True)
    for line in warnings:
        err.print(f"[yellow]warning:[/] {escape(line)}")


@app.command("filters")
def filters_cmd() -> None:
    """List the filters with their paper and a one-line description."""
    from .filters import FILTERS

    for name, cls in sorted(FILTERS.items()):
        typer.echo(f"{name:<10} {cls.summary}  [{cls.paper}]")


@app.command("compile")
def compile_cmd(
    filters: Annotated[str, typer.Option(help="Comma-separated filter names whose kernels to compile.",
                                         autocompletion=_filter_names)] = "all",
    native: Annotated[bool, typer.Option(
        "--native/--no-native", help="Also build the native module from numba's cache (needs a C compiler): "
        "runs then start without numba.")] = True,
) -> None:
    """Compile navpp's numba kernels once (every filter, the smoother, the MCAP/ROS readers) into the
    cache, so that every later run loads them instead of compiling or running interpreted; then build
    the native module (every kernel signature in the cache, compiled ahead of time for this CPU) that
    later runs use without importing numba.  Run it again after upgrading navpp."""
    import time

    from rich.console import Console

    from . import jitmode
    from .errors import NavppError

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    wanted = jitmode.ALL_FILTERS if filters.strip().lower() == "all" else tuple(
        f.strip().lower() for f in filters.split(",") if f.strip())
    t0 = time.process_time()
    try:
        from . import api

        steps = api.compile_kernels(wanted, progress=lambda name: note(err, f"compiling: {name} ..."),
                                    native=native)
    except NavppError as exc:
        _fail(str(exc), exc)
        return
    for name, cpu in steps:
        typer.echo(f"{name}: {cpu:.1f} s of CPU")
    from .jitcache import cache_place

    typer.echo(f"navpp's kernels are compiled ({time.process_time() - t0:.1f} s of CPU) and cached in {cache_place()}")


@app.command("config")
def config_cmd() -> None:
    """Print a commented TOML template of every config key with its default, unit and meaning
    (navpp config > navpp.toml; it loads as the built-in defaults)."""
    from .config_template import config_template

    typer.echo(config_template(), nl=False)


def main() -> None:
    """The ``navpp`` command.  SIGINT and SIGTERM stop a run cleanly (:mod:`navpp.interrupts`):
    its ``finally`` blocks remove the staging files, drop the ``--out`` lock and stop the
    workers; then one line ``navpp: interrupted ...`` and exit code 130.

    A command is one job, so Python's cyclic garbage collector is off for it: its collections
    walked every object of the imports again and again (0.2-0.3 s of a 2 s run), while navpp's
    own objects are freed by reference counting (the 1-hour log's peak: 1 MB more).  It comes
    back on when numba compiles (:class:`navpp.kernel.CollectorOnCompile`).  At the end the
    objects left are frozen, so the interpreter's exit does not walk them either."""
    import gc

    from . import interrupts
    from .spill import allow_large_block_mapping

    gc.disable()
    interrupts.install()
    allow_large_block_mapping()     # the command's own process: large blocks back to the system when freed
    _numba_cache_note()
    from .kernel import CollectorOnCompile

    try:
        with CollectorOnCompile():      # on again if numba compiles (its garbage is cyclic)
            app(prog_name="navpp")
    except BaseException as exc:
        signum = interrupts.received()
        if signum is None or (isinstance(exc, SystemExit) and interrupts.committed()):
            if isinstance(exc, SystemExit):
                interrupts.ignore_from_now()      # the run is over: a late signal changes nothing
            raise
        interrupts.exit_interrupted(signum)
    finally:
        gc.freeze()


def _numba_cache_note() -> None:
    """Print the note of :func:`navpp.jitcache.configure`, if it had to move the numba cache."""
    from .jitcache import NOTE

    if NOTE:
        sys.stderr.write(f"note: {NOTE[0]}\n")


if __name__ == "__main__":
    sys.exit(main())
