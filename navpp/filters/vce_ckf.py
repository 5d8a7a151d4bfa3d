"""VCE-adaptive cubature Kalman filter (paper 003): the CKF with a Helmert VCE adaptation.

The cubature rule and sigma-point template of the CKF; the process noise of every time update
is the model's noise groups scaled by the adaptation's factors, the measurement noise is the
given R scaled per axis, and every update that passed the gate feeds the adaptation
(:mod:`navpp.filters.vce`).  With ``adapt = "none"`` it is the CKF exactly.

References: paper 003 eqs 6-18, 35-39 (VCE), 19-34 (CKF); docs/algorithms.md.
"""

from __future__ import annotations

from typing import Any, ClassVar

from .base import register
from .ckf import CKF
from .vce import HelmertVCE, VCEOptions


@register("vce-ckf")
class VCECKF(CKF):
    """CKF + Helmert VCE of the process-noise groups and the measurement noise per axis.

    ``noise_report()``: ``q_factor`` (G,) in the order of :attr:`q_group_names` and
    ``r_factor`` (m,), both relative to the configured noise (the R used is recorded from the
    :class:`~navpp.filters.states.Innovation`).
    """

    paper = "paper 003 eqs 6-18, 35-39 (VCE) with eqs 19-34 (CKF)"
    summary = "CKF with Helmert variance component estimation of the process-noise groups and R."
    Options = VCEOptions
    oracle_options: ClassVar[dict[str, Any]] = {"adapt": "none"}
    adapter: HelmertVCE

    def make_adapter(self) -> HelmertVCE:
        return HelmertVCE(self.options)

    @property
    def q_group_names(self) -> list[str]:
        """Names of the process-noise groups, in the order of ``noise_report()["q_factor"]``."""
        return list(self.adapter.q_group_names or [])
