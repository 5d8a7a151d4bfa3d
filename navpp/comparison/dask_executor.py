"""``navpp compare --executor dask``: the comparison's runs on a Dask cluster.

Each (log, filter) run is one task.  The task carries only names (the log's path, the filter,
the config file, topics); the worker reads the log itself, runs the filter and returns what
the local executor returns: the summary row (metrics, counts, run time) and the decimated plot
series (at most a few thousand numbers).  The trajectories never leave the worker, so the
scheduler only ever sees small messages.  A worker keeps the last recording it read (one per
worker thread), so the filters of a log that land on the same worker read it once.

A run that fails is a row with the reason, as with the local executor; so is a task whose worker
died (``KilledWorker``) or whose result could not come back.  Each log's figures are drawn by
the cluster as soon as that log's runs are in, while the other runs go on.

Paths are made absolute before they are sent: the workers must see the same file system (a
shared or network file system for a remote cluster).
"""

from __future__ import annotations

import os
import threading
from collections import Counter
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InputError
from .figures import FIGURE_KINDS, FigurePlan, Plot, plots_by_log, render_figures
from .runs import ProgressFn, RecordingCache, RunOutcome, RunTask, failed_outcome, internal_error, run_task
from .schedule import submission_order

_local = threading.local()


def _cache() -> RecordingCache:
    """This worker thread's recording cache."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = RecordingCache()
    return cache


def execute_task(task: RunTask) -> RunOutcome:
    """Run one comparison task on a worker (its thread's recording cache, no progress)."""
    return run_task(task, _cache(), None)


def render_log_figures(plan: FigurePlan, log: str, kind: str, *outcomes: RunOutcome) -> list[Plot]:
    """Draw one kind of figure of ``log`` from its runs' outcomes.  Runs on a worker, with the
    outcomes passed as the run tasks' futures: dask hands them over worker to worker, so the
    plot series never travel through the scheduler (nor back to the client first)."""
    return render_figures(replace(plan.job(log, list(outcomes)), kinds=(kind,)))


def _absolute(task: RunTask) -> RunTask:
    """The task with its paths absolute (the workers may run in another directory)."""
    def ab(p: str | None) -> str | None:
        return None if p is None else str(Path(p).expanduser().resolve())

    return replace(task, path=ab(task.path or task.log), config=ab(task.config), reference=ab(task.reference))


def _connect(scheduler: str | None, workers: int):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("--executor dask needs dask.distributed: pip install 'navpp[dask]'") from None
    # results come straight from the workers, never through the scheduler
    if scheduler is None:
        import dask

        # the workers' statistical profiler samples every thread's stack every 10 ms: a cost to
        # every run, for a profile nobody looks at
        with dask.config.set({"distributed.worker.profile.enabled": False}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
        return Client(cluster, direct_to_workers=True), cluster
    try:
        return Client(scheduler, timeout="20s", direct_to_workers=True), None
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there "
                         f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None


def run_dask(tasks: Sequence[RunTask], workers: int | None, scheduler: str | None, progress: ProgressFn | None,
             draw: FigurePlan | None) -> tuple[list[RunOutcome], dict[str, list[Plot]], int]:
    """Run ``tasks`` on Dask; returns (outcomes in task order, plots per log, number of
    workers).  ``workers``: LocalCluster size when ``scheduler`` is None (None: one per CPU)."""
    from distributed import as_completed

    def draw_here(log: str, kinds) -> None:          # from the outcomes that came back, in this process
        whole = draw.job(log, [results[t.index] for t in tasks if t.log == log])
        for kind in kinds:
            drawn[log, kind] = render_figures(replace(whole, kinds=(kind,)))

    results: dict[int, Any] = {}
    drawn: dict[tuple[str, str], list] = {}
    client, cluster = _connect(scheduler, workers or os.cpu_count() or 2)
    try:
        n_workers = len(client.scheduler_info().get("workers", {})) or (workers or 1)
        order = submission_order(tasks)
        futures: dict[Any, Any] = {}
        for rank, task in enumerate(order):       # costly filters of each log first, logs in order
            fut = client.submit(execute_task, _absolute(task), key=f"navpp-run-{task.index}-{os.getpid()}",
                                pure=False, priority=len(order) - rank)
            futures[fut] = task
        run_futures: dict[int, Any] = {t.index: f for f, t in futures.items()}
        left = Counter(t.log for t in tasks)
        pending = as_completed(list(futures))
        for fut in pending:
            item = futures.pop(fut)
            if isinstance(item, tuple):               # (log, kind) of a figure task
                try:
                    drawn[item] = fut.result()
                except Exception:  # noqa: BLE001  (draw it here instead)
                    draw_here(item[0], (item[1],))
                fut.release()
                continue
            try:
                results[item.index] = fut.result()
            except Exception as exc:  # noqa: BLE001  (KilledWorker, a result that does not travel: a row)
                results[item.index] = failed_outcome(item, f"the Dask worker failed: {internal_error(exc)}")
            if progress:
                progress("all runs", len(results) / len(tasks))
            left[item.log] -= 1
            if left[item.log] == 0:
                mine = [t for t in tasks if t.log == item.log]
                ok = all(run_futures[t.index].status == "finished" for t in mine)
                if draw is not None and ok:
                    deps = [run_futures[t.index] for t in mine]
                    for kind in FIGURE_KINDS:
                        f = client.submit(render_log_figures, draw, item.log, kind, *deps, pure=False,
                                          priority=len(order) + 1)
                        futures[f] = (item.log, kind)
                        pending.add(f)
                elif draw is not None:                # a run's worker died: draw from what came back, here
                    draw_here(item.log, FIGURE_KINDS)
                for t in mine:
                    run_futures.pop(t.index).release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [results[t.index] for t in tasks], plots_by_log(tasks, drawn) if draw is not None else {}, n_workers


__all__ = ["execute_task", "run_dask"]
