"""The comparison report: ``report.md`` (PNG figures beside it) and a self-contained ``report.html``.

Content, for every log x filter: the position error against the reference (E/N/U/horizontal
MAE and RMSE, m; the best, i.e. smallest, value of each column per log in bold), the GNSS fixes
the gate rejected and the filter's run time (s); per log with a reference, a "raw GNSS" row: its
GNSS fixes themselves against the reference (:func:`~navpp.comparison.rows.with_raw_gnss`).
Then, per log, its figures (:mod:`navpp.comparison.figures`: per run the error per axis with
its +-3-sigma band, and an overview map) and the warnings of its runs.

A log without a reference has status, rejected fixes and run time only, and no error plots
(the trajectories, and the adaptive noise, need no reference); the report says so.
The HTML embeds every PNG as a base64 data URI and its CSS inline, and each overview map as an
inline ``<iframe srcdoc>`` (the map page itself, :mod:`navpp.mapview`): the only thing it may
fetch is the map's background tiles, when the report is served over http and online.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from .. import outdir
from ..errors import InputError
from ..outfiles import os_reason, write_text_file
from ..version import __version__
from .figures import Plot, log_label
from .rows import CompareRow, with_raw_gnss

#: Table columns: (summary.csv column, header); the error columns are metres.
TABLE_ERROR_COLUMNS = (("east_mae", "E MAE"), ("east_rmse", "E RMSE"), ("north_mae", "N MAE"),
                       ("north_rmse", "N RMSE"), ("up_mae", "U MAE"), ("up_rmse", "U RMSE"),
                       ("horizontal_mae", "H MAE"), ("horizontal_rmse", "H RMSE"))


@dataclass(frozen=True)
class LogSection:
    """One log's part of the report: its rows, plots and what to say about it."""

    log: str
    rows: tuple[CompareRow, ...]
    plots: tuple[Plot, ...]
    has_reference: bool
    read_error: str | None          # the first run's reason when every run failed and nothing is drawn


# --------------------------------------------------------------------------- table logic


def _number(row: CompareRow, column: str) -> float | None:
    v = row.summary().get(column)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def best_cells(rows: Sequence[CompareRow], columns: Sequence[str] | None = None) -> set[tuple[int, str]]:
    """``(row index, column)`` of the smallest value of each column among each log's rows
    (ties: all of them), from the ``summary.csv`` values; rows without a value take no part."""
    columns = [c for c, _ in TABLE_ERROR_COLUMNS] if columns is None else list(columns)
    best: set[tuple[int, str]] = set()
    logs = list(dict.fromkeys(r.log for r in rows))
    for log in logs:
        idx = [i for i, r in enumerate(rows) if r.log == log and not r.is_raw_gnss]
        for c in columns:
            vals = {i: v for i in idx if (v := _number(rows[i], c)) is not None}
            if vals:
                low = min(vals.values())
                best.update((i, c) for i, v in vals.items() if v == low)
    return best


def _fmt(v: float | None) -> str:
    return "" if v is None else f"{v:.4f}"


def _table(rows: Sequence[CompareRow]) -> tuple[list[str], list[list[tuple[str, bool]]]]:
    """Header and cells (text, is best) of the comparison table; ``rows`` with the raw-GNSS rows
    (:func:`~navpp.comparison.rows.with_raw_gnss`), which take no part in the best values."""
    with_ref = any(r.metrics is not None for r in rows)
    head = ["log", "filter", "status"]
    if with_ref:
        head += [h for _, h in TABLE_ERROR_COLUMNS]
    head += ["GNSS used", "rejected", "time s"]
    best = best_cells(rows)
    body = []
    for i, r in enumerate(rows):
        cells = [(log_label(r.log), False), (r.filter, False), ("ok" if r.ok else "failed", False)]
        if with_ref:
            cells += [(_fmt(_number(r, c)), (i, c) in best) for c, _ in TABLE_ERROR_COLUMNS]
        if r.is_raw_gnss:
            cells += [(str(r.gnss_epochs), False), ("", False), ("", False)]
        elif r.ok:
            cells += [(str(r.gnss_epochs), False), (str(r.gnss_rejected), False), (f"{r.runtime_s:.2f}", False)]
        else:
            cells += [("", False)] * 3
        body.append(cells)
    return head, body


# --------------------------------------------------------------------------- documents


