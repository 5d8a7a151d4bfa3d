"""Shared fixtures: one short simulated CSV log per test session (its truth is the oracle)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

# Compiled kernels for the whole test session and the CLI processes it starts: with the
# command line's default (auto), a first short CLI run in this process would make every later
# test run interpreted (navpp.jitmode).  Tests of the choice itself set the mode explicitly.
os.environ["NAVPP_JIT"] = "on"
# numba's dispatchers, not a native module (navpp.kernel): one built on this machine for these
# sources would otherwise serve the tests (same results, but no numba compile events to test).
# tests/test_native.py builds its own modules and turns them on in the processes it starts.
os.environ["NAVPP_NATIVE"] = "0"

#: The session log: 120 s at 125 Hz IMU / 5 Hz GNSS, 30 s still first, automotive IMU.
SIM_DURATION_S = 120.0
SIM_STILL_S = 30.0
SIM_SEED = 3


@pytest.fixture(scope="session")
def sim_log_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated CSV log directory (imu.csv, gnss.csv, reference.csv, navpp.toml), made once.

    Read-only for tests: copy it (``log_copy``) before changing anything in it.
    """
    from navpp.simulate import SimulationSpec, simulate, write_csv_log

    out = tmp_path_factory.mktemp("simlog") / "drive"
    sim = simulate(SimulationSpec(duration_s=SIM_DURATION_S, still_s=SIM_STILL_S, seed=SIM_SEED))
    write_csv_log(sim, out)
    return out


@pytest.fixture
def log_copy(sim_log_dir: Path, tmp_path: Path) -> Path:
    """A private copy of the session log that a test may edit."""
    dst = tmp_path / "log"
    shutil.copytree(sim_log_dir, dst)
    return dst
