"""IMU-rate arrays that do not stay in memory: beyond the run's memory budget (``[output] memory``,
``--memory``) the IMU samples as read (:mod:`navpp.io.csv` writes them there block by block), the
path, the output 1-sigma and the body rate live in a file-backed mapping whose pages each
sequential pass releases behind itself (:func:`windows`, :class:`Behind`).

The file is a temporary file in ``$TMPDIR`` (Python's :func:`tempfile.gettempdir`, as the
smoother's :class:`~navpp.filters.smoother.ForwardStore` spills), unlinked at once (on Linux it
never has a name): it disappears when the last array on it is freed, on an error or Ctrl-C too.
A tmpfs ``/tmp`` is RAM: point ``TMPDIR`` at a disk directory for the spill to save memory.
The mapping is ``MAP_SHARED``, so releasing pages (``madvise(MADV_DONTNEED)``) keeps their data
in the file (the page cache writes it back) and a later access reads it again: a release is a
hint about memory, never a change of the values, and a pass that touches a released row again
gets the same bits.  Arrays not on a mapping (the budget not exceeded) are left alone by every
function here, so the callers need no second path.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import mmap
import os
import tempfile
import weakref
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import NavppError

#: rows per window of a sequential pass over a spilled array (64 Ki: 5 MB of the (N, 10) path)
WINDOW_ROWS = 1 << 16
#: bytes a spilled array written in order keeps in memory behind its writer before
#: :func:`release_before` releases them (1 MiB: a window of the (N, 10) path is 5 MB, of the
#: per-fix (M, 3, 3) records 4.7 MB, and an 8-hour run writes about ten such arrays at once)
RELEASE_BYTES = 1 << 20
#: bytes around a faulting page that Linux maps from the page cache with it (``fault_around_bytes``,
#: 64 KiB by default): :func:`release` releases them before the rows too
FAULT_AROUND = 1 << 16


@dataclass
class _Mapping:
    """One spill file's mapping: the ``mmap`` (held here until its array is freed), the address
    of its first byte in this process, its size in bytes, and the bytes from its start that
    :func:`release_before` has released."""

    mm: mmap.mmap
    address: int
    size: int
    released: int = 0


#: the live mappings by ``id`` of their ``mmap`` (an entry goes when the mapping's array is freed)
_MAPPINGS: dict[int, _Mapping] = {}


def empty_rows(n_rows: int, row_shape: tuple[int, ...], dtype: Any, spill: bool,
               what: str = "IMU-rate output") -> np.ndarray:
    """An uninitialised (n_rows, *row_shape) array: in memory, or with ``spill`` on a mapping of
    an unlinked temporary file in ``$TMPDIR`` (see the module docstring); ``what`` names the
    array in the error of a spill that does not fit."""
    shape = (int(n_rows), *row_shape)
    dt = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
    if not spill or nbytes == 0:
        return np.empty(shape, dt)
    with tempfile.TemporaryFile(prefix="navpp-output-") as f:   # the mapping keeps the file alive
        try:    # blocks reserved now: a full disk later would kill the process (SIGBUS), not raise
            os.posix_fallocate(f.fileno(), 0, nbytes)
        except OSError as exc:
            raise NavppError(
                f"cannot spill {nbytes / 2**20:.0f} MB of {what} to {tempfile.gettempdir()} "
                f"({exc.strerror or exc}): free space there, set TMPDIR to a disk with room, or raise "
                "--memory ([output] memory) to keep it in memory") from None
        mm = mmap.mmap(f.fileno(), nbytes, flags=mmap.MAP_SHARED, prot=mmap.PROT_READ | mmap.PROT_WRITE)
    root = np.frombuffer(mm, np.uint8)            # every view's base: its end frees the entry
    _MAPPINGS[id(mm)] = _Mapping(mm, root.ctypes.data, nbytes)
    weakref.finalize(root, _MAPPINGS.pop, id(mm), None)
    out: np.ndarray = root.view(dt).reshape(shape)
    return out


def like(rows: np.ndarray, n_rows: int, row_shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    """:func:`empty_rows` spilled if and only if ``rows`` is (the outputs of a pass follow its input)."""
    return empty_rows(n_rows, row_shape, dtype, spilled(rows))


def _mapping(a: np.ndarray) -> _Mapping | None:
    """The mapping ``a`` (or the array it is a view of) lives on; None: it is in memory."""
    base: Any = a
    while isinstance(base, np.ndarray):
        base = base.base
    if isinstance(base, memoryview):           # np.frombuffer's base: a view of the mmap
        base = base.obj
    m = _MAPPINGS.get(id(base)) if isinstance(base, mmap.mmap) else None
    return m if m is not None and m.mm is base else None


def spilled(a: np.ndarray | None) -> bool:
    """Whether ``a`` lives on a spill mapping."""
    return a is not None and _mapping(a) is not None


def release(arrays: Iterable[np.ndarray | None], start: int, stop: int) -> None:
    """Release the pages of rows ``start:stop`` of each spilled array in ``arrays`` (views of a
    spilled array included; the others are skipped): the pages holding the rows' bytes leave
    the process's memory and their data stays in the file (a page the rows share with a
    neighbour goes too: the neighbour's next access reads it back).  The :data:`FAULT_AROUND`
    bytes before the rows go too: a read of the rows' first page maps the cached pages around it
    again, those before it included, and a pass releasing window by window would leave them."""
    for a in arrays:
        m = None if a is None or stop <= start else _mapping(a)
        if m is None:
            continue
        assert a is not None
        first = a.__array_interface__["data"][0] - m.address + start * a.strides[0]
        end = min(first + (stop - start) * a.strides[0], m.size)
        first = max(first - FAULT_AROUND, 0) // mmap.PAGESIZE * mmap.PAGESIZE
        end = -(-end // mmap.PAGESIZE) * mmap.PAGESIZE
        if end > first:
            m.mm.madvise(mmap.MADV_DONTNEED, first, end - first)


def release_all(*arrays: np.ndarray | None) -> None:
    """Release every row of each spilled array in ``arrays`` (after a pass over them, so that
    the pages it touched do not stay resident: the next pass reads them back)."""
    for a in arrays:
        if a is not None and a.ndim:
            release((a,), 0, a.shape[0])


def release_before(a: np.ndarray, row: int) -> None:
    """Release the rows of a spilled ``a`` before ``row`` once they make :data:`RELEASE_BYTES` more
    than the last release (cheap to call per GNSS epoch from a loop writing ``a`` in order)."""
    m = _mapping(a)
    if m is None:
        return
    offset = a.__array_interface__["data"][0] - m.address + row * a.strides[0]   # from the mapping's start
    if offset - m.released < RELEASE_BYTES:
        return
    end = offset // mmap.PAGESIZE * mmap.PAGESIZE
    if end > m.released:
        m.mm.madvise(mmap.MADV_DONTNEED, m.released, end - m.released)
        m.released = end


def windows(n_rows: int, *arrays: np.ndarray | None, rows: int | None = None) -> Iterator[tuple[int, int]]:
    """``(start, stop)`` windows of :data:`WINDOW_ROWS` rows over ``n_rows`` rows, one window for an
    array in memory (given ``rows``: windows of that many rows either way, for a pass whose
    per-row temporaries are larger than its arrays); after each window the rows of the spilled
    ``arrays`` are released."""
    step = rows if rows is not None else WINDOW_ROWS if any(spilled(a) for a in arrays) else max(n_rows, 1)
    for start in range(0, n_rows, step):
        stop = min(n_rows, start + step)
        yield start, stop
        release(arrays, start, stop)


class Behind:
    """Releases the rows of spilled arrays that a pass in time order has left behind: ``t`` (N,)
    the rows' stamps (s, increasing; released too), ``arrays`` sampled at them (the IMU's gyro
    and accel).  ``behind(t_s)`` releases the rows stamped before ``t_s`` once they make
    :data:`WINDOW_ROWS` more than the last release (cheap to call per epoch).  A pass that
    starts again before the last release (another run over the same samples) releases from
    where it starts.  Nothing spilled: a call costs nothing."""

    def __init__(self, t: np.ndarray | None, *arrays: np.ndarray | None) -> None:
        self.t = t
        self.arrays = [a for a in (t, *arrays) if spilled(a)]
        self.row = 0            # the rows before it are released
        self._mark()

    def _mark(self) -> None:
        """The stamps (s) of row ``self.row`` and of the row a window after it: between them a
        call has nothing to do."""
        n = 0 if self.t is None or not self.arrays else self.t.shape[0]
        self.t_row = float(self.t[min(self.row, n - 1)]) if n else math.inf
        self.t_next = float(self.t[self.row + WINDOW_ROWS]) if self.row + WINDOW_ROWS < n else math.inf

    def __call__(self, t_s: float) -> None:
        if self.t_row <= t_s < self.t_next or not self.arrays:
            return
        assert self.t is not None
        row = int(np.searchsorted(self.t, t_s))
        if row < self.row:
            self.row = row
        elif row - self.row >= WINDOW_ROWS:
            release(self.arrays, self.row, row)
            self.row = row
        self._mark()


def full_rows(n_rows: int, row_shape: tuple[int, ...], value: float, spill: bool) -> np.ndarray:
    """:func:`empty_rows` (float64) filled with ``value``, window by window when spilled."""
    out = empty_rows(n_rows, row_shape, np.float64, spill)
    for a, b in windows(n_rows, out):
        out[a:b] = value
    return out


def copy_rows(rows: np.ndarray) -> np.ndarray:
    """A copy of ``rows``, spilled like it, copied window by window."""
    out = like(rows, rows.shape[0], rows.shape[1:], rows.dtype)
    for a, b in windows(rows.shape[0], rows, out):
        out[a:b] = rows[a:b]
    return out


def _malloc_trim() -> Any:
    """glibc's ``malloc_trim`` (None on another C library: musl, macOS, Windows)."""
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


