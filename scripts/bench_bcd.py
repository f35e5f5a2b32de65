"""BCD refinement speed: GeVI's ``bcd_refine`` on recorded pipeline windows, against a floor.

    python scripts/bench_bcd.py record SEQUENCE OUT.pkl [--frames 300]
    python scripts/bench_bcd.py time WINDOWS.pkl [WINDOWS.pkl ...] [--repeat 5] [--baseline GITREV]

e.g. ``record ../shared/data/euroc_micro /tmp/euroc.pkl --frames 95`` (one keyframe: 20-frame
windows) and ``record <pool-easy render> /tmp/pool.pkl`` (short windows, many points), then
``time /tmp/euroc.pkl /tmp/pool.pkl --repeat 7 --baseline <rev before a change>``.

``record`` runs `gevi run --method gevi` in-process on the first frames of SEQUENCE with a spy on
``gevi_cli.estimators.bcd_refine`` (the pipeline calls ``est.bcd_refine``) and pickles every
``FusionWindow`` with its keyword arguments and the returned (state, Sigma, cost history).

``time`` replays the recorded windows: per window, ``bcd_refine`` and the floor are timed
interleaved ``--repeat`` times (median per window; the table gives the mean and median over
windows, ms per call).  The floor is one dense evaluation of the whitened visual residuals at the
initial estimate (rotate and translate the n points, project, whiten by the 2x2 inverse Cholesky
factors: what any estimator over these points pays at least once per cost evaluation).  The ratio
bcd / floor is the refinement's cost in such evaluations; with the default schedule a refinement
evaluates the residuals ~10 times and the Jacobian / normal equations ~7 times, so ~10 is what a
free Jacobian and free bookkeeping would reach.
The outputs are compared with the recorded ones (max over windows of max|a - b| / max|b| for the
state vector psi/t/tilts, Sigma and cov_last_tilt).  ``--baseline GITREV`` also times ``fusion.py`` as of that revision (loaded from
``git show`` as a sibling module), interleaved with the others, and compares the outputs with it.
"""
from __future__ import annotations

import argparse
import copy
import os
import pickle
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def record(seq: Path, frames: int, out: Path):
    from gevi_cli import estimators as est
    from gevi_cli.run.session import RunRequest, execute

    calls = []
    real = est.bcd_refine

    def spy(window, **kw):
        w = copy.deepcopy(window)  # the pipeline may reuse its arrays
        res = real(window, **kw)
        calls.append((w, dict(kw), copy.deepcopy(res)))
        return res

    est.bcd_refine = spy
    try:
        with tempfile.TemporaryDirectory() as d:
            execute(RunRequest(sequence=str(seq), method="gevi", max_frames=frames, out=d, quiet=True),
                    echo=lambda *a, **k: None)
    finally:
        est.bcd_refine = real
    with open(out, "wb") as f:
        pickle.dump(calls, f)
    n = [len(c[0].p) for c in calls]
    K = [len(c[0].acc_dir) for c in calls]
    print(f"{len(calls)} windows from {seq} -> {out} (points: median {int(np.median(n))}, "
          f"frames K: median {int(np.median(K))}, max {max(K)})")


def _floor_fn(w):
    """One dense evaluation of the whitened visual residuals (see the module docstring)."""
    from gevi_cli.estimators.fusion import (
        _check_window,
        _chol2_inv,
        _vis_covariance,
        propagate_tilts,
    )
    from gevi_cli.geometry import project, rot_z, rtilt

    w = _check_window(w)
    tilts0 = propagate_tilts(w.prior_mean, w.gyro_inc) if w.tilts0 is None else w.tilts0
    x = np.r_[w.psi0, w.t0, tilts0.ravel()]
    Wvis = _chol2_inv(_vis_covariance(w, x))
    a = w.p @ w.R_ic.T

    def f():
        M = w.R_ic.T @ rtilt(*tilts0[-1]).T @ rot_z(w.psi0) @ rtilt(*tilts0[0])
        X = a @ M.T + w.t0
        r = w.q - project(X)
        return np.einsum("nij,nj->ni", Wvis, r).ravel()

    return f


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def load_baseline(rev: str):
    """``gevi_cli/estimators/fusion.py`` as of git revision ``rev``, as module gevi_cli.estimators._fusion_<rev>."""
    import importlib.util
    import subprocess
    import sys

    import gevi_cli.estimators as pkg

    root = Path(pkg.__file__).resolve().parents[2]
    src = subprocess.run(["git", "-C", str(root), "show", f"{rev}:gevi_cli/estimators/fusion.py"],
                         check=True, capture_output=True, text=True).stdout
    name = f"gevi_cli.estimators._fusion_{''.join(c for c in rev if c.isalnum())}"
    spec = importlib.util.spec_from_loader(name, loader=None)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "gevi_cli.estimators"
    sys.modules[name] = mod  # (dataclasses look their module up)
    exec(compile(src, f"{rev}:fusion.py", "exec"), mod.__dict__)  # noqa: S102 (this repository's own file)
    return mod


