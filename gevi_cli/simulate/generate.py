"""Assemble a simulated sequence (rig, trajectory, IMU, mocap, scene) and render its frames.

Time: stamps are int64 nanoseconds, ``t0_ns`` + offsets; the motion's time 0 is ``t0_ns``.  Frame k
is at ``t0_ns + round(k * 1e9 / rate_hz)``; IMU/ground-truth samples at ``t0_ns + k * 1e9 / imu_rate``
cover every frame.  Random draws use separate generators seeded with ``[seed, tag, ...]`` so that
renders are reproducible in any order (and with any number of worker threads).
"""
from __future__ import annotations

import collections
import concurrent.futures
import os
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from typing import Iterator

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.geometry import make_T
from gevi_cli.simulate.constants import MOCAP_NOISE_POS_M, MOCAP_NOISE_ROT_DEG, MOCAP_RATE_HZ
from gevi_cli.simulate.imu import ImuParams, ImuSeries, synthesize_imu
from gevi_cli.simulate.motion import MotionSample
from gevi_cli.simulate.presets import (
    PRESETS,
    PresetSpec,
    build_motion,
    build_rig,
    mocap_marker_extrinsic,
)
from gevi_cli.simulate.render import CameraRenderer, SensorModel
from gevi_cli.simulate.scenes import build_scene

#: stamp of the first sample (2023-11-14 22:13:20 UTC), an EuRoC-like epoch time in ns
T0_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class SimulationConfig:
    """User options; ``None`` means the preset's default.

    Attributes:
        preset: one of :data:`~gevi_cli.simulate.presets.PRESETS`.
        seed: seeds textures, trajectory, IMU noise, image noise and mocap noise.
        duration_s, rate_hz: sequence length [s] and camera rate [Hz].
        resolution: (width, height) [px]; intrinsics are scaled to keep the field of view.
        baseline_m: stereo baseline [m].
        distortion: render with the preset's radtan distortion (False for KITTI output).
        image_noise: add shot/read noise to the images.
        imu: IMU rate and noise model.
        supersample: sub-samples per pixel and axis.
        a_max: peak acceleration of hovering presets [m/s^2] (None: the preset's).
        moving_start: hovering presets start in full motion (no still start, no ramp).
        disparity_shift_px: the right image is rendered moved right by this many pixels (its principal
            point shifted) while the written calibration keeps the true one, so every measured disparity
            reads this much short: a rectified pair with a known disparity offset.
    """

    preset: str
    seed: int = 0
    duration_s: float | None = None
    rate_hz: float | None = None
    resolution: tuple[int, int] | None = None
    baseline_m: float | None = None
    distortion: bool = True
    image_noise: bool = True
    imu: ImuParams | None = None
    supersample: int = 2
    a_max: float | None = None
    moving_start: bool = False
    disparity_shift_px: float = 0.0

    @property
    def spec(self) -> PresetSpec:
        return PRESETS[self.preset]

    @classmethod
    def from_description(cls, desc: dict) -> "SimulationConfig":
        """The config of a render from its ``simulation.yaml`` (:meth:`SimulatedSequence.description`):
        ``build_sequence`` of it gives the same trajectory, scene and IMU again.  ValueError (one line)
        when ``desc`` is not such a description."""
        try:
            o = desc["options"]
            return cls(desc["preset"], seed=int(desc["seed"]), duration_s=float(o["duration_s"]),
                       rate_hz=float(o["rate_hz"]), resolution=tuple(int(v) for v in o["resolution"]),
                       baseline_m=float(o["baseline_m"]), distortion=bool(o["distortion"]),
                       image_noise=bool(o["image_noise"]), imu=ImuParams(**desc["imu"]),
                       supersample=int(o["supersample"]),
                       a_max=float(o["a_max"]) if "a_max" in o else None,
                       moving_start=bool(o.get("moving_start", False)),
                       disparity_shift_px=float(o.get("disparity_shift_px", 0.0)))
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"not a gevi simulate description ({type(err).__name__}: {err})") from None

    def resolved(self) -> "SimulationConfig":
        """A copy with every ``None`` replaced by the preset default."""
        s = self.spec
        return replace(self, duration_s=float(self.duration_s if self.duration_s is not None else s.duration_s),
                       rate_hz=float(self.rate_hz if self.rate_hz is not None else s.rate_hz),
                       resolution=tuple(self.resolution or (s.camera.width, s.camera.height)),
                       baseline_m=float(self.baseline_m if self.baseline_m is not None else s.baseline_m),
                       imu=self.imu or s.imu)


