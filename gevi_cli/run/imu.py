"""`gevi imu`'s run: open the sequence, build the report (evaluation.imu_report), write and print it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gevi_cli.errors import GeviError


def run_imu_report(sequence, *, out, results_root, imu_time_offset, plots, kind, groundtruth, calib, imu_calib, topics,
                   cameras, imu_stride: int = 1, align: bool = True, align_rotation: bool = False, echo=print) -> Path:
    """`gevi imu`: ``align`` False (``--no-align``) scores on the ground truth as given; a BROAD trial's
    reference is aligned by its authors and is never re-aligned.  A reference the dataset states to be in
    the IMU frame gets a clock offset only, unless ``align_rotation`` (``--align-rotation``); the
    alignment always reads the full-rate gyro, whatever ``imu_stride``."""
    from gevi_cli.datasets import open_sequence
    from gevi_cli.datasets.registry import sequence_kwargs
    from gevi_cli.evaluation.imu_report import imu_report
    from gevi_cli.inertial.imu_stream import ImuStream
    from gevi_cli.run.folder import make_run_dir

    path = Path(sequence)
    if not path.exists():
        raise GeviError(path, "no such file or folder")
    from gevi_cli.datasets.bagfile import is_bag
    from gevi_cli.datasets.registry import detect_kind

    warn = lambda m: echo(f"gevi: warning: {m}", err=True)  # noqa: E731
    from gevi_cli.datasets.broad import is_broad_mat

    if kind is None and is_broad_mat(path):
        from gevi_cli.datasets.broad import BroadTrial

        seq = BroadTrial(path)
    elif kind is None and is_imu_only_euroc(path):
        from gevi_cli.datasets.euroc_imu import EurocImu

        seq = EurocImu(path, groundtruth=groundtruth)
    elif (kind or detect_kind(path)) == "rosbag" and is_bag(path):
        # a bag's IMU needs neither images nor a camera calibration (IMU-only bags are reports too)
        from gevi_cli.datasets.bag_imu import BagImu

        seq = BagImu(path, topics=topics, imu_calib=imu_calib, groundtruth=groundtruth)
        for message in seq.warnings:
            warn(message)
    else:
        seq = open_sequence(path, kind=kind, **sequence_kwargs(groundtruth, calib, topics, cameras, imu_calib))
    imu = seq.imu
    if imu is None or len(imu) < 2:
        raise GeviError(path, "has no IMU data" if imu is None else "has fewer than 2 IMU samples")
    offset = imu_time_offset if imu_time_offset is not None else float(seq.imu_time_offset_s)
    full = ImuStream.from_sequence(imu, offset, f"{path} (IMU)") if imu_stride > 1 else None
    if imu_stride > 1:
        imu = strided_imu(imu, imu_stride)
    stream = ImuStream.from_sequence(imu, offset, f"{path} (IMU)")  # the report says which noise model it used
    gt = seq.groundtruth
    if gt is not None and gt.frame not in ("body", "unknown"):
        warn(f"ground truth is in the {gt.frame} frame, not the body (IMU) frame: roll/pitch not compared")
        gt = None
    scored = getattr(seq, "scored_t_ns", None)  # BROAD: the movement samples
    if scored is not None and imu_stride > 1:
        scored = scored[np.isin(scored, stream.t_ns)]
    in_imu = "" if align_rotation else getattr(seq, "reference_in_imu_frame", "")
    rep = imu_report(stream, gt, align=align and not getattr(seq, "reference_aligned", False), scored_t_ns=scored,
                     align_gyro=(full.t_ns, full.gyro) if full is not None else None, in_imu_frame=in_imu)
    if stream.noise_missing:
        warn(f"{path} (IMU): {rep.noise_note}")
    run_dir = make_run_dir(out, Path(results_root), "imu", seq.name + (f"_stride{imu_stride}" if imu_stride > 1 else ""))
    _write(run_dir, stream, rep, plots)
    for line in summary_lines(rep, stream):
        echo(line)
    echo(f"wrote {run_dir}")
    return run_dir


def is_imu_only_euroc(path: Path) -> bool:
    """An EuRoC-layout folder with ``mav0/imu0/data.csv`` and no camera folders (``gevi simulate mav``)."""
    from gevi_cli.datasets.euroc import find_mav0

    return path.is_dir() and find_mav0(path) is None and any(
        (c / "imu0" / "data.csv").is_file() for c in (path / "mav0", path))


def strided_imu(imu, k: int):
    """Every ``k``-th sample of ``imu`` (an ImuData), noise model kept: a k-times slower IMU."""
    from dataclasses import replace

    return replace(imu, t_ns=imu.t_ns[::k], gyro=imu.gyro[::k], acc=imu.acc[::k])


def summary_lines(rep, stream) -> list[str]:
    lines = [f"IMU: {rep.n} samples, {rep.duration_s:.1f} s at {rep.rate_hz:.1f} Hz, "
             f"{len(rep.gaps)} gap(s)" + (f" (longest {max(g[1] for g in rep.gaps):.3f} s at "
                                          f"{max(rep.gaps, key=lambda g: g[1])[0]:.2f} s)" if rep.gaps else "")]
    if rep.standstills:
        shown = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in rep.standstills[:6])
        lines.append(f"standstill (IMU at rest, s): {shown}" + (" ..." if len(rep.standstills) > 6 else ""))
    else:
        lines.append("standstill: none found")
    if rep.start is not None:
        s = rep.start
        lines.append(f"starting standstill {s.duration_s:.2f} s: gyro bias [{s.b_g[0]:+.5f} {s.b_g[1]:+.5f} "
                     f"{s.b_g[2]:+.5f}] rad/s, roll {np.degrees(s.roll):+.3f} deg, pitch {np.degrees(s.pitch):+.3f} deg, "
                     f"mean |a| {s.acc_norm:.4f} m/s^2")
    if rep.noise_measured:
        m, st = rep.noise_measured, rep.noise_stated

        def against(key):
            return "none stated" if st.get(key) is None else f"stated {st[key]:.3g}, x{m[key] / st[key]:.1f}"

        lines.append(f"white noise at rest ({m['over_s']:.1f} s): gyro {m['gyro_noise_density']:.3g} rad/s/sqrt(Hz) "
                     f"({against('gyro_noise_density')}), acc {m['acc_noise_density']:.3g} m/s^2/sqrt(Hz) "
                     f"({against('acc_noise_density')})"
                     + ("; above the stated noise = vibration" if any(v is not None for v in st.values()) else ""))
    if rep.noise_note:
        lines.append(rep.noise_note)
    for f in rep.flags:
        lines.append(f"flag: {f}")
    if rep.comparison:
        lines.append("")
        lines.append(rep.reference_note)
        lines.append("| roll/pitch against ground truth | tilt RMSE [deg] | roll, pitch RMSE [deg] | tilt trend [deg/min] "
                     "| note |")
        lines.append("|---|---|---|---|---|")
        lines += [f"| {n} | {v[0]:.3f} | {v[1]:.3f} | {v[2]:+.3f} | {note} |" for n, v, note in rep.comparison]
        lines.append("(tilt = angle between estimated and true gravity direction in the body frame, BROAD's "
                     "inclination error; roll, pitch = RMS of both Euler-angle differences, amplified near pitch "
                     "+-90 deg; trend = least-squares slope of the tilt RMSE over 5 s windows; the reference "
                     "interpolated at each row's stamps, IMU sample k = the rate over (t_k-1, t_k]; causal: uses "
                     "no later sample; offline: the whole recording; oracle: chosen on the ground truth)")
        from gevi_cli.inertial.vqf_rows import default_params

        p = default_params()
        lines.append("(VQF parameters, the package's defaults: " + ", ".join(
            f"{k} {p[k]}" for k in ("tauAcc", "motionBiasEstEnabled", "restBiasEstEnabled", "biasSigmaInit",
                                    "biasForgettingTime", "biasClip", "biasSigmaMotion", "biasVerticalForgettingFactor",
                                    "biasSigmaRest", "restMinT", "restFilterTau", "restThGyr", "restThAcc") if k in p)
                     + "; tau in s, bias sigmas and clip in deg/s)")
    return lines


def _write(run_dir: Path, stream, rep, plots: bool) -> None:
    from gevi_cli import estimators as est
    from gevi_cli.trajectory import Trajectory, write_trajectory

    att = rep.attitude
    roll, pitch = est.tilt_angles(att.R_WI)
    yaw = np.arctan2(att.R_WI[:, 1, 0], att.R_WI[:, 0, 0])
    g = att.R_WI[:, 2, :]  # R^T e3 per row: gravity in the body frame
    proj = np.eye(3) - g[:, :, None] * g[:, None, :]
    tilt_std = np.sqrt(np.maximum(np.einsum("nij,njk,nki->n", proj, att.Sigma, proj), 0.0))
    sc = att.scale if att.scale is not None else np.zeros_like(att.b_g)
    with open(run_dir / "imu_states.csv", "w") as f:
        # rad, rad/s, dimensionless scale-factor errors, rad (posterior std of the tilt)
        f.write("t_ns,roll,pitch,yaw,bgx,bgy,bgz,sgx,sgy,sgz,tilt_std\n")
        for k in range(len(att.t_ns)):
            f.write(f"{att.t_ns[k]},{roll[k]:.9g},{pitch[k]:.9g},{yaw[k]:.9g},{att.b_g[k, 0]:.9g},{att.b_g[k, 1]:.9g},"
                    f"{att.b_g[k, 2]:.9g},{sc[k, 0]:.9g},{sc[k, 1]:.9g},{sc[k, 2]:.9g},{tilt_std[k]:.9g}\n")
    # attitude.tum: standstill-compensated VQF online (causal), the causal row with the lowest mean tilt error over
    # the real flight, BROAD and euroc_micro (docs/studies/imu_attitude.md); attitude_offline.tum: its offline form
    # (the whole recording).  One stamp convention, the report's: the row stamped t_k has integrated IMU sample k,
    # the rate over (t_k-1, t_k] (VQF's and BROAD's); the velocity-aided filter stays in imu_states.csv, its own stamps
    for name, R in (("attitude.tum", rep.attitude_causal), ("attitude_offline.tum", rep.attitude_offline)):
        if R is not None:
            write_trajectory(Trajectory.from_rotations(stream.t_ns, R, np.zeros((len(stream.t_ns), 3)), frame="body"),
                             run_dir / name, "tum")
    (run_dir / "report.md").write_text("# gevi imu\n\n" + "\n".join(summary_lines(rep, stream)) + "\n")
    if plots:
        from gevi_cli.evaluation.plots import plot_imu_states

        plot_imu_states(run_dir / "imu_states.csv", run_dir / "imu_states.png")
