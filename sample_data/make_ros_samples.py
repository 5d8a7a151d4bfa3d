"""Write the CSV sample drive (sample_data/drive) as ROS logs with navpp's own writers.

    python sample_data/make_ros_samples.py

Produces sample_data/drive.mcap (ROS 2, zstd chunks), sample_data/drive.bag (ROS 1, lz4) and
sample_data/drive_ros2/ (ROS 2 bag, sqlite3), each with /imu/data (sensor_msgs/Imu) and
/gnss/fix (sensor_msgs/NavSatFix) carrying exactly the CSV log's stamps and values, and copies
drive/navpp.toml and drive/reference.csv beside them as the shared navpp.toml and
reference.csv that navpp picks up for logs in this directory.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from navpp.io.csv import read_csv_log
from navpp.io.roswrite import write_mcap_ros2, write_ros1_bag, write_ros2_bag


def main() -> None:
    here = Path(__file__).resolve().parent
    rec = read_csv_log(here / "drive")
    write_mcap_ros2(rec, here / "drive.mcap", compression="zstd")
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
