"""Decoded topics -> Recording: roles, message semantics and validation (synthetic topics
built from a simulated recording, so the expected Recording is known exactly)."""

import numpy as np
import pytest

from navpp.errors import InputError
from navpp.io.assemble import recording_from_log
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    TWIST_COV_TYPE,
    FixMessages,
    ImuMessages,
    LogContents,
    TopicInfo,
    TwistMessages,
)
from navpp.simulate import SimulationSpec, simulate


@pytest.fixture(scope="module")
def rec():
    return simulate(SimulationSpec(duration_s=40.0, still_s=20.0, seed=1, gnss_velocity=True)).recording()


def _imu_msgs(rec, topic="/imu/data", stamps=None):
    ns = rec.t0_ns + np.round(rec.imu.t * 1e9).astype(np.int64) if stamps is None else stamps
    return ImuMessages(topic, ns, ns + 1000, rec.imu.gyro.copy(), rec.imu.accel.copy())


def _fix_msgs(rec, topic="/gnss/fix", status=None, cov_type=2):
    g = rec.gnss
    ns = rec.t0_ns + np.round(g.t * 1e9).astype(np.int64)
    m = len(g)
    cov = np.zeros((m, 9))
    cov[:, [0, 4, 8]] = g.std_enu ** 2
    return FixMessages(topic, ns, ns + 1000, np.zeros(m, np.int8) if status is None else status,
                       g.lat_deg.copy(), g.lon_deg.copy(), g.alt.copy(), cov, np.full(m, cov_type, np.uint8))


def _contents(imus, fixes, twists=()):
    topics = tuple([TopicInfo(m.topic, IMU_TYPE, len(m.stamp_ns)) for m in imus]
                   + [TopicInfo(m.topic, FIX_TYPE, len(m.stamp_ns)) for m in fixes]
                   + [TopicInfo(m.topic, TWIST_COV_TYPE, len(m.stamp_ns)) for m in twists])
    return LogContents("log.mcap", topics, {m.topic: m for m in imus}, {m.topic: m for m in fixes},
                       {m.topic: m for m in twists})


def test_round_trip_is_exact(rec):
    out = recording_from_log(_contents([_imu_msgs(rec)], [_fix_msgs(rec)]))
    assert out.t0_ns == rec.t0_ns
    np.testing.assert_allclose(out.imu.t, rec.imu.t, atol=1e-9)
    np.testing.assert_array_equal(out.imu.gyro, rec.imu.gyro)
    np.testing.assert_array_equal(out.gnss.lat_deg, rec.gnss.lat_deg)
    np.testing.assert_allclose(out.gnss.std_enu, rec.gnss.std_enu, rtol=1e-12)
    assert out.warnings == ()


def test_log_time_is_used_when_asked(rec):
    out = recording_from_log(_contents([_imu_msgs(rec)], [_fix_msgs(rec)]), time_source="log")
    assert out.t0_ns == rec.t0_ns + 1000


def test_several_imu_topics_need_a_choice(rec):
    c = _contents([_imu_msgs(rec, "/a/imu"), _imu_msgs(rec, "/b/imu")], [_fix_msgs(rec)])
    with pytest.raises(InputError, match=r"/a/imu, /b/imu; choose one with --imu-topic"):
        recording_from_log(c)
    out = recording_from_log(c, imu_topic="/b/imu")
    assert len(out.imu) == len(rec.imu)
    with pytest.raises(InputError, match="no topic '/c/imu'"):
        recording_from_log(c, imu_topic="/c/imu")
    with pytest.raises(InputError, match="is sensor_msgs/NavSatFix, not sensor_msgs/Imu"):
        recording_from_log(c, imu_topic="/gnss/fix")


