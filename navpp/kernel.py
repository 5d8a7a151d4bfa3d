"""navpp's compiled kernels: numba functions, or the same functions compiled ahead of time.

Every numerical kernel of navpp is declared with :func:`njit` from this module (not numba's).
Where no native module is built, :func:`njit` *is* ``numba.njit``: the kernel is a numba
dispatcher, compiled on its first call or loaded from numba's cache (:mod:`navpp.jitcache`).

Loading a kernel from numba's cache is not free: importing numba costs about 0.25 s of CPU and
each cached kernel about 50 ms more (its machine code is linked again in every process), which
on an hour-long log was a third of ``navpp process``'s time.  So ``navpp compile`` also builds a
**native module** (:mod:`navpp.native`): numba's ahead-of-time compiler (``numba.pycc``) turns
every kernel signature in numba's cache into one Python extension module, built with the
machine's C compiler for this CPU.  When that module is present and matches the sources,
:func:`njit` returns a :class:`Kernel` instead of a dispatcher, and a call whose argument types
match a compiled signature runs the native code without numba being imported at all.

The module is looked for in :func:`native_dir` under a name carrying :func:`native_key`: a hash
of every ``navpp/*.py`` source's name, size and time stamp (what numba's own cache checks;
reading them all would cost 14 ms a run), the Python version and ABI, numpy's, numba's and
llvmlite's versions, numba's CPU settings and the CPU (model and instruction-set flags). Editing
any source, upgrading numpy or Python, or another CPU reading a shared home directory simply
finds no module: the kernels are numba's again. ``NAVPP_NATIVE=0`` turns the module off; it is
never used when the kernels run interpreted (``--jit off``, ``NUMBA_DISABLE_JIT=1``).

A native entry point does not check its arguments (it reinterprets an array of the wrong type),
so :class:`Kernel` matches them first: :func:`value_spec` describes each argument the way
numba's ``typeof`` types it (an array's dtype, dimensions, layout and writability; Python and
numpy scalars; ``None``; plain tuples of these) and only an exact match with a compiled
signature calls the native code.  Anything else (a signature the cache did not hold, keyword
arguments, a type outside that list) goes to the numba dispatcher, created on that first miss
(numba is then imported, and the kernel loaded from its cache or compiled, as without the
module).  The results are the same bits either way: the same numba compiles both, with the
same options (checked by the tests on every kernel of a run).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.machinery
import importlib.util
import json
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

#: environment variable: a directory for the native module (default: see :func:`native_dir`)
ENV_DIR = "NAVPP_NATIVE_DIR"
#: environment variable: ``0`` ignores the native module (numba's dispatchers only)
ENV_USE = "NAVPP_NATIVE"
#: file name prefix of the native module and its manifest
PREFIX = "navpp_native_"

_ROOT = os.path.dirname(os.path.abspath(__file__))
_INT64_MIN, _INT64_MAX = -(1 << 63), (1 << 63) - 1

#: Every kernel :func:`njit` made in this process, in order (numba dispatchers, :class:`Kernel`
#: objects, or plain functions when interpreted): what :mod:`navpp.native` compiles.
CREATED: list[Any] = []
#: Functions to run once numba is imported (by a dispatcher made here): see :func:`on_numba`.
_NUMBA_HOOKS: list[Callable[[], None]] = []
_state: dict[str, Any] = {}


# --------------------------------------------------------------------------- argument types


def value_spec(v: object) -> str | None:
    """The type numba's ``typeof`` gives ``v``, as text (:func:`navpp.native.type_spec` writes
    the same text from a numba type), or None for a value outside the types the native module
    takes (then the numba dispatcher runs)."""
    t = type(v)
    if t is np.ndarray or t is np.memmap:
        a: np.ndarray = v  # type: ignore[assignment]
        flags = a.flags
        if not flags.aligned or a.dtype.kind not in "biufc":
            return None
        layout = "C" if flags.c_contiguous else ("F" if flags.f_contiguous else "A")
        return f"a{a.dtype.str}{a.ndim}{layout}{'w' if flags.writeable else 'r'}"
    if t is float:
        return "float64"
    if t is int:
        return "int64" if _INT64_MIN <= v <= _INT64_MAX else None  # type: ignore[operator]
    if t is bool:
        return "bool"
    if t is tuple:
        parts = [value_spec(e) for e in v]  # type: ignore[attr-defined]
        if any(p is None for p in parts):
            return None
        return "(" + ",".join(parts) + ")"  # type: ignore[arg-type]
    if v is None:
        return "none"
    if isinstance(v, np.generic) and type(v).__module__ == "numpy" and v.dtype.kind in "biuf":
        return v.dtype.name
    return None


def call_spec(args: tuple) -> str | None:
    """The argument types of a call as one key (None: some argument is outside the native types)."""
    parts = []
    for a in args:
        s = value_spec(a)
        if s is None:
            return None
        parts.append(s)
    return ";".join(parts)


# --------------------------------------------------------------------------- the native module


def native_dir() -> str:
    """Where native modules are kept: ``$NAVPP_NATIVE_DIR``, else ``navpp-native`` in
    ``$NUMBA_CACHE_DIR`` when that is set, else ``$XDG_CACHE_HOME/navpp/native`` (default
    ``~/.cache/navpp/native``)."""
    chosen = os.environ.get(ENV_DIR, "")
    if chosen:
        return chosen
    numba_dir = os.environ.get("NUMBA_CACHE_DIR", "")
    if numba_dir:
        return os.path.join(numba_dir, "navpp-native")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "navpp", "native")


def _cpu_id() -> str:
    """The CPU's model and instruction-set flags (Linux ``/proc/cpuinfo``), else the platform's
    words: a module compiled for one CPU is never loaded on another."""
    words = [os.uname().machine if hasattr(os, "uname") else sys.platform]    # not platform.processor(): a subprocess
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if not line.strip():
                    break                               # the first processor's block is enough
                key = line.split(":", 1)[0].strip()
                if key in ("vendor_id", "model name", "flags", "Features", "CPU part", "CPU implementer"):
                    words.append(line.strip())
    except OSError:
        pass
    return "\n".join(words)


def _numba_version() -> str:
    """numba's and llvmlite's installed versions (their ``.dist-info`` names), without importing
    them: after an upgrade, runs must not mix the old numba's module with the new one's code."""
    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.origin:
        return ""
    site = os.path.dirname(os.path.dirname(spec.origin))
    try:
        return ",".join(sorted(n for n in os.listdir(site) if n.endswith(".dist-info")
                               and n.lower().startswith(("numba-", "llvmlite-"))))
    except OSError:
        return ""


def native_key() -> str:
    """The hash naming the native module that fits these sources, this Python, numpy and CPU."""
    cached = _state.get("key")
    if cached is not None:
        return cached
    h = hashlib.sha256()
    for d, subdirs, files in sorted(os.walk(_ROOT)):
        subdirs[:] = sorted(s for s in subdirs if s != "__pycache__")
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(d, name)
                st = os.stat(path)          # as numba's cache: a source's size and time stamp
                h.update(f"{os.path.relpath(path, _ROOT)}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    for word in (sys.version, importlib.machinery.EXTENSION_SUFFIXES[0], np.__version__, _cpu_id(),
                 _numba_version(), os.environ.get("NUMBA_CPU_NAME", ""), os.environ.get("NUMBA_CPU_FEATURES", "")):
        h.update(b"\0" + word.encode())
    key = h.hexdigest()[:24]
    _state["key"] = key
    return key


def native_paths(key: str | None = None) -> tuple[str, str, str]:
    """(module name, extension file, manifest file) of the native module for ``key``."""
    key = native_key() if key is None else key
    name = PREFIX + key
    where = native_dir()
    return name, os.path.join(where, name + importlib.machinery.EXTENSION_SUFFIXES[0]), \
        os.path.join(where, name + ".json")


def _jit_disabled() -> bool:
    config = sys.modules.get("numba.core.config")
    if config is not None:
        return bool(getattr(config, "DISABLE_JIT", 0))
    return os.environ.get("NUMBA_DISABLE_JIT", "0").strip() not in ("", "0")


def native() -> dict[str, dict[str, Callable[..., Any]]] | None:
    """The loaded native module's entry points, by kernel (``module:qualname``) and argument
    types (:func:`call_spec`); None when there is none for these sources, it is turned off, or
    the kernels run interpreted.  Looked for once per process."""
    if "native" in _state:
        return _state["native"]
    found = None
    if os.environ.get(ENV_USE, "1").strip() != "0" and not _jit_disabled():
        found = _load()
    _state["native"] = found
    return found


def without_native() -> bool:
    """Use numba's dispatchers only in this process (as ``NAVPP_NATIVE=0``), e.g. to build a native
    module from numba's cache; False when kernels made on the native module exist already."""
    if _state.get("native") is not None:
        return False
    _state["native"] = None
    return True


