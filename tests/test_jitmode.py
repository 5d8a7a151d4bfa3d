"""Compiled or interpreted kernels (navpp.jitmode): the choice, the cache check, and the
interpreted readers against the compiled kernels they stand in for (the oracle)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp import jitmode
from navpp.cli import app
from navpp.io import mcap as mcap_reader
from navpp.io import messages

SAMPLES = Path(__file__).resolve().parent.parent / "sample_data"
runner = CliRunner()


# --------------------------------------------------------------------------- the choice


def test_decide_takes_the_cheaper_side() -> None:
    """Interpreted when its estimated extra CPU is below the compile cost of the missing groups,
    compiled when every group is cached, when asked, or when a log's size is unknown."""
    small = [(37_500, 39_000, "mcap")]
    big = [(1_200 * 125, 1_200 * 130, "mcap")]     # 20 min: beyond the EKF break-even (about 12.5 min)
    missing = ("ins", "ros", "mcap")
    assert not jitmode.decide("auto", small, ["ekf"], False, missing).compiled
    assert jitmode.decide("auto", big, ["ekf"], False, missing).compiled
    # a sigma-point filter interpreted costs about 2 ms a sample: 37,500 samples outweigh compiling
    assert jitmode.decide("auto", small, ["ckf"], False, (*missing, "sigma")).compiled
    # a process is compiled or interpreted as a whole: with the INS cached, compiling only the
    # smoother's group beats interpreting the whole smoothed run
    assert jitmode.decide("auto", small, ["ekf"], True, ("smooth",)).compiled
    assert not jitmode.decide("auto", [(20_000, 21_000, "mcap")], ["ekf"], True, (*missing, "smooth")).compiled
    assert jitmode.decide("auto", [(75_000, 78_000, "mcap")], ["ekf"], True, (*missing, "smooth")).compiled
    assert jitmode.decide("auto", small, ["ekf"], False, ()).compiled
    assert jitmode.decide("auto", [None], ["ekf"], False, missing).compiled
    assert not jitmode.decide("off", big, ["ckf"], False, ()).compiled
    assert jitmode.decide("on", small, ["ekf"], False, missing).compiled
    choice = jitmode.decide("auto", small, ["ekf"], False, missing)
    assert "to compile (ins, ros, mcap)" in choice.why and "interpreted" in jitmode.note(choice)
    assert jitmode.note(jitmode.decide("on", small, ["ekf"], False, missing)) == ""


def test_workers_are_announced() -> None:
    """compare --jobs N: workers compile on their own, so the parent says so before they start."""
    cold = jitmode.decide("auto", [(900_000, 0, "csv")], ["ekf"], False, ("ins",))
    assert cold.compiled and cold.missing == ("ins",)
    line = jitmode.workers_note(cold, 2)
    assert "each of the 2 worker processes first compiles" in line and "about 94 s" in line
    assert jitmode.workers_note(cold, 1) == ""
    assert jitmode.workers_note(jitmode.decide("auto", [(10, 0, "csv")], ["ekf"], False, ()), 4) == ""


def test_every_group_names_a_kernel_of_its_file() -> None:
    """Each sentinel is a numba kernel defined (not merely imported) in the file it names, so a
    rename or a move cannot leave a group that is never found in the cache."""
    import importlib

    from numba.core.dispatcher import Dispatcher

    for group, kernels in jitmode.GROUPS.items():
        for rel, name in kernels:
            module = importlib.import_module("navpp." + rel.removesuffix(".py").replace("/", "."))
            kernel = getattr(module, name)
            assert isinstance(kernel, Dispatcher), (group, rel, name)
            assert kernel.py_func.__code__.co_filename == str(jitmode._ROOT / rel), (group, rel, name)
            assert jitmode._first_line(jitmode._ROOT / rel, name) == kernel.py_func.__code__.co_firstlineno


def test_needed_groups() -> None:
    assert jitmode.needed_groups([(10, 0, "csv")], ["ekf"], False) == ("ins",)
    assert jitmode.needed_groups([(10, 12, "mcap")], ["vce-ckf", "ckf"], True) == (
        "ins", "ros", "mcap", "sigma", "vce", "smooth")


def test_requested_mode_and_its_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(jitmode.ENV, raising=False)
    assert jitmode.requested(None) == "auto"
    monkeypatch.setenv(jitmode.ENV, "OFF")
    assert jitmode.requested(None) == "off"
    assert jitmode.requested("on") == "on"
    monkeypatch.setenv(jitmode.ENV, "fast")
    with pytest.raises(Exception, match="NAVPP_JIT: unknown mode 'fast'; choose one of auto, on, off"):
        jitmode.requested(None)


