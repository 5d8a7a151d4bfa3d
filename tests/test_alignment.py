"""Alignment against closed-form static IMU data and simulated drives."""

import math

import numpy as np
import pytest

from navpp import geodesy
from navpp.errors import InputError
from navpp.ins.alignment import AlignmentSettings, align, detect_still, gyrocompass, level
from navpp.ins.attitude import rph_to_dcm
from navpp.simulate import SimulationSpec, simulate

LAT = math.radians(45.0)


def _static(roll, pitch, heading, h=300.0):
    C = rph_to_dcm(roll, pitch, heading)
    w = C.T @ geodesy.earth_rate_enu(LAT)
    f = C.T @ np.array([0.0, 0.0, geodesy.gravity(LAT, h)])
    return w, f


@pytest.mark.parametrize("heading_deg", [0, 37, 90, 145, 180, 260, 359])
@pytest.mark.parametrize("roll_deg,pitch_deg", [(0, 0), (5, -3), (-20, 10)])
def test_level_and_gyrocompass_closed_form(heading_deg, roll_deg, pitch_deg):
    r, p, h = math.radians(roll_deg), math.radians(pitch_deg), math.radians(heading_deg)
    w, f = _static(r, p, h)
    rr, pp = level(f)
    assert (rr, pp) == pytest.approx((r, p), abs=1e-12)
    hh = gyrocompass(w, rr, pp)
    assert math.remainder(hh - h, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_still_period_is_found_and_trimmed_to_the_truth():
    # the IMU test alone is generous (vibration) and runs into the smooth pull-away; the
    # specific-force drift and the GNSS track trim it back to the real stop
    sim = simulate(SimulationSpec(duration_s=120.0, still_s=25.0, preset="consumer", seed=4))
    imu = sim.imu
    noise_arw = 0.5 * math.pi / 180 / 60
    i0, i1 = detect_still(imu.t, imu.gyro, imu.accel, min_duration=2.0, gyro_arw=noise_arw, accel_vrw=0.1 / 60)
    assert i0 == 0 and imu.t[i1 - 1] >= 23.0
    al = align(imu.t, imu.gyro, imu.accel, sim.gnss, AlignmentSettings(gyro_arw=noise_arw, accel_vrw=0.1 / 60,
                                                                       gyro_bias_sigma=math.radians(200) / 3600))
    assert al.still[0] == 0.0
    assert 23.0 <= al.still[1] <= 27.0


def test_detect_still_none_when_always_moving():
    t = np.arange(0, 20, 0.01)
    gyro = np.column_stack([0.3 * np.sin(t), 0.2 * np.cos(2 * t), 0.5 * np.sin(0.7 * t)])
    accel = np.column_stack([np.sin(3 * t), np.cos(t), 9.8 + 0.3 * np.sin(5 * t)])
    assert detect_still(t, gyro, accel, min_duration=2.0) is None


def _settings(sim, **kw):
    g = sim.spec
    return AlignmentSettings(gyro_bias_sigma=math.radians(10) / 3600, gyro_arw=math.radians(1) / 60,
                             accel_bias_sigma=2e-3 * 9.80665, accel_vrw=0.05 / 60, lever_arm_b=g.lever_arm_m, **kw)


@pytest.mark.parametrize("heading0", [30.0, 300.0])
def test_heading_from_gnss_course_with_automotive_gyro(heading0):
    sim = simulate(SimulationSpec(duration_s=200.0, still_s=40.0, seed=5, heading0_deg=heading0,
                                  lever_arm_m=(0.2, 0.1, 1.0)))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings(sim))
    assert any("GNSS track" in line for line in al.lines)
    assert al.still[0] == 0.0 and 38.0 <= al.still[1] <= 42.0
    truth = sim.reference.rph_deg[0]
    roll, pitch, heading = np.degrees(np.array(sim_rph(al.x)))
    assert abs(roll - truth[0]) < 0.5 and abs(pitch - truth[1]) < 0.5
    sigma = math.degrees(math.sqrt(al.P[2, 2]))
    err = math.remainder(heading - truth[2], 360.0)
    assert abs(err) < 3 * sigma
    # position: IMU origin = averaged antenna fixes minus the rotated lever arm
    e = geodesy.geodetic_to_enu(al.x[7], al.x[8], al.x[9], math.radians(sim.reference.lat_deg[0]),
                                math.radians(sim.reference.lon_deg[0]), sim.reference.alt[0])
    assert np.all(np.abs(e) < 1.0)


