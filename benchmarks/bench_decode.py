"""MCAP decoding speed: navpp's bulk reader against the library decoders, in the same run.

Writes (once; cached in a temp directory) a ROS 2 MCAP of a 1-hour drive: ``sensor_msgs/Imu``
at 125 Hz on ``/imu`` and ``sensor_msgs/NavSatFix`` at 5 Hz on ``/fix``, zstd chunks of 1 MiB
(the ``mcap`` writer's defaults), then reports messages per second for

* ``navpp.io.mcap.read_mcap`` (the fast path: bulk chunk scan + numba field decoding), with its
  peak traced memory relative to the decoded arrays;
* ``mcap_ros2.reader.read_ros2_messages`` (``mcap``'s iteration + the ``mcap_ros2`` decoder);
* ``rosbags``' ``Typestore.deserialize_cdr`` over the same payloads (already in memory: the
  timing excludes reading the file).

It also checks that the three agree on the IMU values.

    python benchmarks/bench_decode.py [--minutes 60] [--cache-dir DIR] [--repeat 3]
"""

from __future__ import annotations

import argparse
import gc
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

IMU_RATE_HZ = 125.0
FIX_RATE_HZ = 5.0
T0_NS = 1_700_000_000 * 1_000_000_000
IMU_FRAME = "imu_link"
FIX_FRAME = "gnss"


