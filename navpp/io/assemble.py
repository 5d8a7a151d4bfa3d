"""Decoded ROS-log topics -> a validated :class:`navpp.recording.Recording`.

Role detection: the IMU topic is the one ``sensor_msgs/Imu`` topic (``--imu-topic`` picks
among several), the GNSS topic the one ``sensor_msgs/NavSatFix`` topic that is not the
reference (``--gnss-topic`` picks), GNSS velocity the one Twist topic if there is exactly
one that is not in a vehicle frame, wheel odometry the topic
:func:`navpp.io.detect.choose_odometry_topic` picks (``--odometry-topic`` chooses, ``none`` disables).
Message semantics (ROS REP-145 and the message definitions):

- stamps: header stamps by default (``[time] source = "header"``), record times with "log";
- NavSatFix ``status < 0`` (no fix) and NaN positions are dropped and counted;
- ``position_covariance_type`` 0 (unknown): the config's default std; otherwise the square
  roots of the covariance diagonal (ENU, as the message defines it);
- Imu orientation is ignored; covariance element 0 = -1 means "not provided".
Every failure is an InputError naming the file, the topic and the message (index and time).
"""

from __future__ import annotations

import numpy as np

from .. import spill
from ..errors import InputError
from ..findings import with_code
from ..intervals import interval_median
from ..recording import GnssData, ImuData, OdometryData, Recording, ReferenceData, lone_stamp, order_samples
from .detect import choose_odometry_topic, gnss_velocity_topics, in_vehicle_frame
from .ros import FIX_TYPE, IMU_TYPE, FixMessages, ImuMessages, LogContents

GAP_FACTOR = 2.5


def topics_of_type(contents: LogContents, msgtype: str) -> list[str]:
    return [t.topic for t in contents.topics if t.msgtype == msgtype]


def choose_topic(contents: LogContents, msgtype: str, role: str, option: str, given: str | None,
                 exclude: tuple[str, ...] = ()) -> str | None:
    """The topic playing ``role``: ``given`` (checked), else the only candidate of ``msgtype``."""
    candidates = [t for t in topics_of_type(contents, msgtype) if t not in exclude]
    if given is not None:
        known = {t.topic: t.msgtype for t in contents.topics}
        if given not in known:
            raise InputError(f"{contents.source}: no topic {given!r} ({option}); topics: "
                             f"{', '.join(sorted(known)) or 'none'}")
        if known[given] != msgtype:
            raise InputError(f"{contents.source}: topic {given!r} ({option}) is {known[given]}, not {msgtype}")
        return given
    if len(candidates) > 1:
        raise InputError(f"{contents.source}: several {msgtype} topics could be the {role}: "
                         f"{', '.join(candidates)}; choose one with {option}")
    return candidates[0] if candidates else None


def _type_of(contents: LogContents, topic: str) -> str:
    return next((t.msgtype for t in contents.topics if t.topic == topic), "")


def _stamp_text(ns) -> str:
    """An absolute ns stamp as exact decimal seconds (float64 seconds are ~0.2 us coarse)."""
    sec, frac = divmod(int(ns), 1_000_000_000)
    return f"{sec}.{frac:09d} s"


def _stamps(msgs, source: str, what: str | None = None) -> np.ndarray:
    """The messages' stamps (ns): header stamps, or record times with ``source == "log"``.
    With ``what``, refuses a topic of 2+ messages whose stamps are all the same (a driver that
    never fills ``header.stamp`` leaves every one 0): said as such, not as "too few messages"."""
    stamps = np.asarray(msgs.log_ns if source == "log" else msgs.stamp_ns, dtype=np.int64)
    if what is not None and stamps.shape[0] >= 2 and stamps[0] == stamps[-1] and (stamps == stamps[0]).all():
        value = "0" if stamps[0] == 0 else f"the same, t = {_stamp_text(stamps[0])}"
        kind = "header stamps" if source != "log" else "record (log) times"
        hint = ('; the driver does not fill header.stamp: use the record times, [time] source = "log"'
                if source != "log" else "")
        raise InputError(f"{what}: all {stamps.shape[0]} {kind} are {value}{hint}")
    return stamps


def _ordered(stamps: np.ndarray, values: np.ndarray, what: str, warnings: list[str]) -> np.ndarray:
    """Indices putting messages in strictly increasing stamp order: the shared policy of
    :func:`navpp.recording.order_samples` (reordered messages sorted, exact duplicates dropped,
    conflicting duplicates keep the first, a clock jump back is an error), all warned."""
    try:
        return order_samples(stamps, values, what, warnings)
    except InputError as exc:
        raise InputError(f'{exc} (try [time] source = "log")') from None


