"""Bad inputs, round two (issue 15): parsing and the messages that misled (points 3, 9, 12).

The table holds the inputs that must be refused (exit 1, one ``navpp:`` line naming the file and
line or topic, nothing written, inputs untouched, bounded time and memory: tests/badinputs.py).
The plain tests below cover what is now accepted: stamps in e-notation (and '+', 'E', blanks)
give byte-identical results to the plain form (the oracle), a later row with more decimals is
read exactly, exact duplicate rows are named as such, and ``compare`` names the log in warnings.
"""

from __future__ import annotations

import json
import shutil
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from badinputs import DRIVE, Case, copy_drive, edit_csv, params, run_case, run_in_process

IMU_ROWS = 37501       # data rows of sample_data/drive/imu.csv (header = line 1)


def _process(log: Path, work: Path) -> list[str]:
    return ["process", str(log), "--out", str(work / "out")]


# --------------------------------------------------------------------------- point 9: NULs, long lines


def _nul_tail(size: int):
    def build(work: Path) -> list[str]:
        log = copy_drive(work)
        imu = log / "imu.csv"
        with open(imu, "r+b") as f:          # sparse: a 2 GB tail of NULs costs no disk
            f.truncate(imu.stat().st_size + size)
        return _process(log, work)
    return build


def _long_cell(work: Path) -> list[str]:
    log = copy_drive(work)
    edit_csv(log / "imu.csv", lambda ls: ls[:100] + [ls[100].replace(",", "," + "9" * (50 << 20), 1)] + ls[101:])
    return _process(log, work)


def _long_header(work: Path) -> list[str]:
    log = copy_drive(work)
    edit_csv(log / "gnss.csv", lambda ls: [ls[0] + ",note" + "x" * (3 << 20)] + ls[1:])
    return _process(log, work)


def _big_text_cell(work: Path) -> list[str]:
    """500 kB of text in a numeric column (line 10, gx): under the line limit, so the parser meets
    it; the message echoes ~60 characters of it."""
    def edit(lines):
        cells = lines[9].split(",")
        cells[1] = "abc" + "z" * 500_000
        return lines[:9] + [",".join(cells)] + lines[10:]
    log = copy_drive(work)
    edit_csv(log / "imu.csv", edit)
    return _process(log, work)


# --------------------------------------------------------------------------- point 3: stamps


def _bad_e_stamp(work: Path) -> list[str]:
    log = copy_drive(work)
    edit_csv(log / "gnss.csv", lambda ls: ls[:5] + ["1.7000000008e+09x" + ls[5][ls[5].index(","):]] + ls[6:])
    return _process(log, work)


# --------------------------------------------------------------------------- point 12: messages


def _separator(name: str, sep: str):
    def build(work: Path) -> list[str]:
        log = copy_drive(work)
        edit_csv(log / name, lambda ls: [x.replace(",", sep) for x in ls])
        return _process(log, work)
    return build


def _zero_header_stamps(work: Path) -> list[str]:
    """An MCAP whose IMU and GNSS header stamps are all 0 (record times correct)."""
    from navpp.io import roswrite
    from navpp.io.csv import read_csv_log

    rec = read_csv_log(DRIVE)
    saved = {name: getattr(roswrite, name) for name in ("encode_imu", "encode_navsatfix")}
    try:
        for name, orig in saved.items():
            setattr(roswrite, name, lambda st, *a, _o=orig, **k: _o(np.zeros_like(st), *a, **k))
        roswrite.write_mcap_ros2(rec, work / "zero.mcap")
    finally:
        for name, orig in saved.items():
            setattr(roswrite, name, orig)
    return _process(work / "zero.mcap", work)


