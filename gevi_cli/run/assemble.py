"""The front end and odometry objects of a run: built from the opened source, its kind, the checked
configuration and the method (``cfo`` or ``gevi``), with the input checks that need them (image size
against the calibration; GeVI's IMU stream and camera-IMU extrinsic), one-line errors for unusable input.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.errors import GeviError


def make_pipeline(r, warn=None):
    """(front end, odometry) of a resolved run (:class:`gevi_cli.run.session.Resolved`), after checking the
    images have the calibration's size."""
    if r.kind != "ov2slam-tracks":
        _check_image_size(r.source, r.start, r.req.sequence)
    return build(r.source, r.kind, r.cfg, r.req.method, warn=warn, start=r.start)


def pipeline_factory(r, warn=None, first=None):
    """A factory of (front end, odometry) for a run (``run_and_evaluate(pipeline=...)``): the first call gives
    ``first`` (a pair already built) or builds one with ``warn``; later calls, for a restart, build fresh ones
    quietly (their warnings were given once)."""
    pending = [first if first is not None else make_pipeline(r, warn=warn)]

    def factory():
        return pending.pop() if pending else make_pipeline(r, warn=lambda msg: None)
    return factory


def build(source, kind: str, cfg, method: str, warn=None, start: int = 0):
    """(front end, odometry) for ``source``."""
    from gevi_cli.pipelines.cfo import CurrentFeatureOdometry

    if kind == "ov2slam-tracks":
        from gevi_cli.frontend.export import ExportFrontEnd

        frontend = ExportFrontEnd(source, use_outlier_flags=cfg.verify.use_export_flags)
    else:
        from gevi_cli.frontend.image_frontend import ImageFrontEnd

        frontend = ImageFrontEnd(source.calibration, cfg.frontend)
    if method == "cfo":
        return frontend, CurrentFeatureOdometry(frontend, cfg)
    if method == "gevi":
        from gevi_cli.pipelines.gevi import GeviOdometry

        imu = _imu_stream(source, kind, cfg, warn, start)
        stamps = source.stamps_ns
        period = float(np.median(np.diff(stamps))) * 1e-9
        return frontend, GeviOdometry(frontend, cfg, imu, period)
    raise GeviError("--method", f"unknown method {method!r}")


def _check_image_size(source, start: int, sequence) -> None:
    """The first frame's images must have the calibration's size (else wrong intrinsics): one-line error."""
    from gevi_cli.errors import DataError

    try:
        frame = source.read_pair(start)
    except DataError:
        return  # an unreadable frame is skipped by the driver and reported there
    rig = source.calibration
    for name, img, cam in (("cam0", frame.left, rig.cam0), ("cam1", frame.right, rig.cam1)):
        h, w = np.asarray(img).shape[:2]
        if (w, h) != tuple(cam.resolution):
            where = source.calibration_file or sequence
            raise GeviError(where, f"{name} images are {w}x{h} but the calibration is for "
                                   f"{cam.resolution[0]}x{cam.resolution[1]}: wrong calibration for these images")


def _imu_stream(source, kind: str, cfg, warn, start: int):
    """The checked IMU of ``source`` for GeVI (one-line errors, exit 2, for unusable input)."""
    from gevi_cli.inertial.imu_stream import ImuStream

    name = source.path
    imu = source.imu
    if kind == "ov2slam-tracks" or imu is None or len(imu) < 2:
        raise GeviError(name, "has no IMU: GeVI is stereo-inertial; use --method cfo")
    R = np.asarray(source.calibration.T_B_C0, dtype=float)[:3, :3]
    if not (np.all(np.isfinite(R)) and np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0):
        raise GeviError(source.calibration_file or name,
                        f"camera-IMU extrinsic T_B_C0 is not a rotation (det {np.linalg.det(R):.6g}, "
                        f"|R R^T - I| = {np.abs(R @ R.T - np.eye(3)).max():.3g})")
    offset = cfg.imu.time_offset_s
    if offset is None:
        offset = float(source.imu_time_offset_s)
    stream = ImuStream.from_sequence(imu, offset, f"{name} (IMU)", warn, cfg.imu.max_gap_factor)
    t0 = int(source.stamps_ns[start])
    t_last = int(source.stamps_ns[-1])
    need = min(t0 + int(max(cfg.init.window_s, cfg.init.still_min_s) * 1e9), t_last)
    if not stream.covers(t0, need):
        have = (f"{stream.t_ns[0] * 1e-9:.3f}..{stream.t_ns[-1] * 1e-9:.3f} s" if len(stream.t_ns) else "none")
        raise GeviError(f"{name} (IMU)", f"no IMU over the initialisation window {t0 * 1e-9:.3f}..{need * 1e-9:.3f} s "
                                         f"(IMU covers {have}, or has a gap there)")
    return stream
