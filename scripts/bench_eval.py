#!/usr/bin/env python3
"""Time `gevi eval` of the 20 rpg_trajectory_evaluation runs (vislam_rp, MH_04 + V1_02, 10 trials each).

Usage:  python scripts/bench_eval.py [--data ../shared/data] [--repeat 3] [--no-plots]

Runs the CLI in a subprocess (a cold start, as a user would) with plots by default, into a temporary
eval folder, and prints the wall time of each repetition and the best one.  Target: < 20 s on 2 cores.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RPG = "trajectories/rpg_trajectory_evaluation/results/euroc_vislam_mono/laptop"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO / ".." / "shared" / "data")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-plots", action="store_true")
    args = ap.parse_args()
    root = (args.data / RPG).resolve()
    if not root.is_dir():
        print(f"bench_eval: {root} not found (the shared data folder next to the repo)", file=sys.stderr)
        return 2
    times = []
    for k in range(args.repeat):
        with tempfile.TemporaryDirectory(prefix="gevi-bench-") as tmp:
            cmd = [sys.executable, "-m", "gevi_cli.cli", "eval", "--results", str(root), "--method", "vislam_rp",
                   "--align", "auto", "--min-coverage", "0.5", "-q", "-o", str(Path(tmp) / "eval")]
            if args.no_plots:
                cmd.append("--no-plots")
            t0 = time.perf_counter()
            p = subprocess.run(cmd, capture_output=True, text=True, env={"HOME": tmp, "MPLCONFIGDIR": tmp,
                                                                          "PATH": "/usr/bin:/bin"})
            dt = time.perf_counter() - t0
            if p.returncode != 0:
                print(p.stdout, p.stderr, file=sys.stderr)
                return p.returncode
            n_png = len(list((Path(tmp) / "eval" / "plots").glob("*.png")))
        times.append(dt)
        print(f"run {k + 1}: {dt:.2f} s (20 estimates, {n_png} PNG + {n_png} PDF figures)")
    print(f"best {min(times):.2f} s, median {sorted(times)[len(times) // 2]:.2f} s "
          f"({'plots' if not args.no_plots else 'no plots'}; target < 20 s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
