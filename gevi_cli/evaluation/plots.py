"""Figures of an evaluation, drawn on Agg canvases (``matplotlib.figure.Figure`` + ``FigureCanvasAgg``).

gevi never imports ``matplotlib.pyplot`` here, so the user's matplotlib backend is never switched and
no GUI opens; every figure is saved as PNG and PDF.

Per sequence ``S`` (in ``<out>/plots/``):

* ``traj_S``: top view and side view of the GT and every method's aligned estimate (of a method with
  trials, the trial with the median ATE), in the GT's world (:func:`world_of`, :func:`view_of`): a
  z-up world (EuRoC ground truth): top = x-y; a KITTI camera world (x right, y down, z forward):
  top = x-z, the road; any other: the two axes of largest extent.  Metres.
* ``ate_S``: translation error (m) over time (s since the GT start; frame number for KITTI).
* ``rpe_S``: box plots of the RPE translation (m) and rotation (deg) errors per method (all trials pooled).

And ``summary_ate``: grouped bars of the ATE translation RMSE per sequence and method (error bars: std
over trials).  ``gevi run`` adds one small PNG to every run folder (:func:`plot_run_trajectory`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def _figure(w=10.0, h=4.5, ncols=1, nrows=1, layout="constrained"):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), layout=layout)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes.ravel()


def _save(fig, base: Path) -> list[Path]:
    out = []
    for ext in ("png", "pdf"):
        p = base.with_suffix(f".{ext}")
        fig.savefig(p, dpi=110)
        out.append(p)
    return out


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", name)


def _thin(x: np.ndarray, n: int = 4000) -> np.ndarray:
    return x[:: max(1, len(x) // n)]


#: Worlds a trajectory's positions can be in (``None``: unknown), with what each axis points at.
#: ``z-up``: gravity-aligned, z up (GeVI's world after its initialisation; EuRoC and simulator ground
#: truth).  ``camera-level``: the first camera frame of a level-mounted vehicle camera, x right, y down,
#: z forward, so gravity is close to +y (KITTI ground truth; a stereo odometry's world on KITTI).
#: ``camera``: a first camera frame whose attitude is unknown (x right, y down, z forward of that camera).
WORLDS = {"z-up": ("horizontal", "horizontal", "up"), "camera-level": ("right", "down", "forward"),
          "camera": ("right", "down", "forward")}
_UP_AXIS = {"z-up": 2, "camera-level": 1}  # the axis along gravity of the gravity-aligned worlds


def world_of(traj) -> str | None:
    """The world of a trajectory read from a file, from its format: EuRoC ground truth is z-up (the
    motion-capture world), a KITTI pose file is in the first cam0 frame of KITTI's level camera
    (``camera-level``); any other format (TUM, bags) says nothing (None)."""
    fmt = (getattr(traj, "meta", None) or {}).get("format")
    if fmt == "euroc":
        return "z-up"
    if fmt in ("kitti", "kitti-idx") or getattr(traj, "indexed", False):
        return "camera-level"
    return None


@dataclass(frozen=True)
class View:
    """How to draw positions (metres) of a world: ``top`` = (horizontal, vertical) axis indices of the
    picture's top view, ``normal`` the third axis (up or down in a gravity-aligned world), ``labels``
    per axis x, y, z, e.g. ``"z [m] (forward)"``; ``normal_down``: the normal axis points down (camera y),
    so a side view flips it to show up as up."""

    top: tuple
    normal: int
    labels: tuple
    normal_down: bool = False


def view_of(positions: np.ndarray, world: str | None) -> View:
    """The view of ``positions`` ((n, 3) metres) in ``world`` (a key of :data:`WORLDS` or None).

    A gravity-aligned world (``z-up``, ``camera-level``) is seen in the plane perpendicular to gravity
    (x-y, respectively x-z: the road of a KITTI sequence, even where the camera's height changed more
    than it moved sideways); any other from the normal of its two axes of largest extent.
    """
    if world in _UP_AXIS:
        normal = _UP_AXIS[world]
    else:
        extent = np.ptp(np.asarray(positions, dtype=float).reshape(-1, 3), axis=0) if len(positions) else np.zeros(3)
        normal = 2 - int(np.argmin(extent[::-1]))  # of equal extents the last: x-y for a still trajectory
    top = tuple(a for a in range(3) if a != normal)
    names = WORLDS.get(world)
    labels = tuple(f"{'xyz'[a]} [m]" + (f" ({names[a]})" if names else "") for a in range(3))
    return View(top=top, normal=normal, labels=labels, normal_down=names is not None and names[normal] == "down")


def _draw_view(ax, view: View, series, side: bool = False) -> None:
    """Plot ``series`` ((positions, matplotlib format, keyword dict) each) in ``view``: its top plane, or
    ``side``: the longer top axis against the normal (up drawn up)."""
    if side:
        ext = [max((np.ptp(p[:, a]) if len(p) else 0.0) for p, _, _ in series) for a in view.top]
        i, j = view.top[int(np.argmax(ext))], view.normal
    else:
        i, j = view.top
    for p, fmt, kw in series:
        ax.plot(p[:, i], p[:, j], fmt, **kw)
    ax.set_xlabel(view.labels[i])
    ax.set_ylabel(view.labels[j])
    if side and view.normal_down:
        ax.invert_yaxis()
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)


def plot_run_trajectory(png: Path, est: np.ndarray, gt: np.ndarray | None, world: str | None, title: str) -> Path:
    """One small top-view PNG of a run (320 x 320 px): the estimate's positions ``est`` ((n, 3) metres)
    over the ground truth's ``gt`` (the same world, e.g. the aligned estimate; None: no ground truth)."""
    fig, (ax,) = _figure(4.0, 4.0, layout=None)  # fixed margins: a constrained layout draws twice
    fig.subplots_adjust(left=0.19, right=0.97, bottom=0.12, top=0.92)
    series = ([(_thin(gt, 1000), "k--", {"lw": 1.0, "label": "ground truth"})] if gt is not None else []) + \
        [(_thin(est, 1000), "-", {"lw": 1.0, "color": "tab:blue", "label": "estimate"})]
    view = view_of(np.vstack([p for p, _, _ in series]), world)
    _draw_view(ax, view, series)
    ax.plot(*est[0, list(view.top)], "o", ms=3, color="tab:blue")  # where it starts
    ax.set_title(title, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.xaxis.label.set_size(8)
    ax.yaxis.label.set_size(8)
    if gt is not None:
        ax.legend(fontsize=7, loc="upper right")
    fig.savefig(png, dpi=80)
    return Path(png)


def representative(results):
    """Per method, the ok trial with the median ATE (None when all failed)."""
    out = {}
    for m in dict.fromkeys(r.method for r in results):
        ok = [r for r in results if r.method == m and r.ok and r.ate is not None and r.aligned is not None]
        if ok:
            ok.sort(key=lambda r: r.ate.trans_rmse)
            out[m] = ok[(len(ok) - 1) // 2]
    return out


def plot_sequence(out_dir: Path, sequence: str, gt, results) -> list[Path]:
    """All per-sequence figures; ``results`` are the PairResults of this sequence."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    reps = representative(results)
    fig, (a1, a2) = _figure(12, 5.5, ncols=2)
    series = [(_thin(gt.positions), "k--", {"lw": 1.2, "label": "ground truth"})] + \
        [(_thin(r.aligned.positions), "-", {"lw": 1.0, "label": f"{m} ({r.align})"}) for m, r in reps.items()]
    view = view_of(gt.positions, world_of(gt))
    for ax, side, title in ((a1, False, "top view"), (a2, True, "side view")):
        _draw_view(ax, view, series, side=side)
        ax.set_title(f"{sequence}: {title}")
    a1.legend(fontsize=8, loc="best")
    written += _save(fig, out_dir / f"traj_{_safe(sequence)}")

    fig, (ax,) = _figure(10, 4)
    for m, r in reps.items():
        t = r.association.gt.t_ns
        x = (t // 100_000_000) if gt.indexed else (t - gt.t_ns[0]) * 1e-9
        ax.plot(x, r.ate.trans_errors, lw=0.9, label=f"{m}: RMSE {r.ate.trans_rmse:.3g} m")
    ax.set_xlabel("frame" if gt.indexed else "time since GT start [s]")
    ax.set_ylabel("translation error [m]")
    ax.set_title(f"{sequence}: absolute translation error after alignment")
    ax.grid(True, alpha=0.3)
    if reps:
        ax.legend(fontsize=8)
    written += _save(fig, out_dir / f"ate_{_safe(sequence)}")

    methods = [m for m in dict.fromkeys(r.method for r in results)]
    te, re_, labels = [], [], []
    for m in methods:
        rs = [r for r in results if r.method == m and r.ok and r.rpe is not None]
        if rs:
            te.append(np.concatenate([r.rpe.trans_errors for r in rs]))
            re_.append(np.concatenate([r.rpe.rot_errors_deg for r in rs]))
            labels.append(m)
    fig, (b1, b2) = _figure(12, 4.5, ncols=2)
    if labels:
        b1.boxplot(te, tick_labels=labels, showfliers=False)
        b2.boxplot(re_, tick_labels=labels, showfliers=False)
        rpe = next(r.rpe for r in results if r.ok and r.rpe is not None)
        d = f"delta {rpe.delta:g} {rpe.unit}"
        b1.set_title(f"{sequence}: RPE translation ({d})")
        b2.set_title(f"{sequence}: RPE rotation ({d})")
    b1.set_ylabel("[m]")
    b2.set_ylabel("[deg]")
    for b in (b1, b2):
        b.grid(True, axis="y", alpha=0.3)
        b.tick_params(axis="x", labelrotation=20)
    written += _save(fig, out_dir / f"rpe_{_safe(sequence)}")
    return written


def plot_summary(out_dir: Path, table) -> list[Path]:
    """Grouped bar chart of one table (normally ATE translation RMSE)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    seqs, methods = table.sequences, table.methods
    fig, (ax,) = _figure(max(6.0, 1.2 * len(seqs) * max(1, len(methods)) * 0.5 + 3), 4.5)
    width = 0.8 / max(1, len(methods))
    x = np.arange(len(seqs))
    for k, m in enumerate(methods):
        mean = np.array([table.cell(s, m).stat("mean") for s in seqs])
        std = np.array([table.cell(s, m).stat("std") for s in seqs])
        bars = ax.bar(x + (k - (len(methods) - 1) / 2) * width, np.nan_to_num(mean), width,
                      yerr=np.nan_to_num(std), capsize=3, label=m)
        for b, v in zip(bars, mean):
            if np.isnan(v):
                ax.annotate("failed", (b.get_x() + b.get_width() / 2, 0), ha="center", va="bottom", fontsize=7,
                            rotation=90)
    ax.set_xticks(x, seqs)
    ax.set_ylabel(table.title.split(" — ")[0])
    ax.set_title(table.title, fontsize=9)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, out_dir / "summary_ate")


def plot_imu_states(csv_path: Path, png_path: Path) -> Path:
    """Roll/pitch/yaw (deg), gyro bias and sqrt(tr Sigma_imu) (`gevi imu`: the tilt std) over time from an ``imu_states.csv``
    (written by `gevi run --method gevi` and `gevi imu`; angles rad, bias rad/s)."""
    import pandas as pd

    s = pd.read_csv(csv_path)
    t = (s.t_ns.to_numpy(np.int64) - int(s.t_ns.iloc[0])) * 1e-9
    fig, ax = _figure(9.0, 7.0, nrows=3)
    for k in ("roll", "pitch", "yaw"):
        ax[0].plot(t, np.degrees(np.unwrap(s[k].to_numpy(float))), label=k, lw=0.9)
    ax[0].set_ylabel("deg")
    ax[0].legend(loc="upper right")
    for k in ("bgx", "bgy", "bgz"):
        ax[1].plot(t, s[k], label=k, lw=0.9)
    ax[1].set_ylabel("gyro bias [rad/s]")
    ax[1].legend(loc="upper right")
    if "tilt_std" in s.columns:  # `gevi imu`: the velocity-aided filter's posterior tilt std
        ax[2].semilogy(t, np.degrees(s.tilt_std.to_numpy(float)), lw=0.9)
        ax[2].set_ylabel("tilt std [deg]")
    else:
        ax[2].semilogy(t, np.degrees(np.sqrt(s.sigma_trace.to_numpy(float))), lw=0.9)
        ax[2].set_ylabel("sqrt tr Sigma_imu [deg]")
    ax[2].set_xlabel("time [s]")
    fig.savefig(png_path, dpi=100)
    return Path(png_path)
