"""Bad inputs, round two (issue 15), points 1, 2, 6 and part of 12: inputs on which a filter
used to write a plausible-looking but wrong trajectory (adaptive filters that learn the error
away, GNSS standard deviations in cm, FRD data declared FLU, zero IMU noise) or a misleading
message (lat/lon swapped, latitude in radians, identical fixes).  Each row: exit code 1, one
``navpp:`` line holding the fragments, nothing written, inputs untouched (tests/badinputs.py)."""

from __future__ import annotations

import math

import pytest
from badinputs import Case, copy_drive, edit_csv, params, run_case


def _cols(edit):
    """An edit of every data row of a CSV file given as ``edit(header, values) -> values``."""
    def fn(lines):
        head = lines[0].split(",")
        out = [lines[0]]
        for ln in lines[1:]:
            if ln.strip():
                out.append(",".join(edit(head, ln.split(","))))
        return out
    return fn


def _scale(names, factor):
    def edit(head, v):
        for n in names:
            i = head.index(n)
            v[i] = repr(float(v[i]) * factor)
        return v
    return edit


def _swap(a, b):
    def edit(head, v):
        i, j = head.index(a), head.index(b)
        v[i], v[j] = v[j], v[i]
        return v
    return edit


def _chain(*edits):
    def edit(head, v):
        for e in edits:
            v = e(head, v)
        return v
    return edit


def _argv(work, log, *extra):
    return ["process", str(log), "--out", str(work / "out"), *extra]


def _drive(filt, edit):
    """A row's build step: a copy of the sample drive changed by ``edit(log_dir)``, processed
    with the filter ``filt``."""
    def build(work):
        log = copy_drive(work)
        edit(log)
        return _argv(work, log, "--filter", filt)
    return build


def _csv(name, fn):
    """An ``edit(log_dir)`` that rewrites the log's CSV file ``name`` through ``fn(lines)``."""
    def edit(log):
        edit_csv(log / name, fn)
    return edit


#: what the refusal of a 10x gyro says (the track's turns against the gyro's)
GYRO_X10_SAYS = ("turns 0.0", "the gyro reads 10.", "gyro columns' unit and scale", "gyro_units")


def gyro_x10(filt):
    return _drive(filt, _csv("imu.csv", _cols(_scale(("gx", "gy", "gz"), 10.0))))


def imu_xy_swapped(filt):
    return _drive(filt, _csv("imu.csv", _cols(_chain(_swap("gx", "gy"), _swap("ax", "ay")))))


def latlon_swapped(filt):
    return _drive(filt, _csv("gnss.csv", _cols(_swap("lat", "lon"))))


def lat_in_radians(filt):
    return _drive(filt, _csv("gnss.csv", _cols(_scale(("lat", "lon"), math.pi / 180.0))))


def first_fix_elsewhere(filt):
    def fn(lines):
        v = lines[1].split(",")
        v[1], v[2] = "-33.9", "151.2"        # Sydney, for a drive near Turin
        return [lines[0], ",".join(v), *lines[2:]]
    return _drive(filt, _csv("gnss.csv", fn))


def std_x100(filt):
    return _drive(filt, _csv("gnss.csv", _cols(_scale(("std_e", "std_n", "std_u"), 100.0))))


def frd_as_flu(filt):
    """Forward-right-down samples declared forward-left-up, with ``[auto] mounting`` off (on, the
    run rotates the IMU itself and says so: tests/test_calibrate.py)."""
    def edit(log):
        edit_csv(log / "imu.csv", _cols(_scale(("gy", "gz", "ay", "az"), -1.0)))
        with open(log / "navpp.toml", "a") as f:
            f.write("\n[auto]\nmounting = false\n")
    return _drive(filt, edit)


def zero_noise(filt, keys=("gyro_arw_deg_per_sqrt_h", "accel_vrw_mps_per_sqrt_h")):
    def edit(log):
        text = (log / "navpp.toml").read_text().replace("[imu]\n", "[imu]\n" + "".join(f"{k} = 0\n" for k in keys))
        (log / "navpp.toml").write_text(text)
    return _drive(filt, edit)


def identical_fixes(filt):
    def fn(lines):
        first = lines[1].split(",")
        return [lines[0]] + [",".join([ln.split(",")[0], *first[1:]]) for ln in lines[1:] if ln.strip()]
    return _drive(filt, _csv("gnss.csv", fn))


CASES = [
    Case("sage-husa-gyro-x10", gyro_x10("sage-husa"), GYRO_X10_SAYS),
    Case("aekf-imu-xy-swapped", imu_xy_swapped("aekf"), ("aekf diverged", "configured GNSS sigma", "mounting_rpy_deg")),
    Case("aukf-gyro-x10", gyro_x10("aukf"), GYRO_X10_SAYS),
    Case("latlon-swapped", latlon_swapped("sage-husa"), ("gnss.csv", "lat and lon swapped")),
    Case("first-fix-elsewhere", first_fix_elsewhere("sage-husa"), ("sage-husa diverged", "configured GNSS sigma")),
    Case("first-fix-elsewhere-ekf", first_fix_elsewhere("ekf"), "ekf diverged", slow=True),
    Case("std-x100", std_x100("ekf"), ("std_e, std_n, std_u of gnss.csv", "too large")),
    Case("std-x100-sage-husa", std_x100("sage-husa"), ("std_e, std_n, std_u of gnss.csv", "too large"), slow=True),
    Case("frd-as-flu", frd_as_flu("ekf"), ("-z", "forward-left-up", "mounting_rpy_deg = [180, 0, 0]")),
    Case("zero-noise", zero_noise("ekf"), ("navpp.toml", "gyro_arw_deg_per_sqrt_h = 0")),
    Case("zero-accel-noise", zero_noise("ekf", ("accel_vrw_mps_per_sqrt_h",)),
         ("navpp.toml", "accel_vrw_mps_per_sqrt_h"), slow=True),
    Case("lat-in-radians", lat_in_radians("ekf"), ("gnss.csv", "radians")),
    Case("lat-in-radians-sage-husa", lat_in_radians("sage-husa"), ("gnss.csv", "radians"), slow=True),
    Case("identical-fixes", identical_fixes("ekf"), ("all 1501 fixes of gnss.csv are identical",)),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input(case, tmp_path):
    run_case(case, tmp_path)
