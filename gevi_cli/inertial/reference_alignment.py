"""A motion-capture reference brought onto the IMU's clock and into the IMU's frame, from the angular
rates alone (never from an attitude estimate's error).

A mocap system tracks a marker body ``R`` whose stamps lead or lag the IMU's and whose axes are those
of the marker set, not the IMU's ``I``.  Both see the same rigid-body rotation, so the body rates obey
``w_I(t) = R_IR w_R(t - offset) + b`` (``b``: the gyro bias).  Two steps:

1. **Clock offset**: the ``offset`` (s) that maximises the correlation of ``|w_I|`` with ``|w_R|``
   (magnitudes do not depend on ``R_IR``).  ``w_R`` over each reference interval ``[t_k, t_k+s]`` is
   ``Log(R_WR(t_k)^T R_WR(t_k+s)) / dt`` (``s`` poses apart so that the interval spans at least one IMU
   sample period); the gyro over the same interval shifted by ``offset`` is its exact mean when sample
   ``k`` is the mean rate over ``(t_k-1, t_k]`` (the cumulative integral, interpolated).  That is the
   convention of VQF and of BROAD's reference (an estimate's output at ``t_k`` has integrated sample
   ``k``); :mod:`gevi_cli.evaluation.imu_report` stamps every row by it.  Coarse grid at half the finer sample
   period over ``+-max_offset_s``, then refined to 1/20 of that step around the best.
2. **Rotation**: ``R_IR`` by Kabsch/Wahba (``scipy.spatial.transform.Rotation.align_vectors``) on the
   centred rate pairs at that offset (centring removes the constant bias ``b``).

The aligned reference is ``R_WI(t + offset) = R_WR(t) R_IR^T``: stamps shifted by ``offset`` (a pose
stamped ``t`` on the mocap clock happened at IMU time ``t + offset``), rotations turned into the IMU
frame.  Units: s, rad, rad/s; stamps int64 ns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gevi_cli.datasets.sequence import GAP_FACTOR


@dataclass(frozen=True)
class ReferenceAlignment:
    """``offset_s``: add to the reference's stamps to put them on the IMU clock (s); ``R_IR``: rotation
    from the reference (marker) body frame to the IMU frame (``w_I = R_IR w_R``); ``correlation``: of the
    rate magnitudes at that offset; ``rate_residual``: RMS of ``w_I - R_IR w_R - b`` (rad/s); ``n``: rate
    pairs used."""

    offset_s: float
    R_IR: np.ndarray
    correlation: float
    rate_residual: float
    n: int

    @property
    def angle_deg(self) -> float:
        """The rotation angle of ``R_IR`` (deg)."""
        return float(np.degrees(Rotation.from_matrix(self.R_IR).magnitude()))

    def apply(self, gt):
        """The reference Trajectory ``gt`` (poses ``T_W_R``) as IMU orientations on the IMU clock
        (positions kept: the lever arm is irrelevant to attitude)."""
        from dataclasses import replace

        R = gt.rotations @ self.R_IR.T
        q = np.roll(Rotation.from_matrix(R).as_quat(), 1, axis=1)
        return replace(gt, t_ns=gt.t_ns + int(round(self.offset_s * 1e9)), quat_wxyz=q)

    def describe(self, why_no_rotation: str = "") -> str:
        """One line; ``why_no_rotation``: the reason no rotation was estimated (then ``R_IR`` = I)."""
        rv = Rotation.from_matrix(self.R_IR).as_rotvec()
        rot = (f"no IMU-from-reference rotation ({why_no_rotation})" if why_no_rotation else
               f"IMU-from-reference rotation {self.angle_deg:.2f} deg (rotation vector [{rv[0]:+.4f} {rv[1]:+.4f} "
               f"{rv[2]:+.4f}] rad)")
        return (f"reference aligned to the IMU from the angular rates: clock offset {self.offset_s * 1e3:+.1f} ms "
                f"(reference stamps + offset = IMU time), {rot}; |rate| correlation "
                f"{self.correlation:.3f}, rate residual {self.rate_residual:.3g} rad/s over {self.n} intervals")


def reference_rates(t_ns: np.ndarray, R: np.ndarray, min_dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body rates ``Log(R_k^T R_k+s) / dt`` (rad/s) of a pose series over intervals of at least
    ``min_dt_s``: (start ns, end ns, rates (m, 3)).  Intervals longer than GAP_FACTOR x the median (gaps) dropped."""
    t = np.asarray(t_ns, dtype=np.int64)
    dt_med = float(np.median(np.diff(t))) * 1e-9
    s = max(int(np.ceil(min_dt_s / dt_med - 1e-9)), 1)
    a, b = t[:-s], t[s:]
    dt = (b - a) * 1e-9
    rel = Rotation.from_matrix(np.transpose(R[:-s], (0, 2, 1)) @ R[s:])
    w = rel.as_rotvec() / dt[:, None]
    keep = dt <= GAP_FACTOR * s * dt_med
    return a[keep], b[keep], w[keep]


