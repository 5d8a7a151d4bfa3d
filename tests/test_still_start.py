"""A long still start: the still period found whole, the start position the mean of its fixes
with an honest 1-sigma, no jump when the filter starts (against the simulator's truth)."""

import numpy as np

from navpp.ins.alignment import bridged


def test_bridged_fills_short_breaks_only():
    t = np.arange(0.0, 20.0, 0.5)
    mask = np.ones(t.size, bool)
    mask[4:6] = False          # 1.0 s of False: 1.5 s from the last True before to the first after
    mask[20:32] = False        # 6.0 s: 6.5 s across
    out = bridged(t, mask, 5.0)
    assert out[:20].all()                      # the short break is filled
    assert not out[20:32].any() and out[32:].all()
    # a leading or trailing False run is no break between two rests
    m2 = np.r_[np.zeros(3, bool), np.ones(5, bool), np.zeros(3, bool)]
    assert np.array_equal(bridged(np.arange(11.0), m2, 5.0), m2)
