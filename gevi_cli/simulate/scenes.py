"""Scene builders for the presets (textures generated from the seed).

World frame W, z up.  Pool: x in [0, 10], y in [0, 5], floor z = 0, water surface z = 2.  Room
(euroc-like): x in [-4, 4], y in [-3, 3], z in [0, 3].  Street (kitti-like): ground z = 0, the road
centre line follows the car motion's ``road(x)`` with facades on both sides.  Highway (kitti-highway):
the same ground plane, and only far structures (warehouse facades and tree lines 35-90 m from the road).
"""
from __future__ import annotations

import numpy as np

from gevi_cli.simulate import textures as tx
from gevi_cli.simulate.scene import Scene, Texture, rect_plane

POOL_SIZE = (10.0, 5.0, 2.0)

EX, EY, EZ = np.eye(3)


def _rng(seed: int, *tags: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), 2002, *tags])


def _lit(img: np.ndarray, texel: float, rng, amp: float, wl=(1.5, 4.0)) -> np.ndarray:
    """Bake uneven, static illumination into a texture: ``1 + amp sin(2pi u/wl_u + a) sin(2pi v/wl_v + b)``."""
    h, w = img.shape
    wu, wv = rng.uniform(*wl, 2)
    pu, pv = rng.uniform(0, 2 * np.pi, 2)
    u = (np.arange(w, dtype=np.float32) + 0.5) * np.float32(texel)
    v = (np.arange(h, dtype=np.float32) + 0.5) * np.float32(texel)
    field = 1.0 + amp * np.outer(np.sin(2 * np.pi * v / wv + pv), np.sin(2 * np.pi * u / wu + pu)).astype(np.float32)
    return (img * field).astype(np.float32)


def _pool_box(floor_tex: Texture, wall_texs, surface_tex: Texture) -> list:
    L, W, D = POOL_SIZE
    planes = [rect_plane([0, 0, 0], EX, EY, L, W, floor_tex, gain=1.0, name="floor")]
    # walls: u horizontal along the wall, v up
    planes.append(rect_plane([0, 0, 0], EX, EZ, L, D, wall_texs[0], gain=0.9, name="wall_y0"))
    planes.append(rect_plane([0, W, 0], EX, EZ, L, D, wall_texs[1], gain=0.9, name="wall_y5"))
    planes.append(rect_plane([0, 0, 0], EY, EZ, W, D, wall_texs[2], gain=0.85, name="wall_x0"))
    planes.append(rect_plane([L, 0, 0], EY, EZ, W, D, wall_texs[3], gain=0.85, name="wall_x10"))
    planes.append(rect_plane([0, 0, D], EX, EY, L, W, surface_tex, gain=1.0, name="surface"))
    return planes


def pool_easy(seed: int) -> Scene:
    """Floor of small repetitive tiles with gravel patches; tiled walls."""
    L, W, D = POOL_SIZE
    texel = 0.0025
    shape = (int(W / texel), int(L / texel))
    rng = _rng(seed, 1)
    floor = tx.tiles(shape, rng, tile_px=int(0.15 / texel), grout_px=2, base=0.62, grout=0.22, variation=0.06)
    stones = tx.gravel(shape, rng, stone_px=0.035 / texel, background=0.25)
    mask = tx.value_noise(shape, rng, cell_px=1.2 / texel, octaves=2)
    mask = np.clip((mask - 0.45) * 8.0, 0.0, 1.0)
    floor = floor * (1 - mask) + stones * mask
    floor_tex = Texture.from_image(_lit(floor, texel, rng, 0.25), texel)
    wtex = 0.005
    walls = []
    for i, length in enumerate((L, L, W, W)):
        wr = _rng(seed, 10 + i)
        img = tx.tiles((int(D / wtex), int(length / wtex)), wr, tile_px=int(0.1 / wtex), grout_px=1, base=0.7,
                       grout=0.3, variation=0.05)
        # a dark lane-marking band near the floor and a darker coping stripe at the top
        img[-int(0.25 / wtex):-int(0.15 / wtex), :] *= 0.35
        img[: int(0.1 / wtex), :] *= 0.5
        walls.append(Texture.from_image(_lit(img, wtex, wr, 0.2), wtex))
    surf = Texture.from_image(0.95 + 0.03 * (tx.value_noise((250, 500), _rng(seed, 20), 40) - 0.5), 0.02)
    planes = _pool_box(floor_tex, walls, surf)
    return Scene(tuple(planes), sky=0.9, sky_gradient=0.0, name="pool-easy")


