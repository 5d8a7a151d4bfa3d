"""The CSV reader's fast path (:mod:`navpp.io.csvparse`): every value bit for bit what Python's
``float`` (and pandas) make of the text, anything not plain handed to the pandas path, the
same Recording and the same errors either way, and no pandas imported for a plain log."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from navpp import jitmode
from navpp.errors import InputError
from navpp.io import csv as csv_io
from navpp.io.csv import read_csv_log

pytestmark = pytest.mark.skipif(jitmode.interpreted(), reason="the fast path runs only compiled")

REPO = Path(__file__).resolve().parents[1]


def _parse(path: Path, n_fields: int) -> np.ndarray | None:
    from navpp.io.csvparse import parse_columns

    got = parse_columns(path, n_fields, list(range(n_fields)))
    return None if got is None else np.array(got[0])


def _random_cells(rng: np.random.Generator, n: int) -> list[str]:
    """Numbers as loggers write them and as the rounding's hard cases need them: repr, %.17g,
    %.15e, fixed decimals, random digit strings of 1..19 significant digits with exponents
    across the normal range, leading and trailing zeros, ties between two doubles."""
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n)
    cells = [repr(float(v)) for v in x[: n // 5]]
    cells += [f"{v:.17g}" for v in x[n // 5: 2 * n // 5]]
    cells += [f"{v:.15e}" for v in x[2 * n // 5: 3 * n // 5]]
    cells += [f"{v:.6f}" for v in x[3 * n // 5: 4 * n // 5]]
    for _ in range(n - len(cells)):
        digits = "".join(str(d) for d in rng.integers(0, 10, int(rng.integers(1, 20))))
        exp = int(rng.integers(-300, 290))
        sign = rng.choice(["", "-", "+"])
        form = int(rng.integers(0, 3))
        if form == 0:
            cells.append(f"{sign}{digits}e{exp}")
        elif form == 1:
            cells.append(f"{sign}0.{'0' * int(rng.integers(0, 5))}{digits}")
        else:
            cells.append(f"{sign}{digits[:1]}.{digits[1:] or '0'}E{exp:+d}")
    # ties: 2^53 + 1 and 2^53 + 3 (halfway, to even); the largest and smallest normals
    cells += ["9007199254740993", "9007199254740995", "1.7976931348623157e308", "2.2250738585072014e-308",
              "0.0", "-0.0", "00012.50", "-0.000000000000000000000000001"]
    return cells


def test_every_value_is_the_double_python_reads(tmp_path: Path) -> None:
    rng = np.random.default_rng(21)
    cells = _random_cells(rng, 70_000)
    cells = cells[: len(cells) // 7 * 7]
    rows = [",".join(cells[k:k + 7]) for k in range(0, len(cells), 7)]
    path = tmp_path / "values.csv"
    path.write_text("a,b,c,d,e,f,g\n" + "\n".join(rows) + "\n")
    got = _parse(path, 7)
    assert got is not None
    want = np.array([float(c) for c in cells]).reshape(-1, 7).T
    assert got.shape == want.shape
    assert got.tobytes() == np.ascontiguousarray(want).tobytes()


def test_significands_of_every_bit_length_round_as_python(tmp_path: Path) -> None:
    """Digit strings whose integer value has 1..64 bits (2^k - 1, 2^k, 2^k + 1 within 19
    digits), with exponents across the normal range: the normalising shift of every length."""
    rng = np.random.default_rng(64)
    cells = []
    for k in range(64):
        for w in (2**k - 1, 2**k, 2**k + 1):
            if 0 < w < 10**19:
                exp = int(rng.integers(-300, 290))
                cells += [f"{w}", f"{w}e{exp}", f"-{w}E{-abs(exp) // 2}", f"0.{w}"]
    cells = cells[: len(cells) // 4 * 4]
    path = tmp_path / "bits.csv"
    path.write_text("a,b,c,d\n" + "".join(",".join(cells[k:k + 4]) + "\n" for k in range(0, len(cells), 4)))
    got = _parse(path, 4)
    want = np.array([float(c) for c in cells]).reshape(-1, 4).T
    assert got is not None and got.tobytes() == np.ascontiguousarray(want).tobytes()


@pytest.mark.parametrize("end", ["\n", "\r\n", ""])
def test_lines_across_the_mapped_windows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, end: str) -> None:
    """Windows far smaller than the file, so that lines straddle every window edge at every
    offset (the windows start on page boundaries, the lines anywhere); with and without an
    end on the last line: every row, in order."""
    from navpp.io import csvparse

    monkeypatch.setattr(csvparse, "_BLOCK_BYTES", 3 * 4096 + 17)
    values = np.arange(20_000) * 0.001 - 7.0
    lines = [f"{k},{float(v)!r},{'x' * (k % 37)}" for k, v in enumerate(values)]
    path = tmp_path / "f.csv"
    path.write_text("t,v,note\n" + "\n".join(lines) + end, newline="")
    if end == "\r\n":
        path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    got = csvparse.parse_columns(path, 3, [0, 1], 0)
    assert got is not None
    assert np.array_equal(got[0][0], np.arange(20_000, dtype=float))
    assert got[0][1].tobytes() == values.tobytes()
    assert got[1] is not None and np.array_equal(got[1], np.arange(20_000) * 1_000_000_000)


def test_a_line_longer_than_a_window_or_a_pipe_goes_to_pandas(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from navpp.io import csvparse

    monkeypatch.setattr(csvparse, "_BLOCK_BYTES", 2 * 4096)
    path = tmp_path / "f.csv"
    path.write_text("a,b\n1,2\n3," + "0" * 10_000 + "4\n5,6\n")
    assert csvparse.parse_columns(path, 2, [0]) is None
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    writer = subprocess.Popen([sys.executable, "-c", f"open({str(fifo)!r}, 'w').write('a,b\\n1,2\\n')"])
    try:
        assert csvparse.parse_columns(fifo, 2, [0, 1]) is None
    finally:
        writer.wait(timeout=30)


@pytest.mark.parametrize("text", [
    "1,2\n3,4\n",                 # plain
    "1,2\r\n3,4\r\n",             # CRLF
    "1,2\n3,4",                   # no end on the last line
    "1,x2\n3,4\n",                # an unwanted field holds anything but quotes and non-ASCII
])
def test_plain_forms_take_the_fast_path(tmp_path: Path, text: str) -> None:
    from navpp.io.csvparse import parse_columns

    path = tmp_path / "f.csv"
    path.write_bytes(b"a,b\n" + text.encode())
    wanted = [0] if "x" in text else [0, 1]
    got = parse_columns(path, 2, wanted)
    assert got is not None and got[0][0].tolist() == [1.0, 3.0]


def test_more_rows_than_the_first_block_suggests(tmp_path: Path) -> None:
    """Long rows first, then short ones over several blocks: the output grows, every row kept."""
    from navpp.io.csvparse import parse_columns

    path = tmp_path / "f.csv"
    long = [f"{k},{'x' * 200}" for k in range(1000)]
    short = [f"{k}," for k in range(1000, 1_200_000)]
    path.write_text("a,note\n" + "\n".join(long + short) + "\n")
    got = parse_columns(path, 2, [0], 0)
    assert got is not None and np.array_equal(got[0][0], np.arange(1_200_000, dtype=float))
    assert got[1] is not None and np.array_equal(got[1], np.arange(1_200_000) * 1_000_000_000)


def test_stamps_become_the_exact_nanoseconds_of_their_text(tmp_path: Path) -> None:
    """As the text path (decimal.Decimal, half-even at 1 ns): unix stamps with 9 and more
    decimals, e-notation, signs, ties below 1 ns; None when one does not fit int64."""
    from decimal import Decimal

    from navpp.io.csvparse import parse_columns

    rng = np.random.default_rng(5)
    cells = [f"17{rng.integers(0, 10**8):08d}.{rng.integers(0, 10**9):09d}" for _ in range(2000)]
    cells += [f"{rng.integers(0, 10**9)}.{rng.integers(0, 10**9):09d}{rng.integers(0, 10):d}" for _ in range(2000)]
    cells += ["0.0000000005", "0.0000000015", "-0.0000000025", "1.700000000000000005e9", "+12.5E-3", "-0.0",
              "9.223372036854775807e9", "0.00000000000000000000000001"]
    path = tmp_path / "t.csv"
    path.write_text("t,x\n" + "".join(f"{c},1\n" for c in cells))
    got = parse_columns(path, 2, [0, 1], 0)
    assert got is not None and got[1] is not None
    want = [int(Decimal(c).scaleb(9).to_integral_value()) for c in cells]
    assert got[1].tolist() == want
    path.write_text("t,x\n1,1\n1e10,1\n")
    got = parse_columns(path, 2, [0, 1], 0)
    assert got is not None and got[1] is None


@pytest.mark.parametrize("text", [
    "1,2\n\n3,4\n", "1,2\n3,4\n\n", "1, 2\n3,4\n", '1,"2"\n3,4\n', "1,nan\n3,4\n", "1,\n3,4\n", "1\n3,4\n",
    "1,2,5\n3,4\n", "1.,2\n3,4\n", ".5,2\n3,4\n", "1e,2\n3,4\n", "1,2\r3,4\n", "1,1e400\n3,4\n", "1,1e-310\n3,4\n",
    "1,12345678901234567891\n3,4\n", "1,1.5000000000000000000000\n3,4\n",
    "1,inf\n3,4\n", "1,0x10\n3,4\n", "1,2\n3,4é\n", "1,--2\n3,4\n",
])
def test_anything_not_plain_goes_to_pandas(tmp_path: Path, text: str) -> None:
    path = tmp_path / "f.csv"
    path.write_bytes(b"a,b\n" + text.encode())
    assert _parse(path, 2) is None


def _both_paths(monkeypatch: pytest.MonkeyPatch, read) -> tuple[object, object]:
    """``read()``'s result (or InputError message) through the fast path and through pandas."""
    def run() -> object:
        try:
            return read()
        except InputError as e:
            return str(e)

    fast = run()
    with monkeypatch.context() as m:
        m.setattr(csv_io, "_parse_plain", lambda *args: None)
        slow = run()
    return fast, slow


