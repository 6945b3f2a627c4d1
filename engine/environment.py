"""Image-based environment light: an HDRI world as Cycles maps it, with importance sampling.

What it computes
    ``Environment(pixels, ...)`` holds one equirectangular (or mirror-ball) image and answers
    * ``radiance(directions)`` (N, 3) [W m^-2 sr^-1]: the image looked up along unit world
      directions (N, 3) as Cycles' Environment Texture does it (``svm_node_tex_environment``:
      the vector normalised, ``direction_to_equirectangular``: u = 1/2 - atan2(y, x) / 2 pi,
      v = 1 - acos(z) / pi; or ``direction_to_mirrorball``), texel centres at
      ((i + 1/2) / W, (j + 1/2) / H), row 0 at the bottom, Repeat extension in u and v
      (``EnvironmentTextureNode::image_params``), Closest / Linear (default) / Cubic
      (B-spline; Smart reads as Cubic) interpolation; 8-bit sRGB images interpolate their
      encoded values and decode afterwards, as Cycles does; times ``strength`` (Background
      Strength x Color scale, RGB).
    * ``sample(u)`` -> (wi (N, 3), radiance (N, 3), pdf (N,) [1/sr]): directions drawn from a
      piecewise-constant 2-D distribution over the equirectangular grid of the texture's frame
      (pbrt-v3 ``Distribution2D`` / ``InfiniteAreaLight``, Cycles' background map): a cell's
      weight is its mean luminance times sin(theta) of its row centre, a row picked from the
      marginal CDF, a column from that row's conditional CDF, uniform inside the cell; the
      solid-angle density is p(u, v) / (2 pi^2 sin(theta)).
    * ``solid_angle_pdf(points, normals, wi)`` (N,) [1/sr]: that density for directions ``wi``
      (points and normals are not used: the sampler does not depend on them; the name and
      signature are the ones every light shares for MIS).
    * ``integral()`` (3,) [W m^-2]: the radiance integrated over the sphere (for photon shares
      and the mean colour).

    A cell's weight is the cell mean of the interpolated image, not its texel: with Linear the
    mean of the bilinear surface over a texel's cell is (1/8, 3/4, 1/8) of its neighbours per
    axis, so every cell whose interpolated radiance is > 0 somewhere has a positive density
    (an unbiased estimator) and the density follows the integrand closely. Cubic uses that
    kernel twice (its support, 5 texels); Closest the texels themselves. A mirror-ball image is
    resampled onto an equirectangular grid of 2H x H cells (the maximum of 3 x 3 look-ups per
    cell, then the same kernel) for its distribution.

Parameters
    ``pixels``          (H, W, C) float32 (linear) or uint8 (encoded), C >= 3, bottom row first
    ``encoding``        "linear" (default) or "srgb" (8-bit images: decoded after the look-up)
    ``strength``        scalar or RGB multiplier (Background Strength), default 1
    ``rotation``        (3, 3) world -> texture rotation (a Mapping node's rotation), default I
    ``projection``      "EQUIRECTANGULAR" (default) or "MIRROR_BALL"
    ``interpolation``   "Linear" (default), "Closest", "Cubic", "Smart"
    ``name``            what reports call it (the world's name)

Units: radiance W m^-2 sr^-1; densities 1/sr; directions unit vectors, Z up (Blender's).
"""
from __future__ import annotations

import numpy as np

from .nodes import srgb_to_linear

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
CELL_MEAN = np.array([0.125, 0.75, 0.125])   # mean of a bilinear surface over a texel's cell


def _cubic_weights(t):
    """Uniform cubic B-spline weights for offsets -1, 0, 1, 2 (Cycles' cubic look-up)."""
    return ((((-1.0 / 6.0) * t + 0.5) * t - 0.5) * t + (1.0 / 6.0),
            ((0.5 * t - 1.0) * t) * t + (2.0 / 3.0),
            ((-0.5 * t + 0.5) * t + 0.5) * t + (1.0 / 6.0),
            (1.0 / 6.0) * t * t * t)


