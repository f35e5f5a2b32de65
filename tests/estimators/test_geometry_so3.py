import numpy as np

from gevi_cli import geometry as lie  # SO(3) helpers live in the one geometry module


def test_exp_log_roundtrip(rng):
    w = rng.standard_normal((200, 3)) * rng.uniform(0, 3.1, (200, 1)) / np.sqrt(3)
    w = w[np.linalg.norm(w, axis=1) < np.pi - 1e-3]
    R = lie.exp_so3(w)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(lie.log_so3(R), w, atol=1e-9)
    # tiny and near-pi angles
    assert np.allclose(lie.log_so3(lie.exp_so3(np.array([1e-9, 0, 0]))), [1e-9, 0, 0], atol=1e-15)
    wp = np.array([0.0, np.pi - 1e-7, 0.0])
    assert np.allclose(np.abs(lie.log_so3(lie.exp_so3(wp))), np.abs(wp), atol=1e-6)


def test_tilt_is_yaw_invariant(rng):
    for _ in range(50):
        roll, pitch, yaw = rng.uniform(-1, 1, 3)
        M = lie.rot_z(yaw) @ lie.rtilt(roll, pitch)
        r, p = lie.tilt_angles(M)
        assert abs(r - roll) < 1e-12 and abs(p - pitch) < 1e-12


def test_drot_z_matches_difference():
    a = 0.7
    h = 1e-6
    num = (lie.rot_z(a + h) - lie.rot_z(a - h)) / (2 * h)
    assert np.allclose(lie.drot_z(a), num, atol=1e-9)
    assert np.allclose(lie.drot_z(a), lie.skew([0, 0, 1]) @ lie.rot_z(a), atol=1e-15)


def test_wrap_angle():
    assert np.isclose(lie.wrap_angle(3 * np.pi / 2), -np.pi / 2)
    assert np.isclose(lie.wrap_angle(np.pi), np.pi)
