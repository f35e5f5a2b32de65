"""GeVI, its ablations and CurrentFeature Odometry on simulated pool renders: the acceptance table.

Renders (60 s, underwater accelerations; ~90 s each on 2 cores):

    for p in pool-easy pool-hard; do for s in 1 2 3; do
      gevi simulate $p sims60/${p}_s$s --duration 60 --seed $s; done; done

Then ``python scripts/gevi_sweep.py sims60/pool-easy_s1 ... -o sweep_gevi`` runs every variant with
``gevi run`` (one process each, as a user would), and prints a Markdown table per sequence and the
means per preset: ATE / RPE (SE(3), body frame, RPE over one frame), roll/pitch RMSE over the run
and over its first and last 10 s after the initialisation (gravity-direction angle, no alignment),
its trend (least-squares slope of the 5 s windows' RMSE after the initialisation, deg/min),
frames/s and the mean verification time per frame.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

VARIANTS = {
    "gevi": ["--method", "gevi"],
    "gevi --no-adaptive": ["--method", "gevi", "--no-adaptive"],
    "gevi --no-fusion": ["--method", "gevi", "--no-fusion"],
    "gevi --ransac 5pt": ["--method", "gevi", "--ransac", "5pt"],
    "gevi --no-ba": ["--method", "gevi", "--no-ba"],
    "cfo": ["--method", "cfo"],
}


def tilt_windows(run: Path, seq: Path) -> tuple[float, float, float, float]:
    from gevi_cli.datasets import open_sequence
    from gevi_cli.evaluation.tilt import tilt_errors
    from gevi_cli.trajectory import read_trajectory

    gt = open_sequence(seq).groundtruth
    te = tilt_errors(read_trajectory(run / "traj_body.tum", frame="body"), gt)
    status = json.loads((run / "status.json").read_text())
    t_init = te.t_ns[0] + int(status.get("imu", {}).get("initialisation", {}).get("at_s", 0.0) * 1e9)
    first = te.window_rmse_deg(t_init, t_init + 10_000_000_000)
    last = te.window_rmse_deg(te.t_ns[-1] - 10_000_000_000, te.t_ns[-1])
    return te.rmse_deg, first, last, te.trend_deg_per_min(t_init)


def run_one(seq: Path, variant: str, out: Path) -> dict:
    run = out / seq.name / variant.replace(" ", "_").replace("-", "")
    if not (run / "status.json").is_file() or json.loads((run / "status.json").read_text()).get("state") == "running":
        subprocess.run(["gevi", "run", str(seq), *VARIANTS[variant], "-q", "-o", str(run)], check=False,
                       stdout=subprocess.DEVNULL)
    st = json.loads((run / "status.json").read_text())
    ev = st.get("evaluation", {})
    timing = pd.read_csv(run / "timing.csv")
    row = {"sequence": seq.name, "variant": variant, "state": st["state"],
           "tracked": f"{st['frames_tracked']}/{st['frames_done']}", "inertial": len(st.get("inertial_frames", [])),
           "ATE_mm": 1e3 * ev.get("ate_m", np.nan), "RPE_mm": 1e3 * ev.get("rpe_m", np.nan),
           "fps": st["frames_done"] / st["elapsed_s"], "verify_ms": timing["verify_ms"].mean()}
    if st.get("method", variant.split()[0]) == "cfo":
        # CFO's world is its first camera, not gravity-aligned: a tilt against the truth means nothing
        row["tilt_deg"] = row["tilt_first10_deg"] = row["tilt_last10_deg"] = row["tilt_trend_deg_min"] = np.nan
    else:
        row["tilt_deg"], row["tilt_first10_deg"], row["tilt_last10_deg"], row["tilt_trend_deg_min"] = \
            tilt_windows(run, seq)
    return row


def markdown(df: pd.DataFrame) -> str:
    def cell(v):
        return f"{v:.3f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequences", nargs="+", type=Path)
    ap.add_argument("-o", "--out", type=Path, default=Path("results/gevi_sweep"))
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated subset of: " + ", ".join(VARIANTS))
    a = ap.parse_args()
    rows = []
    for seq in a.sequences:
        for v in a.variants.split(","):
            rows.append(run_one(seq, v, a.out))
            r = rows[-1]
            a.out.mkdir(parents=True, exist_ok=True)
            pd.DataFrame(rows).to_csv(a.out / "sweep.csv", index=False)  # after every run: a killed sweep keeps its rows
            print(f"{r['sequence']:16s} {v:20s} ATE {r['ATE_mm']:8.3f} mm RPE {r['RPE_mm']:7.3f} mm tilt "
                  f"{r['tilt_deg']:.3f} deg ({r['tilt_first10_deg']:.3f} -> {r['tilt_last10_deg']:.3f}, trend "
                  f"{r['tilt_trend_deg_min']:+.3f} deg/min) "
                  f"{r['fps']:.1f} fps verify {r['verify_ms']:.2f} ms {r['tracked']} (inertial {r['inertial']})",
                  flush=True)
    df = pd.DataFrame(rows)
    a.out.mkdir(parents=True, exist_ok=True)
    df.to_csv(a.out / "sweep.csv", index=False)
    df["preset"] = df.sequence.str.replace(r"_s\d+$", "", regex=True)
    means = df.groupby(["preset", "variant"], sort=False)[["ATE_mm", "RPE_mm", "tilt_deg", "tilt_first10_deg",
                                                            "tilt_last10_deg", "tilt_trend_deg_min", "fps",
                                                            "verify_ms"]].mean()
    text = "## per run\n\n" + markdown(df.drop(columns="preset"))
    text += "\n\n## mean over seeds\n\n" + markdown(means.reset_index()) + "\n"
    (a.out / "sweep.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
