"""navpp.intervals and the calibration's run sums: what the whole-log numpy calls give, to the
bit, for stamps and rows spilled to a file (read window by window) as for arrays in memory."""

import numpy as np
import pytest

from navpp.ins.calibrate import rows_mean, sample_period
from navpp.intervals import interval_median, long_intervals, mean_interval, pairwise_sum
from navpp.spill import WINDOW_ROWS, empty_rows


def _spilled(x: np.ndarray) -> np.ndarray:
    out = empty_rows(x.shape[0], x.shape[1:], np.float64, True)
    out[:] = x
    return out


def _stamps() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    return {
        "regular": np.arange(3 * WINDOW_ROWS + 17) * 0.008,
        "jitter": np.cumsum(0.008 + rng.normal(0.0, 1e-4, 2 * WINDOW_ROWS + 5)),
        "quantised": np.round(np.cumsum(0.008 + rng.normal(0.0, 1e-4, WINDOW_ROWS + 9)), 3),
        "gaps": np.concatenate([np.arange(WINDOW_ROWS) * 0.01, 900.0 + np.arange(WINDOW_ROWS + 1) * 0.01]),
        "unsorted": rng.normal(0.0, 1.0, WINDOW_ROWS + 2),
        "even count": np.cumsum(rng.exponential(0.01, 1001)),
        "three": np.array([0.0, 1.0, 1.5]),
        "two": np.array([0.0, 1.0]),
    }


@pytest.mark.parametrize("name", list(_stamps()))
def test_intervals_match_numpy(name):
    t = _stamps()[name]
    d = np.diff(t)
    med = float(np.median(d))
    keep = d <= 5.0 * med
    for arr in (t, _spilled(t)):
        assert interval_median(arr) == med
        assert np.array_equal(long_intervals(arr, 5.0 * med), np.nonzero(d > 5.0 * med)[0])
        assert mean_interval(arr, 5.0 * med) == (float(d[keep].mean()) if keep.any() else None)
        assert sample_period(arr) == sample_period(np.array(t))


def test_pairwise_sum_is_numpys():
    rng = np.random.default_rng(1)
    for n in (7, 200, 131073, 3 * WINDOW_ROWS + 5):
        x = rng.standard_normal(n) * 1e-3 + 0.008
        parts = (x[a:a + 5000] for a in range(0, n, 5000))
        assert pairwise_sum(parts, n) == np.add.reduce(x)


def test_rows_mean_is_numpys():
    rng = np.random.default_rng(5)
    n = 2 * WINDOW_ROWS + 11
    wide = _spilled(rng.normal(0.3, 1.0, (n, 7)))
    runs = [(3, 1000), (5000, WINDOW_ROWS + 300), (2 * WINDOW_ROWS, n)]
    sel = np.concatenate([np.arange(a, b) for a, b in runs])
    for x in (wide[:, 1:4], np.ascontiguousarray(wide[:, 4:7])):
        assert np.array_equal(rows_mean(x, [(0, n)], n), x.mean(axis=0))
        assert np.array_equal(rows_mean(x, runs, sel.size), x[sel].mean(axis=0))


def test_grid_is_the_arange():
    """The clock-offset spline's grid without the array (timing_estimates._Grid): its rows, its
    searchsorted and the spline through it are those of ``np.arange``'s."""
    from navpp.ins import timing_estimates as te

    for start, step, stop in [(1.125, 0.008, 1500.0), (0.3, 0.01, 0.35)]:
        n = te._arange_length(start, stop, step)
        grid, whole = te._Grid(start, step, n), np.arange(start, stop, step)
        idx = np.array([0, 1, 2, n - 1, n // 2, 3])
        assert np.array_equal(grid[idx], whole[idx]) and grid[-1] == whole[-1] and grid[1] == whole[1]
        assert np.array_equal(grid[2:n // 3], whole[2:n // 3]) and np.array_equal(grid[n - 5:n + 10], whole[n - 5:])
        v = np.sort(np.random.default_rng(0).uniform(start - 1, stop + 1, 1000))
        v[:3] = whole[:3]
        for side in ("left", "right"):
            assert np.array_equal(grid.searchsorted(v, side=side), np.searchsorted(whole, v, side=side))
        y = np.cumsum(np.random.default_rng(1).normal(size=n))
        q = np.random.default_rng(2).uniform(start, whole[-1], 5000)
        assert np.array_equal(te._spline(grid, y)(q), te._spline(whole, y)(q), equal_nan=True)


@pytest.mark.parametrize("spill", [False, True])
def test_band_row_sums_are_the_whole_logs(spill):
    """calibrate._band_row_sums part by part: the row sums of the whole log's second differences
    of the group means."""
    from navpp.ins import calibrate

    rng = np.random.default_rng(4)
    size, w, nb = 5, 125, 2 * calibrate._STAT_CHUNK_BLOCKS + 7
    x = rng.normal(0.0, 1.0, (nb * w, 3))
    a = x.reshape(-1, size, 3).mean(axis=1)
    d = np.zeros_like(a)
    d[1:-1] = a[2:] - 2.0 * a[1:-1] + a[:-2]
    d[0], d[-1] = d[1], d[-2]
    whole = calibrate._row_sums(d.reshape(nb, w // size * 3))
    parts = calibrate._band_row_sums(_spilled(x) if spill else x, size, w, nb)
    assert all(np.array_equal(p, q) for p, q in zip(parts, whole))


@pytest.mark.parametrize("spill", [False, True])
def test_kept_rows_are_the_selection(spill):
    """engine.prepare.kept_rows (the stale-row drop): each array's kept rows, spilled as it is."""
    from navpp.engine.prepare import kept_rows
    from navpp.spill import spilled

    rng = np.random.default_rng(6)
    n = 2 * WINDOW_ROWS + 3
    t, gyro = np.cumsum(rng.uniform(0.001, 0.01, n)), rng.normal(0.0, 1.0, (n, 3))
    keep = rng.uniform(size=n) > 0.3
    arrays = (_spilled(t), _spilled(gyro)) if spill else (t, gyro)
    got = kept_rows(keep, *arrays)
    assert np.array_equal(got[0], t[keep]) and np.array_equal(got[1], gyro[keep])
    assert all(spilled(g) == spill for g in got)


@pytest.mark.parametrize("spill", [False, True])
def test_rotated_rows_are_the_product(spill):
    """engine.prepare.rotated_rows (a gross mounting's rotation): ``x @ rot.T``, spilled as x is."""
    from navpp.engine.prepare import rotated_rows
    from navpp.spill import spilled

    rng = np.random.default_rng(7)
    n = 2 * WINDOW_ROWS + 3
    x = rng.normal(0.0, 1.0, (n, 7))
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    arr = _spilled(x)[:, 1:4] if spill else x[:, 1:4]
    got = rotated_rows(arr, rot)
    assert np.array_equal(got, x[:, 1:4] @ rot.T) and spilled(got) == spill
