"""Front-end pieces for lamp-lit, feature-poor floors: shading removal, the percentile quality
reference of the grid detector, and the fitted image motion of GeVI's standstill test.

Synthetic scenes with known answers: a faint band-limited texture (a few grey levels) under a strong
camera-fixed light spot, as an underwater vehicle's lamps make it (docs/method.md, "Shading").
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gevi_cli.frontend.config import FrontendConfig
from gevi_cli.frontend.grid import detect_grid
from gevi_cli.frontend.image_motion import fitted_flow_px
from gevi_cli.frontend.klt import build_pyramid
from gevi_cli.frontend.shading import remove_shading
from gevi_cli.frontend.stereo import match_stereo

CFG = FrontendConfig()
H, W = 240, 400


def faint_texture(shift_u: float = 0.0, seed: int = 0, contrast: float = 6.0) -> np.ndarray:
    """Zero-mean band-limited texture T(u - shift_u, v) (periods 8-30 px), float, peak |T| = contrast."""
    rng = np.random.default_rng(seed)
    k = 60
    ang, freq, ph = rng.uniform(0, np.pi, k), rng.uniform(0.2, 0.8, k), rng.uniform(0, 2 * np.pi, k)
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    x = x - shift_u
    t = sum(np.sin(f * (np.cos(a) * x + np.sin(a) * y) + p) for a, f, p in zip(ang, freq, ph))
    return contrast * t / np.abs(t).max()


def lamp(cu: float, cv: float, amplitude: float = 90.0, sigma: float = 150.0) -> np.ndarray:
    """A smooth light spot centred at pixel (cu, cv), fixed to the camera."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    return amplitude * np.exp(-((x - cu) ** 2 + (y - cv) ** 2) / (2 * sigma**2))


def to_u8(f: np.ndarray) -> np.ndarray:
    return np.clip(np.round(f), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("size", [31, 61])
def test_shading_removal_keeps_the_texture_and_drops_the_light_spot(size):
    """What is left is the texture: of the spot's variation (std ~20 grey levels here) at most 5 %
    remains (a local mean cannot follow the spot's curvature exactly: the residual grows as
    size^2 / sigma^2), and the texture passes unchanged on average."""
    tex, spot = faint_texture(), lamp(150, 100)
    img = to_u8(90 + spot + tex)
    out = remove_shading(img, size)
    assert out.dtype == np.uint8 and out.shape == img.shape
    inner = (slice(40, H - 40), slice(40, W - 40))  # away from the border's replicated mean
    rest = out[inner].astype(float) - 128.0
    assert np.std(rest - tex[inner]) < 0.05 * np.std(spot[inner])
    assert np.abs(rest.mean()) < 1.0
    gain = np.sum(rest * tex[inner]) / np.sum(tex[inner] ** 2)  # texture periods << size: passes
    assert 0.9 < gain < 1.05
    assert remove_shading(img, 0) is img and remove_shading(img, 1) is img


@pytest.mark.parametrize("size", [31, 61])
def test_stereo_on_a_lamp_lit_faint_floor_needs_the_shading_removed(size):
    """Right camera sees the texture shifted by the disparity but the light spot where its own lamp
    puts it: LK aligns the spot on the raw images; after removal the matches have the true disparity."""
    d_true = 18.4
    left = to_u8(80 + lamp(170, 120, sigma=70.0) + faint_texture())
    right = to_u8(80 + lamp(230, 120, sigma=70.0) + faint_texture(-d_true))
    cfg = replace(CFG, shading_px=size)
    fake = type("Cam", (), {"fx": 400.0, "baseline": 0.1})()
    uv = detect_grid(remove_shading(left, size), None, cfg)
    uv = uv[(uv[:, 0] > 40) & (uv[:, 0] < W - 40) & (uv[:, 1] > 30) & (uv[:, 1] < H - 30)]
    assert len(uv) > 30

    def correct(l_img, r_img):
        uv_r, ok = match_stereo(build_pyramid(l_img, cfg), build_pyramid(r_img, cfg), uv, fake, cfg,
                                disparity_prior=d_true)
        return ok & (np.abs(uv[:, 0] - uv_r[:, 0] - d_true) < 0.3)

    after = correct(remove_shading(left, size), remove_shading(right, size))
    raw = correct(left, right)
    assert after.mean() > 0.8
    assert raw.mean() < after.mean() - 0.2


def test_a_bright_marker_does_not_take_the_faint_floor_corners_away():
    """quality relative to the strongest corner: one checkerboard leaves the floor with nothing;
    relative to the 90th percentile of the cells' best, the floor keeps its corners."""
    img = 100 + faint_texture(contrast=4.0)
    img[20:60, 20:60] = np.where((np.add.outer(np.arange(40) // 10, np.arange(40) // 10) % 2) == 0, 10, 245)
    img = to_u8(img)
    floor = lambda uv: ((uv[:, 0] > 80) | (uv[:, 1] > 80)).sum()  # noqa: E731
    n_max = floor(detect_grid(img, None, CFG))
    n_p90 = floor(detect_grid(img, None, replace(CFG, quality_percentile=90.0)))
    cells = (W // CFG.cell_px) * (H // CFG.cell_px)
    assert n_max < 0.1 * cells
    assert n_p90 > 0.8 * cells


def test_config_rejects_bad_values():
    with pytest.raises(ValueError):
        FrontendConfig(quality_percentile=0.0)
    with pytest.raises(ValueError):
        FrontendConfig(shading_px=-1)


def test_fitted_flow_sees_a_common_motion_not_a_random_walk():
    """Independent 3 px walks of 100 features read about 3 px/sqrt(n) per parameter, not the walk's
    90th percentile (~6.4 px for a 2-D Gaussian of 3 px); a common 5 px shift plus the same walk reads
    5 px; a rotation about the image centre reads its displacement at the features."""
    rng = np.random.default_rng(3)
    p0 = rng.uniform([0, 0], [752, 480], (100, 2))
    walk = rng.normal(0, 3.0, (100, 2))
    raw = np.percentile(np.linalg.norm(walk, axis=1), 90)
    assert raw > 5.0
    assert fitted_flow_px(p0, p0 + walk) < 1.5
    assert abs(fitted_flow_px(p0, p0 + walk + [4.0, 3.0]) - 5.0) < 1.0
    c = np.array([376.0, 240.0])
    th = np.radians(1.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    p1 = (p0 - c) @ R.T + c
    expect = np.percentile(np.linalg.norm(p1 - p0, axis=1), 90)
    assert abs(fitted_flow_px(p0, p1) - expect) < 0.01 * expect
    assert fitted_flow_px(p0, p0 + walk) == fitted_flow_px(p0, p0 + walk)  # seeded: same answer
    assert fitted_flow_px(p0[:2], p0[:2]) == 0.0


def test_flow_percentile_is_numpys_to_the_bit():
    """The standstill test's partial-sort percentile returns np.percentile's float (linear method)."""
    from gevi_cli.frontend.image_motion import _percentile

    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 10, 151, 226):
        for q in (0.0, 37.5, 50.0, 90.0, 100.0):
            x = rng.random(n) * 10.0
            assert _percentile(x, q) == float(np.percentile(x, q)), (n, q)
