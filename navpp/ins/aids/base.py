"""What every aiding measurement shares: the protocol methods on top of a compiled model
``h(x, p)``, its Jacobian ``H(x, p)`` and its sigma-point images, with the measurement's
parameters packed in ``p``.

An aid module defines ``h`` and ``H`` as numba kernels and gets its sigma-point images from
:func:`points_kernel`, one implementation compiled once per aid.
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import ClassVar, Protocol, cast

import numpy as np

from navpp.kernel import njit

from ...filters.protocols import MeasurementBase
from ..model import plus


class ModelKernel(Protocol):
    """An aid's compiled model ``h(x, p)``: nominal (16,) and parameters -> predicted measurement (k,)."""

    def __call__(self, x: np.ndarray, p: np.ndarray) -> np.ndarray: ...


class PointsKernel(Protocol):
    """An aid's compiled sigma-point images ``(x, dX, p) -> h(x ⊞ dX_i, p) - h(x, p)``, (m, k)."""

    def __call__(self, x: np.ndarray, dX: np.ndarray, p: np.ndarray) -> np.ndarray: ...


def _model(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Stands for the aid's ``h`` in :func:`_points_template` (each compiled copy reads its own)."""
    raise NotImplementedError


def _points_template(x: np.ndarray, dX: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``h(x ⊞ dX_i, p) - h(x, p)`` for error points ``dX`` (m, 15): (m, k)."""
    z0 = _model(x, p)
    Z = np.empty((dX.shape[0], z0.shape[0]))
    for i in range(dX.shape[0]):
        Z[i] = _model(plus(x, dX[i]), p) - z0
    return Z


def points_kernel(model: ModelKernel) -> PointsKernel:
    """The compiled sigma-point images ``h(x ⊞ dX_i, p) - h(x, p)`` of the aid model ``model``
    (an ``njit`` kernel).

    A kernel that took ``h`` as an argument could not go into numba's on-disk cache, so each aid
    gets its own copy of :func:`_points_template` whose global ``_model`` is that aid's ``h``.
    numba caches a kernel beside the file it names and checks that file's time stamp: the copy
    names the aid's source file (and a name of its own there), so editing the aid's ``h``
    recompiles its images.  After editing the template (or :func:`navpp.ins.model.plus`), clear
    numba's cache, as after editing any function a cached kernel calls.
    """
    py_h = cast(types.FunctionType, getattr(model, "py_func", model))
    name = f"{py_h.__name__}_points"
    code = _points_template.__code__.replace(co_filename=py_h.__code__.co_filename, co_name=name,
                                             co_qualname=name)
    namespace = dict(_points_template.__globals__)
    namespace["_model"] = model
    fn = types.FunctionType(code, namespace, name)
    fn.__qualname__ = name
    fn.__module__ = py_h.__module__
    fn.__doc__ = _points_template.__doc__
    return cast(PointsKernel, njit(cache=True)(fn))


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
    def model(x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Compiled ``h(x, p)``: the predicted measurement (k,) at nominal ``x`` (16,)."""
        raise NotImplementedError

    @staticmethod
    def model_points(x: np.ndarray, dX: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Compiled ``h(x ⊞ dX_i, p) - h(x, p)`` for error points ``dX`` (m, 15): (m, k)
        (:func:`points_kernel` of ``model``)."""
        raise NotImplementedError

    @staticmethod
    def model_jacobian(x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Compiled ``dh/d(error)`` (k, 15) at nominal ``x``."""
        raise NotImplementedError

    def innovation_at(self, x: np.ndarray) -> np.ndarray:
        """``z - h(x, p)`` (k,)."""
        nu: np.ndarray = self.z - self.model(x, self.p)
        return nu

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """H (k, 15) at nominal ``x``."""
        return self.model_jacobian(x, self.p)

    def predict_points(self, x: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``h(x ⊞ dX_i) - h(x)`` (m, k) for error points ``dX`` (m, 15)."""
        return self.model_points(x, np.ascontiguousarray(dX, dtype=float), self.p)
