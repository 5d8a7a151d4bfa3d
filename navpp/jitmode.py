"""Compiled or interpreted: whether navpp's numba kernels are compiled in this process.

navpp's numerical kernels are numba functions (``njit(cache=True)``).  Compiled, they are fast,
but compiling them costs CPU once per machine and path (about 20 s of CPU for the default EKF
path on a 2-core EPYC, and 9-12 s more for each sigma-point family or the smoother); the
machine code then lives in numba's cache (:mod:`navpp.jitcache`).  The same functions also run
as plain Python (numba's ``NUMBA_DISABLE_JIT``): no compilation, byte-identical results, but
each IMU sample costs far more (about 80 µs on the EKF and 1 ms on a sigma-point filter).

So a short job on a cold cache is done sooner interpreted, and a long one (or any job once the
kernels are cached) compiled.  :func:`choose` decides once per process, before the first kernel
module is imported (numba reads the flag when a function is decorated):

``on``
    compile (load from the cache what is there; compile the rest, announced);
``off``
    interpret (nothing compiled, nothing cached);
``auto`` (default)
    compile when every kernel group the job needs is in the cache; else estimate both costs,
    the CPU seconds of compiling the missing groups (:data:`COMPILE_S`) against the extra CPU
    seconds of interpreting this job (IMU samples x filters, :data:`INTERPRETED_US`), and take
    the cheaper, charging this job half the compile cost (:data:`COMPILE_SHARE`: compiled
    kernels serve later runs too).  With an EKF the break-even is near 12.5 minutes of 125 Hz
    IMU; with a sigma-point filter, about 3.5 minutes (the SIF: 45 s).  The sample counts come
    from the logs' indexes (MCAP summary, ROS 2 ``metadata.yaml``, ROS 1 bag index) or, for
    CSV, from the file size and its first lines.

The choice comes from ``--jit`` (process, compare), else ``NAVPP_JIT``, else ``auto`` on the
command line and ``on`` in the Python API (``navpp.process(..., jit=...)``: a program may go on
to larger jobs in the same process); it is passed to worker processes through
``NUMBA_DISABLE_JIT``.  ``navpp compile`` fills the cache
for every filter and the smoother, after which ``auto`` always compiles (loads), and builds the
native module (:mod:`navpp.kernel`): a kernel it holds counts as cached without numba being
imported, and compiled runs use it; interpreted runs never do.

The cost figures are CPU seconds measured on the development machine (see
``benchmarks/bench_startup.py``); both sides are Python-bound work (numba's compiler is mostly
Python), so their ratio carries over to other machines better than either figure.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

MODES = ("auto", "on", "off")
ENV = "NAVPP_JIT"

#: Kernel groups: (source file under navpp/, function) of the kernels whose presence in numba's
#: cache stands for the group (each group's other kernels are compiled along with these).
GROUPS: dict[str, tuple[tuple[str, str], ...]] = {
    "ins": (("ins/strapdown.py", "integrate"), ("ins/model.py", "integrate_with_jacobian"),
            ("filters/linalg.py", "joseph"), ("filters/linalg.py", "gain_and_nis"),
            ("engine/output.py", "interpolated_std"), ("engine/fused.py", "ekf_epochs"),
            ("io/csvformat.py", "_format_block")),
    "ros": (("io/messages.py", "_decode_kernel"),),
    "mcap": (("io/mcap.py", "_scan_kernel"),),
    "csv": (("io/csvparse.py", "_parse_block"),),
    "sigma": (("ins/model.py", "_propagate_points"), ("ins/model.py", "gnss_points")),
    "vce": (("ins/model.py", "integrate_noise_groups"),),
    "smooth": (("ins/model.py", "rts_means"), ("ins/model.py", "apply_node_corrections")),
}
#: CPU seconds to compile each group from an empty cache (2-core EPYC, numba 0.68; "ins": a
#: cold sample-drive EKF run 50.9 s against 2.3 s warm, less the "csv" group, with the compiled
#: EKF epoch and the writers' formatter, both added in issue 21; then 3 % more with the still
#: epochs' ZUPT and ZARU in the compiled epoch and the block-structured transition: a cold
#: sample-drive EKF run 68.4 -> 70.4 s CPU, the two side by side at load 11; on 3 Dec 2026, after
#: the rejected GNSS fixes and the block moments went into compiled kernels, a cold 1-hour CSV
#: EKF run with ``--jit on`` took 98.8 s of CPU at load ~1, against ~3 s warm: 94.5 s for "ins").
COMPILE_S = {"ins": 94.5, "ros": 1.5, "mcap": 0.5, "csv": 1.5, "sigma": 9.0, "vce": 10.0, "smooth": 9.0}
#: Extra CPU µs per IMU sample when interpreted, per filter (forward run), and per sample
#: for the smoother's backward pass; per message for decoding a ROS log.  Measured with
#: ``benchmarks/bench_interpreted.py`` (sample drive cut to 60 and 120 s, the slope of
#: interpreted minus compiled CPU; 2-core EPYC, load 6-16, 3 Dec 2026): EKF 509, AEKF 494,
#: UKF 2049, CKF 1957, AUKF 1967, RWCKF 2362, VCE-CKF 2971, SIF 9221; the smoother (EKF with
#: ``--smooth``, less the forward run) 368.  The figures these replace (40 µs for the EKF, about
#: 1 ms for the sigma-point filters, 130 µs for the smoother) were 2 to 13 times too low, so
#: ``auto`` ran EKF logs of up to 80 minutes interpreted (an hour: ~230 s of CPU by these figures).
INTERPRETED_US = {"ekf": 510.0, "aekf": 495.0, "sif": 9200.0, "ckf": 1960.0, "ukf": 2050.0, "aukf": 1970.0,
                  "rwckf": 2360.0, "vce-ckf": 2970.0}
SMOOTH_US = 370.0
DECODE_US = {"ros": 5.0, "mcap": 5.0}
#: The share of the compile cost charged to this job (the rest to the later runs it also serves).
COMPILE_SHARE = 0.5
#: Kernel groups each filter needs beyond ``ins``.
FILTER_GROUPS = {"ckf": ("sigma",), "ukf": ("sigma",), "aukf": ("sigma",), "rwckf": ("sigma",),
                 "sif": ("sigma",), "vce-ckf": ("sigma", "vce")}
#: navpp modules whose import decorates kernels: once one is imported, the mode is fixed.
KERNEL_MODULES = ("navpp.ins.strapdown", "navpp.ins.model", "navpp.filters.linalg", "navpp.io.messages",
                  "navpp.io.mcap", "navpp.io.csvparse", "navpp.engine.output")

_ROOT = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Choice:
    """The mode taken (``compiled``) and why, in a few words for the notes."""

    compiled: bool
    why: str
    #: kernel groups not in the cache (known only for ``auto``): what a compiled run compiles
    missing: tuple[str, ...] = ()

    @property
    def word(self) -> str:
        return "compiled" if self.compiled else "interpreted"


def requested(value: str | None = None, default: str = "auto") -> str:
    """The mode asked for: ``value`` (a ``--jit`` option), else ``$NAVPP_JIT``, else ``default``."""
    mode = (value or os.environ.get(ENV) or default).strip().lower()
    if mode not in MODES:
        from .errors import ConfigError

        source = "--jit" if value else ENV
        raise ConfigError(f"{source}: unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    return mode


def decided() -> bool | None:
    """The mode in force if a kernel module is already imported (True: compiled), else None."""
    if not any(m in sys.modules for m in KERNEL_MODULES):
        return None
    return not interpreted()


def apply(compiled: bool) -> None:
    """Set the mode for kernels decorated from now on, here and in worker processes; compiled,
    with scipy's BLAS module loaded on its own first (:func:`navpp.scipy_parts.preload_blas`)."""
    os.environ["NUMBA_DISABLE_JIT"] = "0" if compiled else "1"
    if compiled:
        from .scipy_parts import preload_blas

        preload_blas()              # numba's BLAS helper (the native module's too) would import scipy.linalg
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.DISABLE_JIT = 0 if compiled else 1  # type: ignore[attr-defined]


