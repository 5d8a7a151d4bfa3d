"""What the ``navpp`` command prints: a run's summary, the comparison table, the CI gate's
regressions, and the dimmed note lines.

Warnings and notes go to stderr, results to stdout; everything is printed with ``rich``
(imported when something is printed, so ``navpp --help`` stays fast).  Numbers are metres and
seconds unless a header says otherwise.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer


def note(console: Any, line: str) -> None:
    """A note line (what navpp chose or noticed), dimmed, on ``console``."""
    from rich.markup import escape

    console.print(f"[dim]·[/] {escape(line)}")


def print_process_summary(res: Any, quiet: bool, details: list[str] = (), compile_s: float | None = None) -> None:
    """``navpp process``: its warnings and notes (stderr), then the run's figures, the error
    table against the reference, the outage lines and the files written (stdout); ``quiet``:
    the warnings only.  ``details``: more note lines after the notes (``--verbose``).
    ``compile_s``: the command's seconds compiling navpp's kernels (reading and writing
    included, :class:`navpp.jitcache.CompileAnnouncer`); default the filter run's."""
    if quiet and not res.warnings:
        return                          # nothing to print: rich is not imported
    from rich.console import Console
    from rich.markup import escape

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    for line in res.warnings:
        err.print(f"[yellow]warning:[/] {escape(line)}")
    if quiet:
        return
    from rich.table import Table

    for line in (*res.notes, *details):
        note(err, line)
    if compile_s is None:
        compile_s = getattr(res.run, "compile_s", 0.0) or 0.0
    if compile_s > 0.5:
        note(err, f"compiled navpp's kernels in {compile_s:.1f} s (first run only; cached for next time)")
    con = Console(highlight=False, soft_wrap=True)
    run = res.run
    con.print(f"{escape(res.recording.source)}: {len(res.recording.imu)} IMU samples at "
              f"{res.recording.imu.rate_hz:.1f} Hz, "
              f"{run.gnss_epochs} GNSS epochs used ({run.gnss_rejected} rejected by the gate), "
              f"filter [bold]{res.filter_name}[/] ran in {run.runtime_s:.2f} s")
    aids = {k: v for k, v in (getattr(run, "updates", None) or {}).items() if k != "gnss_position"}
    if aids:
        con.print("aiding updates applied (rejected): " + ", ".join(
            f"{k} {v['applied']} ({v['rejected']})" for k, v in aids.items()))
    if res.metrics is not None:
        m = res.metrics
        tab = Table(title=f"position error vs reference ({m['epochs']} epochs), metres")
        for col in ("", "MAE", "RMSE", "max", "p95"):
            tab.add_column(col, justify="right")
        rows = [("east", m["position_m"]["east"]), ("north", m["position_m"]["north"]), ("up", m["position_m"]["up"]),
                ("horizontal", m["position_m"]["horizontal"]), ("3-D", m["position_m"]["3d"])]
        if "horizontal" in m.get("gnss_position_m", {}):     # absent: no fix inside the reference's span
            rows.append(("raw GNSS horiz.", m["gnss_position_m"]["horizontal"]))
            rows.append(("raw GNSS up", m["gnss_position_m"]["up"]))
        for name, s in rows:
            tab.add_row(name, *(f"{s[k]:.3f}" if k in s else "" for k in ("mae", "rmse", "max", "p95")))
        con.print(tab)
        if "forward" in m:
            f = m["forward"]["position_m"]
            p = m["position_m"]
            con.print(f"smoothed vs forward filter: horizontal RMSE {p['horizontal']['rmse']:.3f} m vs "
                      f"{f['horizontal']['rmse']:.3f} m, up RMSE {p['up']['rmse']:.3f} m vs {f['up']['rmse']:.3f} m")
    for line in outage_lines(res):
        con.print(escape(line))
    con.print(escape("wrote " + ", ".join(str(p) for p in res.files)))


def outage_lines(res) -> list[str]:
    """One summary line per simulated GNSS outage window: fixes removed and, with a reference,
    the position error at its end and inside it (m)."""
    windows = (res.metrics or {}).get("outages") or list(getattr(res, "outages", ()))
    lines = []
    forward = ((res.metrics or {}).get("forward") or {}).get("outages") or [None] * len(windows)
    for w, fw in zip(windows, forward):
        head = (f"GNSS outage {w['start_s']:g}-{w['end_s']:g} s ({w['duration_s']:g} s, "
                f"{w.get('gnss_removed', 0)} fixes removed)")
        if "horizontal_m" in w:
            h, v = w["horizontal_m"], w["vertical_m"]
            line = (f"{head}: at its end horizontal {h['end']:.2f} m, vertical {v['end']:.2f} m; inside: "
                    f"horizontal max {h['max']:.2f} m, RMSE {h['rmse']:.2f} m, vertical max {v['max']:.2f} m, "
                    f"RMSE {v['rmse']:.2f} m ({w['epochs']} reference epochs)")
            if fw is not None and "horizontal_m" in fw:
                line += (f"; forward filter: end {fw['horizontal_m']['end']:.2f} m, "
                         f"RMSE {fw['horizontal_m']['rmse']:.2f} m horizontal")
            lines.append(line)
        elif res.metrics is not None:
            lines.append(f"{head}: no reference epoch inside")
        else:
            lines.append(head)
    return lines


