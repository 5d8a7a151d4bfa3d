"""Where numba caches navpp's compiled kernels, so a read-only install still runs.

navpp's kernels are compiled with ``cache=True``.  numba stores the machine code beside the
sources (``__pycache__``) or in the user's cache directory (``$XDG_CACHE_HOME/numba`` or
``~/.cache/numba``), or in ``$NUMBA_CACHE_DIR`` when set; if none of these can be written
(a read-only install, a service account without a writable home) it raises ``RuntimeError:
cannot cache function ...: no locator available`` at import, which would stop even ``navpp filters``.

:func:`configure` (called when :mod:`navpp` is imported, before numba is) checks those places
the way numba does (creating the directory and a temporary file in it) and, when none is
writable, points ``NUMBA_CACHE_DIR`` at ``<temp dir>/navpp-numba-cache-<uid>`` (created with
mode 0700; one that another user owns or others may write is not used, since numba loads
pickled code from it), else at a fresh private temporary directory (no cache kept between
runs).  The reason is kept in :data:`NOTE`; the command line prints it as a ``note:`` line.
Spawned worker processes inherit the variable.
"""

from __future__ import annotations

import os
import sys
from typing import Any

#: One line saying where the cache went and why, when :func:`configure` moved it; else empty.
NOTE: list[str] = []


def _writable(path: str) -> bool:
    """What numba's locators check: the directory can be created and a file made in it."""
    import tempfile

    try:
        os.makedirs(path, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
        return True
    except OSError:
        return False


def _looks_writable(path: str) -> bool:
    """A cheap first look (``os.access``, which also sees a read-only file system)."""
    target = path if os.path.isdir(path) else os.path.dirname(path)
    return os.access(target, os.W_OK | os.X_OK)


def _package_dirs() -> list[str]:
    root = os.path.dirname(os.path.abspath(__file__))
    return [d for d, subdirs, _ in os.walk(root) if os.path.basename(d) != "__pycache__"]


def _user_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "numba")


def _private_dir(path: str) -> bool:
    """``path`` is (now) a directory of this user that no one else may write."""
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return False
    try:
        st = os.lstat(path)
    except OSError:
        return False
    import stat

    return (stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid() and not st.st_mode & 0o022
            and _writable(path))


def configure() -> None:
    """Set ``NUMBA_CACHE_DIR`` to a writable temporary place if numba could not cache otherwise."""
    if NOTE or sys.platform == "win32":
        return
    chosen = os.environ.get("NUMBA_CACHE_DIR", "")
    if chosen:
        if _writable(chosen):
            return
        why = f"NUMBA_CACHE_DIR {chosen} is not writable"
    else:
        caches = [os.path.join(d, "__pycache__") for d in _package_dirs()]
        if all(_looks_writable(c) for c in caches) or all(_writable(c) for c in caches):
            return
        user = _user_cache_dir()
        if _writable(user):
            return
        why = f"neither navpp's install directory nor {user} is writable"
    import tempfile

    shared = os.path.join(tempfile.gettempdir(), f"navpp-numba-cache-{os.getuid()}")
    if _private_dir(shared):
        where, kept = shared, "kept between runs"
    else:
        try:
            where, kept = tempfile.mkdtemp(prefix="navpp-numba-"), "for this run only"
        except OSError:
            NOTE.append(f"numba cannot cache navpp's compiled kernels: {why}, nor is a temporary directory; "
                        "set NUMBA_CACHE_DIR to a writable directory")
            return
    os.environ["NUMBA_CACHE_DIR"] = where
    numba_config: Any = sys.modules.get("numba.core.config")
    if numba_config is not None:          # numba already imported: its config read the variable already
        numba_config.CACHE_DIR = where
    NOTE.append(f"{why}: compiled kernels are cached in {where} ({kept}); set NUMBA_CACHE_DIR to choose")


def cache_place() -> str:
    """Where numba keeps navpp's compiled kernels, in words."""
    chosen = os.environ.get("NUMBA_CACHE_DIR", "")
    if chosen:
        return chosen
    root = os.path.dirname(os.path.abspath(__file__))
    return f"the __pycache__ directories under {root} (else {_user_cache_dir()})"


class CompileAnnouncer:
    """Says when navpp's kernels are about to compile, and how long compiling took.

    numba compiles a kernel when it is first called with argument types that neither this
    process nor the on-disk cache (``NUMBA_CACHE_DIR``, see :func:`configure`) holds; it
    emits a ``numba:compile`` START event just before, which is the one sure sign of a cold
    cache (no guess from cache files, whose names and keys are numba's own).  Used as a context
    manager around a command: at the first START of a navpp kernel called from Python (not one
    compiled as part of another), ``write`` gets :attr:`LINE`, once.  ``seconds`` is the wall
    time spent in those outermost compilations of navpp's kernels (s); ``kernels`` counts them.
    Compilations in other processes (``navpp compare --jobs N`` workers) are not seen.
    """

    LINE = ("compiling navpp's numba kernels for this path (first run only; later runs load them from the "
            "cache) ...")

    def __init__(self, write: Any) -> None:
        self.write = write
        self.announced = False
        self.seconds = 0.0
        self.kernels = 0
        self._depth = 0
        self._started = 0.0
        self._ours = False
        self._listener: Any = None

    def _start(self, event: Any) -> None:
        import time

        self._depth += 1
        if self._depth > 1:
            return
        dispatcher = (event.data or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
        self._ours = module.split(".")[0] == "navpp"
        if self._ours and not self.announced:
            self.announced = True
            self.write(self.LINE)
        self._started = time.perf_counter()

    def _end(self, event: Any) -> None:
        import time

        self._depth -= 1
        if self._depth == 0 and self._ours:
            self.seconds += time.perf_counter() - self._started
            self.kernels += 1

    def __enter__(self) -> CompileAnnouncer:
        from .kernel import CompileEvents

        outer = self

        def listener(numba_event: Any) -> Any:
            class _Listener(numba_event.Listener):
                def on_start(self, event: Any) -> None:
                    outer._start(event)

                def on_end(self, event: Any) -> None:
                    outer._end(event)

            return _Listener()

        self._listener = CompileEvents(listener).__enter__()    # registered when numba is imported
        return self

    def __exit__(self, *exc: object) -> None:
        self._listener.__exit__(*exc)