def _same_recording(a: object, b: object) -> None:
    import dataclasses

    assert type(a) is type(b)
    if isinstance(a, str):
        assert a == b
        return
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), f.name
        elif dataclasses.is_dataclass(x):
            _same_recording(x, y)
        else:
            assert x == y, f.name


def test_the_sample_drive_reads_the_same_either_way(monkeypatch: pytest.MonkeyPatch) -> None:
    fast, slow = _both_paths(monkeypatch, lambda: read_csv_log(REPO / "sample_data" / "drive"))
    _same_recording(fast, slow)


@pytest.mark.parametrize("edit", ["none", "gap", "duplicate", "backwards", "nan", "extra", "fields", "crlf"])
def test_a_log_reads_and_fails_the_same_either_way(log_copy: Path, monkeypatch: pytest.MonkeyPatch,
                                                    edit: str) -> None:
    imu = log_copy / "imu.csv"
    lines = imu.read_text().splitlines()
    if edit == "gap":
        del lines[200:260]
    elif edit == "duplicate":
        lines.insert(101, lines[100])
    elif edit == "backwards":
        lines[100], lines[101] = lines[101], lines[100]
    elif edit == "nan":
        lines[150] = lines[150].rsplit(",", 1)[0] + ",NaN"
    elif edit == "extra":
        lines = [line + ("," + ("extra" if k == 0 else str(k))) for k, line in enumerate(lines)]
    elif edit == "fields":
        lines[300] += ",1"
    imu.write_text(("\r\n" if edit == "crlf" else "\n").join(lines) + "\n")
    fast, slow = _both_paths(monkeypatch, lambda: read_csv_log(log_copy))
    _same_recording(fast, slow)


