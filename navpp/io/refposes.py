"""References given as poses in a local frame: TUM files and ``nav_msgs/Odometry`` /
``geometry_msgs/PoseStamped`` topics, anchored to WGS-84.

A local-frame pose (``x y z`` metres, an orientation quaternion) becomes a
:class:`navpp.recording.ReferenceData` (latitude, longitude, ellipsoidal height, roll / pitch /
heading) once its frame is tied to the Earth.  navpp supports one kind of local frame: ENU
(x east, y north, z up) on the tangent plane of an *anchor* point, the frame of navpp's own
exports (:mod:`navpp.io.frames`): ``trajectory.tum`` and the ``map`` frame of
``trajectory.mcap``.  The pose is the body (IMU) origin, the orientation the rotation taking
body FLU vectors (x forward, y left, z up) into the anchor's ENU axes.

Where the anchor comes from, first found wins:

1. given by the user (``--reference-anchor LAT,LON,ALT``: degrees, degrees, metres above the
   WGS-84 ellipsoid);
2. a TUM file's own comment line as navpp writes it
   (``# x y z: m, local ENU (east, north, up) about lat .. deg, lon .. deg, height .. m``);
3. for a topic of an MCAP file written by navpp whose frame is ``map``: the file's ``navpp``
   metadata record (``map_anchor_lat_deg``, ``map_anchor_lon_deg``, ``map_anchor_alt_m``).

Without one, the reference is refused (a local frame cannot be compared with a geodetic
solution).  Positions are converted exactly (through ECEF); the orientation is turned from the
anchor's ENU axes into the local-level ENU axes at each position (the inverse of
:func:`navpp.io.frames.body_to_map`), so navpp's own exports read back give the solution's
roll, pitch and heading.  An Odometry's ``twist.linear`` (body frame, m/s) becomes the ENU
velocity.

Decoding uses the ``mcap_ros2`` / ``mcap_ros1`` decoders (MCAP) and ``rosbags`` (bags), one
message at a time: a reference topic is read once, and is small next to the IMU.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..ins.attitude import dcm_to_rph, quat_to_dcm_batch
from ..recording import ReferenceData
from .frames import Anchor
from .ros import ODOM_TYPE as ODOMETRY_TYPE
from .ros import POSE_TYPE

#: The message types a pose reference topic may have (ROS 1 names).
POSE_REFERENCE_TYPES = (ODOMETRY_TYPE, POSE_TYPE)

_TUM_ANCHOR = re.compile(r"about lat\s+(\S+)\s+deg,\s+lon\s+(\S+)\s+deg,\s+height\s+(\S+)\s+m")


@dataclass(frozen=True)
class PoseTrack:
    """Poses of the body origin in a local frame, in time order.

    stamp_ns : (N,) int64, absolute ns on the log's time base.
    xyz : (N, 3) float, m, local frame (ENU about the anchor).
    quat_xyzw : (N, 4) float, body FLU -> local frame, or None (no orientation).
    vel_body : (N, 3) float, m/s, body FLU, or None.
    frame_id : the local frame's name ('' for a file); what : names the source in messages.
    linenos : (N,) int, the file's line of each pose (TUM), None for a topic (message index).
    """

    stamp_ns: np.ndarray
    xyz: np.ndarray
    quat_xyzw: np.ndarray | None
    vel_body: np.ndarray | None
    frame_id: str
    what: str
    linenos: np.ndarray | None = None


def parse_anchor(text: str, what: str = "--reference-anchor") -> Anchor:
    """``"LAT,LON,ALT"`` (deg, deg, m above the WGS-84 ellipsoid) -> :class:`Anchor`."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"{what}: {text!r} is not LAT,LON,ALT (degrees, degrees, metres)") from None
    if not (np.isfinite([lat, lon, alt]).all() and -90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
        raise InputError(f"{what}: {text!r} is not a position (latitude -90..90 deg, longitude -180..360 deg)")
    return Anchor(lat, lon, alt)


# --------------------------------------------------------------------------- TUM files


def is_tum(path: str | Path) -> bool:
    """True for a TUM trajectory file: a ``.tum`` suffix, or (any suffix but ``.csv``) a first data
    line of 8 whitespace-separated fields without a comma (evo writes ``.txt``)."""
    p = Path(path)
    if p.suffix.lower() == ".tum":
        return True
    if p.suffix.lower() == ".csv" or not p.is_file():
        return False
    try:
        with open(p, encoding="utf-8", errors="replace") as f:
            for line in f:
                s = line.strip()
                if s and not s.startswith("#"):
                    return len(s.split()) == 8 and "," not in s
    except OSError:
        return False
    return False


def _decimal_ns(text: str) -> int | None:
    """``"1700000000.123456"`` -> integer ns, exactly (None if not a plain decimal)."""
    m = re.fullmatch(r"([+-]?)(\d+)(?:\.(\d*))?", text)
    if m is None:
        return None
    frac = (m.group(3) or "")[:9].ljust(9, "0")
    ns = int(m.group(2)) * 1_000_000_000 + int(frac)
    return -ns if m.group(1) == "-" else ns


def read_tum(path: str | Path) -> tuple[PoseTrack, Anchor | None]:
    """A TUM file (``t x y z qx qy qz qw`` per line, ``#`` comments) and the anchor its comment
    lines name (navpp's own ``trajectory.tum``), or None.  ``t``: seconds on the log's time base."""
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"{p}: cannot read: {exc.strerror or exc}") from None
    anchor = None
    stamps: list[int] = []
    rows: list[list[float]] = []
    linenos: list[int] = []
    for lineno, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = _TUM_ANCHOR.search(s)
            if m is not None and anchor is None:
                anchor = parse_anchor(",".join(m.groups()), f"{p}: line {lineno}")
            continue
        fields = s.split()
        ns = _decimal_ns(fields[0]) if fields else None
        if len(fields) != 8 or ns is None:
            raise InputError(f"{p}: line {lineno}: expected 8 numbers 't x y z qx qy qz qw' (TUM), got {s[:60]!r}")
        try:
            values = [float(v) for v in fields[1:]]
        except ValueError:
            raise InputError(f"{p}: line {lineno}: not a number in {s[:60]!r}") from None
        stamps.append(ns)
        rows.append(values)
        linenos.append(lineno)
    if not rows:
        raise InputError(f"{p}: no pose (a TUM file holds lines 't x y z qx qy qz qw')")
    table = np.asarray(rows, dtype=float)
    return PoseTrack(np.asarray(stamps, dtype=np.int64), table[:, :3], table[:, 3:7], None, "", str(p),
                     np.asarray(linenos)), anchor


