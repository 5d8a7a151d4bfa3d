"""Property-based robustness of the readers (issue 6, points 5 and 7).

Valid inputs (a short simulated drive as a CSV log, MCAP files, ROS 1 bags, a ROS 2 sqlite3
bag, and an RTKLIB .pos file) are mutated by hypothesis: cut at a random byte, random bytes flipped, ranges
zeroed, rows shuffled, duplicated or dropped, cells replaced by NaN / inf / garbage, header
columns removed or renamed, a BOM or CRLF line ends added, metadata.yaml damaged.  Whatever
the mutation, reading must either succeed or raise a ``NavppError`` whose message is one line
and names the input; any other exception is a reader bug.

The runs are deterministic (``derandomize=True``, no example database).  The default budget
(40 examples per input kind) keeps this module near 12 s of CPU; the ``slow`` variants explore 600
(``NAVPP_FUZZ_EXAMPLES`` raises that for a search by hand).  Every failure these searches found
is also pinned by a plain regression test at the end of the module.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from navpp import api
from navpp.config import Config
from navpp.errors import InputError, NavppError

FAST = settings(max_examples=40, derandomize=True, database=None, deadline=None,
                suppress_health_check=list(HealthCheck))
#: NAVPP_FUZZ_EXAMPLES=5000 explores further by hand (the slow budget is kept lean for CI).
SLOW = settings(FAST, max_examples=int(os.environ.get("NAVPP_FUZZ_EXAMPLES", "600")))
BUDGETS = [pytest.param(FAST, id="fast"), pytest.param(SLOW, id="slow", marks=pytest.mark.slow)]

#: Text a damaged or hand-edited CSV cell may hold.
BAD_CELLS = ("nan", "NaN", "inf", "-inf", "", " ", "abc", "1e400", "-1e400", "0x1F", '"', "1,2", "1.2.3",
             "\x00", "é", "--1", "1e-400", "9" * 40)

#: What a CSV error names besides the file: the line, or why there is no line to name.
CSV_POSITION = r"line \d+|empty file|t=\d|\d s\b"

# ----------------------------------------------------------------------------- the valid logs


@pytest.fixture(scope="module")
def originals(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One short drive in every input format (written once per module, never modified)."""
    from navpp.io import roswrite
    from navpp.simulate import SimulationSpec, simulate, write_csv_log

    base = tmp_path_factory.mktemp("fuzz-originals")
    sim = simulate(SimulationSpec(duration_s=40.0, still_s=20.0, seed=5, gnss_velocity=True))
    rec = sim.recording()
    write_csv_log(sim, base / "csv")
    roswrite.write_mcap_ros2(rec, base / "log.mcap", chunk_size=16_000)
    roswrite.write_mcap_ros2(rec, base / "plain.mcap", compression="none", chunk_size=16_000)
    roswrite.write_ros1_bag(rec, base / "log.bag")
    roswrite.write_ros1_bag(rec, base / "lz4.bag", compression="lz4", chunk_size=32_000)
    roswrite.write_ros2_bag(rec, base / "ros2")
    return {"csv": base / "csv", "mcap": base / "log.mcap", "mcap-plain": base / "plain.mcap",
            "ros1": base / "log.bag", "ros1-lz4": base / "lz4.bag", "ros2": base / "ros2"}


def check_outcome(run: Callable[[], object], names: str, position: str | None = None) -> NavppError | None:
    """Run ``run``: success, or a one-line NavppError mentioning ``names`` (and matching the
    regular expression ``position``, e.g. a line number); anything else fails."""
    try:
        run()
    except NavppError as exc:
        text = str(exc)
        assert text and "\n" not in text and "\r" not in text, f"not one line: {text!r}"
        assert names in text, f"the message does not name {names}: {text!r}"
        assert "Traceback" not in text
        assert position is None or re.search(position, text), f"no position ({position}) in: {text!r}"
        return exc
    return None


def read(path: Path) -> None:
    api.read_log(path, Config())


# ------------------------------------------------------------------------------ byte mutations


