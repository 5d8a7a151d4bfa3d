"""Bulk message decoding (navpp.io.messages) against the libraries' own decoders.

Payloads are made by the libraries: ``mcap_ros2``'s encoder (little-endian CDR), ``rosbags``'
``serialize_cdr(little_endian=False)`` (big-endian CDR) and ``cdr_to_ros1`` (ROS 1), and every
decoded value is compared bit for bit with ``mcap_ros2`` / ``mcap_ros1`` / ``rosbags``
decoding the same bytes one message at a time.
"""

from __future__ import annotations

import io
import math
import struct

import numpy as np
import pytest
from mcap.records import Schema
from mcap_ros1._vendor.genpy.dynamic import generate_dynamic
from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
from ros_oracles import expected_from_objects, fill_genpy, ros2_name
from rosbags.typesys import Stores, get_typestore

from navpp.errors import InputError
from navpp.io.messages import (
    TopicDecoder,
    build_messages,
    decode,
    decode_with_library,
    schema_is_standard,
)
from navpp.io.ros import (
    FIX_TYPE,
    IMU_TYPE,
    ODOM_TYPE,
    SUPPORTED_TYPES,
    TWIST_COV_TYPE,
    TWIST_TYPE,
    FixMessages,
    ImuMessages,
    TwistMessages,
)

STORE2 = get_typestore(Stores.ROS2_HUMBLE)
STORE1 = get_typestore(Stores.ROS1_NOETIC)


MSGDEF2 = {t: STORE2.generate_msgdef(ros2_name(t), ros_version=2)[0] for t in SUPPORTED_TYPES}
MSGDEF1 = {t: STORE1.generate_msgdef(ros2_name(t), ros_version=1)[0] for t in SUPPORTED_TYPES}
GENPY = {t: generate_dynamic(t, MSGDEF1[t])[t] for t in SUPPORTED_TYPES}
ENCODE2 = {t: serialize_dynamic(ros2_name(t), MSGDEF2[t])[ros2_name(t)] for t in SUPPORTED_TYPES}

#: Values that must survive bit for bit.
SPECIAL = [math.nan, math.inf, -math.inf, -0.0, 5e-324, 1.7976931348623157e308,
           struct.unpack("<d", struct.pack("<Q", 0x7FF8_0000_DEAD_BEEF))[0]]


def _f(rng: np.random.Generator, i: int, k: int) -> float:
    """A float: mostly random, sometimes a special value."""
    if (i * 7 + k) % 23 == 0:
        return SPECIAL[(i + k) % len(SPECIAL)]
    return float(rng.normal(0.0, 10.0 ** rng.integers(-6, 4)))


