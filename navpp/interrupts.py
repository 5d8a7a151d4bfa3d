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

import signal
from collections.abc import Iterator
from contextlib import contextmanager

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


def _handler(signum: int, frame) -> None:
    global _received
    if _received is not None:        # already stopping: let the clean-up run undisturbed
        return
    _received = signum
    if _committing:                  # the results are being moved into place: finish that
        return
    raise Interrupted(signum)


def install() -> None:
    """SIGINT and SIGTERM raise :class:`Interrupted` in the main thread (CLI only).  A signal
    the process was started with ignored (``nohup``, a background job of a script) stays
    ignored, as Python itself does for SIGINT."""
    global _installed
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _handler)
    _installed = True


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
    """Raise :class:`Interrupted` if a signal was received (and swallowed on the way)."""
    if _received is not None and not _committing:
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


def exit_interrupted(signum: int) -> None:
    """One line for a run stopped by ``signum`` (``navpp: interrupted by SIGINT``, and when the
    run held an output directory ``; nothing was written to DIR (earlier results there are
    unchanged)``), then exit 130.  The interpreter's teardown still runs (it releases the worker pool's semaphores,
    else multiprocessing's resource tracker complains on stderr), under a watchdog: if it
    hangs for 5 s, the process exits at once."""
    import os
    import sys
    import threading

    try:
        name = signal.Signals(signum).name
    except ValueError:
        name = f"signal {signum}"
    try:
        sys.stdout.flush()
    except Exception:  # noqa: BLE001  (a closed pipe: nothing more to say there)
        pass
    where = (f"; nothing was written to {_guarded[0]} (earlier results there are unchanged)"
             if len(_guarded) == 1 and not _committing else "")
    sys.stderr.write(f"navpp: interrupted by {name}{where}\n")
    sys.stderr.flush()
    watchdog = threading.Timer(5.0, os._exit, (130,))
    watchdog.daemon = True
    watchdog.start()
    raise SystemExit(130)
