"""Global photon map: emission per light type, Russian-roulette tracing, kd-tree estimates.

What it computes (seed sections 9.1-9.5, corrections in DESIGN.md §4)
    ``emit_photons(scene, count, rng)``  photons leaving every light, shared among the lights
        in proportion to their flux; each carries its light's RGB flux / its photon count:
        point (uniform sphere, 9.1.1), spot (uniform in its cone, weighted by Blender's mask),
        sun (a disk covering the scene's bounds), area lights (area-uniform points, cosine
        directions, Eq. 9.5; collimated ones along the normal, 9.1.2), emissive meshes
        (triangle by area with ``searchsorted`` on cumulative areas, the seed's "area line",
        area-uniform points, cosine directions, 9.1.3) and a constant world (a uniform
        direction and a point on a disk covering the scene).
    ``trace_photons(scene, accel, emitted, rng)``  all photons advance together through
        Embree; at each hit Russian roulette (9.2) with the channel-averaged reflectances
        Pd, Ps chooses diffuse / specular / absorb and scales the survivor's RGB power by
        rho / P per channel, so colour stays unbiased. Photons are stored at diffuse hits.
        ``max_bounces`` caps the path so a white (rho = 1) enclosure ends.
    ``PhotonMap``  compact float32/float16 arrays (36 bytes a photon), a kd-tree from a
        library (pykdtree or scipy's cKDTree, whichever is faster here), and the radiance
        estimate of Eq. 9.11 with the seed's filters: photons arriving from below the surface
        are rejected and only photons in the disc of Fig. 9.5 count; the radius is capped.

Parameters and units
    Photon power is radiant flux [W] per RGB channel. ``k`` (default 50) photons per
    estimate; ``max_radius`` [m] (default 5 % of the scene's extent); ``disc_thickness``
    (default 0.25): photons farther from the tangent plane than this fraction of the search
    radius are outside the disc. Irradiance estimate E = sum(Phi_p) / (pi r^2) [W/m^2];
    reflected radiance = rho_d / pi * E.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import sampling
from .accel import offset_distance
from .lights import LUMINANCE, area_light_triangles, spot_mask
from .scene import AreaLight, PointLight, Scene, SpotLight, SunLight


@dataclass
class EmittedPhotons:
    origins: np.ndarray        # (N, 3) float64 [m]
    directions: np.ndarray     # (N, 3) float64 unit
    power: np.ndarray          # (N, 3) float64 [W]
    per_light: dict = field(default_factory=dict)   # name -> photon count


def _cosine_directions(normals, u):
    t, b = sampling.orthonormal_basis(normals)
    return sampling.to_world(sampling.square_to_cosine_hemisphere(u), t, b, normals)


def _light_fluxes(scene: Scene):
    """(name, RGB flux [W], emitter) for every light that emits photons."""
    out = []
    lo, hi = scene.bounds()
    center, radius = (lo + hi) / 2, max(np.linalg.norm(hi - lo) / 2, 1e-9)
    for light in scene.lights:
        if isinstance(light, PointLight):
            out.append((light.name, light.flux, ("point", light)))
        elif isinstance(light, SpotLight):
            # Flux inside the cone: Phi / (4 pi) * integral of the mask over the cone.
            cos_half = np.cos(light.half_angle)
            mu = np.linspace(cos_half, 1.0, 2049)
            mask = spot_mask(mu, cos_half, light.blend)
            solid = 2 * np.pi * np.trapz(mask, mu)
            out.append((light.name, light.flux / (4 * np.pi) * solid, ("spot", light)))
        elif isinstance(light, SunLight):
            out.append((light.name, light.irradiance * np.pi * radius ** 2,
                        ("sun", light, center, radius)))
        elif isinstance(light, AreaLight):
            out.append((light.name, light.power, ("area", light)))
    table = scene.material_table()
    if len(scene.triangles):
        emissive = np.nonzero(np.any(table["exitance"][scene.material_ids] > 0, axis=1))[0]
        if len(emissive):
            areas = scene.triangle_areas()[emissive]
            mids = scene.material_ids[emissive]
            sides = np.where(table["both_sides"][mids], 2.0, 1.0)
            flux = (table["exitance"][mids].astype(np.float64) * (areas * sides)[:, None]).sum(0)
            out.append(("emissive meshes", flux, ("mesh", emissive, areas * sides, mids)))
    if not scene.world.is_black:
        out.append(("World", scene.world.radiance * 4 * np.pi ** 2 * radius ** 2,
                    ("world", center, radius)))
    return out


def emit_photons(scene: Scene, count: int, rng: np.random.Generator) -> EmittedPhotons:
    """``count`` photons shared among the lights in proportion to their flux."""
    lights = [entry for entry in _light_fluxes(scene) if np.any(entry[1] > 0)]
    if not lights or count <= 0:
        z = np.zeros((0, 3))
        return EmittedPhotons(z, z.copy(), z.copy())
    lum = np.array([max(float(flux @ LUMINANCE), 1e-30) for _, flux, _ in lights])
    share = np.maximum(np.floor(count * lum / lum.sum()).astype(int), 1)
    origins, directions, powers, per_light = [], [], [], {}
    for (name, flux, spec), n in zip(lights, share):
        u = sampling.stratified_2d(1, n, rng)[0]           # directions / points, stratified
        v = rng.random((n, 2))
        kind = spec[0]
        power = np.broadcast_to(flux / n, (n, 3)).copy()
        if kind == "point":
            o = np.broadcast_to(spec[1].position, (n, 3)).copy()
            d = sampling.square_to_sphere(u)
        elif kind == "spot":
            light = spec[1]
            cos_half = np.cos(light.half_angle)
            t, b = sampling.orthonormal_basis(light.direction[None])
            local = sampling.square_to_cone(u, cos_half)
            d = local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * light.direction
            mask = spot_mask(local[:, 2], cos_half, light.blend)
            # Uniform in the cone, power weighted by the mask; normalised to the cone's flux.
            power = flux[None] * (mask / mask.mean())[:, None] / n
            o = np.broadcast_to(light.position, (n, 3)).copy()
        elif kind == "sun":
            light, center, radius = spec[1], spec[2], spec[3]
            t, b = sampling.orthonormal_basis(light.direction[None])
            disk = sampling.square_to_disk(u) * radius
            o = center - light.direction * (2 * radius) + disk[:, 0:1] * t + disk[:, 1:2] * b
            d = np.broadcast_to(light.direction, (n, 3)).copy()
        elif kind == "area":
            light = spec[1]
            if light.shape in ("DISK", "ELLIPSE"):
                disk = sampling.square_to_disk(u)
                o = light.center + disk[:, 0:1] * light.axis_u + disk[:, 1:2] * light.axis_v
            else:
                o = light.center + (2 * u[:, 0:1] - 1) * light.axis_u + (2 * u[:, 1:2] - 1) * light.axis_v
            normal = np.broadcast_to(light.normal, (n, 3))
            d = normal.copy() if light.collimated else _cosine_directions(np.ascontiguousarray(normal), v)
        elif kind == "mesh":
            tri_idx, weights, _mids = spec[1], spec[2], spec[3]
            table = scene.material_table()
            cdf = np.cumsum(weights)
            pick = np.minimum(np.searchsorted(cdf, u[:, 0] * cdf[-1], side="right"), len(cdf) - 1)
            lower = np.where(pick > 0, cdf[np.maximum(pick - 1, 0)], 0.0)
            u0 = np.clip((u[:, 0] * cdf[-1] - lower) / weights[pick], 0.0, 1.0 - 1e-12)
            bary = sampling.square_to_triangle(np.stack([u0, u[:, 1]], 1))
            tri = scene.triangles[tri_idx[pick]].astype(np.float64)
            o = tri[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + tri[:, 1] * bary[:, 0:1] + tri[:, 2] * bary[:, 1:2]
            nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            both = table["both_sides"][scene.material_ids[tri_idx[pick]]]
            flip = both & (rng.random(n) < 0.5)
            nrm[flip] *= -1
            d = _cosine_directions(nrm, v)
            # Leave the emitting surface (it is geometry too), as accel.offset_origins does.
            eps = offset_distance(o, scene.extent)
            o = o + nrm * eps[:, None]
            # Per-photon colour: each triangle's exitance, normalised to the meshes' flux.
            m = table["exitance"][scene.material_ids[tri_idx[pick]]].astype(np.float64)
            power = m / np.maximum((m @ LUMINANCE)[:, None], 1e-30) * (flux @ LUMINANCE) / n
        else:  # world
            center, radius = spec[1], spec[2]
            d = -sampling.square_to_sphere(u)                 # travelling inwards
            t, b = sampling.orthonormal_basis(d)
            disk = sampling.square_to_disk(v) * radius
            o = center - d * (2 * radius) + disk[:, 0:1] * t + disk[:, 1:2] * b
        origins.append(o); directions.append(d); powers.append(power)
        per_light[name] = int(n)
    return EmittedPhotons(np.concatenate(origins), np.concatenate(directions),
                          np.concatenate(powers), per_light)


@dataclass
class PhotonMap:
    """Stored photons: 36 bytes each (float32 position and power, float16 directions)."""

    positions: np.ndarray       # (P, 3) float32 [m]
    power: np.ndarray           # (P, 3) float32 [W]
    incoming: np.ndarray        # (P, 3) float16, the direction the photon travelled
    normals: np.ndarray         # (P, 3) float16, surface normal on the side it arrived
    bounces: np.ndarray         # (P,) uint8 diffuse/specular bounces before it was stored
    stats: dict = field(default_factory=dict)
    _tree: object = None

    def __len__(self):
        return len(self.positions)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.positions, self.power, self.incoming, self.normals,
                                      self.bounces))

    def build(self, library: str = "pykdtree"):
        t0 = time.perf_counter()
        if len(self) == 0:
            self._tree = None
        elif library == "pykdtree":
            from pykdtree.kdtree import KDTree
            self._tree = KDTree(self.positions.astype(np.float32), leafsize=16)
        else:
            from scipy.spatial import cKDTree
            self._tree = cKDTree(self.positions, leafsize=16)
        self.library = library
        self.stats["build_seconds"] = time.perf_counter() - t0
        return self

    def query(self, points: np.ndarray, k: int):
        """Distances and indices of the k nearest photons (k clipped to the map's size)."""
        k = int(min(k, len(self)))
        if self.library == "pykdtree":
            dist, idx = self._tree.query(np.ascontiguousarray(points, np.float32), k=k)
        else:
            dist, idx = self._tree.query(points, k=k, workers=-1)
        return dist.reshape(len(points), k), idx.reshape(len(points), k)

    def irradiance(self, points, normals, k=50, max_radius=np.inf, disc_thickness=0.25,
                   min_bounces=0):
        """Irradiance estimate E (N, 3) [W/m^2] at ``points`` on the side ``normals`` face.

        Eq. 9.11 over the k nearest photons within ``max_radius``: photons that arrived from
        below the surface, whose surface faces the other way, or that lie farther than
        ``disc_thickness`` x radius from the tangent plane (Fig. 9.5) are left out; the
        radius is the k-th distance, or ``max_radius`` when fewer photons lie within it.
        ``min_bounces`` = 1 keeps only photons that bounced at least once (indirect light).
        """
        e = np.zeros((len(points), 3))
        if self._tree is None or len(points) == 0:
            return e
        dist, idx = self.query(points, k)
        radius = np.minimum(dist[:, -1], max_radius)
        radius = np.where(np.isfinite(radius) & (radius > 0), radius, max_radius)
        pos = self.positions[idx].astype(np.float64)                  # (N, k, 3)
        offset = pos - points[:, None, :]
        height = np.abs(np.einsum("nkj,nj->nk", offset, normals))
        arriving = np.einsum("nkj,nj->nk", self.incoming[idx].astype(np.float32), normals) < 0
        same_side = np.einsum("nkj,nj->nk", self.normals[idx].astype(np.float32), normals) > 0.5
        keep = (dist <= radius[:, None]) & arriving & same_side & (height <= disc_thickness * radius[:, None])
        if min_bounces:
            keep &= self.bounces[idx] >= min_bounces
        flux = np.einsum("nk,nkc->nc", keep.astype(np.float64), self.power[idx].astype(np.float64))
        area = np.pi * radius ** 2
        return flux / np.where(area > 0, area, np.inf)[:, None]


def trace_photons(scene: Scene, accel, emitted: EmittedPhotons, rng: np.random.Generator,
                  max_bounces: int = 64) -> PhotonMap:
    """Trace emitted photons (Russian roulette, 9.2) and store them at diffuse hits."""
    table = scene.material_table()
    rho_d = table["diffuse"].astype(np.float64)
    rho_s = table["specular"].astype(np.float64)
    p_d = rho_d.mean(axis=1)
    p_s = rho_s.mean(axis=1)
    normals_geo = scene.geometric_normals().astype(np.float64)
    o, d, power = emitted.origins.copy(), emitted.directions.copy(), emitted.power.copy()
    depth = np.zeros(len(o), np.int32)
    stored = {"positions": [], "power": [], "incoming": [], "normals": [], "bounces": []}
    absorbed = np.zeros(3)
    escaped = np.zeros(3)
    capped = 0
    capped_power = np.zeros(3)
    while len(o):
        _t, prim, _u, _v = accel.intersect(o, d)
        hit = prim >= 0
        escaped += power[~hit].sum(axis=0)
        o, d, power, prim, depth, t = o[hit], d[hit], power[hit], prim[hit], depth[hit], _t[hit]
        if len(o) == 0:
            break
        x = o + t[:, None].astype(np.float64) * d
        n = normals_geo[prim]
        n = np.where((np.einsum("ij,ij->i", n, d) < 0)[:, None], n, -n)    # towards the photon
        mat = scene.material_ids[prim]
        diffuse = p_d[mat] > 0
        if np.any(diffuse):
            stored["positions"].append(x[diffuse].astype(np.float32))
            stored["power"].append(power[diffuse].astype(np.float32))
            stored["incoming"].append(d[diffuse].astype(np.float16))
            stored["normals"].append(n[diffuse].astype(np.float16))
            stored["bounces"].append(np.minimum(depth[diffuse], 255).astype(np.uint8))
        # Russian roulette with channel-averaged reflectances.
        xi = rng.random(len(o))
        go_diffuse = xi < p_d[mat]
        go_specular = ~go_diffuse & (xi < p_d[mat] + p_s[mat])
        dead = ~(go_diffuse | go_specular)
        absorbed += power[dead].sum(axis=0)
        new_dir = np.empty_like(d)
        if np.any(go_diffuse):
            new_dir[go_diffuse] = _cosine_directions(n[go_diffuse], rng.random((int(go_diffuse.sum()), 2)))
            power[go_diffuse] *= rho_d[mat[go_diffuse]] / p_d[mat[go_diffuse]][:, None]
        if np.any(go_specular):
            ds, ns = d[go_specular], n[go_specular]
            new_dir[go_specular] = ds - 2 * np.einsum("ij,ij->i", ds, ns)[:, None] * ns
            power[go_specular] *= rho_s[mat[go_specular]] / p_s[mat[go_specular]][:, None]
        alive = ~dead
        depth = depth + 1
        over = alive & (depth > max_bounces)
        if np.any(over):
            capped += int(over.sum())
            capped_power += power[over].sum(axis=0)
            alive &= ~over
        o = accel.offset_origins(x[alive], n[alive], new_dir[alive])
        d, power, depth = new_dir[alive], power[alive], depth[alive]

    def cat(key, dtype, width):
        parts = stored[key]
        return np.concatenate(parts) if parts else np.zeros((0, width) if width else 0, dtype)

    pmap = PhotonMap(cat("positions", np.float32, 3), cat("power", np.float32, 3),
                     cat("incoming", np.float16, 3), cat("normals", np.float16, 3),
                     cat("bounces", np.uint8, 0))
    pmap.stats.update({
        "emitted": int(len(emitted.origins)), "stored": int(len(pmap)),
        "flux_emitted": emitted.power.sum(axis=0).tolist(),
        "flux_absorbed": absorbed.tolist(), "flux_escaped": escaped.tolist(),
        "flux_stored_first_hit": (pmap.power[pmap.bounces == 0].astype(np.float64).sum(axis=0).tolist()
                                  if len(pmap) else [0.0, 0.0, 0.0]),
        "capped_paths": capped, "flux_capped": capped_power.tolist(),
        "photons_per_light": emitted.per_light, "bytes": pmap.nbytes,
    })
    return pmap
