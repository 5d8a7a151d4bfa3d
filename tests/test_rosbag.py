"""navpp.io.rosbag: round trips through navpp's own writers (ROS 1 bag, ROS 2 sqlite3 and mcap
bags), split and compressed bags, the bulk decoder against the library decoder, and every
bad input giving one InputError line that names the file."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from navpp.errors import InputError
from navpp.io import rosbag
from navpp.io import roswrite as rw
from navpp.io.ros import FIX_TYPE, IMU_TYPE, TWIST_COV_TYPE, TWIST_TYPE, LogContents
from navpp.io.rosbag import list_topics, read_rosbag
from navpp.recording import Recording

LOG_OFFSET_NS = 2_500_000  # log (receive) time = header stamp + 2.5 ms


@pytest.fixture(scope="module")
def rec() -> Recording:
    from navpp.simulate import SimulationSpec, simulate

    return simulate(SimulationSpec(duration_s=40, still_s=20, gnss_velocity=True)).recording()


WRITERS = {
    "ros1": lambda rec, p, **kw: rw.write_ros1_bag(rec, p / "log.bag", **kw),
    "ros1-lz4": lambda rec, p, **kw: rw.write_ros1_bag(rec, p / "log.bag", compression="lz4", chunk_size=64_000, **kw),
    "ros1-bz2": lambda rec, p, **kw: rw.write_ros1_bag(rec, p / "log.bag", compression="bz2", **kw),
    "ros2-sqlite3": lambda rec, p, **kw: rw.write_ros2_bag(rec, p / "bag", **kw),
    "ros2-mcap": lambda rec, p, **kw: rw.write_ros2_bag(rec, p / "bag", storage="mcap", **kw),
    "ros2-mcap-zstd": lambda rec, p, **kw: rw.write_ros2_bag(rec, p / "bag", storage="mcap", compression="storage",
                                                            **kw),
    "ros2-sqlite3-message": lambda rec, p, **kw: rw.write_ros2_bag(rec, p / "bag", compression="message", **kw),
    "ros2-sqlite3-file": lambda rec, p, **kw: rw.write_ros2_bag(rec, p / "bag", compression="file", **kw),
}
MAIN_KINDS = ["ros1", "ros2-sqlite3", "ros2-mcap"]


def write(kind: str, rec: Recording, directory: Path, **kw) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    WRITERS[kind](rec, directory, reference_topic="/reference/fix", log_offset_ns=LOG_OFFSET_NS, **kw)
    return directory / ("log.bag" if kind.startswith("ros1") else "bag")


@pytest.fixture(scope="module")
def logs(rec, tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("rosbags")
    return {kind: write(kind, rec, base / kind) for kind in WRITERS}


def assert_matches_recording(lc: LogContents, rec: Recording, *, ros1: bool) -> None:
    imu = lc.imu["/imu/data"]
    stamps = rw.stamps_ns(rec, rec.imu.t)
    assert imu.stamp_ns.dtype == np.int64
    np.testing.assert_array_equal(imu.stamp_ns, stamps)
    np.testing.assert_array_equal(imu.log_ns, stamps + LOG_OFFSET_NS)
    np.testing.assert_array_equal(imu.gyro, rec.imu.gyro)
    np.testing.assert_array_equal(imu.accel, rec.imu.accel)
    np.testing.assert_array_equal(imu.gyro_cov0, 0.0)
    np.testing.assert_array_equal(imu.accel_cov0, 0.0)
    assert imu.frame_id == "imu_link"

    fix = lc.fix["/gnss/fix"]
    g = rec.gnss
    gstamps = rw.stamps_ns(rec, g.t)
    np.testing.assert_array_equal(fix.stamp_ns, gstamps)
    np.testing.assert_array_equal(fix.log_ns, gstamps + LOG_OFFSET_NS)
    np.testing.assert_array_equal(fix.lat_deg, g.lat_deg)
    np.testing.assert_array_equal(fix.lon_deg, g.lon_deg)
    np.testing.assert_array_equal(fix.alt, g.alt)
    np.testing.assert_array_equal(fix.cov[:, [0, 4, 8]], g.std_enu**2)
    np.testing.assert_array_equal(fix.cov[:, [1, 2, 3, 5, 6, 7]], 0.0)
    np.testing.assert_array_equal(fix.cov_type, 2)
    np.testing.assert_array_equal(fix.status, 0)
    assert fix.frame_id == "gnss"

    vel = lc.twist["/gnss/vel"]
    np.testing.assert_array_equal(vel.stamp_ns, gstamps)
    np.testing.assert_array_equal(vel.vel, g.vel_enu)
    np.testing.assert_array_equal(vel.cov_diag, g.std_vel_enu**2)

    ref = lc.fix["/reference/fix"]
    r = rec.reference
    np.testing.assert_array_equal(ref.stamp_ns, rw.stamps_ns(rec, r.t))
    np.testing.assert_array_equal(ref.lat_deg, r.lat_deg)
    np.testing.assert_array_equal(ref.alt, r.alt)
    np.testing.assert_array_equal(ref.cov_type, 0)

    info = {t.topic: t for t in lc.topics}
    assert {k: v.msgtype for k, v in info.items()} == {"/imu/data": IMU_TYPE, "/gnss/fix": FIX_TYPE,
                                                       "/gnss/vel": TWIST_COV_TYPE, "/reference/fix": FIX_TYPE}
    assert info["/imu/data"].count == len(rec.imu)
    assert info["/imu/data"].first_ns == stamps[0] + LOG_OFFSET_NS
    assert info["/imu/data"].last_ns == stamps[-1] + LOG_OFFSET_NS
    assert {t.encoding for t in lc.topics} == {"ros1" if ros1 else "cdr"}
    assert lc.warnings == ()


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_round_trip_is_exact(logs, rec, kind):
    lc = read_rosbag(logs[kind])
    assert lc.source == str(logs[kind])
    assert_matches_recording(lc, rec, ros1=kind.startswith("ros1"))


@pytest.mark.parametrize("kind", MAIN_KINDS)
def test_bulk_and_library_decoders_agree(logs, monkeypatch, kind):
    pytest.importorskip("navpp.io.messages")
    decode = rosbag._bulk_decoder()
    assert decode is not None
    calls = []

    def spy(*args, **kwargs):
        calls.append(args[1])
        return decode(*args, **kwargs)

    monkeypatch.setattr(rosbag, "_bulk_decoder", lambda: spy)
    bulk = read_rosbag(logs[kind])
    assert sorted(calls) == sorted([IMU_TYPE, FIX_TYPE, FIX_TYPE, TWIST_COV_TYPE])
    monkeypatch.setattr(rosbag, "_bulk_decoder", lambda: None)
    library = read_rosbag(logs[kind])
    assert_same_contents(bulk, library)


@pytest.mark.parametrize("kind", ["ros1", "ros1-lz4", "ros1-bz2"])
def test_ros1_index_path_and_rosbags_iteration_agree(logs, monkeypatch, kind):
    fast = read_rosbag(logs[kind])
    assert fast.warnings == ()      # navpp's index path was taken, not rosbags' reader
    assert list_topics(logs[kind]) == _rosbags_topics([logs[kind]])
    monkeypatch.setattr(rosbag, "_FAST_ROS1", False)
    slow = read_rosbag(logs[kind])
    assert_same_contents(fast, slow)


def test_ros1_index_path_on_split_bags(rec, tmp_path, monkeypatch):
    files = [tmp_path / "s_0.bag", tmp_path / "s_1.bag"]
    rw.write_ros1_bag(rec, files[0], time_range=(-1.0, 15.0), chunk_size=20_000)
    rw.write_ros1_bag(rec, files[1], time_range=(15.0, 1e9), compression="lz4")
    fast = read_rosbag(files)
    assert fast.warnings == ()
    assert list_topics(files) == _rosbags_topics(files)
    monkeypatch.setattr(rosbag, "_FAST_ROS1", False)
    assert_same_contents(fast, read_rosbag(files))


def _rosbags_topics(files):
    """The topics as rosbags' AnyReader gives them (its per-message index)."""
    with rosbag._open(files) as reader:
        return rosbag._topic_infos(reader)


