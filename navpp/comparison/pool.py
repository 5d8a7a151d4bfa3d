"""The local executors of a comparison: in this process, or on a pool of spawned worker processes.

The pool (:func:`run_parallel`) is a :class:`concurrent.futures.ProcessPoolExecutor` with the
``spawn`` start method (safe with numba and threads, and the same on every OS; a script that
calls :func:`navpp.comparison.compare` with ``jobs > 1`` needs the usual
``if __name__ == "__main__":`` guard): one task per run, in :func:`submission_order`, each
worker keeping the last recording it read.  Each log's figures are drawn in the pool as well,
one task per figure, as soon as that log's runs are done.  A worker that dies becomes a failed
row; an interrupt stops every worker at once.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import replace
from typing import Any

from .. import interrupts
from .figures import FIGURE_KINDS, FigurePlan, Plot, plots_by_log, render_figures
from .runs import ProgressFn, RecordingCache, RunOutcome, RunTask, failed_outcome, internal_error, run_task
from .schedule import submission_order

_WORKER_CACHE: RecordingCache | None = None
_WORKER_QUEUE: Any = None


def _init_worker(queue: Any, parent_pid: int | None = None) -> None:
    """Set up a worker process: its recording cache, its progress queue, its exit."""
    import atexit

    _die_with_parent(parent_pid)
    global _WORKER_CACHE, _WORKER_QUEUE
    _WORKER_CACHE = RecordingCache()
    _WORKER_QUEUE = queue
    if queue is not None:
        queue.cancel_join_thread()       # progress is best effort: never wait at exit to flush it
    atexit.register(_exit_at_once)


def _die_with_parent(parent_pid: int | None) -> None:
    """A worker stops with the comparison that started it: it ignores SIGINT (a Ctrl-C reaches
    the whole process group; the parent alone decides, and stops the workers), and on Linux the
    kernel sends it SIGKILL when the parent dies, however the parent dies (``PR_SET_PDEATHSIG``),
    so no worker is left waiting forever."""
    import os
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent_pid is None or not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)           # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:                          # the parent died before the prctl
        os._exit(1)


def _stop_workers(ex: Any) -> None:
    """Stop the pool's worker processes now (SIGTERM), not after their current task: the
    comparison was interrupted or failed, and nothing will read their results."""
    for proc in list((getattr(ex, "_processes", None) or {}).values()):
        with suppress(OSError, ValueError, AttributeError):
            proc.terminate()
    ex.shutdown(wait=False, cancel_futures=True)


def _exit_at_once() -> None:
    """A worker's last act: skip the interpreter's teardown (slow once numba kernels and
    matplotlib are loaded, and paid at every shutdown of the pool).  Nothing is lost: results went
    back through the executor's queue synchronously before the worker was told to stop."""
    import os
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


class _QueueProgress:
    """Progress from a worker: (stage, fraction) on the queue, at most every 2 %."""

    def __init__(self, queue: Any) -> None:
        self.queue = queue
        self.sent: dict[str, float] = {}

    def __call__(self, stage: str, fraction: float) -> None:
        last = self.sent.get(stage, -1.0)
        if fraction >= 1.0 or fraction - last >= 0.02:
            self.sent[stage] = fraction
            self.queue.put((stage, float(fraction)))


def _execute_in_worker(task: RunTask) -> RunOutcome:
    """:func:`run_task` in a worker process, with the worker's cache and progress queue."""
    if _WORKER_CACHE is None:
        raise RuntimeError("navpp.comparison: worker process used without _init_worker")
    progress = _QueueProgress(_WORKER_QUEUE) if _WORKER_QUEUE is not None else None
    return run_task(task, _WORKER_CACHE, progress)


def run_serial(tasks: Sequence[RunTask], progress: ProgressFn | None, draw: FigurePlan | None
               ) -> tuple[list[RunOutcome], dict[str, list[Plot]]]:
    """The tasks one after the other in this process (one recording cache), then each log's
    figures; returns (outcomes in task order, figures per log)."""
    cache = RecordingCache()
    out: list[RunOutcome] = []
    try:
        for k, task in enumerate(tasks):
            interrupts.check()            # an interrupt a run turned into a failed row stops here
            out.append(run_task(task, cache, progress))
            if progress:
                progress("all runs", (k + 1) / len(tasks))
    finally:
        cache.clear()
    plots: dict[str, list] = {}
    if draw is not None:
        for log in dict.fromkeys(t.log for t in tasks):
            plots[log] = render_figures(draw.job(log, [o for o in out if o.row.log == log]))
    return out, plots


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread (POSIX): a process spawned meanwhile inherits the mask, so
    a Ctrl-C during its start-up (before :func:`_die_with_parent` runs) cannot print a
    traceback from it.  A SIGINT arriving meanwhile is delivered here on leaving."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


