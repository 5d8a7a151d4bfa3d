"""Snapshot of every output navpp makes on ``sample_data/``: the instrument that shows a refactor
left behaviour unchanged.

Usage (from anywhere; the repository is this file's parent's parent)::

    python benchmarks/snapshot.py record OUT.json [--jobs 2] [--benchmarks] [--keep DIR]
    python benchmarks/snapshot.py compare A.json B.json

Before a refactor: ``record before.json``; after it: ``record after.json`` and
``compare before.json after.json``, which prints every difference and exits 1 if there is any
(0: identical).  A snapshot is not committed: it is recorded from the code at hand.

``record`` runs each case below through navpp's command line, in-process (``typer``'s
``CliRunner``, ``--jobs`` worker processes, cwd = the repository, logs given by their relative
path ``sample_data/...``), each into its own directory of a temporary root, and stores per case
the exit code, the normalised stdout and stderr, and per output file a sha256 of its normalised
bytes, plus what ``compare`` needs to say how large a difference is:

* ``process`` of every filter (``navpp filters``) on ``sample_data/drive`` (CSV), ``drive.mcap``,
  ``drive.bag``, ``drive_ros2`` and ``walk_0827``;
* ``process --smooth`` of every filter on ``drive`` and of ``ekf`` on ``walk_0827``;
* ``process --format csv,mcap,tum,geojson,kml`` (``ekf``) on ``drive`` and ``walk_0827``, and
  ``--format mcap --embed-input`` on ``drive.mcap``; ``process --output-rate 10 --gnss-outage``
  on ``drive``;
* ``compare --smooth --json`` (default filters) on ``drive`` and ``walk_0827``: summary.csv,
  report.md, report.html, the figures and the JSON on stdout;
* ``inspect`` of the five logs, ``filters``, ``simulate`` (seeded: a plain 60-s drive and a
  ``--realism`` one);
* ``bench`` of every paper benchmark with ``--runs 2`` (the cheap run; stdout).

With ``--benchmarks`` it also runs, as child processes, the expensive ones: every paper
benchmark with the paper's number of runs, and the accuracy scripts of ``benchmarks/``
(``bench_filters``, ``bench_faults``, ``bench_smoother``, ``bench_aiding``, ``bench_realism``;
``bench_real`` when its data directory exists), recording their stdout.  The pure timing
benchmarks (``bench_process``, ``bench_compare``, ``bench_dask``, ``bench_decode``,
``bench_writer``) print no accuracy figure and are not run.

What is normalised (everything else is hashed byte for byte):

* in every text output (CSV, JSON, GeoJSON, KML, TUM, Markdown, HTML, stdout, stderr): the
  temporary root's absolute path becomes ``<OUT>`` and the repository's ``<REPO>``;
* JSON (files and ``compare --json``'s stdout): the values of the keys ``runtime_s``,
  ``smoothing_s``, ``compile_s``, ``wall_s`` and ``seconds`` (wall times, s) become
  ``"<time>"``; the JSON is re-serialised with sorted keys;
* CSV: the cells of a column named like those keys become ``<time>``;
* Markdown: in metrics.md the ``- runtime: X s`` line and the smoothing's time in
  ``(Rauch-Tung-Striebel, N nodes, X s)``, in report.md the cells of a table column headed
  ``time s``; HTML: the ``<td>`` cells of a column headed ``time s`` (report.html);
* stdout of the benchmarks: the time in the header ``(R runs, seed S, X s)``, the rows whose
  label starts with ``run time`` are dropped (and runs of blanks collapsed: a table's column
  width follows its widest cell, which can be a dropped run-time row), and in the scripts' stdout every number followed
  by a time unit (``s``, ``ms``, ``us``, ``µs``) and every ``x`` speed ratio becomes ``<time>``;
* stderr: lines about compiling kernels (numba's cache state, not behaviour) are dropped.

numba caches navpp's compiled kernels keyed on the source file of each kernel: a constant of
another module that a kernel reads as a global (e.g. ``geodesy.OMEGA_E``) is frozen into the
cached machine code, so after such a change record with ``--cold-cache`` (kernels compiled
afresh in a temporary cache) or the snapshot can show the old behaviour.

Binary files (MCAP, PNG) are hashed as written.  What is kept to measure a difference: for CSV
and TUM files per numeric column its count, minimum, maximum, sum and sum of absolute values
(``compare`` prints the largest difference of these, a lower bound of the largest cell
difference; with ``record --keep DIR`` on both sides and the directories still there, it reads
both files and prints the exact largest cell difference per column); for JSON the numeric
leaves (up to 20,000) and ``compare`` prints the largest difference; for other text up to
40,000 characters, and ``compare`` prints the first differing lines.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import hashlib
import json
import math
import multiprocessing
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LOGS = ("sample_data/drive", "sample_data/drive.mcap", "sample_data/drive.bag", "sample_data/drive_ros2",
        "sample_data/walk_0827")
TIME_KEYS = frozenset({"runtime_s", "smoothing_s", "compile_s", "wall_s", "seconds"})
TEXT_SUFFIXES = frozenset({".csv", ".json", ".geojson", ".kml", ".tum", ".md", ".html", ".txt", ".toml", ".yaml"})
TEXT_KEEP_CHARS = 40_000
JSON_KEEP_LEAVES = 20_000
SCRIPT_BENCHMARKS = ("bench_filters", "bench_faults", "bench_smoother", "bench_aiding", "bench_realism")


@dataclass
class Case:
    """One navpp command line: ``argv`` with ``{out}`` standing for the case's output directory."""
    name: str
    argv: list[str]
    script: bool = False           # a benchmarks/ script run as a child process, not a navpp command
    extra: dict = field(default_factory=dict)


