"""navpp: post-processing of inertial navigation logs (strapdown INS + loosely coupled GNSS).

Data contract
-------------
Frames
    Navigation frame: local-level ENU (east, north, up). Body frame: FLU (x forward, y left,
    z up), as ROS REP-103/105. A vector ``v`` resolved in frame ``a`` is written ``v_a`` or
    named for its frame (``vel_enu``); a rotation projecting frame ``b`` into ``a`` is ``mat_ab``
    (``mat_nb``: body -> navigation). Quaternions are scalar first ``[w, x, y, z]``.
Positions
    WGS-84 geodetic: latitude and longitude in radians inside the numerics and in degrees where
    a name ends in ``_deg`` (and in every file), height in metres above the ellipsoid. Errors and
    offsets are local ENU metres.
Angles for people
    roll (right side down positive), pitch (nose up positive), heading (clockwise from north),
    in degrees, in files and reports; ``mat_nb = Rz(pi/2 - heading) Ry(-pitch) Rx(roll)``.
Units
    SI inside navpp (rad, rad/s, m, m/s, m/s^2, s). Datasheet units (deg/sqrt(h), deg/h,
    m/s/sqrt(h), mg) appear only in the config and are converted once, in :mod:`navpp.config`.
Time
    Integer nanoseconds on the log's own time base at the I/O boundary (``Recording.t0_ns``);
    float seconds relative to the first IMU sample inside the numerics; outputs are written
    back on the log's own time base.
Error state (15 elements, in this order)
    attitude error phi (ENU, rad; ``C_true = exp([phi x]) C_est``), velocity error (ENU, m/s),
    position error (ENU, m), gyro bias (body, rad/s), accelerometer bias (body, m/s^2).

Public API
----------
``navpp.process(log, filter_name="ekf", formats=None, ...)`` -> :class:`navpp.api.ProcessResult`
(:func:`navpp.api.process`): ``result.trajectory`` and ``result.diagnostics`` are pandas
DataFrames with the columns of ``trajectory.csv`` / ``diagnostics.csv`` (``t`` in seconds on
the log's time base), ``result.metrics`` the dict of ``metrics.json`` (None without a
reference)::

    import navpp
    res = navpp.process("drive.mcap", filter_name="aekf", formats="csv,tum,geojson")
    res.trajectory[["t", "lat", "lon"]]

``navpp.compare(logs, filters, ...)`` runs several filters on several logs
(:func:`navpp.comparison.compare`); ``navpp.simulate_log(out, **spec)``; the containers in
:mod:`navpp.recording`; the filter registry ``navpp.filters.FILTERS``.  Heavy modules are
imported on first use, so ``import navpp`` (and ``navpp --help``) stays fast.
"""

from __future__ import annotations

from typing import Any

__all__ = ["__version__", "compare", "process", "simulate_log"]

from .jitcache import configure as _configure_jit_cache  # before any module imports numba
from .version import __version__

_configure_jit_cache()


def _compare(*args: Any, **kwargs: Any) -> Any:
    """Run several filters on several logs: :func:`navpp.comparison.compare` (see its docstring).

    Resolved when called, so ``navpp.compare`` exists before :mod:`navpp.comparison` is imported.
    """
    from .comparison import compare

    return compare(*args, **kwargs)


def __getattr__(name: str) -> Any:
    if name in ("process", "simulate_log"):
        from . import api

        return getattr(api, name)
    if name == "compare":
        try:
            from .comparison import compare
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.comparison":
                raise
            return _compare          # not there yet: look again at call time
        return compare
    raise AttributeError(f"module 'navpp' has no attribute {name!r}")
