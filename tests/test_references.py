"""References of every kind and --gnss on ROS logs (issue 19, points 3 and 4).

Oracles: the simulator's truth (the session log's reference.csv) written by navpp's own
exporters (``write_tum``, ``write_trajectory_mcap``: :func:`navpp.io.frames.body_to_map`, the
forward direction) and read back through :mod:`navpp.io.refposes` (the inverse); closed-form
poses written with ``rosbags`` (an independent serializer); the CSV log processed with the same
RTKLIB file (byte-identical trajectory).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp.cli import app
from navpp.config import load_config
from navpp.errors import InputError
from navpp.io.csv import read_csv_log
from navpp.reading import read_log
from navpp.recording import Recording, ReferenceData, Solution

runner = CliRunner()
M_PER_DEG = 111_000.0   # metres per degree of latitude, near enough for a tolerance


def invoke(*args: str | Path):
    return runner.invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def truth_solution(rec: Recording) -> Solution:
    ref = rec.reference
    assert ref is not None and ref.rph_deg is not None and ref.vel_enu is not None
    return Solution(ref.t, ref.lat_deg, ref.lon_deg, ref.alt, ref.vel_enu, ref.rph_deg,
                    np.zeros((len(ref), 3)), t0_ns=rec.t0_ns)


def assert_same_reference(got: ReferenceData, want: ReferenceData, pos_m: float, att_deg: float) -> None:
    assert got.t.shape == want.t.shape
    np.testing.assert_allclose(got.t, want.t, atol=1e-6)
    coslat = np.cos(np.radians(want.lat_deg))
    assert np.abs(got.lat_deg - want.lat_deg).max() * M_PER_DEG < pos_m
    assert (np.abs(got.lon_deg - want.lon_deg) * coslat).max() * M_PER_DEG < pos_m
    assert np.abs(got.alt - want.alt).max() < pos_m
    assert got.rph_deg is not None and want.rph_deg is not None
    d = got.rph_deg - want.rph_deg
    d[:, 2] = (d[:, 2] + 180.0) % 360.0 - 180.0
    assert np.abs(d).max() < att_deg


@pytest.fixture(scope="module")
def rec(sim_log_dir: Path) -> Recording:
    return read_csv_log(sim_log_dir)


# --------------------------------------------------------------------------- TUM


def test_navpps_own_tum_reads_back_as_the_reference(sim_log_dir: Path, rec: Recording, tmp_path: Path) -> None:
    from navpp.io.exports import write_tum

    tum = tmp_path / "truth.tum"
    write_tum(tum, truth_solution(rec), rec)
    got = read_log(sim_log_dir, load_config(sim_log_dir / "navpp.toml"), reference=tum)
    assert got.reference is not None and rec.reference is not None
    # 4 decimals of metres and 9 of the quaternion in the file
    assert_same_reference(got.reference, rec.reference, pos_m=1e-4, att_deg=1e-5)
    note = next(n for n in got.notes if n.startswith("reference:"))
    assert f"file {tum} (TUM" in note and "(its header)" in note and "anchored at lat 4" in note


def test_tum_needs_an_anchor_and_takes_one_given(sim_log_dir: Path, rec: Recording, tmp_path: Path) -> None:
    from navpp.io.exports import write_tum
    from navpp.io.frames import anchor_for

    tum = tmp_path / "truth.tum"
    write_tum(tum, truth_solution(rec), rec)
    bare = tmp_path / "bare.tum"             # evo's and other tools' TUM: no anchor in it
    bare.write_text("".join(line + "\n" for line in tum.read_text().splitlines() if not line.startswith("#")))
    res = invoke("process", sim_log_dir, "--reference", bare, "--out", tmp_path / "o")
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert "no anchor" in flat(res.stderr) and "--reference-anchor" in flat(res.stderr) and str(bare) in res.stderr
    assert not (tmp_path / "o" / "trajectory.csv").exists()
    a = anchor_for(truth_solution(rec), rec)
    got = read_log(sim_log_dir, load_config(sim_log_dir / "navpp.toml"), reference=bare,
                   reference_anchor=f"{a.lat_deg!r},{a.lon_deg!r},{a.alt!r}")
    assert got.reference is not None and rec.reference is not None
    assert_same_reference(got.reference, rec.reference, pos_m=1e-4, att_deg=1e-5)
    assert any("(--reference-anchor)" in n for n in got.notes)


@pytest.mark.parametrize(("edit", "expect"), [
    (lambda rows: rows[:5] + [rows[5].replace(rows[5].split()[2], "nan", 1)] + rows[6:], "line 11"),
    (lambda rows: [f"{float(r.split()[0]) + 1e6:.6f} " + r.split(" ", 1)[1] for r in rows], "no pose inside"),
    (lambda rows: rows[:3] + rows[2:], "line 9"),
])
def test_bad_tum_one_line_exit_1(sim_log_dir: Path, rec: Recording, tmp_path: Path, edit, expect) -> None:
    from navpp.io.exports import write_tum

    tum = tmp_path / "truth.tum"
    write_tum(tum, truth_solution(rec), rec)
    lines = tum.read_text().splitlines()
    head = [line for line in lines if line.startswith("#")]
    tum.write_text("\n".join(head + edit([line for line in lines if not line.startswith("#")])) + "\n")
    res = invoke("process", sim_log_dir, "--reference", tum, "--out", tmp_path / "o")
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert expect in flat(res.stderr) and str(tum) in res.stderr
    assert len(res.stderr.strip().splitlines()) >= 1 and not (tmp_path / "o" / "trajectory.csv").exists()


def test_anchor_without_a_local_frame_reference_is_refused(sim_log_dir: Path, tmp_path: Path) -> None:
    res = invoke("process", sim_log_dir, "--reference-anchor", "45,7,300", "--out", tmp_path / "o")
    assert res.exit_code != 0 and "--reference-anchor" in flat(res.stderr) and "Traceback" not in res.output


# --------------------------------------------------------------------------- compare --reference-anchor


def _bare_tum(rec: Recording, tmp_path: Path) -> tuple[Path, str]:
    """The truth as a TUM file without navpp's anchor comment, and that anchor as LAT,LON,ALT."""
    from navpp.io.exports import write_tum
    from navpp.io.frames import anchor_for

    tum = tmp_path / "truth.tum"
    write_tum(tum, truth_solution(rec), rec)
    bare = tmp_path / "bare.tum"
    bare.write_text("".join(line + "\n" for line in tum.read_text().splitlines() if not line.startswith("#")))
    a = anchor_for(truth_solution(rec), rec)
    return bare, f"{a.lat_deg!r},{a.lon_deg!r},{a.alt!r}"


