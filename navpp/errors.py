"""Exceptions navpp raises on purpose.

Every ``NavppError`` carries a message that names the input (file, column or topic) and the
row or time at fault; the CLI prints it as one line and exits with code 1.
"""

from __future__ import annotations


class NavppError(Exception):
    """Base class: a failure the user can act on (bad input, bad config, divergence).

    ``notes`` and ``warnings`` hold what the run had found out before it failed (what it measured
    in the data, what it decided): the CLI prints them before the error line, since they often
    name the cause."""

    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()

    def with_context(self, notes, warnings) -> NavppError:
        """Attach the run's notes and warnings (kept when already set by an inner run)."""
        if not self.notes and not self.warnings:
            self.notes = tuple(notes)
            self.warnings = tuple(warnings)
        return self


class InputError(NavppError):
    """A log, reference or GNSS file that cannot be used as it is."""


class ConfigError(NavppError):
    """A configuration file or command-line option that is invalid."""


class FilterDivergedError(NavppError):
    """The filter's covariance or state became non-finite or lost positive definiteness.

    ``why`` is what went wrong without the name of the filter that saw it ("" when the raiser
    did not say it apart from the message); :meth:`in_filter` builds both."""

    why: str = ""

    @classmethod
    def in_filter(cls, filter_name: str, why: str) -> FilterDivergedError:
        """The error a filter raises: message ``"<filter_name>: <why>"``, ``why`` kept apart."""
        exc = cls(f"{filter_name}: {why}")
        exc.why = why
        return exc


class RunRefused(FilterDivergedError):
    """A run the engine stops: the filter diverged, or its finished solution is not plausible.

    The message is one line (the source, what was seen, the likely cause); ``warnings`` end with
    the other causes to check."""
