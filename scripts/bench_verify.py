"""Verification speed: GeVI's upright 3-point RANSAC against OpenCV's 5-point RANSAC on the same matches.

    python scripts/bench_verify.py SEQUENCE [--frames 300] [--repeat 5] [--in-pipeline]

Runs `gevi run --method gevi` in-process on the first frames of SEQUENCE (a stereo-IMU sequence),
records the inputs of every 3-point verification (keyframe-left / current-left normalized matches,
levelling rotations, threshold), then times both RANSACs on exactly those inputs, interleaved, with
the pipeline's confidence and threshold (5-point: the same Sampson threshold, OpenCV's
``findEssentialMat``).  Prints the median time per frame, the iterations and the inlier agreement.  ``--outliers 0.3``
replaces 30 % of the current points by random ones (S1's outlier study) on the same inputs.
``--in-pipeline`` times the call where the run makes it instead (the images have just gone through
the caches: the 3-point's many small numpy calls pay more for that than OpenCV's one call), and the
run's whole verification stage (``verify_ms`` of ``timing.csv``: matching, RANSAC, parallax, l1 drop).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402


def record(seq: Path, frames: int):
    from gevi_cli import estimators as est
    from gevi_cli.run.session import RunRequest, execute

    calls = []
    real = est.ransac_3pt_upright

    def spy(z, q, L_k, L_c, threshold, seed=0, confidence=0.99, **kw):
        # the run's generator state before the call: replays draw exactly the run's samples
        state = seed.bit_generator.state if isinstance(seed, np.random.Generator) else seed
        calls.append((z.copy(), q.copy(), L_k.copy(), L_c.copy(), float(threshold), state, float(confidence)))
        return real(z, q, L_k, L_c, threshold, seed=seed, confidence=confidence, **kw)

    est.ransac_3pt_upright = spy
    try:
        with tempfile.TemporaryDirectory() as d:
            execute(RunRequest(sequence=str(seq), method="gevi", max_frames=frames, out=d, quiet=True),
                    echo=lambda *a, **k: None)
    finally:
        est.ransac_3pt_upright = real
    return calls


def in_pipeline(seq: Path, frames: int, repeat: int) -> None:
    """Time the RANSAC call inside the run, as the pipeline meets it (after the front end's image work), for
    ``gevi run --method gevi`` and ``--ransac 5pt``, runs interleaved; prints the mean ms per call."""
    import pandas as pd

    from gevi_cli import estimators as est
    from gevi_cli.run.session import RunRequest, execute

    real3, real5 = est.ransac_3pt_upright, cv2.findEssentialMat

    def timed(f, acc):
        def call(*args, **kw):
            t0 = time.perf_counter()
            out = f(*args, **kw)
            acc.append(time.perf_counter() - t0)
            return out
        return call

    res = {"3pt": [], "5pt": []}
    stage = {"3pt": [], "5pt": []}  # the run's whole verify stage (timing.csv: matching, RANSAC, l1 drop)
    for _ in range(repeat):
        for ransac in res:
            acc = []
            if ransac == "3pt":
                est.ransac_3pt_upright = timed(real3, acc)
            else:
                cv2.findEssentialMat = timed(real5, acc)
            try:
                with tempfile.TemporaryDirectory() as d:
                    execute(RunRequest(sequence=str(seq), method="gevi", ransac=ransac, max_frames=frames, out=d,
                                       quiet=True), echo=lambda *a, **k: None)
                    stage[ransac].append(pd.read_csv(Path(d) / "timing.csv")["verify_ms"].mean())
            finally:
                est.ransac_3pt_upright, cv2.findEssentialMat = real3, real5
            res[ransac].append(1e3 * np.mean(acc))
    print(f"inside the pipeline ({frames} frames of {seq.name}, {repeat} runs each, interleaved; mean ms per call "
          f"of each run; load {os.getloadavg()[0]:.2f}):")
    print("| RANSAC | call, runs | call, median | verify stage per frame, runs | stage, median |")
    print("|---|---|---|---|---|")
    for ransac, label in (("3pt", "3-point upright (gevi)"), ("5pt", "5-point OpenCV (--ransac 5pt)")):
        print(f"| {label} | {' '.join(f'{x:.3f}' for x in res[ransac])} | {np.median(res[ransac]):.3f} | "
              f"{' '.join(f'{x:.3f}' for x in stage[ransac])} | {np.median(stage[ransac]):.3f} |")


def _generator(state):
    if not isinstance(state, dict):
        return np.random.default_rng(state)
    g = np.random.Generator(getattr(np.random, state["bit_generator"])())
    g.bit_generator.state = state
    return g


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--outliers", type=float, default=0.0,
                    help="also replace this fraction of the current points by uniform random image points (S1's study)")
    ap.add_argument("--in-pipeline", action="store_true",
                    help="instead: time the RANSAC call inside `gevi run` (3-point, then --ransac 5pt), --repeat runs each")
    a = ap.parse_args()
    if a.in_pipeline:
        cv2.setNumThreads(1)
        in_pipeline(a.sequence, a.frames, a.repeat)
        return
    from gevi_cli import estimators as est

    cv2.setNumThreads(1)
    calls = record(a.sequence, a.frames)
    t3, t5, it3, agree = [], [], [], []
    rng = np.random.default_rng(0)
    for z, q, L_k, L_c, thr, state, conf in calls:
        if a.outliers > 0:
            q = q.copy()
            k = rng.random(len(q)) < a.outliers
            lo, hi = q.min(0), q.max(0)
            q[k] = rng.uniform(lo, hi, (int(k.sum()), 2))
        r3, r5 = [], []
        for _ in range(a.repeat):
            rng = _generator(state)
            t0 = time.perf_counter()
            _, _, in3, it = est.ransac_3pt_upright(z, q, L_k, L_c, thr, seed=rng, confidence=conf)
            r3.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            _, mask = cv2.findEssentialMat(z.reshape(-1, 1, 2), q.reshape(-1, 1, 2), np.eye(3), method=cv2.RANSAC,
                                           prob=conf, threshold=thr)
            r5.append(time.perf_counter() - t0)
        t3.append(np.median(r3))
        t5.append(np.median(r5))
        it3.append(it)
        if mask is not None:
            agree.append(np.mean(in3 == mask.ravel().astype(bool)))
    n = [len(c[0]) for c in calls]
    print(f"{len(calls)} verifications on {a.sequence.name} (matches per frame: median {int(np.median(n))}; "
          f"added outliers {100 * a.outliers:.0f} %)")
    print("| RANSAC | median ms / frame | mean ms / frame |")
    print("|---|---|---|")
    print(f"| 3-point upright (gevi) | {1e3 * np.median(t3):.3f} | {1e3 * np.mean(t3):.3f} |")
    print(f"| 5-point OpenCV | {1e3 * np.median(t5):.3f} | {1e3 * np.mean(t5):.3f} |")
    print(f"3-point minimal samples drawn: median {int(np.median(it3))}; inlier-mask agreement with 5-point "
          f"{100 * np.mean(agree):.1f} %")


if __name__ == "__main__":
    main()