class _Agree:
    def __init__(self):
        self.dx = self.ds = self.dc = 0.0
        self.mono = True

    def add(self, res, ref):
        st, Sig, hist = res
        st0, Sig0, _ = ref
        self.dx = max(self.dx, _rel(st.as_vector(), st0.as_vector()))
        self.ds = max(self.ds, _rel(Sig, Sig0))
        if np.all(np.isfinite(st0.cov_last_tilt)):
            self.dc = max(self.dc, _rel(st.cov_last_tilt, st0.cov_last_tilt))
        self.mono &= bool(np.all(np.diff(hist) <= 1e-12 * np.abs(np.asarray(hist[:-1]))))

    def __str__(self):
        return (f"state {self.dx:.2e}, Sigma {self.ds:.2e}, cov_last_tilt {self.dc:.2e} (max relative); "
                f"cost history non-increasing: {self.mono}")


def time_windows(path: Path, repeat: int, base=None, base_name=""):
    from gevi_cli.estimators import bcd_refine

    with open(path, "rb") as f:
        calls = pickle.load(f)
    fns = [("bcd_refine", bcd_refine)] + ([(f"bcd_refine @ {base_name}", base.bcd_refine)] if base else [])
    times = {k: [] for k, _ in fns}
    tf = []
    vs_rec, vs_base = _Agree(), _Agree()
    for w, kw, rec in calls:
        floor = _floor_fn(w)
        rt = {k: [] for k, _ in fns}
        rf = []
        for _ in range(repeat):
            res = {}
            for k, fn in fns:
                t0 = time.perf_counter()
                res[k] = fn(w, **kw)
                rt[k].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            floor()
            rf.append(time.perf_counter() - t0)
        for k, _ in fns:
            times[k].append(np.median(rt[k]))
        tf.append(np.median(rf))
        vs_rec.add(res["bcd_refine"], rec)
        if base:
            vs_base.add(res["bcd_refine"], res[fns[1][0]])
    tf = np.array(tf) * 1e3
    n = [len(c[0].p) for c in calls]
    K = [len(c[0].acc_dir) for c in calls]
    print(f"\n{path.name}: {len(calls)} windows (points median {int(np.median(n))}, K median {int(np.median(K))}), "
          f"median of {repeat} interleaved repeats per window")
    print("| | mean ms / call | median ms / call | mean ratio to floor |")
    print("|---|---|---|---|")
    for k, _ in fns:
        t = np.array(times[k]) * 1e3
        print(f"| {k} | {t.mean():.3f} | {np.median(t):.3f} | {t.mean() / tf.mean():.1f} |")
    print(f"| floor (1 visual residual eval) | {tf.mean():.4f} | {np.median(tf):.4f} | 1 |")
    if base:
        tb, t0 = np.array(times[fns[1][0]]), np.array(times["bcd_refine"])
        print(f"speed-up vs {base_name}: {tb.sum() / t0.sum():.2f}x (total), median per window {np.median(tb / t0):.2f}x")
        print(f"agreement vs {base_name}: {vs_base}")
    print(f"agreement vs recording: {vs_rec}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("sequence", type=Path)
    r.add_argument("out", type=Path)
    r.add_argument("--frames", type=int, default=300)
    t = sub.add_parser("time")
    t.add_argument("windows", type=Path, nargs="+")
    t.add_argument("--repeat", type=int, default=5)
    t.add_argument("--baseline", default=None, help="git revision whose fusion.py is timed alongside")
    a = ap.parse_args()
    if a.cmd == "record":
        record(a.sequence, a.frames, a.out)
        return
    base = load_baseline(a.baseline) if a.baseline else None
    for p in a.windows:
        time_windows(p, a.repeat, base, a.baseline or "")


if __name__ == "__main__":
    main()
