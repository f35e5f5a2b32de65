"""The keyframe's point gate: depth limits in metres and a disparity floor in pixels."""
from __future__ import annotations

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.observations import RectifiedStereo, StereoObs
from gevi_cli.pipelines.keyframe import make_keyframe


def _stereo(disparities_px, rig):
    d = np.asarray(disparities_px, float)
    uv_l = np.column_stack([rig.cx + 40.0 * np.arange(len(d)), np.full(len(d), rig.cy + 10.0)])
    return StereoObs(np.arange(len(d), dtype=np.int64), uv_l, uv_l - np.column_stack([d, np.zeros(len(d))]))


def test_min_disparity_is_the_same_cap_on_every_baseline():
    """2.4 px is EuRoC's 20 m (0.11 m x 435 px) and KITTI's 159 m (0.54 m x 707 px): the gate keeps the
    points whose disparity is at least the floor, whatever the baseline, and the depth limits still apply."""
    for baseline, f in ((0.11, 435.0), (0.54, 707.0)):
        rig = RectifiedStereo(Intrinsics(1241, 376, f, f, 620.0, 188.0), baseline)
        disp = [1.0, 2.3, 2.5, 5.0, 50.0]
        kf = make_keyframe(0, 0, np.eye(4), _stereo(disp, rig), rig, 0.5, 1000.0, min_disparity_px=2.4)
        assert kf.ids.tolist() == [2, 3, 4]
        np.testing.assert_allclose(kf.p[:, 2], f * baseline / np.array([2.5, 5.0, 50.0]), rtol=1e-9)
        # without the floor every point inside the depth limits stays
        kf = make_keyframe(0, 0, np.eye(4), _stereo(disp, rig), rig, 0.5, 1000.0)
        assert len(kf.ids) == len([d for d in disp if 0.5 <= f * baseline / d <= 1000.0])


def test_a_keyframe_short_of_near_points_keeps_its_far_ones():
    """Fewer than fill_points inside the far gate: the points beyond it are kept too, down to a disparity
    of 3 standard deviations of a disparity (sqrt(2) sigma_px) above zero; enough near points: the gate holds."""
    rig = RectifiedStereo(Intrinsics(1241, 376, 707.0, 707.0, 620.0, 188.0), 0.54)  # 100 m = 3.82 px
    disp = [0.2, 0.5, 1.0, 3.0, 10.0, 50.0]
    sigma_px = 0.1  # floor 3 x sqrt(2) x 0.1 = 0.42 px
    kf = make_keyframe(0, 0, np.eye(4), _stereo(disp, rig), rig, 0.5, 100.0, fill_points=3, sigma_px=sigma_px)
    assert kf.ids.tolist() == [1, 2, 3, 4, 5]
    np.testing.assert_allclose(kf.p[:, 2], 707.0 * 0.54 / np.array(disp[1:]), rtol=1e-9)
    # the far points' depth uncertainty is in their covariance: std of Z grows as Z^2 / (f b)
    sz = np.sqrt(kf.cov_unit[:, 2, 2])
    np.testing.assert_allclose(sz[:2] / sz[-1], (np.array(disp[-1]) / np.array(disp[1:3])) ** 2, rtol=0.05)
    for fill in (0, 2):  # two near points (10, 50 px) are enough: nothing beyond the gate
        kf = make_keyframe(0, 0, np.eye(4), _stereo(disp, rig), rig, 0.5, 100.0, fill_points=fill, sigma_px=sigma_px)
        assert kf.ids.tolist() == [4, 5]