def _load() -> dict[str, dict[str, Callable[..., Any]]] | None:
    name, ext_path, manifest_path = native_paths()
    try:
        with open(manifest_path, encoding="utf-8") as f:
            manifest = json.load(f)
        if manifest.get("module") != name:
            return None
        loader = importlib.machinery.ExtensionFileLoader(name, ext_path)
        spec = importlib.util.spec_from_file_location(name, ext_path, loader=loader)
        if spec is None:
            return None
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
    except (OSError, ValueError, ImportError, AttributeError):
        return None                     # none built for these sources, or unreadable: numba's kernels
    table: dict[str, dict[str, Callable[..., Any]]] = {}
    for kernel, entries in manifest.get("kernels", {}).items():
        fns = {spec_text: getattr(module, symbol, None) for spec_text, symbol in entries}
        table[kernel] = {s: f for s, f in fns.items() if f is not None}
    _state["module"] = module
    _state["inner"] = frozenset(manifest.get("inner", ()))
    return table


def covers(module: str, qualname: str) -> bool:
    """Whether the native module in force holds kernel ``module.qualname`` (an entry point, or
    inside one: compiled only for calls from other kernels), without importing numba."""
    table = native()
    key = f"{module}:{qualname}"
    return bool(table is not None and (table.get(key) or key in _state.get("inner", ())))