def test_sample_counts_from_the_indexes() -> None:
    """37,501 IMU messages in every ROS form of the sample drive (its IMU file: 37,501 rows)."""
    rows = (SAMPLES / "drive" / "imu.csv").read_bytes().count(b"\n") - 1
    assert rows == 37_501
    for log in ("drive.mcap", "drive.bag", "drive_ros2"):
        imu, total, family = jitmode.samples(SAMPLES / log)
        assert (imu, total) == (37_501, 39_002)
        assert family == ("mcap" if log.endswith(".mcap") else "ros")
    est, _, family = jitmode.samples(SAMPLES / "drive")
    assert family == "csv" and abs(est - rows) / rows < 0.05
    assert jitmode.samples(SAMPLES / "no-such-log.mcap") is None


def test_kernel_cached_follows_numba_s_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A kernel this process has compiled or loaded is in the cache; an empty cache holds none."""
    from numba.core import config

    from navpp.filters.linalg import joseph

    P, K, H, R = np.eye(2), np.eye(2) * 0.5, np.eye(2), np.eye(2)
    joseph(P, K, H, R)
    assert jitmode.kernel_cached("filters/linalg.py", "joseph")
    assert not jitmode.kernel_cached("filters/linalg.py", "no_such_kernel")
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))
    assert not jitmode.kernel_cached("filters/linalg.py", "joseph")
    assert jitmode.missing_groups(("ins", "smooth")) == ("ins", "smooth")


# --------------------------------------------------------------------------- interpreted readers


def _payloads(path: Path) -> tuple[dict[str, list[bytes]], dict[str, str]]:
    """Raw payloads per topic of an MCAP file and each topic's message type (mcap library)."""
    from mcap.reader import make_reader

    out: dict[str, list[bytes]] = {}
    kinds: dict[str, str] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append(message.data)
            kinds[channel.topic] = schema.name
    return out, kinds


def _both(payloads: list[bytes], msgtype: str, cdr: bool) -> None:
    """Decode with the compiled kernel and the array version; every output must agree."""
    starts = np.cumsum([0] + [len(p) for p in payloads[:-1]]).astype(np.int64)
    lengths = np.array([len(p) for p in payloads], dtype=np.int64)
    buf = np.frombuffer(b"".join(payloads) + bytes(64), dtype=np.uint8)
    layout = messages._LAYOUTS[msgtype if msgtype in messages._LAYOUTS else msgtype.replace("/msg/", "/")]
    results = []
    for decode in (messages._decode_kernel, messages._decode_arrays):
        out = np.zeros((len(payloads), layout.n_cols), dtype=np.uint64)
        stamps = np.zeros(len(payloads), dtype=np.int64)
        frame_len = np.zeros(len(payloads), dtype=np.int64)
        flag = np.zeros(len(payloads), dtype=np.uint8)
        decode(buf, starts, lengths, cdr, *layout.arrays(), out, stamps, frame_len, flag)
        results.append((out, stamps, frame_len, flag))
    for a, b in zip(*results):
        np.testing.assert_array_equal(a, b)
    return results[0][3]


def _mutated(payloads: list[bytes], rng: np.random.Generator) -> list[bytes]:
    """Cut, padded, re-encapsulated and byte-swapped copies: every flag the decoders give."""
    out = []
    for p in payloads:
        kind = rng.integers(6)
        if kind == 0:
            p = p[: rng.integers(0, len(p))]
        elif kind == 1:
            p = p + bytes(int(rng.integers(1, 12)))
        elif kind == 2 and len(p) > 2:
            p = p[:1] + bytes([int(rng.integers(0, 4))]) + p[2:]
        elif kind == 3 and len(p) > 1:
            p = bytes([1]) + p[1:]
        elif kind == 4 and len(p) > 16:      # a frame_id length that runs past the end
            p = p[:12] + (len(p)).to_bytes(4, "little") + p[16:]
        out.append(p)
    return out


@pytest.mark.parametrize("log", ["drive.mcap", "drive_odometry.mcap"])
def test_decode_arrays_equals_the_kernel(log: str) -> None:
    payloads, kinds = _payloads(SAMPLES / log)
    rng = np.random.default_rng(7)
    for topic, data in payloads.items():
        if kinds[topic] not in messages._LAYOUTS:
            continue
        data = data[:600]
        assert not _both(data, kinds[topic], True).any()           # the file's messages all decode
        flags = _both(_mutated(data, rng), kinds[topic], True)
        assert {0, messages._SHORT, messages._LONG, messages._ENCAPSULATION} <= set(flags.tolist())


def test_decode_arrays_equals_the_kernel_ros1() -> None:
    from rosbags.rosbag1 import Reader

    with Reader(SAMPLES / "drive.bag") as reader:
        per_type: dict[str, list[bytes]] = {}
        for conn, _, raw in reader.messages():
            kept = per_type.setdefault(conn.msgtype.replace("/msg/", "/"), [])
            if len(kept) < 400:
                kept.append(bytes(raw))
    rng = np.random.default_rng(3)
    for msgtype, data in per_type.items():
        assert not _both(data, msgtype, False).any()
        flags = _both(_mutated(data, rng), msgtype, False)
        assert {0, messages._SHORT, messages._LONG} <= set(flags.tolist())