def test_reading_a_plain_log_imports_no_pandas(sim_log_dir: Path) -> None:
    """Reading a plain CSV log does not import pandas (before the fast path it did)."""
    code = ("import sys; from navpp.io.csv import read_csv_log; read_csv_log(sys.argv[1]); "
            "print('pandas' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code, str(sim_log_dir)], capture_output=True, text=True,
                         env=env, cwd=REPO, check=True).stdout
    assert out.strip() == "False"


def _stamp_cases() -> dict[str, list[str]]:
    """Stamp columns whose decimals the parse counts: more decimals after the first 2000 lines
    (below float64's resolution, then rounded to the first lines' decimals; above it, then
    exact), e-notation, signs, fewer rows than 2000."""
    unix = [f"{1_700_000_000 + 0.008 * k:.6f}" for k in range(3000)]
    below = list(unix)
    below[2500] = below[2500] + "001"              # 1 ns more: under float64's resolution at 1.7e9 s
    above = [f"{0.008 * k:.6f}" for k in range(3000)]
    above[2600] = above[2600] + "7"                # 0.1 us more at ~20 s: float64 resolves it
    return {
        "unix": unix, "below": below, "above": above,
        "e-notation": [f"{1.7e9 + 0.01 * k:.12e}" for k in range(2500)],
        "signs": [f"{-3.0 + 0.004 * k:+.4f}" for k in range(2100)],
        "integers": [str(10 * k) for k in range(50)],
        "short": [f"{0.5 * k:.3f}" for k in range(20)] + ["12.0001"],
    }


