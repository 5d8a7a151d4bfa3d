"""Wheel odometry in ROS logs (issue 18): nav_msgs/Odometry and vehicle-frame Twist topics.

A short simulated drive is written with navpp's own ROS writers (MCAP, ROS 1 bag, ROS 2 bag)
plus a ``/wheel/odom`` nav_msgs/Odometry topic (child frame base_link) and a GNSS velocity
TwistStamped (frame gnss).  The oracle is the arrays written: the odometry read back must be
them (stamps to the ns on the IMU's time base, values bit for bit), the GNSS velocity must still
be the GNSS velocity, and the topic choice must follow --odometry-topic.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp import api
from navpp.cli import app
from navpp.config import load_config
from navpp.inspection import inspect
from navpp.io import roswrite
from navpp.io.detect import choose_odometry_topic, gnss_velocity_topics
from navpp.io.mcap import read_mcap
from navpp.io.ros import ODOM_TYPE, TWIST_TYPE, LogContents, TopicInfo, TwistMessages
from navpp.reading import read_log
from navpp.recording import OdometryData, Recording

ODOM_RATE_HZ = 20.0
KINDS = ("mcap", "ros1", "ros2")


def _odometry(rec: Recording) -> OdometryData:
    """20 Hz odometry over the drive: speed = the reference's horizontal speed, a made-up yaw
    rate, per-sample sigmas (arbitrary values: they only have to come back unchanged)."""
    ref = rec.reference
    assert ref is not None and ref.vel_enu is not None
    t = np.arange(0.013, float(rec.imu.t[-1]) - 0.1, 1.0 / ODOM_RATE_HZ)
    speed = np.interp(t, ref.t, np.hypot(ref.vel_enu[:, 0], ref.vel_enu[:, 1])) * 1.0123 + 1e-3 * np.sin(t)
    yaw = 0.05 * np.sin(0.3 * t)
    return OdometryData(t, speed, yaw, 0.02 + 0.001 * np.cos(t), np.full(t.size, 0.004), source="truth")


@pytest.fixture(scope="module")
def drive() -> Recording:
    from navpp.simulate import SimulationSpec, simulate

    rec = simulate(SimulationSpec(duration_s=40.0, still_s=10.0, seed=5)).recording()
    ref = rec.reference
    assert ref is not None and ref.vel_enu is not None
    vel = np.column_stack([np.interp(rec.gnss.t, ref.t, ref.vel_enu[:, k]) for k in range(3)])
    gnss = replace(rec.gnss, vel_enu=vel, std_vel_enu=np.full(vel.shape, 0.05))
    return replace(rec, gnss=gnss, odometry=_odometry(rec))


def _write_twist_velocity(rec: Recording, path: Path, kind: str) -> None:
    """The log with the GNSS velocity as a TwistStamped (frame gnss) on /gnss/vel: writers write
    TwistWithCovarianceStamped, so the stream list is patched to the plain Twist here."""
    g = rec.gnss
    st = roswrite.stamps_ns(rec, g.t)
    enc = "ros1" if kind == "ros1" else "cdr"
    orig = roswrite._streams

    def streams(r, encoding, opts):
        out = [s for s in orig(r, encoding, opts) if s.topic != "/gnss/vel"]
        out.append(roswrite._Stream("/gnss/vel", roswrite._TWIST_STAMPED, st,
                                    roswrite.encode_twist(st, g.vel_enu, encoding=enc, frame_id="gnss")))
        return out

    roswrite._streams = streams
    try:
        _write(rec, path, kind)
    finally:
        roswrite._streams = orig


def _write(rec: Recording, path: Path, kind: str, **kw) -> None:
    if kind == "mcap":
        roswrite.write_mcap_ros2(rec, path, **kw)
    elif kind == "ros1":
        roswrite.write_ros1_bag(rec, path, **kw)
    else:
        roswrite.write_ros2_bag(rec, path, **kw)


@pytest.fixture(scope="module")
def logs(drive: Recording, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("odomlogs")
    out = {"mcap": d / "drive.mcap", "ros1": d / "drive.bag", "ros2": d / "drive_ros2"}
    for kind, path in out.items():
        _write_twist_velocity(drive, path, kind)
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_odometry_is_read_with_the_written_values_and_stamps(drive, logs, kind):
    rec = read_log(logs[kind], load_config(None))
    od, want = rec.odometry, drive.odometry
    assert od is not None and want is not None
    assert od.source == "/wheel/odom"
    # stamps: integer ns written as t0 + round(t * 1e9); read back on the same t0 (the IMU's)
    assert rec.t0_ns == drive.t0_ns
    want_ns = roswrite.stamps_ns(drive, want.t)
    got_ns = rec.t0_ns + np.rint(od.t * 1e9).astype(np.int64)
    assert np.array_equal(got_ns, want_ns)
    assert np.array_equal(od.speed, want.speed)
    assert np.array_equal(od.yaw_rate, want.yaw_rate)
    assert np.allclose(od.std_speed, want.std_speed, rtol=1e-15, atol=0)
    assert np.allclose(od.std_yaw_rate, want.std_yaw_rate, rtol=1e-15, atol=0)
    # the roles do not collide: the TwistStamped in frame gnss is still the GNSS velocity
    assert rec.gnss.vel_enu is not None
    assert np.array_equal(rec.gnss.vel_enu, drive.gnss.vel_enu)


@pytest.mark.parametrize("kind", KINDS)
def test_odometry_topic_none_and_explicit(logs, kind):
    cfg = load_config(None)
    assert read_log(logs[kind], cfg, odometry_topic="none").odometry is None
    chosen = read_log(logs[kind], cfg, odometry_topic="/wheel/odom")
    assert chosen.odometry is not None and chosen.odometry.source == "/wheel/odom"
    # the GNSS velocity TwistStamped chosen explicitly as odometry: then it is not GNSS velocity
    as_odom = read_log(logs[kind], cfg, odometry_topic="/gnss/vel")
    assert as_odom.odometry is not None and as_odom.gnss.vel_enu is None
    assert any("not in a vehicle frame" in w for w in as_odom.warnings)
    assert not any("vehicle frame" in w for w in chosen.warnings)


def test_inspect_lists_the_odometry_role(logs):
    for kind in KINDS:
        _, rows, _ = inspect(logs[kind])
        roles = {r.name: r.role for r in rows}
        assert roles["/wheel/odom"] == "odometry", kind
        assert roles["/gnss/vel"] == "GNSS velocity", kind


def test_process_notes_and_bad_topic_via_cli(logs, tmp_path):
    res = api.process(logs["mcap"], write=False, output_rate_hz=5.0)
    assert any(n.startswith("odometry: /wheel/odom (") for n in res.notes)
    runner = CliRunner()
    bad = runner.invoke(app, ["process", str(logs["mcap"]), "--odometry-topic", "/no/such", "--out",
                              str(tmp_path / "o")])
    assert bad.exit_code == 1
    text = bad.output.strip()
    assert "'/no/such'" in text and "--odometry-topic" in text and "Traceback" not in text
    assert len(text.splitlines()) == 1
    wrong = runner.invoke(app, ["process", str(logs["ros1"]), "--odometry-topic", "/imu/data", "--out",
                                str(tmp_path / "o2")])
    assert wrong.exit_code == 1 and "not one of" in wrong.output and len(wrong.output.strip().splitlines()) == 1


def test_inspect_cli_shows_odometry(logs):
    out = CliRunner().invoke(app, ["inspect", str(logs["ros2"])])
    assert out.exit_code == 0
    lines = out.output.splitlines()
    assert any("/wheel/odom" in line and "odometry" in line.split("Odometry", 1)[-1] for line in lines)


def test_embedded_input_keeps_the_odometry(drive, logs, tmp_path):
    """--embed-input: the odometry topic is copied from an MCAP input (same bytes), encoded
    from the Recording otherwise; either way it reads back as the recording's odometry."""
    for kind in ("mcap", "ros1"):
        res = api.process(logs[kind], write=True, out_dir=tmp_path / kind, formats=["mcap"], embed_input=True,
                          output_rate_hz=5.0)
        path = tmp_path / kind / "trajectory.mcap"
        back = read_mcap(path, ["/wheel/odom"])
        tw = back.twist["/wheel/odom"]
        od = res.recording.odometry
        assert od is not None
        assert np.array_equal(tw.stamp_ns, roswrite.stamps_ns(res.recording, od.t)), kind
        assert np.array_equal(tw.vel[:, 0], od.speed) and np.array_equal(tw.angular[:, 2], od.yaw_rate), kind
        assert tw.child_frame_id == "base_link", kind
    # copied, not re-encoded: an input whose log times are 1 us after the stamps keeps them
    shifted = tmp_path / "shifted.mcap"
    roswrite.write_mcap_ros2(drive, shifted, log_offset_ns=1000)
    api.process(shifted, write=True, out_dir=tmp_path / "shifted", formats=["mcap"], embed_input=True,
                output_rate_hz=5.0)
    copied = read_mcap(tmp_path / "shifted" / "trajectory.mcap", ["/wheel/odom"]).twist["/wheel/odom"]
    assert np.array_equal(copied.log_ns - copied.stamp_ns, np.full(copied.log_ns.size, 1000))


