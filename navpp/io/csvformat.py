"""Fast path of the fixed-decimal writers (``trajectory.csv``, ``diagnostics.csv``, TUM, KML
coordinates): a block of rows formatted by a numba kernel (:func:`_format_block`) straight into a
byte buffer.

The text is the one :mod:`navpp.io.writers`' vectorised formatter writes, which is Python's
``format(x, ".Nf")`` of every value: the exact binary value rounded to N decimals, ties to even
(``x * 10**N`` rounded, and where that double product lands exactly on a half-integer the sign
of its rounding error, Dekker's exact product, decides), ``"nan"``, ``"inf"``, ``"-inf"``, and a
minus sign on every negative value and on -0.0 (``"-0.0000"``).  A time column (``t0_s`` given)
is ``t0_s + t`` rounded once to the microsecond, with ``t0_s``'s whole seconds added as integer
microseconds after the rounding, as :func:`navpp.io.writers.write_trajectory_csv` describes.
The kernel covers the finite values with ``|x| * 10**N < 2**52``, where every half-integer is a
double and the rounded value fits int64; a block holding a larger finite value makes
:meth:`BlockFormatter.rows` return None and the caller formats that block the exact, slower way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from .writers import _FAST_LIMIT
from .writers import _product_error as _exact_product_error

__all__ = ["BlockFormatter"]

_MAX_DECIMALS = 18  # 10**18 < 2**63
_INT_DIGITS = 19  # digits of the largest int64 magnitude written (the time column, < 1e12 s in us)
_POWERS = np.array([10 ** i for i in range(_INT_DIGITS)], dtype=np.uint64)
_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"), dtype=np.uint8)


_product_error = njit(cache=True)(_exact_product_error)
"""The exact error of a double product (:func:`navpp.io.writers._product_error`), compiled."""


@njit(cache=True)
def _put_text(out, pos, text):
    """``text`` into ``out`` from ``pos`` (uint64); returns the position after it."""
    for c in text:
        out[pos] = c
        pos += np.uint64(1)
    return pos


@njit(cache=True)
def _format_block(values, n, decimals, scales, offsets, sum_sign, out, sep,
                  nan_text, inf_text, neg_inf_text):
    """Columns ``0..n-1`` of ``values`` ((k, capacity) float64: row j holds the values of text
    column j) as n lines of text into ``out`` (uint8); returns the number of bytes written, or -1
    when a finite value has ``|x| * 10**d >= 2**52``.

    Text column j gets ``decimals[j]`` (uint64) decimals (``scales[j] = 10.0**decimals[j]``);
    ``offsets[j]`` (units of ``10**-decimals[j]``) is added to the rounded value, and with
    ``sum_sign[j]`` the sign written is the sum's (``total < 0``), else ``x``'s sign bit.  Cells
    are separated by ``sep`` and rows end with ``"\\n"``; ``out`` must hold
    ``n * sum(23 + decimals)`` bytes.  Positions and digits are unsigned (uint64), which spares
    the compiled code the checks and corrections of negative indices and floor division.
    """
    k = values.shape[0]
    pairs = _PAIRS
    powers = _POWERS
    zero, one, two, ten, hundred = np.uint64(0), np.uint64(1), np.uint64(2), np.uint64(10), np.uint64(100)
    char0 = np.uint64(48)  # '0'
    max_digits = np.uint64(_INT_DIGITS)
    pos = zero
    for i in range(n):
        for j in range(k):
            x = values[j, i]
            if math.isnan(x):
                pos = _put_text(out, pos, nan_text)
            elif math.isinf(x):
                pos = _put_text(out, pos, inf_text if x > 0.0 else neg_inf_text)
            else:
                scale = scales[j]
                p = x * scale
                if not abs(p) < _FAST_LIMIT:
                    return -1
                low = np.floor(p)
                # rint(p), ties to even, for |p| < 2**52
                r = (p + _FAST_LIMIT) - _FAST_LIMIT if p >= 0.0 else (p - _FAST_LIMIT) + _FAST_LIMIT
                if p - low == 0.5:
                    err = _product_error(x, scale, p)
                    if err > 0.0:
                        r = low + 1.0
                    elif err < 0.0:
                        r = low
                total = np.int64(r) + offsets[j]
                neg = total < 0 if sum_sign[j] else math.copysign(1.0, x) < 0.0
                m = np.uint64(-total if total < 0 else total)
                d = decimals[j]
                n_digits = d + one  # written: at least one integer digit
                while n_digits < max_digits and m >= powers[n_digits]:
                    n_digits += one
                end = pos + n_digits + (one if neg else zero) + (one if d > zero else zero)
                # right to left, ``done`` digits of n_digits written: one alone when d is odd,
                # then pairs, which then never straddle the '.' (written when done reaches d)
                q = end
                done = zero
                if d & one:
                    m10 = m // ten
                    q -= one
                    out[q] = char0 + (m - m10 * ten)
                    m = m10
                    done = one
                    if d == one:
                        q -= one
                        out[q] = 46  # '.'
                while n_digits - done >= two:
                    m100 = m // hundred
                    pair = two * (m - m100 * hundred)
                    m = m100
                    q -= two
                    out[q] = pairs[pair]
                    out[q + one] = pairs[pair + one]
                    done += two
                    if done == d:
                        q -= one
                        out[q] = 46  # '.'
                if n_digits > done:
                    q -= one
                    out[q] = char0 + m
                if neg:
                    out[q - one] = 45  # '-'
                pos = end
            out[pos] = sep if j < k - 1 else 10
            pos += one
    return np.int64(pos)


_NAN = np.frombuffer(b"nan", dtype=np.uint8)
_INF = np.frombuffer(b"inf", dtype=np.uint8)
_NEG_INF = np.frombuffer(b"-inf", dtype=np.uint8)


class BlockFormatter:
    """Formats blocks of rows of float columns with fixed decimals per column, reusing its buffers.

    Parameters
    ----------
    decimals : decimals per column (0 to 18).
    t0_s : when given, the first column is time in s relative to ``t0_s`` and is written as
        ``t0_s + t`` on the log's time base (6 decimals; ``decimals[0]`` must be 6).
    sep : the cell separator (one ASCII byte).
    """

    def __init__(self, decimals: Sequence[int], *, t0_s: float | None = None, sep: bytes = b",") -> None:
        if not decimals or any(not 0 <= d <= _MAX_DECIMALS for d in decimals):
            raise ValueError(f"decimals must be 0..{_MAX_DECIMALS}, one per column, got {list(decimals)}")
        if t0_s is not None and decimals[0] != 6:
            raise ValueError("the time column is written with 6 decimals")
        self.decimals = np.asarray(decimals, dtype=np.uint64)
        self.scales = np.array([10.0 ** d for d in decimals])
        self.offsets = np.zeros(len(decimals), dtype=np.int64)
        self.sum_sign = np.zeros(len(decimals), dtype=np.bool_)
        self.t_frac = 0.0
        if t0_s is not None:
            t0_int = math.floor(t0_s)
            self.t_frac = t0_s - t0_int  # added to t in float; the whole seconds as integer us
            self.offsets[0] = t0_int * 1_000_000
            self.sum_sign[0] = True
        self.timed = t0_s is not None
        self.sep = np.uint8(ord(sep))
        self.row_bytes = sum(decimals) + len(decimals) * (4 + _INT_DIGITS)  # sign, digits, ".", sep
        self.values = np.empty((len(decimals), 0))
        self.out = np.empty(0, dtype=np.uint8)

    def rows(self, columns: Sequence[np.ndarray]) -> memoryview | None:
        """The text of the rows of ``columns`` (equal-length 1-D arrays of any float, int or bool
        dtype, widened to float64 as they are copied in), or None when a finite value is too large
        for the kernel (``|x| * 10**d >= 2**52``).  The view is valid until the next call."""
        n = int(np.shape(columns[0])[0])
        if n > self.values.shape[1]:
            self.values = np.empty((len(self.decimals), n))
            self.out = np.empty(n * self.row_bytes, dtype=np.uint8)
        for j, c in enumerate(columns):
            self.values[j, :n] = c
        if self.timed:
            self.values[0, :n] += self.t_frac
        size = _format_block(self.values, n, self.decimals, self.scales, self.offsets, self.sum_sign,
                             self.out, self.sep, _NAN, _INF, _NEG_INF)
        return None if size < 0 else memoryview(self.out)[:size]
