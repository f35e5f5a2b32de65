"""The LK front end: raw stereo frames -> tracked left features with persistent ids, stereo at keyframes.

Pixels are pixels of the *rectified* images (:attr:`ImageFrontEnd.camera`); ids int64, increasing,
never reused.  Per frame (protocol :class:`~gevi_cli.frontend.FrontEnd`):

- ``track(frame, rotation)``: rectify the left image (and remove its lamp shading when ``shading_px``
  is set, :mod:`~gevi_cli.frontend.shading`), LK from the previous frame (forward-backward checked;
  with the predicted camera rotation removed first, :mod:`~gevi_cli.frontend.derotate`), drop the
  failures.  The first call detects instead.
- ``keyframe(frame)`` (same frame, after ``track``): detect in the grid cells without a feature
  (new ids), rectify the right image and match all current features left -> right.  Only the
  matched ones are returned; the unmatched stay tracked.

State between frames is the previous left image (as a :class:`~gevi_cli.frontend.klt.Pyramid`),
the ids and pixels, and one number (the previous keyframe's median disparity, the stereo prior).
Within one frame, identified by ``t_ns``, nothing is computed twice.
"""
from __future__ import annotations

import time

import numpy as np

from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.frontend import reacquire
from gevi_cli.frontend.affine import PatchTemplates
from gevi_cli.frontend.config import DEROTATE_MIN_DEG, FB_MAX_PX, FrontendConfig
from gevi_cli.frontend.derotate import apply_homography, derotate, fit_inplane, rotation_homography
from gevi_cli.frontend.grid import GridDetector
from gevi_cli.frontend.klt import Pyramid, build_pyramid, in_image, track_lk, track_lk_scaled
from gevi_cli.frontend.rectify import Rectifier
from gevi_cli.frontend.shading import remove_shading
from gevi_cli.frontend.stereo import match_stereo
from gevi_cli.geometry import log_so3
from gevi_cli.observations import FeatureObs, Prediction, RectifiedStereo, StereoObs

STAGES = ("rectify", "pyramid", "derotate", "lk", "affine", "detect", "stereo", "reacquire")


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False  # handed out without copying: nobody may change our state through it
    return a


