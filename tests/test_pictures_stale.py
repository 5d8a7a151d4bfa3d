"""Figures of an earlier run do not stay behind (issue 19, point 9): a run into the same output
directory without ``--plot``, or with another filter or log, removes the figures navpp wrote
there before (the manifest lists them) and never a file it did not write (the oracle: the
names each run wrote, and the user's files byte for byte)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from navpp import api, outdir
from navpp.comparison.report import write_report
from navpp.comparison.rows import CompareRow


def _writer(data: bytes) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        Path(path).write_bytes(data)
    return write


def _manifest(out: Path) -> set[str]:
    return set(json.loads((out / outdir.MANIFEST_NAME).read_text())["files"])


def _files(out: Path) -> set[str]:
    return {p.name for p in out.iterdir()} - {outdir.MANIFEST_NAME}


def test_a_run_with_other_figures_removes_the_earlier_ones_it_wrote(tmp_path: Path):
    out = tmp_path
    first = {"trajectory.csv": b"1", "drive_ekf_errors.png": b"e", "drive_trajectory.png": b"t",
             "drive_adaptive.png": b"a", "drive_map.html": b"m"}
    api.write_outputs(out, [(n, _writer(d)) for n, d in first.items()])
    mine = {"holiday_trajectory.png": b"mine", "notes_map.html": b"mine too", "drive_ekf_errors.png.bak": b"b"}
    for n, d in mine.items():
        (out / n).write_bytes(d)
    # another filter, still with --plot: its own figures, the ekf and adaptive ones are stale
    second = {"trajectory.csv": b"2", "drive_ckf_errors.png": b"c", "drive_trajectory.png": b"t2",
              "drive_map.html": b"m2"}
    api.write_outputs(out, [(n, _writer(d)) for n, d in second.items()])
    assert _files(out) == set(second) | set(mine)
    assert _manifest(out) == set(second)
    assert all((out / n).read_bytes() == d for n, d in {**second, **mine}.items())
    # without --plot: no figure of navpp's left, the user's untouched
    api.write_outputs(out, [("trajectory.csv", _writer(b"3"))])
    assert _files(out) == {"trajectory.csv"} | set(mine)
    assert _manifest(out) == {"trajectory.csv"}
    assert all((out / n).read_bytes() == d for n, d in mine.items())


def test_without_a_manifest_no_figure_is_removed(tmp_path: Path):
    """Figures written by a navpp without a manifest, or the user's under navpp's names, stay."""
    (tmp_path / "drive_ekf_errors.png").write_bytes(b"old")
    api.write_outputs(tmp_path, [("trajectory.csv", _writer(b"1"))])
    assert (tmp_path / "drive_ekf_errors.png").read_bytes() == b"old"
    assert _manifest(tmp_path) == {"trajectory.csv"}


def test_compare_report_removes_only_the_figures_navpp_wrote(tmp_path: Path):
    from navpp.comparison.figures import Plot

    out = tmp_path
    row = CompareRow("drive", "ekf", "ok", None, 10, 0, 0.1, 100)
    (out / "summary.csv").write_text("log\n")        # what the runner writes before the report
    old = [Plot("drive_ekf_innovations.png", "old", b"\x89PNG old"), Plot("drive_map.html", "map", b"<html>")]
    write_report(out, [row], {"drive": old})
    (out / "holiday_trajectory.png").write_bytes(b"mine")
    assert _manifest(out) == {"summary.csv", "report.md", "report.html", "drive_ekf_innovations.png",
                              "drive_map.html"}
    new = [Plot("drive_trajectory.png", "track", b"\x89PNG new")]
    write_report(out, [row], {"drive": new})
    assert _files(out) == {"summary.csv", "report.md", "report.html", "drive_trajectory.png",
                           "holiday_trajectory.png"}
    assert _manifest(out) == {"summary.csv", "report.md", "report.html", "drive_trajectory.png"}
    assert (out / "holiday_trajectory.png").read_bytes() == b"mine"


@pytest.mark.slow
def test_process_without_plot_removes_the_figures_of_a_run_with_plot(sim_log_dir: Path, tmp_path: Path):
    """End to end: ``process --plot`` and then ``process`` (no ``--plot``) into the same --out."""
    out = tmp_path / "out"
    first = api.process(sim_log_dir, filter_name="ekf", out_dir=out, plot=True, formats="csv")
    figures = {p.name for p in first.files if p.name.endswith(outdir.FIGURE_SUFFIXES)}
    assert figures == {"drive_ekf_errors.png", "drive_trajectory.png", "drive_map.html"}
    (out / "my_map.html").write_text("mine")
    second = api.process(sim_log_dir, filter_name="ekf", out_dir=out, formats="csv")
    assert _files(out) == {p.name for p in second.files} | {"my_map.html"}
    assert not _files(out) & figures and (out / "my_map.html").read_text() == "mine"


def test_the_figure_endings_are_those_of_compare_s_leftovers():
    """One list of figure endings: the temporary files of a killed compare are cleaned for the same."""
    from navpp.comparison import COMPARE_FILES

    assert {n[1:] for n in COMPARE_FILES if n.startswith("*")} == set(outdir.FIGURE_SUFFIXES)
