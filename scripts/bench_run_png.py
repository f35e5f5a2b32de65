#!/usr/bin/env python3
"""What the run folder's ``trajectory.png`` costs `gevi run`, next to the run itself.

    python scripts/bench_run_png.py [--data ../shared/data] [--repeat 5]

Runs `gevi run` on kitti06_head (CFO, 51 frames, evaluated) in a subprocess and reads the run's own
wall time (the peer); then, in a fresh interpreter (a cold start, as in `gevi run`): the import of
matplotlib's Agg figure, the first PNG and the best of ``--repeat`` further ones, each drawn from the
run's estimate over its ground truth (51 poses), and over EuRoC V1_01's ground truth (2895 poses,
thinned to 1000 for the picture).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gevi_cli.shared_data import shared_data_dir

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
t_import = time.perf_counter() - t0
from gevi_cli.evaluation.plots import plot_run_trajectory, world_of
from gevi_cli.trajectory import read_trajectory
run, gt_file, long_gt, repeat = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
gt = read_trajectory(gt_file)
est = read_trajectory(run + "/traj_body.tum").positions
out = {"import_ms": t_import * 1e3}
for name, e, g, world in (("kitti06_head", est, gt.positions, world_of(gt)),):
    t0 = time.perf_counter()
    plot_run_trajectory(run + "/first.png", e, g, world, "first")
    out["first_ms"] = (time.perf_counter() - t0) * 1e3
long = read_trajectory(long_gt)
for name, e, g, world in (("kitti06_head", est, gt.positions, world_of(gt)),
                          ("euroc_V1_01_gt", long.positions, long.positions, world_of(long))):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        plot_run_trajectory(run + f"/{name}.png", e, g, world, name)
        best = min(best, time.perf_counter() - t0)
    out[name + "_ms"] = best * 1e3
print(json.dumps(out))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=shared_data_dir())
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    seq = args.data / "kitti06_head" / "dataset" / "sequences" / "06"
    gt = args.data / "kitti06_head" / "dataset" / "poses" / "06.txt"
    long_gt = args.data / "euroc_micro" / "groundtruth" / "V1_01_easy.csv"
    if not (seq.is_dir() and long_gt.is_file()):
        print(f"bench_run_png: {seq} or {long_gt} not found (the shared data folder)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="gevi-bench-") as tmp:
        run = Path(tmp) / "run"
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "gevi_cli.cli", "run", str(seq), "-q", "-o", str(run)], check=True,
                       capture_output=True)
        wall = time.perf_counter() - t0
        elapsed = json.loads((run / "status.json").read_text())["elapsed_s"]
        child = subprocess.run([sys.executable, "-c", CHILD, str(run), str(gt), str(long_gt), str(args.repeat)],
                               check=True, capture_output=True, text=True)
        r = json.loads(child.stdout)
    print(f"gevi run kitti06_head (CFO, 51 frames, evaluated): {wall * 1e3:.0f} ms wall, odometry {elapsed * 1e3:.0f} ms")
    print("trajectory.png (4 x 4 in at 80 dpi: 320 x 320 px):")
    print(f"  matplotlib Agg import (cold):       {r['import_ms']:7.1f} ms")
    print(f"  first PNG in the process:           {r['first_ms']:7.1f} ms")
    print(f"  next PNGs, best of {args.repeat}, 51 poses:    {r['kitti06_head_ms']:7.1f} ms")
    print(f"  next PNGs, best of {args.repeat}, 2895 poses:  {r['euroc_V1_01_gt_ms']:7.1f} ms")
    cold = r["import_ms"] + r["first_ms"]
    print(f"  cold total {cold:.0f} ms = {100 * cold / (wall * 1e3):.1f} % of the run's wall time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