def _check_lone_stamp(stamps: np.ndarray, what: str, time_source: str) -> None:
    """One message whose stamp is far from its regular neighbours (a header stamp of 0, a clock
    not yet set: :func:`navpp.recording.lone_stamp`): an error naming the message, its index
    and stamp (checked before :func:`navpp.recording.order_samples`, which would call a lone stamp
    far back a clock jump, and one far ahead a jump back of the message after it)."""
    hit = lone_stamp(stamps)
    if hit is None:
        return
    k, dist = hit
    hint = '; try [time] source = "log"' if time_source == "header" else ""
    raise InputError(f"{what}: message {k} (t = {_stamp_text(stamps[k])}) lies {dist:.4g} s from its neighbours "
                     f"while the messages around it are regular: a lone bad stamp (a clock not yet set?){hint}")


def _first_bad(a: np.ndarray) -> int | None:
    """The first row of ``a`` with a non-finite value, or None."""
    bad = ~np.isfinite(a)
    if bad.ndim > 1:
        bad = bad.any(axis=1)
    return int(np.argmax(bad)) if bad.any() else None


def _finite_rows(arrays: list[np.ndarray], names: list[str], what: str, stamps: np.ndarray,
                 first_bad: list[int | None] | None = None) -> None:
    """InputError naming the first message of the first array in ``arrays`` with a non-finite
    value; ``first_bad``: those first rows when already found (:func:`_imu_rows`)."""
    for i, (a, name) in enumerate(zip(arrays, names, strict=True)):
        k = _first_bad(a) if first_bad is None else first_bad[i]
        if k is not None:
            raise InputError(f"{what}: message {k} (t = {_stamp_text(stamps[k])}): non-finite {name}")


def _gap_warning(what: str, t: np.ndarray, nominal: float, warnings: list[str]) -> None:
    """Warn about intervals of ``t`` (s) longer than ``GAP_FACTOR`` times ``nominal`` (s, the
    median interval), window by window over a spilled ``t`` (:func:`navpp.spill.windows`)."""
    if t.shape[0] < 3:
        return
    n, k, largest = 0, -1, -np.inf
    for a, b in spill.windows(t.shape[0] - 1, t):
        dt = t[a + 1:b + 1] - t[a:b]
        gaps = dt > GAP_FACTOR * nominal
        n += int(np.count_nonzero(gaps))
        if gaps.any():
            j = int(np.argmax(np.where(gaps, dt, -np.inf)))
            if dt[j] > largest:
                k, largest = a + j, float(dt[j])
    if n:
        warnings.append(f"{what}: {n} gap{'s' if n > 1 else ''} longer than {GAP_FACTOR} x the nominal interval "
                        f"{nominal:.4g} s; largest {largest:.4g} s from t = {float(t[k]):.3f} s (message {k}, "
                        "t relative to the first IMU stamp)")


