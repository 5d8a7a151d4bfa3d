"""The compare report: the Markdown table's numbers are summary.csv's; the best (minimum) of
each column per log is highlighted and nothing else; the HTML stands alone (every figure a
valid PNG data URI, no external URL); a log without reference says so and has no error plots."""

from __future__ import annotations

import base64
import csv
import html
import io
import re
from pathlib import Path

import numpy as np
import pytest

from navpp.comparison import CompareRow, compare, minmax_decimate
from navpp.comparison.report import TABLE_ERROR_COLUMNS, best_cells

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
HEADER_TO_COLUMN = {h: c for c, h in TABLE_ERROR_COLUMNS}


@pytest.fixture(scope="module")
def report_dir(sim_log_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One comparison with a reference (ekf, the adaptive vce-ckf) and one log without it."""
    import shutil

    root = tmp_path_factory.mktemp("report")
    noref = root / "noref"
    shutil.copytree(sim_log_dir, noref)
    (noref / "reference.csv").unlink()
    out = root / "out"
    out.mkdir()
    (out / "old_trajectory.png").write_bytes(b"stale")           # an earlier run's, in its manifest
    (out / ".navpp-manifest.json").write_text('{"files": ["old_trajectory.png"]}')
    (out / "holiday_trajectory.png").write_bytes(b"mine")        # the user's: navpp never wrote it
    (out / "notes.txt").write_text("mine")
    compare([sim_log_dir, noref], ["ekf", "vce-ckf"], out_dir=out)
    return out


def md_table(text: str) -> tuple[list[str], list[list[str]]]:
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    return head, [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[2:]]


def test_files_and_stale_figures(report_dir: Path):
    names = sorted(p.name for p in report_dir.iterdir())
    assert names == [".navpp-manifest.json", "drive_adaptive.png", "drive_ekf_errors.png", "drive_error_cdf.png",
                     "drive_error_time.png", "drive_map.html", "drive_trajectory.png", "drive_vce-ckf_errors.png",
                     "holiday_trajectory.png", "noref_adaptive.png", "noref_ekf_innovations.png", "noref_map.html",
                     "noref_trajectory.png", "noref_vce-ckf_innovations.png",
                     "notes.txt", "report.html", "report.md", "summary.csv"]
    assert (report_dir / "holiday_trajectory.png").read_bytes() == b"mine"
    assert not list(report_dir.glob(".*.tmp"))


def test_markdown_numbers_are_the_summary_and_best_is_the_minimum(report_dir: Path):
    head, body = md_table((report_dir / "report.md").read_text())
    with open(report_dir / "summary.csv", newline="") as f:
        summary = list(csv.DictReader(f))
    assert len(body) == len(summary) == 5                    # 2 x 2 runs and the raw GNSS row of drive
    assert [s["filter"] for s in summary] == ["ekf", "vce-ckf", "raw GNSS", "ekf", "vce-ckf"]
    checked = 0
    for cells, srow in zip(body, summary):
        assert cells[head.index("filter")] == srow["filter"]
        for h, c in HEADER_TO_COLUMN.items():
            cell = cells[head.index(h)]
            if srow[c] == "":
                assert cell == ""
                continue
            assert float(cell.strip("*")) == float(srow[c])
            checked += 1
            same_log = [float(s[c]) for s in summary if s["log"] == srow["log"] and s[c] != ""
                        and s["filter"] != "raw GNSS"]     # the raw fixes are shown, never "best"
            best = srow["filter"] != "raw GNSS" and float(srow[c]) == min(same_log)
            assert cell.startswith("**") == best, (h, srow["filter"])
        assert cells[head.index("rejected")] == srow["gnss_rejected"]
        if srow["filter"] == "raw GNSS":
            assert cells[head.index("time s")] == srow["runtime_s"] == ""
        else:
            assert float(cells[head.index("time s")]) == pytest.approx(float(srow["runtime_s"]), abs=0.006)
    assert checked == 3 * len(HEADER_TO_COLUMN)              # the log without reference has no numbers
    text = (report_dir / "report.md").read_text()
    for png in (p for p in report_dir.glob("*.png") if p.name != "holiday_trajectory.png"):
        assert f"]({png.name})" in text


def test_html_is_self_contained_with_valid_pngs(report_dir: Path):
    from matplotlib.image import imread

    text = (report_dir / "report.html").read_text()
    uris = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    pngs = sorted(p for p in report_dir.glob("*.png") if p.name != "holiday_trajectory.png")   # the user's
    assert len(uris) == len(pngs) == 10
    assert sorted(base64.b64decode(u) for u in uris) == sorted(p.read_bytes() for p in pngs)
    for u in uris:
        data = base64.b64decode(u, validate=True)
        assert data.startswith(PNG_SIGNATURE)
        assert imread(io.BytesIO(data), format="png").ndim == 3
    rest = re.sub(r'<img src="data:image/png;base64,[A-Za-z0-9+/=]+"', "<img", text)
    # the overview maps: the map pages themselves, inline; their only URLs are the tile server the
    # page tries (falling back to a plain background) and the tiles' copyright note
    frames = re.findall(r'<iframe srcdoc="([^"]*)"', rest)
    assert len(frames) == 2
    for frame in frames:
        page = html.unescape(frame)
        assert 'id="navpp-map-data"' in page
        assert set(re.findall(r"https?://[a-z.]+", page)) == {"https://tile.openstreetmap.org",
                                                             "https://www.openstreetmap.org"}
    rest = re.sub(r'<iframe srcdoc="[^"]*"', "<frame", rest)
    assert not re.search(r"https?:|ftp:|//[a-z]|<link|<script|<iframe|@import|url\(|src=|href=", rest, re.IGNORECASE)
    assert text.count('<td class="num best">') == sum(1 for _ in re.finditer(r"\*\*", (report_dir / "report.md")
                                                                                 .read_text())) // 2


def test_a_log_without_reference_is_stated(report_dir: Path):
    md = (report_dir / "report.md").read_text()
    section = md.split("## noref", 1)[1]
    assert "No reference for this log" in section and "noref_trajectory.png" in section
    assert "noref_error" not in section
    assert "No reference for this log" in (report_dir / "report.html").read_text()


def _row(log: str, filt: str, h: float | None, status: str = "ok") -> CompareRow:
    if h is None:
        return CompareRow(log, filt, status, None)
    stats = {"mae": h, "rmse": h, "max": h, "p95": h}
    pos = {k: dict(stats) for k in ("east", "north", "up", "horizontal", "3d")}
    return CompareRow(log, filt, status, {"epochs": 1, "position_m": pos})


def test_best_cells_per_log_with_ties_and_failures():
    rows = [_row("a", "ekf", 1.0), _row("a", "ckf", 0.5), _row("a", "ukf", 0.5), _row("a", "x", None, "failed"),
            _row("b", "ekf", 3.0), _row("b", "ckf", None)]
    best = best_cells(rows, ["horizontal_rmse"])
    assert best == {(1, "horizontal_rmse"), (2, "horizontal_rmse"), (4, "horizontal_rmse")}
    # on the values summary.csv holds (0.1 mm): 0.50001 and 0.5 are a tie
    rows[1] = _row("a", "ckf", 0.50001)
    assert (1, "horizontal_rmse") in best_cells(rows, ["horizontal_rmse"])


def test_minmax_decimation_keeps_every_peak():
    t = np.arange(100_000) * 0.01
    y = np.abs(np.sin(t)) + 0.0
    y[54_321] = 50.0
    y[77_777] = -3.0
    y[12] = np.nan
    td, yd = minmax_decimate(t, y, 500)
    assert len(yd) <= 1000 and yd.max() == 50.0 and yd.min() == -3.0
    assert np.all(np.diff(td) > 0) and t[54_321] in td
