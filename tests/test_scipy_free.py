"""What replaces scipy on a run's default path gives scipy's bits (issue 21, point 3): the
chi-square quantiles of the gates (:mod:`navpp.chi2`), the clock-offset search's spline
evaluation (:class:`~navpp.ins.timing_estimates.Cubic`)."""

import numpy as np
import pytest
from scenarios import spline_samples
from scipy import interpolate, special

from navpp import chi2
from navpp.ins import timing_estimates


@pytest.mark.parametrize(("dof", "tail"), sorted(chi2.UPPER_QUANTILES))
def test_table_quantiles_are_scipys(dof, tail):
    assert chi2.chdtri(dof, tail) == float(special.chdtri(dof, tail))


@pytest.mark.parametrize(("dof", "p"), [(3, 0.9999), (1, 0.9999), (6, 0.999), (2, 0.95), (7, 0.9999), (3, 0.5)])
def test_quantiles_as_the_callers_ask(dof, p):
    """The callers' ``1.0 - p`` (table or not) and the 3-dof lower quantile of the checks."""
    assert chi2.chdtri(dof, 1.0 - p) == float(special.chdtri(dof, 1.0 - p))
    assert chi2.chdtri(3, p) == float(special.chdtri(3, p))


@pytest.mark.parametrize("seed", range(30))
def test_cubic_is_ppoly(seed):
    """Random not-a-knot splines (jittery stamps, stamps with gaps, an even grid far from 0;
    values over six decades) at points inside, outside, on the breakpoints and their neighbours,
    and NaN: the intervals found from the offsets are the binary search's."""
    rng = np.random.default_rng(seed)
    t, y = spline_samples(rng, int(rng.integers(4, 3000)), seed % 3, gaps=3, shift=True)
    got = timing_estimates._spline(t, y)
    ref = interpolate.CubicSpline(t, y, extrapolate=False)
    q = np.concatenate([np.linspace(t[0] - 0.5, t[-1] + 0.5, 2001), t, rng.uniform(t[0], t[-1], 2000),
                        [np.nan, np.nextafter(t[0], np.inf), np.nextafter(t[-1], -np.inf)]])
    assert ref(q).tobytes() == got(q).tobytes()
    assert ref(q[:100].reshape(10, 10)).tobytes() == got(q[:100].reshape(10, 10)).tobytes()