class ImageFrontEnd:
    """:class:`~gevi_cli.frontend.FrontEnd` on raw :class:`~gevi_cli.datasets.StereoFrame` objects.

    ``timings`` maps each stage of :data:`STAGES` to its seconds in the last ``track`` or
    ``keyframe`` call (0.0 for stages that call did not run).
    """

    camera: RectifiedStereo

    def __init__(self, rig: StereoRig, cfg: FrontendConfig | None = None):
        self.cfg = cfg if cfg is not None else FrontendConfig()
        self.rectifier = Rectifier(rig)
        self.camera = self.rectifier.camera
        self._detect = GridDetector(self.cfg)
        self.ids = _frozen(np.empty(0, np.int64))
        self.uv = _frozen(np.empty((0, 2)))
        self._next_id = 0
        self._t_ns: int | None = None          # stamp of the frame the state describes
        self._left: Pyramid | None = None      # its rectified left image
        self._right: Pyramid | None = None     # its rectified right image, made by keyframe() only
        self._stereo: StereoObs | None = None  # its keyframe result, if keyframe() ran
        self._disparity_prior: float | None = None
        self._step: tuple[np.ndarray, np.ndarray] | None = None  # the last step's tracks (before, after)
        self._templates: PatchTemplates | None = None  # the last keyframe's patches (affine re-alignment)
        self._f32: tuple[Pyramid, np.ndarray] | None = None  # (pyramid, its image as float32)
        self._kf_pyr: Pyramid | None = None  # the last keyframe's rectified left image
        self._kf_features: tuple[np.ndarray, np.ndarray] | None = None  # its stereo features (ids, pixels)
        self._kf_patches: reacquire.KeyframePatches | None = None  # their ORB descriptors, made when first needed
        self.timings: dict[str, float] = dict.fromkeys(STAGES, 0.0)

    # -- protocol ---------------------------------------------------------------------------------
    def track(self, frame, rotation: np.ndarray | None = None, predicted: Prediction | None = None) -> FeatureObs:
        """Left features of ``frame`` (rectified pixels) with the ids they had before.

        ``rotation``: predicted ``R_cp`` (3, 3), previous rectified-left camera coordinates ->
        current ones (None: the rotation fitted to the last step's tracks); removed before LK when
        ``cfg.derotate`` is on and it exceeds ``DEROTATE_MIN_DEG``.  ``predicted``: the back end's
        predicted pixels and patch scales in ``frame`` of some features (their keyframe points seen from
        the predicted pose); LK starts there instead of at the previous pixel, at that scale."""
        self.timings = dict.fromkeys(STAGES, 0.0)
        self._track(frame, rotation, predicted)
        return FeatureObs(self.ids, self.uv)

    def reacquire(self, frame, predicted: Prediction | None = None, keep_tracks: bool = False) -> FeatureObs | None:
        """The last keyframe's features found again in ``frame`` (the frame ``track`` just ran on) by
        ORB descriptors, guided by ``predicted`` pixels where given (within ``REACQUIRE_RADIUS_PX``;
        :mod:`~gevi_cli.frontend.reacquire`).

        Each match is refined to sub-pixel by LK from the keyframe's image, started at the matched
        detection with the patch scaled by the detection's pyramid scale, and kept only if that LK
        passes its forward-backward check.  A feature LK had lost is tracked again; one LK still
        holds keeps its LK pixel with ``keep_tracks`` (a top-up), else the re-found pixel replaces it
        unless the two agree within ``FB_MAX_PX`` x 4 px (LK has just failed the pose).  Returns the
        frame's features with that done, or None when re-acquisition is off or there is no keyframe;
        the front end's own features change only when the back end :meth:`adopt` s them."""
        if not self.cfg.reacquire or self._kf_pyr is None or int(frame.t_ns) != self._t_ns:
            return None
        with self._timed("reacquire"):  # added to this frame's track() timings
            if self._kf_patches is None:
                self._kf_patches = reacquire.describe(self._kf_pyr.image, *self._kf_features, self.cfg)
            ids, uv, scale = reacquire.match(self._kf_patches, self._left.image, self.cfg, predicted)
            order = np.argsort(self._kf_patches.ids)
            kf_uv = self._kf_patches.uv[order[np.searchsorted(self._kf_patches.ids, ids, sorter=order)]]
            uv, ok = track_lk_scaled(self._kf_pyr, self._left, kf_uv, self.cfg, uv, scale)
            ids, uv = ids[ok], uv[ok]
            _, i_state, i_new = np.intersect1d(self.ids, ids, assume_unique=True, return_indices=True)
            agree = np.linalg.norm(self.uv[i_state] - uv[i_new], axis=1) <= 4 * FB_MAX_PX
            keep = np.ones(len(self.ids), bool)
            fresh = np.ones(len(ids), bool)
            if keep_tracks:
                fresh[i_new] = False
            else:
                keep[i_state[~agree]] = False  # LK's track of a re-found feature went elsewhere: the descriptor wins
                fresh[i_new[agree]] = False
            all_ids = np.concatenate([self.ids[keep], ids[fresh]])
            all_uv = np.concatenate([self.uv[keep], uv[fresh]])
            order = np.argsort(all_ids, kind="stable")
        return FeatureObs(_frozen(all_ids[order]), _frozen(all_uv[order]))

    def adopt(self, frame, obs: FeatureObs) -> None:
        """Make ``obs`` (what :meth:`reacquire` returned for ``frame``) the front end's features of ``frame``."""
        if int(frame.t_ns) != self._t_ns:
            raise ValueError("adopt: features of a frame other than the last tracked one")
        self.ids, self.uv = obs.ids, obs.uv
        self._step = None  # the last step's tracks no longer describe this frame's features

    def keyframe(self, frame) -> StereoObs:
        """Detect in empty cells (new ids), then stereo-match every current feature of ``frame``."""
        self.timings = dict.fromkeys(STAGES, 0.0)
        t_ns = self._track(frame)  # no-op when track(frame) ran, as the protocol has it
        if self._stereo is not None:
            return self._stereo
        if self._right is None:  # first, so that a bad right image leaves the state untouched
            with self._timed("rectify"):
                right = remove_shading(self.rectifier.right(self._image(frame, "right", t_ns)),
                                       self.cfg.shading_px)
            with self._timed("pyramid"):
                self._right = build_pyramid(right, self.cfg)
        with self._timed("detect"):
            new = self._detect(self._left.image, self.uv)
        self._add(new)
        with self._timed("stereo"):
            uv_r, ok = match_stereo(self._left, self._right, self.uv, self.camera, self.cfg,
                                    disparity_prior=self._disparity_prior)
        if ok.any():
            self._disparity_prior = float(np.median(self.uv[ok, 0] - uv_r[ok, 0]))
        self._stereo = StereoObs(_frozen(self.ids[ok]), _frozen(self.uv[ok]), _frozen(uv_r[ok]))
        # what re-acquisition looks for later: the features with a stereo point, in this image
        self._kf_pyr, self._kf_features, self._kf_patches = self._left, (self._stereo.ids, self._stereo.uv_left), None
        if self.cfg.affine:
            # the features with a stereo point only: they are what the pose and the BA's keyframe pairs use
            with self._timed("affine"):
                self._templates = PatchTemplates(self._left_f32(), self._stereo.ids, self._stereo.uv_left)
        return self._stereo

    def keyframe_decision(self, frame) -> None:
        """The back end's keyframe rule decides."""
        return None

    # -- internals --------------------------------------------------------------------------------
    def _align(self) -> None:
        """The current tracks re-aligned to the last keyframe's patches (affine warp)."""
        if self._templates is None or not len(self.uv):
            return
        with self._timed("affine"):
            uv, _ = self._templates.align(self._left_f32(), self.ids, self.uv)
        self.uv = _frozen(uv)

    def _left_f32(self) -> np.ndarray:
        """The current left image as float32 (what the affine re-alignment samples), made once per frame."""
        if self._f32 is None or self._f32[0] is not self._left:
            self._f32 = (self._left, self._left.image.astype(np.float32))
        return self._f32[1]

    def _timed(self, stage: str):
        return _Timer(self.timings, stage)

    @staticmethod
    def _image(frame, side: str, t_ns: int) -> np.ndarray:
        img = getattr(frame, side, None)
        if img is None:
            raise ValueError(f"frame t_ns={t_ns}: the {side} image is None (unreadable or missing file)")
        return img

    def _add(self, uv_new: np.ndarray) -> None:
        if len(uv_new) == 0:
            return
        ids = np.arange(self._next_id, self._next_id + len(uv_new), dtype=np.int64)
        self._next_id += len(uv_new)
        self.ids = _frozen(np.concatenate([self.ids, ids]))
        self.uv = _frozen(np.concatenate([self.uv, uv_new]))

    def _track(self, frame, rotation: np.ndarray | None = None, predicted: Prediction | None = None) -> int:
        """Bring the state to ``frame`` (idempotent per ``t_ns``); returns its stamp."""
        if frame is None:
            raise ValueError("frame is None")
        t_ns = int(frame.t_ns)
        if t_ns == self._t_ns:
            return t_ns
        raw = self._image(frame, "left", t_ns)
        with self._timed("rectify"):
            left = remove_shading(self.rectifier.left(raw), self.cfg.shading_px)
        with self._timed("pyramid"):
            pyr = build_pyramid(left, self.cfg)
        if self._left is None:
            with self._timed("detect"):
                first = self._detect(pyr.image, None)
            self._add(first)
        elif len(self.uv):
            H = self._derotation(rotation)
            guess, has, scale = self._guesses(predicted)
            if H is None:
                with self._timed("lk"):
                    uv, ok = self._lk(pyr, guess, scale)
            else:
                with self._timed("derotate"):
                    pyr_d = build_pyramid(derotate(pyr.image, H), self.cfg)
                    if guess is not None:  # predicted pixels into the derotated image
                        guess[has] = apply_homography(np.linalg.inv(H), guess[has])
                with self._timed("lk"):
                    uv, ok = self._lk(pyr_d, guess, scale)
                    uv = apply_homography(H, uv)  # (NaN stays NaN)
                    ok &= in_image(uv, pyr.shape)
            uv_ok = _frozen(uv[ok])
            self._step = (self.uv[ok], uv_ok)
            self.ids, self.uv = _frozen(self.ids[ok]), uv_ok
        self._t_ns, self._left, self._right, self._stereo = t_ns, pyr, None, None
        if self.cfg.affine:
            self._align()
        return t_ns

    def _lk(self, pyr, guess: np.ndarray | None, scale: np.ndarray | None):
        """LK of the state's features from the previous image into ``pyr``, from the predicted pixels
        and patch scales where there are any."""
        if guess is None:
            return track_lk(self._left, pyr, self.uv, self.cfg)
        return track_lk_scaled(self._left, pyr, self.uv, self.cfg, guess, scale)

    def _guesses(self, predicted: Prediction | None):
        """LK start pixels: the predicted pixel where ``predicted`` has the feature (inside the image),
        else the previous pixel; the mask of the predicted ones; their predicted patch scales (1
        elsewhere).  (None, None, None) without a prediction."""
        if predicted is None or not len(predicted):
            return None, None, None
        _, i_state, i_pred = np.intersect1d(self.ids, predicted.ids, assume_unique=True, return_indices=True)
        inside = in_image(predicted.uv[i_pred], self._left.shape)
        if not inside.any():
            return None, None, None
        guess = np.array(self.uv, dtype=np.float64)
        guess[i_state[inside]] = predicted.uv[i_pred[inside]]
        has = np.zeros(len(guess), bool)
        has[i_state[inside]] = True
        scale = np.ones(len(guess))
        scale[i_state[inside]] = predicted.scale[i_pred[inside]]
        return guess, has, scale

    def _derotation(self, rotation: np.ndarray | None) -> np.ndarray | None:
        """The homography (previous -> current pixels) to remove before LK: of the back end's
        ``rotation``, else of the last step's image rotation; None when off or too small to matter."""
        if not self.cfg.derotate:
            return None
        if rotation is None:  # fitted only when needed: with a back-end prior it is not
            fit = fit_inplane(*self._step) if self._step is not None else None
            if fit is None or fit[1] < DEROTATE_MIN_DEG:
                return None
            return fit[0]
        R = np.asarray(rotation, dtype=float)
        if (R.shape != (3, 3) or not np.all(np.isfinite(R))
                or np.degrees(np.linalg.norm(log_so3(R))) < DEROTATE_MIN_DEG):
            return None
        return rotation_homography(R, self.camera.K)


class _Timer:
    """Adds the wall time of a ``with`` block to ``timings[stage]`` (seconds)."""

    __slots__ = ("timings", "stage", "t0")

    def __init__(self, timings: dict[str, float], stage: str):
        self.timings, self.stage = timings, stage

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        self.timings[self.stage] += time.perf_counter() - self.t0
        return False
