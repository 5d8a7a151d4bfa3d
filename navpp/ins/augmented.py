"""The INS with extra states appended: blocks of first-order Gauss-Markov (or random-constant)
states that the sensors' errors need, e.g. the GNSS position error (:mod:`navpp.ins.gnss_error`)
or the odometer's scale factor (:mod:`navpp.ins.aids.odometer`).

Layout: the 15 INS error elements (:mod:`navpp.ins.state`) then each block's elements in order;
the nominal: the 16 INS elements then each block's estimate, in the block's own units.  Over an
interval of ``T`` s a block decays by ``a = exp(-T / tau)`` (``tau = inf``: ``a = 1``, a random
constant, or a random walk when it has a drive) with ``Qd = sigma^2 (1 - a^2)`` per element for a
Gauss-Markov block (exact; its stationary variance stays ``sigma^2``) and ``Qd = psd T`` for a
random walk.  The blocks do not couple to the INS in the dynamics, only through measurements,
which see them through their own Jacobian columns; a measurement of the plain INS is carried
over with zero columns (:class:`Padded`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .model import InsModel, minus, plus, rts_means
from .state import N_ERR, NOMINAL_SIZE


@dataclass(frozen=True)
class StateBlock:
    """A block of extra states.

    name : the block's name (process-noise group, diagnostics prefix); labels : one name per element.
    tau_s : correlation time, s (``inf``: no decay).
    sigma : per element, the stationary 1-sigma of a Gauss-Markov block (finite ``tau_s``) or the
        initial 1-sigma of a random constant / random walk (``tau_s = inf``), in the element's units.
    walk_psd : per element, the drive of a random walk (units^2 / s; only with ``tau_s = inf``).
    """

    name: str
    labels: tuple[str, ...]
    tau_s: float
    sigma: tuple[float, ...]
    walk_psd: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.labels)
        sig = tuple(float(s) for s in self.sigma)
        if n == 0 or len(sig) != n or not all(math.isfinite(s) and s > 0.0 for s in sig):
            raise ValueError(f"StateBlock {self.name}: sigma must be {n} finite numbers > 0, got {self.sigma!r}")
        if not (self.tau_s > 0.0):
            raise ValueError(f"StateBlock {self.name}: tau_s must be > 0 (inf allowed), got {self.tau_s!r}")
        if self.walk_psd is not None and (not math.isinf(self.tau_s) or len(self.walk_psd) != n):
            raise ValueError(f"StateBlock {self.name}: walk_psd needs tau_s = inf and {n} values")
        object.__setattr__(self, "sigma", sig)

    @property
    def size(self) -> int:
        return len(self.labels)

    @property
    def variance(self) -> np.ndarray:
        """Stationary (Gauss-Markov) or initial (random constant / walk) variance per element."""
        var: np.ndarray = np.square(np.asarray(self.sigma))
        return var

    def decay(self, dt: float) -> float:
        """``exp(-dt / tau)`` over ``dt`` s (1 without decay)."""
        return 1.0 if math.isinf(self.tau_s) else math.exp(-max(dt, 0.0) / self.tau_s)

    def drive(self, dt: float) -> np.ndarray:
        """Qd diagonal over ``dt`` s, per element."""
        if math.isinf(self.tau_s):
            q: np.ndarray = (np.zeros(self.size) if self.walk_psd is None
                             else np.asarray(self.walk_psd, dtype=float) * max(dt, 0.0))
            return q
        a = self.decay(dt)
        return self.variance * (1.0 - a * a)


#: ``x ⊞ dx``, ``x1 ⊟ x0`` and the smoother's mean recursion on an augmented state: the INS's own
#: kernels, which carry the elements beyond the INS's additively
plus_aug = plus
minus_aug = minus
rts_means_aug = rts_means


def ins_part(x: np.ndarray) -> np.ndarray:
    """The INS nominal (16,) of an augmented nominal, contiguous."""
    return np.ascontiguousarray(x[:NOMINAL_SIZE])


class AugmentedInsModel:
    """An :class:`~navpp.ins.model.InsModel` (``ins``) with ``blocks`` appended (module docstring):
    the filters' model protocol, the smoother's mean recursion and VCE's noise groups (each block
    one group, named as the block)."""

    #: VCE: the INS noise groups reach the measurements through many time updates
    noise_share: ClassVar[str] = "propagated"

    def __init__(self, ins: InsModel, blocks: tuple[StateBlock, ...]) -> None:
        if not blocks:
            raise ValueError("AugmentedInsModel needs at least one block")
        names = [b.name for b in blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"AugmentedInsModel: block names repeat: {names}")
        self.ins, self.blocks = ins, tuple(blocks)
        self.n_extra = sum(b.size for b in blocks)
        self.dim = N_ERR + self.n_extra
        self.n_nominal = NOMINAL_SIZE + self.n_extra
        self._offset: dict[str, int] = {}
        k = 0
        for b in blocks:
            self._offset[b.name] = k
            k += b.size

    def err_slice(self, name: str) -> slice:
        """Error-state slice of block ``name``."""
        o = N_ERR + self._offset[name]
        return slice(o, o + self.block(name).size)

    def nominal_slice(self, name: str) -> slice:
        """Nominal-state slice of block ``name``."""
        o = NOMINAL_SIZE + self._offset[name]
        return slice(o, o + self.block(name).size)

    def block(self, name: str) -> StateBlock:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(name)

    def has(self, name: str) -> bool:
        return name in self._offset

    def state_labels(self) -> list[tuple[str, int, int]]:
        """Every extra element: (label, error-state index, nominal index), in order."""
        out = []
        for b in self.blocks:
            e, n = self.err_slice(b.name), self.nominal_slice(b.name)
            out += [(label, e.start + i, n.start + i) for i, label in enumerate(b.labels)]
        return out

    # ⊞ / ⊟ -----------------------------------------------------------------------------------
    # the INS's own: they carry the extra elements additively
    plus = staticmethod(InsModel.plus)
    minus = staticmethod(InsModel.minus)

    rts_means = staticmethod(rts_means_aug)

    # propagation -----------------------------------------------------------------------------
    def decays(self, interval: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """(per extra element: decay a, Qd diagonal) over ``interval``."""
        dt = interval[1] - interval[0]
        a = np.concatenate([np.full(b.size, b.decay(dt)) for b in self.blocks])
        q = np.concatenate([b.drive(dt) for b in self.blocks])
        return a, q

    def _nominal(self, xn_ins: np.ndarray, x: np.ndarray, a: np.ndarray) -> np.ndarray:
        out = np.empty(self.n_nominal)
        out[:NOMINAL_SIZE] = xn_ins
        out[NOMINAL_SIZE:] = a * x[NOMINAL_SIZE:]
        return out

    def _augmented(self, M15: np.ndarray, diag: np.ndarray) -> np.ndarray:
        M = np.zeros((self.dim, self.dim))
        M[:N_ERR, :N_ERR] = M15
        idx = np.arange(N_ERR, self.dim)
        M[idx, idx] = diag
        return M

    def transition(self, x: np.ndarray, interval: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The INS's transition with each block's decay and drive appended."""
        xn, Phi, Qd = self.ins.transition(ins_part(x), interval)
        a, q = self.decays(interval)
        return self._nominal(xn, x, a), self._augmented(Phi, a), self._augmented(Qd, q)

    def process_noise(self, x: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
        """Qd over the interval."""
        _, q = self.decays(interval)
        return self._augmented(self.ins.process_noise(ins_part(x), interval), q)

    def propagate_points(self, x: np.ndarray, dX: np.ndarray, interval: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """The INS's points through the strapdown; the blocks' parts decay linearly."""
        dX = np.asarray(dX, dtype=float)
        xn, dY = self.ins.propagate_points(ins_part(x), np.ascontiguousarray(dX[:, :N_ERR]), interval)
        a, _ = self.decays(interval)
        out = np.empty((dX.shape[0], self.dim))
        out[:, :N_ERR] = dY
        out[:, N_ERR:] = a * dX[:, N_ERR:]
        return self._nominal(xn, x, a), out

    def noise_groups(self, x: np.ndarray, interval: tuple[float, float], per: str = "triad"
                     ) -> tuple[list[str], np.ndarray]:
        """The INS's noise groups (padded) and one group per block with a drive, named as the block."""
        names, Qs = self.ins.noise_groups(ins_part(x), interval, per)
        _, q = self.decays(interval)
        driven = [b for b in self.blocks if np.any(b.drive(interval[1] - interval[0]) > 0.0)
                  or not math.isinf(b.tau_s)]
        out = np.zeros((len(names) + len(driven), self.dim, self.dim))
        if len(names):
            out[:len(names), :N_ERR, :N_ERR] = Qs
        for g, b in enumerate(driven, start=len(names)):
            s = self.err_slice(b.name)
            idx = np.arange(s.start, s.stop)
            out[g, idx, idx] = q[s.start - N_ERR:s.stop - N_ERR]
        return [*names, *(b.name for b in driven)], out

    # start and measurements --------------------------------------------------------------------
    def start(self, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The augmented start from the INS's (16,) ``x`` and (15, 15) ``P``: every block's
        estimate zero with its (stationary or initial) variance, uncorrelated."""
        xa = np.zeros(self.n_nominal)
        xa[:NOMINAL_SIZE] = x[:NOMINAL_SIZE]
        Pa = np.zeros((self.dim, self.dim))
        Pa[:N_ERR, :N_ERR] = P
        for b in self.blocks:
            s = self.err_slice(b.name)
            idx = np.arange(s.start, s.stop)
            Pa[idx, idx] = b.variance
        return xa, Pa

    def measurement(self, meas: Any) -> Any:
        """``meas`` as a measurement of this model: one that knows the augmented layout (it has
        ``for_model``) is built for it, any other is padded (:class:`Padded`)."""
        for_model = getattr(meas, "for_model", None)
        return for_model(self) if for_model is not None else Padded(meas, self.dim)


class Padded:
    """A measurement of the 15-element INS on an augmented model (``n`` error elements): the
    same innovation and R, zero Jacobian columns for the extra states, its points taken on the
    INS part; every other attribute is the wrapped measurement's (``inner``)."""

    def __init__(self, inner: Any, n: int) -> None:
        self.inner, self.n = inner, n

    def __getattr__(self, name: str) -> Any:      # kind, axes, adaptive, forceable, t, R, ...
        if name in ("inner", "n"):                # not set yet (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        nu: np.ndarray = self.inner.innovation_at(ins_part(x))
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        H15 = self.inner.jacobian(ins_part(x))
        H = np.zeros((H15.shape[0], self.n))
        H[:, :N_ERR] = H15
        return H

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        Z: np.ndarray = self.inner.predict_points(ins_part(x), np.ascontiguousarray(np.asarray(dX)[:, :N_ERR]))
        return Z

    def reanchor(self, P: np.ndarray, nu: np.ndarray, R: np.ndarray) -> np.ndarray | None:
        out: np.ndarray | None = self.inner.reanchor(P, nu, R)
        return out


__all__ = ["AugmentedInsModel", "Padded", "StateBlock", "ins_part", "minus_aug", "plus_aug", "rts_means_aug"]
