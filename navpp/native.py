"""Build navpp's native module: every kernel signature in numba's cache, compiled ahead of time.

:mod:`navpp.kernel` explains what the module is for and how runs use it.  :func:`build` (run by
``navpp compile`` after it has filled numba's cache) imports every navpp module that declares
kernels, collects each kernel's signatures (those compiled in this process and those numba's
on-disk cache holds for the current sources: every path run on this machine), and compiles
them with ``numba.pycc`` into one extension module for this CPU, beside a manifest (JSON) that
maps each kernel and argument-type key (:func:`navpp.kernel.call_spec`) to its entry point.
Both are written under temporary names and renamed into place, the manifest last, so a run
never sees half a module.  Older modules of other source versions in the same directory are
removed.

Besides ``navpp compile``, a ``navpp process`` run that had to compile kernels (a first run, a
new path) builds the module at its end (:func:`build_due`, ``python -m navpp.native`` in a child
process, announced), so the next run starts without numba; a build that fails leaves a marker
beside the module's name so that later runs do not try again for these sources.

A signature whose types the native entry points cannot check (:func:`type_spec` gives None:
records, strings, lists, functions, omitted defaults) is left to numba.  Building needs a C
compiler (numba's ``pycc`` calls it through setuptools); without one :func:`build` raises
:class:`NativeBuildError` and runs simply keep using numba's cache.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import importlib
import importlib.util
import json
import os
import pkgutil
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from . import kernel


class NativeBuildError(RuntimeError):
    """The native module could not be built (no C compiler, a kernel numba's AOT compiler refused)."""


@dataclass(frozen=True)
class BuildResult:
    """What :func:`build` made: the extension's path, kernels and entry points, CPU seconds,
    the signatures left to numba (kernel, types, why)."""

    path: str
    kernels: int
    entries: int
    cpu_s: float
    skipped: tuple[tuple[str, str, str], ...]
    #: False when an up-to-date module with the same entry points was kept
    built: bool = True


def type_spec(ty: Any) -> str | None:
    """A numba type as :func:`navpp.kernel.value_spec` writes the type of a value; None for a
    type the native entry points do not take."""
    from numba.core import types
    from numba.np import numpy_support

    if type(ty) is types.Array:
        if not ty.aligned or not isinstance(ty.dtype, (types.Integer, types.Float, types.Boolean, types.Complex)):
            return None
        dt = numpy_support.as_dtype(ty.dtype)
        return f"a{dt.str}{ty.ndim}{ty.layout}{'w' if ty.mutable else 'r'}"
    if type(ty) in (types.Integer, types.Float, types.Boolean):
        return str(ty)
    if isinstance(ty, types.NoneType):
        return "none"
    if type(ty) in (types.UniTuple, types.Tuple):
        parts = [type_spec(t) for t in ty.types]
        if any(p is None for p in parts):
            return None
        return "(" + ",".join(parts) + ")"  # type: ignore[arg-type]
    return None


def kernel_modules() -> list[str]:
    """navpp's modules that declare kernels (their source uses :func:`navpp.kernel.njit`, or
    :func:`navpp.filters.linalg.compiled`, which calls it)."""
    names = []
    for info in pkgutil.walk_packages([os.path.dirname(os.path.abspath(kernel.__file__))], "navpp."):
        spec = importlib.util.find_spec(info.name)
        origin = getattr(spec, "origin", None)
        if not origin or not origin.endswith(".py"):
            continue
        with open(origin, encoding="utf-8") as f:
            text = f.read()
        if ("import njit" in text or "@compiled" in text) and info.name not in ("navpp.kernel", "navpp.native"):
            names.append(info.name)
    return names


def _cached_signatures(disp: Any) -> list[tuple]:
    """The argument types numba's on-disk cache holds for dispatcher ``disp``, for its current
    source and this machine (stale entries are not returned)."""
    cache = getattr(disp, "_cache", None)
    if cache is None or not hasattr(cache, "_cache_file"):
        return []
    try:
        index = cache._cache_file._load_index()
        codegen = disp.targetctx.codegen()
        return [key[0] for key in index if key == cache._index_key(key[0], codegen)]
    except Exception:  # noqa: BLE001 - numba's internals changed: only this process's signatures
        return []


def _symbol(key: str, spec: str) -> str:
    """An entry point's name from its kernel and argument types: a manifest paired with a module
    of another build (a run reading one just as the other is replaced) can only miss names,
    never call one kernel's code for another's."""
    return "k_" + hashlib.sha256(f"{key}\0{spec}".encode()).hexdigest()[:24]


def _entries(dispatchers: list[Any], progress: Any
             ) -> tuple[list[tuple[str, str, str, Any, Any]], list[tuple[str, str, str]], list[str]]:
    """(kernel key, argument-type key, symbol, signature, function) of every signature to build;
    those left to numba; the kernels numba compiled only as parts of other kernels (a literal
    argument), which the module holds inside its entry points."""
    from numba.core import types
    from numba.core.registry import CPUDispatcher

    todo: list[tuple[str, str, str, Any, Any]] = []
    skipped: list[tuple[str, str, str]] = []
    seen: set[tuple[str, str]] = set()
    inner: set[str] = set()
    for disp in dispatchers:
        if not isinstance(disp, CPUDispatcher):
            continue
        fn = disp.py_func
        key = f"{fn.__module__}:{fn.__qualname__}"
        sigs = list(disp.signatures)
        sigs += [s for s in _cached_signatures(disp) if s not in sigs]
        for sig in sigs:
            if any(isinstance(t, types.Literal) for t in sig):
                inner.add(key)              # compiled for a call from another kernel: inside that one
                continue
            specs = [type_spec(t) for t in sig]
            if any(s is None for s in specs):
                skipped.append((key, str(sig), "argument types the native module cannot check"))
                continue
            spec = ";".join(specs)  # type: ignore[arg-type]
            if (key, spec) in seen:
                continue
            seen.add((key, spec))
            try:
                disp.compile(tuple(sig))           # loaded from the cache (or compiled)
                cres = disp.overloads[tuple(sig)]
            except Exception as exc:  # noqa: BLE001 - numba refused a cached signature: leave it to numba
                skipped.append((key, str(sig), f"numba: {exc}".splitlines()[0]))
                continue
            todo.append((key, spec, _symbol(key, spec), cres.signature, fn))
    return todo, skipped, sorted(inner - {t[0] for t in todo})


def build(progress: Any = None, dispatchers: list[Any] | None = None, force: bool = False) -> BuildResult:
    """Compile the native module for the current sources (module docstring) into
    :func:`navpp.kernel.native_dir`; returns what was built.  ``dispatchers``: the kernels to
    compile (default: every kernel of navpp's kernel modules, imported here).  A module already
    there with the same entry points is kept (``entries`` then counts them, ``cpu_s`` is the
    check's), unless ``force``.  Builds are serialised by a lock file beside the module.  Raises
    :class:`NativeBuildError` when it cannot be built (a file system error included)."""
    from . import jitmode

    if jitmode.interpreted():
        raise NativeBuildError("the kernels run interpreted in this process (--jit off / NUMBA_DISABLE_JIT)")
    if kernel.native() is not None:
        raise NativeBuildError("this process runs on a native module already; build with NAVPP_NATIVE=0")
    name, ext_path, manifest_path = kernel.native_paths()      # the sources as the build starts
    where = os.path.dirname(ext_path)
    try:
        os.makedirs(where, mode=0o700, exist_ok=True)
        with _locked(os.path.join(where, name + ".lock")):
            return _build_locked(progress, dispatchers, force, name, ext_path, manifest_path)
    except OSError as exc:
        raise NativeBuildError(f"{where}: {exc.strerror or exc}") from exc


@contextlib.contextmanager
def _locked(path: str) -> Iterator[None]:
    """An exclusive lock on ``path`` (``flock``; none where there is no ``fcntl``) while the block runs."""
    try:
        import fcntl
    except ImportError:             # pragma: no cover - Windows: builds are not serialised
        yield
        return
    with open(path, "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


@contextlib.contextmanager
def _host_features() -> Iterator[None]:
    """numba's AOT code generator for this CPU's actual features, as its JIT uses them (and
    ``NUMBA_CPU_FEATURES`` when set), not every feature the CPU model's name implies: a virtual
    machine that hides some (AVX-512, say) would otherwise get instructions it cannot run."""
    from numba.core.codegen import AOTCPUCodegen

    original = AOTCPUCodegen._customize_tm_features
    AOTCPUCodegen._customize_tm_features = lambda self: self._get_host_cpu_features()  # type: ignore[method-assign]
    try:
        yield
    finally:
        AOTCPUCodegen._customize_tm_features = original  # type: ignore[method-assign]


def _build_locked(progress: Any, dispatchers: list[Any] | None, force: bool, name: str, ext_path: str,
                  manifest_path: str) -> BuildResult:
    t0 = time.process_time()
    if dispatchers is None:
        for module in kernel_modules():
            importlib.import_module(module)
        dispatchers = kernel.CREATED
    todo, skipped, inner = _entries(dispatchers, progress)
    if not todo:
        raise NativeBuildError("numba's cache holds no navpp kernel to compile (run navpp compile first)")
    kernels: dict[str, list[list[str]]] = {}
    for key, spec, symbol, _, _ in todo:
        kernels.setdefault(key, []).append([spec, symbol])
    manifest = {"module": name, "kernels": kernels, "inner": inner, "skipped": [list(s) for s in skipped]}
    if not force and os.path.isfile(ext_path) and _same_entries(manifest_path, manifest):
        return BuildResult(ext_path, len(kernels), len(todo), time.process_time() - t0, tuple(skipped), False)
    where = os.path.dirname(ext_path)
    with tempfile.TemporaryDirectory(prefix="build-", dir=where) as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")             # pycc's pending-deprecation warning
            try:
                from numba.pycc import CC
            except ImportError as exc:
                raise NativeBuildError(f"numba's ahead-of-time compiler is unavailable: {exc}") from exc
            cc = CC(name)
            cc.output_dir = tmp
            cc.target_cpu = "host"
            cc.verbose = False
            for _, _, symbol, sig, fn in todo:
                cc.export(symbol, sig)(fn)
            if progress:
                progress(f"native module {name}: {len(todo)} signatures of {len(kernels)} kernels, through "
                         "numba's AOT compiler and the C compiler")
            try:
                with _host_features():
                    cc.compile()
            except Exception as exc:  # compiler missing or a kernel refused
                why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise NativeBuildError(f"building the native module failed: {why}") from exc
        suffix = os.path.basename(ext_path)[len(name):]
        built = [b for b in glob.glob(os.path.join(tmp, name + "*")) if os.path.isfile(b) and b.endswith(suffix)]
        if not built:
            raise NativeBuildError(f"the AOT compiler wrote no {os.path.basename(ext_path)}")
        staged = os.path.join(tmp, "manifest.json")
        with open(staged, "w", encoding="utf-8") as f:
            json.dump(manifest, f, indent=1, sort_keys=True)
        kernel._state.pop("key", None)
        if kernel.native_paths()[0] != name:
            raise NativeBuildError("navpp's sources changed during the build; build again")
        os.replace(built[0], ext_path)
        os.replace(staged, manifest_path)
    _remove_stale(where, name)
    with contextlib.suppress(OSError):
        os.remove(_failed_marker())
    return BuildResult(ext_path, len(kernels), len(todo), time.process_time() - t0, tuple(skipped), True)


def _same_entries(manifest_path: str, manifest: dict) -> bool:
    try:
        with open(manifest_path, encoding="utf-8") as f:
            old = json.load(f)
    except (OSError, ValueError):
        return False
    return bool(old.get("module") == manifest["module"] and old.get("kernels") == manifest["kernels"])


#: a module of other sources is removed when it has not been written for this long (s): another
#: checkout or environment sharing the directory would otherwise rebuild its own again and again
STALE_AFTER_S = 14 * 24 * 3600.0


def _remove_stale(where: str, keep: str) -> None:
    """Native modules of other source versions in ``where`` not written for :data:`STALE_AFTER_S`."""
    now = time.time()
    for path in glob.glob(os.path.join(where, kernel.PREFIX + "*")):
        if not os.path.basename(path).startswith(keep):
            with contextlib.suppress(OSError):
                if now - os.path.getmtime(path) > STALE_AFTER_S:
                    os.remove(path)


def _failed_marker() -> str:
    name, _, _ = kernel.native_paths()
    return os.path.join(kernel.native_dir(), name + ".failed")


def c_compiler() -> str | None:
    """The C compiler numba's AOT build would call (``$CC``, else ``cc`` or ``gcc`` on the PATH)."""
    for cand in (os.environ.get("CC", "").split(" ")[0], "cc", "gcc"):
        if cand and shutil.which(cand):
            return cand
    return None


def build_due() -> bool:
    """Whether a run that just compiled kernels should build the native module (anew, with what
    it compiled): compiled mode, not turned off (``NAVPP_NATIVE=0``), a C compiler there, and no
    earlier failed build for these sources.  A build that finds the module up to date (another
    run's, say) keeps it."""
    from . import jitmode

    if jitmode.interpreted() or os.environ.get(kernel.ENV_USE, "1").strip() == "0" or sys.platform == "win32":
        return False
    if c_compiler() is None:
        return False
    return not os.path.exists(_failed_marker())


def build_in_child() -> str:
    """Build the native module in a child process (``python -m navpp.native``: this process's
    memory stays as it is); returns the child's one-line report."""
    env = {**os.environ, kernel.ENV_USE: "0"}
    proc = subprocess.run([sys.executable, "-m", "navpp.native"], env=env, capture_output=True, text=True)
    lines = (proc.stdout.strip() or proc.stderr.strip() or f"exit code {proc.returncode}").splitlines()
    return lines[-1]


def main() -> int:
    """``python -m navpp.native``: build the module for the current sources; one line on stdout;
    exit 1 (and a marker that stops later runs from retrying) when it cannot be built."""
    from . import jitmode

    jitmode.apply(True)
    try:
        r = build()
    except NativeBuildError as exc:
        with contextlib.suppress(OSError):
            os.makedirs(kernel.native_dir(), mode=0o700, exist_ok=True)
            with open(_failed_marker(), "w", encoding="utf-8") as f:
                f.write(f"{exc}\n")
        print(f"the native module was not built: {exc} (navpp compile tries again)")
        return 1
    with contextlib.suppress(OSError):
        os.remove(_failed_marker())
    print(f"native module: {r.entries} entry points of {r.kernels} kernels in {r.path} ({r.cpu_s:.0f} s of CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