def pool_hard(seed: int) -> Scene:
    """Nearly textureless floor with a few isolated markers and one calibration board; plain walls."""
    L, W, D = POOL_SIZE
    texel = 0.0025
    shape = (int(W / texel), int(L / texel))
    rng = _rng(seed, 3)
    floor = 0.55 + 0.05 * (tx.value_noise(shape, rng, cell_px=0.6 / texel, octaves=5) - 0.5)
    floor += 0.03 * (tx.value_noise(shape, rng, cell_px=4, octaves=2) - 0.5)
    floor = floor.astype(np.float32)
    # sparse faint stains and chips (~1 per square metre): weak, isolated features
    for _ in range(int(L * W)):
        r = int(rng.uniform(0.015, 0.05) / texel)
        x, y = int(rng.uniform(0, L) / texel), int(rng.uniform(0, W) / texel)
        patch = floor[max(y - 2 * r, 0):y + 2 * r, max(x - 2 * r, 0):x + 2 * r]
        yy, xx = np.mgrid[0:patch.shape[0], 0:patch.shape[1]]
        cy, cx = min(y, 2 * r), min(x, 2 * r)
        blob = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2 * rng.uniform(0.4, 1.0)) / (2.0 * r * r / 4))
        patch += float(rng.choice([-1.0, 1.0]) * rng.uniform(0.06, 0.15)) * blob.astype(np.float32)
    # a few isolated ArUco-like markers (0.2-0.3 m) scattered over the floor
    # one calibration-board-like patch: 6 x 8 squares of 6 cm (0.6 m x 0.48 m with its margin)
    board = tx.checkerboard(6, 8, int(0.06 / texel))
    board_xy = (4.6, 2.1)
    tx.paste(floor, board, int(board_xy[0] / texel), int(board_xy[1] / texel))
    taken = [(board_xy[0] + 0.3, board_xy[1] + 0.24)]
    placed = 0
    while placed < 7:  # isolated markers: at least 1 m from each other and from the board
        cx, cy = rng.uniform(0.8, L - 1.1), rng.uniform(0.6, W - 0.9)
        if min(np.hypot(cx - a, cy - b) for a, b in taken) < 1.0:
            continue
        taken.append((cx, cy))
        cell = int(rng.uniform(0.022, 0.032) / texel)
        m = tx.marker(rng, bits=6, cell_px=cell)
        tx.paste(floor, m, int(cx / texel) - m.shape[1] // 2, int(cy / texel) - m.shape[0] // 2)
        placed += 1
    floor_tex = Texture.from_image(_lit(floor, texel, rng, 0.25), texel)
    wtex = 0.01
    walls = []
    for i, length in enumerate((L, L, W, W)):
        wr = _rng(seed, 30 + i)
        img = 0.6 + 0.04 * (tx.value_noise((int(D / wtex), int(length / wtex)), wr, 60, octaves=3) - 0.5)
        img[-int(0.3 / wtex):-int(0.2 / wtex), :] = 0.25
        walls.append(Texture.from_image(_lit(img.astype(np.float32), wtex, wr, 0.2), wtex))
    surf = Texture.from_image(0.95 + 0.03 * (tx.value_noise((250, 500), _rng(seed, 40), 40) - 0.5), 0.02)
    planes = _pool_box(floor_tex, walls, surf)
    return Scene(tuple(planes), sky=0.9, sky_gradient=0.0, name="pool-hard")


def euroc_room(seed: int) -> Scene:
    """An 8 m x 6 m x 3 m lab: poster-covered walls, a gravel/mat floor, a tiled ceiling, free panels."""
    X, Y, H = 4.0, 3.0, 3.0
    rng = _rng(seed, 5)
    texel = 0.006
    planes = []
    floor_shape = (int(2 * Y / texel), int(2 * X / texel))
    floor = 0.5 * tx.gravel(floor_shape, rng, stone_px=0.06 / texel, background=0.2) + \
        0.5 * tx.value_noise(floor_shape, rng, 0.5 / texel)
    planes.append(rect_plane([-X, -Y, 0], EX, EY, 2 * X, 2 * Y, Texture.from_image(_lit(floor, texel, rng, 0.15), texel),
                             gain=0.9, name="floor"))
    ceil = tx.tiles((int(2 * Y / 0.01), int(2 * X / 0.01)), rng, tile_px=60, grout_px=3, base=0.85, grout=0.4)
    planes.append(rect_plane([-X, -Y, H], EX, EY, 2 * X, 2 * Y, Texture.from_image(ceil, 0.01), gain=0.95, name="ceiling"))
    walls = [([-X, -Y, 0], EX, 2 * X), ([-X, Y, 0], EX, 2 * X), ([-X, -Y, 0], EY, 2 * Y), ([X, -Y, 0], EY, 2 * Y)]
    for i, (o, ax, length) in enumerate(walls):
        wr = _rng(seed, 50 + i)
        shape = (int(H / texel), int(length / texel))
        if i == 2:
            bg = tx.bricks(shape, wr, (int(0.24 / texel), int(0.075 / texel)), 2, base=0.45)
        else:
            bg = 0.55 + 0.15 * (tx.value_noise(shape, wr, 0.3 / texel) - 0.5)
        img = tx.posters(shape, wr, count=int(length * 2.5), size_px=(int(0.3 / texel), int(1.0 / texel)), background=bg)
        planes.append(rect_plane(o, ax, EZ, length, H, Texture.from_image(_lit(img, texel, wr, 0.15), texel),
                                 gain=0.95, name=f"wall{i}"))
    # free-standing panels and boxes for depth variety
    for i in range(5):
        wr = _rng(seed, 60 + i)
        w, h = wr.uniform(0.6, 1.4), wr.uniform(0.5, 1.6)
        ang = wr.uniform(0, np.pi)
        r = wr.uniform(2.2, 3.2)
        phi = 2 * np.pi * i / 5 + wr.uniform(-0.3, 0.3)
        c = np.array([r * np.cos(phi) * X / 3.2, r * np.sin(phi) * Y / 3.2, 0.0])
        c[0] = np.clip(c[0], -X + 0.4, X - 0.4)
        c[1] = np.clip(c[1], -Y + 0.4, Y - 0.4)
        ax = np.array([np.cos(ang), np.sin(ang), 0.0])
        img = tx.posters((int(h / texel), int(w / texel)), wr, count=4, size_px=(int(0.15 / texel), int(0.5 / texel)))
        planes.append(rect_plane(c - ax * w / 2 + EZ * wr.uniform(0.0, 0.6), ax, EZ, w, h,
                                 Texture.from_image(img, texel), gain=1.0, name=f"panel{i}"))
    return Scene(tuple(planes), sky=0.5, sky_gradient=0.0, name="euroc-like")


def kitti_street(seed: int, road, x_range: tuple[float, float]) -> Scene:
    """Ground plane plus building facades along ``y = road(x)`` for x in ``x_range`` (world metres)."""
    rng = _rng(seed, 7)
    g_texel = 0.01
    ground = tx.make_periodic(tx.asphalt((832, 832), rng, 1.0 / g_texel), 32)  # 8 m period
    planes = [rect_plane([0, 0, 0], EX, EY, np.inf, np.inf, Texture.from_image(ground, g_texel, wrap=True),
                         gain=1.0, name="ground")]
    f_texel = 0.03
    styles = [Texture.from_image(tx.facade((int(20 / f_texel), int(32 / f_texel)), _rng(seed, 70 + i), 1 / f_texel),
                                 f_texel) for i in range(8)]
    road_y = lambda x: float(road(np.array([x]))[0][0])  # noqa: E731
    for side in (-1.0, 1.0):
        x = x_range[0] - rng.uniform(0, 10)
        while x < x_range[1]:
            width = rng.uniform(12.0, 30.0)
            gap = rng.uniform(0.0, 6.0) if rng.random() < 0.4 else 0.0
            setback = rng.uniform(8.0, 12.0)
            height = rng.uniform(8.0, 19.0)
            xa, xb = x + gap, x + gap + width
            pa = np.array([xa, road_y(xa) + side * setback, 0.0])
            pb = np.array([xb, road_y(xb) + side * setback, 0.0])
            seg = pb - pa
            length = float(np.linalg.norm(seg))
            tex = styles[int(rng.integers(0, len(styles)))]
            # facade texture row 0 is the top of the building: v runs downwards from the roof line
            top = pa + EZ * height
            planes.append(rect_plane(top, seg, -EZ, min(length, tex.period_u), height, tex,
                                     gain=float(rng.uniform(0.8, 1.1)), name=f"facade{side:+.0f}_{xa:.0f}"))
            x = xb
    return Scene(tuple(planes), sky=0.75, sky_gradient=0.25, name="kitti-like")


def kitti_highway(seed: int, road, x_range: tuple[float, float]) -> Scene:
    """Ground plane plus far structures along ``y = road(x)`` for x in ``x_range`` (world metres):
    warehouse facades and tree lines 35-90 m either side of the road, 6-18 m high, with open gaps, so
    that apart from the road surface the texture is far (a few pixels of disparity at 0.54 m baseline)."""
    rng = _rng(seed, 8)
    g_texel = 0.01
    ground = tx.make_periodic(tx.asphalt((832, 832), rng, 1.0 / g_texel), 32)  # 8 m period
    planes = [rect_plane([0, 0, 0], EX, EY, np.inf, np.inf, Texture.from_image(ground, g_texel, wrap=True),
                         gain=1.0, name="ground")]
    f_texel = 0.06  # coarser than the street's: seen from 35 m and more
    shape = (int(20 / f_texel), int(32 / f_texel))
    styles = [Texture.from_image(tx.facade(shape, _rng(seed, 80 + i), 1 / f_texel), f_texel) for i in range(4)]
    styles += [Texture.from_image(tx.normalize(tx.value_noise(shape, _rng(seed, 90 + i), cell_px=0.8 / f_texel,
                                                              octaves=4), 0.08, 0.5), f_texel) for i in range(4)]
    road_y = lambda x: float(road(np.array([x]))[0][0])  # noqa: E731
    for side in (-1.0, 1.0):
        x = x_range[0] - rng.uniform(0, 40)
        while x < x_range[1]:
            width = rng.uniform(20.0, 32.0)
            gap = rng.uniform(10.0, 60.0) if rng.random() < 0.5 else 0.0
            setback = rng.uniform(35.0, 90.0)
            height = rng.uniform(6.0, 18.0)
            xa, xb = x + gap, x + gap + width
            pa = np.array([xa, road_y(xa) + side * setback, 0.0])
            pb = np.array([xb, road_y(xb) + side * setback, 0.0])
            seg = pb - pa
            tex = styles[int(rng.integers(0, len(styles)))]
            planes.append(rect_plane(pa + EZ * height, seg, -EZ, min(float(np.linalg.norm(seg)), tex.period_u), height,
                                     tex, gain=float(rng.uniform(0.8, 1.1)), name=f"far{side:+.0f}_{xa:.0f}"))
            x = xb
    return Scene(tuple(planes), sky=0.75, sky_gradient=0.25, name="kitti-highway")


def build_scene(spec, seed: int, motion, duration: float) -> Scene:
    """The scene of preset ``spec`` for ``seed`` (the street depends on the car's road)."""
    if spec.scene == "pool-easy":
        return pool_easy(seed)
    if spec.scene == "pool-hard":
        return pool_hard(seed)
    if spec.scene == "euroc-like":
        return euroc_room(seed)
    if spec.scene == "kitti-like":
        x_end = float(motion(np.array([duration])).p_W[0, 0]) + 150.0
        return kitti_street(seed, motion.road, (-30.0, x_end))
    if spec.scene == "kitti-highway":
        x_end = float(motion(np.array([duration])).p_W[0, 0]) + 300.0  # far structures are seen from afar
        return kitti_highway(seed, motion.road, (-60.0, x_end))
    raise ValueError(f"unknown scene {spec.scene!r}")
