#!/usr/bin/env python3
"""Stereo pairs/s of the EuRoC reader vs a bare ``cv2.imread`` loop over the same files.

    python scripts/bench_io.py [--path ../shared/data/euroc_micro] [--repeat 3]

Target (foundation issue): the reader costs <= 1.2x the bare loop.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2

from gevi_cli.datasets import open_sequence


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--path", default=str(Path(__file__).resolve().parents[1].parent / "shared/data/euroc_micro"))
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    t0 = time.perf_counter()
    seq = open_sequence(args.path)
    t_open = time.perf_counter() - t0
    left = [str(Path(p)) for p in seq._left]
    right = [str(Path(p)) for p in seq._right]

    best_bare, best_reader = float("inf"), float("inf")
    for _ in range(args.repeat):  # interleaved, best of N: the page cache is warm for both
        t0 = time.perf_counter()
        for l, r in zip(left, right):
            cv2.imread(l, cv2.IMREAD_GRAYSCALE)
            cv2.imread(r, cv2.IMREAD_GRAYSCALE)
        best_bare = min(best_bare, time.perf_counter() - t0)
        t0 = time.perf_counter()
        for _frame in seq.frames():
            pass
        best_reader = min(best_reader, time.perf_counter() - t0)
    n = len(seq)
    print(f"sequence: {args.path} ({n} stereo pairs), open (metadata, IMU csv): {t_open * 1e3:.1f} ms")
    print(f"{'loop':<22}{'pairs/s':>10}{'ms/pair':>10}")
    print(f"{'bare cv2.imread':<22}{n / best_bare:>10.1f}{best_bare / n * 1e3:>10.2f}")
    print(f"{'gevi reader':<22}{n / best_reader:>10.1f}{best_reader / n * 1e3:>10.2f}")
    ratio = best_reader / best_bare
    print(f"reader / bare = {ratio:.3f}  (target <= 1.2: {'met' if ratio <= 1.2 else 'NOT met'})")


if __name__ == "__main__":
    main()
