"""navpp against its peers on one simulated log: pyins (python-ins) and, given its binary, KF-GINS.

Usage:  python benchmarks/bench_peers.py [--duration 3600] [--repeats 3] [--kf-gins PATH]
                                         [--tools navpp,pyins,kf-gins] [--workdir DIR]

pyins is not a navpp dependency; install it into the same environment to compare with it:
``pip install python-ins`` (the bench skips it with one line when it is missing).  KF-GINS
(https://github.com/i2Nav-WHU/KF-GINS, C++) runs when ``--kf-gins`` names its built binary.
``--tools navpp,kf-gins`` leaves pyins out (it would take about 23 CPU minutes on a 1-hour log).

What runs: navpp's simulator writes one log (car drive, automotive IMU at 125 Hz, GNSS position
at 5 Hz, seed 7; cached in the work directory).  Each tool then runs on that log in its own
fresh process, end to end (read the files, filter, write the IMU-rate trajectory):

* navpp: ``python -m navpp process LOG --filter ekf --out DIR`` (numba cache warmed by
  ``navpp compile`` and one run before the timed ones: a run alone does not cache on a short log,
  whose kernels navpp then runs interpreted; this also computes metrics against reference.csv,
  as always);
* pyins: our glue (``_pyins_child``): pandas reads imu.csv/gnss.csv, FLU axes turned to
  pyins's FRD, ``pyins.strapdown.compute_increments_from_imu``,
  ``pyins.filters.run_feedback_filter`` with ``pyins.measurements.Position``, the trajectory
  written as CSV;
* KF-GINS: its input files (IMU increments, GNSS positions, YAML config) written once in
  KF-GINS's formats (``write_kfgins_inputs``, not timed), then ``KF-GINS config.yaml``.

pyins is slow (pandas in its per-step loop: on the 2-core machine about 0.38 s of CPU time per
second of log beyond a fixed ~13 s, from 120 s and 300 s logs), so a 1-hour log would cost it
about 23 CPU minutes per run;
``--duration 120`` is the practical size to compare with it (navpp's figures there are mostly
start-up: import and loading the cached kernels); navpp's own scaling to hours is
bench_process.py's.

Timing: navpp and pyins alternate, ``--repeats`` times each (KF-GINS after them in each
round); the figures are medians.  Wall time is the parent's clock around the child; CPU time is
the child's user + system time (``RUSAGE_CHILDREN``); peak memory is the child's own high-water
mark, ``VmHWM`` of /proc/<pid>/status read at its exit (KF-GINS: the maximum resident set size
GNU time reports for it, ``gnu_time_cmd``; the ``ru_maxrss`` the bench sees would include the
Python parent's resident size at the spawn).

Accuracy: each trajectory is interpolated (linearly, in time) to reference.csv's epochs where
all of them have a solution, and horizontal / up RMSE against the simulated truth are computed
with the same code (``navpp.metrics.position_errors_enu``).

Fairness, and where the tools differ (printed too):

* same IMU and GNSS samples; the IMU noise model of every filter is the simulator's truth for
  the log's preset (navpp's ``[imu] preset`` in the log's navpp.toml, the numbers of
  ``navpp.simulate.IMU_GRADES``); GNSS position standard deviations from gnss.csv (pyins and
  KF-GINS take one value per axis for the whole log: the median);
* all three are loosely coupled, GNSS position only, error-state with feedback (closed loop),
  no smoothing, zero lever arm (the simulator's);
* pyins and KF-GINS are given the true initial position, velocity and attitude (neither
  aligns by itself), at their first epoch (pyins: the first IMU sample; KF-GINS: the end of the
  first IMU increment, reference.csv interpolated there), with the same initial 1-sigma (2 m,
  0.1 m/s, 1 deg level, 5 deg heading); navpp aligns from the data (static levelling, heading
  from GNSS);
* pyins models biases as random constant + random walk (we give the walk that matches the
  Gauss-Markov instability over its correlation time), no scale factors, and propagates its
  covariance every 0.1 s (its default); KF-GINS and navpp use first-order Gauss-Markov biases;
  KF-GINS also estimates scale factors (we give the simulator's 1-sigma);
* navpp applies its car aids (zero-velocity and zero-rate updates while standing still); the
  others do not.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

TOOLS = ("navpp", "pyins", "kf-gins")      # --tools names
G0 = 9.80665                       # m/s^2 per g, as the simulator's mg
DEG_PER_H = math.pi / 180.0 / 3600.0          # rad/s per deg/h
DEG_PER_SQRT_H = math.pi / 180.0 / 60.0       # rad/sqrt(s) per deg/sqrt(h)
MPS_PER_SQRT_H = 1.0 / 60.0                   # m/s/sqrt(s) per m/s/sqrt(h)
MGAL_PER_MG = 1e-3 * G0 / 1e-5                # 1 mGal = 1e-5 m/s^2

# The child's peak memory: read /proc/self/status at interpreter exit, write it to a file.
_HWM_HOOK = """
import atexit, os, sys
def _bench_hwm(path=os.environ["BENCH_HWM_FILE"]):
    with open("/proc/self/status", encoding="ascii") as f:
        kb = next(int(l.split()[1]) for l in f if l.startswith("VmHWM:"))
    with open(path, "w", encoding="ascii") as f:
        f.write(str(kb))
