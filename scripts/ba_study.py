#!/usr/bin/env python3
"""The epipolar local BA of CurrentFeature Odometry against a render's truth, window by window.

    python scripts/ba_study.py RENDER [RENDER ...] [--max-window 12] [--ideal-tracks [--noise-seed N]]

For every RENDER (a folder written by `gevi simulate`) it runs `gevi run RENDER --method cfo` in this
process (the render's config, BA on) and records every BA window the pipeline solves (spec 10: the
previous keyframe KF1, the frames between, the new keyframe KF2) with the options the pipeline used.
Then, window by window and from the same inputs, it compares the pose of KF2 in KF1 (``T_K1K2``,
rectified cam0) with the render's truth for:

* ``tracking``: the pose the 6-DOF tracking step gave (the BA's start);
* ``BA``: the BA as the pipeline ran it (its kernel, delta 3 sigma);
* ``BA huber`` / ``BA truncated``: the other kernel;
* ``BA left only``: without the pairs that involve a right image (scale then rests on the start);
* ``BA + PnP terms`` [a study variant, not in gevi]: the BA's epipolar residuals (inliers of the
  start within 3 sigma) plus, for every frame of the window, the whitened reprojection residuals of
  KF1's stereo points (covariance of spec 4, tied rows, plus the frame's noise, as ``be-w``; those
  whose whitened residual at the start is within 3), solved
  with ``scipy.optimize.least_squares``.

With ``--ideal-tracks`` the same windows are also solved (the pipeline's options, from the same
tracked start) on observations built from the render's truth: every feature's KF1-left ray is cast
to the scene's planes with the true pose and projected with the true poses into every image of the
window in which the front end observed it (same features, same images), then

* ``BA, ideal tracks``: plus Gaussian noise of the window's own sigma in every image;
* ``BA, real tracks, KF2-left ideal``: the real observations, except KF2-left's (ideal + noise);
* ``BA, real tracks, frames ideal``: the real observations, except F_1..F_K's (ideal + noise).

These separate the estimator (is it biased under Gaussian noise in this geometry?) from the front
end's errors, and say which images' errors the BA turns into its drift.

Only windows of at most ``--max-window`` frames (KF2 included) are compared, for every variant alike
(the study solver is slow on long windows); the count is printed.

Printed per render and variant: RMS of the rotation error (deg) and of the translation error (mm) of
KF2, and the *sum* of the rotation-error vectors over the windows (deg, KF1 camera axes): a sum much
larger than RMS x sqrt(windows) is a bias, and a bias is what accumulates into drift (ATE).  Why:
docs/method.md 10.  A reproduction, not a test; a 20 s euroc-like render takes about a minute.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np


def record(render: Path) -> list[dict]:
    """Run CFO (with BA) on ``render``; every BA window with its options and the true ``T_K1K2``."""
    from gevi_cli import estimators as est
    from gevi_cli.cli import main as gevi_main
    from gevi_cli.datasets import open_sequence
    from gevi_cli.pipelines import odometry as od

    recs: list[dict] = []
    ctx: dict = {}
    orig_ba, orig_local = est.epipolar_local_ba, od.KeyframeOdometry._local_ba

    def spy_local(self, new):
        ctx.update(t1=self.kf.t_ns, t2=new.t_ns, T_B_C0=np.asarray(self.camera.T_B_C0),
                   t_frames=[f.t_ns for f in self.window], R0=self.frontend.rectifier.R0.copy())
        return orig_local(self, new)

    def spy_ba(window, options=None):
        recs.append(dict(ctx, window=window, options=options))
        return orig_ba(window, options)

    est.epipolar_local_ba, od.KeyframeOdometry._local_ba = spy_ba, spy_local
    try:
        with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(sys.stderr):
            try:
                gevi_main(["run", str(render), "--method", "cfo", "-q", "-o", tmp])
            except SystemExit as ex:
                if ex.code not in (0, 3, None):
                    raise
    finally:
        est.epipolar_local_ba, od.KeyframeOdometry._local_ba = orig_ba, orig_local
    gt = open_sequence(render).groundtruth
    row = {int(t): i for i, t in enumerate(gt.t_ns)}
    out = []
    for r in recs:
        if r["t1"] in row and r["t2"] in row:
            T1, T2 = gt.matrices[row[r["t1"]]] @ r["T_B_C0"], gt.matrices[row[r["t2"]]] @ r["T_B_C0"]
            r["T_12"] = np.linalg.inv(T1) @ T2
            out.append(r)
    return out


def ba_with_pnp_terms(w) -> tuple[np.ndarray, np.ndarray]:
    """KF2's (R, t) in KF1 from the epipolar residuals plus KF1-point reprojection residuals."""
    from scipy.optimize import least_squares

    from gevi_cli import estimators as est
    from gevi_cli.estimators.epipolar_ba import BAProblem, euler_zyx
    from gevi_cli.geometry import project_jacobian

    sig = float(w.sigma)
    prob = BAProblem(w)
    x0 = prob.x0.copy()
    inl = np.abs(prob.residuals(x0)) < 3 * sig
    _, il, ir = np.intersect1d(w.kf1_left.ids, w.kf1_right.ids, return_indices=True)
    z, y, ids = w.kf1_left.xy[il], w.kf1_right.xy[ir], w.kf1_left.ids[il]
    p, cov = est.triangulate(z, y, w.R_rl, w.t_rl, sig**2, tied_rows=z[:, 1] == y[:, 1])
    ok = np.all(np.isfinite(p), axis=1) & (p[:, 2] > 0.5)
    p, cov, ids = p[ok], cov[ok], ids[ok]
    P0 = x0.reshape(-1, 6)
    R0 = euler_zyx(P0[:, :3])
    terms = []  # (frame, points, q, whitening (n, 2, 2), kept)
    for k, o in enumerate(list(w.frames) + [w.kf2_left]):
        _, ia, ib = np.intersect1d(ids, o.ids, return_indices=True)
        X = (p[ia] - P0[k, 3:]) @ R0[k]
        Jh = project_jacobian(X) @ R0[k].T
        L = np.linalg.inv(np.linalg.cholesky(Jh @ cov[ia] @ np.swapaxes(Jh, 1, 2) + sig**2 * np.eye(2)))
        r0 = np.einsum("nij,nj->ni", L, o.xy[ib] - X[:, :2] / X[:, 2:3])
        terms.append((k, p[ia], o.xy[ib], L, np.linalg.norm(r0, axis=1) < 3.0))

    def fun(x):
        P = x.reshape(-1, 6)
        R = euler_zyx(P[:, :3])
        res = [prob.residuals(x)[inl] / sig]
        for k, pk, q, L, keep in terms:
            X = (pk - P[k, 3:]) @ R[k]
            res.append(np.einsum("nij,nj->ni", L, q - X[:, :2] / X[:, 2:3])[keep].ravel())
        return np.concatenate(res)

    x = least_squares(fun, x0, method="lm", max_nfev=50).x.reshape(-1, 6)
    return euler_zyx(x[-1:, :3])[0], x[-1, 3:]


