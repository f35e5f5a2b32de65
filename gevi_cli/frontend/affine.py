"""Affine re-alignment of tracks to their patches in the keyframe's image.

Why: the front end tracks frame to frame with OpenCV's LK, which fits a *translation* of a 21 px
window.  Where the scene is a slanted plane seen from a moving camera, the window's content also
stretches and shears between frames, and the fitted translation is not the motion of the window's
centre: each feature is off by an amount its texture decides, with the same sign frame after frame,
so the error grows with the frames since the keyframe (rotation is removed frame to frame by
:mod:`~gevi_cli.frontend.derotate`; what is left on the euroc-like renders is 0.39 px RMS after 8
frames).  The epipolar BA turns the new keyframe's track errors into rotation (docs/method.md,
sections 10 and 12.1).  So each track is re-aligned directly to its patch in the keyframe's image with
an affine warp (6 parameters: the centre and a 2x2 linear part), which models a plane's local
perspective change to first order.

How (inverse compositional Lucas-Kanade, Baker & Matthews 2004, vectorised over the features):
:class:`PatchTemplates` samples each keyframe feature's patch (a ``window`` x ``window`` grid of
offsets ``x`` around ``p0``, every other pixel with ``checkerboard``), its gradients and the 6x6
normal matrices once; :meth:`PatchTemplates.align` warps a later image at ``c + M x`` and takes at
most ``iters`` Gauss-Newton steps, a feature stopping when its centre moves less than ``eps_px``.
``c`` starts at the LK track, ``M`` at the feature's last accepted warp, else at the affine map of its
``neighbours`` nearest features' motion since the keyframe.  Patch gain and offset are normalised
each step.  Only tracks whose neighbourhood stretched or sheared enough to bias LK (``min_deform_px``
at a patch corner) are re-aligned; a result is kept only where it converged, moved the centre by at
most ``max_shift_px``, kept ``M``'s singular values within ``[1/max_scale, max_scale]`` and reached a
patch correlation (ZNCC) of ``min_zncc`` and no less than at its start; elsewhere the LK track stays.
Pixels: rectified left image coordinates, float64 in and out (float32 inside).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class AffineRefineConfig:
    window: int = 21          # patch side (px, odd)
    iters: int = 3           # Gauss-Newton iterations at most
    eps_px: float = 0.05      # convergence: the centre's move in an update (px)
    neighbours: int = 8       # features in the local fit of M's start
    checkerboard: bool = True  # Gauss-Newton on every other pixel of the patch
    min_deform_px: float = 0.1  # re-align where the local stretch since the keyframe moves a patch corner this far
    max_shift_px: float = 1.5  # largest accepted move of a track (px)
    max_scale: float = 1.5    # M's singular values within [1/max_scale, max_scale]
    min_zncc: float = 0.95     # patch correlation after refinement


def _sample(img: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Bilinear samples of the float32 image ``img`` at the pixels (X, Y), float32 maps (n, m);
    NaN outside the image."""
    if X.size == 0:
        return np.empty(X.shape, np.float32)
    return cv2.remap(img, X, Y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)


def _normalise(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero-mean patches and their standard deviations (rows)."""
    Z = P - P.mean(axis=1, keepdims=True)
    return Z, np.sqrt(np.mean(Z * Z, axis=1))


def singular_values_2x2(M: np.ndarray) -> np.ndarray:
    """Singular values (n, 2), largest first, of the 2x2 matrices ``M`` (n, 2, 2), in closed form
    (LAPACK per 2x2 matrix costs ~5 us each, a third of the re-alignment's budget at 200 features)."""
    a, b, c, d = M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1]
    q = a * a + b * b + c * c + d * d
    r = np.sqrt(np.maximum(q * q - 4.0 * (a * d - b * c) ** 2, 0.0))
    return np.sqrt(np.column_stack([(q + r) / 2.0, np.maximum(q - r, 0.0) / 2.0]))


def _inv_2x2(M: np.ndarray) -> np.ndarray:
    a, b, c, d = M[..., 0, 0], M[..., 0, 1], M[..., 1, 0], M[..., 1, 1]
    det = a * d - b * c
    return np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2) / det[..., None, None]


