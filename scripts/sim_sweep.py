#!/usr/bin/env python3
"""Sweep `gevi run --method cfo` variants over simulated sequences and tabulate ATE / RPE.

A reproduction script (not a test).  For every sequence folder it runs, one after the other,

    gevi run SEQ -q -o OUT/runs/<sequence>/<variant> --method cfo [variant options]

for the variants ``be-w`` (the default pose estimator, with BA), ``epnp`` (``--pnp epnp``),
``no-ba`` (``--no-ba``) and optionally ``be`` (``--pnp be``) and ``ls`` (``--pnp ls``).  From each
run folder's ``status.json`` it collects ``state``, ``frames_tracked``, ``frames_done``,
``evaluation.ate_m``, ``evaluation.rpe_m`` (after BA), ``elapsed_s`` and ``pose_fallbacks``.  A run whose ``status.json`` says
``lost-tracking`` (gevi run's exit 3) keeps its numbers and is marked with a dagger; the outcome is
taken from ``state``, not the exit status alone.  A run that crashes (an exit status other than 0/3,
or no usable ``status.json``) becomes a failed cell with its message; the sweep continues either way.

It prints a Markdown table (preset, seed, frames tracked, ATE / RPE per variant), then per preset the
mean over the seeds of each variant and the two checks:

    (1) be-w RPE  < epnp RPE   (mean over the seeds of the preset)
    (2) be-w ATE  < no-ba ATE  (after-BA vs no-BA trajectory, mean over the seeds of the preset)

Every finished run folder's online trajectory ``traj_online_body.tum`` (each frame's pose as tracked,
as tracked, chained from keyframe poses that earlier BAs refined; the primary ``traj_body.tum`` is after BA) is evaluated too (unless ``--no-online``),

    gevi eval --gt SEQ -e online=RUN/traj_online_body.tum --align se3 --no-plots --no-kitti -o OUT/online/<sequence>/<variant>

and the variants of ``--online=VARIANTS`` (default: all of ``--variants``) get online ATE / RPE columns,
per-preset means and check (1) on the online trajectories as well.  Runs that lost tracking are listed with the reasons (status.json
``message`` and ``lost_intervals``, and the ``message`` column of frames.csv over the frames not tracked).

The table goes to ``OUT/sweep.md`` as well, every number to ``OUT/sweep.json`` (rewritten after
each run, so an interrupted sweep keeps what it measured).  With ``--reuse`` a reused run's exit
status and wall time are read back from its log ``OUT/runs/<sequence>/<variant>.log``.

Sequences
---------
The default sequences are eight `gevi simulate` renders, expected as ``ROOT/<preset>_s<seed>``
(``--root``, default ``results/sims``).  Regenerate them with (`gevi simulate` is deterministic:
same seed and options give byte-identical files)::

    gevi simulate pool-easy  ROOT/pool-easy_s1  --duration 30 --seed 1
    gevi simulate pool-easy  ROOT/pool-easy_s2  --duration 30 --seed 2
    gevi simulate pool-hard  ROOT/pool-hard_s1  --duration 30 --seed 1
    gevi simulate pool-hard  ROOT/pool-hard_s2  --duration 30 --seed 2
    gevi simulate euroc-like ROOT/euroc-like_s1 --duration 20 --seed 1
    gevi simulate euroc-like ROOT/euroc-like_s2 --duration 20 --seed 2
    gevi simulate kitti-like ROOT/kitti-like_s1 --duration 20 --seed 1 --format kitti
    gevi simulate kitti-like ROOT/kitti-like_s2 --duration 20 --seed 2 --format kitti

(other options at their defaults: EuRoC layout, 752x480, 20 Hz for the pool and euroc-like presets).
``pool-easy_s1`` and ``pool-hard_s1`` are the renders ORB-SLAM3 was run on for
``../shared/data/sim_baselines`` (its SOURCE.md).  ``--print-commands`` prints the commands above for
the chosen ``--root``.

ORB-SLAM3 reference
-------------------
With ``--baselines DIR`` (e.g. ``../shared/data/sim_baselines``), every sequence with a folder
``DIR/<sequence>/orbslam3_stereo/f_run.txt`` also gets an ORB-SLAM3 stereo column, evaluated as

    gevi eval --gt SEQ -e orbslam3=DIR/<sequence>/orbslam3_stereo/f_run.txt --est-frame cam0 \\
        --T-B-C0 T_B_C0.txt --align se3 --no-plots -o OUT/baselines/<sequence>

where ``T_B_C0.txt`` holds the 16 numbers of ``T_BS`` of ``DIR/<sequence>/cam0_sensor.yaml``
(written by this script into OUT/baselines/: gevi eval's ``--T-B-C0`` YAML reader does not accept the
OpenCV ``%YAML:1.0`` first line of EuRoC sensor files).  The script first checks that the render's
``mav0/state_groundtruth_estimate0/data.csv`` equals ``DIR/<sequence>/groundtruth.csv`` (bytes, else
numerically); a mismatch means the baseline belongs to a different render and is flagged.  For
pool-easy_s1, SOURCE.md gives ATE 5.0 mm / RPE 2.07 mm; pool-hard_s1 fails the 90 % coverage rule.

Usage
-----
::

    python scripts/sim_sweep.py --root results/sims -o results/sim_sweep
    python scripts/sim_sweep.py --root results/sims --baselines ../shared/data/sim_baselines \\
        --variants be-w,epnp,no-ba,be,ls
    python scripts/sim_sweep.py --root results/sims pool-easy_s1 --variants be-w   # one run
    python scripts/sim_sweep.py --root results/sims --print-commands               # render commands
    python scripts/sim_sweep.py --root results/sims --reuse --online=be-w,epnp --baselines ../shared/data/sim_baselines

Existing run folders are an error unless ``--reuse`` (take finished runs as they are) or
``--overwrite`` (delete and re-run; only folders holding a ``status.json``).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

# (sequence name, gevi simulate arguments after PRESET OUT_DIR)
DEFAULT_SEQUENCES = [
    ("pool-easy_s1", "pool-easy", ["--duration", "30", "--seed", "1"]),
    ("pool-easy_s2", "pool-easy", ["--duration", "30", "--seed", "2"]),
    ("pool-hard_s1", "pool-hard", ["--duration", "30", "--seed", "1"]),
    ("pool-hard_s2", "pool-hard", ["--duration", "30", "--seed", "2"]),
    ("euroc-like_s1", "euroc-like", ["--duration", "20", "--seed", "1"]),
    ("euroc-like_s2", "euroc-like", ["--duration", "20", "--seed", "2"]),
    ("kitti-like_s1", "kitti-like", ["--duration", "20", "--seed", "1", "--format", "kitti"]),
    ("kitti-like_s2", "kitti-like", ["--duration", "20", "--seed", "2", "--format", "kitti"]),
]

# variant name -> extra `gevi run` options
VARIANTS = {
    "be-w": [],
    "epnp": ["--pnp", "epnp"],
    "no-ba": ["--no-ba"],
    "be": ["--pnp", "be"],
    "ls": ["--pnp", "ls"],
}
DEFAULT_VARIANTS = ["be-w", "epnp", "no-ba"]
FINISHED = ("ok", "lost-tracking")


# ------------------------------------------------------------------------------------------ helpers
def gevi_command() -> list[str]:
    """The `gevi` entry point next to this interpreter, else ``python -m gevi_cli.cli``."""
    exe = Path(sys.executable).parent / ("gevi.exe" if sys.platform == "win32" else "gevi")
    if exe.is_file():
        return [str(exe)]
    return [sys.executable, "-m", "gevi_cli.cli"]


def split_name(name: str) -> tuple[str, str]:
    """``pool-easy_s1`` -> (``pool-easy``, ``1``); other names -> (name, '')."""
    m = re.fullmatch(r"(.+)_s(\d+)", name)
    return (m.group(1), m.group(2)) if m else (name, "")


def num(x) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def mm(x, digits: int = 2) -> str:
    v = num(x)
    return "n/a" if v is None else f"{v * 1e3:.{digits}f}"


def tail(text: str, n: int = 8) -> str:
    return "\n".join(text.strip().splitlines()[-n:])


def code_fingerprint() -> dict:
    """What code the `gevi` subprocesses run: sha256 over the gevi_cli package's *.py and configs/*.yaml
    (as found by this interpreter), plus the checkout's HEAD (read only).  Other work on the checkout
    during a sweep would otherwise silently mix code versions between runs."""
    import hashlib
    import importlib.util

    spec = importlib.util.find_spec("gevi_cli")
    if spec is None or not spec.submodule_search_locations:
        return {"sha256": None, "head": None, "root": None}
    pkg = Path(list(spec.submodule_search_locations)[0])
    root = pkg.parent
    h = hashlib.sha256()
    files = sorted(pkg.rglob("*.py")) + sorted((pkg / "configs").glob("*.yaml"))
    for f in files:
        try:
            h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
        except OSError:
            pass
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        head = None
    if head is None and (root / "COMMIT").is_file():  # a --code-dir copy made with `git archive`
        head = (root / "COMMIT").read_text().split()[0][:7] or None
    return {"sha256": h.hexdigest()[:16], "head": head, "root": str(root)}


def log_header(log_path: Path) -> tuple[int | None, float | None]:
    """(exit status, wall seconds) from the ``# exit N, X s`` line of a run log written by this script."""
    try:
        text = log_path.read_text()
    except OSError:
        return None, None
    m = re.search(r"^# exit (\S+), ([0-9.]+) s$", text, re.M)  # the header is the first lines of the log
    if not m:
        return None, None
    rc = int(m.group(1)) if re.fullmatch(r"-?\d+", m.group(1)) else None
    return rc, float(m.group(2))


