"""Cubature Kalman filter: the sigma-point template with the third-degree cubature rule.

References: paper 001 eqs 3-18; paper 003 eqs 19-34.
"""

from __future__ import annotations

from .base import register
from .rules import CubatureRule
from .sigma import SigmaPointFilter


@register("ckf")
class CKF(SigmaPointFilter):
    paper = "paper 001 eqs 3-18; paper 003 eqs 19-34"
    summary = "Cubature Kalman filter: 2n points through the real strapdown, equal weights."

    def make_rule(self) -> CubatureRule:
        return CubatureRule()
