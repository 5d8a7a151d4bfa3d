"""``navpp.layout.json``: a Foxglove layout for ``trajectory.mcap`` (import it in Foxglove with
Layouts -> Import from file, then open the MCAP).

Panels (a Foxglove layout is ``configById``, panel id ``"<Type>!<id>"`` -> its settings, and a
``layout`` tree of ``first`` / ``second`` / ``direction`` / ``splitPercentage`` splits):

- Map (``map!navpp``): the ``/navpp/fix`` NavSatFix track on a map (Foxglove's map panel reads
  NavSatFix topics and draws the position covariance).
- 3D (``3D!navpp``): ``/tf`` and ``/tf_static`` (map -> odom -> base_link, base_link -> imu_link
  and gnss) and ``/navpp/odometry`` (pose with its covariance), following ``base_link``.
- Plot "position 1-sigma (m)" (``Plot!navppsigma``): ``/navpp/odometry.pose.covariance[0]``,
  ``[7]``, ``[14]`` (E, N, U variances, m²) -- Foxglove plots message fields as they are.
- Plot "NIS and adaptive factors" (``Plot!navppadapt``): ``/navpp/diagnostics.nis`` and
  ``.values[k]`` for every adaptive value of the run, labelled by its name (the
  ``names[k]`` of the diagnostics message: ``q_factor_*``, ``r_factor_*``, ``fading``, ...).

The file is written beside ``trajectory.mcap`` whenever the MCAP format is written; it names
only navpp's own topics, so one layout serves every run of the same filter.  Every topic,
message path and frame it names is checked against the ``trajectory.mcap`` of the same run
(``tests/test_layout_topics.py``: channels, decoded fields, tf frames); Foxglove itself is not
run by the tests.
"""

from __future__ import annotations

import json
import os
from typing import Any

from .writers import adaptive_columns, atomic_write

LAYOUT_FILE = "navpp.layout.json"

__all__ = ["LAYOUT_FILE", "layout", "write_layout"]


def _plot(title: str, paths: list[tuple[str, str]]) -> dict[str, Any]:
    return {"title": title,
            "paths": [{"value": value, "label": label, "enabled": True, "timestampMethod": "receiveTime"}
                      for value, label in paths],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
            "isSynced": True, "xAxisVal": "timestamp"}


def layout(diagnostics: Any = None) -> dict[str, Any]:
    """The layout (module docstring) as a dict; ``diagnostics`` (:class:`navpp.engine.Diagnostics`)
    names the adaptive values to plot (None: the NIS only)."""
    names: list[str] = []
    if diagnostics is not None:
        names = list(adaptive_columns(diagnostics)[0])
    sigma = [(f"/navpp/odometry.pose.covariance[{i}]", f"{axis} variance (m²)")
             for i, axis in ((0, "east"), (7, "north"), (14, "up"))]
    adapt = [("/navpp/diagnostics.nis", "NIS")] + [(f"/navpp/diagnostics.values[{k}]", name)
                                                   for k, name in enumerate(names)]
    config = {
        "map!navpp": {"layer": "map", "customTileUrl": "", "disabledTopics": [], "topicColors": {},
                      "followTopic": "/navpp/fix", "zoomLevel": 17},
        "3D!navpp": {"followMode": "follow-pose", "followTf": "base_link",
                     "topics": {"/navpp/odometry": {"visible": True}, "/navpp/fix": {"visible": False}},
                     "transforms": {"frame:map": {"visible": True}, "frame:odom": {"visible": True},
                                    "frame:base_link": {"visible": True}, "frame:imu_link": {"visible": True},
                                    "frame:gnss": {"visible": True}}},
        "Plot!navppsigma": _plot("position 1-sigma squared (m², ENU)", sigma),
        "Plot!navppadapt": _plot("NIS and adaptive factors", adapt),
    }
    tree = {"first": {"first": "map!navpp", "second": "3D!navpp", "direction": "column", "splitPercentage": 50},
            "second": {"first": "Plot!navppsigma", "second": "Plot!navppadapt", "direction": "column",
                       "splitPercentage": 50},
            "direction": "row", "splitPercentage": 55}
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": tree}


def write_layout(path: str | os.PathLike[str], diagnostics: Any = None) -> None:
    """Write ``navpp.layout.json`` (module docstring) atomically, UTF-8, indented."""
    text = json.dumps(layout(diagnostics), indent=2, ensure_ascii=False) + "\n"
    atomic_write(path, lambda f: f.write(text), mode="w")