atexit.register(_bench_hwm)
"""


# --------------------------------------------------------------------------- the log

def read_log_arrays(log: Path) -> dict[str, np.ndarray]:
    """imu (N, 7: t s unix, gyro rad/s FLU, accel m/s^2 FLU), gnss (M, 7: t, lat deg, lon deg,
    alt m, std east/north/up m), reference (K, 10: t, lat, lon, alt, v east/north/up m/s,
    roll/pitch/heading deg)."""
    out = {}
    for name in ("imu", "gnss", "reference"):
        out[name] = np.loadtxt(log / f"{name}.csv", delimiter=",", skiprows=1, ndmin=2)
    return out


def imu_noise(log: Path) -> dict[str, float]:
    """The simulator's IMU error budget (datasheet units) for the preset of the log's navpp.toml."""
    import tomllib

    from navpp.simulate import IMU_GRADES

    preset = "automotive"
    toml = log / "navpp.toml"
    if toml.exists():
        preset = tomllib.loads(toml.read_text()).get("imu", {}).get("preset", preset)
    g = IMU_GRADES[preset]
    return {"preset": preset, **{k: getattr(g, k) for k in g.__dataclass_fields__}}  # type: ignore[dict-item]


def flu_to_frd(v: np.ndarray) -> np.ndarray:
    """Body FLU (x forward, y left, z up) vectors (..., 3) to FRD (forward, right, down)."""
    return v * np.array([1.0, -1.0, -1.0])


def initial_state(ref: np.ndarray, t: float | None = None) -> dict[str, list[float]]:
    """True initial state from reference.csv (rows t, lat, lon, alt, v east/north/up, roll, pitch,
    heading) at unix time ``t`` s (linear in time, heading unwrapped; default: its first row):
    lat/lon deg, alt m; velocity NED m/s; roll, pitch, heading deg of FRD body to NED, which are
    navpp's angles as they are (roll right side down, pitch nose up, heading clockwise from north)."""
    r = ref[0]
    if t is not None:
        cols = ref.copy()
        cols[:, 9] = np.unwrap(cols[:, 9], period=360.0)
        r = np.array([np.interp(t, cols[:, 0], cols[:, k]) for k in range(cols.shape[1])])
        r[9] %= 360.0
    return {"lla": [r[1], r[2], r[3]], "vel_ned": [r[5], r[4], -r[6]], "rph": [r[7], r[8], r[9]]}


# --------------------------------------------------------------------------- KF-GINS files

