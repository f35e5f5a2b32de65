"""VQF 6D (Laidig and Seel, "VQF: Highly accurate IMU orientation estimation with bias estimation and
magnetic disturbance rejection", Information Fusion 91, 2023), the field's reference attitude filter,
through the ``vqf`` package: the reference rows of `gevi imu`'s table.

``online``: :class:`vqf.VQF` (causal); ``offline``: :func:`vqf.offlineVQF` (forward-backward bias
estimation, non-causal).  Both run with the package's default parameters at the stream's nominal
sample period (VQF assumes equally spaced samples), gyro rad/s and accelerometer m/s^2 in the IMU
frame.  VQF integrates sample ``k``'s rate into its output ``k``: sample ``k`` is the mean rate over
``(t_k-1, t_k]``, the stamping convention of the report.  Returns ``R_WI`` (n, 3, 3) per sample, world
z up (heading arbitrary: 6D).
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import numpy as np
from scipy.spatial.transform import Rotation


def vqf_version() -> str:
    try:
        return version("vqf")
    except PackageNotFoundError:  # pragma: no cover - a dependency
        return "unknown"


def vqf_attitude(gyro: np.ndarray, acc: np.ndarray, dt_s: float, offline: bool = False,
                 params: dict | None = None) -> np.ndarray:
    """R_WI per sample (n, 3, 3) from VQF 6D (online, or ``offline``) with ``params`` over its defaults."""
    from vqf import VQF, offlineVQF

    g = np.ascontiguousarray(gyro, dtype=np.float64)
    a = np.ascontiguousarray(acc, dtype=np.float64)
    params = dict(params or {})
    q = offlineVQF(g, a, None, float(dt_s), params)["quat6D"] if offline else VQF(float(dt_s), **params).updateBatch(g, a)["quat6D"]
    return Rotation.from_quat(np.roll(q, -1, axis=1)).as_matrix()  # VQF's quaternions are w x y z


def default_params() -> dict:
    """VQF's default parameters (the ones the rows use), as the package states them."""
    from vqf import VQF

    return dict(VQF(0.01).params)