def interpreted() -> bool:
    """True when navpp's kernels run as plain Python in this process."""
    config = sys.modules.get("numba.core.config")
    if config is not None:
        return bool(getattr(config, "DISABLE_JIT", 0))
    return os.environ.get("NUMBA_DISABLE_JIT", "0").strip() not in ("", "0")


# --------------------------------------------------------------------------- the cache


def _first_line(path: Path, name: str) -> int | None:
    """Line (1-based) of the first decorator of module-level function ``name`` (numba's cache
    key), found in the text without parsing the module (``ast.parse`` of the kernel modules
    costs about 40 ms of every run's start): the ``def name(`` at column 0, and above it the
    lines of its decorators (each starting with ``@``, their continuations indented or closing
    a bracket), up to a blank or other line."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, ValueError):
        return None
    head = f"def {name}("
    for k, line in enumerate(lines):
        if line.startswith(head):
            first = k
            j = k
            while j > 0 and lines[j - 1].strip() and lines[j - 1][0] in "@ \t)]}":
                j -= 1
                if lines[j].startswith("@"):
                    first = j
            return first + 1
    return None


def kernel_cached(rel_path: str, name: str) -> bool:
    """Whether numba's cache holds a compiled version of navpp's kernel ``name`` in
    ``navpp/<rel_path>`` for its current source (index present, same numba, same source hash).

    Uses numba's own cache locator and index reader on a stand-in function with the kernel's
    file, name and first line, so nothing of navpp's kernels is imported or decorated.
    """
    from . import kernel

    if kernel.covers("navpp." + rel_path.removesuffix(".py").replace("/", "."), name):
        return True                             # compiled ahead of time: numba not even imported
    path = _ROOT / rel_path
    line = _first_line(path, name)
    if line is None:
        return False
    try:
        from numba.core.caching import CompileResultCacheImpl, IndexDataCacheFile

        def stand_in() -> None:  # pragma: no cover - never called
            pass

        stand_in.__code__ = stand_in.__code__.replace(co_filename=str(path), co_firstlineno=line, co_name=name,
                                                      co_qualname=name)
        stand_in.__qualname__ = name
        stand_in.__name__ = name
        impl = CompileResultCacheImpl(stand_in)
        index = IndexDataCacheFile(impl.locator.get_cache_path(), impl.filename_base,
                                   impl.locator.get_source_stamp())
        return bool(index._load_index())
    except Exception:  # noqa: BLE001 - numba's internals moved: "not cached", the safe side is to estimate
        return False


def missing_groups(groups: tuple[str, ...]) -> tuple[str, ...]:
    """The groups among ``groups`` with a kernel not in numba's cache."""
    return tuple(g for g in groups if not all(kernel_cached(p, n) for p, n in GROUPS[g]))


