"""Every log format gives the same Recording and the same results; ROS logs through the CLI.

Issue 3, points 4, 5, 8 and 9.  One simulated drive is written as a CSV log, then the
Recording read back from that CSV is written by navpp's own writers as a ROS 2 MCAP, a ROS 1
bag and a ROS 2 sqlite3 bag.  The oracle is the CSV path: each ROS log must read to the same
Recording (t0_ns equal, times within 1 ns, IMU and GNSS values bit for bit, GNSS std equal)
and process to the same solution arrays and metrics.

Why the ROS logs are written from the CSV's Recording and not from the simulator's: the CSV
stores GNSS positions with 12 decimals, so only the values the CSV holds can be compared
bit for bit.  Times: the CSV reader turns its decimal stamps into exact integer ns and
``(ns - t0_ns) * 1e-9``, the ROS readers do the same with the header stamps, so the relative
times agree exactly (asserted to 1 ns, as the issue states it).

Bad input goes through the CLI: one line on stderr naming the file and the topic / message /
time, exit code 1 (``test_cli.assert_one_line_error``); a cut-off recording and a slow IMU are
processed with a warning instead.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from test_cli import assert_one_line_error, flat, invoke

from navpp import api
from navpp.config import config_from_dict
from navpp.io import roswrite
from navpp.io.csv import read_csv_log
from navpp.outdir import MANIFEST_NAME as MANIFEST
from navpp.simulate import SimulationSpec, simulate, write_csv_log

SPEC = SimulationSpec(duration_s=120, still_s=30, seed=3, lever_arm_m=(0.3, 0.0, 1.2))
CONFIG = {"imu": {"preset": "automotive"}, "gnss": {"lever_arm_m": [0.3, 0.0, 1.2]}}
CONFIG_TOML = '[imu]\npreset = "automotive"\n\n[gnss]\nlever_arm_m = [0.3, 0.0, 1.2]\n'
N_IMU, N_GNSS = 15001, 601  # 120 s at 125 Hz and 5 Hz, both ends included

ROS_KINDS = ("mcap", "ros1", "ros2")
IMU_TYPE_ROS2 = "sensor_msgs/msg/Imu"
FIX_TYPE_ROS2 = "sensor_msgs/msg/NavSatFix"
SCHEMAS = {IMU_TYPE_ROS2: roswrite.IMU_MSGDEF, FIX_TYPE_ROS2: roswrite.NAVSATFIX_MSGDEF}


def ns_text(ns: int) -> str:
    return f"{ns // 10**9}.{ns % 10**9:09d} s"


# --------------------------------------------------------------------------------- fixtures


class Logs:
    """The CSV log, its Recording and the same Recording as ROS logs."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.csv = root / "drive"
        write_csv_log(simulate(SPEC), self.csv)
        self.rec = read_csv_log(self.csv)
        self.paths = {"mcap": root / "drive.mcap", "ros1": root / "drive.bag", "ros2": root / "drive_ros2"}
        roswrite.write_mcap_ros2(self.rec, self.paths["mcap"])
        roswrite.write_ros1_bag(self.rec, self.paths["ros1"])
        roswrite.write_ros2_bag(self.rec, self.paths["ros2"], storage="sqlite3")
        self.config_file = root / "test.toml"
        self.config_file.write_text(CONFIG_TOML)
        self.imu_ns = roswrite.stamps_ns(self.rec, self.rec.imu.t)
        self.gnss_ns = roswrite.stamps_ns(self.rec, self.rec.gnss.t)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Logs:
    return Logs(tmp_path_factory.mktemp("formats"))


@pytest.fixture(scope="module")
def config():
    return config_from_dict(CONFIG, "test_formats")


@pytest.fixture(scope="module")
def csv_result(logs: Logs, config):
    return api.process(logs.csv, config=config, write=False)


def imu_stream(logs: Logs, topic: str = "/imu/data", *, stamps=None, gyro=None, accel=None, log_ns=None):
    """(topic, type, log times, payloads) of the recording's IMU, optionally altered."""
    rec = logs.rec
    stamps = logs.imu_ns if stamps is None else stamps
    payloads = roswrite.encode_imu(stamps, rec.imu.gyro if gyro is None else gyro,
                                   rec.imu.accel if accel is None else accel, encoding="cdr")
    return topic, IMU_TYPE_ROS2, stamps if log_ns is None else log_ns, payloads


