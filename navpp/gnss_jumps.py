"""GNSS jumps no motion explains: a fix farther from the previous one than the vehicle can move.

Two fixes ``i`` and ``j`` are *consistent* when their 3-D distance (m, ECEF chord) is at most

    ``MAX_SPEED_MPS[vehicle type] * (t_j - t_i) + JUMP_SIGMAS * sqrt(s_i^2 + s_j^2)``

with ``s`` the 3-D 1-sigma of a fix (m; the per-fix standard deviations, else ``[gnss]
default_std_m``).  A jump is a pair of consecutive fixes that are not.  What follows a jump
decides what it is:

- the fixes come back (a later fix within ``[gnss] reanchor_after_s`` of the jump is consistent
  with the fix before it): an outlier or a short burst, which the innovation gate rejects
  fix by fix;
- they stay displaced for longer than that: the gate would give way and re-anchor the filter on
  the displaced fixes (the path jumps across the globe and ends with a small sigma), so the log
  is inconsistent and the run is refused, naming the first fix of the jump.

A short displaced run at the very start of the log (up to ``reanchor_after_s``) is left to the
alignment and the gate as well: there is no earlier fix to say which side is right.

Cost: O(M) vectorised over the fixes, plus, per jump, one vectorised look over the fixes within
``reanchor_after_s`` after it.
"""

from __future__ import annotations

import numpy as np

from . import geodesy
from .errors import InputError
from .recording import Recording

#: The fastest a vehicle of each ``[vehicle] type`` moves, m/s: generous bounds (a car at
#: 360 km/h; any other platform navpp serves, from a pedestrian to a helicopter, at the speed of
#: sound), since the check is for jumps no motion explains, not for a fast vehicle.
MAX_SPEED_MPS = {"car": 100.0, "none": 340.0}
#: Sigmas of the two fixes' combined position noise a consistent pair may differ by.
JUMP_SIGMAS = 5.0


def _consistent(p: np.ndarray, t: np.ndarray, s: np.ndarray, i: int, j: np.ndarray, vmax: float) -> np.ndarray:
    """Whether fix ``i`` is consistent with each fix in ``j`` (see the module docstring)."""
    dist = np.linalg.norm(p[j] - p[i], axis=1)
    return dist <= vmax * np.abs(t[j] - t[i]) + JUMP_SIGMAS * np.hypot(s[i], s[j])


def check_gnss_jumps(recording: Recording, vehicle_type: str, default_std_m, reanchor_after_s: float,
                     std_scale: float = 1.0) -> None:
    """Raise InputError when the GNSS fixes inside the IMU span jump by more than any motion
    explains and stay displaced for longer than ``reanchor_after_s`` (s); see the module
    docstring.  Outliers and short bursts are left to the innovation gate.  The log's sigmas are
    taken times ``std_scale`` (``[gnss] std_scale``), as the filter takes them."""
    gnss, imu = recording.gnss, recording.imu
    if len(gnss) < 2 or len(imu) < 2:
        return
    inside = np.nonzero((gnss.t >= imu.t[0]) & (gnss.t <= imu.t[-1]))[0]
    if inside.size < 2:
        return
    t = np.asarray(gnss.t[inside], dtype=float)
    p = geodesy.geodetic_to_ecef(np.radians(gnss.lat_deg[inside]), np.radians(gnss.lon_deg[inside]),
                                 np.asarray(gnss.alt[inside], dtype=float))
    std = (np.asarray(gnss.std_enu[inside], dtype=float) * std_scale if gnss.std_enu is not None
           else np.tile(np.asarray(default_std_m, dtype=float), (inside.size, 1)))
    s = np.linalg.norm(std, axis=1)
    vmax = MAX_SPEED_MPS.get(vehicle_type, MAX_SPEED_MPS["none"])
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    ok = step <= vmax * np.diff(t) + JUMP_SIGMAS * np.hypot(s[:-1], s[1:])
    jumps = np.nonzero(~ok)[0]
    resolved_to = -1                       # fixes up to this index are explained already
    for k in (int(j) for j in jumps):
        if k < resolved_to:
            continue
        if t[k] - t[0] <= reanchor_after_s and _leading_run(p, t, s, k, vmax, reanchor_after_s):
            resolved_to = k + 1
            continue
        hi = int(np.searchsorted(t, t[k + 1] + reanchor_after_s, side="right"))
        later = np.arange(k + 2, hi)
        back = later[_consistent(p, t, s, k, later, vmax)] if later.size else later
        if back.size:
            resolved_to = int(back[0])
            continue
        dist = float(step[k])
        at = recording.absolute_time(t[k + 1])
        raise InputError(
            f"{recording.source}: GNSS: the fix at t = {t[k + 1]:.3f} s (stamp {at:.3f}) lies {_km(dist)} from the one "
            f"{t[k + 1] - t[k]:.3g} s before, more than a {vehicle_type if vehicle_type != 'none' else 'vehicle'} "
            f"moves ({vmax:g} m/s), and the fixes stay displaced for over {reanchor_after_s:g} s: the GNSS log is "
            "inconsistent")


def _leading_run(p, t, s, k: int, vmax: float, window_s: float) -> bool:
    """Whether the fixes before jump ``k`` are a short displaced run at the start of the log: the
    fixes after the jump agree with each other for at least as long."""
    hi = int(np.searchsorted(t, t[k + 1] + window_s, side="right"))
    after = np.arange(k + 2, hi)
    return bool(after.size == 0 or np.all(_consistent(p, t, s, k + 1, after, vmax)))


def _km(dist_m: float) -> str:
    return f"{dist_m / 1000.0:,.0f} km" if dist_m >= 10_000.0 else f"{dist_m:.0f} m"


__all__ = ["JUMP_SIGMAS", "MAX_SPEED_MPS", "check_gnss_jumps"]
