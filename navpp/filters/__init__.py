"""Kalman algebra, generic over a model; knows nothing about IMUs or GNSS.

``FILTERS`` maps registry names (the CLI's ``--filter`` choices) to filter classes.
"""

from .base import FILTERS, Filter, GaussianState, Innovation, get_filter, register
from . import ekf  # noqa: F401  (registers "ekf")

__all__ = ["FILTERS", "Filter", "GaussianState", "Innovation", "get_filter", "register"]
