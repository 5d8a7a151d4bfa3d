"""MCAP reading (navpp.io.mcap) against the mcap libraries, on files their writers make.

Every decoded topic is compared message for message, bit for bit, with ``mcap``'s own
iteration + the ``mcap_ros2`` / ``mcap_ros1`` decoders (log-time order), over chunked and
unchunked files, zstd / lz4 / no compression, with and without a summary, little- and
big-endian CDR and ROS 1; plus cut-off files, corrupted chunks and files that are not MCAP.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType
from mcap.writer import Writer as McapWriter
from mcap_ros1._vendor.genpy.dynamic import generate_dynamic
from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
from mcap_ros1.writer import Writer as Ros1Writer
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from ros_oracles import expected_from_objects, fill_genpy, ros2_name
from rosbags.typesys import Stores, get_typestore

from navpp.errors import InputError
from navpp.findings import code_of
from navpp.io.mcap import list_topics, read_mcap
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    SUPPORTED_TYPES,
    TWIST_COV_TYPE,
    TWIST_TYPE,
    normalise_type,
)

STORE2 = get_typestore(Stores.ROS2_HUMBLE)
STORE1 = get_typestore(Stores.ROS1_NOETIC)
STRING_TYPE = "std_msgs/String"
TYPES = (*SUPPORTED_TYPES, STRING_TYPE)
T0_NS = 1_700_000_000_123_456_789
PERIOD_NS = 8_000_000  # 125 Hz


MSGDEF2 = {t: STORE2.generate_msgdef(ros2_name(t), ros_version=2)[0] for t in TYPES}
MSGDEF1 = {t: STORE1.generate_msgdef(ros2_name(t), ros_version=1)[0] for t in TYPES}
ENCODE2 = {t: serialize_dynamic(ros2_name(t), MSGDEF2[t])[ros2_name(t)] for t in TYPES}
GENPY = {t: generate_dynamic(t, MSGDEF1[t])[t] for t in TYPES}

#: (topic, type, every k-th step): the log's streams.
STREAMS = (("/imu", IMU_TYPE, 1), ("/fix", FIX_TYPE, 25), ("/vel", TWIST_COV_TYPE, 25),
           ("/vel_plain", TWIST_TYPE, 50), ("/chatter", STRING_TYPE, 10))


# --------------------------------------------------------------------------- writing logs


def make_message(msgtype: str, i: int) -> dict:
    """Message ``i`` of a stream as a nested dict; frame_id of 0..9 characters, covariances
    filled, a few NaNs."""
    sec, nsec = divmod(T0_NS + i * PERIOD_NS - 1_500_000, 1_000_000_000)
    header = {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": "frame_id_x"[: i % 10]}
    a = 1e-3 * i

    def cov(n: int) -> list[float]:
        return [1e-4 * (k + 1) + a for k in range(n)]

    if msgtype == IMU_TYPE:
        return {"header": header, "orientation": {"x": 0.1, "y": 0.2, "z": 0.3, "w": 0.927},
                "orientation_covariance": cov(9),
                "angular_velocity": {"x": a, "y": -a, "z": 0.5 + a},
                "angular_velocity_covariance": [-1.0 if i % 5 == 0 else 1e-6] + cov(8),
                "linear_acceleration": {"x": 0.1 - a, "y": float("nan") if i == 7 else a,
                                        "z": 9.81 + a},
                "linear_acceleration_covariance": cov(9)}
    if msgtype == FIX_TYPE:
        return {"header": header, "status": {"status": (i % 4) - 1, "service": 1 + i % 8},
                "latitude": 48.1 + a, "longitude": 11.5 - a, "altitude": 520.0 + i,
                "position_covariance": cov(9), "position_covariance_type": i % 4}
    twist = {"linear": {"x": a, "y": 2 * a, "z": -a}, "angular": {"x": 0.0, "y": 0.1, "z": a}}
    if msgtype == TWIST_COV_TYPE:
        return {"header": header, "twist": {"twist": twist, "covariance": cov(36)}}
    if msgtype == TWIST_TYPE:
        return {"header": header, "twist": twist}
    return {"data": "hello " * (i % 4)}


def genpy_message(msgtype: str, values: dict):
    obj = GENPY[msgtype]()

    fill_genpy(obj, values)
    return obj


def payload(msgtype: str, values: dict, encoding: str) -> bytes:
    """Serialized by the libraries: mcap_ros2 (cdr), rosbags (cdr_be), genpy (ros1)."""
    if encoding == "ros1":
        buf = io.BytesIO()
        genpy_message(msgtype, values).serialize(buf)
        return buf.getvalue()
    le = bytes(ENCODE2[msgtype](values))
    if encoding == "cdr_be":
        obj = STORE2.deserialize_cdr(le, ros2_name(msgtype))
        return bytes(STORE2.serialize_cdr(obj, ros2_name(msgtype), little_endian=False))
    return le


def stream(n_steps: int, streams=STREAMS, log_offset_ns=None):
    """(topic, type, log_time, index, values) in writing order."""
    for i in range(n_steps):
        for topic, msgtype, every in streams:
            if i % every == 0:
                k = i // every
                log = T0_NS + i * PERIOD_NS + (0 if log_offset_ns is None else log_offset_ns(i))
                yield topic, msgtype, log, k, make_message(msgtype, k)


def write_raw(path: Path, *, encoding: str = "cdr", n_steps: int = 200,
              compression: CompressionType = CompressionType.ZSTD, chunk_size: int = 2048,
              use_chunking: bool = True, summary: bool = True, enable_crcs: bool = True,
              streams=STREAMS, log_offset_ns=None) -> Path:
    """A log written with mcap.writer.Writer (every option) from library-serialized payloads.

    ``encoding``: ``cdr`` (little endian), ``cdr_be``, ``cdr_mixed`` (/imu alternates), ``ros1``.
    """
    options = {} if summary else {
        "index_types": IndexType.NONE, "repeat_channels": False, "repeat_schemas": False,
        "use_statistics": False, "use_summary_offsets": False}
    ros1 = encoding == "ros1"
    with open(path, "wb") as f:
        w = McapWriter(f, chunk_size=chunk_size, compression=compression,
                       use_chunking=use_chunking, enable_crcs=enable_crcs, **options)
        w.start(profile="ros1" if ros1 else "ros2", library="navpp tests")
        channels: dict[str, int] = {}
        for topic, msgtype, *_ in streams:
            name, text = (msgtype, MSGDEF1[msgtype]) if ros1 else (ros2_name(msgtype), MSGDEF2[msgtype])
            sid = w.register_schema(name, "ros1msg" if ros1 else "ros2msg", text.encode())
            channels[topic] = w.register_channel(topic, "ros1" if ros1 else "cdr", sid)
        for topic, msgtype, log, k, values in stream(n_steps, streams, log_offset_ns):
            enc = encoding
            if encoding == "cdr_mixed":
                enc = "cdr_be" if k % 2 else "cdr"
            w.add_message(channels[topic], log_time=log, publish_time=log,
                          data=payload(msgtype, values, enc), sequence=k)
        w.finish()
    return path


def write_with_ros2_writer(path: Path, n_steps: int = 200, **kwargs) -> Path:
    with open(path, "wb") as f:
        w = Ros2Writer(f, **kwargs)
        schemas = {t: w.register_msgdef(ros2_name(t), MSGDEF2[t]) for t in TYPES}
        for topic, msgtype, log, _, values in stream(n_steps):
            w.write_message(topic, schemas[msgtype], values, log_time=log)
        w.finish()
    return path


def write_with_ros1_writer(path: Path, n_steps: int = 200, **kwargs) -> Path:
    with open(path, "wb") as f:
        w = Ros1Writer(f, **kwargs)
        for topic, msgtype, log, _, values in stream(n_steps):
            w.write_message(topic, genpy_message(msgtype, values), log_time=log)
        w.finish()
    return path


# --------------------------------------------------------------------------- the oracle


def library_arrays(path: Path) -> tuple[dict[str, tuple[str, dict[str, np.ndarray]]], dict]:
    """Per supported topic: (type, expected arrays) from mcap's iteration + the ROS decoders;
    and per topic (count, first log, last log) over every topic."""
    per: dict[str, tuple[str, list, list]] = {}
    spans: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[Ros2DecoderFactory(), Ros1DecoderFactory()])
        for schema, channel, message, obj in reader.iter_decoded_messages(log_time_order=True):
            span = spans.setdefault(channel.topic, [0, message.log_time, message.log_time])
            span[0] += 1
            span[1] = min(span[1], message.log_time)
            span[2] = max(span[2], message.log_time)
            msgtype = normalise_type(schema.name)
            if msgtype in SUPPORTED_TYPES:
                entry = per.setdefault(channel.topic, (msgtype, [], []))
                entry[1].append(message.log_time)
                entry[2].append(obj)
    out = {}
    for topic, (msgtype, logs, objs) in per.items():
        arrays = expected_from_objects(msgtype, objs)
        arrays["log_ns"] = np.array(logs, dtype=np.int64)
        out[topic] = (msgtype, arrays)
    return out, {t: tuple(s) for t, s in spans.items()}


def decoded(contents) -> dict:
    return {**contents.imu, **contents.fix, **contents.twist}


def assert_same_arrays(actual, expected: dict[str, np.ndarray], what: str) -> None:
    for name, want in expected.items():
        got = getattr(actual, name)
        assert got.shape == want.shape and got.dtype == want.dtype, f"{what}: {name}"
        if got.dtype.kind == "f":  # bit for bit: NaNs and signed zeros too
            assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), f"{what}: {name}"
        else:
            assert np.array_equal(got, want), f"{what}: {name}"


def assert_matches_library(path: Path) -> None:
    """read_mcap (fast and library engines) = the libraries, topic by topic, message by message."""
    expected, spans = library_arrays(path)
    fast = read_mcap(path)
    slow = read_mcap(path, engine="library")
    assert fast.warnings == ()
    for contents in (fast, slow):
        got = decoded(contents)
        assert set(got) == set(expected)
        for topic, (_msgtype, arrays) in expected.items():
            assert_same_arrays(got[topic], arrays, f"{path.name} {topic}")
        infos = {i.topic: (i.count, i.first_ns, i.last_ns) for i in contents.topics}
        assert infos == spans
    assert fast.topics == slow.topics


# --------------------------------------------------------------------------- formats

FORMATS = [
    pytest.param(CompressionType.ZSTD, True, True, id="zstd-chunked-summary"),
    pytest.param(CompressionType.LZ4, True, True, id="lz4-chunked-summary"),
    pytest.param(CompressionType.NONE, True, True, id="none-chunked-summary"),
    pytest.param(CompressionType.ZSTD, True, False, id="zstd-chunked-nosummary"),
    pytest.param(CompressionType.LZ4, True, False, id="lz4-chunked-nosummary"),
    pytest.param(CompressionType.NONE, False, True, id="unchunked-summary"),
    pytest.param(CompressionType.NONE, False, False, id="unchunked-nosummary"),
]


@pytest.mark.parametrize(("compression", "chunked", "summary"), FORMATS)
def test_ros2_cdr_file_matches_the_library(tmp_path: Path, compression, chunked: bool,
                                           summary: bool) -> None:
    path = write_raw(tmp_path / "log.mcap", compression=compression, use_chunking=chunked,
                     summary=summary)
    assert_matches_library(path)


@pytest.mark.parametrize(("compression", "chunked", "summary"), FORMATS[::3])
def test_ros1_file_matches_the_library(tmp_path: Path, compression, chunked: bool,
                                       summary: bool) -> None:
    path = write_raw(tmp_path / "log.mcap", encoding="ros1", compression=compression,
                     use_chunking=chunked, summary=summary)
    assert_matches_library(path)


@pytest.mark.parametrize("encoding", ["cdr_be", "cdr_mixed"])
def test_big_endian_cdr_matches_the_library(tmp_path: Path, encoding: str) -> None:
    path = write_raw(tmp_path / "be.mcap", encoding=encoding)
    assert_matches_library(path)


def test_files_of_the_ros_writers_match_the_library(tmp_path: Path) -> None:
    assert_matches_library(write_with_ros2_writer(tmp_path / "ros2.mcap", chunk_size=4096))
    assert_matches_library(write_with_ros1_writer(tmp_path / "ros1.mcap",
                                                  compression=CompressionType.LZ4))
    default = write_with_ros2_writer(tmp_path / "big_chunks.mcap", n_steps=300)  # one chunk
    assert_matches_library(default)


def test_log_times_out_of_order_come_back_in_log_order(tmp_path: Path) -> None:
    """Late messages across chunks are sorted by log time, stably, as mcap's reader does."""
    path = write_raw(tmp_path / "late.mcap", chunk_size=1024,
                     log_offset_ns=lambda i: -60 * PERIOD_NS if i % 37 == 5 else 0)
    contents = read_mcap(path)
    assert np.all(np.diff(contents.imu["/imu"].log_ns) >= 0)
    assert_matches_library(path)


