"""Bad inputs, round two (issue 15), the output directory and the install: a run never removes or
replaces one of its own inputs nor a file navpp did not write (point 4), two runs into one
``--out`` cannot both "succeed" (point 7), and a read-only install without a writable cache
directory still runs (point 11).  Rows go through :func:`badinputs.run_case`; the cases that
must succeed, or need two processes or a read-only file system, are plain tests."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from badinputs import ROOT, SAMPLE, Case, copy_drive, edit_csv, params, run_case, run_in_process, run_navpp, snapshot

from navpp.jitcache import CompileAnnouncer
from navpp.outdir import LOCK_NAME, MANIFEST_NAME


def _mcap_in_out(work: Path) -> Path:
    """``work/out/trajectory.mcap``: a log (the bundled drive) kept in the output directory."""
    out = work / "out"
    out.mkdir()
    shutil.copy(SAMPLE / "drive.mcap", out / "trajectory.mcap")
    return out


def _reprocess_into_own_input(work: Path) -> list[str]:
    out = _mcap_in_out(work)
    return ["process", str(out / "trajectory.mcap"), "--out", str(out), "--format", "csv,mcap"]


def _reference_in_out(work: Path) -> list[str]:
    log = copy_drive(work)
    out = work / "out"
    out.mkdir()
    shutil.move(log / "reference.csv", out / "trajectory.csv")
    return ["process", str(log), "--reference", str(out / "trajectory.csv"), "--out", str(out)]


def _config_in_out(work: Path) -> list[str]:
    log = copy_drive(work)
    out = work / "out"
    out.mkdir()
    shutil.copy(log / "navpp.toml", out / "metrics.md")
    return ["process", str(log), "--config", str(out / "metrics.md"), "--out", str(out)]


CASES = [
    Case("output-would-replace-the-log", _reprocess_into_own_input,
         ("--out", "trajectory.mcap there is an input of this run", "choose another --out")),
    Case("output-would-replace-the-reference", _reference_in_out, ("trajectory.csv there is an input",)),
    Case("output-would-replace-the-config", _config_in_out, ("metrics.md there is an input",)),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_output_dir(case, tmp_path):
    run_case(case, tmp_path)


# ------------------------------------------------------------------ point 4: only navpp's own files go


def test_reprocessing_a_log_in_out_keeps_it_and_removes_only_listed_outputs(tmp_path: Path) -> None:
    """``process out/trajectory.mcap --out out`` used to delete the log as a "stale output"."""
    out = _mcap_in_out(tmp_path)
    log = out / "trajectory.mcap"
    log_bytes = log.read_bytes()
    (out / "metrics.json").write_text('{"filter": "old"}\n')        # an earlier navpp result
    (out / "trajectory.tum").write_text("mine: not listed\n")       # a navpp name, not navpp's file
    (out / MANIFEST_NAME).write_text(json.dumps({"files": ["trajectory.mcap", "metrics.json", "trajectory.kml"]}))
    code, _, err, _ = run_in_process(["process", str(log), "--out", str(out), "-q"], tmp_path)
    assert code == 0, err
    assert log.read_bytes() == log_bytes                            # the input survives
    assert (out / "trajectory.tum").read_text() == "mine: not listed\n"
    assert not (out / "metrics.json").exists()                      # navpp's stale result: removed
    names = sorted(p.name for p in out.iterdir())
    assert names == [MANIFEST_NAME, "diagnostics.csv", "trajectory.csv", "trajectory.mcap", "trajectory.tum"]
    listed = json.loads((out / MANIFEST_NAME).read_text())["files"]
    assert {"diagnostics.csv", "trajectory.csv"} <= set(listed) and "metrics.json" not in listed


def test_leftover_staging_of_a_killed_run_is_removed(tmp_path: Path) -> None:
    """What a run killed by SIGKILL leaves (a ``.navpp-run-*`` staging directory, a temporary
    file, its lock file) goes at the next run into ``--out``, which the old lock file does not
    block; a user's hidden directory with a similar name stays."""
    log = copy_drive(tmp_path)
    out = tmp_path / "out"
    stage = out / ".navpp-run-k1ll3d"
    stage.mkdir(parents=True)
    (stage / "trajectory.csv").write_text("t,lat\n1,2\n")
    (out / ".trajectory.csv.abcd1234.tmp").write_text("half")
    (out / ".navpp-runs").mkdir()
    (out / LOCK_NAME).write_text("999999\n")
    code, _, err, _ = run_in_process(["process", str(log), "--out", str(out), "-q", "--output-rate", "1"], tmp_path)
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, ".navpp-runs", "diagnostics.csv", "metrics.json",
                                                     "metrics.md", "trajectory.csv"]


# ------------------------------------------------------------------ point 7: one run per --out


def test_second_run_into_a_busy_out_fails_at_once(tmp_path: Path) -> None:
    log = copy_drive(tmp_path)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    first = subprocess.Popen([sys.executable, "-m", "navpp", "process", str(log), "--out", str(out), "-q",
                              "--filter", "ukf", "--smooth"], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (out / LOCK_NAME).exists():      # the first run holds the lock from before it reads
            assert first.poll() is None, first.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        code, _stdout, stderr, wall = run_navpp(["process", str(log), "--out", str(out), "-q"])
        still_running = first.poll() is None
    finally:
        _f_out, f_err = first.communicate(timeout=120)
    assert still_running, "the first run ended before the second started: the test proves nothing"
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert code == 1 and len(lines) == 1, stderr
    assert lines[0] == (f"navpp: error: --out {out}: another navpp run (pid {first.pid}) is writing there; "
                        "wait for it to end or choose another --out")
    assert wall < 20
    assert first.returncode == 0, f_err
    # the first run's results are whole, and the lock is gone with it
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "diagnostics.csv", "metrics.json", "metrics.md",
                                                     "trajectory.csv", "trajectory_forward.csv"]
    assert json.loads((out / "metrics.json").read_text())["filter"] == "ukf"