def native_hint() -> str:
    """A note for a compiled run that loaded its kernels through numba (no native module for
    these sources, and none turned off): what ``navpp compile`` would save; else empty."""
    if "numba" not in sys.modules or _jit_disabled() or os.environ.get(ENV_USE, "1").strip() == "0":
        return ""
    if native() is not None:
        return ""
    return ("navpp's kernels came from numba's cache: `navpp compile` also builds a native module for these "
            "sources, with which runs start without numba (about 0.7 s of CPU and 120 MB less a run)")


# --------------------------------------------------------------------------- numba, when needed


def on_numba(hook: Callable[[], None]) -> None:
    """Run ``hook`` now if numba is imported, else right after a dispatcher of this module
    first imports it (a compile-event listener registered late, a numba-only global injected)."""
    if "numba" in sys.modules:
        hook()
    else:
        _NUMBA_HOOKS.append(hook)


def _numba_njit(fn: Callable[..., Any], options: dict[str, Any]) -> Any:
    first = "numba" not in sys.modules
    import numba
    from numba.core import types
    from numba.extending import typeof_impl

    if not _state.get("typeof"):
        @typeof_impl.register(Kernel)
        def _typeof_kernel(val: Kernel, c: Any) -> Any:    # a Kernel called inside another kernel
            return types.Dispatcher(val.dispatcher)

        _state["typeof"] = True
    if first or _NUMBA_HOOKS:
        hooks, _NUMBA_HOOKS[:] = list(_NUMBA_HOOKS), []
        for hook in hooks:
            hook()
    return numba.njit(**options)(fn)