def ideal_windows(render: Path, recs: list[dict], noise_seed: int = 0) -> None:
    """Add ``ideal``, ``ideal_kf2`` and ``ideal_frames`` windows (see the module docstring) to every
    record whose images can all be cast (records lacking a truth stamp are left without)."""
    import yaml
    from track_bias import cast_to_scene

    from gevi_cli import estimators as est
    from gevi_cli.datasets import open_sequence
    from gevi_cli.simulate.generate import SimulationConfig, build_sequence

    meta = yaml.safe_load((render / "simulation.yaml").read_text())
    sim = build_sequence(SimulationConfig.from_description(meta))
    # frame k of the written sequence is frame k of the render (KITTI-format renders restart the clock)
    index = {int(t): i for i, t in enumerate(open_sequence(render).stamps_ns)}
    rng = np.random.default_rng(noise_seed)

    def T_W_raw(k: int) -> np.ndarray:  # raw left camera in W
        return sim.body_state(sim.frame_t_ns[k:k + 1]).T_WB[0] @ sim.rig.T_B_C0

    for r in recs:
        w, R0 = r["window"], r["R0"]
        if r["t1"] not in index or not all(t in index for t in r["t_frames"]):
            continue

        def T_W_rect(k: int) -> np.ndarray:  # rectified left camera in W: X_C0 = R0^T X_C0r
            T = T_W_raw(k).copy()
            T[:3, :3] = T[:3, :3] @ R0.T
            return T

        k1 = index[r["t1"]]
        T1 = T_W_rect(k1)
        T_1k = [np.linalg.inv(T1) @ T_W_rect(index[t]) for t in r["t_frames"]]  # T_K1Fk, last = KF2
        ray = np.column_stack([w.kf1_left.xy, np.ones(len(w.kf1_left.ids))]) @ R0  # raw-camera rays
        P_W = cast_to_scene(sim.scene, T_W_raw(k1), ray / np.linalg.norm(ray, axis=1)[:, None])
        P_1 = (P_W - T1[:3, 3]) @ T1[:3, :3]
        ok = np.all(np.isfinite(P_1), axis=1) & (P_1[:, 2] > 0)
        ids1, P_1 = w.kf1_left.ids[ok], P_1[ok]

        def ideal(o, T, right):
            _, ia, ib = np.intersect1d(ids1, o.ids, assume_unique=True, return_indices=True)
            X = (P_1[ia] - T[:3, 3]) @ T[:3, :3]
            if right:
                X = X @ np.asarray(w.R_rl).T + np.asarray(w.t_rl).reshape(3)
            xy = X[:, :2] / X[:, 2:3] + rng.normal(0.0, w.sigma, (len(ia), 2))
            return est.ImageObs(o.ids[ib], xy)

        def real(o):  # the same features (those with a cast ray) as observed
            keep = np.isin(o.ids, ids1)
            return est.ImageObs(o.ids[keep], o.xy[keep])

        I4 = np.eye(4)
        kf1 = (ideal(w.kf1_left, I4, False), ideal(w.kf1_right, I4, True))
        kf1_real = (real(w.kf1_left), real(w.kf1_right))
        frames = [ideal(f, T_1k[k], False) for k, f in enumerate(w.frames)]
        kf2 = (ideal(w.kf2_left, T_1k[-1], False), ideal(w.kf2_right, T_1k[-1], True))
        kf2_real = (real(w.kf2_left), real(w.kf2_right))
        frames_real = [real(f) for f in w.frames]

        def window(a, f, b):
            return est.BAWindow(a[0], a[1], f, b[0], b[1], w.R_init, w.t_init, w.R_rl, w.t_rl, sigma=w.sigma)

        r["ideal"] = window(kf1, frames, kf2)
        r["ideal_kf2"] = window(kf1_real, frames_real, (kf2[0], kf2_real[1]))
        r["ideal_frames"] = window(kf1_real, frames, kf2_real)


