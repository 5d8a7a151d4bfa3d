"""The order in which a comparison's runs are handed to the workers.

Log by log, the costliest filters of each log first (longest processing time first), so that
no worker idles long at the end and a log's figures can be drawn while the next log runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .runs import RunTask

#: Run time of each filter relative to the EKF on the same log (rounded ratios, dimensionless);
#: used only to order the parallel tasks, so only their order matters.
RELATIVE_COST = {"ekf": 1.0, "aekf": 1.0, "sage-husa": 1.2, "ckf": 4.0, "ukf": 4.0, "aukf": 4.0,
                 "vce-ckf": 6.0, "rwckf": 8.0, "sif": 8.0}


def relative_cost(name: str) -> float:
    """:data:`RELATIVE_COST`; for a filter not in it, 5 for a sigma-point filter (it pushes
    2n+1 points through the strapdown at every step) and 1 otherwise."""
    if name in RELATIVE_COST:
        return RELATIVE_COST[name]
    from ..filters import get_filter
    from ..filters.sigma import SigmaPointFilter

    return 5.0 if issubclass(get_filter(name), SigmaPointFilter) else 1.0


def submission_order(tasks: Sequence[RunTask]) -> list[RunTask]:
    """Submission order for the pool: log by log (consecutive tasks of a log tend to meet the
    worker that read it, and a log's figures can be drawn while the next log runs), the costly
    filters of each log first (longest processing time first: the last tasks to start are short
    ones, so no worker idles long at the end)."""
    cost = {name: relative_cost(name) for name in dict.fromkeys(t.filter for t in tasks)}
    log_order = {log: k for k, log in enumerate(dict.fromkeys(t.log for t in tasks))}
    return sorted(tasks, key=lambda t: (log_order[t.log], -cost[t.filter], t.index))