def test_heading_from_config():
    sim = simulate(SimulationSpec(duration_s=60.0, still_s=20.0, seed=6))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss,
               _settings(sim, heading=math.radians(123.0), method="config"))
    assert math.degrees(sim_rph(al.x)[2]) == pytest.approx(123.0, abs=1e-9)
    assert any("(config)" in line for line in al.lines)


def test_no_motion_and_no_heading_is_a_clear_error():
    from navpp.recording import GnssData

    w, f = _static(0.01, 0.02, 1.0)
    t = np.arange(0.0, 30.0, 0.01)
    n = t.size
    tg = np.arange(0.0, 30.0, 0.2)
    gnss = GnssData(tg, np.full(tg.size, 45.0), np.full(tg.size, 7.0), np.full(tg.size, 300.0))
    settings = AlignmentSettings(gyro_bias_sigma=math.radians(10) / 3600, gyro_arw=math.radians(1) / 60)
    with pytest.raises(InputError, match="heading"):
        align(t, np.tile(w, (n, 1)), np.tile(f, (n, 1)), gnss, settings)


def sim_rph(x):
    from navpp.ins.attitude import dcm_to_rph, quat_to_dcm

    return dcm_to_rph(quat_to_dcm(x[0:4]))


@pytest.mark.parametrize("gnss_velocity", [False, True])
def test_heading_from_gnss_track_is_accurate_and_honest(gnss_velocity):
    # over several drives and start headings: the heading error is small and its sigma honest
    errors, sigmas = [], []
    for seed in range(8):
        sim = simulate(SimulationSpec(duration_s=200.0, still_s=30.0, seed=seed, heading0_deg=float(seed * 47 % 360),
                                      gnss_velocity=gnss_velocity))
        al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings(sim))
        errors.append(math.remainder(math.degrees(sim_rph(al.x)[2]) - sim.reference.rph_deg[0, 2], 360.0))
        sigmas.append(math.degrees(math.sqrt(al.P[2, 2])))
    errors, sigmas = np.array(errors), np.array(sigmas)
    assert np.sqrt(np.mean(errors ** 2)) < (0.6 if gnss_velocity else 1.5)
    assert np.all(np.abs(errors) < 3.0 * sigmas)


def test_smooth_motion_is_not_taken_for_a_still_period():
    # the simulator has no vibration: a smooth pull-away looks quiet to the IMU; the GNSS track
    # (or the specific force) must overrule it
    sim = simulate(SimulationSpec(duration_s=200.0, still_s=0.0, seed=2))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings(sim))
    assert al.still is None
    assert any("starting in motion" in line for line in al.lines)
    truth = sim.reference
    k = int(np.searchsorted(truth.t, al.t))
    err = geodesy.geodetic_to_enu(al.x[7], al.x[8], al.x[9], math.radians(truth.lat_deg[k]),
                                  math.radians(truth.lon_deg[k]), truth.alt[k])
    assert np.all(np.abs(err[:2]) < 3 * 1.8)
    assert np.linalg.norm(al.x[4:6] - truth.vel_enu[k, :2]) < 3.0


