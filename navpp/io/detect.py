"""Which reader a log needs, chosen by content (magic bytes), not only by suffix.

Kinds: ``csv`` (a directory with imu.csv and gnss.csv), ``mcap`` (an MCAP file, ROS 2 or
ROS 1 encoded), ``ros1`` (a ROS 1 .bag file, or a directory of the .bag files of a split
recording), ``ros2`` (a ROS 2 bag directory with metadata.yaml; its .db3 file may be given
instead).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .ros import LogContents, TopicInfo

MCAP_MAGIC = b"\x89MCAP0\r\n"
BAG_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


def log_kind(path: Path) -> tuple[str, Path]:
    """(kind, the path to hand to its reader); InputError for anything else."""
    from .csv import GNSS_FILE, IMU_FILE, is_csv_log

    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    if path.is_dir():
        if is_csv_log(path):
            return "csv", path
        if (path / "metadata.yaml").is_file():
            return "ros2", path
        if any(path.glob("*.bag")):
            return "ros1", path          # a split ROS 1 recording: every .bag file in it
        present = [name for name in (IMU_FILE, GNSS_FILE) if (path / name).is_file()]
        if len(present) == 1:  # half a CSV log: name the file that is missing
            missing = GNSS_FILE if present[0] == IMU_FILE else IMU_FILE
            raise InputError(f"{path / missing}: file not found (a CSV log needs {IMU_FILE} and {GNSS_FILE})")
        if any(path.glob("*.db3")) or any(path.glob("*.mcap")):
            raise InputError(f"{path}: looks like a ROS 2 bag but has no metadata.yaml")
        raise InputError(f"{path}: not a log directory (expected imu.csv and gnss.csv, or a ROS 2 bag with "
                         "metadata.yaml)")
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not head:
        raise InputError(f"{path}: empty file")
    if head.startswith(MCAP_MAGIC):
        return "mcap", path
    if head.startswith(BAG_MAGIC):
        return "ros1", path
    if head.startswith(SQLITE_MAGIC):
        if (path.parent / "metadata.yaml").is_file():
            return "ros2", path.parent
        raise InputError(f"{path}: a sqlite3 file without the metadata.yaml of a ROS 2 bag beside it")
    raise InputError(f"{path}: not a log navpp reads (MCAP, ROS 1 bag, ROS 2 bag directory, or a directory with "
                     "imu.csv and gnss.csv)")


def _bag_paths(kind: str, path: Path) -> Path | list[Path]:
    """The files of a split ROS 1 recording given as a directory, else the path itself."""
    if kind == "ros1" and path.is_dir():
        return sorted(path.glob("*.bag"))
    return path


def list_topics(kind: str, path: Path) -> tuple[TopicInfo, ...]:
    """Every topic of a ROS log, cheaply (summary or index)."""
    if kind == "mcap":
        from .mcap import list_topics as mcap_topics

        return mcap_topics(path)
    from .rosbag import list_topics as bag_topics

    return bag_topics(_bag_paths(kind, path))


def read_topics(kind: str, path: Path, topics: list[str]) -> LogContents:
    """Decode the given topics of a ROS log."""
    if kind == "mcap":
        from .mcap import read_mcap

        return read_mcap(path, topics)
    from .rosbag import read_rosbag

    return read_rosbag(_bag_paths(kind, path), topics)
