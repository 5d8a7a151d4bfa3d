"""benchmarks/docstring_audit.py: the share of documentation lines per module and the history /
figure wording it flags, on sources whose counts are known by construction."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

SOURCE = '''"""A module docstring.

It tried X and that was not enough.
"""
import math  # a comment on a code line

X = 1.0
"""An attribute docstring: X is 2.8x faster than before."""


def f(x: float) -> float:
    # the angle, rad
    return math.sin(x)
'''


@pytest.fixture(scope="module")
def audit():
    spec = importlib.util.spec_from_file_location("navpp_docstring_audit", REPO / "benchmarks" / "docstring_audit.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod                  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def test_counts_docstring_and_comment_lines(audit) -> None:
    a = audit.audit_source(Path("m.py"), SOURCE)
    # non-blank lines: 3 of the module docstring, import, X, attribute docstring, def, comment, return
    assert a.lines == 9
    # documentation: the module docstring's 3, the import's comment, the attribute docstring, the comment
    assert a.doc_lines == 6
    assert a.share == pytest.approx(100.0 * 6 / 9)


def test_flags_history_and_figures_not_descriptions(audit) -> None:
    a = audit.audit_source(Path("m.py"), SOURCE)
    kinds = {(no, kind) for no, kind, _ in a.flags}
    assert kinds == {(3, "history: tried"), (3, "history: not enough"),
                     (8, "history: instead of before"), (8, "figure: speed ratio")}
    for text in ("the candidates are tried in order", "the value is used to scale the noise",
                 "rates measured on the rows that are not repeats", "a pull-away (0 -> 12 m/s in 10 s)"):
        assert audit.flags_in(text) == [], text
    for text, kind in (("we found that it diverges", "history: we found"),
                       ("before issue 14 the gate used the posterior", "history: before issue"),
                       ("add_message costs ~2.5 us per message", "figure: timing"),
                       ("it previously read the whole file", "history: previously")):
        assert kind in audit.flags_in(text), text


def test_report_lists_modules_total_and_flags(audit, tmp_path: Path, capsys) -> None:
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "a.py").write_text(SOURCE)
    (tmp_path / "pkg" / "b.py").write_text("x = 1\n")
    assert audit.main([str(tmp_path / "pkg"), "--flags"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split()[1:] for line in out[1:4]}
    assert rows[str(tmp_path / "pkg" / "a.py")] == ["9", "6", "66.7", "4"]
    assert rows[str(tmp_path / "pkg" / "b.py")] == ["1", "0", "0.0", "0"]
    assert rows["total"] == ["10", "6", "60.0", "4"]
    assert sum(": [history:" in line or ": [figure:" in line for line in out) == 4
