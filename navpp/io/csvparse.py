"""Fast path of the CSV reader: the numeric columns of a plain comma-separated file, parsed by
a numba kernel (:func:`_parse_block`) a 4 MiB block of the file at a time (read into one reused
buffer, not mapped: a file cut short while it is read is an error line, not a SIGBUS), without pandas.

The kernel takes only the plain form every logger writes: each data line ``n_fields`` cells
separated by ``,``, ended by ``\\n`` or ``\\r\\n`` (the last one may lack it); a wanted cell is
``[+-]digits[.digits][(e|E)[+-]digits]`` with no blanks.  Decimal to binary is the
Eisel-Lemire algorithm (Lemire, "Number parsing at a gigabyte per second", 2021; the form
without fallback of Mushtak and Lemire, 2023, as in the ``fast_float`` library): correctly
rounded (half-even), so every value is the double Python's ``float`` and pandas give for the
same text; the stamp column also becomes exact integer nanoseconds.  Digits are taken eight
at a time where eight follow (SWAR), and the buffer is indexed unsigned (numba tests signed
indices for wraparound on every byte).  Anything else (an empty or quoted cell, ``nan``,
blanks, a blank line, a wrong number of cells, a byte outside ASCII, more than 19 significant
digits, a value that would be subnormal or overflow) makes :func:`parse_columns` return None,
and the caller reads the file with its exact, slower parser that also locates and names the
fault.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navpp.kernel import njit, on_numba
from navpp.spill import empty_rows, release, spilled, windows

#: numba's count of leading zero bits (an intrinsic), set when numba is imported: a run on the
#: native kernels (:mod:`navpp.kernel`) or interpreted (pandas parses then) never calls it.
leading_zeros: Any = None


def _numba_parts() -> None:
    global leading_zeros
    from numba.cpython.unsafe.numbers import leading_zeros as numba_leading_zeros

    leading_zeros = numba_leading_zeros


on_numba(_numba_parts)

__all__ = ["parse_columns"]

_BLOCK_BYTES = 1 << 22
"""Bytes of the file mapped per call of the kernel (4 MiB): the file is never held whole."""

_OK, _FALLBACK, _FULL = 0, 1, 2     # kernel status: block done; not the plain form; output full

_NONE = -(1 << 62)                  # in the decimals' stats: no row yet

_SMALLEST_POWER = -342              # 10^q with q below this is 0, above _LARGEST_POWER infinite
_LARGEST_POWER = 308


def _powers_of_five() -> np.ndarray:
    """(2 * 651,) uint64: for q = -342..308, 5^q as a 128-bit number normalised so that its top
    bit is bit 127 (high word, low word), truncated for q >= 0 and rounded up (with extra
    precision) for q < 0, as ``fast_float``'s table generator makes it."""
    words: list[int] = []
    for q in range(_SMALLEST_POWER, _LARGEST_POWER + 1):
        if q < 0:
            power5 = 5 ** -q
            z = power5.bit_length()           # the least z with 2^z >= 5^-q (never a power of 2)
            b = z + 127 if q >= -27 else 2 * z + 128
            c = 2 ** b // power5 + 1
        else:
            c = 5 ** q
        shift = c.bit_length() - 128          # top bit to bit 127: shifted left, or truncated right
        c = c << -shift if shift < 0 else c >> shift
        words += [c >> 64, c & ((1 << 64) - 1)]
    return np.array(words, dtype=np.uint64)


_POW5 = _powers_of_five()


@njit(cache=True, inline="always")
def _mul128(a, b):
    """High and low 64-bit words of the 128-bit product of uint64 ``a`` and ``b``."""
    m32 = np.uint64(0xFFFFFFFF)
    s32 = np.uint64(32)
    a_lo, a_hi = a & m32, a >> s32
    b_lo, b_hi = b & m32, b >> s32
    p0 = a_lo * b_lo
    p1 = a_lo * b_hi
    p2 = a_hi * b_lo
    p3 = a_hi * b_hi
    mid = (p0 >> s32) + (p1 & m32) + (p2 & m32)
    lo = (p0 & m32) | (mid << s32)
    hi = p3 + (p1 >> s32) + (p2 >> s32) + (mid >> s32)
    return hi, lo


