"""Compare two runs of a batch (the real-data board or the render seeds) under the rule for defaults.

    python scripts/board_compare.py BEFORE_RESULTS AFTER_RESULTS [--seeds]

BEFORE/AFTER are `gevi batch` output folders (their report/results.json).  Per (sequence, method) it
prints ATE and RPE before and after, the ratio, and the frames tracked, and flags a row worse than the
developers' guide allows: more than max(3 sigma, 10 %) above before (sigma: the trials' std where a row
has several, else 0).  With --seeds, per preset (the sequence name up to its `_s<seed>`): the
geometric mean over seeds of ATE after / before (at most 1.05) and the worst seed (at most 1.5x).
"""
from __future__ import annotations

import argparse
import json
import re
from collections import defaultdict
from pathlib import Path

import numpy as np


def _runs(folder: Path) -> dict:
    res = json.loads((folder / "report" / "results.json").read_text())
    rows = defaultdict(list)
    for r in res["runs"]:
        rows[(r["sequence"], r["method"])].append(r)
    return rows


def _mean(rows, key):
    vals = [r.get(key) for r in rows if r.get(key) is not None]
    return (float(np.mean(vals)), float(np.std(vals))) if vals else (float("nan"), 0.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--seeds", action="store_true", help="also the per-preset rule over render seeds")
    a = ap.parse_args()
    before, after = _runs(a.before), _runs(a.after)
    worse = 0
    print("| sequence | method | ATE before | ATE after | after/before | RPE before | RPE after | tracked |")
    print("|---|---|---|---|---|---|---|---|")
    ratios = defaultdict(list)
    for key in sorted(before):
        if key not in after:
            continue
        (ab, sb), (aa, _) = _mean(before[key], "ate_m"), _mean(after[key], "ate_m")
        (rb, srb), (ra, _) = _mean(before[key], "rpe_m"), _mean(after[key], "rpe_m")
        tb = sum(r.get("frames_tracked") or 0 for r in before[key])
        ta = sum(r.get("frames_tracked") or 0 for r in after[key])
        bad = aa > ab + max(3 * sb, 0.1 * ab) or ra > rb + max(3 * srb, 0.1 * rb) or ta < tb
        worse += bad
        print(f"| {key[0]} | {key[1]} | {ab:.4g} | {aa:.4g} | {aa / ab:.3f} | {rb:.4g} | {ra:.4g} | {tb} -> {ta} |"
              + (" **worse**" if bad else ""))
        m = re.match(r"(.+)_s(\d+)$", key[0])
        if m:
            ratios[(m.group(1), key[1])].append(aa / ab)
    if a.seeds:
        print("\n| preset | method | seeds | geometric mean after/before | worst seed |")
        print("|---|---|---|---|---|")
        for (preset, method), r in sorted(ratios.items()):
            g = float(np.exp(np.mean(np.log(r))))
            bad = g > 1.05 or max(r) > 1.5
            worse += bad
            print(f"| {preset} | {method} | {len(r)} | {g:.3f} | {max(r):.3f} |" + (" **worse**" if bad else ""))
    print(f"\n{worse} row(s) outside the rule")
    return 1 if worse else 0


if __name__ == "__main__":
    raise SystemExit(main())
