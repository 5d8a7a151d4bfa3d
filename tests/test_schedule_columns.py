"""Issue 21 (GNSS-rate records): the run's epochs as columns (:class:`navpp.engine.schedule.Schedule`)
give the same stops, field for field, as a list of :class:`Epoch` made one by one, and the
compiled path reads the same columns from either."""

from __future__ import annotations

import numpy as np

from navpp.engine.schedule import Epoch, Schedule, coast_stops, epochs


def _one_by_one(t_start, t_end, times, fix, constraints, imu_t, knot_s=1.0):
    """The oracle: the stops appended one at a time (coasting stops through :func:`coast_stops`)."""
    out, t_prev = [], t_start
    for e, t_e in enumerate(times):
        out += coast_stops(t_prev, float(t_e), knot_s)
        k = int(np.searchsorted(imu_t, t_e))
        sample = k if k < imu_t.shape[0] and imu_t[k] == t_e else -1
        out.append(Epoch(float(t_e), e, int(fix[e]), bool(constraints[e]), sample))
        t_prev = float(t_e)
    out += coast_stops(t_prev, t_end, knot_s)
    if (out[-1].t if out else t_start) < t_end:
        out.append(Epoch(t_end, coast=True))
    return out


def _fields(stops):
    return [(e.t, e.index, e.fix, e.constraints, e.sample, e.coast) for e in stops]


def test_the_columns_give_the_stops_one_by_one_would():
    rng = np.random.default_rng(21)
    for case in range(200):
        n = int(rng.integers(0, 40))
        steps = rng.choice([0.2, 0.2, 0.2, 1.3, 2.6, 7.05], n)
        times = np.unique(np.round(0.1 + np.cumsum(steps), 3))
        n = times.shape[0]
        fix, cons = rng.integers(-1, 30, n), rng.random(n) < 0.5
        imu_t = np.unique(np.concatenate([np.arange(0.0, 60.0, 0.008), times[::2]]))
        t_end = float(times[-1]) if (n and case % 3 == 0) else float(imu_t[-1])
        got = epochs(0.0, t_end, times, fix, cons, imu_t)
        want = _one_by_one(0.0, t_end, times, fix, cons, imu_t)
        assert isinstance(got, Schedule) and len(got) == len(want)
        assert _fields(got) == _fields(want) == _fields(got[k] for k in range(len(got)))
        assert all(type(a) is type(b) for x, y in zip(_fields(got), _fields(want)) for a, b in zip(x, y))
        assert _fields(got[2:7]) == _fields(want[2:7])
        for a, b in zip(Schedule.columns(got), Schedule.columns(want)):
            assert a.dtype == b.dtype and np.array_equal(a, b)