# --------------------------------------------------------------------------- the job's size


def _mcap_counts(path: Path) -> tuple[int, int] | None:
    """(IMU messages, all messages) from an MCAP file's summary statistics."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return None
    counts = summary.statistics.channel_message_counts
    imu = sum(n for cid, n in counts.items() if cid in summary.channels
              and summary.schemas.get(summary.channels[cid].schema_id) is not None
              and summary.schemas[summary.channels[cid].schema_id].name.endswith("Imu"))
    return imu, sum(counts.values())


def _ros2_counts(path: Path) -> tuple[int, int] | None:
    """(IMU messages, all messages) from a ROS 2 bag's metadata.yaml."""
    from ruamel.yaml import YAML  # rosbags' own YAML reader

    with open(path / "metadata.yaml", encoding="utf-8") as f:
        info = YAML(typ="safe").load(f)["rosbag2_bagfile_information"]
    entries = info.get("topics_with_message_count") or []
    total = sum(int(e["message_count"]) for e in entries)
    imu = sum(int(e["message_count"]) for e in entries if str(e["topic_metadata"]["type"]).endswith("Imu"))
    return (imu, total) if total else None


def _ros1_counts(path: Path) -> tuple[int, int] | None:
    """(IMU messages, all messages) from a ROS 1 bag's chunk infos (navpp's index reader: no
    object per message, as rosbags' Reader builds)."""
    from navpp.io.ros1index import read_index

    with read_index(path) as bag:
        counts = bag.counts()
        imu = sum(counts[c.conn] for c in bag.connections if c.msgtype.endswith("Imu"))
    return imu, sum(counts.values())


