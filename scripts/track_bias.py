#!/usr/bin/env python3
"""Systematic errors of the front end's tracks on a `gevi simulate` render, against the render's geometry.

    python scripts/track_bias.py RENDER [--keyframes 8] [--span 4] [--no-noise] [--derotate] [--set frontend.KEY=VALUE ...]

RENDER is a folder written by `gevi simulate` (EuRoC/pool layout; its ``simulation.yaml`` names the
preset, the seed and the options, so the very frames are re-rendered here, optionally without sensor
noise).  At ``--keyframes`` frames spread over the sequence a fresh front end (the configuration
`gevi run` would use, plus ``--set``) detects and stereo-matches as at a keyframe, then tracks the
next ``--span`` frames: without a rotation prior, or with ``--derotate`` given the true
frame-to-frame camera rotation as the prior of its rotation-compensated LK (the pipelines give it
the gyro's or the last step's rotation, so this is its best case).  The truth of a feature is its keyframe-left ray, cast to the scene's planes
with the true camera pose, and projected with the true poses into the right image and the following
frames (rectified pixels).

Printed, as mean +- standard error:

* the stereo disparity error (px), and the relative depth error it makes (-error / disparity);
* per frame after the keyframe, the RMS of the tracks' 2-D error (px; tracks within 2 px of the truth
  and more than 2 px of flow), the temporal track error along the true flow (px), and that error as
  a fraction of the flow length: a scale-like shortening or lengthening of the tracked motion, which
  a stereo odometry turns into a scale error of its translation.

Why: after the epipolar BA the euroc-like renders come out ~0.15 % long in scale and without it ~0.2 %
short (docs/method.md, "Simulated sequences"), while the BA itself is unbiased under Gaussian noise
(tests/estimators/test_epipolar_ba.py).  This script measures what the tracks contribute.
"""
from __future__ import annotations

import argparse
import os
import sys
import types
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402


def cast_to_scene(scene, T_WC: np.ndarray, d_C: np.ndarray) -> np.ndarray:
    """World points (n, 3) where the unit camera rays ``d_C`` (n, 3) first hit a plane of ``scene``
    (inf where none is hit)."""
    d_W = d_C @ T_WC[:3, :3].T
    c = T_WC[:3, 3]
    t_best = np.full(len(d_W), np.inf)
    for pl in scene.planes:
        n = pl.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (n @ (np.asarray(pl.origin) - c)) / (d_W @ n)
        P = c + t[:, None] * d_W
        u, v = (P - pl.origin) @ pl.axis_u, (P - pl.origin) @ pl.axis_v
        hit = (t > 1e-3) & (u >= 0) & (v >= 0) & (u <= pl.size_u) & (v <= pl.size_v)
        t_best = np.where(hit & (t < t_best), t, t_best)
    return c + t_best[:, None] * d_W