def test_contents_topics_and_values(tmp_path: Path) -> None:
    path = write_raw(tmp_path / "log.mcap", n_steps=100)
    contents = read_mcap(path)
    assert contents.source == str(path)
    infos = {i.topic: i for i in contents.topics}
    assert list(infos) == [s[0] for s in STREAMS]
    assert infos["/chatter"].msgtype == STRING_TYPE and infos["/chatter"].count == 10
    assert infos["/imu"].msgtype == IMU_TYPE and infos["/imu"].encoding == "cdr"
    assert infos["/imu"].first_ns == T0_NS and infos["/imu"].last_ns == T0_NS + 99 * PERIOD_NS
    assert set(contents.imu) == {"/imu"} and set(contents.fix) == {"/fix"}
    assert set(contents.twist) == {"/vel", "/vel_plain"}
    imu = contents.imu["/imu"]
    assert imu.stamp_ns[0] == T0_NS - 1_500_000 and imu.frame_id == ""
    assert imu.gyro_cov0[0] == -1.0 and imu.gyro[3, 2] == 0.5 + 3e-3
    fix = contents.fix["/fix"]
    assert fix.status.tolist() == [-1, 0, 1, 2]
    assert fix.cov_type.tolist() == [0, 1, 2, 3]
    assert contents.twist["/vel_plain"].cov_diag is None
    assert contents.twist["/vel"].cov_diag.shape == (4, 3)