def _truncated_bag_mcap(work: Path) -> list[str]:
    from navpp.io import roswrite
    from navpp.io.csv import read_csv_log

    roswrite.write_ros2_bag(read_csv_log(DRIVE), work / "bag", storage="mcap")
    (storage,) = (work / "bag").glob("*.mcap")
    with open(storage, "r+b") as f:
        f.truncate(storage.stat().st_size // 2)
    return _process(work / "bag", work)


def _outage_past_end(work: Path) -> list[str]:
    return _process(copy_drive(work), work) + ["--gnss-outage", "290:60"]


def _outage_after_end(work: Path) -> list[str]:
    return _process(copy_drive(work), work) + ["--gnss-outage", "310:5"]


def _compare_option_typo(work: Path) -> list[str]:
    return ["compare", str(copy_drive(work)), "--filters", "ekf,rwckf[candidtes=4]", "--out", str(work / "out")]


CASES = [
    Case("imu-nul-tail-2gb", _nul_tail(2 << 30), ("imu.csv", f"line {IMU_ROWS + 2}", "NUL byte"), slow=True,
         process=True),
    Case("imu-nul-tail-200mb", _nul_tail(200 << 20), ("imu.csv", f"line {IMU_ROWS + 2}", "NUL byte"), process=True),
    Case("imu-50mb-cell", _long_cell, ("imu.csv", "line 101", "longer than 1 MiB"), process=True),
    Case("gnss-3mb-header", _long_header, ("gnss.csv", "line 1:", "longer than 1 MiB")),
    Case("imu-500kb-text-cell", _big_text_cell, ("imu.csv", "line 10", "non-numeric value 'abczzz", "characters)")),
    Case("gnss-bad-e-stamp", _bad_e_stamp, ("gnss.csv", "line 6", "column 't'", "1.7000000008e+09x")),
    Case("gnss-semicolons", _separator("gnss.csv", ";"), ("gnss.csv", "line 1", "semicolons")),
    Case("imu-tabs", _separator("imu.csv", "\t"), ("imu.csv", "line 1", "tabs")),
    Case("mcap-zero-header-stamps", _zero_header_stamps,
         ("zero.mcap", "'/imu/data'", "header stamps are 0", '[time] source = "log"')),
    Case("ros2-bag-truncated-mcap", _truncated_bag_mcap, ("bag.mcap", "truncated")),
    Case("outage-past-the-end", _outage_past_end, ("290:60", "runs past the end", "300.000 s", "290:10")),
    Case("outage-after-the-end", _outage_after_end, ("310:5", "starts after the log ends"), slow=True),
    Case("compare-filter-option-typo", _compare_option_typo, ("'candidtes'", "valid keys", "candidates")),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


# --------------------------------------------------------------------------- accepted forms of t


def _rewrite_t(log: Path, form) -> None:
    """Rewrite the ``t`` cell of every data row of the log's three CSV files with ``form(text)``."""
    for name in ("imu.csv", "gnss.csv", "reference.csv"):
        def edit(lines, form=form):
            out = [lines[0]]
            for line in lines[1:]:
                t, _, rest = line.partition(",")
                out.append(f"{form(t)},{rest}")
            return out
        edit_csv(log / name, edit)


def _e_notation(cell: str) -> str:
    """Same digits, numpy-style e-notation: '1700000000.008000' -> '1.700000000008e+09'."""
    d = Decimal(cell).normalize()
    text = f"{d:e}"
    mantissa, exp = text.split("e")
    return f"{mantissa}e{int(exp):+03d}"


FORMS = {
    "e-notation": _e_notation,
    "capital-E-plus-sign-blanks": lambda c: f" +{_e_notation(c).upper()}  ",
    "plus-sign-trailing-blanks": lambda c: f"+{c}   ",
}


def _outputs(work: Path, log: Path) -> dict[str, object]:
    out = work / "out"
    code, _, stderr, _ = run_in_process(["process", str(log), "--out", str(out)], work)
    assert code == 0, stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("log", "reference", "runtime_s"):      # the path and the wall time differ, nothing else
        metrics.pop(key, None)
    return {"trajectory.csv": (out / "trajectory.csv").read_bytes(),
            "diagnostics.csv": (out / "diagnostics.csv").read_bytes(), "metrics": metrics,
            "warnings": [ln.replace(str(log), "LOG") for ln in stderr.splitlines() if ln.startswith("warning:")]}


@pytest.fixture(scope="module")
def plain_outputs(tmp_path_factory):
    work = tmp_path_factory.mktemp("plain")
    return _outputs(work, copy_drive(work))


@pytest.mark.parametrize("form", [pytest.param(f, marks=[] if f == "e-notation" else [pytest.mark.slow])
                                  for f in FORMS], ids=list(FORMS))
def test_stamp_forms_give_the_plain_results(form, plain_outputs, tmp_path):
    """Oracle: the same log with t written plainly; the results must be byte-identical (the
    e-notation log gave 4.25 m instead of 0.60 m: its stamps were rounded to whole seconds)."""
    log = copy_drive(tmp_path)
    _rewrite_t(log, FORMS[form])
    first = (log / "imu.csv").read_text().splitlines()[2]
    assert first.split(",")[0] != "1700000000.008000", "the form was not applied"
    got = _outputs(tmp_path, log)
    assert got == plain_outputs


def test_a_later_row_with_more_decimals_is_read_exactly(tmp_path):
    """The decimals are counted over the first 2000 rows (fast path); a later row with more of
    them must not be rounded to 3 decimals (the residual check sends it to the exact path)."""
    from navpp.io.csv import read_reference_csv

    t0 = 1_700_000_000
    rows = [f"{t0 + k * 0.1:.3f},45,7,300" for k in range(2500)]
    rows.append(f"{t0 + 250}.0000125,45,7,300")
    rows.append("1.7000002515e9,45,7,300")
    (tmp_path / "r.csv").write_text("t,lat,lon,alt\n" + "\n".join(rows) + "\n")
    ref = read_reference_csv(tmp_path / "r.csv", t0 * 10**9)
    assert ref.t[2500] == pytest.approx(250.0000125, abs=1e-9)     # rounded to 3 decimals: 250.000
    assert ref.t[2501] == pytest.approx(251.5, abs=1e-12)
    assert ref.t[2499] == pytest.approx(249.9, abs=1e-12)


def test_duplicate_rows_are_named_not_called_coarse_stamps(tmp_path):
    """Every IMU row written twice: a warning naming exact duplicate rows (lines 3 = 2), not
    'stamps too coarse'; the recording is the plain one."""
    from navpp.io.csv import read_csv_log

    log = copy_drive(tmp_path)
    edit_csv(log / "imu.csv", lambda ls: ls[:1] + [x for line in ls[1:] for x in (line, line)])
    rec = read_csv_log(log)
    (w,) = [w for w in rec.warnings if w.startswith("imu.csv")]
    assert f"dropped {IMU_ROWS} duplicate timestamps (first at line 3); all are exact duplicate rows" in w
    assert "line 3 = line 2" in w and "coarse" not in w
    plain = read_csv_log(DRIVE)
    np.testing.assert_array_equal(rec.imu.t, plain.imu.t)
    np.testing.assert_array_equal(rec.imu.gyro, plain.imu.gyro)


def test_compare_warnings_name_the_log(sim_log_dir, tmp_path):
    """Two logs with the same file names (copies of the 120-s session log): each warning says
    which log it is about."""
    logs = [Path(shutil.copytree(sim_log_dir, tmp_path / name)) for name in ("a", "b")]
    edit_csv(logs[1] / "imu.csv", lambda ls: [ls[0] + ",temp"] + [line + ",21.5" for line in ls[1:]])
    argv = ["compare", *map(str, logs), "--filters", "ekf", "--out", str(tmp_path / "out")]
    code, _, stderr, _ = run_in_process(argv, tmp_path)
    assert code == 0, stderr[-2000:]
    warnings = [ln for ln in stderr.splitlines() if "ignoring extra column" in ln]
    assert warnings == [f"warning: {logs[1] / 'imu.csv'}: ignoring extra column(s) 'temp'"], stderr[-2000:]
