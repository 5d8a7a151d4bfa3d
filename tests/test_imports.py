"""Start-up: ``import navpp.api`` and the command line's own modules load none of the heavy
modules; each is imported on the path that needs it (issue 21, point 3)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "pandas", "scipy", "numba", "matplotlib", "dask", "mcap", "rosbags")


def _loaded_after(statement: str) -> list[str]:
    """The modules of :data:`HEAVY` in ``sys.modules`` after ``statement``, in a fresh interpreter."""
    code = f"import sys; {statement}; print(','.join(m for m in {HEAVY!r} if m in sys.modules))"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO, check=True)
    return [m for m in out.stdout.strip().split(",") if m]


@pytest.mark.parametrize("statement", ["import navpp", "import navpp.api", "import navpp.cli",
                                       "from navpp.api import process, read_log, resolve_config, simulate_log"])
def test_importing_loads_no_heavy_module(statement: str) -> None:
    assert _loaded_after(statement) == []


def test_apply_outages_is_still_importable_from_api() -> None:
    from navpp import api, outages

    assert api.apply_outages is outages.apply_outages
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = api.no_such_name  # type: ignore[attr-defined]
