"""The KITTI odometry devkit metric (evo has none), as kitti-odom-eval computes it.

For start frames every ``step`` (10) GT frames and each segment length L in 100, 200, ..., 800 m:
the end frame is the first GT frame whose accumulated GT path length exceeds the start's by more than
L; the segment is used when both frames have an estimate pose.  With ``dG = inv(G_a) G_b`` and
``dP = inv(P_a) P_b`` the error pose is ``E = inv(dP) dG``;

* ``t_err = |t(E)| / L`` (reported in %),
* ``r_err = arccos(clamp((trace(R(E)) - 1) / 2, -1, 1)) / L`` (reported in deg / 100 m).

Both are averaged per length and pooled over all segments (the "Trans. err" / "Rot. err" the
devkit and kitti-odom-eval print).  The block also carries kitti-odom-eval's "RPE": the **mean** over
consecutive frame pairs (i, i+1) of ``|t(E)|`` (m) and of the arccos-of-trace angle (deg) of
``E = inv(inv(G_i) G_i+1) @ inv(P_i) P_i+1``.

Exactness: the relative poses above do not depend on a rigid alignment (it cancels), only on the
scale of a Sim3 alignment, which is applied to the estimate translations.  KITTI files store rotation
matrices with ~6 significant digits, so they are not exactly orthonormal; kitti-odom-eval uses them as
written, and the arccos of the trace of a product of such matrices differs from the angle of the
nearest rotation by ~0.4 % for per-frame angles of ~0.06 deg.  To reproduce its numbers,
:func:`raw_poses` re-reads KITTI files as written (other formats use the trajectory's matrices).  Poses are KITTI cam0 poses or any other sensor frame, in metres;
frames are GT frame numbers (KITTI) or the order of the matched pairs (stamped data).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

KITTI_LENGTHS = (100, 200, 300, 400, 500, 600, 700, 800)


@dataclass(frozen=True)
class KittiResult:
    """Pooled KITTI errors: ``t_err_pct`` in %, ``r_err_deg_per_100m`` in deg/100 m; NaN without segments.

    ``per_length`` maps L (m) to ``(t_err_pct, r_err_deg_per_100m, n_segments)``.
    """

    t_err_pct: float
    r_err_deg_per_100m: float
    n_segments: int
    per_length: dict = field(default_factory=dict)
    rpe_trans_mean_m: float = float("nan")
    rpe_rot_mean_deg: float = float("nan")
    segments: np.ndarray = field(repr=False, compare=False, default=None)  # (k, 4): first, L, t_err, r_err

    def as_dict(self) -> dict:
        return {"t_err_pct": self.t_err_pct, "r_err_deg_per_100m": self.r_err_deg_per_100m,
                "n_segments": self.n_segments, "rpe_trans_mean_m": self.rpe_trans_mean_m,
                "rpe_rot_mean_deg": self.rpe_rot_mean_deg,
                "per_length": {str(k): {"t_err_pct": v[0], "r_err_deg_per_100m": v[1], "n_segments": v[2]}
                               for k, v in self.per_length.items()}}


def path_distances(T: np.ndarray) -> np.ndarray:
    """Accumulated path length (m) at each pose of (n, 4, 4) poses."""
    steps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def raw_poses(traj) -> tuple[np.ndarray, np.ndarray]:
    """(frames, (n, 4, 4) poses) of a trajectory; KITTI files are re-read exactly as written.

    Frames are KITTI frame numbers for indexed trajectories, else 0..n-1.
    """
    from gevi_cli.trajectory.trajectory import KITTI_NOMINAL_PERIOD_NS

    frames = traj.t_ns // KITTI_NOMINAL_PERIOD_NS if traj.indexed else np.arange(len(traj))
    path, fmt = traj.meta.get("path"), traj.meta.get("format")
    if traj.indexed and fmt in ("kitti", "kitti-idx") and path:
        try:
            a = np.loadtxt(path, ndmin=2, comments=("#", "%"))
        except (OSError, ValueError):
            a = None
        if a is not None and a.shape[1] in (12, 13):
            f = a[:, 0].astype(np.int64) if a.shape[1] == 13 else np.arange(len(a), dtype=np.int64)
            if len(f) == len(frames):
                sel = np.searchsorted(f, frames)
                if np.all(sel < len(f)) and np.array_equal(f[sel], frames):
                    T = np.tile(np.eye(4), (len(frames), 1, 1))
                    T[:, :3, :] = a[sel, -12:].reshape(-1, 3, 4)
                    return frames, T
    return frames, traj.matrices


def kitti_errors(gt_frames: np.ndarray, gt_T: np.ndarray, est_frames: np.ndarray, est_T: np.ndarray,
                 lengths=KITTI_LENGTHS, step: int = 10, scale: float = 1.0) -> KittiResult:
    """KITTI devkit errors.

    Args:
        gt_frames: (N,) increasing frame numbers of the GT poses; gt_T: (N, 4, 4) GT poses.
        est_frames: (M,) frame numbers with an estimate; est_T: (M, 4, 4) estimate poses (after
            alignment: only the scale of a Sim3 alignment changes the result).
        lengths: segment lengths in metres; step: start-frame stride in GT frames.
    """
    gt_frames = np.asarray(gt_frames, dtype=np.int64)
    est_frames = np.asarray(est_frames, dtype=np.int64)
    est_T = np.array(est_T, dtype=np.float64)
    est_T[:, :3, 3] *= scale
    dist = path_distances(gt_T)
    est_pos = {int(f): k for k, f in enumerate(est_frames)}
    inv_gt = np.linalg.inv(gt_T)
    inv_est = np.linalg.inv(est_T)
    rows = []
    for a in range(0, len(gt_frames), step):
        ka = est_pos.get(int(gt_frames[a]))
        for L in lengths:
            b = int(np.searchsorted(dist, dist[a] + L, side="right"))
            if b >= len(dist):
                continue
            kb = est_pos.get(int(gt_frames[b]))
            if ka is None or kb is None:
                continue
            dG = inv_gt[a] @ gt_T[b]
            dP = inv_est[ka] @ est_T[kb]
            E = np.linalg.inv(dP) @ dG
            r = np.arccos(max(min(0.5 * (E[0, 0] + E[1, 1] + E[2, 2] - 1.0), 1.0), -1.0))
            t = np.linalg.norm(E[:3, 3])
            rows.append((gt_frames[a], L, t / L, r / L))
    seg = np.array(rows, dtype=np.float64).reshape(-1, 4)
    rpe_t, rpe_r = _consecutive_rpe(gt_frames, gt_T, est_frames, est_T)
    if len(seg) == 0:
        return KittiResult(float("nan"), float("nan"), 0, {}, rpe_t, rpe_r, seg)
    to_pct, to_deg100 = 100.0, 180.0 / np.pi * 100.0
    per = {}
    for L in lengths:
        m = seg[:, 1] == L
        if m.any():
            per[int(L)] = (float(seg[m, 2].mean() * to_pct), float(seg[m, 3].mean() * to_deg100), int(m.sum()))
    return KittiResult(float(seg[:, 2].mean() * to_pct), float(seg[:, 3].mean() * to_deg100), len(seg), per,
                       rpe_t, rpe_r, seg)


def _consecutive_rpe(gt_frames, gt_T, est_frames, est_T) -> tuple[float, float]:
    """kitti-odom-eval's RPE: mean over est frames i with i+1 also estimated (m, deg)."""
    gt_pos = {int(f): k for k, f in enumerate(gt_frames)}
    est_pos = {int(f): k for k, f in enumerate(est_frames)}
    te, re = [], []
    for f in est_frames[:-1].tolist():
        if f + 1 not in est_pos or f not in gt_pos or f + 1 not in gt_pos:
            continue
        g = np.linalg.inv(gt_T[gt_pos[f]]) @ gt_T[gt_pos[f + 1]]
        p = np.linalg.inv(est_T[est_pos[f]]) @ est_T[est_pos[f + 1]]
        E = np.linalg.inv(g) @ p
        te.append(np.linalg.norm(E[:3, 3]))
        re.append(np.arccos(max(min(0.5 * (E[0, 0] + E[1, 1] + E[2, 2] - 1.0), 1.0), -1.0)))
    if not te:
        return float("nan"), float("nan")
    return float(np.mean(te)), float(np.degrees(np.mean(re)))
