"""``navpp.layout.json`` against the ``trajectory.mcap`` of the same run (issue 19, point 5).

Foxglove itself is not available here, so the layout is not opened; instead every topic,
message path and frame it names is looked up in the file navpp wrote: the channels (``mcap``'s
summary), the fields of the decoded messages (``mcap_ros2``'s decoder, from the schemas in the
file) and the frames of ``/tf`` and ``/tf_static``.  Oracle: the file.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import pytest

#: A Foxglove message path: ``/topic`` then ``.field`` / ``[index]`` steps.
_STEP = re.compile(r"\.([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]")


@pytest.fixture(scope="module")
def run(sim_log_dir: Path, tmp_path_factory) -> Path:
    """The session log by VCE-CKF (adaptive values to plot), MCAP written with its layout."""
    from navpp import api

    out = tmp_path_factory.mktemp("layout")
    api.process(sim_log_dir, filter_name="vce-ckf", out_dir=out, formats="mcap", output_rate_hz=1.0)
    return out


def _first_messages(path: Path) -> tuple[dict[str, object], dict[str, str]]:
    """The first decoded message of every topic, and every topic's schema name."""
    from mcap.reader import make_reader

    with warnings.catch_warnings():     # mcap_ros2 imports a deprecated module
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.decoder import DecoderFactory

        first: dict[str, object] = {}
        types: dict[str, str] = {}
        with open(path, "rb") as f:
            for schema, ch, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                first.setdefault(ch.topic, msg)
                types[ch.topic] = schema.name
    return first, types


def _resolve(msg: object, path: str) -> object:
    pos = 0
    value = msg
    while pos < len(path):
        m = _STEP.match(path, pos)
        assert m is not None, f"cannot parse {path!r} at {pos}"
        value = getattr(value, m.group(1)) if m.group(1) else value[int(m.group(2))]
        pos = m.end()
    return value


def _strings(node: object, out: list[str]) -> list[str]:
    """Every string in a JSON tree, keys included."""
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(k)
            _strings(v, out)
    elif isinstance(node, list):
        for v in node:
            _strings(v, out)
    elif isinstance(node, str):
        out.append(node)
    return out


def test_every_topic_path_and_frame_of_the_layout_is_in_the_mcap(run: Path) -> None:
    layout = json.loads((run / "navpp.layout.json").read_text(encoding="utf-8"))
    first, types = _first_messages(run / "trajectory.mcap")
    frames = set()
    for topic in ("/tf", "/tf_static"):
        for t in first[topic].transforms:
            frames |= {t.header.frame_id, t.child_frame_id}

    named = [s for s in _strings(layout, []) if s.startswith("/")]
    assert len(named) >= 8
    for text in named:
        topic, _, rest = text.partition(".")
        assert topic in first, f"{text}: no topic {topic} in trajectory.mcap"
        if rest:
            value = _resolve(first[topic], "." + rest)
            assert isinstance(value, (int, float)) and math.isfinite(value), text
    for text in _strings(layout, []):
        if text.startswith("frame:"):
            assert text.removeprefix("frame:") in frames, text

    config = layout["configById"]
    assert types[config["map!navpp"]["followTopic"]] == "sensor_msgs/msg/NavSatFix"
    assert config["3D!navpp"]["followTf"] in frames
    diag = first["/navpp/diagnostics"]
    adaptive = [p for p in config["Plot!navppadapt"]["paths"] if ".values[" in p["value"]]
    assert len(adaptive) == len(diag.names) > 0
    for p in adaptive:                      # each curve is labelled with the name the message gives it
        k = int(p["value"].rsplit("[", 1)[1].rstrip("]"))
        assert p["label"] == diag.names[k]
