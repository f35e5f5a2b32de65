"""Microbenchmark: epipolar local BA (spec 10) and IMU preintegration (spec 9.2).

Prints the median ms per ``epipolar_local_ba`` call (default options: Huber, built-in LM, 10
iterations; 1 px noise, start with 8 % scale error + 0.3 deg + 2 cm) for K = 3, 5, 8 frames and
100 / 200 features, and ms per ``preintegrate`` of 0.1 s at 200 Hz (20 samples), plus the batched
form over 30 such intervals. The window simulator is ``gevi_cli.studies.simulation.ba_window``.

    python scripts/bench_ba.py [--repeat 5] [--scipy]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gevi_cli.estimators.epipolar_ba import BAOptions, epipolar_local_ba
from gevi_cli.estimators.preintegration import preintegrate, preintegrate_batch
from gevi_cli.studies.simulation import ba_window, perturb_ba_window


def _median_ms(fn, repeat):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(ts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scipy", action="store_true", help="also time solver='scipy' (dense trf and sparse lsmr)")
    a = ap.parse_args()
    print("epipolar_local_ba [ms per call, median]")
    print(f"{'K':>3} {'n':>5} {'resid':>7} {'iters':>5} {'lm':>9}" + ("  scipy-dense scipy-sparse" if a.scipy else ""))
    for K in (3, 5, 8):
        for n in (100, 200):
            w, R, t = ba_window(7 + K, K=K, n=n, sigma_px=1.0)
            w = perturb_ba_window(w, K, t_sigma=0.02)
            res = epipolar_local_ba(w)
            line = f"{K:>3} {n:>5} {res.n_residuals:>7} {res.nfev:>5} {_median_ms(lambda: epipolar_local_ba(w), a.repeat):>9.1f}"
            if a.scipy:
                dense = _median_ms(lambda: epipolar_local_ba(w, BAOptions(solver="scipy")), max(1, a.repeat // 2))
                sparse = _median_ms(lambda: epipolar_local_ba(w, BAOptions(solver="scipy", sparse=True)), max(1, a.repeat // 2))
                line += f"  {dense:>11.1f} {sparse:>12.1f}"
            print(line)
    rng = np.random.default_rng(0)
    m = 20
    gyro = rng.normal(size=(m, 3)) * 0.3
    acc = rng.normal(size=(m, 3)) + [0, 0, 9.81]
    dts = np.full(m, 0.005)
    reps = max(200, 40 * a.repeat)
    ms = _median_ms(lambda: preintegrate(gyro, acc, dts), reps)
    print(f"preintegrate 0.1 s @ 200 Hz (20 samples): {ms:.3f} ms per interval")
    segs = [(gyro, acc, dts)] * 30
    msb = _median_ms(lambda: preintegrate_batch(segs), max(20, 4 * a.repeat))
    print(f"preintegrate_batch 30 x 0.1 s: {msb:.3f} ms total ({msb / 30:.3f} ms per interval)")


if __name__ == "__main__":
    main()
