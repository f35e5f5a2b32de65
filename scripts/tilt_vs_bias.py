#!/usr/bin/env python3
"""How much of a GeVI run's roll/pitch error is its accelerometer-bias error.

    python scripts/tilt_vs_bias.py RUN_FOLDER SEQUENCE [--window 12]

SEQUENCE is an EuRoC-layout folder whose ground truth carries the biases (``gevi simulate`` writes
them, as EuRoC's ``state_groundtruth_estimate0`` does); RUN_FOLDER a ``gevi run --method gevi``
folder (its ``traj_body.tum`` and ``imu_states.csv``).  A horizontal bias error moves every gravity
direction by ``(b_true - b_est) / g`` rad in the body frame (docs/method.md 9b), so per window of
``--window`` seconds this prints the RMS of the tilt error vector (estimated minus true up direction,
body frame), of that bias prediction, and of their difference (what the bias does not explain), with
the mean true and estimated biases.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from gevi_cli.inertial.standstill import GRAVITY
from gevi_cli.trajectory import read_trajectory

E3 = np.array([0.0, 0.0, 1.0])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--window", type=float, default=12.0, help="seconds per row")
    a = ap.parse_args()
    gt_file = a.sequence / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    for f in (gt_file, a.run / "imu_states.csv", a.run / "traj_body.tum"):
        if not f.is_file():
            print(f"tilt_vs_bias: error: {f}: not found", file=sys.stderr)
            return 2
    gt = pd.read_csv(gt_file).to_numpy(float)
    if gt.shape[1] < 17:
        print(f"tilt_vs_bias: error: {gt_file}: the ground truth has no bias columns", file=sys.stderr)
        return 2
    st = pd.read_csv(a.run / "imu_states.csv")
    est = read_trajectory(a.run / "traj_body.tum", frame="body")
    t_gt = gt[:, 0].astype(np.int64)
    t = st.t_ns.to_numpy(np.int64)
    i = np.clip(np.searchsorted(t_gt, t), 0, len(t_gt) - 1)  # stamps are exact to the ns in all three
    j = np.clip(np.searchsorted(est.t_ns, t), 0, len(est.t_ns) - 1)
    R_gt = Rotation.from_quat(gt[i][:, [5, 6, 7, 4]]).as_matrix()
    R_est = est.rotations[j]
    up_gt = np.einsum("nji,j->ni", R_gt, E3)
    err = np.einsum("nji,j->ni", R_est, E3) - up_gt
    b_true, b_est = gt[i, 14:17], st[["bax", "bay", "baz"]].to_numpy(float)
    pred = (b_true - b_est) / GRAVITY
    pred -= np.sum(pred * up_gt, axis=1)[:, None] * up_gt  # only the part across gravity tilts
    tau = (t - t[0]) * 1e-9
    moving = (st.phase != "init").to_numpy()

    def rms_deg(v):
        return float(np.degrees(np.sqrt(np.mean(np.sum(v * v, axis=1)))))

    print(f"{'window s':>10} {'tilt err':>9} {'b/g pred':>9} {'rest':>7}   true b_a (m/s^2)           estimated b_a")
    for lo in np.arange(0.0, tau[-1], a.window):
        m = moving & (tau >= lo) & (tau < lo + a.window)
        if m.sum() < 2:
            continue
        print(f"{lo:4.0f}-{lo + a.window:<4.0f} {rms_deg(err[m]):8.3f}° {rms_deg(pred[m]):8.3f}° {rms_deg(err[m] - pred[m]):6.3f}°"
              f"   {np.array2string(b_true[m].mean(0), precision=4)}  {np.array2string(b_est[m].mean(0), precision=4)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
