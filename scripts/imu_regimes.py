"""The acceptance table of `gevi imu`'s attitude filter across regimes (issue 36, docs/studies/imu_attitude.md).

Rows: euroc_micro's real IMU at 200, 100 and 50 Hz (``--imu-stride 1/2/4``), ``gevi simulate mav``
renders (seeds 1-3 at 50 and 200 Hz) and, for calm underwater-like motion, ``gevi simulate pool-easy
--imu-only --duration 60`` (seeds 1-3, 200 Hz).  Each row is one ``gevi imu`` run; the table gives the tilt
RMSE of the filters it compares (on the reference aligned to the IMU from the angular rates, printed),
the complementary filter's chosen time constant, the VQF reference rows and gevi's standstill-compensated
VQF rows (causal and offline).

    python scripts/imu_regimes.py [--work DIR] [--data ../shared/data] [--no-noise-model]

``--no-noise-model`` renders without a stated noise model (the filter then uses the one measured at
rest).  Renders are cached in ``--work`` (default /tmp/gevi_imu_regimes).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path


def gevi(*args) -> str:
    cmd = [sys.executable, "-c", "from gevi_cli.cli import main; main()", *map(str, args)]
    return subprocess.run(cmd, check=True, capture_output=True, text=True, env=os.environ).stdout


def rows_of(out: str) -> dict:
    rows = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.split("|")]
        if line.startswith("| ") and len(cells) > 5 and re.fullmatch(r"[0-9.]+", cells[2]):
            rows[cells[1]] = (float(cells[2]), cells[5])
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/gevi_imu_regimes")
    ap.add_argument("--data", default=os.environ.get("GEVI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--no-noise-model", action="store_true")
    ap.add_argument("--seeds", default="1,2,3")
    a = ap.parse_args()
    work = Path(a.work)
    jobs = []
    euroc = Path(a.data) / "euroc_micro"
    if euroc.is_dir():
        gt = euroc / "groundtruth" / "V1_01_easy.csv"
        for k, hz in ((1, 200), (2, 100), (4, 50)):
            jobs.append((f"euroc_micro {hz} Hz", [euroc, "--gt", gt, "--imu-stride", k]))
    extra = ["--no-noise-model"] if a.no_noise_model else []
    for seed in (int(s) for s in a.seeds.split(",")):
        for hz in (50, 200):
            out = work / f"mav_s{seed}_{hz}hz{'_nonoise' if extra else ''}"
            if not out.is_dir():
                gevi("simulate", "mav", out, "--imu-rate", hz, "--seed", seed, "-q", *extra)
            jobs.append((f"mav seed {seed} {hz} Hz", [out]))
    for seed in (int(s) for s in a.seeds.split(",")):
        out = work / f"pool_easy_s{seed}{'_nonoise' if extra else ''}"
        if not out.is_dir():
            gevi("simulate", "pool-easy", out, "--imu-only", "--duration", 60, "--seed", seed, *extra)
        jobs.append((f"pool-easy seed {seed} 200 Hz", [out]))
    print("| sequence | velocity-aided (gevi imu) | gravity prior, adaptive | best complementary (oracle) | its time "
          "constant | VQF online | VQF offline | compensated VQF online | compensated VQF offline | reference alignment |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, args in jobs:
        out = gevi("imu", *args, "-o", work / "imu" / name.replace(" ", "_"), "--no-plots")
        r = rows_of(out)
        al = re.search(r"clock offset ([-+0-9.]+ ms).*?rotation ([0-9.]+ deg)", out)
        al = f"{al.group(1)}, {al.group(2)}" if al else "none"
        vqf = [v for k, v in r.items() if k.startswith("VQF 6D online")][0][0], \
            [v for k, v in r.items() if k.startswith("VQF 6D offline")][0][0]
        ours = r["velocity-aided filter (gevi imu), causal"][0]
        cvqf = [v[0] for k, v in r.items() if k.startswith("standstill-compensated VQF")]
        comp, note = r["complementary filter, fixed gain (oracle)"]
        tau = re.search(r"time constant ([0-9.e+-]+) s", note).group(1)
        edge = " (GRID EDGE)" if "EDGE" in note else ""
        mark = "**" if ours <= comp else ""
        print(f"| {name} | {mark}{ours:.2f}{mark} | {r['gravity-prior filter, adaptive weight, causal'][0]:.2f} | {comp:.2f} | "
              f"{tau} s{edge} | {vqf[0]:.2f} | {vqf[1]:.2f} | {cvqf[0]:.2f} | {cvqf[1]:.2f} | {al} |", flush=True)


if __name__ == "__main__":
    main()
