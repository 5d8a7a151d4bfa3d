"""``navpp --version``, shell completion, ``navpp config`` (the commented template), ``--verbose``,
and where a smoothed run says its forward solution went (issue 19, points 2 and 7).

Oracles: pyproject.toml's version; Click's own completion protocol; the config loader and the
dataclasses' defaults (the template must load back as them); the files on disk (sizes, names);
an unsmoothed run of the same log (its trajectory.tum is the forward solution)."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from navpp import api
from navpp.cli import app
from navpp.config import Config, config_from_dict, load_config
from navpp.config_template import attribute_docs, config_sections, config_template

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]


def test_version_is_the_package_version():
    want = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0, res.output
    assert res.stdout == f"navpp {want}\n"


def test_shell_completion_is_offered_and_completes(monkeypatch):
    res = runner.invoke(app, ["--help"])
    assert "--install-completion" in res.stdout and "--show-completion" in res.stdout
    # a user's shell is detected from the process tree (shellingham); here it is named instead
    monkeypatch.setenv("_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION", "1")
    script = runner.invoke(app, ["--show-completion", "bash"], prog_name="navpp")
    assert script.exit_code == 0 and "_NAVPP_COMPLETE=complete_bash" in script.stdout, (script.output, script.exception)
    # what the installed script does when the user presses tab: Click's completion protocol
    env = {"_NAVPP_COMPLETE": "complete_bash", "COMP_WORDS": "navpp con", "COMP_CWORD": "1"}
    got = runner.invoke(app, [], prog_name="navpp", env=env)
    assert got.stdout.split() == ["config"]
    env = {"_NAVPP_COMPLETE": "complete_bash", "COMP_WORDS": "navpp process LOG --verb", "COMP_CWORD": "3"}
    assert runner.invoke(app, [], prog_name="navpp", env=env).stdout.split() == ["--verbose"]
    from navpp.filters import FILTERS

    env = {"_NAVPP_COMPLETE": "complete_bash", "COMP_WORDS": "navpp process LOG --filter a", "COMP_CWORD": "4"}
    assert runner.invoke(app, [], prog_name="navpp", env=env).stdout.split() == sorted(
        n for n in FILTERS if n.startswith("a"))


def _template_keys(text: str) -> dict[str, list[str]]:
    """``section -> keys`` shown in the template, set or commented out."""
    out: dict[str, list[str]] = {}
    section = None
    for line in text.splitlines():
        if m := re.fullmatch(r"(?:# )?\[([\w.-]+)\]", line):
            section = m.group(1)
            out.setdefault(section, [])
        elif section and (m := re.match(r"(?:# )?(\w+) =", line)):
            out[section].append(m.group(1))
    return out


def test_config_template_loads_back_as_the_defaults(tmp_path):
    res = runner.invoke(app, ["config"])
    assert res.exit_code == 0, res.output
    assert res.stdout == config_template()
    path = tmp_path / "navpp.toml"
    path.write_text(res.stdout)
    cfg = load_config(path)
    default = Config.default()
    for name in config_sections():
        assert getattr(cfg, name) == getattr(default, name), name
    assert dict(cfg.filters) == {}
    # every key of every section is shown, in its section, once
    shown = _template_keys(res.stdout)
    for name, cls in config_sections().items():
        assert shown[name] == [f.name for f in dataclasses.fields(cls)], name
    assert set(config_sections()) == {f.name for f in dataclasses.fields(Config)} - {"filters", "source", "notes"}


def test_config_template_filter_tables_uncommented_are_valid_and_default():
    from navpp.filters import FILTERS

    text = config_template()
    body = text[text.index("\n# [filter.<name>]"):]
    uncommented = "\n".join(line[2:] if re.fullmatch(r"# (\[filter\.[\w-]+\]|\w+ = .*)", line) else line
                            for line in body.splitlines())
    cfg = config_from_dict(tomllib.loads(uncommented), "template")
    with_options = {n for n, c in FILTERS.items() if dataclasses.fields(c.Options)}
    assert set(cfg.filters) == with_options
    for name in with_options:
        cls = FILTERS[name]
        assert cls.options_from_mapping(cfg.filters[name], "template") == cls.Options(), name


def test_every_config_key_is_documented():
    """The template's meanings come from the dataclasses' docstrings: a new key without its
    Attributes line would print as undocumented."""
    for name, cls in config_sections().items():
        docs = attribute_docs(cls)
        missing = [f.name for f in dataclasses.fields(cls) if not docs.get(f.name)]
        assert not missing, f"[{name}] keys without an Attributes entry: {missing}"
    assert "(undocumented)" not in config_template()


def _size(path: Path) -> str:
    n = path.stat().st_size
    return f"{path.name} {n / 1e6:.2f} MB" if n >= 100_000 else f"{path.name} {n / 1e3:.1f} kB"


def _cut(log: Path, seconds: float) -> Path:
    """The CSV log cut to its first ``seconds`` s (every file's rows by their stamp): a cheaper run."""
    for name in ("imu.csv", "gnss.csv", "reference.csv"):
        lines = (log / name).read_text().splitlines()
        t0 = float(lines[1].split(",")[0])
        (log / name).write_text("\n".join([lines[0]] + [x for x in lines[1:] if float(x.split(",")[0]) < t0 + seconds])
                                + "\n")
    return log


def test_smoothed_verbose_run_writes_and_names_the_forward_tum(log_copy, tmp_path):
    """One CLI run: --smooth --format csv,tum -v.  The note names the forward files written; the
    forward TUM read back matches trajectory_forward.csv (another writer) in the TUM's own ENU
    frame; -v names the config's changed keys (the file's), the stage times and the file sizes."""
    import numpy as np
    import pandas as pd

    from navpp.geodesy import geodetic_to_enu

    _cut(log_copy, 60.0)                   # 30 s still, 30 s driving
    toml = log_copy / "navpp.toml"
    text = toml.read_text()
    assert "[gnss]\n" in text and "[output]" not in text and "gate_probability" not in text
    toml.write_text(text.replace("[gnss]\n", "[gnss]\ngate_probability = 0.999\n") + "\n[output]\nsmooth = true\n")
    out = tmp_path / "o"
    res = runner.invoke(app, ["process", str(log_copy), "--out", str(out), "--format", "csv,tum", "-v"])
    assert res.exit_code == 0, res.output
    err = " ".join(res.stderr.split())
    assert "the forward solution is in trajectory_forward.csv and trajectory_forward.tum" in err
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(
        ["trajectory.csv", "trajectory_forward.csv", "diagnostics.csv", "metrics.json", "metrics.md",
         "trajectory.tum", "trajectory_forward.tum", "log-ekf.tum", "reference.tum"])
    # the forward TUM against the forward CSV, in the anchor the TUM's header states
    lines = (out / "trajectory_forward.tum").read_text().splitlines()
    assert "filter: ekf (forward, not smoothed)" in lines[1]
    lat0, lon0, h0 = (float(x) for x in re.search(r"lat ([-\d.]+) deg, lon ([-\d.]+) deg, height ([-\d.]+) m",
                                                   lines[3]).groups())
    assert (out / "trajectory.tum").read_text().splitlines()[3] == lines[3]      # same anchor as the smoothed
    tum = np.loadtxt(out / "trajectory_forward.tum", comments="#")
    csv = pd.read_csv(out / "trajectory_forward.csv")
    assert len(tum) == len(csv)
    np.testing.assert_allclose(tum[:, 0], csv["t"], atol=2e-6)
    enu = geodetic_to_enu(np.radians(csv["lat"]), np.radians(csv["lon"]), csv["alt"].to_numpy(), np.radians(lat0),
                          np.radians(lon0), h0)
    np.testing.assert_allclose(tum[:, 1:4], enu, atol=2e-3)       # the CSV rounds to 1e-9 deg (0.1 mm)
    smoothed = np.loadtxt(out / "trajectory.tum", comments="#")
    assert np.abs(smoothed[:, 1:3] - tum[:, 1:3]).max() > 0.01    # a different solution, not a copy
    # --verbose: the config's changed keys, as the file gives them; stage times; file sizes
    cfg = load_config(toml)
    assert cfg.gnss.gate_probability == 0.999 and cfg.output.smooth
    assert f"config: {toml}; 2 differ from the defaults: [gnss] gate_probability = 0.999; [output] smooth = true" \
        in err
    assert f"reference: {log_copy / 'reference.csv'}" in err
    assert re.search(r"wall time: start-up and reading [\d.]+ s, alignment and filtering [\d.]+ s, smoothing, "
                     r"metrics and files [\d.]+ s; total [\d.]+ s", err)
    assert "files: " + ", ".join(_size(out / n) for n in ("trajectory.csv", "trajectory_forward.csv",
                                                          "diagnostics.csv", "metrics.json", "metrics.md",
                                                          "trajectory.tum", "trajectory_forward.tum")) in err


@pytest.mark.parametrize(("formats", "forward"), [
    (("tum", "mcap"), "trajectory_forward.tum and the /navpp/forward/fix and /navpp/forward/odometry topics"),
    (("csv",), "the forward solution is in trajectory_forward.csv"),
    (("geojson",), "the forward solution is not written (geojson holds the smoothed one only"),
])
def test_forward_outputs_note_names_what_is_written(formats, forward):
    note = api.forward_outputs_note(formats)
    assert forward in note
    for f, name in api.FORWARD_OUTPUTS.items():
        assert (name in note) == (f in formats)




@pytest.mark.slow          # a compare run with a worker's start-up: about 4.5 s
def test_compare_verbose_names_config_reference_and_stages(log_copy, tmp_path):
    log = _cut(log_copy, 60.0)
    toml = log / "navpp.toml"
    toml.write_text(toml.read_text().replace("[gnss]\n", "[gnss]\ngate_probability = 0.999\n"))
    res = runner.invoke(app, ["compare", str(log), "--filters", "ekf", "--out", str(tmp_path / "c"), "-v"])
    assert res.exit_code == 0, res.output
    err = " ".join(res.stderr.split())
    assert (f"{log}: config {toml}; 1 differs from the defaults: [gnss] gate_probability = 0.999; "
            f"reference {log / 'reference.csv'}") in err
    stages = re.search(r"stages done at \(s from the start\): (.*?) ·", err + " ·").group(1)
    ends = [(name, float(t)) for name, t in re.findall(r"(\S+(?: \S+)?) \+([\d.]+)", stages)]
    assert [n for n, _ in ends] == ["reading log", "log ekf", "all runs"]
    assert [t for _, t in ends] == sorted(t for _, t in ends)
    runtime = float(next(line for line in (tmp_path / "c" / "summary.csv").read_text().splitlines()[1:]).split(",")[
        (tmp_path / "c" / "summary.csv").read_text().splitlines()[0].split(",").index("runtime_s")])
    total = re.search(r"total ([\d.]+) s wall time for 1 runs; their filters took ([\d.]+) s in all", err)
    assert total and abs(float(total.group(2)) - runtime) < 0.01 and float(total.group(1)) >= runtime
