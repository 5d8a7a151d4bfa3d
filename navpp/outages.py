"""Simulated GNSS outages: the fixes inside given time windows removed from a recording.

A window is ``(start_s, duration_s)``, seconds from the log start (its first IMU sample),
validated by :func:`navpp.config.check_outages`; ``navpp process --gnss-outage`` and the
``[gnss] outages`` config give them.  The INS coasts through each window, and the metrics
report the error at its end.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import InputError
from .recording import Recording


def apply_outages(rec: Recording, windows: Sequence[tuple[float, float]],
                  label: str) -> tuple[Recording, list[dict]]:
    """Remove the GNSS fixes inside simulated outage windows.

    Parameters
    ----------
    rec : the recording; its times are s from the log start (the first IMU sample).
    windows : validated ``(start_s, duration_s)`` pairs (:func:`navpp.config.check_outages`).
    label : how the log is named in error messages.

    Returns
    -------
    The recording without the fixes at ``start <= t <= start + duration`` of any window (its
    IMU, odometry and reference untouched: an outage is of the GNSS only), and one dict per
    window: ``start_s``, ``duration_s``, ``end_s``, ``gnss_removed`` (fixes inside that window;
    overlapping windows count a fix in each).

    Raises
    ------
    InputError
        A window that does not lie inside the log's IMU span: one starting after the log's end,
        or one running past it (not clipped: the outage metrics are read as the error after
        ``duration`` s without GNSS; the message gives the longest window that fits).
    """
    from dataclasses import fields, replace

    if not windows:
        return rec, []
    t_end = float(rec.imu.t[-1]) if len(rec.imu) else 0.0
    t = np.asarray(rec.gnss.t, dtype=float)
    drop = np.zeros(t.shape, bool)
    info = []
    for start, dur in windows:
        end = start + dur
        if start >= t_end:
            raise InputError(f"{label}: GNSS outage {start:g}:{dur:g} ({start:g}-{end:g} s) starts after the log "
                             f"ends: it spans 0-{t_end:.3f} s from its first IMU sample")
        if end > t_end + 1e-9:
            # not clipped: the outage metrics are read as "error after DUR s without GNSS"
            raise InputError(f"{label}: GNSS outage {start:g}:{dur:g} ({start:g}-{end:g} s) runs past the end of "
                             f"the log at {t_end:.3f} s (from its first IMU sample); the longest outage from "
                             f"{start:g} s is {start:g}:{math.floor((t_end - start) * 1000) / 1000:g}")
        inside = (t >= start) & (t <= end)
        drop |= inside
        info.append({"start_s": float(start), "duration_s": float(dur), "end_s": float(end),
                     "gnss_removed": int(np.count_nonzero(inside))})
    if drop.any():
        keep = ~drop
        g = rec.gnss
        cut = {f.name: np.asarray(getattr(g, f.name))[keep] for f in fields(g)
               if isinstance(getattr(g, f.name), np.ndarray) and getattr(g, f.name).shape[:1] == t.shape}
        rec = replace(rec, gnss=replace(g, **cut))
    return rec, info

