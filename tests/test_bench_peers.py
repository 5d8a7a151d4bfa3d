"""benchmarks/bench_peers.py's KF-GINS input writer: the files hold what the log holds, in
KF-GINS's units and axes (README "Data format"), checked against values computed here by hand."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location(
    "bench_peers", Path(__file__).resolve().parent.parent / "benchmarks" / "bench_peers.py")
assert _SPEC is not None and _SPEC.loader is not None
bench_peers = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench_peers)


def _write_log(d: Path) -> None:
    d.mkdir()
    t = 1700000000.0 + 0.01 * np.arange(5)
    gyro = np.array([[0.1, 0.2, 0.3]]) + 0.01 * np.arange(5)[:, None]      # rad/s, FLU
    acc = np.array([[1.0, -2.0, 9.8]]) + 0.1 * np.arange(5)[:, None]       # m/s^2, FLU
    with open(d / "imu.csv", "w") as f:
        f.write("t,gx,gy,gz,ax,ay,az\n")
        for row in np.column_stack([t, gyro, acc]):
            f.write(",".join(f"{v:.10f}" for v in row) + "\n")
    (d / "gnss.csv").write_text("t,lat,lon,alt,std_e,std_n,std_u\n"
                                "1700000000.02,45.0,7.0,300.0,1.5,1.8,2.5\n")
    (d / "reference.csv").write_text("t,lat,lon,alt,ve,vn,vu,roll,pitch,heading\n"
                                     "1700000000.0,45.0,7.0,300.0,1.0,2.0,0.5,0.0,0.0,30.0\n")
    (d / "navpp.toml").write_text('[imu]\npreset = "automotive"\n')


def test_kfgins_inputs_round_trip(tmp_path: Path) -> None:
    log = tmp_path / "log"
    _write_log(log)
    noise = bench_peers.imu_noise(log)
    cfg = bench_peers.write_kfgins_inputs(log, tmp_path / "kf", noise)

    imu = bench_peers.read_kfgins_imu(tmp_path / "kf" / "imu.txt")
    assert imu.shape == (4, 7)                                   # one increment per interval
    np.testing.assert_allclose(imu[:, 0], 1.0 + 0.01 * np.arange(1, 5), atol=1e-9)
    # interval 1 -> 2: gyro FLU (0.11, 0.21, 0.31) and (0.12, 0.22, 0.32): trapezoid * 0.01 s,
    # y and z negated for FRD; dt comes from float64 unix seconds (ulp 2.4e-7 s at 1.7e9 s): rtol 1e-4
    np.testing.assert_allclose(imu[1, 1:4], [0.115 * 0.01, -0.215 * 0.01, -0.315 * 0.01], rtol=1e-4)
    np.testing.assert_allclose(imu[1, 4:7], [1.15 * 0.01, 1.85 * 0.01, -9.95 * 0.01], rtol=1e-4)

    gnss = np.loadtxt(tmp_path / "kf" / "gnss.txt", ndmin=2)
    np.testing.assert_allclose(gnss[0], [1.02, 45.0, 7.0, 300.0, 1.8, 1.5, 2.5], atol=1e-9)  # std N, E, D

    text = cfg.read_text()
    assert "imudatarate: 100\n" in text                          # an integer: KF-GINS reads an int
    assert "starttime: 1.010000\n" in text                       # its first IMU row, not before it
    assert "initvel: [ 2, 1, -0.5 ]" in text                    # NED from ENU
    assert "initatt: [ 0, 0, 30 ]" in text
    # automotive: 2 mg turn-on accel bias = 2e-3 * 9.80665 m/s^2 = 1961.33 mGal; tau 300 s
    assert "initbastd: [ 1961.33, 1961.33, 1961.33 ]" in text
    assert f"corrtime: {300.0 / 3600.0:.10g}" in text
    assert math.isclose(noise["gyro_arw_deg_per_sqrt_h"], 1.0)

    res_dir = tmp_path / "res"
    res_dir.mkdir()
    np.savetxt(res_dir / "KF_GINS_Navresult.nav", [[0, 1.02, 45.0, 7.0, 300.0, 0, 0, 0, 0, 0, 30]])
    back = bench_peers.read_kfgins_result(res_dir, 1700000000.0)
    np.testing.assert_allclose(back, [[1700000000.02, 45.0, 7.0, 300.0]], atol=1e-6)


def test_initial_state_interpolated_in_time() -> None:
    # t, lat, lon, alt, ve, vn, vu, roll, pitch, heading; heading crosses north between the rows
    ref = np.array([[100.0, 45.0, 7.0, 300.0, 1.0, 2.0, 0.0, 1.0, 0.0, 350.0],
                    [101.0, 45.0, 7.0, 302.0, 3.0, 4.0, 0.2, 3.0, 2.0, 10.0]])
    s = bench_peers.initial_state(ref, 100.5)
    np.testing.assert_allclose(s["lla"], [45.0, 7.0, 301.0])
    np.testing.assert_allclose(s["vel_ned"], [3.0, 2.0, -0.1])              # NED from ENU
    np.testing.assert_allclose(s["rph"], [2.0, 1.0, 0.0], atol=1e-9)        # 350 -> 10 deg through 0
    assert bench_peers.initial_state(ref)["rph"] == [1.0, 0.0, 350.0]       # default: the first row


def test_tools_must_include_navpp(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "argv", ["bench_peers.py", "--tools", "pyins,kf-gins"])
    with pytest.raises(SystemExit, match="navpp in it"):
        bench_peers.main()
    monkeypatch.setattr(sys, "argv", ["bench_peers.py", "--tools", "navpp,kfgins"])
    with pytest.raises(SystemExit, match="a subset of navpp,pyins,kf-gins"):
        bench_peers.main()


def test_native_peak_from_gnu_time(tmp_path: Path) -> None:
    cmd = bench_peers.gnu_time_cmd(["/bin/true"], tmp_path / "hwm.txt")
    if not Path("/usr/bin/time").is_file():
        assert cmd == ["/bin/true"]
        return
    assert cmd[-1] == "/bin/true"
    parent = np.ones(12_500_000)                        # 100 MB resident in the parent at the spawn
    run = bench_peers.run_child(cmd, tmp_path / "hwm.txt", peak_source="GNU time %M")
    assert run["peak_source"] == "GNU time %M"
    assert 0.0 < run["peak_mb"] < 20.0 < parent.nbytes / 2**20   # /bin/true's own, not the parent's