def test_compare_takes_a_reference_anchor(sim_log_dir: Path, rec: Recording, tmp_path: Path) -> None:
    """Oracle: the same truth given as reference.csv (geodetic, no anchor needed)."""
    from navpp.comparison import compare

    bare, anchor = _bare_tum(rec, tmp_path)
    (csv_row,) = compare([sim_log_dir], ["ekf"], report=False).rows
    (tum_row,) = compare([sim_log_dir], ["ekf"], reference=bare, reference_anchor=anchor, report=False).rows
    assert csv_row.status == tum_row.status == "ok" and str(bare) in tum_row.reference
    for axis in ("horizontal", "up", "3d"):
        assert tum_row.metrics["position_m"][axis]["rmse"] == pytest.approx(
            csv_row.metrics["position_m"][axis]["rmse"], abs=2e-4), axis     # the TUM file rounds to 0.1 mm
    (no_anchor,) = compare([sim_log_dir], ["ekf"], reference=bare, report=False).rows
    assert "no anchor" in no_anchor.status and "--reference-anchor" in no_anchor.status


@pytest.mark.parametrize("bad", ["45,x,300", "95,7,300", "45,7"])
def test_compare_refuses_a_bad_anchor_as_process_does(sim_log_dir: Path, rec: Recording, tmp_path: Path,
                                                      bad: str) -> None:
    bare, _ = _bare_tum(rec, tmp_path)
    runs = [invoke(cmd, sim_log_dir, "--reference", bare, "--reference-anchor", bad, "--out", tmp_path / cmd,
                   *(["--filters", "ekf"] if cmd == "compare" else [])) for cmd in ("process", "compare")]
    for res in runs:
        assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    process_line, compare_line = (res.stderr.strip().splitlines()[-1] for res in runs)
    assert compare_line == process_line and f"--reference-anchor: {bad!r}" in compare_line
    assert not (tmp_path / "compare").exists()


