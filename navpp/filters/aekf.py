"""Adaptive EKFs of paper 002: the standard Sage-Husa filter and the improved AEKF.

Both are the EKF with a measurement-noise adapter (:class:`navpp.filters.noise.SageHusaAdapter`);
the improved one gains with the previous epoch's R and drops the ``- H P- H^T`` term, so R stays
positive definite.  Only fixes that pass the innovation gate are learnt into R (not those forced
through it after a run of rejections).

References: paper 002 section 3; docs/algorithms.md "Sage-Husa and the improved adaptive EKF".
"""

from __future__ import annotations

from typing import Any, ClassVar

from .base import register
from .ekf import EKF
from .noise import SageHusaAdapter, SageHusaOptions


@register("aekf")
class AEKF(EKF):
    paper = "paper 002 section 3, eqs 6-16 (improved Sage-Husa)"
    summary = "Improved adaptive EKF: R learnt from the innovations (gain with R_k-1, no -HPH' term)."
    Options = SageHusaOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": False}

    def make_adapter(self) -> SageHusaAdapter:
        return SageHusaAdapter(self.options, improved=True)


@register("sage-husa")
class SageHusaEKF(EKF):
    paper = "paper 002 section 3, eqs 6-13 (standard Sage-Husa)"
    summary = "Standard Sage-Husa adaptive EKF: R_k = (1-d) R_k-1 + d (e e' - H P H'), before the gain."
    Options = SageHusaOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": False}

    def make_adapter(self) -> SageHusaAdapter:
        return SageHusaAdapter(self.options, improved=False)
