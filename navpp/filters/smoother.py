"""Rauch-Tung-Striebel smoothing over a stored forward run, generic over the model.

The forward filter is closed-loop: after each update the estimated error is fed back into the
nominal state, so the forward run is a chain of *nodes* (the start, then the end of every time
update, with or without a measurement there).  Of node ``k`` the forward run has

- ``x_prior[k], P_prior[k]``: the prior the measurement update used (for most filters the time
  update's output; the prior an adaptive filter actually corrected, e.g. the AUKF's faded
  covariance or the RWCKF's re-weighted moments);
- ``x_post[k], P_post[k]``: the posterior (= the prior when nothing was applied);
- ``D[k]``: the cross-covariance of the error at node ``k - 1`` (posterior) with the error at
  node ``k`` (prior), ``E[dx_{k-1} dx_k^T]``: ``P_{k-1}^+ Phi^T`` for the EKF, the weighted sum
  of centred point deviations ``sum_i w_i dX_i dY_i^T`` for the sigma-point filters (the
  unscented / cubature RTS smoother, Särkkä 2008);
- ``x_ref[k]``: the nominal the time update propagated to node ``k`` (the path the model
  recorded between nodes: the EKF's prior mean, the sigma-point filters' central point);
- ``reset[k]``: the update re-anchored the covariance (a fix forced through the gate): no
  information is carried back across it (the forward filter itself declared its prior wrong).

Backward, for ``k = M-2 .. 0`` (docs/algorithms.md; error-state form of Rauch, Tung & Striebel 1965):

``C_k = D_{k+1} (P_{k+1}^-)^{-1}`` (Cholesky solve),
``x_k^s = x_k^+ ⊞ C_k (x_{k+1}^s ⊟ x_{k+1}^-)``,
``P_k^s = P_k^+ + C_k (P_{k+1}^s - P_{k+1}^-) C_k^T = M_k + C_k P_{k+1}^s C_k^T`` with
``M_k = P_k^+ - C_k D_{k+1}^T`` (``C_k P_{k+1}^- C_k^T = C_k D_{k+1}^T``).

The store (:class:`ForwardStore`) computes ``C_k`` and ``M_k`` in float64 during the forward
run, as soon as node ``k + 1``'s prior is final (a reset at ``k + 1`` or a prior that is not
positive definite: ``C_k = 0``), so the backward pass factors nothing.  Per node it keeps the
nominal states ``x_post``, ``x_prior``, ``x_ref`` (float64), ``C_k`` (in the row of node
``k + 1``, as the mean recursion reads it) and the upper triangle of ``M_k`` (in the store's
dtype, float32 by default: the 15-state INS needs 1.8 kB per node, about 35 MB per hour of
5 Hz GNSS with 1 s coast knots), in blocks of :data:`BLOCK_NODES` nodes; beyond a memory
budget the full blocks go to an unlinked temporary file.  The backward pass reads the blocks
back newest first and keeps of the smoothed covariance only its diagonal.
"""

from __future__ import annotations

import io
import tempfile
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import FilterDivergedError
from ..spill import trim_heap
from .linalg import chol_solve, cholesky, compiled
from .protocols import SmoothableModel
from .states import GaussianState, Prediction

#: nodes per block of the store: the unit in which it grows, spills and is smoothed
BLOCK_NODES = 4096
#: bytes of blocks the store keeps in memory before it spills full ones to a temporary file
DEFAULT_BUDGET_BYTES = 128 << 20


@dataclass
class _Node:
    """A node not yet in a block: what the forward run made of it (float64, by reference) and
    ``gain`` (n, n), ``C_{k-1}`` into it (zero for node 0 and across a break)."""

    t: float
    x_prior: np.ndarray
    x_post: np.ndarray
    x_ref: np.ndarray
    P_prior: np.ndarray
    P_post: np.ndarray
    D: np.ndarray
    reset: bool = False
    gain: np.ndarray | None = None


@compiled
def _close_step(P_post: np.ndarray, P_prior_next: np.ndarray, D_next: np.ndarray, reset_next: bool,
                m_out: np.ndarray) -> tuple[np.ndarray, int]:
    """``C_k = D_{k+1} (P_{k+1}^-)^{-1}`` (float64) and, into ``m_out`` (n (n + 1) / 2,), the upper
    triangle row by row of ``M_k = P_k^+ - C_k D_{k+1}^T`` (symmetrised).  Status 0; 1: a reset
    at ``k + 1``, 2: ``P_{k+1}^-`` not positive definite (both: ``C_k = 0``, ``M_k = P_k^+``)."""
    n = P_post.shape[0]
    C = np.zeros((n, n))
    status = 1 if reset_next else 0
    R = P_post
    if status == 0:
        L, ok = cholesky(P_prior_next)
        if ok:
            Ct = chol_solve(L, np.ascontiguousarray(D_next.T))     # P^-1 D^T = C^T (P symmetric)
            C = np.ascontiguousarray(Ct.T)
            R = P_post - C @ np.ascontiguousarray(D_next.T)
        else:
            status = 2
    idx = 0
    for i in range(n):
        for j in range(i, n):
            m_out[idx] = 0.5 * (R[i, j] + R[j, i])
            idx += 1
    return C, status