def assert_same_contents(a: LogContents, b: LogContents) -> None:
    assert a.topics == b.topics
    for group in ("imu", "fix", "twist"):
        da, db = getattr(a, group), getattr(b, group)
        assert da.keys() == db.keys()
        for topic in da:
            for name in da[topic].__dataclass_fields__:
                x, y = getattr(da[topic], name), getattr(db[topic], name)
                if isinstance(x, np.ndarray):
                    assert x.dtype == y.dtype, (topic, name)
                    np.testing.assert_array_equal(x, y, err_msg=f"{topic} {name}")
                else:
                    assert x == y, (topic, name)


def test_bag_without_suffix_and_ros2_storage_file(logs, tmp_path, rec):
    odd = tmp_path / "drive.bag.orig"
    shutil.copy(logs["ros1"], odd)
    assert_matches_recording(read_rosbag(odd), rec, ros1=True)
    # a ROS 2 bag directory whose name ends in .bag
    d = tmp_path / "drive.bag"
    shutil.copytree(logs["ros2-mcap"], d)
    lc = read_rosbag(d)
    np.testing.assert_array_equal(lc.imu["/imu/data"].gyro, rec.imu.gyro)
    assert lc.source == str(d)
    # a ROS 2 bag's storage file on its own (rosbags reads .db3 / .mcap storage files too)
    db3 = logs["ros2-sqlite3"] / "bag.db3"
    lc = read_rosbag(db3)
    np.testing.assert_array_equal(lc.imu["/imu/data"].gyro, rec.imu.gyro)


