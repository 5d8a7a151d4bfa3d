"""The replay engine: the only code that knows time.

Merges IMU and GNSS on the recording's relative time axis, aligns, then for every GNSS epoch
inside the IMU span predicts through the IMU samples up to the exact epoch (the IMU is
interpolated to it), builds the GNSS measurement (lever arm, per-epoch std or the config
default) and lets the filter gate and apply it; the aids (:mod:`navpp.aiding`) add their
epochs.  Closed-loop feedback happens inside the filter's ``correct`` (``x ⊞ K nu``).  The
nominal state at every IMU sample is recorded as the model propagates; position 1-sigma at each
sample interpolates the variance between the posterior of the previous epoch and the prior of
the next.

Modules, one job each:

- :mod:`~navpp.engine.run` — :func:`run`: the steps from a recording to a :class:`RunResult`;
- :mod:`~navpp.engine.segments` — a log cut at IMU gaps the INS cannot bridge, run piecewise;
- :mod:`~navpp.engine.checks` — checks of the input data (findings, or an InputError);
- :mod:`~navpp.engine.prepare` — mounting, noise model, alignment settings, timing fixes, calibration;
- :mod:`~navpp.engine.mounting` — the vehicle mounting's first pass;
- :mod:`~navpp.engine.schedule` — the GNSS fixes used and the epochs the filter stops at;
- :mod:`~navpp.engine.loop` — the loop that runs a filter over a schedule;
- :mod:`~navpp.engine.measurements` — the run's measurements per epoch (fix, velocity, aids, recovery);
- :mod:`~navpp.engine.recorder` — the output arrays the loop fills;
- :mod:`~navpp.engine.output` — smoothing, sigma interpolation, conversion to the solution;
- :mod:`~navpp.engine.verdict` — the checks of the result and the refusal of a wrong run;
- :mod:`~navpp.engine.results` — the result types.
"""

from __future__ import annotations

from .checks import check_data, check_imu_plausible
from .output import solution_from_path
from .prepare import HEADING_FLOOR_DEG, alignment_settings, mounting_matrix, noise_model, timing_fixes
from .results import BiasHistory, Diagnostics, RunResult, SmoothedRun
from .run import run
from .schedule import KNOT_S
from .segments import ProgressFn, imu_segments

__all__ = ["HEADING_FLOOR_DEG", "KNOT_S", "BiasHistory", "Diagnostics", "ProgressFn", "RunResult", "SmoothedRun",
           "alignment_settings", "check_data", "check_imu_plausible", "imu_segments", "mounting_matrix",
           "noise_model", "run", "solution_from_path", "timing_fixes"]
