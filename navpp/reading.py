"""Finding and reading a log: its configuration, the files beside it, any format into a Recording.

A *log* is a CSV log directory (``imu.csv``, ``gnss.csv``, optional ``reference.csv``), an
MCAP file (ROS 2 or ROS 1 encoded), a ROS 1 bag or a ROS 2 bag directory; the reader is chosen
by content (:func:`navpp.io.detect.log_kind`).  Files that go with a log (its ``navpp.toml``,
its reference) are found by :func:`companion`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from .config import Config, load_config
from .errors import ConfigError, InputError

if TYPE_CHECKING:
    from .io.frames import Anchor
    from .io.ros import LogContents
    from .recording import Recording, ReferenceData

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
             gnss_file: str | Path | None = None, odometry_topic: str | None = None,
             reference_anchor: str | None = None) -> Recording:
    """Read any supported log into a validated :class:`Recording`.

    CSV log directories, MCAP files (ROS 2 or ROS 1 encoded), ROS 1 bags and ROS 2 bag
    directories; the reader is chosen by content.  ``gnss_file`` (an RTKLIB .pos) replaces or
    supplies the log's GNSS (a ROS log's NavSatFix topic is then not read); ``reference`` (a CSV
    or a TUM file) or ``reference_topic`` (a NavSatFix, Odometry or PoseStamped topic) gives the
    reference, else a ``reference.csv`` / ``reference.tum`` found by :func:`companion`; a pose
    reference in a local frame needs an anchor (``reference_anchor`` ``"LAT,LON,ALT"``, or the
    one its file names: :mod:`navpp.io.refposes`).  ``odometry_topic`` the wheel odometry topic
    of a ROS log (None: the automatic choice of :func:`navpp.io.detect.choose_odometry_topic`);
    ``"none"`` leaves any log's odometry out.  ``Recording.notes`` says which reference and GNSS
    were used and how they were found.
    """
    from dataclasses import replace

    from .io import csv as csv_io
    from .io.detect import list_topics, log_kind

    path = Path(log)
    kind, where = log_kind(path)
    notes: list[str] = []
    pose_topic = None
    replaced = ["gnss.csv"]
    if kind == "csv":
        no_odometry = odometry_topic is not None and odometry_topic.lower() == "none"
        if imu_topic or gnss_topic or reference_topic or (odometry_topic and not no_odometry):
            raise ConfigError(f"{path}: --imu-topic, --gnss-topic, --reference-topic and --odometry-topic apply to "
                              "ROS logs, not to a CSV log (--odometry-topic none does: no odometry)")
        csv_ref = reference if reference is not None and not _is_tum(reference) else None
        rec = csv_io.read_csv_log(where, reference=csv_ref, time_base=config.time.base,
                                  gyro_units=config.imu.gyro_units, accel_units=config.imu.accel_units,
                                  time_offset_s=config.gnss.time_offset_s, progress=progress,
                                  memory=config.output.memory)
        if no_odometry and rec.odometry is not None:
            rec = replace(rec, odometry=None)
        if reference is None and rec.reference is not None:
            notes.append(_reference_note(rec.reference, "in the log directory"))
    else:
        types = {t.topic: t.msgtype for t in list_topics(kind, where)}
        if reference_topic is not None and types.get(reference_topic) in _pose_types():
            pose_topic, reference_topic = reference_topic, None
        rec, replaced = _read_ros_log(kind, where, config, imu_topic, gnss_topic, reference_topic,
                                      gnss_file is not None, odometry_topic, pose_topic)
        if reference_topic is not None and rec.reference is not None:
            n = len(rec.reference)
            notes.append(f"reference: topic {reference_topic} (NavSatFix, {n:,} fix{'es' if n != 1 else ''})")
    if pose_topic is not None:
        rec = _with_pose_reference(rec, kind, where, pose_topic, types[pose_topic], config, reference_anchor, notes)
    elif reference is not None and (kind != "csv" or _is_tum(reference)):
        rec = _with_file_reference(rec, reference, reference_anchor, "--reference", notes)
    elif reference is None and reference_topic is None and kind != "csv":
        found = companion(path, csv_io.REFERENCE_FILE) or companion(path, REFERENCE_TUM)    # e.g. drive.reference.csv
        if found is not None:
            rec = _with_file_reference(rec, found, reference_anchor, "found beside the log", notes)
    elif reference is not None:
        notes.append(_reference_note(rec.reference, "--reference"))
    if gnss_file is not None:
        from .io.rtklib import read_pos

        gnss, warnings, _ = read_pos(gnss_file, time_base=config.time.base, t0_ns=rec.t0_ns)
        if config.gnss.time_offset_s:
            gnss = replace(gnss, t=gnss.t + config.gnss.time_offset_s)
        what = (f"replacing the log's {'topics' if len(replaced) > 1 else 'topic' if kind != 'csv' else ''} "
                f"{', '.join(replaced)}".replace("  ", " ") if replaced else "the log has no GNSS")
        notes.append(f"GNSS: {gnss_file} (RTKLIB, {len(gnss.t):,} fixes), {what}")
        rec = replace(rec, gnss=gnss, warnings=tuple(rec.warnings) + tuple(warnings))
    if reference_anchor is not None and not any(n.endswith("(--reference-anchor)") for n in notes):
        raise ConfigError(f"--reference-anchor {reference_anchor}: applies to a reference in a local frame (a TUM "
                          "file, an Odometry or PoseStamped topic); this run's reference is "
                          + (str(rec.reference.source) if rec.reference is not None else "none"))
    return replace(rec, notes=tuple(rec.notes) + tuple(notes))


#: A reference in TUM format found beside a ROS log (as reference.csv is).
REFERENCE_TUM = "reference.tum"


def _is_tum(reference: str | Path) -> bool:
    from .io.refposes import is_tum

    return is_tum(reference)


def _pose_types() -> tuple[str, ...]:
    from .io.refposes import POSE_REFERENCE_TYPES

    return POSE_REFERENCE_TYPES


def _reference_note(ref: ReferenceData | None, how: str) -> str:
    if ref is None:
        return f"reference: none ({how})"
    n = len(ref)
    att = ", with attitude" if ref.rph_deg is not None else ""
    return f"reference: {ref.source}, {how} ({n:,} epoch{'s' if n != 1 else ''}{att})"


def _anchor_text(anchor: Anchor) -> str:
    return f"lat {anchor.lat_deg:.9f} deg, lon {anchor.lon_deg:.9f} deg, height {anchor.alt:.4f} m"


def _chosen_anchor(given: str | None, found: Anchor | None, what: str, found_how: str) -> tuple[Anchor, str]:
    """The anchor of a local-frame reference: ``--reference-anchor`` first, then the one its file
    names; InputError naming the reference when there is none."""
    from .io.refposes import parse_anchor

    if given is not None:
        return parse_anchor(given), "--reference-anchor"
    if found is not None:
        return found, found_how
    raise InputError(f"{what}: poses in a local frame and no anchor for it: give its origin with "
                     "--reference-anchor LAT,LON,ALT (deg, deg, m above the WGS-84 ellipsoid; ENU axes)")


def _with_file_reference(rec: Recording, reference: str | Path, anchor_text: str | None, how: str,
                         notes: list[str]) -> Recording:
    """``rec`` with the reference CSV or TUM file ``reference``; its note appended to ``notes``."""
    from dataclasses import replace

    from .io import csv as csv_io

    if not _is_tum(reference):
        warnings: list[str] = []
        ref = csv_io.read_reference_csv(reference, rec.t0_ns, warnings_out=warnings)
        notes.append(_reference_note(ref, how))
        return replace(rec, reference=ref, warnings=tuple(rec.warnings) + tuple(warnings))
    from .io.refposes import read_tum, reference_from_poses

    track, found = read_tum(reference)
    anchor, anchored = _chosen_anchor(anchor_text, found, str(reference), "its header")
    ref = reference_from_poses(track, anchor, rec.t0_ns, float(rec.imu.t[-1]), str(reference))
    notes.append(f"reference: file {reference} (TUM, {len(ref):,} poses, with attitude), {how}; anchored at "
                 f"{_anchor_text(anchor)} ({anchored})")
    return replace(rec, reference=ref)


def _with_pose_reference(rec: Recording, kind: str, where: Path, topic: str, msgtype: str, config: Config,
                         anchor_text: str | None, notes: list[str]) -> Recording:
    """``rec`` with an Odometry / PoseStamped topic as the reference; its note appended."""
    from dataclasses import replace

    from .io.detect import bag_paths
    from .io.refposes import read_pose_topic, reference_from_poses

    track, found = read_pose_topic(kind, bag_paths(kind, where), topic, msgtype, config.time.source)
    anchor, anchored = _chosen_anchor(anchor_text, found, track.what, "the MCAP's navpp map anchor")
    ref = reference_from_poses(track, anchor, rec.t0_ns, float(rec.imu.t[-1]), f"{rec.source}:{topic}")
    vel = ", velocity" if ref.vel_enu is not None else ""
    notes.append(f"reference: topic {topic} ({msgtype.rsplit('/', 1)[-1]}, frame {track.frame_id!r}, "
                 f"{len(ref):,} poses, with attitude{vel}; chosen with --reference-topic), anchored at "
                 f"{_anchor_text(anchor)} ({anchored})")
    return replace(rec, reference=ref)


def _read_ros_log(kind: str, path: Path, config: Config, imu_topic: str | None, gnss_topic: str | None,
                  reference_topic: str | None, gnss_from_file: bool, odometry_topic: str | None = None,
                  pose_topic: str | None = None) -> tuple[Recording, list[str]]:
    """The ROS log as a Recording, and the NavSatFix topics a GNSS file replaces (not read)."""
    from .io.assemble import choose_topic, recording_from_log
    from .io.detect import list_topics, read_topics
    from .io.ros import FIX_TYPE, IMU_TYPE, ODOMETRY_TYPES, VELOCITY_TYPES, LogContents

    topics = list_topics(kind, path)
    index = LogContents(str(path), topics)
    wanted = [choose_topic(index, IMU_TYPE, "IMU", "--imu-topic", imu_topic)]
    replaced: list[str] = []
    if gnss_from_file:
        replaced = [t.topic for t in topics if t.msgtype == FIX_TYPE and t.topic != reference_topic]
        if gnss_topic is not None and gnss_topic not in replaced:
            choose_topic(index, FIX_TYPE, "GNSS", "--gnss-topic", gnss_topic)    # names a wrong one
    else:
        wanted.append(choose_topic(index, FIX_TYPE, "GNSS", "--gnss-topic", gnss_topic,
                                   (reference_topic,) if reference_topic else ()))
        # every velocity topic: its frame tells GNSS velocity from wheel odometry
        wanted += [t.topic for t in topics if t.msgtype in VELOCITY_TYPES]
    if odometry_topic is None:
        wanted += [t.topic for t in topics if t.msgtype in ODOMETRY_TYPES and t.topic != pose_topic]
    elif odometry_topic.lower() != "none":
        known = {t.topic: t.msgtype for t in topics}     # a missing or wrong one: the assembler says so
        wanted.append(odometry_topic if known.get(odometry_topic) in ODOMETRY_TYPES else None)
    if reference_topic:
        wanted.append(choose_topic(index, FIX_TYPE, "reference", "--reference-topic", reference_topic))
    contents = read_topics(kind, path, list(dict.fromkeys(w for w in wanted if w)), config.output.memory)
    if gnss_from_file:
        contents = _with_placeholder_fix(contents, set(replaced))
        gnss_topic = _PLACEHOLDER
    rec = recording_from_log(contents, imu_topic=imu_topic, gnss_topic=gnss_topic, reference_topic=reference_topic,
                             time_source=config.time.source, time_base=config.time.base,
                             default_std_m=config.gnss.default_std_m, gyro_scale=config.imu.gyro_scale,
                             accel_scale=config.imu.accel_scale, time_offset_s=config.gnss.time_offset_s,
                             odometry_topic=odometry_topic)
    return rec, replaced


_PLACEHOLDER = "(--gnss)"


def _with_placeholder_fix(contents: LogContents, replaced: set[str]) -> LogContents:
    """The log's contents for a run whose GNSS comes from --gnss: the NavSatFix topics it
    replaces (``replaced``, not decoded) left out, and one IMU-timed placeholder fix so the
    assembler can build the Recording; the caller then puts the file's fixes in."""
    import numpy as np

    from .io.ros import FIX_TYPE, FixMessages, TopicInfo

    imu = next(iter(contents.imu.values()))
    ns = imu.stamp_ns[:1]
    fix = FixMessages(_PLACEHOLDER, ns, ns, np.zeros(1, np.int8), np.zeros(1), np.zeros(1), np.zeros(1),
                      np.zeros((1, 9)), np.zeros(1, np.uint8))
    kept = tuple(t for t in contents.topics if t.topic not in replaced)
    return type(contents)(contents.source, kept + (TopicInfo(_PLACEHOLDER, FIX_TYPE, 1),),
                          contents.imu, {**contents.fix, _PLACEHOLDER: fix}, contents.twist, contents.warnings)