def test_split_ros1_bags_read_together(rec, tmp_path):
    half = 20.0
    rw.write_ros1_bag(rec, tmp_path / "drive_0.bag", time_range=(-1.0, half), log_offset_ns=LOG_OFFSET_NS,
                      reference_topic="/reference/fix")
    rw.write_ros1_bag(rec, tmp_path / "drive_1.bag", time_range=(half, 1e9), log_offset_ns=LOG_OFFSET_NS,
                      reference_topic="/reference/fix")
    files = [tmp_path / "drive_0.bag", tmp_path / "drive_1.bag"]
    for order in (files, files[::-1]):
        lc = read_rosbag(order)
        assert " + " in lc.source
        assert_matches_recording(lc, rec, ros1=True)
    assert sum(t.count for t in list_topics(files) if t.topic == "/imu/data") == len(rec.imu)


def test_header_stamps_and_log_times_are_kept_apart(rec, tmp_path):
    rw.write_ros2_bag(rec, tmp_path / "bag", log_offset_ns=-7)
    imu = read_rosbag(tmp_path / "bag").imu["/imu/data"]
    np.testing.assert_array_equal(imu.log_ns - imu.stamp_ns, -7)


def test_twist_stamped_and_covariances(tmp_path):
    """TwistStamped (no covariance) and IMU covariances from a given noise, written by hand."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    stamps = np.array([1_600_000_000_000_000_001, 1_600_000_000_100_000_002], dtype=np.int64)
    vel = np.array([[1.0, -2.0, 0.5], [np.pi, 0.0, -0.0]])
    imu = rw.encode_imu(stamps, vel, vel * 2, encoding="ros1", frame_id="x", gyro_var=1e-6, accel_var=4e-4)
    tw = rw.encode_twist(stamps, vel, encoding="ros1", frame_id="gps")
    ts = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "t.bag"
    with Writer(path) as w:
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        ct = w.add_connection("/vel", "geometry_msgs/msg/TwistStamped", typestore=ts)
        for i in range(2):
            w.write(ci, int(stamps[i]), imu[i])
            w.write(ct, int(stamps[i]), tw[i])
    for fast in (True, False):
        lc = read_rosbag(path) if fast else _read_with_library(path)
        t = lc.twist["/vel"]
        np.testing.assert_array_equal(t.vel, vel)
        np.testing.assert_array_equal(t.stamp_ns, stamps)
        assert t.cov_diag is None and t.frame_id == "gps"
        np.testing.assert_array_equal(lc.imu["/imu"].gyro_cov0, 1e-6)
        np.testing.assert_array_equal(lc.imu["/imu"].accel_cov0, 4e-4)
        assert {x.topic: x.msgtype for x in lc.topics} == {"/imu": IMU_TYPE, "/vel": TWIST_TYPE}


def _read_with_library(path):
    saved = rosbag._bulk_decoder
    rosbag._bulk_decoder = lambda: None
    try:
        return read_rosbag(path)
    finally:
        rosbag._bulk_decoder = saved


# --------------------------------------------------------------------------- topics


@pytest.mark.parametrize("kind", MAIN_KINDS)
def test_list_topics_is_cheap_and_complete(logs, rec, kind):
    topics = {t.topic: t for t in list_topics(logs[kind])}
    assert {k: (v.msgtype, v.count) for k, v in topics.items()} == {
        "/imu/data": (IMU_TYPE, len(rec.imu)), "/gnss/fix": (FIX_TYPE, len(rec.gnss)),
        "/gnss/vel": (TWIST_COV_TYPE, len(rec.gnss)), "/reference/fix": (FIX_TYPE, len(rec.reference))}
    first = topics["/imu/data"].first_ns
    if kind == "ros1":  # the ROS 1 index holds every message's time
        assert first == rec.t0_ns + LOG_OFFSET_NS
    else:
        assert first is None


def test_only_the_asked_topics_are_decoded(logs):
    lc = read_rosbag(logs["ros1"], topics=["/imu/data", "/gnss/fix"])
    assert list(lc.imu) == ["/imu/data"] and list(lc.fix) == ["/gnss/fix"] and lc.twist == {}
    assert len(lc.topics) == 4  # every topic is still listed
    by = {t.topic: t for t in lc.topics}
    assert by["/reference/fix"].count > 0


def test_unknown_topic_lists_the_topics(logs):
    with pytest.raises(InputError) as e:
        read_rosbag(logs["ros2-sqlite3"], topics=["/imu"])
    msg = str(e.value)
    assert str(logs["ros2-sqlite3"]) in msg and "'/imu'" in msg and "/imu/data" in msg and "\n" not in msg


# --------------------------------------------------------------------------- bad input


def check_error(exc: pytest.ExceptionInfo, path: Path, *words: str) -> str:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    assert str(path) in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


@pytest.mark.parametrize("reader", [read_rosbag, list_topics])
def test_not_a_bag(tmp_path, reader):
    p = tmp_path / "notes.bag"
    p.write_text("hello\n")
    with pytest.raises(InputError) as e:
        reader(p)
    check_error(e, p, "not a ROS bag")


@pytest.mark.parametrize("reader", [read_rosbag, list_topics])
def test_empty_file(tmp_path, reader):
    p = tmp_path / "empty.bag"
    p.write_bytes(b"")
    with pytest.raises(InputError) as e:
        reader(p)
    check_error(e, p, "empty file")


def test_missing_path(tmp_path):
    with pytest.raises(InputError) as e:
        read_rosbag(tmp_path / "nope.bag")
    check_error(e, tmp_path / "nope.bag", "no such file")
    with pytest.raises(InputError, match="no ROS bag given"):
        read_rosbag([])


def test_ros2_directory_without_metadata(logs, tmp_path):
    d = tmp_path / "bag"
    shutil.copytree(logs["ros2-sqlite3"], d)
    (d / "metadata.yaml").unlink()
    with pytest.raises(InputError) as e:
        read_rosbag(d)
    check_error(e, d, "metadata.yaml")


@pytest.mark.parametrize("kind", ["ros1", "ros2-mcap"])
def test_bag_without_messages(tmp_path, kind):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        p = tmp_path / "empty.bag"
        with Writer1(p) as w:
            w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=get_typestore(Stores.ROS1_NOETIC))
    else:
        p = tmp_path / "emptybag"
        with Writer2(p, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=get_typestore(Stores.ROS2_HUMBLE))
    for reader in (read_rosbag, list_topics):
        with pytest.raises(InputError) as e:
            reader(p)
        check_error(e, p, "no messages")


def test_truncated_ros1_bag(logs, tmp_path):
    p = tmp_path / "cut.bag"
    data = logs["ros1"].read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as e:
        read_rosbag(p)
    check_error(e, p, "truncated")


def test_unindexed_ros1_bag(logs, tmp_path):
    """A bag whose recording was killed: rosbag leaves index_pos = 0."""
    p = tmp_path / "active.bag"
    data = bytearray(logs["ros1"].read_bytes())
    k = data.index(b"index_pos=") + len(b"index_pos=")
    data[k:k + 8] = bytes(8)
    p.write_bytes(bytes(data))
    with pytest.raises(InputError) as e:
        list_topics(p)
    check_error(e, p, "no index", "rosbag reindex")


def test_corrupted_chunk_in_ros1_bag(logs, tmp_path):
    p = tmp_path / "bad.bag"
    data = bytearray(logs["ros1-lz4"].read_bytes())
    k = data.index(b"compression=lz4") + 200
    data[k:k + 64] = b"\xff" * 64
    p.write_bytes(bytes(data))
    with pytest.raises(InputError) as e:
        read_rosbag(p)
    check_error(e, p, "cannot read the bag")


@pytest.mark.parametrize("kind", ["ros2-sqlite3", "ros2-mcap"])
def test_truncated_ros2_bag(logs, tmp_path, kind):
    d = tmp_path / "bag"
    shutil.copytree(logs[kind], d)
    storage = next(f for f in d.iterdir() if f.suffix in (".db3", ".mcap"))
    data = storage.read_bytes()
    storage.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as e:
        read_rosbag(d)
    check_error(e, d)


def test_mixing_ros1_and_ros2(logs):
    with pytest.raises(InputError) as e:
        read_rosbag([logs["ros1"], logs["ros2-sqlite3"]])
    check_error(e, logs["ros1"], "ROS 1 and ROS 2")


def test_bad_file_among_split_bags_is_named(logs, tmp_path):
    good = tmp_path / "a_0.bag"
    shutil.copy(logs["ros1"], good)
    bad = tmp_path / "a_1.bag"
    data = logs["ros1"].read_bytes()
    bad.write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError) as e:
        read_rosbag([good, bad])
    msg = check_error(e, bad, "truncated")
    assert not msg.startswith(str(good))


# --------------------------------------------------------------------------- message definitions


def _custom_imu_store(imu_text: str):
    """A typestore whose sensor_msgs/msg/Imu is ``imu_text`` (ROS 1 msg syntax)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    base = get_typestore(Stores.ROS1_NOETIC)
    ts = get_typestore(Stores.EMPTY)
    ts.register({name: base.fielddefs[name] for name in ("builtin_interfaces/msg/Time", "std_msgs/msg/Header",
                                                           "geometry_msgs/msg/Vector3")})
    ts.register(get_types_from_msg(imu_text, "sensor_msgs/msg/Imu"))
    return ts


