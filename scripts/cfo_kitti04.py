#!/usr/bin/env python3
"""CurrentFeature Odometry on the authors' real KITTI 04 tracks, next to the paper's table.

The CurrentFeature authors exported OV2SLAM's front end on KITTI 04 (``../shared/data/cfo_kitti04``,
read its SOURCE.md).  This script runs ``gevi run`` on those exports (the pipeline itself: the same
back end as on images, the export replacing the LK front end), for the gray and colour pairs, with
and without OV2SLAM's own outlier flags, and prints the online and after-BA numbers next to the
published ones, under the paper's protocol (SE(3) ATE, RPE over consecutive frames).

    python scripts/cfo_kitti04.py [--cameras gray,colour] [--out DIR] [--set KEY=VALUE ...]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cfo_kitti04"
EXPORTS = {"gray": ("ov2slam_data_kitti_04_gray", "gray_calib.txt"), "colour": ("ov2slam_data_kitti_04", "colour_calib.txt")}
PUBLISHED = {  # ATE, RPE (m): SOURCE.md
    "gray": {"paper, CurrentFeature": (0.726, 0.0197), "authors' re-run": (1.043, 0.0216),
             "paper, OV2SLAM": (1.306, 0.0239), "paper, ORB-SLAM3": (0.213, 0.0198)},
    "colour": {"paper, CurrentFeature": (2.328, 0.0353), "authors' re-run": (2.717, 0.0394),
               "paper, OV2SLAM": (3.453, 0.0487), "paper, ORB-SLAM3": (3.160, 0.0445)},
}


def evaluate(gt: Path, traj: Path) -> tuple[float, float]:
    from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair
    from gevi_cli.trajectory import read_trajectory

    r = evaluate_pair(read_trajectory(gt, frame="cam0"), read_trajectory(traj, frame="cam0"), EvalSettings(), "se3",
                      method="cfo", sequence="04")
    return r.ate.trans_rmse, r.rpe.trans_rmse


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cameras", default="gray,colour")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "cfo_kitti04")
    ap.add_argument("--set", dest="sets", action="append", default=[])
    a = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA}: not found (the read-only ../shared/data next to the repo)")
    from gevi_cli.run.session import RunRequest, execute

    gt = DATA / "data" / "gt_poses" / "kitti_gt_pose" / "04.txt"
    for cameras in a.cameras.split(","):
        folder, calib = EXPORTS[cameras]
        rows = []
        for flags in (False, True):
            out = a.out / f"{cameras}{'_flags' if flags else ''}"
            req = RunRequest(sequence=str(DATA / "data" / "ov2slam_data" / folder), calib=str(DATA / "calib" / calib),
                             groundtruth=str(gt), out=str(out), quiet=True,
                             sets=tuple(a.sets) + (f"verify.use_export_flags={str(flags).lower()}",))
            execute(req, echo=lambda *x, **k: None)
            st = json.loads((out / "status.json").read_text())
            label = "gevi cfo" + (", OV2SLAM flags" if flags else "")
            rows.append((f"{label}, after BA", evaluate(gt, out / "traj_body_kitti.txt"), st))
            # the online poses as KITTI rows: same association by frame index
            from gevi_cli.trajectory import read_trajectory, write_trajectory

            online = read_trajectory(out / "traj_online_body.tum")
            write_trajectory(online, out / "traj_online_body_kitti.txt", "kitti")
            rows.append((f"{label}, online", evaluate(gt, out / "traj_online_body_kitti.txt"), st))
        print(f"\nKITTI 04 ({cameras}): {rows[0][2]['frames_tracked']}/{rows[0][2]['frames_done']} frames tracked, "
              f"{rows[0][2]['keyframes']} keyframes, {rows[0][2]['elapsed_s']:.1f} s")
        print(f"| {'method':36s} | ATE [m] | RPE [m] |\n|---|---|---|")
        for label, (ate, rpe), _ in rows:
            print(f"| {label:36s} | {ate:.3f} | {rpe:.4f} |")
        for label, (ate, rpe) in PUBLISHED[cameras].items():
            print(f"| {label:36s} | {ate:.3f} | {rpe:.4f} |")


if __name__ == "__main__":
    main()
