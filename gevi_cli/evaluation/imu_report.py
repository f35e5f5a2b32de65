"""`gevi imu`: what a user checks before trusting a VIO run on a recording.

Rate and gaps; standstill intervals; the gyro bias and gravity direction of the starting standstill;
white-noise levels measured at standstill next to the stated densities; roll/pitch over the whole
stream from the IMU-only filter of :mod:`gevi_cli.inertial.velocity_aided`, against ground truth when
there is some, next to the gravity-prior filter of :mod:`gevi_cli.inertial.attitude` (GeVI's), plain
gyro integration and a fixed-gain complementary filter (both levelled
from the accelerometer at the start, with the standstill gyro bias; the complementary filter at the
best time constant of a 1-2-5 grid, chosen on the ground truth, the grid extended past an edge that
wins: an oracle row), and VQF 6D online and offline (:mod:`gevi_cli.inertial.vqf_rows`, the field's
reference).  With no noise model stated, the filter uses the white noise measured at rest.

The reference: a motion-capture ground truth is brought onto the IMU clock and into the IMU frame from
the angular rates alone (:mod:`gevi_cli.inertial.reference_alignment`) unless it is known to be
aligned (``align=False``: ``--no-align``, BROAD).  Every row is scored on that same reference,
interpolated (slerp) at the row's own stamps, over ``scored_t_ns`` when given (BROAD's movement
samples).  Stamps follow one convention, VQF's and BROAD's: IMU sample ``k`` is the mean rate over
``(t_k-1, t_k]``, so an output that has integrated sample ``k`` is stamped ``t_k`` (gevi's own filters
propagate sample ``k`` over ``[t_k, t_k+1)``; their outputs are stamped one sample earlier here).
Units: s, rad (printed in deg), m/s^2.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.datasets.sequence import GAP_FACTOR
from gevi_cli.inertial.attitude import (
    AttitudeFilterConfig,
    GravityAttitudeFilter,
    complementary_bank,
    gyro_only,
    level_rotations,
    run_filter,
)
from gevi_cli.inertial.imu_stream import ImuNoise, ImuStream
from gevi_cli.inertial.reference_alignment import ReferenceAlignment, estimate_alignment
from gevi_cli.inertial.standstill import (
    GRAVITY,
    STILL_LIMITS,
    StandstillEstimate,
    imu_at_rest,
    standstill_bias_track,
    standstill_estimate,
    tilt_from_specific_force,
)
from gevi_cli.inertial.velocity_aided import VelocityAidedConfig, VelocityAidedFilter
from gevi_cli.inertial.vqf_rows import compensated_vqf_attitude

#: standstill detection on the IMU alone (no images here): windows of this length (s) whose gyro std, |a| std
#: and | mean |a| - g | stay below STILL_LIMITS (inertial.standstill, the same as GeVI's start)
STILL_WINDOW_S = 0.5
#: |mean |a| at rest - g| above this (m/s^2) is flagged, and the velocity-aided filter rescales the specific force
ACC_SCALE_LIMIT = 0.3
#: prior std of the starting velocity (m/s) when the stream does not start at rest
MOVING_START_VELOCITY_SIGMA = 1.0
#: the complementary baseline's time constants (s; gain 1/tau rad/s per rad of gravity-direction error,
#: the same filter at any sample rate): a 1-2-5 series, extended by up to MAX_GRID_EXTENSION values
#: past an edge that wins, so that the oracle's choice is a minimum, not a bound
COMPLEMENTARY_TAUS_S = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0)
MAX_GRID_EXTENSION = 4


def step_125(tau: float, up: bool) -> float:
    """The next value of the 1-2-5 series above (``up``) or below ``tau``."""
    e = int(np.floor(np.log10(tau) + 1e-9))
    cands = [float(f"{v}e{e + d}") for d in (-1, 0, 1) for v in (1, 2, 5)]
    return min(c for c in cands if c > tau * (1 + 1e-9)) if up else max(c for c in cands if c < tau * (1 - 1e-9))


@dataclass(frozen=True)
class GridChoice:
    """The oracle's pick on a grid: ``best`` time constant (s), its ``score``, every (tau, score) tried,
    and ``at_edge`` when the best is still an end of the (extended) grid."""

    best: float
    score: tuple
    tried: tuple
    at_edge: bool


def best_on_grid(taus, score, min_tau: float = 0.0, max_extension: int = MAX_GRID_EXTENSION) -> GridChoice:
    """Minimise ``score(list of taus) -> list of tuples`` (first entry compared) over ``taus``; while the
    best is an end of the grid, add the next 1-2-5 value beyond it (not below ``min_tau``), at most
    ``max_extension`` times."""
    grid = sorted(float(t) for t in taus)
    scores = dict(zip(grid, score(grid)))
    for _ in range(max_extension):
        ordered = sorted(scores)
        best = min(ordered, key=lambda t: scores[t][0])
        if best == ordered[0] and step_125(best, up=False) >= min_tau:
            new = step_125(best, up=False)
        elif best == ordered[-1]:
            new = step_125(best, up=True)
        else:
            break
        scores[new] = score([new])[0]
    ordered = sorted(scores)
    best = min(ordered, key=lambda t: scores[t][0])
    return GridChoice(best, scores[best], tuple((t, scores[t]) for t in ordered), best in (ordered[0], ordered[-1]))


@dataclass
class ImuReport:
    n: int
    duration_s: float
    rate_hz: float
    gaps: list  # (start_s, length_s) relative to the first sample, longer than the gap limit
    standstills: list  # (start_s, end_s)
    start: StandstillEstimate | None  # the standstill the stream starts with
    noise_measured: dict  # gyro / acc white-noise density estimated at the longest standstill
    noise_stated: dict  # the dataset's densities (None where it states none)
    noise_used: ImuNoise | None = None  # what the filter ran with
    noise_note: str = ""  # one line: where noise_used comes from
    flags: list = field(default_factory=list)
    attitude: object = None  # AttitudeTrack of the velocity-aided filter (causal)
    # R_WI (n, 3, 3) of VQF 6D offline on the standstill-compensated gyro, one per IMU sample, stamped t_k
    # (sample k = the rate over (t_k-1, t_k]): the offline attitude gevi imu writes
    attitude_offline: np.ndarray | None = None
    attitude_causal: np.ndarray | None = None  # standstill-compensated VQF online: attitude.tum (stream stamps)
    comparison: list = field(default_factory=list)  # (name, (tilt RMSE, roll/pitch RMSE deg, tilt trend deg/min), note)
    complementary_choice: GridChoice | None = None  # the complementary baseline's grid (with ground truth)
    alignment: ReferenceAlignment | None = None  # how the reference was put on the IMU clock and frame
    reference_note: str = ""  # one line: which reference the rows are scored on


def _standstills(stream: ImuStream) -> list[tuple[int, int]]:
    """Index ranges [i0, i1) of merged windows that pass the IMU rest test."""
    w = max(int(round(STILL_WINDOW_S / stream.dt_nominal)), 4)
    out: list[list[int]] = []
    for i0 in range(0, len(stream.t_ns) - w + 1, w):
        if imu_at_rest(stream.gyro[i0:i0 + w], stream.acc[i0:i0 + w], *STILL_LIMITS):
            if out and out[-1][1] == i0:
                out[-1][1] = i0 + w
            else:
                out.append([i0, i0 + w])
    return [(a, b) for a, b in out]


def imu_report(stream: ImuStream, gt=None, cfg: VelocityAidedConfig = VelocityAidedConfig(), *, align: bool = True,
               scored_t_ns=None, align_gyro=None, in_imu_frame: str = "") -> ImuReport:
    """The whole report for ``stream``; ``gt`` an optional gravity-aligned Trajectory of the reference body
    (mocap markers, or the IMU itself).  The attitude is
    :class:`~gevi_cli.inertial.velocity_aided.VelocityAidedFilter`'s; with ground truth, the gravity-prior
    filter of :mod:`.attitude` (adaptive and fixed weight), gyro-only, complementary and VQF rows are
    compared on the reference aligned to the IMU (``align``; see the module docstring), over the stamps
    ``scored_t_ns`` (ns on the IMU clock) when given.  ``align_gyro``: ``(stamps ns, gyro rad/s)`` at the
    IMU's full rate for the alignment (default: the stream's, which may be strided); ``in_imu_frame``: why
    the reference is known to be in the IMU frame already (then only its clock offset is estimated; "": a
    rotation is estimated too)."""
    t, g, a = stream.t_ns, stream.gyro, stream.acc
    t0 = int(t[0])
    dt = np.diff(t)
    gaps = [((int(t[i]) - t0) * 1e-9, dt[i] * 1e-9) for i in np.flatnonzero(dt > stream.max_gap_ns)]
    still = _standstills(stream)
    standstills = [((int(t[i0]) - t0) * 1e-9, (int(t[i1 - 1]) - t0) * 1e-9) for i0, i1 in still]
    start = None
    if still and still[0][0] == 0:
        i1 = still[0][1]
        start = standstill_estimate(t[:i1], g[:i1], a[:i1])
    measured = {}
    if still:
        i0, i1 = max(still, key=lambda r: r[1] - r[0])
        # per-sample std x sqrt(dt) = the continuous-time density if the rest were pure white noise
        measured = {"gyro_noise_density": float(np.mean(g[i0:i1].std(0)) * np.sqrt(stream.dt_nominal)),
                    "acc_noise_density": float(np.mean(a[i0:i1].std(0)) * np.sqrt(stream.dt_nominal)),
                    "over_s": (int(t[i1 - 1]) - int(t[i0])) * 1e-9}
    missing = set(getattr(stream, "noise_missing", ()))
    stated = {k: (None if k in missing else getattr(stream.noise, k)) for k in ("gyro_noise_density", "acc_noise_density")}
    noise, note = noise_model(stream, measured, standstills, still)
    flags = _flags(stream, start)
    rep = ImuReport(len(t), (int(t[-1]) - t0) * 1e-9, stream.rate_hz, gaps, standstills, start, measured, stated,
                    noise_used=noise, flags=flags, noise_note=note)

    # the attitude: levelled from the starting standstill (or the first 0.5 s of specific force)
    if start is not None:
        roll, pitch, b_g = start.roll, start.pitch, start.b_g
    else:
        k = max(int(round(0.5 / stream.dt_nominal)), 1)
        roll, pitch = tilt_from_specific_force(a[:k].mean(0))
        b_g = np.zeros(3)
    R0 = est.rtilt(roll, pitch)
    if start is None:  # in motion from the first sample: the starting velocity is unknown
        cfg = replace(cfg, velocity_sigma0=MOVING_START_VELOCITY_SIGMA)
    else:  # as uncertain as the standstill's own spread says (slow motion passes the loose IMU test)
        tilt_spread, bias_spread = _start_spread(stream, still[0][1])
        cfg = replace(cfg, tilt_sigma0=max(cfg.tilt_sigma0, tilt_spread), bias_sigma0=max(cfg.bias_sigma0, bias_spread))
    rep.attitude = VelocityAidedFilter(R0, b_g, noise, stream.dt_nominal, cfg).run(t, g, _in_g(a, start))
    rep.attitude_offline = compensated_vqf_attitude(g, a, stream.dt_nominal, compensation(stream, still, b_g, causal=False),
                                                    offline=True)
    rep.attitude_causal = compensated_vqf_attitude(g, a, stream.dt_nominal, compensation(stream, still, b_g, causal=True))
    if gt is not None:
        if align:
            t_al, g_al = align_gyro if align_gyro is not None else (t, g)
            rep.alignment = estimate_alignment(t_al, np.asarray(g_al) - b_g, gt, rotation=not in_imu_frame)
            rep.reference_note = (rep.alignment.describe(in_imu_frame) if rep.alignment is not None else
                                  "reference NOT aligned: too little rotation to estimate a clock offset")
        else:
            rep.reference_note = "reference used as given (--no-align, or aligned to the IMU by the dataset)"
        ref = rep.alignment.apply(gt) if rep.alignment is not None else gt
        if scored_t_ns is not None:
            rep.reference_note += f"; scored over {len(scored_t_ns)} samples (the dataset's movement phases)"
        rep.comparison = _compare(rep, stream, TiltReference(ref, scored_t_ns), R0, b_g, cfg, still)
    return rep


def compensation(stream: ImuStream, still: list, b_g, causal: bool) -> np.ndarray:
    """The gyro bias (n, 3) rad/s the standstill-compensated VQF rows subtract: ``b_g`` (the starting
    standstill's) re-measured at every later standstill whose specific force stayed still
    (:func:`~gevi_cli.inertial.standstill.standstill_bias_track`), causal or offline."""
    w = max(int(round(STILL_WINDOW_S / stream.dt_nominal)), 4)
    return standstill_bias_track(stream.t_ns, stream.gyro, stream.acc, still, b_g, w, causal)


def _start_spread(stream: ImuStream, i1: int) -> tuple[float, float]:
    """What the levelling and the bias from the starting standstill are worth when it was slow motion
    rather than rest, from its STILL_WINDOW_S tiles: the RMS angle (rad) of their specific-force
    directions around the mean (the levelling is the start's tilt, which is one of them) and the
    standard error (rad/s, largest axis) of the mean rate over the tiles (the bias is that mean)."""
    w = max(int(round(STILL_WINDOW_S / stream.dt_nominal)), 4)
    n = (i1 // w) * w
    if n < 2 * w:
        return 0.0, 0.0
    a = stream.acc[:n].reshape(-1, w, 3).mean(1)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    m = a.mean(0)
    m /= np.linalg.norm(m)
    g = stream.gyro[:n].reshape(-1, w, 3).mean(1)
    return (float(np.sqrt(np.mean(np.arccos(np.clip(a @ m, -1.0, 1.0)) ** 2))),
            float(np.sqrt(np.mean((g - g.mean(0)) ** 2, axis=0) / len(g)).max()))


def _in_g(acc: np.ndarray, start: StandstillEstimate | None) -> np.ndarray:
    """The specific force the velocity-aided filter integrates: rescaled to g at rest when the starting
    standstill's mean |a| is off by more than ACC_SCALE_LIMIT (units in g, or a scale error: flagged)."""
    if start is not None and abs(start.acc_norm - GRAVITY) > ACC_SCALE_LIMIT:
        return acc * (GRAVITY / start.acc_norm)
    return acc


def noise_model(stream: ImuStream, measured: dict, standstills: list, still: list) -> tuple[ImuNoise, str]:
    """The noise model the filter runs with and one line saying where it comes from: the dataset's where it
    states one; where it does not, the white-noise densities measured at the longest standstill (the
    random walks, which seconds at rest cannot measure, stay EuRoC ADIS16448's)."""
    missing = set(getattr(stream, "noise_missing", ()))
    if not missing:
        return stream.noise, "noise model: as stated by the dataset"
    measurable = {"gyro_noise_density", "acc_noise_density"} & missing
    if not measured or not measurable:
        return stream.noise, (f"noise model: none stated for {', '.join(sorted(missing))} and no standstill to measure "
                              "it: EuRoC ADIS16448 values")
    noise = replace(stream.noise, **{k: measured[k] for k in measurable})
    i = max(range(len(still)), key=lambda j: still[j][1] - still[j][0])
    a, b = standstills[i]
    rest = sorted(missing - measurable)
    return noise, (f"noise model: none stated; using the white noise measured at rest ({a:.1f}-{b:.1f} s): gyro "
                   f"{noise.gyro_noise_density:.3g} rad/s/sqrt(Hz), acc {noise.acc_noise_density:.3g} m/s^2/sqrt(Hz)"
                   + (f" ({', '.join(rest)}: EuRoC ADIS16448's)" if rest else ""))


def _flags(stream: ImuStream, start: StandstillEstimate | None) -> list[str]:
    out = []
    if start is not None and abs(start.acc_norm - GRAVITY) > ACC_SCALE_LIMIT:
        out.append(f"mean |specific force| at rest is {start.acc_norm:.3f} m/s^2, not 9.81: accelerometer units or "
                   "scale wrong (g instead of m/s^2?); the velocity-aided filter rescales it to 9.81")
    peak = float(np.abs(stream.gyro).max())
    if (start is not None and np.linalg.norm(start.b_g) > 0.5) or peak > 35.0:
        at_rest = f"|rate at rest| {np.linalg.norm(start.b_g):.3g} rad/s, " if start is not None else ""
        out.append(f"gyro looks like deg/s, not rad/s ({at_rest}peak {peak:.3g})")
    if start is None:
        out.append("the stream does not start at rest: levelled from the first 0.5 s of specific force, gyro bias 0")
    return out


def _traj(t_ns, R):
    from gevi_cli.trajectory import Trajectory

    return Trajectory.from_rotations(np.asarray(t_ns, dtype=np.int64), R, np.zeros((len(t_ns), 3)), frame="body")


class TiltReference:
    """The reference attitude (Trajectory, IMU clock and frame), slerp-interpolated at any stamps inside
    its span and not across its gaps (intervals over GAP_FACTOR x its median); ``scored_t_ns``: only these stamps
    count (None: all)."""

    def __init__(self, gt, scored_t_ns=None):
        from scipy.spatial.transform import Rotation, Slerp

        self.t_ns = gt.t_ns
        self._t0 = int(gt.t_ns[0])
        self._slerp = Slerp((gt.t_ns - self._t0) * 1e-9, Rotation.from_quat(gt.quat_xyzw))
        self._gap_ns = GAP_FACTOR * float(np.median(np.diff(gt.t_ns))) if len(gt) > 1 else 0.0
        self.scored = None if scored_t_ns is None else np.asarray(scored_t_ns, dtype=np.int64)

    def tilt(self, t_ns, R):
        """:class:`~gevi_cli.evaluation.tilt.TiltErrors` of the estimate ``R`` (n, 3, 3) stamped ``t_ns``."""
        from gevi_cli.evaluation.tilt import tilt_errors

        t = np.asarray(t_ns, dtype=np.int64)
        ok = (t >= self.t_ns[0]) & (t <= self.t_ns[-1])
        if self.scored is not None:
            ok &= np.isin(t, self.scored)
        i = np.clip(np.searchsorted(self.t_ns, t), 1, len(self.t_ns) - 1)
        ok &= (self.t_ns[i] - self.t_ns[i - 1]) <= self._gap_ns
        t = t[ok]
        R_ref = self._slerp((t - self._t0) * 1e-9).as_matrix()
        return tilt_errors(_traj(t, np.asarray(R)[ok]), _traj(t, R_ref), max_diff_s=1e-7)


def held_back(t_out, t_samples) -> np.ndarray:
    """Stamps of outputs that integrated the samples before ``t_out`` (gevi's filters: sample ``k`` over
    ``[t_k, t_k+1)``), in the report's convention: the sample before (-1 for the first)."""
    i = np.searchsorted(t_samples, t_out)
    return np.where(i > 0, t_samples[np.maximum(i - 1, 0)], -1)


def _compare(rep: ImuReport, stream: ImuStream, ref: TiltReference, R0, b_g, cfg: VelocityAidedConfig,
             still: list) -> list:
    from gevi_cli.inertial.vqf_rows import COMPENSATED_PARAMS, vqf_attitude, vqf_version

    t, g, a = stream.t_ns, stream.gyro, stream.acc

    def tilt_stats(t_ns, R, forward_hold=True):  # (tilt RMSE, roll/pitch RMSE, trend)
        te = ref.tilt(held_back(t_ns, t) if forward_hold else t_ns, R)
        if len(te.t_ns) == 0:
            return float("nan"), float("nan"), float("nan")
        return te.rmse_deg, te.roll_pitch_rmse_deg, te.trend_deg_per_min(int(te.t_ns[0]))

    rows = [("velocity-aided filter (gevi imu), causal", tilt_stats(rep.attitude.t_ns, rep.attitude.R_WI),
             "online gyro bias and scale; gravity weighted by the measured acceleration; bounded velocity")]
    for adaptive, name, note in ((True, "gravity-prior filter, adaptive weight", "adaptive Sigma_imu (GeVI --no-fusion)"),
                                 (False, "gravity-prior filter, fixed weight", "Sigma = noise floor")):
        old = GravityAttitudeFilter(R0, b_g, rep.noise_used, stream.dt_nominal, AttitudeFilterConfig(adaptive=adaptive))
        trk = run_filter(old, t, g, a)
        rows.append((name + ", causal", tilt_stats(trk.t_ns, trk.R_WI), note))
    rows.append(("gyro-only integration", tilt_stats(t, gyro_only(R0, b_g, t, g)), "standstill gyro bias"))

    def scores(taus):
        return [tilt_stats(t, level_rotations(gb)) for gb in complementary_bank(R0, b_g, t, g, a, taus)]

    ch = best_on_grid(COMPLEMENTARY_TAUS_S, scores, min_tau=stream.dt_nominal)
    lo, hi = ch.tried[0][0], ch.tried[-1][0]
    edge = ", AT THE GRID'S EDGE" if ch.at_edge else ""
    rows.append(("complementary filter, fixed gain (oracle)", ch.score,
                 f"time constant {ch.best:g} s chosen on the ground truth, best of {len(ch.tried)} ({lo:g}-{hi:g} s, "
                 f"1-2-5){edge}"))
    rep.complementary_choice = ch
    v = vqf_version()
    for offline, name, note in ((False, f"VQF 6D online (vqf {v}), causal", "vqf.VQF, default parameters"),
                                (True, f"VQF 6D offline (vqf {v}), offline", "vqf.offlineVQF, default parameters")):
        rows.append((name, tilt_stats(t, vqf_attitude(g, a, stream.dt_nominal, offline), forward_hold=False),
                     note + f"; sample period {stream.dt_nominal * 1e3:.4g} ms"))
    params = ", ".join(f"{k} {v:g}" for k, v in COMPENSATED_PARAMS.items())
    comp = ("VQF 6D on the gyro minus the standstill bias (re-measured at each standstill whose specific force stayed "
            "still{}), " + params + " (deg/s, s)")
    rows.append(("standstill-compensated VQF online (gevi imu attitude.tum), causal",
                 tilt_stats(t, rep.attitude_causal, forward_hold=False), comp.format(": the latest")))
    rows.append(("standstill-compensated VQF offline (gevi imu attitude_offline.tum), offline",
                 tilt_stats(t, rep.attitude_offline, forward_hold=False), comp.format(": linear between them")))
    return rows