@njit(cache=True, inline="always")
def _to_bits(w, q, negative, pow5):
    """IEEE-754 bits (uint64) of the double nearest ``w * 10^q`` (``w`` uint64 > 0 of at most 19
    digits), or 0 with ``ok`` False when the result would be subnormal or overflow."""
    one = np.uint64(1)
    sign = np.uint64(1) << np.uint64(63) if negative else np.uint64(0)
    if q < _SMALLEST_POWER or q > _LARGEST_POWER:
        return np.uint64(0), False
    lz = np.int64(leading_zeros(w))         # w shifted so that its top bit is bit 63
    w <<= np.uint64(lz)
    index = 2 * (q - _SMALLEST_POWER)
    hi, lo = _mul128(w, pow5[index])
    mask = np.uint64(0x1FF)                   # the bits below the 55 the rounding needs
    if hi & mask == mask:                     # the truncated power may matter: refine
        hi2, _ = _mul128(w, pow5[index + 1])
        new_lo = lo + hi2
        if hi2 > new_lo:
            hi += one
        lo = new_lo
    upper = hi >> np.uint64(63)
    shift = upper + np.uint64(9)
    mantissa = hi >> shift
    power2 = (((152170 + 65536) * q) >> 16) + 63 + np.int64(upper) - lz + 1023
    if power2 <= 0:
        return np.uint64(0), False
    if lo <= one and -4 <= q <= 23 and mantissa & np.uint64(3) == one and (mantissa << shift) == hi:
        mantissa &= ~one                      # exactly half-way: round to even
    mantissa += mantissa & one
    mantissa >>= one
    if mantissa >= (np.uint64(2) << np.uint64(52)):
        mantissa = one << np.uint64(52)
        power2 += 1
    mantissa &= ~(one << np.uint64(52))
    if power2 >= 0x7FF:
        return np.uint64(0), False
    return sign | mantissa | (np.uint64(power2) << np.uint64(52)), True


@njit(cache=True)
def _digits(buf, i, w):
    """``w`` with the decimal digits from ``buf[i]`` on appended (uint64, wraps beyond 19
    digits), and the index of the first byte that is not a digit.

    Eight digits at a time while eight bytes are digits (SWAR: Lemire's test and conversion of
    eight ASCII digits in a 64-bit word), then one at a time."""
    ten = np.uint64(10)
    high = np.uint64(0xF0F0F0F0F0F0F0F0)
    while i + 8 <= buf.shape[0]:
        j = np.uint64(i)            # unsigned: no wraparound test, so that the 8 loads fuse into one
        v = np.uint64(0)
        for k in range(8):          # buf[i:i + 8] as one little-endian uint64 (first byte lowest)
            v |= np.uint64(buf[j + np.uint64(k)]) << np.uint64(8 * k)
        # every byte 0x30..0x39: high nibble 3, and adding 6 leaves it 3
        if ((v & high) | (((v + np.uint64(0x0606060606060606)) & high) >> np.uint64(4))) \
                != np.uint64(0x3333333333333333):
            break
        v -= np.uint64(0x3030303030303030)
        v = v * ten + (v >> np.uint64(8))                   # byte pairs: 2-digit values
        mask = np.uint64(0x000000FF000000FF)
        v = ((v & mask) * np.uint64(0x000F424000000064)
             + ((v >> np.uint64(16)) & mask) * np.uint64(0x0000271000000001)) >> np.uint64(32)
        w = w * np.uint64(100000000) + (v & np.uint64(0xFFFFFFFF))
        i += 8
    while True:
        d = np.uint64(buf[np.uint64(i)]) - np.uint64(48)      # wraps to a huge value below '0'
        if d > 9:
            return w, i
        w = w * ten + d
        i += 1


_NO_NS = np.uint64(1) << np.uint64(63)
"""In the stamp row: a value whose nanoseconds do not fit int64 (as int64: its minimum)."""