def evaluate(recs: list[dict], max_window: int) -> dict[str, tuple]:
    """Per variant: windows, rotation RMS (deg), summed rotation-error vector (deg), translation RMS (mm)."""
    from scipy.spatial.transform import Rotation

    from gevi_cli import estimators as est

    def ba(opt_change, key="window"):
        def fn(r):
            if key not in r:
                return None
            res = est.epipolar_local_ba(r[key], replace(r["options"], **opt_change))
            return res.R[-1], res.t[-1]
        return fn

    variants = {
        "tracking": lambda r: (r["window"].R_init[-1], r["window"].t_init[-1]),
        "BA": ba({}),
        "BA huber": ba({"kernel": "huber"}),
        "BA truncated": ba({"kernel": "truncated"}),
        "BA left only": ba({"use_right": False}),
        "BA + PnP terms": lambda r: ba_with_pnp_terms(r["window"]),
    }
    if any("ideal" in r for r in recs):
        variants.update({"BA, ideal tracks": ba({}, "ideal"), "BA, real tracks, KF2-left ideal": ba({}, "ideal_kf2"),
                         "BA, real tracks, frames ideal": ba({}, "ideal_frames")})
    recs = [r for r in recs if len(r["window"].frames) < max_window]
    out = {}
    for name, fn in variants.items():
        rv, te = [], []
        for r in recs:
            try:
                with np.errstate(invalid="ignore", divide="ignore"):
                    got = fn(r)
            except est.EstimatorError:
                got = None
            if got is None:
                continue
            R, t = got
            G = r["T_12"]
            rv.append(Rotation.from_matrix(G[:3, :3].T @ R).as_rotvec())
            te.append(np.linalg.norm(t - G[:3, 3]) * 1e3)
        rv, te = np.degrees(np.array(rv)), np.array(te)
        out[name] = (len(te), float(np.sqrt(np.mean(np.sum(rv**2, axis=1)))), rv.sum(axis=0),
                     float(np.sqrt(np.mean(te**2))))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("renders", nargs="+", type=Path, help="folders written by gevi simulate")
    ap.add_argument("--max-window", type=int, default=12,
                    help="compare the windows of at most this many frames (default 12)")
    ap.add_argument("--ideal-tracks", action="store_true",
                    help="also solve every window on observations built from the render's truth (see above)")
    ap.add_argument("--noise-seed", type=int, default=0, help="seed of the Gaussian noise of --ideal-tracks")
    args = ap.parse_args(argv)
    import yaml

    from gevi_cli.simulate.generate import SimulationConfig

    for r in args.renders:
        if not (r / "simulation.yaml").is_file():
            print(f"ba_study.py: error: {r}: not a gevi simulate render (no simulation.yaml)", file=sys.stderr)
            return 2
        try:  # the truth of --ideal-tracks is rebuilt from it: fail now, not after the runs
            SimulationConfig.from_description(yaml.safe_load((r / "simulation.yaml").read_text()))
        except (yaml.YAMLError, ValueError) as err:
            print(f"ba_study.py: error: {r / 'simulation.yaml'}: {str(err).splitlines()[0]}", file=sys.stderr)
            return 2
    print("| render | variant | windows | R RMS deg | summed R error deg (x, y, z) | t RMS mm |")
    print("|---|---|---|---|---|---|")
    for r in args.renders:
        recs = record(r)
        if args.ideal_tracks:
            ideal_windows(r, recs, args.noise_seed)
        for name, (n, rot, s, tr) in evaluate(recs, args.max_window).items():
            print(f"| {r.name} | {name} | {n} | {rot:.4f} | {s[0]:+.3f}, {s[1]:+.3f}, {s[2]:+.3f} | {tr:.3f} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
