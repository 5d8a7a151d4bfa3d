"""The native module (navpp.kernel, navpp.native): argument types matched as numba types them,
entry points giving numba's results, every other call going to numba.

Oracles: numba's own ``typeof`` for the argument types; numpy for the kernels' figures; for the
whole pipeline (slow), the same run on numba's dispatchers, byte for byte.
"""

from __future__ import annotations

import collections
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from navpp import kernel

SAMPLES = Path(__file__).resolve().parent.parent / "sample_data"
ROOT = Path(__file__).resolve().parent.parent


def _values() -> list[object]:
    """Arguments of every kind a kernel may get: arrays of each dtype, rank and layout, read-only
    and memory-mapped; Python and numpy scalars; None; tuples, nested."""
    a = np.arange(24.0).reshape(4, 6)
    ro = np.arange(5.0)
    ro.flags.writeable = False
    out: list[object] = [a, a.T, a[:, ::2], a[0], a[:, 0], np.asfortranarray(a), ro, np.empty((0, 3)),
                         np.array(2.0), np.zeros((2, 3, 4), np.float32), np.zeros(3, np.int64),
                         np.zeros(3, np.int32), np.zeros(3, np.uint8), np.zeros(3, np.uint64), np.zeros(3, bool),
                         np.zeros(3, np.complex128), 1.5, 3, -(1 << 63), (1 << 63) - 1, True, False, None,
                         np.float64(1.0), np.float32(1.0), np.int64(2), np.int32(2), np.uint8(3), np.bool_(True),
                         (a, 1.0), (a, a), (1, (2.0, None)), ()]
    return out


def test_value_spec_is_numba_typeof() -> None:
    """For each kind of argument, the text navpp.kernel writes from the value equals the text
    navpp.native writes from numba's type of it (numba.typeof is the oracle)."""
    from numba import typeof

    from navpp.native import type_spec

    for v in _values():
        assert kernel.value_spec(v) == type_spec(typeof(v)), repr(v)[:80]


def test_value_spec_declines_what_it_cannot_check(tmp_path: Path) -> None:
    """Values whose numba type the native entry points do not take (or that numba types in its
    own way) give None, so the call goes to numba: strings, lists, records, named tuples, masked
    arrays, unaligned arrays, integers beyond int64; a memory map is an array like any other."""
    Pair = collections.namedtuple("Pair", "a b")
    record = np.zeros(3, dtype=[("x", "f8"), ("y", "i4")])
    unaligned = np.frombuffer(bytes(17), dtype=np.uint8)[1:].view(np.float64)
    assert not unaligned.flags.aligned
    for v in ["text", [1.0], record, Pair(1.0, 2.0), np.ma.masked_array([1.0]), unaligned, 1 << 63, {1: 2},
              (1.0, "x")]:
        assert kernel.value_spec(v) is None, repr(v)[:80]
    mm = np.memmap(tmp_path / "m.bin", dtype=np.float64, mode="w+", shape=(4, 2))
    assert kernel.value_spec(mm) == "a<f82Cw"
    ro = np.memmap(tmp_path / "m.bin", dtype=np.float64, mode="r", shape=(4, 2))
    assert kernel.value_spec(ro) == "a<f82Cr"
    assert kernel.call_spec((ro, 1.0, (2, None))) == "a<f82Cr;float64;(int64,none)"
    assert kernel.call_spec((ro, "x")) is None


KERNELS = '''
import numpy as np
from navpp.kernel import njit


@njit(cache=True, inline="always")
def _square(x):
    return x * x


@njit(cache=True)
def weighted(a, w, scale):
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        out[i] = _square(a[i]) * w[i] * scale
    return out


@njit(cache=True)
def total(a, pair):
    return weighted(a, pair[0], pair[1]).sum() + pair[1]
'''

USE = '''
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import nk_mod
from navpp import kernel

a = np.arange(6.0)
w = np.linspace(1.0, 2.0, 6)
out = {"kernel": isinstance(nk_mod.weighted, kernel.Kernel),
       "signatures": sorted(nk_mod.weighted.native_signatures)}
out["weighted"] = nk_mod.weighted(a, w, 2.0).tolist()
out["total"] = nk_mod.total(a, (w, 3.0))
out["numba_after_native"] = "numba" in sys.modules
# an int64 array has a float64's size: the entry point would reinterpret it; it must go to numba
out["int"] = nk_mod.weighted(np.arange(6), w, 2.0).tolist()
out["numba_after_int"] = "numba" in sys.modules
out["strided"] = nk_mod.weighted(a[::2], w[::2], 2.0).tolist()
out["keyword"] = nk_mod.weighted(a, w, scale=2.0).tolist()
# numba compiles total for strided arrays: its callee weighted is a Kernel, typed as its dispatcher
out["total_strided"] = nk_mod.total(a[::2], (w[::2], 3.0))
print(json.dumps(out))
'''


