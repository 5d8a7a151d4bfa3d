"""Which reader a log needs, chosen by content (magic bytes), not only by suffix.

Kinds: ``csv`` (a directory with imu.csv and gnss.csv), ``mcap`` (an MCAP file, ROS 2 or
ROS 1 encoded), ``ros1`` (a ROS 1 .bag file, or a directory of the .bag files of a split
recording), ``ros2`` (a ROS 2 bag directory with metadata.yaml; its .db3 file may be given
instead).

Also which velocity topic of a ROS log is wheel odometry and which GNSS velocity
(:func:`choose_odometry_topic`, :func:`gnss_velocity_topics`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from .ros import ODOM_TYPE, ODOMETRY_TYPES, VELOCITY_TYPES, LogContents, TopicInfo, TwistMessages

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


def bag_paths(kind: str, path: Path) -> Path | list[Path]:
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

    return bag_topics(bag_paths(kind, path))


def read_topics(kind: str, path: Path, topics: list[str], memory: int | None = None) -> LogContents:
    """Decode the given topics of a ROS log; a topic's messages beyond ``memory`` bytes (None:
    never) go to a spill file as they are decoded (:mod:`navpp.spill`)."""
    if kind == "mcap":
        from .mcap import read_mcap

        return read_mcap(path, topics, memory=memory)
    from .rosbag import read_rosbag

    return read_rosbag(bag_paths(kind, path), topics, memory=memory)


# --------------------------------------------------------------------------- wheel odometry role
#
# A velocity topic is either GNSS velocity (ENU, as GNSS drivers publish it: frame 'gps', 'gnss',
# 'enu' or empty) or wheel odometry (forward speed and yaw rate in the vehicle frame: the
# child_frame_id of a nav_msgs/Odometry, the frame_id of a Twist).  The frame decides, so one log
# can have both and they never collide.  Fused outputs (robot_localization's /odometry/filtered,
# an EKF's odometry, navpp's own /navpp/odometry) are never picked automatically: their twist
# already holds the IMU and GNSS that navpp fuses itself (counting them twice would make the
# filter overconfident); the wheel controller's own topic is the independent measurement.  They
# can still be chosen with --odometry-topic.

#: Vehicle (body) frames of REP-105 and common drivers, optionally namespaced ('husky/base_link').
_VEHICLE_FRAME = re.compile(r"(^|[/_])(base_link|base_footprint|base|chassis|vehicle|body|wheel_odom)$", re.I)
#: The odometry frame an Odometry's pose is in when the controller leaves child_frame_id empty.
_ODOM_FRAME = re.compile(r"(^|[/_])odom(etry)?(_combined)?$", re.I)
#: Topic names of fused or commanded velocities and GNSS: never wheel odometry automatically.
_NOT_WHEEL_TOPIC = re.compile(r"filtered|ekf|ukf|fused|global|gps|gnss|navsat|cmd|^/navpp/", re.I)
#: The rate (Hz) of a wheel odometry topic: controllers publish at 10-100 Hz.
ODOMETRY_RATE_HZ = (5.0, 200.0)
#: ``--odometry-topic`` value that turns odometry off.
NO_ODOMETRY = "none"


def _rate_hz(stamps_ns: np.ndarray) -> float | None:
    d = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    d = d[d > 0]
    return 1e9 / float(np.median(d)) if d.size else None


def _frame(msgs: TwistMessages, msgtype: str) -> str:
    """The frame the twist is expressed in: an Odometry's child frame, a Twist's header frame."""
    return msgs.child_frame_id if msgtype == ODOM_TYPE else msgs.frame_id


def in_vehicle_frame(msgs: TwistMessages, msgtype: str) -> bool:
    """True when the twist is in a vehicle frame (base_link, ...; an Odometry with an empty child
    frame but an odom-frame pose counts, as some controllers leave child_frame_id empty)."""
    if _VEHICLE_FRAME.search(_frame(msgs, msgtype)):
        return True
    return msgtype == ODOM_TYPE and not msgs.child_frame_id and bool(_ODOM_FRAME.search(msgs.frame_id))


def odometry_verdict(topic: str, msgtype: str, msgs: TwistMessages | None) -> str:
    """'' when ``topic`` looks like wheel odometry, else why not (for notes and ``inspect``)."""
    if msgtype not in ODOMETRY_TYPES:
        return f"type {msgtype}"
    if _NOT_WHEEL_TOPIC.search(topic):
        return "a fused, commanded or GNSS velocity by its name"
    if msgs is None or msgs.stamp_ns.shape[0] < 2:
        return "fewer than 2 messages"
    if not in_vehicle_frame(msgs, msgtype):
        return f"frame {_frame(msgs, msgtype)!r} is not a vehicle frame"
    rate = _rate_hz(msgs.stamp_ns)
    lo, hi = ODOMETRY_RATE_HZ
    if rate is None or not lo <= rate <= hi:
        return f"rate {rate or 0:.3g} Hz outside {lo:g}-{hi:g} Hz"
    return ""


def _preference(topic: str, msgtype: str) -> tuple[int, int, int]:
    """Sort key among wheel odometry candidates (higher first): a controller's Odometry named
    like one (``/husky_velocity_controller/odom``, ``/wheel/odom``), then any Odometry, then an
    'odom' / 'wheel' name."""
    name = topic.lower()
    odom = msgtype == ODOM_TYPE
    return (int(odom and "odom" in name and ("wheel" in name or "velocity_controller" in name)), int(odom),
            int("odom" in name or "wheel" in name))


def choose_odometry_topic(contents: LogContents, given: str | None) -> tuple[str | None, str]:
    """The wheel odometry topic of a decoded log and a note saying why (or why none).

    ``given``: ``--odometry-topic`` (checked to exist and be one of the odometry types; ``none``
    turns odometry off); None chooses among the decoded topics that look like wheel odometry
    (:func:`odometry_verdict`), preferring :func:`_preference`.  Several equally good candidates
    choose none (the note names them).  InputError for a bad ``given``.
    """
    src = contents.source
    if given is not None and given.lower() == NO_ODOMETRY:
        return None, "odometry: off (--odometry-topic none)"
    types = {t.topic: t.msgtype for t in contents.topics}
    if given is not None:
        if given not in types:
            raise InputError(f"{src}: no topic {given!r} (--odometry-topic); topics: "
                             f"{', '.join(sorted(types)) or 'none'}")
        if types[given] not in ODOMETRY_TYPES:
            raise InputError(f"{src}: topic {given!r} (--odometry-topic) is {types[given]}, not one of "
                             f"{', '.join(ODOMETRY_TYPES)}")
        return given, f"odometry: {given} ({types[given]}, chosen with --odometry-topic)"
    cands = [t for t, m in types.items() if m in ODOMETRY_TYPES and not odometry_verdict(t, m, contents.twist.get(t))]
    if not cands:
        return None, "odometry: none (no topic looks like wheel odometry)"
    cands.sort(key=lambda t: _preference(t, types[t]), reverse=True)
    best = [t for t in cands if _preference(t, types[t]) == _preference(cands[0], types[cands[0]])]
    if len(best) > 1:
        return None, (f"odometry: not used: several topics look like wheel odometry ({', '.join(best)}); "
                      "choose one with --odometry-topic")
    msgs = contents.twist[best[0]]
    frame = _frame(msgs, types[best[0]])
    return best[0], (f"odometry: {best[0]} ({types[best[0]]}, frame {frame or msgs.frame_id!r}, "
                     f"{_rate_hz(msgs.stamp_ns) or 0:.3g} Hz)")


def gnss_velocity_topics(contents: LogContents, odometry_topic: str | None = None) -> list[str]:
    """The Twist topics that may be GNSS velocity: not the odometry topic and not in a vehicle
    frame (when decoded)."""
    out = []
    for t in contents.topics:
        if t.msgtype not in VELOCITY_TYPES or t.topic == odometry_topic:
            continue
        msgs = contents.twist.get(t.topic)
        if msgs is not None and in_vehicle_frame(msgs, t.msgtype):
            continue
        out.append(t.topic)
    return out