def fix_stream(logs: Logs, topic: str = "/gnss/fix"):
    g = logs.rec.gnss
    payloads = roswrite.encode_navsatfix(logs.gnss_ns, g.lat_deg, g.lon_deg, g.alt, encoding="cdr",
                                         cov_diag=g.std_enu ** 2)
    return topic, FIX_TYPE_ROS2, logs.gnss_ns, payloads


def write_mcap(path: Path, streams, schemas: dict[str, str] = SCHEMAS) -> Path:
    """A ROS 2 MCAP (zstd chunks) of ``(topic, type, log_ns, payloads)`` streams, in log-time order;
    a stream may be empty (a channel without messages).  ``schemas``: type -> definition text."""
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test_formats")
        schema_ids: dict[str, int] = {}
        items = []
        for topic, msgtype, log_ns, payloads in streams:
            if msgtype not in schema_ids:
                schema_ids[msgtype] = w.register_schema(msgtype, "ros2msg", schemas[msgtype].encode())
            channel = w.register_channel(topic, "cdr", schema_ids[msgtype])
            items += [(int(t), channel, p) for t, p in zip(log_ns, payloads, strict=True)]
        items.sort(key=lambda item: item[0])
        for t, channel, data in items:
            w.add_message(channel_id=channel, log_time=t, publish_time=t, data=data)
        w.finish()
    return path


def table_rows(stdout: str) -> dict[str, list[str]]:
    """``navpp inspect``'s table: first cell (topic / file) -> the other cells."""
    rows = {}
    for line in stdout.splitlines():
        cells = [c.strip() for c in line.split("│")[1:-1]]
        if cells and cells[0] and cells[0] != "topic / file":
            rows[cells[0]] = cells[1:]
    return rows


def ok(res) -> None:
    assert res.exit_code == 0, (res.exit_code, res.output, res.exception)
    assert res.exception is None, repr(res.exception)


# ------------------------------------------------------------------------ 1. same Recording


@pytest.mark.parametrize("kind", ROS_KINDS)
def test_ros_logs_read_to_the_csv_recording(logs: Logs, config, kind: str) -> None:
    csv = logs.rec
    rec = api.read_log(logs.paths[kind], config, reference=logs.csv / "reference.csv")
    assert rec.t0_ns == csv.t0_ns
    assert rec.time_base == csv.time_base == "unix"
    assert len(rec.imu) == len(csv.imu) == N_IMU
    assert len(rec.gnss) == len(csv.gnss) == N_GNSS
    # times within 1 ns (the tolerance); values bit for bit
    assert np.max(np.abs(rec.imu.t - csv.imu.t)) <= 1e-9
    assert np.max(np.abs(rec.gnss.t - csv.gnss.t)) <= 1e-9
    np.testing.assert_array_equal(rec.imu.gyro, csv.imu.gyro)
    np.testing.assert_array_equal(rec.imu.accel, csv.imu.accel)
    for name in ("lat_deg", "lon_deg", "alt", "std_enu"):
        np.testing.assert_array_equal(getattr(rec.gnss, name), getattr(csv.gnss, name), err_msg=name)
    assert rec.gnss.vel_enu is None and csv.gnss.vel_enu is None
    # NavSatFix status 0 (STATUS_FIX) for every message; the CSV has no fix column
    np.testing.assert_array_equal(rec.gnss.fix, np.zeros(N_GNSS, dtype=np.int64))
    for name in ("t", "lat_deg", "lon_deg", "alt", "vel_enu", "rph_deg"):
        np.testing.assert_array_equal(getattr(rec.reference, name), getattr(csv.reference, name), err_msg=name)
    assert rec.warnings == ()