#: The status of a run whose worker process died.
_WORKER_DIED = "a worker process died (killed, or out of memory?)"


def _drain(q: Any, progress: ProgressFn | None) -> None:
    """Pass the progress messages the workers put on ``q`` (None: none) to ``progress``."""
    import queue as queue_mod

    while q is not None and progress is not None:
        try:
            stage, fraction = q.get_nowait()
        except queue_mod.Empty:
            return
        progress(stage, fraction)


def _outcome(fut: Any, task: RunTask) -> RunOutcome:
    """The outcome a finished run's future holds; a worker that died, or a result that does not
    come back (e.g. one that does not unpickle), is a failed row, not a crash."""
    from concurrent.futures.process import BrokenProcessPool

    try:
        return fut.result()
    except BrokenProcessPool:
        return failed_outcome(task, _WORKER_DIED)
    except Exception as exc:  # noqa: BLE001
        return failed_outcome(task, internal_error(exc))


def run_parallel(tasks: Sequence[RunTask], workers: int, progress: ProgressFn | None, draw: FigurePlan | None
                 ) -> tuple[list[RunOutcome], dict[str, list[Plot]]]:
    """The tasks on ``workers`` spawned processes, in :func:`submission_order` order.  Each log's
    figures are drawn by the pool too (one task per figure), as soon as that log's runs are
    done, while the other runs go on."""
    import multiprocessing
    from collections import Counter, deque
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue() if progress else None
    results: dict[int, RunOutcome] = {}
    drawn: dict[tuple[str, str], list] = {}          # (log, figure kind) -> plots
    left = Counter(t.log for t in tasks)
    todo_runs = deque(submission_order(tasks))
    todo_figures: deque = deque()                    # FigureJobs, drawn before further runs start
    in_flight: dict[Any, Any] = {}                   # future -> RunTask or FigureJob
    ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(q, os.getpid()))

    def draw_here(job) -> None:                      # the pool broke: draw it in this process
        drawn[job.log, job.kinds[0]] = render_figures(job)

    try:
        # the executor runs what it is given in order: hand it only a little more than it can
        # run, so a log's figures overtake the runs still waiting
        while todo_runs or todo_figures or in_flight:
            while (todo_runs or todo_figures) and len(in_flight) < workers + 1:
                item = todo_figures.popleft() if todo_figures else todo_runs.popleft()
                try:
                    with _sigint_blocked():       # a worker started now is born deaf to Ctrl-C
                        fut = ex.submit(_execute_in_worker if isinstance(item, RunTask) else render_figures, item)
                except (BrokenProcessPool, RuntimeError):
                    if isinstance(item, RunTask):
                        results[item.index] = failed_outcome(item, _WORKER_DIED)
                        left[item.log] -= 1
                    else:
                        draw_here(item)
                    continue
                in_flight[fut] = item
            done, _ = wait(in_flight, timeout=0.1 if progress else None, return_when=FIRST_COMPLETED)
            _drain(q, progress)
            for fut in done:
                item = in_flight.pop(fut)
                if not isinstance(item, RunTask):
                    try:
                        drawn[item.log, item.kinds[0]] = fut.result()
                    except BrokenProcessPool:
                        draw_here(item)
                    continue
                results[item.index] = _outcome(fut, item)
                if progress:
                    progress("all runs", len(results) / len(tasks))
                left[item.log] -= 1
            for log in [log for log, n in left.items() if n == 0]:
                del left[log]
                if draw is not None:
                    whole = draw.job(log, [results[t.index] for t in tasks if t.log == log])
                    todo_figures.extend(replace(whole, kinds=(kind,)) for kind in FIGURE_KINDS)
        _drain(q, progress)
    except BaseException:
        _stop_workers(ex)
        raise
    ex.shutdown(wait=True)
    if q is not None:
        q.close()
    return [results[t.index] for t in tasks], plots_by_log(tasks, drawn) if draw is not None else {}