def test_native_module_runs_numba_results_and_declines_the_rest(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A module built from two small kernels (one calling the other, which inlines a third):
    a process with the module runs them without importing numba, with numpy's figures; an int64
    array (a float64's size, which the entry point would misread), a strided array and a keyword
    argument go to numba, imported then, with the right figures too."""
    from navpp.native import build

    (tmp_path / "nk_mod.py").write_text(KERNELS)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("NAVPP_NATIVE_DIR", str(tmp_path / "native"))
    import nk_mod

    a, w = np.arange(6.0), np.linspace(1.0, 2.0, 6)
    expected = a * a * w * 2.0
    np.testing.assert_array_equal(nk_mod.weighted(a, w, 2.0), expected)    # compiled here by numba
    jit_total = nk_mod.total(a, (w, 3.0))
    result = build(dispatchers=[nk_mod._square, nk_mod.weighted, nk_mod.total])
    assert result.built and result.kernels == 2 and result.entries == 2
    manifest = json.loads(Path(kernel.native_paths()[2]).read_text())
    assert set(manifest["kernels"]) == {"nk_mod:weighted", "nk_mod:total"}
    again = build(dispatchers=[nk_mod._square, nk_mod.weighted, nk_mod.total])
    assert not again.built                          # same entry points: the module is kept

    env = {**os.environ, "NAVPP_NATIVE": "1", "NAVPP_NATIVE_DIR": str(tmp_path / "native"),
           "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", USE, str(tmp_path)], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    assert got["kernel"] and got["signatures"] == ["a<f81Cw;a<f81Cw;float64"]
    assert got["weighted"] == expected.tolist()
    assert got["total"] == jit_total
    assert got["numba_after_native"] is False
    assert got["int"] == (np.arange(6) ** 2 * w * 2.0).tolist()
    assert got["numba_after_int"] is True
    assert got["strided"] == (a[::2] ** 2 * w[::2] * 2.0).tolist()
    assert got["keyword"] == expected.tolist()
    assert got["total_strided"] == pytest.approx(float((a[::2] ** 2 * w[::2] * 3.0).sum() + 3.0), rel=1e-15)
    # entry points are named by kernel and argument types: another build's manifest can only miss
    from navpp.native import _symbol

    for key, entries in manifest["kernels"].items():
        assert all(symbol == _symbol(key, spec) for spec, symbol in entries)
    assert _symbol("nk_mod:weighted", "a<f81Cw") != _symbol("nk_mod:total", "a<f81Cw")
    # a directory it cannot write: one NativeBuildError naming it, no traceback of OSError
    from navpp.native import NativeBuildError

    monkeypatch.setenv("NAVPP_NATIVE_DIR", "/proc/navpp-cannot-write")
    with pytest.raises(NativeBuildError, match="/proc/navpp-cannot-write"):
        build(dispatchers=[nk_mod.weighted], force=True)


def test_no_module_for_other_sources(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The module's name carries the sources' hash: a manifest of another version is not read,
    and a module named right but with a manifest naming another module is not loaded."""
    monkeypatch.setenv("NAVPP_NATIVE_DIR", str(tmp_path))
    monkeypatch.setenv("NAVPP_NATIVE", "1")
    name, _ext, manifest = kernel.native_paths()
    assert name.startswith(kernel.PREFIX) and kernel.native_key() in name
    Path(manifest).write_text(json.dumps({"module": kernel.PREFIX + "0" * 24, "kernels": {}}))
    monkeypatch.setattr(kernel, "_state", {"key": kernel.native_key()})
    assert kernel.native() is None
    assert not kernel.covers("navpp.engine.fused", "ekf_epochs")


def _untimed(d: object) -> object:
    """A metrics.json tree without its timing fields (at any depth)."""
    if isinstance(d, dict):
        return {k: _untimed(v) for k, v in d.items() if k not in ("runtime_s", "compile_s", "smoothing_s")}
    return d


@pytest.mark.slow
def test_pipeline_on_the_native_module_is_numbas_byte_for_byte(tmp_path: Path) -> None:
    """The sample drive processed with the EKF and smoothed, on numba's dispatchers; a native
    module built from that run's kernels; the same run on it: identical outputs, numba not
    imported."""
    env = {**os.environ, "NAVPP_NATIVE_DIR": str(tmp_path / "native"), "PYTHONPATH": str(ROOT),
           "NAVPP_JIT": "on"}
    run = [sys.executable, "-X", "importtime", "-m", "navpp", "process", str(SAMPLES / "drive.mcap"), "--smooth",
           "-q"]
    first = subprocess.run(run + ["--out", str(tmp_path / "numba")], env={**env, "NAVPP_NATIVE": "0"},
                           capture_output=True, text=True, timeout=900)
    assert first.returncode == 0, first.stderr[-2000:]
    built = subprocess.run([sys.executable, "-m", "navpp.native"], env={**env, "NAVPP_NATIVE": "0"},
                           capture_output=True, text=True, timeout=900)
    assert built.returncode == 0, built.stderr[-2000:]
    assert built.stdout.startswith("native module: ") and int(built.stdout.split()[2]) > 10
    second = subprocess.run(run + ["--out", str(tmp_path / "native-out")], env={**env, "NAVPP_NATIVE": "1"},
                            capture_output=True, text=True, timeout=900)
    assert second.returncode == 0, second.stderr[-2000:]
    imported = [line.split("|")[-1].strip() for line in second.stderr.splitlines() if line.startswith("import time")]
    assert "numba" not in imported and "llvmlite" not in imported
    files = sorted(p.name for p in (tmp_path / "numba").iterdir())
    assert files == sorted(p.name for p in (tmp_path / "native-out").iterdir())
    for name in files:
        a, b = (tmp_path / "numba" / name).read_bytes(), (tmp_path / "native-out" / name).read_bytes()
        if name == "metrics.json":
            assert _untimed(json.loads(a)) == _untimed(json.loads(b))
        elif name == "metrics.md":
            untimed = [re.sub(r"\d+\.\d+ s\b", "<time> s", text.decode()) for text in (a, b)]
            assert untimed[0] == untimed[1]
        else:
            assert a == b, name


def test_the_builder_finds_every_module_with_kernels() -> None:
    """The kernels made by importing the modules the builder imports (navpp.native.kernel_modules)
    are all the kernels importing every module of navpp makes: none is left out of the module
    (two fresh interpreters; a kernel is named by its function's module and name)."""
    made = ("import json; from navpp import kernel; print(json.dumps(sorted({getattr(k, 'py_func', k).__module__"
            " + ':' + getattr(k, 'py_func', k).__qualname__ for k in kernel.CREATED})))")
    only = "import importlib; from navpp.native import kernel_modules\nfor m in kernel_modules(): " \
           "importlib.import_module(m)\n" + made
    every = "import importlib, pkgutil, navpp\nfor i in pkgutil.walk_packages(navpp.__path__, 'navpp.'):\n" \
            "    i.name == 'navpp.__main__' or importlib.import_module(i.name)\n" + made
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    got = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True,
                          timeout=300).stdout for code in (only, every)]
    builder, everything = (set(json.loads(g)) for g in got)
    assert len(everything) > 50 and everything <= builder


