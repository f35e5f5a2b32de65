"""On-manifold IMU preintegration (spec section 9.2) with first-order bias correction.

Discretisation (spec 9.2, zero-order hold): raw sample k, ``(w_k, a_k)``, is held constant over
``[t_k, t_k + dt_k)``; with ``w^ = w_k - b_g``, ``a^ = a_k - b_a`` (``b`` = linearisation point)

    dp <- dp + dv dt + 1/2 dR a^ dt^2,   dv <- dv + dR a^ dt,   dR <- dR Exp(w^ dt),

and the five bias Jacobians are updated *before* ``dR`` (spec order)::

    J_p_a <- J_p_a + J_v_a dt - 1/2 dR dt^2
    J_v_a <- J_v_a - dR dt
    J_p_g <- J_p_g + J_v_g dt - 1/2 dR [a^]x J_R_g dt^2
    J_v_g <- J_v_g - dR [a^]x J_R_g dt
    J_R_g <- Exp(w^ dt)^T J_R_g - J_r(w^ dt) dt

Implementation: the only inherently sequential part is the running product ``dR_{k+1} = dR_k
Exp(w^_k dt_k)`` (one 3x3 matmul per sample, no other per-sample work). Everything else is the
closed-form solution of the recursions above, evaluated with cumulative sums:

    J_R_g,k = dR_k^T C_k,          C_k = -sum_{i<k} dR_{i+1} J_r(w^_i dt_i) dt_i
    dR_k [a^_k]x J_R_g,k = [f_k]x C_k,   f_k = dR_k a^_k

(proof by induction: ``E_k^T dR_k^T C_k - J_r dt = dR_{k+1}^T (C_k - dR_{k+1} J_r dt)``). The
literal per-sample recursion is kept as :func:`preintegrate_reference` (used by the tests: both
agree to ~1e-15). Padding samples with ``dt = 0`` leaves every quantity unchanged, which is how
:func:`preintegrate_batch` integrates many intervals of different lengths in one pass.

Frames: ``dR = R_i^T R_j``, ``dv = R_i^T (v_j - v_i - g T)``, ``dp = R_i^T (p_j - p_i - v_i T - g T^2/2)``
(IMU poses ``R_i, p_i`` in a gravity-carrying frame, ``g`` the gravity vector there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.geometry import exp_so3, skew

from .errors import DegenerateInput, NonFiniteInput, ShapeError

__all__ = [
    "Increments",
    "Preintegrated",
    "integrate_increments",
    "preintegrate",
    "preintegrate_batch",
    "preintegrate_reference",
    "imu_segment",
    "right_jacobian_batch",
]


def right_jacobian_batch(phi) -> np.ndarray:
    """``J_r(phi) = I - (1-cos|phi|)/|phi|^2 [phi]x + (|phi|-sin|phi|)/|phi|^3 [phi]x^2`` for (..., 3)."""
    phi = np.asarray(phi, dtype=float)
    th2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = th2 < 1e-10
    ths2 = np.where(small, 1.0, th2)
    th = np.sqrt(ths2)
    a = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / ths2)
    b = np.where(small, 1.0 / 6.0 - th2 / 120.0, (th - np.sin(th)) / (ths2 * th))
    K = skew(phi)
    return np.eye(3) - a * K + b * (K @ K)


@dataclass(frozen=True)
class Preintegrated:
    """Preintegrated IMU increments over one interval (spec 9.2).

    ``dt`` total time [s]; ``dR, dv, dp`` at the bias linearisation point ``(b_g, b_a)``;
    Jacobians ``J_R_g = d Log(dR_bar^T dR(b)) / d b_g``, ``J_v_g, J_v_a, J_p_g, J_p_a``.
    The raw samples are kept (``gyro, acc, dts``) so the interval can be re-integrated at a new
    linearisation point (:meth:`reintegrate`).
    """

    dt: float
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    J_R_g: np.ndarray
    J_v_g: np.ndarray
    J_v_a: np.ndarray
    J_p_g: np.ndarray
    J_p_a: np.ndarray
    b_g: np.ndarray
    b_a: np.ndarray
    gyro: np.ndarray = field(repr=False)
    acc: np.ndarray = field(repr=False)
    dts: np.ndarray = field(repr=False)

    def predict(self, b_g=None, b_a=None):
        """First-order bias-corrected ``(dR, dv, dp)`` at biases ``(b_g, b_a)``.

        ``dR(b) = dR Exp(J_R_g db_g)``, ``dv(b) = dv + J_v_g db_g + J_v_a db_a``, same for dp,
        with ``db = b - b_lin``. Exact in ``b_a`` (the increments are affine in it).
        """
        dbg = np.zeros(3) if b_g is None else np.asarray(b_g, float) - self.b_g
        dba = np.zeros(3) if b_a is None else np.asarray(b_a, float) - self.b_a
        dR = self.dR @ exp_so3(self.J_R_g @ dbg)
        dv = self.dv + self.J_v_g @ dbg + self.J_v_a @ dba
        dp = self.dp + self.J_p_g @ dbg + self.J_p_a @ dba
        return dR, dv, dp

    def reintegrate(self, b_g=None, b_a=None) -> "Preintegrated":
        """Re-run the integration of the stored samples at a new linearisation point."""
        return preintegrate(
            self.gyro, self.acc, self.dts,
            self.b_g if b_g is None else b_g,
            self.b_a if b_a is None else b_a,
        )


def _check_samples(gyro, acc, dts):
    gyro = np.asarray(gyro, dtype=float)
    acc = np.asarray(acc, dtype=float)
    dts = np.asarray(dts, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or acc.shape != gyro.shape or dts.shape != gyro.shape[:1]:
        raise ShapeError(f"gyro/acc must be (m, 3) and dts (m,), got {gyro.shape}, {acc.shape}, {dts.shape}")
    if gyro.shape[0] == 0:
        raise DegenerateInput("no IMU samples in the interval")
    if not (np.all(np.isfinite(gyro)) and np.all(np.isfinite(acc)) and np.all(np.isfinite(dts))):
        raise NonFiniteInput("IMU samples contain non-finite values")
    if np.any(dts < 0) or not np.any(dts > 0):
        raise DegenerateInput("sample intervals must be >= 0 with a positive total")
    return gyro, acc, dts


def _bias(b, name):
    b = np.zeros(3) if b is None else np.asarray(b, dtype=float).reshape(-1)
    if b.shape != (3,):
        raise ShapeError(f"{name} must have 3 entries")
    if not np.all(np.isfinite(b)):
        raise NonFiniteInput(f"{name} is not finite")
    return b


def _integrate(w, a, dt, b_g, b_a, jacobians=True):
    """Batched core: w, a (B, m, 3), dt (B, m), b_g, b_a (B, 3). Returns a dict of (B, ...) arrays
    (without the bias Jacobians if ``jacobians`` is false: dt, dR, dv, dp by the same operations)."""
    B, m = dt.shape
    wh = w - b_g[:, None, :]
    ah = a - b_a[:, None, :]
    phi = wh * dt[..., None]
    E = exp_so3(phi)  # (B, m, 3, 3)
    # sequential part: running rotation product dR_0 = I, dR_{k+1} = dR_k E_k
    Rk = np.empty((B, m + 1, 3, 3))
    Rk[:, 0] = np.eye(3)
    for k in range(m):
        np.matmul(Rk[:, k], E[:, k], out=Rk[:, k + 1])
    R0 = Rk[:, :-1]  # dR_k before the update of sample k
    dt1 = dt[..., None]
    dt2 = dt[..., None, None]
    f = np.einsum("bkij,bkj->bki", R0, ah)  # dR_k a^_k
    # velocity / position
    fv = f * dt1
    v_incl = np.cumsum(fv, axis=1)
    v_excl = v_incl - fv
    dv = v_incl[:, -1]
    dp = np.sum(v_excl * dt1 + 0.5 * fv * dt1, axis=1)
    if not jacobians:
        return dict(dt=dt.sum(axis=1), dR=Rk[:, -1], dv=dv, dp=dp)
    Jr = right_jacobian_batch(phi)
    # accelerometer-bias Jacobians
    Ra = R0 * dt2
    Jva_incl = -np.cumsum(Ra, axis=1)
    Jva_excl = Jva_incl + Ra
    J_v_a = Jva_incl[:, -1]
    J_p_a = np.sum(Jva_excl * dt2 - 0.5 * Ra * dt2, axis=1)
    # gyro-bias Jacobians via C_k (see module docstring)
    Cterm = (Rk[:, 1:] @ Jr) * dt2
    C_incl = -np.cumsum(Cterm, axis=1)
    C_excl = C_incl + Cterm
    J_R_g = np.swapaxes(Rk[:, -1], -1, -2) @ C_incl[:, -1]
    G = skew(f) @ C_excl * dt2  # dR_k [a^]x J_R_g,k dt
    Jvg_incl = -np.cumsum(G, axis=1)
    Jvg_excl = Jvg_incl + G
    J_v_g = Jvg_incl[:, -1]
    J_p_g = np.sum(Jvg_excl * dt2 - 0.5 * G * dt2, axis=1)
    return dict(dt=dt.sum(axis=1), dR=Rk[:, -1], dv=dv, dp=dp, J_R_g=J_R_g, J_v_g=J_v_g,
                J_v_a=J_v_a, J_p_g=J_p_g, J_p_a=J_p_a)


def preintegrate(gyro, acc, dts, b_g=None, b_a=None) -> Preintegrated:
    """Preintegrate one interval. ``gyro`` [rad/s], ``acc`` [m/s^2] (m, 3); ``dts`` (m,) [s] hold times.

    ``b_g, b_a`` is the bias linearisation point (default zero). Raises ``DegenerateInput`` for an
    empty interval, ``NonFiniteInput``/``ShapeError`` on bad arrays.
    """
    gyro, acc, dts = _check_samples(gyro, acc, dts)
    bg, ba = _bias(b_g, "b_g"), _bias(b_a, "b_a")
    out = _integrate(gyro[None], acc[None], dts[None], bg[None], ba[None])
    return Preintegrated(
        **{k: (float(v[0]) if k == "dt" else v[0]) for k, v in out.items()},
        b_g=bg, b_a=ba, gyro=gyro, acc=acc, dts=dts,
    )


@dataclass(frozen=True)
class Increments:
    """``dt`` [s], ``dR``, ``dv``, ``dp`` of one interval (frames as :class:`Preintegrated`), no Jacobians."""

    dt: float
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray


def integrate_increments(gyro, acc, dts, b_g=None, b_a=None) -> Increments:
    """The increments of :func:`preintegrate` (the same numbers) without the bias Jacobians: for a
    caller that chains intervals at known biases and never corrects them (about half the work)."""
    gyro, acc, dts = _check_samples(gyro, acc, dts)
    bg, ba = _bias(b_g, "b_g"), _bias(b_a, "b_a")
    out = _integrate(gyro[None], acc[None], dts[None], bg[None], ba[None], jacobians=False)
    return Increments(float(out["dt"][0]), out["dR"][0], out["dv"][0], out["dp"][0])


def preintegrate_batch(segments, b_g=None, b_a=None) -> list[Preintegrated]:
    """Preintegrate many intervals in one pass (zero-``dt`` padding to the longest interval).

    ``segments`` is a sequence of ``(gyro, acc, dts)``; ``b_g``/``b_a`` are either one (3,) bias for
    all intervals or (B, 3). Same result as calling :func:`preintegrate` per interval.
    """
    segs = [_check_samples(*s) for s in segments]
    B = len(segs)
    if B == 0:
        return []
    bg = np.broadcast_to(np.zeros(3) if b_g is None else np.asarray(b_g, float), (B, 3)).copy()
    ba = np.broadcast_to(np.zeros(3) if b_a is None else np.asarray(b_a, float), (B, 3)).copy()
    if not (np.all(np.isfinite(bg)) and np.all(np.isfinite(ba))):
        raise NonFiniteInput("biases are not finite")
    m = max(s[2].shape[0] for s in segs)
    W = np.zeros((B, m, 3))
    A = np.zeros((B, m, 3))
    D = np.zeros((B, m))
    for i, (g, a, d) in enumerate(segs):
        W[i, : len(d)] = g
        A[i, : len(d)] = a
        D[i, : len(d)] = d
    out = _integrate(W, A, D, bg, ba)
    return [
        Preintegrated(
            **{k: (float(v[i]) if k == "dt" else v[i]) for k, v in out.items()},
            b_g=bg[i], b_a=ba[i], gyro=segs[i][0], acc=segs[i][1], dts=segs[i][2],
        )
        for i in range(B)
    ]


def preintegrate_reference(gyro, acc, dts, b_g=None, b_a=None) -> Preintegrated:
    """Literal per-sample recursion of spec 9.2 (slow; reference for tests)."""
    gyro, acc, dts = _check_samples(gyro, acc, dts)
    bg, ba = _bias(b_g, "b_g"), _bias(b_a, "b_a")
    dR = np.eye(3)
    dv = np.zeros(3)
    dp = np.zeros(3)
    JRg, Jvg, Jva, Jpg, Jpa = (np.zeros((3, 3)) for _ in range(5))
    for w, a, dt in zip(gyro, acc, dts):
        ah = a - ba
        phi = (w - bg) * dt
        dp = dp + dv * dt + 0.5 * dR @ ah * dt**2
        dv = dv + dR @ ah * dt
        Jpa = Jpa + Jva * dt - 0.5 * dR * dt**2
        Jva = Jva - dR * dt
        Sa = skew(ah)
        Jpg = Jpg + Jvg * dt - 0.5 * dR @ Sa @ JRg * dt**2
        Jvg = Jvg - dR @ Sa @ JRg * dt
        E = exp_so3(phi)
        JRg = E.T @ JRg - right_jacobian_batch(phi) * dt
        dR = dR @ E
    return Preintegrated(float(dts.sum()), dR, dv, dp, JRg, Jvg, Jva, Jpg, Jpa, bg, ba, gyro, acc, dts)


def imu_segment(t_ns, gyro, acc, t0_ns: int, t1_ns: int):
    """Samples covering ``[t0, t1]`` (int nanoseconds) with zero-order hold.

    Sample k is held over ``[t_k, t_{k+1})``; the returned hold times are clipped to the interval,
    so the first sample is the last one at or before ``t0``. Requires ``t_0 <= t0 < t1 <= t_last``
    and at least one sample stamp inside ``[t0, t1]``; otherwise ``DegenerateInput``.
    Returns ``(gyro_seg, acc_seg, dts_seconds)``.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    t0, t1 = int(t0_ns), int(t1_ns)
    if t1 <= t0:
        raise DegenerateInput(f"empty interval [{t0}, {t1}] ns")
    if t.size == 0 or t[0] > t0 or t[-1] < t1:
        raise DegenerateInput(f"IMU data do not cover the interval [{t0}, {t1}] ns")
    k0 = int(np.searchsorted(t, t0, side="right")) - 1
    k1 = int(np.searchsorted(t, t1, side="left"))  # samples k0 .. k1-1 are used
    if np.searchsorted(t, t1, side="right") - np.searchsorted(t, t0, side="left") == 0:
        raise DegenerateInput(f"no IMU samples in the interval [{t0}, {t1}] ns")
    idx = np.arange(k0, k1)
    starts = np.maximum(t[idx], t0)
    ends = np.minimum(t[idx + 1], t1)
    dts = (ends - starts).astype(float) * 1e-9
    return np.asarray(gyro, float)[idx], np.asarray(acc, float)[idx], dts
