"""Harness for the table-driven bad-input tests (issue 15): one :class:`Case` per bad input.

A case builds its inputs in a fresh directory (a mutated copy of ``sample_data/drive`` or a
log of its own), runs the ``navpp`` command line in a subprocess (``python -m navpp``, so the
checkout under test is the one imported) and checks the user's contract for bad input:

- the exit code (1 for bad input, 130 for an interrupt);
- stderr ends with one ``navpp: ...`` line under 300 characters holding the case's fragment
  (case-insensitive), with no traceback; lines before it may only be ``warning: ...`` lines
  about the data and ``· ...`` notes (what the run noticed before it stopped);
- nothing is written: the ``--out`` directory is absent afterwards, or holds exactly what it
  held before (same names, same bytes);
- every input is untouched (same names, same bytes, same mtimes under the input directory);
- the run ends within the case's time limit (60 s) and its peak memory (RSS of the child) is
  under 1 GB.

Each area's rows live in their own ``tests/test_bad_inputs_*.py`` as a list of cases passed to
:func:`run_case`.
"""

from __future__ import annotations

import hashlib
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_data"
DRIVE = SAMPLE / "drive"

MAX_LINE = 300
MAX_SECONDS = 60.0
MAX_RSS_BYTES = 1 << 30


@dataclass(frozen=True)
class Case:
    """One bad input.

    name : the test id.
    build : ``build(work) -> argv`` makes the inputs under ``work`` (a fresh directory) and
        returns the arguments after ``navpp`` (e.g. ``["process", str(log), "--out", str(out)]``).
        The output directory must be ``work / "out"`` (it may already exist with files in it:
        those must survive byte for byte).
    fragment : text the one-line message must contain (case-insensitive), or a tuple of texts
        that must all appear.
    code : expected exit code.
    env : extra environment variables for the child.
    slow : a variant of a faster row (another filter, a bigger file): run with the slow tests
        only, so the default run stays within its CPU budget.
    process : run ``python -m navpp`` in a child process (peak memory measured, the interpreter's
        own exit path taken).  Otherwise the command line runs in this process through
        ``typer.testing.CliRunner`` (about 1 s less per row: no interpreter and import start-up),
        which checks the same contract bar the memory figure.  Rows with ``env`` always run in a
        child.
    """

    name: str
    build: Callable[[Path], list[str]]
    fragment: str | tuple[str, ...]
    code: int = 1
    env: dict[str, str] = field(default_factory=dict)
    timeout_s: float = MAX_SECONDS
    slow: bool = False
    process: bool = False


def params(cases: list[Case]) -> list:
    """``cases`` as pytest parameters: named by the case, the ``slow`` ones marked slow."""
    import pytest

    return [pytest.param(c, id=c.name, marks=[pytest.mark.slow] if c.slow else []) for c in cases]


def copy_drive(work: Path, name: str = "log") -> Path:
    """A writable copy of ``sample_data/drive`` under ``work/name``; returns its path."""
    dst = work / name
    shutil.copytree(DRIVE, dst)
    return dst


def edit_csv(path: Path, edit: Callable[[list[str]], list[str]]) -> None:
    """Rewrite a CSV file through ``edit(lines) -> lines`` (lines without newline)."""
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


def snapshot(root: Path, skip: Path | None = None) -> dict[str, tuple[str, int]]:
    """{relative path: (sha256, mtime_ns)} of every file under ``root`` (``skip`` excluded)."""
    out: dict[str, tuple[str, int]] = {}
    if not root.exists():
        return out
    for p in sorted(root.rglob("*")):
        if skip is not None and (p == skip or skip in p.parents):
            continue
        if p.is_file():
            # hashed a block at a time: a whole 2 GB input read into this process would raise its
            # peak RSS, which a vfork'ed child's ru_maxrss then reports as its own
            with open(p, "rb") as f:
                digest = hashlib.file_digest(f, "sha256").hexdigest()
            out[str(p.relative_to(root))] = (digest, p.stat().st_mtime_ns)
    return out


def _child_env(extra: dict[str, str]) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("COLUMNS", "200")
    env.update(extra)
    return env


def run_navpp(argv: list[str], env: dict[str, str] | None = None, timeout_s: float = MAX_SECONDS,
              cwd: Path | None = None) -> tuple[int, str, str, float]:
    """Run ``python -m navpp argv``; returns (exit code, stdout, stderr, wall seconds)."""
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "navpp", *argv], capture_output=True, text=True,
                          env=_child_env(env or {}), timeout=timeout_s, cwd=cwd)
    return proc.returncode, proc.stdout, proc.stderr, time.monotonic() - t0


def run_in_process(argv: list[str], cwd: Path) -> tuple[int, str, str, float]:
    """Run the ``navpp`` command line ``argv`` in this process (``CliRunner``, cwd = ``cwd``);
    returns (exit code, stdout, stderr, wall seconds).  An exception that escapes the command
    (other than SystemExit) is returned as its traceback on stderr, so a case sees it."""
    import traceback

    from typer.testing import CliRunner

    from navpp.cli import app

    here = os.getcwd()
    t0 = time.monotonic()
    try:
        os.chdir(cwd)
        res = CliRunner().invoke(app, argv, env={"COLUMNS": "200"})
    finally:
        os.chdir(here)
    wall = time.monotonic() - t0
    stderr = res.stderr
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        stderr += "".join(traceback.format_exception(res.exception))
    return res.exit_code, res.stdout, stderr, wall


def run_case(case: Case, work: Path) -> str:
    """Build, run and check ``case`` in the fresh directory ``work``; returns the message line."""
    work.mkdir(parents=True, exist_ok=True)
    argv = case.build(work)
    out = work / "out"
    before_out = snapshot(out)
    before_in = snapshot(work, skip=out)
    child = case.process or bool(case.env)
    rss0 = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if child:
        code, stdout, stderr, wall = run_navpp(argv, case.env, case.timeout_s, cwd=work)
    else:
        code, stdout, stderr, wall = run_in_process(argv, work)
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    where = f"{case.name}: navpp {' '.join(argv)}\nexit {code}\nstderr:\n{stderr[-3000:]}\nstdout:\n{stdout[-1500:]}"
    assert code == case.code, where
    assert "Traceback" not in stderr and "Traceback" not in stdout, where
    errors = [ln for ln in lines if ln.startswith("navpp:")]
    assert len(errors) == 1 and lines[-1] == errors[0], f"expected one 'navpp: ...' line, last on stderr\n{where}"
    # the run's warnings and its notes ("· ...", what it measured before it failed) may come first,
    # as in tests/test_cli.py's assert_one_line_error
    assert all(ln.startswith(("warning:", "· ")) for ln in lines[:-1]), \
        f"stderr holds more than warnings, notes and the error\n{where}"
    msg = errors[0]
    assert len(msg) < MAX_LINE, f"message of {len(msg)} characters\n{where}"
    frags = (case.fragment,) if isinstance(case.fragment, str) else case.fragment
    for frag in frags:
        assert frag.lower() in msg.lower(), f"{frag!r} not in the message\n{where}"
    assert snapshot(out) == before_out, f"--out changed\n{where}"
    assert snapshot(work, skip=out) == before_in, f"an input changed or a file was left beside the inputs\n{where}"
    assert wall < case.timeout_s, where
    if child and rss > rss0:   # ru_maxrss is the largest child so far (KiB on Linux): only a new maximum is this run's
        assert rss * 1024 < MAX_RSS_BYTES, f"peak RSS {rss / 1024:.0f} MB\n{where}"
    return msg
