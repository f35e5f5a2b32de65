"""Outlier study of S1 Fig. 4c (spec 11.3): 3-point RANSAC (+BE+GN) with noisy roll/pitch priors
against OpenCV's 5-point RANSAC. Shared by the test and ``scripts/fig4_ransac.py``.
"""

from __future__ import annotations

import time

import numpy as np

from gevi_cli.estimators import pnp4
from gevi_cli.estimators.minimal3pt import ransac_3pt_upright
from gevi_cli.estimators.triangulation import triangulate
from gevi_cli.geometry import wrap_angle
from gevi_cli.studies import simulation as sim
from gevi_cli.studies.montecarlo import perturb_levelling


def yaw_of(R, L_k, L_c):
    """Yaw psi of the closest 4-DOF model: L_c R L_k^T ~ Rz(psi)."""
    M = L_c @ R @ L_k.T
    return float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1]))


def angle_between(a, b):
    c = abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))  # sign-free for 2D-2D methods
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def run_trial(rng, n, ratio, rp_noise_deg=0.2, thr_sigma=3.0, with_opencv=True, seed=0):
    """One trial. Returns a dict of errors (rad), recall, iterations and wall times (s)."""
    s = sim.scene4(rng, n)
    q, out_mask = sim.add_outliers(rng, s.q, ratio)
    sr = np.radians(rp_noise_deg)
    Lk = perturb_levelling(rng, s.L_k, sr)
    Lc = perturb_levelling(rng, s.L_c, sr)
    thr = thr_sigma * s.sigma
    res = {}
    t0 = time.perf_counter()
    psi3, tdir, inl, iters = ransac_3pt_upright(s.z, q, Lk, Lc, thr, seed=seed)
    res["time_3pt"] = time.perf_counter() - t0
    res["yaw_3pt"] = abs(float(wrap_angle(psi3 - s.psi)))
    res["tdir_3pt"] = angle_between(tdir, s.t)
    res["recall"] = float(np.mean(inl[~out_mask]))
    res["precision"] = float(np.mean(~out_mask[inl])) if inl.any() else 0.0
    res["iterations"] = iters
    t0 = time.perf_counter()
    p, cov = triangulate(s.z[inl], s.y[inl], s.R_rl, s.t_rl, s.sigma**2)
    be = pnp4.pnp4_be(p, cov, q[inl], Lk, Lc)
    gn = pnp4.pnp4_gn(*be, s.z[inl], s.y[inl], q[inl], Lk, Lc, s.R_rl, s.t_rl)
    res["time_begn"] = time.perf_counter() - t0
    res["yaw_ours"] = abs(float(wrap_angle(gn[0] - s.psi)))
    res["tdir_ours"] = angle_between(gn[1], s.t)
    res["t_ours"] = float(np.linalg.norm(gn[1] - s.t))
    if with_opencv:
        import cv2

        t0 = time.perf_counter()
        E, mask = cv2.findEssentialMat(s.z, q, np.eye(3), method=cv2.RANSAC, prob=0.99, threshold=thr)
        if E is None or E.shape != (3, 3):
            E = E[:3] if E is not None else None
        if E is None:
            res.update(yaw_5pt=np.nan, tdir_5pt=np.nan, time_5pt=time.perf_counter() - t0)
        else:
            _, R5, t5, _ = cv2.recoverPose(E, s.z, q, np.eye(3), mask=mask)
            res["time_5pt"] = time.perf_counter() - t0
            res["yaw_5pt"] = abs(float(wrap_angle(yaw_of(R5, s.L_k, s.L_c) - s.psi)))
            res["tdir_5pt"] = angle_between(t5.ravel(), s.t)
    return res


def run_study(n, ratio, trials, seed=0, **kw):
    rng = np.random.default_rng(seed)
    rows = [run_trial(rng, n, ratio, seed=seed * 100003 + k, **kw) for k in range(trials)]
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}
