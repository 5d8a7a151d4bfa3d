"""``navpp inspect``: what a log holds, stream by stream, and the role navpp would give each.

A stream is a topic of a ROS log or a file of a CSV log; for each: its message type (CSV: its
columns), count, rate (Hz), first and last stamp (s on the log's time base), gaps and repeated
stamps.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .config import Config
from .errors import InputError

if TYPE_CHECKING:
    from .io.ros import LogContents


@dataclass(frozen=True)
class StreamSummary:
    """One row of ``navpp inspect``: a topic (ROS logs) or a file (CSV logs)."""

    name: str
    msgtype: str
    count: int
    rate_hz: float | None
    first_s: float | None            # absolute stamps, s on the log's time base
    last_s: float | None
    gaps: int                        # intervals longer than 3 nominal periods
    largest_gap_s: float | None
    duplicates: int                  # repeated stamps
    role: str


def stream_stats(stamps_ns) -> tuple[float | None, float | None, float | None, int, float | None, int]:
    """Of a stream's stamps (ns): (rate Hz from the median interval, first s, last s, gaps longer
    than 3 nominal intervals, the largest such gap s, repeated stamps); None where undefined."""
    import numpy as np

    t = np.asarray(stamps_ns, dtype=np.int64)
    if t.size == 0:
        return None, None, None, 0, None, 0
    first, last = t[0] * 1e-9, t[-1] * 1e-9
    if t.size < 2:
        return None, first, last, 0, None, 0
    d = np.diff(t) * 1e-9
    dup = int(np.count_nonzero(d == 0))
    pos = d[d > 0]
    if pos.size == 0:
        return None, first, last, 0, None, dup
    nominal = float(np.median(pos))
    gaps = d > 3.0 * nominal
    return (1.0 / nominal, first, last, int(np.count_nonzero(gaps)),
            float(d[gaps].max()) if gaps.any() else None, dup)


def inspect(log: str | Path, *, config: str | Path | Config | None = None
            ) -> tuple[str, list[StreamSummary], tuple[str, ...]]:
    """What a log holds and the role navpp would give each stream: (kind, rows, reader warnings)."""
    import numpy as np
    import pandas as pd

    from .io.detect import list_topics, log_kind, read_topics
    from .io.ros import FIX_TYPE, IMU_TYPE, POSE_TYPE, SUPPORTED_TYPES

    path = Path(log)
    kind, where = log_kind(path)
    rows: list[StreamSummary] = []
    if kind == "csv":
        roles = {"imu.csv": "IMU", "gnss.csv": "GNSS", "reference.csv": "reference"}
        for name, role in roles.items():
            f = where / name
            if not f.is_file():
                continue
            from .io.csv import prescan
            prescan(f)      # NUL bytes, overlong lines: refused before pandas holds them in memory
            try:
                t = pd.read_csv(f, usecols=["t"], dtype={"t": float}, engine="c")["t"].to_numpy()
                ns = np.round(t * 1e9).astype(np.int64)
            except (ValueError, KeyError) as exc:
                raise InputError(f"{f}: cannot read column 't': {exc}") from None
            columns = ", ".join(pd.read_csv(f, nrows=0).columns)
            rate, first, last, gaps, largest, dup = stream_stats(ns)
            rows.append(StreamSummary(name, columns, int(ns.size), rate, first, last, gaps, largest, dup, role))
        return kind, rows, ()
    topics = list_topics(kind, where)
    wanted = [t.topic for t in topics if t.msgtype in SUPPORTED_TYPES]
    contents = read_topics(kind, where, wanted)
    n_imu = sum(t.msgtype == IMU_TYPE for t in topics)
    n_fix = sum(t.msgtype == FIX_TYPE for t in topics)
    velocity_roles = _velocity_roles(contents)
    for t in topics:
        msgs = contents.imu.get(t.topic) or contents.fix.get(t.topic) or contents.twist.get(t.topic)
        if msgs is not None:
            rate, first, last, gaps, largest, dup = stream_stats(msgs.stamp_ns)
        else:
            rate = (t.count - 1) / ((t.last_ns - t.first_ns) * 1e-9) if (t.first_ns is not None and t.last_ns
                                                                          and t.last_ns > t.first_ns) else None
            first = t.first_ns * 1e-9 if t.first_ns is not None else None
            last = t.last_ns * 1e-9 if t.last_ns is not None else None
            gaps, largest, dup = 0, None, 0
        if t.msgtype == IMU_TYPE:
            role = "IMU" if n_imu == 1 else "IMU? (choose with --imu-topic)"
        elif t.msgtype == FIX_TYPE:
            role = "GNSS" if n_fix == 1 else "GNSS or reference? (--gnss-topic / --reference-topic)"
        elif t.msgtype == POSE_TYPE:
            role = "reference? (--reference-topic, anchored: --reference-anchor)"
        else:
            role = velocity_roles.get(t.topic, "")
        rows.append(StreamSummary(t.topic, t.msgtype, t.count, rate, first, last, gaps, largest, dup, role))
    return kind, rows, tuple(contents.warnings)


def _velocity_roles(contents: LogContents) -> dict[str, str]:
    """Roles of the Twist and Odometry topics: ``odometry`` (wheel odometry, the automatic choice),
    ``GNSS velocity``, or why not used (:func:`navpp.io.detect.odometry_verdict`)."""
    from .io.detect import choose_odometry_topic, gnss_velocity_topics, odometry_verdict
    from .io.ros import ODOMETRY_TYPES

    chosen, _ = choose_odometry_topic(contents, None)
    velocity = gnss_velocity_topics(contents, chosen)
    roles: dict[str, str] = {}
    for t in contents.topics:
        if t.msgtype not in ODOMETRY_TYPES:
            continue
        verdict = odometry_verdict(t.topic, t.msgtype, contents.twist.get(t.topic))
        if t.topic == chosen:
            roles[t.topic] = "odometry"
        elif t.topic in velocity:
            roles[t.topic] = "GNSS velocity" if len(velocity) == 1 else "not used (several velocity topics)"
        elif not verdict:          # a candidate, but several equally good ones
            roles[t.topic] = "odometry? (choose with --odometry-topic)"
        else:
            roles[t.topic] = f"not used ({verdict})"
    return roles
