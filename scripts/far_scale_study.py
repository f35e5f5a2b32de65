"""Why CFO's steps are too long where the texture is far (docs/studies/far_scenes.md).

    python scripts/far_scale_study.py SEQ_DIR [--stride K] [--plot OUT.png]

Runs CurrentFeature Odometry (disparity-offset self-calibration off) on a KITTI sequence folder with
ground truth and keeps, per keyframe, its
triangulated points and, per frame, the matches the pose step used.  Prints (1) each keyframe point's
stereo depth against its depth triangulated over the later frames' tracks from the ground-truth poses
(rays least squares, parallax > 0.5 deg), per disparity bin; (2) the median ratio of the keyframe ->
frame translation to the ground truth's for the pose step as run, for the unweighted Bias-Eli step
(`be`), and for the rule the study measured and the pipeline no longer has: the Bias-Eli step with the
stereo covariances, then the weighted steps with the far points (beyond 40 baselines) by bearing only,
per disparity band of the points used.  Frames: keyframe-left camera, metres; ground truth: the
sequence's cam0 poses.
"""
from __future__ import annotations

import argparse

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.geometry import invert_pose
from gevi_cli.pipelines.pose6 import _weighted_steps, tracked_pose6
from gevi_cli.run.assemble import make_pipeline
from gevi_cli.run.session import RunRequest, resolve

BINS = [0, 5, 10, 20, 40, 80, 1000]


def capture(seq: str, stride: int, sets=()):
    r = resolve(RunRequest(sequence=seq, method="cfo", stride=stride, quiet=True, sets=tuple(sets)))
    fe, od = make_pipeline(r, warn=lambda m: None)
    kfs, steps, obs = {}, [], {}
    insert, estimate = od._insert_keyframe, od.estimate_T_ck

    def on_insert(frame, res, timings):
        insert(frame, res, timings)
        if res.keyframe:
            kfs[od.kf.index] = (od.kf.ids.copy(), od.kf.z.copy(), od.kf.p.copy())

    def on_estimate(m, frame):
        T = estimate(m, frame)
        steps.append(dict(index=od.index, kf=od.kf.index, ids=m.ids, z=m.z, y=m.y, q=m.q, p=m.p,
                          cov=m.cov_unit * od.sigma2, sigma2=od.sigma2, T_ck=T))
        return T

    od._insert_keyframe, od.estimate_T_ck = on_insert, on_estimate
    for i, frame in enumerate(r.source.frames(start=r.start, stop=r.stop)):
        od.track(frame)
        obs[i] = (od.obs.ids.copy(), fe.camera.normalize(od.obs.uv))
    gt = r.source.groundtruth
    stamps = np.asarray(r.source.stamps_ns[r.start:r.stop]) * 1e-9
    T_gt = [gt.matrices[np.argmin(np.abs(gt.t_s - t))] for t in stamps]
    return kfs, steps, obs, T_gt, fe.camera, r.cfg