class Kernel:
    """A navpp kernel with native entry points (module docstring): a call whose argument types
    a native entry point was compiled for runs it; any other call goes to the numba dispatcher
    (:attr:`dispatcher`, made on first need).  Inside other kernels numba sees the dispatcher.
    ``py_func`` and ``targetoptions`` are what numba reads of a dispatcher to inline it."""

    def __init__(self, fn: Callable[..., Any], options: dict[str, Any],
                 entries: dict[str, Callable[..., Any]]) -> None:
        self.py_func = fn
        self.targetoptions = dict(options)
        self._entries = entries
        self._dispatcher: Any = None
        functools.update_wrapper(self, fn)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if not kwargs:
            spec = call_spec(args)
            entry = self._entries.get(spec) if spec is not None else None
            if entry is not None:
                return entry(*args)
        return self.dispatcher(*args, **kwargs)

    @property
    def dispatcher(self) -> Any:
        """The numba dispatcher of this kernel (numba imported, if it was not, on first use)."""
        if self._dispatcher is None:
            self._dispatcher = _numba_njit(self.py_func, self.targetoptions)
        return self._dispatcher

    @property
    def native_signatures(self) -> tuple[str, ...]:
        """The argument types (:func:`call_spec`) the native module has entry points for."""
        return tuple(self._entries)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("_entries", "_dispatcher", "py_func", "targetoptions"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __reduce__(self) -> tuple[Any, tuple[str, str]]:
        return _kernel_named, (self.py_func.__module__, self.py_func.__qualname__)


    def __repr__(self) -> str:
        return f"<navpp kernel {self.py_func.__module__}.{self.py_func.__qualname__}>"


#: Kernels by ``module:qualname`` of their function, as :func:`njit` made them (for unpickling)
_BY_NAME: dict[str, Any] = {}


def _kernel_named(module: str, qualname: str) -> Any:
    importlib.import_module(module)
    if f"{module}:{qualname}" in _BY_NAME:
        return _BY_NAME[f"{module}:{qualname}"]
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def njit(*, cache: bool = True, inline: str | None = None) -> Callable[[F], F]:
    """navpp's kernel decorator, in place of ``numba.njit(cache=True[, inline=...])``: a numba
    dispatcher, a :class:`Kernel` with native entry points, or (interpreted) the function itself."""
    options: dict[str, Any] = {"cache": cache}
    if inline is not None:
        options["inline"] = inline

    def decorate(fn: F) -> F:
        kernel: Any
        if _jit_disabled():
            kernel = fn
        else:
            table = native()
            if table is None:
                kernel = _numba_njit(fn, options)
            else:
                kernel = Kernel(fn, options, table.get(f"{fn.__module__}:{fn.__qualname__}", {}))
        CREATED.append(kernel)
        if isinstance(kernel, Kernel):
            _BY_NAME.setdefault(f"{fn.__module__}:{fn.__qualname__}", kernel)
        return kernel  # type: ignore[no-any-return]

    return decorate


class CompileEvents:
    """numba's ``numba:compile`` events while the ``with`` block runs (:attr:`buffer`: the
    (time, event) pairs of a numba recorder), or ``listener`` called with each event.  The
    listener is registered when numba is imported, so a run on native kernels alone imports
    nothing; a kernel that falls back to numba mid-run is still seen (:func:`on_numba`)."""

    def __init__(self, listener: Any = None) -> None:
        self._given = listener
        self._listener: Any = None
        self._active = False

    def _attach(self) -> None:
        if not self._active:
            return
        from numba.core import event

        self._listener = self._given(event) if self._given is not None else event.RecordingListener()
        event.register("numba:compile", self._listener)

    @property
    def buffer(self) -> list:
        """The recorded (time, event) pairs (empty if nothing was compiled or numba never came)."""
        return list(getattr(self._listener, "buffer", []))

    def __enter__(self) -> CompileEvents:
        self._active = True
        on_numba(self._attach)
        return self

    def __exit__(self, *exc: object) -> None:
        self._active = False
        if self._attach in _NUMBA_HOOKS:
            _NUMBA_HOOKS.remove(self._attach)
        if self._listener is not None:
            from numba.core import event

            event.unregister("numba:compile", self._listener)


class CollectorOnCompile:
    """Python's cyclic garbage collector turned on at numba's first compilation while the
    ``with`` block runs (a command or run that keeps it off for speed): numba's compiler leaves
    much cyclic garbage, and with the collector off a compiling run's peak memory doubled
    (760 against 474 MB for the sample drive on an empty cache)."""

    def __enter__(self) -> CollectorOnCompile:
        import gc

        def listener(numba_event: Any) -> Any:
            class _Listener(numba_event.Listener):
                def on_start(self, event: Any) -> None:
                    gc.enable()

                def on_end(self, event: Any) -> None:
                    pass

            return _Listener()

        self._events = CompileEvents(listener).__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self._events.__exit__(*exc)
