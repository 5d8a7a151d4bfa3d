"""navpp.io.mcap_out: ``trajectory.mcap`` read back by three independent readers (the ``mcap``
package's ROS 2 decoder, rosbags with only the schemas the file carries, navpp's own reader);
the oracles are the arrays that were written."""

from __future__ import annotations

import dataclasses
import functools
import os
import types
import warnings
from pathlib import Path

import numpy as np
import pytest

from navpp.io import frames, mcap_out
from navpp.io import roswrite as rw
from navpp.recording import GnssData, ImuData, Recording, Solution

OUTPUT_TOPICS = sorted(mcap_out.TOPICS)


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def processed(sim_log_dir: Path):
    """The session log processed by VCE-CKF (adaptive values) at 10 Hz output."""
    from navpp import api

    return api.process(sim_log_dir, filter_name="vce-ckf", write=False, output_rate_hz=10.0)


def _write(path: Path, res, **kw) -> Path:
    mcap_out.write_trajectory_mcap(path, solution=res.solution, recording=res.recording,
                                   diagnostics=res.run.diagnostics, biases=res.run.biases,
                                   filter_name=res.filter_name, **kw)
    return path


@pytest.fixture(scope="module")
def trajectory(processed, tmp_path_factory) -> Path:
    return _write(tmp_path_factory.mktemp("traj") / "trajectory.mcap", processed)


def _stamp(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _by_topic(path: Path) -> dict[str, list]:
    with warnings.catch_warnings():     # mcap_ros2.reader warns that it imports a deprecated module
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

        out: dict[str, list] = {}
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(m)
    return out


def _raw_messages(path: Path, topics=None) -> dict[str, list]:
    """(schema, channel, message) per topic, in file order, with CRCs checked."""
    from mcap.reader import make_reader

    out: dict[str, list] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f, validate_crcs=True).iter_messages(topics=topics):
            out.setdefault(channel.topic, []).append((schema, channel, message))
    return out


def _expected(res):
    sol, rec = res.solution, res.recording
    anchor = frames.anchor_for(sol, rec)
    return {
        "stamps": rec.t0_ns + np.rint(sol.t * 1e9).astype(np.int64),
        "pos": anchor.enu(sol.lat_deg, sol.lon_deg, sol.alt),
        "quat": frames.quat_xyzw(frames.body_to_map(sol, anchor)),
        "vel_b": frames.velocity_body(sol),
        "anchor": anchor,
    }


# --------------------------------------------------------------------------- readers


def test_read_back_with_mcap_ros2(processed, trajectory):
    res, exp = processed, _expected(processed)
    sol, diag, bias = res.solution, res.run.diagnostics, res.run.biases
    msgs = _by_topic(trajectory)
    assert sorted(msgs) == OUTPUT_TOPICS
    n, m = len(sol), res.run.gnss_epochs
    assert [len(msgs[t]) for t in ("/navpp/fix", "/navpp/odometry", "/tf")] == [n, n, n]
    assert [len(msgs[t]) for t in ("/navpp/bias/gyro", "/navpp/bias/accel", "/navpp/diagnostics")] == [m, m, m]
    assert len(msgs["/tf_static"]) == 1
    for topic, items in msgs.items():
        stamps = np.array([_stamp(x.ros_msg.transforms[0].header if topic.startswith("/tf") else x.ros_msg.header)
                           for x in items])
        assert np.array_equal(stamps, [x.log_time_ns for x in items]), topic
        assert np.array_equal(stamps, [x.publish_time_ns for x in items]), topic
        if topic == "/tf_static":
            continue
        want = exp["stamps"] if len(items) == n else res.recording.t0_ns + np.rint(diag.t * 1e9).astype(np.int64)
        assert np.array_equal(stamps, want), topic

    fix = [x.ros_msg for x in msgs["/navpp/fix"]]
    assert np.array_equal([f.latitude for f in fix], sol.lat_deg)
    assert np.array_equal([f.longitude for f in fix], sol.lon_deg)
    assert np.array_equal([f.altitude for f in fix], sol.alt)
    cov = np.array([f.position_covariance for f in fix])
    assert np.array_equal(cov[:, [0, 4, 8]], sol.std_enu ** 2)
    assert not cov[:, [1, 2, 3, 5, 6, 7]].any()
    assert {f.position_covariance_type for f in fix} == {2}
    assert {(f.status.status, f.status.service, f.header.frame_id) for f in fix} == {(0, 1, "base_link")}

    odo = [x.ros_msg for x in msgs["/navpp/odometry"]]
    assert {(o.header.frame_id, o.child_frame_id) for o in odo} == {("map", "base_link")}
    pos = np.array([[o.pose.pose.position.x, o.pose.pose.position.y, o.pose.pose.position.z] for o in odo])
    q = np.array([[o.pose.pose.orientation.x, o.pose.pose.orientation.y, o.pose.pose.orientation.z,
                   o.pose.pose.orientation.w] for o in odo])
    lin = np.array([[o.twist.twist.linear.x, o.twist.twist.linear.y, o.twist.twist.linear.z] for o in odo])
    ang = np.array([[o.twist.twist.angular.x, o.twist.twist.angular.y, o.twist.twist.angular.z] for o in odo])
    assert np.array_equal(pos, exp["pos"]) and np.array_equal(q, exp["quat"]) and np.array_equal(lin, exp["vel_b"])
    assert np.array_equal(ang, sol.rate_body)       # the body rate (tests/test_outputs_frames.py)
    pcov = np.array([o.pose.covariance for o in odo]).reshape(n, 6, 6)
    tcov = np.array([o.twist.covariance for o in odo]).reshape(n, 6, 6)
    assert np.array_equal(np.diagonal(pcov, axis1=1, axis2=2),
                          np.column_stack([sol.std_enu ** 2, np.square(sol.std_att)]))
    assert np.array_equal(tcov, mcap_out.odometry_covariances(sol, bias, 0.0)[1])
    assert np.count_nonzero(pcov) == 6 * n

    tf = [x.ros_msg.transforms for x in msgs["/tf"]]
    assert {len(t) for t in tf} == {1}
    assert {(t[0].header.frame_id, t[0].child_frame_id) for t in tf} == {("odom", "base_link")}
    tr = np.array([[t[0].transform.translation.x, t[0].transform.translation.y, t[0].transform.translation.z]
                   for t in tf])
    rot = np.array([[t[0].transform.rotation.x, t[0].transform.rotation.y, t[0].transform.rotation.z,
                     t[0].transform.rotation.w] for t in tf])
    assert np.array_equal(tr, exp["pos"]) and np.array_equal(rot, exp["quat"])

    for topic, values in (("/navpp/bias/gyro", bias.gyro), ("/navpp/bias/accel", bias.accel)):
        v = np.array([[x.ros_msg.vector.x, x.ros_msg.vector.y, x.ros_msg.vector.z] for x in msgs[topic]])
        assert np.array_equal(v, values), topic
        assert {x.ros_msg.header.frame_id for x in msgs[topic]} == {"base_link"}

    d = [x.ros_msg for x in msgs["/navpp/diagnostics"]]
    names, values = mcap_out.adaptive_columns(diag)
    assert names and all(list(x.names) == names for x in d)
    assert np.array_equal(np.array([x.values for x in d]), values, equal_nan=True)
    assert np.array_equal(np.array([x.innovation_enu for x in d]), diag.nu, equal_nan=True)
    assert np.array_equal(np.array([x.r_std_enu for x in d]), diag.r_std, equal_nan=True)
    assert np.array_equal(np.array([x.nis for x in d]), diag.nis, equal_nan=True)
    assert np.array_equal([x.accepted for x in d], diag.accepted)
    assert np.array_equal([x.forced for x in d], diag.forced)


