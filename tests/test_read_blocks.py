"""The reader's memory-lean paths: the fast parser's column groups (the final (N, 3) arrays,
no copy), and the stamp checks that run a block of rows at a time (a finding in a later block
is the same as in the first)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navpp import jitmode
from navpp.io.csv import read_csv_log
from navpp.recording import BLOCK_ROWS, lone_stamp


@pytest.mark.skipif(jitmode.interpreted(), reason="the fast path runs only compiled")
def test_groups_hold_the_same_bits_as_single_columns(tmp_path: Path) -> None:
    """Fields in groups of (1, 3, 3) come back as (n,) and C-contiguous (n, 3) arrays with the
    bits of the one-column form, also when the output outgrows its first guess."""
    from navpp.io.csvparse import parse_columns

    rng = np.random.default_rng(3)
    x = rng.standard_normal((5000, 7))
    long = [",".join(f"{v:.17g}" for v in row) for row in x[:100]]
    short = [",".join(f"{v:.3f}" for v in row) for row in x[100:]]       # shorter rows: the output grows
    path = tmp_path / "f.csv"
    path.write_text("a,b,c,d,e,f,g\n" + "\n".join(long + short) + "\n")
    single = parse_columns(path, 7, list(range(7)), 0)
    grouped = parse_columns(path, 7, list(range(7)), 0, widths=(1, 3, 3))
    assert single is not None and grouped is not None
    cols, ns = grouped
    assert [c.shape for c in cols] == [(5000,), (5000, 3), (5000, 3)]
    assert all(c.flags.c_contiguous for c in cols)
    assert np.hstack([cols[0][:, None], cols[1], cols[2]]).tobytes() == np.array(single[0]).T.copy().tobytes()
    assert ns is not None and single[1] is not None and ns.tobytes() == single[1].tobytes()


def test_lone_stamp_in_a_later_block() -> None:
    t = np.arange(3 * BLOCK_ROWS) * 0.01
    k = 2 * BLOCK_ROWS + 17
    t[k] += 50.0
    assert lone_stamp(t, reorder_s=0.0) == (k, pytest.approx(50.0 - 0.01))
    assert lone_stamp(np.round(t * 1e9).astype(np.int64), reorder_s=0.0)[0] == k


def test_more_decimals_in_a_later_block_take_the_exact_stamps(tmp_path: Path) -> None:
    """Two decimals over the first lines, a stamp with nine beyond the first block: the exact
    ns of that stamp, not the rounded value."""
    n = BLOCK_ROWS + 1000
    stamps = [f"{1000 + 0.01 * k:.2f}" for k in range(n)]
    stamps[BLOCK_ROWS + 500] = f"{1000 + 0.01 * (BLOCK_ROWS + 500):.2f}0000007"
    rows = "".join(f"{s},0.001,0.002,0.003,0.1,0.2,9.8\n" for s in stamps)
    (tmp_path / "imu.csv").write_text("t,gx,gy,gz,ax,ay,az\n" + rows)
    (tmp_path / "gnss.csv").write_text("t,lat,lon,alt\n" + "".join(
        f"{1000 + 0.2 * k:.1f},45.0,7.0,300.0\n" for k in range(int(n * 0.01 / 0.2))))
    rec = read_csv_log(tmp_path, time_base="relative")
    k = BLOCK_ROWS + 500
    assert rec.t0_ns == 1000 * 10**9
    assert round((rec.imu.t[k] - rec.imu.t[k - 1]) * 1e9) == 10_000_007