def _csv_rows(path: Path) -> int | None:
    """Rows of a CSV file from its size and the mean length of its first lines."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    lines = head.count(b"\n")
    if lines < 2:
        return None
    return int(size / (len(head) / lines))


def samples(log: Path) -> tuple[int, int, str] | None:
    """(IMU samples, messages to decode, format family) of one log, from its index or size;
    None when it cannot be told cheaply (then the job counts as large)."""
    try:
        if log.is_dir():
            if (log / "metadata.yaml").is_file():
                got = _ros2_counts(log)
                return None if got is None else (got[0], got[1], "ros")
            rows = _csv_rows(log / "imu.csv") if (log / "imu.csv").is_file() else None
            return None if rows is None else (rows, 0, "csv")
        suffix = log.suffix.lower()
        if suffix == ".mcap":
            got = _mcap_counts(log)
            return None if got is None else (got[0], got[1], "mcap")
        if suffix == ".bag":
            got = _ros1_counts(log)
            return None if got is None else (got[0], got[1], "ros")
    except Exception:  # noqa: BLE001 - an unreadable log is the reader's to report, in its own words
        return None
    return None


# --------------------------------------------------------------------------- the choice


#: The last :func:`choose` of this process (for the command line's note after ``compare``).
CHOSEN: list[Choice] = []


def workers_note(choice: Choice, workers: int) -> str:
    """A line said before ``workers`` processes start that will each compile kernels first
    (their own compilation is not seen by this process's announcer), else empty."""
    if workers < 2 or not choice.compiled or not choice.missing:
        return ""
    cpu = sum(COMPILE_S[g] for g in choice.missing)
    return (f"each of the {workers} worker processes first compiles navpp's kernels for this path "
            f"({', '.join(choice.missing)}: about {cpu:.0f} s of CPU each, once; `navpp compile` does it ahead)")


def note(choice: Choice) -> str:
    """A line for the notes when the kernels ran interpreted, else empty."""
    if choice.compiled:
        return ""
    if choice.why.startswith("about"):
        return (f"navpp's kernels ran interpreted, not compiled: this job is short and they are not in the cache "
                f"({choice.why}); `navpp compile` compiles them once, after which runs like this are several "
                f"times faster")
    return f"navpp's kernels ran interpreted, not compiled ({choice.why})"


def choose(mode: str | None, logs: list[Path], filters: list[str], smooth: bool, default: str = "on") -> Choice:
    """Decide and apply the mode for a job of ``filters`` on ``logs`` (see the module docstring).

    ``mode`` None: ``$NAVPP_JIT``, else ``default``: ``on`` for the Python API (a program may
    go on to larger jobs in the same process), ``auto`` for the command line (one job)."""
    choice = _choose(requested(mode, default), logs, filters, smooth)
    CHOSEN[:] = [choice]
    return choice


def _choose(mode: str, logs: list[Path], filters: list[str], smooth: bool) -> Choice:
    already = decided()
    if already is not None:
        if CHOSEN and CHOSEN[0].compiled == already:
            return CHOSEN[0]
        return Choice(already, "fixed earlier in this process")
    sizes = [samples(log) for log in logs] if mode == "auto" else []
    choice = decide(mode, sizes, filters, smooth,
                    missing_groups(needed_groups(sizes, filters, smooth)) if mode == "auto" else ())
    apply(choice.compiled)
    return choice


def needed_groups(sizes: list[tuple[int, int, str] | None], filters: list[str], smooth: bool) -> tuple[str, ...]:
    """The kernel groups a job needs: the INS always, the readers of its logs' formats, the
    filters' own and the smoother's."""
    families = {s[2] for s in sizes if s is not None}
    groups = ["ins"]
    if families & {"mcap", "ros"} or any(s is None for s in sizes):
        groups.append("ros")
    if "mcap" in families:
        groups.append("mcap")
    for f in filters:
        groups.extend(g for g in FILTER_GROUPS.get(f, ()) if g not in groups)
    if smooth:
        groups.append("smooth")
    return tuple(groups)


def decide(mode: str, sizes: list[tuple[int, int, str] | None], filters: list[str], smooth: bool,
           missing: tuple[str, ...]) -> Choice:
    """The choice for ``mode`` given the logs' (IMU samples, messages, format family) ``sizes``
    (None: unknown), the ``filters``, ``smooth`` and the kernel groups ``missing`` from the
    cache (see the module docstring)."""
    if mode != "auto":
        return Choice(mode == "on", f"asked for: jit {mode}")
    if not missing:
        return Choice(True, "kernels cached")
    if any(s is None for s in sizes):
        return Choice(True, "log size unknown", missing)
    compile_s = sum(COMPILE_S[g] for g in missing)
    per_sample = sum(INTERPRETED_US.get(f, max(INTERPRETED_US.values())) for f in filters)
    if smooth:
        per_sample += SMOOTH_US * len(filters)
    interp_s = 1e-6 * sum(s[0] * per_sample + s[1] * DECODE_US.get(s[2], 0.0) for s in sizes if s is not None)
    return Choice(interp_s >= COMPILE_SHARE * compile_s,
                  f"about {interp_s:.0f} s of CPU interpreted against {compile_s:.0f} s to compile "
                  f"({', '.join(missing)})", missing)


# --------------------------------------------------------------------------- navpp compile

def interpreted_error() -> Exception:
    """The error for compiling in a process whose kernels already run interpreted."""
    from .errors import ConfigError

    return ConfigError("navpp's kernels already run interpreted in this process (NUMBA_DISABLE_JIT=1?); "
                       "compile in a process without it")


#: Filters compiled by :func:`navpp.api.compile_kernels` when none are named.
ALL_FILTERS = ("ekf", "aekf", "ckf", "ukf", "vce-ckf", "rwckf", "aukf", "sif")