# --------------------------------------------------------------------------- ROS topics


def _stamp_ns(msg: Any) -> int:
    st = msg.header.stamp
    if hasattr(st, "nanosec"):
        return int(st.sec) * 1_000_000_000 + int(st.nanosec)
    return int(st.secs) * 1_000_000_000 + int(st.nsecs)


def _pose_row(msgtype: str, msg: Any) -> tuple[list[float], list[float] | None]:
    pose = msg.pose.pose if msgtype == ODOMETRY_TYPE else msg.pose
    p, q = pose.position, pose.orientation
    row = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
    vel = None
    if msgtype == ODOMETRY_TYPE:
        v = msg.twist.twist.linear
        vel = [v.x, v.y, v.z]
    return row, vel


def _track(what: str, msgtype: str, stamps: list[int], logs: list[int], rows: list[list[float]],
           vels: list[list[float]], frame_id: str, time_source: str) -> PoseTrack:
    if not rows:
        raise InputError(f"{what}: no message (an empty reference topic)")
    table = np.asarray(rows, dtype=float)
    ns = np.asarray(logs if time_source == "log" else stamps, dtype=np.int64)
    vel = np.asarray(vels, dtype=float) if msgtype == ODOMETRY_TYPE else None
    return PoseTrack(ns, table[:, :3], table[:, 3:7], vel, frame_id, what)


