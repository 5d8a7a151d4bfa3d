"""Aiding measurements of the 15-state INS model beyond the GNSS position, one per file.

Each is a measurement in the filter-core protocol (``innovation_at``, ``jacobian``,
``predict_points``, ``R``, ``axes``), so every registered filter applies it through its own
update template with no aid-specific code:

- :mod:`.gnss_velocity`: GNSS velocity with the lever-arm rate term;
- :mod:`.zero_velocity`: ZUPT, the body velocity is zero while still;
- :mod:`.zero_rate`: ZARU, the body turns only with the Earth while still (gyro bias observable);
- :mod:`.nonholonomic`: NHC, a wheeled vehicle has no lateral or vertical velocity;
- :mod:`.standstill`: the detector that says when the vehicle is still.

Frames and units: navigation ENU, body FLU, velocities m/s, rates rad/s (docs/algorithms.md).
"""

from .base import Aid
from .gnss_velocity import GnssVelocity
from .nonholonomic import NonHolonomic
from .zero_rate import ZeroRate
from .zero_velocity import ZeroVelocity

__all__ = ["Aid", "GnssVelocity", "NonHolonomic", "ZeroRate", "ZeroVelocity"]
