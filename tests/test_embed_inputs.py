"""``--embed-input`` (issue 19, point 5): every topic of the input in trajectory.mcap as it was,
the left-out topics in the run's notes, the input's own frames in the tf tree.

Oracles: the input files themselves, read with ``mcap`` (raw records) and ``rosbags`` (raw
payloads, and its own CDR deserializer for ``/tf_static`` and the embedded headers); the
mounting and lever arm given to the writer.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp.cli import app
from navpp.io import mcap_out
from navpp.io import roswrite as rw
from navpp.reading import read_log, resolve_config
from navpp.recording import Recording, Solution

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data"
#: The frames the synthetic inputs use: not navpp's own "imu_link" and "gnss".
IMU_FRAME, GNSS_FRAME = "xsens", "gps_antenna"
MOUNTING_RPY_DEG = (0.0, 0.0, 90.0)       # one axis: no rotation-order convention in the oracle
LEVER_ARM_M = (0.5, -0.2, 1.25)
#: The part of the session log the synthetic inputs hold (s from its start): the 30 s still start
#: and 30 s of driving (enough for `navpp process`), small and quick.
SPAN_S = (0.0, 60.0)


@functools.cache
def _humble():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _cdr(msg, msgtype: str) -> bytes:
    return bytes(_humble().serialize_cdr(msg, msgtype))


def _string(text: str) -> bytes:
    return _cdr(_humble().types["std_msgs/msg/String"](data=text), "std_msgs/msg/String")


def _tf(ns: int) -> bytes:
    t = _humble().types
    tr = t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                        frame_id="world"),
        child_frame_id="robot", transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=3.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    return _cdr(t["tf2_msgs/msg/TFMessage"](transforms=[tr]), "tf2_msgs/msg/TFMessage")


def _msgdef(msgtype: str) -> bytes:
    return _humble().generate_msgdef(msgtype, ros_version=2)[0].encode()


def _extra_messages(rec: Recording) -> dict[str, list[tuple[int, int, bytes]]]:
    """Topics a real recording has besides the IMU and GNSS: (log ns, publish ns, payload)."""
    t0 = rec.t0_ns
    return {"/chatter": [(t0 + k * 997_000_000, t0 + k * 997_000_000 - 123, _string(f"hello {k}")) for k in range(9)],
            "/tf": [(t0 + k * 2_000_000_000 + 5, t0 + k * 2_000_000_000, _tf(t0 + k * 2_000_000_000))
                    for k in range(4)]}


@pytest.fixture(scope="module")
def sim_rec(sim_log_dir: Path) -> Recording:
    return read_log(sim_log_dir, resolve_config(sim_log_dir, None))


@pytest.fixture(scope="module")
def busy_mcap(sim_rec: Recording, tmp_path_factory) -> Path:
    """The session log's first 60 s as a ROS 2 MCAP with frames ``xsens`` / ``gps_antenna``, log time 1.5 ms
    after the stamp, plus ``/chatter`` (QoS metadata, publish time before log time), ``/tf``
    (named like navpp's output) and ``/status`` (JSON, not ROS)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    d = tmp_path_factory.mktemp("busy")
    base = d / "base.mcap"
    rw.write_mcap_ros2(sim_rec, base, frame_id_imu=IMU_FRAME, frame_id_gnss=GNSS_FRAME, log_offset_ns=1_500_000,
                       compression="lz4", chunk_size=200_000, time_range=SPAN_S)
    path = d / "busy.mcap"
    with open(base, "rb") as f_in, open(path, "wb") as f:
        w = Writer(f, chunk_size=300_000)
        w.start(profile="ros2", library="test")
        ids: dict[str, int] = {}
        for schema, channel, m in make_reader(f_in).iter_messages():
            if channel.topic not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.topic] = w.register_channel(channel.topic, channel.message_encoding, sid, channel.metadata)
            w.add_message(ids[channel.topic], m.log_time, m.data, m.publish_time, m.sequence)
        extra = _extra_messages(sim_rec)
        qos = "- history: 1\n  depth: 7\n"
        for topic, msgtype, meta in (("/chatter", "std_msgs/msg/String", {"offered_qos_profiles": qos}),
                                     ("/tf", "tf2_msgs/msg/TFMessage", {})):
            cid = w.register_channel(topic, "cdr", w.register_schema(msgtype, "ros2msg", _msgdef(msgtype)), meta)
            for k, (log, pub, data) in enumerate(extra[topic]):
                w.add_message(cid, log, data, pub, 100 + k)
        cid = w.register_channel("/status", "json", w.register_schema("Status", "jsonschema", b"{}"), {})
        w.add_message(cid, sim_rec.t0_ns, b'{"ok": true}', sim_rec.t0_ns)
        w.finish()
    return path