@compiled
def _backward_block(M: np.ndarray, C: np.ndarray, P_s: np.ndarray, gain_next: np.ndarray,
                    var_out: np.ndarray) -> None:
    """The covariance recursion over one block of ``b`` rows, newest first:
    ``P_s <- M_i + C_i P_s C_i^T`` with ``C_i`` the gain in row ``i + 1`` (``gain_next`` (n, n),
    float64, for the block's last row: row 0 of the next block, zero after the last node).
    ``P_s`` (n, n) float64 enters as the smoothed covariance of the node after the block and
    leaves as that of the block's first node; ``var_out[i]`` gets its diagonal."""
    b = var_out.shape[0]
    n = P_s.shape[0]
    G = gain_next.copy()
    Ms = np.empty((n, n))
    for i in range(b - 1, -1, -1):
        if i + 1 < b:
            for r in range(n):
                for c in range(n):
                    G[r, c] = C[i + 1, r, c]
        idx = 0
        for r in range(n):
            for c in range(r, n):
                Ms[r, c] = M[i, idx]
                Ms[c, r] = M[i, idx]
                idx += 1
        Ps = Ms + G @ P_s @ G.T
        for r in range(n):
            for c in range(n):
                P_s[r, c] = 0.5 * (Ps[r, c] + Ps[c, r])
            var_out[i, r] = P_s[r, r]