def _write_custom_imu_bag(path: Path, ts, make_msg, n: int = 5) -> None:
    from rosbags.rosbag1 import Writer

    msgdef, md5 = ts.generate_msgdef("sensor_msgs/msg/Imu")
    with Writer(path) as w:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", msgdef=msgdef, md5sum=md5)
        for i in range(n):
            w.write(c, 1_000_000_000 + i, bytes(ts.serialize_ros1(make_msg(ts, i), "sensor_msgs/msg/Imu")))


def test_garbage_message_definition(tmp_path):
    from rosbags.rosbag1 import Writer

    p = tmp_path / "garbage.bag"
    with Writer(p) as w:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", msgdef="this is ] not { a definition", md5sum="0" * 32)
        w.write(c, 1, b"\0" * 300)
    with pytest.raises(InputError) as e:
        read_rosbag(p)
    check_error(e, p, "message definitions")


def test_definition_without_needed_fields(tmp_path):
    text = "std_msgs/Header header\nfloat64 x\n"
    ts = _custom_imu_store(text)
    T = ts.types
    p = tmp_path / "odd.bag"

    def make(ts, i):
        hdr = T["std_msgs/msg/Header"](i, T["builtin_interfaces/msg/Time"](1, i), "f")
        return T["sensor_msgs/msg/Imu"](hdr, 1.0)

    _write_custom_imu_bag(p, ts, make)
    with pytest.raises(InputError) as e:
        read_rosbag(p)
    check_error(e, p, "'/imu'", "angular_velocity")


def test_nonstandard_but_compatible_definition_is_decoded_by_the_library(tmp_path):
    """An Imu with an extra field: the fixed-offset decoder must not be used; values still right."""
    text = ("std_msgs/Header header\nuint8 quality\ngeometry_msgs/Vector3 angular_velocity\n"
            "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
            "float64[9] linear_acceleration_covariance\n")
    ts = _custom_imu_store(text)
    T = ts.types
    V = T["geometry_msgs/msg/Vector3"]
    p = tmp_path / "extra.bag"

    def make(ts, i):
        hdr = T["std_msgs/msg/Header"](i, T["builtin_interfaces/msg/Time"](100 + i, 7), "imu")
        cov = np.zeros(9)
        cov[0] = -1.0
        return T["sensor_msgs/msg/Imu"](hdr, 3, V(i, 2.0, 3.0), cov, V(4.0, 5.0, -i), np.zeros(9))

    _write_custom_imu_bag(p, ts, make)
    lc = read_rosbag(p)
    imu = lc.imu["/imu"]
    np.testing.assert_array_equal(imu.stamp_ns, (100 + np.arange(5)) * 10**9 + 7)
    np.testing.assert_array_equal(imu.gyro[:, 0], np.arange(5))
    np.testing.assert_array_equal(imu.accel[:, 2], -np.arange(5))
    np.testing.assert_array_equal(imu.gyro_cov0, -1.0)
    assert len(lc.warnings) == 1 and "differs from the standard" in lc.warnings[0]


def test_ros2_bag_without_stored_definitions_uses_the_standard_ones(logs, tmp_path, rec):
    """ROS 2 Foxy/Galactic bags store no message definitions."""
    d = tmp_path / "bag"
    shutil.copytree(logs["ros2-sqlite3"], d)
    con = sqlite3.connect(d / "bag.db3")
    con.execute("DELETE FROM message_definitions")
    con.commit()
    con.close()
    lc = read_rosbag(d)
    np.testing.assert_array_equal(lc.imu["/imu/data"].accel, rec.imu.accel)


def test_undecodable_message_names_topic_and_index(tmp_path, monkeypatch):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    stamps = np.arange(1, 4, dtype=np.int64) * 10**9
    good = rw.encode_imu(stamps, np.zeros((3, 3)), np.zeros((3, 3)), encoding="ros1")
    p = tmp_path / "short.bag"
    with Writer(p) as w:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=get_typestore(Stores.ROS1_NOETIC))
        for i, payload in enumerate(good):
            w.write(c, int(stamps[i]), payload if i != 2 else payload[:40])
    for bulk in (True, False):
        if not bulk:
            monkeypatch.setattr(rosbag, "_bulk_decoder", lambda: None)
        with pytest.raises(InputError) as e:
            read_rosbag(p)
        check_error(e, p, "/imu", "2")