def print_comparison(result, json_out: bool, verdict=None, exit_code: int = 0) -> None:
    """The summary table on stdout (best per column and log in bold), or the JSON document;
    warnings, gate notes and the gate's regressions on stderr."""
    import json

    from rich import box
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from .comparison.report import best_cells
    from .comparison.rows import with_raw_gnss

    rows = result.rows
    err = Console(stderr=True, highlight=False, soft_wrap=True)
    for line in dict.fromkeys(w for r in rows for w in r.warnings):
        err.print(f"[yellow]warning:[/] {escape(line)}")
    if verdict is not None:
        for line in verdict.notes:
            note(err, line)
        if verdict.failures:
            print_gate(verdict)
    if json_out:
        doc = {"rows": [r.summary_record() for r in rows], "runs": len(rows), "failed": len(result.failed),
               "gate": verdict.as_dict() if verdict is not None else None,
               "files": [str(p) for p in result.files], "exit_code": exit_code}
        typer.echo(json.dumps(doc, indent=1))
        return
    con = Console(highlight=False, soft_wrap=True)
    if not con.is_terminal:
        con = Console(highlight=False, width=200)
    with_ref = any(r.metrics is not None for r in rows)
    tab = Table(title="position error vs reference, m (best per log in bold)" if with_ref else "no reference",
                caption=("E = longitude, N = latitude; " if with_ref else "")
                + "rej. = GNSS fixes rejected by the gate; s = filter run time",
                box=box.SIMPLE_HEAD, pad_edge=False)
    metric_cols = [("horizontal_mae", "H MAE"), ("horizontal_rmse", "H RMSE"), ("east_rmse", "E RMSE"),
                   ("north_rmse", "N RMSE"), ("up_rmse", "U RMSE")]
    cols = ["log", "filter"] + ([h for _, h in metric_cols] if with_ref else []) + ["rej.", "s"]
    for c in cols:
        tab.add_column(c, justify="left" if c in ("log", "filter") else "right", no_wrap=True)
    rows = with_raw_gnss(rows)           # + each log's raw GNSS fixes against the reference (no rej., no s)
    best = best_cells(rows, [c for c, _ in metric_cols])
    for i, r in enumerate(rows):
        cells = [escape(Path(r.log).name), r.filter]
        if not r.ok:
            cells += ["failed"] + [""] * (len(cols) - 3)
            tab.add_row(*cells, style="red")
            continue
        if with_ref:
            s = r.summary()
            for c, _ in metric_cols:
                v = s.get(c)
                text = f"{v:.3f}" if isinstance(v, float) else ""
                cells.append(f"[bold]{text}[/]" if text and (i, c) in best else text)
        if r.is_raw_gnss:
            tab.add_row(*cells, "", "", style="dim")
            continue
        cells += [str(r.gnss_rejected), f"{r.runtime_s:.2f}"]
        tab.add_row(*cells)
    con.print(tab)
    if result.files:
        names = [p.name for p in result.files if p.suffix != ".png" and not p.name.endswith("_map.html")]
        n_png = sum(p.suffix == ".png" for p in result.files)
        n_map = sum(p.name.endswith("_map.html") for p in result.files)
        con.print(escape(f"wrote {', '.join(str(result.out_dir / n) for n in names)}"
                         + (f" and {n_png} figure{'s' * (n_png != 1)}" if n_png else "")
                         + (f" and {n_map} map{'s' * (n_map != 1)}" if n_map else "")))


def print_gate(verdict) -> None:
    """The CI gate's regressions as a short table on stderr."""
    from rich import box
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    if not err.is_terminal:
        err = Console(stderr=True, highlight=False, width=200)
    tab = Table(title="CI gate: regressions (m)", box=box.SIMPLE_HEAD, pad_edge=False)
    for c in ("log", "filter", "metric", "gate", "baseline/limit", "allowed", "value", "worse %"):
        tab.add_column(c, justify="left" if c in ("log", "filter", "metric", "gate") else "right", no_wrap=True)
    for f in verdict.failures:
        worse = "" if f.worse_pct is None else "inf" if f.worse_pct == float("inf") else f"{f.worse_pct:+.1f}"
        tab.add_row(escape(Path(f.log).name), f.filter, f.metric, f.gate, f"{f.reference:.4f}", f"{f.allowed:.4f}",
                    "none" if f.value is None else f"{f.value:.4f}", worse)
    err.print(tab)