def neighbours(p0: np.ndarray, k: int) -> np.ndarray:
    """Indices (n, min(k + 1, n)) of each point's nearest points in ``p0`` (itself first)."""
    return cKDTree(p0).query(p0, k=min(k + 1, len(p0)))[1].reshape(len(p0), -1)


def local_affine(p0: np.ndarray, p1: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Per point, the linear part (n, 2, 2) of the affine map ``p1 ~ A p0 + b`` fitted over its
    neighbours ``nb`` (n, k) (see :func:`neighbours`); rows of ``p1`` that are NaN (lost tracks) take
    no part.  Identity where fewer than 3 neighbours are left."""
    w = np.isfinite(p1).all(1)[nb].astype(np.float64)             # (n, k)
    P0, P1 = p0[nb], np.nan_to_num(p1)[nb]                         # (n, k, 2)
    sw = np.maximum(w.sum(1, keepdims=True), 1e-12)
    X = P0 - (w[..., None] * P0).sum(1, keepdims=True) / sw[..., None]
    Y = P1 - (w[..., None] * P1).sum(1, keepdims=True) / sw[..., None]
    Xw = X * w[..., None]
    S = Xw.transpose(0, 2, 1) @ X + 1e-6 * np.eye(2)
    C = (Y * w[..., None]).transpose(0, 2, 1) @ X
    A = C @ _inv_2x2(S)
    A[sw[:, 0] < 3] = np.eye(2)
    return A


class PatchTemplates:
    """The previous keyframe's patches, prepared once for the inverse compositional updates.

    ``img0`` (2-D, uint8 or float32): the keyframe's rectified left image; ``ids`` (n,) and ``p0``
    (n, 2): its features and their pixels.  :meth:`align` re-aligns later tracks of these features.
    """

    def __init__(self, img0: np.ndarray, ids: np.ndarray, p0: np.ndarray, cfg: AffineRefineConfig = AffineRefineConfig()):
        self.cfg = cfg
        self.ids = np.asarray(ids, np.int64).reshape(-1)
        self.p0 = np.asarray(p0, np.float64).reshape(-1, 2)
        h = cfg.window // 2
        g = np.arange(-h, h + 1, dtype=np.float32)
        gx_, gy_ = np.meshgrid(g, g)
        self.offsets = np.column_stack([gx_.reshape(-1), gy_.reshape(-1)])  # (w*w, 2), row-major patch order
        dx, dy = self.offsets[:, 0], self.offsets[:, 1]
        # the template and its gradients (central differences of bilinear samples, one remap of the
        # patch plus a ring), float32 throughout; x and y maps kept apart (numpy is slow on a trailing
        # axis of 2)
        I0 = np.asarray(img0, np.float32)
        w = cfg.window
        ge = np.arange(-h - 1, h + 2, dtype=np.float32)  # the patch plus a one-pixel ring, for the gradients
        ex, ey = (a.reshape(-1) for a in np.meshgrid(ge, ge))
        n = len(self.p0)
        S = _sample(I0, self.p0[:, :1].astype(np.float32) + ex, self.p0[:, 1:].astype(np.float32) + ey)
        S = S.reshape(n, w + 2, w + 2)
        T = np.ascontiguousarray(S[:, 1:-1, 1:-1]).reshape(n, w * w)
        gx = (0.5 * (S[:, 1:-1, 2:] - S[:, 1:-1, :-2])).reshape(n, w * w)
        gy = (0.5 * (S[:, 2:, 1:-1] - S[:, :-2, 1:-1])).reshape(n, w * w)
        if cfg.checkerboard:
            # every other pixel (a checkerboard) of the patch: the same extent, which is what makes the
            # deformation observable, at half the samples per Gauss-Newton step
            keep = ((np.arange(w)[:, None] + np.arange(w)[None, :]) % 2 == 0).reshape(-1)
            T, gx, gy, self.offsets = T[:, keep], gx[:, keep], gy[:, keep], self.offsets[keep]
            dx, dy = self.offsets[:, 0], self.offsets[:, 1]
        valid = ~(np.isnan(T).any(1) | np.isnan(gx).any(1) | np.isnan(gy).any(1))
        if not valid.all():
            T, gx, gy = np.nan_to_num(T), np.nan_to_num(gx), np.nan_to_num(gy)
        self.Tz, self.sT = _normalise(T)
        # The steepest-descent images are (gx, gy) x (1, dx, dy); they are never formed: J^T e is
        # (gx e, gy e) against the basis B = (1, dx, dy), and J^T J the products of the gradients
        # against the basis' products (six numbers per gradient product).
        self.gx, self.gy = gx, gy
        self.B = np.column_stack([np.ones_like(dx), dx, dy])                       # (w*w, 3)
        BB = np.column_stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy])  # (w*w, 6)
        xx, xy, yy = (gx * gx) @ BB, (gx * gy) @ BB, (gy * gy) @ BB                # (n, 6) each
        sym = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])  # (1, dx, dy) x (1, dx, dy) -> column of BB
        H = np.empty((len(self.p0), 6, 6))
        H[:, 0::2, 0::2], H[:, 0::2, 1::2] = xx[:, sym], xy[:, sym]   # parameter order: (tx, ax1, ax2) of
        H[:, 1::2, 0::2], H[:, 1::2, 1::2] = xy[:, sym], yy[:, sym]   # x interleaved with y, reordered below
        order = [0, 1, 2, 4, 3, 5]  # interleaved (tx, ty, a11, a21, a12, a22) -> (tx, ty, a11, a12, a21, a22)
        H = H[:, order][:, :, order]
        self.valid = valid & (self.sT > 1e-3)
        H[~self.valid] = np.eye(6)
        # a feature whose 2x2 translation block (Shi-Tomasi) is near-singular cannot be aligned
        tr, det = H[:, 0, 0] + H[:, 1, 1], H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
        self.valid &= det > 1e-6 * tr ** 2
        self.Hinv = np.linalg.inv(H)
        self.nb = neighbours(self.p0, cfg.neighbours) if len(self.p0) else np.zeros((0, 1), int)
        # each feature's last accepted linear part: the next frame's start (seen False: not aligned yet)
        self.M = np.tile(np.eye(2), (len(self.ids), 1, 1))
        self.seen = np.zeros(len(self.ids), bool)

    def align(self, img1: np.ndarray, ids: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tracks ``p1`` (m, 2) of features ``ids`` (m,) in ``img1``, re-aligned to their keyframe
        patches.  Returns the positions (m, 2) and ``accepted`` (m,) bool (False: ``p1`` unchanged,
        also for features the keyframe did not have)."""
        ids = np.asarray(ids, np.int64).reshape(-1)
        p1 = np.asarray(p1, np.float64).reshape(-1, 2)
        out, accepted = p1.copy(), np.zeros(len(p1), bool)
        _, i0, i1 = np.intersect1d(self.ids, ids, assume_unique=True, return_indices=True)
        if len(i0):
            cur = np.full_like(self.p0, np.nan)  # every template feature's current track (NaN: lost)
            cur[i0] = p1[i1]
            # Only where the neighbourhood stretched or sheared since the keyframe: LK's translation is
            # biased by the patch's deformation (a rotation is removed frame to frame by the front end's
            # derotation), while the 6-parameter fit adds noise of its own, independent per frame.  On
            # the 10 s pool-easy render of the CI gate (a floor below a hovering camera), re-aligning
            # every track moved ATE / RPE by -56 % / +27 %, with this gate (0.1 px) by -46 % / +4 %.
            M = local_affine(self.p0, cur, self.nb[i0])
            sv = singular_values_2x2(M)
            deform = (self.cfg.window // 2) * np.abs(sv - 1.0).max(axis=1)
            sel = np.flatnonzero(deform >= self.cfg.min_deform_px)
            if len(sel):
                i0, i1 = i0[sel], i1[sel]
                out[i1], accepted[i1] = self._align(np.asarray(img1, np.float32), i0, p1[i1], M[sel])
        return out, accepted

    def _align(self, I1, k, p1, M_local):
        cfg = self.cfg
        Tz, sT, gx, gy, Hinv, B = self.Tz[k], self.sT[k], self.gx[k], self.gy[k], self.Hinv[k], self.B
        n = len(k)

        def warped(c, M):
            # the maps as one product each: (centre, first row of M) against the basis (1, dx, dy)
            return _sample(I1, np.column_stack([c[:, 0], M[:, 0, 0], M[:, 0, 1]]).astype(np.float32) @ B.T,
                           np.column_stack([c[:, 1], M[:, 1, 0], M[:, 1, 1]]).astype(np.float32) @ B.T)

        def zncc(P, sel=slice(None)):
            Pz, sP = _normalise(np.nan_to_num(P))
            return np.mean(Pz * Tz[sel], axis=1) / np.maximum(sP * sT[sel], 1e-12), Pz, sP

        fin = np.isfinite(p1).all(1)
        c = np.where(fin[:, None], p1, self.p0[k])
        # start: the feature's last accepted warp, else the affine map of its neighbours' motion
        M = self.M[k].copy()
        new = fin & ~self.seen[k]
        M[new] = M_local[new]
        bad = ~np.isfinite(M).all(axis=(1, 2)) | (np.abs(M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]) < 1e-3)
        M[bad] = np.eye(2)
        # Gauss-Newton steps; a feature stops once its centre moves less than eps_px in a step (its
        # correlation, taken at that step's start, tells the match)
        ok = self.valid[k] & fin
        zncc0, z = np.full(n, -np.inf), np.full(n, -np.inf)
        step = np.full(n, np.inf)
        idx = np.flatnonzero(ok)
        for it in range(cfg.iters):
            if len(idx) == 0:
                break
            sel = idx if len(idx) < n else slice(None)  # (no copies while every feature takes part)
            P = warped(c[sel], M[sel])
            inside = ~np.isnan(P).any(1)
            zi, Pz, sP = zncc(P, sel)
            z[idx] = zi
            if it == 0:
                zncc0[idx] = zi
            E = Pz * (sT[sel] / np.maximum(sP, 1e-12))[:, None] - Tz[sel]   # gain/offset matched error
            bx, by = (gx[sel] * E) @ B, (gy[sel] * E) @ B                      # (m, 3): J^T e by gradient
            b = np.column_stack([bx[:, 0], by[:, 0], bx[:, 1], bx[:, 2], by[:, 1], by[:, 2]]).astype(np.float64)
            dp = np.matmul(Hinv[sel], b[:, :, None])[:, :, 0]
            # the warp's update: W <- W o W(dp)^-1, with W(dp)(x) = dp[:2] + (I + A) x
            Mn = M[sel] @ _inv_2x2(np.eye(2) + dp[:, 2:].reshape(-1, 2, 2))
            cn = c[sel] - (Mn @ dp[:, :2, None])[:, :, 0]
            good = inside & np.isfinite(cn).all(1)
            step[idx] = np.where(good, np.linalg.norm(cn - c[sel], axis=1), np.inf)
            c[idx[good]], M[idx[good]] = cn[good], Mn[good]
            ok[idx[~good]] = False
            idx = idx[good & (step[idx] >= cfg.eps_px)]
        sv = singular_values_2x2(M)
        accepted = (ok & (step < cfg.eps_px) & (np.linalg.norm(c - p1, axis=1) <= cfg.max_shift_px)
                    & (sv[:, 0] <= cfg.max_scale) & (sv[:, 1] >= 1.0 / cfg.max_scale)
                    & (z >= cfg.min_zncc) & (z >= zncc0))
        self.M[k[accepted]], self.seen[k[accepted]] = M[accepted], True
        return np.where(accepted[:, None], c, p1), accepted