def _imu_payloads(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` little-endian CDR ``sensor_msgs/Imu`` payloads (frame_id ``imu_link``) as a
    (n, 324) uint8 array, and their header stamps (ns).

    Layout: encapsulation 00 01 00 00; stamp at 4; frame_id length 9 at 12 and "imu_link\\0" at
    16; padding to 28 (8-byte alignment counted from byte 4); 37 float64 from 28.
    """
    dtype = np.dtype({
        "names": ["encap", "sec", "nanosec", "frame_len", "frame", "orientation", "orientation_cov",
                  "gyro", "gyro_cov", "accel", "accel_cov"],
        "formats": ["<u4", "<i4", "<u4", "<u4", "S9", ("<f8", 4), ("<f8", 9), ("<f8", 3),
                    ("<f8", 9), ("<f8", 3), ("<f8", 9)],
        "offsets": [0, 4, 8, 12, 16, 28, 60, 132, 156, 228, 252],
        "itemsize": 324,
    })
    rec = np.zeros(n, dtype=dtype)
    stamps = T0_NS + np.round(np.arange(n) * 1e9 / IMU_RATE_HZ).astype(np.int64)
    rec["encap"] = 0x00000100  # bytes 00 01 00 00: CDR_LE
    rec["sec"] = stamps // 1_000_000_000
    rec["nanosec"] = stamps % 1_000_000_000
    rec["frame_len"] = len(IMU_FRAME) + 1
    rec["frame"] = IMU_FRAME.encode()
    rec["orientation"][:, 3] = 1.0
    rec["orientation_cov"][:, 0] = -1.0
    rec["gyro"] = rng.normal(0.0, 0.01, (n, 3))
    rec["gyro_cov"][:, [0, 4, 8]] = 1e-6
    rec["accel"] = rng.normal(0.0, 0.05, (n, 3)) + [0.0, 0.0, 9.81]
    rec["accel_cov"][:, [0, 4, 8]] = 1e-4
    return rec.view(np.uint8).reshape(n, dtype.itemsize), stamps


def _fix_payloads(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` CDR ``sensor_msgs/NavSatFix`` payloads (frame_id ``gnss``): (n, 125) uint8."""
    dtype = np.dtype({
        "names": ["encap", "sec", "nanosec", "frame_len", "frame", "status", "service", "lla",
                  "cov", "cov_type"],
        "formats": ["<u4", "<i4", "<u4", "<u4", "S5", "i1", "<u2", ("<f8", 3), ("<f8", 9), "u1"],
        "offsets": [0, 4, 8, 12, 16, 21, 22, 28, 52, 124],
        "itemsize": 125,
    })
    rec = np.zeros(n, dtype=dtype)
    stamps = T0_NS + np.round(np.arange(n) * 1e9 / FIX_RATE_HZ).astype(np.int64)
    rec["encap"] = 0x00000100
    rec["sec"] = stamps // 1_000_000_000
    rec["nanosec"] = stamps % 1_000_000_000
    rec["frame_len"] = len(FIX_FRAME) + 1
    rec["frame"] = FIX_FRAME.encode()
    rec["service"] = 1
    rec["lla"] = np.column_stack([48.1 + rng.normal(0, 1e-5, n), 11.5 + rng.normal(0, 1e-5, n),
                                  520.0 + rng.normal(0, 0.5, n)])
    rec["cov"][:, [0, 4, 8]] = [0.25, 0.25, 1.0]
    rec["cov_type"] = 2
    return rec.view(np.uint8).reshape(n, dtype.itemsize), stamps


def write_log(path: Path, minutes: float, seed: int = 7) -> None:
    """Write the benchmark MCAP (ROS 2, zstd chunks, with summary) to ``path``."""
    from mcap.writer import CompressionType, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    rng = np.random.default_rng(seed)
    n_imu = int(minutes * 60 * IMU_RATE_HZ)
    n_fix = int(minutes * 60 * FIX_RATE_HZ)
    imu, imu_stamps = _imu_payloads(n_imu, rng)
    fix, fix_stamps = _fix_payloads(n_fix, rng)
    # Log (receive) time: the stamp plus 0.5 to 3 ms of transport latency.
    imu_log = imu_stamps + rng.integers(500_000, 3_000_000, n_imu)
    fix_log = fix_stamps + rng.integers(20_000_000, 60_000_000, n_fix)
    tmp = path.with_suffix(".part")
    with open(tmp, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="navpp bench_decode")
        ids = {}
        for topic, typename in (("/imu", "sensor_msgs/msg/Imu"), ("/fix", "sensor_msgs/msg/NavSatFix")):
            text, _ = store.generate_msgdef(typename, ros_version=2)
            sid = w.register_schema(typename, "ros2msg", text.encode())
            ids[topic] = w.register_channel(topic, "cdr", sid)
        # Merge the two streams in log-time order, as a recorder would write them.
        topic_of = np.concatenate([np.zeros(n_imu, np.int8), np.ones(n_fix, np.int8)])
        index = np.concatenate([np.arange(n_imu), np.arange(n_fix)])
        log = np.concatenate([imu_log, fix_log])
        order = np.argsort(log, kind="stable")
        imu_bytes, fix_bytes = imu.tobytes(), fix.tobytes()
        isz, fsz = imu.shape[1], fix.shape[1]
        add = w.add_message
        imu_id, fix_id = ids["/imu"], ids["/fix"]
        for k, i, t in zip(topic_of[order].tolist(), index[order].tolist(), log[order].tolist()):
            if k == 0:
                add(channel_id=imu_id, log_time=t, publish_time=t, data=imu_bytes[i * isz:(i + 1) * isz])
            else:
                add(channel_id=fix_id, log_time=t, publish_time=t, data=fix_bytes[i * fsz:(i + 1) * fsz])
        w.finish()
    tmp.replace(path)


def _best_of(repeat: int, fn):
    best, result = float("inf"), None
    for _ in range(repeat):
        gc.collect()
        t = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0, help="log duration (default 60)")
    parser.add_argument("--cache-dir", type=Path,
                        default=Path(tempfile.gettempdir()) / "navpp-bench-decode")
    parser.add_argument("--repeat", type=int, default=3, help="best of N for the fast path")
    args = parser.parse_args()

    from navpp.io.mcap import read_mcap

    args.cache_dir.mkdir(parents=True, exist_ok=True)
    path = args.cache_dir / f"imu125-fix5-{args.minutes:g}min-zstd.mcap"
    if not path.exists():
        t = time.perf_counter()
        write_log(path, args.minutes)
        print(f"wrote {path} in {time.perf_counter() - t:.1f} s")
    size_mb = path.stat().st_size / 2**20

    read_mcap(path, ["/fix"])  # load (or compile) the numba kernels outside the timing
    t_fast, contents = _best_of(args.repeat, lambda: read_mcap(path))
    imu, fix = contents.imu["/imu"], contents.fix["/fix"]
    n_total = imu.stamp_ns.shape[0] + fix.stamp_ns.shape[0]
    decoded_bytes = sum(v.nbytes for m in (imu, fix) for v in vars(m).values()
                        if isinstance(v, np.ndarray))
    del contents
    gc.collect()
    tracemalloc.start()
    read_mcap(path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()

    # mcap_ros2: mcap's message iteration + the mcap_ros2 decoder (one object per message).
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

    def ros2_pass() -> tuple[int, np.ndarray]:
        n = 0
        gyro_x = np.empty(imu.stamp_ns.shape[0])
        k = 0
        for m in read_ros2_messages(str(path)):
            n += 1
            if m.channel.topic == "/imu":
                gyro_x[k] = m.ros_msg.angular_velocity.x
                k += 1
        return n, gyro_x

    t_ros2, (n_ros2, gyro_x_ros2) = _best_of(1, ros2_pass)

    # rosbags deserialize_cdr over the same payloads, already in memory.
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    with open(path, "rb") as f:
        payloads = [(ch.topic, msg.data) for _, ch, msg in make_reader(f).iter_messages()]
    names = {"/imu": "sensor_msgs/msg/Imu", "/fix": "sensor_msgs/msg/NavSatFix"}

    def rosbags_pass() -> np.ndarray:
        gyro_x = []
        for topic, data in payloads:
            msg = store.deserialize_cdr(data, names[topic])
            if topic == "/imu":
                gyro_x.append(msg.angular_velocity.x)
        return np.array(gyro_x)

    t_rb, gyro_x_rb = _best_of(1, rosbags_pass)

    same = (n_ros2 == n_total and np.array_equal(gyro_x_ros2, imu.gyro[:, 0])
            and np.array_equal(gyro_x_rb, imu.gyro[:, 0]))
    rate_fast = n_total / t_fast
    print(f"log: {path.name}, {size_mb:.1f} MiB, {imu.stamp_ns.shape[0]} Imu + "
          f"{fix.stamp_ns.shape[0]} NavSatFix messages")
    print(f"navpp read_mcap (fast path)      {t_fast:8.3f} s  {rate_fast:12,.0f} msg/s")
    print(f"mcap_ros2 read_ros2_messages     {t_ros2:8.3f} s  {n_ros2 / t_ros2:12,.0f} msg/s  "
          f"({rate_fast / (n_ros2 / t_ros2):.0f}x slower)")
    print(f"rosbags deserialize_cdr (in mem) {t_rb:8.3f} s  {len(payloads) / t_rb:12,.0f} msg/s  "
          f"({rate_fast / (len(payloads) / t_rb):.0f}x slower)")
    print(f"read_mcap peak traced memory {peak / 2**20:.1f} MiB = {peak / decoded_bytes:.2f} x the "
          f"decoded arrays ({decoded_bytes / 2**20:.1f} MiB)")
    print(f"all three decoders agree on the IMU values: {same}")
    if not same:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