def read_pose_topic(kind: str, path: Path | list[Path], topic: str, msgtype: str,
                    time_source: str = "header") -> tuple[PoseTrack, Anchor | None]:
    """An Odometry / PoseStamped topic of a ROS log (``kind`` as :func:`navpp.io.detect.log_kind`)
    and, for an MCAP file written by navpp with the topic in its ``map`` frame, that map's anchor."""
    what = f"{path}: topic {topic!r}"
    stamps: list[int] = []
    logs: list[int] = []
    rows: list[list[float]] = []
    vels: list[list[float]] = []
    frame_id = ""
    anchor = None

    def add(msg: Any, log_ns: int) -> str:
        row, vel = _pose_row(msgtype, msg)
        stamps.append(_stamp_ns(msg))
        logs.append(log_ns)
        rows.append(row)
        if vel is not None:
            vels.append(vel)
        return frame_id or str(msg.header.frame_id)

    try:
        if kind == "mcap":
            from mcap.reader import make_reader
            from mcap_ros1.decoder import DecoderFactory as Ros1Factory
            from mcap_ros2.decoder import DecoderFactory as Ros2Factory

            with open(str(path), "rb") as f:
                reader = make_reader(f, decoder_factories=[Ros2Factory(), Ros1Factory()])
                for _schema, _channel, message, msg in reader.iter_decoded_messages(topics=[topic],
                                                                                     log_time_order=True):
                    frame_id = add(msg, int(message.log_time))
                f.seek(0)
                meta = next((m.metadata for m in make_reader(f).iter_metadata() if m.name == "navpp"), None)
            if meta is not None and frame_id == "map" and "map_anchor_lat_deg" in meta:
                anchor = Anchor(float(meta["map_anchor_lat_deg"]), float(meta["map_anchor_lon_deg"]),
                                float(meta["map_anchor_alt_m"]))
        else:
            from rosbags.highlevel import AnyReader

            files = path if isinstance(path, list) else [path]
            with AnyReader(list(files)) as bag:
                conns = [c for c in bag.connections if c.topic == topic]
                for conn, log_ns, raw in bag.messages(connections=conns):
                    frame_id = add(bag.deserialize(raw, conn.msgtype), int(log_ns))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - decoder and container errors: all bad input
        raise InputError(f"{what}: cannot decode ({type(exc).__name__}: {exc})") from None
    return _track(what, msgtype, stamps, logs, rows, vels, frame_id, time_source), anchor


# --------------------------------------------------------------------------- to a reference


def reference_from_poses(track: PoseTrack, anchor: Anchor, t0_ns: int, t_end_s: float,
                         source: str) -> ReferenceData:
    """The poses as a :class:`ReferenceData` (t relative to ``t0_ns``; geodetic positions; roll,
    pitch, heading in the local-level ENU frame; ENU velocity from an Odometry's body twist).

    InputError: a non-finite value or a zero quaternion (naming the row), stamps going back, or
    no pose inside the log's span ``0 .. t_end_s`` (s from ``t0_ns``).
    """
    what = track.what
    cols = [track.xyz] + ([track.quat_xyzw] if track.quat_xyzw is not None else []) \
        + ([track.vel_body] if track.vel_body is not None else [])
    bad = ~np.isfinite(np.hstack(cols)).all(axis=1)
    q = track.quat_xyzw
    if q is not None:
        bad |= np.linalg.norm(np.where(np.isfinite(q), q, 0.0), axis=1) < 1e-6

    def where(k: int) -> str:
        return f"line {int(track.linenos[k])}" if track.linenos is not None else f"message {k}"

    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{what}: {where(k)} (t = {track.stamp_ns[k] * 1e-9:.6f} s): non-finite value or zero "
                         "quaternion")
    d = np.diff(track.stamp_ns)
    if (d <= 0).any():
        k = int(np.argmax(d <= 0)) + 1
        raise InputError(f"{what}: {where(k)} (t = {track.stamp_ns[k] * 1e-9:.6f} s) is not after the one before "
                         "it: the times must increase")
    t = (track.stamp_ns - int(t0_ns)) * 1e-9
    if not np.any((t >= 0.0) & (t <= t_end_s)):
        raise InputError(f"{what}: no pose inside the log's time span ({t0_ns * 1e-9:.3f} .. "
                         f"{t0_ns * 1e-9 + t_end_s:.3f} s); the reference is {track.stamp_ns[0] * 1e-9:.3f} .. "
                         f"{track.stamp_ns[-1] * 1e-9:.3f} s: is it on the log's time base?")
    lat0, lon0 = np.radians(anchor.lat_deg), np.radians(anchor.lon_deg)
    lat, lon, alt = geodesy.enu_to_geodetic(track.xyz, lat0, lon0, anchor.alt)
    rph = vel = None
    if q is not None:
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        c_map_body = quat_to_dcm_batch(np.column_stack([qn[:, 3], qn[:, :3]]))
        m_a = geodesy.mat_enu_from_ecef(lat0, lon0)
        m_p = geodesy.mat_enu_from_ecef(lat, lon)
        c_nb = np.einsum("nij,kj,nkl->nil", m_p, m_a, c_map_body, optimize=True)   # M_p M_a^T C_map_body
        roll, pitch, heading = dcm_to_rph(c_nb)
        rph = np.degrees(np.column_stack([roll, pitch, heading]))
        if track.vel_body is not None:
            vel = np.einsum("nij,nj->ni", c_nb, track.vel_body)
    return ReferenceData(t, np.degrees(lat), np.degrees(lon), np.asarray(alt, dtype=float), vel_enu=vel,
                         rph_deg=rph, source=source)
