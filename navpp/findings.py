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
    # the engine's checks of the input data (navpp.engine.checks, navpp.engine.prepare)
    "gyro-rate-high": "gyro rates no land vehicle turns at (a gyro in deg/s read as rad/s?)",
    "imu-gap": "IMU intervals longer than a few nominal periods, integrated across",
    "imu-saturated": "IMU samples held at a channel's extreme value or beyond the configured range",
    "spans-partly-overlap": "the IMU and GNSS time spans only partly overlap",
    "gyro-scale": "the GNSS track turns by a different amount than the gyro measures",
    "stale-rows-dropped": "IMU rows repeating the previous row's values under a new stamp were dropped",
    "clock-offset-applied": "an IMU-GNSS clock offset estimated from the data was applied to the GNSS stamps",
    "gross-mounting": "gravity is not on the IMU's +z axis: the IMU was rotated so that it is",
    "imu-tilted": "the IMU at rest is tilted beyond what a level mounting explains (axes not forward-left-up?)",
    "imu-segments": "IMU gaps the INS cannot bridge: the log was processed as separate segments",
    "imu-segment-left-out": "an IMU segment that could not be processed on its own was left out",
    "vehicle-mounting-unknown": "too little straight driving to estimate the vehicle mounting",
    # the engine's checks of a run's result (navpp.engine.verdict, navpp.engine.run)
    "ins-recovered": "the INS had drifted from the GNSS; its velocity was re-aligned on the GNSS",
    "gnss-rejected": "more than 5 % of the GNSS fixes failed the innovation gate",
    "innovations-large": "the GNSS innovations are larger than the filter predicts",
    "solution-doubtful": "the finished solution is doubtful against the prior GNSS sigma or the vehicle",
    "aid-rejected": "an aid's updates failed the innovation gate often",
    "gnss-velocity-sigma": "the GNSS velocity innovations show [gnss] default_vel_std_mps far off",
    "smoothing-breaks": "steps the smoother carries no information back across",
    "refusal-causes": "the other causes to check when a run is refused",
    "gnss-errors-correlated": "the GNSS innovations are correlated over seconds while the fixes are taken as white",
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
