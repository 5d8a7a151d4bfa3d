"""Standstill detection from the IMU, for ZUPT and ZARU.

The IMU is cut into blocks of ``window_s``; a block is still when, on every axis, the standard
deviation of the specific force is at most ``max(accel_floor, k * sigma_a)`` and that of the
rate at most ``max(gyro_floor, k * sigma_g)``, and the mean rate is below ``max_rate``.
``sigma_a = VRW / sqrt(dt)`` and ``sigma_g = ARW / sqrt(dt)`` are the per-sample white noise of
the configured IMU grade, so the thresholds scale with it; the floors stand for the engine's
vibration, which the datasheet does not give.  A sample is still when its block and both
neighbours are (a stop is confirmed from both sides, so braking into it and pulling away do not
count).

Smooth motion at constant speed is as quiet as a stop for an IMU; the engine therefore also
requires the filter's own speed, and the GNSS speed when the log has velocity, to be near zero
and known to be so before it applies a ZUPT or ZARU (:func:`speed_allows`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StandstillSettings:
    """Detector thresholds (SI): ``window_s`` s; ``k`` multiples of the per-sample white-noise
    sigma; ``accel_floor`` m/s^2 and ``gyro_floor`` rad/s (standard-deviation floors);
    ``max_rate`` rad/s (mean rate); ``max_speed`` m/s (filter / GNSS speed gate)."""

    window_s: float = 0.5
    k: float = 4.0
    accel_floor: float = 0.05
    gyro_floor: float = math.radians(0.5)
    max_rate: float = math.radians(1.0)
    max_speed: float = 0.2


def quiet_blocks(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, window_s: float, thr_a: float,
                 thr_g: float, max_rate: float) -> tuple[int, np.ndarray]:
    """The IMU cut into blocks of ``window_s``: ``(w, quiet)``, ``w`` samples per block and, per
    block, whether every specific-force axis has a standard deviation <= ``thr_a`` (m/s^2), every
    rate axis <= ``thr_g`` (rad/s) and the mean rate magnitude per axis < ``max_rate`` (rad/s).
    Shared by the alignment's still-period search and :func:`still_mask`."""
    n = t.shape[0]
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    w = max(2, int(round(window_s / dt)))
    nb = n // w
    quiet = np.empty(nb, bool)
    chunk = max(1, 20000 // w)               # blocks per pass: bounded temporaries on long logs
    for b0 in range(0, nb, chunk):
        b1 = min(nb, b0 + chunk)
        a = accel[b0 * w: b1 * w].reshape(b1 - b0, w, 3)
        g = gyro[b0 * w: b1 * w].reshape(b1 - b0, w, 3)
        quiet[b0:b1] = ((a.std(axis=1).max(axis=1) <= thr_a) & (g.std(axis=1).max(axis=1) <= thr_g)
                        & (np.abs(g.mean(axis=1)).max(axis=1) < max_rate))
    return w, quiet


def still_mask(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, gyro_arw: float, accel_vrw: float,
               settings: StandstillSettings) -> np.ndarray:
    """(N,) bool: which IMU samples are still (see the module docstring).

    ``t`` (N,) s; ``gyro`` (N, 3) rad/s; ``accel`` (N, 3) m/s^2, body FLU; ``gyro_arw``
    rad/sqrt(s); ``accel_vrw`` m/s/sqrt(s).
    """
    n = t.shape[0]
    out = np.zeros(n, bool)
    if n < 3:
        return out
    dt = float(np.median(np.diff(t)))
    thr_a = max(settings.accel_floor, settings.k * accel_vrw / math.sqrt(dt))
    thr_g = max(settings.gyro_floor, settings.k * gyro_arw / math.sqrt(dt))
    w, still = quiet_blocks(t, gyro, accel, settings.window_s, thr_a, thr_g, settings.max_rate)
    nb = still.shape[0]
    if nb < 3:
        return out
    confirmed = still.copy()
    confirmed[1:] &= still[:-1]
    confirmed[:-1] &= still[1:]
    confirmed[0] = confirmed[-1] = False
    out[:nb * w] = np.repeat(confirmed, w)
    return out


def speed_allows(speed: float, speed_std: float, settings: StandstillSettings) -> bool:
    """The speed gate: a speed estimate (m/s, with its 1-sigma) that says the vehicle is (nearly)
    still, ``speed <= max_speed`` with ``sigma <= 2 max_speed``.  An uncertain speed allows
    nothing: a filter whose covariance has grown (a long outage, a fading filter) would otherwise
    accept a ZUPT while cruising, and a wrong ZUPT feeds its own error."""
    return speed <= settings.max_speed and speed_std <= 2.0 * settings.max_speed