def test_topic_selection(tmp_path: Path) -> None:
    path = write_raw(tmp_path / "log.mcap", n_steps=60)
    only = read_mcap(path, ["/fix"])
    assert set(only.fix) == {"/fix"} and not only.imu and not only.twist
    assert len(only.topics) == len(STREAMS)  # every topic listed regardless
    assert not decoded(read_mcap(path, []))
    with pytest.raises(InputError, match=r"log\.mcap: topic '/gps' not found .*/fix, /imu"):
        read_mcap(path, ["/imu", "/gps"])
    with pytest.raises(InputError, match=r"topic '/chatter' has type 'std_msgs/String'"):
        read_mcap(path, ["/chatter"])


@pytest.mark.parametrize("summary", [True, False])
def test_list_topics(tmp_path: Path, summary: bool) -> None:
    path = write_raw(tmp_path / "log.mcap", n_steps=60, summary=summary)
    listed = list_topics(path)
    full = read_mcap(path, []).topics
    assert [(i.topic, i.msgtype, i.count, i.encoding) for i in listed] == \
        [(i.topic, i.msgtype, i.count, i.encoding) for i in full]
    if not summary:
        assert listed == full  # scanned: time spans known


def test_non_standard_definition_is_decoded_by_the_library(tmp_path: Path) -> None:
    """An Imu schema with extra fields: the fast layout does not apply, the library decodes."""
    name = "sensor_msgs/msg/Imu"
    text = MSGDEF2[IMU_TYPE].replace("float64[9] linear_acceleration_covariance",
                                     "float64[9] linear_acceleration_covariance\nuint32 counter", 1)
    encode = serialize_dynamic(name, text)[name]
    path = tmp_path / "custom.mcap"
    with open(path, "wb") as f:
        w = McapWriter(f, chunk_size=1024)
        w.start(profile="ros2", library="navpp tests")
        cid = w.register_channel("/imu", "cdr", w.register_schema(name, "ros2msg", text.encode()))
        for i in range(50):
            values = {**make_message(IMU_TYPE, i), "counter": i}
            w.add_message(cid, log_time=T0_NS + i, publish_time=T0_NS + i, data=bytes(encode(values)))
        w.finish()
    assert_matches_library(path)


