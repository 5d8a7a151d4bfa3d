"""Rows and series of the noise factors a VCE filter reports (``q_factor``, ``r_factor`` of
:meth:`~navpp.filters.base.Filter.noise_report`), for paper 003's benchmarks: the last-epoch
factor, mean over runs, against the true factor the benchmark's setup implies."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .montecarlo import Stats
from .registry import Row

#: noise_report() names of noise factors relative to the configured noise (the VCE-CKF's)
FACTOR_REPORTS = {"q_factor": "q", "r_factor": "r"}


def factor_rows(name: str, s: Stats, truth: dict[str, float], labels: dict[str, Sequence[str]]
                ) -> tuple[list[Row], dict[str, np.ndarray], list[str]]:
    """Rows and series for the noise factors a filter reports (VCE's ``q_factor``, ``r_factor``):
    the last-epoch value, mean over runs, against ``truth["q"]`` / ``truth["r"]``; factor(k)
    means over runs as series ``"<filter>/<report>/<label>"``.  ``labels`` names the elements.
    The note gives the adapter's pooled redundancy over its last window, when it reports one."""
    rows, series, parts = [], {}, []
    for key, kind in FACTOR_REPORTS.items():
        arr = s.reports.get(key)
        if arr is None or arr.size == 0:
            continue
        names = list(labels.get(key, ()))
        names += [str(i) for i in range(len(names), arr.shape[2])]
        mean_curve = np.nanmean(arr, axis=0)                   # (N, k)
        final = arr[:, -1, :]                                  # (R, k): the last epoch of every run
        red = s.diagnostics.get(f"redundancy_{kind}")
        if red is not None and red.shape == (arr.shape[2],):
            parts += [f"{names[i]} {red[i]:.3g}" for i in range(red.size)]
        for i in range(arr.shape[2]):
            series[f"{name}/{key}/{names[i]}"] = mean_curve[:, i]
            rows.append(Row(f"VCE {key} {names[i]}, last epoch", name, float(np.nanmean(final[:, i])), truth[kind],
                            "", f"truth {truth[kind]:.3g}; runs {np.nanmin(final[:, i]):.3g}-"
                                f"{np.nanmax(final[:, i]):.3g}"))
    notes = [(f"{name}: pooled redundancy over the last window, mean over runs: {', '.join(parts)} (a factor "
              f"is re-estimated only while its pooled redundancy exceeds min_redundancy, default 1).")] if parts else []
    return rows, series, notes