def _rosbags_typestore(schemas):
    """A typestore holding only what the file's schemas define."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.EMPTY)
    for schema in schemas:
        assert schema.encoding == "ros2msg"
        ts.register(get_types_from_msg(schema.data.decode("utf-8"), schema.name))
    return ts


def test_read_back_with_rosbags_from_embedded_schemas_only(processed, trajectory):
    from mcap.reader import make_reader

    with open(trajectory, "rb") as f:
        summary = make_reader(f).get_summary()
    ts = _rosbags_typestore(summary.schemas.values())
    raw = _raw_messages(trajectory)
    assert sorted(raw) == OUTPUT_TOPICS
    decoded = {t: [ts.deserialize_cdr(bytes(m.data), s.name) for s, _, m in items] for t, items in raw.items()}
    exp, sol = _expected(processed), processed.solution
    odo = decoded["/navpp/odometry"]
    pos = np.array([[o.pose.pose.position.x, o.pose.pose.position.y, o.pose.pose.position.z] for o in odo])
    q = np.array([[o.pose.pose.orientation.x, o.pose.pose.orientation.y, o.pose.pose.orientation.z,
                   o.pose.pose.orientation.w] for o in odo])
    assert np.array_equal(pos, exp["pos"]) and np.array_equal(q, exp["quat"])
    assert np.array_equal([_stamp(o.header) for o in odo], exp["stamps"])
    fix = decoded["/navpp/fix"]
    assert np.array_equal([f.latitude for f in fix], sol.lat_deg)
    assert np.array_equal(np.array([f.position_covariance for f in fix])[:, [0, 4, 8]], sol.std_enu ** 2)
    tf = decoded["/tf"]
    assert np.array_equal([t.transforms[0].transform.rotation.w for t in tf], exp["quat"][:, 3])
    diag = processed.run.diagnostics
    d = decoded["/navpp/diagnostics"]
    assert np.array_equal(np.array([x.innovation_enu for x in d]), diag.nu, equal_nan=True)
    assert np.array_equal(np.array([x.values for x in d]), mcap_out.adaptive_columns(diag)[1], equal_nan=True)
    g = decoded["/navpp/bias/gyro"]
    assert np.array_equal(np.array([[v.vector.x, v.vector.y, v.vector.z] for v in g]), processed.run.biases.gyro)


def test_schemas_are_complete_and_standard(trajectory):
    """Each schema is a full ``ros2msg`` text, every dependency a ``===`` separated ``MSG:``
    section; the standard ones are the ROS 2 Humble definitions."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    humble = get_typestore(Stores.ROS2_HUMBLE)
    with open(trajectory, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == "ros2"
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    assert {s.name for s in summary.schemas.values()} == set(mcap_out.TOPICS.values())
    for schema in summary.schemas.values():
        text = schema.data.decode("utf-8")
        assert schema.encoding == "ros2msg" and text.strip()
        parsed = get_types_from_msg(text, schema.name)
        deps = sorted(set(parsed) - {schema.name})
        assert deps and "std_msgs/msg/Header" in deps
        sections = [part.split("\n", 1)[0] for part in text.split("=" * 80 + "\n")[1:]]
        assert sorted(sections) == sorted(f"MSG: {d.replace('/msg/', '/')}" for d in deps), schema.name
        for typ, (_, fields) in parsed.items():
            if not typ.startswith("navpp_msgs/"):
                assert fields == humble.fielddefs[typ][1], typ
        _rosbags_typestore([schema])          # registers with nothing else: the text is complete


def test_navpp_reader_reads_fix_as_gnss(processed, trajectory):
    from navpp.io.mcap import read_mcap

    sol = processed.solution
    for engine in ("fast", "library"):
        contents = read_mcap(trajectory, ["/navpp/fix"], engine=engine)
        fix = contents.fix["/navpp/fix"]
        assert np.array_equal(fix.stamp_ns, _expected(processed)["stamps"])
        assert np.array_equal(fix.lat_deg, sol.lat_deg) and np.array_equal(fix.lon_deg, sol.lon_deg)
        assert np.array_equal(fix.alt, sol.alt)
        assert np.array_equal(np.asarray(fix.cov)[:, [0, 4, 8]], sol.std_enu ** 2)
    topics = {t.topic: (t.msgtype, t.count) for t in contents.topics}
    assert topics["/navpp/fix"] == ("sensor_msgs/NavSatFix", len(sol))


def test_log_time_order_summary_and_metadata(processed, trajectory):
    from mcap.reader import make_reader
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    with open(trajectory, "rb") as f:     # front to back, as a streaming reader sees the file
        logs = [r.log_time for r in StreamReader(f, validate_crcs=True).records if isinstance(r, Message)]
    assert len(logs) == 3 * len(processed.solution) + 3 * processed.run.gnss_epochs + 1      # + /tf_static
    assert np.all(np.diff(logs) >= 0)
    with open(trajectory, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary.statistics.message_count == len(logs)
    assert summary.statistics.message_start_time == logs[0] and summary.statistics.message_end_time == logs[-1]
    n, m = len(processed.solution), processed.run.gnss_epochs
    counts = {summary.channels[c].topic: k for c, k in summary.statistics.channel_message_counts.items()}
    assert counts == {"/navpp/fix": n, "/navpp/odometry": n, "/tf": n, "/navpp/bias/gyro": m,
                      "/navpp/bias/accel": m, "/navpp/diagnostics": m, "/tf_static": 1}
    assert summary.statistics.channel_count == len(summary.channels) == 7
    assert summary.statistics.schema_count == len(summary.schemas) == 5      # biases share one, so do the tfs
    assert {(s.name, s.encoding) for s in summary.schemas.values()} == {
        (mcap_out.TOPICS[t], "ros2msg") for t in mcap_out.TOPICS}
    assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
    assert summary.statistics.chunk_count == len(summary.chunk_indexes)
    assert summary.statistics.metadata_count == 1
    with open(trajectory, "rb") as f:
        assert make_reader(f).get_header().profile == "ros2"
    assert summary.chunk_indexes and {c.compression for c in summary.chunk_indexes} == {"zstd"}
    anchor = _expected(processed)["anchor"]
    assert meta["navpp"]["filter"] == "vce-ckf"
    assert float(meta["navpp"]["map_anchor_lat_deg"]) == anchor.lat_deg
    assert float(meta["navpp"]["map_anchor_alt_m"]) == anchor.alt
    assert int(meta["navpp"]["t0_ns"]) == processed.recording.t0_ns


def test_a_fixed_solution_decodes_to_the_expected_messages(tmp_path):
    """Two hand-made rows at the anchor (heading north, then east), decoded with rosbags' Humble
    types from the file alone; the expectation is written out, independent of the writer."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    t0 = 1_700_000_000_000_000_000
    rec = Recording(ImuData(np.arange(3) * 0.5, np.zeros((3, 3)), np.tile([0.0, 0.0, 9.8], (3, 1))),
                    GnssData(np.array([0.5, 1.0]), np.array([45.0, 45.0]), np.array([7.0, 7.0]),
                             np.array([100.0, 100.0])), t0_ns=t0)
    sol = Solution(np.array([0.5, 1.0]), np.array([45.0, 45.0]), np.array([7.0, 7.0]), np.array([100.0, 100.0]),
                   np.array([[0.0, 2.0, 0.0], [3.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 90.0]]),
                   np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]))
    biases = types.SimpleNamespace(t=np.array([1.0]), gyro=np.array([[1e-4, -2e-4, 3e-4]]),
                                   accel=np.array([[0.01, 0.02, -0.03]]))
    diag = types.SimpleNamespace(t=np.array([1.0]), nu=np.array([[0.5, -0.25, 2.0]]), nis=np.array([1.5]),
                                 accepted=np.array([True]), forced=np.array([False]),
                                 r_std=np.array([[1.0, 1.0, 2.0]]), adaptive={"fading": np.array([1.25])})
    path = tmp_path / "fixed.mcap"
    mcap_out.write_trajectory_mcap(path, solution=sol, recording=rec, diagnostics=diag, biases=biases,
                                   filter_name="ekf")
    store = get_typestore(Stores.ROS2_HUMBLE)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_header().profile == "ros2"
        got = [(c.topic, s.name, s.encoding, c.message_encoding, m.log_time, m.publish_time, m.sequence, m.data)
               for s, c, m in reader.iter_messages(log_time_order=False)]
    s1, s2 = t0 + 500_000_000, t0 + 1_000_000_000
    assert got[3][0] == "/tf_static" and (got[3][4], got[3][6]) == (s1, 0)
    got = got[:3] + got[4:]
    assert [g[0] for g in got] == ["/navpp/fix", "/navpp/odometry", "/tf", "/navpp/fix", "/navpp/odometry", "/tf",
                                   "/navpp/bias/gyro", "/navpp/bias/accel", "/navpp/diagnostics"]
    assert [(g[4], g[5], g[6]) for g in got] == [(s1, s1, 0)] * 3 + [(s2, s2, 1)] * 3 + [(s2, s2, 0)] * 3
    assert {(g[2], g[3]) for g in got} == {("ros2msg", "cdr")}
    for g in got:
        if g[0] == "/navpp/diagnostics":
            assert g[1] == "navpp_msgs/msg/FilterDiagnostics"
    msgs = [store.deserialize_cdr(bytes(g[7]), g[1]) if g[0] != "/navpp/diagnostics" else None for g in got]
    half = np.sqrt(0.5)
    for k, (stamp, quat, forward) in enumerate(((s1, [0.0, 0.0, half, half], 2.0), (s2, [0.0, 0.0, 0.0, 1.0], 3.0))):
        fix, odo, tf = msgs[3 * k:3 * k + 3]
        sec, nsec = divmod(stamp, 10**9)
        for m in (fix, odo, tf.transforms[0]):
            assert (m.header.stamp.sec, m.header.stamp.nanosec) == (sec, nsec)
        assert (fix.header.frame_id, fix.status.status, fix.status.service) == ("base_link", 0, 1)
        assert (fix.latitude, fix.longitude, fix.altitude) == (45.0, 7.0, 100.0)
        assert list(fix.position_covariance) == [1.0, 0, 0, 0, 4.0, 0, 0, 0, 9.0]
        assert fix.position_covariance_type == 2
        assert (odo.header.frame_id, odo.child_frame_id) == ("map", "base_link")
        p = odo.pose.pose.position
        assert np.allclose([p.x, p.y, p.z], 0.0, atol=1e-9)
        q = odo.pose.pose.orientation
        assert np.allclose([q.x, q.y, q.z, q.w], quat, atol=1e-12)
        assert np.array_equal(np.diag(odo.pose.covariance.reshape(6, 6)), [1.0, 4.0, 9.0, 1e6, 1e6, 1e6])
        assert np.count_nonzero(odo.pose.covariance) == 6
        assert np.array_equal(np.diag(odo.twist.covariance.reshape(6, 6)), [1e6] * 6)
        v, w = odo.twist.twist.linear, odo.twist.twist.angular
        assert np.allclose([v.x, v.y, v.z], [forward, 0.0, 0.0], atol=1e-12)
        assert (w.x, w.y, w.z) == (0.0, 0.0, 0.0)
        assert len(tf.transforms) == 1
        tr = tf.transforms[0]
        assert (tr.header.frame_id, tr.child_frame_id) == ("odom", "base_link")
        assert np.allclose([tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z],
                           0.0, atol=1e-9)
        r = tr.transform.rotation
        assert (r.x, r.y, r.z, r.w) == (q.x, q.y, q.z, q.w)
    gyro, accel = msgs[6], msgs[7]
    assert (gyro.header.frame_id, gyro.header.stamp.sec, gyro.header.stamp.nanosec) == ("base_link", s2 // 10**9, 0)
    assert (gyro.vector.x, gyro.vector.y, gyro.vector.z) == (1e-4, -2e-4, 3e-4)
    assert (accel.vector.x, accel.vector.y, accel.vector.z) == (0.01, 0.02, -0.03)
    from rosbags.typesys import get_types_from_msg

    store.register(get_types_from_msg(rw.FILTER_DIAGNOSTICS_MSGDEF, "navpp_msgs/msg/FilterDiagnostics"))
    d = store.deserialize_cdr(bytes(got[8][7]), "navpp_msgs/msg/FilterDiagnostics")
    assert (d.header.frame_id, d.header.stamp.sec, d.header.stamp.nanosec) == ("map", s2 // 10**9, 0)
    assert list(d.innovation_enu) == [0.5, -0.25, 2.0] and d.nis == 1.5
    assert (d.accepted, d.forced) == (True, False)
    assert list(d.r_std_enu) == [1.0, 1.0, 2.0]
    assert list(d.names) == ["fading"] and list(d.values) == [1.25]


# --------------------------------------------------------------------------- frames


def test_odometry_at_the_anchor_is_zero_and_quaternion_matches_heading(processed, tmp_path):
    """A solution passing exactly through the anchor (the first GNSS fix in its span) with
    heading 0 (north): position ~0 there and the map rotation is +90 deg about up."""
    rec = processed.recording
    g = rec.gnss
    k = 5
    t = np.array([g.t[k] - 0.1, g.t[k], g.t[k] + 0.1])
    lat = np.array([g.lat_deg[k] - 1e-6, g.lat_deg[k], g.lat_deg[k] + 1e-6])
    lon = np.array([g.lon_deg[k], g.lon_deg[k], g.lon_deg[k] + 1e-6])
    alt = np.array([g.alt[k] + 1.0, g.alt[k], g.alt[k]])
    rph = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [10.0, -5.0, 90.0]])
    vel = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0], [3.0, 0.0, 0.0]])
    sol = Solution(t, lat, lon, alt, vel, rph, np.ones((3, 3)))
    path = tmp_path / "a.mcap"
    mcap_out.write_trajectory_mcap(path, solution=sol, recording=rec)
    odo = [x.ros_msg for x in _by_topic(path)["/navpp/odometry"]]
    p = odo[1].pose.pose.position
    assert abs(p.x) < 1e-6 and abs(p.y) < 1e-6 and abs(p.z) < 1e-6
    assert odo[0].pose.pose.position.y < -0.1 and odo[0].pose.pose.position.z == pytest.approx(1.0, abs=1e-3)
    q = odo[1].pose.pose.orientation
    s = np.sqrt(0.5)
    assert np.allclose([q.x, q.y, q.z, q.w], [0.0, 0.0, s, s], atol=1e-12)
    # heading 90 (east) with roll/pitch, a tiny distance away: the rotation of frames.body_to_map
    q2 = odo[2].pose.pose.orientation
    assert np.array_equal([q2.x, q2.y, q2.z, q2.w], _expected_quat(sol, rec)[2])
    # body velocity: heading north at 2 m/s north -> forward 2 m/s
    v = odo[1].twist.twist.linear
    assert np.allclose([v.x, v.y, v.z], [2.0, 0.0, 0.0], atol=1e-12)
    # no diagnostics / biases given: no such topics
    assert sorted(_by_topic(path)) == ["/navpp/fix", "/navpp/odometry", "/tf", "/tf_static"]


def _expected_quat(sol, rec):
    return frames.quat_xyzw(frames.body_to_map(sol, frames.anchor_for(sol, rec)))


# --------------------------------------------------------------------------- embedded input


def test_embed_csv_input_reads_back_as_the_same_recording(processed, sim_log_dir, tmp_path):
    from navpp.io.assemble import recording_from_log
    from navpp.io.mcap import read_mcap

    path = _write(tmp_path / "trajectory.mcap", processed, embed_input=True, input_log=sim_log_dir)
    contents = read_mcap(path)
    assert {t.topic for t in contents.topics} == set(OUTPUT_TOPICS) | {"/imu/data", "/gnss/fix"}
    back = recording_from_log(contents, imu_topic="/imu/data", gnss_topic="/gnss/fix")
    rec = processed.recording
    assert back.t0_ns == rec.t0_ns
    for name in ("t", "gyro", "accel"):
        assert np.array_equal(getattr(back.imu, name), getattr(rec.imu, name)), name
    for name in ("t", "lat_deg", "lon_deg", "alt", "std_enu"):
        assert np.array_equal(getattr(back.gnss, name), getattr(rec.gnss, name)), name
    assert not back.warnings
    logs = [m.log_time for items in _raw_messages(path).values() for _, _, m in items]
    assert len(logs) == (len(rec.imu) + len(rec.gnss) + 3 * len(processed.solution) + 3 * processed.run.gnss_epochs
                         + 1)


@pytest.fixture(scope="module")
def mcap_input(processed, tmp_path_factory) -> Path:
    """The session recording as a ROS 2 MCAP (lz4, small chunks, log time 1.5 ms after the
    stamp) with a reference NavSatFix topic beside the GNSS one."""
    path = tmp_path_factory.mktemp("in") / "drive.mcap"
    rec = processed.recording
    ref = dataclasses.replace(rec.reference, lat_deg=rec.reference.lat_deg + 1e-7)
    rw.write_mcap_ros2(dataclasses.replace(rec, reference=ref), path, reference_topic="/reference/fix",
                       compression="lz4", chunk_size=100_000, log_offset_ns=1_500_000)
    return path


def test_embed_mcap_input_copies_the_records_exactly(mcap_input, tmp_path):
    from navpp import api
    from navpp.io.assemble import recording_from_log
    from navpp.io.mcap import read_mcap

    res = api.process(mcap_input, write=False, output_rate_hz=5.0, reference_topic="/reference/fix")
    path = _write(tmp_path / "trajectory.mcap", res, embed_input=True, input_log=mcap_input)
    src, out = _raw_messages(mcap_input), _raw_messages(path)
    assert set(out) == set(OUTPUT_TOPICS) | {"/imu/data", "/gnss/fix", "/reference/fix"}   # every input topic
    for topic in ("/imu/data", "/gnss/fix", "/reference/fix"):
        a, b = src[topic], out[topic]
        assert len(a) == len(b) > 0
        assert all(x[2].data == y[2].data for x, y in zip(a, b)), topic
        for field in ("log_time", "publish_time", "sequence"):
            assert [getattr(x[2], field) for x in a] == [getattr(y[2], field) for y in b], (topic, field)
        assert a[0][0].data == b[0][0].data and a[0][0].name == b[0][0].name
        assert a[0][1].metadata == b[0][1].metadata
    assert out["/imu/data"][0][2].log_time != _stamp_of(out["/imu/data"][0])     # copied, not re-encoded
    back = recording_from_log(read_mcap(path), imu_topic="/imu/data", gnss_topic="/gnss/fix")
    for name in ("t", "gyro", "accel"):
        assert np.array_equal(getattr(back.imu, name), getattr(res.recording.imu, name)), name
    for name in ("t", "lat_deg", "lon_deg", "alt", "std_enu"):
        assert np.array_equal(getattr(back.gnss, name), getattr(res.recording.gnss, name)), name


@functools.cache
def _humble():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _stamp_of(item) -> int:
    return _stamp(_humble().deserialize_cdr(bytes(item[2].data), item[0].name).header)


def test_embed_mcap_input_whose_gnss_was_replaced_encodes_the_recordings_gnss(processed, mcap_input, tmp_path):
    """GNSS from elsewhere (e.g. ``--gnss FILE.pos``): every input topic is copied, the recording's
    GNSS encoded beside them (on ``/navpp/input/gnss/fix``: the input has ``/gnss/fix``)."""
    rec = processed.recording
    g = dataclasses.replace(rec.gnss, lat_deg=rec.gnss.lat_deg + 1e-6)
    res = dataclasses.replace(processed, recording=dataclasses.replace(rec, gnss=g))
    path = _write(tmp_path / "trajectory.mcap", res, embed_input=True, input_log=mcap_input)
    out = _raw_messages(path, ["/imu/data", "/gnss/fix", "/navpp/input/gnss/fix"])
    src = _raw_messages(mcap_input, ["/imu/data", "/gnss/fix"])
    for topic in ("/imu/data", "/gnss/fix"):
        assert [x[2].data for x in out[topic]] == [x[2].data for x in src[topic]]
    lat = [_fix_lat(x) for x in out["/navpp/input/gnss/fix"]]
    assert np.array_equal(lat, g.lat_deg)
    assert [x[2].log_time for x in out["/navpp/input/gnss/fix"]] == [_stamp_of(x) for x in out["/navpp/input/gnss/fix"]]


def _fix_lat(item) -> float:
    return _humble().deserialize_cdr(bytes(item[2].data), item[0].name).latitude


# --------------------------------------------------------------------------- container and failures


@pytest.mark.parametrize(("compression", "chunk_size"), [("lz4", 3000), ("none", 50_000), ("zstd", 1 << 30)])
def test_container_variants_read_back(processed, tmp_path, compression, chunk_size):
    from mcap.reader import NonSeekingReader, make_reader

    path = _write(tmp_path / "t.mcap", processed, chunk_size=chunk_size, compression=compression)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        f.seek(0)
        streamed = [(c.topic, m.log_time, m.data)
                    for _, c, m in NonSeekingReader(f, validate_crcs=True).iter_messages()]
        f.seek(0)
        indexed = [(c.topic, m.log_time, m.data) for _, c, m in
                   make_reader(f, validate_crcs=True).iter_messages(log_time_order=True)]
    assert len(streamed) == len(indexed) == 3 * len(processed.solution) + 3 * processed.run.gnss_epochs + 1
    assert [m[1] for m in streamed] == sorted(m[1] for m in streamed)
    for topic in {m[0] for m in streamed}:
        assert [m for m in streamed if m[0] == topic] == [m for m in indexed if m[0] == topic]
    if chunk_size == 3000:
        assert len(summary.chunk_indexes) > 10
    expected = {"lz4": "lz4", "none": "", "zstd": "zstd"}[compression]
    assert {c.compression for c in summary.chunk_indexes} == {expected}


def test_failure_leaves_no_file_and_keeps_an_old_one(processed, tmp_path, monkeypatch):
    path = tmp_path / "trajectory.mcap"
    calls = {"n": 0}
    real = rw.pack_tf_message

    def failing(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 2:          # after some chunks have been written
            raise RuntimeError("injected")
        return real(*args, **kwargs)

    monkeypatch.setattr(rw, "pack_tf_message", failing)
    with pytest.raises(RuntimeError, match="injected"):
        _write_small_chunks(path, processed)
    assert os.listdir(tmp_path) == []
    path.write_bytes(b"old")
    calls["n"] = 0
    with pytest.raises(RuntimeError, match="injected"):
        _write_small_chunks(path, processed)
    assert os.listdir(tmp_path) == ["trajectory.mcap"] and path.read_bytes() == b"old"


def _write_small_chunks(path, res):
    mcap_out.write_trajectory_mcap(path, solution=res.solution, recording=res.recording, chunk_size=10_000)


def test_bad_inputs_are_rejected_before_writing(processed, tmp_path):
    sol, rec = processed.solution, processed.recording
    empty = Solution(sol.t[:0], sol.lat_deg[:0], sol.lon_deg[:0], sol.alt[:0], sol.vel_enu[:0], sol.rph_deg[:0],
                     sol.std_enu[:0])
    with pytest.raises(ValueError, match="empty"):
        mcap_out.write_trajectory_mcap(tmp_path / "a.mcap", solution=empty, recording=rec)
    with pytest.raises(ValueError, match="t0_ns"):
        mcap_out.write_trajectory_mcap(tmp_path / "a.mcap", solution=dataclasses.replace(sol, t0_ns=5),
                                       recording=rec)
    with pytest.raises(ValueError, match="ROS time"):
        mcap_out.write_trajectory_mcap(tmp_path / "a.mcap", solution=dataclasses.replace(sol, t0_ns=-10**12),
                                       recording=dataclasses.replace(rec, t0_ns=-10**12))
    with pytest.raises(ValueError, match="compression"):
        mcap_out.write_trajectory_mcap(tmp_path / "a.mcap", solution=sol, recording=rec, compression="bz2")
    assert os.listdir(tmp_path) == []


# --------------------------------------------------------------------------- bulk packers


def _header(T, encoding, stamp, frame, seq=0):
    sec, nsec = divmod(int(stamp), 10**9)
    t = T["builtin_interfaces/msg/Time"](sec, nsec)
    return T["std_msgs/msg/Header"](t, frame) if encoding == "cdr" else T["std_msgs/msg/Header"](seq, t, frame)


@pytest.mark.parametrize("encoding", ["cdr", "ros1"])
@pytest.mark.parametrize("frame", ["map", "", "ab", "é"])
def test_packers_match_rosbags_serializer(encoding, frame):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE if encoding == "cdr" else Stores.ROS1_NOETIC)
    diag_type = get_types_from_msg(rw.FILTER_DIAGNOSTICS_MSGDEF, rw.FILTER_DIAGNOSTICS_TYPE)
    ts.register({rw.FILTER_DIAGNOSTICS_TYPE: diag_type[rw.FILTER_DIAGNOSTICS_TYPE]})  # the store's own Header
    if "tf2_msgs/msg/TFMessage" not in ts.types:      # not in rosbags' ROS 1 store: its one-line definition
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    ser = ts.serialize_cdr if encoding == "cdr" else ts.serialize_ros1
    rng = np.random.default_rng(4)
    stamps = np.array([1_700_000_000_123_456_789, 7], dtype=np.int64)
    a = rng.standard_normal((2, 12)) * 1e3
    a[1, :3] = [np.nan, -0.0, np.inf]
    child = frame[::-1] + "x"
    def V(v):
        return T["geometry_msgs/msg/Vector3"](*v)
    def Q(v):
        return T["geometry_msgs/msg/Quaternion"](*v)
    pose_var = np.abs(a[:, 6:12])
    twist_var = np.arange(6.0)
    odo = rw.pack_odometry(stamps, a[:, :3], a[:, 3:7], a[:, 7:10], a[:, [10, 11, 0]], encoding=encoding,
                           frame_id=frame, child_frame_id=child, pose_var=pose_var, twist_var=twist_var)
    tf = rw.pack_tf_message(stamps, a[:, :3], a[:, 3:7], encoding=encoding, frame_id=frame, child_frame_id=child)
    vec = rw.pack_vector3_stamped(stamps, a[:, 4:7], encoding=encoding, frame_id=frame)
    names = ["q_factor", "", "weights_1"]
    diag = rw.pack_filter_diagnostics(stamps, a[:, :3], a[:, 3], [True, False], [False, True], a[:, 4:7], names,
                                      a[:, 7:10], encoding=encoding, frame_id=frame)
    for i in range(2):
        h = _header(T, encoding, stamps[i], frame, i)
        pc = np.zeros(36)
        pc[[0, 7, 14, 21, 28, 35]] = pose_var[i]
        tc = np.zeros(36)
        tc[[0, 7, 14, 21, 28, 35]] = twist_var
        msg = T["nav_msgs/msg/Odometry"](
            h, child,
            T["geometry_msgs/msg/PoseWithCovariance"](T["geometry_msgs/msg/Pose"](
                T["geometry_msgs/msg/Point"](*a[i, :3]), Q(a[i, 3:7])), pc),
            T["geometry_msgs/msg/TwistWithCovariance"](T["geometry_msgs/msg/Twist"](
                V(a[i, 7:10]), V(a[i, [10, 11, 0]])), tc))
        assert bytes(ser(msg, "nav_msgs/msg/Odometry")) == odo[i].tobytes()
        ts_msg = T["geometry_msgs/msg/TransformStamped"](
            _header(T, encoding, stamps[i], frame, i), child,
            T["geometry_msgs/msg/Transform"](V(a[i, :3]), Q(a[i, 3:7])))
        assert bytes(ser(T["tf2_msgs/msg/TFMessage"]([ts_msg]), "tf2_msgs/msg/TFMessage")) == tf[i].tobytes()
        msg = T["geometry_msgs/msg/Vector3Stamped"](h, V(a[i, 4:7]))
        assert bytes(ser(msg, "geometry_msgs/msg/Vector3Stamped")) == vec[i].tobytes()
        msg = T[rw.FILTER_DIAGNOSTICS_TYPE](h, a[i, :3].copy(), a[i, 3], bool(i == 0), bool(i == 1), a[i, 4:7].copy(),
                                            names, a[i, 7:10].copy())
        assert bytes(ser(msg, rw.FILTER_DIAGNOSTICS_TYPE)) == diag[i].tobytes()
    assert rw.payload_bytes(vec) == [vec[0].tobytes(), vec[1].tobytes()]


def test_diagnostics_without_adaptive_values_and_multi_column_names(processed, tmp_path):
    """Empty name list (EKF), a single value (AUKF's fading) and a (M, k) entry (named ``key_<i>``
    as in diagnostics.csv)."""
    diag = processed.run.diagnostics
    m = len(diag.t)
    for adaptive, names in (({}, []), ({"fading": np.linspace(1.0, 2.0, m)}, ["fading"]),
                            ({"weights": np.arange(3.0 * m).reshape(m, 3), "fading": np.ones((m, 1))},
                             ["weights_0", "weights_1", "weights_2", "fading"])):
        d = dataclasses.replace(diag, adaptive=adaptive)
        path = tmp_path / f"d{len(names)}.mcap"
        mcap_out.write_trajectory_mcap(path, solution=processed.solution, recording=processed.recording,
                                       diagnostics=d)
        msgs = [x.ros_msg for x in _by_topic(path)["/navpp/diagnostics"]]
        assert len(msgs) == m and all(list(x.names) == names for x in msgs)
        assert np.array_equal(np.array([list(x.values) for x in msgs], dtype=float), mcap_out.adaptive_columns(d)[1])


def test_message_indexes_point_at_their_messages(trajectory):
    """Chunk and Message Index records, which the ``mcap`` readers do not check: every entry
    names a Message record of its channel and log time, and every message is indexed once."""
    import io
    import struct

    from mcap.data_stream import ReadDataStream
    from mcap.reader import make_reader
    from mcap.records import Chunk, MessageIndex

    with open(trajectory, "rb") as f:
        summary = make_reader(f).get_summary()
        data = f.seek(0) or f.read()
    total = 0
    for ci in summary.chunk_indexes:
        assert data[ci.chunk_start_offset] == 0x06
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[ci.chunk_start_offset + 9:
                                                          ci.chunk_start_offset + ci.chunk_length])))
        records = np.frombuffer(_decompressed(chunk), dtype=np.uint8)
        assert records.size == ci.uncompressed_size == chunk.uncompressed_size
        first = min(ci.message_index_offsets.values())
        assert first == ci.chunk_start_offset + ci.chunk_length
        assert sum(struct.unpack_from("<Q", data, o + 1)[0] + 9 for o in ci.message_index_offsets.values()) \
            == ci.message_index_length
        seen = 0
        for cid, off in ci.message_index_offsets.items():
            assert data[off] == 0x07
            (length,) = struct.unpack_from("<Q", data, off + 1)
            index = MessageIndex.read(ReadDataStream(io.BytesIO(data[off + 9:off + 9 + length])))
            assert index.channel_id == cid
            for log_time, rec in index.records:
                assert records[rec] == 0x05
                assert struct.unpack_from("<HIQ", records, rec + 9)[::2] == (cid, log_time)
                assert ci.message_start_time <= log_time <= ci.message_end_time
            seen += len(index.records)
        n = 0
        pos = 0
        while pos < records.size:
            n += records[pos] == 0x05
            pos += 9 + struct.unpack_from("<Q", records, pos + 1)[0]
        assert seen == n
        total += n
    assert total == summary.statistics.message_count


def _decompressed(chunk) -> bytes:
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk.data)
    assert chunk.compression == ""
    return chunk.data


@pytest.mark.parametrize("kind", ["mcap", "ros2", "none"])
def test_embedded_gnss_velocity_is_copied_or_encoded(processed, tmp_path, kind):
    """GNSS velocity goes with the GNSS: copied from an MCAP input, encoded otherwise."""
    from navpp.io.assemble import recording_from_log
    from navpp.io.mcap import read_mcap

    rec = processed.recording
    m = len(rec.gnss)
    vel = np.column_stack([np.linspace(-3.0, 3.0, m), np.sin(np.arange(m)), np.full(m, 0.01)])
    rec = dataclasses.replace(rec, gnss=dataclasses.replace(rec.gnss, vel_enu=vel, std_vel_enu=np.full((m, 3), 0.1)))
    log = None
    if kind == "mcap":
        log = tmp_path / "in.mcap"
        rw.write_mcap_ros2(rec, log, gnss_vel_topic="/ins/gnss_vel")
    elif kind == "ros2":
        log = tmp_path / "bag"
        rw.write_ros2_bag(rec, log, gnss_vel_topic="/ins/gnss_vel")
    path = tmp_path / "trajectory.mcap"
    mcap_out.write_trajectory_mcap(path, solution=processed.solution, recording=rec, embed_input=True,
                                   input_log=log)
    contents = read_mcap(path)
    vel_topic = "/gnss/vel" if kind == "none" else "/ins/gnss_vel"
    assert {t.topic for t in contents.topics} == {"/imu/data", "/gnss/fix", vel_topic, *mcap_out.TOPICS} - {
        "/navpp/bias/gyro", "/navpp/bias/accel", "/navpp/diagnostics"}
    back = recording_from_log(contents, imu_topic="/imu/data", gnss_topic="/gnss/fix")
    assert np.array_equal(back.gnss.vel_enu, vel)
    assert np.array_equal(back.gnss.std_vel_enu, rec.gnss.std_vel_enu)
    if kind == "mcap":
        src = _raw_messages(log, [vel_topic])[vel_topic]   # (a ROS 2 bag: tests/test_embed_inputs.py)
        assert [x[2].data for x in _raw_messages(path, [vel_topic])[vel_topic]] == [x[2].data for x in src]


def test_embed_from_a_cut_off_mcap_input(processed, tmp_path):
    """A recording cut off mid-chunk: navpp reads what is there; the embedded input holds the
    same messages (what cannot be copied whole is encoded from the Recording)."""
    from navpp import api
    from navpp.io.assemble import recording_from_log
    from navpp.io.mcap import read_mcap

    full = tmp_path / "full.mcap"     # lz4: navpp's reader decodes the whole messages of the cut chunk
    rw.write_mcap_ros2(processed.recording, full, chunk_size=200_000, compression="lz4", log_offset_ns=1000)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.6)])
    res = api.process(cut, write=False, output_rate_hz=5.0)
    assert any("cut off" in w for w in res.recording.warnings)
    path = _write(tmp_path / "trajectory.mcap", res, embed_input=True, input_log=cut)
    back = recording_from_log(read_mcap(path), imu_topic="/imu/data", gnss_topic="/gnss/fix")
    for name in ("t", "gyro", "accel"):
        assert np.array_equal(getattr(back.imu, name), getattr(res.recording.imu, name)), name
    assert np.array_equal(back.gnss.lat_deg, res.recording.gnss.lat_deg)
    imu = _raw_messages(path, ["/imu/data"])["/imu/data"]
    assert imu[0][2].log_time == _stamp_of(imu[0])          # encoded: log time = stamp (the input's is +1 us)
