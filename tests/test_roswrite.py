"""navpp.io.roswrite: bulk serialisation against the libraries' encoders, schema texts, the
MCAP writer (read back with mcap / mcap_ros2), atomic replacement of files and directories."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from navpp.io import roswrite as rw
from navpp.recording import GnssData, ImuData, Recording, ReferenceData

FRAMES = ["imu_link", "", "a", "ab", "abc", "gnss_antenna_1", "é"]
T0_NS = 1_700_000_000_123_456_789


def small_recording(n_imu: int = 250, n_gnss: int = 11, *, with_vel: bool = True, with_std: bool = True,
                    with_ref: bool = True, t0_ns: int = T0_NS) -> Recording:
    """A hand-made recording with awkward values (negative, tiny, huge, irrational)."""
    rng = np.random.default_rng(7)
    t = np.arange(n_imu) / 125.0
    gyro = rng.standard_normal((n_imu, 3)) * np.array([1e-3, 1.0, 1e3])
    accel = rng.standard_normal((n_imu, 3)) + np.array([0.0, 0.0, 9.80665])
    tg = np.arange(n_gnss) / 5.0 + 0.0004  # not on the IMU grid
    lat = 45.0 + rng.standard_normal(n_gnss) * 1e-5
    lon = -122.0 + rng.standard_normal(n_gnss) * 1e-5
    alt = 30.0 + rng.standard_normal(n_gnss)
    std = np.abs(rng.standard_normal((n_gnss, 3))) + 0.5 if with_std else None
    vel = rng.standard_normal((n_gnss, 3)) if with_vel else None
    svel = np.full((n_gnss, 3), 0.05) if with_vel else None
    ref = None
    if with_ref:
        tr = np.arange(2 * n_gnss) / 10.0
        ref = ReferenceData(tr, 45.0 + tr * 1e-6, -122.0 + tr * 1e-6, 30.0 + tr)
    return Recording(ImuData(t, gyro, accel), GnssData(tg, lat, lon, alt, std_enu=std, vel_enu=vel, std_vel_enu=svel),
                     t0_ns=t0_ns, reference=ref)


# --------------------------------------------------------------------------- serialisation


def _typestore(encoding: str):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE if encoding == "cdr" else Stores.ROS1_NOETIC)


def _library_messages(encoding: str, frame: str, stamps, g, a):
    """The same messages built as rosbags objects and serialised by rosbags."""
    ts = _typestore(encoding)
    T = ts.types
    ser = ts.serialize_cdr if encoding == "cdr" else ts.serialize_ros1
    V = T["geometry_msgs/msg/Vector3"]

    def header(i):
        sec, nsec = divmod(int(stamps[i]), 10**9)
        stamp = T["builtin_interfaces/msg/Time"](sec, nsec)
        header = T["std_msgs/msg/Header"]
        return header(stamp, frame) if encoding == "cdr" else header(i, stamp, frame)

    out = {"imu": [], "fix": [], "twistcov": [], "twist": []}
    for i in range(len(stamps)):
        oc = np.zeros(9)
        oc[0] = -1.0
        gc = np.zeros(9)
        gc[[0, 4, 8]] = 2.5e-7
        ac = np.zeros(9)
        ac[[0, 4, 8]] = 1e-4
        imu = T["sensor_msgs/msg/Imu"](header(i), T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0), oc,
                                       V(*g[i]), gc, V(*a[i]), ac)
        out["imu"].append(bytes(ser(imu, "sensor_msgs/msg/Imu")))
        pc = np.zeros(9)
        pc[[0, 4, 8]] = a[i] ** 2
        fix = T["sensor_msgs/msg/NavSatFix"](header(i), T["sensor_msgs/msg/NavSatStatus"](0, 1), g[i, 0], g[i, 1],
                                             g[i, 2], pc, 2)
        out["fix"].append(bytes(ser(fix, "sensor_msgs/msg/NavSatFix")))
        tc = np.zeros(36)
        tc[[0, 7, 14]] = a[i] ** 2
        twist = T["geometry_msgs/msg/Twist"](V(*g[i]), V(0.0, 0.0, 0.0))
        out["twistcov"].append(bytes(ser(T["geometry_msgs/msg/TwistWithCovarianceStamped"](
            header(i), T["geometry_msgs/msg/TwistWithCovariance"](twist, tc)),
            "geometry_msgs/msg/TwistWithCovarianceStamped")))
        out["twist"].append(bytes(ser(T["geometry_msgs/msg/TwistStamped"](header(i), twist),
                                      "geometry_msgs/msg/TwistStamped")))
    return out


def _bulk_messages(encoding: str, frame: str, stamps, g, a):
    return {
        "imu": rw.encode_imu(stamps, g, a, encoding=encoding, frame_id=frame, gyro_var=2.5e-7, accel_var=1e-4),
        "fix": rw.encode_navsatfix(stamps, g[:, 0], g[:, 1], g[:, 2], encoding=encoding, frame_id=frame,
                                   cov_diag=a**2),
        "twistcov": rw.encode_twist_with_covariance(stamps, g, encoding=encoding, frame_id=frame, cov_diag=a**2),
        "twist": rw.encode_twist(stamps, g, encoding=encoding, frame_id=frame),
    }


@pytest.mark.parametrize("encoding", ["cdr", "ros1"])
@pytest.mark.parametrize("frame", FRAMES)
def test_bulk_encoders_match_rosbags_serializer(encoding, frame):
    rng = np.random.default_rng(1)
    stamps = np.array([T0_NS, 5, 2**31 * 10**9 - 1], dtype=np.int64)
    g = rng.standard_normal((3, 3)) * 1e3
    g[1] = [np.nan, np.inf, -0.0]
    a = rng.standard_normal((3, 3))
    lib = _library_messages(encoding, frame, stamps, g, a)
    bulk = _bulk_messages(encoding, frame, stamps, g, a)
    for kind in lib:
        assert bulk[kind] == lib[kind], kind


@pytest.mark.parametrize("frame", ["imu_link", "", "abc"])
def test_bulk_cdr_matches_mcap_ros2_encoder(frame):
    from mcap_ros2._dynamic import serialize_dynamic

    stamps = np.array([T0_NS, T0_NS + 8_000_000], dtype=np.int64)
    g = np.array([[0.1, -0.2, 0.3], [1e-9, 2.0, -3e5]])
    a = g[::-1].copy()
    enc = serialize_dynamic("sensor_msgs/msg/Imu", rw.IMU_MSGDEF)["sensor_msgs/msg/Imu"]
    payloads = rw.encode_imu(stamps, g, a, encoding="cdr", frame_id=frame)
    for i in range(2):
        sec, nsec = divmod(int(stamps[i]), 10**9)
        msg = {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame},
               "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
               "orientation_covariance": [-1.0] + [0.0] * 8,
               "angular_velocity": dict(zip("xyz", g[i].tolist())), "angular_velocity_covariance": [0.0] * 9,
               "linear_acceleration": dict(zip("xyz", a[i].tolist())),
               "linear_acceleration_covariance": [0.0] * 9}
        assert bytes(enc(msg)) == payloads[i]
    enc = serialize_dynamic("sensor_msgs/msg/NavSatFix", rw.NAVSATFIX_MSGDEF)["sensor_msgs/msg/NavSatFix"]
    payloads = rw.encode_navsatfix(stamps, g[:, 0], g[:, 1], g[:, 2], encoding="cdr", frame_id=frame)
    sec, nsec = divmod(int(stamps[0]), 10**9)
    msg = {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame},
           "status": {"status": 0, "service": 1}, "latitude": g[0, 0], "longitude": g[0, 1], "altitude": g[0, 2],
           "position_covariance": [0.0] * 9, "position_covariance_type": 0}
    assert bytes(enc(msg)) == payloads[0]


@pytest.mark.parametrize("name", sorted(set(rw.MSGDEFS) - {rw.FILTER_DIAGNOSTICS_TYPE}))
def test_schema_texts_parse_to_the_standard_definitions(name):
    from rosbags.typesys import get_types_from_msg

    std = _typestore("cdr")
    parsed = get_types_from_msg(rw.MSGDEFS[name], name)
    assert name in parsed
    for typ, (_, fields) in parsed.items():
        assert fields == std.fielddefs[typ][1], typ


def test_stamps_are_integer_ns_and_exact():
    rec = small_recording(t0_ns=T0_NS)
    s = rw.stamps_ns(rec, rec.imu.t)
    assert s.dtype == np.int64
    assert s[0] == T0_NS and s[1] == T0_NS + 8_000_000 and s[-1] == T0_NS + 249 * 8_000_000


def test_stamp_outside_ros_time_is_rejected():
    with pytest.raises(ValueError, match="ROS time"):
        rw.encode_imu(np.array([-1], dtype=np.int64), np.zeros((1, 3)), np.zeros((1, 3)), encoding="cdr")
    with pytest.raises(ValueError, match="integer"):
        rw.encode_imu(np.array([1.5]), np.zeros((1, 3)), np.zeros((1, 3)), encoding="cdr")


# --------------------------------------------------------------------------- MCAP writer


@pytest.mark.parametrize("compression,chunk_size", [("zstd", 1 << 20), ("lz4", 4096), ("none", 1 << 20), ("none", 0)])
def test_mcap_read_back_with_mcap_ros2(tmp_path, compression, chunk_size):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    def read_ros2_messages(path, topics):
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            return [(m, ros) for _, _, m, ros in reader.iter_decoded_messages(topics=topics, log_time_order=False)]

    rec = small_recording()
    path = tmp_path / "log.mcap"
    rw.write_mcap_ros2(rec, path, reference_topic="/reference/fix", compression=compression, chunk_size=chunk_size,
                       log_offset_ns=1234)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts == {"/imu/data": 250, "/gnss/fix": 11, "/gnss/vel": 11, "/reference/fix": 22}
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    assert (len(summary.chunk_indexes) > 0) == (chunk_size > 0)
    if chunk_size:
        assert {c.compression for c in summary.chunk_indexes} == {"" if compression == "none" else compression}

    msgs = read_ros2_messages(path, ["/imu/data"])
    stamps = rw.stamps_ns(rec, rec.imu.t)
    got = np.array([r.header.stamp.sec * 10**9 + r.header.stamp.nanosec for _, r in msgs])
    np.testing.assert_array_equal(got, stamps)
    np.testing.assert_array_equal([m.log_time for m, _ in msgs], stamps + 1234)
    gyro = np.array([[r.angular_velocity.x, r.angular_velocity.y, r.angular_velocity.z] for _, r in msgs])
    np.testing.assert_array_equal(gyro, rec.imu.gyro)
    assert msgs[0][1].header.frame_id == "imu_link"
    assert msgs[0][1].orientation_covariance[0] == -1.0
    fix = read_ros2_messages(path, ["/gnss/fix"])[3][1]
    assert fix.position_covariance_type == 2
    assert fix.position_covariance[4] == rec.gnss.std_enu[3, 1] ** 2
    assert fix.status.status == 0 and fix.status.service == 1


def test_mcap_messages_are_in_log_time_order(tmp_path):
    from mcap.reader import make_reader

    rec = small_recording()
    path = tmp_path / "log.mcap"
    rw.write_mcap_ros2(rec, path, chunk_size=2000)
    with open(path, "rb") as f:
        times = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert times == sorted(times) and len(times) == 250 + 11 + 11


def test_time_range_and_optional_topics(tmp_path):
    from mcap.reader import make_reader

    rec = small_recording(with_vel=False, with_std=False)
    path = tmp_path / "part.mcap"
    rw.write_mcap_ros2(rec, path, time_range=(0.5, 1.0), reference_topic="/ref")
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts == {"/imu/data": int(np.sum((rec.imu.t >= 0.5) & (rec.imu.t < 1.0))),
                      "/gnss/fix": int(np.sum((rec.gnss.t >= 0.5) & (rec.gnss.t < 1.0))),
                      "/ref": int(np.sum((rec.reference.t >= 0.5) & (rec.reference.t < 1.0)))}


def test_bad_options_are_rejected(tmp_path):
    rec = small_recording()
    with pytest.raises(ValueError, match="compression"):
        rw.write_mcap_ros2(rec, tmp_path / "x.mcap", compression="gzip")
    with pytest.raises(ValueError, match="compression"):
        rw.write_ros1_bag(rec, tmp_path / "x.bag", compression="zstd")
    with pytest.raises(ValueError, match="storage"):
        rw.write_ros2_bag(rec, tmp_path / "x", storage="leveldb")
    with pytest.raises(ValueError, match="mcap"):
        rw.write_ros2_bag(rec, tmp_path / "x", compression="storage")
    with pytest.raises(ValueError, match="differ"):
        rw.write_mcap_ros2(rec, tmp_path / "x.mcap", gnss_topic="/imu/data")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- atomic output


def test_files_and_directories_are_replaced_atomically(tmp_path):
    rec = small_recording()
    for writer, name in ((rw.write_mcap_ros2, "log.mcap"), (rw.write_ros1_bag, "log.bag"),
                         (rw.write_ros2_bag, "bag2")):
        target = tmp_path / name
        writer(rec, target)
        first = _snapshot(target)
        writer(rec, target, imu_topic="/imu/other")  # replaces
        assert _snapshot(target) != first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag2", "log.bag", "log.mcap"]
    assert sorted(p.name for p in (tmp_path / "bag2").iterdir()) == ["bag2.db3", "metadata.yaml"]


def _snapshot(target: Path) -> dict[str, bytes]:
    if target.is_dir():
        return {p.name: p.read_bytes() for p in sorted(target.iterdir())}
    return {target.name: target.read_bytes()}


@pytest.mark.parametrize("kind", ["mcap", "ros1", "ros2"])
def test_failed_write_leaves_the_old_output_and_no_temporary(tmp_path, monkeypatch, kind):
    rec = small_recording()
    writer, name = {"mcap": (rw.write_mcap_ros2, "log.mcap"), "ros1": (rw.write_ros1_bag, "log.bag"),
                    "ros2": (rw.write_ros2_bag, "bag2")}[kind]
    target = tmp_path / name
    writer(rec, target)
    before = _snapshot(target)

    calls = {"n": 0}

    def failing_add(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 100:
            raise OSError("disk full")
        return original(*args, **kwargs)

    if kind == "mcap":
        import mcap.writer

        cls = mcap.writer.Writer
        original = cls.add_message
        monkeypatch.setattr(cls, "add_message", failing_add)
    else:
        import rosbags.rosbag1
        import rosbags.rosbag2

        cls = rosbags.rosbag1.Writer if kind == "ros1" else rosbags.rosbag2.Writer
        original = cls.write
        monkeypatch.setattr(cls, "write", failing_add)
    with pytest.raises(OSError, match="disk full"):
        writer(rec, target, imu_topic="/other")
    assert _snapshot(target) == before
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_new_file_gets_default_permissions(tmp_path):
    rec = small_recording()
    rw.write_ros1_bag(rec, tmp_path / "a.bag")
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "a.bag").stat().st_mode & 0o777 == 0o666 & ~umask
