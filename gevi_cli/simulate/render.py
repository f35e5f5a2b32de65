"""Per-pixel ray casting of a :class:`~gevi_cli.simulate.scene.Scene` (vectorized numpy + cv2.remap).

For each camera the unit ray of every sub-pixel sample (``supersample`` x ``supersample`` per pixel,
through the *distorted* pixel positions, so images come out distorted exactly like a real radtan
lens) is precomputed once in the camera frame.  A frame is rendered by

1. intersecting all rays with every plane that can be visible (depth test, two-sided planes);
2. sampling each plane's texture with trilinear mip-mapping (``cv2.remap`` on level pairs);
3. multiplying by uneven illumination, applying underwater attenuation/backscatter;
4. box-averaging the sub-samples (anti-aliasing), range-dependent blur;
5. adding sensor noise (shot + read noise) and quantizing to uint8.

Poses: ``T_W_C`` maps camera coordinates into the world (camera centre ``T_W_C[:3, 3]``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.simulate.camera import pixel_rays
from gevi_cli.simulate.scene import Plane, Scene

_REMAP_COLS = 4096


@dataclass(frozen=True)
class SensorModel:
    """Photometric sensor model.

    ``DN = 255 * exposure * I``; noise std in DN is ``sqrt(DN * 255 / full_well_e + read_noise_dn^2)``
    (Gaussian approximation of Poisson shot noise plus read noise), then rounding and clipping to
    uint8.  ``vignetting`` is the power of ``cos(angle to the optical axis)`` applied to irradiance.
    """

    exposure: float = 1.0
    full_well_e: float = 6000.0
    read_noise_dn: float = 1.0
    vignetting: float = 2.0
    noise: bool = True


def _remap_flat(img: np.ndarray, x: np.ndarray, y: np.ndarray, wrap: bool) -> np.ndarray:
    """Bilinear samples of ``img`` at float coordinates (x, y) (pixel centres at integers)."""
    n = x.size
    if n == 0:
        return np.zeros(0, np.float32)
    cols = min(_REMAP_COLS, n)
    rows = -(-n // cols)
    pad = rows * cols - n
    if pad:
        x = np.concatenate([x, np.zeros(pad, np.float32)])
        y = np.concatenate([y, np.zeros(pad, np.float32)])
    out = cv2.remap(img, x.reshape(rows, cols), y.reshape(rows, cols), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_WRAP if wrap else cv2.BORDER_REPLICATE)
    return out.reshape(-1)[:n]


class CameraRenderer:
    """Renders one camera of a scene.

    Args:
        camera: intrinsics and distortion.
        supersample: sub-samples per pixel along each axis (2 = 2x2).
    """

    def __init__(self, camera: Intrinsics, supersample: int = 2):
        self.camera = camera
        self.s = int(supersample)
        rays = pixel_rays(camera, self.s)
        self.shape_ss = rays.shape[:2]
        r = rays.reshape(-1, 3)
        self.rx = np.ascontiguousarray(r[:, 0], dtype=np.float32)
        self.ry = np.ascontiguousarray(r[:, 1], dtype=np.float32)
        self.rz = np.ascontiguousarray(r[:, 2], dtype=np.float32)
        # angular spacing of sub-samples (rad) for mip-level selection
        self.delta = 1.0 / (camera.f * self.s)
        # bounds of the field of view in normalized coordinates, for plane culling, and per sample
        # row / column, to restrict each plane to the block of samples its projection can cover
        xn = (r[:, 0] / r[:, 2]).reshape(self.shape_ss)
        yn = (r[:, 1] / r[:, 2]).reshape(self.shape_ss)
        self.fov_box = (xn.min(), xn.max(), yn.min(), yn.max())
        self.row_y = (yn.min(axis=1), yn.max(axis=1))
        self.col_x = (xn.min(axis=0), xn.max(axis=0))
        self._vign_cache: dict[float, np.ndarray] = {}

    # -------------------------------------------------------------------------------- helpers
    def _cos_axis_power(self, power: float) -> np.ndarray:
        if power not in self._vign_cache:
            self._vign_cache[power] = np.power(self.rz, np.float32(power)).astype(np.float32)
        return self._vign_cache[power]

    def _sample_block(self, plane: Plane, R_CW: np.ndarray, c_W: np.ndarray):
        """(row slice, column slice) of the sub-sample grid that can see ``plane``, or None.

        Conservative: the rectangle is clipped to z > near in the camera frame; its projection is a
        convex polygon whose normalized-coordinate bounding box selects the rows and columns whose
        rays can pass through it.
        """
        full = (slice(None), slice(None))
        corners = plane.corners()
        if corners is None:
            return full
        P = (corners - c_W) @ R_CW.T  # camera coordinates
        near = 1e-3
        pts = []
        for i in range(4):
            a, b = P[i], P[(i + 1) % 4]
            if a[2] > near:
                pts.append(a)
            if (a[2] > near) != (b[2] > near):
                s = (near - a[2]) / (b[2] - a[2])
                pts.append(a + s * (b - a))
        if not pts:
            return None
        pts = np.array(pts)
        xn, yn = pts[:, 0] / pts[:, 2], pts[:, 1] / pts[:, 2]
        rows = np.flatnonzero((self.row_y[1] >= yn.min()) & (self.row_y[0] <= yn.max()))
        cols = np.flatnonzero((self.col_x[1] >= xn.min()) & (self.col_x[0] <= xn.max()))
        if rows.size == 0 or cols.size == 0:
            return None
        return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)

    # --------------------------------------------------------------------------------- render
    def radiance(self, scene: Scene, T_W_C: np.ndarray, vignetting: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free image irradiance (float32, H x W, ~[0, 1]) and per-pixel mean range [m].

        ``vignetting`` is the power of cos(angle to the optical axis) applied to the irradiance.
        """
        R_WC = np.asarray(T_W_C[:3, :3], float)
        c_W = np.asarray(T_W_C[:3, 3], float)
        R_CW = R_WC.T
        shape = self.shape_ss
        n = self.rx.size
        rx2, ry2, rz2 = (a.reshape(shape) for a in (self.rx, self.ry, self.rz))
        t_best = np.full(shape, np.inf, np.float32)
        pid = np.full(shape, -1, np.int16)
        u_best = np.zeros(shape, np.float32)
        v_best = np.zeros(shape, np.float32)
        dn_best = np.ones(shape, np.float32)
        blocks = {}

        for k, plane in enumerate(scene.planes):
            block = self._sample_block(plane, R_CW, c_W)
            if block is None:
                continue
            nrm = plane.normal
            num = float(nrm @ (np.asarray(plane.origin) - c_W))
            if abs(num) < 1e-9:
                continue  # camera centre on the plane
            bx, by, bz = rx2[block], ry2[block], rz2[block]
            tmp = np.empty(bx.shape, np.float32)

            def dot(vec_C):
                a, b, c = (np.float32(x) for x in vec_C)
                out = bx * a
                np.multiply(by, b, out=tmp)
                out += tmp
                np.multiply(bz, c, out=tmp)
                out += tmp
                return out

            dn = dot(R_CW @ nrm)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.float32(num) / dn
            tb = t_best[block]
            hit = (t > 0) & (t < tb)
            if not hit.any():
                continue
            cu = float((c_W - plane.origin) @ plane.axis_u)
            cv_ = float((c_W - plane.origin) @ plane.axis_v)
            if plane.texture.wrap:
                cu = cu % plane.texture.period_u
                cv_ = cv_ % plane.texture.period_v
            u = dot(R_CW @ plane.axis_u)
            u *= t
            u += np.float32(cu)
            v = dot(R_CW @ plane.axis_v)
            v *= t
            v += np.float32(cv_)
            if np.isfinite(plane.size_u) or np.isfinite(plane.size_v):
                hit &= (u >= 0) & (u <= np.float32(plane.size_u)) & (v >= 0) & (v <= np.float32(plane.size_v))
            np.copyto(tb, t, where=hit)
            np.copyto(pid[block], np.int16(k), where=hit)
            np.copyto(u_best[block], u, where=hit)
            np.copyto(v_best[block], v, where=hit)
            np.copyto(dn_best[block], dn, where=hit)
            blocks[k] = block

        t_best, pid, u_best, v_best, dn_best = (a.reshape(-1) for a in (t_best, pid, u_best, v_best, dn_best))
        rx, ry, rz = self.rx, self.ry, self.rz
        value = np.empty(n, np.float32)
        counts = np.bincount(pid.astype(np.intp) + 1, minlength=len(scene.planes) + 1)
        for k in np.flatnonzero(counts) - 1:
            if counts[k + 1] == n:
                idx = slice(None)  # one surface fills the view: no gathers
            elif k >= 0 and blocks[k] != (slice(None), slice(None)):
                rs, cs = blocks[k]
                ri, ci = np.nonzero(pid.reshape(shape)[rs, cs] == k)
                idx = (ri + rs.start) * shape[1] + (ci + cs.start)
            else:
                idx = np.flatnonzero(pid == k)
            if k < 0:
                dz = rx[idx] * np.float32(R_WC[2, 0]) + ry[idx] * np.float32(R_WC[2, 1]) + rz[idx] * np.float32(R_WC[2, 2])
                value[idx] = np.float32(scene.sky) + np.float32(scene.sky_gradient) * dz
                continue
            value[idx] = self._shade(scene.planes[k], u_best[idx], v_best[idx], t_best[idx], dn_best[idx])

        # camera-side illumination falloff: lens vignetting (and the lamp cone under water)
        power = float(vignetting)
        water = scene.water
        t_clip = np.minimum(t_best, np.float32(1e4))
        if water is not None:
            power += water.lamp_power
            att = np.exp(np.float32(-water.attenuation) * t_clip)
            value *= att
            value += np.float32(water.veil) * (np.float32(1.0) - att)
        if power:
            value *= self._cos_axis_power(power)
        img = self._downsample(value)
        if water is not None and water.blur_max > 0:
            rng_m = self._downsample(t_clip)
            blurred = cv2.GaussianBlur(img, (0, 0), water.blur_sigma_px)
            w = np.float32(water.blur_max) * (np.float32(1.0) - np.exp(-rng_m / np.float32(water.blur_range)))
            img = img + w * (blurred - img)
        else:
            rng_m = None
        return img, rng_m

    def _downsample(self, flat: np.ndarray) -> np.ndarray:
        """Box average of s x s sub-samples (exact block mean; INTER_AREA with an integer factor)."""
        H, W, s = self.camera.height, self.camera.width, self.s
        a = flat.reshape(H * s, W * s)
        if s == 1:
            return a.copy()
        return cv2.resize(a, (W, H), interpolation=cv2.INTER_AREA)

    def _shade(self, plane: Plane, u, v, t, dn) -> np.ndarray:
        """Texture value (trilinear mip-mapping) times gain and illumination for one plane's samples."""
        tex = plane.texture
        nlev = len(tex.levels)
        # footprint of a sub-sample on the plane [m]; sqrt(|cos|) trades blur against aliasing at
        # grazing angles.  frexp gives floor(log2) and a mantissa in [0.5, 1): the blend weight
        # between the two levels is linear in the footprint (a cheap stand-in for log2's fraction).
        foot = t * np.float32(self.delta / tex.texel_m) / np.sqrt(np.abs(dn))
        mant, expo = np.frexp(np.maximum(foot, np.float32(1.0)))
        l0 = expo - 1
        frac = mant * np.float32(2.0) - np.float32(1.0)
        top = l0 >= nlev - 1
        if top.any():
            l0[top] = nlev - 1
            frac[top] = 0.0
        out = np.empty(u.shape, np.float32)
        lmin, lmax = int(l0.min()), int(l0.max())
        for level in range(lmin, lmax + 1):
            sel = np.flatnonzero(l0 == level) if lmin != lmax else slice(None)
            us, vs = u[sel], v[sel]
            if us.size == 0:
                continue
            a = self._sample_level(tex, level, us, vs)
            if level + 1 < nlev:
                b = self._sample_level(tex, level + 1, us, vs)
                b -= a
                b *= frac[sel]
                a += b
            out[sel] = a
        if plane.gain != 1.0:
            out *= np.float32(plane.gain)
        return out

    @staticmethod
    def _sample_level(tex, level: int, u, v) -> np.ndarray:
        img = tex.levels[level]
        h, w = img.shape
        x = u * np.float32(w / tex.period_u) - np.float32(0.5)
        y = v * np.float32(h / tex.period_v) - np.float32(0.5)
        return _remap_flat(img, x, y, tex.wrap)

    def render(self, scene: Scene, T_W_C: np.ndarray, sensor: SensorModel, rng: np.random.Generator | None) -> np.ndarray:
        """A uint8 image of ``scene`` seen from pose ``T_W_C`` (camera -> world)."""
        img, _ = self.radiance(scene, T_W_C, sensor.vignetting)
        dn = img * np.float32(255.0 * sensor.exposure)
        if sensor.noise and rng is not None:
            var = np.maximum(dn, 0) * np.float32(255.0 / sensor.full_well_e) + np.float32(sensor.read_noise_dn ** 2)
            dn = dn + np.sqrt(var) * rng.standard_normal(dn.shape, dtype=np.float32)
        return np.clip(np.rint(dn), 0, 255).astype(np.uint8)
