"""RTKLIB .pos reader and the GPS/UTC time base: hand-written files, hand-computed oracles.

Oracles used below (worked out by hand, not by the code under test):
- 2024-01-01 00:00:00 UTC = unix 1704067200 (19723 days * 86400); GPS-UTC = 18 s then, so
  2024/01/01 00:00:00 GPST = 2023-12-31 23:59:42 UTC = unix 1704067182, and on the "gpst" base
  (GPS calendar time counted like unix time) it is 1704067200.
- GPS week 2295 starts 2023-12-31 00:00:00 GPST ((1703980800 - 315964800) / 604800 = 2295);
  week 2296 starts 2024-01-07 00:00:00 GPST = unix 1704585600 - 18.
- Leap second at the end of 2016-12-31: 2017-01-01 00:00:00 UTC = unix 1483228800; GPS-UTC
  17 s before, 18 s after; 23:59:60 UTC = 2017/01/01 00:00:17 GPST.
- First leap second after the GPS epoch, end of 1981-06-30: 1981-07-01 = 4018 + 181 = 4199
  days after 1970-01-01 = unix 362793600; GPS-UTC 0 before, 1 after, so 1981/07/01 00:00:01
  GPST = unix 362793600 = GPS week 77 (542 days after 1980-01-06) tow 3 * 86400 + 1.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from navpp import timebase as tb
from navpp.errors import ConfigError, InputError
from navpp.io.rtklib import read_pos

NS = 1_000_000_000


@pytest.fixture(autouse=True, params=["fast", "line-by-line"])
def parser_path(request, monkeypatch):
    """Every test runs with the pandas fast path and with the line-by-line parser."""
    from navpp.io import rtklib

    monkeypatch.setattr(rtklib, "_FAST_PATH", request.param == "fast")
    return request.param

LEGEND = ("% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,"
          "ns=# of satellites)")
COLS_LLH = ("latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)"
            "  sdeu(m)  sdun(m) age(s)  ratio")
COLS_VEL = "    vn(m/s)    ve(m/s)    vu(m/s)      sdvn    sdve    sdvu   sdvne   sdveu   sdvun"
LLH_BODY = "   35.123456789  139.123456789    50.1234   1   8   0.0030   0.0040   0.0090   0.0010   0.0000  -0.0020   0.00    0.0"  # noqa: E501 (an RTKLIB line as written)


def write_pos(tmp_path: Path, lines: list[str], name: str = "sol.pos") -> Path:
    p = tmp_path / name
    p.write_text("\r\n".join(lines) + "\r\n")  # RTKLIB writes CRLF
    return p


def header(ts: str = "GPST", cols: str = COLS_LLH, legend: bool = True) -> list[str]:
    out = ["% program   : RTKPOST ver.2.4.3 b34",
           "% obs start : 2024/01/01 00:00:00.0 GPST (week2295  86400.0s)"]
    if legend:
        out.append(LEGEND)
    out.append(f"%  {ts:<22s}{cols}")
    return out


# --------------------------------------------------------------------------------------------
# timebase
# --------------------------------------------------------------------------------------------


def test_leap_table_values():
    assert tb.LEAP_SECONDS[0] == ("1981-07-01", 1)
    assert tb.LEAP_SECONDS[-1] == ("2017-01-01", 18)
    assert [v for _, v in tb.LEAP_SECONDS] == list(range(1, 19))
    assert tb.GPS_EPOCH_UNIX == 315964800 == 3657 * 86400
    assert np.datetime64(tb.LEAP_TABLE_VALID_UNTIL_UNIX, "s") == np.datetime64("2026-07-01T00:00:00")
    u = np.array([315964800, 362793599, 362793600, 1483228799, 1483228800, 1704067200]) * NS
    assert tb.leap_seconds_at_unix_ns(u).tolist() == [0, 0, 1, 17, 18, 18]


def test_leap_table_matches_system_list():
    """Cross-check against the IANA/IERS leap-seconds.list shipped with tzdata, when present."""
    f = Path("/usr/share/zoneinfo/leap-seconds.list")
    if not f.is_file():
        pytest.skip("no system leap-seconds.list")
    ntp_to_unix = 2208988800
    rows = []
    for line in f.read_text().splitlines():
        m = re.match(r"^(\d+)\s+(\d+)", line)
        if m:
            unix, tai_utc = int(m.group(1)) - ntp_to_unix, int(m.group(2))
            if unix > tb.GPS_EPOCH_UNIX:
                rows.append((unix, tai_utc - 19))
    ours = [(int(u // NS), v) for u, v in zip(tb.LEAP_STARTS_UNIX_NS, (v for _, v in tb.LEAP_SECONDS))]
    assert rows == ours, "update navpp.timebase.LEAP_SECONDS from the IERS list"


def test_gpst_unix_scalar_oracles():
    # 2024/01/01 00:00:00 GPST
    gps = 1704067200 - tb.GPS_EPOCH_UNIX
    assert tb.gpst_to_unix(gps) == 1704067182.0
    assert tb.unix_to_gpst(1704067182.0) == gps
    assert tb.convert(1704067200.0, "gpst", "unix") == 1704067182.0
    assert tb.convert(1704067182.0, "unix", "gpst") == 1704067200.0
    assert tb.convert(1704067182.5, "unix", "unix") == 1704067182.5
    # GPS weeks
    assert tb.gps_week_tow_to_unix(2295, 0.0) == 1703980800 - 18
    assert tb.gps_week_tow_to_unix(2296, 0.0) == 1704585600 - 18
    assert tb.gps_week_tow_to_unix_ns(2296, 0.25) == (1704585600 - 18) * NS + 250_000_000
    week, tow = tb.unix_to_gps_week_tow(1704067200.0)
    assert (int(week), float(tow)) == (2295, 86418.0)
    # first leap second after 1980
    assert tb.gps_week_tow_to_unix(77, 3 * 86400 + 1) == 362793600
    assert tb.gps_week_tow_to_unix(77, 3 * 86400 - 1) == 362793599
    assert tb.gpst_to_unix(0.0) == tb.GPS_EPOCH_UNIX


def test_gpst_unix_vectorised_and_exact_ns():
    unix_ns = np.array([362793599, 362793600, 1483228799, 1483228800, 1704067200], dtype=np.int64) * NS
    unix_ns = unix_ns + 123_456_789
    gps_ns = tb.unix_to_gpst_ns(unix_ns)
    assert gps_ns.dtype == np.int64
    expect_leap = np.array([0, 1, 17, 18, 18])
    assert np.array_equal(gps_ns, unix_ns + expect_leap * NS - tb.GPS_EPOCH_UNIX * NS)
    assert np.array_equal(tb.gpst_to_unix_ns(gps_ns), unix_ns)
    base = tb.convert_ns(unix_ns, "unix", "gpst")
    assert np.array_equal(base, unix_ns + expect_leap * NS)
    assert np.array_equal(tb.convert_ns(base, "gpst", "unix"), unix_ns)
    # float arrays: whole-second shifts only
    u = unix_ns.astype(np.float64) / NS
    assert np.array_equal(tb.convert(u, "unix", "gpst"), u + expect_leap)
    assert np.array_equal(tb.gpst_to_unix(tb.unix_to_gpst(u)), u)
    with pytest.raises(TypeError):
        tb.convert_ns(np.array([1.5]), "unix", "gpst")


def test_leap_second_instant_and_bases():
    # 23:59:60 UTC on 2016-12-31 = gpst base 1483228817: no unix value of its own
    g = np.array([1483228816, 1483228817, 1483228817_500_000_000 // NS, 1483228818]) * NS
    assert tb.in_leap_second_gpst_base_ns(g).tolist() == [False, True, True, False]
    assert tb.in_leap_second_gpst_base_ns(np.array([362793600 * NS])).tolist() == [True]
    assert tb.convert_ns(np.array([1483228816 * NS]), "gpst", "unix")[0] == 1483228799 * NS
    assert tb.convert_ns(np.array([1483228818 * NS]), "gpst", "unix")[0] == 1483228800 * NS
    with pytest.raises(ValueError, match="relative"):
        tb.convert(1.0, "relative", "unix")
    with pytest.raises(ValueError, match="unknown"):
        tb.convert(1.0, "tai", "unix")
    assert tb.convert(5.0, "relative", "relative") == 5.0


# --------------------------------------------------------------------------------------------
# read_pos: times
# --------------------------------------------------------------------------------------------


def test_gpst_calendar_to_unix_and_gpst(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:00.000" + LLH_BODY,
        "2024/01/01 00:00:00.200" + LLH_BODY,
        "2024/01/01 00:00:01.000" + LLH_BODY,
    ])
    g, w, t0 = read_pos(p)
    assert t0 == 1704067182 * NS
    assert g.t.tolist() == [0.0, 0.2, 1.0]
    assert w == []
    g2, _, t0g = read_pos(p, time_base="gpst")
    assert t0g == 1704067200 * NS
    assert np.array_equal(g2.t, g.t)


def test_utc_and_jst_calendar(tmp_path):
    p = write_pos(tmp_path, header("UTC") + ["2024/01/01 00:00:00.000" + LLH_BODY])
    assert read_pos(p)[2] == 1704067200 * NS
    assert read_pos(p, time_base="gpst")[2] == 1704067218 * NS
    p = write_pos(tmp_path, header("JST") + ["2024/01/01 09:00:00.000" + LLH_BODY], "jst.pos")
    assert read_pos(p)[2] == 1704067200 * NS


def test_week_tow_gpst_and_utc(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2295      0.000" + LLH_BODY,
        "2296      0.000" + LLH_BODY,
    ])
    g, _, t0 = read_pos(p)
    assert t0 == (1703980800 - 18) * NS
    assert g.t.tolist() == [0.0, 604800.0]
    assert read_pos(p, time_base="gpst")[2] == 1703980800 * NS
    # RTKLIB with UTC + week/tow counts UTC weeks from 1980-01-06 00:00:00 UTC
    p = write_pos(tmp_path, header("UTC") + ["2295  86400.000" + LLH_BODY], "utc.pos")
    assert read_pos(p)[2] == 1704067200 * NS


def test_t0_given_and_fractional_seconds_exact(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:00.123456789" + LLH_BODY,
        "2024/01/01 00:00:00.1234567896" + LLH_BODY,  # rounds to ...790 ns
    ])
    t0 = 1704067180 * NS
    g, _, t0_used = read_pos(p, t0_ns=t0)
    assert t0_used == t0
    assert g.t[0] == pytest.approx(2.123456789, abs=1e-12)
    assert (g.t[1] - g.t[0]) == pytest.approx(1e-9, abs=1e-13)


def test_gpst_across_2016_leap_second(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2016/12/31 23:59:59.000" + LLH_BODY,   # GPS-UTC = 17
        "2017/01/01 00:00:16.000" + LLH_BODY,   # 23:59:59 UTC
        "2017/01/01 00:00:17.000" + LLH_BODY,   # 23:59:60 UTC: no unix time
        "2017/01/01 00:00:18.000" + LLH_BODY,   # 00:00:00 UTC
        "2017/01/01 00:00:30.000" + LLH_BODY,   # 00:00:12 UTC
    ])
    g, w, _ = read_pos(p, t0_ns=0)
    assert (g.t * NS).round().astype(np.int64).tolist() == [
        1483228782 * NS, 1483228799 * NS, 1483228800 * NS, 1483228812 * NS]
    assert any("leap second" in x and "line 7" in x for x in w), w
    assert any("GPS-UTC 17 -> 18" in x for x in w), w
    # on the gpst base nothing is dropped and nothing shifts
    g2, w2, _ = read_pos(p, time_base="gpst", t0_ns=1483228799 * NS)
    assert g2.t.tolist() == [0.0, 17.0, 18.0, 19.0, 31.0]
    assert w2 == []


def test_utc_file_across_leap_second_rtklib_duplicates(tmp_path):
    # RTKLIB prints 23:59:60.x UTC as 00:00:00.x of the next day, so time steps back there
    p = write_pos(tmp_path, header("UTC") + [
        "2016/12/31 23:59:59.500" + LLH_BODY,
        "2017/01/01 00:00:00.000" + LLH_BODY,   # really 23:59:60.0
        "2017/01/01 00:00:00.500" + LLH_BODY,   # really 23:59:60.5
        "2017/01/01 00:00:00.000" + LLH_BODY,
        "2017/01/01 00:00:00.500" + LLH_BODY,
    ])
    g, w, t0 = read_pos(p, time_base="gpst")
    assert t0 == 1483228799_500_000_000 + 17 * NS
    assert g.t.tolist() == [0.0, 1.5, 2.0]
    assert any("inside a leap second" in x and "lines 6, 7" in x for x in w), w


def test_first_leap_second_after_1980(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "1981/06/30 23:59:59.000" + LLH_BODY,
        "1981/07/01 00:00:01.000" + LLH_BODY,
        "1981/07/01 00:00:02.000" + LLH_BODY,
    ])
    g, _, _ = read_pos(p, t0_ns=0)
    assert (g.t * NS).round().astype(np.int64).tolist() == [
        362793599 * NS, 362793600 * NS, 362793601 * NS]
    p = write_pos(tmp_path, header("GPST") + ["77 259201.000" + LLH_BODY], "wk.pos")
    assert read_pos(p)[2] == 362793600 * NS


# --------------------------------------------------------------------------------------------
# read_pos: values
# --------------------------------------------------------------------------------------------


def test_fix_sats_std_mapping(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:00.000   35.0  139.0  50.0   1   8   0.0030   0.0040   0.0090   0 0 0  0.0  3.0",
        "2024/01/01 00:00:01.000   35.0  139.0  50.0   2  11   0.1000   0.2000   0.3000   0 0 0  1.0  1.0",
        "2024/01/01 00:00:02.000  -35.5 -139.5  -5.0   5   4   1.5000   2.5000   3.5000   0 0 0  0.0  0.0",
        "2024/01/01 00:00:03.000   35.0  139.0  50.0   0   0   0.0000   0.0000   0.0000   0 0 0  0.0  0.0",
    ])
    g, w, _ = read_pos(p)
    assert g.fix.tolist() == [1, 2, 5]
    assert g.num_sats.tolist() == [8, 11, 4]
    # columns are sdn, sde, sdu -> std_enu = (sde, sdn, sdu)
    assert g.std_enu.tolist() == [[0.004, 0.003, 0.009], [0.2, 0.1, 0.3], [2.5, 1.5, 3.5]]
    assert g.lat_deg.tolist() == [35.0, 35.0, -35.5]
    assert g.lon_deg.tolist() == [139.0, 139.0, -139.5]
    assert g.alt.tolist() == [50.0, 50.0, -5.0]
    assert g.vel_enu is None and g.std_vel_enu is None
    assert any("1 epoch with Q = 0" in x and "line 8" in x for x in w), w


def test_velocity_columns(tmp_path):
    vel = "    1.00000    2.00000   -0.50000   0.01000 0.02000 0.03000 0.00000 0.00000 0.00000"
    p = write_pos(tmp_path, header("GPST", COLS_LLH + COLS_VEL) + [
        "2024/01/01 00:00:00.000" + LLH_BODY + vel,
    ])
    g, _, _ = read_pos(p)
    assert g.vel_enu.tolist() == [[2.0, 1.0, -0.5]]       # (ve, vn, vu)
    assert g.std_vel_enu.tolist() == [[0.02, 0.01, 0.03]]  # (sdve, sdvn, sdvu)


def test_dms_positions(tmp_path):
    cols = ("latitude(d'\") longitude(d'\")  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)"
            "  sdeu(m)  sdue(m) age(s)  ratio")
    tail = "    50.1234   1   8   0.0030   0.0040   0.0090   0.0000   0.0000   0.0000   0.00    0.0"
    p = write_pos(tmp_path, header("GPST", cols) + [
        "2024/01/01 00:00:00.000   35 07 30.00000  139 30 00.00000" + tail,
        "2024/01/01 00:00:01.000   -0 30 00.00000   -1 15 36.00000" + tail,
    ])
    g, _, _ = read_pos(p)
    assert g.lat_deg[0] == pytest.approx(35.125, abs=1e-12)
    assert g.lon_deg[0] == pytest.approx(139.5, abs=1e-12)
    assert g.lat_deg[1] == pytest.approx(-0.5, abs=1e-12)   # sign on a "-0" degrees field
    assert g.lon_deg[1] == pytest.approx(-1.26, abs=1e-12)
    assert g.std_enu.tolist()[0] == [0.004, 0.003, 0.009]


COLS_XYZ = ("     x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   sdz(m)  sdxy(m)"
            "  sdyz(m)  sdzx(m) age(s)  ratio")
COLS_XYZ_VEL = "    vx(m/s)    vy(m/s)    vz(m/s)      sdvx    sdvy    sdvz   sdvxy   sdvyz   sdvzx"


def test_xyz_ecef_on_equator(tmp_path):
    # lat 0, lon 0: up = +x, east = +y, north = +z.  lat 0, lon 90: up = +y, east = -x.
    h = 100.0
    r = 6378137.0 + h
    p = write_pos(tmp_path, header("GPST", COLS_XYZ + COLS_XYZ_VEL, legend=False) + [
        (f"2024/01/01 00:00:00.000 {r:.4f} 0.0000 0.0000 1 9 0.3000 0.1000 0.2000 0 0 0 0.0 0.0"
         " 1.0 2.0 3.0 0.03 0.01 0.02 0 0 0"),
        (f"2024/01/01 00:00:01.000 0.0000 {r:.4f} 0.0000 2 9 0.1000 0.3000 0.2000 0 0 0 0.0 0.0"
         " -2.0 1.0 3.0 0.01 0.03 0.02 0 0 0"),
    ])
    g, w, _ = read_pos(p)
    np.testing.assert_allclose(g.lat_deg, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.lon_deg, [0.0, 90.0], atol=1e-12)
    np.testing.assert_allclose(g.alt, [h, h], atol=1e-6)
    np.testing.assert_allclose(g.std_enu, [[0.1, 0.2, 0.3], [0.1, 0.2, 0.3]], atol=1e-12)
    np.testing.assert_allclose(g.vel_enu, [[2.0, 3.0, 1.0], [2.0, 3.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(g.std_vel_enu, [[0.01, 0.02, 0.03]] * 2, atol=1e-12)
    assert g.fix.tolist() == [1, 2]
    assert w == []


def test_xyz_covariance_cross_terms(tmp_path):
    from navpp.geodesy import geodetic_to_ecef, mat_enu_from_ecef

    lat, lon, h = np.radians(48.7), np.radians(9.1), 320.0
    xyz = geodetic_to_ecef(lat, lon, h)
    c_enu = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.25]])
    m = mat_enu_from_ecef(lat, lon)
    c = m.T @ c_enu @ m
    def sq(v):  # RTKLIB's sqvar
        return np.sign(v) * np.sqrt(abs(v))

    line = (f"2024/01/01 00:00:00.000 {xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f} 1 12 "
            f"{np.sqrt(c[0, 0]):.8f} {np.sqrt(c[1, 1]):.8f} {np.sqrt(c[2, 2]):.8f} "
            f"{sq(c[0, 1]):.8f} {sq(c[1, 2]):.8f} {sq(c[2, 0]):.8f} 0.0 0.0")
    g, _, _ = read_pos(write_pos(tmp_path, header("GPST", COLS_XYZ, legend=False) + [line]))
    assert g.lat_deg[0] == pytest.approx(48.7, abs=1e-9)
    assert g.lon_deg[0] == pytest.approx(9.1, abs=1e-9)
    assert g.alt[0] == pytest.approx(320.0, abs=1e-3)
    np.testing.assert_allclose(g.std_enu[0], [0.2, 0.3, 0.5], atol=1e-7)


def test_comma_separator_and_missing_legend(tmp_path):
    p = tmp_path / "comma.pos"
    p.write_text(
        "%  GPST                   ,latitude(deg),longitude(deg),height(m),Q,ns,sdn(m),sde(m),sdu(m),"
        "sdne(m),sdeu(m),sdun(m),age(s),ratio\n"
        "2024/01/01 00:00:00.000,35.0,139.0,50.0,1,8,0.003,0.004,0.009,0,0,0,0.0,0.0\n"
    )
    g, w, t0 = read_pos(p)
    assert t0 == 1704067182 * NS
    assert g.std_enu.tolist() == [[0.004, 0.003, 0.009]]
    assert any("height type" in x for x in w)


def test_time_system_argument(tmp_path):
    p = write_pos(tmp_path, ["%  latitude(deg) longitude(deg) height(m) Q ns",
                             "2024/01/01 00:00:00.000 35.0 139.0 50.0 1 8"])
    with pytest.raises(InputError, match=r"sol\.pos: line 1: .*does not name the time system"):
        read_pos(p)
    assert read_pos(p, time_system="UTC")[2] == 1704067200 * NS
    assert read_pos(p, time_system="gpst")[2] == 1704067182 * NS
    q = write_pos(tmp_path, header("GPST") + ["2024/01/01 00:00:00.000" + LLH_BODY], "g.pos")
    with pytest.raises(InputError, match="header says GPST but UTC"):
        read_pos(q, time_system="UTC")


# --------------------------------------------------------------------------------------------
# read_pos: errors
# --------------------------------------------------------------------------------------------


def test_no_column_header(tmp_path):
    p = write_pos(tmp_path, ["% program   : RTKPOST ver.2.4.3",
                             "2024/01/01 00:00:00.000" + LLH_BODY])
    with pytest.raises(InputError, match=r"sol\.pos: no RTKLIB column header.*time system"):
        read_pos(p)


@pytest.mark.parametrize("bad, lineno, what", [
    ("2024/01/01 00:00:00.000   35.1  139.1  abc   1   8   0.003 0.004 0.009 0 0 0 0.0 0.0", 6, "height"),
    ("2024/01/01 00:00:00.000   35.1  139.1  50.0  1   8   0.003 0.004", 6, "fields, expected 15"),
    ("2024/13/01 00:00:00.000" + LLH_BODY, 6, "bad time"),
    ("2024/01/01 00:0x:00.000" + LLH_BODY, 6, "bad time"),
    ("2024/01/01 00:00:00.000   35.1  139.1  nan   1   8   0.003 0.004 0.009 0 0 0 0.0 0.0", 6, "finite"),
    ("2024/01/01 00:00:00.000   95.1  139.1  50.0  1   8   0.003 0.004 0.009 0 0 0 0.0 0.0", 6, "out of range"),
    ("2024/01/01 00:00:00.000   35.1  139.1  50.0  1.5 8   0.003 0.004 0.009 0 0 0 0.0 0.0", 6, "Q is 1.5"),
])
def test_garbled_line_names_file_and_line(tmp_path, bad, lineno, what):
    p = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:00.000" + LLH_BODY,  # line 5
        bad.replace("00:00:00.000", "00:00:01.000", 1),
    ])
    with pytest.raises(InputError, match=rf"sol\.pos: line {lineno}: .*{re.escape(what)}"):
        read_pos(p)


def test_time_backwards_and_duplicates(tmp_path):
    p = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:01.000" + LLH_BODY,
        "2024/01/01 00:00:01.000" + LLH_BODY,
        "2024/01/01 00:00:02.000" + LLH_BODY,
    ])
    g, w, _ = read_pos(p)
    assert len(g) == 2 and any("repeat" in x and "line 6" in x for x in w)
    p = write_pos(tmp_path, header("UTC") + [
        "2024/01/01 00:00:01.000" + LLH_BODY,
        "2024/01/01 00:00:00.500" + LLH_BODY,
    ], "back.pos")
    with pytest.raises(InputError, match=r"back\.pos: line 6: time goes backwards"):
        read_pos(p)


@pytest.mark.parametrize("content, message", [
    ("", "empty file"),
    ("\n\n", "empty file"),
    ("$GPGGA,000000.00,3507.4074,N,13907.4074,E,4,08,1.0,50.0,M,0.0,M,0.0,0000*5B\n", "NMEA"),
    ("%  GPST  e-baseline(m) n-baseline(m) u-baseline(m) Q ns\n2024/01/01 00:00:00 1 2 3 1 8\n",
     "baseline"),
    (("% (lat/lon/height=WGS84/geodetic,Q=1:fix)\n%  GPST latitude(deg) longitude(deg) height(m) Q ns\n"
      "2024/01/01 00:00:00 35 139 50 1 8\n"), "geodetic"),
    ("%  GPST latitude(deg) longitude(deg) height(m) Q ns\n", "no solution lines"),
])
def test_unusable_files(tmp_path, content, message):
    p = tmp_path / "x.pos"
    p.write_text(content)
    with pytest.raises(InputError, match=rf"x\.pos.*{message}"):
        read_pos(p)


def test_missing_file_and_bad_time_base(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_pos(tmp_path / "nope.pos")
    p = write_pos(tmp_path, header("GPST") + ["2024/01/01 00:00:00.000" + LLH_BODY])
    with pytest.raises(ConfigError, match="relative"):
        read_pos(p, time_base="relative")
    with pytest.raises(ConfigError, match="'tai'"):
        read_pos(p, time_base="tai")


def test_warns_beyond_leap_table_validity(tmp_path):
    p = write_pos(tmp_path, header("GPST") + ["2030/01/01 00:00:00.000" + LLH_BODY])
    _, w, _ = read_pos(p)
    assert any("leap-second table" in x for x in w)


def test_many_lines_read_in_order(tmp_path):
    """2,000 epochs at 10 Hz: every line read, times from the file's GPST stamps (the reading
    speed on an hour of lines is measured by benchmarks/bench_rtklib.py)."""
    n = 2_000
    t = 1704067200 + np.arange(n) * 0.1
    lines = header("GPST", COLS_LLH + COLS_VEL)
    stamps = [np.datetime64(round(x * 1000), "ms").astype(str).replace("-", "/").replace("T", " ")
              for x in t]
    vel = "    1.00000    2.00000   -0.50000   0.01000 0.02000 0.03000 0.00000 0.00000 0.00000"
    lines += [s + LLH_BODY + vel for s in stamps]
    p = write_pos(tmp_path, lines)
    g, _, t0 = read_pos(p)
    assert len(g) == n and t0 == 1704067182 * NS
    np.testing.assert_allclose(g.t, np.arange(n) * 0.1, atol=1e-9)


def test_fast_path_takes_common_files(tmp_path, monkeypatch):
    """The pandas path must itself handle RTKLIB's usual layouts, not fall back silently."""
    from navpp.io import rtklib

    monkeypatch.setattr(rtklib, "_FAST_PATH", True)

    def no_slow(*a, **k):
        raise AssertionError("fell back to the line-by-line parser")

    monkeypatch.setattr(rtklib, "_parse_slow", no_slow)
    cal = write_pos(tmp_path, header("GPST") + [
        "2024/01/01 00:00:00.123456789" + LLH_BODY, "2024/01/01 00:00:01.000000000" + LLH_BODY])
    g, _, t0 = read_pos(cal)
    assert t0 == 1704067182 * NS + 123_456_789
    assert g.t.tolist() == [0.0, 0.876543211]
    whole = write_pos(tmp_path, header("UTC") + ["2024/01/01 00:00:00" + LLH_BODY], "whole.pos")
    assert read_pos(whole)[2] == 1704067200 * NS
    wk = write_pos(tmp_path, header("GPST") + ["2295  86400.125" + LLH_BODY], "wk.pos")
    assert read_pos(wk)[2] == 1704067182 * NS + 125_000_000
    cols = "latitude(d'\") longitude(d'\")  height(m)   Q  ns"
    dms = write_pos(tmp_path, header("GPST", cols) + [
        "2024/01/01 00:00:00.000   -0 30 00.00000  139 30 00.00000  50.0 1 8"], "dms.pos")
    g, _, _ = read_pos(dms)
    assert (g.lat_deg[0], g.lon_deg[0]) == (-0.5, 139.5)
