"""The clock-offset search's blockwise passes (navpp.ins.timing_estimates) against the whole-array
computations they replace, to the bit."""

import numpy as np
import pytest

from navpp import spill
from navpp.ins import calibrate
from navpp.ins import timing_estimates as te


def test_arange_rows_are_numpys_to_the_bit():
    rng = np.random.default_rng(7)
    for _ in range(300):
        start = float(rng.uniform(-1e5, 1e5) * rng.choice([1e-3, 1.0, 1e3]))
        step = float(rng.uniform(1e-4, 0.05))
        stop = start + float(rng.uniform(1.0, 5000.0)) * step
        whole = np.arange(start, stop, step)
        n = te._arange_length(start, stop, step)
        assert n == whole.shape[0]
        for lo, hi in ((0, n), (0, 1), (1, 2), (0, 2), (n // 3, n), (2, max(n - 1, 2))):
            assert te._arange_rows(start, step, lo, hi).tobytes() == whole[lo:hi].tobytes()


def _whole_gyro_angle(t, w, smooth_s):
    """The smoothed gyro angle as the whole-array computation forms it (the oracle)."""
    theta_at = te._spline(t, calibrate.trapezoid_integral(t, w))
    step = float(np.median(np.diff(t)))
    grid = np.arange(t[0] + 0.5 * smooth_s, t[-1] - 0.5 * smooth_s, step)
    lo = np.clip(grid - 0.5 * smooth_s, t[0], t[-1])
    hi = np.clip(grid + 0.5 * smooth_s, t[0], t[-1])
    ws = (theta_at(hi) - theta_at(lo)) / (hi - lo)
    return te._spline(grid, calibrate.trapezoid_integral(step, ws)), float(grid[0]), float(grid[-1])


@pytest.mark.parametrize("spilled", [False, True])
def test_gyro_angle_blockwise_is_the_whole_computation(monkeypatch, spilled):
    monkeypatch.setattr(te, "BLOCK_ROWS", 4096)
    monkeypatch.setattr(calibrate, "BLOCK_ROWS", 4096)
    rng = np.random.default_rng(3)
    n = 30000
    t = 100.0 + np.cumsum(rng.uniform(0.0075, 0.0085, n))
    gyro = spill.empty_rows(n, (3,), float, spilled)
    gyro[:] = rng.normal(0.0, 0.3, (n, 3))
    up = np.array([0.1, -0.05, 1.0])
    up /= np.linalg.norm(up)
    w = gyro @ up
    whole, lo0, hi0 = _whole_gyro_angle(t, w, 0.25)
    block, lo1, hi1 = te._gyro_angle(t, te._vertical_rate(gyro, up), 0.25)
    assert (lo0, hi0) == (lo1, hi1)
    q = np.linspace(lo0, hi0, 7777)
    assert whole(q).tobytes() == block(q).tobytes()


def test_clock_offset_from_the_gyro_and_up_is_that_of_the_vertical_rate():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 600.0, 0.008)
    yaw_rate = 0.3 * np.sin(2 * np.pi * t / 40.0)
    up = np.array([0.0, 0.0, 1.0])
    gyro = np.column_stack([rng.normal(0, 0.01, t.shape[0]), rng.normal(0, 0.01, t.shape[0]), yaw_rate])
    tg = np.arange(1.0, 599.0, 0.2)
    course = np.interp(tg - 0.05, t, calibrate.trapezoid_integral(t, yaw_rate))
    vel = 10.0 * np.column_stack([np.cos(course), np.sin(course)])
    a = te.estimate_clock_offset(t, gyro @ up, tg, vel)
    b = te.estimate_clock_offset(t, gyro, tg, vel, up=up)
    assert a == b and np.isfinite(a.offset_s)


@pytest.mark.parametrize("start", [0.0, 1.7e9 + 0.125, -321.5])
def test_cubic_on_a_grid_is_scipys_on_its_rows(start):
    """The spline over a _Grid (rows formed in the evaluation kernel) is CubicSpline's over the
    np.arange rows to the bit: on and next to the breakpoints, inside, outside, NaN."""
    from scipy import interpolate

    rng = np.random.default_rng(11)
    step = 0.008
    rows = np.arange(start, start + 4000 * step, step)
    y = np.cumsum(rng.standard_normal(rows.shape[0]))
    got = te._spline(te._Grid(start, step, rows.shape[0]), y)
    ref = interpolate.CubicSpline(rows, y, extrapolate=False)
    q = np.concatenate([rows, np.nextafter(rows, np.inf), np.nextafter(rows, -np.inf),
                        rng.uniform(rows[0] - 1.0, rows[-1] + 1.0, 5000), [np.nan]])
    assert got(q).tobytes() == ref(q).tobytes()