# --------------------------------------------------------------------------- the choice rules


def _contents(topics: dict[str, tuple[str, str, str, float]]) -> LogContents:
    """A decoded log of velocity topics: name -> (type, frame_id, child_frame_id, rate Hz)."""
    infos, twist = [], {}
    for name, (msgtype, frame, child, rate) in topics.items():
        ns = (np.arange(50) * (1e9 / rate)).astype(np.int64)
        infos.append(TopicInfo(name, msgtype, 50))
        twist[name] = TwistMessages(name, ns, ns, np.zeros((50, 3)), frame_id=frame, child_frame_id=child,
                                    angular=np.zeros((50, 3)))
    return LogContents("log", tuple(infos), twist=twist)


def test_choice_prefers_the_controller_and_skips_fused_and_own_outputs():
    c = _contents({"/husky_velocity_controller/odom": (ODOM_TYPE, "odom", "base_link", 10.0),
                   "/odometry/filtered": (ODOM_TYPE, "odom", "base_link", 30.0),
                   "/navpp/odometry": (ODOM_TYPE, "map", "base_link", 100.0),
                   "/base_vel": (TWIST_TYPE, "base_link", "", 50.0),
                   "/gps/vel": (TWIST_TYPE, "gps", "", 5.0)})
    topic, note = choose_odometry_topic(c, None)
    assert topic == "/husky_velocity_controller/odom" and "10 Hz" in note
    # the vehicle-frame twist is neither odometry (not preferred) nor GNSS velocity
    assert gnss_velocity_topics(c, topic) == ["/gps/vel"]