def filter_names() -> list[str]:
    """The registered filters' names (what ``navpp filters`` lists), sorted."""
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from navpp.filters import FILTERS
    return sorted(FILTERS)


def paper_benchmarks() -> list[str]:
    """The names ``navpp bench`` lists (the first word of each line of its listing)."""
    res = _run_case(Case("bench-list", ["bench"]), str(REPO))
    return sorted(ln.split()[0] for ln in res["stdout"].splitlines() if ln.strip())


def build_cases(logs: list[str], filters: list[str], extras: bool, benchmarks: bool) -> list[Case]:
    """The cases of a snapshot: ``process`` of every filter on every log, and with ``extras`` the
    rest of the list in the module docstring; with ``benchmarks`` the expensive benchmarks too."""
    def slug(log: str) -> str:
        return Path(log).name.replace(".", "_")

    cases = [Case(f"process-{slug(log)}-{f}", ["process", log, "-f", f, "--out", "{out}", "-q"])
             for log in logs for f in filters]
    if not extras:
        return cases
    cases += [Case(f"smooth-drive-{f}", ["process", "sample_data/drive", "-f", f, "--smooth", "--out", "{out}", "-q"])
              for f in filters]
    cases += [
        Case("smooth-walk_0827-ekf", ["process", "sample_data/walk_0827", "--smooth", "--out", "{out}", "-q"]),
        Case("formats-drive-ekf", ["process", "sample_data/drive", "--format", "csv,mcap,tum,geojson,kml",
                                   "--out", "{out}", "-q"]),
        Case("formats-walk_0827-ekf", ["process", "sample_data/walk_0827", "--format", "csv,mcap,tum,geojson,kml",
                                       "--out", "{out}", "-q"]),
        Case("embed-drive_mcap-ekf", ["process", "sample_data/drive.mcap", "--format", "mcap", "--embed-input",
                                      "--out", "{out}", "-q"]),
        Case("rate-outage-drive-ekf", ["process", "sample_data/drive", "--output-rate", "10",
                                       "--gnss-outage", "120:30", "--out", "{out}", "-q"]),
        Case("compare-smooth", ["compare", "sample_data/drive", "sample_data/walk_0827", "--smooth", "--json",
                                "--out", "{out}", "-q"]),
        Case("filters", ["filters"]),
        Case("simulate-seed7", ["simulate", "{out}", "--duration", "60", "--still", "30", "--seed", "7"]),
        Case("simulate-realism-seed3", ["simulate", "{out}", "--duration", "60", "--realism", "consumer-car",
                                        "--seed", "3"]),
    ]
    cases += [Case(f"inspect-{slug(log)}", ["inspect", log]) for log in LOGS]
    cases += [Case(f"bench-{b}-runs2", ["bench", b, "--runs", "2"]) for b in paper_benchmarks()]
    if benchmarks:
        cases += [Case(f"bench-{b}", ["bench", b]) for b in paper_benchmarks()]
        cases += [Case(f"script-{s}", [str(REPO / "benchmarks" / f"{s}.py")], script=True) for s in SCRIPT_BENCHMARKS]
        real = REPO.parent / "shared" / "data" / "real"
        if real.is_dir():
            cases.append(Case("script-bench_real", [str(REPO / "benchmarks" / "bench_real.py")], script=True))
    return cases