def test_channel_without_schema_is_listed_not_decoded(tmp_path: Path) -> None:
    path = tmp_path / "noschema.mcap"
    with open(path, "wb") as f:
        w = McapWriter(f)
        w.start(profile="", library="navpp tests")
        cid = w.register_channel("/raw", "cdr", 0)
        w.add_message(cid, log_time=1, publish_time=1, data=b"\x00\x01\x00\x00")
        w.finish()
    contents = read_mcap(path)
    assert contents.topics[0].topic == "/raw" and contents.topics[0].msgtype == ""
    assert contents.topics[0].count == 1 and not decoded(contents)


# --------------------------------------------------------------------------- damaged files


def _library_prefix_check(full, cut) -> int:
    """Every topic of ``cut`` is a prefix of the same topic in ``full``; messages read."""
    n = 0
    got_full = decoded(full)
    for topic, msgs in decoded(cut).items():
        k = msgs.stamp_ns.shape[0]
        n += k
        ref = got_full[topic]
        for name, value in vars(msgs).items():
            if isinstance(value, np.ndarray):
                want = getattr(ref, name)[:k]
                assert np.array_equal(value.view(np.uint8), np.ascontiguousarray(want).view(np.uint8))
    return n


@pytest.mark.parametrize(("compression", "chunked"), [(CompressionType.ZSTD, True),
                                                      (CompressionType.LZ4, True),
                                                      (CompressionType.NONE, True),
                                                      (CompressionType.NONE, False)])