class ForwardStore:
    """What RTS smoothing needs of a forward run, node by node (see the module docstring).

    Nodes are written into preallocated blocks of ``block_nodes`` rows as soon as the next
    node's prior is final (the last two nodes wait as references to the filter's own arrays,
    which are immutable); once the blocks in memory would exceed ``budget_bytes``, the full ones
    are written to a temporary file (unlinked at once: it disappears when the store is closed,
    on error or interrupt too) and read back one by one by the backward pass.  At least the
    block being filled stays in memory.

    Parameters
    ----------
    n_err : error-state dimension n (the covariance is (n, n)).
    n_x : nominal state length.
    dtype : float type of the stored gains and covariance parts (``np.float32`` or ``np.float64``).
    budget_bytes : memory for blocks before spilling (default :data:`DEFAULT_BUDGET_BYTES`).
    block_nodes : rows per block (None: :data:`BLOCK_NODES`).
    spill_dir : directory of the temporary file (None: ``$TMPDIR``).
    """

    def __init__(self, n_err: int, n_x: int, *, dtype: Any = np.float32,
                 budget_bytes: int = DEFAULT_BUDGET_BYTES, block_nodes: int | None = None,
                 spill_dir: str | None = None) -> None:
        self.n_err, self.n_x = int(n_err), int(n_x)
        n = self.n_err
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"ForwardStore: dtype must be float32 or float64, got {self.dtype}")
        self.block_nodes = int(BLOCK_NODES if block_nodes is None else block_nodes)
        self.budget_bytes = int(budget_bytes)
        self.spill_dir = spill_dir
        f8 = np.dtype(np.float64)
        fields = (("t", f8, ()), ("x_post", f8, (n_x,)), ("x_prior", f8, (n_x,)), ("x_ref", f8, (n_x,)),
                  ("M", self.dtype, (n * (n + 1) // 2,)), ("C", self.dtype, (n, n)), ("reset", np.dtype(bool), ()))
        self._layout: list[tuple[str, np.dtype, tuple[int, ...], int]] = []
        offset = 0
        for name, dt, shape in fields:
            self._layout.append((name, dt, shape, offset))
            offset += -(-self.block_nodes * int(np.prod(shape, dtype=int)) * dt.itemsize // 8) * 8
        self.block_bytes = offset
        self._blocks: list[np.ndarray | int] = []     # a block in memory, or its offset in the spill file
        self._fill = 0                                 # rows written into the last block
        self._last: dict[str, np.ndarray] = {}         # the last block's fields
        self._spill: io.BufferedRandom | None = None
        self._prev: _Node | None = None                # final, waiting for the next node's prior
        self._cur: _Node | None = None                 # the last node: its update may still come
        self.breaks = 0                                # resets crossed
        self.repaired = 0                              # priors that were not positive definite

    @property
    def n(self) -> int:
        """Nodes stored so far."""
        rows = (len(self._blocks) - 1) * self.block_nodes + self._fill if self._blocks else 0
        return rows + (self._prev is not None) + (self._cur is not None)

    @property
    def spilled_blocks(self) -> int:
        """Blocks written to the temporary file."""
        return sum(1 for b in self._blocks if isinstance(b, int))

    @property
    def nbytes(self) -> int:
        """Bytes of the blocks, in memory and spilled."""
        return len(self._blocks) * self.block_bytes

    def start(self, state: GaussianState) -> None:
        """Node 0: the initial state (its prior is itself; no cross-covariance)."""
        if self.n:
            raise ValueError("ForwardStore.start: the store already has nodes")
        self._cur = _Node(state.t, state.x, state.x, state.x, state.P, state.P, np.zeros((self.n_err, self.n_err)))

    def predicted(self, prediction: Prediction) -> None:
        """A time update ended at ``prediction.state.t``: a new node whose posterior is the
        prior until :meth:`updated` says otherwise, with the update's cross-covariance and
        propagated nominal."""
        if self.n == 0:
            raise ValueError("ForwardStore.predicted: call start() first")
        if prediction.cross_cov.shape != (self.n_err, self.n_err):
            raise ValueError(f"ForwardStore.predicted: cross_cov has shape {prediction.cross_cov.shape}, "
                             f"expected ({self.n_err}, {self.n_err})")
        self._close()
        s = prediction.state
        self._cur = _Node(s.t, s.x, s.x, prediction.x_ref, s.P, s.P, prediction.cross_cov)

    def updated(self, used_prior: GaussianState | None, posterior: GaussianState, reset: bool = False) -> None:
        """The last node's measurement update: the prior it corrected (None: the time update's
        output), the posterior, and whether the covariance was re-anchored (forced fix)."""
        node = self._cur
        if node is None:
            raise ValueError("ForwardStore.updated: no node to update")
        if used_prior is not None:
            node.x_prior, node.P_prior = used_prior.x, used_prior.P
        node.x_post, node.P_post = posterior.x, posterior.P
        node.reset = bool(reset)

    def _close(self) -> None:
        """The last node's prior is final: the gain into it, and the node before it to a block."""
        node, prev = self._cur, self._prev
        if node is None:
            return
        if prev is None:
            node.gain = np.zeros((self.n_err, self.n_err))
        else:
            i = self._row()
            gain, status = _close_step(prev.P_post, node.P_prior, node.D, node.reset, self._last["M"][i])
            self.breaks += status == 1
            self.repaired += status == 2
            node.gain = gain
            self._write(i, prev)
        self._prev, self._cur = node, None

    def finish(self) -> None:
        """No more nodes: the last ones to the blocks (called by :meth:`blocks`)."""
        self._close()
        last = self._prev
        if last is not None:
            i = self._row()
            _close_step(last.P_post, last.P_post, last.D, True, self._last["M"][i])    # M = P+, packed
            self._write(i, last)
            self._prev = None

    def _row(self) -> int:
        """The next free row of the last block (a new block when it is full)."""
        if not self._blocks or self._fill == self.block_nodes:
            self._reserve()
        return self._fill

    def _write(self, i: int, node: _Node) -> None:
        """Row ``i`` of the last block: the node (its ``M`` is written already)."""
        v = self._last
        v["t"][i] = node.t
        v["x_post"][i] = node.x_post
        v["x_prior"][i] = node.x_prior
        v["x_ref"][i] = node.x_ref
        v["C"][i] = node.gain
        v["reset"][i] = node.reset
        self._fill += 1

    def _reserve(self) -> None:
        """A new block, after spilling the oldest ones in memory beyond the budget."""
        in_memory = [i for i, b in enumerate(self._blocks) if isinstance(b, np.ndarray)]
        while in_memory and (len(in_memory) + 1) * self.block_bytes > self.budget_bytes:
            i = in_memory.pop(0)
            if self._spill is None:
                # open until close(): unlinked at once, so gone with the process whatever happens
                self._spill = tempfile.TemporaryFile(prefix="navpp-smoother-", dir=self.spill_dir)  # noqa: SIM115
            buf = self._blocks[i]
            assert isinstance(buf, np.ndarray)
            self._spill.seek(0, 2)
            self._blocks[i] = self._spill.tell()
            self._spill.write(buf.data)
        block = np.empty(self.block_bytes, np.uint8)
        self._blocks.append(block)
        self._last = self._views(block)
        self._fill = 0

    def _views(self, buf: np.ndarray) -> dict[str, np.ndarray]:
        """The fields of a block buffer, (block_nodes, ...) each."""
        return {name: np.ndarray((self.block_nodes, *shape), dt, buf, offset)
                for name, dt, shape, offset in self._layout}

    def blocks(self) -> Any:
        """The stored rows block by block, newest first: ``(first_node, fields)`` with ``fields``
        name -> (b, ...) views (``t``, ``x_post``, ``x_prior``, ``x_ref``, ``M`` packed upper
        triangles, ``C`` gains into each node, ``reset``), valid until the next block is read;
        finishes the store first."""
        self.finish()
        spare: np.ndarray | None = None
        for j in range(len(self._blocks) - 1, -1, -1):
            buf = self._blocks[j]
            if isinstance(buf, int):
                assert self._spill is not None
                if spare is None:
                    spare = np.empty(self.block_bytes, np.uint8)
                self._spill.seek(buf)
                if self._spill.readinto(spare.data) != self.block_bytes:
                    raise OSError("ForwardStore: the spill file was cut short")
                buf = spare
            b = self._fill if j == len(self._blocks) - 1 else self.block_nodes
            yield j * self.block_nodes, {name: v[:b] for name, v in self._views(buf).items()}

    def close(self) -> None:
        """Release the blocks and the temporary file; the freed blocks' pages go back to the
        system (:func:`~navpp.spill.trim_heap`: 8-hour log, 100 MB)."""
        self._blocks, self._last = [], {}
        self._prev = self._cur = None
        if self._spill is not None:
            self._spill.close()
            self._spill = None
        trim_heap()


@dataclass(frozen=True)
class Smoothed:
    """The smoothed nodes: ``t`` (M,) s, ``x`` (M, n_x) nominal states, ``var`` (M, n) the
    diagonal of the smoothed error covariances, ``x_post`` and ``x_ref`` (M, n_x) the forward
    run's posterior and propagated nominal at each node, ``breaks``: resets crossed (no
    smoothing across), and ``repaired``: steps where the prior covariance was not positive
    definite and the step was treated as a break."""

    t: np.ndarray
    x: np.ndarray
    var: np.ndarray
    x_post: np.ndarray
    x_ref: np.ndarray
    breaks: int
    repaired: int


def rts_smooth(store: ForwardStore, model: SmoothableModel) -> Smoothed:
    """Smooth the stored forward run (see the module docstring) block by block, newest first;
    closes the store.  The model's ``rts_means`` runs the mean recursion (compiled on the INS)
    over each block extended by the first node of the block after it."""
    if store.n == 0:
        raise ValueError("rts_smooth: the store is empty")
    try:
        m, n = store.n, store.n_err
        out = {"t": np.empty(m), "x": np.empty((m, store.n_x)), "var": np.empty((m, n)),
               "x_post": np.empty((m, store.n_x)), "x_ref": np.empty((m, store.n_x))}
        P_s = np.zeros((n, n))
        nxt: tuple[np.ndarray, np.ndarray, np.ndarray, bool] | None = None  # gain, xs, x_prior, reset
        for first, f in store.blocks():
            b = f["t"].shape[0]
            sl = slice(first, first + b)
            gain_next = np.zeros((n, n)) if nxt is None else nxt[0]
            _backward_block(f["M"], f["C"], P_s, gain_next, out["var"][sl])
            gains = f["C"].astype(np.float64)
            if nxt is None:
                xs = model.rts_means(f["x_post"], f["x_prior"], gains, f["reset"])
            else:
                ext = model.rts_means(np.concatenate([f["x_post"], nxt[1][None]]),
                                      np.concatenate([f["x_prior"], nxt[2][None]]),
                                      np.concatenate([gains, nxt[0][None]]),
                                      np.append(f["reset"], nxt[3]))
                xs = ext[:b]
            out["x"][sl] = xs
            out["t"][sl] = f["t"]
            out["x_post"][sl] = f["x_post"]
            out["x_ref"][sl] = f["x_ref"]
            nxt = (gains[0].copy(), xs[0].copy(), f["x_prior"][0].copy(), bool(f["reset"][0]))
        breaks, repaired = store.breaks, store.repaired
    finally:
        store.close()
    if not (np.all(np.isfinite(out["x"])) and np.all(np.isfinite(out["var"]))):
        raise FilterDivergedError("RTS smoother: the smoothed state became non-finite")
    return Smoothed(out["t"], out["x"], out["var"], out["x_post"], out["x_ref"], breaks, repaired)


__all__ = ["BLOCK_NODES", "DEFAULT_BUDGET_BYTES", "ForwardStore", "Smoothed", "rts_smooth"]
