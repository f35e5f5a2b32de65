"""Procedural grayscale textures (float32 in [0, 1]), deterministic for a given numpy Generator.

Each generator returns an (H, W) float32 array; the caller decides the physical texel size.  All
randomness comes from the ``rng`` argument, and OpenCV drawing/resizing is deterministic, so equal
seeds give bit-identical textures.
"""
from __future__ import annotations

import cv2
import numpy as np


def value_noise(shape: tuple[int, int], rng: np.random.Generator, cell_px: float, octaves: int = 4,
                persistence: float = 0.55) -> np.ndarray:
    """Multi-octave smooth noise in [0, 1]; the coarsest features are ``cell_px`` texels wide."""
    h, w = shape
    out = np.zeros(shape, np.float32)
    amp, total = 1.0, 0.0
    cell = float(cell_px)
    for _ in range(octaves):
        gh, gw = max(2, int(np.ceil(h / cell)) + 2), max(2, int(np.ceil(w / cell)) + 2)
        grid = rng.random((gh, gw)).astype(np.float32)
        up = cv2.resize(grid, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
        out += amp * up[:h, :w]
        total += amp
        amp *= persistence
        cell = max(cell / 2.0, 1.0)
    out /= total
    return normalize(out)


def normalize(a: np.ndarray, lo: float = 0.0, hi: float = 1.0) -> np.ndarray:
    a = a.astype(np.float32)
    mn, mx = float(a.min()), float(a.max())
    if mx - mn < 1e-12:
        return np.full_like(a, (lo + hi) / 2)
    return (lo + (a - mn) * ((hi - lo) / (mx - mn))).astype(np.float32)


def tiles(shape: tuple[int, int], rng: np.random.Generator, tile_px: int, grout_px: int, base: float = 0.72,
          grout: float = 0.25, variation: float = 0.05, grain: float = 0.04) -> np.ndarray:
    """Square tiles with dark grout lines: many nearly identical corners (repetitive texture)."""
    h, w = shape
    ny, nx = h // tile_px + 2, w // tile_px + 2
    tile_val = base + variation * rng.standard_normal((ny, nx)).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w]
    img = tile_val[yy // tile_px, xx // tile_px]
    inside_x = (xx % tile_px) >= grout_px
    inside_y = (yy % tile_px) >= grout_px
    img = np.where(inside_x & inside_y, img, grout).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), max(grout_px / 3.0, 0.6))
    img += grain * (value_noise(shape, rng, max(tile_px / 8, 2), octaves=3) - 0.5)
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def gravel(shape: tuple[int, int], rng: np.random.Generator, stone_px: float, contrast: float = 1.0,
           background: float = 0.3) -> np.ndarray:
    """Pebbles: Voronoi cells with random brightness, rounded shading and dark gaps (corner rich)."""
    h, w = shape
    n = int(h * w / (stone_px * stone_px) * 1.1)
    seeds = np.ones((h, w), np.uint8)
    ys = rng.integers(0, h, n)
    xs = rng.integers(0, w, n)
    seeds[ys, xs] = 0
    dist, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    nl = int(labels.max()) + 1
    val = rng.uniform(0.35, 0.95, nl).astype(np.float32)
    radius = (stone_px * rng.uniform(0.35, 0.6, nl)).astype(np.float32)
    lab = labels
    r = radius[lab]
    shade = np.clip(1.0 - (dist / r) ** 2, 0.0, 1.0)
    stone = val[lab] * (0.55 + 0.45 * np.sqrt(shade))
    img = np.where(dist < r, stone, background).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    img = background + contrast * (img - background)
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def marker(rng: np.random.Generator, bits: int = 6, cell_px: int = 16) -> np.ndarray:
    """An ArUco-like square marker: random bits inside a black border inside a white margin."""
    code = rng.integers(0, 2, (bits, bits)).astype(np.float32)
    m = np.zeros((bits + 2, bits + 2), np.float32)
    m[1:-1, 1:-1] = code
    m = np.pad(m, 1, constant_values=1.0)
    img = np.kron(m, np.ones((cell_px, cell_px), np.float32))
    return 0.08 + 0.84 * img


