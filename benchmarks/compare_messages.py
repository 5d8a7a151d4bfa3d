"""Compare two ROS logs message by message: two MCAP files, or two bags (ROS 1 ``.bag`` files or
ROS 2 bag directories).

Usage (from the repository root)::

    python benchmarks/compare_messages.py A.mcap B.mcap
    python benchmarks/compare_messages.py A.bag B.bag
    python benchmarks/compare_messages.py bag_dir_a bag_dir_b

What is compared, ignoring the container's bytes (chunk boundaries, compression, indexes):

* MCAP: the header's profile; every channel (topic, message encoding, metadata) with its schema
  (name, encoding, text); the Metadata records; and every message in file order: topic,
  log time, publish time, sequence and payload bytes.
* Bags (read with ``rosbags``' ``AnyReader``): every connection (topic, message type, message
  definition, md5sum / type hash), and every message in file order: topic, timestamp and raw
  payload bytes.

Prints the counts and each difference (at most ``--max-report`` of them) and exits 1 when there
is any, 0 when the two logs hold the same messages.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from itertools import zip_longest
from pathlib import Path
from typing import Any


def _mcap_messages(path: Path) -> Iterator[tuple[Any, ...]]:
    """(topic, log time, publish time, sequence, payload) of every message, in file order."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            yield channel.topic, message.log_time, message.publish_time, message.sequence, bytes(message.data)


def _mcap_description(path: Path) -> dict[str, Any]:
    """Profile, channels with their schemas (by topic) and metadata records of an MCAP file."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    if summary is None:
        raise SystemExit(f"{path}: no summary section")
    channels: dict[str, list] = {}
    for ch in summary.channels.values():
        schema = summary.schemas.get(ch.schema_id)
        channels.setdefault(ch.topic, []).append(
            (ch.message_encoding, dict(ch.metadata),
             None if schema is None else (schema.name, schema.encoding, bytes(schema.data))))
    counts = {summary.channels[cid].topic: n
              for cid, n in (summary.statistics.channel_message_counts.items() if summary.statistics else ())}
    return {"profile": header.profile, "channels": channels, "metadata": metadata, "counts": counts}


def _bag_messages(path: Path) -> Iterator[tuple[Any, ...]]:
    """(topic, timestamp, payload) of every message of a bag, in file order."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        for conn, timestamp, raw in reader.messages():
            yield conn.topic, timestamp, bytes(raw)


def _bag_description(path: Path) -> dict[str, Any]:
    """Connections (by topic) of a bag: type, definition and digest."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        channels: dict[str, list] = {}
        for conn in reader.connections:
            channels.setdefault(conn.topic, []).append((conn.msgtype, conn.msgdef, conn.digest))
        counts: dict[str, int] = {}
        for conn in reader.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
    return {"channels": channels, "counts": counts}


def compare(a: Path, b: Path, max_report: int = 20) -> list[str]:
    """The differences between the messages of logs ``a`` and ``b`` (empty: the same)."""
    is_mcap = a.suffix == ".mcap" and a.is_file()
    if is_mcap != (b.suffix == ".mcap" and b.is_file()):
        return [f"{a} and {b} are not both MCAP files or both bags"]
    describe, messages = (_mcap_description, _mcap_messages) if is_mcap else (_bag_description, _bag_messages)
    da, db = describe(a), describe(b)
    diffs = [f"{key}: {da[key]!r} != {db[key]!r}" for key in da if key not in ("channels",) and da[key] != db[key]]
    for topic in sorted(set(da["channels"]) | set(db["channels"])):
        ca, cb = da["channels"].get(topic), db["channels"].get(topic)
        if ca != cb:
            diffs.append(f"channel {topic}: {ca!r} != {cb!r}")
    n = 0
    for n, (ma, mb) in enumerate(zip_longest(messages(a), messages(b)), start=1):
        if ma != mb:
            if ma is None or mb is None:
                diffs.append(f"message {n}: only in {a if mb is None else b}")
                break
            fields = ("topic", "log_time", "publish_time", "sequence", "data") if is_mcap else \
                ("topic", "timestamp", "data")
            which = [f for f, x, y in zip(fields, ma, mb) if x != y]
            diffs.append(f"message {n} ({ma[0]} at {ma[1]}): {', '.join(which)} differ")
            if len(diffs) >= max_report:
                diffs.append("... (stopped)")
                break
    print(f"{a}: {n} messages compared with {b}; topics: "
          + ", ".join(f"{t} {c}" for t, c in sorted(da["counts"].items())))
    return diffs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--max-report", type=int, default=20)
    args = ap.parse_args()
    diffs = compare(args.a, args.b, args.max_report)
    for d in diffs:
        print(d)
    print("identical messages" if not diffs else f"{len(diffs)} difference(s)")
    sys.exit(1 if diffs else 0)


if __name__ == "__main__":
    main()
