"""The command line's option values without pydantic: the plain cases typer would give the same.

Typer 0.29 coerces every parameter's text through a pydantic ``TypeAdapter`` (built on the
parameter's first use); importing pydantic and building the adapters of a ``navpp process``
costs about 0.16 s of CPU, a tenth of a run on the 1-hour log.  :func:`install` gives each
parameter of a command about to run a :class:`PlainValue` coercion instead (before its
arguments are parsed), which converts a value itself only when the result is certainly what
pydantic gives:

- ``str``: a ``str`` as it is;
- ``Path``: a ``str`` as ``Path(text)`` (then typer's own path checks);
- ``int``: the text ``[+-]digits`` (at most 18 digits) as ``int(text)``;
- ``float``: the text ``[+-]digits[.digits][e[+-]digits]`` (or ``.digits``) as ``float(text)``,
  both correctly rounded;
- ``list[...]`` of these: item by item.

Anything else (a value pydantic would reject, ``1_000``, `` 5``, ``inf``, another annotation)
goes to typer's own pydantic coercion, built then, so every error message and every unusual
form is typer's own.  With a typer that does not coerce through pydantic (before 0.29: no
``typer._coercion``) :func:`install` does nothing.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, get_args, get_origin

_INT = re.compile(r"[+-]?[0-9]{1,18}")
_FLOAT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")

try:                              # typer >= 0.29: coercion through pydantic, built per parameter
    from typer._coercion import RuntimeParam, build_runtime_param
    from typer._param_types import coerce_cli_path
except ImportError:               # an older typer coerces through click: nothing to replace
    RuntimeParam = None  # type: ignore[assignment,misc]


def _plain(annotation: Any, value: Any, param: Any, ctx: Any) -> tuple[bool, Any]:
    """``(True, coerced)`` when ``value`` is one of the plain cases of the module docstring for
    ``annotation``, else ``(False, None)``."""
    if annotation is str:
        return (True, value) if isinstance(value, str) else (False, None)
    if not isinstance(value, str):
        return False, None
    if annotation is Path:
        info = param.type_descriptor.parameter_info
        return True, coerce_cli_path(Path(value), info, path_type=Path, param=param, ctx=ctx)
    if annotation is int and _INT.fullmatch(value):
        return True, int(value)
    if annotation is float and _FLOAT.fullmatch(value):
        return True, float(value)
    return False, None


if RuntimeParam is not None:
    class PlainValue(RuntimeParam):
        """Typer's runtime coercion of one parameter: the plain cases here, the rest by typer's own
        (pydantic) coercion of the same parameter, built on first need."""

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            annotation: Any = self.annotation
            try:
                if get_origin(annotation) is list and isinstance(value, (list, tuple)):
                    (item_type,) = get_args(annotation)
                    items = [_plain(item_type, v, param, ctx) for v in value]
                    if all(ok for ok, _ in items):
                        return [v for _, v in items]
                else:
                    ok, coerced = _plain(annotation, value, param, ctx)
                    if ok:
                        return coerced
            except (TypeError, AttributeError):     # typer's helpers not as 0.29's: its own coercion
                pass
            own = _OWN.get(param)
            if own is None:
                own = _OWN[param] = build_runtime_param(param.type_descriptor)
            return own._coerce_value(value, param=param, ctx=ctx)

    #: typer's own coercion of a parameter, built the first time a value is not a plain one
    _OWN: dict[Any, Any] = {}


def install(command: Any, ctx: Any) -> None:
    """Give each parameter of ``command`` (a typer command or group about to parse its arguments
    in click context ``ctx``; its ``--help`` option included) the :class:`PlainValue` coercion,
    unless it has one already, takes files (typer opens those) or has its own parser, bounds or
    path type (typer's coercion applies them)."""
    if RuntimeParam is None:
        return
    for param in command.get_params(ctx):
        descriptor = getattr(param, "type_descriptor", None)
        if getattr(param, "_runtime_param", True) is not None or descriptor is None or descriptor.is_file:
            continue
        info = descriptor.parameter_info
        own = [getattr(info, name, None) for name in ("parser", "min", "max", "path_type")]
        if all(v is None for v in own) and not getattr(info, "clamp", False):
            try:
                plain = PlainValue(annotation=descriptor.annotation, parameter_info=descriptor.parameter_info)
            except TypeError:       # a typer whose coercion class is not 0.29's: its own coercion throughout
                return
            param._runtime_param = plain
