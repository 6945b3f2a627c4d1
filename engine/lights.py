"""Light models: irradiance at surface points, light sampling, and selection weights.

What it computes
    ``LightSet(scene)`` sorts the scene's lights into
    * delta lights, evaluated exactly with one shadow ray each: point (Eq. 7.1), spot (a point
      light masked to a cone, Blender's falloff), sun with zero angle, and collimated disks /
      rectangles (Blender's area light with Spread ~ 0: the seed's circular directional light,
      Eq. 7.2, E = Phi cos(theta) / (pi r^2) inside the beam);
    * sampled lights, integrated by Monte Carlo: area lights (square, rectangle, disk,
      ellipse), emissive meshes (seed 3.3.3, 7.1.3), suns with an angular diameter, point and
      spot lights with a radius (``SphereLight``: Cycles 4.x/5.x sphere lights, or its facing
      disk under Soft Falloff; radiance Phi / (4 pi^2 R^2)), a constant world (``WorldLight``), and an image world or a world with portals
      (``EnvironmentLight``: a radiance per sample, ``sample_rgb``; a mixture of the image's
      CDF, cosine directions and points on portals weighted by the mixture's density, the
      portals' share smaller where CDF directions leave through them (``PORTAL_SHIFT``),
      whose ``solid_angle_pdf(points, normals, wi)`` serves MIS).
    Each sampled light gives, for points x with normals n and uniform numbers u, a direction,
    a distance for the shadow ray and a scalar weight: the irradiance estimate before visibility
    is ``weight * light.rgb`` (L cos(theta_x) / pdf(omega) for emitters); plus a cheap unoccluded estimate of its contribution used to share the samples
    among lights (``selection_weights``).

Sampling
    Triangles (emissive meshes with up to ``SOLID_ANGLE_MAX_TRIANGLES`` triangles, and
    rectangles as two triangles) are sampled by solid angle: a triangle is chosen in proportion
    to the solid angle it subtends (Van Oosterom and Strackee 1983) and a direction is drawn
    uniformly inside its spherical triangle (Arvo 1995, "Stratified sampling of spherical
    triangles"), so the estimate is L cos(theta_x) Omega_total. Triangles subtending less than
    ``SOLID_ANGLE_MIN`` sr are sampled by area instead (Arvo's map loses precision there).
    The solid angles of all triangles at N points are formed from the unit directions to the
    emitter's distinct vertices ((N, V) component arrays; corners that triangles share are
    normalised once). Larger meshes choose a triangle by area with ``searchsorted`` on
    cumulative areas (the seed's "area line") and an area-uniform point (DESIGN.md §4). Disks
    and ellipses are sampled by area through the concentric map. An emitting triangle gives
    nothing to the points that lie on it (``TriangleEmitter.on_surface``: a camera hit on a
    lit emission panel sees its own triangle edge-on). Suns with an angle sample their cone
    uniformly; the world is sampled with cosine-distributed directions (E = pi L V). Sphere
    lights sample the cone they subtend uniformly (the standard sphere-light sampling; Cycles
    ``point_light_sample``), cosine directions from inside, and their facing disk by area; a
    spot's mask is evaluated on each sample's direction (``SphereLight``). A mesh whose
    emission is textured (``TexturedTriangleEmitter``) draws half its samples by solid angle
    x each triangle's mean luminance, half from about 4096 parts by their power (area x mean
    luminance, as its photons leave), weighted by the balance heuristic (one-sample MIS,
    Veach 1997 §9.2.4); each sample reads the radiance at its own point.
    ``seen_light_radiance`` gives what camera rays after a bounce see of the lights that are
    not geometry (``ray_visible``).

Densities for multiple importance sampling
    Every sampled light has ``solid_angle_pdf(points, normals, wi)`` -> (N,): the density
    [1/sr] with which its own ``sample`` at ``points`` (N, 3) with unit ``normals`` (N, 3)
    produces the unit directions ``wi`` (N, 3), given that this light was picked; 0 where wi
    misses the light. Where a direction meets an emitter more than once (a closed mesh), the
    nearest point along it decides (the only one a ray can meet: the far faces' samples are
    in shadow). Spot masks and one-sided facing weight the estimate, not the density, so they
    are not in it. ``LightSet.sample_density(points, normals, wi, index, light_samples)``
    adds the pick and the count of ``direct.direct_terms``: light_samples x
    ``selection_weights`` x ``solid_angle_pdf`` (Veach 1997 §9.2.2's n_i p_i). A light type
    added later (an HDRI world) must give the same method with the same signature.

Units: see ``engine/scene.py``. Radiance in W m^-2 sr^-1, irradiance in W m^-2.
"""
from __future__ import annotations

import numpy as np

from . import sampling
from .accel import Accelerator, offset_distance
from .bsdf import MaterialTable
from .scene import AreaLight, PointLight, Scene, SpotLight, SunLight