def test_a_run_on_numbas_cache_is_told_about_the_native_module(monkeypatch: pytest.MonkeyPatch) -> None:
    """The note of a compiled run that went through numba (no native module): once numba is
    imported and none is loaded; never with NAVPP_NATIVE=0, interpreted, or on a native module."""
    import numba  # noqa: F401 - a run through numba has it imported

    monkeypatch.setattr(kernel, "_state", {"native": None})
    monkeypatch.setenv("NAVPP_NATIVE", "1")
    monkeypatch.setenv("NUMBA_DISABLE_JIT", "0")
    assert "navpp compile" in kernel.native_hint()
    monkeypatch.setenv("NAVPP_NATIVE", "0")
    assert kernel.native_hint() == ""
    monkeypatch.setenv("NAVPP_NATIVE", "1")
    monkeypatch.setattr(kernel, "_state", {"native": {"navpp.x:y": {}}})
    assert kernel.native_hint() == ""


def test_a_build_is_due_once_and_not_after_a_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """After a run that compiled: a build is due when there is a C compiler; not with
    NAVPP_NATIVE=0, not without a compiler, and not after a failed build for these sources (its
    marker), which ``python -m navpp.native`` writes with a one-line reason and exit code 1 (here:
    nothing in numba's cache to build)."""
    from navpp import native

    monkeypatch.setenv("NAVPP_NATIVE_DIR", str(tmp_path / "native"))
    monkeypatch.setenv("NAVPP_NATIVE", "1")
    monkeypatch.setattr(kernel, "_state", {"native": None})
    monkeypatch.setattr(native, "c_compiler", lambda: "cc")
    assert native.build_due()
    monkeypatch.setenv("NAVPP_NATIVE", "0")
    assert not native.build_due()
    monkeypatch.setenv("NAVPP_NATIVE", "1")
    monkeypatch.setattr(native, "c_compiler", lambda: None)
    assert not native.build_due()
    monkeypatch.setattr(native, "c_compiler", lambda: "cc")
    empty = tmp_path / "empty-cache"
    env = {**os.environ, "NAVPP_NATIVE_DIR": str(tmp_path / "native"), "PYTHONPATH": str(ROOT),
           "NUMBA_CACHE_DIR": str(empty)}
    proc = subprocess.run([sys.executable, "-m", "navpp.native"], env={**env, "NAVPP_NATIVE": "0"},
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1 and proc.stdout.startswith("the native module was not built: ")
    assert not native.build_due()                   # the marker: later runs do not try again
    name, _, _ = kernel.native_paths()
    Path(tmp_path / "native" / (name + ".failed")).unlink()
    assert native.build_due()


def test_the_collector_comes_back_when_numba_compiles() -> None:
    """With the cyclic collector off (the command line, a run), numba's first compilation inside
    CollectorOnCompile turns it on (its compiler's garbage is cyclic: the peak doubled); a block
    that compiles nothing leaves it off."""
    import gc

    from numba import njit

    was = gc.isenabled()
    try:
        gc.disable()
        with kernel.CollectorOnCompile():
            pass
        assert not gc.isenabled()
        with kernel.CollectorOnCompile():
            njit(lambda x: x + 1)(1)
        assert gc.isenabled()
    finally:
        (gc.enable if was else gc.disable)()