@njit(cache=True, inline="always")
def _exact_ns(w, q, negative):
    """``w * 10^(q + 9)`` (``w`` uint64 of at most 19 digits) rounded half-even to an integer,
    with the sign, as int64 two's-complement bits in a uint64; :data:`_NO_NS` if it does not fit."""
    ten = np.uint64(10)
    shift = q + 9
    if shift >= 0:
        for _ in range(shift):
            if w > np.uint64(922337203685477580):    # (2^63 - 1) // 10: the next step overflows
                return _NO_NS
            w *= ten
    elif w != 0:
        if shift < -19:
            w = np.uint64(0)                         # below 10^-19 of 1 ns: rounds to 0
        else:
            p = np.uint64(1)
            for _ in range(-shift):
                p *= ten
            quotient = w // p
            rest = w - quotient * p
            half = p >> np.uint64(1)
            if rest > half or (rest == half and quotient & np.uint64(1) == np.uint64(1)):
                quotient += np.uint64(1)
            w = quotient
    if w >= _NO_NS:
        return _NO_NS
    return (~w + np.uint64(1)) if negative and w != 0 else w


@njit(cache=True)
def _parse_block(buf, target, component, stamp_field, outs, row0, pow5, stats):
    """Parse the whole lines of ``buf`` (those up to its last ``\n``; the bytes after it are left)
    into ``outs[target[field]][row0 + row, component[field]]`` as IEEE bits (``outs`` a tuple of
    (capacity, width) uint64 arrays).

    ``target`` (n_fields,) int64: the output array of each field, -1 for a field not wanted;
    ``component`` (n_fields,) int64: its column there.  Field ``stamp_field`` (if >= 0) is also
    written to ``outs[-1][:, 0]`` as the exact integer nanoseconds its text says (:func:`_exact_ns`),
    and the decimals its text carries (digits after the point less the exponent) raise
    ``stats[0]`` (over rows ``row < stats[3]``) and ``stats[1]`` (over all rows) to their most;
    ``stats[2]`` becomes 1 when a field not wanted holds a CR not followed by LF (a line end
    to a reader with universal newlines).
    Returns (rows parsed, bytes consumed, status): ``_OK``; ``_FULL`` when ``outs`` have no room
    for the next line (consumed stops before it); ``_FALLBACK`` when a line is not in the plain
    form (see the module docstring)."""
    # buf[np.uint64(i)]: every index is >= 0; as unsigned, numba adds no wraparound test per byte
    stop = buf.shape[0]
    while stop > 0 and buf[np.uint64(stop - 1)] != 10:
        stop -= 1
    n_fields = target.shape[0]
    capacity = outs[0].shape[0]
    last = len(outs) - 1
    pos = 0
    row = row0
    most_first, most, first_rows = stats[0], stats[1], stats[3]   # in registers, not in memory
    while pos < stop:
        if row == capacity:
            stats[0], stats[1] = most_first, most
            return row - row0, pos, _FULL
        i = pos
        for field in range(n_fields):
            col = target[field]
            if col < 0:                       # a field not wanted: skip it
                while True:
                    c = buf[np.uint64(i)]
                    if c == 44 or c == 10 or (c == 13 and buf[np.uint64(i + 1)] == 10):
                        break
                    if c == 34 or c >= 128:
                        return row - row0, pos, _FALLBACK
                    if c == 13:
                        stats[2] = 1
                    i += 1
            else:
                c = buf[np.uint64(i)]
                negative = c == 45
                if c == 45 or c == 43:
                    i += 1
                int_start = i
                while buf[np.uint64(i)] == 48:           # leading zeros
                    i += 1
                sig_start = i
                w, i = _digits(buf, i, np.uint64(0))
                n_sig = i - sig_start
                if i == int_start:
                    return row - row0, pos, _FALLBACK   # no digit before the point (or the cell)
                exp10 = 0
                if buf[np.uint64(i)] == 46:
                    i += 1
                    frac_start = i
                    if n_sig == 0:
                        while buf[np.uint64(i)] == 48:   # zeros after "0.": not significant
                            i += 1
                    sig_start = i
                    w, i = _digits(buf, i, w)
                    n_sig += i - sig_start
                    exp10 = frac_start - i
                    if i == frac_start:
                        return row - row0, pos, _FALLBACK   # no digit after the point
                if n_sig > 19:
                    return row - row0, pos, _FALLBACK       # more precision than 19 digits
                c = buf[np.uint64(i)]
                if c == 101 or c == 69:
                    i += 1
                    c = buf[np.uint64(i)]
                    e_negative = c == 45
                    if c == 45 or c == 43:
                        i += 1
                    e_start = i
                    while buf[np.uint64(i)] == 48:
                        i += 1
                    digits_start = i
                    e, i = _digits(buf, i, np.uint64(0))
                    if i == e_start or i - digits_start > 4:
                        return row - row0, pos, _FALLBACK   # no exponent digit, or an absurd one
                    exp10 += -np.int64(e) if e_negative else np.int64(e)
                if w == 0:
                    bits = np.uint64(1) << np.uint64(63) if negative else np.uint64(0)
                else:
                    bits, ok = _to_bits(w, exp10, negative, pow5)
                    if not ok:
                        return row - row0, pos, _FALLBACK
                outs[col][np.uint64(row), np.uint64(component[field])] = bits
                if field == stamp_field:
                    outs[last][np.uint64(row), 0] = _exact_ns(w, exp10, negative)
                    most = max(most, -exp10)
                    if row < first_rows:
                        most_first = max(most_first, -exp10)
            if field < n_fields - 1:
                if buf[np.uint64(i)] != 44:
                    return row - row0, pos, _FALLBACK   # too few fields, or not a plain number
                i += 1
        if buf[np.uint64(i)] == 13:
            i += 1
        if buf[np.uint64(i)] != 10:
            return row - row0, pos, _FALLBACK           # too many fields, or not a plain number
        row += 1
        pos = i + 1
    stats[0], stats[1] = most_first, most
    return row - row0, pos, _OK