SOLID_ANGLE_MAX_TRIANGLES = 64
SOLID_ANGLE_MIN = 1e-4
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _normalize(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _towards(pos, x):
    """Unit directions from points x to ``pos``, distances and 1/r^2 (column-wise, fast)."""
    d = np.empty_like(x)
    for c in range(3):                       # pos - x, a column at a time (fast)
        np.subtract(x.dtype.type(pos[c]), x[:, c], out=d[:, c])
    r2 = sampling.dot_rows(d, d)
    np.maximum(r2, 1e-30, out=r2)
    r = np.sqrt(r2)
    sampling.scale_rows(d, 1.0 / r, out=d)
    return d, r, 1.0 / r2


def spot_mask(cos_axis: np.ndarray, cos_half: float, blend: float) -> np.ndarray:
    """Blender/Cycles spot cone: 0 outside, smoothstep over the outer ``blend`` share of
    (1 - cos_half), 1 inside."""
    smooth = (1.0 - cos_half) * blend
    t = cos_axis - cos_half
    if smooth <= 0:
        return (t > 0).astype(np.float64)
    x = np.clip(t / smooth, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def sphere_emission_origins(center, radius: float, directions: np.ndarray,
                            u: np.ndarray) -> np.ndarray:
    """Origins (N, 3) on a Lambertian sphere light for photons leaving along unit
    ``directions`` (N, 3), from uniform numbers ``u`` (N, 2): a uniform point of the disk the
    sphere projects across each direction (concentric map), lifted onto the hemisphere facing
    it. With directions uniform over the sphere this is the same ray distribution as an
    area-uniform point with a cosine direction about the outward normal (the radiance is
    uniform, so the rays along a direction fill the projected disk evenly), and a spot keeps
    its cone sampling of directions."""
    t, b = sampling.orthonormal_basis(directions)
    disk = sampling.square_to_disk(u)
    lift = np.sqrt(np.maximum(0.0, 1.0 - _dot(disk, disk)))
    return np.asarray(center, np.float64) + radius * (disk[:, 0:1] * t + disk[:, 1:2] * b
                                                      + lift[:, None] * directions)


# Spherical triangles -----------------------------------------------------------------------
def solid_angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Solid angle of spherical triangles with unit corner directions a, b, c (..., 3)."""
    triple = np.abs(np.einsum("...i,...i->...", a, np.cross(b, c)))
    denom = 1.0 + np.einsum("...i,...i->...", a, b) + np.einsum("...i,...i->...", b, c) \
        + np.einsum("...i,...i->...", c, a)
    return 2.0 * np.arctan2(triple, denom)


def sample_spherical_triangle(a: np.ndarray, b: np.ndarray, c: np.ndarray,
                              u: np.ndarray) -> np.ndarray:
    """Arvo's uniform sampling of spherical triangles (a, b, c unit (N, 3), u (N, 2))."""
    def plane_angle(p, q, r):
        n1 = _normalize(np.cross(p, q))
        n2 = _normalize(np.cross(p, r))
        return np.arccos(np.clip(_dot(n1, n2), -1.0, 1.0))

    alpha = plane_angle(a, b, c)
    beta = plane_angle(b, c, a)
    gamma = plane_angle(c, a, b)
    area = np.maximum(alpha + beta + gamma - np.pi, 0.0)
    area_hat = u[:, 0] * area
    s = np.sin(area_hat - alpha)
    t = np.cos(area_hat - alpha)
    cos_alpha, sin_alpha = np.cos(alpha), np.sin(alpha)
    cos_c = _dot(a, b)
    uu = t - cos_alpha
    vv = s + sin_alpha * cos_c
    denom = (vv * s + uu * t) * sin_alpha
    q = np.where(np.abs(denom) > 1e-300, ((vv * t - uu * s) * cos_alpha - vv) / np.where(denom == 0, 1, denom), 1.0)
    q = np.clip(q, -1.0, 1.0)
    c_perp = _normalize(c - _dot(c, a)[:, None] * a)
    c_hat = q[:, None] * a + np.sqrt(np.maximum(0.0, 1.0 - q * q))[:, None] * c_perp
    z = 1.0 - u[:, 1] * (1.0 - _dot(c_hat, b))
    ch_perp = _normalize(c_hat - _dot(c_hat, b)[:, None] * b)
    return z[:, None] * b + np.sqrt(np.maximum(0.0, 1.0 - z * z))[:, None] * ch_perp


# Sampled lights -----------------------------------------------------------------------------
def _over_pdf(valid, value, pdf):
    """(N,) ``value`` / ``pdf`` where ``valid`` (and the density is positive), else 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(valid, value / np.where(pdf > 0, pdf, 1.0), 0.0)


class TriangleEmitter:
    """Emitting triangles of one object (or a rectangle light): radiance ``rgb`` (3,) times a
    per-triangle factor ``scale`` (T,) in [0, 1] (1 by default); triangles are sampled in
    proportion to their area x factor. A textured emitter (``textured_emitter``) gives
    ``radiance_at(tri, points)`` -> (N, 3), the radiance [W m^-2 sr^-1] at sampled points on
    triangles ``tri``: its samples then carry their own radiance (``per_sample_rgb``,
    ``sample_rgb``), ``rgb`` x ``scale`` only shapes where they go, and ``mean_radiance``
    (T, 3) gives each triangle's mean, from which ``power`` is summed (what shadow photons
    are shared by)."""

    kind = "mesh"
    camera_visible = False       # a rectangle light's Visibility > Camera (``ray_visible``)

    def __init__(self, name: str, triangles: np.ndarray, radiance: np.ndarray, two_sided: bool,
                 in_bvh: bool = False, scale: np.ndarray | None = None, radiance_at=None,
                 mean_radiance: np.ndarray | None = None):
        self.name = name
        self.radiance_at = radiance_at
        self.per_sample_rgb = radiance_at is not None    # ``direct.direct_terms`` reads it
        self.in_bvh = in_bvh   # an emissive mesh is also geometry: shadow rays must stop short
        self.tris = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
        self.rgb = np.asarray(radiance, np.float64).reshape(3)   # one radiance per emitter
        self.scale = None if scale is None else np.asarray(scale, np.float64).reshape(-1)
        self.two_sided = two_sided
        e1 = self.tris[:, 1] - self.tris[:, 0]
        e2 = self.tris[:, 2] - self.tris[:, 0]
        cross = np.cross(e1, e2)
        self.areas = 0.5 * np.linalg.norm(cross, axis=1)
        self.normals = _normalize(cross)
        self.total_area = float(self.areas.sum())
        emitting = self.areas if self.scale is None else self.areas * self.scale
        self.cdf = np.cumsum(emitting) / emitting.sum()
        self.use_solid_angle = len(self.tris) <= SOLID_ANGLE_MAX_TRIANGLES
        if self.use_solid_angle:
            # Corners shared between triangles (a subdivided quad, a disk's fan) are one
            # vertex: the directions to them are normalised once per shading point.
            self.vertices, corner = np.unique(self.tris.reshape(-1, 3), axis=0,
                                              return_inverse=True)
            self.corner_index = corner.reshape(-1, 3)
            self.plane_offset = _dot(self.tris[:, 0], self.normals)   # n . corner 0
        self.lower = self.tris.reshape(-1, 3).min(axis=0)      # the emitter's box [m]
        self.upper = self.tris.reshape(-1, 3).max(axis=0)
        self.extent = float(np.linalg.norm(self.upper - self.lower))
        self.centroid = (self.tris.mean(axis=1) * self.areas[:, None]).sum(0) / self.total_area
        self.mean_scale = float(emitting.sum()) / self.total_area
        sides = 2 if two_sided else 1
        self.power = (np.pi * self.rgb * float(emitting.sum()) * sides if mean_radiance is None
                      else np.pi * (self.areas[:, None] * mean_radiance).sum(axis=0) * sides)

    def intersect(self, origins, directions, t_max):
        """Nearest hit t (N,) of rays with the triangles on their emitting side (inf: none
        before ``t_max``) and the radiance factor there (1; 0 for no hit): Moller-Trumbore
        over the (few) triangles of an area light that is not geometry."""
        tri, t = self.nearest_triangle(origins, directions, t_max, emitting_side=True)
        hit = tri >= 0
        return np.where(hit, t, np.inf), hit.astype(np.float64)

    def nearest_triangle(self, origins, directions, t_max=np.inf, emitting_side=False):
        """(triangle index (N,), -1 for none; distance t (N,)) of the nearest triangle each
        ray meets before ``t_max`` (with ``emitting_side``: only triangles met on their
        emitting side). Moller-Trumbore a triangle at a time over the rays for up to
        ``SOLID_ANGLE_MAX_TRIANGLES`` triangles, an Embree BVH of the emitter's own
        triangles (built at the first call) for larger meshes."""
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        w = np.asarray(directions, np.float64).reshape(-1, 3)
        best = np.broadcast_to(np.asarray(t_max, np.float64), (len(o),)).copy()
        index = np.full(len(o), -1)
        if len(self.tris) > SOLID_ANGLE_MAX_TRIANGLES:
            if getattr(self, "bvh", None) is None:
                self.bvh = Accelerator(self.tris, threads=1)
            t, prim, _u, _v = self.bvh.intersect(o, w, np.minimum(best, 1e37))
            t = t.astype(np.float64)
            hit = (prim >= 0) & (t < best)
            if emitting_side and not self.two_sided:
                hit &= _dot(w, self.normals[np.maximum(prim, 0)]) < 0
            return np.where(hit, prim, -1), np.where(hit, t, np.inf)
        for k, (tri, normal) in enumerate(zip(self.tris, self.normals)):
            e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
            p = np.cross(w, e2)
            det = p @ e1
            ok = np.abs(det) > 1e-300
            inv = 1.0 / np.where(ok, det, 1.0)
            s = o - tri[0]
            u = _dot(s, p) * inv
            q = np.cross(s, e1)
            v = _dot(w, q) * inv
            t = (q @ e2) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < best)
            if emitting_side and not self.two_sided:
                hit &= w @ normal < 0
            best = np.where(hit, t, best)
            index = np.where(hit, k, index)
        return index, np.where(index >= 0, best, np.inf)

    def on_surface(self, x, n, tri):
        """Whether points x (N, 3) with normals n (N, 3) lie on the emitter's triangles
        ``tri`` (N,) (one each): within the offset that rays leave surfaces by
        (``accel.offset_distance``, at the emitter's own size) of the triangle's plane, with
        a normal within 60 degrees of its. Such a triangle is the point's own surface (or
        flush with it), seen edge-on: it sends no light there. Without this a camera hit on a
        two-sided emitter, rounded to its far side, took its own triangle's light over a
        whole hemisphere: Blender's Principled BSDF with Emission over the default Base
        Color, a lone plane, rendered 7 % too bright, single pixels 47 %; a one-sided
        emitter lost its samples there. A point near an emitting wall of another orientation
        (on the floor, 10 um from the wall) is not on it and gets its light
        (tests/test_hard_cases.py). ``n`` None: no point is on any."""
        if n is None:
            return np.zeros(len(x), bool)
        band = offset_distance(x, self.extent)
        normals = self.normals[tri]
        height = _dot(self.tris[tri, 0] - x, normals)
        return (np.abs(height) <= band) & (np.abs(_dot(n, normals)) >= 0.5)

    def _solid_angles(self, x, n=None, with_units: bool = False):
        """(N, T) solid angles [sr] of the triangles seen from points x, 0 for one-sided
        triangles seen from behind and for those x lies on (with normals n: ``on_surface``),
        times each triangle's factor ``scale`` (the sampler's choice of triangle,
        ``sample``); ``with_units``: also the unit directions to the vertices, per component
        ([x, y, z] of (N, V))."""
        # Unit directions to the vertices, component by component (N, V), then the
        # triangles' solid angles (Van Oosterom and Strackee) from their corners (N, T).
        unit = [self.vertices[None, :, k] - x[:, k:k + 1] for k in range(3)]
        length = np.sqrt(unit[0] * unit[0] + unit[1] * unit[1] + unit[2] * unit[2])
        inv = 1.0 / np.where(length > 0, length, 1.0)
        for k in range(3):
            unit[k] *= inv
        i0, i1, i2 = self.corner_index.T
        ax, ay, az = (u_k[:, i0] for u_k in unit)
        bx, by, bz = (u_k[:, i1] for u_k in unit)
        cx, cy, cz = (u_k[:, i2] for u_k in unit)
        triple = np.abs(ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz)
                        + az * (bx * cy - by * cx))
        denom = (1.0 + (ax * bx + ay * by + az * bz) + (bx * cx + by * cy + bz * cz)
                 + (cx * ax + cy * ay + cz * az))
        omega = 2.0 * np.arctan2(triple, denom)                              # (N, T)
        # Triangles that x lies on (``on_surface``: few pairs, tested where x is near the
        # plane) or that it sees from behind (one-sided) give nothing: skip them.
        if n is not None:
            band = offset_distance(x, self.extent)[:, None]
            near = np.flatnonzero(np.all((x >= self.lower - band) & (x <= self.upper + band),
                                         axis=1))           # within the emitter's box
            if len(near):
                height = self.plane_offset[None, :] - x[near] @ self.normals.T
                rows, cols = np.nonzero(np.abs(height) <= band[near])
                rows = near[rows]
                on = self.on_surface(x[rows], n[rows], cols)
                omega[rows[on], cols[on]] = 0.0
        if not self.two_sided:
            side = self.plane_offset[None, :] - x @ self.normals.T        # (c0 - x) . n
            omega = np.where(side < 0, omega, 0.0)
        if self.scale is not None:
            omega = omega * self.scale[None, :]    # triangles by solid angle x factor
        return (omega, unit) if with_units else omega

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) the density [1/sr] with which ``sample`` at ``points`` gives the unit
        directions ``wi`` (0 where wi misses the emitter): the nearest triangle along wi
        decides; solid-angle sampling 1 / Omega_total (a small triangle's area sampling:
        Omega_t / Omega_total x r^2 / (cos_l A_t)); area sampling r^2 / (cos_l A_total)."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        n = None if normals is None else np.asarray(normals, np.float64).reshape(-1, 3)
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        pdf = np.zeros(len(x))
        tri, t = self.nearest_triangle(x, w)
        hit = np.flatnonzero(tri >= 0)
        if len(hit) == 0:
            return pdf
        k, r = tri[hit], t[hit]
        cos_l = np.abs(_dot(w[hit], self.normals[k]))
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.use_solid_angle:
                omega = self._solid_angles(x[hit], None if n is None else n[hit])
                total = omega.sum(axis=1)
                chosen = omega[np.arange(len(hit)), k]
                small = chosen / total * r * r / (cos_l * self.areas[k])
                factor = 1.0 if self.scale is None else self.scale[k]
                value = np.where(chosen > SOLID_ANGLE_MIN, factor / total, small)
                value = np.where((chosen > 0) & (total > 0), value, 0.0)
            else:
                factor = 1.0 if self.scale is None else self.scale[k] / self.mean_scale
                value = factor * r * r / (cos_l * self.total_area)
                # Never sampled where x lies on the triangle (``sample``).
                value = np.where(self.on_surface(x[hit], None if n is None else n[hit], k),
                                 0.0, value)
        pdf[hit] = np.where(np.isfinite(value) & (cos_l > 0), value, 0.0)
        return pdf

    def _facing(self, x, tri_index, direction_to_light):
        """1 where the emitter's lit side faces x along ``direction_to_light``."""
        if self.two_sided:
            return np.ones(len(x))
        return (_dot(self.normals[tri_index], direction_to_light) < 0).astype(np.float64)

    def selection_weight(self, x, n):
        d = self.centroid - x
        r2 = np.maximum(_dot(d, d), 1e-300)
        r = np.sqrt(r2)
        cos_x = np.maximum(_dot(n, d) / r, 0.0)
        omega = np.minimum(self.total_area / r2, 2 * np.pi)
        return (self.rgb @ LUMINANCE) * self.mean_scale * omega * (0.25 + cos_x)

    def sample(self, x, n, u):
        """Directions, shadow distances and irradiance estimates L cos(theta_x) / pdf in
        units of ``rgb`` (x ``scale`` of the sampled triangle)."""
        direction, dist, pdf_w, tri, valid, cos_x, facing = self._sample_directions(x, n, u)
        if self.scale is not None:
            facing = facing * self.scale[tri]        # the radiance there: rgb x its factor
        return direction, np.where(valid, dist, 0.0), _over_pdf(valid, cos_x * facing, pdf_w)

    def sample_rgb(self, x, n, u, pick=None):
        """``sample`` with a radiance per sample (a textured emitter, ``textured_emitter``):
        (directions (N, 3), shadow distances (N,), cos(theta_x) / pdf (N,), the radiance
        (N, 3) [W m^-2 sr^-1] at each sampled point, read from the texture only where the
        sample can count); the irradiance estimate is their product. ``pick`` is unused (the
        signature of ``EnvironmentLight.sample_rgb``)."""
        direction, dist, pdf_w, tri, valid, cos_x, facing = self._sample_directions(x, n, u)
        weight = _over_pdf(valid, cos_x * facing, pdf_w)
        rgb = np.zeros((len(x), 3))
        live = np.flatnonzero(weight > 0)
        if len(live):
            rgb[live] = self.radiance_at(np.take(tri, live), np.take(x, live, axis=0)
                                         + np.take(direction, live, axis=0)
                                         * np.take(dist, live)[:, None])
        return direction, np.where(valid, dist, 0.0), weight, rgb

    def _sample_directions(self, x, n, u):
        """The geometry of ``sample``: directions (N, 3), distances (N,), densities [1/sr]
        (N,), the sampled triangles (N,), which samples are valid (N,), cos(theta_x) (N,) and
        1 where the emitting side faces the point (N,)."""
        count = len(x)
        if self.use_solid_angle:
            rows = np.arange(count)
            omega, unit = self._solid_angles(x, n, with_units=True)   # x the triangles' factors
            total = omega.sum(axis=1)
            cdf = np.cumsum(omega, axis=1)
            pick_u = u[:, 0] * total
            tri = np.minimum((cdf < pick_u[:, None]).sum(axis=1), len(self.tris) - 1)
            # Re-use the selection number inside the chosen triangle's share.
            lower = np.where(tri > 0, cdf[rows, np.maximum(tri - 1, 0)], 0.0)
            chosen = omega[rows, tri]
            u0 = np.clip((pick_u - lower) / np.where(chosen > 0, chosen, 1.0), 0.0, 1.0 - 1e-12)
            tri_pts = self.tris[tri]
            big = chosen > SOLID_ANGLE_MIN
            direction = np.zeros((count, 3))
            dist = np.zeros(count)
            pdf_w = np.zeros(count)
            if np.any(big):
                rb, corners = rows[big], self.corner_index[tri[big]]
                ab, bb, cb = (np.stack([u_k[rb, corners[:, j]] for u_k in unit], axis=1)
                              for j in range(3))
                w = sample_spherical_triangle(ab, bb, cb, np.stack([u0[big], u[big, 1]], 1))
                w = _normalize(w)
                # Distance to the triangle's plane along w.
                nrm = self.normals[tri[big]]
                denom = _dot(w, nrm)
                dist_b = _dot(tri_pts[big, 0] - x[big], nrm) / np.where(np.abs(denom) > 1e-300, denom, 1e-300)
                direction[big] = w
                dist[big] = dist_b
                pdf_w[big] = (1.0 if self.scale is None else self.scale[tri[big]]) / total[big]
            small = ~big & (chosen > 0)
            if np.any(small):
                bary = sampling.square_to_triangle(np.stack([u0[small], u[small, 1]], 1))
                tp = tri_pts[small]
                p = tp[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + tp[:, 1] * bary[:, 0:1] + tp[:, 2] * bary[:, 1:2]
                d = p - x[small]
                r2 = np.maximum(_dot(d, d), 1e-300)
                r = np.sqrt(r2)
                w = d / r[:, None]
                cos_l = np.abs(_dot(w, self.normals[tri[small]]))
                pdf_area_to_w = r2 / np.maximum(cos_l * self.areas[tri[small]], 1e-300)
                direction[small] = w
                dist[small] = r
                pdf_w[small] = (chosen[small] / total[small]) * pdf_area_to_w
            valid = (total > 0) & (pdf_w > 0) & np.isfinite(dist) & (dist > 0)
        else:
            tri = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"),
                             len(self.tris) - 1)
            lower = np.where(tri > 0, self.cdf[np.maximum(tri - 1, 0)], 0.0)
            share = self.cdf[tri] - lower
            u0 = np.clip((u[:, 0] - lower) / np.where(share > 0, share, 1.0), 0.0, 1.0 - 1e-12)
            bary = sampling.square_to_triangle(np.stack([u0, u[:, 1]], 1))
            tp = self.tris[tri]
            p = tp[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + tp[:, 1] * bary[:, 0:1] + tp[:, 2] * bary[:, 1:2]
            d = p - x
            r2 = np.maximum(_dot(d, d), 1e-300)
            dist = np.sqrt(r2)
            direction = d / dist[:, None]
            cos_l = np.abs(_dot(direction, self.normals[tri]))
            pdf_w = share * r2 / np.maximum(cos_l * self.areas[tri], 1e-300)
            # A point on the sampled triangle gets nothing from it (``on_surface``).
            valid = (cos_l > 0) & ~self.on_surface(x, n, tri)
        cos_x = np.maximum(_dot(n, direction), 0.0)
        return direction, dist, pdf_w, tri, valid, cos_x, self._facing(x, tri, direction)


# Points per sub-triangle at which a textured emitter's radiance is averaged, and the least
# sampling factor a sub-triangle gets (of the brightest's).
TEXTURED_EMITTER_POINTS = 16
TEXTURED_EMITTER_FLOOR = 0.02
# Sub-triangles a textured emitter is cut into (at least its own triangles): each costs a
# solid angle per light sample. Measured on the textured room (final, seeds 1-3; 2026-12-04):
# a quad cut into 8 rendered with a per-pixel error (rel. RMSE less the reference's noise)
# of 11.15-11.33 % in 28 s of CPU, uncut (2) 10.22-10.59 % in 24 s; 150 made light sampling
# 6x slower. So a mesh keeps its own triangles (a single triangle is not cut either).
TEXTURED_EMITTER_TRIANGLES = 2


def subdivide_triangles(tris: np.ndarray, segments: int):
    """Each of the (T, 3, 3) triangles cut into segments^2 congruent ones: (T * s^2, 3, 3)
    corners and, per sub-triangle, the parent's index (T * s^2,) and its corners' barycentrics
    (u, v) in the parent (T * s^2, 3, 2)."""
    s = int(segments)
    up = [((i, j), (i + 1, j), (i, j + 1)) for i in range(s) for j in range(s - i)]
    down = [((i + 1, j), (i + 1, j + 1), (i, j + 1)) for i in range(s) for j in range(s - i - 1)]
    local = np.array(up + down, np.float64) / s                       # (s^2, 3, 2)
    count = len(tris)
    bary = np.broadcast_to(local, (count,) + local.shape).reshape(-1, 3, 2)
    parent = np.repeat(np.arange(count), len(local))
    t = np.asarray(tris, np.float64)[parent]
    u, v = bary[..., 0:1], bary[..., 1:2]
    corners = t[:, None, 0] * (1 - u - v) + t[:, None, 1] * u + t[:, None, 2] * v
    return corners, parent, bary


def _segments(triangles: int, parts: int) -> int:
    """The cuts per edge that ``emitter_parts`` makes of each of ``triangles`` triangles for
    about ``parts`` parts."""
    return max(1, int(np.sqrt(parts / max(triangles, 1))))


def emitter_parts(scene, materials, triangles: np.ndarray, parts: int):
    """The emitting triangles ``triangles`` (indices into the scene) cut into about ``parts``
    congruent sub-triangles (``subdivide_triangles``; at least the triangles themselves), and
    each one's mean radiance over ``TEXTURED_EMITTER_POINTS`` stratified points: (corners
    (S, 3, 3), the scene triangle of each (S,), their corners' barycentrics in it (S, 3, 2),
    mean radiance (S, 3) [W m^-2 sr^-1])."""
    corners, parent, bary = subdivide_triangles(scene.triangles[triangles],
                                                _segments(len(triangles), parts))
    k = TEXTURED_EMITTER_POINTS
    u = sampling.square_to_triangle(sampling.stratified_2d(1, k, np.random.default_rng(0))
                                    .reshape(-1, 2))                  # (k, 2) in a sub-triangle
    w = np.stack([1 - u[:, 0] - u[:, 1], u[:, 0], u[:, 1]], axis=1)   # corner weights
    points = np.einsum("kc,scd->skd", w, bary).reshape(-1, 2)         # parent barycentrics
    parents = np.asarray(triangles)[parent]                            # scene triangle per S
    prim = np.repeat(parents, k)
    radiance = materials.at(scene.material_ids[prim], prim, points[:, 0],
                            points[:, 1]).emitted_radiance
    return corners, parents, bary, radiance.reshape(len(corners), k, 3).mean(axis=1)


# A textured emitter's light samples (``TexturedTriangleEmitter``): this share by solid angle
# over its triangles, the rest from about ``TEXTURED_LIGHT_PARTS`` parts by their power (area
# x mean luminance, floored at ``TEXTURED_EMITTER_FLOOR`` of the brightest's, as its photons
# are), weighted by the balance heuristic of the two densities.
TEXTURED_SOLID_ANGLE_SHARE = 0.5
TEXTURED_LIGHT_PARTS = 4096


def textured_emitter(name: str, scene, materials, triangles: np.ndarray, two_sided: bool):
    """The light-sampling emitter of a mesh whose emission is textured (issue 24), or None
    where it emits nothing: its triangles (indices ``triangles`` into the scene) cut into
    ``TEXTURED_EMITTER_TRIANGLES`` sub-triangles (at least the triangles themselves), each
    with its mean radiance over ``TEXTURED_EMITTER_POINTS`` points, sampled by solid angle x
    that radiance's luminance (floored at ``TEXTURED_EMITTER_FLOOR`` of the brightest's, so
    that no part that emits goes unsampled); and the same triangles cut into about
    ``TEXTURED_LIGHT_PARTS`` parts, sampled by their power (``TexturedTriangleEmitter``).
    Its samples read the texture at their own points (``radiance_at``, ``sample_rgb``): the
    estimate is unbiased, the strategies only shape its noise. One light, as Cycles samples a
    textured emissive mesh: three lights, one per colour channel, paid every light sample's
    solid angles, shadow rays and shadow photons three times."""
    corners, parents, _bary, radiance = emitter_parts(scene, materials, triangles,
                                                      TEXTURED_EMITTER_TRIANGLES)
    luminance = radiance @ LUMINANCE
    brightest = int(np.argmax(luminance))
    peak = float(luminance[brightest])
    if peak <= 0:
        return None
    # Per sub-triangle, the linear map from a point on its scene triangle's plane to that
    # triangle's barycentrics (least squares on the plane): (bu, bv) = rows @ (p - origin).
    t = scene.triangles[parents].astype(np.float64)
    rows, origin = _barycentric_rows(t)

    def radiance_at(tri, points):
        bary = np.einsum("nij,nj->ni", np.take(rows, tri, axis=0),
                         points - np.take(origin, tri, axis=0))
        bu = np.clip(bary[:, 0], 0.0, 1.0)
        bv = np.clip(bary[:, 1], 0.0, 1.0 - bu)
        prim = np.take(parents, tri)
        return materials.at(scene.material_ids[prim], prim, bu, bv).emitted_radiance

    scale = np.maximum(luminance / peak, TEXTURED_EMITTER_FLOOR)
    # The parts cut the emitter's own triangles (TEXTURED_EMITTER_TRIANGLES = 2 cuts none):
    # part i lies on triangle i // s^2.
    parts = emitter_parts(scene, materials, triangles, TEXTURED_LIGHT_PARTS)
    part_luminance = parts[3] @ LUMINANCE
    part_luminance = np.maximum(part_luminance, TEXTURED_EMITTER_FLOOR * part_luminance.max())
    return TexturedTriangleEmitter(name, corners, radiance[brightest], two_sided=two_sided,
                                   scale=scale, radiance_at=radiance_at, mean_radiance=radiance,
                                   parts=(parts[0], part_luminance,
                                          _segments(len(triangles), TEXTURED_LIGHT_PARTS)),
                                   rows=rows, origin=origin)


def _barycentric_rows(t: np.ndarray):
    """For triangles t (T, 3, 3): the maps (T, 2, 3) and origins (T, 3) with which a point p
    on a triangle's plane has barycentrics (bu, bv) = rows @ (p - origin)."""
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    a11, a12, a22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    det = a11 * a22 - a12 * a12
    det = np.where(np.abs(det) > 1e-300, det, 1.0)[:, None]
    rows = np.stack([(a22[:, None] * e1 - a12[:, None] * e2) / det,
                     (a11[:, None] * e2 - a12[:, None] * e1) / det], axis=1)   # (T, 2, 3)
    return rows, t[:, 0]


class TexturedTriangleEmitter(TriangleEmitter):
    """A textured emissive mesh's light (``textured_emitter``): one sample in
    ``TEXTURED_SOLID_ANGLE_SHARE`` is drawn as ``TriangleEmitter`` draws (solid angle x each
    triangle's mean luminance), the others from its parts, picked by their power and
    uniform on each; a sample of either counts cos(theta_x) / (s p_solid + (1 - s) p_parts)
    (one-sample MIS, balance heuristic), so that a small bright texel is found by the parts
    and a large dim emitter close by keeps its solid-angle sampling. ``parts``: (corners
    (T s^2, 3, 3) of the ``subdivide_triangles`` cut of each triangle into s^2, their
    luminance (T s^2,), s); ``rows``, ``origin``: ``_barycentric_rows`` of the triangles."""

    def __init__(self, name, triangles, radiance, two_sided, scale, radiance_at, mean_radiance,
                 parts, rows, origin):
        super().__init__(name, triangles, radiance, two_sided=two_sided, in_bvh=True,
                         scale=scale, radiance_at=radiance_at, mean_radiance=mean_radiance)
        corners, luminance, segments = parts
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        self.part_corners = corners
        self.part_areas = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
        weights = self.part_areas * luminance
        self.part_prob = weights / weights.sum()
        self.part_cdf = np.cumsum(self.part_prob)
        self.segments = int(segments)
        self.rows, self.origin = rows, origin
        # (i, j, upper?) -> the part's index within its triangle, in ``subdivide_triangles``'
        # order: the upright (i, j) first, then the inverted ones.
        s = self.segments
        table = np.zeros((s, s, 2), np.int64)
        k = 0
        for i in range(s):
            for j in range(s - i):
                table[i, j, 0] = k
                k += 1
        for i in range(s):
            for j in range(s - i - 1):
                table[i, j, 1] = k
                k += 1
        self.part_table = table

    def _part_of(self, tri, points):
        """The part (N,) holding each point on triangle ``tri`` (N,)."""
        bary = np.einsum("nij,nj->ni", np.take(self.rows, tri, axis=0),
                         points - np.take(self.origin, tri, axis=0))
        s = self.segments
        su = np.clip(bary[:, 0], 0.0, 1.0) * s
        sv = np.clip(bary[:, 1], 0.0, 1.0) * s
        i = np.clip(np.floor(su).astype(np.int64), 0, s - 1)
        j = np.clip(np.floor(sv).astype(np.int64), 0, s - 1 - i)
        inverted = ((su - i) + (sv - j) >= 1.0) & (i + j < s - 1)
        return tri * s * s + self.part_table[i, j, inverted.astype(np.int64)]

    def _parts_pdf(self, tri, points, dist, direction):
        """The parts strategy's density [1/sr] of the directions to ``points`` on ``tri``."""
        part = self._part_of(tri, points)
        cos_l = np.abs(_dot(direction, self.normals[tri]))
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = self.part_prob[part] / self.part_areas[part] * dist * dist / cos_l
        return np.where(np.isfinite(pdf) & (cos_l > 0), pdf, 0.0)

    def _sample_parts(self, x, n, u):
        """Directions, distances and triangles of samples drawn from the parts."""
        part = np.minimum(np.searchsorted(self.part_cdf, u[:, 0] * self.part_cdf[-1],
                                          side="right"), len(self.part_prob) - 1)
        lower = np.where(part > 0, self.part_cdf[np.maximum(part - 1, 0)], 0.0)
        share = self.part_prob[part]
        u0 = np.clip((u[:, 0] * self.part_cdf[-1] - lower) / np.where(share > 0, share, 1.0),
                     0.0, 1.0 - 1e-12)
        bary = sampling.square_to_triangle(np.stack([u0, u[:, 1]], 1))
        c = self.part_corners[part]
        p = c[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + c[:, 1] * bary[:, 0:1] \
            + c[:, 2] * bary[:, 1:2]
        d = p - x
        dist = np.sqrt(np.maximum(_dot(d, d), 1e-300))
        return d / dist[:, None], dist, part // (self.segments * self.segments)

    def _mixed(self, x, n, u):
        """Directions, distances, triangles and cos(theta_x) / (mixed density) x facing."""
        share = TEXTURED_SOLID_ANGLE_SHARE
        solid = u[:, 0] < share
        direction = np.zeros((len(x), 3))
        dist = np.zeros(len(x))
        tri = np.zeros(len(x), np.int64)
        p_solid = np.zeros(len(x))
        if solid.any():
            us = np.stack([u[solid, 0] / share, u[solid, 1]], 1)
            d, r, pdf, t, valid, _cos, _facing = self._sample_directions(x[solid], n[solid], us)
            direction[solid], dist[solid], tri[solid] = d, np.where(valid, r, 0.0), t
            p_solid[solid] = pdf                 # the density it drew them with
        rest = ~solid
        if rest.any():
            up = np.stack([(u[rest, 0] - share) / (1.0 - share), u[rest, 1]], 1)
            direction[rest], dist[rest], tri[rest] = self._sample_parts(x[rest], n[rest], up)
            p_solid[rest] = TriangleEmitter.solid_angle_pdf(self, x[rest], n[rest],
                                                            direction[rest])
        points = x + direction * dist[:, None]
        p_parts = self._parts_pdf(tri, points, dist, direction)
        cos_x = np.maximum(_dot(n, direction), 0.0)
        facing = self._facing(x, tri, direction)
        valid = (dist > 0) & np.isfinite(dist) & ~self.on_surface(x, n, tri)
        weight = _over_pdf(valid, cos_x * facing, share * p_solid + (1.0 - share) * p_parts)
        return direction, np.where(valid, dist, 0.0), tri, weight

    def sample(self, x, n, u):
        """``TriangleEmitter.sample``'s estimates, in units of ``rgb`` (the radiance read at
        each sample, over ``rgb``'s luminance)."""
        direction, dist, weight, rgb = self.sample_rgb(x, n, u)
        return direction, dist, weight * (rgb @ LUMINANCE) / max(float(self.rgb @ LUMINANCE),
                                                                 1e-300)

    def sample_rgb(self, x, n, u, pick=None):
        """``TriangleEmitter.sample_rgb`` by the two strategies of the class docstring."""
        direction, dist, tri, weight = self._mixed(x, n, u)
        rgb = np.zeros((len(x), 3))
        live = np.flatnonzero(weight > 0)
        if len(live):
            rgb[live] = self.radiance_at(np.take(tri, live), np.take(x, live, axis=0)
                                         + np.take(direction, live, axis=0)
                                         * np.take(dist, live)[:, None])
        return direction, dist, weight, rgb

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) the mixed density [1/sr] with which ``sample`` gives ``wi`` from ``points``."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        share = TEXTURED_SOLID_ANGLE_SHARE
        pdf = share * TriangleEmitter.solid_angle_pdf(self, x, normals, w)
        tri, t = self.nearest_triangle(x, w)
        hit = np.flatnonzero(tri >= 0)
        if len(hit):
            k, r = tri[hit], t[hit]
            pdf[hit] += (1.0 - share) * self._parts_pdf(k, x[hit] + w[hit] * r[:, None], r,
                                                         w[hit])
        return pdf


def area_light_triangles(light: AreaLight) -> np.ndarray:
    """A rectangle light as two triangles wound so that their normal is the emission side."""
    c, du, dv = light.center, light.axis_u, light.axis_v
    p00, p10, p11, p01 = c - du - dv, c + du - dv, c + du + dv, c - du + dv
    tris = np.array([[p00, p11, p10], [p00, p01, p11]])
    # Winding (p00, p11, p10) has normal -(du x dv), the emission side (local -Z).
    return tris


class EllipseEmitter:
    """Disk and ellipse area lights, one-sided: sampled by area (concentric map) from afar, and
    as a fan of triangles by solid angle from close by."""

    kind = "area"

    def __init__(self, light: AreaLight):
        self.name = light.name
        self.camera_visible = light.camera_visible
        self.center = light.center
        self.du, self.dv = light.axis_u, light.axis_v
        self.normal = light.normal
        self.area = light.area
        self.rgb = light.radiance
        self.power = light.power
        # Close to the light, area sampling is noisy (the 1/r^2 peak): there the light is a fan
        # of FAN_SEGMENTS triangles, scaled to the same area, sampled by solid angle.
        k = self.FAN_SEGMENTS
        phi = 2 * np.pi * np.arange(k + 1) / k
        grow = np.sqrt(np.pi / (0.5 * k * np.sin(2 * np.pi / k)))
        rim = self.center + grow * (np.cos(phi)[:, None] * self.du + np.sin(phi)[:, None] * self.dv)
        # Wound so that the triangles' normal is the emission side (-(du x dv)).
        fan = np.stack([np.broadcast_to(self.center, (k, 3)), rim[1:], rim[:-1]], axis=1)
        self.fan = TriangleEmitter(light.name, fan, self.rgb, two_sided=False)
        self.near_distance = 3.0 * max(np.linalg.norm(self.du), np.linalg.norm(self.dv))

    FAN_SEGMENTS = 64

    def intersect(self, origins, directions, t_max):
        """Nearest hit t (N,) of rays with the ellipse on its emitting side (inf: none before
        ``t_max``) and the radiance factor there (1; 0 for no hit)."""
        cos = directions @ self.normal
        t = _dot(self.center - origins, np.broadcast_to(self.normal, origins.shape)) / \
            np.where(cos < 0, cos, -1.0)
        q = origins + t[:, None] * directions - self.center
        a = q @ self.du / max(float(self.du @ self.du), 1e-300)
        b = q @ self.dv / max(float(self.dv @ self.dv), 1e-300)
        hit = (cos < 0) & (t > 0) & (t < t_max) & (a * a + b * b <= 1.0)
        return np.where(hit, t, np.inf), hit.astype(np.float64)

    def sample(self, x, n, u):
        near = np.linalg.norm(x - self.center, axis=1) < self.near_distance
        if not np.any(near):
            return self._sample_area(x, n, u)
        if np.all(near):
            return self.fan.sample(x, n, u)
        w = np.zeros((len(x), 3)); dist = np.zeros(len(x)); e = np.zeros(len(x))
        for mask, fn in ((near, self.fan.sample), (~near, self._sample_area)):
            w[mask], dist[mask], e[mask] = fn(x[mask], n[mask], u[mask])
        return w, dist, e

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) the density [1/sr] of ``sample``'s directions ``wi`` from ``points``: near the
        light the fan's (``TriangleEmitter.solid_angle_pdf``), from afar the area sampling's
        r^2 / (cos_l A) where wi meets the ellipse on its emitting side, else 0."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        near = np.linalg.norm(x - self.center, axis=1) < self.near_distance
        pdf = np.zeros(len(x))
        if near.any():
            pdf[near] = self.fan.solid_angle_pdf(
                x[near], None if normals is None else np.asarray(normals).reshape(-1, 3)[near],
                w[near])
        far = ~near
        if far.any():
            t, hit = self.intersect(x[far], w[far], np.inf)
            cos_l = -(w[far] @ self.normal)
            with np.errstate(divide="ignore", invalid="ignore"):
                value = t * t / (cos_l * self.area)
            pdf[far] = np.where((hit > 0) & (cos_l > 0) & np.isfinite(value), value, 0.0)
        return pdf

    def selection_weight(self, x, n):
        d = self.center - x
        r2 = np.maximum(_dot(d, d), 1e-300)
        r = np.sqrt(r2)
        cos_x = np.maximum(_dot(n, d) / r, 0.0)
        cos_l = np.maximum(-_dot(d, self.normal[None]) / r, 0.0)
        omega = np.minimum(self.area * (0.1 + cos_l) / r2, 2 * np.pi)
        return (self.rgb @ LUMINANCE) * omega * (0.25 + cos_x)

    def _sample_area(self, x, n, u):
        disk = sampling.square_to_disk(u)
        p = self.center + disk[:, 0:1] * self.du + disk[:, 1:2] * self.dv
        d = p - x
        r2 = np.maximum(_dot(d, d), 1e-300)
        dist = np.sqrt(r2)
        w = d / dist[:, None]
        cos_l = np.maximum(-_dot(w, self.normal[None]), 0.0)   # lit side only
        cos_x = np.maximum(_dot(n, w), 0.0)
        weight = cos_x * cos_l * self.area / r2
        return w, dist, weight


