"""Filters for the papers' benchmarks: a spec ``name[key=value; ...]`` read into the filter's
name and options, and a fresh, seeded filter built from it with the innovation gate off.

The papers' filters do not gate (navpp's chi-square gate is a GNSS setting of the application),
so a benchmark filter is built here from the filter registry alone, not from a configuration.
"""

from __future__ import annotations

import tomllib
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..filters import Filter, get_filter


def parse_filter_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"rwckf"`` -> ("rwckf", {}); ``"rwckf[covariance=random; candidates=32]"`` -> the name and
    its options (values read as TOML values, bare words as strings), checked against the
    filter's Options (ConfigError naming the key otherwise)."""
    spec = spec.strip()
    name, opts = spec, {}
    if "[" in spec:
        if not spec.endswith("]"):
            raise ConfigError(f"filter {spec!r}: write options as name[key=value; key=value]")
        name, body = spec[:-1].split("[", 1)
        name = name.strip()
        for item in filter(None, (part.strip() for part in body.split(";"))):
            if "=" not in item:
                raise ConfigError(f"filter {spec!r}: option {item!r} is not key=value")
            key, value = (v.strip() for v in item.split("=", 1))
            try:
                opts[key] = tomllib.loads(f"v = {value}")["v"]
            except tomllib.TOMLDecodeError:
                opts[key] = value
    cls = get_filter(name)
    cls.options_from_mapping(opts, f"filter {spec!r}")
    return name, opts


def make_bench_filter(spec: str, seed: int) -> Filter:
    """A fresh filter for a benchmark run: the spec's options, a generator seeded with ``seed``
    and the chi-square gate off (``gate_probability = 0``; with no gate, no fix is ever
    re-anchored, so the filter's default ``reanchor_after_s`` is never used)."""
    name, opts = parse_filter_spec(spec)
    cls = get_filter(name)
    options = cls.options_from_mapping(opts, f"filter {spec!r}")
    return cls(options, gate_probability=0.0, rng=np.random.default_rng(seed))