def test_lock_taken_in_process_blocks_a_second_taker(tmp_path: Path) -> None:
    """The lock itself: held -> a second taker fails naming the directory; released -> free again,
    and the lock file is gone."""
    from navpp.errors import InputError
    from navpp.outdir import OutDirLock

    with OutDirLock(tmp_path, "--out"):
        assert (tmp_path / LOCK_NAME).read_text().strip() == str(os.getpid())
        # flock locks belong to the open file: a second open in this process conflicts too
        with pytest.raises(InputError, match=rf"--out {tmp_path}: another navpp run \(pid {os.getpid()}\)"):
            OutDirLock(tmp_path, "--out").acquire()
    assert not (tmp_path / LOCK_NAME).exists()
    with OutDirLock(tmp_path, "--out"):
        pass


# ------------------------------------------------------------------ point 11: read-only install


def _read_only_install(tmp_path: Path) -> tuple[Path, Path, list[str]]:
    """A copy of the package on a read-only place and a HOME that cannot be written; returns
    (install dir, writable TMPDIR, command prefix).  As root, permissions do not stop writes, so
    the copy is bind-mounted read-only in a private mount namespace (``unshare -m``)."""
    ro = tmp_path / "ro"
    shutil.copytree(ROOT / "navpp", ro / "navpp", ignore=shutil.ignore_patterns("__pycache__"))
    (ro / "home").mkdir()
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    if os.geteuid() != 0:
        for p in [ro, *ro.rglob("*")]:
            p.chmod(p.stat().st_mode & ~0o222)
        return ro, tmp, []
    if shutil.which("unshare") is None:
        pytest.skip("root without unshare: cannot make a read-only install")
    probe = subprocess.run(["unshare", "-m", "sh", "-c",
                            f"mount --bind {ro} {ro} && mount -o remount,ro,bind {ro} {ro}"],
                           capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot bind-mount read-only: {probe.stderr.decode()[:200]}")
    return ro, tmp, ["unshare", "-m", "sh", "-c",
                     f'mount --bind {ro} {ro} && mount -o remount,ro,bind {ro} && exec "$@"', "sh"]


def _run_read_only(tmp_path: Path, argv: list[str]) -> tuple[int, str, str, Path]:
    ro, tmp, prefix = _read_only_install(tmp_path)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "XDG_"))}
    env.update(PYTHONPATH=str(ro), HOME=str(ro / "home"), TMPDIR=str(tmp), COLUMNS="200")
    proc = subprocess.run([*prefix, sys.executable, "-m", "navpp", *argv], capture_output=True, text=True, env=env,
                          timeout=120, cwd=tmp_path)
    return proc.returncode, proc.stdout, proc.stderr, tmp


def test_read_only_install_lists_the_filters(tmp_path: Path) -> None:
    code, stdout, stderr, tmp = _run_read_only(tmp_path, ["filters"])
    assert code == 0, stderr
    assert "Traceback" not in stderr and "no locator" not in stderr
    assert stdout.splitlines()[3].startswith("ekf ")
    cache = tmp / f"navpp-numba-cache-{os.getuid()}"
    assert stderr.strip() == (f"note: neither navpp's install directory nor {tmp_path}/ro/home/.cache/numba "
                              "is writable: "
                              f"compiled kernels are cached in {cache} (kept between runs); "
                              "set NUMBA_CACHE_DIR to choose")
    assert cache.is_dir() and cache.stat().st_mode & 0o777 == 0o700


def test_read_only_install_reports_a_bad_input_in_one_line(tmp_path: Path) -> None:
    log = copy_drive(tmp_path)
    edit_csv(log / "gnss.csv", lambda ls: [",".join(x.split(",")[:3]) for x in ls])
    before = snapshot(log)
    code, _, stderr, _ = _run_read_only(tmp_path, ["process", str(log), "--out", str(tmp_path / "out")])
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert code == 1, stderr
    assert "Traceback" not in stderr
    assert lines[0].startswith("note: ") and lines[-1].startswith("navpp: error: ") and "gnss.csv" in lines[-1]
    # on this cold cache the CSV parser's kernel compiles while imu.csv is read: announced, one line
    said = ("note: ", "warning: ")
    assert all(ln.startswith(said) or ln.endswith(CompileAnnouncer.LINE) for ln in lines[:-1]), stderr
    assert snapshot(log) == before and not (tmp_path / "out").exists()


def test_unwritable_numba_cache_dir_falls_back(tmp_path: Path) -> None:
    """``NUMBA_CACHE_DIR`` naming a place that cannot be written (here: below a file) is replaced."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    env = {"NUMBA_CACHE_DIR": str(blocker / "cache"), "TMPDIR": str(tmp_path)}
    code, _stdout, stderr, _ = run_navpp(["filters"], env=env)
    assert code == 0, stderr
    assert stderr.startswith(f"note: NUMBA_CACHE_DIR {blocker / 'cache'} is not writable: compiled kernels are "
                             f"cached in {tmp_path}/navpp-numba-cache-{os.getuid()}")