def mutate_bytes(data: st.DataObject, raw: bytes) -> bytes:
    """Cut, flip bytes in, or zero a range of ``raw`` (one to three mutations)."""
    buf = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        if not buf:
            break
        kind = data.draw(st.sampled_from(["truncate", "flip", "zero", "flip-tail"]), label="kind")
        n = len(buf)
        if kind == "truncate":
            del buf[data.draw(st.integers(0, n - 1), label="cut at"):]
        elif kind in ("flip", "flip-tail"):
            # flip-tail aims at the summary / index / footer at the end of the file
            lo = max(0, n - 4096) if kind == "flip-tail" else 0
            for _ in range(data.draw(st.integers(1, 8), label="flips")):
                pos = data.draw(st.integers(lo, n - 1), label="pos")
                buf[pos] ^= data.draw(st.integers(1, 255), label="xor")
        else:
            start = data.draw(st.integers(0, n - 1), label="zero from")
            length = data.draw(st.integers(1, 4096), label="zero length")
            buf[start:start + length] = bytes(len(buf[start:start + length]))
    return bytes(buf)


# ---------------------------------------------------------------------------------- CSV logs


def mutate_csv(data: st.DataObject, text: str) -> str:
    """A damaged version of a CSV file's text (rows, cells, header, line ends, bytes)."""
    lines = text.splitlines()
    header, rows = lines[0], lines[1:]
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        kind = data.draw(st.sampled_from(["shuffle", "duplicate", "drop", "cell", "cell", "remove-column",
                                          "rename-column", "extra-cells", "truncate"]), label="kind")
        if not rows:
            break
        n = len(rows)
        i = data.draw(st.integers(0, n - 1), label="row")
        if kind == "shuffle":
            j = data.draw(st.integers(i, min(n, i + 50)), label="to")
            block = rows[i:j]
            data.draw(st.randoms(use_true_random=False), label="rng").shuffle(block)
            rows[i:j] = block
        elif kind == "duplicate":
            rows.insert(i, rows[i])
        elif kind == "drop":
            del rows[i:i + data.draw(st.integers(1, 200), label="drop rows")]
        elif kind == "cell":
            cells = rows[i].split(",")
            cells[data.draw(st.integers(0, len(cells) - 1), label="col")] = data.draw(st.sampled_from(BAD_CELLS))
            rows[i] = ",".join(cells)
        elif kind == "extra-cells":
            rows[i] = rows[i] + ",1" * data.draw(st.integers(-1, 3), label="extra") if rows[i] else rows[i]
        elif kind == "truncate":
            rows[i] = rows[i][:data.draw(st.integers(0, max(0, len(rows[i]) - 1)), label="cut")]
        else:
            cols = header.split(",")
            k = data.draw(st.integers(0, len(cols) - 1), label="column")
            if kind == "remove-column":
                del cols[k]
            else:
                cols[k] = data.draw(st.sampled_from(["", "T", cols[k].upper(), cols[k] + " ", "x", cols[0]]))
            header = ",".join(cols)
    newline = "\r\n" if data.draw(st.booleans(), label="crlf") else "\n"
    bom = "\ufeff" if data.draw(st.booleans(), label="bom") else ""
    return bom + newline.join([header, *rows]) + newline


def damaged_csv_log(data: st.DataObject, original: Path, where: Path) -> Path:
    log = where / "log"
    shutil.copytree(original, log)
    name = data.draw(st.sampled_from(["imu.csv", "gnss.csv", "reference.csv"]), label="file")
    target = log / name
    if data.draw(st.booleans(), label="text mutation"):
        target.write_text(mutate_csv(data, target.read_text()), newline="")
    else:
        target.write_bytes(mutate_bytes(data, target.read_bytes()))
    return log


