"""What every aiding measurement shares: the protocol methods on top of a compiled model
``h(x, p)``, its Jacobian ``H(x, p)`` and its sigma-point images, with the measurement's
parameters packed in ``p``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numba import njit

from ...filters.protocols import MeasurementBase


@njit(cache=True, inline="always")
def skew(a):
    """``[a x]``: the cross-product matrix, ``skew(a) @ b == a x b``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@dataclass(frozen=True)
class Aid(MeasurementBase):
    """An aiding measurement at time ``t`` (s): value ``z`` (k,), covariance ``R`` (k, k), and
    the parameters ``p`` its model needs (documented per aid).

    Class attributes: ``kind`` (name in counts and diagnostics), ``axes`` (names of the
    elements), ``adaptive = False`` (adaptive filters learn their noise from the GNSS position
    only and use an aid's ``R`` as given), ``forceable = False`` (an aid the gate rejects is
    dropped, never forced in after a run of rejections as a GNSS fix is); no re-anchoring
    (:class:`~navpp.filters.protocols.MeasurementBase`).
    """

    t: float
    z: np.ndarray
    R: np.ndarray
    p: np.ndarray

    kind: ClassVar[str] = ""
    axes: ClassVar[tuple[str, ...]] = ()
    adaptive: ClassVar[bool] = False
    forceable: ClassVar[bool] = False

    @staticmethod
    def model(x: np.ndarray, p: np.ndarray) -> np.ndarray:       # compiled h(x, p)
        raise NotImplementedError

    @staticmethod
    def model_points(x: np.ndarray, dX: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Compiled ``h(x ⊞ dX_i, p) - h(x, p)`` for error points ``dX`` (m, 15): (m, k).  Each aid
        compiles its own (a kernel taking ``h`` as an argument cannot go into numba's cache)."""
        raise NotImplementedError

    @staticmethod
    def model_jacobian(x: np.ndarray, p: np.ndarray) -> np.ndarray:   # compiled dh/d(error)
        raise NotImplementedError

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        return self.z - self.model(x, self.p)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.model_jacobian(x, self.p)

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        return self.model_points(x, np.ascontiguousarray(dX, dtype=float), self.p)
