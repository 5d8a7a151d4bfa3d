"""The shape of the code a newcomer reads first: no function longer than 80 lines in the engine,
the filters and the papers' benchmarks (docs/ARCHITECTURE.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

NAVPP = Path(__file__).resolve().parents[1] / "navpp"
MAX_LINES = 80


def long_functions(root: Path, limit: int = MAX_LINES) -> list[str]:
    """``file:line name (n lines)`` of every function or method under ``root`` longer than ``limit``
    lines, decorators excluded, docstring included."""
    out = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > limit:
                    out.append(f"{path.name}:{node.lineno} {node.name} ({n} lines)")
    return out


@pytest.mark.parametrize("package", ["engine", "filters", "papers"])
def test_no_function_over_80_lines(package: str) -> None:
    assert long_functions(NAVPP / package) == []


def test_the_check_finds_a_long_function(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES))
    (tmp_path / "m.py").write_text(f"def short():\n    return 1\n\n\ndef long():\n{body}\n", encoding="utf-8")
    found = long_functions(tmp_path)
    assert len(found) == 1 and "long (81 lines)" in found[0]