def test_scan_struct_equals_the_kernel() -> None:
    """The top-level record walk of a whole MCAP file, and of spans cut at odd places."""
    buf = np.frombuffer((SAMPLES / "drive_odometry.mcap").read_bytes(), dtype=np.uint8)
    start = 8                                            # after the magic
    cuts = [buf.shape[0], buf.shape[0] - 1, start + 9, start + 100, buf.shape[0] // 2]
    for stop in cuts:
        results = []
        for scan in (mcap_reader._scan_kernel, mcap_reader._scan_struct):
            empty = np.zeros(0, dtype=np.int64)
            n_msg, n_rec, _, _ = scan(buf, start, stop, True, False, *([empty] * 7))
            arrays = [np.zeros(n, dtype=np.int64) for n in (n_msg,) * 4 + (n_rec,) * 3]
            head = scan(buf, start, stop, True, True, *arrays)
            results.append((tuple(int(v) for v in head), arrays))
        assert results[0][0] == results[1][0]
        for a, b in zip(results[0][1], results[1][1]):
            np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- end to end


def _process(args: list[str], env_extra: dict[str, str]) -> subprocess.CompletedProcess:
    env = dict(os.environ, **env_extra)
    return subprocess.run([sys.executable, "-m", "navpp", "process", *args], env=env,
                          capture_output=True, text=True, check=False)


@pytest.mark.parametrize("case", ["ekf", pytest.param("ckf-smooth", marks=pytest.mark.slow)])
def test_interpreted_run_is_byte_identical(tmp_path: Path, case: str) -> None:
    """The same log through interpreted kernels (a child process) and compiled ones (this
    process, which has its kernels compiled): identical trajectory and diagnostics files.  The
    EKF child runs with the command line's default on an empty cache: auto takes interpreted
    for a short log and says so; the CKF one is told --jit off (auto would compile)."""
    import navpp

    log = navpp.simulate_log(tmp_path / "log", duration_s=75.0, still_s=30.0, seed=4)
    extra = ["--filter", "ckf", "--smooth", "--jit", "off"] if case == "ckf-smooth" else []
    done = _process([str(log), "--out", str(tmp_path / "off"), *extra],
                    {jitmode.ENV: "", "NUMBA_CACHE_DIR": str(tmp_path / "empty-cache")})
    assert done.returncode == 0, done.stderr
    assert "navpp's kernels ran interpreted, not compiled" in done.stderr
    assert "compiling navpp's numba kernels" not in done.stderr
    navpp.process(log, filter_name="ckf" if extra else "ekf", smooth=bool(extra), out_dir=tmp_path / "on")
    for name in ("trajectory.csv", "diagnostics.csv"):
        assert (tmp_path / "off" / name).read_bytes() == (tmp_path / "on" / name).read_bytes(), name


def test_jit_option_errors(tmp_path: Path) -> None:
    res = runner.invoke(app, ["process", str(SAMPLES / "drive.mcap"), "--jit", "maybe", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "auto, on or off" in res.output
    done = _process([str(SAMPLES / "drive.mcap"), "--out", str(tmp_path / "o")], {jitmode.ENV: "fast"})
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        "navpp: error: NAVPP_JIT: unknown mode 'fast'; choose one of auto, on, off"]
    res = runner.invoke(app, ["compile", "--filters", "ekf,nope"])
    assert res.exit_code == 1 and "nope" in res.output and "Traceback" not in res.output


@pytest.mark.slow
def test_navpp_compile_fills_the_cache(tmp_path: Path) -> None:
    """`navpp compile --filters ekf` into an empty cache; then auto finds every group an EKF run on
    an MCAP log needs (smoother included) and a run of the sample drive compiles nothing."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NAVPP_JIT="")
    done = subprocess.run([sys.executable, "-m", "navpp", "compile", "--filters", "ekf"], env=env,
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "navpp's kernels are compiled" in done.stdout
    assert "native module (not built: NAVPP_NATIVE=0)" in done.stdout      # the test session's setting
    probe = ("from navpp import jitmode; "
             "print(jitmode.missing_groups(('ins', 'ros', 'mcap', 'smooth')), jitmode.missing_groups(('sigma',)))")
    got = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
    assert got.stdout.split() == ["()", "('sigma',)"]
    run = subprocess.run([sys.executable, "-m", "navpp", "process", str(SAMPLES / "drive.mcap"), "--smooth",
                          "--out", str(tmp_path / "out")], env=env, capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    assert "compiling navpp's numba kernels" not in run.stderr
    assert "ran interpreted" not in run.stderr
