"""Layout of the INS state vectors: the nominal state, the error state and the recorded path.

Plain module-level integers and slices: the numba kernels read them as compile-time
constants (after changing one, clear numba's cache: it is keyed on each kernel's own file).

Nominal state ``x``, float64 (:data:`NOMINAL_SIZE` = 16), what the strapdown integrates:

=================  =====  ====================================================================
name               index  meaning
=================  =====  ====================================================================
``NOMINAL_Q``      0:4    ``q_nb``: scalar-first unit quaternion, body FLU -> navigation ENU
                          (elements ``X_QW, X_QX, X_QY, X_QZ``)
``NOMINAL_VEL``    4:7    velocity, ENU, m/s (``X_VE, X_VN, X_VU``)
``NOMINAL_POS``    7:10   latitude (rad), longitude (rad), height above the WGS-84 ellipsoid
                          (m) (``X_LAT, X_LON, X_H``)
``NOMINAL_BG``     10:13  gyro bias, body FLU, rad/s (first element ``X_BG``)
``NOMINAL_BA``     13:16  accelerometer bias, body FLU, m/s^2 (first element ``X_BA``)
=================  =====  ====================================================================

Error state ``dx`` (:data:`N_ERR` = 15), ``true = nominal ⊞ dx`` (``navpp.ins.model.plus``):

=========  =====  ============================================================================
name       index  meaning
=========  =====  ============================================================================
``ATT``    0:3    attitude error phi, ENU, rad: ``C_true = exp([phi x]) C_est`` (first ``DX_ATT``)
``VEL``    3:6    velocity error, ENU, m/s (first ``DX_VEL``)
``POS``    6:9    position error, local ENU metres (``DP_E, DP_N, DP_U``; first ``DX_POS``)
``BG``     9:12   gyro bias error, body FLU, rad/s (first ``DX_BG``)
``BA``     12:15  accelerometer bias error, body FLU, m/s^2 (first ``DX_BA``)
=========  =====  ============================================================================

Mind the two position blocks: the nominal holds geodetic (lat, lon, h), the error state local
east, north, up metres (``x[X_LAT]`` is a latitude, ``dx[DP_E]`` an east offset).

Recorded path row (:data:`PATH_SIZE` = 10): the nominal's first ten elements, ``q_nb``,
velocity and position (the biases change only at updates and are kept per epoch).
"""

from __future__ import annotations

# nominal state -------------------------------------------------------------------------------
NOMINAL_SIZE = 16
NOMINAL_Q = slice(0, 4)
NOMINAL_VEL = slice(4, 7)
NOMINAL_POS = slice(7, 10)
NOMINAL_BG = slice(10, 13)
NOMINAL_BA = slice(13, 16)
X_QW, X_QX, X_QY, X_QZ = 0, 1, 2, 3
X_VE, X_VN, X_VU = 4, 5, 6
X_LAT, X_LON, X_H = 7, 8, 9
X_BG = 10
X_BA = 13

#: columns of a recorded path row: q_nb, velocity, lat, lon, h (the nominal's first ten)
PATH_SIZE = 10

# error state ---------------------------------------------------------------------------------
N_ERR = 15
ATT = slice(0, 3)
VEL = slice(3, 6)
POS = slice(6, 9)
BG = slice(9, 12)
BA = slice(12, 15)
DX_ATT = 0
DX_VEL = 3
DX_POS = 6
DX_BG = 9
DX_BA = 12
DP_E, DP_N, DP_U = 6, 7, 8

__all__ = [
    "ATT", "BA", "BG", "DP_E", "DP_N", "DP_U", "DX_ATT", "DX_BA", "DX_BG", "DX_POS", "DX_VEL", "NOMINAL_BA",
    "NOMINAL_BG", "NOMINAL_POS", "NOMINAL_Q", "NOMINAL_SIZE", "NOMINAL_VEL", "N_ERR", "PATH_SIZE", "POS", "VEL",
    "X_BA", "X_BG", "X_H", "X_LAT", "X_LON", "X_QW", "X_QX", "X_QY", "X_QZ", "X_VE", "X_VN", "X_VU",
]
