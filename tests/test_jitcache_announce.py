"""The compile announcement (navpp.jitcache.CompileAnnouncer): one line before navpp's first
cold kernel compiles, none when everything is already compiled, and the compile seconds."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from numba import njit

from navpp.jitcache import CompileAnnouncer

ROOT = Path(__file__).resolve().parents[1]


def _kernel(fn, module: str = "navpp._probe"):
    """``fn`` jitted (not cached, so it compiles in this process), owned by ``module``."""
    fn.__module__ = module
    return njit(fn)


def test_announces_once_before_the_first_compile() -> None:
    def inner(a):
        return a * 2.0

    k_inner = _kernel(inner)

    def outer(a):
        return k_inner(a) + 1.0

    k_outer = _kernel(outer)

    def other(a):
        return a - 3.0

    k_other = _kernel(other)
    said = []
    with CompileAnnouncer(lambda line: said.append((line, list(k_outer.signatures)))) as jit:
        assert k_outer(2.0) == 5.0          # outer compiles, inner inside it
        assert k_other(2.0) == -1.0         # a second cold kernel: no second line
        assert k_outer(3.0) == 7.0          # already compiled: nothing
    assert said == [(CompileAnnouncer.LINE, [])]        # said before outer had any compiled signature
    assert jit.kernels == 2                             # outermost compilations only (inner is part of outer)
    assert jit.seconds > 0.0


def test_silent_when_warm_and_for_foreign_kernels() -> None:
    def warm(a):
        return a + 1.0

    k_warm = _kernel(warm)
    k_warm(1.0)                                         # compiled before the command

    def foreign(a):
        return a + 2.0

    k_foreign = _kernel(foreign, module="someone_else")
    said = []
    with CompileAnnouncer(said.append) as jit:
        assert k_warm(2.0) == 3.0
        assert k_foreign(1.0) == 3.0                    # compiles, but not navpp's
    assert said == [] and jit.kernels == 0 and jit.seconds == 0.0

    def later(a):
        return a + 4.0

    _kernel(later)(1.0)                                 # after the command: the listener is gone
    assert said == []


@pytest.mark.slow
def test_cold_process_announces_and_warm_does_not(tmp_path) -> None:
    """A first `navpp process` with an empty NUMBA_CACHE_DIR says it compiles (before the summary
    reports the seconds); the same command again loads the cache and says neither."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    log = str(ROOT / "sample_data" / "drive.mcap")
    errs = []
    for i in range(2):
        p = subprocess.run([sys.executable, "-m", "navpp", "process", log, "--out", str(tmp_path / f"o{i}")],
                           env=env, capture_output=True, text=True, cwd=tmp_path, check=True)
        errs.append(p.stderr)
    cold, warm = errs
    assert cold.count("compiling navpp's numba kernels") == 1
    assert cold.index("compiling navpp's numba kernels") < cold.index("compiled navpp's kernels in")
    assert "compiling navpp's numba kernels" not in warm and "compiled navpp's kernels" not in warm
    assert (tmp_path / "o0" / "trajectory.csv").read_bytes() == (tmp_path / "o1" / "trajectory.csv").read_bytes()
