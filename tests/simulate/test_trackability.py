"""Textures carry enough corner structure for Shi-Tomasi + LK (pool-easy), far less in pool-hard."""
from __future__ import annotations

import cv2
import numpy as np

from gevi_cli.simulate.generate import SimulationConfig, build_sequence


def _track_stats(preset: str):
    seq = build_sequence(SimulationConfig(preset, seed=2, duration_s=8.0, rate_hz=10.0, resolution=(320, 180)))
    counts, ratios = [], []
    for k in (40, 60, 75):  # moving part of the sequence
        a, _ = seq.render_frame(k)
        b, _ = seq.render_frame(k + 1)
        pts = cv2.goodFeaturesToTrack(a, 300, 0.01, 7)
        n = 0 if pts is None else len(pts)
        counts.append(n)
        if n:
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(a, b, pts, None, winSize=(21, 21), maxLevel=3)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, nxt, None, winSize=(21, 21), maxLevel=3)
            ok = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm(back - pts, axis=2).ravel() < 0.5)
            ratios.append(ok.mean())
    return np.mean(counts), np.mean(ratios) if ratios else 0.0


def test_pool_easy_is_trackable_and_pool_hard_is_sparse():
    n_easy, ok_easy = _track_stats("pool-easy")
    n_hard, _ = _track_stats("pool-hard")
    print(f"pool-easy: {n_easy:.0f} corners, {ok_easy:.2f} tracked; pool-hard: {n_hard:.0f} corners")
    assert n_easy > 150 and ok_easy > 0.8
    assert n_hard < 0.5 * n_easy