@pytest.mark.parametrize("case", list(_stamp_cases()))
def test_the_decimals_the_parse_counts_give_the_same_stamps(tmp_path: Path, case: str) -> None:
    """The stamps' decimals counted by the kernel (over the first 2000 lines and over all rows)
    give the ns :func:`navpp.io.csv._stamps_ns` gives from the text (without the counts)."""
    import dataclasses

    stamps = _stamp_cases()[case]
    path = tmp_path / "imu.csv"
    path.write_text("t,note,x\n" + "".join(f"{s},n{k % 7},1\n" for k, s in enumerate(stamps)))
    header = csv_io._read_header(path)
    table = csv_io._read_table(path, header, ["t", "x"], [])
    assert table.stamp_decimals is not None
    first = max(csv_io._stamp_decimals(path, header), 0)
    assert max(table.stamp_decimals[0], 0) == first
    assert table.stamp_decimals[1] == max(csv_io._cell_decimals(s) for s in stamps)
    got = csv_io._stamps_ns(table, header)
    want = csv_io._stamps_ns(dataclasses.replace(table, stamp_decimals=None), header)
    assert got.dtype == want.dtype and got.tolist() == want.tolist()


def test_a_lone_cr_in_an_ignored_cell_leaves_the_decimals_to_the_text(tmp_path: Path) -> None:
    """A CR without LF inside a cell the kernel skips is a line break to the text scan of the
    stamps' decimals: then the kernel's counts are not used."""
    path = tmp_path / "imu.csv"
    rows = [f"{0.01 * k:.2f},n,1" for k in range(100)]
    rows[10] = "0.10,a\r0.123456789,1"
    path.write_bytes(("t,note,x\n" + "\n".join(rows) + "\n").encode())
    header = csv_io._read_header(path)
    table = csv_io._read_table(path, header, ["t", "x"], [])
    assert table.stamps_ns is not None and table.stamp_decimals is None
    assert csv_io._stamp_decimals(path, header) == 9


def test_a_lone_cr_in_the_header_leaves_the_decimals_to_the_text(tmp_path: Path) -> None:
    """A header ending in CR CR LF is one line to the parse, two to the text scan (which then
    looks at one data line fewer): the kernel's counts are not used."""
    path = tmp_path / "imu.csv"
    rows = [f"{0.01 * k:.2f},1" for k in range(2000)] + ["20.001,1"]
    rows[1999] = "19.99999,1"                 # the 2000th data line: beyond the text scan's window here
    path.write_bytes(("t,x\r\r\n" + "\n".join(rows) + "\n").encode())
    header = csv_io._read_header(path)
    assert header == ["t", "x"]
    table = csv_io._read_table(path, header, ["t", "x"], [])
    assert table.stamps_ns is not None and table.stamp_decimals is None
    assert csv_io._stamp_decimals(path, header) == 2
