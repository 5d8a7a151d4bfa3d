"""Finding and reading a log: its configuration, the files beside it, any format into a Recording.

A *log* is a CSV log directory (``imu.csv``, ``gnss.csv``, optional ``reference.csv``), an
MCAP file (ROS 2 or ROS 1 encoded), a ROS 1 bag or a ROS 2 bag directory; the reader is chosen
by content (:func:`navpp.io.detect.log_kind`).  Files that go with a log (its ``navpp.toml``,
its reference) are found by :func:`companion`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from .config import Config, load_config
from .errors import ConfigError
from .recording import Recording

#: The configuration file navpp looks for beside (or inside) a log.
CONFIG_IN_LOG_DIR = "navpp.toml"


def companion(log: Path, name: str) -> Path | None:
    """A file that goes with a log: ``name`` inside a log directory; else ``<stem>.<name>``
    beside the log; else ``name`` in the log's directory (shared by the logs there)."""
    candidates = [log / name] if log.is_dir() else []
    candidates += [log.parent / f"{log.stem if log.is_file() else log.name}.{name}", log.parent / name]
    return next((c for c in candidates if c.is_file()), None)


def resolve_config(log: Path, config_path: str | Path | None) -> Config:
    """Explicit ``--config``; else the log's ``navpp.toml`` (:func:`companion`); else defaults."""
    if config_path is not None:
        return load_config(config_path)
    found = companion(log, CONFIG_IN_LOG_DIR)
    return load_config(found)


def read_log(log: str | Path, config: Config, *, reference: str | Path | None = None,
             progress: Callable[[float], None] | None = None, imu_topic: str | None = None,
             gnss_topic: str | None = None, reference_topic: str | None = None,
             gnss_file: str | Path | None = None, odometry_topic: str | None = None) -> Recording:
    """Read any supported log into a validated :class:`Recording`.

    CSV log directories, MCAP files (ROS 2 or ROS 1 encoded), ROS 1 bags and ROS 2 bag
    directories; the reader is chosen by content.  ``gnss_file`` (an RTKLIB .pos) replaces or
    supplies the log's GNSS; ``reference`` (a CSV) or ``reference_topic`` gives the reference;
    ``odometry_topic`` the wheel odometry topic of a ROS log (None: the automatic choice of
    :func:`navpp.io.detect.choose_odometry_topic`); ``"none"`` leaves any log's odometry out.
    """
    from dataclasses import replace

    from .io import csv as csv_io
    from .io.detect import log_kind

    path = Path(log)
    kind, where = log_kind(path)
    if kind == "csv":
        no_odometry = odometry_topic is not None and odometry_topic.lower() == "none"
        if imu_topic or gnss_topic or reference_topic or (odometry_topic and not no_odometry):
            raise ConfigError(f"{path}: --imu-topic, --gnss-topic, --reference-topic and --odometry-topic apply to "
                              "ROS logs, not to a CSV log (--odometry-topic none does: no odometry)")
        rec = csv_io.read_csv_log(where, reference=reference, time_base=config.time.base,
                                  gyro_units=config.imu.gyro_units, accel_units=config.imu.accel_units,
                                  time_offset_s=config.gnss.time_offset_s, progress=progress)
        if no_odometry and rec.odometry is not None:
            rec = replace(rec, odometry=None)
    else:
        rec = _read_ros_log(kind, where, config, imu_topic, gnss_topic, reference_topic, gnss_file is not None,
                            odometry_topic)
        if reference is None and reference_topic is None:
            reference = companion(path, csv_io.REFERENCE_FILE)       # e.g. drive.reference.csv
        if reference is not None:
            rec = replace(rec, reference=csv_io.read_reference_csv(reference, rec.t0_ns))
    if gnss_file is not None:
        from .io.rtklib import read_pos

        gnss, warnings, _ = read_pos(gnss_file, time_base=config.time.base, t0_ns=rec.t0_ns)
        if config.gnss.time_offset_s:
            gnss = replace(gnss, t=gnss.t + config.gnss.time_offset_s)
        rec = replace(rec, gnss=gnss, warnings=tuple(rec.warnings) + tuple(warnings))
    return rec


def _read_ros_log(kind: str, path: Path, config: Config, imu_topic: str | None, gnss_topic: str | None,
                  reference_topic: str | None, gnss_from_file: bool, odometry_topic: str | None = None) -> Recording:
    from .io.assemble import choose_topic, recording_from_log
    from .io.detect import list_topics, read_topics
    from .io.ros import FIX_TYPE, IMU_TYPE, ODOMETRY_TYPES, VELOCITY_TYPES, LogContents

    topics = list_topics(kind, path)
    index = LogContents(str(path), topics)
    wanted = [choose_topic(index, IMU_TYPE, "IMU", "--imu-topic", imu_topic)]
    if not gnss_from_file:
        wanted.append(choose_topic(index, FIX_TYPE, "GNSS", "--gnss-topic", gnss_topic,
                                   (reference_topic,) if reference_topic else ()))
        # every velocity topic: its frame tells GNSS velocity from wheel odometry
        wanted += [t.topic for t in topics if t.msgtype in VELOCITY_TYPES]
    if odometry_topic is None:
        wanted += [t.topic for t in topics if t.msgtype in ODOMETRY_TYPES]
    elif odometry_topic.lower() != "none":
        known = {t.topic: t.msgtype for t in topics}     # a missing or wrong one: the assembler says so
        wanted.append(odometry_topic if known.get(odometry_topic) in ODOMETRY_TYPES else None)
    if reference_topic:
        wanted.append(choose_topic(index, FIX_TYPE, "reference", "--reference-topic", reference_topic))
    contents = read_topics(kind, path, list(dict.fromkeys(w for w in wanted if w)))
    if gnss_from_file and not any(t.msgtype == FIX_TYPE for t in contents.topics):
        contents = _with_placeholder_fix(contents)
    return recording_from_log(contents, imu_topic=imu_topic, gnss_topic=gnss_topic, reference_topic=reference_topic,
                              time_source=config.time.source, time_base=config.time.base,
                              default_std_m=config.gnss.default_std_m, gyro_scale=config.imu.gyro_scale,
                              accel_scale=config.imu.accel_scale, time_offset_s=config.gnss.time_offset_s,
                              odometry_topic=odometry_topic)


def _with_placeholder_fix(contents):
    """A log without GNSS whose GNSS comes from --gnss: give the assembler one IMU-timed fix
    so it can build the Recording; the engine then uses the file's fixes."""
    import numpy as np

    from .io.ros import FIX_TYPE, FixMessages, TopicInfo

    imu = next(iter(contents.imu.values()))
    ns = imu.stamp_ns[:1]
    fix = FixMessages("(--gnss)", ns, ns, np.zeros(1, np.int8), np.zeros(1), np.zeros(1), np.zeros(1),
                      np.zeros((1, 9)), np.zeros(1, np.uint8))
    return type(contents)(contents.source, contents.topics + (TopicInfo("(--gnss)", FIX_TYPE, 1),),
                          contents.imu, {"(--gnss)": fix}, contents.twist, contents.warnings)