def make_message(msgtype: str, i: int, rng: np.random.Generator, frame_id: str,
                 sec: int | None = None) -> dict:
    """A message as the nested dict mcap_ros2's encoder takes."""
    sec = int(1_700_000_000 + i) if sec is None else sec
    header = {"stamp": {"sec": sec, "nanosec": int(rng.integers(0, 1_000_000_000))},
              "frame_id": frame_id}

    def vec(k: int) -> dict:
        return {"x": _f(rng, i, k), "y": _f(rng, i, k + 1), "z": _f(rng, i, k + 2)}

    def arr(n: int, k: int) -> list[float]:
        return [_f(rng, i, k + j) for j in range(n)]

    if msgtype == IMU_TYPE:
        return {"header": header,
                "orientation": {"x": _f(rng, i, 0), "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": arr(9, 1), "angular_velocity": vec(10),
                "angular_velocity_covariance": [-1.0 if i % 3 == 0 else _f(rng, i, 13)] + arr(8, 14),
                "linear_acceleration": vec(22),
                "linear_acceleration_covariance": arr(9, 25)}
    if msgtype == FIX_TYPE:
        return {"header": header,
                "status": {"status": [-1, 0, 1, 2][i % 4], "service": [1, 2, 4, 8, 15][i % 5]},
                "latitude": _f(rng, i, 0), "longitude": _f(rng, i, 1), "altitude": _f(rng, i, 2),
                "position_covariance": arr(9, 3), "position_covariance_type": i % 4}
    twist = {"linear": vec(0), "angular": vec(3)}
    if msgtype == TWIST_COV_TYPE:
        return {"header": header, "twist": {"twist": twist, "covariance": arr(36, 6)}}
    if msgtype == ODOM_TYPE:  # a second string (child_frame_id) of 0..6 characters moves the fields
        pose = {"position": vec(42), "orientation": {"x": _f(rng, i, 45), "y": 0.0, "z": 0.0, "w": 1.0}}
        return {"header": header, "child_frame_id": "base_link"[: (i * 3) % 7],
                "pose": {"pose": pose, "covariance": arr(36, 46)},
                "twist": {"twist": twist, "covariance": arr(36, 6)}}
    return {"header": header, "twist": twist}


def ros1_payload(msgtype: str, message: dict) -> bytes:
    """ROS 1 serialization by genpy (the serializer mcap_ros1's writer uses)."""
    obj = GENPY[msgtype]()

    fill_genpy(obj, message)
    buf = io.BytesIO()
    obj.serialize(buf)
    return buf.getvalue()


def payloads_for(msgtype: str, encoding: str, n: int, seed: int = 0) -> list[bytes]:
    """``n`` library-serialized payloads with frame_ids of 0..9 characters.

    ``encoding``: ``cdr_le`` (mcap_ros2 encoder), ``cdr_be`` (rosbags, big endian), ``cdr_mixed``
    (alternating), ``ros1`` (rosbags cdr_to_ros1).
    """
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        frame_id = "abcdefghij"[: i % 10]
        le = bytes(ENCODE2[msgtype](make_message(msgtype, i, rng, frame_id)))
        big = encoding == "cdr_be" or (encoding == "cdr_mixed" and i % 2 == 1)
        if big:
            obj = STORE2.deserialize_cdr(le, ros2_name(msgtype))
            out.append(bytes(STORE2.serialize_cdr(obj, ros2_name(msgtype), little_endian=False)))
        elif encoding == "ros1":
            out.append(ros1_payload(msgtype, make_message(msgtype, i, rng, frame_id)))
        else:
            out.append(le)
    return out


def library_decoder(msgtype: str, encoding: str):
    """mcap_ros2 / mcap_ros1's decoder built from the standard schema text."""
    if encoding == "ros1":
        schema = Schema(id=1, name=msgtype, encoding="ros1msg", data=MSGDEF1[msgtype].encode())
        return Ros1DecoderFactory().decoder_for("ros1", schema)
    schema = Schema(id=1, name=ros2_name(msgtype), encoding="ros2msg",
                    data=MSGDEF2[msgtype].encode())
    return Ros2DecoderFactory().decoder_for("cdr", schema)


def assert_bitwise_equal(actual: np.ndarray, expected: np.ndarray, name: str) -> None:
    """Exact equality, NaN payloads and signed zeros included."""
    assert actual.shape == expected.shape, name
    assert actual.dtype == expected.dtype, name
    if actual.dtype.kind == "f":
        assert np.array_equal(actual.view(np.uint64), expected.view(np.uint64)), name
    else:
        assert np.array_equal(actual, expected), name


def assert_matches(result, expected: dict[str, np.ndarray]) -> None:
    for name, want in expected.items():
        assert_bitwise_equal(getattr(result, name), want, name)


# --------------------------------------------------------------------------- fast path = library

CASES = [(t, e) for t in SUPPORTED_TYPES for e in ("cdr_le", "cdr_be", "cdr_mixed", "ros1")]


@pytest.mark.parametrize(("msgtype", "encoding"), CASES)
def test_fast_path_equals_library_decoders(msgtype: str, encoding: str) -> None:
    payloads = payloads_for(msgtype, encoding, 40, seed=hash(encoding) % 1000)
    wire = "ros1" if encoding == "ros1" else "cdr"
    log_ns = np.arange(40, dtype=np.int64) * 7 + 3
    dec = TopicDecoder("/t", msgtype, wire, source="log.mcap",
                       schema_text=(MSGDEF1 if wire == "ros1" else MSGDEF2)[msgtype])
    dec.add(*_buffer(payloads), log_ns)
    result = dec.result()
    assert dec.fast and dec.n_fallback == 0
    lib = library_decoder(msgtype, wire)
    assert_matches(result, expected_from_objects(msgtype, [lib(p) for p in payloads]))
    # rosbags agrees as well (its own deserializer, ROS 1 and CDR).
    if wire == "ros1":
        objs = [STORE1.deserialize_ros1(p, ros2_name(msgtype)) for p in payloads]
    else:
        objs = [STORE2.deserialize_cdr(p, ros2_name(msgtype)) for p in payloads]
    assert_matches(result, expected_from_objects(msgtype, objs))
    assert np.array_equal(result.log_ns, log_ns)
    assert result.topic == "/t"
    assert result.frame_id == ""  # message 0 has the empty frame_id
    expected_type = {IMU_TYPE: ImuMessages, FIX_TYPE: FixMessages}.get(msgtype, TwistMessages)
    assert isinstance(result, expected_type)


def _buffer(payloads: list[bytes], gap: bytes = b"") -> tuple[bytes, np.ndarray, np.ndarray]:
    """(buffer, starts, lengths) with ``gap`` bytes between payloads."""
    lengths = np.array([len(p) for p in payloads], dtype=np.int64)
    starts = np.cumsum([0] + [len(p) + len(gap) for p in payloads[:-1]]).astype(np.int64)
    return gap.join(payloads), starts, lengths


def test_decode_accepts_payload_list_and_spans_in_a_shared_buffer() -> None:
    payloads = payloads_for(IMU_TYPE, "cdr_le", 25, seed=4)
    log_ns = np.arange(25)
    from_list = decode("sensor_msgs/msg/Imu", "cdr", payloads, log_ns, "/imu")
    from_spans = decode(IMU_TYPE, "cdr", _buffer(payloads, gap=b"\xff" * 5), log_ns, "/imu")
    from_views = decode(IMU_TYPE, "cdr", [memoryview(p) for p in payloads], log_ns, "/imu")
    for other in (from_spans, from_views):
        for name in ("stamp_ns", "gyro", "accel", "gyro_cov0", "accel_cov0"):
            assert_bitwise_equal(getattr(other, name), getattr(from_list, name), name)


def test_output_arrays_have_the_contract_dtypes_and_shapes() -> None:
    imu = decode(IMU_TYPE, "cdr", payloads_for(IMU_TYPE, "cdr_le", 5), np.arange(5), "/imu")
    assert imu.gyro.shape == (5, 3) and imu.gyro.flags.c_contiguous and imu.gyro.dtype == np.float64
    assert imu.stamp_ns.dtype == np.int64 and imu.log_ns.dtype == np.int64
    fix = decode(FIX_TYPE, "ros1", payloads_for(FIX_TYPE, "ros1", 5), np.arange(5), "/fix")
    assert fix.status.dtype == np.int8 and fix.cov_type.dtype == np.uint8
    assert fix.cov.shape == (5, 9) and fix.cov.flags.c_contiguous
    tw = decode(TWIST_TYPE, "cdr", payloads_for(TWIST_TYPE, "cdr_le", 5), np.arange(5), "/v")
    assert tw.cov_diag is None and tw.vel.shape == (5, 3)
    twc = decode(TWIST_COV_TYPE, "cdr", payloads_for(TWIST_COV_TYPE, "cdr_le", 5), np.arange(5), "/v")
    assert twc.cov_diag is not None and twc.cov_diag.shape == (5, 3)


def test_empty_topic_decodes_to_empty_arrays() -> None:
    imu = decode(IMU_TYPE, "cdr", [], np.zeros(0), "/imu")
    assert imu.gyro.shape == (0, 3) and imu.stamp_ns.shape == (0,)


def test_stamp_edge_cases_match_the_libraries() -> None:
    """sec = 0, negative (int32 in ROS 2) and the largest uint32 (ROS 1)."""
    rng = np.random.default_rng(1)
    cdr_secs = [0, -5, 2**31 - 1, -(2**31)]
    cdr = [bytes(ENCODE2[IMU_TYPE](make_message(IMU_TYPE, i, rng, "x" * i, sec=s)))
           for i, s in enumerate(cdr_secs)]
    got = decode(IMU_TYPE, "cdr", cdr, np.arange(4), "/imu")
    lib = library_decoder(IMU_TYPE, "cdr")
    assert_matches(got, expected_from_objects(IMU_TYPE, [lib(p) for p in cdr]))
    assert got.stamp_ns[1] < 0
    big = ros1_payload(IMU_TYPE, make_message(IMU_TYPE, 0, rng, "imu", sec=2**32 - 1))
    got1 = decode(IMU_TYPE, "ros1", [big], [0], "/imu")
    lib1 = library_decoder(IMU_TYPE, "ros1")
    assert_matches(got1, expected_from_objects(IMU_TYPE, [lib1(big)]))
    assert got1.stamp_ns[0] >= (2**32 - 1) * 1_000_000_000


def test_frame_id_of_the_first_message_is_kept() -> None:
    rng = np.random.default_rng(2)
    for encoding in ("cdr", "ros1"):
        p = bytes(ENCODE2[FIX_TYPE](make_message(FIX_TYPE, 0, rng, "gnss_ant")))
        if encoding == "ros1":
            p = ros1_payload(FIX_TYPE, make_message(FIX_TYPE, 0, rng, "gnss_ant"))
        assert decode(FIX_TYPE, encoding, [p], [0], "/fix").frame_id == "gnss_ant"


# --------------------------------------------------------------------------- schemas and fallback


@pytest.mark.parametrize("msgtype", SUPPORTED_TYPES)
def test_standard_schemas_are_recognised(msgtype: str) -> None:
    assert schema_is_standard(msgtype, "cdr", MSGDEF2[msgtype])
    assert schema_is_standard(ros2_name(msgtype), "ros1", MSGDEF1[msgtype])
    # ROS 1 recorders write "Header header" at the top and comments everywhere.
    text = MSGDEF1[msgtype].replace("std_msgs/Header header", "Header header  # stamp!")
    assert schema_is_standard(msgtype, "ros1", "# a comment\n" + text)


def test_non_standard_schemas_are_detected() -> None:
    extra = MSGDEF2[IMU_TYPE].replace(
        "float64[9] linear_acceleration_covariance",
        "float64[9] linear_acceleration_covariance\nfloat32 temperature", 1)
    assert not schema_is_standard(IMU_TYPE, "cdr", extra)
    float32_vec = MSGDEF2[IMU_TYPE].replace("MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z",
                                            "MSG: geometry_msgs/Vector3\nfloat32 x\nfloat32 y\nfloat32 z")
    assert float32_vec != MSGDEF2[IMU_TYPE]
    assert not schema_is_standard(IMU_TYPE, "cdr", float32_vec)
    assert not schema_is_standard(IMU_TYPE, "ros1", MSGDEF2[IMU_TYPE])  # ROS 2 Header in ROS 1
    assert not schema_is_standard("std_msgs/String", "cdr", "string data")


def test_topic_with_a_non_standard_schema_goes_through_the_library_decoder() -> None:
    name = "sensor_msgs/msg/Imu"
    text = MSGDEF2[IMU_TYPE].replace(
        "float64[9] linear_acceleration_covariance",
        "float64[9] linear_acceleration_covariance\nfloat32 temperature\nstring note", 1)
    encode = serialize_dynamic(name, text)[name]
    rng = np.random.default_rng(3)
    msgs = []
    for i in range(12):
        m = make_message(IMU_TYPE, i, rng, "imu"[: i % 4])
        m.update(temperature=20.5 + i, note="n" * i)
        msgs.append(m)
    payloads = [bytes(encode(m)) for m in msgs]
    dec = TopicDecoder("/imu", IMU_TYPE, "cdr", source="x.mcap", schema_name=name, schema_text=text)
    dec.add(*_buffer(payloads), np.arange(12))
    got = dec.result()
    assert not dec.fast and dec.n_fallback == 12
    schema = Schema(id=1, name=name, encoding="ros2msg", data=text.encode())
    lib = Ros2DecoderFactory().decoder_for("cdr", schema)
    assert_matches(got, expected_from_objects(IMU_TYPE, [lib(p) for p in payloads]))
    # Without the schema, the longer payloads are not Imu messages: a clear error.
    with pytest.raises(InputError, match=r"x\.mcap: topic '/imu', message #0 .*cannot decode"):
        decode(IMU_TYPE, "cdr", payloads, np.arange(12), "/imu", source="x.mcap")


def test_definition_without_the_needed_fields_is_an_input_error() -> None:
    name = "sensor_msgs/Imu"
    text = "Header header\nfloat64 temperature\n" + MSGDEF1[IMU_TYPE].split("\n", 7)[-1]
    assert not schema_is_standard(IMU_TYPE, "ros1", text)
    schema = Schema(id=1, name=name, encoding="ros1msg", data=text.encode())
    cls = Ros1DecoderFactory().decoder_for("ros1", schema)(b"\0" * 200).__class__
    m = cls()
    m.header.frame_id = "f"
    buf = io.BytesIO()
    m.serialize(buf)
    with pytest.raises(InputError, match=r"b\.mcap: topic '/imu', message #0 .*unknown message "
                                         r"definition.*angular_velocity"):
        decode(IMU_TYPE, "ros1", [buf.getvalue()], [5], "/imu", source="b.mcap",
               schema_name=name, schema_text=text)


def test_truncated_payload_names_topic_index_and_time() -> None:
    payloads = payloads_for(IMU_TYPE, "cdr_le", 6)
    payloads[4] = payloads[4][:-20]
    log_ns = np.arange(6, dtype=np.int64) * 1_000_000_000 + 1_700_000_000_000_000_000
    with pytest.raises(InputError, match=r"d\.mcap: topic '/imu', message #4 \(log time "
                                         r"1700000004\.000000000 s\): cannot decode .*shorter"):
        decode(IMU_TYPE, "cdr", payloads, log_ns, "/imu", source="d.mcap")


def test_unsupported_cdr_encapsulation_is_an_input_error() -> None:
    payloads = payloads_for(FIX_TYPE, "cdr_le", 3)
    payloads[1] = b"\x00\x07" + payloads[1][2:]  # CDR2_LE: different alignment rules
    with pytest.raises(InputError, match=r"message #1 .*unsupported CDR encapsulation 0x0007"):
        decode(FIX_TYPE, "cdr", payloads, np.arange(3), "/fix", source="e.mcap")


def test_cdr_trailing_padding_is_accepted() -> None:
    """XCDR1 writers may pad a payload to a multiple of 4 bytes."""
    payloads = [p + b"\0" * ((-len(p)) % 4) for p in payloads_for(FIX_TYPE, "cdr_le", 9)]
    dec = TopicDecoder("/fix", FIX_TYPE, "cdr")
    dec.add(*_buffer(payloads), np.arange(9))
    got = dec.result()
    assert dec.n_fallback == 0
    lib = library_decoder(FIX_TYPE, "cdr")
    assert_matches(got, expected_from_objects(FIX_TYPE, [lib(p) for p in payloads]))


def test_unsupported_type_or_encoding_is_an_input_error() -> None:
    with pytest.raises(InputError, match="std_msgs/msg/String"):
        decode("std_msgs/msg/String", "cdr", [], [], "/s")
    with pytest.raises(InputError, match="'json'"):
        decode(IMU_TYPE, "json", [], [], "/imu")


@pytest.mark.parametrize("encoding", ["cdr_le", "cdr_be", "ros1"])
def test_library_fallback_equals_fast_path(encoding: str) -> None:
    """decode_with_library (used for fallbacks and the library engine) = the kernel."""
    wire = "ros1" if encoding == "ros1" else "cdr"
    for msgtype in SUPPORTED_TYPES:
        payloads = payloads_for(msgtype, encoding, 15, seed=9)
        fast = decode(msgtype, wire, payloads, np.arange(15), "/t")
        for text in (None, (MSGDEF1 if wire == "ros1" else MSGDEF2)[msgtype]):
            table, stamps, frame_ids = decode_with_library(msgtype, wire, payloads,
                                                           schema_text=text)
            slow = build_messages(msgtype, "/t", table, stamps, np.arange(15), frame_ids[0])
            for name, value in vars(fast).items():
                if isinstance(value, np.ndarray):
                    assert_bitwise_equal(getattr(slow, name), value, f"{msgtype} {name}")
            assert slow.frame_id == fast.frame_id
