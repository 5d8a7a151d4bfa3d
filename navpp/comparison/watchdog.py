"""The compare watchdog: a run that takes far longer than its log's size warrants is stopped.

A stopped run becomes a failed row naming the log; the other runs go on.  The limit scales with
the log (:func:`watchdog_limit_s`); the alarm is SIGALRM, so it works on the main thread of a
POSIX process only (the CLI and the ``--jobs`` worker processes), not in Dask's worker threads.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: The compare watchdog (:func:`watchdog_limit_s`): a run may take ``time_limit`` s for every
#: 100,000 IMU samples of its log (about 17 minutes of log at 100 Hz), and never less than
#: WATCHDOG_MIN_S (s).  The default is many times what the slowest filter takes with smoothing:
#: the watchdog is for a run that hangs, not for a slow one.
DEFAULT_TIME_LIMIT_S = 600.0
WATCHDOG_MIN_S = 120.0
#: While the log is read its sample count is not known: the files' size over this many bytes
#: (less than any reader's IMU row or message takes) stands for it.
WATCHDOG_BYTES_PER_SAMPLE = 40.0


def watchdog_limit_s(time_limit_s: float, n_imu: float) -> float:
    """The watchdog's limit (s) for a run on a log of ``n_imu`` IMU samples; 0: no watchdog."""
    if not time_limit_s > 0.0:
        return 0.0
    return max(WATCHDOG_MIN_S, time_limit_s * n_imu / 1e5)


class WatchdogExpired(BaseException):
    """Raised in a run by the watchdog's alarm (a BaseException: no ``except Exception`` of the
    run's own code swallows it)."""


class Watchdog:
    """``with Watchdog(seconds):`` raises :class:`WatchdogExpired` in the block once
    ``seconds`` have passed (SIGALRM).  Only on the main thread of a POSIX process (the CLI,
    and the worker processes of ``--jobs``); elsewhere (Dask's worker threads) it does nothing.
    The alarm is handled when the interpreter next runs Python code: a compiled kernel that never
    returns is not interrupted."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.old: Any = None

    def __enter__(self) -> Watchdog:
        import signal
        import threading

        on_main = threading.current_thread() is threading.main_thread()
        if self.seconds > 0.0 and hasattr(signal, "setitimer") and on_main:
            def expired(signum, frame):
                raise WatchdogExpired(self.seconds)

            self.old = signal.signal(signal.SIGALRM, expired)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        return self

    def __exit__(self, *exc) -> None:
        import signal

        if self.old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self.old)
            self.old = None


def log_size_bytes(path: Path) -> int:
    """Size of a log on disk (a file, or the files of a directory), bytes; 0 if unreadable."""
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def watchdog_message(log: str, time_limit_s: float, seconds: float, n_imu: int | None) -> str:
    """The status of a run the watchdog stopped after ``seconds`` (s): while reading the log
    (``n_imu`` None) or while filtering its ``n_imu`` IMU samples."""
    what = (f"the limit for {n_imu} IMU samples" if n_imu is not None else "reading the log")
    return (f"{log}: stopped by the watchdog after {seconds:.0f} s ({what}; compare --time-limit sets it, "
            f"{time_limit_s:g} s per 100,000 samples)")
