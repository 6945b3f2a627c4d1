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
    * ``sample(u, u_cell=None)`` -> (wi (N, 3), radiance (N, 3), pdf (N,) [1/sr]):
      directions drawn from a piecewise-bilinear density over the equirectangular grid of the
      texture's frame (flat texel cells for Closest: below). Knots sit at the texel centres;
      patch (i, j) spans knots (i, j) .. (i + 1, j + 1), wrapping in u and in v (the top
      row's upper half is the south pole's cap); inside a patch the density in (u, v)
      follows the bilinear surface of its four knots plus ``PATCH_FLOOR`` x their mean,
      sampled with pbrt-v4's ``SampleBilinear`` (t from the marginal's linear density, s
      given t). A patch's weight is its mean knot
      times the exact mean of sin(theta) over its v-range (the Jacobian of the sphere); the
      solid-angle density is p(u, v) / (2 pi^2 sin(theta)). The bilinear shape follows the
      interpolated image inside a texel (a sun a few texels wide is sampled by its shape, not
      by flat cells: 47 % per-sample spread on the yard's sun with flat cells, 2.7 % now).
      The patches are sorted by weight, brightest first, in one 1-D table, and ``u_cell``
      (stratified over a point's samples by the caller) picks one: a sun's few patches then
      get a nearly fixed share of a point's samples, not a binomial one (with a row CDF and a
      column CDF, two numbers decide it jointly: 6 % pixel noise on the yard's sunlit ground
      at ``final`` from that alone). Without ``u_cell``, ``u[:, 0]`` picks the patch and its
      remainder inside the patch's step of the table is reused to place the point. Photons
      and the portals' probes draw from this table of all patches (``table``); light
      samples draw from ``bright`` where the image has one: the same patches restricted to
      those whose radiance is over ``BRIGHT_DENSITY`` x the sphere's mean (a sun), kept
      where they hold at least ``BRIGHT_MIN_POWER`` of the image's weight. The rest of the
      sky is then left to the light's cosine samples (``lights.EnvironmentLight``), which
      spread a diffuse point's samples by its own cosine: on the yard's open ground the
      spread of a point's 8-sample estimate falls from 4.4 % to 2.8 %, in the sun's shadow
      from 20 % to 13 %; or, where a final gather runs, to the gather's rays that leave the
      scene (``smooth_radiance``: the image outside the bright patches).
    * ``solid_angle_pdf(points, normals, wi)`` (N,) [1/sr]: that density for directions ``wi``
      (points and normals are not used: the sampler does not depend on them; the name and
      signature are the ones every light shares for MIS).
    * ``integral()`` (3,) [W m^-2]: the radiance integrated over the sphere (for photon shares
      and the mean colour).

    Unbiased wherever the image is: in the table of all patches every patch whose
    interpolated radiance is > 0 somewhere has a positive density (the floor); the bright
    table leaves the other patches to the light's cosine samples, which reach every direction
    above a point. Knots are the texels themselves for Linear (it reads only a patch's four
    corners there); Cubic's B-spline reaches one texel further, so its knots are the texels
    smoothed once by (1/8, 3/4, 1/8) per axis. Closest is constant over each texel, so an
    equirectangular Closest image is sampled by flat patches that are the texels' own cells
    (bilinear patches straddle a sun's sharp texel edges: the spread of a point's 8-sample
    light estimate under a 3 x 3-texel sun 21 % that way, 7 % with flat cells, 7.4 % for the
    same sun under Linear, all from the table of all patches). A mirror-ball image is
    resampled onto an equirectangular grid of 2H x H knots (the maximum of 3 x 3 look-ups
    around each, smoothed twice) for its distribution. Non-finite texels weigh 0.

Parameters
    ``pixels``          (H, W, C) float32 (linear) or uint8 (encoded), C >= 3, bottom row first
    ``encoding``        "linear" (default) or "srgb" (8-bit images: decoded after the look-up)
    ``strength``        scalar or RGB multiplier (Background Strength), default 1
    ``rotation``        (3, 3) world -> texture rotation (a Mapping node's rotation), default I
    ``projection``      "EQUIRECTANGULAR" (default) or "MIRROR_BALL"
    ``interpolation``   "Linear" (default), "Closest", "Cubic", "Smart"
    ``name``            what reports call it (the world's name)
    ``PATCH_FLOOR``     (module constant, 0.02) a patch's density floor, as a fraction of its
                        mean: keeps the density > 0 where a corner is dark, at 2 % of the
                        samples' efficiency on smooth patches
    ``BRIGHT_DENSITY``  (module constant, 10) the radiance, over the sphere's mean, above
                        which a patch is bright (a clear sky's gradient stays within a few
                        times its mean, a sun is thousands of times brighter)
    ``BRIGHT_MIN_POWER`` (module constant, 0.25) the least share of the image's weight the
                        bright patches must hold for light samples to use them alone
    ``RANKED_PATCHES``  (module constant, 65,536) a table of at most this many patches keeps
                        each patch's knots and corner texels by rank (``PatchTable.by_rank``:
                        a sun's light samples read them with one ``np.take`` each, 3x faster)
    ``GUIDE_BINS``      (module constant, 65,536) bins of a table's guide to its rows
                        (``PatchTable.rank``: no binary search where a bin holds one row)

Units: radiance W m^-2 sr^-1; densities 1/sr; directions unit vectors, Z up (Blender's).
"""
from __future__ import annotations

import numpy as np

from .nodes import srgb_to_linear

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
CELL_MEAN = np.array([0.125, 0.75, 0.125])   # mean of a bilinear surface over a texel's cell
PATCH_FLOOR = 0.02   # a patch's density: its bilinear surface + this x its mean (kept > 0)
# The light samples' table (``Environment.bright``): patches whose radiance is over
# BRIGHT_DENSITY x the sphere's mean, kept where they hold at least BRIGHT_MIN_POWER of the
# image's weight.
BRIGHT_DENSITY = 10.0
BRIGHT_MIN_POWER = 0.25
# A table's guide to its rows (``PatchTable.rank``): bins of [0, 1) (exact: a power of two).
GUIDE_BINS = 1 << 16
# A table of at most this many patches keeps what sampling reads of each by rank
# (``PatchTable.by_rank``): a sun's few patches, sampled at every light sample of a render.
RANKED_PATCHES = 1 << 16


def _cubic_weights(t):
    """Uniform cubic B-spline weights for offsets -1, 0, 1, 2 (Cycles' cubic look-up)."""
    return ((((-1.0 / 6.0) * t + 0.5) * t - 0.5) * t + (1.0 / 6.0),
            ((0.5 * t - 1.0) * t) * t + (2.0 / 3.0),
            ((-0.5 * t + 0.5) * t + 0.5) * t + (1.0 / 6.0),
            (1.0 / 6.0) * t * t * t)


def _sample_linear(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Inverse CDF on [0, 1] of the density proportional to (1 - t) a + t b (a, b >= 0, not
    both 0), for numbers ``x`` in [0, 1) (pbrt-v4's ``SampleLinear``)."""
    lerp = np.sqrt(np.maximum((1.0 - x) * a * a + x * b * b, 0.0))
    denom = a + lerp
    t = np.where(denom > 0, x * (a + b) / np.where(denom > 0, denom, 1.0), x)
    return np.clip(t, 0.0, 1.0 - 1e-12)


def _wrapped(i0: np.ndarray, offsets, n: int) -> list:
    """Indices i0 + o wrapped into [0, n) (Repeat), one array per offset o (|o| < n)."""
    base = np.mod(i0, n)
    out = []
    for o in offsets:
        if len(offsets) > n:                     # a tiny image: offsets wrap more than once
            out.append(np.mod(base + o, n))
            continue
        i = base + o
        if o > 0:
            i[i >= n] -= n
        elif o < 0:
            i[i < 0] += n
        out.append(i)
    return out


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


def equirectangular_to_direction(u: np.ndarray, v: np.ndarray, with_sin: bool = False):
    """Inverse of :func:`direction_to_equirectangular`: unit directions (N, 3); with
    ``with_sin``, (directions, sin(theta) (N,)) (theta from +Z: the sphere's Jacobian)."""
    phi = np.pi - 2.0 * np.pi * u
    theta = np.pi * (1.0 - v)
    s = np.sin(theta)
    d = np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=1)
    return (d, s) if with_sin else d


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
        flat = px.reshape(h * w, px.shape[2])         # texels by flat index (one take each)
        u = np.asarray(u, np.float64)
        v = np.asarray(v, np.float64)
        if self.interpolation == "Closest":
            ix = np.mod(np.floor(u * w).astype(np.int64), w)
            iy = np.mod(np.floor(v * h).astype(np.int64), h)
            out = np.take(flat, iy * w + ix, axis=0).astype(np.float64)
        else:
            sx, sy = u * w - 0.5, v * h - 0.5
            fx, fy = np.floor(sx), np.floor(sy)
            tx, ty = sx - fx, sy - fy
            ix0, iy0 = fx.astype(np.int64), fy.astype(np.int64)
            if self.interpolation == "Linear":
                offs, wx, wy = (0, 1), (1.0 - tx, tx), (1.0 - ty, ty)
            else:                                          # Cubic, Smart: B-spline
                offs, wx, wy = (-1, 0, 1, 2), _cubic_weights(tx), _cubic_weights(ty)
            cols, rows = _wrapped(ix0, offs, w), _wrapped(iy0, offs, h)
            out = np.zeros((len(u), 3))
            # A channel at a time from the texels' flat array: 1-D takes run at twice the
            # speed of row gathers (the sky of the yard's gather rays: 1.8x; same sums).
            channels = px.reshape(-1)
            for j, row in enumerate(rows):
                row *= w
                for i, ix in enumerate(cols):
                    weight = wx[i] * wy[j]
                    at = (row + ix) * 3
                    for c in range(3):
                        out[:, c] += weight * np.take(channels, at + c if c else at)
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
    def _knot_luminance(self) -> np.ndarray:
        """Luminance (Hd, Wd) at the knots of the sampling grid: the texel centres of an
        equirectangular image (the texels themselves for Closest and Linear, once smoothed
        by the cell-mean kernel for Cubic, whose B-spline reaches a texel further); for a
        mirror ball, the maximum of 3 x 3 look-ups around each centre of a 2H x H grid,
        smoothed twice (conservative: positive wherever the ball is near there)."""
        weights = LUMINANCE * self.strength
        if self.projection == "EQUIRECTANGULAR":
            rgb = self.pixels.astype(np.float64)
            if self.pixels.dtype == np.uint8:
                rgb = rgb / 255.0
            if self.encoding == "srgb":
                rgb = srgb_to_linear(rgb)
            lum = rgb @ weights
            passes = 0 if self.interpolation in ("Closest", "Linear") else 1
        else:
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
        lum = np.where(np.isfinite(lum), np.maximum(lum, 0.0), 0.0)
        for _ in range(passes):
            lum = _filter_wrap(_filter_wrap(lum, CELL_MEAN, 0), CELL_MEAN, 1)
        return lum

    def _build_distribution(self):
        knots = self._knot_luminance()
        h, w = knots.shape
        self.grid = (h, w)
        self.black = not knots.sum() > 0
        if self.black:
            knots = np.ones_like(knots)
        # Closest (equirectangular): the image is constant over each texel, so the patches
        # are the texels' own cells, flat inside (a sun of a few texels sampled by bilinear
        # patches straddling its sharp edges: 2.3x the spread of a point's light estimate).
        self.flat = self.projection == "EQUIRECTANGULAR" and self.interpolation == "Closest"
        self.offset = 0.0 if self.flat else 0.5          # texel fraction from a cell's edge
        self.knots = knots
        if self.flat:
            mean = knots
            self.floor = np.zeros_like(knots)
        else:
            # Patch (i, j) spans knots (i, j) .. (i + 1, j + 1), both axes wrapping (Repeat):
            # its corners, the bilinear surface's mean and the floor that keeps its density
            # positive.
            c10 = np.roll(knots, -1, axis=1)                  # u + 1
            c01 = np.roll(knots, -1, axis=0)                  # v + 1
            c11 = np.roll(c10, -1, axis=0)
            mean = 0.25 * (knots + c10 + c01 + c11)
            self.floor = PATCH_FLOOR * mean
        # Mean sin(theta) over each patch row's v-range [(i + offset) / H, (i + offset + 1) / H]:
        # the top row wraps over both poles (|sin(pi v)| there).
        v0 = (np.arange(h) + self.offset) / h
        v1 = v0 + 1.0 / h
        mean_sin = (np.cos(np.pi * v0) - np.cos(np.pi * np.minimum(v1, 1.0))) / np.pi
        over = np.maximum(v1 - 1.0, 0.0)
        mean_sin = (mean_sin + (1.0 - np.cos(np.pi * over)) / np.pi) * h
        f = mean * mean_sin[:, None]
        total = f.sum()
        # Patches sorted by weight, brightest first, in one 1-D table: a caller's stratified
        # number picks a patch (``sample(u, u_cell)``), so that a compact bright region (a
        # sun: a few patches holding most of the light) gets a nearly fixed count of a
        # point's samples, not a binomial one.
        self.table = PatchTable(f)
        # The light samples' table: the patches whose radiance is over BRIGHT_DENSITY x the
        # sphere's mean (their solid-angle density over uniform: a sun near a pole as near
        # the horizon), where they hold at least BRIGHT_MIN_POWER of the image's weight;
        # else None.
        sphere_mean = total / (w * mean_sin.sum())
        bright = mean > BRIGHT_DENSITY * sphere_mean
        power = float(self.table.share[bright].sum())
        self.bright = PatchTable(np.where(bright, f, 0.0)) if power >= BRIGHT_MIN_POWER else None
        self.bright_power = power if self.bright is not None else 0.0   # its share of weight
        for table in (self.table, self.bright):
            if table is not None and table.count <= RANKED_PATCHES:
                table.by_rank = self.rank_patches(table)

    def rank_patches(self, table: "PatchTable") -> dict:
        """What ``sample`` reads of each of ``table``'s patches of weight > 0, by rank:
        ``row``, ``col`` (int64), ``density`` (share x W x H), ``knots`` four (count,) arrays:
        the floored knots k00, k10, k01, k11, and for an equirectangular Linear or Closest
        image ``texels`` [channel][corner] (count,) arrays: the texels at the patch's corners
        k00, k10, k01, k11 (Linear: the image inside the patch is their bilinear blend at the
        sample's (s, t), the look-up's own arithmetic; Closest: the patch is its one texel),
        before decoding."""
        h, w = self.grid
        row, col = np.divmod(table.order[:table.count].astype(np.int64), w)
        # One contiguous 1-D array per corner (and per channel): ``np.take`` of a 1-D array
        # by rank is several times faster than fancy indexing of an (n, 4, 3) array.
        out = {"row": row, "col": col, "density": table.share[row, col] * (w * h),
               "knots": [np.ascontiguousarray(k) for k in self._corners(row, col)]}
        if self.projection == "EQUIRECTANGULAR" and self.interpolation in ("Linear",
                                                                           "Closest"):
            ph, pw = self.pixels.shape[:2]
            if self.flat:
                corner = [(row, col)]
            else:
                r1, c1 = (row + 1) % ph, (col + 1) % pw
                corner = [(row, col), (row, c1), (r1, col), (r1, c1)]
            out["texels"] = [[np.ascontiguousarray(self.pixels[r, c, ch], np.float64)
                              for r, c in corner] for ch in range(3)]
        return out

    def _corners(self, row, col):
        """The four floored knots (k00, k10, k01, k11) of patches (row, col): (i, j),
        (i, j + 1), (i + 1, j), (i + 1, j + 1), wrapping."""
        h, w = self.grid
        r1, c1 = (row + 1) % h, (col + 1) % w
        k, fl = self.knots, self.floor[row, col]
        return k[row, col] + fl, k[row, c1] + fl, k[r1, col] + fl, k[r1, c1] + fl

    @staticmethod
    def _over_mean(corners, s, t):
        """The bilinear surface of ``corners`` at local (s, t) over its mean (the density's
        shape inside a patch)."""
        k00, k10, k01, k11 = corners
        value = (1 - s) * (1 - t) * k00 + s * (1 - t) * k10 + (1 - s) * t * k01 + s * t * k11
        mean = 0.25 * (k00 + k10 + k01 + k11)
        return value / np.where(mean > 0, mean, 1.0)

    def sample_uv(self, u_patch: np.ndarray, u: np.ndarray, table: "PatchTable | None" = None,
                  rank: np.ndarray | None = None):
        """(u, v) texture coordinates in [0, 1) and their density in (u, v) (N,): a patch
        picked by ``u_patch`` (N,) from the sorted ``table`` (default: all patches,
        ``self.table``), the point inside it by ``u`` (N, 2): uniform in a flat cell, else
        from the patch's bilinear surface (pbrt-v4's ``SampleBilinear``: t from the
        marginal's linear density, then s given t). ``rank``: ``table.rank(u_patch)`` where
        the caller has it already."""
        uu, vv, density, _ = self._sample_patch(u_patch, u, table, rank)
        return uu, vv, density

    def _sample_patch(self, u_patch, u, table, rank):
        """``sample_uv``'s (u, v) and density, with the patches' ranks and local (s, t) for
        ``sample``'s look-up: (u, v, density, (rank, s, t))."""
        h, w = self.grid
        table = self.table if table is None else table
        u = np.clip(np.asarray(u, np.float64).reshape(-1, 2), 0.0, 1.0 - 1e-12)
        rank = table.rank(u_patch) if rank is None else rank
        ranked = table.by_rank
        if ranked is not None:
            row, col = ranked["row"][rank], ranked["col"][rank]
            density = ranked["density"][rank]
        else:
            row, col = np.divmod(table.order[rank].astype(np.int64), w)
            density = table.share[row, col] * (w * h)
        if self.flat:
            s, t = u[:, 0], u[:, 1]
        else:
            if ranked is not None:
                corners = tuple(np.take(k, rank) for k in ranked["knots"])
            else:
                corners = self._corners(row, col)
            k00, k10, k01, k11 = corners
            t = _sample_linear(u[:, 1], k00 + k10, k01 + k11)
            s = _sample_linear(u[:, 0], k00 + (k01 - k00) * t, k10 + (k11 - k10) * t)
            density = density * self._over_mean(corners, s, t)
        # The top row's upper half lies past v = 1: Repeat wraps it to the south pole's cap.
        off = self.offset
        return (np.mod((col + off + s) / w, 1.0), np.mod((row + off + t) / h, 1.0), density,
                (rank, s, t))

    def sample(self, u: np.ndarray, u_cell: np.ndarray | None = None,
               table: "PatchTable | None" = None):
        """(wi (N, 3) unit world directions, radiance (N, 3), pdf (N,) [1/sr]) for numbers
        ``u`` (N, 2) in [0, 1)^2, from ``table`` (default: all patches); with ``u_cell``
        (N,), the patch is picked by it and ``u`` places the point inside; without,
        ``u[:, 0]`` picks the patch and what is left of it inside the patch's step of the
        table is reused in its place (module docstring)."""
        table = self.table if table is None else table
        u = np.asarray(u, np.float64).reshape(-1, 2)
        rank = None
        if u_cell is None:
            u_cell = u[:, 0]
            rank = table.rank(u_cell)
            lo, hi = table.cdf[rank], table.cdf[rank + 1]
            u = np.stack([(u_cell - lo) / np.where(hi > lo, hi - lo, 1.0), u[:, 1]], 1)
        uu, vv, p_uv, (rank, s, t) = self._sample_patch(u_cell, u, table, rank)
        tex, sin_t = equirectangular_to_direction(uu, vv, with_sin=True)
        pdf = np.where(sin_t > 0, p_uv / (2.0 * np.pi ** 2 * np.maximum(sin_t, 1e-300)), 0.0)
        wi = tex @ self.rotation                 # texture -> world (rotation transposed)
        if self.projection != "EQUIRECTANGULAR":
            return wi, self.radiance(wi), pdf
        ranked = table.by_rank
        if ranked is None or "texels" not in ranked:   # the image at the sampled (u, v)
            return wi, self.lookup_uv(uu, vv) * self.strength, pdf
        # The same value from the patch's own corner texels (rank_patches).
        value = np.empty((len(rank), 3))
        if self.flat:
            for ch, (texel,) in enumerate(ranked["texels"]):
                value[:, ch] = np.take(texel, rank)
        else:
            weights = ((1.0 - s) * (1.0 - t), s * (1.0 - t), (1.0 - s) * t, s * t)
            for ch, texels in enumerate(ranked["texels"]):
                acc = weights[0] * np.take(texels[0], rank)
                for weight, texel in zip(weights[1:], texels[1:]):
                    acc += weight * np.take(texel, rank)
                value[:, ch] = acc
        if self.pixels.dtype == np.uint8:
            value = value / 255.0
        if self.encoding == "srgb":
            value = srgb_to_linear(value)
        return wi, value * self.strength, pdf

    def _patch_of(self, wi: np.ndarray):
        """The patches (row, col) that unit world directions ``wi`` (N, 3) fall in, their
        local (s, t) and the directions in the texture's frame."""
        tex = self.to_texture(wi)
        u, v = direction_to_equirectangular(tex)
        h, w = self.grid
        su, sv = u * w - self.offset, v * h - self.offset
        col, row = np.floor(su), np.floor(sv)
        s, t = su - col, sv - row
        return np.mod(row.astype(np.int64), h), np.mod(col.astype(np.int64), w), s, t, tex

    def direction_pdf(self, wi: np.ndarray, table: "PatchTable | None" = None) -> np.ndarray:
        """Solid-angle density (N,) [1/sr] of ``sample`` from ``table`` (default: all
        patches) at unit world directions ``wi``."""
        table = self.table if table is None else table
        row, col, s, t, tex = self._patch_of(wi)
        h, w = self.grid
        p_uv = table.share[row, col] * (w * h)
        if not self.flat:
            p_uv = p_uv * self._over_mean(self._corners(row, col), s, t)
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - tex[:, 2] ** 2))
        return np.where(sin_t > 0, p_uv / (2.0 * np.pi ** 2 * np.maximum(sin_t, 1e-300)), 0.0)

    def smooth_radiance(self, wi: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) from unit world directions ``wi`` outside the bright patches
        (``bright``; 0 inside them): the sky without its sun, the part of the image a final
        gather takes over from the light samples (``lights.EnvironmentLight.gather_sky``).
        Inside and outside are decided by the patch a direction falls in, as ``sample`` and
        ``direction_pdf`` decide it, so the two parts add up to ``radiance`` exactly."""
        wi = np.asarray(wi, np.float64).reshape(-1, 3)
        if self.bright is None:
            return self.radiance(wi)
        row, col, _s, _t, tex = self._patch_of(wi)
        keep = np.flatnonzero(self.bright.share[row, col] == 0)
        value = np.zeros((len(wi), 3))
        u, v = self._uv(tex[keep])
        value[keep] = self.lookup_uv(u, v) * self.strength
        return value

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
        return int(self.pixels.nbytes + self.knots.nbytes + self.floor.nbytes
                   + self.table.nbytes + (self.bright.nbytes if self.bright else 0))


def _nbytes(arrays) -> int:
    """Bytes of the arrays in (nested) lists."""
    if isinstance(arrays, np.ndarray):
        return int(arrays.nbytes)
    return sum(_nbytes(a) for a in arrays)


class PatchTable:
    """Patches sorted by weight, brightest first, in one 1-D table: ``share`` (H, W) each
    patch's probability, ``order`` the flat patch indices by falling weight, ``cdf`` their
    running sum (from 0 to 1), ``count`` the patches of weight > 0 (at least 1), from
    weights ``f`` (H, W) >= 0 with a positive sum.

    ``by_rank``: for a table of at most ``RANKED_PATCHES`` patches of weight > 0 (a sun's
    table), what ``Environment.sample`` reads of each, by rank: its row and column, its
    density in (u, v), its four floored knots and its four corner texels
    (``Environment.rank_patches``); None for larger tables, which look them up per sample."""

    def __init__(self, f: np.ndarray):
        total = f.sum()
        flat_f = f.ravel()
        self.share = f / total
        self.order = np.argsort(-flat_f, kind="stable").astype(np.int32)
        self.cdf = np.concatenate([[0.0], np.cumsum(flat_f[self.order]) / total])
        self.count = max(1, int(np.count_nonzero(flat_f > 0)))
        self.by_rank = None
        # A guide over GUIDE_BINS equal bins of [0, 1): the rank at each bin's lower edge and
        # at its upper one; a number in a bin whose two agree has that rank without a search
        # (a sun's table: nearly every bin), the others search the CDF.
        edges = np.arange(GUIDE_BINS + 1, dtype=np.float64) / GUIDE_BINS
        at_edge = self._search(edges)
        self.guide, self.guide_unique = at_edge[:-1], at_edge[:-1] == at_edge[1:]

    def _search(self, u) -> np.ndarray:
        return np.clip(np.searchsorted(self.cdf, u, side="right") - 1, 0,
                       self.count - 1).astype(np.int64)

    def rank(self, u_patch) -> np.ndarray:
        """The table rows (N,) that numbers ``u_patch`` (N,) in [0, 1) fall in: the largest
        row whose running sum is at most the number (the guide's answer where its bin holds
        one row, else a binary search: the same rows either way)."""
        u = np.asarray(u_patch, np.float64)
        bins = np.clip((u * GUIDE_BINS).astype(np.int64), 0, GUIDE_BINS - 1)
        out = np.take(self.guide, bins)
        search = np.flatnonzero(~np.take(self.guide_unique, bins))
        if len(search):
            out[search] = self._search(u[search])
        return out

    @property
    def nbytes(self) -> int:
        ranked = 0 if self.by_rank is None else _nbytes(list(self.by_rank.values()))
        return int(self.share.nbytes + self.order.nbytes + self.cdf.nbytes + ranked
                   + self.guide.nbytes + self.guide_unique.nbytes)