def _mean_se(x: np.ndarray) -> str:
    if len(x) == 0:
        return "-"
    return f"{x.mean():+.4f} +- {x.std() / np.sqrt(len(x)):.4f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("render", type=Path)
    ap.add_argument("--keyframes", type=int, default=8)
    ap.add_argument("--span", type=int, default=4)
    ap.add_argument("--no-noise", action="store_true", help="re-render without sensor noise")
    ap.add_argument("--derotate", action="store_true",
                    help="give the front end the true frame-to-frame rotation as its LK rotation prior")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--split-edges", type=float, default=0.02, metavar="REL",
                    help="also report the features whose LK window (its corners and edge midpoints) "
                         "spans depths differing by more than REL apart from the others")
    a = ap.parse_args(argv)

    from gevi_cli.datasets import open_sequence
    from gevi_cli.frontend.image_frontend import ImageFrontEnd
    from gevi_cli.run.session import RunRequest, resolve_config
    from gevi_cli.simulate.generate import SimulationConfig, build_sequence

    spec = a.render / "simulation.yaml"
    if not spec.is_file():
        print(f"track_bias: error: {spec}: not found (RENDER must be a folder written by `gevi simulate`)",
              file=sys.stderr)
        return 2
    try:
        meta = yaml.safe_load(spec.read_text())
        config = SimulationConfig.from_description(meta)
    except (yaml.YAMLError, ValueError) as err:
        print(f"track_bias: error: {spec}: {str(err).splitlines()[0]}", file=sys.stderr)
        return 2
    sim = build_sequence(replace(config, image_noise=config.image_noise and not a.no_noise))
    seq = open_sequence(a.render)
    kind = "pool" if meta.get("water") else "euroc"
    cfg, sources = resolve_config(RunRequest(sequence=str(a.render), sets=a.sets), kind)
    print(f"{meta['preset']} seed {meta['seed']}: config {', '.join(sources)}; noise {'off' if a.no_noise else 'as rendered'}; "
          f"rotation prior {'true rotation' if a.derotate else 'none'}")

    def T_WC(k: int) -> np.ndarray:
        return sim.body_state(sim.frame_t_ns[k:k + 1]).T_WB[0] @ sim.rig.T_B_C0

    def frame(k: int):
        left, right = sim.render_frame(int(k))
        return types.SimpleNamespace(left=left, right=right, t_ns=int(sim.frame_t_ns[k]), index=int(k))

    disp_err, disp_true = [], []
    along = {m: [] for m in range(1, a.span + 1)}
    err2 = {m: [] for m in range(1, a.span + 1)}
    frac = {m: [] for m in range(1, a.span + 1)}
    on_edge = {m: [] for m in range(1, a.span + 1)}
    for k0 in np.linspace(5, sim.frame_t_ns.size - a.span - 5, a.keyframes).astype(int):
        fe = ImageFrontEnd(seq.calibration, cfg.frontend)
        st = fe.keyframe(frame(k0))
        cam, rect = fe.camera, fe.rectifier
        xy = rect.rectified_to_raw_normalized(st.uv_left)
        d_C = np.column_stack([xy, np.ones(len(xy))])
        P_W = cast_to_scene(sim.scene, T_WC(k0), d_C / np.linalg.norm(d_C, axis=1)[:, None])

        def project(k):
            T = T_WC(k)
            Xr = ((P_W - T[:3, 3]) @ T[:3, :3]) @ rect.R0.T  # rectified left camera of frame k
            return Xr, cam.intrinsics.project(Xr)

        X0, uv0 = project(k0)
        # depth at the LK window's corners and edge midpoints: a window over an occlusion boundary
        # tracks a blend of two motions, not the motion of the surface under its centre
        h = cfg.frontend.lk_window // 2
        zc = []
        for du, dv in ((-h, -h), (0, -h), (h, -h), (-h, 0), (h, 0), (-h, h), (0, h), (h, h)):
            xy_n = rect.rectified_to_raw_normalized(st.uv_left + [du, dv])
            d_n = np.column_stack([xy_n, np.ones(len(xy_n))])
            Pn = cast_to_scene(sim.scene, T_WC(k0), d_n / np.linalg.norm(d_n, axis=1)[:, None])
            T0 = T_WC(k0)
            zc.append((((Pn - T0[:3, 3]) @ T0[:3, :3]) @ rect.R0.T)[:, 2])
        zc = np.array(zc)
        with np.errstate(invalid="ignore"):
            edge = ~np.all(np.abs(zc / X0[:, 2] - 1.0) <= a.split_edges, axis=0)
        ok = np.isfinite(X0[:, 2]) & (np.abs(uv0[:, 0] - st.uv_left[:, 0]) < 1e-3)
        d_t = cam.fx * cam.baseline / X0[ok, 2]
        disp_err.append((st.uv_left[ok, 0] - st.uv_right[ok, 0]) - d_t)
        disp_true.append(d_t)
        for m in range(1, a.span + 1):
            # R_cp of the rectified left camera: previous -> current coordinates
            R_cp = rect.R0 @ T_WC(k0 + m)[:3, :3].T @ T_WC(k0 + m - 1)[:3, :3] @ rect.R0.T
            obs = fe.track(frame(k0 + m), R_cp if a.derotate else None)
            _, uv = project(k0 + m)
            _, i0, i1 = np.intersect1d(st.ids, obs.ids, assume_unique=True, return_indices=True)
            e = obs.uv[i1] - uv[i0]
            flow = uv[i0] - st.uv_left[i0]
            fl = np.linalg.norm(flow, axis=1)
            good = np.isfinite(e).all(1) & (np.linalg.norm(e, axis=1) < 2.0) & (fl > 2.0)
            a_m = np.sum(e[good] * flow[good], axis=1) / fl[good]
            along[m].append(a_m)
            err2[m].append(np.sum(e[good] ** 2, axis=1))
            frac[m].append(a_m / fl[good])
            on_edge[m].append(edge[i0][good])

    e, d = np.concatenate(disp_err), np.concatenate(disp_true)
    inl = np.abs(e) < 1.0
    print(f"stereo: {inl.sum()} of {len(e)} matches within 1 px; disparity error {_mean_se(e[inl])} px "
          f"(median disparity {np.median(d):.1f} px); relative depth error {_mean_se(-e[inl] / d[inl] * 100)} %")
    print(f"| frames after the keyframe | tracks | RMS error, px | error along the true flow, px | as % of the flow length | "
          f"windows within {a.split_edges:.0%} in depth: tracks, % | the others: tracks, % |")
    print("|---|---|---|---|---|---|---|")
    for m in range(1, a.span + 1):
        x, f, g = np.concatenate(along[m]), np.concatenate(frac[m]), np.concatenate(on_edge[m])
        rms = float(np.sqrt(np.mean(np.concatenate(err2[m]))))
        print(f"| {m} | {len(x)} | {rms:.3f} | {_mean_se(x)} | {_mean_se(f * 100)} | {(~g).sum()}, {_mean_se(f[~g] * 100)} | "
              f"{g.sum()}, {_mean_se(f[g] * 100)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