_TRIM = _malloc_trim()
#: glibc's ``mallopt`` parameter of the size from which a block is its own mapping
_M_MMAP_THRESHOLD = -3
#: blocks of at least this many bytes get their own mapping in a long run (:func:`map_large_blocks`)
LARGE_BLOCK = 4 << 20


#: Whether :func:`map_large_blocks` may change the C allocator's setting, which is process-wide
#: and for good: the ``navpp`` command allows it (:func:`allow_large_block_mapping`); a program
#: that calls :func:`navpp.process` keeps glibc's own setting.
_LARGE_BLOCKS_ALLOWED = [False]


def allow_large_block_mapping() -> None:
    """Let :func:`map_large_blocks` act in this process (the ``navpp`` command calls this)."""
    _LARGE_BLOCKS_ALLOWED[0] = True


def map_large_blocks() -> None:
    """From now on, give every block of :data:`LARGE_BLOCK` bytes or more its own mapping, which
    goes back to the system when it is freed (glibc ``mallopt(M_MMAP_THRESHOLD)``; elsewhere
    nothing is done).  By default glibc raises that threshold to the largest block freed so far
    (up to 32 MB), so a long run's reference-, GNSS- and window-length temporaries come from the
    heap, whose freed holes the next stage's blocks of other sizes do not fill: an 8-hour run's
    peak with metrics 316 -> 298 MB.  It costs a page fault per page of each such block, so a run
    whose arrays stay in memory (the budget not exceeded: the fastest case) leaves it alone.  It
    stays set for the process (glibc cannot go back to the adaptive threshold); values are
    untouched.  Only in the ``navpp`` command (:func:`allow_large_block_mapping`): a library
    user's process keeps its allocator as it was."""
    if _TRIM is None or not _LARGE_BLOCKS_ALLOWED[0]:
        return
    name = ctypes.util.find_library("c")
    ctypes.CDLL(name).mallopt(ctypes.c_int(_M_MMAP_THRESHOLD), ctypes.c_int(LARGE_BLOCK))


def trim_heap() -> None:
    """Give the pages of freed memory back to the system after a stage that freed large arrays.
    glibc keeps a freed block of up to 32 MB in the process once a block that large was freed
    (its mmap threshold rises to it), so the IMU- and GNSS-length transients of one stage stay
    resident beside the next stage's (8-hour log: 175 MB after ``engine.run``);
    ``malloc_trim(0)`` releases the free pages (a few ms).  Values are untouched; without glibc
    nothing is done."""
    if _TRIM is not None:
        _TRIM(0)


__all__ = ["LARGE_BLOCK", "RELEASE_BYTES", "WINDOW_ROWS", "Behind", "allow_large_block_mapping", "copy_rows",
           "empty_rows", "full_rows", "like", "map_large_blocks", "release", "release_all", "release_before", "spilled",
           "trim_heap", "windows"]