def _ros2_bag(rec: Recording, path: Path, storage: str, compress: bool = False) -> Path:
    """The busy input as a ROS 2 bag (rosbags' writer): /imu/data, /gnss/fix, /chatter, /tf;
    ``compress``: each payload zstd compressed (rosbag2's message compression)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    base = path.parent / f"{path.name}-base.mcap"
    rw.write_mcap_ros2(rec, base, frame_id_imu=IMU_FRAME, frame_id_gnss=GNSS_FRAME, log_offset_ns=1_500_000,
                       time_range=SPAN_S)
    streams = {topic: [(log, data) for log, _, data in items] for topic, items in _extra_messages(rec).items()}
    types = {"/chatter": "std_msgs/msg/String", "/tf": "tf2_msgs/msg/TFMessage"}
    for topic, items in _raw(base).items():
        types[topic] = items[0]["schema"]
        streams[topic] = [(m["log"], m["data"]) for m in items]
    merged = sorted((log, topic, data) for topic, items in streams.items() for log, data in items)
    w = Writer(path, version=Writer.VERSION_LATEST,
               storage_plugin=StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP)
    if compress:
        w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with w:
        conns = {topic: w.add_connection(topic, types[topic], typestore=_humble()) for topic in types}
        for log, topic, data in merged:
            w.write(conns[topic], log, data)
    return path


@pytest.fixture(scope="module")
def inputs(busy_mcap: Path, sim_rec: Recording, tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bags")
    return {"mcap": busy_mcap, "ros2-sqlite3": _ros2_bag(sim_rec, d / "sqlite", "sqlite3"),
            "ros2-mcap": _ros2_bag(sim_rec, d / "mcapbag", "mcap"),
            "ros2-mcap-compressed": _ros2_bag(sim_rec, d / "zbag", "mcap", compress=True)}


def _raw(path: Path) -> dict[str, list[dict]]:
    """Every message of an MCAP file per topic, as stored (CRCs checked)."""
    from mcap.reader import make_reader

    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        for schema, ch, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False):
            out.setdefault(ch.topic, []).append({
                "schema": schema.name if schema else "", "schema_data": bytes(schema.data) if schema else b"",
                "encoding": ch.message_encoding, "metadata": dict(ch.metadata), "log": m.log_time,
                "publish": m.publish_time, "sequence": m.sequence, "data": bytes(m.data)})
    for items in out.values():
        items.sort(key=lambda m: m["log"])
    return out


def _raw_bag(path: Path) -> dict[str, list[dict]]:
    """Every message of a ROS 2 bag per topic, as rosbags returns it (payload, receive time)."""
    from rosbags.rosbag2 import Reader

    out: dict[str, list[dict]] = {}
    with Reader(path) as r:
        for c, stamp, raw in r.messages():
            out.setdefault(c.topic, []).append({"schema": c.msgtype, "log": int(stamp), "data": bytes(raw)})
    return out


def _small_solution(rec: Recording) -> Solution:
    """Three rows: what the embedded input is does not depend on the solution."""
    g = rec.gnss
    k = [0, len(g) // 2, len(g) - 1]
    return Solution(g.t[k], g.lat_deg[k], g.lon_deg[k], g.alt[k], np.zeros((3, 3)), np.zeros((3, 3)),
                    np.ones((3, 3)), t0_ns=rec.t0_ns)


def _embed(log: Path, out: Path) -> tuple[list[str], Recording]:
    rec = read_log(log, resolve_config(log, None))
    skipped = mcap_out.write_trajectory_mcap(out, solution=_small_solution(rec), recording=rec, embed_input=True,
                                             input_log=log, imu_mounting_rpy_deg=MOUNTING_RPY_DEG,
                                             gnss_lever_arm_m=LEVER_ARM_M)
    return skipped, rec


NAVPP_TOPICS = {"/navpp/fix", "/navpp/odometry", "/tf", "/tf_static"}


# --------------------------------------------------------------------------- every topic, raw


@pytest.mark.parametrize("kind", ["mcap", "ros2-sqlite3", "ros2-mcap", "ros2-mcap-compressed"])
def test_every_topic_is_copied_byte_for_byte(inputs, kind, tmp_path):
    log = inputs[kind]
    out = tmp_path / "trajectory.mcap"
    skipped, _ = _embed(log, out)
    got = _raw(out)
    if kind == "ros2-mcap":          # the storage file's own records: publish times and sequences too
        (storage,) = log.glob("*.mcap")
        want = _raw(storage)
    elif kind == "mcap":
        want = _raw(log)
    else:                           # the payloads after rosbag2's own decompression
        want = _raw_bag(log)
    left_out = {"/tf", "/status"} & set(want)
    assert [line.split(" ")[0] for line in skipped] == sorted(left_out, key=list(want).index)
    assert all("navpp output topic" in line for line in skipped if line.startswith("/tf "))
    assert set(got) == (set(want) - left_out) | NAVPP_TOPICS
    for topic in set(want) - left_out:
        a, b = want[topic], got[topic]
        assert len(a) == len(b) > 0, topic
        assert [m["data"] for m in a] == [m["data"] for m in b], topic
        assert [m["log"] for m in a] == [m["log"] for m in b], topic
        assert {m["schema"] for m in b} == {a[0]["schema"]} and {m["encoding"] for m in b} == {"cdr"}, topic
        if "publish" in a[0]:
            for key in ("publish", "sequence", "schema_data", "metadata"):
                assert [m[key] for m in a] == [m[key] for m in b], (topic, key)
        else:                       # a sqlite3 bag keeps one time per message
            assert [m["publish"] for m in b] == [m["log"] for m in a], topic
    tf = got["/tf"]                                   # navpp's /tf, not the input's
    assert len(tf) == 3 and all(m["data"] not in [x["data"] for x in want["/tf"]] for m in tf)
    from mcap.reader import make_reader

    with open(out, "rb") as f:
        meta = {r.name: r.metadata for r in make_reader(f).iter_metadata()}["navpp"]
    assert meta["embedded_input_skipped"] == "; ".join(skipped)


#: the bundled MCAP runs always; the other logs (8 s of CPU) with the slow tests, for the default run
#: embeds ROS 2 bags in test_every_topic_is_copied_byte_for_byte, a ROS 1 log converted to CDR in
#: test_every_embedded_frame_resolves_to_map and an odometry topic in test_odometry_ros.py
SLOW_SAMPLE_LOGS = ("drive_odometry.mcap", "drive_ros2", "drive.bag")


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW_SAMPLE_LOGS else [])
                                  for n in ("drive.mcap", *SLOW_SAMPLE_LOGS)])
def test_sample_logs_embed_every_topic_once(name, tmp_path):
    """The bundled logs: every input topic once, with its message count (ROS 1: converted to
    CDR; MCAP and ROS 2: the same bytes), nothing encoded a second time."""
    log = SAMPLES / name
    out = tmp_path / "trajectory.mcap"
    skipped, _ = _embed(log, out)
    got = _raw(out)
    if name.endswith(".mcap"):
        want = _raw(log)
    elif name == "drive_ros2":
        want = _raw_bag(log)
    else:
        from rosbags.highlevel import AnyReader

        want = {}
        with AnyReader([log]) as r:
            for c, stamp, _ in r.messages():
                want.setdefault(c.topic, []).append({"log": int(stamp), "data": b""})
    assert skipped == []
    assert set(got) == set(want) | NAVPP_TOPICS
    for topic, items in want.items():
        assert [m["log"] for m in got[topic]] == [m["log"] for m in items], topic
        if name != "drive.bag":
            assert [m["data"] for m in got[topic]] == [m["data"] for m in items], topic
    tree = _tree(got)                      # the bundled logs use one frame per topic: their first message's
    for topic in want:
        msg = _humble().deserialize_cdr(got[topic][0]["data"], got[topic][0]["schema"])
        assert _reaches_map(msg.header.frame_id, tree), (topic, msg.header.frame_id)


@pytest.fixture(scope="module")
def ros1_mcap(sim_rec: Recording, tmp_path_factory) -> Path:
    """The first 20 s of the session log as a ROS 1 encoded MCAP (ros1msg schemas from
    rosbags), with /chatter."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    ts1 = get_typestore(Stores.ROS1_NOETIC)
    i, g = sim_rec.imu.t < 20.0, sim_rec.gnss
    k = g.t < 20.0
    stamps = rw.stamps_ns(sim_rec, sim_rec.imu.t[i])
    fix_stamps = rw.stamps_ns(sim_rec, g.t[k])
    topics = {
        "/imu/data": ("sensor_msgs/Imu", stamps, rw.encode_imu(stamps, sim_rec.imu.gyro[i], sim_rec.imu.accel[i],
                                                                encoding="ros1", frame_id=IMU_FRAME)),
        "/gnss/fix": ("sensor_msgs/NavSatFix", fix_stamps, rw.encode_navsatfix(
            fix_stamps, g.lat_deg[k], g.lon_deg[k], g.alt[k], encoding="ros1", frame_id=GNSS_FRAME,
            cov_diag=np.square(g.std_enu[k]))),
        "/chatter": ("std_msgs/String", fix_stamps[::10], [
            bytes(ts1.serialize_ros1(ts1.types["std_msgs/msg/String"](data=f"hi {j}"), "std_msgs/msg/String"))
            for j in range(fix_stamps[::10].size)]),
    }
    path = tmp_path_factory.mktemp("ros1mcap") / "drive_ros1.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros1", library="test")
        msgs = []
        for topic, (name, st, data) in topics.items():
            full = name.replace("/", "/msg/")
            sid = w.register_schema(name, "ros1msg", ts1.generate_msgdef(full, ros_version=1)[0].encode())
            cid = w.register_channel(topic, "ros1", sid, {"md5sum": ts1.generate_msgdef(full, ros_version=1)[1]})
            msgs += [(int(t) + 3000, cid, k, d) for k, (t, d) in enumerate(zip(st, data))]
        for log, cid, k, d in sorted(msgs):
            w.add_message(cid, log, d, log - 7, k)
        w.finish()
    return path