@pytest.mark.parametrize("kind", ROS_KINDS)
def test_ros_logs_process_to_the_csv_results(logs: Logs, config, csv_result, kind: str) -> None:
    res = api.process(logs.paths[kind], config=config, write=False, reference=logs.csv / "reference.csv")
    a, b = csv_result.solution, res.solution
    assert b.t0_ns == a.t0_ns
    for name in ("t", "lat_deg", "lon_deg", "alt", "vel_enu", "rph_deg", "std_enu"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    assert (res.run.gnss_epochs, res.run.gnss_rejected) == (csv_result.run.gnss_epochs, csv_result.run.gnss_rejected)
    # the same notes, but for how the reference was found (given here, in the CSV log's directory there)
    def found(notes: tuple[str, ...]) -> list[str]:
        return [n.replace(", --reference (", ", in the log directory (") for n in notes]

    assert found(res.notes) == found(csv_result.notes)
    ma, mb = dict(csv_result.metrics), dict(res.metrics)
    assert (ma.pop("log"), mb.pop("log")) == (str(logs.csv), str(logs.paths[kind]))
    ma.pop("runtime_s"), mb.pop("runtime_s")
    assert mb == ma


def test_gnss_velocity_topic_reads_and_processes_like_the_csv(tmp_path: Path, config) -> None:
    """A TwistWithCovarianceStamped topic gives the CSV's ve, vn, vu and std, exactly."""
    spec = SimulationSpec(duration_s=60, still_s=30, seed=5, gnss_velocity=True, lever_arm_m=(0.3, 0.0, 1.2))
    write_csv_log(simulate(spec), tmp_path / "drive")
    csv = read_csv_log(tmp_path / "drive")
    assert csv.gnss.vel_enu is not None
    roswrite.write_mcap_ros2(csv, tmp_path / "v.mcap")
    roswrite.write_ros1_bag(csv, tmp_path / "v.bag")
    base = api.process(tmp_path / "drive", config=config, write=False)
    for path in (tmp_path / "v.mcap", tmp_path / "v.bag"):
        rec = api.read_log(path, config)
        np.testing.assert_array_equal(rec.gnss.vel_enu, csv.gnss.vel_enu)
        np.testing.assert_array_equal(rec.gnss.std_vel_enu, csv.gnss.std_vel_enu)
        res = api.process(path, config=config, write=False, reference=tmp_path / "drive" / "reference.csv")
        np.testing.assert_array_equal(res.solution.lat_deg, base.solution.lat_deg)
        np.testing.assert_array_equal(res.solution.rph_deg, base.solution.rph_deg)


# ------------------------------------------------------------------------ 2. the CLI on ROS logs


def test_process_mcap_writes_trajectory(logs: Logs, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = invoke("process", logs.paths["mcap"], "--config", logs.config_file, "--out", out)
    ok(res)
    text = flat(res.stdout)
    assert f"{N_IMU} IMU samples at 125.0 Hz" in text and "trajectory.csv" in text
    lines = (out / "trajectory.csv").read_text().splitlines()
    assert lines[0].startswith("t,lat,lon,alt,")
    assert len(lines) == 1 + N_IMU
    assert lines[1].startswith("1700000000.000000,") and lines[-1].startswith("1700000120.000000,")
    # no reference, no metrics
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == ["diagnostics.csv", "trajectory.csv"]


@pytest.mark.parametrize("kind", ROS_KINDS)
def test_inspect_lists_topics_with_counts_and_roles(logs: Logs, kind: str) -> None:
    res = invoke("inspect", logs.paths[kind])
    ok(res)
    assert f"({kind})" in res.stdout
    rows = table_rows(res.stdout)
    assert set(rows) == {"/imu/data", "/gnss/fix"}
    imu, fix = rows["/imu/data"], rows["/gnss/fix"]
    assert imu[:3] == ["sensor_msgs/Imu", str(N_IMU), "125.0"] and imu[-1] == "IMU"
    assert fix[:3] == ["sensor_msgs/NavSatFix", str(N_GNSS), "5.0"] and fix[-1] == "GNSS"
    assert imu[3] == fix[3] == "1700000000.000" and imu[4] == fix[4] == "120.0"  # first stamp, span


@pytest.fixture(scope="module")
def two_imus(logs: Logs) -> Path:
    return write_mcap(logs.root / "two_imus.mcap", [imu_stream(logs, "/imu/a"), imu_stream(logs, "/imu/b"),
                                                    fix_stream(logs)])


def test_two_imu_topics_need_imu_topic(logs: Logs, two_imus: Path, tmp_path: Path) -> None:
    line = assert_one_line_error(invoke("process", two_imus, "--out", tmp_path / "out"), tmp_path / "out")
    assert str(two_imus) in line and "/imu/a" in line and "/imu/b" in line and "--imu-topic" in line
    out = tmp_path / "b"
    ok(invoke("process", two_imus, "--imu-topic", "/imu/b", "--config", logs.config_file, "--out", out, "-q"))
    assert len((out / "trajectory.csv").read_text().splitlines()) == 1 + N_IMU
    rows = table_rows(invoke("inspect", two_imus).stdout)
    assert "--imu-topic" in rows["/imu/a"][-1] and "--imu-topic" in rows["/imu/b"][-1]


@pytest.mark.parametrize(("option", "value", "expected"), [
    ("--imu-topic", "/imu/c", "no topic '/imu/c' (--imu-topic); topics: /gnss/fix, /imu/a, /imu/b"),
    ("--imu-topic", "/gnss/fix", "topic '/gnss/fix' (--imu-topic) is sensor_msgs/NavSatFix, not sensor_msgs/Imu"),
    ("--gnss-topic", "/imu/a", "topic '/imu/a' (--gnss-topic) is sensor_msgs/Imu, not sensor_msgs/NavSatFix"),
])
def test_bad_topic_choice_is_named(two_imus: Path, tmp_path: Path, option: str, value: str, expected: str) -> None:
    args = [option, value] if option == "--imu-topic" else ["--imu-topic", "/imu/a", option, value]
    line = assert_one_line_error(invoke("process", two_imus, *args, "--out", tmp_path / "o"), tmp_path / "o")
    assert line == f"navpp: error: {two_imus}: {expected}"


def test_gnss_topic_and_reference_topic(logs: Logs, tmp_path: Path) -> None:
    """A second NavSatFix topic (a DGPS receiver): ambiguous until named; as --reference-topic it
    gives metrics.json with the position figures of the CSV run with reference.csv, exactly (a
    NavSatFix has no velocity or attitude, so neither has figures)."""
    path = tmp_path / "with_ref.mcap"
    roswrite.write_mcap_ros2(logs.rec, path, reference_topic="/reference/fix")
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert str(path) in line and "/gnss/fix, /reference/fix" in line and "--gnss-topic" in line

    out = tmp_path / "gnss"  # --gnss-topic alone settles the GNSS; no reference
    ok(invoke("process", path, "--gnss-topic", "/gnss/fix", "--config", logs.config_file, "--out", out, "-q"))
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == ["diagnostics.csv", "trajectory.csv"]

    out = tmp_path / "ref"
    res = invoke("process", path, "--reference-topic", "/reference/fix", "--config", logs.config_file,
                 "--out", out, "-q")
    ok(res)
    assert res.stderr.strip() == ""  # no warning (e.g. about the reference's unknown covariance)
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "diagnostics.csv", "metrics.json", "metrics.md", "trajectory.csv"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["reference"] == f"{path}:/reference/fix"
    assert m["epochs"] == 1201  # the 10 Hz reference over 120 s
    assert "velocity_mps" not in m and "attitude_deg" not in m
    base = invoke("process", logs.csv, "--config", logs.config_file, "--out", tmp_path / "csv", "-q")
    ok(base)
    m_csv = json.loads((tmp_path / "csv" / "metrics.json").read_text())
    assert m["position_m"] == m_csv["position_m"]


# ------------------------------------------------------------------------ 3. bad input


@pytest.mark.parametrize("name", ["empty.mcap", "empty.bag", "empty.db3"])
def test_empty_file(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"")
    for command in ("process", "inspect"):
        extra = ["--out", tmp_path / "o"] if command == "process" else []
        line = assert_one_line_error(invoke(command, path, *extra), tmp_path / "o")
        assert line == f"navpp: error: {path}: empty file"


@pytest.mark.parametrize("name", ["random.mcap", "random.bag"])
def test_not_a_log(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(7).bytes(4096))
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line.startswith(f"navpp: error: {path}: not a log navpp reads")


def test_no_imu_topic(logs: Logs, tmp_path: Path) -> None:
    path = write_mcap(tmp_path / "fix_only.mcap", [fix_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line == f"navpp: error: {path}: no sensor_msgs/Imu topic; topics: /gnss/fix (sensor_msgs/NavSatFix)"


def test_imu_topic_without_messages(logs: Logs, tmp_path: Path) -> None:
    empty = ("/imu/data", IMU_TYPE_ROS2, [], [])
    path = write_mcap(tmp_path / "no_imu_messages.mcap", [empty, fix_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line == f"navpp: error: {path}: topic '/imu/data' has no IMU message"


def test_no_gnss_topic(logs: Logs, tmp_path: Path) -> None:
    path = write_mcap(tmp_path / "imu_only.mcap", [imu_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line == (f"navpp: error: {path}: no sensor_msgs/NavSatFix topic for the GNSS; "
                    "topics: /imu/data (sensor_msgs/Imu)")


def test_truncated_mcap_is_processed_up_to_the_cut(logs: Logs, tmp_path: Path, csv_result) -> None:
    data = logs.paths["mcap"].read_bytes()
    cut_at = int(len(data) * 0.7)
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut_at])
    out = tmp_path / "out"
    res = invoke("process", path, "--config", logs.config_file, "--out", out, "-q")
    ok(res)
    assert res.stdout.strip() == ""
    warnings = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(warnings) == 1, res.stderr
    w = flat(warnings[0])
    assert w.startswith(f"warning: {path}: the recording is cut off: the file ends at byte {cut_at} "
                        "inside the record starting at byte ")
    last_log = int(w.split("the last message read has log time ")[1].split(".")[0])
    # the trajectory runs to the last IMU message read, well past half the drive
    t_last = float((out / "trajectory.csv").read_text().splitlines()[-1].split(",")[0])
    assert 1_700_000_060 < t_last <= last_log + 1
    # the messages before the cut are the log's first messages, unchanged
    rec = api.read_log(path, csv_result.config)
    n = len(rec.imu)
    assert 0.5 * N_IMU < n < N_IMU
    np.testing.assert_array_equal(rec.imu.gyro, logs.rec.imu.gyro[:n])


def test_truncated_mcap_with_nothing_left_is_one_clear_error(logs: Logs, tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    path.write_bytes(logs.paths["mcap"].read_bytes()[:3000])  # inside the first chunk
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line.startswith(f"navpp: error: {path}: no sensor_msgs/Imu topic; topics: none "
                           "(the recording is cut off: the file ends at byte 3000 inside the record")
    assert "no message could be read" in line


def _corrupt_zstd_chunk(path: Path, k: int, out: Path):
    """Flip one byte of chunk ``k``'s zstd data where it still decompresses (to other bytes), so
    only the CRC can tell; returns the chunk index record."""
    import zstandard
    from mcap.reader import make_reader

    data = bytearray(path.read_bytes())
    idx = make_reader(io.BytesIO(bytes(data))).get_summary().chunk_indexes[k]
    assert idx.compression == "zstd"
    start = idx.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + len(idx.compression) + 8
    original = bytes(data[start:start + idx.compressed_size])
    clean = zstandard.ZstdDecompressor().decompress(original, max_output_size=idx.uncompressed_size)
    for pos in range(idx.compressed_size // 2, idx.compressed_size):
        damaged = bytearray(original)
        damaged[pos] ^= 0x10
        try:
            raw = zstandard.ZstdDecompressor().decompress(bytes(damaged), max_output_size=idx.uncompressed_size)
        except zstandard.ZstdError:
            continue
        if len(raw) == idx.uncompressed_size and raw != clean:
            data[start + pos] ^= 0x10
            out.write_bytes(bytes(data))
            return idx
    raise AssertionError("no byte of the chunk decompresses to other data")


def test_corrupted_chunk_names_the_chunk_and_its_time(logs: Logs, tmp_path: Path) -> None:
    path = tmp_path / "corrupt.mcap"
    idx = _corrupt_zstd_chunk(logs.paths["mcap"], 2, path)
    chunk = (f"{path}: chunk at byte {idx.chunk_start_offset} (log time {ns_text(idx.message_start_time)} to "
             f"{ns_text(idx.message_end_time)}) is corrupted: CRC mismatch")
    for args in (("process", path, "--out", tmp_path / "o"), ("inspect", path)):
        line = assert_one_line_error(invoke(*args), tmp_path / "o")
        assert line.startswith(f"navpp: error: {chunk}"), line


@pytest.mark.parametrize(("field", "value", "name"), [("gyro", np.nan, "angular_velocity"),
                                                      ("accel", np.inf, "linear_acceleration")])
def test_non_finite_imu_field_names_topic_and_message(logs: Logs, tmp_path: Path, field: str, value: float,
                                                      name: str) -> None:
    k = 5000
    arr = getattr(logs.rec.imu, field).copy()
    arr[k, 1] = value
    path = write_mcap(tmp_path / "bad_value.mcap", [imu_stream(logs, **{field: arr}), fix_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line == (f"navpp: error: {path}: topic '/imu/data': message {k} "
                    f"(t = {ns_text(int(logs.imu_ns[k]))}): non-finite {name}")


def test_header_stamps_going_backwards(logs: Logs, tmp_path: Path) -> None:
    k = 7000
    stamps = logs.imu_ns.copy()
    stamps[k] = stamps[k - 10] - 3_000_000_000  # log times stay in order: only the header stamp jumps 3 s back
    path = write_mcap(tmp_path / "backwards.mcap", [imu_stream(logs, stamps=stamps, log_ns=logs.imu_ns),
                                                     fix_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    # one message 3 s back among regular neighbours: a lone bad stamp, named (issue 15)
    assert line.startswith(f"navpp: error: {path}: topic '/imu/data': message {k} "
                           f"(t = {ns_text(int(stamps[k]))}) lies ")
    assert "a lone bad stamp" in line
    assert line.endswith('try [time] source = "log"')


def test_header_stamps_jumping_back_for_good(logs: Logs, tmp_path: Path) -> None:
    k = 7000
    stamps = logs.imu_ns.copy()
    stamps[k:] -= 3_000_000_000  # every stamp from k on 3 s back: a clock jump
    path = write_mcap(tmp_path / "backwards.mcap", [imu_stream(logs, stamps=stamps, log_ns=logs.imu_ns),
                                                     fix_stream(logs)])
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert line.startswith(f"navpp: error: {path}: topic '/imu/data': sample {k} has stamp "
                           f"{ns_text(int(stamps[k]))}, ")
    assert "a clock jump (more than 1 s back), not a reordering" in line
    assert line.endswith('(try [time] source = "log")')


def test_header_stamps_slightly_out_of_order_are_sorted(logs: Logs, tmp_path: Path) -> None:
    k = 7000
    stamps = logs.imu_ns.copy()
    stamps[k] = stamps[k - 10]  # a repeat of an earlier stamp, with other values: sorted, then dropped
    path = write_mcap(tmp_path / "backwards.mcap", [imu_stream(logs, stamps=stamps, log_ns=logs.imu_ns),
                                                     fix_stream(logs)])
    res = api.process(path, write=False)
    text = "\n".join(res.warnings)
    assert f"topic '/imu/data': 1 sample out of stamp order, sorted (first: sample {k} at " in text
    assert "1 conflicting duplicate" in text
    assert len(res.recording.imu) == len(stamps) - 1


def test_slow_imu_is_processed_with_a_warning(tmp_path: Path) -> None:
    sim = simulate(SimulationSpec(duration_s=60, still_s=30, seed=3, imu_rate_hz=20.0))
    path = tmp_path / "slow.mcap"
    roswrite.write_mcap_ros2(sim.recording(), path)
    out = tmp_path / "out"
    res = invoke("process", path, "--out", out, "-q")
    ok(res)
    warnings = [flat(line) for line in res.stderr.splitlines() if line.strip()]
    expected = (f"warning: {path}: topic '/imu/data': IMU rate 20.0 Hz is low for strapdown navigation "
                "(100-200 Hz expected); processed anyway")
    assert warnings == [expected]
    assert len((out / "trajectory.csv").read_text().splitlines()) == 1 + 60 * 20 + 1


def test_unparsable_message_definition_in_an_mcap(logs: Logs, tmp_path: Path) -> None:
    garbage = {**SCHEMAS, IMU_TYPE_ROS2: "this is not a message definition ((("}
    path = write_mcap(tmp_path / "garbage_schema.mcap", [imu_stream(logs), fix_stream(logs)], garbage)
    line = assert_one_line_error(invoke("process", path, "--out", tmp_path / "o"), tmp_path / "o")
    assert str(path) in line and "'/imu/data'" in line and "definition" in line


def test_inspect_of_a_cut_mcap_warns(logs: Logs, tmp_path: Path) -> None:
    data = logs.paths["mcap"].read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: int(len(data) * 0.7)])
    res = invoke("inspect", path)
    ok(res)
    assert "the recording is cut off" in flat(res.stderr)


def test_cut_mcap_failing_later_names_the_cut(logs: Logs, tmp_path: Path) -> None:
    # cut inside the still period: alignment cannot find a heading; the one line says why
    data = logs.paths["mcap"].read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: int(len(data) * 0.12)])
    line = assert_one_line_error(invoke("process", path, "--config", logs.config_file, "--out", tmp_path / "o"),
                                 tmp_path / "o")
    assert "the recording is cut off" in line
