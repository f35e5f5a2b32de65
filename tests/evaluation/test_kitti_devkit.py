"""KITTI devkit metric on synthetic data with known answers."""
import numpy as np
import pytest

from gevi_cli.evaluation.kitti_devkit import kitti_errors, path_distances


def straight(n=1200, step=1.0):
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 2, 3] = np.arange(n) * step  # drive along z (KITTI forward)
    return T


def test_perfect_estimate_has_zero_error():
    T = straight()
    r = kitti_errors(np.arange(len(T)), T, np.arange(len(T)), T)
    assert r.t_err_pct == 0 and r.r_err_deg_per_100m == 0
    assert set(r.per_length) == {100, 200, 300, 400, 500, 600, 700, 800}
    # starts every 10 frames; a segment of L metres needs L+1 frames beyond the start (strictly more than L)
    assert r.per_length[800][2] == len(range(0, 1200 - 801, 10))


def test_scale_error_gives_that_percentage_and_scale_corrects_it():
    T = straight()
    E = T.copy()
    E[:, :3, 3] *= 1.02
    r = kitti_errors(np.arange(len(T)), T, np.arange(len(T)), E)
    # segment end is the first frame with distance > L, i.e. L+1 metres travelled: error 2 % of L+1 over L
    expect = np.mean([0.02 * (L + 1) / L for L in range(100, 900, 100) for _ in range(1)])
    assert r.per_length[100][0] == pytest.approx(2.0 * 101 / 100)
    assert r.t_err_pct > 2.0 and abs(r.t_err_pct - 100 * expect) < 0.01
    assert kitti_errors(np.arange(len(T)), T, np.arange(len(T)), E, scale=1 / 1.02).t_err_pct < 1e-9


def test_only_segments_with_both_frames_estimated():
    T = straight()
    keep = np.arange(2, len(T))  # estimate starts at frame 2 (kitti-odom-eval example_0)
    r = kitti_errors(np.arange(len(T)), T, keep, T[keep])
    assert r.segments[:, 0].min() == 10  # start frame 0 is not estimated
    assert np.isnan(kitti_errors(np.arange(50), T[:50], np.arange(50), T[:50]).t_err_pct)  # < 100 m


def test_rotation_error_uses_clamped_arccos():
    """A constant yaw drift of 0.01 deg per frame: r_err = (L + 1) * 0.01 deg over L metres."""
    from scipy.spatial.transform import Rotation

    T = straight()
    E = T.copy()
    E[:, :3, :3] = Rotation.from_euler("y", np.deg2rad(0.01) * np.arange(len(T))[:, None]).as_matrix()
    r = kitti_errors(np.arange(len(T)), T, np.arange(len(T)), E)
    for L, (_, r_err, _) in r.per_length.items():
        assert r_err == pytest.approx(100 * 0.01 * (L + 1) / L, rel=1e-6)
    assert np.all(np.isfinite(r.segments))
    assert r.rpe_rot_mean_deg == pytest.approx(0.01, rel=1e-6)
    assert path_distances(T)[-1] == pytest.approx(len(T) - 1)
