"""Issue 19 points 5 and 6: the MCAP's covariances, body rate and tf tree read back with
mcap_ros2 and rosbags; reference.tum against an evo-style APE; the labelled TUM name; the
Foxglove layout against the MCAP it is for."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from navpp.engine.output import body_rate
from navpp.ins.attitude import quat_to_dcm, rph_to_dcm, rpy_deg_to_dcm
from navpp.io import exports, foxglove, mcap_out


@pytest.fixture(scope="module")
def run(sim_log_dir: Path, tmp_path_factory):
    """The session log by the EKF at 10 Hz (the reference's grid), MCAP + TUM + CSV written."""
    from navpp import api

    out = tmp_path_factory.mktemp("s19out")
    res = api.process(sim_log_dir, filter_name="vce-ckf", output_rate_hz=10.0, formats=["csv", "mcap", "tum"],
                      out_dir=out)
    return res, out


@pytest.fixture(scope="module")
def decoded(run) -> dict[str, list]:
    """trajectory.mcap of ``run`` decoded once with mcap_ros2, by topic."""
    return _decoded(run[1] / "trajectory.mcap")


def _decoded(path: Path) -> dict[str, list]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

        out: dict[str, list] = {}
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(m.ros_msg)
    return out


def test_odometry_covariances_and_rate_come_from_the_filter(run, decoded):
    """Pose: position = the CSV's sigmas squared, orientation = the solution's attitude sigmas;
    twist: the ENU velocity sigmas rotated into base_link (rotated back: the solution's), the
    body rate = the solution's; every 6x6 block symmetric positive definite."""
    import pandas as pd

    res, out = run
    sol = res.solution
    odo = decoded["/navpp/odometry"]
    n = len(sol)
    assert len(odo) == n and sol.std_att is not None and sol.std_vel_enu is not None and sol.rate_body is not None
    pcov = np.array([o.pose.covariance for o in odo]).reshape(n, 6, 6)
    tcov = np.array([o.twist.covariance for o in odo]).reshape(n, 6, 6)
    for c in (pcov, tcov):
        assert np.allclose(c, np.swapaxes(c, 1, 2), rtol=0, atol=1e-15)
        assert np.linalg.eigvalsh(c).min() > 0.0
    csv = pd.read_csv(out / "trajectory.csv")
    # the CSV rounds sigmas to 1e-4 m
    assert np.abs(np.sqrt(np.diagonal(pcov[:, :3, :3], axis1=1, axis2=2))
                  - csv[["std_e", "std_n", "std_u"]].to_numpy()).max() <= 0.5e-4 + 1e-9
    assert np.allclose(np.diagonal(pcov[:, 3:, 3:], axis1=1, axis2=2), np.square(sol.std_att), rtol=1e-12, atol=0)
    assert (np.diagonal(pcov[:, 3:, 3:], axis1=1, axis2=2) < mcap_out.NOT_ESTIMATED_VARIANCE).all()
    rph = np.radians(np.asarray(sol.rph_deg))
    c_nb = rph_to_dcm(rph[:, 0], rph[:, 1], rph[:, 2])
    back = np.einsum("nij,njk,nlk->nil", c_nb, tcov[:, :3, :3], c_nb)      # base_link -> ENU
    assert np.allclose(back, np.einsum("ni,ij->nij", np.square(sol.std_vel_enu), np.eye(3)), rtol=1e-9,
                       atol=1e-15)
    ang = np.array([[o.twist.twist.angular.x, o.twist.twist.angular.y, o.twist.twist.angular.z] for o in odo])
    assert np.array_equal(ang, np.asarray(sol.rate_body))
    assert np.abs(ang[:, 2]).max() > 0.05        # the simulated drive turns: a rate is there


def test_tf_tree_is_connected_and_static_frames_read_back_with_rosbags(run, decoded):
    """/tf_static (decoded with rosbags from the file's own schema) holds map -> odom,
    base_link -> imu_link (the mounting) and base_link -> gnss (the lever arm); /tf odom ->
    base_link; every frame reaches map."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    res, out = run
    path = out / "trajectory.mcap"
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        ts = get_typestore(Stores.EMPTY)
        for s in summary.schemas.values():
            ts.register(get_types_from_msg(s.data.decode("utf-8"), s.name))
        static = [ts.deserialize_cdr(bytes(m.data), s.name)
                  for s, _, m in reader.iter_messages(topics=["/tf_static"])]
    assert len(static) == 1
    parent = {t.child_frame_id: (t.header.frame_id, t.transform) for t in static[0].transforms}
    assert {k: v[0] for k, v in parent.items()} == {"odom": "map", "imu_link": "base_link", "gnss": "base_link"}
    lever = parent["gnss"][1].translation
    assert [lever.x, lever.y, lever.z] == list(res.config.gnss.lever_arm_m)
    r = parent["imu_link"][1].rotation
    assert np.allclose(quat_to_dcm(np.array([r.w, r.x, r.y, r.z])), rpy_deg_to_dcm(res.config.imu.mounting_rpy_deg),
                       atol=1e-12)
    tf = decoded["/tf"]
    assert {(m.transforms[0].header.frame_id, m.transforms[0].child_frame_id) for m in tf} == {("odom", "base_link")}
    links = {k: v[0] for k, v in parent.items()} | {"base_link": "odom"}
    for frame in ("imu_link", "gnss", "base_link", "odom"):
        seen = [frame]
        while seen[-1] in links:
            seen.append(links[seen[-1]])
        assert seen[-1] == "map"


def test_static_mounting_rotation_is_written_as_given(tmp_path, run):
    """A mounting of (0, 0, 90) deg: imu_link's x is base_link's y."""
    res, _ = run
    path = tmp_path / "t.mcap"
    sol = exports._subset(res.solution, np.arange(3))
    mcap_out.write_trajectory_mcap(path, solution=sol, recording=res.recording,
                                   imu_mounting_rpy_deg=(0.0, 0.0, 90.0))
    (st,) = _decoded(path)["/tf_static"]
    r = {t.child_frame_id: t.transform.rotation for t in st.transforms}["imu_link"]
    m = quat_to_dcm(np.array([r.w, r.x, r.y, r.z]))
    assert np.allclose(m @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


def test_body_rate_closed_form():
    """gyro = C_bn (w_ie + w_en) + bias + w_true  ->  body_rate returns w_true."""
    rng = np.random.default_rng(1)
    n = 50
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lat, h = np.radians(45.0) + rng.normal(0, 0.01, n), 300.0 + rng.normal(0, 5, n)
    vel = rng.normal(0, 10, (n, 3))
    path = np.column_stack([q, vel, lat, np.zeros(n), h])
    t = np.arange(n) * 0.1
    bias_t, bias = np.array([1.0, 3.0]), rng.normal(0, 1e-3, (2, 3))
    bias0 = rng.normal(0, 1e-3, 3)
    w_true = rng.normal(0, 0.3, (n, 3))
    from navpp.geodesy import OMEGA_E, radii

    rm, rn = radii(lat)
    w_in = np.column_stack([-vel[:, 1] / (rm + h), OMEGA_E * np.cos(lat) + vel[:, 0] / (rn + h),
                            OMEGA_E * np.sin(lat) + vel[:, 0] * np.tan(lat) / (rn + h)])
    c_nb = np.array([quat_to_dcm(qi) for qi in q])
    b = np.where((t < 1.0)[:, None], bias0, np.where((t < 3.0)[:, None], bias[0], bias[1]))
    gyro = np.einsum("nji,nj->ni", c_nb, w_in) + b + w_true
    assert np.allclose(body_rate(t, path, gyro, bias_t, bias, bias0), w_true, rtol=0, atol=1e-15)


def _tum(path: Path) -> tuple[np.ndarray, list[str]]:
    lines = path.read_text().splitlines()
    return np.array([[float(v) for v in ln.split(" ")] for ln in lines if not ln.startswith("#")]), \
        [ln for ln in lines if ln.startswith("#")]


def test_reference_tum_gives_navpps_3d_rmse_the_way_evo_ape_computes_it(run):
    """An independent evo_ape (translation part, no alignment): each reference.tum stamp paired
    with the nearest trajectory.tum stamp within 0.01 s; the RMSE of the position differences
    equals metrics.json's 3-D RMSE to the files' 0.1 mm (the output rows fall on the
    reference's 10 Hz grid); both files name the same anchor."""
    res, out = run
    ref, ref_head = _tum(out / "reference.tum")
    est, est_head = _tum(out / "trajectory.tum")
    anchor = [h for h in ref_head if h.startswith("# x y z")]
    assert anchor and anchor == [h for h in est_head if h.startswith("# x y z")]
    k = np.clip(np.searchsorted(est[:, 0], ref[:, 0]), 1, len(est) - 1)
    k = np.where(np.abs(est[k - 1, 0] - ref[:, 0]) <= np.abs(est[k, 0] - ref[:, 0]), k - 1, k)
    ok = np.abs(est[k, 0] - ref[:, 0]) <= 0.01
    assert ok.all() and len(ref) == res.metrics["epochs"]
    rmse = float(np.sqrt(np.mean(np.sum((est[k, 1:4] - ref[:, 1:4]) ** 2, axis=1))))
    assert abs(rmse - res.metrics["position_m"]["3d"]["rmse"]) < 1e-4
    # the labelled copy is the same file
    name = exports.labelled_tum_name(res.recording.source or "drive", "vce-ckf")
    assert (out / name).read_bytes() == (out / "trajectory.tum").read_bytes()


@pytest.mark.parametrize(("log", "filt", "name"), [
    ("/x/drive.mcap", "ekf", "drive-ekf.tum"), ("/x/my drive.bag", "aekf", "my_drive-aekf.tum"),
    ("rel/log_dir/", "vce-ckf", "log_dir-vce-ckf.tum")])
def test_labelled_tum_name(log, filt, name):
    assert exports.labelled_tum_name(log, filt) == name


def test_foxglove_layout_names_only_what_the_mcap_holds(run, decoded):
    """Every topic the layout plots or shows is in trajectory.mcap; each ``.values[k]`` is
    labelled with the ``names[k]`` of the diagnostics messages; the layout tree names exactly
    the configured panels."""
    _, out = run
    lay = json.loads((out / foxglove.LAYOUT_FILE).read_text())
    msgs = decoded
    names = list(msgs["/navpp/diagnostics"][0].names)
    panels: list[str] = []

    def walk(node):
        if isinstance(node, str):
            panels.append(node)
        else:
            walk(node["first"])
            walk(node["second"])
    walk(lay["layout"])
    assert sorted(panels) == sorted(lay["configById"])
    assert {p.split("!")[0] for p in panels} == {"map", "3D", "Plot"}
    paths = [p for c in lay["configById"].values() for p in c.get("paths", [])]
    for p in paths:
        topic = p["value"].split(".")[0]
        assert topic in msgs
        if ".values[" in p["value"]:
            k = int(p["value"].split("[")[1].rstrip("]"))
            assert p["label"] == names[k]
    assert sum(".values[" in p["value"] for p in paths) == len(names) > 0
    assert lay["configById"]["map!navpp"]["followTopic"] in msgs
    assert set(lay["configById"]["3D!navpp"]["topics"]) <= set(msgs)


# --------------------------------------------------------------------------- --embed-input from ROS 1


def _flat(m, prefix: str = "") -> dict:
    """Every leaf field of a decoded message by its dotted path (constants left out)."""
    out: dict = {}
    names = list(getattr(m, "__dataclass_fields__", None) or getattr(m, "__slots__", ()))
    for k in names:
        if k.startswith("_") or k.isupper():
            continue
        v = getattr(m, k)
        if not isinstance(v, (str, bytes, int, float, list, tuple, np.ndarray)) and (
                hasattr(v, "__dataclass_fields__") or hasattr(v, "__slots__")):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def _path(m, dotted: str):
    for part in dotted.split("."):
        m = getattr(m, part)
    return m


@pytest.fixture(scope="module")
def ros1_bag(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A 5 s ROS 1 bag as a driver writes one: ``/imu`` with an orientation estimate, ``/fix``
    with status GBAS_FIX and covariance type APPROXIMATED, and a ``/chatter`` String topic."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    path = tmp_path_factory.mktemp("ros1") / "drive.bag"
    t0 = 1_700_000_000_000_000_000
    rng = np.random.default_rng(7)
    fixes = []

    def header(seq: int, ns: int, frame: str):
        return T["std_msgs/msg/Header"](seq=seq, stamp=T["builtin_interfaces/msg/Time"](
            sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    def vec(v):
        return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    with Writer(path) as w:
        imu_c = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        fix_c = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        txt_c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        for i in range(500):                           # 100 Hz, at rest
            ns = t0 + i * 10_000_000
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            msg = T["sensor_msgs/msg/Imu"](
                header=header(i, ns, "imu_frame"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
                orientation_covariance=np.arange(9, dtype=float) * 1e-3,
                angular_velocity=vec(rng.normal(0, 1e-3, 3)), angular_velocity_covariance=np.full(9, 2e-6),
                linear_acceleration=vec([0.0, 0.0, 9.81] + rng.normal(0, 1e-2, 3)),
                linear_acceleration_covariance=np.full(9, 3e-4))
            w.write(imu_c, ns + 1_000_000, ts.serialize_ros1(msg, "sensor_msgs/msg/Imu"))
            if i % 20 == 0:
                fns = ns
                fix = T["sensor_msgs/msg/NavSatFix"](
                    header=header(i // 20, fns, "gps"),
                    status=T["sensor_msgs/msg/NavSatStatus"](status=2, service=5),
                    latitude=45.0 + rng.normal(0, 1e-6), longitude=7.0 + rng.normal(0, 1e-6),
                    altitude=300.0 + rng.normal(0, 1.0), position_covariance=np.diag([4.0, 4.5, 9.0]).ravel(),
                    position_covariance_type=1)
                w.write(fix_c, fns + 2_000_000, ts.serialize_ros1(fix, "sensor_msgs/msg/NavSatFix"))
                fixes.append((fns - t0, fix.latitude, fix.longitude, fix.altitude))
            if i % 100 == 0:
                w.write(txt_c, ns, ts.serialize_ros1(T["std_msgs/msg/String"](data=f"hello {i}"),
                                                     "std_msgs/msg/String"))
    return path, np.array(fixes, dtype=float)


def test_embed_ros1_bag_keeps_every_topic_as_it_was(ros1_bag, tmp_path):
    """Oracle: the bag read with rosbags (ROS 1) against the output read with mcap_ros2 from the
    schemas in the file: same topics, types, receive times, message counts and every field
    value (IMU orientation, NavSatFix status and covariance type included); only the ROS 1
    ``header.seq`` has no ROS 2 counterpart."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from navpp.recording import GnssData, ImuData, Recording, Solution

    ros1_bag, fixes = ros1_bag
    t_imu = np.arange(500) * 0.01
    rec = Recording(imu=ImuData(t_imu, np.zeros((500, 3)), np.zeros((500, 3))),     # only its times matter
                    gnss=GnssData(fixes[:, 0] * 1e-9, fixes[:, 1], fixes[:, 2], fixes[:, 3]),
                    t0_ns=1_700_000_000_000_000_000, source=str(ros1_bag))
    t = np.array([1.0, 2.0])
    sol = Solution(t=t, lat_deg=np.full(2, 45.0), lon_deg=np.full(2, 7.0), alt=np.full(2, 300.0),
                   vel_enu=np.zeros((2, 3)), rph_deg=np.zeros((2, 3)), std_enu=np.ones((2, 3)), t0_ns=rec.t0_ns)
    out = tmp_path / "trajectory.mcap"
    mcap_out.write_trajectory_mcap(out, solution=sol, recording=rec, embed_input=True, input_log=ros1_bag)

    want: dict[str, list] = {}
    with AnyReader([ros1_bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        for c, stamp, raw in r.messages():
            want.setdefault(c.topic, []).append((stamp, c.msgtype, r.deserialize(raw, c.msgtype)))
    got: dict[str, list] = {}
    with open(out, "rb") as f:
        for schema, ch, m, ros in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=list(want)):
            got.setdefault(ch.topic, []).append((m.log_time, schema.name, ros))
    assert sorted(want) == sorted(got) == ["/chatter", "/fix", "/imu"]
    for topic, items in want.items():
        assert len(got[topic]) == len(items)
        for (s1, ty1, m1), (s2, ty2, m2) in zip(items, got[topic]):
            assert (s1, ty1) == (s2, ty2)
            fields = {k: v for k, v in _flat(m1).items() if k != "header.seq"}
            for k, v in fields.items():
                assert np.array_equal(np.asarray(v), np.asarray(_path(m2, k))), (topic, k)
    fix = got["/fix"][0][2]
    assert (fix.status.status, fix.status.service, fix.position_covariance_type) == (2, 5, 1)
    assert got["/imu"][0][2].orientation.w != 0.0
