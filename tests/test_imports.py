"""Start-up: ``import navpp.api`` and the command line's own modules load none of the heavy
modules; each is imported on the path that needs it, and a default run does without some
(issue 21, point 3)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "pandas", "scipy", "numba", "matplotlib", "dask", "mcap", "rosbags")
#: What a default run (CSV log, EKF, outputs written) does without: pandas, and scipy's
#: interpolation (0.3 s of start; the clock-offset search's own spline evaluation gives its bits)
#: and optimisation with the special functions it brings (0.4 s; the search's lag is refined by
#: its own golden-section search)
KEPT_OUT = ("pandas", "scipy.interpolate", "scipy.optimize", "scipy.special", "scipy.stats", "matplotlib",
            "dask")


def _loaded_after(statement: str, modules: tuple[str, ...] = HEAVY) -> list[str]:
    """The modules of ``modules`` in ``sys.modules`` after ``statement``, in a fresh interpreter."""
    code = f"import sys; {statement}; print(','.join(m for m in {modules!r} if m in sys.modules))"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO, check=True)
    return [m for m in out.stdout.strip().split(",") if m]


@pytest.mark.parametrize("statement", ["import navpp", "import navpp.api", "import navpp.cli",
                                       "from navpp.api import process, read_log, resolve_config, simulate_log"])
def test_importing_loads_no_heavy_module(statement: str) -> None:
    assert _loaded_after(statement) == []


def test_a_default_run_loads_none_of_the_kept_out_modules(tmp_path: Path) -> None:
    log = REPO / "sample_data" / "drive"
    assert _loaded_after(f"from navpp.api import process; process({str(log)!r}, out_dir={str(tmp_path)!r})",
                         KEPT_OUT) == []


def test_apply_outages_is_still_importable_from_api() -> None:
    from navpp import api, outages

    assert api.apply_outages is outages.apply_outages
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = api.no_such_name  # type: ignore[attr-defined]
