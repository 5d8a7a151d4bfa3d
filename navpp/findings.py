"""Findings: the notes and warnings a run reports, each with a stable code.

A :class:`Finding` is the text the user reads (it *is* a ``str``, so it prints, joins and
compares like one) plus a ``code`` that callers test instead of searching the text.  Codes
are short kebab-case names (``"recording-cut-off"``, ``"imu-gap"``); a finding built from a
plain string has the code ``""`` (not yet classified).

Every module that reports a condition another module reacts to gives it a code here, in
:data:`CODES`, so the list of what can be tested is in one place.
"""

from __future__ import annotations

from collections.abc import Iterable

#: code -> what it means; a code used anywhere in navpp is listed here
CODES: dict[str, str] = {
    "recording-cut-off": "the log ends inside a record (a recording that was interrupted)",
}


class Finding(str):
    """A note or warning: its text (the ``str`` value) and its ``code`` (kebab-case, or "")."""

    code: str

    def __new__(cls, code: str, message: str) -> Finding:
        if code and code not in CODES:
            raise ValueError(f"unknown finding code {code!r}; add it to navpp.findings.CODES")
        obj = super().__new__(cls, message)
        obj.code = code
        return obj

    def __getnewargs__(self) -> tuple[str, str]:      # type: ignore[override]  # pickled across processes
        return (self.code, str(self))

    def __repr__(self) -> str:
        return f"Finding({self.code!r}, {str(self)!r})"


def code_of(item: str) -> str:
    """The code of a finding; "" for a plain string."""
    return item.code if isinstance(item, Finding) else ""


def with_code(items: Iterable[str], code: str) -> list[str]:
    """The findings among ``items`` that carry ``code``."""
    return [w for w in items if code_of(w) == code]
