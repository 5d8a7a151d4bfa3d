"""Strapdown mechanisation against oracles that do not come from the strapdown itself:
the closed-form ideal IMU of a vehicle at rest on the rotating Earth, and the simulator's
error-free IMU derived analytically from a defined trajectory."""

import numpy as np
import pytest

from navpp import geodesy
from navpp.ins.attitude import dcm_to_quat, quat_to_dcm_batch, rph_to_dcm
from navpp.ins.strapdown import free_inertial
from navpp.simulate import SimulationSpec, simulate


def _nominal(lat, lon, h, mat_nb, vel=(0.0, 0.0, 0.0)):
    x = np.zeros(16)
    x[0:4] = dcm_to_quat(mat_nb)
    x[4:7] = vel
    x[7], x[8], x[9] = lat, lon, h
    return x


@pytest.mark.parametrize("lat_deg,rph_deg", [(45.0, (1.0, -2.0, 30.0)), (-70.0, (0.0, 0.0, 200.0))])
def test_one_hour_at_rest_on_the_rotating_earth(lat_deg, rph_deg):
    lat, lon, h = np.radians(lat_deg), np.radians(7.0), 300.0
    C = rph_to_dcm(*np.radians(rph_deg))
    # closed form: the gyro sees the Earth rate, the accelerometer the reaction to gravity
    w_b = C.T @ np.array([0.0, geodesy.OMEGA_E * np.cos(lat), geodesy.OMEGA_E * np.sin(lat)])
    f_b = C.T @ np.array([0.0, 0.0, geodesy.gravity(lat, h)])
    rate = 125.0
    n = int(3600 * rate) + 1
    t = np.arange(n) / rate
    out = free_inertial(_nominal(lat, lon, h, C), t, np.tile(w_b, (n, 1)), np.tile(f_b, (n, 1)))
    drift = geodesy.geodetic_to_enu(out[-1, 7], out[-1, 8], out[-1, 9], lat, lon, h)
    assert np.linalg.norm(drift) < 0.1
    np.testing.assert_allclose(out[-1, 4:7], 0.0, atol=1e-4)
    np.testing.assert_allclose(quat_to_dcm_batch(out[-1, 0:4]), C, atol=1e-9)


def _free_inertial_errors(rate_hz, duration=600.0):
    sim = simulate(SimulationSpec(duration_s=duration + 10, imu_rate_hz=rate_hz, preset="ideal", still_s=10.0))
    imu, ref = sim.truth_imu, sim.reference
    assert ref.t[0] == imu.t[0] == 0.0
    r = np.radians(ref.rph_deg[0])
    x0 = _nominal(np.radians(ref.lat_deg[0]), np.radians(ref.lon_deg[0]), ref.alt[0], rph_to_dcm(*r), ref.vel_enu[0])
    out = free_inertial(x0, imu.t, imu.gyro, imu.accel)
    k = int(np.searchsorted(ref.t, duration))
    i = int(np.searchsorted(imu.t, ref.t[k]))
    assert imu.t[i] == pytest.approx(ref.t[k], abs=1e-9)
    err = geodesy.geodetic_to_enu(out[i, 7], out[i, 8], out[i, 9], np.radians(ref.lat_deg[k]),
                                  np.radians(ref.lon_deg[k]), ref.alt[k])
    return err, out[i, 4:7] - ref.vel_enu[k], sim


def test_free_inertial_drive_600_s_with_error_free_imu():
    err, verr, sim = _free_inertial_errors(125.0)
    speed = np.linalg.norm(sim.reference.vel_enu, axis=1)
    assert speed.max() > 15.0                    # a real drive: turns, a hill, 20 m/s
    assert np.linalg.norm(err) < 1.0
    assert np.linalg.norm(verr) < 0.01


def test_free_inertial_error_shrinks_with_rate():
    # a second-order algorithm: doubling the rate must cut the drift several-fold
    e100, _, _ = _free_inertial_errors(100.0, 300.0)
    e200, _, _ = _free_inertial_errors(200.0, 300.0)
    assert np.linalg.norm(e200) < 0.5 * np.linalg.norm(e100)


def test_stopping_between_samples_changes_nothing():
    # reaching an epoch between two IMU samples (rates interpolated there) and going on must
    # agree with integrating straight through: the engine stops at every GNSS epoch
    from navpp.ins import strapdown as S

    sim = simulate(SimulationSpec(duration_s=100.0, imu_rate_hz=100.0, preset="ideal", still_s=10.0))
    imu, ref = sim.truth_imu, sim.reference
    k = int(np.searchsorted(ref.t, 40.0))
    x0 = _nominal(np.radians(ref.lat_deg[k]), np.radians(ref.lon_deg[k]), ref.alt[k],
                  rph_to_dcm(*np.radians(ref.rph_deg[k])), ref.vel_enu[k])
    t, g, a = (np.ascontiguousarray(v) for v in (imu.t, imu.gyro, imu.accel))
    no = np.empty((1, S.PATH_SIZE))
    direct = x0.copy()
    S.integrate(direct, t, g, a, 40.0, 50.0, no, False, 0.0, S.NO_SEG_X, S.NO_SEG_FN, S.NO_SEG_T)
    split = x0.copy()
    stops = np.arange(40.0, 50.0, 1.0 / 3.0)[1:]          # 3 Hz epochs, between the 100 Hz samples
    t_prev = 40.0
    for ts in list(stops) + [50.0]:
        S.integrate(split, t, g, a, t_prev, float(ts), no, False, 0.0, S.NO_SEG_X, S.NO_SEG_FN, S.NO_SEG_T)
        t_prev = float(ts)
    d = geodesy.geodetic_to_enu(split[7], split[8], split[9], direct[7], direct[8], direct[9])
    assert np.linalg.norm(d) < 1e-3
    np.testing.assert_allclose(split[4:7], direct[4:7], atol=1e-4)