class SphereLight:
    """A point or spot light with a radius R > 0 (``PointLight.radius``, ``SpotLight.radius``),
    as Cycles 4.x/5.x lights it (``kernel/light/point.h``, ``spot.h``; ``scene/light.cpp``).

    Radiance L = Phi / (4 pi^2 R^2) per channel (Cycles: strength / (pi x 4 pi R^2)). Two
    shapes, Blender's Soft Falloff switch:
    * sphere (``soft_falloff`` False): a Lambertian sphere, flux Phi. From outside, directions
      are uniform in the cone the sphere subtends (sin^2 theta_max = R^2 / d^2), estimate
      L cos(theta_x) 2 pi (1 - cos theta_max); the shadow ray ends on the sphere (law of
      cosines). From inside (d <= R), as Cycles: cosine directions about the normal, estimate
      pi L, the ray ends where it leaves the sphere.
    * facing disk (``soft_falloff`` True, Blender's default): a disk of radius R through the
      centre, facing the shading point, sampled by area (concentric map), estimate
      L cos(theta_x) cos(theta_l) pi R^2 / t^2; on its axis E = Phi cos / (4 pi (d^2 + R^2)).
    A spot multiplies each sample by its cone mask (``spot_mask``) evaluated on that sample's
    own direction from the light to the point (Cycles ``spot_light_attenuation(-D)``); a
    sphere spot applies no mask to points inside the sphere.
    Not geometry: camera paths see it through ``seen_light_radiance``; no shadow photons
    (``engine/shadow_photons.py`` covers area lights and emissive meshes only), so every
    shadow ray to it is traced.
    """

    kind = "sphere"
    in_bvh = False
    shadow_photons = False

    def __init__(self, light):
        self.name = light.name
        self.camera_visible = bool(getattr(light, "camera_visible", False))
        self.center = np.asarray(light.position, np.float64)
        self.radius = float(light.radius)
        self.sphere = not light.soft_falloff
        self.power = np.asarray(light.flux, np.float64)
        self.rgb = self.power / (4.0 * np.pi ** 2 * self.radius ** 2)
        if isinstance(light, SpotLight):
            self.axis = np.asarray(light.direction, np.float64)
            self.cos_half = float(np.cos(light.half_angle))
            self.blend = light.blend
        else:
            self.axis = None

    def mask(self, travel: np.ndarray) -> np.ndarray:
        """The spot cone for unit directions of travel from the light (N, 3); 1 for a point."""
        if self.axis is None:
            return np.ones(len(travel))
        return spot_mask(travel @ self.axis, self.cos_half, self.blend)

    def selection_weight(self, x, n):
        d = self.center - x
        r2 = np.maximum(_dot(d, d), 1e-300)
        r = np.sqrt(r2)
        cos_x = np.maximum(_dot(n, d) / r, 0.0)
        # Unoccluded irradiance of a point light of the same flux, capped by pi L inside;
        # a spot's mask on the centre's direction, floored (the sphere reaches past the cone).
        e = np.minimum((self.power @ LUMINANCE) / (4 * np.pi * r2), np.pi * (self.rgb @ LUMINANCE))
        m = 0.1 + self.mask(-d / r[:, None])
        return e * m * (0.25 + cos_x)

    def sample(self, x, n, u):
        """Directions (unit, to the light), shadow-ray distances, estimates: irradiance before
        visibility = weight * rgb."""
        count = len(x)
        rel = self.center - x
        d2 = _dot(rel, rel)
        d = np.sqrt(d2)
        to_c = rel / np.where(d > 0, d, 1.0)[:, None]
        r, r2 = self.radius, self.radius ** 2
        w = np.empty((count, 3))
        t = np.empty(count)
        weight = np.empty(count)
        masked = np.ones(count, bool)
        if self.sphere:
            out = d2 > r2
            if np.any(out):
                s2 = r2 / d2[out]
                omc = s2 / (1.0 + np.sqrt(1.0 - s2))           # 1 - cos theta_max, precise
                z = 1.0 - u[out, 0] * omc
                rho = np.sqrt(np.maximum(0.0, u[out, 0] * omc * (2.0 - u[out, 0] * omc)))
                phi = 2.0 * np.pi * u[out, 1]
                tt, bb = sampling.orthonormal_basis(to_c[out])
                wo = (rho * np.cos(phi))[:, None] * tt + (rho * np.sin(phi))[:, None] * bb \
                    + z[:, None] * to_c[out]
                w[out] = wo
                do = d[out]
                t[out] = do * z - np.sqrt(np.maximum(0.0, r2 - do * do * (1.0 - z * z)))
                weight[out] = 2.0 * np.pi * omc
            inside = ~out
            if np.any(inside):
                ni = n[inside].astype(np.float64)
                tt, bb = sampling.orthonormal_basis(ni)
                wi = sampling.to_world(sampling.square_to_cosine_hemisphere(u[inside]), tt, bb, ni)
                w[inside] = wi
                di = d[inside]
                c = _dot(wi, to_c[inside])
                t[inside] = di * c + np.sqrt(np.maximum(0.0, r2 - di * di * (1.0 - c * c)))
                weight[inside] = np.pi          # cos / pdf, cos is in the pdf
                masked[inside] = False
            cos_x = np.where(out, np.maximum(_dot(n, w), 0.0), 1.0)
        else:
            # Disk through the centre facing x (normal from the centre to x).
            facing = -to_c
            facing[d <= 0] = (0.0, 0.0, 1.0)
            tt, bb = sampling.orthonormal_basis(facing)
            disk = sampling.square_to_disk(u) * r
            p = self.center + disk[:, 0:1] * tt + disk[:, 1:2] * bb
            v = p - x
            t = np.sqrt(np.maximum(_dot(v, v), 1e-300))
            w = v / t[:, None]
            cos_l = np.maximum(-_dot(w, facing), 0.0)
            cos_x = np.maximum(_dot(n, w), 0.0)
            weight = np.pi * r2 * cos_l / (t * t)
        if self.axis is not None:
            weight = weight * np.where(masked, self.mask(-w), 1.0)
        weight = weight * cos_x
        ok = np.isfinite(weight) & (t > 0)
        return w, np.where(ok, t, 0.0), np.where(ok, weight, 0.0)

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) the density [1/sr] of ``sample``'s directions ``wi`` from ``points`` with
        ``normals``: the sphere's cone 1 / (2 pi (1 - cos theta_max)) where wi meets the
        sphere (from inside, cos / pi about the normal); the facing disk's t^2 / (cos_l pi R^2)
        where wi meets the disk; else 0. The spot's mask weights the estimate, not the pdf."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        rel = self.center - x
        d2 = _dot(rel, rel)
        r2 = self.radius ** 2
        b = _dot(w, rel)                                   # |rel| cos(angle to the centre)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.sphere:
                out = d2 > r2
                s2 = np.where(out, r2 / np.where(out, d2, 1.0), 1.0)
                omc = s2 / (1.0 + np.sqrt(np.maximum(0.0, 1.0 - s2)))
                # wi inside the cone: 1 - cos(angle) <= 1 - cos theta_max, the angle's cosine
                # b / d > 0 (precise form: 1 - cos = |w x rel|^2 / (d^2 (1 + cos))).
                cos_a = b / np.sqrt(np.where(d2 > 0, d2, 1.0))
                cross = np.cross(w, rel)
                one_minus = _dot(cross, cross) / np.where(d2 > 0, d2, 1.0) / (1.0 + cos_a)
                inside_cone = (cos_a > 0) & (one_minus <= omc)
                pdf = np.where(out & inside_cone, 1.0 / (2.0 * np.pi * omc), 0.0)
                if not out.all():
                    n = np.asarray(normals, np.float64).reshape(-1, 3)
                    pdf = np.where(out, pdf, np.maximum(_dot(n, w), 0.0) / np.pi)
            else:
                d = np.sqrt(d2)
                cos_l = b / np.where(d > 0, d, 1.0)          # wi against the disk's normal
                t = d / np.where(cos_l > 0, cos_l, 1.0)
                q = t[:, None] * w - rel
                hit = (cos_l > 0) & (d > 0) & (_dot(q, q) < r2)
                pdf = np.where(hit, t * t / (cos_l * np.pi * r2), 0.0)
        return np.where(np.isfinite(pdf), pdf, 0.0)

    def intersect(self, origins, directions, t_max):
        """Nearest hit t (N,) of rays with the light as Cycles intersects it (inf: none before
        ``t_max``), and the radiance factor there (1, or a spot's mask; 0 for no hit)."""
        rel = origins - self.center                     # from the centre to the origins
        d2 = _dot(rel, rel)
        r2 = self.radius ** 2
        b = _dot(directions, rel)
        if self.sphere:
            disc = b * b - (d2 - r2)
            root = np.sqrt(np.maximum(disc, 0.0))
            near, far = -b - root, -b + root
            t = np.where(near > 0, near, far)
            hit = (disc >= 0) & (t > 0)
            apply_mask = d2 > r2
        else:
            # The plane through the centre with normal towards the origin: t = d / cos.
            d = np.sqrt(d2)
            cos_a = -b / np.where(d > 0, d, 1.0)       # cos between the ray and the normal
            t = d / np.where(cos_a > 0, cos_a, 1.0)
            q = rel + t[:, None] * directions
            hit = (cos_a > 1e-12) & (d > 0) & (_dot(q, q) < r2)
            apply_mask = np.ones(len(t), bool)
        if self.axis is not None:
            hit &= b < 0                                 # Cycles: spots are one-sided
        hit &= t < t_max
        t = np.where(hit, t, np.inf)
        factor = hit.astype(np.float64)
        if self.axis is not None:
            factor *= np.where(apply_mask, self.mask(-directions), 1.0)
        return t, factor


