"""The ``navpp`` command line: what users type, what they get (INTERFACES.md).

Most tests drive the Typer app in-process with ``CliRunner`` (this Typer vendors Click >= 8.2:
``result.stdout`` and ``result.stderr`` are separate, ``result.output`` mixes both); one test
runs the installed console script.  The simulated session log (``conftest.sim_log_dir``) has
a known truth, so accuracy checks compare against it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from navpp.cli import app
from navpp.outdir import MANIFEST_NAME as MANIFEST

TRAJECTORY_HEADER = "t,lat,lon,alt,ve,vn,vu,roll,pitch,heading,std_e,std_n,std_u"
METRICS_KEYS = {"filter", "log", "reference", "epochs", "position_m", "velocity_mps", "attitude_deg",
                "runtime_s", "imu_samples", "gnss_epochs", "gnss_rejected"}

runner = CliRunner()


# --------------------------------------------------------------------------------- helpers


def invoke(*args: str | Path):
    return runner.invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    """Whitespace collapsed: rich wraps long lines at the console width."""
    return " ".join(text.split())


def read_lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def write_lines(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def set_cell(path: Path, line_no: int, column: str, value: str) -> None:
    """Replace one cell; ``line_no`` counts file lines from 1 (the header is line 1)."""
    lines = read_lines(path)
    header = lines[0].split(",")
    fields = lines[line_no - 1].split(",")
    fields[header.index(column)] = value
    lines[line_no - 1] = ",".join(fields)
    write_lines(path, lines)


def column(path: Path, name: str) -> np.ndarray:
    lines = read_lines(path)
    j = lines[0].split(",").index(name)
    return np.array([float(line.split(",")[j]) for line in lines[1:]])


def assert_one_line_error(res, out_dir: Path) -> str:
    """Exit 1 via a clean failure: one error line, last on stderr, after only the run's own
    warnings and notes (what it found before it failed); nothing on stdout, no files."""
    assert res.exit_code == 1, (res.exit_code, res.output, res.exception)
    # CliRunner turns an uncaught exception into exit code 1 too: make sure it was a clean exit
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    assert res.stdout.strip() == ""
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert lines and lines[-1].startswith("navpp: error: "), res.stderr
    assert all(line.startswith(("warning: ", "· ")) for line in lines[:-1]), res.stderr
    leftovers = sorted(p.name for p in out_dir.rglob("*")) if out_dir.exists() else []
    assert leftovers == [], leftovers
    return lines[-1]


# --------------------------------------------------------------------------------- process


@pytest.fixture(scope="module")
def processed(sim_log_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    """``navpp process LOG --out DIR`` on the session log (reference.csv picked up from LOG)."""
    out = tmp_path_factory.mktemp("process") / "run"
    res = invoke("process", sim_log_dir, "--out", out)
    return res, out


def test_process_exit_and_summary(processed) -> None:
    res, _out = processed
    assert res.exit_code == 0, (res.output, res.exception)
    assert res.exception is None
    text = flat(res.stdout)
    assert "15001 IMU samples at 125.0 Hz" in text
    assert "filter ekf" in text
    m = json.loads((processed[1] / "metrics.json").read_text())
    assert f"{m['gnss_epochs']} GNSS epochs used ({m['gnss_rejected']} rejected by the gate)" in text
    assert "horizontal" in text and "raw GNSS horiz." in text
    assert "wrote" in text and all(n in text for n in ("trajectory.csv", "metrics.json", "metrics.md"))


def test_process_trajectory_one_row_per_imu_sample(processed, sim_log_dir: Path) -> None:
    _, out = processed
    traj = out / "trajectory.csv"
    lines = read_lines(traj)
    assert lines[0] == TRAJECTORY_HEADER
    t_traj = column(traj, "t")
    t_imu = column(sim_log_dir / "imu.csv", "t")
    # rows start at the alignment start, which is an IMU stamp, then follow every IMU sample
    expected = t_imu[t_imu >= t_traj[0] - 1e-7]
    assert len(t_traj) == len(expected)
    np.testing.assert_allclose(t_traj, expected, rtol=0.0, atol=1e-6)
    assert all(len(line.split(",")) == 13 for line in lines[1:])


def test_process_metrics_files(processed, sim_log_dir: Path) -> None:
    _, out = processed
    assert (out / "metrics.md").is_file()
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "diagnostics.csv", "metrics.json", "metrics.md", "trajectory.csv"]
    m = json.loads((out / "metrics.json").read_text())
    assert set(m) >= METRICS_KEYS
    assert m["filter"] == "ekf"
    assert m["reference"] == str(sim_log_dir / "reference.csv")   # auto-pickup from the log dir
    assert m["epochs"] > 1000
    assert set(m["position_m"]) >= {"east", "north", "up", "horizontal", "3d"}
    for axis in ("east", "north", "up"):
        assert {"mae", "rmse", "max"} <= set(m["position_m"][axis])
    assert {"mae", "rmse", "p95"} <= set(m["position_m"]["horizontal"])
    assert {"mae", "rmse"} <= set(m["position_m"]["3d"])
    assert m["imu_samples"] == 15001
    assert m["gnss_epochs"] > 500 and 0 <= m["gnss_rejected"] < m["gnss_epochs"]
    assert m["runtime_s"] > 0.0


def test_process_beats_raw_gnss(processed) -> None:
    """The fused solution is closer to the simulator's truth than the raw GNSS fixes."""
    _, out = processed
    m = json.loads((out / "metrics.json").read_text())
    fused = m["position_m"]["horizontal"]["rmse"]
    raw = m["gnss_position_m"]["horizontal"]["rmse"]
    assert 0.0 < fused < raw, (fused, raw)