def multiview_depth(k, ids, z, obs, T_gt):
    """Depth (m) in keyframe ``k`` of each point, from its keyframe ray and its later tracks with the
    ground-truth poses (NaN: fewer than 2 later views or under 0.5 deg of parallax)."""
    ray0 = np.column_stack([z, np.ones(len(z))])
    ray0 /= np.linalg.norm(ray0, axis=1)[:, None]
    A = np.eye(3) - ray0[:, :, None] * ray0[:, None, :]
    b = np.zeros((len(ids), 3))
    views, parallax = np.zeros(len(ids), int), np.zeros(len(ids))
    for j in range(k + 1, len(T_gt)):
        oid, q = obs[j]
        _, ia, ib = np.intersect1d(ids, oid, return_indices=True)
        if not len(ia):
            continue
        T_kj = invert_pose(T_gt[k]) @ T_gt[j]
        r = np.column_stack([q[ib], np.ones(len(ib))]) @ T_kj[:3, :3].T
        r /= np.linalg.norm(r, axis=1)[:, None]
        P = np.eye(3) - r[:, :, None] * r[:, None, :]
        A[ia] += P
        b[ia] += P @ T_kj[:3, 3]
        views[ia] += 1
        parallax[ia] = np.maximum(parallax[ia], np.degrees(np.arccos(np.clip((r * ray0[ia]).sum(1), -1, 1))))
    out = np.full(len(ids), np.nan)
    ok = (views >= 2) & (parallax > 0.5)
    out[ok] = np.linalg.solve(A[ok], b[ok][:, :, None])[:, 2, 0]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence")
    ap.add_argument("--stride", type=int, default=1)
    ap.add_argument("--plot", help="write the depth-ratio plot here (PNG)")
    a = ap.parse_args()
    # the data as the pair gives it: without the disparity-offset self-calibration the study led to
    kfs, steps, obs, T_gt, cam, cfg = capture(a.sequence, a.stride, ["triangulation.self_calibrate=false"])
    fb = cam.fx * cam.baseline
    pairs = []
    for k, (ids, z, p) in sorted(kfs.items()):
        zmv = multiview_depth(k, ids, z, obs, T_gt)
        ok = np.isfinite(zmv) & (zmv > 0)
        pairs.append(np.column_stack([fb / p[ok, 2], p[ok, 2] / zmv[ok]]))
    pairs = np.vstack(pairs)
    print("| disparity [px] | points | median stereo Z / multi-view Z |\n|---|---|---|")
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        m = (pairs[:, 0] >= lo) & (pairs[:, 0] < hi)
        if m.sum():
            print(f"| {lo}-{hi} | {m.sum()} | {np.median(pairs[m, 1]):.3f} |")
    print("\n| points used | steps | as run (be-w, every point by depth) | be | be-w, far points by bearing |")
    print("|---|---|---|---|---|")
    for lo, hi in [(0, 10), (10, 20), (20, 1000), (0, 1000)]:
        rows = []
        for s in steps:
            T_ck_gt = invert_pose(T_gt[s["index"]]) @ T_gt[s["kf"]]
            tg = np.linalg.norm(T_ck_gt[:3, 3])
            d = fb / s["p"][:, 2]
            m = (d >= lo) & (d < hi)
            if m.sum() < 12 or tg < 0.3:
                continue
            p, cov, q, y, z = s["p"][m], s["cov"][m], s["q"][m], s["y"][m], s["z"][m]
            try:
                _, t_w, _ = tracked_pose6(p, cov, q, cfg.pnp, s["sigma2"], cam.f)
                R_b, t_b = est.pnp6_be(p, cov, q)
                far = (z[:, 0] - y[:, 0]) < 1 / 40.0
                _, t_f = _weighted_steps(R_b, t_b, p, est.bearing_only(p, cov, far), q, cfg.pnp, s["sigma2"])
            except Exception:  # a band too small or degenerate for a pose: left out
                continue
            rows.append([np.linalg.norm(t_w) / tg, np.linalg.norm(t_b) / tg, np.linalg.norm(t_f) / tg])
        if rows:
            med = np.median(np.array(rows), axis=0)
            band = "all" if hi == 1000 and lo == 0 else f"{lo}-{hi} px" if hi < 1000 else f">= {lo} px"
            print(f"| {band} | {len(rows)} | {med[0]:.4f} | {med[1]:.4f} | {med[2]:.4f} |")
    if a.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.semilogx(pairs[:, 0], pairs[:, 1], ".", ms=2, alpha=0.3, label="keyframe points")
        centers, meds = [], []
        for lo, hi in zip(BINS[:-1], BINS[1:]):
            m = (pairs[:, 0] >= max(lo, 1)) & (pairs[:, 0] < hi)
            if m.sum() > 10:
                centers.append(np.sqrt(max(lo, 1) * hi))
                meds.append(np.median(pairs[m, 1]))
        ax.plot(centers, meds, "o-", color="k", label="median per bin")
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.axvline(cam.fx / 40.0, color="r", lw=0.8, ls="--", label="40 baselines")
        ax.set_ylim(0.5, 2.0)
        ax.set_xlabel("stereo disparity [px]")
        ax.set_ylabel("stereo Z / multi-view Z")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
