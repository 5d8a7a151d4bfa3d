"""Unscented Kalman filter: the sigma-point template with the scaled unscented rule.

References: paper 001 (comparison filter); Wan & van der Merwe (2000).
"""

from __future__ import annotations

from dataclasses import dataclass

from .base import register
from .rules import UnscentedRule
from .sigma import SigmaPointFilter


@dataclass(frozen=True)
class UKFOptions:
    """``[filter.ukf]``: scaled unscented transform parameters."""

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        if not self.alpha > 0:
            raise ValueError(f"alpha must be > 0, got {self.alpha!r}")


@register("ukf")
class UKF(SigmaPointFilter):
    paper = "paper 001 (comparison filter); Wan & van der Merwe 2000"
    summary = "Unscented Kalman filter (scaled: alpha, beta, kappa) through the real strapdown."
    Options = UKFOptions

    def make_rule(self) -> UnscentedRule:
        return UnscentedRule(self.options.alpha, self.options.beta, self.options.kappa)