def write_kfgins_inputs(log: Path, out: Path, noise: dict[str, float]) -> Path:
    """Write KF-GINS's inputs for ``log`` into ``out``: imu.txt, gnss.txt, kf-gins.yaml.

    Formats (KF-GINS README, "Data format"; config keys from its dataset/kf-gins.yaml):
    imu.txt rows ``t, dtheta_xyz rad, dvel_xyz m/s`` (FRD body; the increment over the interval
    ending at t, here the trapezoid of the two rate samples); gnss.txt rows ``t, lat deg, lon deg,
    h m, std north/east/down m``.  t is seconds since the first IMU sample plus 1 (KF-GINS reads
    GNSS seconds of week; a log-relative clock keeps an 8-hour log inside one "week").  The
    config (keys and units of KF-GINS's kf_gins.cpp ``loadConfig``: deg, deg/h, mGal, ppm, h)
    starts at imu.txt's first row (KF-GINS refuses a ``starttime`` before it) with the true
    state there; ``imudatarate`` is an integer (KF-GINS reads an int).  Returns the config path.
    """
    d = read_log_arrays(log)
    imu, gnss, ref = d["imu"], d["gnss"], d["reference"]
    t0 = imu[0, 0]
    t = imu[:, 0] - t0 + 1.0
    dt = np.diff(t)[:, None]
    gyro, acc = flu_to_frd(imu[:, 1:4]), flu_to_frd(imu[:, 4:7])
    dtheta = 0.5 * (gyro[1:] + gyro[:-1]) * dt
    dvel = 0.5 * (acc[1:] + acc[:-1]) * dt
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "imu.txt", np.column_stack([t[1:], dtheta, dvel]), fmt="%.6f" + " %.12e" * 6)
    g = np.column_stack([gnss[:, 0] - t0 + 1.0, gnss[:, 1:4], gnss[:, 5], gnss[:, 4], gnss[:, 6]])
    np.savetxt(out / "gnss.txt", g, fmt="%.6f %.12f %.12f %.4f %.4f %.4f %.4f")
    s = initial_state(ref, float(imu[1, 0]))          # KF-GINS's state epoch: its first IMU row
    rate = round(1.0 / float(np.median(np.diff(imu[:, 0]))))      # Hz, an integer for KF-GINS
    tau_h = noise["gyro_bias_corr_time_s"] / 3600.0
    sf = noise["scale_factor_ppm"]
    bg, ba = noise["gyro_bias_deg_per_h"], noise["accel_bias_mg"] * MGAL_PER_MG

    def v3(x: float | list[float]) -> str:
        return "[ " + ", ".join(f"{float(a):.10g}" for a in (x if isinstance(x, list) else [x] * 3)) + " ]"

    cfg = out / "kf-gins.yaml"
    cfg.write_text("\n".join([
        "# written by navpp benchmarks/bench_peers.py",
        f'imupath: "{out / "imu.txt"}"', f'gnsspath: "{out / "gnss.txt"}"', f'outputpath: "{out}"',
        "imudatalen: 7", f"imudatarate: {rate}", f"starttime: {t[1]:.6f}", "endtime: -1",
        f"initpos: {v3(s['lla'])}", f"initvel: {v3(s['vel_ned'])}", f"initatt: {v3(s['rph'])}",
        f"initgyrbias: {v3(0.0)}", f"initaccbias: {v3(0.0)}", f"initgyrscale: {v3(0.0)}",
        f"initaccscale: {v3(0.0)}",
        f"initposstd: {v3(2.0)}", f"initvelstd: {v3(0.1)}", f"initattstd: {v3([1.0, 1.0, 5.0])}",
        f"initbgstd: {v3(bg)}", f"initbastd: {v3(ba)}", f"initsgstd: {v3(sf)}", f"initsastd: {v3(sf)}",
        "imunoise:",
        f"  arw: {v3(noise['gyro_arw_deg_per_sqrt_h'])}",
        f"  vrw: {v3(noise['accel_vrw_mps_per_sqrt_h'])}",
        f"  gbstd: {v3(noise['gyro_bias_instability_deg_per_h'])}",
        f"  abstd: {v3(noise['accel_bias_instability_mg'] * MGAL_PER_MG)}",
        f"  gsstd: {v3(sf)}", f"  asstd: {v3(sf)}",
        f"  corrtime: {tau_h:.10g}",
        f"antlever: {v3(0.0)}", "",
    ]))
    return cfg


def read_kfgins_imu(path: Path) -> np.ndarray:
    """imu.txt back as (N, 7): t s, dtheta rad, dvel m/s (FRD)."""
    return np.loadtxt(path, ndmin=2)


def read_kfgins_result(out: Path, t0: float) -> np.ndarray:
    """KF-GINS's KF_GINS_Navresult.nav (week, sow, lat, lon, h, vn, ve, vd, roll, pitch, yaw) as
    (N, 4): unix t s, lat deg, lon deg, alt m."""
    r = np.loadtxt(out / "KF_GINS_Navresult.nav", ndmin=2)
    return np.column_stack([r[:, 1] - 1.0 + t0, r[:, 2:5]])


# --------------------------------------------------------------------------- pyins child

