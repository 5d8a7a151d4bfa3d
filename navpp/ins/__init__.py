"""Inertial physics: attitude algebra, strapdown mechanisation, alignment, the INS error model.

No I/O and no Kalman algebra here.
"""