def test_process_reference_option_overrides(log_copy: Path, tmp_path: Path) -> None:
    ref = tmp_path / "truth-elsewhere.csv"
    shutil.copyfile(log_copy / "reference.csv", ref)
    (log_copy / "reference.csv").unlink()
    out = tmp_path / "out"
    res = invoke("process", log_copy, "--reference", ref, "--out", out, "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    m = json.loads((out / "metrics.json").read_text())
    assert m["reference"] == str(ref)
    assert m["position_m"]["horizontal"]["rmse"] < m["gnss_position_m"]["horizontal"]["rmse"]


def test_process_without_reference_writes_trajectory_only(log_copy: Path, tmp_path: Path) -> None:
    (log_copy / "reference.csv").unlink()
    out = tmp_path / "out"
    res = invoke("process", log_copy, "--out", out)
    assert res.exit_code == 0, (res.output, res.exception)
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == ["diagnostics.csv", "trajectory.csv"]
    assert "position error" not in res.stdout
    assert "trajectory.csv" in flat(res.stdout)


def test_process_output_rate(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = invoke("process", sim_log_dir, "--out", out, "--output-rate", "10", "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    traj = out / "trajectory.csv"
    lines = read_lines(traj)
    assert lines[0] == TRAJECTORY_HEADER
    t_text = [line.split(",", 1)[0] for line in lines[1:]]
    # t on whole multiples of 0.1 s (6 decimals written: the last five are zero)
    assert all(s.split(".")[1][1:] == "00000" for s in t_text), t_text[:5]
    t = np.array([float(s) for s in t_text])
    np.testing.assert_allclose(np.diff(t), 0.1, atol=1e-6)
    span = t[-1] - t[0]
    assert span > 115.0
    assert abs(len(t) / span - 10.0) < 0.1


def test_process_quiet_prints_nothing_on_stdout(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = invoke("process", sim_log_dir, "--out", out, "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    assert res.stdout == ""
    assert (out / "trajectory.csv").is_file()


def test_process_duplicate_imu_stamps_warned(log_copy: Path, tmp_path: Path) -> None:
    imu = log_copy / "imu.csv"
    lines = read_lines(imu)
    lines.insert(300, lines[299])          # file line 300 repeated as line 301
    lines.insert(500, lines[499])
    write_lines(imu, lines)
    out = tmp_path / "out"
    res = invoke("process", log_copy, "--out", out)
    assert res.exit_code == 0, (res.output, res.exception)
    assert "imu.csv: dropped 2 duplicate timestamps (first at line 301)" in flat(res.stderr)
    assert (out / "trajectory.csv").is_file()


def test_process_gyro_in_deg_per_s_is_refused_naming_the_setting(log_copy: Path, tmp_path: Path) -> None:
    imu = log_copy / "imu.csv"
    lines = read_lines(imu)
    rows = []
    for line in lines[1:]:
        f = line.split(",")
        f[1:4] = [repr(float(v) * 180.0 / np.pi) for v in f[1:4]]
        rows.append(",".join(f))
    write_lines(imu, [lines[0], *rows])
    res = invoke("process", log_copy, "--out", tmp_path / "out", "--quiet")
    msg = assert_one_line_error(res, tmp_path / "out")
    # the GNSS track turns 1/57 as much as the gyro says: refused before any filtering
    assert "gnss track turns 0.0" in msg.lower() and 'gyro_units = "deg/s"' in msg


def test_process_warnings_are_printed_even_when_quiet(log_copy: Path, tmp_path: Path) -> None:
    imu = log_copy / "imu.csv"
    lines = read_lines(imu)
    lines.insert(300, lines[299])
    write_lines(imu, lines)
    res = invoke("process", log_copy, "--out", tmp_path / "out", "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    assert "duplicate timestamp" in flat(res.stderr)
    assert res.stdout.strip() == ""


def test_process_reference_on_another_time_base_is_warned(log_copy: Path, tmp_path: Path) -> None:
    ref = log_copy / "reference.csv"
    lines = read_lines(ref)
    shifted = [lines[0]] + [",".join([f"{float(line.split(',')[0]) + 18.0:.6f}", *line.split(",")[1:]])
                            for line in lines[1:]]
    write_lines(ref, shifted)                   # 18 s: GPS time vs UTC
    res = invoke("process", log_copy, "--out", tmp_path / "out")
    assert res.exit_code == 0, (res.output, res.exception)
    assert "another time base or datum" in flat(res.stderr)


def test_process_rerun_without_reference_leaves_no_stale_metrics(log_copy: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = invoke("process", log_copy, "--out", out, "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == [
        "diagnostics.csv", "metrics.json", "metrics.md", "trajectory.csv"]
    first = (out / "trajectory.csv").read_bytes()
    (log_copy / "reference.csv").unlink()
    res = invoke("process", log_copy, "--out", out, "--output-rate", "10")
    assert res.exit_code == 0, (res.output, res.exception)
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == ["diagnostics.csv", "trajectory.csv"]
    assert (out / "trajectory.csv").read_bytes() != first
    assert res.stdout.splitlines()[-1] == f"wrote {out / 'trajectory.csv'}, {out / 'diagnostics.csv'}"


def test_process_out_is_an_existing_file(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "results"
    out.write_text("keep me\n")
    res = invoke("process", sim_log_dir, "--out", out)
    msg = assert_one_line_error(res, tmp_path / "nothing-here")
    assert msg == f"navpp: error: --out {out}: cannot write there (it is a file, not a directory)"
    assert out.read_text() == "keep me\n"


def test_process_out_below_a_file(sim_log_dir: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "results"
    blocker.write_text("x")
    out = blocker / "sub"
    msg = assert_one_line_error(invoke("process", sim_log_dir, "--out", out), out)
    assert msg == f"navpp: error: --out {out}: cannot write there ({blocker} is a file, not a directory)"


def test_process_out_checked_before_reading(log_copy: Path, tmp_path: Path) -> None:
    """A broken log and an unwritable --out: the --out problem is reported (nothing was read)."""
    (log_copy / "imu.csv").write_text("garbage\n")
    blocker = tmp_path / "results"
    blocker.write_text("x")
    msg = assert_one_line_error(invoke("process", log_copy, "--out", blocker), tmp_path / "nothing-here")
    assert f"--out {blocker}: cannot write there" in msg


@pytest.mark.parametrize("rate", ["nan", "inf", "-inf", "-1", "0"])
def test_process_output_rate_usage_error(sim_log_dir: Path, tmp_path: Path, rate: str) -> None:
    out = tmp_path / "out"
    res = invoke("process", sim_log_dir, "--out", out, "--output-rate", rate)
    assert res.exit_code == 2, (res.output, res.exception)
    assert "Traceback" not in res.output and res.stdout == ""
    (line,) = [line for line in res.stderr.splitlines() if line.startswith("Error:")]
    assert line == f"Error: Invalid value for '--output-rate': must be a finite number of Hz > 0, got {rate}"
    assert not out.exists()


def test_process_output_rate_above_imu_rate(sim_log_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", sim_log_dir, "--out", out, "--output-rate", "500"), out)
    assert msg == (f"navpp: error: --output-rate 500 Hz is above the IMU rate of {sim_log_dir} (125.0 Hz); "
                   "the trajectory cannot be finer than the IMU")
    assert not out.exists()


def test_process_help_shows_defaults() -> None:
    res = runner.invoke(app, ["process", "--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    text = flat(res.stdout)
    assert "Output directory, created if needed. [default: navpp-out/<log>-<filter>]" in text
    assert "Trajectory rate in Hz, at most the IMU rate. [default: every IMU sample]" in text
    assert "[default: ekf]" in text
    for option in ("--filter", "--config", "--reference", "--out", "--output-rate", "--quiet"):
        assert option in text


def test_simulate_help_shows_defaults() -> None:
    res = runner.invoke(app, ["simulate", "--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    text = flat(res.stdout)
    for expected in ("--duration <float> Drive length, s, >= 30 (includes the initial still period). [default: 900.0]",
                     "--seed <int> Random seed (same seed, same log). [default: 0]",
                     "'x,y,z'. [default: 0,0,0]", "[default: 60.0]", "[default: automotive]"):
        assert expected in text, expected


# --------------------------------------------------------------------------------- summary notes


@pytest.fixture(scope="module")
def computed(sim_log_dir: Path):
    from navpp import api

    return api.process(sim_log_dir, write=False)


class _Run:
    """The engine's RunResult, with ``compile_s`` set to a given value or absent (as before the
    engine had the field)."""

    def __init__(self, run, compile_s: float | None) -> None:
        self._run, self._compile_s = run, compile_s

    def __getattr__(self, name: str):
        if name == "compile_s":
            if self._compile_s is None:
                raise AttributeError(name)
            return self._compile_s
        return getattr(self._run, name)


@pytest.mark.parametrize("compile_s, quiet, shown", [(2.34, False, True), (0.4, False, False), (0.0, False, False),
                                                     (None, False, False), (2.34, True, False)])
def test_summary_compile_note(computed, capsys, compile_s, quiet, shown) -> None:
    import dataclasses

    from navpp import cli_print

    res = dataclasses.replace(computed, run=_Run(computed.run, compile_s))
    assert hasattr(res.run, "compile_s") is (compile_s is not None)
    cli_print.print_process_summary(res, quiet)
    captured = capsys.readouterr()
    err = flat(captured.err)
    assert ("· compiled navpp's kernels in 2.3 s (first run only; cached for next time)" in err) is shown
    assert ("compiled navpp's kernels" in err) is shown
    assert "compiled" not in captured.out
    if not quiet:
        assert all(flat(line) in err for line in computed.notes)   # printed with the other notes


# --------------------------------------------------------------------------------- filters, simulate


def test_filters_lists_ekf_with_paper() -> None:
    res = invoke("filters")
    assert res.exit_code == 0, res.output
    (line,) = [line for line in res.stdout.splitlines() if line.startswith("ekf ")]
    assert "paper 002" in line
    assert "Kalman" in line


def test_simulate_writes_log_and_is_reproducible(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    for d in (a, b):
        res = invoke("simulate", d, "--duration", "40", "--seed", "1")
        assert res.exit_code == 0, (res.output, res.exception)
        assert "wrote" in res.stdout and str(d) in res.stdout
        assert sorted(p.name for p in d.iterdir()) == ["gnss.csv", "imu.csv", "navpp.toml", "reference.csv"]
    assert (a / "imu.csv").read_bytes() == (b / "imu.csv").read_bytes()
    assert (a / "gnss.csv").read_bytes() == (b / "gnss.csv").read_bytes()
    assert len(read_lines(a / "imu.csv")) == 1 + 40 * 125 + 1


@pytest.mark.parametrize("lever", ["1,2", "a,b,c", "1,2,nan"])
def test_simulate_bad_lever_arm(tmp_path: Path, lever: str) -> None:
    out = tmp_path / "sim"
    res = invoke("simulate", out, "--duration", "40", "--lever-arm", lever)
    assert res.exit_code == 2
    assert "Traceback" not in res.output
    assert (f"Error: Invalid value for '--lever-arm': needs three finite numbers 'x,y,z' (m), got {lever!r}"
            in res.stderr.splitlines())
    assert not out.exists()


@pytest.mark.parametrize("option, value, requirement", [
    ("--seed", "-1", "a non-negative integer"),
    ("--duration", "20", "a finite number of seconds >= 30"),
    ("--duration", "inf", "a finite number of seconds >= 30"),
    ("--duration", "nan", "a finite number of seconds >= 30"),
    ("--imu-rate", "0", "a finite number of Hz > 0"),
    ("--imu-rate", "inf", "a finite number of Hz > 0"),
    ("--gnss-rate", "20", "a number of Hz within 1-10"),
    ("--preset", "'cheap'", "one of consumer, automotive, tactical, navigation, ideal"),
    ("--gnss-std-h", "-1", "a finite number of metres >= 0"),
    ("--gnss-std-u", "nan", "a finite number of metres >= 0"),
    ("--gnss-error", "'pink'", "'white' or 'correlated'"),
    ("--still", "-5", "a finite number of seconds >= 0"),
])
def test_simulate_bad_option_names_it(tmp_path: Path, option: str, value: str, requirement: str) -> None:
    out = tmp_path / "sim"
    res = invoke("simulate", out, option, value.strip("'"))
    assert res.exit_code == 2, (res.output, res.exception)
    assert "Traceback" not in res.output and res.stdout == ""
    assert f"Error: Invalid value for '{option}': must be {requirement}, got {value}" in res.stderr.splitlines()
    assert not out.exists()


def test_simulate_still_period_shortened_note(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    res = invoke("simulate", out, "--duration", "40", "--still", "100", "--imu-rate", "10")
    assert res.exit_code == 0, (res.output, res.exception)
    assert flat(res.stderr) == "· still period shortened to 20 s: --still 100 s is more than half of --duration 40 s"
    # oracle: the reference truth stands still for exactly the first 20 s, then moves
    lines = read_lines(out / "reference.csv")
    t = column(out / "reference.csv", "t")
    speed = np.hypot(column(out / "reference.csv", "ve"), column(out / "reference.csv", "vn"))
    t -= t[0]
    assert len(lines) == len(t) + 1
    assert np.all(speed[t <= 20.0] == 0.0)
    assert np.all(speed[(t > 20.5)] > 0.0)
    assert "(still 20 s first)" in (out / "navpp.toml").read_text()


def test_simulate_no_note_when_still_fits(tmp_path: Path) -> None:
    res = invoke("simulate", tmp_path / "sim", "--duration", "40", "--still", "20", "--imu-rate", "10")
    assert res.exit_code == 0, (res.output, res.exception)
    assert res.stderr == ""


# --------------------------------------------------------------------------------- bad input


def test_missing_imu_csv(log_copy: Path, tmp_path: Path) -> None:
    (log_copy / "imu.csv").unlink()
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(log_copy / "imu.csv") in msg and "not found" in msg


def test_gnss_missing_column(log_copy: Path, tmp_path: Path) -> None:
    gnss = log_copy / "gnss.csv"
    lines = read_lines(gnss)
    j = lines[0].split(",").index("alt")
    write_lines(gnss, [",".join(f for i, f in enumerate(line.split(",")) if i != j) for line in lines])
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(gnss) in msg and "'alt'" in msg and "line 1" in msg


def test_imu_non_numeric_value(log_copy: Path, tmp_path: Path) -> None:
    imu = log_copy / "imu.csv"
    set_cell(imu, 101, "gz", "abc")
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(imu) in msg and "line 101" in msg and "'gz'" in msg and "'abc'" in msg


def test_gnss_nan(log_copy: Path, tmp_path: Path) -> None:
    gnss = log_copy / "gnss.csv"
    set_cell(gnss, 51, "lat", "NaN")
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(gnss) in msg and "line 51" in msg and "'lat'" in msg


def test_imu_time_goes_backwards(log_copy: Path, tmp_path: Path) -> None:
    imu = log_copy / "imu.csv"
    lines = read_lines(imu)
    lines[200], lines[201] = lines[201], lines[200]       # file lines 201 and 202 swapped
    write_lines(imu, lines)
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(imu) in msg and "line 202" in msg and "backwards" in msg and "line 201" in msg


def test_config_unknown_key(log_copy: Path, tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[imu]\npreset = "automotive"\ngyro_arw_deg_per_sqrt = 1.0\n')
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--config", cfg, "--out", out), out)
    assert str(cfg) in msg and "'gyro_arw_deg_per_sqrt'" in msg
    assert "[imu]" in msg and "did you mean 'gyro_arw_deg_per_sqrt_h'" in msg


def test_unknown_filter_lists_filters(sim_log_dir: Path, tmp_path: Path) -> None:
    from navpp.filters import FILTERS

    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", sim_log_dir, "--filter", "ekff", "--out", out), out)
    assert "'ekff'" in msg
    assert all(name in msg for name in FILTERS)


def test_log_does_not_exist(tmp_path: Path) -> None:
    log, out = tmp_path / "no-such-log", tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log, "--out", out), out)
    assert str(log) in msg and "no such file or directory" in msg


def test_directory_is_not_a_log(tmp_path: Path) -> None:
    log, out = tmp_path / "empty", tmp_path / "out"
    log.mkdir()
    msg = assert_one_line_error(invoke("process", log, "--out", out), out)
    assert str(log) in msg and "imu.csv" in msg and "gnss.csv" in msg


def test_not_a_log_file(tmp_path: Path) -> None:
    log, out = tmp_path / "drive.txt", tmp_path / "out"
    log.write_text("t,gx\n0,0\n")
    msg = assert_one_line_error(invoke("process", log, "--out", out), out)
    assert str(log) in msg and "not a log navpp reads" in msg


def test_empty_file(tmp_path: Path) -> None:
    log, out = tmp_path / "drive.mcap", tmp_path / "out"
    log.write_bytes(b"")
    msg = assert_one_line_error(invoke("process", log, "--out", out), out)
    assert str(log) in msg and "empty file" in msg


def test_gnss_outside_imu_span(log_copy: Path, tmp_path: Path) -> None:
    gnss = log_copy / "gnss.csv"
    lines = read_lines(gnss)
    shifted = [lines[0]]
    for line in lines[1:]:
        t, rest = line.split(",", 1)
        shifted.append(f"{float(t) + 1000.0:.6f},{rest}")
    write_lines(gnss, shifted)
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(gnss) in msg and "'t'" in msg and "outside the IMU time span" in msg
    assert "1700001000.0" in msg and "1700000000.0" in msg       # both spans, as written


def test_no_still_period_and_gnss_never_moves(log_copy: Path, tmp_path: Path) -> None:
    """Starting in motion, heading must come from the GNSS track; a frozen track cannot give it."""
    imu, gnss = log_copy / "imu.csv", log_copy / "gnss.csv"
    lines = read_lines(imu)
    t0 = float(lines[1].split(",", 1)[0])
    write_lines(imu, [lines[0]] + [line for line in lines[1:] if float(line.split(",", 1)[0]) >= t0 + 40.0])
    lines = read_lines(gnss)
    first = lines[1].split(",")
    frozen = [lines[0]]
    for line in lines[1:]:
        f = line.split(",")
        f[1:4] = first[1:4]                                  # lat, lon, alt never change
        frozen.append(",".join(f))
    write_lines(gnss, frozen)
    (log_copy / "reference.csv").unlink()
    out = tmp_path / "out"
    msg = assert_one_line_error(invoke("process", log_copy, "--out", out), out)
    assert str(log_copy) in msg
    assert "cannot find the heading" in msg and "[init] heading_deg" in msg


# --------------------------------------------------------------------------------- console script


def test_console_script_help() -> None:
    exe = Path(sys.executable).parent / "navpp"
    assert exe.is_file(), f"console script not installed at {exe}"
    env = dict(os.environ, COLUMNS="120")
    proc = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 0, proc.stderr
    for command in ("process", "simulate", "filters"):
        assert command in proc.stdout
    assert "Traceback" not in proc.stderr


def test_inspect_csv_log(sim_log_dir: Path) -> None:
    res = invoke("inspect", sim_log_dir)
    assert res.exit_code == 0, (res.output, res.exception)
    text = res.stdout
    for name, role, count in (("imu.csv", "IMU", "15001"), ("gnss.csv", "GNSS", "601"),
                              ("reference.csv", "reference", "1201")):
        line = next(line for line in text.splitlines() if name in line)
        assert role in line and count in line, line
    assert "125.0" in text


def test_inspect_not_a_log(tmp_path: Path) -> None:
    f = tmp_path / "x.bin"
    f.write_bytes(b"\x00\x01garbage")
    res = invoke("inspect", f)
    assert res.exit_code == 1 and "not a log navpp reads" in flat(res.stderr)


def _write_pos_gpst(path: Path, gnss_csv: Path) -> None:
    """The fixes of a CSV log as an RTKLIB .pos in GPST (unix + 18 s since 2017)."""
    import datetime as dt

    lines = read_lines(gnss_csv)
    cols = lines[0].split(",")
    out = ["% program   : RTKPOST ver.2.4.3 b34",
           "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
           "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
           "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio"]
    for line in lines[1:]:
        v = dict(zip(cols, line.split(","), strict=True))
        t = dt.datetime(1970, 1, 1) + dt.timedelta(seconds=float(v["t"]) + 18.0)
        stamp = t.strftime("%Y/%m/%d %H:%M:%S.") + f"{t.microsecond // 1000:03d}"
        out.append(f"{stamp} {float(v['lat']):14.9f} {float(v['lon']):14.9f} {float(v['alt']):10.4f}   5  10 "
                   f"{float(v['std_n']):8.4f} {float(v['std_e']):8.4f} {float(v['std_u']):8.4f}   0.0000   0.0000"
                   "   0.0000   0.00    0.0")
    path.write_text("\n".join(out) + "\n")


def test_process_with_rtklib_gnss_matches_the_csv_gnss(log_copy: Path, tmp_path: Path) -> None:
    pos = tmp_path / "rover.pos"
    _write_pos_gpst(pos, log_copy / "gnss.csv")
    base = invoke("process", log_copy, "--out", tmp_path / "a", "--quiet")
    assert base.exit_code == 0, (base.output, base.exception)
    (log_copy / "gnss.csv").write_text((log_copy / "gnss.csv").read_text().replace("1.8,1.8,2.5", "9.0,9.0,9.0"))
    res = invoke("process", log_copy, "--gnss", pos, "--out", tmp_path / "b", "--quiet")
    assert res.exit_code == 0, (res.output, res.exception)
    a = json.loads((tmp_path / "a" / "metrics.json").read_text())["position_m"]["horizontal"]["rmse"]
    b = json.loads((tmp_path / "b" / "metrics.json").read_text())["position_m"]["horizontal"]["rmse"]
    assert b == pytest.approx(a, abs=0.02)


def test_split_ros1_recording_as_a_directory(sim_log_dir: Path, tmp_path: Path) -> None:
    from navpp.io.csv import read_csv_log
    from navpp.io.roswrite import write_ros1_bag, write_ros2_bag

    rec = read_csv_log(sim_log_dir)
    split = tmp_path / "split"
    split.mkdir()
    write_ros1_bag(rec, split / "drive_0.bag", time_range=(0.0, 60.0))
    write_ros1_bag(rec, split / "drive_1.bag", time_range=(60.0, 1e9))
    whole = tmp_path / "whole"
    write_ros2_bag(rec, whole)
    cfg = sim_log_dir / "navpp.toml"
    a = invoke("process", split, "--config", cfg, "--out", tmp_path / "a", "-q")
    b = invoke("process", whole, "--config", cfg, "--out", tmp_path / "b", "-q")
    assert a.exit_code == 0 and b.exit_code == 0, (a.output, b.output)
    assert (tmp_path / "a" / "trajectory.csv").read_bytes() == (tmp_path / "b" / "trajectory.csv").read_bytes()


def test_the_bundled_real_walk_processes_and_prints_its_raw_fix_row(tmp_path: Path):
    """The README's real log end to end through the command line: the summary once indexed a
    raw-GNSS row the metrics may lack and crashed after writing (exit 1 with a traceback)."""
    walk = Path(__file__).resolve().parent.parent / "sample_data" / "walk_0827"
    res = invoke("process", walk, "--out", tmp_path / "out")
    assert res.exit_code == 0, res.output
    assert "raw GNSS horiz." in res.stdout
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["gnss_position_m"]["epochs"] > 0 and "horizontal" in m["gnss_position_m"]


def test_metrics_interpolate_across_holes_unless_asked_not_to():
    from navpp.metrics import associate

    t_est = np.r_[np.arange(0.0, 10.0, 0.1), np.arange(60.0, 70.0, 0.1)]     # a 50 s hole
    t_ref = np.array([5.0, 30.0, 65.0])
    assert associate(t_est, t_ref).idx_ref.tolist() == [0, 1, 2]
    assert associate(t_est, t_ref, skip_holes=True).idx_ref.tolist() == [0, 2]