def test_gnss_starting_after_the_still_period_starts_in_motion_at_the_first_fix():
    from dataclasses import replace

    sim = simulate(SimulationSpec(duration_s=200.0, still_s=30.0, seed=3))
    g = sim.gnss
    keep = g.t >= 45.0                          # the car drives off at 30 s
    gnss = replace(g, t=g.t[keep], lat_deg=g.lat_deg[keep], lon_deg=g.lon_deg[keep], alt=g.alt[keep],
                   std_enu=g.std_enu[keep])
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, gnss, _settings(sim))
    assert al.still is None and al.t == pytest.approx(45.0, abs=0.01)
    assert any("no GNSS fix yet" in line for line in al.lines)


def test_tilted_mounting_is_warned_and_an_upside_down_one_refused():
    from navpp.errors import InputError
    from navpp.recording import GnssData

    t = np.arange(0.0, 10.0, 0.01)
    n = t.size
    tg = np.arange(0.0, 10.0, 0.2)
    gnss = GnssData(tg, np.full(tg.size, 45.0), np.full(tg.size, 7.0), np.full(tg.size, 300.0))
    w, f = _static(math.radians(60.0), 0.0, 1.0)         # tilted, z still up: a warning
    al = align(t, np.tile(w, (n, 1)), np.tile(f, (n, 1)), gnss, AlignmentSettings(heading=0.5, method="config"))
    assert any("mounting_rpy_deg" in wline for wline in al.warnings)
    w, f = _static(math.radians(180.0), 0.0, 1.0)        # FRD-like: z axis pointing down (issue 15)
    with pytest.raises(InputError, match=r"-z of the declared forward-left-up body.*mounting_rpy_deg = \[180, 0, 0\]"):
        align(t, np.tile(w, (n, 1)), np.tile(f, (n, 1)), gnss, AlignmentSettings(heading=0.5, method="config"))


def test_config_heading_is_cross_checked_against_the_track():
    sim = simulate(SimulationSpec(duration_s=200.0, still_s=30.0, seed=5, heading0_deg=30.0))
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings(sim, heading=math.radians(60.0)))
    assert any("differs by -30" in w and "not a ROS yaw" in w for w in al.warnings), al.warnings
    assert math.degrees(sim_rph(al.x)[2]) == pytest.approx(60.0)          # the user's word stands
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, sim.gnss, _settings(sim, heading=math.radians(30.5)))
    assert al.warnings == ()


def test_wrong_gnss_velocity_columns_are_caught_by_the_positions():
    from dataclasses import replace

    sim = simulate(SimulationSpec(duration_s=200.0, still_s=30.0, seed=5, heading0_deg=30.0, gnss_velocity=True))
    g = sim.gnss
    swapped = replace(g, vel_enu=g.vel_enu[:, [1, 0, 2]].copy())          # NED-style north, east
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, swapped, _settings(sim))
    assert any("GNSS velocity differs" in w for w in al.warnings)
    err = math.remainder(math.degrees(sim_rph(al.x)[2]) - sim.reference.rph_deg[0, 2], 360.0)
    assert abs(err) < 3.0
    al = align(sim.imu.t, sim.imu.gyro, sim.imu.accel, g, _settings(sim))
    assert al.warnings == ()


def test_idling_engine_vibration_still_gives_a_still_period():
    sim = simulate(SimulationSpec(duration_s=150.0, still_s=40.0, seed=7))
    imu = sim.imu
    phase = 2 * np.pi * 31.0 * imu.t
    accel = imu.accel + 0.3 * np.column_stack([np.sin(phase), np.cos(1.3 * phase), np.sin(0.7 * phase)])
    gyro = imu.gyro + np.radians(0.3) * np.column_stack([np.cos(phase), np.sin(1.1 * phase), np.sin(phase)])
    al = align(imu.t, gyro, accel, sim.gnss, _settings(sim))
    assert al.still is not None and al.still[0] == 0.0 and 38.0 <= al.still[1] <= 42.0
    truth = sim.reference.rph_deg[0]
    roll, pitch, _ = np.degrees(np.array(sim_rph(al.x)))
    assert abs(roll - truth[0]) < 0.3 and abs(pitch - truth[1]) < 0.3
