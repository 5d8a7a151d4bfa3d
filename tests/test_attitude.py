"""Attitude algebra against scipy's Rotation (an independent implementation)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navpp.ins import attitude as att


def _rng():
    return np.random.default_rng(42)


def test_rph_to_dcm_matches_scipy_zyx():
    rng = _rng()
    for _ in range(20):
        r, p, h = rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(0, 2 * np.pi)
        # navigation convention -> intrinsic ZYX (yaw = pi/2 - heading, pitch_y = -pitch, roll)
        ref = Rotation.from_euler("ZYX", [np.pi / 2 - h, -p, r]).as_matrix()
        np.testing.assert_allclose(att.rph_to_dcm(r, p, h), ref, atol=1e-12)
        rr, pp, hh = att.dcm_to_rph(ref)
        assert (rr, pp) == pytest.approx((r, p), abs=1e-9)
        assert np.angle(np.exp(1j * (hh - h))) == pytest.approx(0.0, abs=1e-9)


def test_axes_meaning():
    # heading 90 deg: body forward = east; pitch up: forward gains +up; roll right-down: left axis gains +up
    m = att.rph_to_dcm(0.0, 0.0, np.pi / 2)
    np.testing.assert_allclose(m[:, 0], [1, 0, 0], atol=1e-12)
    assert att.rph_to_dcm(0.0, 0.2, 0.0)[2, 0] > 0
    assert att.rph_to_dcm(0.2, 0.0, 0.0)[2, 1] > 0


def test_quaternion_ops_match_scipy():
    rng = _rng()
    for _ in range(20):
        a, b = Rotation.random(random_state=rng.integers(1 << 30)), Rotation.random(random_state=rng.integers(1 << 30))
        qa = np.roll(a.as_quat(), 1)
        qb = np.roll(b.as_quat(), 1)
        np.testing.assert_allclose(att.quat_to_dcm(qa), a.as_matrix(), atol=1e-12)
        np.testing.assert_allclose(att.quat_to_dcm(att.quat_mul(qa, qb)), (a * b).as_matrix(), atol=1e-12)
        np.testing.assert_allclose(att.quat_to_dcm_batch(qa[None])[0], a.as_matrix(), atol=1e-12)
        q = att.dcm_to_quat(a.as_matrix())
        assert q[0] >= 0
        np.testing.assert_allclose(att.quat_to_dcm(q), a.as_matrix(), atol=1e-12)
        rv = a.as_rotvec()
        np.testing.assert_allclose(att.quat_to_dcm(att.rotvec_to_quat(rv)), a.as_matrix(), atol=1e-12)
        np.testing.assert_allclose(att.quat_to_rotvec(att.rotvec_to_quat(rv)), rv, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_small_rotation_vectors_keep_precision(angle):
    rv = angle * np.array([0.6, -0.8, 0.0])
    np.testing.assert_allclose(att.quat_to_rotvec(att.rotvec_to_quat(rv)), rv, rtol=1e-12, atol=1e-300)


def test_skew():
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 4.0, -1.0])
    np.testing.assert_allclose(att.skew(a) @ b, np.cross(a, b))


def test_body_to_nav_rotation_convention():
    h, p, r = 30.0, 10.0, 20.0
    rad = math.radians
    c = att.rph_deg_to_dcm([0.0, 0.0, h])
    np.testing.assert_allclose(c @ [1, 0, 0], [math.sin(rad(h)), math.cos(rad(h)), 0], atol=1e-15)
    np.testing.assert_allclose(c @ [0, 1, 0], [-math.cos(rad(h)), math.sin(rad(h)), 0], atol=1e-15)
    # nose up: forward axis rises
    np.testing.assert_allclose(att.rph_deg_to_dcm([0.0, p, 0.0]) @ [1, 0, 0],
                               [0, math.cos(rad(p)), math.sin(rad(p))], atol=1e-15)
    # right side down: the left (y) axis rises, the up (z) axis leans right (east at heading 0)
    c = att.rph_deg_to_dcm([r, 0.0, 0.0])
    np.testing.assert_allclose(c @ [0, 1, 0], [-math.cos(rad(r)), 0, math.sin(rad(r))], atol=1e-15)
    np.testing.assert_allclose(c @ [0, 0, 1], [math.sin(rad(r)), 0, math.cos(rad(r))], atol=1e-15)
    many = att.rph_deg_to_dcm(np.random.default_rng(0).uniform(-180, 180, (10, 3)))
    np.testing.assert_allclose(many @ np.swapaxes(many, -1, -2), np.broadcast_to(np.eye(3), (10, 3, 3)),
                               atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(many), 1.0)


def test_rpy_to_dcm_matches_scipy_intrinsic_zyx():
    rng = _rng()
    for _ in range(20):
        r, p, y = rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)
        ref = Rotation.from_euler("ZYX", [y, p, r]).as_matrix()
        np.testing.assert_allclose(att.rpy_to_dcm(r, p, y), ref, atol=1e-12)
        np.testing.assert_allclose(att.rpy_deg_to_dcm(np.degrees([r, p, y])), ref, atol=1e-12)
    rpy = rng.uniform(-180.0, 180.0, (7, 3))
    batch = att.rpy_deg_to_dcm(rpy)
    assert batch.shape == (7, 3, 3)
    for k in range(7):
        np.testing.assert_array_equal(batch[k], att.rpy_deg_to_dcm(rpy[k]))


def test_navigation_angles_are_the_rpy_rotation():
    """rph (heading clockwise from north, pitch nose up) is rpy with yaw = pi/2 - heading and the
    pitch negated, bit for bit (one builder)."""
    rng = _rng()
    r, p, h = rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(0.0, 2 * np.pi, 50)
    np.testing.assert_array_equal(att.rph_to_dcm(r, p, h), att.rpy_to_dcm(r, -p, 0.5 * np.pi - h))
    np.testing.assert_array_equal(att.rph_deg_to_dcm(np.degrees(np.stack([r, p, h], -1))),
                                  att.rph_to_dcm(*np.radians(np.degrees([r, p, h]))))