def test_reference_topic_and_gnss_choice(rec):
    c = _contents([_imu_msgs(rec)], [_fix_msgs(rec, "/gnss/fix"), _fix_msgs(rec, "/dgps/fix")])
    with pytest.raises(InputError, match="--gnss-topic"):
        recording_from_log(c)
    out = recording_from_log(c, reference_topic="/dgps/fix")
    assert out.reference is not None and len(out.reference) == len(rec.gnss)
    np.testing.assert_array_equal(out.gnss.lat_deg, rec.gnss.lat_deg)


def test_no_fix_dropped_and_unknown_covariance_uses_default(rec):
    m = len(rec.gnss)
    status = np.zeros(m, np.int8)
    status[3:6] = -1
    out = recording_from_log(_contents([_imu_msgs(rec)], [_fix_msgs(rec, status=status, cov_type=0)]),
                             default_std_m=(3.0, 3.0, 5.0))
    assert len(out.gnss) == m - 3
    np.testing.assert_array_equal(out.gnss.std_enu[0], [3.0, 3.0, 5.0])
    text = " ".join(out.warnings)
    assert "dropped 3 of" in text and "default_std_m" in text


def test_nan_stamps_and_clock_jumps_are_errors_naming_the_message(rec):
    imu = _imu_msgs(rec)
    gyro = imu.gyro.copy()
    gyro[100, 1] = np.nan
    bad = ImuMessages(imu.topic, imu.stamp_ns, imu.log_ns, gyro, imu.accel)
    with pytest.raises(InputError, match=r"topic '/imu/data': message 100 .*angular_velocity"):
        recording_from_log(_contents([bad], [_fix_msgs(rec)]))
    ns = imu.stamp_ns.copy()
    ns[201:] -= 2_000_000_000                   # the clock steps 2 s back: not a reordering
    with pytest.raises(InputError, match=r"sample 201 .* clock jump"):
        recording_from_log(_contents([_imu_msgs(rec, stamps=ns)], [_fix_msgs(rec)]))


def test_reordered_stamps_are_sorted_and_warned(rec):
    ns = _imu_msgs(rec).stamp_ns.copy()
    ns[200], ns[201] = ns[201], ns[200]
    out = recording_from_log(_contents([_imu_msgs(rec, stamps=ns)], [_fix_msgs(rec)]))
    np.testing.assert_allclose(out.imu.t, rec.imu.t, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(out.imu.gyro[[200, 201]], rec.imu.gyro[[201, 200]])   # values follow stamps
    assert any("1 sample out of stamp order, sorted (first: sample 201" in w for w in out.warnings)


def test_duplicate_stamps_dropped(rec):
    ns = _imu_msgs(rec).stamp_ns.copy()
    ns[11] = ns[10]
    out = recording_from_log(_contents([_imu_msgs(rec, stamps=ns)], [_fix_msgs(rec)]))
    assert len(out.imu) == len(rec.imu) - 1
    np.testing.assert_array_equal(out.imu.gyro[10], rec.imu.gyro[10])      # the first of the stamp kept
    assert any("1 conflicting duplicate" in w and "sample 11" in w for w in out.warnings)


def test_gnss_velocity_from_the_twist_topic(rec):
    g = rec.gnss
    ns = rec.t0_ns + np.round(g.t * 1e9).astype(np.int64)
    tw = TwistMessages("/gnss/vel", ns, ns, g.vel_enu.copy(), np.full((len(g), 3), 0.01))
    out = recording_from_log(_contents([_imu_msgs(rec)], [_fix_msgs(rec)], [tw]))
    np.testing.assert_array_equal(out.gnss.vel_enu, g.vel_enu)
    np.testing.assert_allclose(out.gnss.std_vel_enu, 0.1)


def test_missing_roles_are_named(rec):
    with pytest.raises(InputError, match="no sensor_msgs/Imu topic"):
        recording_from_log(_contents([], [_fix_msgs(rec)]))
    with pytest.raises(InputError, match="no sensor_msgs/NavSatFix topic"):
        recording_from_log(_contents([_imu_msgs(rec)], []))
