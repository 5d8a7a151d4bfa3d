"""Unit factors between datasheet units and SI, shared by the configuration and the papers' benchmarks."""

from __future__ import annotations

import math
from typing import Final

STANDARD_GRAVITY: Final[float] = 9.80665
"""Conventional standard gravity g0, m/s^2 (the g of "mg" and of ``accel_units = "g"``)."""
DEG_TO_RAD: Final[float] = math.pi / 180.0
"""deg -> rad."""
DEG_PER_SQRT_H_TO_RAD_PER_SQRT_S: Final[float] = DEG_TO_RAD / 60.0
"""Angle random walk: deg/sqrt(h) -> rad/sqrt(s)  (sqrt(3600 s) = 60 sqrt(s))."""
MPS_PER_SQRT_H_TO_MPS_PER_SQRT_S: Final[float] = 1.0 / 60.0
"""Velocity random walk: m/s/sqrt(h) -> m/s/sqrt(s)."""
DEG_PER_H_TO_RAD_PER_S: Final[float] = DEG_TO_RAD / 3600.0
"""Gyro bias: deg/h -> rad/s."""
MG_TO_MPS2: Final[float] = STANDARD_GRAVITY * 1e-3
"""Accelerometer bias: mg -> m/s^2."""
