"""Inertial physics: attitude algebra, strapdown mechanisation, alignment, the INS error model.

No I/O and no Kalman algebra here.  One job per module:

- :mod:`.state`: the layout of the nominal (16) and error (15) state vectors;
- :mod:`.attitude`: quaternions, rotation matrices, rotation vectors, Euler angles (one builder);
- :mod:`.strapdown`: the nominal's mechanisation in ENU through the IMU samples;
- :mod:`.model`: the INS as a state-space model for the filters (⊞/⊟, Phi and Qd, GNSS position);
- :mod:`.alignment`: the initial state and covariance (still period, levelling, heading);
- :mod:`.calibrate`: what the log tells before filtering (standstill, biases, noise, gravity axis);
- :mod:`.timing_estimates`: stale IMU rows and the IMU-to-GNSS clock offset;
- :mod:`.aids`: the aiding measurements (GNSS velocity, ZUPT, ZARU, NHC) and the standstill
  detector, and the vehicle mounting from a solution.
"""
