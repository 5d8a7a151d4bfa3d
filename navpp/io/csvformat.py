"""Fixed-decimal text of float columns, block by block, for the writers (``trajectory.csv``,
``diagnostics.csv``, TUM, KML coordinates): :class:`BlockFormatter`.

The text is Python's ``format(x, ".Nf")`` of every value: the exact binary value rounded to N
decimals, ties to even (``x * 10**N`` rounded, and where that double product lands exactly on a
half-integer the sign of its rounding error, Dekker's exact product, decides), ``"nan"``,
``"inf"``, ``"-inf"``, and a minus sign on every negative value and on -0.0 (``"-0.0000"``).  A
time column (``t0_s`` given) is ``t0_s + t`` rounded once to the microsecond, with ``t0_s``'s
whole seconds added as integer microseconds after the rounding, as
:func:`navpp.io.writers.write_trajectory_csv` describes.

Two paths write the same text.  A numba kernel (:func:`_format_block`) formats the rows straight
into a reused byte buffer; it covers the finite values with ``|x| * 10**N < 2**52``, where every
half-integer is a double and the rounded value fits int64.  A block holding a larger finite value
goes to the exact vectorised path (:func:`_field_from_values`, :func:`_time_field`,
:func:`_layout`: numpy, such values formatted by Python).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from navpp.kernel import njit

from ..jitmode import interpreted

__all__ = ["BlockFormatter"]

_FAST_LIMIT = 2.0 ** 52  # |x * 10**d| below this: every half-integer is a double, int64 is exact
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp splitting constant
_MAX_DECIMALS = 18  # 10**18 < 2**63
_INT_DIGITS = 19  # digits of the largest int64 magnitude written (the time column, < 1e12 s in us)
_POWERS = np.array([10 ** i for i in range(_INT_DIGITS)], dtype=np.uint64)
_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"), dtype=np.uint8)


# --------------------------------------------------------------------------- the exact vectorised path


def _product_error(a: np.ndarray, b: float, p: np.ndarray) -> np.ndarray:
    """Exact rounding error ``a*b - p`` of the double product ``p = fl(a*b)`` (Dekker's TwoProduct)."""
    c = _SPLIT * a
    ah = c - (c - a)
    al = a - ah
    cb = _SPLIT * b
    bh = cb - (cb - b)
    bl = b - bh
    return ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _round_scaled(x: np.ndarray, decimals: int) -> tuple[np.ndarray, np.ndarray]:
    """``round(x * 10**decimals)`` of the exact binary value, ties to even, as int64.

    Returns ``(r, fast)``: ``fast`` marks the finite values with ``|x| * 10**decimals < 2**52``;
    ``r`` is the correctly rounded scaled value there and 0 elsewhere.

    ``p = fl(x * 10**d)`` can differ from the exact product, but rounding is monotonic and every
    half-integer below 2**52 is a double, so ``rint(p)`` is the correct answer unless ``p`` lands
    exactly on a half-integer; there the sign of the exact product error decides.
    """
    scale = 10.0 ** decimals
    with np.errstate(invalid="ignore", over="ignore"):
        p = x * scale
        fast = np.abs(p) < _FAST_LIMIT
    p = np.where(fast, p, 0.0)
    r = np.rint(p)
    tie = (p - np.floor(p)) == 0.5
    if tie.any():
        idx = np.flatnonzero(tie)
        err = _product_error(x[idx], scale, p[idx])
        low = np.floor(p[idx])
        r[idx] = np.where(err > 0.0, low + 1.0, np.where(err < 0.0, low, r[idx]))
    return r.astype(np.int64), fast


def _n_digits(v: int) -> int:
    return max(1, len(str(int(v))))


class _Field:
    """One column of one chunk, ready to be laid out: magnitude, sign and special strings."""

    def __init__(self, mag: np.ndarray, neg: np.ndarray, decimals: int,
                 special_rows: np.ndarray, special_text: np.ndarray) -> None:
        self.mag = mag  # (n,) int64 >= 0, scaled by 10**decimals (0 on special rows)
        self.neg = neg  # (n,) bool, write a minus sign
        self.decimals = decimals
        self.special_rows = special_rows  # (k,) int rows written as text instead
        self.special_text = special_text  # (k,) bytes ("S") array
        int_part_max = int(mag.max()) // 10 ** decimals if mag.size else 0
        self.n_digits = _n_digits(int_part_max)  # integer digits of the largest number
        self.n_int = self.n_digits  # integer positions of the slot (wider if a text is longer)
        frac_width = decimals + 1 if decimals else 0
        if special_rows.size:
            longest = special_text.dtype.itemsize
            self.n_int = max(self.n_int, longest - 1 - frac_width)
        #: bytes in the row buffer: sign, integer digits, '.', fraction, separator
        self.width = 1 + self.n_int + frac_width + 1


def _field_from_values(x: np.ndarray, decimals: int) -> _Field:
    """Fixed-point field of ``x`` identical to ``format(v, f'.{decimals}f')`` per value."""
    x = np.asarray(x, dtype=np.float64)
    r, fast = _round_scaled(x, decimals)
    neg = np.signbit(x) & fast
    rows = np.flatnonzero(~fast)
    return _Field(np.abs(r), neg, decimals, rows, _special_text(x[rows], decimals))


def _special_text(v: np.ndarray, decimals: int) -> np.ndarray:
    """Text of values the fast path does not cover: nan, +-inf and |v| >= 2**52 / 10**decimals."""
    if v.size == 0:
        return np.empty(0, dtype="S1")
    finite = np.isfinite(v)
    longest = 4
    texts: dict[int, bytes] = {}
    for i in np.flatnonzero(finite):  # enormous finite values only: rare
        s = format(float(v[i]), f".{decimals}f").encode("ascii")
        texts[int(i)] = s
        longest = max(longest, len(s))
    out = np.empty(v.shape[0], dtype=f"S{longest}")
    out[np.isnan(v)] = b"nan"
    out[np.isposinf(v)] = b"inf"
    out[np.isneginf(v)] = b"-inf"
    for k, s in texts.items():
        out[k] = s
    return out


_DIGITS = np.frombuffer(b"0123456789", dtype=np.uint8)


def _layout(fields: Sequence[_Field], n: int, sep: bytes = b",") -> np.ndarray:
    """Lay the fields out in a zero-padded (n, width) byte buffer and squeeze out the padding.

    Each field is ``[sign][integer digits, right-aligned]['.'][fraction][sep or '\\n']``;
    unused positions stay 0 and are dropped, so the result is the text of the n rows.
    """
    total = sum(f.width for f in fields)
    buf = np.zeros((n, total), dtype=np.uint8)
    c0 = 0
    for j, f in enumerate(fields):
        buf[:, c0] = np.where(f.neg, ord("-"), 0).astype(np.uint8)
        d = f.decimals
        q = f.mag // 10 ** d
        frac = f.mag - q * 10 ** d
        units = c0 + f.n_int  # position of the integer units digit
        for k in range(f.n_digits):
            digit = _DIGITS[q % 10]
            if k == 0:
                buf[:, units] = digit
            else:
                buf[:, units - k] = np.where(q > 0, digit, 0)
            q //= 10
        if d:
            buf[:, units + 1] = ord(".")
            for k in range(d):
                buf[:, units + 1 + d - k] = _DIGITS[frac % 10]
                frac //= 10
        if f.special_rows.size:
            k = f.special_text.dtype.itemsize
            buf[f.special_rows, c0:c0 + f.width - 1] = 0
            buf[f.special_rows, c0:c0 + k] = f.special_text.view(np.uint8).reshape(-1, k)
        buf[:, c0 + f.width - 1] = ord("\n") if j == len(fields) - 1 else ord(sep)
        c0 += f.width
    return buf[buf != 0]


def _time_field(t_rel: np.ndarray, t0_s: float) -> _Field:
    """``t0_s + t_rel`` with 6 decimals, without the rounding of the float sum.

    ``t0_s`` is split into whole seconds and a fraction (both exact), the fraction is added to
    the relative times (small numbers, ~1e-11 s resolution) and the whole seconds are added
    back as integer microseconds.  Negative values that round to zero are written ``0.000000``.
    """
    t0_int = math.floor(t0_s)
    rel = (t0_s - t0_int) + np.asarray(t_rel, dtype=np.float64)
    r, fast = _round_scaled(rel, 6)
    total = r + np.int64(t0_int) * 1_000_000
    neg = (total < 0) & fast
    rows = np.flatnonzero(~fast)
    special = _special_text(t0_int + rel[rows], 6)
    return _Field(np.where(fast, np.abs(total), 0), neg, 6, rows, special)


# --------------------------------------------------------------------------- the compiled path


_product_error_kernel = njit(cache=True)(_product_error)
"""The exact error of a double product (:func:`_product_error`) of scalars, compiled."""


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
                    err = _product_error_kernel(x, scale, p)
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
        self.t0_s = t0_s
        self.sep_text = sep
        self.sep = np.uint8(ord(sep))
        self.row_bytes = sum(decimals) + len(decimals) * (4 + _INT_DIGITS)  # sign, digits, ".", sep
        self.values = np.empty((len(decimals), 0))
        self.out = np.empty(0, dtype=np.uint8)

    def text(self, columns: Sequence[np.ndarray]) -> memoryview:
        """The text of the rows of ``columns`` (equal-length 1-D arrays of any float, int or bool
        dtype): the kernel's, or, when a finite value is too large for it (``|x| * 10**d >=
        2**52``) or the kernels run interpreted (``--jit off``: its per-digit loop as Python
        costs about 0.5 s per 5,000 rows of 13 columns), the exact vectorised path's (:func:`_layout`), which is the
        same text.  The view is valid until the next call."""
        text = None if interpreted() else self.rows(columns)
        if text is not None:
            return text
        fields = [_time_field(columns[0], self.t0_s)] if self.t0_s is not None else []
        fields += [_field_from_values(c, int(d)) for c, d in zip(columns[len(fields):], self.decimals[len(fields):])]
        layout: memoryview = _layout(fields, int(np.shape(columns[0])[0]), self.sep_text).data
        return layout

    def rows(self, columns: Sequence[np.ndarray]) -> memoryview | None:
        """The kernel's text of the rows of ``columns`` (as :meth:`text`; widened to float64 as
        they are copied in), or None when a finite value is too large for it.  The view is valid
        until the next call."""
        n = int(np.shape(columns[0])[0])
        if n > self.values.shape[1]:
            self.values = np.empty((len(self.decimals), n))
            self.out = np.empty(n * self.row_bytes, dtype=np.uint8)
        for j, c in enumerate(columns):
            self.values[j, :n] = c
        if self.t0_s is not None:
            self.values[0, :n] += self.t_frac
        size = _format_block(self.values, n, self.decimals, self.scales, self.offsets, self.sum_sign,
                             self.out, self.sep, _NAN, _INF, _NEG_INF)
        if size < 0:
            return None
        block: memoryview = self.out[:size].data
        return block