def loss_reasons(frames_csv: Path) -> dict[str, int]:
    """Messages of the frames that were not tracked (frames.csv ``status`` != ok), numbers as N, with counts."""
    import csv
    from collections import Counter

    counts: Counter = Counter()
    try:
        with open(frames_csv, newline="") as fh:
            for row in csv.DictReader(fh):
                if row.get("status") not in (None, "", "ok"):
                    msg = re.sub(r"(?<![\w.])-?\d+(\.\d+)?(?![\w.])|\binf\b|\bnan\b", "N", (row.get("message") or "").strip())
                    counts[f"{row['status']}: {msg or '(no message)'}"] += 1
    except (OSError, csv.Error, KeyError):
        return {}
    return dict(counts.most_common())


def read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


# ------------------------------------------------------------------------------------------ one run
def run_one(seq_path: Path, seq_name: str, variant: str, run_dir: Path, log_path: Path, extra: list[str],
            timeout: float | None, reuse: bool) -> dict:
    preset, seed = split_name(seq_name)
    cmd = gevi_command() + ["run", str(seq_path), "-q", "-o", str(run_dir), "--method", "cfo"] + VARIANTS[variant] + extra
    rec = {"sequence": seq_name, "preset": preset, "seed": seed, "variant": variant, "path": str(seq_path),
           "run_dir": str(run_dir), "command": cmd, "returncode": None, "wall_s": None, "reused": False}
    st = read_json(run_dir / "status.json") if reuse else None
    if st is not None and st.get("state") in FINISHED:
        rec["reused"] = True  # this sweep did not run it: exit status and wall time from its log, if any
        rec["returncode"], rec["wall_s"] = log_header(log_path)
        try:
            m = re.search(r"^# code (\S+) \(HEAD (\S+)\)$", log_path.read_text(), re.M)
        except OSError:
            m = None
        rec["code"] = {"sha256": m.group(1), "head": m.group(2), "from_log": True} if m else None
    else:
        run_dir.parent.mkdir(parents=True, exist_ok=True)
        rec["code"] = code_fingerprint()
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
            rec["returncode"], out, err = proc.returncode, proc.stdout, proc.stderr
        except subprocess.TimeoutExpired as exc:
            rec["returncode"] = None
            out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            err = (exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")) + f"\ntimeout after {timeout} s"
        rec["wall_s"] = time.perf_counter() - t0
        after = code_fingerprint()
        if after["sha256"] != rec["code"]["sha256"]:
            rec["code_changed_during_run"] = after
        log_path.write_text(f"# code {rec['code']['sha256']} (HEAD {rec['code']['head']})\n"
                            + (f"# code changed during the run to {after['sha256']} (HEAD {after['head']})\n"
                               if "code_changed_during_run" in rec else "") + f"$ {' '.join(cmd)}\n# exit {rec['returncode']}, {rec['wall_s']:.1f} s\n"
                            f"--- stdout\n{out}--- stderr\n{err}")
        rec["stdout_tail"], rec["stderr_tail"] = tail(out), tail(err)
        st = read_json(run_dir / "status.json")

    rc = rec["returncode"]
    if st is None:
        rec.update(state="crashed", message=rec.get("stderr_tail") or f"exit {rc}, no status.json")
    else:
        ev = st.get("evaluation") or {}
        rec.update(state=st.get("state"), message=st.get("message", ""), frames_total=st.get("frames_total"),
                   frames_done=st.get("frames_done"), frames_tracked=st.get("frames_tracked"),
                   keyframes=st.get("keyframes"), elapsed_s=st.get("elapsed_s"),
                   pose_fallbacks=st.get("pose_fallbacks"), ate_m=num(ev.get("ate_m")),
                   rpe_m=num(ev.get("rpe_m")), ate_rot_deg=num(ev.get("ate_rot_deg")),
                   eval_failed=ev.get("failed"), lost_intervals=len(st.get("lost_intervals") or []),
                   lost=st.get("lost_intervals") or [], bridged=len(st.get("bridged_frames") or []),
                   loss_reasons=loss_reasons(run_dir / "frames.csv"))
        if not rec["reused"] and rc not in (0, 3) and rec["state"] in FINISHED:
            # finished odometry but the process failed afterwards (e.g. in the evaluation)
            rec["state"] = "crashed"
            rec["message"] = rec.get("stderr_tail") or f"exit {rc}"
    return rec


# ------------------------------------------------------------------------------------------ online
ONLINE = "traj_online_body.tum"



def run_eval_command(cmd: list[str], eval_dir: Path, log: Path) -> dict:
    """Run one `gevi eval` command, keep its log, and read the first result of its metrics.json."""
    proc = subprocess.run(cmd, capture_output=True, text=True)
    log.write_text(f"$ {' '.join(cmd)}\n# exit {proc.returncode}\n--- stdout\n{proc.stdout}--- stderr\n{proc.stderr}")
    o: dict = {"returncode": proc.returncode}
    metrics = read_json(eval_dir / "metrics.json")
    if proc.returncode != 0 or not metrics or not metrics.get("results"):
        o.update(status="failed", reason=tail(proc.stderr, 3) or f"exit {proc.returncode}")
        return o
    r = metrics["results"][0]
    ate, rpe, assoc = r.get("ate") or {}, r.get("rpe") or {}, r.get("association") or {}
    o.update(status=r.get("status"), reason=r.get("reason", ""), align=r.get("align"), ate_m=num(ate.get("trans_rmse")),
             rpe_m=num(rpe.get("trans_rmse")), ate_rot_deg=num(ate.get("rot_rmse_deg")), matched=assoc.get("matched"),
             coverage=num(assoc.get("coverage")), warnings=r.get("warnings", []))
    return o

def eval_online(rec: dict, seq_path: Path, eval_dir: Path, align: str) -> dict | None:
    """`gevi eval` of the run folder's online (as-tracked) trajectory ``traj_online_body.tum``.

    The same metrics as the run's own evaluation of its primary (body frame, RPE over 1 frame); the
    default --min-coverage 0.9 applies (a run bridges lost frames, so its coverage is that of its frames).
    """
    if rec.get("state") not in FINISHED:
        return None
    est = Path(rec["run_dir"]) / ONLINE
    if not est.is_file():
        return {"status": "failed", "reason": f"{est} missing"}
    cmd = gevi_command() + ["eval", "--gt", str(seq_path), "-e", f"online={est}", "--align", align,
                            "--no-plots", "--no-kitti", "-q", "-o", str(eval_dir), "--overwrite"]
    o: dict = {"estimate": str(est), "eval_dir": str(eval_dir), "command": cmd}
    eval_dir.parent.mkdir(parents=True, exist_ok=True)
    o.update(run_eval_command(cmd, eval_dir, eval_dir.with_suffix(".log")))
    return o


# ------------------------------------------------------------------------------------------ baselines
def read_T_BS(sensor_yaml: Path) -> list[float]:
    """T_BS (16 numbers) of an EuRoC/OpenCV sensor.yaml (its ``%YAML:1.0`` line is skipped)."""
    import yaml

    text = "\n".join(line for line in sensor_yaml.read_text().splitlines() if not line.startswith("%YAML"))
    data = yaml.safe_load(text)
    v = data["T_BS"]
    vals = [float(x) for x in (v["data"] if isinstance(v, dict) else v)]
    if len(vals) != 16:
        raise ValueError(f"{sensor_yaml}: T_BS has {len(vals)} numbers, expected 16")
    return vals


def compare_gt(render_gt: Path, baseline_gt: Path) -> tuple[bool | None, str]:
    """(same?, how): byte compare, else numerically (1e-9 relative)."""
    if not render_gt.is_file():
        return None, f"{render_gt} missing"
    if not baseline_gt.is_file():
        return None, f"{baseline_gt} missing"
    if render_gt.read_bytes() == baseline_gt.read_bytes():
        return True, "byte-identical"
    import numpy as np

    try:
        a = np.loadtxt(render_gt, delimiter=",", comments="#")
        b = np.loadtxt(baseline_gt, delimiter=",", comments="#")
    except ValueError as exc:
        return False, f"differ in bytes and cannot be compared numerically: {exc}"
    if a.shape != b.shape:
        return False, f"different shapes {a.shape} vs {b.shape}"
    if np.allclose(a, b, rtol=1e-9, atol=1e-12):
        return True, f"numerically equal (max |diff| {np.abs(a - b).max():.3g})"
    return False, f"differ (max |diff| {np.abs(a - b).max():.3g})"


def eval_baseline(seq_path: Path, seq_name: str, bdir: Path, out: Path) -> dict | None:
    """ORB-SLAM3 stereo of DIR/<sequence>/ evaluated against the render, or None (no baseline)."""
    f_run = bdir / seq_name / "orbslam3_stereo" / "f_run.txt"
    if not f_run.is_file():
        return None
    rec: dict = {"sequence": seq_name, "estimate": str(f_run)}
    same, how = compare_gt(seq_path / "mav0" / "state_groundtruth_estimate0" / "data.csv", bdir / seq_name / "groundtruth.csv")
    rec["gt_matches_render"], rec["gt_check"] = same, how
    out.mkdir(parents=True, exist_ok=True)
    tbc = out / f"{seq_name}_T_B_C0.txt"
    try:
        tbc.write_text(" ".join(repr(x) for x in read_T_BS(bdir / seq_name / "cam0_sensor.yaml")) + "\n")
    except (OSError, KeyError, ValueError, TypeError) as exc:
        rec.update(status="failed", reason=f"cam0_sensor.yaml: {exc}")
        return rec
    eval_dir = out / seq_name
    cmd = gevi_command() + ["eval", "--gt", str(seq_path), "-e", f"orbslam3={f_run}", "--est-frame", "cam0",
                            "--T-B-C0", str(tbc), "--align", "se3", "--no-plots", "-q", "-o", str(eval_dir), "--overwrite"]
    rec["command"] = cmd
    rec.update(run_eval_command(cmd, eval_dir, out / f"{seq_name}.log"))
    return rec


# ------------------------------------------------------------------------------------------ tables
def cell(rec: dict | None, key: str) -> str:
    if rec is None:
        return ""
    if rec.get("state") not in FINISHED:
        return rec.get("state") or "failed"
    s = mm(rec.get(key))
    return s + (" †" if rec.get("state") == "lost-tracking" else "")


def online_cell(rec: dict | None, key: str) -> str:
    if rec is None:
        return ""
    if rec.get("state") not in FINISHED:
        return rec.get("state") or "failed"
    o = rec.get("online")
    if o is None:
        return "not evaluated"
    if o.get("status") != "ok":
        return "failed" + (f": coverage {o['coverage'] * 100:.1f} %" if o.get("coverage") is not None else "")
    return mm(o.get(key)) + (" †" if rec.get("state") == "lost-tracking" else "")


def tracked_cell(rec: dict | None) -> str:
    if rec is None:
        return ""
    if rec.get("frames_tracked") is None:
        return rec.get("state") or "failed"
    return f"{rec['frames_tracked']}/{rec.get('frames_done')}" + (" †" if rec.get("state") == "lost-tracking" else "")


def baseline_cell(b: dict | None) -> tuple[str, str]:
    if b is None:
        return "", ""
    flag = "" if b.get("gt_matches_render") else " (GT≠render)"
    if b.get("status") != "ok":
        reason = b.get("reason") or "failed"
        if b.get("coverage") is not None:
            reason = f"failed: coverage {b['coverage'] * 100:.1f} %"
        return reason + flag, reason + flag
    return mm(b.get("ate_m")) + flag, mm(b.get("rpe_m")) + flag


def mean_of(values: list) -> float | None:
    vals = [num(v) for v in values]
    return None if not vals or any(v is None for v in vals) else sum(vals) / len(vals)


def summarize(records: list[dict], seqs: list[tuple[str, Path]], variants: list[str],
              online: list[str] | None = None) -> dict:
    """Per preset: mean over its seeds of ATE / RPE per variant, and the two checks."""
    by = {(r["sequence"], r["variant"]): r for r in records}
    presets: dict[str, list[str]] = {}
    for name, _ in seqs:
        presets.setdefault(split_name(name)[0], []).append(name)
    out = {}
    for preset, names in presets.items():
        entry: dict = {"sequences": names, "variants": {}}
        for v in variants:
            rs = [by.get((n, v)) for n in names]
            usable = [r for r in rs if r is not None and r.get("state") in FINISHED]
            entry["variants"][v] = {
                "n": len(usable), "of": len(names),
                "ate_m": mean_of([r.get("ate_m") for r in usable]) if len(usable) == len(names) else None,
                "rpe_m": mean_of([r.get("rpe_m") for r in usable]) if len(usable) == len(names) else None,
                "lost": sum(1 for r in usable if r.get("state") == "lost-tracking"),
            }
            if online is not None:
                ons = [r.get("online") for r in usable]
                full = len(usable) == len(names) and all(o and o.get("status") == "ok" for o in ons)
                entry["variants"][v]["online_ate_m"] = mean_of([o.get("ate_m") for o in ons]) if full else None
                entry["variants"][v]["online_rpe_m"] = mean_of([o.get("rpe_m") for o in ons]) if full else None

        def check(a: str, b: str, key: str):
            if a not in entry["variants"] or b not in entry["variants"]:
                return None
            x, y = entry["variants"][a][key], entry["variants"][b][key]
            return None if x is None or y is None else bool(x < y)

        entry["check1_bew_rpe_lt_epnp"] = check("be-w", "epnp", "rpe_m")
        entry["check2_bew_ate_lt_noba"] = check("be-w", "no-ba", "ate_m")
        if online is not None:
            entry["check1_online_bew_rpe_lt_epnp"] = check("be-w", "epnp", "online_rpe_m")
        out[preset] = entry
    return out


def render_markdown(records: list[dict], seqs: list[tuple[str, Path]], variants: list[str], summary: dict,
                    baselines: dict[str, dict] | None, online_cols: list[str] | None = None) -> str:
    by = {(r["sequence"], r["variant"]): r for r in records}
    online_cols = online_cols or []
    head = ["preset", "seed", "frames"]
    for v in variants:
        head += [f"{v} tracked", f"{v} ATE", f"{v} RPE"]
    for v in online_cols:
        head += [f"{v} online ATE", f"{v} online RPE"]
    if baselines is not None:
        head += ["ORB-SLAM3 stereo ATE", "ORB-SLAM3 stereo RPE"]
    head.append("pose fallbacks (" + " / ".join(variants) + ")")
    head.append("elapsed s (" + " / ".join(variants) + ")")
    lines = ["## Runs (ATE / RPE: translation RMSE in mm; RPE over 1 frame; body frame, alignment as gevi run's eval)", "",
             "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for name, _ in seqs:
        preset, seed = split_name(name)
        rs = [by.get((name, v)) for v in variants]
        total = next((r.get("frames_total") for r in rs if r and r.get("frames_total")), None)
        row = [preset, seed, str(total) if total else "?"]
        for r in rs:
            row += [tracked_cell(r), cell(r, "ate_m"), cell(r, "rpe_m")]
        for v in online_cols:
            r = by.get((name, v))
            row += [online_cell(r, "ate_m"), online_cell(r, "rpe_m")]
        if baselines is not None:
            row += list(baseline_cell(baselines.get(name)))
        row.append(" / ".join("" if r is None or r.get("pose_fallbacks") is None else str(r["pose_fallbacks"]) for r in rs))
        row.append(" / ".join("" if r is None or r.get("elapsed_s") is None else f"{r['elapsed_s']:.0f}" for r in rs))
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "† status.json state `lost-tracking`: tracking lost at least once, lost frames bridged at constant velocity; "
              "the numbers are of that trajectory."]
    if online_cols:
        lines += ["", f"online: `{ONLINE}` (each frame's pose when it was tracked, as tracked, chained from keyframe poses that earlier BAs refined), "
                  "`gevi eval --align se3`, same metrics as the after-BA columns."]
    lines += ["pose fallbacks: status.json `pose_fallbacks`.",
              "elapsed s: status.json `elapsed_s` (odometry only, without loading and evaluation).", ""]

    head = ["preset", "seeds"] + [f"{v} ATE" for v in variants] + [f"{v} RPE" for v in variants] + \
           [f"{v} online ATE" for v in online_cols] + [f"{v} online RPE" for v in online_cols] + \
           ["(1) be-w RPE < epnp RPE"] + (["(1) online: be-w RPE < epnp RPE"] if online_cols else []) + \
           ["(2) be-w ATE < no-ba ATE"]
    lines += ["## Mean over seeds per preset (mm)", "", "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]

    def yn(x):
        return "n/a" if x is None else ("yes" if x else "**no**")

    for preset, e in summary.items():
        seeds = ",".join(split_name(n)[1] or n for n in e["sequences"])
        vv = e["variants"]

        def m(v, key):
            d = vv[v]
            return mm(d.get(key)) if d.get(key) is not None else f"n/a ({d['n']}/{d['of']} runs)"

        row = [preset, seeds] + [m(v, "ate_m") for v in variants] + [m(v, "rpe_m") for v in variants] + \
              [m(v, "online_ate_m") for v in online_cols] + [m(v, "online_rpe_m") for v in online_cols] + \
              [yn(e["check1_bew_rpe_lt_epnp"])] + ([yn(e.get("check1_online_bew_rpe_lt_epnp"))] if online_cols else []) + \
              [yn(e["check2_bew_ate_lt_noba"])]
        lines.append("| " + " | ".join(row) + " |")
    lines.append("")
    if baselines:
        lines += ["ORB-SLAM3 stereo: `gevi eval --est-frame cam0 --align se3` (default --min-coverage 0.9) of "
                  "`<baselines>/<sequence>/orbslam3_stereo/f_run.txt`; "
                  "GT check of the render vs the baseline's groundtruth.csv:", ""]
        for name, b in baselines.items():
            lines.append(f"- {name}: {b.get('gt_check')}; {b.get('status')}"
                         + (f" ({b['reason']})" if b.get("reason") else ""))
        lines.append("")
    lost = [r for r in records if r.get("state") == "lost-tracking"]
    if lost:
        lines += ["## Runs that lost tracking", "",
                  "status.json `message`; then the `message` column of frames.csv over the frames not tracked "
                  "(numbers as N, with counts); then the first losses of status.json `lost_intervals`.", ""]
        for r in lost:
            lines.append(f"- {r['sequence']} {r['variant']} (exit {r.get('returncode')}): {r.get('message')}")
            reasons = r.get("loss_reasons") or {}
            if reasons:
                lines.append("  - frames.csv: " + "; ".join(f"{k} ×{n}" for k, n in reasons.items()))
            ivs = r.get("lost") or []
            if ivs:
                lines.append("  - first: " + "; ".join(f"frame {iv.get('first_index')} ({iv.get('frames')} bridged): "
                                                       f"{iv.get('reason')}" for iv in ivs[:3])
                             + (f"; … {len(ivs) - 3} more" if len(ivs) > 3 else ""))
        lines.append("")
    versions: dict = {}
    for r in records:
        c = r.get("code") or {}
        versions.setdefault((c.get("sha256"), c.get("head")), []).append(f"{r['sequence']} {r['variant']}")
    changed = [f"{r['sequence']} {r['variant']}" for r in records if r.get("code_changed_during_run")]
    lines += ["## Code", ""]
    if len(versions) == 1 and not changed:
        (sha, head), _ = next(iter(versions.items()))
        lines.append(f"All runs: gevi_cli + configs sha256 {sha} (HEAD {head}).")
    else:
        lines.append("**WARNING: the runs did not all run the same code** (the checkout changed during the sweep):")
        for (sha, head), names in versions.items():
            lines.append(f"- sha256 {sha} (HEAD {head}): {len(names)} run(s): {', '.join(names)}")
        if changed:
            lines.append(f"- code changed while running: {', '.join(changed)}")
    lines.append("")
    failed = [r for r in records if r.get("state") not in FINISHED]
    if failed:
        lines += ["## Failed runs", ""]
        for r in failed:
            msg = (r.get("message") or "").strip().replace("\n", " / ")
            lines.append(f"- {r['sequence']} {r['variant']}: {r.get('state')} (exit {r.get('returncode')}): {msg[:300]}")
        lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="See the module docstring (scripts/sim_sweep.py) for the render commands.")
    ap.add_argument("sequences", nargs="*", metavar="SEQ",
                    help="sequence folders, or names under --root (default: the eight renders of the docstring)")
    ap.add_argument("--root", type=Path, default=Path("results/sims"),
                    help="folder holding the renders <preset>_s<seed> (default: results/sims)")
    ap.add_argument("-o", "--out", type=Path, default=Path("results/sim_sweep"),
                    help="output folder: runs/, baselines/, sweep.md, sweep.json (default: results/sim_sweep)")
    ap.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                    help=f"comma-separated, of {','.join(VARIANTS)} (default: {','.join(DEFAULT_VARIANTS)})")
    ap.add_argument("--baselines", type=Path, default=None,
                    help="sim_baselines folder: add ORB-SLAM3 stereo columns for sequences it holds")
    og = ap.add_mutually_exclusive_group()
    og.add_argument("--online", nargs="?", const="", default="", metavar="VARIANTS",
                    help=f"variants whose online (as-tracked) trajectory {ONLINE} is evaluated (`gevi eval "
                         "--align se3`, into OUT/online/) and tabulated (default: all of --variants)")
    og.add_argument("--no-online", action="store_true", help=f"do not evaluate the online trajectories {ONLINE}")
    ap.add_argument("--code-dir", type=Path, default=None, metavar="DIR",
                    help="run gevi from this frozen copy of the checkout (gevi_cli/ and configs/; PYTHONPATH=DIR), "
                         "e.g. `git archive HEAD gevi_cli configs | tar -x -C DIR` with the commit in DIR/COMMIT: "
                         "edits to the working checkout during the sweep then cannot mix code versions")
    ap.add_argument("--jobs", type=int, default=1, help="runs in parallel (default 1: sequential)")
    ap.add_argument("--timeout", type=float, default=None, help="seconds per gevi run (default: none)")
    ap.add_argument("--run-arg", action="append", default=[], metavar="ARG",
                    help="extra argument passed to every gevi run (repeatable), e.g. --run-arg=--max-frames=100")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--reuse", action="store_true", help="keep finished run folders (state ok / lost-tracking)")
    g.add_argument("--overwrite", action="store_true", help="delete existing run folders (with status.json) and re-run")
    ap.add_argument("--print-commands", action="store_true", help="print the gevi simulate commands for --root and exit")
    args = ap.parse_args(argv)

    if args.print_commands:
        for name, preset, opts in DEFAULT_SEQUENCES:
            print(" ".join(["gevi", "simulate", preset, str(args.root / name)] + opts))
        return 0

    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    bad = [v for v in variants if v not in VARIANTS]
    if bad or not variants:
        ap.error(f"unknown variant(s) {bad}; choose from {', '.join(VARIANTS)}")
    if args.jobs < 1:
        ap.error("--jobs must be >= 1")
    online_cols = None
    if not args.no_online:
        online_cols = [v.strip() for v in args.online.split(",") if v.strip()] or list(variants)
        bad = [v for v in online_cols if v not in variants]
        if bad:
            ap.error(f"--online: variant(s) {bad} not in --variants")

    if args.code_dir is not None:
        import importlib
        import os

        code_dir = args.code_dir.resolve()
        if not (code_dir / "gevi_cli" / "__init__.py").is_file():
            ap.error(f"--code-dir: {code_dir}/gevi_cli/__init__.py missing")
        os.environ["PYTHONPATH"] = os.pathsep.join([str(code_dir)] + [x for x in [os.environ.get("PYTHONPATH")] if x])
        sys.path.insert(0, str(code_dir))  # for code_fingerprint() in this process
        importlib.invalidate_caches()

    known = {name: (preset, opts) for name, preset, opts in DEFAULT_SEQUENCES}
    seqs: list[tuple[str, Path]] = []
    for s in args.sequences or [n for n, _, _ in DEFAULT_SEQUENCES]:
        p = Path(s)
        if not p.is_dir():
            p = args.root / s
        seqs.append((p.name, p))
    missing = [(n, p) for n, p in seqs if not p.is_dir()]
    if missing:
        msg = ["missing sequence folder(s); render them with:"]
        for n, p in missing:
            if n in known:
                msg.append("  " + " ".join(["gevi", "simulate", known[n][0], str(p)] + known[n][1]))
            else:
                msg.append(f"  {p} (unknown name)")
        print("\n".join(msg), file=sys.stderr)
        return 2
    if len({n for n, _ in seqs}) != len(seqs):
        ap.error("two sequences have the same folder name")

    out = args.out
    runs_root = out / "runs"
    jobs = []
    conflicts = []
    for name, path in seqs:
        for v in variants:
            run_dir = runs_root / name / v
            if run_dir.exists() and any(run_dir.iterdir()):
                if args.overwrite:
                    if not (run_dir / "status.json").is_file():
                        conflicts.append(f"{run_dir} (not a gevi run folder: not deleted)")
                        continue
                elif not args.reuse:
                    conflicts.append(str(run_dir))
                    continue
            jobs.append((path, name, v, run_dir))
    if conflicts:
        print("existing run folder(s) (use --reuse or --overwrite):\n  " + "\n  ".join(conflicts), file=sys.stderr)
        return 2
    if args.overwrite:
        for _, _, _, run_dir in jobs:
            if (run_dir / "status.json").is_file():
                shutil.rmtree(run_dir)
    out.mkdir(parents=True, exist_ok=True)

    settings = {"code_at_start": code_fingerprint(), "code_dir": str(args.code_dir) if args.code_dir else None,
                "root": str(args.root), "out": str(out), "variants": {v: VARIANTS[v] for v in variants},
                "sequences": [str(p) for _, p in seqs], "gevi": gevi_command(), "run_args": args.run_arg,
                "baselines": str(args.baselines) if args.baselines else None, "jobs": args.jobs,
                "online": online_cols, "reuse": args.reuse, "overwrite": args.overwrite}
    records: list[dict] = []
    baselines: dict[str, dict] | None = {} if args.baselines else None
    t_sweep = time.perf_counter()

    def save() -> None:
        data = {"settings": settings, "runs": records, "presets": summarize(records, seqs, variants, online_cols),
                "baselines": baselines, "wall_s": time.perf_counter() - t_sweep}
        tmp = out / "sweep.json.tmp"
        tmp.write_text(json.dumps(data, indent=1, default=str) + "\n")
        tmp.replace(out / "sweep.json")

    def do(job):
        path, name, v, run_dir = job
        rec = run_one(path, name, v, run_dir, runs_root / name / f"{v}.log", args.run_arg, args.timeout, args.reuse)
        if online_cols is not None:
            rec["online"] = eval_online(rec, path, out / "online" / name / v, "se3")
        return rec

    def report(rec):
        ate, rpe = mm(rec.get("ate_m")), mm(rec.get("rpe_m"))
        how = "reused run folder" if rec.get("reused") else f"exit {rec.get('returncode')}"
        print(f"[{len(records)}/{len(jobs)}] {rec['sequence']} {rec['variant']}: {rec.get('state')} ({how}), "
              f"tracked {rec.get('frames_tracked')}/{rec.get('frames_done')}, "
              f"ATE {ate} mm, RPE {rpe} mm, pose fallbacks {rec.get('pose_fallbacks')}, {rec.get('elapsed_s') or 0:.1f} s"
              + (f" (online ATE {mm(rec['online'].get('ate_m'))} mm, RPE {mm(rec['online'].get('rpe_m'))} mm)"
                 if rec.get("online") else "")
              + (" [over 5 min]" if (rec.get("wall_s") or 0) > 300 else ""), file=sys.stderr, flush=True)

    if args.jobs == 1:
        for job in jobs:
            records.append(do(job))
            report(records[-1])
            save()
    else:
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            for rec in pool.map(do, jobs):
                records.append(rec)
                report(rec)
                save()

    if args.baselines is not None:
        for name, path in seqs:
            b = eval_baseline(path, name, args.baselines, out / "baselines")
            if b is not None:
                baselines[name] = b
                print(f"baseline {name}: ORB-SLAM3 stereo {b.get('status')}, ATE {mm(b.get('ate_m'))} mm, "
                      f"RPE {mm(b.get('rpe_m'))} mm; GT {b.get('gt_check')}", file=sys.stderr, flush=True)
    save()
    md = render_markdown(records, seqs, variants, summarize(records, seqs, variants, online_cols), baselines, online_cols)
    (out / "sweep.md").write_text(md + "\n")
    print(md)
    print(f"wrote {out / 'sweep.md'} and {out / 'sweep.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