def parse_columns(path: Path, n_fields: int, positions: list[int], stamp_position: int | None = None,
                  progress: Callable[[float], None] | None = None, widths: Sequence[int] | None = None,
                  budget_bytes: int | None = None, decimals: list[int] | None = None,
                  decimal_rows: int = 2000) -> tuple[list[np.ndarray], np.ndarray | None] | None:
    """The data rows of CSV file ``path`` (a header line, then rows of ``n_fields`` cells) as
    float64 arrays, the fields ``positions`` split in consecutive groups of ``widths`` (default
    one each): a group of one an (n_rows,) array, a wider one an (n_rows, width) C-contiguous
    array, so that the caller keeps them as they are (nothing is copied after the parse).  For
    field ``stamp_position`` (one of ``positions``), also the exact integer nanoseconds each
    cell's text says ((n_rows,) int64, half-even at 1 ns; None if one does not fit int64).  None
    when the file is not in the plain form the kernel takes (then nothing is known about why).
    ``progress(fraction)`` follows the bytes read.  When the arrays would hold more than
    ``budget_bytes`` (None: never) they are made on a spill file (:mod:`navpp.spill`) and each
    window's rows are released once parsed, so the file's values never stay in memory whole.
    When ``decimals`` (a list) is given, the most decimals a stamp cell carries (digits after
    the point less the exponent; -2**62 for no row) over the first ``decimal_rows`` rows and
    over all rows are appended to it, unless the header or a cell not wanted holds a lone CR (a
    line break to Python's universal newlines, not to this parse)."""
    widths = [1] * len(positions) if widths is None else list(widths)
    target = np.full(n_fields, -1, dtype=np.int64)
    component = np.zeros(n_fields, dtype=np.int64)
    starts = np.cumsum([0] + widths)
    for g, width in enumerate(widths):
        target[positions[starts[g]:starts[g] + width]] = g
        component[positions[starts[g]:starts[g] + width]] = np.arange(width)
    stamp_field = -1 if stamp_position is None else stamp_position
    shapes = widths + [1] * (stamp_position is not None)     # the stamps' ns in the last array
    with open(path, "rb") as fh:
        info = os.fstat(fh.fileno())
        if not stat.S_ISREG(info.st_mode):
            return None                       # a pipe or device: the slow path reads it
        size = info.st_size
        header = fh.readline(_BLOCK_BYTES)
        if not header.endswith(b"\n") or b'"' in header:
            return None
        header_cr = b"\r" in header[:-2 if header.endswith(b"\r\n") else -1]   # a lone CR: a line end to text mode
        sample = fh.read(1 << 16)
        # room for the rows if they are as long as those of the first 64 KiB, and 5 % more;
        # grown if not (pages never written cost no memory)
        per_row = len(sample) / max(sample.count(b"\n"), 1)
        capacity = int((size - len(header)) / max(per_row, 1.0) * 1.05) + 16
        spill = budget_bytes is not None and capacity * sum(shapes) * 8 > budget_bytes
        what = f"the values of {path.name}"
        outs = tuple(empty_rows(capacity, (width,), np.uint64, spill, what) for width in shapes)
        rows = 0
        start = len(header)                   # file offset of the first line not parsed yet
        buf = np.empty(_BLOCK_BYTES + 1, dtype=np.uint8)    # one byte more: the last line's missing end
        stats = np.array([_NONE, _NONE, 0, decimal_rows], dtype=np.int64)
        while start < size:
            # read into one reused buffer, not mapped: a file cut short while it is read must
            # give an error line, not a SIGBUS
            fh.seek(start)
            got = fh.readinto(buf[:min(_BLOCK_BYTES, size - start)].data)
            if got < min(_BLOCK_BYTES, size - start):
                raise OSError(f"the file got shorter while it was read (at byte {start + got} of {size})")
            last = start + got == size
            if last and buf[got - 1] != 10:
                buf[got] = 10                 # the last line lacks its end: give it one
                got += 1
            done, outs, status = _parse_lines(buf[:got], target, component, stamp_field, outs, rows, stats,
                                              budget_bytes)
            release(outs, rows, rows + done[0])
            rows += done[0]
            if status == _FALLBACK:
                return None
            if done[1] == 0 or (last and done[1] < got):
                return None                   # no line end in a block: the slow path says why
            start = size if last else start + done[1]
            if progress is not None:
                progress(min(start / max(size, 1), 1.0))
        if os.fstat(fh.fileno()).st_size != size:
            raise OSError("the file changed size while it was read")
        if rows == 0:
            return None                       # no data line: the slow path says so
    values = [out[:rows, 0].view(np.float64) if width == 1 else out[:rows].view(np.float64)
              for out, width in zip(outs, widths)]
    if decimals is not None and stamp_position is not None and stats[2] == 0 and not header_cr:
        decimals += [int(stats[0]), int(stats[1])]
    if stamp_position is None:
        return values, None
    stamps = outs[-1][:rows, 0]
    missing = any(bool(np.any(stamps[a:b] == _NO_NS)) for a, b in windows(rows, stamps))
    return values, None if missing else stamps.view(np.int64)


