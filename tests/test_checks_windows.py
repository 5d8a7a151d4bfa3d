"""The IMU checks of navpp.engine.checks over a spilled IMU, window by window, against the
same checks on the arrays in memory (one window: the whole-array computation)."""

import numpy as np

from navpp import spill
from navpp.engine import checks


def _spilled(a):
    out = spill.empty_rows(a.shape[0], a.shape[1:], a.dtype, True)
    out[:] = a
    return out


def test_every_is_the_strided_subsample(monkeypatch):
    monkeypatch.setattr(spill, "WINDOW_ROWS", 1000)
    a = np.random.default_rng(1).normal(size=(12345, 3))
    s = _spilled(a)
    for step in (1, 7, 180, 999, 1000, 1001, 20000):
        assert checks.every(s, step).tobytes() == a[::step].tobytes()
        assert checks.every(a, step).tobytes() == a[::step].tobytes()


def test_saturation_windowed_is_the_whole_array_check(monkeypatch):
    monkeypatch.setattr(spill, "WINDOW_ROWS", 1000)
    rng = np.random.default_rng(2)
    n = 10500
    t = np.arange(n) * 0.008
    gyro = rng.normal(0, 0.3, (n, 3))
    accel = rng.normal(0, 2.0, (n, 3)) + [0, 0, 9.8]
    gyro[998:1003, 1] = 4.0            # a run across a window's end
    gyro[5000:5002, 0] = -3.0          # too short a run
    accel[10497:, 2] = 40.0            # a run at the end
    for ranges in ((None, None), (1.0, 12.0)):
        whole = checks.saturation("log", t, gyro, accel, *ranges)
        windowed = checks.saturation("log", _spilled(t[:, None])[:, 0], _spilled(gyro), _spilled(accel), *ranges)
        assert [str(f) for f in windowed] == [str(f) for f in whole] and whole