def _pyins_child(log: Path, out_csv: Path) -> None:
    """Run pyins's feedback EKF on ``log`` and write its trajectory (t unix s, lat, lon, alt,
    VN, VE, VD, roll, pitch, heading) to ``out_csv``.  Runs in its own process (timed)."""
    import pandas as pd
    from pyins import filters, inertial_sensor, measurements, strapdown

    noise = imu_noise(log)
    imu_df = pd.read_csv(log / "imu.csv")
    gnss_df = pd.read_csv(log / "gnss.csv")
    ref = pd.read_csv(log / "reference.csv", nrows=1).to_numpy()
    t0 = float(imu_df["t"].iloc[0])
    tt = imu_df["t"].to_numpy() - t0                              # s since the first IMU sample
    imu = pd.DataFrame(np.column_stack([flu_to_frd(imu_df[["gx", "gy", "gz"]].to_numpy()),
                                        flu_to_frd(imu_df[["ax", "ay", "az"]].to_numpy())]),
                       index=tt, columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    increments = strapdown.compute_increments_from_imu(imu, "rate")
    gnss = pd.DataFrame(gnss_df[["lat", "lon", "alt"]].to_numpy(), index=gnss_df["t"].to_numpy() - t0,
                        columns=["lat", "lon", "alt"])
    position = measurements.Position(gnss, 1.0)
    std_ned = np.median(gnss_df[["std_n", "std_e", "std_u"]].to_numpy(), axis=0)
    position.R = np.diag(std_ned ** 2)                            # per-axis, not one sd for all
    s = initial_state(ref)
    pva = pd.Series(s["lla"] + s["vel_ned"] + s["rph"],
                    index=["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"], name=tt[0])
    q = noise
    gyro = inertial_sensor.EstimationModel(
        bias_sd=q["gyro_bias_deg_per_h"] * DEG_PER_H, noise=q["gyro_arw_deg_per_sqrt_h"] * DEG_PER_SQRT_H,
        bias_walk=q["gyro_bias_instability_deg_per_h"] * DEG_PER_H * math.sqrt(2.0 / q["gyro_bias_corr_time_s"]))
    accel = inertial_sensor.EstimationModel(
        bias_sd=q["accel_bias_mg"] * 1e-3 * G0, noise=q["accel_vrw_mps_per_sqrt_h"] * MPS_PER_SQRT_H,
        bias_walk=q["accel_bias_instability_mg"] * 1e-3 * G0 * math.sqrt(2.0 / q["accel_bias_corr_time_s"]))
    res = filters.run_feedback_filter(pva, 2.0, 0.1, 1.0, 5.0, increments, gyro_model=gyro,
                                      accel_model=accel, measurements=[position], time_step=0.1)
    traj = res.trajectory
    traj.index = traj.index + t0
    traj.index.name = "t"
    traj.to_csv(out_csv, float_format="%.9f")


# --------------------------------------------------------------------------- timing

def run_child(cmd: list[str], hwm_file: Path | None, env: dict[str, str] | None = None,
              cwd: Path | None = None, peak_source: str = "VmHWM") -> dict[str, Any]:
    """Run ``cmd``; wall s, CPU s (user + sys), peak MB: the KiB number ``cmd`` writes to
    ``hwm_file`` (``peak_source`` names what it is), else ru_maxrss of the bench's children."""
    if hwm_file is not None and hwm_file.exists():
        hwm_file.unlink()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"bench_peers: {' '.join(cmd[:4])} ... failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if hwm_file is not None and hwm_file.exists():
        peak, how = int(hwm_file.read_text().split()[-1]) / 1024.0, peak_source
    else:
        peak, how = after.ru_maxrss / 1024.0, "ru_maxrss"
    return {"wall_s": wall, "cpu_s": cpu, "peak_mb": peak, "peak_source": how}


def python_cmd(code: str) -> list[str]:
    return [sys.executable, "-c", _HWM_HOOK + code]


def gnu_time_cmd(cmd: list[str], hwm_file: Path) -> list[str]:
    """``cmd`` under GNU time writing the child's maximum resident set size (KiB) to ``hwm_file``.

    A native child cannot report its own ``VmHWM``, and its ``ru_maxrss`` seen from the bench
    counts the (large) Python parent it was spawned from; GNU time is a small parent, so the
    figure it writes is the binary's own peak.  ``cmd`` unchanged when /usr/bin/time is missing.
    """
    gnu_time = Path("/usr/bin/time")
    if not gnu_time.is_file():
        return cmd
    return [str(gnu_time), "-f", "%M", "-o", str(hwm_file)] + cmd


def child_env(hwm_file: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["BENCH_HWM_FILE"] = str(hwm_file)
    root = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


# --------------------------------------------------------------------------- accuracy

def rmse_against_truth(ref: np.ndarray, sols: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Horizontal and up RMSE (m) of each solution ((N, 4): t, lat, lon, alt) at the reference
    epochs inside every solution's time span (linear interpolation in time)."""
    from navpp.metrics import position_errors_enu

    lo = max(s[0, 0] for s in sols.values())
    hi = min(s[-1, 0] for s in sols.values())
    keep = (ref[:, 0] >= lo) & (ref[:, 0] <= hi)
    r = ref[keep]
    out = {}
    for name, s in sols.items():
        est = [np.interp(r[:, 0], s[:, 0], s[:, k]) for k in (1, 2, 3)]
        e = position_errors_enu(*est, r[:, 1], r[:, 2], r[:, 3])
        out[name] = {"horizontal_m": float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))),
                     "up_m": float(np.sqrt(np.mean(e[:, 2] ** 2))), "epochs": int(keep.sum())}
    return out


