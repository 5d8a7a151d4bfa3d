"""The prepare phase's block-wise passes give the bits of the whole-array forms they replace
(issue 21): the trapezoidal angle integral, the cubic spline of the clock-offset search and the
stale-row counts, across block edges."""

import numpy as np
import pytest
from scenarios import spline_samples
from scipy import interpolate

from navpp.ins import calibrate, timing_estimates


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch):
    """Blocks of 64 rows: the tests cross many block edges with small arrays."""
    monkeypatch.setattr(calibrate, "BLOCK_ROWS", 64)
    monkeypatch.setattr(timing_estimates, "BLOCK_ROWS", 64)


def _stamps(n: int, seed: int = 0) -> np.ndarray:
    """(n,) s, a jittery 125 Hz stream."""
    return np.cumsum(0.008 + 0.001 * np.random.default_rng(seed).random(n))


@pytest.mark.parametrize("n", [0, 1, 2, 64, 65, 66, 129, 1000])
def test_trapezoid_integral_bits(n):
    t = _stamps(n)
    w = np.random.default_rng(1).standard_normal(n)
    whole = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    assert whole.tobytes() == calibrate.trapezoid_integral(t, w).tobytes()
    if n:
        uniform = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * 0.008)])
        assert uniform.tobytes() == calibrate.trapezoid_integral(0.008, w).tobytes()


@pytest.mark.parametrize("n", [2, 3, 64, 65, 66, 129, 1000])
def test_trapezoid_integral_at_bits(n):
    """The integral at query times (inside, on stamps and block edges, outside, NaN), the rate
    given block by block: np.interp of the whole integral, to the bit."""
    t = _stamps(n, 6)
    w = np.random.default_rng(7).standard_normal(n)
    q = np.concatenate([t, t[:-1] + 0.3 * np.diff(t), [t[0] - 1.0, t[-1] + 1.0, np.nan],
                        np.random.default_rng(8).uniform(t[0] - 0.1, t[-1] + 0.1, 200)])
    whole = np.interp(q, t, calibrate.trapezoid_integral(t, w))
    got = calibrate.trapezoid_integral_at(t, lambda lo, hi: w[lo:hi], n, q)
    assert whole.tobytes() == got.tobytes()


def test_yaw_scale_with_the_gyro_and_its_up():
    """The rate about ``up`` taken block by block gives the figures of ``gyro @ up`` passed whole."""
    rng = np.random.default_rng(9)
    t = np.arange(0.0, 120.0, 0.008)
    rate = 0.3 * np.sin(t / 5.0)
    up = np.array([0.05, -0.03, 1.0]) / np.linalg.norm([0.05, -0.03, 1.0])
    gyro = rng.standard_normal((t.shape[0], 3)) * 0.01 + rate[:, None] * up
    tg = np.arange(0.5, 119.5, 0.2)
    heading = np.interp(tg, t, np.cumsum(rate) * 0.008)
    east, north = np.cumsum(2.0 * np.cos(heading)), np.cumsum(2.0 * np.sin(heading))
    ref = timing_estimates.yaw_scale_from_track(t, gyro @ up, tg, east, north)
    assert timing_estimates.yaw_scale_from_track(t, gyro, tg, east, north, up=up) == ref
    assert ref.n_pairs > 5


@pytest.mark.parametrize("n", [3, 4, 5, 65, 66, 130, 1000])
def test_spline_is_cubic_spline(n):
    t = _stamps(n, 2)
    y = np.cumsum(np.random.default_rng(3).standard_normal(n))
    ref = interpolate.CubicSpline(t, y, extrapolate=False)
    got = timing_estimates._spline(t, y)
    q = np.concatenate([np.linspace(t[0] - 1.0, t[-1] + 1.0, 257), t, 0.5 * (t[1:] + t[:-1])])
    assert ref(q).tobytes() == got(q).tobytes()
    if n >= 4:                                  # the interpolant keeps the caller's x and y
        assert got.x is t and got.y is y


@pytest.mark.parametrize("seed", range(12))
def test_spline_derivatives_across_blocks(seed):
    """The derivatives solved block by block with their margins are the whole solve's to its
    rounding: thousands of rows over blocks of 64 (jittery stamps, gaps of 0.1 to 100 s, an even
    grid far from 0, where rounding differs in the last bits; values over six decades)."""
    rng = np.random.default_rng(10 + seed)
    t, y = spline_samples(rng, int(rng.integers(300, 6000)), seed % 3, gaps=5)
    ref = interpolate.CubicSpline(t, y, extrapolate=False)
    got = timing_estimates._spline(t, y)
    scale = np.max(np.abs(ref.c[2]))
    assert np.max(np.abs(got.d[:-1] - ref.c[2])) <= 1e-12 * scale
    q = np.concatenate([t, rng.uniform(t[0], t[-1], 3000)])
    assert np.max(np.abs(got(q) - ref(q))) <= 1e-12 * np.max(np.abs(y))
    if seed % 3 != 2:                   # jittery stamps: the same bits
        assert got.d[:-1].tobytes() == ref.c[2].tobytes()


def test_spline_refuses_unordered_stamps():
    t = _stamps(10)
    t[5] = t[4]
    with pytest.raises(ValueError, match="strictly increasing"):
        timing_estimates._spline(t, np.zeros(10))


def test_stale_rows_across_blocks():
    """Stale copies at a random 20 % of the rows, windows of 50 rows over blocks of 64 // 50 * 50:
    the flags are the repeats, the chance figures those of the whole-array counts."""
    rng = np.random.default_rng(4)
    n = 2000
    t = _stamps(n, 5)
    gyro, accel = np.round(rng.standard_normal((n, 3)), 2), np.round(rng.standard_normal((n, 3)), 2)
    for i in np.nonzero(rng.random(n) < 0.2)[0][1:]:
        gyro[i], accel[i] = gyro[i - 1], accel[i - 1]
    res = timing_estimates.find_stale_rows(t, gyro, accel, window_rows=50)
    six = np.concatenate([gyro, accel], axis=1)
    repeats = np.concatenate([[False], np.all(six[1:] == six[:-1], axis=1)])
    assert res.n_repeats == int(repeats.sum())
    assert np.array_equal(res.mask, repeats)
    # the expected count from whole-array per-window rates (windows of the N - 1 row pairs)
    same = six[1:] == six[:-1]
    fresh = ~repeats[1:]
    q_all = same[fresh].mean(axis=0)
    expected = 0.0
    for a in range(0, n - 1, 50):
        f = fresh[a:a + 50]
        q = same[a:a + 50][f].mean(axis=0) if f.sum() >= 20 else q_all
        expected += min(50, n - 1 - a) * timing_estimates._chance_all_repeat(q)
    assert res.expected_by_chance == pytest.approx(expected, rel=1e-12)
