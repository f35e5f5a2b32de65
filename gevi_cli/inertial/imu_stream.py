"""The IMU as the pipelines use it: on the camera clock, validated, with a noise model.

Frames: measurements are in the body (= IMU) frame B; gyro rad/s, accelerometer m/s^2 (specific
force).  Stamps are int64 ns.  ``time_offset_s`` is Kalibr's ``timeshift_cam_imu``
(``t_imu = t_cam + shift``), so a sample stamped ``t_imu`` happened at camera time ``t_imu - shift``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.datasets.sequence import GAP_FACTOR
from gevi_cli.errors import GeviError
from gevi_cli.estimators.preintegration import imu_segment
from gevi_cli.inertial.standstill import WindowMoments

#: EuRoC ADIS16448 values, used (with a warning) when the dataset states no IMU noise.
DEFAULT_NOISE = {"gyro_noise_density": 1.6968e-4, "gyro_random_walk": 1.9393e-5, "acc_noise_density": 2.0e-3,
                 "acc_random_walk": 3.0e-3}


@dataclass(frozen=True)
class ImuNoise:
    """Continuous-time densities: gyro rad/s/sqrt(Hz), accel m/s^2/sqrt(Hz), random walks per sqrt(s)."""

    gyro_noise_density: float
    gyro_random_walk: float
    acc_noise_density: float
    acc_random_walk: float


@dataclass
class FrameImu:
    """What the IMU says about one frame interval (previous frame -> this frame).

    ``dR`` (3, 3): bias-corrected gyro rotation from the previous frame's body to this one;
    ``rotvec`` = Log(dR) (rad); ``n`` samples; ``dt`` (s); ``gap`` True when the IMU does not cover
    the interval (then ``dR`` is the identity and ``n`` 0).
    """

    dR: np.ndarray
    rotvec: np.ndarray
    n: int
    dt: float
    gap: bool = False


class ImuStream:
    """IMU samples on the camera clock with the helpers the stereo-inertial pipeline needs."""

    def __init__(self, t_ns, gyro, acc, noise: ImuNoise, time_offset_s: float = 0.0, source: str = "IMU",
                 max_gap_factor: float = GAP_FACTOR):
        """``max_gap_factor``: an interval longer than this many median sample periods is a gap."""
        t = np.asarray(t_ns, dtype=np.int64)
        gyro = np.asarray(gyro, dtype=np.float64)
        acc = np.asarray(acc, dtype=np.float64)
        if t.ndim != 1 or len(t) < 2 or gyro.shape != (len(t), 3) or acc.shape != (len(t), 3):
            raise GeviError(source, "IMU needs at least two samples with 3-axis gyro and accelerometer")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if len(bad):
            raise GeviError(source, f"IMU stamps out of order or repeated at sample {int(bad[0]) + 1} "
                                    f"({int(t[bad[0]])} ns then {int(t[bad[0] + 1])} ns)")
        if not (np.all(np.isfinite(gyro)) and np.all(np.isfinite(acc))):
            raise GeviError(source, "IMU samples contain NaN or inf")
        self.t_ns = t - int(round(time_offset_s * 1e9))
        self.gyro, self.acc, self.noise = gyro, acc, noise
        self.time_offset_s = float(time_offset_s)
        self.source = source
        self.dt_nominal = float(np.median(np.diff(self.t_ns))) * 1e-9
        self.max_gap_ns = int(max_gap_factor * self.dt_nominal * 1e9)
        self.noise_missing: tuple[str, ...] = ()  # the noise keys the dataset did not state (defaults used)

    @classmethod
    def from_sequence(cls, imu, time_offset_s: float, source: str, warn=None, max_gap_factor: float = GAP_FACTOR) -> "ImuStream":
        """From a dataset's :class:`~gevi_cli.datasets.sequence.ImuData`; missing noise -> defaults + warning."""
        values, missing = {}, []
        for key, default in DEFAULT_NOISE.items():
            v = getattr(imu, key, None)
            if v is None or not np.isfinite(v) or v <= 0:
                missing.append(key)
                v = default
            values[key] = float(v)
        if missing and warn is not None:
            warn(f"{source}: no IMU noise given for {', '.join(missing)}; using EuRoC ADIS16448 values")
        stream = cls(imu.t_ns, imu.gyro, imu.acc, ImuNoise(**values), time_offset_s, source, max_gap_factor)
        stream.noise_missing = tuple(missing)
        return stream

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.dt_nominal

    def covers(self, t0_ns: int, t1_ns: int) -> bool:
        """True when samples exist around [t0, t1] with no gap longer than the gap limit."""
        t = self.t_ns
        if len(t) == 0 or t[0] > t0_ns or t[-1] < t1_ns:
            return False
        i0 = int(np.searchsorted(t, t0_ns, side="right")) - 1
        i1 = int(np.searchsorted(t, t1_ns, side="left"))
        return bool(np.all(np.diff(t[i0:i1 + 1]) <= self.max_gap_ns))

    def window(self, t0_ns: int, t1_ns: int):
        """(stamps, gyro, acc) with t0 <= t <= t1."""
        i0, i1 = self.span(t0_ns, t1_ns)
        return self.t_ns[i0:i1], self.gyro[i0:i1], self.acc[i0:i1]

    def span(self, t0_ns: int, t1_ns: int) -> tuple[int, int]:
        """Index range [i0, i1) of the samples with t0 <= t <= t1."""
        return (int(np.searchsorted(self.t_ns, t0_ns, side="left")),
                int(np.searchsorted(self.t_ns, t1_ns, side="right")))

    @functools.cached_property
    def moments(self):
        """:class:`~gevi_cli.inertial.standstill.WindowMoments` of the stream (its sums grow as asked for)."""
        return WindowMoments(self.gyro, self.acc)

    def interval(self, t0_ns: int, t1_ns: int, b_g: np.ndarray) -> FrameImu:
        """Gyro rotation over [t0, t1] (zero-order hold, bias ``b_g`` removed)."""
        if not self.covers(t0_ns, t1_ns):
            return FrameImu(np.eye(3), np.zeros(3), 0, (t1_ns - t0_ns) * 1e-9, gap=True)
        w, _, dts = imu_segment(self.t_ns, self.gyro, self.acc, t0_ns, t1_ns)
        keep = dts > 0
        w, dts = w[keep], dts[keep]
        dR = np.eye(3)
        for E in est.exp_so3((w - b_g) * dts[:, None]):  # one batched exp; few samples per frame interval
            dR = dR @ E
        return FrameImu(dR, est.log_so3(dR), len(w), float(dts.sum()))
