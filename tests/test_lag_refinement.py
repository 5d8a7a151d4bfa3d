"""The clock-offset search's lag refinement (:func:`navpp.ins.timing_estimates._golden_section_min`)
finds what scipy's bounded scalar minimisation finds, to the tolerance the search needs
(:data:`~navpp.ins.timing_estimates.LAG_TOL_S`): scipy.optimize is the oracle here only."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from navpp.ins import timing_estimates
from navpp.ins.timing_estimates import LAG_TOL_S, _golden_section_min

#: (cost of a lag in s, bracket s): smooth minima inside, near and at an end, flat and sharp,
#: asymmetric, and a monotonic cost (the minimum at the bracket's end)
CASES = [
    (lambda d: (d - 0.0123) ** 2, (-0.05, 0.05)),
    (lambda d: 1.0 - math.cos(40.0 * (d + 0.031)), (-0.1, 0.0)),
    (lambda d: abs(d - 0.2499) ** 1.5 + 0.3 * (d - 0.2499) ** 3, (0.2, 0.3)),
    (lambda d: math.exp(8.0 * (d - 0.61)) - 8.0 * d, (0.55, 0.65)),
    (lambda d: -1.0 / (1.0 + 1e4 * (d + 0.9002) ** 2), (-0.95, -0.85)),
    (lambda d: 1e-6 * (d - 0.04) ** 4, (-0.05, 0.05)),
    (lambda d: 3.0 * d, (-1.0, -0.95)),
    (lambda d: -d, (0.95, 1.0)),
    (lambda d: (d - 0.1) ** 2, (0.0, 0.1)),
]


@pytest.mark.parametrize(("cost", "bracket"), CASES)
def test_golden_section_agrees_with_scipy(cost, bracket):
    x, fx = _golden_section_min(cost, *bracket, LAG_TOL_S)
    ref = minimize_scalar(cost, bounds=bracket, method="bounded", options={"xatol": LAG_TOL_S})
    assert bracket[0] <= x <= bracket[1]
    assert fx == cost(x)
    assert abs(x - ref.x) <= 2.0 * LAG_TOL_S
    # as low a cost as scipy's, to what a lag step of the tolerance changes
    assert fx <= ref.fun + abs(cost(ref.x + LAG_TOL_S) - ref.fun) + abs(cost(ref.x - LAG_TOL_S) - ref.fun) + 1e-15


def _turning_drive(late_s: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 10-minute 125 Hz gyro (vertical rate, rad/s, with noise) and its 5 Hz GNSS velocity
    (east, north m/s) for a car weaving at 10 m/s, the IMU stamps ``late_s`` late."""
    rng = np.random.default_rng(seed)
    t_imu = np.arange(0.0, 600.0, 0.008)
    rate = 0.3 * np.sin(2 * np.pi * t_imu / 23.0) + 0.2 * np.sin(2 * np.pi * t_imu / 7.3 + seed)
    heading = np.cumsum(rate) * 0.008                      # counter-clockwise from east, rad
    gyro = rate + 0.02 * rng.standard_normal(t_imu.shape[0])
    t_g = np.arange(2.0, 598.0, 0.2)
    h = np.interp(t_g + late_s, t_imu, heading)
    vel = 10.0 * np.stack([np.cos(h), np.sin(h)], axis=1)
    return t_imu, gyro, t_g, vel


@pytest.mark.parametrize(("late_s", "seed"), [(0.0, 0), (0.137, 1), (-0.3, 2), (0.05, 3)])
def test_clock_offset_agrees_with_scipys_refinement(late_s, seed, monkeypatch):
    """The whole estimate with the golden-section refinement, then with scipy's in its place."""
    t_imu, gyro, t_g, vel = _turning_drive(late_s, seed)
    ours = timing_estimates.estimate_clock_offset(t_imu, gyro, t_g, vel)

    def scipys(f, lo, hi, tol):
        res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": tol})
        return float(res.x), float(res.fun)

    monkeypatch.setattr(timing_estimates, "_golden_section_min", scipys)
    ref = timing_estimates.estimate_clock_offset(t_imu, gyro, t_g, vel)
    assert abs(ours.offset_s - late_s) < 0.01
    assert abs(ours.offset_s - ref.offset_s) <= 2.0 * LAG_TOL_S
    assert abs(ours.correlation - ref.correlation) < 1e-8
    assert ours.confident == ref.confident and ours.consistent == ref.consistent