def test_definition_hash_mismatch(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    msgdef, _ = get_typestore(Stores.ROS1_NOETIC).generate_msgdef("sensor_msgs/msg/Imu")
    p = tmp_path / "md5.bag"
    with Writer(p) as w:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", msgdef=msgdef, md5sum="0" * 32)
        w.write(c, 1, rw.encode_imu(np.array([1]), np.zeros((1, 3)), np.zeros((1, 3)), encoding="ros1")[0])
    with pytest.raises(InputError) as e:
        read_rosbag(p)
    check_error(e, p, "message definitions", "hash mismatch")


# --------------------------------------------------------------------------- navpp's ROS 1 index reader


def _rewritten_ros1(src: Path, dst: Path, order, *, chunk_bytes: int = 6_000, compression: str | None = None,
                    second_callerid: bool = False) -> None:
    """``src``'s messages written again by rosbags' writer in the order ``order(messages)`` gives
    (lists of (topic, msgtype, log ns, payload)); with ``second_callerid`` the IMU messages
    alternate between two connections of the topic."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([src]) as r:
        msgs = [(c.topic, c.msgtype, t, bytes(d)) for c, t, d in r.messages()]
        defs = {c.topic: (c.msgdef.data, c.digest) for c in r.connections}
    store = get_typestore(Stores.ROS1_NOETIC)
    w = Writer(dst)
    w.chunk_threshold = chunk_bytes
    if compression:
        w.set_compression(getattr(Writer.CompressionFormat, compression))
    with w:
        conns = {}
        for topic, msgtype, _, _ in msgs:
            ids = [topic, topic + "#2"] if second_callerid and topic == "/imu/data" else [topic]
            for key in ids:
                if key not in conns:
                    msgdef, md5 = defs[topic]
                    conns[key] = w.add_connection(topic, msgtype, typestore=store, msgdef=msgdef, md5sum=md5,
                                                  callerid=key)
        for k, (topic, _, t, data) in enumerate(order(msgs)):
            key = topic + "#2" if second_callerid and topic == "/imu/data" and k % 2 else topic
            w.write(conns[key], t, data)


def _blocks_swapped(msgs):
    """Blocks of 300 messages, each pair of blocks written in reverse: the log time goes back
    across chunks (some messages get the time of their neighbour, for ties across chunks)."""
    out = []
    for a in range(0, len(msgs), 600):
        out += msgs[a + 300:a + 600] + msgs[a:a + 300]
    return [(tp, ty, t - (t % 20_000_000) if i % 7 == 0 else t, d) for i, (tp, ty, t, d) in enumerate(out)]


@pytest.mark.parametrize("compression", [None, "LZ4", "BZ2"])
@pytest.mark.parametrize("order", ["as recorded", "back across chunks"])
def test_ros1_index_path_orders_like_anyreader(logs, tmp_path, monkeypatch, order, compression):
    """Messages in AnyReader's order -- by log time, ties by connection, chunk and entry -- also when
    the log time goes back across chunks and a topic has two connections; read by navpp's index
    reader (no warning), not by rosbags' slower one."""
    path = tmp_path / "odd.bag"
    _rewritten_ros1(logs["ros1"], path, (lambda m: m) if order == "as recorded" else _blocks_swapped,
                    compression=compression, second_callerid=True)
    fast = read_rosbag(path)
    assert fast.warnings == ()
    assert list_topics(path) == _rosbags_topics([path])
    monkeypatch.setattr(rosbag, "_FAST_ROS1", False)
    assert_same_contents(fast, read_rosbag(path))


def test_ros1_index_path_left_with_a_note(logs, tmp_path, monkeypatch):
    """A bag navpp's index reader does not take (here: an index entry pointing at a connection
    record, which rosbags skips) is read by rosbags' reader, and a warning says so and why."""
    from navpp.io import ros1index

    real = ros1index.BagIndex.entries

    def shifted(self, record, chunk):
        t_ns, offset = real(self, record, chunk)
        return t_ns, np.where(offset == offset.min(), 0, offset) if chunk is self.chunks[0] else offset

    monkeypatch.setattr(ros1index.BagIndex, "entries", shifted)
    lc = read_rosbag(logs["ros1"])
    (note,) = lc.warnings
    assert note.startswith(f"{logs['ros1']}: chunk at byte ") and "rosbags' reader instead" in note
    monkeypatch.undo()
    assert_same_contents(lc, read_rosbag(logs["ros1"]))


@pytest.mark.parametrize("where", ["index_pos", "chunk_info", "index_data", "chunk_data"])
def test_damaged_ros1_index_gives_one_line(logs, tmp_path, where):
    """Damage in the bag header, the chunk infos, an index-data record or a chunk: one InputError
    line naming the file (rosbags' reader reports it), or the messages read as rosbags reads them."""
    from navpp.io import ros1index

    data = bytearray(logs["ros1-lz4"].read_bytes())
    with ros1index.read_index(logs["ros1-lz4"]) as index:
        chunk = index.chunks[1]
        at = {"index_pos": data.index(b"index_pos=") + 10, "chunk_info": len(data) - 30,
              "index_data": chunk.records[0].pos + 2, "chunk_data": chunk.data_pos + 40}[where]
    data[at:at + 4] = b"\xff\xfe\xfd\xfc"
    path = tmp_path / "bad.bag"
    path.write_bytes(bytes(data))
    try:
        lc = read_rosbag(path)
    except InputError as exc:
        text = str(exc)
        assert text.startswith(str(path)) and "\n" not in text and "Traceback" not in text
    else:
        assert lc.imu["/imu/data"].gyro.shape[0] > 0


def test_ros1_bags_read_without_rosbags_reader(logs, rec, monkeypatch):
    """Reading and listing a ROS 1 bag do not open rosbags' Reader (whose index holds an object
    per message): navpp's index reader does it all."""
    from rosbags.rosbag1 import Reader

    def refused(self):
        raise AssertionError("rosbags' ROS 1 Reader opened")

    monkeypatch.setattr(Reader, "open", refused)
    assert_matches_recording(read_rosbag(logs["ros1-lz4"]), rec, ros1=True)
    assert [t.topic for t in list_topics(logs["ros1"])] == ["/gnss/fix", "/gnss/vel", "/imu/data", "/reference/fix"]


def test_ros1_record_lengths_are_bounded(logs, monkeypatch):
    """A record header or record data longer than such a record holds (a damaged length in a
    large bag would otherwise be read whole, up to 4 GiB) is refused by the index reader with
    its position, and the bag is read by rosbags' reader with that warning."""
    from navpp.io import ros1index

    monkeypatch.setattr(ros1index, "MAX_HEADER_BYTES", 16)
    lc = read_rosbag(logs["ros1"])
    (note,) = lc.warnings
    assert "more than such a record holds (16 at most)" in note and "rosbags' reader instead" in note
    monkeypatch.undo()
    assert_same_contents(lc, read_rosbag(logs["ros1"]))


def test_ros1_chunk_inflates_no_further_than_its_header_says(logs, tmp_path):
    """A chunk whose header states fewer uncompressed bytes than its data hold is decompressed
    only one byte past that size (damaged or crafted data cannot make it inflate further), and
    refused with both figures; rosbags' reader then reports or reads the bag."""
    from navpp.io import ros1index

    data = bytearray(logs["ros1-lz4"].read_bytes())
    at = data.index(b"size=") + 5                      # the first chunk's header
    size = int.from_bytes(data[at:at + 4], "little")
    data[at:at + 4] = (size - 1000).to_bytes(4, "little")
    path = tmp_path / "small.bag"
    path.write_bytes(bytes(data))
    with ros1index.read_index(path) as index, pytest.raises(ros1index.Ros1IndexError) as err:
        index.chunk_data(index.chunks[0])
    assert f"{size - 999} bytes uncompressed, its header says {size - 1000}" in str(err.value)


def test_ros1_chunk_given_twice_is_refused(logs, monkeypatch):
    """Two chunk infos naming the same chunk (its messages would be read twice) are refused by
    the index reader with the index's position; rosbags' reader then reads the bag."""
    from navpp.io import ros1index

    real = ros1index._chunk_info
    first: list = []

    def repeated(f, size):
        info = real(f, size)
        first.append(first[0] if first else info)
        return first[-1]

    monkeypatch.setattr(ros1index, "_chunk_info", repeated)
    lc = read_rosbag(logs["ros1"])
    (note,) = lc.warnings
    assert "gives a chunk position twice" in note and "rosbags' reader instead" in note
    monkeypatch.undo()
    assert_same_contents(lc, read_rosbag(logs["ros1"]))
