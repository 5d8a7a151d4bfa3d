"""Bad inputs, round two (issue 15): each row is one input a new user tried, with the exit code
and a fragment of the one-line message; nothing written, inputs untouched (tests/badinputs.py).
Rows by area live in ``tests/test_bad_inputs_*.py``; this file checks the harness itself."""

from __future__ import annotations

import pytest
from badinputs import Case, copy_drive, edit_csv, params, run_case


def _missing_gnss_column(work):
    log = copy_drive(work)
    edit_csv(log / "gnss.csv", lambda ls: [",".join(x.split(",")[:3]) for x in ls])
    return ["process", str(log), "--out", str(work / "out")]


def _out_with_old_results(work):
    log = copy_drive(work)
    edit_csv(log / "gnss.csv", lambda ls: [",".join(x.split(",")[:3]) for x in ls])
    out = work / "out"
    out.mkdir()
    (out / "trajectory.csv").write_text("t,lat,lon\n1,2,3\n")
    return ["process", str(log), "--out", str(out)]


CASES = [
    Case("missing-gnss-column", _missing_gnss_column, ("gnss.csv", "alt")),
    Case("previous-results-survive", _out_with_old_results, "gnss.csv"),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)


def test_the_harness_catches_a_touched_input(tmp_path):
    """The oracle can fail: a case whose build step lies about the code is caught."""
    with pytest.raises(AssertionError):
        run_case(Case("wrong-code", _missing_gnss_column, "gnss.csv", code=0), tmp_path)
