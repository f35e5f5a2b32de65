"""VQF 6D (Laidig and Seel, "VQF: Highly accurate IMU orientation estimation with bias estimation and
magnetic disturbance rejection", Information Fusion 91, 2023), the field's reference attitude filter,
through the ``vqf`` package: the reference rows of `gevi imu`'s table.

``online``: :class:`vqf.VQF` (causal); ``offline``: :func:`vqf.offlineVQF` (forward-backward bias
estimation, non-causal).  Both run with the package's default parameters at the stream's nominal
sample period (VQF assumes equally spaced samples), gyro rad/s and accelerometer m/s^2 in the IMU
frame.  VQF integrates sample ``k``'s rate into its output ``k``: sample ``k`` is the mean rate over
``(t_k-1, t_k]``, the stamping convention of the report.  Returns ``R_WI`` (n, 3, 3) per sample, world
z up (heading arbitrary: 6D).

**Standstill-compensated VQF** (:func:`compensated_vqf_attitude`, gevi's own rows): VQF clips its gyro
bias estimate at ``biasClip`` (2 deg/s = 0.035 rad/s), and EuRoC's ADIS16448 has a 0.078 rad/s yaw-axis
bias; VQF's rest detection (2 deg/s gyro threshold) never fires on a multirotor whose rotors idle.  The
rate fed to VQF is therefore the gyro minus the bias measured over the starting standstill (rad/s, IMU
frame), re-measured at every later standstill whose specific force stayed still (a bias shifts in flight:
:func:`gevi_cli.inertial.standstill.standstill_bias_track`, per sample), so VQF only estimates what is
left, which lies inside its clip, with the parameters :data:`COMPENSATED_PARAMS` (chosen on `scripts/imu_regimes.py`'s rows and euroc_micro; see
docs/studies/imu_attitude.md).  No ground truth enters it.
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


#: VQF parameters of the standstill-compensated rows, over the package's defaults (deg/s and s): the
#: residual bias starts at 0 with 0.1 deg/s uncertainty (the standstill's mean rate is known that well),
#: and it drifts slowly during motion (biasSigmaMotion 0.02 deg/s, forgotten over 1000 s instead of 0.1
#: and 100 s); tauAcc stays VQF's 3 s
COMPENSATED_PARAMS = {"biasSigmaInit": 0.1, "biasSigmaMotion": 0.02, "biasForgettingTime": 1000.0}


def compensated_vqf_attitude(gyro: np.ndarray, acc: np.ndarray, dt_s: float, gyro_bias: np.ndarray,
                             offline: bool = False) -> np.ndarray:
    """R_WI per sample (n, 3, 3) from VQF 6D on ``gyro - gyro_bias`` (rad/s; (3,) or one per sample (n, 3):
    the standstills' mean rates) with :data:`COMPENSATED_PARAMS`: online (causal) or ``offline``."""
    g = np.asarray(gyro, dtype=np.float64) - np.asarray(gyro_bias, dtype=np.float64)
    return vqf_attitude(g, acc, dt_s, offline, COMPENSATED_PARAMS)


def default_params() -> dict:
    """VQF's default parameters (the ones the rows use), as the package states them."""
    from vqf import VQF

    return dict(VQF(0.01).params)
