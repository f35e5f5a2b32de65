#!/usr/bin/env python
"""Benchmark `gevi simulate`: wall time of a whole render (scene, IMU, images, files).

Default: the acceptance case, a 20 s pool-easy sequence at 10 Hz, 640x360, EuRoC layout (target
<= 30 s on a 2-core machine).  ``--examples DIR`` also writes one downscaled left image per preset
(``DIR/sim_<preset>.png``, the README pictures).

    python scripts/bench_simulate.py
    python scripts/bench_simulate.py --preset kitti-like --format kitti --duration 10
    python scripts/bench_simulate.py --examples docs/img --skip-bench
"""
from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path


def bench(args) -> None:
    from gevi_cli.simulate.generate import SimulationConfig, build_sequence, simulate

    w, h = (int(x) for x in args.resolution.lower().split("x"))
    cfg = SimulationConfig(args.preset, seed=args.seed, duration_s=args.duration, rate_hz=args.rate, resolution=(w, h))
    tmp = Path(tempfile.mkdtemp(prefix="gevi-bench-"))
    try:
        t0 = time.perf_counter()
        seq = build_sequence(cfg)
        _ = seq.scene
        t_scene = time.perf_counter() - t0
        _ = seq.renderers
        t_rays = time.perf_counter() - t0 - t_scene
        t0 = time.perf_counter()
        simulate(cfg, tmp / "out", args.format, progress=not args.quiet, workers=args.workers)
        total = time.perf_counter() - t0
        n = len(seq.frame_t_ns)
        size = sum(p.stat().st_size for p in (tmp / "out").rglob("*") if p.is_file())
        print(f"preset {args.preset}, {args.duration:g} s at {args.rate:g} Hz, {w}x{h}, format {args.format}, "
              f"workers {args.workers or min(2, os.cpu_count() or 1)}, cpus {os.cpu_count()}")
        print(f"  scene textures {t_scene:.2f} s, camera rays {t_rays:.2f} s (both included in the total)")
        print(f"  total {total:.2f} s for {n} stereo frames = {total / n * 1000:.1f} ms per stereo frame, "
              f"{size / 1e6:.1f} MB written")
        target = 30.0
        if (args.preset, args.duration, args.rate, (w, h), args.format) == ("pool-easy", 20.0, 10.0, (640, 360), "euroc"):
            print(f"  acceptance (<= {target:.0f} s): {'met' if total <= target else 'NOT met'}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


EXAMPLES = {  # preset: (time in s, width of the saved picture)
    "pool-easy": (9.0, 480),
    "pool-hard": (None, 480),  # None: the most textured moment (a marker or the board in view)
    "euroc-like": (12.0, 480),
    "kitti-like": (12.0, 620),
}


def examples(folder: Path) -> None:
    import cv2
    import numpy as np

    from gevi_cli.simulate.generate import SimulationConfig, build_sequence

    folder.mkdir(parents=True, exist_ok=True)
    for preset, (t, width) in EXAMPLES.items():
        if t is None:
            probe = build_sequence(SimulationConfig(preset, seed=1, duration_s=30.0, rate_hz=2.0, resolution=(96, 60),
                                                    image_noise=False))
            score = [cv2.Laplacian(probe.render_frame(k)[0], cv2.CV_32F).var() for k in range(len(probe.frame_t_ns))]
            t = float(np.argmax(score)) / 2.0
        seq = build_sequence(SimulationConfig(preset, seed=1, duration_s=t + 1.0, rate_hz=1.0 if t == int(t) else 2.0))
        k = int(np.searchsorted(seq.frame_t_ns, seq.t0_ns + int(t * 1e9)))
        left, _ = seq.render_frame(min(k, len(seq.frame_t_ns) - 1))
        small = cv2.resize(left, (width, round(left.shape[0] * width / left.shape[1])), interpolation=cv2.INTER_AREA)
        path = folder / f"sim_{preset}.png"
        cv2.imwrite(str(path), small, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(f"{path}: {small.shape[1]}x{small.shape[0]}, {path.stat().st_size / 1e3:.0f} kB (left image at t = {t:g} s)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="pool-easy")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--resolution", default="640x360")
    p.add_argument("--format", default="euroc", choices=["euroc", "kitti", "bag"])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--examples", type=Path, help="also write docs pictures sim_<preset>.png into this folder")
    p.add_argument("--skip-bench", action="store_true")
    args = p.parse_args()
    if not args.skip_bench:
        bench(args)
    if args.examples:
        examples(args.examples)


if __name__ == "__main__":
    main()
