#!/usr/bin/env python3
"""Stereo pairs/s of the EuRoC reader vs a bare ``cv2.imread`` loop over the same files; and with
``--export``, the parse of an OV2SLAM track export vs reading and splitting its files.

    python scripts/bench_io.py [--path ../shared/data/euroc_micro] [--repeat 3]
    python scripts/bench_io.py --export [--repeat 3]     # cfo_kitti04's gray export (271 frames)

Targets: the EuRoC reader costs <= 1.2x the bare loop (foundation issue); the track export parses in
under 1 s (it was a test's wall-clock assert; the floor beside it says what the machine could do).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2

from gevi_cli.datasets import open_sequence
from gevi_cli.shared_data import shared_data_dir


def bench_export(repeat: int) -> None:
    """Best-of-``repeat`` s of ``TrackExport`` (parse + every frame) on cfo_kitti04's gray export, next to
    its floor: reading the same files and splitting them into tokens, interleaved with it."""
    from gevi_cli.datasets.track_export import TrackExport

    root = shared_data_dir() / "cfo_kitti04"
    folder = root / "data" / "ov2slam_data" / "ov2slam_data_kitti_04_gray"
    calib = root / "calib" / "gray_calib.txt"
    files = sorted(p for p in folder.iterdir() if p.is_file()) + [calib]
    best_floor, best_read, n = float("inf"), float("inf"), 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        tokens = sum(len(p.read_bytes().split()) for p in files)
        best_floor = min(best_floor, time.perf_counter() - t0)
        t0 = time.perf_counter()
        export = TrackExport(folder, calib)
        n = len(list(export.frames()))
        best_read = min(best_read, time.perf_counter() - t0)
    mb = sum(p.stat().st_size for p in files) / 1e6
    print(f"track export: {folder} ({n} frames, {mb:.1f} MB, {tokens} tokens)")
    print(f"floor (read + split the files): {best_floor * 1e3:8.1f} ms")
    print(f"TrackExport + frames():         {best_read * 1e3:8.1f} ms  ({best_read / best_floor:.1f} x floor; "
          f"target < 1 s: {'met' if best_read < 1.0 else 'NOT met'})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--path", default=str(shared_data_dir() / "euroc_micro"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--export", action="store_true", help="time the cfo_kitti04 track export instead")
    args = parser.parse_args()
    if args.export:
        return bench_export(args.repeat)

    t0 = time.perf_counter()
    seq = open_sequence(args.path)
    t_open = time.perf_counter() - t0
    left = [str(Path(p)) for p in seq._left]
    right = [str(Path(p)) for p in seq._right]

    best_bare, best_reader = float("inf"), float("inf")
    for _ in range(args.repeat):  # interleaved, best of N: the page cache is warm for both
        t0 = time.perf_counter()
        for line, r in zip(left, right):
            cv2.imread(line, cv2.IMREAD_GRAYSCALE)
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
