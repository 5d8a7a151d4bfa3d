"""Write the CSV sample drive (sample_data/drive) as ROS logs with navpp's own writers.

    python sample_data/make_ros_samples.py

Produces sample_data/drive.mcap (ROS 2, zstd chunks), sample_data/drive.bag (ROS 1, lz4) and
sample_data/drive_ros2/ (ROS 2 bag, sqlite3), each with /imu/data (sensor_msgs/Imu) and
/gnss/fix (sensor_msgs/NavSatFix) carrying exactly the CSV log's stamps and values, and copies
drive/navpp.toml and drive/reference.csv beside them as the shared navpp.toml and
reference.csv that navpp picks up for logs in this directory.

Also sample_data/drive_odometry.mcap: the same drive with wheel odometry on
/husky_velocity_controller/odom (nav_msgs/Odometry, 20 Hz), simulated from the drive's own seed
(the simulator draws odometry from a stream of its own, so the IMU and GNSS are the CSV log's):
the odometer reads 2 % high, 0.02 m/s noise, 0.01 m/s resolution, slip under hard acceleration,
and the yaw rate with 0.002 rad/s noise; wheels at rest read 0.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from navpp.io.csv import read_csv_log
from navpp.io.roswrite import write_mcap_ros2, write_ros1_bag, write_ros2_bag
from navpp.simulate import SimulationSpec, simulate

#: the drive's own simulation (sample_data/README.md) with the odometry of drive_odometry.mcap
ODOMETRY_SPEC = SimulationSpec(duration_s=300.0, still_s=30.0, lever_arm_m=(0.3, 0.0, 1.2), seed=2026, odometry=True,
                               odometry_rate_hz=20.0, odometry_scale_error_pct=2.0, odometry_std_mps=0.02,
                               odometry_quantum_mps=0.01, odometry_slip=0.3, odometry_yaw_rate=True)


def odometry_drive(rec):
    """The CSV drive ``rec`` with the odometry of :data:`ODOMETRY_SPEC`, after checking that the
    simulation's IMU is the CSV log's (to its written decimals)."""
    sim = simulate(ODOMETRY_SPEC).recording()
    if sim.imu.t.shape != rec.imu.t.shape or np.abs(sim.imu.gyro - rec.imu.gyro).max() > 1e-8 \
            or np.abs(sim.imu.t - rec.imu.t).max() > 1e-6:
        raise SystemExit("the simulation does not reproduce sample_data/drive: not writing drive_odometry.mcap")
    return replace(rec, odometry=sim.odometry)


def main() -> None:
    here = Path(__file__).resolve().parent
    rec = read_csv_log(here / "drive")
    write_mcap_ros2(rec, here / "drive.mcap", compression="zstd")
    write_mcap_ros2(odometry_drive(rec), here / "drive_odometry.mcap", compression="zstd",
                    odometry_topic="/husky_velocity_controller/odom")
    write_ros1_bag(rec, here / "drive.bag", compression="lz4")
    if (here / "drive_ros2").exists():
        shutil.rmtree(here / "drive_ros2")
    write_ros2_bag(rec, here / "drive_ros2", storage="sqlite3", compression="file")
    shutil.copyfile(here / "drive" / "navpp.toml", here / "navpp.toml")
    shutil.copyfile(here / "drive" / "reference.csv", here / "reference.csv")
    for p in sorted(here.iterdir()):
        size = sum(f.stat().st_size for f in p.rglob("*")) if p.is_dir() else p.stat().st_size
        print(f"{p.name:<22} {size / 1e6:6.2f} MB")


if __name__ == "__main__":
    main()