def config_changes(cfg: Any) -> list[str]:
    """The keys of ``cfg`` (a :class:`navpp.config.Config`) whose value differs from the built-in
    default, as ``[section] key = value`` (TOML values), and each ``[filter.<name>]`` table given."""
    import dataclasses

    from .config_template import config_sections, toml_value

    out = []
    for name, cls in config_sections().items():
        ours, default = getattr(cfg, name), cls()
        for f in dataclasses.fields(cls):
            value = getattr(ours, f.name)
            if value != getattr(default, f.name):
                out.append(f"[{name}] {f.name} = " + ("(not set)" if value is None else toml_value(value)))
    for fname, options in cfg.filters.items():
        out.append(f"[filter.{fname}] " + ", ".join(f"{k} = {v!r}" for k, v in options.items()))
    return out


def _stage_ends(marks: dict[str, list[float]], t_start: float) -> str:
    """``stage +a.b`` per progress stage: when it last reported (s from the command's start), in
    that order; stages may overlap (``compare --jobs``), so ends are shown, not durations."""
    ends = sorted((t1, stage) for stage, (_, t1) in marks.items())
    return ", ".join(f"{stage} +{t1 - t_start:.2f}" for t1, stage in ends)


def _differ(changes: list[str]) -> str:
    if not changes:
        return "all keys at their defaults"
    return f"{len(changes)} differ{'s' * (len(changes) == 1)} from the defaults: " + "; ".join(changes)


def _size(path: Path) -> str:
    try:
        n = path.stat().st_size
    except OSError:
        return f"{path.name} (gone)"
    return f"{path.name} {n / 1e6:.2f} MB" if n >= 100_000 else f"{path.name} {n / 1e3:.1f} kB"


def process_details(res: Any, marks: dict[str, list[float]], t_start: float, t_end: float) -> list[str]:
    """``navpp process --verbose``: note lines on where the config, reference and odometry came
    from, the config keys that differ from the defaults, the wall time of each stage (s, one
    after the other: each runs to the last progress report of its stage) and the size of each
    file written."""
    cfg, rec, run = res.config, res.recording, res.run
    changes = config_changes(cfg)
    lines = [f"config: {cfg.source}; {_differ(changes)}"]
    lines.append("reference: " + (rec.reference.source if rec.reference is not None else "none (no error figures)"))
    od = rec.odometry
    lines.append(f"odometry: {od.source} ({len(od)} samples)" if od is not None and len(od) else "odometry: none")
    labels = {"reading": "start-up and reading", "filtering": "alignment and filtering"}
    parts, last = [], t_start
    for stage, (_, t1) in sorted(marks.items(), key=lambda kv: kv[1][1]):
        parts.append(f"{labels.get(stage, stage)} {t1 - last:.2f} s")
        last = t1
    compile_s = getattr(run, "compile_s", 0.0) or 0.0
    smooth_s = run.smoothed.runtime_s if getattr(run, "smoothed", None) is not None else 0.0
    rest = "smoothing, metrics and files" if res.smoothed else "metrics and files"
    lines.append("wall time: " + ", ".join(parts) + f", {rest} {t_end - last:.2f} s; total "
                 f"{t_end - t_start:.2f} s (the filter {run.runtime_s - smooth_s:.2f} s"
                 + (f", smoothing {smooth_s:.2f} s" if res.smoothed else "")
                 + (f", kernel compilation {compile_s:.2f} s" if compile_s > 0 else "") + ")")
    if res.files:
        lines.append("files: " + ", ".join(_size(p) for p in res.files))
    return lines


def print_compare_details(result: Any, logs: list[Path], config: Path | None, marks: dict[str, list[float]],
                          t_start: float, t_end: float) -> None:
    """``navpp compare --verbose``: on stderr, as notes: each log's config (its source and the
    keys that differ from the defaults) and reference, when each stage (reading a log, a filter
    on a log) was done, and the total wall time against the sum of the runs' filter times."""
    from rich.console import Console

    from .errors import NavppError
    from .reading import resolve_config

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    for log in logs:
        try:
            cfg = resolve_config(Path(log), config)
        except NavppError as exc:
            note(err, f"{log}: config not read ({exc})")
            continue
        changes = config_changes(cfg)
        refs = sorted({r.reference for r in result.rows if r.log == str(log) and r.reference})
        note(err, f"{log}: config {cfg.source}; {_differ(changes)}; reference {', '.join(refs) if refs else 'none'}")
    if marks:
        note(err, f"stages done at (s from the start): {_stage_ends(marks, t_start)}")
    ran = [r.runtime_s for r in result.rows if r.ok]
    note(err, f"total {t_end - t_start:.2f} s wall time for {len(result.rows)} runs; their filters took "
              f"{sum(ran):.2f} s in all")
