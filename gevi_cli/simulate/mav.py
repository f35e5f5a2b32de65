"""`gevi simulate mav`: an IMU-only high-dynamics regime (aggressive multirotor flight) with exact ground truth.

What it models, and why (the regime where a gravity-from-accelerometer attitude filter is hardest):

* **Flight.** A still start (rotors idling), a ramp into flight, flight, a ramp down and a still end.
  Position: sums of sinusoids per axis (periods 2-12 s) scaled to a peak |a_W| of ``a_max``.  The body
  z axis follows the thrust direction ``a_W + g e3`` (a multirotor tilts to accelerate: that tilt is
  invisible in the direction of the specific force, which then reads "level"), then turns by body-frame
  roll/pitch excursions (banked turns, flips; their amplitude ``tilt_deg``) and yaw.  Tilts pass 60 deg.
* **Rotor vibration.** Band-limited noise (``vib_band_hz``, the rotors' frequencies) added to gyro and
  accelerometer, generated on a fine 2 kHz grid and point-sampled at the IMU stamps (a raw MEMS IMU:
  it aliases into the IMU's band), its RMS ``vib_*`` in flight and ``idle`` times that at rest.  The
  same seed gives the same flight and vibration at any IMU rate; only the white noise is per sample.
* **IMU.** The white noise and bias random walks of :func:`~gevi_cli.simulate.imu.synthesize_imu`
  (its ``ImuParams``; what ``imu0/sensor.yaml`` states, vibration not included, as on a datasheet),
  and what a MEMS gyro on a flying MAV adds: a per-axis scale-factor error (``gyro_scale``, std) and a
  bias that shifts once the rotors spin up (``gyro_bias_flight``, std per axis, faded in with the
  flight: vibration rectification and warm-up), so the standstill bias is off in flight and plain
  gyro integration drifts by degrees per minute, as it does on real MAVs.

Frames as everywhere in the simulator: world z up, body = IMU frame; SI units, stamps in ns.
``omega_B`` is the central difference ``Log(R(t-h)^T R(t+h)) / 2h`` (h = 1e-4 s: an error ~1e-8 rad/s).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from gevi_cli.geometry import rot_x, rot_y, rot_z
from gevi_cli.simulate.imu import GRAVITY, ImuParams, ImuSeries, synthesize_imu
from gevi_cli.simulate.motion import MotionSample, Sines, Smoothstep

VIB_RATE_HZ = 2000.0  # the fine grid of the vibration signal
_H = 1e-4  # central-difference step for omega (s)


@dataclass(frozen=True)
class MavParams:
    """The regime's knobs (SI units; angles in deg).

    Attributes:
        duration_s: sequence length; still_start_s / still_end_s: at rest (rotors idling) at both ends;
        ramp_s: into and out of flight.
        a_max: peak |a_W| in flight [m/s^2]; tilt_deg: amplitude of the roll/pitch excursions beyond
        the thrust tilt; yaw_deg: yaw amplitude.
        vib_gyro / vib_acc: per-axis RMS of the rotor vibration in flight [rad/s, m/s^2] (the
        accelerometer's z axis, along the thrust, twice ``vib_acc``); idle: its fraction at rest;
        vib_band_hz: its frequency band.
        gyro_scale: std of the per-axis gyro scale-factor error; gyro_bias_flight: std per axis of the
        gyro-bias shift in flight [rad/s].
    """

    duration_s: float = 60.0
    still_start_s: float = 8.0
    still_end_s: float = 5.0
    ramp_s: float = 2.0
    a_max: float = 6.0
    tilt_deg: float = 40.0
    yaw_deg: float = 120.0
    vib_gyro: float = 0.05
    vib_acc: float = 0.6
    idle: float = 0.25
    vib_band_hz: tuple[float, float] = (70.0, 180.0)
    gyro_scale: float = 0.01
    gyro_bias_flight: float = 0.005


def _align_e3(z):
    """(n, 3, 3) the smallest rotation taking e3 to the unit vectors ``z`` (n, 3) (z_3 > -1)."""
    x, y, c = z[:, 0], z[:, 1], z[:, 2]
    k = 1.0 / (1.0 + c)
    R = np.empty((len(z), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = 1 - k * x * x, -k * x * y, x
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = -k * x * y, 1 - k * y * y, y
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -x, -y, c
    return R


def _log_so3(R):
    """(n, 3) rotation vectors of (n, 3, 3) rotations (angles well below pi)."""
    c = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1)
    k = np.where(th < 1e-8, 0.5, th / (2.0 * np.sin(np.maximum(th, 1e-8))))
    return v * k[:, None]


@dataclass(frozen=True)
class MavMotion:
    """The flight: ``pos`` (x, y, z offsets, m), ``tilt`` (roll, pitch excursions, rad), ``yaw`` (rad);
    each a :class:`Sines`, faded in and out by ``on`` (start ramp) and ``off`` (end ramp, 1 - it)."""

    pos: tuple[Sines, Sines, Sines]
    tilt: tuple[Sines, Sines]
    yaw: Sines
    on: Smoothstep
    off: Smoothstep
    p0: tuple[float, float, float] = (0.0, 0.0, 1.5)

    def flying(self, t):
        """Flight envelope in [0, 1] with its first and second derivatives."""
        a, a1, a2 = self.on(t)
        b, b1, b2 = self.off(t)
        return a * (1 - b), a1 * (1 - b) - a * b1, a2 * (1 - b) - 2 * a1 * b1 - a * b2

    def _faded(self, F: Sines, t):
        s, s1, s2 = self.flying(t)
        f, f1, f2 = F(t)
        f0 = F(np.zeros(1))[0][0]
        f = f - f0
        return s * f, s1 * f + s * f1, s2 * f + 2 * s1 * f1 + s * f2

    def attitude(self, t, a_W):
        z = a_W + np.array([0.0, 0.0, GRAVITY])
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        roll, pitch, yaw = (self._faded(F, t)[0] for F in (*self.tilt, self.yaw))
        return _align_e3(z) @ rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)

    def _accel(self, t):
        P = [self._faded(F, t) for F in self.pos]
        return (np.stack([P[i][0] for i in range(3)], -1) + np.asarray(self.p0),
                np.stack([P[i][1] for i in range(3)], -1), np.stack([P[i][2] for i in range(3)], -1))

    def __call__(self, t) -> MotionSample:
        t = np.atleast_1d(np.asarray(t, float))
        p, v, a = self._accel(t)
        R = self.attitude(t, a)
        Rm = self.attitude(t - _H, self._accel(t - _H)[2])
        Rp = self.attitude(t + _H, self._accel(t + _H)[2])
        omega = _log_so3(np.einsum("nji,njk->nik", Rm, Rp)) / (2 * _H)
        return MotionSample(t, p, v, a, R, omega)


def build_mav_motion(params: MavParams, seed: int) -> MavMotion:
    """The flight of ``seed``: periods 2-12 s (position), 3-8 s (tilt), 6-20 s (yaw), scaled to ``a_max``."""
    rng = np.random.default_rng([int(seed), 7001])
    pos = [Sines.random(rng, 1.0, (2.0, 12.0), 3) for _ in range(3)]
    tilt = [Sines.random(rng, np.radians(params.tilt_deg), (3.0, 8.0), 2) for _ in range(2)]
    yaw = Sines.random(rng, np.radians(params.yaw_deg), (6.0, 20.0), 2)
    t_on = params.still_start_s
    t_off = params.duration_s - params.still_end_s - params.ramp_s
    m = MavMotion(tuple(pos), tuple(tilt), yaw, Smoothstep(t_on, t_on + params.ramp_s),
                  Smoothstep(t_off, t_off + params.ramp_s))
    t = np.arange(0.0, params.duration_s, 0.01)
    k = params.a_max / max(float(np.linalg.norm(m._accel(t)[2], axis=1).max()), 1e-9)
    return replace(m, pos=tuple(F.scaled(k) for F in m.pos))


def band_noise(rng: np.random.Generator, n: int, rate_hz: float, band_hz: tuple[float, float]) -> np.ndarray:
    """(n, 3) Gaussian noise with a flat spectrum in ``band_hz`` and none outside, unit RMS per axis."""
    x = rng.normal(0.0, 1.0, (n, 3))
    X = np.fft.rfft(x, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    X[(f < band_hz[0]) | (f > band_hz[1])] = 0.0
    y = np.fft.irfft(X, n, axis=0)
    return y / np.sqrt(np.mean(y * y, axis=0))


def mav_imu(params: MavParams, imu: ImuParams, seed: int, t0_ns: int) -> tuple[ImuSeries, MotionSample]:
    """IMU samples (with rotor vibration) and the exact body state at the IMU stamps."""
    motion = build_mav_motion(params, seed)
    period = int(round(1e9 / imu.rate_hz))
    n = int(np.floor(params.duration_s * 1e9 / period + 1e-9)) + 1
    t_ns = t0_ns + np.arange(n, dtype=np.int64) * period
    series = synthesize_imu(motion, t_ns, t0_ns, imu, np.random.default_rng([int(seed), 3001]))
    # the vibration on its fine grid, the same at every IMU rate, point-sampled at the stamps
    n_fine = int(np.ceil(params.duration_s * VIB_RATE_HZ)) + 2
    rng = np.random.default_rng([int(seed), 7002])
    vib_g = band_noise(rng, n_fine, VIB_RATE_HZ, params.vib_band_hz) * params.vib_gyro
    vib_a = band_noise(rng, n_fine, VIB_RATE_HZ, params.vib_band_hz) * params.vib_acc * np.array([1.0, 1.0, 2.0])
    ts = (t_ns - t0_ns) * 1e-9
    idx = np.minimum(np.rint(ts * VIB_RATE_HZ).astype(np.int64), n_fine - 1)
    fly = motion.flying(ts)[0]
    env = params.idle + (1.0 - params.idle) * fly
    scale = rng.normal(0.0, params.gyro_scale, 3)
    shift = rng.normal(0.0, params.gyro_bias_flight, 3)
    bias_g = series.bias_gyro + fly[:, None] * shift
    gyro = series.gyro_true * (1.0 + scale) + bias_g + (series.gyro - series.gyro_true - series.bias_gyro)
    gt = motion(ts)
    vib = replace(series, gyro=gyro + env[:, None] * vib_g[idx], acc=series.acc + env[:, None] * vib_a[idx],
                  bias_gyro=bias_g)
    return vib, gt


def mav_description(params: MavParams, imu: ImuParams, seed: int, t0_ns: int, noise_model: bool) -> dict:
    from gevi_cli import __version__

    return {"generator": f"gevi {__version__} simulate", "preset": "mav",
            "description": "IMU only: aggressive multirotor flight (thrust-tilted, tilts past 60 deg, rotor vibration)",
            "seed": int(seed), "format": "euroc", "mav": asdict(params), "imu": asdict(imu),
            "t0_ns": int(t0_ns), "gravity_W": [0.0, 0.0, -GRAVITY],
            "frames_convention": "world z up; body = IMU frame"}


def write_mav(out, params: MavParams, imu: ImuParams, seed: int, noise_model: bool = True):
    """Write the mav regime's IMU-only EuRoC folder into ``out`` (see :func:`write_imu_only`)."""
    from gevi_cli.simulate.generate import T0_NS

    series, gt = mav_imu(params, imu, seed, T0_NS)
    return write_imu_only(out, series, gt, imu, mav_description(params, imu, seed, T0_NS, noise_model), noise_model,
                          "Simulated MAV IMU (white noise stated; rotor vibration not)")


def write_imu_only(out, series: ImuSeries, gt: MotionSample, imu: ImuParams, description: dict, noise_model: bool,
                   comment: str):
    """An IMU-only EuRoC folder: ``mav0/imu0/{data.csv,sensor.yaml}``,
    ``mav0/state_groundtruth_estimate0/{data.csv,sensor.yaml}`` (body poses at the IMU stamps) and
    ``simulation.yaml``.  ``noise_model`` False leaves the noise densities out of ``imu0/sensor.yaml``
    (a recording that states none)."""
    from pathlib import Path

    from gevi_cli.geometry import matrix_to_quat_wxyz
    from gevi_cli.simulate.writers import write_simulation_yaml
    from gevi_cli.simulate.writers.euroc import GT_HEADER, IMU_HEADER, _write_rows, gt_yaml, imu_yaml

    out = Path(out)
    (out / "mav0" / "imu0").mkdir(parents=True)
    (out / "mav0" / "state_groundtruth_estimate0").mkdir()
    _write_rows(out / "mav0" / "imu0" / "data.csv", IMU_HEADER, series.t_ns, np.hstack([series.gyro, series.acc]))
    text = imu_yaml(imu, comment)
    if not noise_model:
        text = text.split("# inertial sensor noise model")[0].rstrip() + "\n"
    (out / "mav0" / "imu0" / "sensor.yaml").write_text(text)
    _write_rows(out / "mav0" / "state_groundtruth_estimate0" / "data.csv", GT_HEADER, series.t_ns,
                np.hstack([gt.p_W, matrix_to_quat_wxyz(gt.R_WB), gt.v_W, series.bias_gyro, series.bias_acc]))
    (out / "mav0" / "state_groundtruth_estimate0" / "sensor.yaml").write_text(gt_yaml())
    write_simulation_yaml(out / "simulation.yaml", {**description, "noise_model_written": bool(noise_model)})
    return out


def write_preset_imu(out, config, noise_model: bool = True):
    """The IMU and ground truth of an image preset's render (``config``: a
    :class:`~gevi_cli.simulate.generate.SimulationConfig`) without its images: the same motion and IMU
    samples as the full render of the same options."""
    from gevi_cli.simulate.generate import build_sequence

    seq = build_sequence(config)
    desc = seq.description("euroc")
    desc = {k: desc[k] for k in ("generator", "preset", "description", "seed", "options", "imu", "t0_ns", "gravity_W",
                                 "frames_convention")}
    desc["format"] = "euroc-imu-only"
    return write_imu_only(out, seq.imu, seq.groundtruth, seq.config.imu, desc, noise_model,
                          f"Simulated {config.preset} IMU (IMU only)")


def simulate_imu_only(out_dir, write, overwrite: bool = False):
    """``write(folder)`` (:func:`write_mav` or :func:`write_preset_imu` bound to their arguments) into ``out_dir``
    with the output-folder rules of :func:`~gevi_cli.simulate.generate.simulate` (empty or absent;
    ``overwrite`` only a previous render), written into a sibling temporary folder and renamed into
    place when complete.  Returns the folder."""
    from gevi_cli.simulate.generate import into_place, output_folder

    out = output_folder(out_dir, overwrite)
    into_place(out, write)
    return out
