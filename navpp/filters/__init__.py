"""Kalman algebra, generic over a model; knows nothing about IMUs or GNSS.

``FILTERS`` maps registry names (the CLI's ``--filter`` choices) to filter classes.
"""

from . import aekf, aukf, ckf, ekf, rwckf, sif, ukf, vce_ckf  # noqa: F401  (register the filters)
from .base import FILTERS, Filter, get_filter, register
from .states import GaussianState, Innovation, Prediction, Update

__all__ = ["FILTERS", "Filter", "GaussianState", "Innovation", "Prediction", "Update", "get_filter", "register"]
