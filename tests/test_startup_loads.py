"""Start-up of a run (issue 21, point 3): which of navpp's own modules and numba kernels a path
loads.  Each kernel loaded from numba's cache costs CPU at start (the first one ~0.35 s of
numba's own set-up, each further one a few to ~100 ms), each module its import."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from navpp import jitmode

REPO = Path(__file__).resolve().parents[1]
LOG = REPO / "sample_data" / "drive"

_LOADED_KERNELS = """
import sys
from numba.core.registry import CPUDispatcher
names = set()
for name, module in list(sys.modules.items()):
    if name.startswith("navpp."):
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.overloads:
                names.add(f"{name}.{attr}")
print(",".join(sorted(names)))
"""


def _run(code: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO,
                          check=True).stdout.strip()


@pytest.mark.parametrize(("formats", "loaded"), [("csv", False), ("csv,tum", True)])
def test_the_export_writers_load_only_for_their_formats(tmp_path: Path, formats: str, loaded: bool) -> None:
    """A run writing trajectory.csv imports neither navpp.io.exports (with xml.sax and urllib)
    nor the Foxglove layout; one writing TUM does import the exports."""
    out = _run(f"import sys; from navpp.api import process; "
               f"process({str(LOG)!r}, out_dir={str(tmp_path)!r}, formats={formats!r}); "
               "print(','.join(m for m in ('navpp.io.exports', 'xml.sax.saxutils', 'navpp.io.foxglove') "
               "if m in sys.modules))")
    assert out == ("navpp.io.exports,xml.sax.saxutils" if loaded else "")


@pytest.mark.skipif(jitmode.interpreted(), reason="kernels are loaded only when compiled")
def test_reading_a_csv_log_loads_one_kernel() -> None:
    """The CSV reader's fast path is one kernel (one overload per table shape)."""
    out = _run(f"from navpp.io.csv import read_csv_log; read_csv_log({str(LOG)!r})\n{_LOADED_KERNELS}")
    assert out == "navpp.io.csvparse._parse_block"