def test_cut_off_recording_reads_up_to_the_cut(tmp_path: Path, compression, chunked: bool) -> None:
    path = write_raw(tmp_path / "full.mcap", n_steps=400, compression=compression,
                     use_chunking=chunked, chunk_size=8192)
    data = path.read_bytes()
    full = read_mcap(path)
    n_full = sum(m.stamp_ns.shape[0] for m in decoded(full).values())
    previous = -1
    for fraction in (0.3, 0.55, 0.8):
        cut_at = int(len(data) * fraction)
        cut = tmp_path / f"cut{fraction}.mcap"
        cut.write_bytes(data[:cut_at])
        contents = read_mcap(cut)
        n = _library_prefix_check(full, contents)
        assert 0 < n < n_full and n > previous
        previous = n
        assert len(contents.warnings) == 1
        warning = contents.warnings[0]
        last_log = max(m.log_ns[-1] for m in decoded(contents).values())
        last = f"{last_log // 10**9}.{last_log % 10**9:09d} s"
        assert str(cut) in warning and "cut off" in warning and last in warning
        assert code_of(warning) == "recording-cut-off"
        assert f"ends at byte {cut_at} inside the record starting at byte" in warning


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4])
def test_partial_compressed_chunk_is_recovered(tmp_path: Path, compression) -> None:
    """Cut inside a large compressed chunk: the messages of its complete compressed blocks
    (zstd: 128 KiB, lz4: 64 KiB of uncompressed data) are still read."""
    path = write_raw(tmp_path / "full.mcap", n_steps=1500, chunk_size=10**7,
                     compression=compression)  # a single chunk of ~0.6 MB
    data = path.read_bytes()
    with open(path, "rb") as f:
        (chunk,) = make_reader(f).get_summary().chunk_indexes
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunk.chunk_start_offset + chunk.chunk_length // 2])
    contents = read_mcap(cut)
    assert 0 < contents.imu["/imu"].stamp_ns.shape[0] < 1500
    _library_prefix_check(read_mcap(path), contents)