def _mean_gyro(G_t: np.ndarray, G: np.ndarray, a_s: np.ndarray, b_s: np.ndarray) -> np.ndarray:
    """Mean gyro over [a, b] (s) from its cumulative integral ``G`` at stamps ``G_t`` (s)."""
    ga = np.stack([np.interp(a_s, G_t, G[:, i]) for i in range(3)], axis=1)
    gb = np.stack([np.interp(b_s, G_t, G[:, i]) for i in range(3)], axis=1)
    return (gb - ga) / (b_s - a_s)[:, None]


def estimate_alignment(imu_t_ns, gyro, gt, max_offset_s: float = 0.5, rotation: bool = True) -> ReferenceAlignment | None:
    """Clock offset and ``R_IR`` of the reference ``gt`` (Trajectory of mocap poses) against the gyro
    (IMU stamps ns, (n, 3) rad/s); ``rotation`` False: the reference is in the IMU frame already, only the
    clock offset is estimated (``R_IR`` = I).  None when fewer than 20 rate intervals overlap or the
    motion is too small to show a rate (|w_R| spread below 0.02 rad/s)."""
    t_i = np.asarray(imu_t_ns, dtype=np.int64)
    g = np.asarray(gyro, dtype=float)
    origin = int(t_i[0])
    t_s = (t_i - origin) * 1e-9
    dt_imu = float(np.median(np.diff(t_s)))
    # cumulative integral of the gyro, sample k the mean rate over (t_k-1, t_k]: exact means over any
    # interval by interpolation
    G = np.vstack([np.zeros(3), np.cumsum(g[1:] * np.diff(t_s)[:, None], axis=0)])
    a_ns, b_ns, w_R = reference_rates(gt.t_ns, gt.rotations, dt_imu)
    a_s, b_s = (a_ns - origin) * 1e-9, (b_ns - origin) * 1e-9
    if len(w_R) < 20 or np.std(np.linalg.norm(w_R, axis=1)) < 0.02:
        return None
    mag_R = np.linalg.norm(w_R, axis=1)

    def score(offset: float) -> float:
        inside = (a_s + offset >= t_s[0]) & (b_s + offset <= t_s[-1])
        if inside.sum() < 20:
            return -np.inf
        m = np.linalg.norm(_mean_gyro(t_s, G, a_s[inside] + offset, b_s[inside] + offset), axis=1)
        return float(np.corrcoef(m, mag_R[inside])[0, 1])

    step = 0.5 * min(dt_imu, float(np.median(b_s - a_s)))
    coarse = np.arange(-max_offset_s, max_offset_s + step / 2, step)
    best = coarse[int(np.argmax([score(o) for o in coarse]))]
    fine = best + np.linspace(-step, step, 41)
    scores = [score(o) for o in fine]
    offset = float(fine[int(np.argmax(scores))])
    inside = (a_s + offset >= t_s[0]) & (b_s + offset <= t_s[-1])
    w_I = _mean_gyro(t_s, G, a_s[inside] + offset, b_s[inside] + offset)
    w_Rin = w_R[inside]
    if rotation:
        rot, _ = Rotation.align_vectors(w_I - w_I.mean(0), w_Rin - w_Rin.mean(0))
        R_IR = rot.as_matrix()
    else:
        R_IR = np.eye(3)
    res = (w_I - w_I.mean(0)) - (w_Rin - w_Rin.mean(0)) @ R_IR.T
    return ReferenceAlignment(offset, R_IR, float(max(scores)), float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
                              int(inside.sum()))
