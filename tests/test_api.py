"""``navpp.api.process``: output directory checks, output rate checks, stale outputs.

Oracles: the exact one-line messages the contract asks for, the files on disk before and
after, and the simulated log's known IMU rate (125 Hz) and truth.
"""

from __future__ import annotations

import errno
import json
import math
from pathlib import Path

import numpy as np
import pytest

from navpp import api, engine
from navpp.errors import ConfigError, InputError
from navpp.io import writers

IMU_RATE_HZ = 125.0  # conftest's simulated log


@pytest.fixture
def no_reading(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if the log is read: the check under test must come first."""

    def read_log(*args, **kwargs):
        raise AssertionError("the log was read before the output was checked")

    monkeypatch.setattr(api, "read_log", read_log)


@pytest.fixture
def no_filtering(monkeypatch: pytest.MonkeyPatch) -> None:
    def run(*args, **kwargs):
        raise AssertionError("the filter ran before the output rate was checked")

    monkeypatch.setattr(engine, "run", run)


def tree(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


# --------------------------------------------------------------------------------- --out


def test_out_is_an_existing_file(sim_log_dir: Path, tmp_path: Path, no_reading) -> None:
    out = tmp_path / "taken"
    out.write_text("not a directory\n")
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir, out_dir=out)
    assert str(exc.value) == f"--out {out}: cannot write there (it is a file, not a directory)"
    assert out.read_text() == "not a directory\n"


def test_out_below_a_file(sim_log_dir: Path, tmp_path: Path, no_reading) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    out = blocker / "sub" / "dir"
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir, out_dir=out)
    assert str(exc.value) == f"--out {out}: cannot write there ({blocker} is a file, not a directory)"


def test_out_not_writable(sim_log_dir: Path, tmp_path: Path, no_reading, monkeypatch: pytest.MonkeyPatch) -> None:
    """Read-only directory (simulated: root ignores permissions); the directories made are removed."""

    def mkstemp(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(api.tempfile, "mkstemp", mkstemp)
    out = tmp_path / "new" / "out"
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir, out_dir=out)
    assert str(exc.value) == f"--out {out}: cannot write there (permission denied)"
    assert sorted(tmp_path.iterdir()) == []


def test_out_mkdir_fails(sim_log_dir: Path, tmp_path: Path, no_reading, monkeypatch: pytest.MonkeyPatch) -> None:
    def mkdir(self, *args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(self))

    monkeypatch.setattr(Path, "mkdir", mkdir)
    out = tmp_path / "out"
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir, out_dir=out)
    assert str(exc.value) == f"--out {out}: cannot write there (permission denied)"


def test_default_out_dir_is_checked_too(sim_log_dir: Path, tmp_path: Path, no_reading,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    Path("navpp-out").write_text("x")
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir)
    expected = Path("navpp-out") / f"{sim_log_dir.name}-ekf"
    assert str(exc.value) == f"output directory {expected}: cannot write there (navpp-out is a file, not a directory)"


def test_write_false_touches_nothing(sim_log_dir: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = api.process(sim_log_dir, out_dir=blocker / "sub", write=False)
    assert res.files == ()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_write_failure_names_the_file(sim_log_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full_disk(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(writers, "write_metrics_json", full_disk)
    out = tmp_path / "out"
    with pytest.raises(InputError) as exc:
        api.process(sim_log_dir, out_dir=out)
    assert str(exc.value) == f"{out / 'metrics.json'}: cannot write (no space left on device)"


def test_failed_run_removes_the_directories_it_made(log_copy: Path, tmp_path: Path) -> None:
    (log_copy / "imu.csv").write_text("t,gx,gy,gz,ax,ay,az\n")
    out = tmp_path / "a" / "b"
    with pytest.raises(InputError):
        api.process(log_copy, out_dir=out)
    assert not (tmp_path / "a").exists()


# --------------------------------------------------------------------------------- output rate


@pytest.mark.parametrize("rate", [math.nan, math.inf, -math.inf, -1.0, 0.0, True, "10"])
def test_output_rate_must_be_finite_positive(sim_log_dir: Path, tmp_path: Path, no_reading, rate) -> None:
    out = tmp_path / "out"
    with pytest.raises(ConfigError) as exc:
        api.process(sim_log_dir, out_dir=out, output_rate_hz=rate)
    assert str(exc.value) == f"--output-rate must be a finite number of Hz > 0, got {rate!r}"
    assert not out.exists()


def _linear_solution(t0: float, t1: float, n: int = 11):
    from navpp.recording import Solution

    t = np.linspace(t0, t1, n)
    return Solution(t=t, lat_deg=45.0 + 1e-3 * t, lon_deg=np.full(n, 7.0), alt=2.0 * t,
                    vel_enu=np.zeros((n, 3)), rph_deg=np.zeros((n, 3)), std_enu=np.ones((n, 3)), t0_ns=0)


@pytest.mark.parametrize("rate", [math.nan, math.inf, 0.0, -5.0])
def test_resample_solution_rejects_bad_rates(rate) -> None:
    with pytest.raises(ConfigError, match=r"^output rate must be a finite number of Hz > 0, got "):
        api.resample_solution(_linear_solution(0.0, 1.0), rate)


def test_resample_solution_grid_and_values() -> None:
    # 4 Hz on [0, 1] s: whole multiples of 0.25 s; values of a linear track interpolate exactly
    r = api.resample_solution(_linear_solution(0.0, 1.0), 4.0)
    np.testing.assert_allclose(r.t, [0.0, 0.25, 0.5, 0.75, 1.0], atol=1e-12)
    np.testing.assert_allclose(r.lat_deg, 45.0 + 1e-3 * r.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.alt, 2.0 * r.t, atol=1e-12)
    # 0.1 Hz: no multiple of 10 s falls inside [0.1, 0.9] s
    with pytest.raises(ConfigError, match="no output epoch"):
        api.resample_solution(_linear_solution(0.1, 0.9), 0.1)


def test_output_rate_above_imu_rate(sim_log_dir: Path, tmp_path: Path, no_filtering) -> None:
    out = tmp_path / "out"
    with pytest.raises(ConfigError) as exc:
        api.process(sim_log_dir, out_dir=out, output_rate_hz=500.0)
    assert str(exc.value) == (f"--output-rate 500 Hz is above the IMU rate of {sim_log_dir} ({IMU_RATE_HZ:.1f} Hz); "
                              "the trajectory cannot be finer than the IMU")
    assert not out.exists()


def test_config_output_rate_above_imu_rate_names_the_config(sim_log_dir: Path, tmp_path: Path, no_filtering) -> None:
    cfg = tmp_path / "rate.toml"
    cfg.write_text("[output]\nrate_hz = 200.0\n")
    with pytest.raises(ConfigError) as exc:
        api.process(sim_log_dir, config=cfg, out_dir=tmp_path / "out")
    assert str(exc.value).startswith(f"{cfg}: [output] rate_hz 200 Hz is above the IMU rate of {sim_log_dir} "
                                     f"({IMU_RATE_HZ:.1f} Hz)")


def test_output_rate_equal_to_imu_rate_is_fine(sim_log_dir: Path, tmp_path: Path) -> None:
    res = api.process(sim_log_dir, output_rate_hz=IMU_RATE_HZ, write=False)
    np.testing.assert_allclose(np.diff(res.solution.t), 1.0 / IMU_RATE_HZ, atol=1e-6)


# --------------------------------------------------------------------------------- stale outputs


def test_rerun_without_reference_removes_stale_metrics(log_copy: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = api.process(log_copy, out_dir=out)
    assert sorted(p.name for p in first.files) == ["diagnostics.csv", "metrics.json", "metrics.md", "trajectory.csv"]
    # files that are not navpp's own outputs (or only look alike) are left alone
    keep = {"notes.txt": b"mine\n", "metrics.json.bak": b"{}", "old": None}
    for name, data in keep.items():
        (out / name).mkdir() if data is None else (out / name).write_bytes(data)
    (out / "old" / "metrics.md").write_text("nested: not ours to remove\n")

    (log_copy / "reference.csv").unlink()
    second = api.process(log_copy, out_dir=out, output_rate_hz=5.0)
    assert second.files == (out / "trajectory.csv", out / "diagnostics.csv")
    assert sorted(p.name for p in out.iterdir()) == [".navpp-manifest.json", "diagnostics.csv", "metrics.json.bak",
                                                     "notes.txt", "old", "trajectory.csv"]
    assert (out / "old" / "metrics.md").is_file()
    lines = (out / "trajectory.csv").read_text().splitlines()
    t = np.array([float(line.split(",", 1)[0]) for line in lines[1:]])
    np.testing.assert_allclose(np.diff(t), 0.2, atol=1e-6)       # the new run's trajectory, at 5 Hz


def test_failed_rerun_keeps_previous_outputs(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    api.process(sim_log_dir, out_dir=out)
    before = tree(out)
    with pytest.raises(ConfigError):
        api.process(sim_log_dir, out_dir=out, output_rate_hz=1000.0)
    assert tree(out) == before
    assert json.loads(before["metrics.json"])["filter"] == "ekf"


def test_the_cyclic_collector_is_paused_for_the_run_and_left_as_it_was(sim_log_dir: Path, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The run goes without the cyclic garbage collector (its walks over the imports' and the
    kernels' objects cost a tenth of a run), which is left after it as it was, also when the run
    fails; a caller that had paused it finds it paused."""
    import gc

    seen = []

    def run(*args, **kwargs):
        seen.append(gc.isenabled())
        raise InputError("stop here")

    monkeypatch.setattr(engine, "run", run)
    assert gc.isenabled()
    for enabled in (True, False):
        (gc.enable if enabled else gc.disable)()
        try:
            with pytest.raises(InputError, match="stop here"):
                api.process(sim_log_dir, out_dir=tmp_path / "out")
            assert gc.isenabled() is enabled
        finally:
            gc.enable()
    assert seen == [False, False]