def checkerboard(rows: int, cols: int, square_px: int, dark: float = 0.08, light: float = 0.92,
                 margin_squares: int = 1) -> np.ndarray:
    """A checkerboard of rows x cols squares with a light margin; inner corners at multiples of square_px."""
    yy, xx = np.mgrid[0:rows, 0:cols]
    board = np.where((xx + yy) % 2 == 0, dark, light).astype(np.float32)
    board = np.pad(board, margin_squares, constant_values=light)
    return np.kron(board, np.ones((square_px, square_px), np.float32))


def paste(dst: np.ndarray, src: np.ndarray, x: int, y: int) -> None:
    """Copy ``src`` into ``dst`` with its top-left corner at (x, y), clipped to ``dst``."""
    h, w = src.shape
    x0, y0 = max(x, 0), max(y, 0)
    x1, y1 = min(x + w, dst.shape[1]), min(y + h, dst.shape[0])
    if x1 > x0 and y1 > y0:
        dst[y0:y1, x0:x1] = src[y0 - y:y1 - y, x0 - x:x1 - x]


def posters(shape: tuple[int, int], rng: np.random.Generator, count: int, size_px: tuple[int, int],
            background: np.ndarray | None = None) -> np.ndarray:
    """Random rectangles, discs and text-like stripes (an office / lab wall)."""
    h, w = shape
    img = background.copy() if background is not None else 0.6 + 0.1 * (value_noise(shape, rng, 64) - 0.5)
    img = np.ascontiguousarray(img, dtype=np.float32)
    for _ in range(count):
        pw, ph = int(rng.uniform(*size_px)), int(rng.uniform(*size_px))
        x, y = int(rng.integers(-pw // 2, w)), int(rng.integers(-ph // 2, h))
        kind = rng.integers(0, 4)
        if kind == 0:
            patch = value_noise((ph, pw), rng, max(min(ph, pw) / 6, 2), octaves=3)
            patch = (patch > 0.5).astype(np.float32) * 0.7 + 0.15
        elif kind == 1:
            patch = np.full((ph, pw), rng.uniform(0.1, 0.9), np.float32)
            for _ in range(int(rng.integers(3, 9))):
                cx, cy = int(rng.integers(0, pw)), int(rng.integers(0, ph))
                rad = int(rng.integers(max(2, min(pw, ph) // 12), max(3, min(pw, ph) // 4)))
                cv2.circle(patch, (cx, cy), rad, float(rng.uniform(0, 1)), -1, lineType=cv2.LINE_AA)
        elif kind == 2:
            patch = np.full((ph, pw), rng.uniform(0.75, 0.95), np.float32)
            lines = int(rng.integers(4, 14))
            for i in range(lines):
                yy = int((i + 0.5) * ph / lines)
                xe = int(pw * rng.uniform(0.3, 0.95))
                cv2.line(patch, (pw // 10, yy), (xe, yy), 0.1, max(1, ph // (lines * 3)))
        else:
            sq = max(4, min(pw, ph) // 8)
            patch = checkerboard(max(1, ph // sq), max(1, pw // sq), sq, margin_squares=0)
        paste(img, patch, x, y)
    return np.clip(img, 0.0, 1.0)


def bricks(shape: tuple[int, int], rng: np.random.Generator, brick_px: tuple[int, int], mortar_px: int = 2,
           base: float = 0.5) -> np.ndarray:
    """Running-bond brick wall."""
    h, w = shape
    bw, bh = brick_px
    yy, xx = np.mgrid[0:h, 0:w]
    row = yy // bh
    xs = xx + (row % 2) * (bw // 2)
    col = xs // bw
    vals = base + 0.12 * rng.standard_normal((h // bh + 2, w // bw + 3)).astype(np.float32)
    img = vals[row, col]
    mortar = ((yy % bh) < mortar_px) | ((xs % bw) < mortar_px)
    img = np.where(mortar, 0.8, img).astype(np.float32)
    img += 0.06 * (value_noise(shape, rng, 6, octaves=3) - 0.5)
    return np.clip(img, 0, 1).astype(np.float32)


def facade(shape: tuple[int, int], rng: np.random.Generator, px_per_m: float) -> np.ndarray:
    """A building facade: plaster or bricks with a grid of windows and a ground-floor band."""
    h, w = shape
    if rng.random() < 0.5:
        img = bricks(shape, rng, (int(0.25 * px_per_m), int(0.08 * px_per_m)), max(1, int(0.012 * px_per_m)),
                     base=float(rng.uniform(0.35, 0.6)))
    else:
        img = float(rng.uniform(0.5, 0.8)) + 0.12 * (value_noise(shape, rng, px_per_m * 0.8) - 0.5)
    img = img.astype(np.float32)
    floor_h = rng.uniform(2.8, 3.5) * px_per_m
    win_w, win_h = rng.uniform(0.9, 1.5) * px_per_m, rng.uniform(1.2, 1.7) * px_per_m
    spacing = rng.uniform(2.2, 3.5) * px_per_m
    frame = max(2, int(0.08 * px_per_m))
    glass = float(rng.uniform(0.05, 0.3))
    nfloors = int(h / floor_h)
    for f in range(1, nfloors):
        y_bottom = h - f * floor_h - 0.9 * px_per_m
        y0 = int(y_bottom - win_h)
        for i in range(int(w / spacing)):
            x0 = int(i * spacing + (spacing - win_w) / 2)
            cv2.rectangle(img, (x0 - frame, y0 - frame), (int(x0 + win_w) + frame, int(y0 + win_h) + frame), 0.9, -1)
            g = glass + 0.15 * rng.random()
            cv2.rectangle(img, (x0, y0), (int(x0 + win_w), int(y0 + win_h)), g, -1)
            cv2.line(img, (int(x0 + win_w / 2), y0), (int(x0 + win_w / 2), int(y0 + win_h)), 0.85, frame)
    # ground floor: shop windows and a dark base band
    base_h = int(0.4 * px_per_m)
    img[h - base_h:, :] = 0.2 + 0.05 * rng.random()
    for i in range(int(w / (4 * px_per_m))):
        x0 = int((i * 4 + 0.6) * px_per_m)
        cv2.rectangle(img, (x0, int(h - 2.6 * px_per_m)), (int(x0 + 2.6 * px_per_m), h - base_h), float(rng.uniform(0.05, 0.35)), -1)
    return np.clip(img, 0, 1).astype(np.float32)


def asphalt(shape: tuple[int, int], rng: np.random.Generator, px_per_m: float) -> np.ndarray:
    """Road surface: grainy asphalt with cracks and patches (periodic-friendly, no lane marks)."""
    img = 0.32 + 0.22 * (value_noise(shape, rng, max(px_per_m * 0.05, 2), octaves=3) - 0.5)
    img += 0.10 * (value_noise(shape, rng, px_per_m * 1.5, octaves=2) - 0.5)
    g = gravel(shape, rng, max(px_per_m * 0.04, 3), contrast=0.35, background=0.32)
    img = 0.5 * img + 0.5 * g
    return np.clip(img, 0, 1).astype(np.float32)


def make_periodic(img: np.ndarray, blend_px: int) -> np.ndarray:
    """Blend opposite borders so the texture tiles without a visible seam (used with wrap-around)."""
    h, w = img.shape
    out = img.copy()
    ramp = np.linspace(0.0, 1.0, blend_px, dtype=np.float32)
    # horizontal: left blend_px columns fade into the right border's continuation
    out[:, :blend_px] = img[:, :blend_px] * ramp[None, :] + img[:, w - blend_px:] * (1 - ramp[None, :])
    out2 = out.copy()
    out2[:blend_px, :] = out[:blend_px, :] * ramp[:, None] + out[h - blend_px:, :] * (1 - ramp[:, None])
    return out2[: h - blend_px, : w - blend_px].copy()
