"""Reproduce GeVI-SLAM Fig. 4c (spec 11.3 outlier study): 3-point RANSAC with known roll/pitch
(+ BE + GN on the inliers) against OpenCV's 5-point findEssentialMat + recoverPose.

10-30 % outliers (q replaced by uniform image points), 400 trials, n = 200, roll/pitch prior
noise 0.2 deg, Sampson threshold 3 sigma, RANSAC confidence 0.99 for both.

    python scripts/fig4_ransac.py [--trials 400] [--quick] [--out DIR]
"""

from __future__ import annotations

import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from gevi_cli.studies.outlier_study import run_study  # noqa: E402

RATIOS = [0.1, 0.2, 0.3]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="60 trials")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results", "fig4_ransac"))
    a = ap.parse_args()
    trials = 60 if a.quick else a.trials
    os.makedirs(a.out, exist_ok=True)
    frames = []
    for ratio in RATIOS:
        r = run_study(a.n, ratio, trials, seed=a.seed + int(100 * ratio))
        df = pd.DataFrame(r)
        df["outlier_ratio"] = ratio
        frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    df.to_csv(os.path.join(a.out, "fig4_ransac.csv"), index=False)
    deg = np.degrees
    summ = []
    for ratio, d in df.groupby("outlier_ratio"):
        summ.append(dict(
            outlier_ratio=ratio,
            yaw_3pt_med_deg=deg(d.yaw_3pt.median()), yaw_ours_med_deg=deg(d.yaw_ours.median()),
            yaw_5pt_med_deg=deg(d.yaw_5pt.median()),
            tdir_3pt_med_deg=deg(d.tdir_3pt.median()), tdir_ours_med_deg=deg(d.tdir_ours.median()),
            tdir_5pt_med_deg=deg(d.tdir_5pt.median()),
            recall_mean=d.recall.mean(), precision_mean=d.precision.mean(), iters_mean=d.iterations.mean(),
            time_3pt_ms=1e3 * d.time_3pt.mean(), time_3pt_begn_ms=1e3 * (d.time_3pt + d.time_begn).mean(),
            time_5pt_ms=1e3 * d.time_5pt.mean(), time_ratio_3pt_over_5pt=d.time_3pt.sum() / d.time_5pt.sum()))
    s = pd.DataFrame(summ)
    s.to_csv(os.path.join(a.out, "fig4_ransac_summary.csv"), index=False)
    pd.set_option("display.width", 250)
    print(f"n = {a.n}, {trials} trials per ratio, roll/pitch noise 0.2 deg (wall times: this machine, one run)")
    print(s.round(4).T.to_string())

    fig, ax = plt.subplots(1, 3, figsize=(13, 4))
    pos = np.arange(len(RATIOS))
    for j, (col3, col5, lab) in enumerate((("yaw_ours", "yaw_5pt", "yaw error [deg]"),
                                            ("tdir_ours", "tdir_5pt", "t-direction error [deg]"))):
        d3 = [deg(df[df.outlier_ratio == r][col3].values) for r in RATIOS]
        d5 = [deg(df[df.outlier_ratio == r][col5].dropna().values) for r in RATIOS]
        b1 = ax[j].boxplot(d3, positions=pos - 0.18, widths=0.3, showfliers=False, patch_artist=True)
        b2 = ax[j].boxplot(d5, positions=pos + 0.18, widths=0.3, showfliers=False, patch_artist=True)
        for b, c in ((b1, "tab:blue"), (b2, "tab:orange")):
            for box in b["boxes"]:
                box.set_facecolor(c)
        ax[j].set_xticks(pos, [f"{int(100 * r)} %" for r in RATIOS])
        ax[j].set_ylabel(lab)
        ax[j].legend([b1["boxes"][0], b2["boxes"][0]], ["3-pt RANSAC + BE + GN", "OpenCV 5-pt"], fontsize=7)
    ax[2].bar(pos - 0.18, s.time_3pt_ms, 0.3, label="3-pt RANSAC")
    ax[2].bar(pos + 0.18, s.time_5pt_ms, 0.3, label="OpenCV 5-pt RANSAC")
    ax[2].set_xticks(pos, [f"{int(100 * r)} %" for r in RATIOS])
    ax[2].set_ylabel("mean wall time [ms]")
    ax[2].legend(fontsize=7)
    for x in ax:
        x.set_xlabel("outlier ratio")
        x.grid(alpha=0.3)
    fig.suptitle(f"GeVI Fig. 4c reproduction (n = {a.n}, {trials} trials, roll/pitch noise 0.2°)")
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "fig4_ransac.png"), dpi=80)
    print("wrote", a.out)


if __name__ == "__main__":
    main()