class SunCone:
    """A sun with an angular diameter: uniform directions in its cone."""

    kind = "sun"

    def __init__(self, light: SunLight):
        self.name = light.name
        self.camera_visible = light.camera_visible
        self.to_light = -light.direction
        self.rgb = light.irradiance
        self.cos_max = np.cos(0.5 * light.angle)
        # The disc's radiance as Cycles gives it (measured: 125.71 for strength 3 and angle
        # 10 degrees, E / (pi sin^2(5 deg)) = 125.71).
        self.disc_radiance = self.rgb / (np.pi * np.sin(0.5 * light.angle) ** 2)
        t, b = sampling.orthonormal_basis(self.to_light[None])
        self.frame = (t[0], b[0])

    def selection_weight(self, x, n):
        return (self.rgb @ LUMINANCE) * (0.1 + np.maximum(n @ self.to_light, 0.0))

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) 1 / (2 pi (1 - cos theta_max)) [1/sr] for directions ``wi`` inside the cone,
        0 outside."""
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        return np.where(w @ self.to_light >= self.cos_max,
                        1.0 / (2.0 * np.pi * (1.0 - self.cos_max)), 0.0)

    def sample(self, x, n, u):
        local = sampling.square_to_cone(u, self.cos_max)
        t, b = self.frame
        w = local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * self.to_light
        cos_x = np.maximum(_dot(n, w), 0.0)
        return w, np.full(len(x), np.inf), cos_x


class WorldLight:
    """A constant environment: cosine-distributed directions, estimate pi L."""

    kind = "world"
    name = "World"

    def __init__(self, radiance):
        self.rgb = np.pi * np.asarray(radiance, np.float64)   # estimate pi L per sample

    def selection_weight(self, x, n):
        return np.full(len(x), self.rgb @ LUMINANCE)

    def solid_angle_pdf(self, points, normals, wi):
        """(N,) cos / pi [1/sr] about ``normals`` for directions ``wi`` (0 below)."""
        n = np.asarray(normals, np.float64).reshape(-1, 3)
        return np.maximum(_dot(n, np.asarray(wi, np.float64).reshape(-1, 3)), 0.0) / np.pi

    def sample(self, x, n, u):
        t, b = sampling.orthonormal_basis(n)
        w = sampling.to_world(sampling.square_to_cosine_hemisphere(u), t, b, n)
        return w, np.full(len(x), np.inf), np.ones(len(x))


ENV_CDF_SHARE = 0.75       # an image world's light samples drawn from its CDF (rest: cosine)
BRIGHT_SHARE = 0.5         # ... from its bright patches' table where it has one (a sun)
PORTAL_SHARE = 0.5         # where portals face a point: samples through them
# Where the image's CDF sees out through the portals (its share ``phi`` of probe directions),
# the portals' share falls to PORTAL_SHARE - PORTAL_SHIFT * phi and the CDF's gains it.
PORTAL_SHIFT = 0.4
PORTAL_PROBES = 8          # the CDF probe directions: a PORTAL_PROBES^2 stratified set


class PortalSet:
    """Light portals (Cycles' ``is_portal`` area lights; ``World.portals``): windows through
    which an environment's light samples and photons go. Each portal: centre c, half axes
    du, dv, unit normal n (its emitting side, into the room), area A, shape."""

    def __init__(self, portals):
        self.lights = list(portals)
        self.centers = np.array([p.center for p in self.lights], np.float64).reshape(-1, 3)
        self.du = np.array([p.axis_u for p in self.lights], np.float64).reshape(-1, 3)
        self.dv = np.array([p.axis_v for p in self.lights], np.float64).reshape(-1, 3)
        self.normals = np.array([p.normal for p in self.lights], np.float64).reshape(-1, 3)
        self.areas = np.array([p.area for p in self.lights], np.float64)
        self.round = np.array([p.shape in ("DISK", "ELLIPSE") for p in self.lights], bool)

    def __len__(self):
        return len(self.lights)

    def sample_points(self, k: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Area-uniform points (N, 3) on portals ``k`` (N,) from numbers ``u`` (N, 2)."""
        square = 2.0 * u - 1.0
        disk = sampling.square_to_disk(u)
        local = np.where(self.round[k][:, None], disk, square)
        return self.centers[k] + local[:, 0:1] * self.du[k] + local[:, 1:2] * self.dv[k]

    def weights(self, x: np.ndarray) -> np.ndarray:
        """(N, P) unnormalised selection weights of the portals at points ``x``: their
        approximate solid angle A cos / r^2 (capped at 2 pi) where x is on the room side, else 0."""
        rel = x[:, None, :] - self.centers[None]                       # (N, P, 3)
        height = np.einsum("npk,pk->np", rel, self.normals)
        r2 = np.maximum(np.einsum("npk,npk->np", rel, rel), 1e-300)
        cos = np.clip(height / np.sqrt(r2), 0.0, 1.0)
        omega = np.minimum(self.areas[None] * np.maximum(cos, 0.05) / np.maximum(r2, self.areas[None]),
                           2 * np.pi)
        return np.where(height > 0, omega, 0.0)

    def through(self, x: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N, K) whether rays from points ``x`` (N, 3) along unit ``directions`` (K, 3) leave
        through a portal (cross one from its room side, ahead of the point)."""
        out = np.zeros((len(x), len(directions)), bool)
        for k in range(len(self)):
            c, n = self.centers[k], self.normals[k]
            du2, dv2 = self.du[k] @ self.du[k], self.dv[k] @ self.dv[k]
            denom = directions @ n                                        # (K,)
            outward = denom < -1e-12
            t = ((c - x) @ n)[:, None] / np.where(outward, denom, -1.0)[None]   # (N, K)
            su = (((x - c) @ self.du[k])[:, None] + t * (directions @ self.du[k])[None]) / du2
            sv = (((x - c) @ self.dv[k])[:, None] + t * (directions @ self.dv[k])[None]) / dv2
            inside = (su * su + sv * sv <= 1.0) if self.round[k] else \
                ((np.abs(su) <= 1.0) & (np.abs(sv) <= 1.0))
            out |= inside & (t > 0) & outward[None]
        return out

    def pdf(self, x: np.ndarray, w: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Solid-angle density (N,) [1/sr] of directions ``w`` from ``x`` under portal
        sampling with selection ``weights`` (N, P) (rows summing to 1 or 0): sum over the
        portals the ray crosses of p_select r^2 / (A |cos|)."""
        out = np.zeros(len(x))
        for k in range(len(self)):
            c, n = self.centers[k], self.normals[k]
            denom = w @ n
            t = ((c - x) @ n) / np.where(np.abs(denom) > 1e-12, denom, 1e-12)
            q = x + t[:, None] * w - c
            su = q @ self.du[k] / (self.du[k] @ self.du[k])
            sv = q @ self.dv[k] / (self.dv[k] @ self.dv[k])
            inside = (su * su + sv * sv <= 1.0) if self.round[k] else \
                ((np.abs(su) <= 1.0) & (np.abs(sv) <= 1.0))
            hit = inside & (t > 0) & (denom < 0) & (weights[:, k] > 0)
            r2 = t * t
            out += np.where(hit, weights[:, k] * r2 / np.maximum(np.abs(denom) * self.areas[k],
                                                                 1e-300), 0.0)
        return out


class EnvironmentLight:
    """The world as a sampled light when it is an image (``environment.Environment``) or has
    portals. Each sample picks one of three strategies, and its weight is cos / p with p the
    mixture of the three densities (one-sample MIS, balance heuristic: Veach 1997, 9.2.4):
    * through a portal facing the point (share ``PORTAL_SHARE`` where one does, less
      ``PORTAL_SHIFT`` x phi, phi the share of a fixed set of ``PORTAL_PROBES``^2 directions
      drawn from the image's CDF that leave through a portal from the point: where the sun
      shines through the window the CDF finds it, the portal's area-uniform points seldom
      do): a portal by its approximate solid angle, an area-uniform point on it;
    * the image's CDF (``ENV_CDF_SHARE`` of the rest, plus the portals' ``PORTAL_SHIFT`` x
      phi; a constant world: cosine instead); where the image has bright patches (a sun:
      ``environment.Environment.bright``), their table alone, at ``BRIGHT_SHARE`` of the
      rest, so that the sun gets a fixed count of a point's samples and the smooth rest of
      the sky the cosine samples;
    * cosine directions about the normal (the rest), which keep sky light seen past an
      occluder that takes the CDF's samples (under an overhang) low in noise.
    A sample's radiance is the image's along its direction (``rgb`` per sample:
    ``sample_rgb``).

    ``gather_sky()`` hands the smooth rest of the sky to the final gather (the pipeline calls
    it where one runs, ``preparation.py``): where the image has bright patches and no portal,
    every light sample then comes from the bright patches (the sun), whose radiance is all
    this light counts (its density is 0 elsewhere, so a BSDF's own samples count the rest
    with full weight), and the gather's rays that leave the scene count the image outside
    them (``environment.Environment.smooth_radiance``). The two parts add up to the image
    exactly, each counted once. Sky light is smooth where a sun is not: the irradiance cache
    interpolates it between records of M x N rays instead of each pixel estimating it from
    its few cosine samples (the yard's error at ``final`` 2.1 -> 1.7 %, seeds 1 and 2 of
    2.1 / 2.3 -> 1.7 / 1.9 %), and the sun alone needs few light samples."""

    kind = "world"
    name = "World"
    per_sample_rgb = True

    def __init__(self, world):
        self.environment = world.environment
        self.constant = np.asarray(world.radiance, np.float64)
        self.portals = PortalSet(world.portals)
        self.rgb = np.ones(3)
        # The image's table for light samples: its bright patches where it has them (a sun:
        # ``BRIGHT_SHARE`` of the samples, the cosine strategy the rest of the sky), else
        # all its patches (``ENV_CDF_SHARE``).
        self.table = None if self.environment is None else self.environment.bright
        self.cdf_share = 0.0 if self.environment is None else \
            ENV_CDF_SHARE if self.table is None else BRIGHT_SHARE
        self.sky_gathered = False
        self.has_sky_to_gather = world.has_sky_to_gather
        self.probes = np.zeros((0, 3))
        if self.environment is not None and len(self.portals):
            u = sampling.stratified_2d(1, PORTAL_PROBES ** 2, np.random.default_rng(0))[0]
            self.probes = self.environment.sample(np.clip(u, 0.0, 1.0 - 1e-12),
                                                  table=self.table)[0]

    def radiance(self, directions):
        if self.environment is not None:
            return self.environment.radiance(directions)
        return np.broadcast_to(self.constant, (len(directions), 3)).copy()

    def gather_sky(self):
        """Leave the sky outside the bright patches to the final gather (class docstring)
        where the image has bright patches and no portal faces the scene: returns the
        radiance function a gather's escaping rays count
        (``environment.Environment.smooth_radiance``), else None (nothing changes)."""
        if not self.has_sky_to_gather:
            return None
        self.sky_gathered = True
        self.cdf_share = 1.0
        return self.environment.smooth_radiance

    def selection_weight(self, x, n):
        share = self.environment.bright_power if self.sky_gathered else 1.0
        return np.full(len(x), np.pi * (self.constant @ LUMINANCE) * share)

    def _portal_weights(self, x):
        if not len(self.portals):
            return np.zeros((len(x), 0)), np.zeros(len(x), bool)
        w = self.portals.weights(x)
        total = w.sum(axis=1)
        faces = total > 0
        return w / np.where(faces, total, 1.0)[:, None], faces

    def _shares(self, x, faces):
        """Per point (N,): the shares of the portal, CDF and cosine strategies (class
        docstring); a function of the point alone, so ``sample_rgb`` and
        ``solid_angle_pdf`` agree."""
        portal = np.where(faces, PORTAL_SHARE, 0.0)
        if len(self.probes) and faces.any():
            phi = np.zeros(len(x))
            phi[faces] = self.portals.through(x[faces], self.probes).mean(axis=1)
            portal = portal - PORTAL_SHIFT * phi * faces
        cdf = np.where(faces, (1.0 - PORTAL_SHARE) * self.cdf_share, self.cdf_share)
        cdf = cdf + (np.where(faces, PORTAL_SHARE, 0.0) - portal)
        return portal, cdf, 1.0 - portal - cdf

    def solid_angle_pdf(self, points, normals, wi, env_pdf=None):
        """Density (N,) [1/sr] of this light's samples at ``points`` with ``normals`` giving
        directions ``wi`` (the mixture of ``sample_rgb``). ``env_pdf`` (N,): the image
        table's own density of ``wi`` where the caller has it (``sample_rgb``: its CDF
        samples bring it from ``Environment.sample``)."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        n = np.asarray(normals, np.float64).reshape(-1, 3)
        w = np.asarray(wi, np.float64).reshape(-1, 3)
        cos_pdf = np.maximum(_dot(n, w), 0.0) / np.pi
        if self.environment is None:
            env_pdf = 0.0
        elif env_pdf is None:
            env_pdf = self.environment.direction_pdf(w, self.table)
        sel, faces = self._portal_weights(x)
        if not faces.any():
            return self.cdf_share * env_pdf + (1.0 - self.cdf_share) * cos_pdf
        portal, cdf, cos = self._shares(x, faces)
        return portal * self.portals.pdf(x, w, sel) + cdf * env_pdf + cos * cos_pdf

    def sample_rgb(self, x, n, u, pick=None):
        """Directions, shadow distances (inf), scalar weights cos / p and radiance (N, 3).
        ``pick`` (N,): numbers stratified over a point's samples (``direct.direct_terms``
        passes the remainder of its light choice) that choose the strategy and, for the
        CDF's samples, the image cell from the cells sorted by brightness
        (``Environment.sample(u, u_cell)``); ``u`` (N, 2) then places the sample inside its
        cell, on its portal or about the normal. Without ``pick``, ``u[:, 0]`` chooses the
        strategy and is reused, rescaled, with ``u[:, 1]`` (the densities are the same)."""
        count = len(x)
        x = np.asarray(x, np.float64)
        n64 = np.asarray(n, np.float64)
        if self.cdf_share >= 1.0 and not len(self.portals) and self.environment is not None:
            return self._sample_table_only(n64, u, pick)
        w = np.empty((count, 3))
        stratified = pick is not None
        pick = np.asarray(u[:, 0] if pick is None else pick, np.float64).copy()
        sel, faces = self._portal_weights(x)
        p_share, c_share, _ = self._shares(x, faces)
        portal = faces & (pick < p_share)
        # The CDF and cosine strategies read their number rescaled to [0, 1) over the rest,
        # split at cdf_share as where no portal faces the point.
        rest = np.maximum(1.0 - p_share, 1e-300)
        pick = np.where(portal, pick / np.where(portal, p_share, 1.0), (pick - p_share) / rest)
        split = c_share / rest
        pick = np.clip(pick, 0.0, 1.0 - 1e-12)
        env = ~portal & (pick < split)
        cos = ~portal & ~env
        if portal.any():
            idx = np.flatnonzero(portal)
            cdf = np.cumsum(sel[idx], axis=1)
            k = np.minimum((cdf < pick[idx, None]).sum(axis=1), len(self.portals) - 1)
            rows = np.arange(len(idx))
            lower = np.where(k > 0, cdf[rows, np.maximum(k - 1, 0)], 0.0)
            share = sel[idx, k]
            u0 = u[idx, 0] if stratified else np.clip(
                (pick[idx] - lower) / np.where(share > 0, share, 1.0), 0.0, 1.0 - 1e-12)
            p = self.portals.sample_points(k, np.stack([u0, u[idx, 1]], 1))
            d = p - x[idx]
            w[idx] = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        rgb = np.zeros((count, 3))
        env_pdf = None
        if env.any():
            idx = np.flatnonzero(env)
            if stratified:
                w[idx], rgb[idx], p_env = self.environment.sample(
                    np.clip(u[idx], 0.0, 1.0 - 1e-12),
                    u_cell=np.clip(pick[idx] / split[idx], 0.0, 1.0 - 1e-12),
                    table=self.table)
            else:
                uu = np.stack([pick[idx] / split[idx], u[idx, 1]], 1)
                w[idx], rgb[idx], p_env = self.environment.sample(
                    np.clip(uu, 0.0, 1.0 - 1e-12), table=self.table)
            env_pdf = np.empty(count)
            env_pdf[idx] = p_env
        if cos.any():
            idx = np.flatnonzero(cos)
            if stratified:
                uu = u[idx]
            else:
                lo = split[idx]
                uu = np.stack([np.clip((pick[idx] - lo) / np.maximum(1.0 - lo, 1e-300), 0.0,
                                       1.0 - 1e-12), u[idx, 1]], 1)
            t, b = sampling.orthonormal_basis(n64[idx])
            w[idx] = sampling.to_world(sampling.square_to_cosine_hemisphere(uu), t, b, n64[idx])
        if env_pdf is not None:
            # The image's density of its own samples came with them; the other strategies'
            # directions look it up.
            rest_idx = np.flatnonzero(~env)
            if len(rest_idx):
                env_pdf[rest_idx] = self.environment.direction_pdf(w[rest_idx], self.table)
        pdf = self.solid_angle_pdf(x, n64, w, env_pdf)
        weight, ok = _cosine_weights(n64, w, pdf, rgb)
        # The image's own samples carry their radiance; the others look it up.
        look = np.flatnonzero(ok & ~env)
        if len(look):
            rgb[look] = self.radiance(w[look])
        return w, np.full(count, np.inf), weight, rgb

    def _sample_table_only(self, n64, u, pick):
        """``sample_rgb`` where every sample comes from the image's table (the sky gathered,
        no portal: ``gather_sky``): the mixture is the table's density alone, which its
        samples bring with them."""
        u_cell = None if pick is None else np.clip(pick, 0.0, 1.0 - 1e-12)
        w, rgb, pdf = self.environment.sample(np.clip(u, 0.0, 1.0 - 1e-12), u_cell=u_cell,
                                              table=self.table)
        weight, _ok = _cosine_weights(n64, w, pdf, rgb)
        return w, np.full(len(w), np.inf), weight, rgb

    def sample(self, x, n, u):
        """As the other lights: (directions, distances, weight) with the radiance's luminance
        folded into the weight (``rgb`` is white); ``sample_rgb`` keeps the colour."""
        w, dist, weight, rgb = self.sample_rgb(x, n, u)
        return w, dist, weight * (rgb @ LUMINANCE)


def _cosine_weights(n, w, pdf, rgb):
    """A world sample's weight cos / pdf (N,) and where it counts (pdf > 0 and in front of
    ``n``); ``rgb`` (N, 3) set to 0 where it does not."""
    cos_x = np.maximum(_dot(n, w), 0.0)
    ok = (pdf > 0) & (cos_x > 0)
    rgb[~ok] = 0.0
    return np.where(ok, cos_x / np.where(ok, pdf, 1.0), 0.0), ok


# The light set ------------------------------------------------------------------------------
class LightSet:
    """All lights of a scene, split into exactly evaluated (delta) and sampled lights."""

    def __init__(self, scene: Scene):
        self.points_pos, self.points_intensity, self.point_names = [], [], []
        self.spots = []            # (position, axis, intensity, cos_half, blend, name)
        self.suns = []             # (to_light, irradiance, name)
        self.collimated = []       # AreaLight with collimated=True
        self.sampled = []
        for light in scene.lights:
            if isinstance(light, (PointLight, SpotLight)) and light.radius > 0:
                self.sampled.append(SphereLight(light))
            elif isinstance(light, PointLight):
                self.points_pos.append(light.position)
                self.points_intensity.append(light.flux / (4 * np.pi))
                self.point_names.append(light.name)
            elif isinstance(light, SpotLight):
                self.spots.append((light.position, light.direction, light.flux / (4 * np.pi),
                                   float(np.cos(light.half_angle)), light.blend, light.name))
            elif isinstance(light, SunLight):
                if light.angle > 1e-6:
                    self.sampled.append(SunCone(light))
                else:
                    self.suns.append((-light.direction, light.irradiance, light.name))
            elif isinstance(light, AreaLight):
                if light.collimated:
                    self.collimated.append(light)
                elif light.shape in ("SQUARE", "RECTANGLE"):
                    self.sampled.append(TriangleEmitter(light.name, area_light_triangles(light),
                                                        light.radiance, two_sided=False))
                else:
                    self.sampled.append(EllipseEmitter(light))
                if not light.collimated:   # the per-light switch read by shadow_photons.py
                    self.sampled[-1].shadow_photons = light.shadow_photons
                    self.sampled[-1].camera_visible = light.camera_visible
        self.points_pos = np.array(self.points_pos, np.float64).reshape(-1, 3)
        self.points_intensity = np.array(self.points_intensity, np.float64).reshape(-1, 3)

        # Emissive meshes: one emitter per object, from triangles whose material emits.
        materials = MaterialTable(scene)
        # Per scene triangle: its emitter's index in ``sampled`` (-1: it emits nothing).
        self.emitter_of_triangle = np.full(len(scene.triangles), -1)
        if len(scene.triangles):
            emissive = materials.is_emissive[scene.material_ids]
            self.emissive_triangles = emissive
            if np.any(emissive):
                idx = np.nonzero(emissive)[0]
                keys = scene.object_ids[idx].astype(np.int64) * 65536 + scene.material_ids[idx]
                for key in np.unique(keys):
                    sel = idx[keys == key]
                    oid, mid = int(key // 65536), int(key % 65536)
                    name = scene.object_names[oid] if oid < len(scene.object_names) else "Mesh"
                    surface = materials.at(np.array([mid]))
                    if materials.textured[mid]:
                        emitter = textured_emitter(name, scene, materials, sel,
                                                   bool(surface.both_sides[0]))
                    else:
                        emitter = TriangleEmitter(
                            name, scene.triangles[sel], surface.emitted_radiance[0],
                            two_sided=bool(surface.both_sides[0]), in_bvh=True)
                    if emitter is not None:
                        self.emitter_of_triangle[sel] = len(self.sampled)
                        self.sampled.append(emitter)
        else:
            self.emissive_triangles = np.zeros(0, bool)
        self.world_index = -1          # the world's index in ``sampled`` (-1: black world)
        if not scene.world.is_black:
            self.world_index = len(self.sampled)
            if scene.world.environment is None and not scene.world.portals:
                self.sampled.append(WorldLight(scene.world.radiance))
            else:
                self.sampled.append(EnvironmentLight(scene.world))

    def gather_sky(self):
        """The world light's ``EnvironmentLight.gather_sky`` (the radiance function a final
        gather's escaping rays count), or None where the world is not an image with bright
        patches and no portals."""
        world = self.sampled[self.world_index] if self.world_index >= 0 else None
        return world.gather_sky() if isinstance(world, EnvironmentLight) else None

    @property
    def delta_count(self) -> int:
        return len(self.points_pos) + len(self.spots) + len(self.suns) + len(self.collimated)

    @property
    def empty(self) -> bool:
        return self.delta_count == 0 and not self.sampled

    def selection_weights(self, x, n) -> np.ndarray:
        """(N, L) probabilities of choosing each sampled light, from unoccluded estimates.

        A floor keeps every light's probability positive, so the estimate stays unbiased where
        the cheap estimate is wrong (a large light seen close up, say)."""
        w = np.stack([light.selection_weight(x, n) for light in self.sampled], axis=1)
        w = np.where(np.isfinite(w), np.maximum(w, 0.0), 0.0)
        w += 0.02 * w.mean(axis=1, keepdims=True) + 1e-30
        return w / w.sum(axis=1, keepdims=True)

    def sample_density(self, points, normals, wi, index, light_samples) -> np.ndarray:
        """(N,) the density [1/sr] with which ``direct.direct_terms`` (``light_samples``
        samples per point shared by the sampled lights: one count, or (N,) counts per point)
        draws the directions ``wi`` from
        light ``index`` of ``sampled`` at ``points`` with shading ``normals``: light_samples x
        its selection probability (``selection_weights``) x its ``solid_angle_pdf``. The
        light weight of multiple importance sampling (Veach 1997 §9.2.2, counts included)."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        n = np.asarray(normals, np.float64).reshape(-1, 3)
        if len(x) == 0:
            return np.zeros(0)
        select = self.selection_weights(x, n)[:, index]
        return light_samples * select * self.sampled[index].solid_angle_pdf(x, n, wi)

    def delta_rays(self, x, n):
        """For each delta light: (direction (N,3), distance (N,), scalar weight (N,), rgb (3,));
        irradiance before visibility = weight * rgb. A generator, so callers batch the rays."""
        for pos, intensity in zip(self.points_pos, self.points_intensity):
            w, r, inv_r2 = _towards(pos, x)
            cos_x = sampling.dot_rows(n, w)
            np.maximum(cos_x, 0.0, out=cos_x)
            cos_x *= inv_r2
            yield w, r, cos_x, intensity
        for pos, axis, intensity, cos_half, blend, _name in self.spots:
            w, r, inv_r2 = _towards(pos, x)
            cos_x = np.einsum("ij,ij->i", n, w)
            mask = spot_mask(-(w @ axis.astype(w.dtype)), cos_half, blend)
            yield w, r, np.maximum(cos_x, 0.0) * inv_r2 * mask, intensity
        for to_light, irradiance, _name in self.suns:
            cos_x = np.maximum(n @ to_light.astype(n.dtype), 0.0)
            yield np.broadcast_to(to_light.astype(x.dtype), x.shape).copy(), np.full(len(x), np.inf), cos_x, irradiance
        for light in self.collimated:
            yield self._collimated(light, x, n)

    @staticmethod
    def _collimated(light: AreaLight, x, n):
        """Seed Eq. 7.2: inside the beam E = (P / A) cos(theta), along -normal_light."""
        nl = light.normal
        to_light = -nl
        rel = x - light.center
        height = rel @ nl                            # distance to the plane, > 0 in the beam
        # Position within the light, in units of its half axes.
        du, dv = light.axis_u, light.axis_v
        su = rel @ du / (du @ du)
        sv = rel @ dv / (dv @ dv)
        if light.shape in ("DISK", "ELLIPSE"):
            inside = su * su + sv * sv <= 1.0
        else:
            inside = (np.abs(su) <= 1.0) & (np.abs(sv) <= 1.0)
        ok = inside & (height > 0)
        cos_x = np.maximum(n @ to_light, 0.0)
        return (np.broadcast_to(to_light, x.shape).copy(), np.where(ok, height, 0.0), cos_x * ok,
                light.power / light.area)

    def describe(self) -> dict:
        return {
            "point": len(self.points_pos), "spot": len(self.spots), "sun": len(self.suns),
            "collimated_area": len(self.collimated),
            "sampled": [f"{getattr(s, 'kind', '?')}:{s.name}" for s in self.sampled],
        }