def test_compare_cli_passes_the_anchor_on(sim_log_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import navpp.comparison as cmp
    from navpp.errors import ConfigError

    seen = {}

    def fake(logs, filters, **kw):
        seen.update(kw)
        raise ConfigError("stop here")

    monkeypatch.setattr(cmp, "compare", fake)
    res = invoke("compare", sim_log_dir, "--filters", "ekf", "--reference-anchor", "45,7,300", "--out", tmp_path / "o")
    assert res.exit_code == 1 and "stop here" in res.stderr and seen["reference_anchor"] == "45,7,300"


# --------------------------------------------------------------------------- ROS topics


def test_navpps_own_odometry_topic_reads_back_as_the_reference(sim_log_dir: Path, rec: Recording,
                                                               tmp_path: Path) -> None:
    from navpp.io.mcap_out import write_trajectory_mcap

    out = tmp_path / "trajectory.mcap"
    write_trajectory_mcap(out, solution=truth_solution(rec), recording=rec, embed_input=True)
    cfg = load_config(sim_log_dir / "navpp.toml")
    got = read_log(out, cfg, gnss_topic="/gnss/fix", reference_topic="/navpp/odometry")
    assert got.reference is not None and rec.reference is not None
    assert_same_reference(got.reference, rec.reference, pos_m=1e-6, att_deg=1e-8)
    assert got.reference.vel_enu is not None and rec.reference.vel_enu is not None
    np.testing.assert_allclose(got.reference.vel_enu, rec.reference.vel_enu, atol=1e-9)
    note = next(n for n in got.notes if n.startswith("reference:"))
    assert "topic /navpp/odometry (Odometry, frame 'map'" in note and "MCAP's navpp map anchor" in note
    assert got.odometry is None                         # the reference is not taken as wheel odometry


def _write_pose_bag(path: Path, ros1: bool, msgtype: str, poses: list[tuple[int, tuple, tuple]],
                    frame: str = "map") -> None:
    """A bag holding one pose topic ``/ref`` written with rosbags' own serializer."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    t = store.types
    name = {"geometry_msgs/PoseStamped": "geometry_msgs/msg/PoseStamped",
            "nav_msgs/Odometry": "nav_msgs/msg/Odometry"}[msgtype]
    if ros1:
        from rosbags.rosbag1 import Writer
    else:
        from rosbags.rosbag2 import Writer  # type: ignore[assignment]
    writer = Writer(path) if ros1 else Writer(path, version=9)
    with writer:
        conn = writer.add_connection("/ref", name, typestore=store)
        for seq, (ns, xyz, q) in enumerate(poses):
            stamp = t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            header = (t["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame) if ros1
                      else t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame))
            pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
                                               orientation=t["geometry_msgs/msg/Quaternion"](
                                                   x=q[0], y=q[1], z=q[2], w=q[3]))
            if msgtype == "geometry_msgs/PoseStamped":
                msg = t[name](header=header, pose=pose)
            else:
                v3 = t["geometry_msgs/msg/Vector3"]
                msg = t[name](header=header, child_frame_id="base_link",
                              pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                              twist=t["geometry_msgs/msg/TwistWithCovariance"](
                                  twist=t["geometry_msgs/msg/Twist"](linear=v3(x=2.0, y=0.0, z=0.0),
                                                                     angular=v3(x=0.0, y=0.0, z=0.0)),
                                  covariance=np.zeros(36)))
            data = store.serialize_ros1(msg, name) if ros1 else store.serialize_cdr(msg, name)
            writer.write(conn, ns, bytes(data))


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
@pytest.mark.parametrize("msgtype", ["geometry_msgs/PoseStamped", "nav_msgs/Odometry"])
def test_pose_topics_of_bags_closed_form(tmp_path: Path, ros1: bool, msgtype: str) -> None:
    """At the anchor, identity orientation = body x east = heading 90 deg; a yaw of +90 deg about
    up = heading 0 (north); 1000 m north of the anchor: the latitude of that arc (exact ECEF)."""
    from navpp import geodesy
    from navpp.io.frames import Anchor
    from navpp.io.refposes import read_pose_topic, reference_from_poses

    s = np.sqrt(0.5)
    t0 = 1_700_000_000 * 10**9
    poses = [(t0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), (t0 + 10**8, (0.0, 1000.0, 0.0), (0.0, 0.0, s, s)),
             (t0 + 2 * 10**8, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, -1.0))]
    path = tmp_path / ("ref.bag" if ros1 else "ref_bag")
    _write_pose_bag(path, ros1, msgtype, poses)
    track, anchor = read_pose_topic("ros1" if ros1 else "ros2", path, "/ref", msgtype)
    assert anchor is None and track.frame_id == "map" and track.stamp_ns.tolist() == [p[0] for p in poses]
    a = Anchor(45.0, 7.0, 300.0)
    ref = reference_from_poses(track, a, t0, 1.0, "x")
    lat, lon, alt = geodesy.enu_to_geodetic(np.array([0.0, 1000.0, 0.0]), np.radians(45.0), np.radians(7.0), 300.0)
    assert ref.lat_deg[0] == pytest.approx(45.0, abs=1e-12) and ref.lon_deg[0] == pytest.approx(7.0, abs=1e-12)
    assert ref.lat_deg[1] == pytest.approx(np.degrees(lat), abs=1e-12)
    assert ref.lon_deg[1] == pytest.approx(np.degrees(lon), abs=1e-12)
    assert ref.alt[1] == pytest.approx(float(alt), abs=1e-9)
    assert ref.rph_deg is not None
    np.testing.assert_allclose(ref.rph_deg[0], [0.0, 0.0, 90.0], atol=1e-9)
    assert ref.rph_deg[1, 2] == pytest.approx(0.0, abs=1e-3) or ref.rph_deg[1, 2] == pytest.approx(360.0, abs=1e-3)
    np.testing.assert_allclose(ref.rph_deg[2], [0.0, 0.0, 90.0], atol=1e-9)      # -q is the same rotation
    if msgtype == "nav_msgs/Odometry":
        assert ref.vel_enu is not None
        np.testing.assert_allclose(ref.vel_enu[0], [2.0, 0.0, 0.0], atol=1e-9)     # body x = east
        assert ref.vel_enu[1, 1] == pytest.approx(2.0, abs=1e-3)                    # body x = north there
    else:
        assert ref.vel_enu is None


def test_empty_pose_topic_is_one_clear_error(tmp_path: Path) -> None:
    from navpp.io.refposes import read_pose_topic

    path = tmp_path / "empty.bag"
    _write_pose_bag(path, True, "geometry_msgs/PoseStamped", [])
    with pytest.raises(InputError, match=r"topic '/ref': no message"):
        read_pose_topic("ros1", path, "/ref", "geometry_msgs/PoseStamped")


# --------------------------------------------------------------------------- --gnss on ROS logs


def _pos_file(path: Path, rec: Recording) -> None:
    """The log's fixes as an RTKLIB .pos in GPST (unix + 18 s)."""
    import datetime as dt

    g = rec.gnss
    assert g.std_enu is not None
    out = ["% program   : RTKPOST ver.2.4.3 b34",
           "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
           "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio"]
    for k in range(len(g.t)):
        ns = rec.t0_ns + round(float(g.t[k]) * 1e9) + 18 * 10**9
        t = dt.datetime(1970, 1, 1) + dt.timedelta(microseconds=ns // 1000)
        out.append(f"{t.strftime('%Y/%m/%d %H:%M:%S.')}{t.microsecond // 1000:03d} {g.lat_deg[k]:14.9f} "
                   f"{g.lon_deg[k]:14.9f} {g.alt[k]:10.4f}   1  10 {g.std_enu[k, 1]:8.4f} {g.std_enu[k, 0]:8.4f} "
                   f"{g.std_enu[k, 2]:8.4f}   0.0000   0.0000   0.0000   0.00    0.0")
    path.write_text("\n".join(out) + "\n")


@pytest.fixture(scope="module")
def pos_and_csv_run(sim_log_dir: Path, rec: Recording, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, bytes]:
    d = tmp_path_factory.mktemp("pos")
    pos = d / "rover.pos"
    _pos_file(pos, rec)
    res = invoke("process", sim_log_dir, "--gnss", pos, "--out", d / "csv", "--output-rate", "10", "-q")
    assert res.exit_code == 0, res.output
    return pos, (d / "csv" / "trajectory.csv").read_bytes()


@pytest.mark.parametrize("kind", ["mcap", pytest.param("ros1", marks=pytest.mark.slow),
                                  pytest.param("ros2", marks=pytest.mark.slow)])
def test_gnss_file_replaces_a_ros_logs_navsatfix_topic(sim_log_dir: Path, rec: Recording, tmp_path: Path,
                                                      pos_and_csv_run: tuple[Path, bytes], kind: str) -> None:
    from navpp import api
    from navpp.io.roswrite import write_mcap_ros2, write_ros1_bag, write_ros2_bag

    pos, csv_bytes = pos_and_csv_run
    log = tmp_path / {"mcap": "drive.mcap", "ros1": "drive.bag", "ros2": "drive_ros2"}[kind]
    {"mcap": write_mcap_ros2, "ros1": write_ros1_bag, "ros2": write_ros2_bag}[kind](rec, log)
    res = api.process(log, config=sim_log_dir / "navpp.toml", gnss_file=pos, out_dir=tmp_path / "o",
                      output_rate_hz=10)
    assert (tmp_path / "o" / "trajectory.csv").read_bytes() == csv_bytes
    assert f"GNSS: {pos} (RTKLIB, {len(rec.gnss.t):,} fixes), replacing the log's topic /gnss/fix" in res.notes
