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


def _decoded(path: Path) -> dict[str, list]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

        out: dict[str, list] = {}
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(m.ros_msg)
    return out


def test_odometry_covariances_and_rate_come_from_the_filter(run):
    """Pose: position = the CSV's sigmas squared, orientation = the solution's attitude sigmas;
    twist: the ENU velocity sigmas rotated into base_link (rotated back: the solution's), the
    body rate = the solution's; every 6x6 block symmetric positive definite."""
    import pandas as pd

    res, out = run
    sol = res.solution
    odo = _decoded(out / "trajectory.mcap")["/navpp/odometry"]
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


def test_tf_tree_is_connected_and_static_frames_read_back_with_rosbags(run, sim_log_dir):
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
    tf = _decoded(path)["/tf"]
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
    mcap_out.write_trajectory_mcap(path, solution=res.solution, recording=res.recording,
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


def test_foxglove_layout_names_only_what_the_mcap_holds(run):
    """Every topic the layout plots or shows is in trajectory.mcap; each ``.values[k]`` is
    labelled with the ``names[k]`` of the diagnostics messages; the layout tree names exactly
    the configured panels."""
    _, out = run
    lay = json.loads((out / foxglove.LAYOUT_FILE).read_text())
    msgs = _decoded(out / "trajectory.mcap")
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