def _header_lines(rows: Sequence[CompareRow]) -> list[str]:
    logs = list(dict.fromkeys(r.log for r in rows))
    filters = list(dict.fromkeys(r.filter for r in rows))
    failed = sum(not r.ok for r in rows)
    counts = (f"{len(logs)} log{'s' * (len(logs) != 1)} x {len(filters)} filter{'s' * (len(filters) != 1)} = "
              f"{len(rows)} runs; {len(rows) - failed} ok, {failed} failed.")
    legend = ("Position error against the reference in metres (E = east/longitude, N = north/latitude, U = up, "
              "H = horizontal); the best (smallest) value of each column per log is highlighted. GNSS used / "
              "rejected: fixes applied / rejected by the gate; time: filter run time, s. The raw GNSS row of a "
              "log: its GNSS fixes themselves against the reference antenna position (GNSS used: fixes "
              "compared).")
    return [counts, legend]


def _section_notes(sec: LogSection) -> list[str]:
    if sec.read_error is not None:
        return [f"Every run on this log failed, so there is nothing to plot: {sec.read_error}"]
    notes = []
    if not sec.has_reference:
        notes.append("No reference for this log: no accuracy figures and no error plots; the table shows status, "
                     "GNSS fixes and run time only, the plots the trajectories against the GNSS fixes, each run's "
                     "GNSS innovations with their ±3√S band (and the noise the adaptive filters chose).")
    else:
        ref = next((r.reference for r in sec.rows if r.reference), "")
        if ref:
            notes.append(f"Reference: {ref}")
    return notes


def _md_escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("*", "\\*").replace("\n", " ")


def markdown(rows: Sequence[CompareRow], sections: Sequence[LogSection], version: str = "") -> str:
    """``report.md``: the table (best in bold), failures, and per log its notes and figures."""
    table_rows = with_raw_gnss(rows)
    head, body = _table(table_rows)
    out = [f"# navpp comparison{f' (navpp {version})' if version else ''}", ""]
    for line in _header_lines(rows):
        out += [line, ""]
    out.append("| " + " | ".join(head) + " |")
    out.append("|" + "|".join("---" if h in ("log", "filter", "status") else "---:" for h in head) + "|")
    for cells in body:
        out.append("| " + " | ".join(f"**{_md_escape(t)}**" if b and t else _md_escape(t) for t, b in cells) + " |")
    out.append("")
    failed = [r for r in rows if not r.ok]
    if failed:
        out += ["## Failed runs", ""] + [f"- {_md_escape(r.filter)} on {_md_escape(r.log)}: {_md_escape(r.status)}"
                                         for r in failed] + [""]
    for sec in sections:
        out += [f"## {_md_escape(log_label(sec.log))}", "", f"Log: `{sec.log}`", ""]
        out += [_md_escape(n) + "\n" for n in _section_notes(sec)]
        for p in sec.plots:
            out += [f"[{_md_escape(p.caption)}]({p.name})" if p.is_page else f"![{_md_escape(p.caption)}]({p.name})",
                    ""]
        warnings = list(dict.fromkeys(w for r in sec.rows for w in r.warnings))
        if warnings:
            out += ["Warnings:", ""] + [f"- {_md_escape(w)}" for w in warnings] + [""]
    return "\n".join(out).rstrip() + "\n"


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1200px;
       color: #222; line-height: 1.45; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; font-size: 0.9em; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f0f0f0; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.best { font-weight: bold; background: #dff3df; }
