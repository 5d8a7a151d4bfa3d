"""benchmarks/snapshot.py, the record / compare instrument for "behaviour unchanged": two records
of the same code are identical, and a changed output file is reported with its largest
difference."""
from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def snapshot():
    spec = importlib.util.spec_from_file_location("navpp_snapshot", REPO / "benchmarks" / "snapshot.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod                  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _change_one_cell(path: Path, column: str, delta: float) -> None:
    lines = path.read_text().splitlines()
    j = lines[0].split(",").index(column)
    cells = lines[100].split(",")
    cells[j] = repr(float(cells[j]) + delta)
    lines[100] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def test_record_twice_is_identical_and_a_changed_file_is_reported(snapshot, tmp_path: Path) -> None:
    cases = snapshot.build_cases(["sample_data/drive"], ["ekf"], extras=False, benchmarks=False)
    assert [c.name for c in cases] == ["process-drive-ekf"]
    a = snapshot.record(cases, jobs=1, keep=tmp_path / "a", quiet=True)
    b = snapshot.record(cases, jobs=1, keep=tmp_path / "b", quiet=True)
    files = a["cases"]["process-drive-ekf"]["files"]
    assert {"trajectory.csv", "diagnostics.csv", "metrics.json", "metrics.md"} <= files.keys()
    assert a["cases"]["process-drive-ekf"]["exit"] == 0
    assert snapshot.compare_snapshots(a, b) == []
    assert json.loads(json.dumps(a)) == a                       # what `record` writes is what it holds

    # one cell of trajectory.csv moved by 1e-3 (lat, deg): the file is named with the exact
    # largest difference (outputs kept on both sides) ...
    _change_one_cell(tmp_path / "b" / "process-drive-ekf" / "trajectory.csv", "lat", 1e-3)
    case = cases[0]
    res = {k: b["cases"][case.name][k]["text"] for k in ("stdout", "stderr")} | {"exit": 0}
    b["cases"][case.name] = snapshot.digest_case(case, res, tmp_path / "b")
    diffs = snapshot.compare_snapshots(a, b)
    assert diffs[0].startswith("process-drive-ekf/trajectory.csv: differs")
    assert "lat: largest cell difference 0.001" in diffs[1]
    assert len([d for d in diffs if not d.startswith(" ")]) == 1

    # ... and without the kept files, by the column statistics
    a["kept"] = b["kept"] = None
    diffs = snapshot.compare_snapshots(a, b)
    assert diffs[0].startswith("process-drive-ekf/trajectory.csv: differs")
    assert "largest column-statistic difference 0.001" in diffs[1] and " lat " in diffs[1]


def test_runtime_fields_are_normalised(snapshot, tmp_path: Path) -> None:
    root = tmp_path.resolve()
    one = {"runtime_s": 1.2, "forward": {"runtime_s": 0.9}, "log": f"{root}/x", "rmse": 0.5}
    two = {"runtime_s": 3.4, "forward": {"runtime_s": 2.0}, "log": f"{root}/x", "rmse": 0.5}
    da = snapshot.digest_bytes("metrics.json", json.dumps(one).encode(), root)
    db = snapshot.digest_bytes("metrics.json", json.dumps(two).encode(), root)
    assert da["sha256"] == db["sha256"] and da["numbers"] == {"rmse": 0.5}
    md = "- runtime: {} s\n\n| log | H RMSE | time s |\n|---|---:|---:|\n| drive | 0.6 | {} |\n"
    assert (snapshot.digest_bytes("r.md", md.format(1.1, 2.2).encode(), root)["sha256"]
            == snapshot.digest_bytes("r.md", md.format(3.3, 4.4).encode(), root)["sha256"])
    assert (snapshot.digest_bytes("r.md", md.format(1.1, 2.2).encode(), root)["sha256"]
            != snapshot.digest_bytes("r.md", md.format(1.1, 2.2).replace("0.6", "0.7").encode(), root)["sha256"])
    html = "<table><tr><th>H</th><th>time s</th></tr><tr><td>0.6</td><td>{}</td></tr></table>"
    assert (snapshot.digest_bytes("r.html", html.format(1.0).encode(), root)["sha256"]
            == snapshot.digest_bytes("r.html", html.format(2.0).encode(), root)["sha256"])
    csv = "log,h_rmse,runtime_s\ndrive,0.6,{}\n"
    assert (snapshot.digest_bytes("s.csv", csv.format(1.0).encode(), root)["sha256"]
            == snapshot.digest_bytes("s.csv", csv.format(2.0).encode(), root)["sha256"])


def test_compare_command_exits_1_on_a_difference(snapshot, tmp_path: Path, capsys) -> None:
    snap = {"navpp_snapshot": 1, "kept": None, "cases": {"c": {
        "argv": [], "exit": 0, "stdout": {"sha256": "x", "text": ""}, "stderr": {"sha256": "y", "text": ""},
        "files": {"m.json": {"size": 2, "sha256": "1", "numbers": {"a.rmse": 0.5}}}}}}
    other = json.loads(json.dumps(snap))
    other["cases"]["c"]["files"]["m.json"] |= {"sha256": "2", "numbers": {"a.rmse": 0.75}}
    pa, pb = tmp_path / "a.json", tmp_path / "b.json"
    pa.write_text(json.dumps(snap))
    pb.write_text(json.dumps(other))
    assert snapshot.main(["compare", str(pa), str(pa)]) == 0
    assert snapshot.main(["compare", str(pa), str(pb)]) == 1
    out = capsys.readouterr().out
    assert "c/m.json: differs" in out and "largest numeric difference 0.25 at a.rmse" in out
