"""The run's GNSS error model (``[gnss] error_model``): its settings from the configuration and
the fixes, and what the run says when the fixes' errors turn out to be correlated
(:mod:`navpp.ins.gnss_error` holds the model itself)."""

from __future__ import annotations

import numpy as np

from ..config import Config
from ..findings import Finding
from ..ins.gnss_error import Correlation, GnssErrorSettings
from .schedule import GnssFixes


def gnss_error_settings(config: Config, fixes: GnssFixes) -> GnssErrorSettings | None:
    """The Gauss-Markov GNSS error of the run (None: the fixes' errors are taken as white).

    The correlated part's stationary 1-sigma per ENU axis is ``sqrt([gnss] correlated_share)``
    times the median 1-sigma of the run's fixes (their R keeps the rest of each fix's variance,
    :class:`~navpp.engine.measurements.RunMeasurements`); its correlation time ``[gnss] corr_time_s``."""
    g = config.gnss
    if g.error_model != "gauss-markov":
        return None
    std = np.sqrt(np.median(np.asarray(fixes.var, dtype=float), axis=0))
    sigma = np.sqrt(g.correlated_share) * std
    return GnssErrorSettings(g.corr_time_s, (float(sigma[0]), float(sigma[1]), float(sigma[2])))


def _measured(corr: Correlation) -> str:
    return (f"the GNSS innovations {corr.lag_s:g} s apart correlate at {corr.rho:.2f} ({corr.pairs} pairs of fixes; "
            f"white fix errors give about 0, the test is {corr.threshold:.2f})")


def correlation_note(corr: Correlation, config: Config) -> str:
    """The note of an ``"auto"`` run that switched the Gauss-Markov model on."""
    g = config.gnss
    return (f"{_measured(corr)}: the fixes' errors last longer than one fix, so the run was repeated with "
            f"Gauss-Markov GNSS error states ([gnss] error_model = \"auto\"; corr_time_s = {g.corr_time_s:g} s, "
            f"correlated_share = {g.correlated_share:g}; error_model = \"white\" keeps them white)")


def correlation_finding(source: str, corr: Correlation) -> Finding:
    """The warning of a run told to take the fixes as white whose innovations say otherwise."""
    return Finding("gnss-errors-correlated",
                   f"{source}: {_measured(corr)}, but [gnss] error_model = \"white\" takes them as independent: the "
                   "filter follows the slow GNSS error and its sigma is too small; set error_model = \"auto\" or "
                   "\"gauss-markov\"")


__all__ = ["correlation_finding", "correlation_note", "gnss_error_settings"]
