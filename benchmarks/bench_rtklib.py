"""RTKLIB ``.pos`` reading speed: ``navpp.io.rtklib.read_pos`` on one hour of 10 Hz solution
lines (36,000 epochs, position and velocity columns), with the pandas fast path and with the
line-by-line parser; prints lines per second and microseconds per line (best of ``--repeat``).

    python benchmarks/bench_rtklib.py [--epochs 36000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from navpp.io import rtklib

HEADER = [
    "% program   : RTKPOST ver.2.4.3 b34",
    "% obs start : 2024/01/01 00:00:00.0 GPST (week2295  86400.0s)",
    "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
    ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)"
     "  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn    sdve    sdvu   sdvne   sdveu"
     "   sdvun"),
]
BODY = ("   35.123456789  139.123456789    50.1234   1   8   0.0030   0.0040   0.0090   0.0010   0.0000  -0.0020"
        "   0.00    0.0    1.00000    2.00000   -0.50000   0.01000 0.02000 0.03000 0.00000 0.00000 0.00000")


def write_file(path: Path, epochs: int) -> Path:
    """A ``.pos`` file of ``epochs`` lines at 10 Hz from 2024-01-01 00:00:00 GPST (CRLF, as RTKLIB writes)."""
    t = 1704067200 + np.arange(epochs) * 0.1
    stamps = [np.datetime64(round(x * 1000), "ms").astype(str).replace("-", "/").replace("T", " ") for x in t]
    path.write_text("\r\n".join(HEADER + [s + BODY for s in stamps]) + "\r\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=36_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        p = write_file(Path(tmp) / "sol.pos", args.epochs)
        for label, fast in (("pandas fast path", True), ("line-by-line", False)):
            rtklib._FAST_PATH = fast
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                g, _, _ = rtklib.read_pos(p)
                best = min(best, time.perf_counter() - t0)
            assert len(g) == args.epochs
            print(f"{label:18s} {args.epochs} lines in {best:.3f} s: {args.epochs / best:,.0f} lines/s, "
                  f"{1e6 * best / args.epochs:.1f} µs per line")


if __name__ == "__main__":
    main()
