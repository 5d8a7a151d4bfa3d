"""``navpp config``: a commented TOML template of every configuration key with its default.

The template is generated from the configuration dataclasses of :mod:`navpp.config` (each
section of :class:`~navpp.config.Config`, its fields' defaults and the ``Attributes`` of its
docstring, which give each key's unit and meaning), and from the ``Options`` dataclasses of the
filters (``[filter.<name>]``), so it cannot drift from what the loader accepts.  Written to a
file, it loads back as the built-in defaults: keys without a default (TOML has no null) and the
IMU noise values a preset fills are printed commented out, the filter tables too.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import textwrap
from typing import Any

from .config import Config, ImuConfig

__all__ = ["attribute_docs", "config_sections", "config_template", "toml_value"]

WIDTH = 100
"""Comment lines are wrapped at this many characters."""


def config_sections() -> dict[str, type]:
    """``section name -> dataclass`` of every ``[section]`` of :class:`Config`, in file order."""
    out: dict[str, type] = {}
    for f in dataclasses.fields(Config):
        factory = f.default_factory
        if factory is not dataclasses.MISSING and isinstance(factory, type) and dataclasses.is_dataclass(factory):
            out[f.name] = factory
    return out


def attribute_docs(cls: type) -> dict[str, str]:
    """``key -> description`` from the ``Attributes`` block of ``cls``'s docstring.

    An entry starts at the block's indentation as ``name : text`` (or ``a, b : text`` for keys
    documented together); indented lines continue it.  The description is the text after the
    colon joined into one line (type, unit, range, default, meaning), RST double backticks
    kept (:func:`config_template` simplifies them).
    """
    doc = inspect.cleandoc(cls.__doc__ or "")
    lines = doc.splitlines()
    try:
        start = next(i for i, line in enumerate(lines[:-1])
                     if line.strip() == "Attributes" and set(lines[i + 1].strip()) == {"-"})
    except StopIteration:
        return {}
    entries: list[tuple[list[str], list[str]]] = []
    for line in lines[start + 2:]:
        if not line.strip():
            continue
        if not line.startswith(" "):
            names, sep, text = line.partition(" : ")
            if not sep:                    # a new heading or prose after the block: it ends here
                break
            entries.append(([n.strip() for n in names.split(",")], [text.strip()]))
        elif entries:
            entries[-1][1].append(line.strip())
    out: dict[str, str] = {}
    for names, text in entries:
        joined = " ".join(text)
        for name in names:
            out[name] = joined
    return out


def toml_value(value: Any) -> str:
    """``value`` written as TOML (bool, int, float incl. ``inf``, str, nested tuples/lists)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def _plain(text: str) -> str:
    """Docstring markup as plain text: ``x`` -> `x`, :func:`a.b` -> `a.b`, and a tuple-of-names
    constant of :mod:`navpp.config` (``PRESET_NAMES``) replaced by its names."""
    from . import config

    text = re.sub(r":\w+:`~?([^`]*)`", r"`\1`", re.sub(r"``([^`]*)``", r"`\1`", text))

    def names(m: re.Match) -> str:
        value = getattr(config, m.group(1), None)
        if isinstance(value, tuple) and value and all(isinstance(v, str) for v in value):
            return ", ".join(f'"{v}"' for v in value)
        return m.group(0)

    return re.sub(r"`([A-Z][A-Z_]+)`", names, text)


def _comment(text: str, indent: str = "") -> list[str]:
    text = _plain(text)
    return textwrap.wrap(text, WIDTH, initial_indent=f"{indent}# ", subsequent_indent=f"{indent}#   ",
                         break_on_hyphens=False, break_long_words=False)


def _field_default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _section_lines(name: str, cls: type) -> list[str]:
    docs = attribute_docs(cls)
    summary = inspect.cleandoc(cls.__doc__ or "").split("\n\n")[0].replace("\n", " ")
    resolved = cls()                      # the defaults as the loader resolves them (IMU preset values)
    lines = ["", *_comment(summary), f"[{name}]"]
    for f in dataclasses.fields(cls):
        lines.append("")
        lines += _comment(f"{f.name}: {docs.get(f.name, '(undocumented)')}")
        default = _field_default(f)
        value = getattr(resolved, f.name)
        if cls is ImuConfig and isinstance(default, float) and math.isnan(default):
            lines.append(f"# {f.name} = {toml_value(value)}    # from the preset unless set here")
        elif value is None:
            lines.append(f"# {f.name} =    # not set by default")
        else:
            lines.append(f"{f.name} = {toml_value(value)}")
    return lines


def _filter_lines() -> list[str]:
    from .filters import FILTERS

    lines = ["", *_comment("[filter.<name>]: each filter's own options (see `navpp filters`); the tables below are "
                           "commented out and show the defaults.  A table for a filter that is not run is checked "
                           "and otherwise ignored.")]
    for fname, fcls in sorted(FILTERS.items()):
        opts = getattr(fcls, "Options", None)
        if opts is None or not dataclasses.is_dataclass(opts) or not dataclasses.fields(opts):
            continue
        lines.append("")
        doc = inspect.cleandoc(opts.__doc__ or "").split("\n\n")[0].replace("\n", " ")
        lines += _comment(doc) if doc else []
        lines.append(f"# [filter.{fname}]")
        for f in dataclasses.fields(opts):
            default = _field_default(f)
            if default is dataclasses.MISSING or default is None:
                lines.append(f"# {f.name} =    # not set by default")
            else:
                lines.append(f"# {f.name} = {toml_value(default)}")
    return lines


def config_template() -> str:
    """The commented TOML template (``navpp config``): every key of every section with its
    default, unit and meaning; loading it gives the built-in defaults."""
    from .version import __version__

    head = [f"# navpp {__version__} configuration: every key with its default.",
            "# Save as navpp.toml beside a log (used automatically) or pass it with --config FILE.toml.",
            "# Every key is optional: delete what you do not change.  Frames: navigation ENU, body FLU",
            "# (x forward, y left, z up); positions WGS-84.  A key shown commented out has no fixed default",
            "# (None: leave it out) or takes it from elsewhere, as its line says."]
    lines = head
    for name, cls in config_sections().items():
        lines += _section_lines(name, cls)
    lines += _filter_lines()
    return "\n".join(lines) + "\n"
