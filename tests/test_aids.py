"""The aids' shared sigma-point kernel (navpp.ins.aids.base.points_kernel): each aid's compiled
images equal its model evaluated point by point through ⊞ (the oracle), and each compiled copy
belongs to its aid's source file (numba's cache follows that file)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from navpp.aiding import vehicle_matrix
from navpp.ins.aids import GnssVelocity, NonHolonomic, ZeroRate, ZeroVelocity
from navpp.ins.model import plus

AIDS = [
    GnssVelocity.at(0.0, np.zeros(3), np.ones(3), np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.3, 1.2])),
    NonHolonomic.at(0.0, (0.1, 0.1), vehicle_matrix((1.0, 2.0, 3.0)), np.array([0.1, -0.2, 0.3]),
                    np.array([-1.0, 0.2, -0.3])),
    ZeroRate.at(0.0, np.zeros(3), 0.2, 1e-3, 0.0),
    ZeroVelocity.at(0.0, 0.1),
]


def _nominal() -> np.ndarray:
    rng = np.random.default_rng(3)
    x = np.zeros(16)
    q = rng.normal(size=4)
    x[0:4] = q / np.linalg.norm(q)
    x[4:7] = [8.0, -5.0, 0.3]
    x[7], x[8], x[9] = 0.7, 0.1, 300.0
    x[10:13] = [1e-3, -2e-3, 5e-4]
    x[13:16] = 0.01
    return x


@pytest.mark.parametrize("meas", AIDS, ids=lambda m: m.kind)
def test_points_are_the_model_through_plus_point_by_point(meas):
    x = _nominal()
    dX = 0.05 * np.random.default_rng(4).normal(size=(31, 15))
    z0 = meas.model(x, meas.p)
    want = np.array([meas.model(plus(x, d), meas.p) - z0 for d in dX])
    np.testing.assert_array_equal(meas.predict_points(x, dX), want)
    assert meas.predict_points(x, dX[:0]).shape == (0, len(meas.axes))


def test_each_aid_compiles_its_own_copy_in_its_own_file():
    kernels = [type(m).model_points for m in AIDS]
    assert len({id(k) for k in kernels}) == len(AIDS)
    for meas, kernel in zip(AIDS, kernels):
        model = type(meas).model
        assert inspect.getfile(kernel.py_func) == inspect.getfile(model.py_func)
        assert kernel.py_func.__globals__["_model"] is model
