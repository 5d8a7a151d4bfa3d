"""The command line's option values without pydantic (navpp.cli_values) and scipy's compiled
modules loaded on their own (navpp.scipy_parts): same values, same messages, less start-up."""

from __future__ import annotations

import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from navpp import cli_values
from navpp.cli import app

REPO = Path(__file__).resolve().parents[1]
LOG = REPO / "sample_data" / "drive"


def _run(code: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO,
                          check=True).stdout.strip()


def _numbers() -> list[str]:
    """Number texts of every form: plain, signed, e-notation, long, tiny, huge, odd."""
    rng = random.Random(21)
    texts = ["0", "-0", "+0", "007", "1.5", "1e3", ".5", "5.", "-.5e-3", "+12.34E+5", "0.1", "1e308", "1e400",
             "2.5e-324", "1e-400", "123456789012345678", "1234567890123456789", "9007199254740993", "1_000",
             " 5", "5 ", "inf", "nan", "0x10", "", "1e", "e5", "."]
    for _ in range(3000):
        s = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 20)))
        if rng.random() < 0.5:
            s = s[:rng.randint(0, len(s))] + "." + s[rng.randint(0, len(s)):]
        if rng.random() < 0.3:
            s += "e" + rng.choice(["", "-", "+"]) + str(rng.randint(0, 400))
        if rng.random() < 0.3:
            s = rng.choice("+-") + s
        texts.append(s)
    return texts


@pytest.mark.skipif(cli_values.RuntimeParam is None, reason="this typer coerces through click, not pydantic")
def test_plain_numbers_are_what_pydantic_gives() -> None:
    """Every text the plain float and int forms take converts to pydantic's value to the bit."""
    from pydantic import TypeAdapter

    as_float, as_int = TypeAdapter(float), TypeAdapter(int)
    taken = 0
    for text in _numbers():
        if cli_values._FLOAT.fullmatch(text):
            taken += 1
            assert repr(float(text)) == repr(as_float.validate_python(text)), text
        if cli_values._INT.fullmatch(text):
            assert int(text) == as_int.validate_python(text), text
    assert taken > 2000


@pytest.mark.parametrize(("args", "message"), [
    (["process", "LOG", "--output-rate", "abc"], "Input should be a valid number"),
    (["process", "LOG", "--output-rate", "0"], "must be a finite number of Hz > 0, got 0"),
    (["compare", "LOG", "--jobs", "1.5"], "Input should be a valid integer"),
    (["simulate", "OUT", "--seed", "-1"], "must be a non-negative integer, got -1"),
])
def test_bad_values_get_typers_own_messages(args: list[str], message: str) -> None:
    """A value the plain forms do not take goes to typer's own coercion: its message, exit 2."""
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2
    assert message in res.output


def test_a_run_loads_neither_pydantic_nor_scipy_linalg(tmp_path: Path) -> None:
    """``navpp process`` of a CSV log (with options of every plain kind) imports neither pydantic
    nor the scipy.linalg package (nor numpy.f2py, which it pulls in)."""
    out = _run("import sys; from navpp.cli import main; "
               f"sys.argv = ['navpp', 'process', {str(LOG)!r}, '--out', {str(tmp_path)!r}, '-q', "
               "'--output-rate', '25', '--gnss-outage', '100:20', '--format', 'csv,tum']\n"
               "try:\n    main()\nexcept SystemExit:\n    pass\n"
               "print(','.join(m for m in ('pydantic', 'scipy.linalg', 'numpy.f2py') if m in sys.modules))")
    assert out == ""
    assert (tmp_path / "trajectory.tum").is_file()


def test_flapack_alone_is_get_lapack_funcs_gtsv() -> None:
    """``dgtsv`` of scipy.linalg._flapack loaded on its own solves to the bit as the function
    ``scipy.linalg.get_lapack_funcs`` gives (imported afterwards, the package uses the same module)."""
    out = _run("import sys\nimport numpy as np\nfrom navpp.scipy_parts import extension\n"
               "alone = extension('scipy.linalg._flapack').dgtsv\n"
               "assert 'scipy.linalg' not in sys.modules\n"
               "rng = np.random.default_rng(1)\n"
               "dl, d, du, b = rng.random(99), rng.random(100) + 4, rng.random(99), rng.random((100, 1))\n"
               "from scipy import linalg\n"
               "gtsv, = linalg.get_lapack_funcs(('gtsv',), (d, b))\n"
               "x = alone(dl.copy(), d.copy(), du.copy(), b.copy())[3]\n"
               "y = gtsv(dl.copy(), d.copy(), du.copy(), b.copy())[3]\n"
               "ab = np.array([[0, 1, 1], [2, 2, 2], [1, 1, 0.0]])\n"
               "print(gtsv is alone, np.array_equal(x, y), linalg.solve_banded((1, 1), ab, np.ones(3)))")
    assert out == "True True [0.5 0.  0.5]"


def test_a_typer_whose_coercion_class_differs_keeps_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """When the plain coercion cannot be made (a typer whose RuntimeParam takes other arguments),
    every value goes through typer's own coercion: same messages, nothing broken."""
    class Other:
        def __init__(self) -> None:
            pass

    monkeypatch.setattr(cli_values, "PlainValue", Other)
    res = CliRunner().invoke(app, ["process", "LOG", "--output-rate", "abc"])
    assert res.exit_code == 2
    assert "Input should be a valid number" in res.output
    res = CliRunner().invoke(app, ["simulate", "OUT", "--seed", "-1"])
    assert res.exit_code == 2
    assert "must be a non-negative integer, got -1" in res.output