def test_file_without_data_end_and_footer_reads_everything_with_a_warning(tmp_path: Path) -> None:
    path = write_raw(tmp_path / "full.mcap", n_steps=100)
    data = path.read_bytes()
    with open(path, "rb") as f:
        reader = make_reader(f)
        last_chunk = reader.get_summary().chunk_indexes[-1]
    end = last_chunk.chunk_start_offset + last_chunk.chunk_length + last_chunk.message_index_length
    cut = tmp_path / "nofooter.mcap"
    cut.write_bytes(data[:end])
    contents = read_mcap(cut)
    assert contents.imu["/imu"].stamp_ns.shape[0] == 100
    assert "without a DataEnd record" in contents.warnings[0]
    assert [i.count for i in list_topics(cut)] == [i.count for i in read_mcap(path).topics]


def test_header_only_file_has_no_messages(tmp_path: Path) -> None:
    path = write_raw(tmp_path / "full.mcap", n_steps=10)
    cut = tmp_path / "head.mcap"
    cut.write_bytes(path.read_bytes()[:12])
    contents = read_mcap(cut)
    assert not decoded(contents) and "no message could be read" in contents.warnings[0]


def _chunk_data_offset(path: Path, k: int) -> tuple[int, int, object]:
    """(file offset of chunk k's (compressed) data, its length, its index record)."""
    with open(path, "rb") as f:
        idx = make_reader(f).get_summary().chunk_indexes[k]
    head = idx.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + len(idx.compression) + 8
    return head, idx.compressed_size, idx


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4,
                                         CompressionType.NONE])
def test_corrupted_chunk_is_an_input_error(tmp_path: Path, compression) -> None:
    path = write_raw(tmp_path / "log.mcap", n_steps=200, compression=compression)
    start, size, idx = _chunk_data_offset(path, 2)
    data = bytearray(path.read_bytes())
    for k in range(start + size // 2, start + size // 2 + 4):
        data[k] ^= 0x5A
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    t0 = f"{idx.message_start_time // 10**9}.{idx.message_start_time % 10**9:09d} s"
    with pytest.raises(InputError, match=rf"bad\.mcap: chunk at byte {idx.chunk_start_offset} "
                                         rf"\(log time {t0} to .*\) is corrupted") as err:
        read_mcap(bad)
    assert "\n" not in str(err.value)
    if compression == CompressionType.NONE:
        assert "CRC mismatch" in str(err.value)
    with pytest.raises(InputError, match=r"bad\.mcap"):
        read_mcap(bad, engine="library")


def test_corruption_without_crc_in_the_record_structure_is_detected(tmp_path: Path) -> None:
    """No CRC stored: a damaged record length inside a chunk is still caught."""
    path = write_raw(tmp_path / "log.mcap", n_steps=100, compression=CompressionType.NONE,
                     enable_crcs=False)
    start, _, _ = _chunk_data_offset(path, 1)
    data = bytearray(path.read_bytes())
    data[start + 1: start + 9] = (10**9).to_bytes(8, "little")  # first record's length
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"chunk at byte \d+ .*is corrupted: record at offset 0"):
        read_mcap(bad)


def test_not_an_mcap_and_empty_file(tmp_path: Path) -> None:
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("t,gx,gy,gz\n0,0,0,0\n")
    for fn in (read_mcap, list_topics):
        with pytest.raises(InputError, match=r"empty\.mcap: empty file"):
            fn(empty)
        with pytest.raises(InputError, match=r"notes\.mcap: not an MCAP file"):
            fn(text)
        with pytest.raises(InputError, match=r"missing\.mcap: cannot read"):
            fn(tmp_path / "missing.mcap")
