"""Interrupts (SIGINT, SIGTERM) of a command-line run: stop cleanly, write nothing, exit 130.

The command line installs :func:`install`: both signals raise :class:`Interrupted` (a
``BaseException``, so no ``except Exception`` swallows it) in the main thread.  The exception
unwinds the run, whose ``finally`` blocks remove the staging directory, drop the ``--out``
lock and stop the worker processes; the CLI then prints one line and exits with 130.

Two subtleties:

- A signal that arrives inside compiled code (numba) can surface as another exception (e.g.
  ``SystemError: CPUDispatcher(...) returned a result with an exception set``), which a reader
  or a comparison may turn into an error message or a failed row.  So the signal is also
  *recorded* (:func:`received`): the CLI treats any failure after a signal as the interrupt,
  and :func:`commit` refuses to start writing results after one.
- Once a run has begun to move its finished files into ``--out`` (:func:`commit`), stopping
  half-way would mix two runs' results; a signal then is recorded but not raised, and the run
  finishes (a fraction of a second) and exits normally with its results complete.

Library use (``navpp.process`` from Python) installs nothing: Ctrl-C there is Python's own
``KeyboardInterrupt``, and the same ``finally`` blocks clean up.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from types import FrameType

_received: int | None = None
_installed = False
_committing = False
_guarded: list[str] = []          # output directories whose earlier results a stop leaves as they were


class Interrupted(BaseException):
    """The run was stopped by a signal (``signum``)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def name(self) -> str:
        try:
            return signal.Signals(self.signum).name
        except ValueError:
            return f"signal {self.signum}"


#: Code where an exception raised by the handler would not unwind the run but be printed as
#: "Exception ignored ..." with a traceback, or turned into a SystemError: numba's and
#: llvmlite's compiler (ctypes callbacks, the dispatcher) and finalizers (``__del__``).
_FRAGILE_PATHS = (f"{os.sep}llvmlite{os.sep}", f"{os.sep}numba{os.sep}")
_FRAGILE_NAMES = ("__del__", "_raw_object_cache_notify", "_raw_object_cache_getbuffer")
_RETRY_S = 0.05
_retrying = False


def _fragile(frame: FrameType | None) -> bool:
    """Whether the signal came while Python runs code that must not raise (see above): the
    current frame and up to 60 callers."""
    for _ in range(60):
        if frame is None:
            return False
        code = frame.f_code
        if code.co_name in _FRAGILE_NAMES or any(p in code.co_filename for p in _FRAGILE_PATHS):
            return True
        frame = frame.f_back
    return False


def _redeliver(signum: int) -> None:
    """Send ``signum`` to this process again in a moment (from a daemon thread)."""
    import threading

    timer = threading.Timer(_RETRY_S, os.kill, (os.getpid(), signum))
    timer.daemon = True
    timer.start()


def _handler(signum: int, frame: FrameType | None) -> None:
    global _received, _retrying
    if _received is None:
        _received = signum
    elif not _retrying:              # already stopping: let the clean-up run undisturbed
        return
    if _committing:                  # the results are being moved into place: finish that
        return
    if _fragile(frame):              # raise it once Python is back in navpp's own code
        _retrying = True
        _redeliver(_received)
        return
    _retrying = False
    raise Interrupted(_received)


def install() -> None:
    """SIGINT and SIGTERM raise :class:`Interrupted` in the main thread (CLI only).  A signal
    the process was started with ignored (``nohup``, a background job of a script) stays
    ignored, as Python itself does for SIGINT."""
    global _installed
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _handler)
    _installed = True


def ignore_from_now() -> None:
    """Ignore SIGINT and SIGTERM for the rest of the process (its exit).  Python resets its own
    handlers to the default at finalisation, so a signal in the last milliseconds of a finished
    run would kill it with no message and a signal's exit status; ignored ones stay ignored."""
    if _installed:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


def received() -> int | None:
    """The signal number received (only when :func:`install` was called), else None."""
    return _received


def guard(out: object) -> None:
    """Note that this run holds ``out`` (its lock, :class:`navpp.outdir.OutDirLock`) and writes
    there only by a final :func:`commit`: an interrupt message can then say it is untouched."""
    if str(out) not in _guarded:
        _guarded.append(str(out))


def committed() -> bool:
    """Whether this run has begun moving its results into place (:func:`commit`)."""
    return _committing


def check() -> None:
    """Raise :class:`Interrupted` if a signal was received (and swallowed on the way).  The run
    stops from here: a redelivery still pending (:func:`_redeliver`, for a signal that came in
    fragile code) is then ignored, so that it cannot break off the clean-up (a staging
    directory half removed) with a second :class:`Interrupted`."""
    global _retrying
    if _received is not None and not _committing:
        _retrying = False
        raise Interrupted(_received)


@contextmanager
def commit() -> Iterator[None]:
    """Around moving a finished run's files into place: refused (:class:`Interrupted`) after a
    signal; a signal during it is recorded and the run finishes normally."""
    global _committing
    check()
    if not _installed:
        yield
        return
    _committing = True               # stays set: after the commit the run is done
    yield


#: Seconds the interpreter's teardown may take after an interrupt before :func:`exit_now` cuts it short.
TEARDOWN_S = 5.0


def exit_now(code: int) -> None:
    """End the process at once with ``code`` (``os._exit``), after releasing what multiprocessing's
    resource tracker holds for this process (the worker pool's and queues' semaphores, with
    multiprocessing's own finalizers for them): without that, the tracker prints "leaked semaphore objects"
    on stderr after the one line an interrupted run owes the user."""
    import sys

    util, sync = sys.modules.get("multiprocessing.util"), sys.modules.get("multiprocessing.synchronize")
    if util is not None and sync is not None:
        with suppress(Exception):   # only the semaphores' unlinks: nothing that could wait on a lock
            cleanup = sync.SemLock._cleanup
            for fin in list(util._finalizer_registry.values()):
                if getattr(fin, "_callback", None) is cleanup:
                    fin()           # once: the registry drops a finalizer before calling it
    with suppress(Exception):
        sys.stderr.flush()
    os._exit(code)


def exit_interrupted(signum: int) -> None:
    """One line for a run stopped by ``signum`` (``navpp: interrupted by SIGINT``, and when the
    run held an output directory ``; nothing was written to DIR (earlier results there are
    unchanged)``), then exit 130.  The interpreter's teardown still runs (it releases the worker pool's semaphores,
    else multiprocessing's resource tracker complains on stderr), under a watchdog: if it
    takes longer than :data:`TEARDOWN_S` (a loaded machine), :func:`exit_now` ends the process."""
    import sys
    import threading

    try:
        name = signal.Signals(signum).name
    except ValueError:
        name = f"signal {signum}"
    with suppress(Exception):  # a closed pipe: nothing more to say there
        sys.stdout.flush()
    where = (f"; nothing was written to {_guarded[0]} (earlier results there are unchanged)"
             if len(_guarded) == 1 and not _committing else "")
    sys.stderr.write(f"navpp: interrupted by {name}{where}\n")
    sys.stderr.flush()
    ignore_from_now()
    watchdog = threading.Timer(TEARDOWN_S, exit_now, (130,))
    watchdog.daemon = True
    watchdog.start()
    raise SystemExit(130)
