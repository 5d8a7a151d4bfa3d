"""The compiled row formatter (navpp.io.csvformat) writes Python's ``format(x, ".Nf")`` text, and
the same bytes as the vectorised exact path it leaves the values beyond 2**52 / 10**d to."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navpp.io import csvformat, writers
from navpp.io.csvformat import BlockFormatter

SPECIAL = [0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 5e-324, -5e-324, 1e-300, -1e-300,
           2.5, -2.5, 0.5, -0.5, 1.5, 0.125, -0.375, 0.00005, -0.00004, -0.00005, 0.99995, -0.99995]


def _python_text(x: np.ndarray, decimals: int) -> bytes:
    return "".join(format(float(v), f".{decimals}f") + "\n" for v in x).encode("ascii")


def _values(decimals: int, rng: np.random.Generator) -> np.ndarray:
    """At least 1e5 values for one column kind: wide random magnitudes, the decimal ties of the
    kind and their neighbours one ulp either side, the largest magnitudes the kernel takes."""
    scale = 10.0 ** decimals
    limit = 2.0 ** 52 / scale
    ties = (rng.integers(-10 ** 9, 10 ** 9, 20_000) + 0.5) / scale
    ties = ties[np.abs(ties) < limit]
    return np.concatenate([
        SPECIAL,
        rng.normal(0.0, 1.0, 10_000), rng.normal(0.0, 1e3, 10_000), rng.uniform(-1e-3, 1e-3, 10_000),
        rng.uniform(-180.0, 360.0, 10_000),
        np.exp(rng.uniform(-30.0, math.log(limit), 10_000)) * rng.choice([-1.0, 1.0], 10_000),
        ties, np.nextafter(ties, np.inf), np.nextafter(ties, -np.inf),
        # exact binary ties: k + 0.5 ulp-free halves at this precision
        (rng.integers(-10 ** 6, 10 ** 6, 5_000) * 2 + 1) / (2.0 * scale),
        np.nextafter(limit, 0.0) * np.array([1.0, -1.0]), np.array([0.4999999999999999, -0.5000000000000001]) / scale,
    ])


@pytest.mark.parametrize("decimals", [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12])
def test_kernel_text_is_python_format(decimals):
    rng = np.random.default_rng(100 + decimals)
    x = _values(decimals, rng)
    assert x.size >= 100_000
    text = BlockFormatter([decimals]).rows([x])
    assert text is not None
    got = bytes(text).split(b"\n")
    want = _python_text(x, decimals).split(b"\n")
    bad = [(float(v), g, w) for v, g, w in zip(x, got, want) if g != w]
    assert not bad, bad[:10]
    assert len(got) == len(want)


def test_several_columns_and_separators():
    rng = np.random.default_rng(7)
    n = 20_000
    cols = [rng.uniform(-90, 90, n), rng.normal(0, 50, n).astype(np.float32), rng.integers(0, 2, n).astype(bool),
            rng.normal(0, 1e4, n)]
    decimals = [9, 4, 0, 6]
    for sep in (b",", b" "):
        text = bytes(BlockFormatter(decimals, sep=sep).rows(cols))
        want = "".join(sep.decode().join(format(float(c[i]), f".{d}f") for c, d in zip(cols, decimals)) + "\n"
                       for i in range(n))
        assert text == want.encode("ascii")


def test_interpreted_kernels_leave_the_text_to_the_exact_path(monkeypatch):
    """With the kernels interpreted (--jit off) the per-digit kernel would run as Python: the
    vectorised exact path writes the same text instead, the kernel untouched."""
    rng = np.random.default_rng(11)
    cols = [rng.uniform(0, 3600, 5000), rng.uniform(-90, 90, 5000), rng.normal(0, 3, 5000).astype(np.float32)]
    decimals = [6, 9, 4]
    compiled = bytes(BlockFormatter(decimals, t0_s=1_700_000_000.25).text(cols))

    def no_kernel(self, columns):
        raise AssertionError("the kernel ran interpreted")

    monkeypatch.setattr(csvformat, "interpreted", lambda: True)
    monkeypatch.setattr(BlockFormatter, "rows", no_kernel)
    assert bytes(BlockFormatter(decimals, t0_s=1_700_000_000.25).text(cols)) == compiled


def test_too_large_values_are_left_to_the_exact_path():
    assert BlockFormatter([4]).rows([np.array([1.0, 1e12])]) is None   # 1e16 >= 2**52
    assert BlockFormatter([4]).rows([np.array([1.0, -1e300])]) is None
    x = np.array([1.25, 1e17, -1e300, 3.0, np.nan, 2.0 ** 52 / 1e4])
    for d in (0, 4, 9):
        assert writers.format_fixed_columns([x], [d]) == _python_text(x, d)


@pytest.mark.parametrize("t0_s", [0.0, 1_700_000_000.123456789, 1_600_000_000.5, -12.75, 999_999_999_999.0])
def test_time_column_is_the_exact_paths(t0_s):
    """``t0_s + t`` to the microsecond: the same text as the exact path (_time_field), negative times that
    round to zero written 0.000000, nan as nan."""
    rng = np.random.default_rng(int(abs(t0_s)) % 1000)
    n = 100_000
    t = np.concatenate([rng.uniform(-1.0, 4e4, n - 8), [-4e-7, -5e-7, -6e-7, 0.0, -0.0, np.nan, 2.5e-7, 1e9]])
    t[: n // 4] = np.round(t[: n // 4] * 1e6) / 1e6 + 5e-7   # near the microsecond ties
    y = rng.normal(0, 1, n)
    got = BlockFormatter([6, 4], t0_s=t0_s).rows([t, y])
    assert got is not None
    want = csvformat._layout([csvformat._time_field(t, t0_s), csvformat._field_from_values(y, 4)], n).tobytes()
    assert bytes(got) == want


def test_the_time_columns_large_values_fall_back(tmp_path):
    formatter = BlockFormatter([6], t0_s=1.7e9)
    t = np.array([0.5, 1e10])          # 1e16 us: beyond the kernel
    assert formatter.rows([t]) is None
    assert bytes(formatter.text([t])) == csvformat._layout([csvformat._time_field(t, 1.7e9)], 2).tobytes()
    spaced = BlockFormatter([6, 4], t0_s=1.7e9, sep=b" ")
    assert bytes(spaced.text([t, np.array([1e300, 2.0])])) == b"1700000000.500000 " + format(1e300, ".4f").encode() + \
        b"\n11700000000.000000 2.0000\n"


def test_buffers_are_reused_and_grow():
    formatter = BlockFormatter([2, 3])
    a = bytes(formatter.rows([np.arange(3.0), np.arange(3.0)]))
    b = bytes(formatter.rows([np.arange(1000.0), -np.arange(1000.0)]))
    c = bytes(formatter.rows([np.arange(3.0), np.arange(3.0)]))
    assert a == c == b"0.00,0.000\n1.00,1.000\n2.00,2.000\n"
    assert b.split(b"\n")[999] == b"999.00,-999.000"


def test_bad_decimals():
    with pytest.raises(ValueError):
        BlockFormatter([19])
    with pytest.raises(ValueError):
        BlockFormatter([4], t0_s=0.0)