@dataclass
class SimulatedSequence:
    """Everything the writers need.  Frames are rendered lazily by :meth:`frames`."""

    config: SimulationConfig
    rig: StereoRig
    motion: object = field(repr=False)
    scene_builder: object = field(repr=False)
    t0_ns: int = T0_NS

    @property
    def spec(self) -> PresetSpec:
        return self.config.spec

    @property
    def sensor(self) -> SensorModel:
        return replace(self.spec.sensor, noise=self.config.image_noise)

    # --------------------------------------------------------------------------------- stamps
    @cached_property
    def frame_t_ns(self) -> np.ndarray:
        c = self.config
        n = max(1, int(np.floor(c.duration_s * c.rate_hz + 1e-9)))
        return self.t0_ns + np.rint(np.arange(n) * (1e9 / c.rate_hz)).astype(np.int64)

    @cached_property
    def imu_t_ns(self) -> np.ndarray:
        c = self.config
        period = int(round(1e9 / c.imu.rate_hz))
        n = int(np.ceil((self.frame_t_ns[-1] - self.t0_ns) / period)) + 1
        n = max(n, int(np.floor(c.duration_s * c.imu.rate_hz + 1e-9)) + 1)
        return self.t0_ns + np.arange(n, dtype=np.int64) * period

    def seconds(self, t_ns) -> np.ndarray:
        return (np.asarray(t_ns, np.int64) - self.t0_ns).astype(np.float64) * 1e-9

    # ---------------------------------------------------------------------------- trajectories
    def body_state(self, t_ns) -> MotionSample:
        """Exact body (= IMU) state at ``t_ns``."""
        return self.motion(self.seconds(t_ns))

    @cached_property
    def groundtruth(self) -> MotionSample:
        """Body state at every IMU stamp."""
        return self.body_state(self.imu_t_ns)

    @cached_property
    def imu(self) -> ImuSeries:
        rng = np.random.default_rng([self.config.seed, 3001])
        return synthesize_imu(self.motion, self.imu_t_ns, self.t0_ns, self.config.imu, rng)

    def camera_poses(self, t_ns, cam: int = 0) -> np.ndarray:
        """(n, 4, 4) ``T_W_C`` of camera ``cam`` at ``t_ns``."""
        T_B_C = self.rig.T_B_C0 if cam == 0 else self.rig.T_B_C1
        return self.body_state(t_ns).T_WB @ T_B_C

    @cached_property
    def T_B_M(self) -> np.ndarray:
        return mocap_marker_extrinsic()

    @cached_property
    def mocap(self) -> tuple[np.ndarray, np.ndarray]:
        """(t_ns, T_W_M) of the mocap marker body at 100 Hz with small pose noise."""
        from scipy.spatial.transform import Rotation

        period = int(round(1e9 / MOCAP_RATE_HZ))
        t_ns = np.arange(self.t0_ns, self.imu_t_ns[-1] + 1, period, dtype=np.int64)
        T = self.body_state(t_ns).T_WB @ self.T_B_M
        rng = np.random.default_rng([self.config.seed, 4001])
        dR = Rotation.from_rotvec(rng.normal(0, np.radians(MOCAP_NOISE_ROT_DEG), (len(t_ns), 3))).as_matrix()
        T[:, :3, :3] = T[:, :3, :3] @ dR
        T[:, :3, 3] += rng.normal(0, MOCAP_NOISE_POS_M, (len(t_ns), 3))
        return t_ns, T

    # -------------------------------------------------------------------------------- images
    @cached_property
    def scene(self):
        return self.scene_builder()

    @cached_property
    def renderers(self) -> tuple[CameraRenderer, CameraRenderer]:
        cam1 = self.rig.cam1
        if self.config.disparity_shift_px:
            cam1 = replace(cam1, cx=cam1.cx + self.config.disparity_shift_px)
        r0 = CameraRenderer(self.rig.cam0, self.config.supersample)
        r1 = r0 if cam1 == self.rig.cam0 else CameraRenderer(cam1, self.config.supersample)
        return r0, r1

    def render_frame(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Left and right uint8 images of frame ``k``."""
        t = self.frame_t_ns[k: k + 1]
        T_WB = self.body_state(t).T_WB[0]
        out = []
        for cam, (renderer, T_B_C) in enumerate(zip(self.renderers, (self.rig.T_B_C0, self.rig.T_B_C1))):
            rng = np.random.default_rng([self.config.seed, 5001, k, cam]) if self.config.image_noise else None
            out.append(renderer.render(self.scene, T_WB @ T_B_C, self.sensor, rng))
        return out[0], out[1]

    def frames(self, progress: bool = True, workers: int | None = None) -> Iterator[tuple[int, int, np.ndarray, np.ndarray]]:
        """Yield ``(k, t_ns, left, right)`` in order.

        With ``workers > 1`` frames are rendered in forked worker processes (the scene's textures are
        shared copy-on-write); the per-image random generators make the output independent of it.
        """
        import multiprocessing

        import cv2
        from tqdm import tqdm

        n = len(self.frame_t_ns)
        if workers is None:
            workers = min(2, os.cpu_count() or 1)
        if "fork" not in multiprocessing.get_all_start_methods():
            workers = 1
        workers = max(1, min(int(workers), n))
        _ = self.scene, self.renderers  # build before forking
        # OpenCV's own threads only add overhead on these small remaps; parallelism is per frame
        cv2_threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        bar = tqdm(total=n, desc=f"rendering {self.config.preset}", unit="frame", disable=not progress,
                   dynamic_ncols=True, leave=False)
        try:
            if workers == 1:
                for k in range(n):
                    left, right = self.render_frame(k)
                    bar.update(1)
                    yield k, int(self.frame_t_ns[k]), left, right
                return
            global _FORKED_SEQUENCE
            _FORKED_SEQUENCE = self
            ctx = multiprocessing.get_context("fork")
            with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
                pending: collections.deque = collections.deque()
                nxt = 0
                for k in range(n):
                    while nxt < n and len(pending) < 3 * workers:
                        pending.append(pool.submit(_render_forked, nxt))
                        nxt += 1
                    left, right = pending.popleft().result()
                    bar.update(1)
                    yield k, int(self.frame_t_ns[k]), left, right
        finally:
            _FORKED_SEQUENCE = None
            cv2.setNumThreads(cv2_threads)
            bar.close()

    # ---------------------------------------------------------------------------- description
    def description(self, fmt: str) -> dict:
        """Everything needed to reproduce the sequence (written as ``simulation.yaml``)."""
        from gevi_cli import __version__

        c = self.config

        def cam_dict(cam: Intrinsics):
            return {"resolution": [cam.width, cam.height], "intrinsics": [cam.fx, cam.fy, cam.cx, cam.cy],
                    "distortion_model": "radial-tangential", "distortion_coefficients": list(cam.distortion)}

        imu = asdict(c.imu)
        return {
            "generator": f"gevi {__version__} simulate",
            "preset": c.preset,
            "description": self.spec.description,
            "seed": int(c.seed),
            "format": fmt,
            "options": {
                "duration_s": c.duration_s, "rate_hz": c.rate_hz, "resolution": list(c.resolution),
                "baseline_m": c.baseline_m, "distortion": bool(c.distortion), "image_noise": bool(c.image_noise),
                "supersample": int(c.supersample),
                # only when set, so that default renders keep their exact simulation.yaml
                **({"a_max": float(c.a_max)} if c.a_max is not None else {}),
                **({"moving_start": True} if c.moving_start else {}),
                **({"disparity_shift_px": float(c.disparity_shift_px)} if c.disparity_shift_px else {}),
            },
            "imu": imu,
            "sensor": asdict(self.sensor),
            "water": asdict(self.spec.water) if self.spec.water else None,
            "frames": int(len(self.frame_t_ns)),
            "t0_ns": int(self.t0_ns),
            "gravity_W": [0.0, 0.0, -9.81],
            "frames_convention": "world z up; body = IMU frame; camera x right, y down, z forward; "
                                 "T_B_C maps camera coordinates into the body frame",
            "cam0": {**cam_dict(self.rig.cam0), "T_B_C": self.rig.T_B_C0.tolist()},
            "cam1": {**cam_dict(self.rig.cam1), "T_B_C": self.rig.T_B_C1.tolist()},
            "baseline_m": self.rig.baseline,
            "mocap": {"rate_hz": MOCAP_RATE_HZ, "T_B_M": self.T_B_M.tolist(), "noise_pos_m": MOCAP_NOISE_POS_M,
                      "noise_rot_deg": MOCAP_NOISE_ROT_DEG} if self.spec.mocap else None,
        }


_FORKED_SEQUENCE: SimulatedSequence | None = None


def _render_forked(k: int):
    """Worker-process entry point: render frame ``k`` of the sequence inherited through fork."""
    return _FORKED_SEQUENCE.render_frame(k)


def build_sequence(config: SimulationConfig) -> SimulatedSequence:
    """Resolve defaults and build the rig, the trajectory and a lazy scene for ``config``."""
    c = config.resolved()
    spec = c.spec
    cam = spec.camera
    if tuple(c.resolution) != (cam.width, cam.height):
        cam = cam.scaled(*c.resolution)
    if not c.distortion:
        cam = replace(cam, distortion=(0.0, 0.0, 0.0, 0.0))
    rig = build_rig(spec, cam, c.baseline_m)
    motion = build_motion(spec, c.seed, c.duration_s, a_max=c.a_max, moving_start=c.moving_start)
    return SimulatedSequence(c, rig, motion, lambda: build_scene(spec, c.seed, motion, c.duration_s))


__all__ = ["SimulationConfig", "SimulatedSequence", "build_sequence", "T0_NS", "make_T"]


def simulate(config: SimulationConfig, out_dir, fmt: str = "euroc", *, overwrite: bool = False, name: str | None = None,
             progress: bool = True, workers: int | None = None):
    """Render ``config`` into ``out_dir`` in layout ``fmt`` ("euroc", "kitti" or "bag").

    The output is written into a temporary sibling folder and renamed into place when complete.
    ``overwrite`` replaces an existing ``out_dir`` only if it is a previous ``gevi simulate`` output
    (it holds ``simulation.yaml``).  Returns the output folder (or, for "bag", the bag file).
    For "kitti" the returned path is ``out_dir/sequences/00``.
    Raises :class:`gevi_cli.errors.GeviError` for unusable output folders.
    """
    from pathlib import Path

    from gevi_cli.simulate.writers import get_writer

    out = output_folder(out_dir, overwrite)
    if fmt == "kitti" and config.distortion:
        config = replace(config, distortion=False)  # KITTI images are rectified and undistorted
    seq = build_sequence(config)
    writer = get_writer(fmt)
    kwargs = {"name": name} if fmt == "bag" else {}
    result, tmp = into_place(out, lambda folder: writer(seq, folder, progress=progress, workers=workers, **kwargs))
    if fmt == "kitti":
        return out / "sequences" / "00"  # the folder a KITTI reader opens
    return out / Path(result).relative_to(tmp) if Path(result) != tmp else out


def output_folder(out_dir, overwrite: bool):
    """``out_dir`` as a Path once it may be written: absent or empty, or with ``overwrite`` a previous
    ``gevi simulate`` output (it holds ``simulation.yaml``); else a one-line GeviError."""
    from pathlib import Path

    from gevi_cli.errors import GeviError

    out = Path(out_dir)
    if out.exists():
        if not out.is_dir():
            raise GeviError(out, "exists and is not a folder; choose another output folder")
        if any(out.iterdir()):
            if not overwrite:
                raise GeviError(out, "exists and is not empty; pass --overwrite to replace it")
            if not (out / "simulation.yaml").is_file():
                raise GeviError(out, "is not a `gevi simulate` output (no simulation.yaml); refusing to delete it "
                                     "with --overwrite, remove it yourself or choose another folder")
    return out


def into_place(out, write):
    """``write(folder)`` into a temporary sibling of ``out``, renamed into place when it returns (an
    interrupted render leaves no half-written ``out``).  Returns (what ``write`` returned, the
    temporary folder's name, for paths inside it)."""
    import shutil
    import tempfile
    from pathlib import Path

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp creates 0700
    try:
        result = write(tmp)
        if out.exists():
            shutil.rmtree(out)
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return result, tmp