def _filter_wrap(a: np.ndarray, kernel: np.ndarray, axis: int) -> np.ndarray:
    """``a`` convolved with a 3-tap ``kernel`` along ``axis``, wrapping (Repeat)."""
    return (kernel[0] * np.roll(a, 1, axis=axis) + kernel[1] * a
            + kernel[2] * np.roll(a, -1, axis=axis))


def euler_rotation(rot) -> np.ndarray:
    """(3, 3) rotation of XYZ Euler angles ``rot`` [rad] (Cycles' ``euler_to_transform``, as
    the Mapping node applies it)."""
    cx, cy, cz = np.cos(rot)
    sx, sy, sz = np.sin(rot)
    return np.array([[cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz],
                     [cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz],
                     [-sy, cy * sx, cy * cx]])


def direction_to_equirectangular(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cycles' (u, v) of unit directions (N, 3) in the texture's frame."""
    u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * np.pi)
    v = 1.0 - np.arccos(np.clip(d[:, 2], -1.0, 1.0)) / np.pi
    return u, v


def equirectangular_to_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Inverse of :func:`direction_to_equirectangular`: unit directions (N, 3)."""
    phi = np.pi - 2.0 * np.pi * u
    theta = np.pi * (1.0 - v)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=1)


def direction_to_mirrorball(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cycles' ``direction_to_mirrorball`` of unit directions (N, 3)."""
    x, y, z = d[:, 0], d[:, 1] - 1.0, d[:, 2]
    div = 2.0 * np.sqrt(np.maximum(-0.5 * y, 0.0))
    inv = np.where(div > 0, 1.0 / np.where(div > 0, div, 1.0), 1.0)
    return 0.5 * (x * inv + 1.0), 0.5 * (z * inv + 1.0)


class Environment:
    """An image world: look-ups, importance sampling and densities (module docstring)."""

    kind = "environment"

    def __init__(self, pixels, encoding: str = "linear", strength=1.0, rotation=None,
                 projection: str = "EQUIRECTANGULAR", interpolation: str = "Linear",
                 name: str = "World"):
        px = np.asarray(pixels)
        if px.ndim == 2:
            px = px[..., None]
        if px.shape[2] < 3:
            px = np.repeat(px[..., :1], 3, axis=2)
        self.pixels = np.ascontiguousarray(px[..., :3] if px.dtype == np.uint8
                                           else px[..., :3].astype(np.float32))
        if self.pixels.dtype != np.uint8:
            self.pixels = np.nan_to_num(np.maximum(self.pixels, 0), nan=0.0, posinf=0.0)
        self.encoding = encoding
        self.strength = np.broadcast_to(np.asarray(strength, np.float64), (3,)).copy()
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
        self.projection = projection
        self.interpolation = interpolation
        self.name = name
        self._build_distribution()

    # Look-ups -------------------------------------------------------------------------------
    def to_texture(self, directions: np.ndarray) -> np.ndarray:
        """World directions (N, 3) -> unit directions in the texture's frame."""
        d = np.asarray(directions, np.float64).reshape(-1, 3) @ self.rotation.T
        n = np.sqrt(np.einsum("ij,ij->i", d, d))
        return d / np.where(n > 0, n, 1.0)[:, None]

    def lookup_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Image RGB (N, 3) at texture coordinates (u, v), linear, before ``strength``."""
        px = self.pixels
        h, w = px.shape[:2]
        u = np.asarray(u, np.float64)
        v = np.asarray(v, np.float64)
        if self.interpolation == "Closest":
            ix = np.mod(np.floor(u * w).astype(np.int64), w)
            iy = np.mod(np.floor(v * h).astype(np.int64), h)
            out = px[iy, ix].astype(np.float64)
        else:
            sx, sy = u * w - 0.5, v * h - 0.5
            fx, fy = np.floor(sx), np.floor(sy)
            tx, ty = sx - fx, sy - fy
            ix0, iy0 = fx.astype(np.int64), fy.astype(np.int64)
            if self.interpolation == "Linear":
                offs, wx, wy = (0, 1), (1.0 - tx, tx), (1.0 - ty, ty)
            else:                                          # Cubic, Smart: B-spline
                offs, wx, wy = (-1, 0, 1, 2), _cubic_weights(tx), _cubic_weights(ty)
            out = np.zeros((len(u), 3))
            for j, oy in enumerate(offs):
                iy = np.mod(iy0 + oy, h)
                for i, ox in enumerate(offs):
                    ix = np.mod(ix0 + ox, w)
                    out += (wx[i] * wy[j])[:, None] * px[iy, ix]
        if px.dtype == np.uint8:
            out /= 255.0
        if self.encoding == "srgb":
            out = srgb_to_linear(out)
        return out

    def _uv(self, tex_dirs: np.ndarray):
        if self.projection == "MIRROR_BALL":
            return direction_to_mirrorball(tex_dirs)
        return direction_to_equirectangular(tex_dirs)

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) [W m^-2 sr^-1] arriving from unit world ``directions`` (N, 3)."""
        u, v = self._uv(self.to_texture(directions))
        return self.lookup_uv(u, v) * self.strength

    # The distribution -----------------------------------------------------------------------
    def _cell_luminance(self) -> np.ndarray:
        """Mean luminance (Hd, Wd) of each cell of the equirectangular sampling grid."""
        weights = LUMINANCE * self.strength
        if self.projection == "EQUIRECTANGULAR":
            rgb = self.pixels.astype(np.float64)
            if self.pixels.dtype == np.uint8:
                rgb = rgb / 255.0
            if self.encoding == "srgb":
                rgb = srgb_to_linear(rgb)
            lum = rgb @ weights
            passes = {"Closest": 0, "Linear": 1}.get(self.interpolation, 2)
        else:
            # Mirror ball: 3 x 3 look-ups per cell of a 2H x H grid, their maximum.
            h = max(8, self.pixels.shape[0])
            w = 2 * h
            best = np.zeros((h, w))
            for a in (0.1, 0.5, 0.9):
                for b in (0.1, 0.5, 0.9):
                    vv, uu = np.meshgrid((np.arange(h) + a) / h, (np.arange(w) + b) / w,
                                         indexing="ij")
                    d = equirectangular_to_direction(uu.ravel(), vv.ravel())
                    mu, mv = direction_to_mirrorball(d)
                    best = np.maximum(best, (self.lookup_uv(mu, mv) @ weights).reshape(h, w))
            lum, passes = best, 2
        lum = np.maximum(lum, 0.0)
        for _ in range(passes):
            lum = _filter_wrap(_filter_wrap(lum, CELL_MEAN, 0), CELL_MEAN, 1)
        return lum

    def _build_distribution(self):
        lum = self._cell_luminance()
        h, w = lum.shape
        self.grid = (h, w)
        theta_centre = np.pi * (1.0 - (np.arange(h) + 0.5) / h)
        f = lum * np.sin(theta_centre)[:, None]
        f = np.where(np.isfinite(f), f, 0.0)
        row_sums = f.sum(axis=1)
        total = row_sums.sum()
        self.black = not total > 0
        if self.black:
            f = np.ones_like(f) * np.sin(theta_centre)[:, None]
            row_sums = f.sum(axis=1)
            total = row_sums.sum()
        # Densities in (u, v) of each cell: f W H / sum(f).
        self.cell_pdf = f * (w * h / total)
        self.marginal_cdf = np.concatenate([[0.0], np.cumsum(row_sums) / total])
        cond = np.cumsum(f, axis=1) / np.where(row_sums > 0, row_sums, 1.0)[:, None]
        self.conditional_cdf = np.concatenate([np.zeros((h, 1)), cond], axis=1)   # (H, W+1)
        self.row_pdf = row_sums / total

    def sample_uv(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u, v) texture coordinates drawn from the distribution for numbers ``u`` (N, 2),
        and their density in (u, v) (N,)."""
        h, w = self.grid
        u = np.asarray(u, np.float64).reshape(-1, 2)
        # Row: marginal CDF (rows from the bottom, v = (row + t) / H).
        row = np.clip(np.searchsorted(self.marginal_cdf, u[:, 1], side="right") - 1, 0, h - 1)
        lo, hi = self.marginal_cdf[row], self.marginal_cdf[row + 1]
        tv = np.clip((u[:, 1] - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0 - 1e-9)
        # Column: the row's conditional CDF, searched in one flat table (row offsets added).
        flat = (self.conditional_cdf[:, 1:] + np.arange(h)[:, None]).ravel()
        key = u[:, 0] + row
        col = np.clip(np.searchsorted(flat, key, side="right") - row * w, 0, w - 1)
        clo = self.conditional_cdf[row, col]
        chi = self.conditional_cdf[row, col + 1]
        tu = np.clip((u[:, 0] - clo) / np.where(chi > clo, chi - clo, 1.0), 0.0, 1.0 - 1e-9)
        uu = (col + tu) / w
        vv = (row + tv) / h
        return uu, vv, self.cell_pdf[row, col]

    def sample(self, u: np.ndarray):
        """(wi (N, 3) unit world directions, radiance (N, 3), pdf (N,) [1/sr]) for numbers
        ``u`` (N, 2) in [0, 1)^2."""
        uu, vv, p_uv = self.sample_uv(u)
        tex = equirectangular_to_direction(uu, vv)
        sin_t = np.sin(np.pi * (1.0 - vv))
        pdf = np.where(sin_t > 0, p_uv / (2.0 * np.pi ** 2 * np.maximum(sin_t, 1e-300)), 0.0)
        wi = tex @ self.rotation                 # texture -> world (rotation transposed)
        return wi, self.radiance(wi), pdf

    def direction_pdf(self, wi: np.ndarray) -> np.ndarray:
        """Solid-angle density (N,) [1/sr] of ``sample`` at unit world directions ``wi``."""
        tex = self.to_texture(wi)
        u, v = direction_to_equirectangular(tex)
        h, w = self.grid
        col = np.mod(np.floor(u * w).astype(np.int64), w)
        row = np.clip(np.floor(v * h).astype(np.int64), 0, h - 1)
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - tex[:, 2] ** 2))
        return np.where(sin_t > 0, self.cell_pdf[row, col]
                        / (2.0 * np.pi ** 2 * np.maximum(sin_t, 1e-300)), 0.0)

    def solid_angle_pdf(self, points, normals, wi) -> np.ndarray:
        """The density (N,) [1/sr] with which ``sample`` gives ``wi`` (N, 3) at ``points``
        with ``normals`` (both unused: the distribution is the same everywhere)."""
        return self.direction_pdf(wi)

    # Integrals ------------------------------------------------------------------------------
    def integral(self) -> np.ndarray:
        """Radiance integrated over the sphere (3,) [W m^-2]: the image at the centres of a
        grid of cells (the sampling grid, at least 256 x 128) times their solid angles."""
        h, w = self.grid
        if h < 128:
            h, w = 128, 256
        v = (np.arange(h) + 0.5) / h
        u = (np.arange(w) + 0.5) / w
        vv, uu = np.meshgrid(v, u, indexing="ij")
        theta = np.pi * (1.0 - (np.arange(h + 1)) / h)
        omega_row = (2.0 * np.pi / w) * np.abs(np.diff(np.cos(theta)))      # (H,)
        d = equirectangular_to_direction(uu.ravel(), vv.ravel())
        values = self.radiance(d @ self.rotation).reshape(h, w, 3)
        return np.einsum("hwc,h->c", values, omega_row)

    def mean_radiance(self) -> np.ndarray:
        """The radiance averaged over the sphere (3,) [W m^-2 sr^-1]."""
        return self.integral() / (4.0 * np.pi)

    @property
    def nbytes(self) -> int:
        return int(self.pixels.nbytes + self.cell_pdf.nbytes + self.conditional_cdf.nbytes)