# ---------------------------------------------------------------------------------------------
# running

def _run_case(case: Case, root: str) -> dict:
    """Run ``case`` with its output directory under ``root``; exit code, stdout, stderr."""
    out = Path(root) / case.name
    argv = [a.replace("{out}", str(out)) for a in case.argv]
    if case.script:
        env = dict(os.environ, PYTHONPATH=str(REPO))
        p = subprocess.run([sys.executable, *argv], cwd=REPO, env=env, capture_output=True, text=True,
                           check=False)
        return {"exit": p.returncode, "stdout": p.stdout, "stderr": p.stderr}
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from typer.testing import CliRunner

    from navpp.cli import app
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        res = CliRunner().invoke(app, argv, env={"COLUMNS": "200"})
    finally:
        os.chdir(cwd)
    stdout, stderr = res.stdout, res.stderr
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        stderr += f"\nexception: {type(res.exception).__name__}: {res.exception}"
    return {"exit": res.exit_code, "stdout": stdout, "stderr": stderr}


def run_cases(cases: list[Case], root: Path, jobs: int, quiet: bool = False) -> dict[str, dict]:
    """Run every case into ``root/<case>``; {case name: exit code, stdout, stderr}."""
    results: dict[str, dict] = {}
    if jobs <= 1:
        for c in cases:
            t0 = time.perf_counter()
            results[c.name] = _run_case(c, str(root))
            if not quiet:
                print(f"  {c.name}: exit {results[c.name]['exit']} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
        return results
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
        futs = {pool.submit(_run_case, c, str(root)): c for c in cases}
        for fut in cf.as_completed(futs):
            c = futs[fut]
            results[c.name] = fut.result()
            if not quiet:
                print(f"  {c.name}: exit {results[c.name]['exit']}", file=sys.stderr)
    return results


# ---------------------------------------------------------------------------------------------
# normalisation and digests

_RUNTIME_LINE = re.compile(r"^- runtime: [0-9.eE+-]+ s$", re.MULTILINE)
_SMOOTHING_TIME = re.compile(r"(\(Rauch-Tung-Striebel, \d+ nodes, )[0-9.]+ s\)")
_BENCH_HEADER_TIME = re.compile(r"(\(\d+ runs?, seed -?\d+, )[0-9.]+ s\)")
_TIME_UNIT = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?\s?(?:s|ms|us|µs)\b")
_SPEED_RATIO = re.compile(r"(?<![\w.])\d+(?:\.\d+)?x\b")


def normalise_text(text: str, root: Path) -> str:
    """Absolute paths of the temporary root and of the repository replaced by ``<OUT>``, ``<REPO>``."""
    return text.replace(str(root), "<OUT>").replace(str(REPO), "<REPO>")


def _blank_times(obj):
    if isinstance(obj, dict):
        return {k: ("<time>" if k in TIME_KEYS and v is not None else _blank_times(v)) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_blank_times(v) for v in obj]
    return obj


def _numeric_leaves(obj, prefix: str = "", out: dict | None = None) -> dict[str, float]:
    out = {} if out is None else out
    if isinstance(obj, dict):
        for k, v in obj.items():
            _numeric_leaves(v, f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            _numeric_leaves(v, f"{prefix}[{i}]", out)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        out[prefix] = float(obj)
    return out


def _blank_md_time_columns(text: str) -> str:
    lines, cols = text.split("\n"), None
    for i, line in enumerate(lines):
        if not line.startswith("|"):
            cols = None
            continue
        cells = line.split("|")
        if cols is None:
            cols = [j for j, c in enumerate(cells) if c.strip() == "time s"]
            continue
        if cols and not set(line) <= set("|-: "):
            for j in cols:
                if j < len(cells) - 1:
                    cells[j] = " <time> "
            lines[i] = "|".join(cells)
    text = _RUNTIME_LINE.sub("- runtime: <time> s", "\n".join(lines))
    return _SMOOTHING_TIME.sub(r"\1<time> s)", text)


def _blank_html_time_columns(text: str) -> str:
    def table(m: re.Match) -> str:
        t = m.group(0)
        heads = re.findall(r"<th[^>]*>(.*?)</th>", t, flags=re.DOTALL)
        cols = [j for j, h in enumerate(heads) if h.strip() == "time s"]
        if not cols:
            return t

        def row(r: re.Match) -> str:
            parts = re.split(r"(<td[^>]*>.*?</td>)", r.group(0), flags=re.DOTALL)
            tds = [k for k, p in enumerate(parts) if p.startswith("<td")]
            for j in cols:
                if j < len(tds):
                    parts[tds[j]] = re.sub(r">.*?</td>$", "><time></td>", parts[tds[j]], flags=re.DOTALL)
            return "".join(parts)
        return re.sub(r"<tr>.*?</tr>", row, t, flags=re.DOTALL)
    return re.sub(r"<table.*?</table>", table, text, flags=re.DOTALL)


def _csv_columns(text: str, delimiter: str | None, header: bool) -> tuple[list[str], list[list[str]]]:
    rows = [(ln.split(delimiter) if delimiter else ln.split()) for ln in text.splitlines() if ln.strip()]
    if header and rows:
        return rows[0], rows[1:]
    n = max((len(r) for r in rows), default=0)
    return [f"col{j}" for j in range(n)], rows


def _column_stats(names: list[str], rows: list[list[str]]) -> dict[str, list[float]]:
    """Per numeric column: [count, min, max, sum, sum of |x|] of its finite values."""
    stats: dict[str, list[float]] = {}
    for j, name in enumerate(names):
        vals = []
        for r in rows:
            if j < len(r):
                try:
                    v = float(r[j])
                except ValueError:
                    break
                if math.isfinite(v):
                    vals.append(v)
        else:
            if vals:
                stats[name] = [float(len(vals)), min(vals), max(vals), math.fsum(vals), math.fsum(abs(v) for v in vals)]
    return stats


def digest_bytes(name: str, data: bytes, root: Path) -> dict:
    """The record of one output file ``name`` (its bytes ``data``): normalised sha256 and size,
    and what ``compare`` uses to measure a difference."""
    suffix = Path(name).suffix.lower()
    rec: dict = {"size": len(data)}
    if suffix not in TEXT_SUFFIXES:
        rec["sha256"] = hashlib.sha256(data).hexdigest()
        return rec
    text = normalise_text(data.decode("utf-8", errors="replace"), root)
    if suffix in (".json", ".geojson"):
        try:
            obj = _blank_times(json.loads(text))
        except json.JSONDecodeError:
            pass
        else:
            text = json.dumps(obj, sort_keys=True, indent=0)
            leaves = _numeric_leaves(obj)
            if len(leaves) <= JSON_KEEP_LEAVES:
                rec["numbers"] = leaves
    elif suffix in (".csv", ".tum"):
        names, rows = _csv_columns(text, "," if suffix == ".csv" else None, header=suffix == ".csv")
        times = [j for j, n in enumerate(names) if n.strip() in TIME_KEYS]
        if times:
            for r in rows:
                for j in times:
                    if j < len(r):
                        r[j] = "<time>"
            text = "\n".join(",".join(r) for r in ([names] + rows))
        rec["columns"] = _column_stats(names, rows)
    elif suffix == ".md":
        text = _blank_md_time_columns(text)
    elif suffix == ".html":
        text = _blank_html_time_columns(text)
    rec["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    if len(text) <= TEXT_KEEP_CHARS and suffix not in (".csv", ".tum", ".json", ".geojson"):
        rec["text"] = text
    return rec


def normalise_stream(text: str, root: Path, case: Case, stream: str) -> str:
    """stdout / stderr of a case, normalised as the module docstring says."""
    text = normalise_text(text, root)
    if stream == "stderr":
        return "\n".join(ln for ln in text.splitlines() if "compil" not in ln.lower())
    if case.argv[:1] == ["compare"] and "--json" in case.argv:
        try:
            return json.dumps(_blank_times(json.loads(text)), sort_keys=True, indent=0)
        except json.JSONDecodeError:
            return text
    if case.argv[:1] == ["bench"] or case.script:
        text = "\n".join(ln for ln in text.splitlines() if not ln.lower().startswith("run time"))
        text = _BENCH_HEADER_TIME.sub(r"\1<time> s)", text)
        text = "\n".join(" ".join(ln.split()) for ln in text.splitlines())   # column widths follow the dropped rows
    if case.script:
        text = _SPEED_RATIO.sub("<time>", _TIME_UNIT.sub("<time>", text))
    return text


def digest_case(case: Case, result: dict, root: Path) -> dict:
    """The record of one case: exit code, normalised stdout/stderr, and its output files."""
    rec: dict = {"argv": case.argv, "exit": result["exit"], "files": {}}
    for stream in ("stdout", "stderr"):
        text = normalise_stream(result[stream], root, case, stream)
        rec[stream] = {"sha256": hashlib.sha256(text.encode()).hexdigest(), "text": text[:TEXT_KEEP_CHARS]}
    out = root / case.name
    if out.is_dir():
        for p in sorted(out.rglob("*")):
            if p.is_file():
                rec["files"][str(p.relative_to(out))] = digest_bytes(p.name, p.read_bytes(), root)
    return rec


def record(cases: list[Case], jobs: int = 2, keep: Path | None = None, quiet: bool = False) -> dict:
    """Run ``cases`` and return the snapshot (a JSON-able dict).  With ``keep`` the outputs stay
    in ``keep`` (made absolute), which the snapshot names, so ``compare`` can read the files."""
    t0 = time.perf_counter()
    if keep is not None:
        root = keep.resolve()
        if root.exists():
            shutil.rmtree(root)
        root.mkdir(parents=True)
        tmp = None
    else:
        tmp = tempfile.TemporaryDirectory(prefix="navpp-snapshot-")
        root = Path(tmp.name).resolve()
    try:
        results = run_cases(cases, root, jobs, quiet)
        snap = {"navpp_snapshot": 1, "kept": str(root) if keep is not None else None,
                "cases": {c.name: digest_case(c, results[c.name], root) for c in cases}}
    finally:
        if tmp is not None:
            tmp.cleanup()
    if not quiet:
        print(f"recorded {len(cases)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return snap


# ---------------------------------------------------------------------------------------------
# comparison

def _largest(a: dict[str, float], b: dict[str, float]) -> tuple[str, float] | None:
    worst = None
    for k in a.keys() & b.keys():
        x, y = a[k], b[k]
        if math.isfinite(x) and math.isfinite(y):
            d = abs(x - y)
        else:
            d = 0.0 if (x == y or (math.isnan(x) and math.isnan(y))) else math.inf
        if d > 0 and (worst is None or d > worst[1]):
            worst = (k, d)
    return worst


def _exact_column_diff(pa: Path, pb: Path) -> str | None:
    """Largest cell difference per numeric column of two CSV / TUM files (the kept outputs)."""
    tum = pa.suffix == ".tum"
    ra = _csv_columns(pa.read_text(), None if tum else ",", not tum)
    rb = _csv_columns(pb.read_text(), None if tum else ",", not tum)
    if ra[0] != rb[0]:
        return f"columns differ: {ra[0]} vs {rb[0]}"
    if len(ra[1]) != len(rb[1]):
        return f"row count {len(ra[1])} vs {len(rb[1])}"
    worst: dict[str, tuple[float, int]] = {}
    for i, (x, y) in enumerate(zip(ra[1], rb[1])):
        for j, name in enumerate(ra[0]):
            if j < len(x) and j < len(y) and x[j] != y[j]:
                try:
                    d = abs(float(x[j]) - float(y[j]))
                except ValueError:
                    d = math.inf
                if name not in worst or d > worst[name][0]:
                    worst[name] = (d, i + 1)
    if not worst:
        return None
    return "; ".join(f"{n}: largest cell difference {d:.6g} (row {r})" for n, (d, r) in
                     sorted(worst.items(), key=lambda kv: -kv[1][0]))


def _text_diff(a: str, b: str, limit: int = 6) -> list[str]:
    import difflib
    lines = [ln for ln in difflib.unified_diff(a.splitlines(), b.splitlines(), "A", "B", n=0, lineterm="")
             if not ln.startswith(("---", "+++", "@@"))]
    more = f"  ... {len(lines) - limit} more diff lines" if len(lines) > limit else None
    return [f"    {ln[:200]}" for ln in lines[:limit]] + ([more] if more else [])


def compare_snapshots(a: dict, b: dict) -> list[str]:
    """Every difference between snapshots ``a`` and ``b``, one message each (empty: identical)."""
    out: list[str] = []
    ca, cb = a["cases"], b["cases"]
    for name in sorted(ca.keys() - cb.keys()):
        out.append(f"{name}: only in A")
    for name in sorted(cb.keys() - ca.keys()):
        out.append(f"{name}: only in B")
    for name in sorted(ca.keys() & cb.keys()):
        x, y = ca[name], cb[name]
        if x["exit"] != y["exit"]:
            out.append(f"{name}: exit code {x['exit']} vs {y['exit']}")
        for stream in ("stdout", "stderr"):
            if x[stream]["sha256"] != y[stream]["sha256"]:
                out.append(f"{name}: {stream} differs")
                out += _text_diff(x[stream]["text"], y[stream]["text"])
        for f in sorted(x["files"].keys() - y["files"].keys()):
            out.append(f"{name}/{f}: only in A")
        for f in sorted(y["files"].keys() - x["files"].keys()):
            out.append(f"{name}/{f}: only in B")
        for f in sorted(x["files"].keys() & y["files"].keys()):
            fa, fb = x["files"][f], y["files"][f]
            if fa["sha256"] == fb["sha256"]:
                continue
            msg = f"{name}/{f}: differs (size {fa['size']} vs {fb['size']} bytes)"
            detail: list[str] = []
            if "numbers" in fa and "numbers" in fb:
                w = _largest(fa["numbers"], fb["numbers"])
                keys = fa["numbers"].keys() ^ fb["numbers"].keys()
                if w:
                    detail.append(f"    largest numeric difference {w[1]:.6g} at {w[0]}")
                if keys:
                    detail.append(f"    numbers only on one side: {sorted(keys)[:5]}")
            if "columns" in fa and "columns" in fb:
                exact = None
                if a.get("kept") and b.get("kept"):
                    pa, pb = Path(a["kept"]) / name / f, Path(b["kept"]) / name / f
                    if pa.is_file() and pb.is_file():
                        exact = _exact_column_diff(pa, pb)
                        if exact:
                            detail.append(f"    {exact}")
                if exact is None:
                    stat = ("count", "min", "max", "sum", "sum|x|")
                    worst = None
                    for col in fa["columns"].keys() & fb["columns"].keys():
                        for s, u, v in zip(stat, fa["columns"][col], fb["columns"][col]):
                            d = abs(u - v)
                            if d > 0 and (worst is None or d > worst[0]):
                                worst = (d, col, s, u, v)
                    if worst:
                        d, col, s, u, v = worst
                        detail.append(f"    largest column-statistic difference {d:.6g}: {col} {s} {u!r} vs {v!r} "
                                      "(a lower bound of the largest cell difference; record --keep for the exact one)")
                    only = fa["columns"].keys() ^ fb["columns"].keys()
                    if only:
                        detail.append(f"    numeric columns on one side only: {sorted(only)}")
            if "text" in fa and "text" in fb:
                detail += _text_diff(fa["text"], fb["text"])
            out.append(msg)
            out += detail
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="run every case and write the snapshot")
    r.add_argument("out", type=Path, help="snapshot file (JSON) to write")
    r.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    r.add_argument("--benchmarks", action="store_true", help="also the expensive benchmarks (tens of minutes)")
    r.add_argument("--keep", type=Path, help="keep the outputs in this directory (emptied first)")
    r.add_argument("--logs", help="comma-separated logs (default: the five of sample_data/)")
    r.add_argument("--filters", help="comma-separated filters (default: every registered filter)")
    r.add_argument("--process-only", action="store_true", help="only the `process` cases of --logs x --filters")
    r.add_argument("--cold-cache", action="store_true",
                   help="compile navpp's kernels afresh (NUMBA_CACHE_DIR = a new temporary directory; a few minutes "
                        "more): numba's cache is keyed on the kernel's own file, so a changed constant of another "
                        "module that a kernel reads can hide behind a cached kernel")
    c = sub.add_parser("compare", help="print every difference between two snapshots; exit 1 if any")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "record":
        if args.cold_cache:          # before navpp (and numba) is imported here or in the workers
            os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="navpp-snapshot-numba-")
        logs = args.logs.split(",") if args.logs else list(LOGS)
        filters = args.filters.split(",") if args.filters else filter_names()
        cases = build_cases(logs, filters, extras=not args.process_only, benchmarks=args.benchmarks)
        snap = record(cases, jobs=args.jobs, keep=args.keep)
        args.out.write_text(json.dumps(snap, indent=1, sort_keys=True))
        failed = [n for n, c in snap["cases"].items() if c["exit"] != 0]
        print(f"wrote {args.out}: {len(snap['cases'])} cases, "
              f"{sum(len(c['files']) for c in snap['cases'].values())} files"
              + (f"; nonzero exit (recorded as such): {', '.join(failed)}" if failed else ""))
        return 0
    diffs = compare_snapshots(json.loads(args.a.read_text()), json.loads(args.b.read_text()))
    for line in diffs:
        print(line)
    n = sum(1 for d in diffs if not d.startswith(" "))
    print(f"{n} difference(s)" if n else "identical")
    return 1 if n else 0


if __name__ == "__main__":
    sys.exit(main())