def test_ros1_encoded_mcap_channels_are_converted(ros1_mcap, tmp_path):
    """Oracle: the input's ROS 1 messages decoded by rosbags from the file's own schemas; the
    output's decoded by mcap_ros2 from its schemas: every field but ``header.seq``, the log and
    publish times and sequence numbers."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path / "trajectory.mcap"
    skipped, _ = _embed(ros1_mcap, out)
    assert skipped == []
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    want: dict[str, list] = {}
    with open(ros1_mcap, "rb") as f:
        for schema, ch, m in make_reader(f).iter_messages():
            msg = ts1.deserialize_ros1(bytes(m.data), schema.name.replace("/", "/msg/"))
            want.setdefault(ch.topic, []).append((m.log_time, m.publish_time, m.sequence, msg))
    got: dict[str, list] = {}
    with open(out, "rb") as f:
        for schema, ch, m, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            got.setdefault(ch.topic, []).append((m.log_time, m.publish_time, m.sequence, msg, schema.name,
                                                 ch.message_encoding))
    assert set(got) == set(want) | NAVPP_TOPICS
    for topic, items in want.items():
        assert len(got[topic]) == len(items), topic
        assert {(x[4], x[5]) for x in got[topic]} == {(items[0][3].__msgtype__, "cdr")}, topic
        for a, b in zip(items, got[topic]):
            assert a[:3] == b[:3], topic
            for name in ("data", "latitude", "longitude", "altitude", "position_covariance", "angular_velocity.x",
                         "linear_acceleration.z", "header.frame_id", "header.stamp.sec", "header.stamp.nanosec"):
                head, _, rest = name.partition(".")
                if hasattr(a[3], head):
                    va, vb = getattr(a[3], head), getattr(b[3], head)
                    for part in rest.split(".") if rest else []:
                        va, vb = getattr(va, part), getattr(vb, part)
                    assert np.array_equal(np.asarray(va), np.asarray(vb)), (topic, name)


# --------------------------------------------------------------------------- the tf tree


def _tree(raw: dict[str, list[dict]]) -> dict[str, tuple[str, object]]:
    """child frame -> (parent frame, transform) of /tf_static and the first /tf of an MCAP file's
    messages as :func:`_raw` read them, decoded by rosbags."""
    tree = {}
    for topic in ("/tf_static", "/tf"):
        msg = _humble().deserialize_cdr(raw[topic][0]["data"], "tf2_msgs/msg/TFMessage")
        for t in msg.transforms:
            tree[t.child_frame_id] = (t.header.frame_id, t.transform)
    return tree


def _reaches_map(frame: str, tree: dict) -> bool:
    seen = set()
    while frame != "map":
        if frame in seen or frame not in tree:
            return False
        seen.add(frame)
        frame = tree[frame][0]
    return True


@pytest.mark.parametrize("kind", ["mcap", "ros2-sqlite3", "ros1", "ros1-mcap"])
def test_every_embedded_frame_resolves_to_map(inputs, sim_rec, ros1_mcap, kind, tmp_path):
    if kind == "ros1":
        log = tmp_path / "drive.bag"
        rw.write_ros1_bag(sim_rec, log, frame_id_imu=IMU_FRAME, frame_id_gnss=GNSS_FRAME, time_range=SPAN_S)
    elif kind == "ros1-mcap":
        log = ros1_mcap
    else:
        log = inputs[kind]
    out = tmp_path / "trajectory.mcap"
    _embed(log, out)
    got = _raw(out)
    tree = _tree(got)
    frames_seen = set()
    ts = _humble()
    for topic, items in got.items():
        fields = ts.fielddefs[items[0]["schema"]][1] if items[0]["schema"] in ts.fielddefs else []
        if topic in NAVPP_TOPICS or not any(name == "header" for name, _ in fields):
            continue
        for m in items:
            msg = ts.deserialize_cdr(m["data"], m["schema"])
            frames_seen.add(msg.header.frame_id)
            assert _reaches_map(msg.header.frame_id, tree), (topic, msg.header.frame_id)
    assert {IMU_FRAME, GNSS_FRAME} <= frames_seen
    imu, gnss = tree[IMU_FRAME], tree[GNSS_FRAME]
    assert imu[0] == gnss[0] == "base_link"
    s = np.sqrt(0.5)                                  # 90 deg about z
    q = imu[1].rotation
    assert np.allclose([q.x, q.y, q.z, q.w], [0.0, 0.0, s, s], atol=1e-12)
    v = gnss[1].translation
    assert (v.x, v.y, v.z) == LEVER_ARM_M
    q = tree["imu_link"][1].rotation                  # navpp's own frame is kept
    assert np.allclose([q.x, q.y, q.z, q.w], [0.0, 0.0, s, s], atol=1e-12)


# --------------------------------------------------------------------------- the notes


def test_left_out_topics_are_in_the_printed_notes(busy_mcap, tmp_path):
    res = CliRunner().invoke(app, ["process", str(busy_mcap), "--format", "mcap", "--embed-input", "--out",
                                   str(tmp_path / "o"), "--output-rate", "1"])
    assert res.exit_code == 0, res.output
    lines = [line for line in res.stderr.splitlines() if "--embed-input:" in line]
    assert len(lines) == 1
    line = " ".join(lines[0].split())
    assert "2 input topics not embedded in trajectory.mcap" in line
    assert "/tf (tf2_msgs/msg/TFMessage): a navpp output topic" in line and "/status (Status): json" in line


def test_note_wording() -> None:
    from navpp.api import embed_note

    assert embed_note(["/tf (tf2_msgs/msg/TFMessage): a navpp output topic"]) == (
        "--embed-input: 1 input topic not embedded in trajectory.mcap: /tf (tf2_msgs/msg/TFMessage): a navpp "
        "output topic")