def test_choice_rejects_wrong_frame_and_rate_and_refuses_to_guess():
    assert choose_odometry_topic(_contents({"/odom": (ODOM_TYPE, "odom", "base_link", 2.0)}), None)[0] is None
    assert choose_odometry_topic(_contents({"/odom": (ODOM_TYPE, "map", "gps", 20.0)}), None)[0] is None
    assert choose_odometry_topic(_contents({"/vel": (TWIST_TYPE, "enu", "", 20.0)}), None)[0] is None
    # an empty child frame with an odom-frame pose is accepted (some controllers leave it empty)
    assert choose_odometry_topic(_contents({"/odom": (ODOM_TYPE, "odom", "", 20.0)}), None)[0] == "/odom"
    two = _contents({"/a/wheel/odom": (ODOM_TYPE, "odom", "base_link", 20.0),
                     "/b/wheel/odom": (ODOM_TYPE, "odom", "base_link", 20.0)})
    topic, note = choose_odometry_topic(two, None)
    assert topic is None and "--odometry-topic" in note
    assert choose_odometry_topic(two, "/b/wheel/odom")[0] == "/b/wheel/odom"


def test_compare_takes_the_odometry_topic_option(logs, tmp_path):
    out = CliRunner().invoke(app, ["compare", str(logs["mcap"]), "--filters", "ekf", "--odometry-topic", "none",
                                   "--out", str(tmp_path / "c"), "--quiet"])
    assert out.exit_code == 0, out.output
    bad = CliRunner().invoke(app, ["compare", str(logs["mcap"]), "--filters", "ekf", "--odometry-topic", "/nope",
                                   "--out", str(tmp_path / "d"), "--quiet"])
    assert bad.exit_code == 1 and "'/nope'" in bad.output


def test_vehicle_frame_twist_is_odometry_and_the_gnss_twist_stays_velocity(drive, tmp_path):
    """Two Twist topics: a TwistStamped in base_link (wheel odometry, 20 Hz) and the writers'
    TwistWithCovarianceStamped in frame gnss (GNSS velocity): each gets its own role."""
    od = drive.odometry
    assert od is not None
    st = roswrite.stamps_ns(drive, od.t)
    vel = np.column_stack([od.speed, np.zeros_like(od.speed), np.zeros_like(od.speed)])
    orig = roswrite._streams

    def streams(r, encoding, opts):
        return [*orig(r, encoding, opts),
                roswrite._Stream("/base/twist", roswrite._TWIST_STAMPED, st,
                                 roswrite.encode_twist(st, vel, encoding=encoding, frame_id="base_link"))]

    path = tmp_path / "twist.mcap"
    roswrite._streams = streams
    try:
        roswrite.write_mcap_ros2(replace(drive, odometry=None), path)
    finally:
        roswrite._streams = orig
    rec = read_log(path, load_config(None))
    assert rec.odometry is not None and rec.odometry.source == "/base/twist"
    assert np.array_equal(rec.odometry.speed, od.speed)
    assert rec.odometry.std_speed is None                   # TwistStamped has no covariance
    assert np.array_equal(rec.gnss.vel_enu, drive.gnss.vel_enu)
    roles = {r.name: r.role for r in inspect(path)[1]}
    assert roles == {"/imu/data": "IMU", "/gnss/fix": "GNSS", "/gnss/vel": "GNSS velocity", "/base/twist": "odometry"}


def test_missing_variances_give_no_std(drive, tmp_path):
    """Twist covariance 0 (unknown) in one message: no std column (the config's sigma applies),
    never a NaN sigma."""
    od = drive.odometry
    assert od is not None
    std = np.array(od.std_speed)
    std[5] = 0.0
    path = tmp_path / "partial.mcap"
    roswrite.write_mcap_ros2(replace(drive, odometry=replace(od, std_speed=std)), path)
    rec = read_log(path, load_config(None))
    assert rec.odometry is not None and rec.odometry.std_speed is None
    assert np.array_equal(rec.odometry.std_yaw_rate, od.std_yaw_rate)
