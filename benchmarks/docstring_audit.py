"""Audit of navpp's docstrings and comments: per module, the share of lines that are documentation,
and the lines whose wording reads as history or as a measured figure that goes stale.

Usage (from anywhere; the repository is this file's parent's parent)::

    python benchmarks/docstring_audit.py [PATH ...] [--flags] [--min-share PCT]

``PATH`` is a file or directory (default: ``navpp``, relative to the repository); every ``*.py``
under it is read.  Per module the table gives the non-blank lines, the lines that are
documentation (inside a docstring or holding a comment), their share in percent, and the number of
flagged lines.  ``--flags`` also lists each flagged line (``path:line: [kind] text``).

A docstring here is any bare string-literal statement (the module, class and function docstrings
and the attribute docstrings after an assignment).  A flag is a hint for a reviewer, not a
verdict: the house rule is that docstrings say what a thing *is* (units, frames, shapes); the
history of how it came to be goes to the commit message and measured figures to ``docs/`` or the
README.  The patterns are :data:`HISTORY` and :data:`FIGURES`.
"""
from __future__ import annotations

import argparse
import ast
import io
import re
import sys
import tokenize
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: wording that tells how the code came to be rather than what it is
HISTORY: tuple[tuple[str, re.Pattern[str]], ...] = tuple(
    (name, re.compile(rx, re.IGNORECASE)) for name, rx in (
        ("tried", r"(?<!are )(?<!is )(?<!be )(?<!were )(?<!order )\btried\b"),
        ("used to", r"(?<!is )(?<!are )(?<!be )(?<!been )(?<!was )(?<!were )(?<!not )\bused to\b"),
        ("previously", r"\bpreviously\b"),
        ("before issue", r"\bbefore (?:issue|#)\s*\d+"),
        ("issue N", r"\bissue\s*#?\d+"),
        ("no longer", r"\bno longer\b"),
        ("was N", r"\bwas\s+[-+]?\d"),
        ("we found", r"\bwe (?:found|saw|tried|noticed|measured|changed|replaced|switched)\b"),
        ("turned out", r"\bturned out\b"),
        ("not enough", r"\bwas not enough\b|\bwere not enough\b|\bnot enough on its own\b"),
        ("formerly", r"\bformerly\b|\boriginally\b"),
        ("instead of before", r"\bthan before\b|\bas before\b|\bthe old (?:code|version|way)\b"),
        ("now does", r"\b(?:is|are) now\b|\bnow (?:uses|does|reads|writes|runs|returns|raises|keeps)\b"),
        ("this release", r"\bthis (?:release|change|fix)\b"),
    )
)

#: wording that quotes a measured speed or accuracy (goes stale with the next change)
FIGURES: tuple[tuple[str, re.Pattern[str]], ...] = tuple(
    (name, re.compile(rx, re.IGNORECASE)) for name, rx in (
        ("speed ratio", r"\d(?:\.\d+)?\s*(?:x|×|times)\s+(?:faster|slower|as fast)"),
        ("percent faster", r"\d+(?:\.\d+)?\s*%\s+(?:faster|slower|less|more)\b"),
        ("measured", r"\bmeasured (?:at|here|today)\b|\bbenchmarked\b|\bon this machine\b"),
        ("timing", r"\b(?:takes?|took|costs?|written in|read in|runs? in)\s+(?:about\s+|~)?\d+(?:\.\d+)?\s*"
                   r"(?:ms|µs|us|s|min)\b|~?\d+(?:\.\d+)?\s*(?:ms|µs|us) per\b"),
    )
)


@dataclass
class ModuleAudit:
    """One module: its counts and flagged lines ``(line, kind, text)``."""

    path: Path
    lines: int = 0          # non-blank lines
    doc_lines: int = 0      # non-blank lines inside a docstring or holding a comment
    flags: list[tuple[int, str, str]] = field(default_factory=list)

    @property
    def share(self) -> float:
        """Documentation lines over non-blank lines, percent."""
        return 100.0 * self.doc_lines / self.lines if self.lines else 0.0


def _docstring_lines(tree: ast.AST) -> set[int]:
    """Line numbers (1-based) covered by bare string-literal statements."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
                and isinstance(node.value.value, str)):
            out.update(range(node.lineno, (node.end_lineno or node.lineno) + 1))
    return out


def _comments(source: str) -> dict[int, str]:
    """Line number -> the comment's text, for every line holding a ``#`` comment."""
    out: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out[tok.start[0]] = tok.string
    return out


def flags_in(text: str) -> list[str]:
    """The kinds of history and figure wording found in one line of documentation."""
    kinds = [f"history: {name}" for name, rx in HISTORY if rx.search(text)]
    return kinds + [f"figure: {name}" for name, rx in FIGURES if rx.search(text)]


def audit_source(path: Path, source: str) -> ModuleAudit:
    """Count and flag the documentation of one module's source text."""
    lines = source.splitlines()
    doc = _docstring_lines(ast.parse(source, filename=str(path)))
    comments = _comments(source)
    result = ModuleAudit(path)
    for no, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        result.lines += 1
        if no in doc:
            text = line
        elif no in comments:
            text = comments[no]
        else:
            continue
        result.doc_lines += 1
        result.flags.extend((no, kind, line.strip()) for kind in flags_in(text))
    return result


def modules(paths: list[Path]) -> list[Path]:
    """Every ``*.py`` file named or under a named directory, sorted."""
    out: list[Path] = []
    for p in paths:
        out.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p])
    return out


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return str(path)


def report(audits: list[ModuleAudit], *, list_flags: bool, min_share: float) -> str:
    """The table (and the flagged lines when ``list_flags``), as text."""
    rows = [a for a in audits if a.share >= min_share]
    width = max((len(_shown(a.path)) for a in rows), default=6)
    out = [f"{'module':<{width}}  {'lines':>6}  {'doc':>6}  {'doc %':>6}  {'flags':>5}"]
    for a in rows:
        out.append(f"{_shown(a.path):<{width}}  {a.lines:>6}  {a.doc_lines:>6}  {a.share:>6.1f}  {len(a.flags):>5}")
    total = sum(a.lines for a in audits)
    doc = sum(a.doc_lines for a in audits)
    n_flags = sum(len(a.flags) for a in audits)
    share = 100.0 * doc / total if total else 0.0
    out.append(f"{'total':<{width}}  {total:>6}  {doc:>6}  {share:>6.1f}  {n_flags:>5}")
    if list_flags:
        out.append("")
        for a in audits:
            out.extend(f"{_shown(a.path)}:{no}: [{kind}] {text}" for no, kind, text in a.flags)
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", type=Path, help="files or directories (default: navpp)")
    ap.add_argument("--flags", action="store_true", help="list every flagged line")
    ap.add_argument("--min-share", type=float, default=0.0, help="show modules with at least this doc %%")
    args = ap.parse_args(argv)
    paths = [p if p.is_absolute() or p.exists() else REPO / p for p in args.paths] or [REPO / "navpp"]
    audits = [audit_source(p, p.read_text(encoding="utf-8")) for p in modules(paths)]
    print(report(audits, list_flags=args.flags, min_share=args.min_share))
    return 0


if __name__ == "__main__":
    sys.exit(main())