def _fixes(fix: FixMessages, source: str, what: str, default_std: tuple[float, float, float],
           warnings: list[str], std_used: bool = True) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Valid fixes of a NavSatFix topic: stamps (ns) and the GnssData columns.  ``std_used``
    False (the reference, whose std nothing uses): no warning about missing covariances."""
    stamps = _stamps(fix, source, what)
    valid = (np.asarray(fix.status) >= 0) & np.isfinite(fix.lat_deg) & np.isfinite(fix.lon_deg) & np.isfinite(fix.alt)
    n_bad = int(np.count_nonzero(~valid))
    if n_bad:
        warnings.append(f"{what}: dropped {n_bad} of {valid.size} fixes with no fix (status < 0 or NaN position)")
    idx = np.nonzero(valid)[0]
    if idx.size == 0:
        raise InputError(f"{what}: no valid fix (every message has status < 0 or a NaN position)")
    values = np.column_stack([np.asarray(fix.lat_deg, float)[idx], np.asarray(fix.lon_deg, float)[idx],
                              np.asarray(fix.alt, float)[idx]])
    idx = idx[_ordered(stamps[idx], values, what, warnings)]
    cov = np.asarray(fix.cov, dtype=float)[idx]
    ctype = np.asarray(fix.cov_type)[idx]
    var = cov[:, [0, 4, 8]]
    known = (ctype > 0) & np.all(np.isfinite(var) & (var > 0), axis=1)
    std = np.where(known[:, None], np.sqrt(np.where(known[:, None], var, 1.0)), np.asarray(default_std)[None, :])
    if std_used and (~known).any():
        warnings.append(f"{what}: {int(np.count_nonzero(~known))} fixes without a usable position covariance: "
                        f"[gnss] default_std_m = {list(default_std)} used for them")
    cols = {"lat_deg": np.asarray(fix.lat_deg, float)[idx], "lon_deg": np.asarray(fix.lon_deg, float)[idx],
            "alt": np.asarray(fix.alt, float)[idx], "std_enu": std,
            "fix": np.asarray(fix.status)[idx].astype(np.int64)}
    return stamps[idx], cols


def recording_from_log(contents: LogContents, *, imu_topic: str | None = None, gnss_topic: str | None = None,
                       reference_topic: str | None = None, time_source: str = "header",
                       time_base: str = "unix", default_std_m=(2.0, 2.0, 4.0),
                       gyro_scale: float = 1.0, accel_scale: float = 1.0, time_offset_s: float = 0.0,
                       odometry_topic: str | None = None) -> Recording:
    """Pick the roles, apply the message semantics, validate, and build the Recording.

    ``time_offset_s`` (s, ``[gnss] time_offset_s``) is added to every GNSS fix stamp (not to
    the reference): a receiver whose fixes are stamped 0.2 s late needs -0.2.

    When the reader found the log cut off, a failure here (a missing topic, too few messages)
    says so too: the cut is the likely cause.
    """
    try:
        return _assemble(contents, imu_topic=imu_topic, gnss_topic=gnss_topic, reference_topic=reference_topic,
                         time_source=time_source, time_base=time_base, default_std_m=default_std_m,
                         gyro_scale=gyro_scale, accel_scale=accel_scale, time_offset_s=time_offset_s,
                         odometry_topic=odometry_topic)
    except InputError as exc:
        cut = with_code(contents.warnings, "recording-cut-off")
        if not cut:
            raise
        note = cut[0].removeprefix(f"{contents.source}: ")
        raise InputError(f"{exc} ({note})") from None


def _imu_data(contents: LogContents, imu_name: str, time_source: str, gyro_scale: float, accel_scale: float,
              warnings: list[str]) -> tuple[ImuData, int]:
    """The IMU topic as :class:`ImuData` (s from its first kept sample; rad/s and m/s^2 times
    the scales) and that first sample's stamp (ns); samples out of order or repeated are
    dropped (with a warning), a low rate and gaps are warned about.  Messages on a spill file
    (:func:`navpp.io.mcap.read_mcap`'s ``memory``) give arrays on a spill file, made window by
    window; the samples stay in memory only when some are out of order or repeated."""
    src = contents.source
    imu = contents.imu.get(imu_name)
    if imu is None or imu.stamp_ns.shape[0] == 0:
        raise InputError(f"{src}: topic {imu_name!r} has no IMU message")
    what = f"{src}: topic {imu_name!r}"
    stamps, gyro, accel, first_bad = _imu_rows(imu, _stamps(imu, time_source, what), gyro_scale, accel_scale)
    _finite_rows([imu.gyro, imu.accel], ["angular_velocity", "linear_acceleration"], what, stamps, first_bad)
    _check_lone_stamp(stamps, what, time_source)
    spill.release_all(stamps)
    if not _increasing(stamps):     # else keep all: what _ordered gives for increasing stamps
        keep = _ordered(stamps, np.hstack([np.asarray(imu.gyro, float), np.asarray(imu.accel, float)]), what,
                        warnings)
        stamps, gyro, accel = stamps[keep], gyro[keep], accel[keep]
    if stamps.shape[0] < 2:
        raise InputError(f"{what}: at least 2 IMU messages are needed, found {stamps.shape[0]}")
    t0_ns = int(stamps[0])
    t_imu = stamps.view(np.float64)       # t = (stamps - t0_ns) * 1e-9 in the stamps' own memory
    for a, b in spill.windows(stamps.shape[0], stamps):
        np.subtract(stamps[a:b], t0_ns, out=stamps[a:b])
        np.multiply(stamps[a:b], 1e-9, out=t_imu[a:b])
    nominal = interval_median(t_imu)     # a spilled t_imu window by window, the same bits
    spill.release_all(t_imu)
    rate = 1.0 / nominal
    if rate < 50.0:
        warnings.append(f"{what}: IMU rate {rate:.1f} Hz is low for strapdown navigation (100-200 Hz expected); "
                        "processed anyway")
    _gap_warning(what, t_imu, nominal, warnings)
    return ImuData(t_imu, gyro, accel), t0_ns


def _imu_rows(imu: ImuMessages, stamps: np.ndarray, gyro_scale: float, accel_scale: float,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int | None]]:
    """The IMU messages' ``stamps`` (ns), gyro and accel times their scales, as contiguous
    copies made in one pass window by window (on a spill file when the messages are: their
    rows released behind), and the first row of gyro and of accel with a non-finite value."""
    n = stamps.shape[0]
    st = spill.like(stamps, n, (), np.int64)
    gyro = spill.like(imu.gyro, n, (3,), np.float64)
    accel = spill.like(imu.accel, n, (3,), np.float64)
    first_bad: list[int | None] = [None, None]
    for a, b in spill.windows(n, stamps, imu.gyro, imu.accel, st, gyro, accel):
        st[a:b] = stamps[a:b]
        for i, (src, out, scale) in enumerate(((imu.gyro, gyro, gyro_scale), (imu.accel, accel, accel_scale))):
            rows = np.asarray(src[a:b], float)
            np.multiply(rows, scale, out=out[a:b])
            k = _first_bad(rows) if first_bad[i] is None else None
            if k is not None:
                first_bad[i] = a + k
    return st, gyro, accel, first_bad


def _increasing(stamps: np.ndarray) -> bool:
    """Whether ``stamps`` increase strictly (window by window over a spilled array)."""
    return all(bool(np.all(stamps[max(a - 1, 0) + 1:b] > stamps[max(a - 1, 0):b - 1]))
               for a, b in spill.windows(stamps.shape[0], stamps))


def _assemble(contents: LogContents, *, imu_topic: str | None = None, gnss_topic: str | None = None,
              reference_topic: str | None = None, time_source: str = "header",
              time_base: str = "unix", default_std_m=(2.0, 2.0, 4.0),
              gyro_scale: float = 1.0, accel_scale: float = 1.0, time_offset_s: float = 0.0,
              odometry_topic: str | None = None) -> Recording:
    src = contents.source
    warnings = list(contents.warnings)
    imu_name = choose_topic(contents, IMU_TYPE, "IMU", "--imu-topic", imu_topic)
    if imu_name is None:
        raise InputError(f"{src}: no {IMU_TYPE} topic; topics: "
                         + (", ".join(f"{t.topic} ({t.msgtype})" for t in contents.topics) or "none"))
    exclude = (reference_topic,) if reference_topic else ()
    gnss_name = choose_topic(contents, FIX_TYPE, "GNSS", "--gnss-topic", gnss_topic, exclude)
    if gnss_name is None:
        raise InputError(f"{src}: no {FIX_TYPE} topic for the GNSS; topics: "
                         + (", ".join(f"{t.topic} ({t.msgtype})" for t in contents.topics) or "none"))
    if reference_topic is not None:
        choose_topic(contents, FIX_TYPE, "reference", "--reference-topic", reference_topic)

    imu_data, t0_ns = _imu_data(contents, imu_name, time_source, gyro_scale, accel_scale, warnings)
    t_imu = imu_data.t

    fix = contents.fix.get(gnss_name)
    if fix is None or fix.stamp_ns.shape[0] == 0:
        raise InputError(f"{src}: topic {gnss_name!r} has no NavSatFix message")
    what = f"{src}: topic {gnss_name!r}"
    g_ns, cols = _fixes(fix, time_source, what, tuple(default_std_m), warnings)
    g_ns = g_ns + round(float(time_offset_s) * 1e9)
    t_gnss = (g_ns - t0_ns) * 1e-9
    if not np.any((t_gnss >= 0) & (t_gnss <= t_imu[-1])):
        raise InputError(f"{what}: no fix inside the IMU time span ({t0_ns * 1e-9:.3f} .. "
                         f"{(t0_ns * 1e-9 + t_imu[-1]):.3f} s); check the stamps of both topics")
    vel = std_vel = None
    odom_name, odom_note = choose_odometry_topic(contents, odometry_topic)
    if odom_note.startswith("odometry: not used"):
        warnings.append(f"{src}: {odom_note}")
    odometry = _odometry_data(contents, odom_name, time_source, t0_ns) if odom_name else None
    odom_msgs = contents.twist.get(odom_name) if odom_name else None
    if odom_name and odom_msgs is not None and not in_vehicle_frame(odom_msgs, _type_of(contents, odom_name)):
        warnings.append(f"{src}: odometry topic {odom_name!r} (--odometry-topic) is not in a vehicle frame "
                        f"(frame {odom_msgs.child_frame_id or odom_msgs.frame_id!r}): its linear.x is used as the "
                        "forward speed anyway")
    twists = gnss_velocity_topics(contents, odom_name)
    if len(twists) == 1 and twists[0] in contents.twist:
        tw = contents.twist[twists[0]]
        tw_ns = _stamps(tw, time_source) + round(float(time_offset_s) * 1e9)   # same receiver
        j = np.clip(np.searchsorted(tw_ns, g_ns), 1, max(len(tw_ns) - 1, 1)) if len(tw_ns) > 1 else np.zeros_like(g_ns)
        if len(tw_ns) > 1:
            j = np.where(np.abs(tw_ns[j - 1] - g_ns) < np.abs(tw_ns[j] - g_ns), j - 1, j)
        near = np.abs(tw_ns[j] - g_ns) < 0.05e9
        if near.mean() > 0.9:
            vel = np.where(near[:, None], np.asarray(tw.vel, float)[j], np.nan)
            if tw.cov_diag is not None:
                std_vel = np.sqrt(np.clip(np.asarray(tw.cov_diag, float)[j], 1e-6, None))
            if not near.all():
                ok = near
                t_gnss, vel = t_gnss[ok], vel[ok]
                std_vel = std_vel[ok] if std_vel is not None else None
                cols = {k: v[ok] for k, v in cols.items()}
        else:
            warnings.append(f"{src}: GNSS velocity topic {twists[0]!r} does not line up with the fixes; not used")
    gnss = GnssData(t_gnss, cols["lat_deg"], cols["lon_deg"], cols["alt"], std_enu=cols["std_enu"], vel_enu=vel,
                    std_vel_enu=std_vel, fix=cols["fix"])

    reference = None
    if reference_topic is not None:
        rfix = contents.fix.get(reference_topic)
        if rfix is None or rfix.stamp_ns.shape[0] == 0:
            raise InputError(f"{src}: reference topic {reference_topic!r} has no message")
        r_ns, rcols = _fixes(rfix, time_source, f"{src}: topic {reference_topic!r}", tuple(default_std_m), warnings,
                             std_used=False)
        reference = ReferenceData((r_ns - t0_ns) * 1e-9, rcols["lat_deg"], rcols["lon_deg"], rcols["alt"],
                                  source=f"{src}:{reference_topic}")
    return Recording(imu=imu_data, gnss=gnss, t0_ns=t0_ns, time_base=time_base, reference=reference,
                     source=src, warnings=tuple(warnings), odometry=odometry)


def _odometry_data(contents: LogContents, topic: str, time_source: str, t0_ns: int) -> OdometryData:
    """The odometry topic as :class:`OdometryData` on the IMU's time base (s from ``t0_ns``, the
    same [time] source; no GNSS time offset): speed = the twist's linear x (m/s, vehicle frame),
    yaw rate = its angular z (rad/s); std from covariance elements 0 / 35 when every message gives
    one > 0 (else None: the config's default sigma applies); source = the topic.  Out-of-order and
    repeated stamps follow :func:`_ordered` (their warnings are dropped: an optional aid); a
    non-finite value is an InputError."""
    msgs = contents.twist.get(topic)
    what = f"{contents.source}: topic {topic!r} (odometry; --odometry-topic none leaves it out)"
    if msgs is None or msgs.stamp_ns.shape[0] == 0:
        raise InputError(f"{what}: no message")
    stamps = _stamps(msgs, time_source, what)
    cols = [np.asarray(msgs.vel, float)[:, 0]]
    if msgs.angular is not None:
        cols.append(np.asarray(msgs.angular, float)[:, 2])
    _finite_rows(cols, ["speed (linear.x)", "yaw rate (angular.z)"][:len(cols)], what, stamps)
    keep = _ordered(stamps, np.column_stack(cols), what, [])

    def std(var: np.ndarray | None) -> np.ndarray | None:
        if var is None:
            return None
        v = np.asarray(var, float)[keep]
        return np.sqrt(v) if bool(np.all(np.isfinite(v) & (v > 0))) else None

    return OdometryData((stamps[keep] - t0_ns) * 1e-9, cols[0][keep], cols[1][keep] if len(cols) > 1 else None,
                        std(None if msgs.cov_diag is None else msgs.cov_diag[:, 0]), std(msgs.var_yaw_rate),
                        source=topic)
