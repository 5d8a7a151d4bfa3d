"""CSV log reader: round trips, increments, units, warnings, and every validation error."""

from __future__ import annotations

import re
from collections.abc import Sequence
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navpp.errors import ConfigError, InputError
from navpp.io.csv import increments_to_rates, is_csv_log, read_csv_log, read_reference_csv

T0 = 1_700_000_000.25  # exactly representable; t0_ns must come out exact
IMU_HEADER = ["t", "gx", "gy", "gz", "ax", "ay", "az"]
INC_HEADER = ["t", "dthx", "dthy", "dthz", "dvx", "dvy", "dvz"]
GNSS_HEADER = ["t", "lat", "lon", "alt"]


def _cell(v: object) -> str:
    return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> Path:
    """Write by hand: floats as repr (round-trip exact), strings as given."""
    lines = [",".join(header)] + [",".join(_cell(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def imu_rows(n: int = 10, dt: float = 0.01, t0: float = T0) -> list[list[object]]:
    return [[t0 + k * dt, 0.01 * k, -0.02, 0.03, 0.1, -0.2, 9.8] for k in range(n)]


def gnss_rows(n: int = 3, dt: float = 0.03, t0: float = T0 + 0.01) -> list[list[object]]:
    return [[t0 + k * dt, 30.5 + 1e-6 * k, 114.25, 20.0] for k in range(n)]


def make_log(
    tmp_path: Path,
    *,
    imu: tuple[Sequence[str], Sequence[Sequence[object]]] | None = None,
    gnss: tuple[Sequence[str], Sequence[Sequence[object]]] | None = None,
    ref: tuple[Sequence[str], Sequence[Sequence[object]]] | None = None,
) -> Path:
    d = tmp_path / "log"
    d.mkdir(exist_ok=True)
    write_csv(d / "imu.csv", *(imu or (IMU_HEADER, imu_rows())))
    write_csv(d / "gnss.csv", *(gnss or (GNSS_HEADER, gnss_rows())))
    if ref is not None:
        write_csv(d / "reference.csv", *ref)
    return d


# ------------------------------------------------------------------------------------------
# happy paths
# ------------------------------------------------------------------------------------------


def test_round_trip_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    n = 50
    t = T0 + np.arange(n) * 0.008
    gyro = rng.normal(size=(n, 3))
    accel = rng.normal(size=(n, 3)) + [0, 0, 9.8]
    imu = pd.DataFrame(np.column_stack([t, gyro, accel]), columns=IMU_HEADER)
    m = 5
    tg = T0 + 0.004 + np.arange(m) * 0.05
    g = {
        "t": tg, "lat": rng.uniform(-90, 90, m), "lon": rng.uniform(-180, 180, m),
        "alt": rng.normal(100, 10, m), "std_e": rng.uniform(0, 2, m), "std_n": rng.uniform(0, 2, m),
        "std_u": rng.uniform(0, 2, m), "ve": rng.normal(size=m), "vn": rng.normal(size=m),
        "vu": rng.normal(size=m), "std_ve": rng.uniform(0, 1, m), "std_vn": rng.uniform(0, 1, m),
        "std_vu": rng.uniform(0, 1, m), "fix": [4, 5, 4, 1, 4], "num_sats": [12, 11, 9, 7, 15],
    }
    gnss = pd.DataFrame(g)
    d = tmp_path / "log"
    d.mkdir()
    imu.to_csv(d / "imu.csv", index=False)
    gnss.to_csv(d / "gnss.csv", index=False)

    rec = read_csv_log(d, time_base="gpst")

    assert rec.t0_ns == 1_700_000_000_250_000_000
    assert rec.time_base == "gpst"
    assert rec.source == str(d)
    assert rec.warnings == ()
    assert rec.reference is None
    text_t = [Decimal(line.split(",")[0]) for line in (d / "imu.csv").read_text().splitlines()[1:]]
    np.testing.assert_allclose(rec.imu.t, [float(v - text_t[0]) for v in text_t], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rec.imu.gyro, gyro)
    np.testing.assert_array_equal(rec.imu.accel, accel)
    text_g = [Decimal(line.split(",")[0]) for line in (d / "gnss.csv").read_text().splitlines()[1:]]
    np.testing.assert_allclose(rec.gnss.t, [float(v - text_t[0]) for v in text_g], rtol=0, atol=1e-12)
    for name, key in [("lat_deg", "lat"), ("lon_deg", "lon"), ("alt", "alt")]:
        np.testing.assert_array_equal(getattr(rec.gnss, name), g[key])
    np.testing.assert_array_equal(rec.gnss.std_enu, np.column_stack([g["std_e"], g["std_n"], g["std_u"]]))
    np.testing.assert_array_equal(rec.gnss.vel_enu, np.column_stack([g["ve"], g["vn"], g["vu"]]))
    np.testing.assert_array_equal(
        rec.gnss.std_vel_enu, np.column_stack([g["std_ve"], g["std_vn"], g["std_vu"]])
    )
    np.testing.assert_array_equal(rec.gnss.fix, g["fix"])
    np.testing.assert_array_equal(rec.gnss.num_sats, g["num_sats"])
    assert rec.gnss.fix is not None and rec.gnss.fix.dtype.kind == "i"
    np.testing.assert_allclose(rec.absolute_time(rec.gnss.t), tg, rtol=0, atol=1e-6)


def test_t0_ns_is_exact_value_of_the_stamp(tmp_path: Path) -> None:
    t0 = 1_700_000_000.123456
    d = make_log(tmp_path, imu=(IMU_HEADER, imu_rows(t0=t0)), gnss=(GNSS_HEADER, gnss_rows(t0=t0)))
    rec = read_csv_log(d)
    # the decimal text of the stamp, exactly: not float64's nearest value (~100 ns off here)
    assert rec.t0_ns == 1_700_000_000_123_456_000
    assert round(Fraction(t0) * 10**9) != rec.t0_ns


def test_stamps_with_more_decimals_than_float64_holds_are_exact(tmp_path: Path) -> None:
    d = tmp_path / "log"
    d.mkdir()
    stamps = [f"1700000000.{k:09d}" for k in (1, 8000003, 16000007, 24000011)]   # ns resolution
    rows = "\n".join(f"{s},0,0,0,0,0,9.8" for s in stamps)
    (d / "imu.csv").write_text("t,gx,gy,gz,ax,ay,az\n" + rows + "\n")
    (d / "gnss.csv").write_text(f"t,lat,lon,alt\n{stamps[1]},45,7,300\n")
    rec = read_csv_log(d)
    assert rec.t0_ns == 1_700_000_000_000_000_001
    np.testing.assert_allclose(rec.imu.t * 1e9, [0, 8000002, 16000006, 24000010], rtol=0, atol=1e-6)


def test_optional_columns_absent_give_none(tmp_path: Path) -> None:
    rec = read_csv_log(make_log(tmp_path))
    g = rec.gnss
    assert g.std_enu is None and g.vel_enu is None and g.std_vel_enu is None
    assert g.fix is None and g.num_sats is None


def test_header_blanks_bom_crlf_and_trailing_blank_lines(tmp_path: Path) -> None:
    d = make_log(tmp_path)
    rows = imu_rows(4)
    text = "\ufeff" + " t , gx, gy, gz, ax, ay, az\r\n"
    text += "".join(",".join(repr(v) for v in r) + "\r\n" for r in rows) + "\r\n\r\n"
    (d / "imu.csv").write_text(text, newline="")
    rec = read_csv_log(d)
    assert len(rec.imu) == 4
    np.testing.assert_array_equal(rec.imu.gyro[:, 0], [r[1] for r in rows])


def test_reference_auto_pickup(tmp_path: Path) -> None:
    ref_rows = [[T0 + 0.02 * k, 30.5, 114.25, 20.0, 1.0, 2.0, 0.0, 1.0, -2.0, 270.0] for k in range(4)]
    header = ["t", "lat", "lon", "alt", "ve", "vn", "vu", "roll", "pitch", "heading"]
    d = make_log(tmp_path, ref=(header, ref_rows))
    rec = read_csv_log(d)
    ref = rec.reference
    assert ref is not None
    assert ref.source == str(d / "reference.csv")
    # the stamps as written (decimal text), not float64's nearest values: exactly k * 0.02 s
    np.testing.assert_allclose(ref.t, 0.02 * np.arange(4), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ref.vel_enu, [[1.0, 2.0, 0.0]] * 4)
    np.testing.assert_array_equal(ref.rph_deg, [[1.0, -2.0, 270.0]] * 4)


def test_reference_override_and_none(tmp_path: Path) -> None:
    d = make_log(tmp_path, ref=(GNSS_HEADER, [[T0, 1.0, 2.0, 3.0]]))
    other = write_csv(tmp_path / "truth.csv", GNSS_HEADER, [[T0 + 1.0, 10.0, 20.0, 30.0]])
    rec = read_csv_log(d, reference=other)
    assert rec.reference is not None
    assert rec.reference.source == str(other)
    np.testing.assert_array_equal(rec.reference.lat_deg, [10.0])
    np.testing.assert_array_equal(rec.reference.t, [1.0])
    assert rec.reference.vel_enu is None and rec.reference.rph_deg is None

    (d / "reference.csv").unlink()
    assert read_csv_log(d).reference is None


def test_read_reference_csv_relative_to_t0_ns_and_warnings(tmp_path: Path) -> None:
    p = write_csv(tmp_path / "r.csv", [*GNSS_HEADER, "quality"], [[T0 + 0.5, 1.0, 2.0, 3.0, 1],
                                                                  [T0 + 0.5, 1.0, 2.0, 3.0, 1],
                                                                  [T0 + 1.5, 1.0, 2.0, 3.0, 1]])
    out: list[str] = []
    ref = read_reference_csv(p, 1_700_000_000_250_000_000, warnings_out=out)
    np.testing.assert_array_equal(ref.t, [0.5, 1.5])
    assert any("r.csv" in w and "'quality'" in w for w in out)
    assert any("dropped 1 duplicate timestamp (first at line 3)" in w for w in out)
    assert len(read_reference_csv(p, 1_700_000_000_250_000_000)) == 2


def test_is_csv_log(tmp_path: Path) -> None:
    d = make_log(tmp_path)
    assert is_csv_log(d)
    assert not is_csv_log(d / "imu.csv")
    (d / "gnss.csv").unlink()
    assert not is_csv_log(d)
    assert not is_csv_log(tmp_path / "nowhere")


# ------------------------------------------------------------------------------------------
# increments
# ------------------------------------------------------------------------------------------


def _increment_log(tmp_path: Path, t: np.ndarray, a: np.ndarray, b: np.ndarray) -> Path:
    """Increments of the rate a + b t (per column), integrated exactly over each interval."""
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    mid = t - dt / 2
    inc = (a + b * mid[:, None]) * dt[:, None]
    return make_log(
        tmp_path,
        imu=(INC_HEADER, np.column_stack([t, inc]).tolist()),
        gnss=(GNSS_HEADER, gnss_rows(t0=float(t[2]))),
    )


def test_increments_constant_rate(tmp_path: Path) -> None:
    t = 10.0 + np.arange(20) * 0.01
    rate = np.array([0.1, -0.2, 0.3, 0.5, -1.0, 9.8])
    d = _increment_log(tmp_path, t, rate, np.zeros(6))
    rec = read_csv_log(d, time_base="relative")
    assert len(rec.imu) == 19  # first row dropped
    assert rec.t0_ns == 10_010_000_000                      # "10.01" as written
    np.testing.assert_allclose(rec.imu.t, 0.01 * np.arange(19), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.imu.gyro, np.tile(rate[:3], (19, 1)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.imu.accel, np.tile(rate[3:], (19, 1)), rtol=0, atol=1e-12)


@pytest.mark.parametrize("jitter", [0.0, 0.3])
def test_increments_linear_rate(tmp_path: Path, jitter: float) -> None:
    rng = np.random.default_rng(7)
    dt = 0.01 * (1.0 + jitter * rng.uniform(-1, 1, 40))
    t = 5.0 + np.cumsum(dt)
    a = np.array([0.1, -0.2, 0.3, 0.5, -1.0, 9.8])
    b = np.array([0.5, 1.0, -2.0, 0.25, 3.0, -0.1])
    d = _increment_log(tmp_path, t, a, b)
    rec = read_csv_log(d, time_base="relative")
    rates = np.column_stack([rec.imu.gyro, rec.imu.accel])
    expected = a + b * t[1:, None]
    # interior samples: the analytic rate at the stamp (uniform or jittered spacing)
    np.testing.assert_allclose(rates[:-1], expected[:-1], rtol=0, atol=1e-12)
    # last sample: its own interval's mean rate = the rate at the interval's midpoint
    np.testing.assert_allclose(rates[-1], a + b * (t[-1] + t[-2]) / 2, rtol=0, atol=1e-12)


def test_increments_to_rates_uniform_is_plain_average() -> None:
    t = np.arange(6) * 0.5
    inc = np.array([[9.0], [1.0], [2.0], [4.0], [1.0], [3.0]])
    t_out, rates = increments_to_rates(t, inc)
    mean = inc[1:, 0] / 0.5
    np.testing.assert_array_equal(t_out, t[1:])
    np.testing.assert_allclose(rates[:, 0], [*((mean[:-1] + mean[1:]) / 2), mean[-1]], rtol=1e-15)
    with pytest.raises(ValueError):
        increments_to_rates(t[:2], inc[:2])


def test_increments_units(tmp_path: Path) -> None:
    t = 10.0 + np.arange(5) * 0.01
    rate = np.array([1.0, 2.0, 3.0, 0.5, 1.0, -1.0])  # deg/s and g
    d = _increment_log(tmp_path, t, rate, np.zeros(6))
    rec = read_csv_log(d, time_base="relative", gyro_units="deg/s", accel_units="g")
    np.testing.assert_allclose(rec.imu.gyro, np.tile(rate[:3] * np.pi / 180, (4, 1)), rtol=1e-12)
    np.testing.assert_allclose(rec.imu.accel, np.tile(rate[3:] * 9.80665, (4, 1)), rtol=1e-12)


# ------------------------------------------------------------------------------------------
# units, options, warnings
# ------------------------------------------------------------------------------------------


def test_units_deg_per_s_and_g(tmp_path: Path) -> None:
    rows = imu_rows(5)
    d = make_log(tmp_path, imu=(IMU_HEADER, rows))
    rec = read_csv_log(d, gyro_units="deg/s", accel_units="g")
    raw = np.array(rows, dtype=float)
    np.testing.assert_array_equal(rec.imu.gyro, raw[:, 1:4] * (np.pi / 180.0))
    np.testing.assert_array_equal(rec.imu.accel, raw[:, 4:7] * 9.80665)


@pytest.mark.parametrize(
    "kwargs, word",
    [({"time_base": "utc"}, "'utc'"), ({"gyro_units": "rpm"}, "'rpm'"), ({"accel_units": "mg"}, "'mg'")],
)
def test_bad_options_are_config_errors(tmp_path: Path, kwargs: dict[str, str], word: str) -> None:
    with pytest.raises(ConfigError, match=word):
        read_csv_log(make_log(tmp_path), **kwargs)


def test_extra_columns_named_once(tmp_path: Path) -> None:
    imu = [[*r, 25.0, k] for k, r in enumerate(imu_rows())]
    gnss = [[*r, "x", 1.2] for r in gnss_rows()]
    d = make_log(
        tmp_path,
        imu=([*IMU_HEADER, "temp", "seq"], imu),
        gnss=([*GNSS_HEADER, "label", "hdop"], gnss),
    )
    rec = read_csv_log(d)
    imu_w = [w for w in rec.warnings if "temp" in w]
    assert imu_w == ["imu.csv: ignoring extra column(s) 'temp', 'seq'"]
    assert [w for w in rec.warnings if "hdop" in w] == ["gnss.csv: ignoring extra column(s) 'label', 'hdop'"]
    assert len(rec.warnings) == 2


def test_trailing_comma_columns_are_ignored_silently(tmp_path: Path) -> None:
    d = make_log(tmp_path, imu=([*IMU_HEADER, ""], [[*r, ""] for r in imu_rows()]))
    assert read_csv_log(d).warnings == ()


def test_duplicate_timestamps_dropped_with_warning(tmp_path: Path) -> None:
    rows = imu_rows(10)
    rows = rows[:3] + [[rows[2][0], 9.0, 9.0, 9.0, 9.0, 9.0, 9.0]] * 2 + rows[3:6] + [rows[5]] + rows[6:]
    d = make_log(tmp_path, imu=(IMU_HEADER, rows))
    rec = read_csv_log(d)
    assert len(rec.imu) == 10
    assert 9.0 not in rec.imu.gyro
    assert any(w.startswith("imu.csv: dropped 3 duplicate timestamps (first at line 5); 2 are exact duplicate rows")
               and "line 6 = line 5" in w for w in rec.warnings), rec.warnings


def test_gap_warning(tmp_path: Path) -> None:
    rows = imu_rows(20, dt=0.01)
    for r in rows[12:]:
        r[0] += 0.5
    for r in rows[5:]:
        r[0] += 0.02  # a smaller gap: 0.03 s > 2.5 x 0.01
    d = make_log(tmp_path, imu=(IMU_HEADER, rows))
    rec = read_csv_log(d)
    (w,) = [w for w in rec.warnings if w.startswith("imu.csv") and "gap" in w]
    assert "2 gaps" in w and "100 Hz" in w
    assert f"largest 0.51 s from t={rows[11][0]!r} (line 13) to t={rows[12][0]!r} (line 14)" in w


def test_gnss_outside_imu_span_kept_and_warned_with_offset(tmp_path: Path) -> None:
    g = [[T0 - 1.0, 30.0, 114.0, 1.0], [T0 + 0.05, 30.0, 114.0, 1.0], [T0 + 5.0, 30.0, 114.0, 1.0],
         [T0 + 6.0, 30.0, 114.0, 1.0]]
    d = make_log(tmp_path, gnss=(GNSS_HEADER, g))
    rec = read_csv_log(d, time_offset_s=0.01)
    np.testing.assert_allclose(rec.gnss.t, [-0.99, 0.06, 5.01, 6.01], atol=1e-6)
    (w,) = [w for w in rec.warnings if "outside" in w]
    assert w.startswith("gnss.csv: 3 of 4 fixes") and "(1 before, 2 after" in w


# ------------------------------------------------------------------------------------------
# errors: each names the file, the column and the line (or time)
# ------------------------------------------------------------------------------------------


def _error(tmp_path: Path, **files: tuple[Sequence[str], Sequence[Sequence[object]]] | str) -> str:
    """Build a log (files given as (header, rows) or raw text), read it, return the error message."""
    d = make_log(tmp_path)
    for name, content in files.items():
        p = d / f"{name}.csv"
        if isinstance(content, str):
            p.write_text(content)
        else:
            write_csv(p, *content)
    with pytest.raises(InputError) as info:
        read_csv_log(d)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


def _assert_names(msg: str, file: str, column: str | None, line: int | None) -> None:
    assert file in msg, msg
    if column is not None:
        assert repr(column) in msg, msg
    if line is not None:
        assert re.search(rf"\bline {line}\b", msg), msg


def test_error_not_a_directory(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not a directory"):
        read_csv_log(make_log(tmp_path) / "imu.csv")


@pytest.mark.parametrize("name", ["imu.csv", "gnss.csv"])
def test_error_missing_file(tmp_path: Path, name: str) -> None:
    d = make_log(tmp_path)
    (d / name).unlink()
    with pytest.raises(InputError) as info:
        read_csv_log(d)
    assert str(d / name) in str(info.value) and "not found" in str(info.value)


def test_error_missing_explicit_reference(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"truth\.csv: file not found"):
        read_csv_log(make_log(tmp_path), reference=tmp_path / "truth.csv")


@pytest.mark.parametrize("name", ["imu", "gnss", "reference"])
def test_error_empty_file(tmp_path: Path, name: str) -> None:
    msg = _error(tmp_path, **{name: ""})
    _assert_names(msg, f"{name}.csv", None, 1)
    assert "empty file" in msg


@pytest.mark.parametrize("name, header", [("imu", IMU_HEADER), ("gnss", GNSS_HEADER), ("reference", GNSS_HEADER)])
def test_error_header_only(tmp_path: Path, name: str, header: list[str]) -> None:
    msg = _error(tmp_path, **{name: ",".join(header) + "\n"})
    _assert_names(msg, f"{name}.csv", None, 1)
    assert "not followed by any data row" in msg


def test_error_missing_imu_columns(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=(["t", "gx", "gy", "gz", "ax", "acc_y"], [[T0, 0, 0, 0, 0, 0]]))
    _assert_names(msg, "imu.csv", "ay", 1)
    assert "'az'" in msg and "found 't', 'gx', 'gy', 'gz', 'ax', 'acc_y'" in msg
    assert "dthx" in msg  # the increment alternative is mentioned


def test_error_missing_increment_columns(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=(["t", "dthx", "dthy", "dthz", "dvx", "dvy"], [[T0, 0, 0, 0, 0, 0]]))
    _assert_names(msg, "imu.csv", "dvz", 1)
    assert "'gx'" not in msg.split("expected")[0]


@pytest.mark.parametrize("name", ["gnss", "reference"])
def test_error_missing_position_columns(tmp_path: Path, name: str) -> None:
    msg = _error(tmp_path, **{name: (["t", "latitude", "lon", "alt"], [[T0, 1, 2, 3]])})
    _assert_names(msg, f"{name}.csv", "lat", 1)
    assert "'latitude'" in msg


@pytest.mark.parametrize(
    "name, extra, missing",
    [
        ("gnss", ["std_e", "std_n"], "std_u"),
        ("gnss", ["ve", "vu"], "vn"),
        ("gnss", ["ve", "vn", "vu", "std_vn"], "std_ve"),
        ("reference", ["roll", "pitch"], "heading"),
        ("reference", ["vn"], "ve"),
    ],
)
def test_error_partial_group(tmp_path: Path, name: str, extra: list[str], missing: str) -> None:
    msg = _error(tmp_path, **{name: ([*GNSS_HEADER, *extra], [[T0, 1, 2, 3, *[1] * len(extra)]])})
    _assert_names(msg, f"{name}.csv", missing, 1)


def test_error_velocity_std_without_velocity(tmp_path: Path) -> None:
    msg = _error(tmp_path, gnss=([*GNSS_HEADER, "std_ve", "std_vn", "std_vu"], [[T0, 1, 2, 3, 1, 1, 1]]))
    _assert_names(msg, "gnss.csv", "std_ve", 1)


def test_error_duplicate_column(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=([*IMU_HEADER, "gx"], [[*r, 0.0] for r in imu_rows()]))
    _assert_names(msg, "imu.csv", "gx", 1)


def test_error_non_numeric(tmp_path: Path) -> None:
    rows = imu_rows()
    rows[2][3] = "abc"
    rows[5][1] = "1..2"
    msg = _error(tmp_path, imu=(IMU_HEADER, rows))
    _assert_names(msg, "imu.csv", "gz", 4)
    assert "non-numeric value 'abc'" in msg


def test_error_non_numeric_gnss_time(tmp_path: Path) -> None:
    rows = gnss_rows()
    rows[1][0] = "2023-11-14T22:13:20"
    msg = _error(tmp_path, gnss=(GNSS_HEADER, rows))
    _assert_names(msg, "gnss.csv", "t", 3)
    assert "'2023-11-14T22:13:20'" in msg


@pytest.mark.parametrize(
    "value, column, line, what",
    [("", "ay", 5, "missing value"), ("nan", "ay", 5, "missing value"), ("inf", "ay", 5, "non-finite value inf"),
     ("-inf", "t", 5, "non-finite")],
)
def test_error_missing_or_non_finite(tmp_path: Path, value: str, column: str, line: int, what: str) -> None:
    rows = imu_rows()
    rows[line - 2][IMU_HEADER.index(column)] = value
    rows[line][2] = ""  # a later offender must not be the one reported
    msg = _error(tmp_path, imu=(IMU_HEADER, rows))
    _assert_names(msg, "imu.csv", column, line)
    assert what in msg


def test_error_blank_line_in_the_middle(tmp_path: Path) -> None:
    text = ",".join(GNSS_HEADER) + "\n" + f"{T0},1,2,3\n\n{T0 + 1},1,2,3\n"
    msg = _error(tmp_path, gnss=text)
    _assert_names(msg, "gnss.csv", "t", 3)
    assert "blank line" in msg


def test_error_short_row(tmp_path: Path) -> None:
    text = ",".join(GNSS_HEADER) + "\n" + f"{T0},1,2,3\n{T0 + 1},1,2\n"
    msg = _error(tmp_path, gnss=text)
    _assert_names(msg, "gnss.csv", "alt", 3)


def test_error_long_row(tmp_path: Path) -> None:
    text = ",".join(GNSS_HEADER) + "\n" + f"{T0},1,2,3\n{T0},1,2,3\n{T0 + 1},1,2,3,4\n"
    msg = _error(tmp_path, gnss=text)
    _assert_names(msg, "gnss.csv", None, 4)
    assert "5 fields" in msg and "4 columns" in msg


@pytest.mark.parametrize(
    "name, column, value",
    [("gnss", "lat", 90.5), ("gnss", "lat", -91.0), ("gnss", "lon", 360.0), ("gnss", "lon", -180.5),
     ("reference", "lat", 100.0), ("reference", "lon", 400.0)],
)
def test_error_lat_lon_range(tmp_path: Path, name: str, column: str, value: float) -> None:
    rows = gnss_rows(4)
    rows[2][GNSS_HEADER.index(column)] = value
    msg = _error(tmp_path, **{name: (GNSS_HEADER, rows)})
    _assert_names(msg, f"{name}.csv", column, 4)
    assert repr(value) in msg


def test_lat_lon_range_edges_accepted(tmp_path: Path) -> None:
    g = [[T0, -90.0, -180.0, 0.0], [T0 + 0.01, 90.0, 359.999, 0.0]]
    rec = read_csv_log(make_log(tmp_path, gnss=(GNSS_HEADER, g)))
    np.testing.assert_array_equal(rec.gnss.lon_deg, [-180.0, 359.999])


@pytest.mark.parametrize("column", ["std_n", "std_vu"])
def test_error_negative_std(tmp_path: Path, column: str) -> None:
    header = [*GNSS_HEADER, "std_e", "std_n", "std_u", "ve", "vn", "vu", "std_ve", "std_vn", "std_vu"]
    rows = [[*r, 1.0, 1.0, 2.0, 0.0, 0.0, 0.0, 0.1, 0.1, 0.2] for r in gnss_rows()]
    rows[1][header.index(column)] = -0.5
    msg = _error(tmp_path, gnss=(header, rows))
    _assert_names(msg, "gnss.csv", column, 3)
    assert "negative" in msg and "-0.5" in msg


@pytest.mark.parametrize("column", ["fix", "num_sats"])
def test_error_non_integer_flags(tmp_path: Path, column: str) -> None:
    rows = [[*r, 4, 10] for r in gnss_rows()]
    rows[2][-1 if column == "num_sats" else -2] = 4.5
    msg = _error(tmp_path, gnss=([*GNSS_HEADER, "fix", "num_sats"], rows))
    _assert_names(msg, "gnss.csv", column, 4)


@pytest.mark.parametrize("name", ["imu", "gnss", "reference"])
def test_error_time_goes_backwards(tmp_path: Path, name: str) -> None:
    header, rows = (IMU_HEADER, imu_rows()) if name == "imu" else (GNSS_HEADER, gnss_rows(5))
    rows[3][0] = rows[1][0] - 0.001
    msg = _error(tmp_path, **{name: (header, rows)})
    _assert_names(msg, f"{name}.csv", "t", 5)
    assert repr(rows[3][0]) in msg and repr(rows[2][0]) in msg and "line 4" in msg


def test_error_single_imu_sample(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=(IMU_HEADER, imu_rows(1)))
    _assert_names(msg, "imu.csv", "t", 2)
    assert "at least 2" in msg


def test_error_imu_single_after_duplicates(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=(IMU_HEADER, imu_rows(1) * 3))
    _assert_names(msg, "imu.csv", "t", 2)
    assert "1 distinct timestamp" in msg


def test_error_increments_need_three_rows(tmp_path: Path) -> None:
    msg = _error(tmp_path, imu=(INC_HEADER, [[T0, 0, 0, 0, 0, 0, 0], [T0 + 0.01, 0, 0, 0, 0, 0, 0]]))
    _assert_names(msg, "imu.csv", "t", None)
    assert "lines 2..3" in msg and "at least 3 rows" in msg


def test_error_not_utf8(tmp_path: Path) -> None:
    d = make_log(tmp_path)
    (d / "gnss.csv").write_bytes(b"\xff\xfe\x00\x01binary")
    with pytest.raises(InputError) as info:
        read_csv_log(d)
    _assert_names(str(info.value), "gnss.csv", None, 1)


def test_zero_std_is_an_error(tmp_path: Path) -> None:
    header = [*GNSS_HEADER, "std_e", "std_n", "std_u"]
    rows = [[*r, 1.0, 1.0, 2.0] for r in gnss_rows()]
    rows[2][header.index("std_u")] = 0.0
    msg = _error(tmp_path, gnss=(header, rows))
    _assert_names(msg, "gnss.csv", "std_u", 4)
    assert "zero" in msg


def test_no_fix_rows_and_null_island_are_dropped(tmp_path: Path) -> None:
    header = [*GNSS_HEADER, "fix"]
    rows = [[*r, 1] for r in gnss_rows()]
    rows[1][header.index("fix")] = 0
    rows[2][1] = rows[2][2] = 0.0            # lat = lon = 0
    rows += [[rows[-1][0] + 0.03 * k, 30.5, 114.25, 20.0, 4] for k in range(1, 3)]
    rec = read_csv_log(make_log(tmp_path, gnss=(header, rows)))
    assert len(rec.gnss) == len(rows) - 2
    assert not np.any((rec.gnss.lat_deg == 0) & (rec.gnss.lon_deg == 0))
    w = " ".join(rec.warnings)
    assert "1 fix with fix = 0" in w and "1 fix at lat = lon = 0" in w and "line 3" in w


@pytest.mark.parametrize("scale,unit", [(1e3, "milliseconds"), (1e9, "nanoseconds")])
def test_stamps_not_in_seconds_are_named(tmp_path: Path, scale: float, unit: str) -> None:
    imu = [[0.01 * k * scale, *row[1:]] for k, row in enumerate(imu_rows())]
    gnss = [[(r[0] - T0) * scale, *r[1:]] for r in gnss_rows()]
    msg = _error(tmp_path, imu=(IMU_HEADER, imu), gnss=(GNSS_HEADER, gnss))
    _assert_names(msg, "imu.csv", "t", None)
    assert unit in msg