def ray_visible(light) -> bool:
    """Whether rays can meet ``light`` though it is not geometry: point and spot lights with a
    radius (``SphereLight``) and area lights (rectangles as ``TriangleEmitter`` outside the
    BVH, disks and ellipses); collimated area lights, suns and the world are not."""
    return isinstance(light, (SphereLight, EllipseEmitter)) or \
        (isinstance(light, TriangleEmitter) and not light.in_bvh)


def seen_sun_radiance(lights, directions, camera=False) -> np.ndarray:
    """Radiance (N, 3) [W m^-2 sr^-1] of the discs of the suns with an angle (``SunCone``)
    that rays leaving the scene along unit ``directions`` (N, 3) look into, summed (Cycles'
    integrate_distant_lights); ``camera``: only the suns whose ``camera_visible`` is on. For
    camera rays and rays after a delta bounce (mirror, smooth glass), which no light sample
    reaches; after a glossy lobe the sun's light samples count it alone."""
    w = np.asarray(directions, np.float64).reshape(-1, 3)
    out = np.zeros((len(w), 3))
    for light in lights.sampled:
        if isinstance(light, SunCone) and (light.camera_visible or not camera):
            inside = w @ light.to_light >= light.cos_max
            out[inside] += light.disc_radiance
    return out


def seen_light_radiance(lights_or_scene, origins, directions, t_hit, with_index=False,
                        camera=False):
    """Radiance (N, 3) [W m^-2 sr^-1] of the lights that are not geometry but that rays
    (``origins`` (N, 3), unit ``directions`` (N, 3)) meet before ``t_hit`` (N,) (np.inf where
    the ray left the scene; ``ray_visible``: point / spot lights with a radius, a spot's mask
    on the ray's direction (Cycles ``spot_light_sample_from_intersection``), and area lights
    on their emitting side); the nearest light wins; 0 elsewhere. ``lights_or_scene``: a
    ``LightSet`` or a ``Scene``. For camera paths after a delta (mirror, smooth glass)
    bounce, where no light sample could reach the light, and after glossy bounces (weighted
    against light samples), and for camera rays (``camera``: only the lights whose
    ``camera_visible`` is on, Blender's Visibility > Camera). ``with_index``: also the index
    (N,) in ``sampled`` of the light each ray sees (-1: none)."""
    lights = lights_or_scene if isinstance(lights_or_scene, LightSet) else LightSet(lights_or_scene)
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    w = np.asarray(directions, np.float64).reshape(-1, 3)
    best = np.broadcast_to(np.asarray(t_hit, np.float64), (len(o),)).copy()
    out = np.zeros((len(o), 3))
    index = np.full(len(o), -1)
    for li, light in enumerate(lights.sampled):
        if not ray_visible(light) or (camera and not light.camera_visible):
            continue
        t, factor = light.intersect(o, w, best)
        nearer = t < best
        best = np.where(nearer, t, best)
        out[nearer] = factor[nearer, None] * light.rgb[None]
        index[nearer] = li
    return (out, index) if with_index else out
