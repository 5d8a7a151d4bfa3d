"""The intervals between consecutive IMU stamps, ``np.diff(t)``, without an array as long as the
log when the stamps are spilled (:mod:`navpp.spill`): their median, the mean of those up to a
limit and where they exceed one, each to the bit what the whole-log ``np.diff`` gives.

Stamps in memory are differenced whole (one window, the numpy call itself); spilled stamps window
by window (:func:`navpp.spill.windows`, which releases the pages each window read).  The median of
spilled intervals is found by selection on the intervals' bits: a float64's bits, as an integer
with the sign bit's meaning folded (:func:`_order_keys`), sort like the value, so a histogram of
16 bits at a time over the windows narrows down to the rows holding the wanted rank (at most
four passes, fewer once the candidates fit in a window).  The mean adds the intervals in the
order numpy's pairwise summation does (:func:`pairwise_sum`), so it is the same float.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from .spill import WINDOW_ROWS, spilled, windows

#: bits of an interval's key per selection pass
_DIGIT_BITS = 16
#: candidates of a selection pass few enough to be gathered and sorted instead of another pass
_GATHER_MAX = WINDOW_ROWS
#: rows numpy's pairwise summation adds as one block (a node of its halving tree, summed by
#: ``np.add.reduce`` itself)
_SUM_LEAF = WINDOW_ROWS
_LOW63 = np.int64(0x7FFFFFFFFFFFFFFF)


def _parts(t: np.ndarray) -> Iterator[np.ndarray]:
    """``np.diff(t)`` (s) in consecutive parts, window by window (one part for stamps in memory)."""
    n = t.shape[0]
    for a, b in windows(n, t):
        if a < n - 1:
            yield np.diff(t[a:min(b + 1, n)])


def _order_keys(d: np.ndarray) -> np.ndarray:
    """int64 keys of the float64 ``d`` that sort as the values do (the negatives' magnitude bits
    flipped)."""
    bits = d.view(np.int64)
    keys: np.ndarray = bits ^ ((bits >> 63) & _LOW63)
    return keys


def _key_value(key: int) -> float:
    """The float64 whose :func:`_order_keys` key is ``key``."""
    k = np.array([key], dtype=np.int64)
    return float((k ^ ((k >> 63) & _LOW63)).view(np.float64)[0])


def _ranked(t: np.ndarray, ranks: list[int], guess: int | None = None) -> dict[int, float]:
    """The intervals of the stamps ``t`` at the 0-based ``ranks`` of their ascending order (s), by
    selection on their keys: each pass histograms the next :data:`_DIGIT_BITS` bits of the keys
    that share the bits above with a rank's candidates; candidates few enough are gathered and
    sorted.  ``guess``: the top 64 - 2 :data:`_DIGIT_BITS` bits the ranks' keys likely share (from
    a sample): the first pass then histograms the keys with them and counts those below, and the
    search starts from the top only when a rank lies outside them.  NaN at every rank when an
    interval is NaN."""
    out: dict[int, float] = {}
    top = 64 - _DIGIT_BITS
    todo: list[tuple[int, int | None, list[int], int | None]] = \
        [(top, None, ranks, 0)] if guess is None else [(_DIGIT_BITS, guess, ranks, None)]
    size = 1 << _DIGIT_BITS
    while todo:
        shift, prefix, wanted, below = todo.pop()
        counts = np.zeros(size, np.int64)
        first = prefix is None or below is None         # the first pass: NaN checked, keys below counted
        under_guess = 0
        for d in _parts(t):
            if first and np.isnan(d).any():
                return {r: math.nan for r in ranks}     # as numpy's median: NaN
            k = _order_keys(d)
            if prefix is not None:
                high = k >> (shift + _DIGIT_BITS)
                if below is None:
                    under_guess += int(np.count_nonzero(high < prefix))
                k = k[high == prefix]
            digit = (k >> shift) + (size >> 1) if prefix is None else (k >> shift) & (size - 1)
            counts += np.bincount(digit, minlength=size)
        if below is None:
            below = under_guess
            if not all(below <= r < below + int(counts.sum()) for r in wanted):
                todo.append((top, None, wanted, 0))     # the guess missed: from the top
                continue
        cum = np.cumsum(counts)
        groups: dict[int, list[int]] = {}
        for r in wanted:
            groups.setdefault(int(np.searchsorted(cum, r - below, side="right")), []).append(r)
        for j, rs in groups.items():
            p = j - (size >> 1) if prefix is None else (prefix << _DIGIT_BITS) | j
            under = below + (int(cum[j - 1]) if j else 0)
            if shift == 0:
                out.update((r, _key_value(p)) for r in rs)
            elif counts[j] <= _GATHER_MAX:
                keys = np.sort(np.concatenate([k[(k >> shift) == p] for k in map(_order_keys, _parts(t))]))
                out.update((r, _key_value(int(keys[r - under]))) for r in rs)
            else:
                todo.append((shift - _DIGIT_BITS, p, rs, under))
    return out


def interval_median(t: np.ndarray) -> float:
    """``float(np.median(np.diff(t)))`` (s) for stamps ``t`` (N,) s, N >= 2; a spilled ``t``
    window by window (see the module docstring)."""
    if not spilled(t):
        return float(np.median(np.diff(t), overwrite_input=True))
    m = t.shape[0] - 1
    lo, hi = (m - 1) // 2, m // 2
    sample = np.diff(t[:WINDOW_ROWS + 1])               # the first window's intervals: the guess
    guess = int(_order_keys(np.median(sample, keepdims=True))[0]) >> (2 * _DIGIT_BITS)
    v = _ranked(t, sorted({lo, hi}), guess)
    return v[lo] if lo == hi else float((np.float64(v[lo]) + np.float64(v[hi])) / 2.0)


def long_intervals(t: np.ndarray, limit: float) -> np.ndarray:
    """Indices k (int64, ascending) of the intervals ``t[k + 1] - t[k]`` over ``limit`` s: the
    ``np.nonzero(np.diff(t) > limit)[0]`` of stamps ``t`` (N,) s."""
    parts, row = [], 0
    for d in _parts(t):
        parts.append(np.nonzero(d > limit)[0] + row)
        row += d.shape[0]
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def _leaves(n: int) -> Iterator[int]:
    """The lengths, in order, of the blocks numpy's pairwise summation of ``n`` values splits them
    into down to :data:`_SUM_LEAF` values (halves rounded down to a multiple of 8)."""
    if n <= _SUM_LEAF:
        yield n
        return
    half = n // 2
    half -= half % 8
    yield from _leaves(half)
    yield from _leaves(n - half)


def pairwise_sum(parts: Iterator[np.ndarray], n: int) -> np.float64:
    """``np.add.reduce`` of the concatenation of ``parts`` (``n`` float64 values in all), the same
    bits, holding no more than a leaf and a part: each leaf of numpy's halving tree
    (:func:`_leaves`) summed by ``np.add.reduce``, the leaves' sums added as the tree adds them."""
    sums: list[np.float64] = []
    buf = np.zeros(0)
    for size in _leaves(n):
        while buf.shape[0] < size:
            buf = np.concatenate([buf, next(parts)])
        sums.append(np.float64(np.add.reduce(buf[:size])))
        buf = buf[size:]
    for _ in parts:         # the rest (empty): the windows' pages released
        pass
    it = iter(sums)

    def tree(k: int) -> np.float64:
        if k <= _SUM_LEAF:
            return next(it)
        half = k // 2
        half -= half % 8
        left = tree(half)
        return left + tree(k - half)
    return tree(n)


def mean_interval(t: np.ndarray, limit: float) -> float | None:
    """The mean (s) of the intervals of the stamps ``t`` (N,) s up to ``limit`` s: ``d[d <=
    limit].mean()`` of ``d = np.diff(t)`` to the bit; None when there is none."""
    if not spilled(t):
        d = np.diff(t)
        keep = d <= limit
        if not keep.all():      # else the same mean without a copy
            d = d[keep]
        return float(d.mean()) if d.size else None
    n = sum(int(np.count_nonzero(d <= limit)) for d in _parts(t))
    if n == 0:
        return None
    return float(pairwise_sum((d[d <= limit] for d in _parts(t)), n) / n)


__all__ = ["interval_median", "long_intervals", "mean_interval", "pairwise_sum"]