def load_csv_positions(path: Path) -> np.ndarray:
    """t, lat, lon, alt columns of a trajectory CSV (header with those names)."""
    import pandas as pd

    df = pd.read_csv(path, usecols=["t", "lat", "lon", "alt"])
    return df[["t", "lat", "lon", "alt"]].to_numpy()


# --------------------------------------------------------------------------- main

def versions() -> dict[str, str]:
    from importlib import metadata

    out = {}
    for dist in ("navpp", "python-ins", "numpy", "numba", "pandas", "scipy"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated log length, s")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of each tool (median)")
    ap.add_argument("--kf-gins", type=Path, help="path of a built KF-GINS binary")
    ap.add_argument("--tools", default=",".join(TOOLS),
                    help="comma-separated tools to run, navpp always among them (default: all; "
                         "pyins runs when installed, KF-GINS when --kf-gins is given)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "navpp-bench-peers")
    ap.add_argument("--pyins-child", nargs=2, type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.pyins_child:
        _pyins_child(*args.pyins_child)
        return
    if args.duration <= 0 or args.repeats < 1:
        sys.exit("bench_peers: --duration must be > 0 and --repeats >= 1")
    tools = {t.strip().lower() for t in args.tools.split(",") if t.strip()}
    if "navpp" not in tools or not tools <= set(TOOLS):
        sys.exit(f"bench_peers: --tools {args.tools!r}: a subset of {','.join(TOOLS)} with navpp in it")
    if args.kf_gins is not None and not (args.kf_gins.is_file() and os.access(args.kf_gins, os.X_OK)):
        sys.exit(f"bench_peers: --kf-gins {args.kf_gins} is not an executable file")

    work = args.workdir
    log = work / f"sim-{int(args.duration)}s"
    if not (log / "imu.csv").exists():
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import sys; from navpp import api; api.simulate_log(sys.argv[1], "
                        "duration_s=float(sys.argv[2]), imu_rate_hz=125.0, gnss_rate_hz=5.0, seed=7)",
                        str(log), str(args.duration)], check=True, env=child_env(work / "unused"))
        print(f"simulated {args.duration:.0f} s log in {time.perf_counter() - t:.1f} s -> {log}")

    import importlib.util

    have_pyins = "pyins" in tools and importlib.util.find_spec("pyins") is not None
    hwm = work / "hwm.txt"
    env = child_env(hwm)
    nav_out, py_out, kf_out = work / "out-navpp", work / "out-pyins", work / "out-kfgins"
    py_out.mkdir(parents=True, exist_ok=True)
    navpp_cli = python_cmd("import runpy, sys; sys.argv = ['navpp'] + sys.argv[1:]; "
                           "runpy.run_module('navpp', run_name='__main__', alter_sys=True)")
    nav_cmd = navpp_cli + ["process", str(log), "--filter", "ekf", "--out", str(nav_out)]
    py_cmd = python_cmd("import runpy, sys; sys.argv = [sys.argv[1], '--pyins-child'] + sys.argv[2:]; "
                        "runpy.run_path(sys.argv[0], run_name='__main__')") + [
        str(Path(__file__).resolve()), str(log), str(py_out / "trajectory.csv")]
    noise = imu_noise(log)
    kf_cmd = None
    if args.kf_gins is not None and "kf-gins" in tools:
        kf_cmd = gnu_time_cmd([str(args.kf_gins.resolve()), str(write_kfgins_inputs(log, kf_out, noise))], hwm)

    print("warm-up: `navpp compile` (numba cache: without it a short log's run stays interpreted) and one "
          "navpp run; pyins's kernels have no disk cache (compiled in each run)")
    run_child(navpp_cli + ["compile"], hwm, env)
    run_child(nav_cmd, hwm, env)
    runs: dict[str, list[dict[str, Any]]] = {"navpp": [], "pyins": [], "KF-GINS": []}
    for _ in range(args.repeats):                   # alternating, paired
        runs["navpp"].append(run_child(nav_cmd, hwm, env))
        if have_pyins:
            runs["pyins"].append(run_child(py_cmd, hwm, env))
        if kf_cmd is not None:
            runs["KF-GINS"].append(run_child(kf_cmd, hwm, env, cwd=kf_out, peak_source="GNU time %M"))
    load = os.getloadavg()

    d = read_log_arrays(log)
    n_imu, n_gnss = len(d["imu"]), len(d["gnss"])
    sols = {"navpp": load_csv_positions(nav_out / "trajectory.csv")}
    if have_pyins:
        sols["pyins"] = load_csv_positions(py_out / "trajectory.csv")
    if kf_cmd is not None:
        sols["KF-GINS"] = read_kfgins_result(kf_out, float(d["imu"][0, 0]))
    acc = rmse_against_truth(d["reference"], sols)

    from bench_process import machine_line  # a sibling script: benchmarks/ is sys.path[0]

    print(machine_line())
    print("versions: " + ", ".join(f"{k} {v}" for k, v in versions().items()))
    print(f"load average after the runs: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"log: {log}: {n_imu} IMU samples ({args.duration:.0f} s, 125 Hz), {n_gnss} GNSS fixes (5 Hz); "
          f"IMU errors: the simulator's {noise['preset']} preset, given to every filter")
    print(f"median of {args.repeats} alternating runs each, end to end (read, filter, write IMU-rate trajectory)")
    print("us/IMU: end-to-end wall and CPU time per IMU sample")
    print(f"{'tool':8s} {'wall s':>8s} {'CPU s':>8s} {'wall us':>8s} {'CPU us':>8s} {'peak MB':>8s} "
          f"{'horiz m':>8s} {'up m':>8s}")
    med: dict[str, dict[str, float]] = {}
    for name, rs in runs.items():
        if not rs:
            continue
        med[name] = {k: statistics.median(r[k] for r in rs) for k in ("wall_s", "cpu_s", "peak_mb")}
        m, a = med[name], acc[name]
        print(f"{name:8s} {m['wall_s']:8.2f} {m['cpu_s']:8.2f} {m['wall_s'] / n_imu * 1e6:8.2f} "
              f"{m['cpu_s'] / n_imu * 1e6:8.2f} "
              f"{m['peak_mb']:8.0f} {a['horizontal_m']:8.3f} {a['up_m']:8.3f}   "
              f"(peak: {rs[0]['peak_source']}; RMSE at {a['epochs']} reference epochs)")
    if "pyins" not in tools:
        print("pyins: not run (not in --tools)")
    elif not have_pyins:
        print("pyins: not run (not installed; `pip install python-ins` into this environment)")
    if "kf-gins" not in tools:
        print("KF-GINS: not run (not in --tools)")
    elif kf_cmd is None:
        print("KF-GINS: not run (give --kf-gins PATH of a built binary)")
    for peer in ("pyins", "KF-GINS"):
        if peer in med:
            a, b = med["navpp"], med[peer]
            print(f"navpp/{peer}: wall {a['wall_s'] / b['wall_s']:.3f}, CPU {a['cpu_s'] / b['cpu_s']:.3f}, "
                  f"peak memory {a['peak_mb'] / b['peak_mb']:.3f}, horizontal RMSE "
                  f"{acc['navpp']['horizontal_m'] / acc[peer]['horizontal_m']:.3f}, "
                  f"up RMSE {acc['navpp']['up_m'] / acc[peer]['up_m']:.3f}")
    print("differences: pyins compiles its numba kernels in every run (no cache); pyins and KF-GINS start "
          "from the true state, navpp aligns itself; pyins: biases "
          "random constant + random walk, no scale factors, covariance every 0.1 s, one GNSS sd per axis; "
          "KF-GINS: scale factors estimated; navpp: zero-velocity/zero-rate updates at standstill, "
          "metrics vs reference.csv inside its run. All: GNSS position only, feedback, no smoothing.")
    (work / "bench_peers.json").write_text(json.dumps({"runs": runs, "accuracy": acc, "n_imu": n_imu}, indent=1))


if __name__ == "__main__":
    main()