tr.failed td { color: #a00; }
tr.raw td { color: #555; font-style: italic; }
figure { margin: 1em 0; } figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; }
code { background: #f5f5f5; padding: 0 0.2em; } .note { color: #555; }
"""


def html_document(rows: Sequence[CompareRow], sections: Sequence[LogSection], version: str = "") -> str:
    """``report.html``: the same content as :func:`markdown`, one file, PNGs as data URIs, CSS inline."""
    e = html.escape
    table_rows = with_raw_gnss(rows)
    head, body = _table(table_rows)
    title = f"navpp comparison{f' (navpp {version})' if version else ''}"
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{e(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>", f"<h1>{e(title)}</h1>"]
    out += [f"<p>{e(line)}</p>" for line in _header_lines(rows)]
    out.append("<table>")
    out.append("<tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr>")
    for r, cells in zip(table_rows, body):
        tds = []
        for k, (text, best) in enumerate(cells):
            cls = " ".join(c for c in ("num" if k >= 3 else "", "best" if best and text else "") if c)
            tds.append(f'<td class="{cls}">{e(text)}</td>' if cls else f"<td>{e(text)}</td>")
        out.append(('<tr class="raw">' if r.is_raw_gnss else "<tr>" if r.ok else '<tr class="failed">')
                   + "".join(tds) + "</tr>")
    out.append("</table>")
    failed = [r for r in rows if not r.ok]
    if failed:
        out.append("<h2>Failed runs</h2><ul>")
        out += [f"<li>{e(r.filter)} on <code>{e(r.log)}</code>: {e(r.status)}</li>" for r in failed]
        out.append("</ul>")
    for sec in sections:
        out.append(f"<h2>{e(log_label(sec.log))}</h2>")
        out.append(f'<p class="note">Log: <code>{e(sec.log)}</code></p>')
        out += [f'<p class="note">{e(n)}</p>' for n in _section_notes(sec)]
        for p in sec.plots:
            if p.is_page:          # the map: the page itself, inline (the report stays one file)
                out.append(f'<figure><iframe srcdoc="{e(p.png.decode("utf-8"))}" title="{e(p.caption)}" '
                           f'style="width:100%;height:620px;border:1px solid #ddd"></iframe>'
                           f"<figcaption>{e(p.caption)} (also <code>{e(p.name)}</code>)</figcaption></figure>")
                continue
            data = base64.b64encode(p.png).decode("ascii")
            out.append(f'<figure><img src="data:image/png;base64,{data}" alt="{e(p.caption)}">'
                       f"<figcaption>{e(p.caption)}</figcaption></figure>")
        warnings = list(dict.fromkeys(w for r in sec.rows for w in r.warnings))
        if warnings:
            out.append('<p class="note">Warnings:</p><ul>' + "".join(f"<li>{e(w)}</li>" for w in warnings) + "</ul>")
    out += ["</body>", "</html>"]
    return "\n".join(out) + "\n"


def build_sections(rows: Sequence[CompareRow], plots: Mapping[str, Sequence[Plot]]) -> list[LogSection]:
    """Group the rows by log, with each log's drawn figures (``plots``: log -> figures)."""
    sections = []
    for log in dict.fromkeys(r.log for r in rows):
        lrows = tuple(r for r in rows if r.log == log)
        figs = tuple(plots.get(log, ()))
        all_failed = all(not r.ok for r in lrows)
        sections.append(LogSection(log, lrows, figs, any(r.metrics is not None for r in lrows),
                                   lrows[0].status if all_failed and not figs else None))
    return sections


def write_report(out_dir: Path, rows: Sequence[CompareRow], plots: Mapping[str, Sequence[Plot]]) -> list[Path]:
    """Write the figures (``plots``: log -> its drawn figures, :func:`render_figures`),
    ``report.md`` and ``report.html`` into ``out_dir`` (atomically); remove the figures of an
    earlier navpp run there (names ending in :data:`navpp.outdir.FIGURE_SUFFIXES`) this one did
    not write, if the directory's manifest lists them (:mod:`navpp.outdir`: a file navpp did not
    write is never removed); then update the manifest.  Returns the files written.
    :class:`~navpp.errors.InputError` if one cannot be written or a stale one removed."""
    out_dir = Path(out_dir)
    sections = build_sections(rows, plots)
    files: list[Path] = []

    def put(path: Path, data: str | bytes) -> None:
        write_text_file(path, data)
        files.append(path)

    for sec in sections:
        for p in sec.plots:
            put(out_dir / p.name, p.png)
    version = __version__
    put(out_dir / "report.md", markdown(rows, sections, version))
    put(out_dir / "report.html", html_document(rows, sections, version))
    written = {p.name for p in files} | ({"summary.csv"} if (out_dir / "summary.csv").is_file() else set())
    ours = outdir.read_manifest(out_dir)
    for old in outdir.stale_figures(out_dir, written, ours):
        try:
            old.unlink()
        except OSError as exc:
            raise InputError(f"{old}: cannot remove this figure of an earlier run ({os_reason(exc)})") from None
    try:
        outdir.write_manifest(out_dir, written | {n for n in ours if (out_dir / n).exists()})
    except OSError as exc:
        raise InputError(f"{out_dir / outdir.MANIFEST_NAME}: cannot write ({os_reason(exc)})") from None
    return files