@pytest.mark.parametrize("budget", BUDGETS)
def test_damaged_csv_log_reads_or_fails_cleanly(originals, budget) -> None:
    @budget
    @given(st.data())
    def run(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            log = damaged_csv_log(data, originals["csv"], Path(tmp))
            check_outcome(lambda: read(log), str(log), CSV_POSITION)

    run()


# ------------------------------------------------------------------------- MCAP and ROS bags


@pytest.mark.parametrize("budget", BUDGETS)
@pytest.mark.parametrize("kind", ["mcap", "mcap-plain", "ros1", "ros1-lz4"])
def test_damaged_single_file_log_reads_or_fails_cleanly(originals, kind: str, budget) -> None:
    original = originals[kind].read_bytes()

    @budget
    @given(st.data())
    def run(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / originals[kind].name
            path.write_bytes(mutate_bytes(data, original))
            check_outcome(lambda: read(path), str(path))

    run()


def mutate_yaml(data: st.DataObject, text: str) -> str:
    lines = text.splitlines()
    for _ in range(data.draw(st.integers(1, 2), label="mutations")):
        kind = data.draw(st.sampled_from(["drop-line", "replace-value", "bytes", "indent"]), label="kind")
        i = data.draw(st.integers(0, len(lines) - 1), label="line")
        if kind == "drop-line":
            del lines[i]
        elif kind == "replace-value" and ":" in lines[i]:
            key = lines[i].split(":", 1)[0]
            value = data.draw(st.sampled_from(["", " null", " -1", " 99999999999999999999999", " [", " {a: 1}",
                                               " 'x'", " 1.5", " []", " !!binary AAAA"]), label="value")
            lines[i] = key + ":" + value
        elif kind == "indent":
            lines[i] = data.draw(st.sampled_from(["", " ", "   ", "\t"]), label="indent") + lines[i].lstrip()
        elif lines:
            lines = mutate_bytes(data, "\n".join(lines).encode()).decode("utf-8", "replace").splitlines() or [""]
        if not lines:
            lines = [""]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("budget", BUDGETS)
def test_damaged_ros2_bag_reads_or_fails_cleanly(originals, budget) -> None:
    original = originals["ros2"]

    @budget
    @given(st.data())
    def run(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            bag = Path(tmp) / "bag"
            shutil.copytree(original, bag)
            if data.draw(st.booleans(), label="damage metadata.yaml"):
                meta = bag / "metadata.yaml"
                meta.write_text(mutate_yaml(data, meta.read_text()))
            else:
                db3 = next(bag.glob("*.db3"))
                db3.write_bytes(mutate_bytes(data, db3.read_bytes()))
            check_outcome(lambda: read(bag), str(bag))

    run()


# ------------------------------------------------------------------------- RTKLIB .pos files


def pos_text(epochs: int = 150) -> str:
    """A valid RTKLIB solution (GPS week / time of week, position and velocity columns)."""
    lines = ["% program   : RTKPOST ver.2.4.3 b34",
             "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
             ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
              "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn    sdve    sdvu"
              "   sdvne   sdveu   sdvun")]
    for k in range(epochs):
        lines.append(f"2295 {86400 + 0.2 * k:11.3f}   {45 + 1e-6 * k:.9f}    {7 + 2e-6 * k:.9f}   {300 + 0.01 * k:9.4f}"
                     f"   1  12   0.0100   0.0120   0.0300   0.0010   0.0000  -0.0020   0.00    9.9"
                     f"    0.1000    0.2000    0.0000   0.0100  0.0100  0.0200  0.0000  0.0000  0.0000")
    return "\r\n".join(lines) + "\r\n"


def mutate_pos(data: st.DataObject, text: str) -> str:
    lines = text.splitlines()
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        if not lines:
            break
        i = data.draw(st.integers(0, len(lines) - 1), label="line")
        kind = data.draw(st.sampled_from(["drop", "duplicate", "swap", "token", "token", "cut"]), label="kind")
        if kind == "drop":
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
        elif kind == "swap":
            j = data.draw(st.integers(0, len(lines) - 1), label="with")
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "token":
            tokens = lines[i].split(" ")
            k = data.draw(st.integers(0, len(tokens) - 1), label="token")
            tokens[k] = data.draw(st.sampled_from((*BAD_CELLS, "%", "2295", "-1", "99", "2024/13/01", "25:61:61")))
            lines[i] = " ".join(tokens)
        else:
            lines[i] = lines[i][:data.draw(st.integers(0, len(lines[i])), label="cut")]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("budget", BUDGETS)
@pytest.mark.parametrize("fast_path", [True, False], ids=["fast-path", "line-by-line"])
def test_damaged_pos_file_reads_or_fails_cleanly(budget, fast_path: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    from navpp.io import rtklib

    monkeypatch.setattr(rtklib, "_FAST_PATH", fast_path)
    original = pos_text()

    @budget
    @given(st.data())
    def run(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "sol.pos"
            if data.draw(st.booleans(), label="text mutation"):
                path.write_text(mutate_pos(data, original))
            else:
                path.write_bytes(mutate_bytes(data, original.encode()))
            check_outcome(lambda: rtklib.read_pos(path, time_base="unix"), path.name)

    run()


# ------------------------------------------------------------- full runs: API and command line


def mildly_damaged_csv_log(data: st.DataObject, original: Path, where: Path) -> Path:
    """Damage that reading usually survives, so that the filter runs too: the IMU file cut off
    (at a line end) in its second half, or a block of GNSS rows lost."""
    log = where / "log"
    shutil.copytree(original, log)
    if data.draw(st.booleans(), label="cut imu.csv"):
        raw = (log / "imu.csv").read_bytes()
        cut = raw.rfind(b"\n", 0, data.draw(st.integers(len(raw) // 2, len(raw) - 1), label="cut at")) + 1
        (log / "imu.csv").write_bytes(raw[:cut])
    else:
        lines = (log / "gnss.csv").read_text().splitlines()
        start = data.draw(st.integers(1, len(lines) - 1), label="from")
        del lines[start:start + data.draw(st.integers(1, 60), label="rows")]
        (log / "gnss.csv").write_text("\n".join(lines) + "\n")
    return log


@pytest.mark.parametrize("budget", [pytest.param(settings(FAST, max_examples=12), id="fast"),
                                    pytest.param(settings(FAST, max_examples=80), id="slow", marks=pytest.mark.slow)])
def test_damaged_log_through_process_and_cli(originals, budget) -> None:
    from test_cli import assert_one_line_error, invoke

    @budget
    @given(st.data())
    def run(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            kind = data.draw(st.sampled_from(["mild", "csv", "mcap"]), label="log")
            if kind == "mild":
                log = mildly_damaged_csv_log(data, originals["csv"], Path(tmp))
            elif kind == "csv":
                log = damaged_csv_log(data, originals["csv"], Path(tmp))
            else:
                log = Path(tmp) / "log.mcap"
                log.write_bytes(mutate_bytes(data, originals["mcap-plain"].read_bytes()))
            error = check_outcome(lambda: api.process(log, write=False), str(log))
            out = Path(tmp) / "out"
            result = invoke("process", log, "--out", out)
            if error is None:
                assert result.exit_code == 0, result.output
            else:       # the same one line, exit code 1, no traceback, no output files
                assert assert_one_line_error(result, out) == f"navpp: error: {error}"

    run()


@pytest.mark.parametrize("kind", ["csv", "mcap", "mcap-plain", "ros1", "ros1-lz4", "ros2"])
def test_the_undamaged_logs_read(originals, kind: str) -> None:
    rec = api.read_log(originals[kind], Config())
    assert len(rec.imu) == 5001 and len(rec.gnss) > 150


# ------------------------------------------------------------- regressions found by the fuzzing


@pytest.mark.parametrize(("line", "value", "field"), [
    ("      name: /imu/data", "      name:", "name"),                           # was AttributeError
    ("      type: sensor_msgs/msg/Imu", "      type: []", "type"),            # was TypeError (unhashable)
    ("  - message_count: 5001", "  - message_count:", "message_count"),    # was TypeError (int + None)
])
def test_ros2_metadata_with_a_damaged_topic_entry(originals, tmp_path: Path, line: str, value: str,
                                                  field: str) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(originals["ros2"], bag)
    meta = bag / "metadata.yaml"
    text = meta.read_text()
    assert line + "\n" in text
    meta.write_text(text.replace(line + "\n", value + "\n", 1))
    with pytest.raises(InputError) as exc:
        read(bag)
    assert str(exc.value).startswith(f"{meta}: topic entry ")
    assert f"has an invalid {field} (" in str(exc.value)


def test_csv_row_that_is_not_utf8_is_named(originals, tmp_path: Path) -> None:
    log = tmp_path / "log"
    shutil.copytree(originals["csv"], log)
    gnss = log / "gnss.csv"
    lines = gnss.read_bytes().split(b"\n")
    lines[7] = lines[7][:5] + b"\xff" + lines[7][6:]          # was "non-numeric value: 'utf-8' codec can't ..."
    gnss.write_bytes(b"\n".join(lines))
    with pytest.raises(InputError) as exc:
        read(log)
    assert str(exc.value) == f"{gnss}: line 8: not a UTF-8 text file (invalid start byte at byte 5 of the line)"


def test_csv_quote_that_never_closes_is_named(originals, tmp_path: Path) -> None:
    log = tmp_path / "log"
    shutil.copytree(originals["csv"], log)
    imu = log / "imu.csv"
    lines = imu.read_text().split("\n")
    lines[40] = '"' + lines[40]                                # was "... C error: EOF inside string starting at row 40"
    imu.write_text("\n".join(lines))
    with pytest.raises(InputError) as exc:
        read(log)
    assert str(exc.value) == f'{imu}: line 41: a quote (") opens a field that is never closed'


# ------------------------------------------------------------------------ interrupted output


def test_interrupted_run_leaves_no_finished_looking_file(originals, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from navpp.io import writers

    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")

    def interrupted(path, *args, **kwargs):
        Path(path).write_text("t,nu_e\n1.0,")             # half a file, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(writers, "write_diagnostics_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        api.process(originals["csv"], out_dir=out, output_rate_hz=5.0, formats="csv,tum")
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]      # no trajectory.csv, no staging dir
    assert (out / "notes.txt").read_text() == "mine\n"

    fresh = tmp_path / "fresh" / "out"
    with pytest.raises(KeyboardInterrupt):
        api.process(originals["csv"], out_dir=fresh, output_rate_hz=5.0)
    assert not (tmp_path / "fresh").exists()


@pytest.mark.parametrize("fast_path", [True, False], ids=["fast-path", "line-by-line"])
@pytest.mark.parametrize("stamp", ["9" * 40 + " 86400.000", "9999/01/01 00:00:00.000"])
def test_pos_time_beyond_int64_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fast_path: bool,
                                        stamp: str) -> None:
    from navpp.io import rtklib

    monkeypatch.setattr(rtklib, "_FAST_PATH", fast_path)
    lines = pos_text(5).splitlines()
    lines[5] = stamp + lines[5][16:]                     # the third epoch; was OverflowError
    path = tmp_path / "sol.pos"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as exc:
        rtklib.read_pos(path)
    assert str(exc.value) == f"sol.pos: line 6: time {stamp!r} is out of range (after the year 2262)"


@pytest.mark.parametrize("truncate", [False, True], ids=["no-crc", "cut-off"])
def test_mcap_schema_record_that_cannot_be_parsed(originals, tmp_path: Path, truncate: bool) -> None:
    import struct

    from navpp.io.detect import MCAP_MAGIC

    data = bytearray(originals["mcap-plain"].read_bytes())
    header_end = len(MCAP_MAGIC) + 9 + struct.unpack_from("<Q", data, len(MCAP_MAGIC) + 1)[0]
    chunk = header_end
    assert data[chunk] == 0x06                                   # the first Chunk record
    compression_len = struct.unpack_from("<I", data, chunk + 9 + 28)[0]
    schema = chunk + 9 + 32 + compression_len + 8
    assert data[schema] == 0x03                                  # its first record: a Schema
    struct.pack_into("<I", data, schema + 9 + 2, 0xFFFF_FFF0)     # name length far past the record
    if truncate:
        data = data[:schema + 2000]                              # cut off: a partial chunk has no CRC to check
    else:
        struct.pack_into("<I", data, chunk + 9 + 24, 0)          # CRC 0: not checked
    path = tmp_path / "bad.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as exc:                        # was mcap.exceptions.EndOfFile
        read(path)
    assert str(exc.value) == (f"{path}: Schema record in the chunk at byte {chunk} is corrupted: EndOfFile")


def test_ros2_metadata_naming_a_topic_the_storage_lacks(originals, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(originals["ros2"], bag)
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("name: /gnss/fix\n", "name: x\n"))
    with pytest.raises(InputError) as exc:                        # was ValueError (reshape of no messages)
        read(bag)
    assert str(exc.value) == (f"{bag}: topic 'x': metadata.yaml lists 201 messages but the bag's storage holds "
                              "none (the metadata does not match the storage file)")


def test_a_damaged_message_count_does_not_size_the_decoded_table(originals, tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The ROS 1 bag's last byte is a message count of its last chunk's connection: flipped, rosbags
    reports ~185 million messages, and the decoded table was sized for them (62 GB reserved on the
    spill file, or "no space left").  The first size is now bounded by what the file can hold."""
    from navpp import spill
    from navpp.io import messages

    data = bytearray(originals["ros1"].read_bytes())
    data[-1] ^= 11
    path = tmp_path / "bad.bag"
    path.write_bytes(bytes(data))
    requested: list[int] = []
    real = spill.empty_rows

    def recorded(n_rows: int, row_shape: tuple[int, ...], dtype: object, spilled: bool, what: str = "") -> object:
        requested.append(n_rows * int(np.prod(row_shape)) * np.dtype(dtype).itemsize)
        return real(n_rows, row_shape, dtype, spilled, what)

    monkeypatch.setattr(messages.spill, "empty_rows", recorded)
    check_outcome(lambda: read(path), str(path))
    assert requested and max(requested) <= 8 * len(data)      # an Imu row: 44 words per message of ≥ 64 bytes
