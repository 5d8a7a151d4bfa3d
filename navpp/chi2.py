"""Chi-square quantiles without importing :mod:`scipy.special` on the default path.

``import scipy.special`` costs about 0.3 s of every run's start (it parses docstrings at
import); the gates and checks of a default run need a few quantiles only, at the default gate
probability (``[gnss] gate_probability = 0.9999``) and the AUKF's detection probability (0.999).
:func:`chdtri` returns those from :data:`UPPER_QUANTILES`, scipy's own values to the bit
(tests/test_scipy_free.py compares them), and asks scipy for any other.
"""

from __future__ import annotations

#: ``scipy.special.chdtri(dof, tail)`` for the (degrees of freedom, upper-tail probability)
#: pairs a default run uses; the tails are written as the callers compute them (``1.0 - p``)
UPPER_QUANTILES: dict[tuple[int, float], float] = {
    (1, 1.0 - 0.9999): 15.136705226623606,
    (2, 1.0 - 0.9999): 18.420680743952584,
    (3, 1.0 - 0.9999): 21.107513466160444,
    (4, 1.0 - 0.9999): 23.512742444991076,
    (5, 1.0 - 0.9999): 25.74483195905612,
    (6, 1.0 - 0.9999): 27.85634123601417,
    (3, 0.9999): 0.005214832329027595,
    (1, 1.0 - 0.999): 10.827566170662733,
    (2, 1.0 - 0.999): 13.815510557964274,
    (3, 1.0 - 0.999): 16.26623619623813,
    (4, 1.0 - 0.999): 18.46682695290317,
    (5, 1.0 - 0.999): 20.515005652432873,
    (6, 1.0 - 0.999): 22.457744484825323,
    (3, 0.999): 0.02429758581569275,
}


def chdtri(dof: int, tail: float) -> float:
    """The chi-square quantile with ``dof`` degrees of freedom and upper-tail probability ``tail``
    (``x`` with ``P(chi2_dof > x) = tail``): ``scipy.special.chdtri(dof, tail)``, bit for bit,
    from :data:`UPPER_QUANTILES` when the pair is there, else from scipy."""
    known = UPPER_QUANTILES.get((dof, tail))
    if known is not None:
        return known
    from scipy.special import chdtri as scipy_chdtri

    return float(scipy_chdtri(dof, tail))