def _parse_lines(buf: np.ndarray, target: np.ndarray, component: np.ndarray, stamp_field: int,
                 outs: tuple[np.ndarray, ...], rows: int, stats: np.ndarray,
                 budget_bytes: int | None = None) -> tuple[tuple[int, int], tuple[np.ndarray, ...], int]:
    """The whole lines of ``buf`` (uint8) parsed into ``outs`` from row ``rows`` on by
    :func:`_parse_block` (``stats`` as there), the outputs grown as often as they fill (onto the
    spill file once they would hold more than ``budget_bytes``; None: never): ((rows parsed, bytes consumed), the
    outputs, status ``_OK`` or ``_FALLBACK``)."""
    done = used = 0
    while True:
        n, u, status = _parse_block(buf[used:], target, component, stamp_field, outs, rows + done, _POW5, stats)
        done += n
        used += u
        if status != _FULL:
            return (done, used), outs, status
        capacity = outs[0].shape[0] * 5 // 4 + 1024
        spill = any(spilled(out) for out in outs) or (
            budget_bytes is not None and capacity * sum(out.shape[1] for out in outs) * 8 > budget_bytes)
        outs = tuple(_grown(out, rows + done, capacity, spill) for out in outs)


def _grown(out: np.ndarray, rows: int, capacity: int, spill: bool) -> np.ndarray:
    """``out`` (capacity, width) with its first ``rows`` rows kept and room for ``capacity``
    (on the spill file if ``spill``, copied a window at a time)."""
    bigger = empty_rows(capacity, (out.shape[1],), out.dtype, spill, "the parsed CSV values")
    for a, b in windows(rows, out, bigger):
        bigger[a:b] = out[a:b]
    return bigger
