"""ROS logs read with a memory budget (``[output] memory``): the decoded messages go to a spill
file chunk by chunk / batch by batch (navpp.io.messages._Rows), and the Recording built from them
(navpp.io.assemble) holds the same bits as one read all in memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navpp import spill
from navpp.config import load_config, with_memory
from navpp.io import roswrite as rw
from navpp.io.assemble import recording_from_log
from navpp.io.mcap import read_mcap
from navpp.io.messages import TopicDecoder, _as_buffer
from navpp.io.ros import IMU_TYPE, LogContents
from navpp.io.rosbag import read_rosbag
from navpp.reading import read_log
from navpp.recording import Recording


@pytest.fixture(scope="module")
def rec() -> Recording:
    from navpp.simulate import SimulationSpec, simulate

    return simulate(SimulationSpec(duration_s=40, still_s=20, gnss_velocity=True)).recording()


WRITERS = {
    "mcap": lambda rec, d: rw.write_mcap_ros2(rec, d / "log.mcap", chunk_size=20_000) or d / "log.mcap",
    "mcap-unchunked": lambda rec, d: rw.write_mcap_ros2(rec, d / "log.mcap", chunk_size=0) or d / "log.mcap",
    "ros2-sqlite3": lambda rec, d: rw.write_ros2_bag(rec, d / "bag") or d / "bag",
    "ros1": lambda rec, d: rw.write_ros1_bag(rec, d / "log.bag", chunk_size=20_000) or d / "log.bag",
}


@pytest.fixture(scope="module")
def logs(rec, tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("spill-logs")
    out = {}
    for kind, write in WRITERS.items():
        (base / kind).mkdir()
        out[kind] = write(rec, base / kind)
    return out


def _read(kind: str, path: Path, memory: int | None) -> LogContents:
    return read_mcap(path, memory=memory) if kind.startswith("mcap") else read_rosbag(path, memory=memory)


def _same_bits(a, b, what: str) -> None:
    if isinstance(a, np.ndarray):
        assert a.shape == b.shape and a.dtype == b.dtype, what
        assert np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes(), what
    else:
        assert a == b, what


def _same_contents(a: LogContents, b: LogContents) -> None:
    assert a.topics == b.topics and a.warnings == b.warnings
    for group in ("imu", "fix", "twist"):
        da, db = getattr(a, group), getattr(b, group)
        assert da.keys() == db.keys()
        for topic in da:
            for name, value in vars(da[topic]).items():
                _same_bits(value, getattr(db[topic], name), f"{group} {topic} {name}")


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_spilled_messages_hold_the_same_bits(logs, kind):
    whole = _read(kind, logs[kind], None)
    spilled = _read(kind, logs[kind], 1)          # every topic beyond a 1-byte budget
    _same_contents(spilled, whole)
    imu = spilled.imu["/imu/data"]
    assert spill.spilled(imu.gyro) and spill.spilled(imu.stamp_ns)
    _same_contents(_read(kind, logs[kind], 128 << 20), whole)   # a budget not reached


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_recording_from_spilled_messages_is_the_same(logs, kind):
    cfg = load_config(None)
    whole = read_log(logs[kind], cfg)
    small = read_log(logs[kind], with_memory(cfg, 1))
    assert spill.spilled(small.imu.t) and spill.spilled(small.imu.gyro) and spill.spilled(small.imu.accel)
    assert not spill.spilled(whole.imu.t)
    for name in ("t", "gyro", "accel"):
        _same_bits(getattr(small.imu, name), getattr(whole.imu, name), name)
    for name, value in vars(whole.gnss).items():
        _same_bits(getattr(small.gnss, name), value, f"gnss {name}")
    assert small.warnings == whole.warnings and small.t0_ns == whole.t0_ns


def test_imu_out_of_order_and_repeated_on_the_spill_file(rec):
    """Stamps out of order and a repeated message: the same samples kept and the same warnings
    whether the messages are on the spill file or in memory."""
    n = 500
    stamps = rw.stamps_ns(rec, rec.imu.t[:n]).copy()
    gyro, accel = rec.imu.gyro[:n].copy(), rec.imu.accel[:n].copy()
    stamps[[10, 11]] = stamps[[11, 10]]
    stamps[30], gyro[30], accel[30] = stamps[29], gyro[29], accel[29]
    payloads = rw.encode_imu(stamps, gyro, accel, encoding="cdr")
    fix = read_mcap_fix(rec)
    results = []
    for memory in (None, 1):
        dec = TopicDecoder("/imu", IMU_TYPE, "cdr", memory=memory, expected=n // 2)   # grows past it too
        buf, starts, lengths = _as_buffer(payloads)
        for a in range(0, n, 64):
            dec.add(buf, starts[a:a + 64], lengths[a:a + 64], stamps[a:a + 64])
        imu = dec.result()
        assert spill.spilled(imu.gyro) == (memory == 1)
        contents = LogContents("test", fix.topics + (_imu_info(n),), {"/imu": imu}, fix.fix, {}, ())
        warnings = list(recording_from_log(contents, imu_topic="/imu", gnss_topic="/gnss/fix").warnings)
        r = recording_from_log(contents, imu_topic="/imu", gnss_topic="/gnss/fix")
        results.append((r, warnings))
    (a, wa), (b, wb) = results
    assert wa == wb and any("out of stamp order" in w for w in wa) and any("duplicate" in w for w in wa)
    for name in ("t", "gyro", "accel"):
        _same_bits(getattr(b.imu, name), getattr(a.imu, name), name)
    assert len(a.imu) == n - 1


def _imu_info(n: int):
    from navpp.io.ros import TopicInfo

    return TopicInfo("/imu", IMU_TYPE, n)


def read_mcap_fix(rec: Recording) -> LogContents:
    """The GNSS fixes of ``rec`` as decoded NavSatFix messages (topic ``/gnss/fix``)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fix.mcap"
        rw.write_mcap_ros2(rec, path, gnss_vel_topic=None, odometry_topic=None)
        lc = read_mcap(path, ["/gnss/fix"])
    return LogContents(lc.source, tuple(t for t in lc.topics if t.topic == "/gnss/fix"), {}, lc.fix, {}, ())
