"""Global photon map: emission per light type, Russian-roulette tracing, kd-tree estimates.

What it computes (seed sections 9.1-9.5, corrections in DESIGN.md §4)
    ``emit_photons(scene, count, rng)``  photons leaving every light, shared among the lights
        in proportion to their flux; each carries its light's RGB flux / its photon count:
        point (uniform sphere, 9.1.1), spot (uniform in its cone, weighted by Blender's mask;
        with a radius both leave from the sphere's surface, ``lights.sphere_emission_origins``:
        the rays of a Lambertian sphere, flux Phi; with Soft Falloff (Blender's default) the
        power is scaled at the first hit by d^2 / (d^2 + R^2), d the distance from the
        light's centre, so that photons deliver Cycles' facing-disk irradiance there, the
        share it never delivers booked as absorbed),
        sun (a disk covering the scene's bounds), area lights (area-uniform points, cosine
        directions, Eq. 9.5; collimated ones along the normal, 9.1.2), emissive meshes
        (triangle by area x exitance with ``searchsorted`` on cumulative weights, the seed's
        "area line", area-uniform points, cosine directions, 9.1.3; a textured emission by
        the power of ``PHOTON_EMITTER_TRIANGLES`` parts, ``mesh_parts``) and the world: a
        constant one (a
        uniform direction and a point on a disk covering the scene), an image world
        (``environment.Environment``: directions from its CDF, power L / p x the disk's area
        / n, pbrt-v3 ``InfiniteAreaLight::Sample_Le``), or, with light portals, through them
        (``_portal_photons``: a point on a portal, a direction into the room from the mixture
        of the CDF and cosine, power L cos A / (p n); photons whose way out to the sky is
        blocked are dropped, which needs ``emit_photons``'s ``accel``), plus
        ``EXTERIOR_SHARE`` (0.25) of the world's photons from its disc as without portals,
        less those whose first segment enters a portal unblocked (the portal photons carry
        that light; ``_enters_portal``): the light on what lies outside the portals (a
        window's outer reveal, the ground seen through it) that the gather reads there. The
        two sets split the sky's first segments between them, so together they are unbiased.
    ``trace_photons(scene, accel, emitted, rng)``  all photons advance together through
        Embree; at each hit Russian roulette (9.2) with Pd, Ps the largest channels of the
        reflectances (``roulette_probabilities``) chooses diffuse / specular / absorb and
        scales the survivor's RGB power by rho / P per channel, so colour stays unbiased and
        no channel's power grows. Photons are stored at diffuse hits. A specular pick on a
        material with glossy lobes samples them (``bsdf.sample_glossy``, GGX) instead of the
        seed's mirror, the power scaled by the sample's weight / Ps.
        ``max_bounces`` caps the path so a white (rho = 1) enclosure ends. Bookkeeping per
        RGB channel: emitted = absorbed + escaped + capped in expectation, where absorbed
        adds (1 - rho_d - rho_s) x the power of every hit.
    ``build_caustic_map(scene, accel, emitted_count, ...)``  the caustic map (Jensen 1996):
        photons traced with ``trace_photons(caustic=True)`` (light -> specular+ -> diffuse
        paths only), in independently emitted chunks; ``specular_share`` (a pilot of
        ``CAUSTIC_PILOT`` photons) measures the share of the lights' photons whose first hit
        is specular, which ``caustic_emission_count`` turns into the count emitted for
        ``auto_caustic_stored`` (2 per pixel, 50k-1M) to reach specular surfaces; the sun's
        and the world's photons are aimed at the specular surfaces' bounding sphere
        (``specular_bounds``); the estimate's radius cap is 4 x the median k-nearest radius
        at its own photons.
    ``PhotonMap``  compact float32/float16 arrays (36 bytes a photon), a kd-tree from a
        library (pykdtree or scipy's cKDTree, whichever is faster here), and the radiance
        estimate of Eq. 9.11 with the seed's filters: photons arriving from below the surface
        are rejected and only photons in the disc of Fig. 9.5 count; the radius is capped.
        Where the disc runs past its surface's edge (a wall rising from a floor, a box's
        rim), the estimate divides by the part of pi r^2 that the surface covers
        (``coverage``, ``Accelerator.disc_coverage``): Fig. 9.5's disc assumes a surface
        that goes on, and counted the rest as unlit (the boundary bias of kernel density
        estimation): about 1 % over a closed box, 2-3 % of the indirect light in
        a room's corners. There, where another surface took more than a quarter of the k
        nearest, the estimate asks for ``REQUERY_FACTOR`` x k and its radius is the k-th
        photon that counts (otherwise the few left, scaled up by the coverage, are noisy).
        The precomputed estimates that gather rays read use both.

Parameters and units
    Photon power is radiant flux [W] per RGB channel. ``k`` (default 50) photons per
    estimate; ``max_radius`` [m] (default 5 % of the scene's extent); ``disc_thickness``
    (default 0.25): photons farther from the tangent plane than this fraction of the search
    radius are outside the disc. Irradiance estimate E = sum(Phi_p) / (c pi r^2) [W/m^2],
    c the disc's covered share (1 without ``coverage``); reflected radiance = rho_d / pi * E.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import sampling
from .accel import offset_distance
from .lights import (ENV_CDF_SHARE, LUMINANCE, TEXTURED_EMITTER_FLOOR, PortalSet, emitter_parts,
                     sphere_emission_origins, spot_mask)
from .npzjson import pack_json, unpack_json
from .scene import MAX_COORDINATE, MAX_VALUE, AreaLight, PointLight, Scene, SpotLight, SunLight
from .bsdf import MaterialTable, sample_glossy
from .surfaces import SceneSurfaces
from .textures import DIFFUSE_RAY

EXTERIOR_SHARE = 0.25     # with portals: the world's photons from its disc, outside them
EMIT_BATCH = 1 << 16      # sky and emissive-mesh photons drawn per batch
# Sub-triangles (about; at least its triangles) that a mesh with a textured emission sends
# photons from, each picked by its mean exitance (``mesh_parts``): photons then leave a panel's
# bright spots in proportion to their power, each carrying about the same power, instead of
# uniformly with powers as uneven as the texture (a photon map as noisy as their spread).
PHOTON_EMITTER_TRIANGLES = 4096


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """10-bit integers (uint32) -> their bits at every third position (30 bits)."""
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


def column_bounds(points: np.ndarray):
    """(min, max) per column of (N, 3) points; a column at a time (numpy's axis-0 reduction
    over a last axis of 3 is ten times slower)."""
    lo = np.array([points[:, c].min() for c in range(3)], points.dtype)
    hi = np.array([points[:, c].max() for c in range(3)], points.dtype)
    return lo, hi


def morton_order(points: np.ndarray, lo=None, hi=None) -> np.ndarray:
    """Permutation that sorts ``points`` (N, 3) along a Z-order (Morton) curve of 1024^3
    cells over [lo, hi]. Photons stored in this order and queries asked in this order touch
    memory that is close together: measured here 175k against 30k k=50 queries a second. The
    sort is stable: photons sharing a cell keep their traced order, so the map (and the sums of
    every estimate) are the same under numpy 1.26 and numpy 2, whose default sorts break such
    ties differently (Blender 5.2 against 5.0 differed by 4.5 % in a 4 x 4 block of noise)."""
    p = np.asarray(points, np.float32)
    if len(p) == 0:
        return np.zeros(0, np.int64)
    if lo is None or hi is None:
        lo, hi = column_bounds(p)
    lo, hi = np.asarray(lo, np.float32), np.asarray(hi, np.float32)
    scale = np.float32(1023.0) / np.maximum(hi - lo, np.float32(1e-30))
    cells = np.clip((p - lo) * scale, 0, 1023).astype(np.uint32)
    code = _spread_bits(cells[:, 0])
    code |= _spread_bits(cells[:, 1]) << 1
    code |= _spread_bits(cells[:, 2]) << 2
    return np.argsort(code, kind="stable")     # ties in a cell keep their order, whatever numpy


@dataclass
class EmittedPhotons:
    origins: np.ndarray        # (N, 3) float64 [m]
    directions: np.ndarray     # (N, 3) float64 unit
    power: np.ndarray          # (N, 3) float64 [W]
    per_light: dict = field(default_factory=dict)   # name -> photon count
    # Soft Falloff lights: per photon the light's centre (N, 3) and R^2 (N,) (0: no dimming);
    # None when no photon comes from one.
    falloff_center: np.ndarray | None = None
    falloff_r2: np.ndarray | None = None

    def subset(self, a: int, b: int) -> "EmittedPhotons":
        """Photons a..b (a chunk)."""
        cut = (lambda v: None if v is None else v[a:b])
        return EmittedPhotons(self.origins[a:b], self.directions[a:b], self.power[a:b],
                              falloff_center=cut(self.falloff_center),
                              falloff_r2=cut(self.falloff_r2))


def _cosine_directions(normals, u):
    t, b = sampling.orthonormal_basis(normals)
    return sampling.to_world(sampling.square_to_cosine_hemisphere(u), t, b, normals)


def mesh_parts(scene, materials, emissive: np.ndarray, sides: np.ndarray):
    """The parts that a mesh with a textured emission sends its photons from: the emitting
    triangles ``emissive`` (ascending scene indices, with their ``sides``, 1 or 2) cut into
    about ``PHOTON_EMITTER_TRIANGLES`` sub-triangles (``lights.emitter_parts``), each picked
    by its area x sides x its mean exitance's luminance (floored at
    ``TEXTURED_EMITTER_FLOOR`` of the brightest's): (scene triangle (S,), the part's corners'
    barycentrics in it (S, 3, 2), the luminance each is picked by (S,), pick weights (S,))."""
    corners, parents, bary, radiance = emitter_parts(scene, materials, emissive,
                                                     PHOTON_EMITTER_TRIANGLES)
    luminance = np.pi * radiance @ LUMINANCE                  # mean exitance's luminance
    luminance = np.maximum(luminance, TEXTURED_EMITTER_FLOOR * max(float(luminance.max()), 0.0))
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    areas = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    part_sides = np.asarray(sides, np.float64)[np.searchsorted(emissive, parents)]
    return parents, bary, luminance, areas * part_sides * luminance


def emissive_meshes(scene: Scene, materials: MaterialTable | None = None) -> list:
    """``_light_fluxes``' entry for the scene's emissive triangles, in a list (empty when
    none emits): ("emissive meshes", RGB flux [W], ("mesh", triangles, pick weights,
    material ids, ``mesh_parts`` or None, the MaterialTable)). ``materials``: the scene's
    ``MaterialTable`` when the caller has one."""
    if not len(scene.triangles):
        return []
    materials = MaterialTable(scene) if materials is None else materials
    emissive = np.nonzero(materials.is_emissive[scene.material_ids])[0]
    if not len(emissive):
        return []
    areas = scene.triangle_areas()[emissive]
    mids = scene.material_ids[emissive]
    surface = materials.at(mids)
    sides = np.where(surface.both_sides, 2.0, 1.0)
    flux = (surface.exitance * (areas * sides)[:, None]).sum(0)
    # Triangles are picked by their flux's luminance, each photon then carries the exitance
    # at its own point. With a textured emission, by parts (``mesh_parts``).
    picks = areas * sides * (surface.exitance @ LUMINANCE)
    parts = (mesh_parts(scene, materials, emissive, sides)
             if materials.textured_emission[mids].any() else None)
    return [("emissive meshes", flux, ("mesh", emissive, picks, mids, parts, materials))]


def _light_fluxes(scene: Scene, target=None, meshes: list | None = None):
    """(name, RGB flux [W], emitter) for every light that emits photons. ``target``: a sphere
    (center, radius [m]) inside the scene that the sun's and the world's photons are aimed
    at (a disc of its radius across their direction, starting outside the scene), instead of
    the scene's bounding sphere: their flux is then that through the sphere's disc.
    ``meshes``: ``emissive_meshes(scene)`` when the caller has it (a render's photon passes
    share one: its textured parts cost 35 ms, its MaterialTable 22 ms on the textured room)."""
    out = []
    lo, hi = scene.bounds()
    center, radius = (lo + hi) / 2, max(np.linalg.norm(hi - lo) / 2, 1e-9)
    back = 2 * radius              # how far back from the disc's centre photons start
    if target is not None:
        back = float(np.linalg.norm(target[0] - center)) + 2 * radius
        center, radius = np.asarray(target[0], float), float(target[1])
    for light in scene.lights:
        if isinstance(light, PointLight):
            out.append((light.name, light.flux, ("point", light)))
        elif isinstance(light, SpotLight):
            # Flux inside the cone: Phi / (4 pi) * integral of the mask over the cone.
            cos_half = np.cos(light.half_angle)
            mu = np.linspace(cos_half, 1.0, 2049)
            mask = spot_mask(mu, cos_half, light.blend)
            # The trapezoid rule written out: numpy 2 (Blender 5.1+) has no np.trapz, and
            # np.trapezoid is not in numpy 1.26 (Blender 4.2-5.0); the same sums as trapz.
            solid = 2 * np.pi * (np.diff(mu) * (mask[1:] + mask[:-1]) / 2.0).sum()
            out.append((light.name, light.flux / (4 * np.pi) * solid, ("spot", light)))
        elif isinstance(light, SunLight):
            out.append((light.name, light.irradiance * np.pi * radius ** 2,
                        ("sun", light, center, radius, back)))
        elif isinstance(light, AreaLight):
            out.append((light.name, light.power, ("area", light)))
    out += emissive_meshes(scene) if meshes is None else meshes
    world = scene.world
    if not world.is_black:
        total = (world.environment.integral() if world.environment is not None
                 else world.radiance * 4 * np.pi)
        disc_flux = total * np.pi * radius ** 2
        if world.portals:
            # Through the portals: the flux crossing them, A int L(w) cos dw per portal.
            portals = PortalSet(world.portals)
            cos_weighted = _cosine_weighted_radiance(world, portals)
            flux = (portals.areas[:, None] * cos_weighted).sum(axis=0)
            out.append(("World", flux, ("portal", world, portals)))
            # Outside them: the disc's photons whose first segment does not enter a portal
            # (the sky's light on the window's outer reveal, the ground seen through it);
            # ``EXTERIOR_SHARE`` of the world's photons whatever their flux.
            out.append(("World outside the portals", disc_flux,
                        ("world", center, radius, portals, float(flux @ LUMINANCE), back)))
        else:
            out.append(("World", disc_flux, ("world", center, radius, None, 0.0, back)))
    return out


def _photon_lights(scene: Scene, target=None, meshes: list | None = None) -> list:
    """``_light_fluxes`` of the lights that send photons: some flux, a photon share above 0."""
    return [entry for entry in _light_fluxes(scene, target, meshes) if np.any(entry[1] > 0)
            and getattr(entry[2][1], "photon_share", 1.0) > 0]


def _cosine_weighted_radiance(world, portals) -> np.ndarray:
    """(P, 3): for each portal, the radiance entering it integrated against the cosine with
    its normal over its outer hemisphere [W/m^2] (a 64 x 128 midpoint grid in (cos, phi))."""
    mu = (np.arange(64) + 0.5) / 64
    phi = 2 * np.pi * (np.arange(128) + 0.5) / 128
    mm, pp = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - mm ** 2)
    local = np.stack([s * np.cos(pp), s * np.sin(pp), mm], -1).reshape(-1, 3)
    out = []
    for k in range(len(portals)):
        n = portals.normals[k][None]
        t, b = sampling.orthonormal_basis(n)
        travel = local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * n
        radiance = world.radiance_towards(-travel)        # seen from inside, looking out
        out.append((radiance * mm.reshape(-1, 1)).sum(axis=0) * (2 * np.pi / mm.size))
    return np.array(out).reshape(-1, 3)


def _in_batches(batch, n: int, pool=None) -> None:
    """``batch(start)`` for the first rows of ``n`` rows' batches of ``EMIT_BATCH`` (each
    batch fills its own rows), on ``pool``'s threads where one is given and there are two
    batches or more."""
    starts = range(0, n, EMIT_BATCH)
    if pool is None or len(starts) < 2:
        for start in starts:
            batch(start)
    else:
        list(pool.map(batch, starts))


def _disc_photons(world, center, radius, back, u, v, n, pool=None):
    """Photons of the world from its disc of ``radius`` [m] facing ``center``, ``back`` [m]
    behind it along each direction: origins and directions of travel (n, 3) and, for an image
    world, powers per unit disc area x n [W/m^2] (n, 3) (else None): sky directions from its
    CDF (``environment.Environment.sample``), power L / p (pbrt-v3
    ``InfiniteAreaLight::Sample_Le``); a constant world's uniform over the sphere. In batches
    of ``EMIT_BATCH``: a million photons' temporaries at once cost more in fresh memory pages
    than in arithmetic (the yard's million sky directions: 1.2 s at once, 0.5 s in batches),
    on ``pool``'s threads where one is given (each batch fills its own rows)."""
    origins, travel = np.empty((n, 3)), np.empty((n, 3))
    power = None if world.environment is None else np.empty((n, 3))

    def batch(start):
        part = slice(start, start + EMIT_BATCH)
        if world.environment is not None:
            wi, radiance, pdf = world.environment.sample(u[part])
            ok = pdf > 0
            d = -wi
            power[part] = np.where(ok[:, None], radiance / np.where(ok, pdf, 1.0)[:, None], 0.0)
        else:
            d = -sampling.square_to_sphere(u[part])           # travelling inwards
        t, b = sampling.orthonormal_basis(d)
        disk = sampling.square_to_disk(v[part]) * radius
        origins[part] = center - d * back + disk[:, 0:1] * t + disk[:, 1:2] * b
        travel[part] = d

    _in_batches(batch, n, pool)
    return origins, travel, power


def emit_photons(scene: Scene, count: int, rng: np.random.Generator,
                 accel=None, target=None, pool=None, meshes: list | None = None) -> EmittedPhotons:
    """``count`` photons shared among the lights in proportion to their flux. ``accel``:
    the scene's ``Accelerator``, which photons through light portals need (a photon whose
    way out to the sky is blocked carries nothing). ``target``: the sphere the sun's and the
    world's photons are aimed at (``_light_fluxes``; the caustic map's
    ``specular_bounds``). ``pool``: threads that draw the world's disc photons in batches
    (the same photons without). ``meshes``: ``emissive_meshes(scene)``, when the caller
    has it."""
    lights = _photon_lights(scene, target, meshes)
    if not lights or count <= 0:
        z = np.zeros((0, 3))
        return EmittedPhotons(z, z.copy(), z.copy())
    # Photons per light: in proportion to its flux (luminance) times its photon share; each
    # photon carries flux / (its light's count), so the share moves noise, not energy.
    lum = np.array([max(float(flux @ LUMINANCE), 1e-30) * getattr(spec[1], "photon_share", 1.0)
                    for _, flux, spec in lights])
    for i, (_, _, spec) in enumerate(lights):
        if spec[0] == "world" and spec[3] is not None:     # photons outside the portals
            lum[i] = spec[4] * EXTERIOR_SHARE / (1.0 - EXTERIOR_SHARE)
    # Largest remainders (Hamilton): the floors, then one more each for the largest fractions
    # until the counts add up to ``count`` (a light alone gets all of them, not 999 of 1000
    # where count x lum / lum rounds to 999.99999); at least one each.
    exact = count * lum / lum.sum()
    share = np.floor(exact).astype(int)
    left = int(min(max(count - share.sum(), 0), len(share)))
    share[np.argsort(share - exact, kind="stable")[:left]] += 1
    share = np.maximum(share, 1)
    origins, directions, powers, per_light = [], [], [], {}
    centers, r2s = [], []
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
            light, center, radius, back = spec[1], spec[2], spec[3], spec[4]
            t, b = sampling.orthonormal_basis(light.direction[None])
            disk = sampling.square_to_disk(u) * radius
            o = center - light.direction * back + disk[:, 0:1] * t + disk[:, 1:2] * b
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
            o, d, power = _mesh_photons(scene, spec[5], spec[1], spec[2], flux, u, v,
                                        rng.random(n), pool, parts=spec[4])
        elif kind == "world":
            center, radius = spec[1], spec[2]
            o, d, per_area = _disc_photons(scene.world, center, radius, spec[5], u, v, n, pool)
            if per_area is not None:
                # Directions from the image's CDF, power L / p over the disc's area.
                power = per_area * (np.pi * radius ** 2 / n)
            if spec[3] is not None:
                # Outside the portals: those entering one first are the portal photons'.
                keep = np.flatnonzero(~_enters_portal(o, d, spec[3], accel)
                                      & (power.max(axis=1) > 0))
                o, d, power, n = o[keep], d[keep], power[keep], len(keep)
        else:  # the world through its portals
            o, d, power = _portal_photons(scene, spec[1], spec[2], u, v, n, accel)
            keep = np.flatnonzero(power.max(axis=1) > 0)      # those that saw the sky
            o, d, power, n = o[keep], d[keep], power[keep], len(keep)
        soft = kind in ("point", "spot") and spec[1].radius > 0 and \
            getattr(spec[1], "soft_falloff", False)
        centers.append(np.broadcast_to(spec[1].position if soft else np.zeros(3), (n, 3)))
        r2s.append(np.full(n, spec[1].radius ** 2 if soft else 0.0))
        if kind in ("point", "spot") and spec[1].radius > 0:   # a sphere light (lights.py)
            o = sphere_emission_origins(spec[1].position, spec[1].radius, d, v)
        if kind in ("point", "spot", "area"):
            # Start an offset away from the light, as shadow rays stop short of it: a light
            # touching or lying in a surface (a panel flush with the ceiling) sends its photons
            # into the room instead of onto that surface's far side at t = 0.
            away = normal if kind == "area" else d
            o = o + away * offset_distance(o, scene.extent)[:, None]
        origins.append(o); directions.append(d); powers.append(power)
        per_light[name] = int(n)
    r2 = _joined(r2s)
    soft = bool(np.any(r2 > 0))
    return EmittedPhotons(_joined(origins), _joined(directions), _joined(powers), per_light,
                          falloff_center=_joined(centers) if soft else None,
                          falloff_r2=r2 if soft else None)


def _mesh_photons(scene, table, tri_idx, weights, flux, u, v, flip, pool=None, parts=None):
    """Photons of the emissive meshes: origins, directions of travel and powers (n, 3) for
    the stratified points ``u`` (n, 2), direction numbers ``v`` (n, 2) and side numbers
    ``flip`` (n,), their materials read through ``table`` (``_light_fluxes``' own). A triangle of ``tri_idx`` is picked by its ``weights`` (area x sides x the
    luminance of its material's mean exitance), an area-uniform point on it, a cosine
    direction about its normal (either side of a two-sided emitter, ``flip`` < 1/2 the back);
    each photon carries the exitance at its own point over the luminance its triangle was
    picked by, scaled to the meshes' ``flux`` [W]. In batches of ``EMIT_BATCH`` on ``pool``'s
    threads where one is given (each batch fills its own rows): the textured room's million
    panel photons took 0.9-1.6 s at once, their texture's temporaries in fresh memory pages
    (0.5 s untextured). ``parts`` (``mesh_parts``, for meshes with a textured emission): the
    sub-triangles are picked instead, by their own weights, and each photon carries the
    exitance at its point over the luminance its part was picked by, times the parts' summed
    weight (the same estimate of the flux, unbiased whatever the parts' luminances)."""
    n = len(u)
    origins, travel, power = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    if parts is not None:
        tri_idx, corner_bary, part_luminance, weights = parts
    cdf = np.cumsum(weights)

    def batch(start):
        part = slice(start, start + EMIT_BATCH)
        uu = u[part]
        pick = np.minimum(np.searchsorted(cdf, uu[:, 0] * cdf[-1], side="right"), len(cdf) - 1)
        lower = np.where(pick > 0, cdf[np.maximum(pick - 1, 0)], 0.0)
        u0 = np.clip((uu[:, 0] * cdf[-1] - lower) / weights[pick], 0.0, 1.0 - 1e-12)
        bary = sampling.square_to_triangle(np.stack([u0, uu[:, 1]], 1))
        prim = tri_idx[pick]
        tri = scene.triangles[prim].astype(np.float64)
        if parts is not None:                 # the point in its part, then in its triangle
            a, b = bary[:, 0:1], bary[:, 1:2]
            c = corner_bary[pick]
            bary = c[:, 0] * (1 - a - b) + c[:, 1] * a + c[:, 2] * b
        o = tri[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + tri[:, 1] * bary[:, 0:1] + tri[:, 2] * bary[:, 1:2]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        materials = scene.material_ids[prim]
        surface = table.at(materials, prim, bary[:, 0], bary[:, 1])
        nrm[surface.both_sides & (flip[part] < 0.5)] *= -1
        travel[part] = _cosine_directions(nrm, v[part])
        # Leave the emitting surface (it is geometry too), as accel.offset_origins does.
        origins[part] = o + nrm * offset_distance(o, scene.extent)[:, None]
        if parts is not None:
            power[part] = surface.exitance / part_luminance[pick][:, None] * cdf[-1] / n
            return
        picked = table.exitance[materials] @ LUMINANCE
        power[part] = surface.exitance / np.maximum(picked[:, None], 1e-30) * (flux @ LUMINANCE) / n

    _in_batches(batch, n, pool)
    return origins, travel, power


def _joined(parts: list) -> np.ndarray:
    """The lights' arrays one after another (a lone light's as it is, not copied)."""
    return np.concatenate(parts) if len(parts) != 1 else np.ascontiguousarray(parts[0])


def _portal_photons(scene, world, portals, u, v, n, accel):
    """Photons of the world entering through light portals: a portal by area, an
    area-uniform point on it, a direction into the room from the mixture of the image's CDF
    (``ENV_CDF_SHARE``; none for a constant world) and cosine about its normal; power
    L(w) cos A / (p n). A photon whose ray back out to the sky meets geometry (``accel``)
    carries nothing. Returns origins, directions of travel and powers (n, 3)."""
    cdf = np.cumsum(portals.areas) / portals.areas.sum()
    k = np.minimum(np.searchsorted(cdf, u[:, 0], side="right"), len(portals) - 1)
    lower = np.where(k > 0, cdf[np.maximum(k - 1, 0)], 0.0)
    u0 = np.clip((u[:, 0] - lower) / (cdf[k] - lower), 0.0, 1.0 - 1e-12)
    points = portals.sample_points(k, np.stack([u0, u[:, 1]], 1))
    normal = portals.normals[k]
    share = ENV_CDF_SHARE if world.environment is not None else 0.0
    from_cdf = v[:, 0] < share
    travel = np.empty((n, 3))
    if from_cdf.any():
        uu = np.stack([v[from_cdf, 0] / share, v[from_cdf, 1]], 1)
        travel[from_cdf] = -world.environment.sample(np.clip(uu, 0.0, 1.0 - 1e-12))[0]
    rest = ~from_cdf
    if rest.any():
        uu = np.stack([np.clip((v[rest, 0] - share) / (1.0 - share), 0.0, 1.0 - 1e-12),
                       v[rest, 1]], 1)
        travel[rest] = _cosine_directions(np.ascontiguousarray(normal[rest]), uu)
    cos = np.einsum("ij,ij->i", travel, normal)
    pdf = (1.0 - share) * np.maximum(cos, 0.0) / np.pi
    if world.environment is not None:
        pdf = pdf + share * world.environment.direction_pdf(-travel)
    ok = (cos > 0) & (pdf > 0)
    radiance = np.zeros((n, 3))
    if ok.any():
        radiance[ok] = world.radiance_towards(-travel[ok])
    power = radiance * np.where(ok, cos * portals.areas.sum() / np.where(ok, pdf, 1.0) / n,
                                0.0)[:, None]
    eps = offset_distance(points, scene.extent)[:, None]
    if accel is not None and ok.any():
        # The way out: from the portal towards the sky; blocked photons carry nothing.
        idx = np.flatnonzero(ok)
        start = np.ascontiguousarray(points[idx] - travel[idx] * eps[idx], np.float32)
        blocked = accel.occluded(start, np.ascontiguousarray(-travel[idx], np.float32),
                                 np.full(len(idx), 1e37, np.float32))
        power[idx[blocked]] = 0.0
    return points + travel * eps, travel, power


def _enters_portal(origins, directions, portals, accel) -> np.ndarray:
    """(N,) whether each ray (from outside the scene) crosses a portal from its outer side
    before it meets geometry (``accel``; without one, any crossing counts)."""
    best = np.full(len(origins), np.inf)
    for k in range(len(portals)):
        c, nrm = portals.centers[k], portals.normals[k]
        denom = directions @ nrm
        inward = denom > 1e-12
        t = np.where(inward, ((c - origins) @ nrm) / np.where(inward, denom, 1.0), np.inf)
        q = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions - c
        su = q @ portals.du[k] / (portals.du[k] @ portals.du[k])
        sv = q @ portals.dv[k] / (portals.dv[k] @ portals.dv[k])
        inside = (su * su + sv * sv <= 1.0) if portals.round[k] else \
            ((np.abs(su) <= 1.0) & (np.abs(sv) <= 1.0))
        best = np.where(inward & inside & (t > 0) & (t < best), t, best)
    crossing = np.isfinite(best)
    if accel is None or not crossing.any():
        return crossing
    idx = np.flatnonzero(crossing)
    blocked = accel.occluded(np.ascontiguousarray(origins[idx], np.float32),
                             np.ascontiguousarray(directions[idx], np.float32),
                             np.ascontiguousarray(best[idx] * (1 - 1e-6), np.float32))
    crossing[idx[blocked]] = False
    return crossing


ESTIMATE_CHUNK = 8192           # queries per kd-tree call in PhotonMap.irradiance
# With a disc coverage: an estimate that kept fewer than KEPT_SHARE of its k - 1 photons (the
# rest lay on another surface) asks for REQUERY_FACTOR x k neighbours and takes its radius
# at the k-th that counts.
KEPT_SHARE = 0.75
REQUERY_FACTOR = 4


@dataclass
class PhotonMap:
    """Stored photons: 36 bytes each (float32 position and power, float16 directions, a byte
    of bounces), and a kd-tree over their positions."""

    positions: np.ndarray       # (P, 3) float32 [m]
    power: np.ndarray           # (P, 3) float32 [W]
    incoming: np.ndarray        # (P, 3) float16, the direction the photon travelled
    normals: np.ndarray         # (P, 3) float16, surface normal on the side it arrived
    bounces: np.ndarray         # (P,) uint8 diffuse/specular bounces before it was stored
    stats: dict = field(default_factory=dict)
    library: str = "pykdtree"
    _tree: object = None
    _directions: np.ndarray | None = None    # (P, 6) float16: incoming | normal, for look-ups
    lo: np.ndarray | None = None             # bounds of the positions (Morton order)
    hi: np.ndarray | None = None

    def __len__(self):
        return len(self.positions)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.positions, self.power, self.incoming, self.normals,
                                      self.bounces))

    def subset(self, keep: np.ndarray) -> "PhotonMap":
        """A new (unbuilt) map of the photons where ``keep`` is true; stats are copied."""
        return PhotonMap(self.positions[keep], self.power[keep], self.incoming[keep],
                         self.normals[keep], self.bounces[keep], dict(self.stats), self.library)

    def build(self, library: str = "pykdtree", reorder: bool = True):
        """Build the kd-tree (``pykdtree``, default, or ``scipy``: scipy's cKDTree). Measured
        here at 1M photons: pykdtree builds in 0.20 s against cKDTree's 0.66 s and answers
        k = 50 queries as fast (63k/s against 65k/s on 2 cores), so pykdtree is the default.
        ``reorder`` False keeps the photons' order (a map saved after its build is already in
        Morton order; ``from_arrays`` rebuilds it bit for bit)."""
        from concurrent.futures import ThreadPoolExecutor

        t0 = time.perf_counter()
        if library == "pykdtree":
            from pykdtree.kdtree import KDTree
            make_tree = lambda x: KDTree(np.ascontiguousarray(x, np.float32), leafsize=16)
        elif library == "scipy":
            from scipy.spatial import cKDTree
            make_tree = lambda x: cKDTree(x, leafsize=16)
        else:
            raise ValueError(f"unknown kd-tree library {library!r} (pykdtree or scipy)")
        self.library = library
        if len(self):
            # Store the photons in Morton order: neighbours in space are neighbours in memory.
            self.lo, self.hi = column_bounds(self.positions)
        order = morton_order(self.positions, self.lo, self.hi) if len(self) and reorder else None
        if order is not None:
            self.positions = np.take(self.positions, order, axis=0)
        # The tree needs only the positions: it builds on a helper thread (pykdtree releases
        # the GIL) while this one reorders the other columns (4.4M photons: 1.15 s against
        # 1.4-1.7 s one after the other, measured here).
        with ThreadPoolExecutor(1) as helper:
            tree = helper.submit(make_tree, self.positions) if len(self) else None
            if order is not None:
                for key in ("power", "incoming", "normals", "bounces"):
                    setattr(self, key, np.take(getattr(self, key), order, axis=0))
            self._directions = np.ascontiguousarray(
                np.concatenate([self.incoming, self.normals], axis=1))
            self._tree = tree.result() if tree is not None else None
        self.stats["build_seconds"] = time.perf_counter() - t0
        self.stats["library"] = library
        return self

    # Persistence (engine/artifacts.py) ----------------------------------------------------
    ARRAY_FIELDS = ("positions", "power", "incoming", "normals", "bounces")
    #: What a saved map must hold (``engine/archive.py``): P photons.
    SCHEMA = {"positions": (("<f4",), ("P", 3)), "power": (("<f4",), ("P", 3)),
              "incoming": (("<f2",), ("P", 3)), "normals": (("<f2",), ("P", 3)),
              "bounces": (("|u1",), ("P",)), "stats": (("U",), ()),
              "library": (("U",), ()), "built": (("|b1",), ())}

    @staticmethod
    def value_problems(arrays) -> list[str]:
        """What is wrong with a saved map's values (the shapes passed ``SCHEMA``): positions
        finite within ``MAX_COORDINATE``, power finite in [0, ``MAX_VALUE``] W, directions
        unit vectors (to float16's precision), a known kd-tree library."""
        out = []
        positions = arrays["positions"]
        if not (np.isfinite(positions).all() and np.abs(positions).max(initial=0) <= MAX_COORDINATE):
            out.append("photon positions are not finite or lie beyond "
                       f"{MAX_COORDINATE:g} m")
        power = arrays["power"]
        if not np.isfinite(power).all():
            out.append("photon power is not finite (NaN or inf)")
        elif power.size and not (power.min() >= 0 and power.max() <= MAX_VALUE):
            out.append(f"photon power lies outside [0, {MAX_VALUE:g}] W "
                       f"({power.min():g} to {power.max():g})")
        for key in ("incoming", "normals"):
            v = arrays[key].astype(np.float32)
            length = np.sqrt(np.einsum("ij,ij->i", v, v))
            if not (np.isfinite(length).all() and np.all(np.abs(length - 1) <= 0.01)):
                out.append(f"photon {key} are not unit vectors")
        if str(arrays["library"]) not in ("pykdtree", "scipy"):
            out.append(f"unknown kd-tree library {str(arrays['library'])!r}")
        return out

    def to_arrays(self) -> dict:
        """The map as named numpy arrays (no Python objects: ``np.load(allow_pickle=False)``
        reads them back): the five photon arrays with their dtypes, ``stats`` as JSON, the
        kd-tree library and whether the photons are in built (Morton) order."""
        out = {key: np.ascontiguousarray(getattr(self, key)) for key in self.ARRAY_FIELDS}
        out["stats"] = pack_json(self.stats)
        out["library"] = np.array(str(self.library))
        out["built"] = np.array(self._tree is not None or len(self) == 0)
        return out

    @classmethod
    def from_arrays(cls, arrays, build: bool = True) -> "PhotonMap":
        """The inverse of ``to_arrays``; ``build`` makes the kd-tree, keeping the saved order
        when the map was saved built (the same map, photon for photon)."""
        pmap = cls(*(np.asarray(arrays[key]) for key in cls.ARRAY_FIELDS))
        pmap.stats = unpack_json(arrays["stats"])
        pmap.library = str(arrays["library"])
        if build:
            pmap.build(pmap.library, reorder=not bool(arrays["built"]))
        return pmap

    def query(self, points: np.ndarray, k: int, max_radius: float = np.inf):
        """Distances (N, k) float32 and indices (N, k) of the k nearest photons within
        ``max_radius`` (k clipped to the map's size). Missing neighbours: distance inf and
        index ``len(self)``."""
        k = int(min(k, len(self)))
        bound = None if not np.isfinite(max_radius) else float(max_radius)
        if self.library == "pykdtree":
            dist, idx = self._tree.query(np.ascontiguousarray(points, np.float32), k=k,
                                         distance_upper_bound=bound)
            idx = idx.astype(np.int64)
        else:
            dist, idx = self._tree.query(points, k=k, workers=-1,
                                         distance_upper_bound=np.inf if bound is None else bound)
        dist = np.asarray(dist, np.float32).reshape(len(points), k)
        idx = idx.reshape(len(points), k)
        missing = ~np.isfinite(dist)
        if missing.any():
            idx[missing] = len(self)
        return dist, idx

    def irradiance(self, points, normals, k=50, max_radius=np.inf, disc_thickness=0.25,
                   min_bounces=0, cone_filter: float | None = None, stats: dict | None = None,
                   coverage=None):
        """Irradiance estimate E (N, 3) [W/m^2] at ``points`` on the side ``normals`` face.

        Eq. 9.11 over the k nearest photons within ``max_radius``: photons that arrived from
        below the surface, whose surface faces the other way, or that lie farther than
        ``disc_thickness`` x radius from the tangent plane (Fig. 9.5) are left out; the
        radius r is the k-th distance (that photon itself is not counted: (k - 1) / (pi r^2)
        is the unbiased k-nearest-neighbour density), or ``max_radius`` when fewer photons
        lie within it (all of them count).
        ``min_bounces`` = 1 keeps only photons that bounced at least once (indirect light).
        ``cone_filter`` = k_c (Jensen 1996, k_c >= 1, typically 1.1) weights each photon by
        1 - d / (k_c r) and normalises by 1 - 2 / (3 k_c): sharper edges, a little more noise.
        ``stats`` (a dict) receives ``queries`` and ``query_seconds``.
        ``coverage``: a function (points (n, 3), normals (n, 3), radii (n,)) -> the share of
        each disc that its surface covers (``Accelerator.disc_coverage``); the estimate then
        divides by that part of pi r^2, not all of it. Without it a disc cut by an edge or a
        corner counts the missing part as unlit: 1-3 % too dark along a room's edges, about
        1 % over a closed box (``tests/test_analytic_modes.py``).
        """
        e = np.zeros((len(points), 3))
        if self._tree is None or len(points) == 0:
            return e
        # Ask in Morton order (coherent tree walks and gathers), in chunks that bound memory.
        order = morton_order(points, self.lo, self.hi)
        points32 = np.ascontiguousarray(points, np.float32)[order]
        normals32 = np.ascontiguousarray(normals, np.float32)[order]
        out = np.empty((len(points), 3))
        for a in range(0, len(points), ESTIMATE_CHUNK):
            b = min(a + ESTIMATE_CHUNK, len(points))
            out[a:b] = self._estimate(points32[a:b], normals32[a:b], k, max_radius,
                                      disc_thickness, min_bounces, cone_filter, stats, coverage)
        e[order] = out
        return e

    def _kept(self, points32, n32, k, max_radius, disc_thickness, min_bounces, stats):
        """The k nearest photons of each point and which of them count (Fig. 9.5's disc):
        (distances (n, k), flat indices (n k,), kept (n, k), full (n,): k were found,
        radius (n,): the k-th distance or ``max_radius``, heights over the plane (n, k))."""
        t0 = time.perf_counter()
        dist, idx = self.query(points32, k, max_radius)
        if stats is not None:
            stats["queries"] = stats.get("queries", 0) + len(points32)
            stats["query_seconds"] = stats.get("query_seconds", 0.0) + time.perf_counter() - t0
        count, k = dist.shape
        full = np.isfinite(dist[:, -1])
        radius = np.where(full, dist[:, -1], np.float32(min(max_radius, 3e38)))
        found = idx < len(self)
        flat = np.where(found, idx, 0).reshape(-1)
        # np.take on flat indices: several times faster than fancy indexing of rows.
        offset = np.take(self.positions, flat, axis=0).reshape(count, k, 3)
        offset -= points32[:, None, :]
        height = np.abs(np.matmul(offset, n32[:, :, None])[..., 0])
        dirs = np.take(self._directions, flat, axis=0).reshape(count, k, 6).astype(np.float32)
        facing = np.matmul(dirs.reshape(count, 2 * k, 3), n32[:, :, None]).reshape(count, k, 2)
        keep = found & (facing[..., 0] < 0) & (facing[..., 1] > 0.5)     # arriving, same side
        keep &= height <= disc_thickness * radius[:, None]
        if min_bounces:
            keep &= np.take(self.bounces, flat).reshape(count, k) >= min_bounces
        return dist, flat, keep, full, radius, height

    def _estimate(self, points32, n32, k, max_radius, disc_thickness, min_bounces, cone_filter,
                  stats, coverage=None):
        dist, flat, keep, full, radius, _height = self._kept(
            points32, n32, k, max_radius, disc_thickness, min_bounces, stats)
        count, k = dist.shape
        # The k-th photon only marks the radius: leave it out, as (k - 1) / (pi r_k^2) is the
        # unbiased density of k-nearest-neighbour estimation (k / (pi r_k^2) is k / (k - 1)
        # too bright: +2 % at k = 50, measured on a sphere lit from its centre).
        keep[:, -1] &= ~full
        weight = keep.astype(np.float32)
        if cone_filter:
            kc = float(cone_filter)
            weight *= np.maximum(0.0, 1.0 - dist / (kc * radius[:, None]))
            norm = 1.0 - 2.0 / (3.0 * kc)
        else:
            norm = 1.0
        power = np.take(self.power, flat, axis=0).reshape(count, k, 3)
        flux = np.matmul(weight[:, None, :], power)[:, 0].astype(np.float64)
        radius = radius.astype(np.float64)
        if coverage is not None and not cone_filter:
            # Where another surface took many of the k (a wall by a floor's edge), the few
            # left would make a noisy estimate, and dividing by the covered share only
            # scales that noise up: ask for more neighbours and let the k-th photon that
            # counts mark the radius.
            short = np.flatnonzero(full & (keep.sum(axis=1) < KEPT_SHARE * (k - 1)))
            if len(short):
                flux[short], radius[short] = self._kept_k(points32[short], n32[short], k,
                                                          max_radius, disc_thickness,
                                                          min_bounces, stats)
        area = norm * np.pi * radius ** 2
        if coverage is not None:
            area *= coverage(points32, n32, radius)
        ok = np.isfinite(area) & (area > 0)
        flux[~ok] = 0.0
        flux[ok] /= area[ok, None]
        return flux

    def _kept_k(self, points32, n32, k, max_radius, disc_thickness, min_bounces, stats):
        """(flux (n, 3) [W], radius (n,)) of the estimate whose radius is the k-th photon
        that counts among the ``REQUERY_FACTOR`` k nearest (that one left out, as in
        ``_estimate``); where fewer count, all of them within the farthest found."""
        dist, flat, keep, full, radius, height = self._kept(
            points32, n32, REQUERY_FACTOR * k, max_radius, disc_thickness, min_bounces, stats)
        count, wide = dist.shape
        rank = np.cumsum(keep, axis=1)
        enough = rank[:, -1] >= k
        at = np.argmax(rank >= k, axis=1)                       # the k-th photon that counts
        r_k = np.where(enough, dist[np.arange(count), at], radius).astype(np.float64)
        inside = keep & np.where(enough[:, None], np.arange(wide)[None, :] < at[:, None], True)
        inside &= height <= disc_thickness * r_k[:, None].astype(np.float32)
        inside[:, -1] &= enough | ~full
        power = np.take(self.power, flat, axis=0).reshape(count, wide, 3)
        flux = np.matmul(inside.astype(np.float32)[:, None, :], power)[:, 0]
        return flux.astype(np.float64), r_k


def trace_photons(scene: Scene, accel, emitted: EmittedPhotons, rng: np.random.Generator,
                  max_bounces: int = 128, ray_log: list | None = None,
                  surfaces: SceneSurfaces | None = None, caustic: bool = False) -> PhotonMap:
    """Trace emitted photons (Russian roulette, 9.2) and store them at diffuse hits.

    All photons advance together: one Embree call per bounce for every live photon. Geometry
    is float32 (Embree's precision); powers stay float64 until they are stored. A photon that
    survives its ``max_bounces``-th bounce is counted in ``capped_paths`` / ``flux_capped``.
    ``surfaces``: the scene's ``SceneSurfaces`` when the caller has them (the photon pass
    makes them once for all its chunks); a hit's material is read through ``bsdf``.
    ``caustic``: trace light -> specular+ -> diffuse paths only (the caustic map, Jensen
    1996): photons whose first hit is not specular are dropped, the roulette's diffuse picks
    end the path, and photons are stored at diffuse hits after at least one specular
    bounce (the path goes on from there only by a specular pick)."""
    if surfaces is None:
        surfaces = SceneSurfaces(scene)
    normals_geo = surfaces.geometric_normals
    o = np.ascontiguousarray(emitted.origins, np.float32)
    d = np.ascontiguousarray(emitted.directions, np.float32)
    power = emitted.power.copy()
    depth = np.zeros(len(o), np.int32)
    falloff_center, falloff_r2 = emitted.falloff_center, emitted.falloff_r2
    stored = {"positions": [], "power": [], "incoming": [], "normals": [], "bounces": []}
    absorbed = np.zeros(3)
    escaped = np.zeros(3)
    capped = 0
    capped_power = np.zeros(3)
    rays = 0
    while len(o):
        rays += len(o)
        if ray_log is not None:
            ray_log.append(("photon", o, d, None))
        t, prim, bu, bv = accel.intersect(o, d)
        hit = prim >= 0
        if not hit.all():
            escaped += power[~hit].sum(axis=0)
            keep = np.flatnonzero(hit)
            if len(keep) == 0:
                break
            o, d, t, prim, bu, bv = (np.take(a, keep, axis=0) for a in (o, d, t, prim, bu, bv))
            power, depth = np.take(power, keep, axis=0), depth[keep]
            if falloff_r2 is not None:
                falloff_center, falloff_r2 = falloff_center[keep], falloff_r2[keep]
        x = sampling.scale_rows(d, t)
        x += o
        if falloff_r2 is not None:
            # Soft Falloff (Cycles' facing disk): E = pi L R^2 / (d^2 + R^2) at the first hit,
            # the sphere's photons give pi L R^2 / d^2 there: scale by d^2 / (d^2 + R^2).
            dd = np.sum((x.astype(np.float64) - falloff_center) ** 2, axis=1)
            scale = np.where(falloff_r2 > 0, dd / np.maximum(dd + falloff_r2, 1e-300), 1.0)
            absorbed += np.einsum("ij,i->j", power, 1.0 - scale)
            power = power * scale[:, None]
            falloff_center = falloff_r2 = None
        n = np.take(normals_geo, prim, axis=0)
        flip = sampling.dot_rows(n, d) > 0                 # turn n towards the photon
        if flip.any():
            n[flip] *= -1
        surface = surfaces.params(prim, bu, bv, d, ray={**DIFFUSE_RAY, "Ray Length": t})
        if caustic:
            # Caustic paths: the first hit must be specular; diffuse stores need a specular
            # bounce before them.
            if not depth.any():
                first = np.flatnonzero(surface.is_transport_specular)
                if len(first) < len(o):
                    o, d, t, prim, x, n, flip = (np.take(a, first, axis=0)
                                                 for a in (o, d, t, prim, x, n, flip))
                    power, depth = np.take(power, first, axis=0), depth[first]
                    surface = surface.subset(first)
                if len(o) == 0:
                    break
        bsdf = surface.bsdf(transport=True)
        diffuse = surface.is_diffuse                    # photons are stored at diffuse hits
        if caustic:
            diffuse = diffuse & (depth > 0)
        if diffuse.all():
            sel = slice(None)
        else:
            sel = np.flatnonzero(diffuse)
        if not isinstance(sel, np.ndarray) or len(sel):
            stored["positions"].append(x[sel].copy() if isinstance(sel, slice) else x[sel])
            stored["power"].append(power[sel].astype(np.float32))
            stored["incoming"].append(d[sel].astype(np.float16))
            stored["normals"].append(n[sel].astype(np.float16))
            stored["bounces"].append(np.minimum(depth[sel], 255).astype(np.uint8))
        # Russian roulette with the reflectances' largest channels (bsdf.roulette_probabilities).
        p_d, p_s = bsdf.lobe_probabilities()
        xi = rng.random(len(o))
        go_diffuse = xi < p_d
        alive = xi < p_d + p_s
        if caustic:
            alive &= ~go_diffuse                       # a diffuse bounce ends a caustic path
        # Absorbed flux, per channel: the expected share (1 - rho_d - rho_s) of every hit.
        # (The power of the photons roulette kills is no estimate of it per channel: a green
        # floor would "absorb" as much red as green.)
        absorbed += np.einsum("ij,ij->j", power, bsdf.absorption())
        depth += 1
        over = alive & (depth > max_bounces)
        if over.any():
            capped += int(over.sum())
            capped_power += power[over].sum(axis=0)
            alive &= ~over
        live = np.flatnonzero(alive)
        if len(live) == 0:
            break
        x, n, d = (np.take(a, live, axis=0) for a in (x, n, d))
        flip_live = flip[live]                     # hit on the back face (glass: inside)
        power, depth, go_diffuse = np.take(power, live, axis=0), depth[live], go_diffuse[live]
        p_d, p_s, lobes = p_d[live], p_s[live], surface.subset(live).bsdf(transport=True)
        # The next segment starts at the hit pulled back along the incoming ray, then pushed
        # off the surface: at a corner the rounded hit can lie outside the neighbouring face
        # (measured: a ceiling corner hit at z = 3.0000002 on the wall, a new direction
        # upwards, and the photon left a closed room), while the incoming segment is on the
        # photon's side of every surface by construction. The pull-back is relative to the
        # coordinates only (as their rounding is), not to the scene's size, so geometry far
        # away does not move the paths. A photon that goes through the surface (glass,
        # translucent) starts from the hit itself, pushed to the far side: pulled back first,
        # a push of the same size left it on the surface at normal incidence, and it met the
        # same face again (measured: a translucent sheet under a zenith sun transmitted each
        # photon twice, x rho_t^2).
        x_hit = x
        pull = offset_distance(x, 0.0)
        x = x - sampling.scale_rows(d, pull.astype(d.dtype, copy=False))
        # A survivor scatters by the lobe the roulette chose, its power scaled by rho / P.
        scale_d = lobes.diffuse.albedo() / np.where(p_d > 0, p_d, 1.0)[:, None]
        turn = None
        if surfaces.materials.has_translucent:
            # The diffuse pick's share rho_t of translucent closures leaves on the far side:
            # through with probability q = max rho_t / (max rho_r + max rho_t), the power
            # then x rho_t / (q P_d), else x rho_r / ((1 - q) P_d) (rho_r = rho - rho_t).
            rho_t = surface.subset(live).translucent
            rho_r = np.maximum(lobes.diffuse.albedo() - rho_t, 0.0)
            m_t, m_r = rho_t.max(axis=1), rho_r.max(axis=1)
            q = np.where(m_t > 0, m_t / np.where(m_t + m_r > 0, m_t + m_r, 1.0), 0.0)
            through = go_diffuse & (rng.random(len(live)) < q)
            if through.any():
                p = np.where(p_d > 0, p_d, 1.0)[:, None]
                scale_d = np.where(through[:, None],
                                   rho_t / (np.where(q > 0, q, 1.0)[:, None] * p),
                                   rho_r / (np.where(q < 1, 1.0 - q, 1.0)[:, None] * p))
                turn = np.where(through, -1.0, 1.0).astype(n.dtype)[:, None]
        if go_diffuse.all():
            d = lobes.diffuse.sample(-d, n if turn is None else n * turn,
                                     rng.random((len(live), 2)))[0]
            power *= scale_d
        else:
            spec = ~go_diffuse
            new_dir = np.empty_like(d)
            if go_diffuse.any():
                side = n[go_diffuse] if turn is None else n[go_diffuse] * turn[go_diffuse]
                new_dir[go_diffuse] = lobes.diffuse.subset(go_diffuse).sample(
                    -d[go_diffuse], side, rng.random((int(go_diffuse.sum()), 2)))[0]
            new_dir[spec] = lobes.mirror.subset(spec).sample(-d[spec], n[spec])[0]
            scale_s = lobes.mirror.albedo() / np.where(p_s > 0, p_s, 1.0)[:, None]
            if surfaces.materials.has_glossy:
                # Materials with glossy lobes (issue 23): the specular pick samples them
                # (bsdf.sample_glossy) instead of the seed's mirror; power x weight / P_s.
                params = surface.subset(live)
                glossy = spec & params.camera_glossy
                if glossy.any():
                    g = np.flatnonzero(glossy)
                    per_hit = params.lobe_inputs
                    wi, weight, _pdf = sample_glossy(
                        surfaces.materials, params.material[g], -d[g].astype(np.float64),
                        n[g].astype(np.float64), rng, ~flip_live[g],
                        per_hit=None if per_hit is None else per_hit[g])
                    new_dir[g] = wi
                    scale_s[g] = weight / np.where(p_s[g] > 0, p_s[g], 1.0)[:, None]
            power *= np.where(go_diffuse[:, None], scale_d, scale_s)
            d = new_dir
        through = sampling.dot_rows(d, n) < 0              # n faces the arrival side
        if through.any():
            x = np.where(through[:, None], x_hit, x)
        o = accel.offset_origins(x, n, d)

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
        "capped_paths": capped, "flux_capped": capped_power.tolist(), "rays": rays,
        "photons_per_light": emitted.per_light, "bytes": pmap.nbytes,
    })
    return pmap


# --- The photon pass: emission, tracing in parallel chunks, one map ------------------------
PHOTON_CHUNK = 1 << 17            # photons traced per task: ~0.1 s, so cancel acts quickly
MIN_AUTO_PHOTONS = 200_000
MAX_AUTO_PHOTONS = 2_000_000


def auto_photon_count(pixels: int) -> int:
    """Default photon count: two per pixel of the render window, between 200k and 2M."""
    return int(np.clip(2 * int(pixels), MIN_AUTO_PHOTONS, MAX_AUTO_PHOTONS))


def photon_spacing(scene: Scene, stored: int) -> float:
    """Mean distance between ``stored`` photons spread evenly over the scene's diffuse
    surface area, sqrt(area / stored) [m] (0 without diffuse area or photons)."""
    if len(scene.triangles) == 0 or stored == 0:
        return 0.0
    diffuse = MaterialTable(scene).is_diffuse[scene.material_ids]
    area = float(scene.triangle_areas()[diffuse].sum())
    return float(np.sqrt(area / stored)) if area > 0 else 0.0


def in_crevice(scene: Scene, accel, pmap: PhotonMap, pool=None) -> np.ndarray:
    """(P,) bool: photons stored under an occluder closer than the photons' mean spacing
    (``photon_spacing``), measured along the normal on the side the photon arrived from.

    An estimate (Eq. 9.11) takes the k nearest photons on the surface's plane and assumes their
    density is smooth over its disc, of radius sqrt(k / pi) = 4 spacings at least (k = 50). A
    crevice thinner than one spacing opens onto the surface beside it within a spacing, so the
    disc of every point near its mouth takes the crevice's photons as its own. Where the
    crevice is bright that is a halo of light that is not there: an emissive quad 0.1 mm under
    a ceiling (the original Cornell box's light) sends half its flux from its back face into
    the 0.1 mm gap, where the ceiling's irradiance is pi L, about 100 x the room's; estimates
    on the visible ceiling 1, 2, 4 mm from the light's edge came out 23, 10 and 3.2 W/m^2
    against 1.5-1.9 (the direct glow out of the gap included), and the room's indirect light
    1 % too bright. Such photons are not stored (their paths go on: the light that leaves the
    crevice is traced, stored and estimated where it lands); what a crevice holds cannot be
    seen but through a gap thinner than a spacing, and the direct light there is exact.
    Hair (``Scene.strands``) makes no crevice: strands a few millimetres apart let light
    through, and a fur ball lost most of the photons on and under its strands (its bounced
    light 25-30 % dark against Cycles); photons whose probe meets a strand are kept.
    The probe is one occlusion ray a photon, no longer than a spacing, in chunks on ``pool``
    (4M photons: 0.9 s on one thread)."""
    n = len(pmap)
    out = np.zeros(n, bool)
    reach = photon_spacing(scene, n)
    if n == 0 or not reach > 0:
        return out

    strands = scene.strands

    def probe(a):
        b = min(a + PHOTON_CHUNK, n)
        normals = pmap.normals[a:b].astype(np.float32)
        normals /= np.maximum(np.sqrt(sampling.dot_rows(normals, normals)), 1e-12)[:, None]
        origins = accel.offset_origins(pmap.positions[a:b], normals, normals)
        if strands is None:
            out[a:b] = accel.occluded(origins, normals, np.float32(reach))
        else:      # hair is no crevice: light passes between strands (StrandEstimates)
            _t, prim, _u, _v = accel.intersect(origins, normals,
                                               np.full(b - a, reach, np.float32))
            out[a:b] = (prim >= 0) & ~strands[np.maximum(prim, 0)]

    starts = range(0, n, PHOTON_CHUNK)
    list(pool.map(probe, starts)) if pool is not None else [probe(a) for a in starts]
    return out


def auto_max_radius(scene: Scene, stored: int, k: int) -> float:
    """Default cap on the gather radius [m]: four times the radius that holds ``k`` photons
    when the ``stored`` photons spread evenly over the scene's diffuse surface area. The cap
    only matters where photons are sparse (dark corners); elsewhere the k-th neighbour sets
    the radius."""
    if len(scene.triangles) == 0 or stored == 0:
        return max(scene.extent, 1e-9) * 0.05
    diffuse = MaterialTable(scene).is_diffuse[scene.material_ids]
    area = float(scene.triangle_areas()[diffuse].sum())
    if not area > 0:
        return max(scene.extent, 1e-9) * 0.05
    return float(4.0 * np.sqrt(k * area / (np.pi * stored)))


def _concatenate(maps: list) -> PhotonMap:
    cat = lambda key: np.concatenate([getattr(m, key) for m in maps])
    out = PhotonMap(cat("positions"), cat("power"), cat("incoming"), cat("normals"), cat("bounces"))
    stats = {}
    for m in maps:
        for key, value in m.stats.items():
            if key == "photons_per_light":
                continue
            if isinstance(value, list):
                stats[key] = (np.asarray(stats.get(key, np.zeros(len(value)))) + value).tolist()
            elif isinstance(value, (int, float)):
                stats[key] = stats.get(key, 0) + value
    stats["bytes"] = out.nbytes
    out.stats = stats
    return out


def build_photon_map(scene: Scene, accel, count: int, seed: int = 0, max_bounces: int = 128,
                     keep: str = "all", library: str = "pykdtree", workers: int = 1,
                     pool=None, progress=None, cancelled=None, ray_log: list | None = None,
                     surfaces: SceneSurfaces | None = None,
                     meshes: list | None = None) -> PhotonMap:
    """Emit ``count`` photons, trace them in chunks of ``PHOTON_CHUNK`` on ``pool`` (or a new
    pool of ``workers`` threads), keep ``"all"`` stored photons or only the ``"indirect"``
    ones (bounced at least once: what the ``full`` mode adds to exact direct light), and
    build the kd-tree. ``stats`` hold the energy bookkeeping: flux emitted / absorbed /
    escaped / capped [W, RGB], photons per light, stored counts, memory and times.

    Chunk i traces with its own random stream (seed, STREAM_PHOTON, i + 1), so a fixed seed
    gives the same map whatever the scheduling. ``progress(fraction)`` is called after each
    chunk and ``cancelled()`` polled; a cancelled pass returns the photons traced so far.
    ``ray_log`` (a list) receives every traced batch of photon rays (for the benchmark).
    ``surfaces`` and ``meshes`` (``emissive_meshes``): the scene's, when the caller has them."""
    from concurrent.futures import ThreadPoolExecutor

    own_pool = pool is None and workers > 1 and count > PHOTON_CHUNK
    executor = ThreadPoolExecutor(workers) if own_pool else pool
    try:
        return _emit_and_trace(scene, accel, count, seed, max_bounces, keep, library, pool,
                               executor, progress, cancelled, ray_log, surfaces, meshes)
    finally:
        if own_pool:
            executor.shutdown(wait=True, cancel_futures=True)


def _emit_and_trace(scene, accel, count, seed, max_bounces, keep, library, pool, executor,
                    progress, cancelled, ray_log, surfaces=None, meshes=None) -> PhotonMap:
    """``build_photon_map`` on ``executor`` (None: in this thread); ``pool``: the caller's,
    for the stages that take one as given."""
    t0 = time.perf_counter()
    emitted = emit_photons(scene, count, sampling.rng_for(seed, sampling.STREAM_PHOTON, 0), accel,
                           pool=executor, meshes=meshes)
    emit_seconds = time.perf_counter() - t0
    n = len(emitted.origins)
    bounds = [(a, min(a + PHOTON_CHUNK, n)) for a in range(0, n, PHOTON_CHUNK)]

    surfaces = surfaces or SceneSurfaces(scene)

    def trace(i):
        a, b = bounds[i]
        part = emitted.subset(a, b)
        return trace_photons(scene, accel, part, sampling.rng_for(seed, sampling.STREAM_PHOTON, i + 1),
                             max_bounces=max_bounces, ray_log=ray_log, surfaces=surfaces)

    t0 = time.perf_counter()
    maps, was_cancelled = [], False
    if executor is None or len(bounds) < 2:
        results = (trace(i) for i in range(len(bounds)))
    else:
        results = executor.map(trace, range(len(bounds)))
    for i, part in enumerate(results):
        maps.append(part)
        if progress is not None:
            progress((i + 1) / len(bounds))
        if cancelled is not None and cancelled():
            was_cancelled = True
            break
    trace_seconds = time.perf_counter() - t0
    pmap = _concatenate(maps) if maps else PhotonMap(*(np.zeros((0, 3), np.float32),) * 2,
                                                    np.zeros((0, 3), np.float16), np.zeros((0, 3), np.float16),
                                                    np.zeros(0, np.uint8))
    stored_all = len(pmap)
    # Photons in a crevice thinner than the photons' spacing are not kept (``in_crevice``).
    t_crevice = time.perf_counter()
    crevice = in_crevice(scene, accel, pmap, pool)
    crevice_seconds = time.perf_counter() - t_crevice
    crevice_flux = pmap.power[crevice].astype(np.float64).sum(axis=0)
    if crevice.any():
        pmap = pmap.subset(~crevice)
    direct_flux = pmap.power[pmap.bounces == 0].astype(np.float64).sum(axis=0)
    indirect_flux = pmap.power[pmap.bounces > 0].astype(np.float64).sum(axis=0)
    if keep == "indirect":
        pmap = pmap.subset(pmap.bounces > 0)
    elif keep != "all":
        raise ValueError(f"keep must be 'all' or 'indirect', not {keep!r}")
    traced = emitted.power[:bounds[len(maps) - 1][1]] if maps else emitted.power[:0]
    pmap.build(library)
    stats = pmap.stats
    stats.update({
        "requested": int(count), "emitted": int(len(traced)), "cancelled": was_cancelled,
        "flux_emitted": traced.sum(axis=0).tolist(),
        "flux_lights": emitted.power.sum(axis=0).tolist(),
        "photons_per_light": emitted.per_light,
        "stored_all": int(stored_all), "stored": int(len(pmap)), "kept": keep,
        "flux_stored_direct": direct_flux.tolist(), "flux_stored_indirect": indirect_flux.tolist(),
        "crevice_dropped": int(crevice.sum()), "flux_crevice": crevice_flux.tolist(),
        "crevice_seconds": crevice_seconds,
        "bytes": int(pmap.nbytes), "bytes_per_photon": round(pmap.nbytes / max(len(pmap), 1), 2),
        "max_bounces": int(max_bounces),
        "emit_seconds": emit_seconds, "trace_seconds": trace_seconds,
        "chunks": len(bounds),
    })
    return pmap


# --- The caustic photon map (issue 23) -------------------------------------------------------
CAUSTIC_PILOT = 20_000            # photons of the pilot that measures what the lights see
MIN_CAUSTIC_STORED = 50_000
MAX_CAUSTIC_STORED = 1_000_000
MAX_CAUSTIC_EMITTED = 16_000_000
# Below this share of the lights' flux passed on by specular surfaces at the first hit, no
# caustic map is made: the gather's rays count the emitters they meet through them (the
# factory cube's dielectric layer passes on about 0.07 %: its pilot asked for 4.4M photons
# for 206 stored, a third of the render).
MIN_CAUSTIC_FLUX = 0.005
# ... unless the specular surfaces the photons meet pass on at least this share of what
# reaches them (mirrors, glass, metals; not a dielectric coat's few per cent): their caustic
# is as bright as the light around it, however small a share of all the flux it holds (a
# mirror ball on a 200 m ground under an HDRI passes on 1.7e-5 of it; without the map, gather
# rays through the ball found the image's bright patch too rarely: the floor beside it 11 %
# dark).
STRONG_CAUSTIC_PASS = 0.5


def specular_share(scene: Scene, accel, seed: int = 0, count: int = CAUSTIC_PILOT,
                   surfaces: SceneSurfaces | None = None, meshes: list | None = None) -> tuple:
    """The share of the lights' photons whose first hit is a specular surface (mirror, glossy
    or glass, or a Principled specular layer: ``MaterialTable.is_transport_specular``): the
    projected size of the specular objects as the lights see them, measured by a pilot of
    ``count`` photons (flux-weighted as ``emit_photons`` shares them); and the share of their
    flux those surfaces pass on specularly (each hit weighted by its largest
    ``transport_specular`` channel), against the flux of all the lights; and the mean share
    of what reaches those surfaces that they pass on. The sun's and the world's photons are
    aimed at ``specular_bounds``. Returns (share, flux share, passed share); zeros when no
    light sees one. ``meshes``: ``emissive_meshes(scene)``, when the caller has it."""
    surfaces = surfaces or SceneSurfaces(scene)
    if not surfaces.materials.has_transport_specular:
        return 0.0, 0.0, 0.0
    if meshes is None:
        meshes = emissive_meshes(scene, surfaces.materials)
    emitted = emit_photons(scene, count, sampling.rng_for(seed, sampling.STREAM_CAUSTIC, 0), accel,
                           specular_bounds(scene, surfaces), meshes=meshes)
    if len(emitted.origins) == 0:
        return 0.0, 0.0, 0.0
    _t, prim, bu, bv = accel.intersect(np.ascontiguousarray(emitted.origins, np.float32),
                                       np.ascontiguousarray(emitted.directions, np.float32))
    hit = prim >= 0
    passed = np.zeros(len(prim))
    passed[hit] = surfaces.params(prim[hit], bu[hit], bv[hit]).transport_specular.max(axis=1)
    weight = emitted.power @ LUMINANCE
    total = float(weight.sum())
    # The flux share is against all the lights' flux, as if no photon were aimed (the sun's
    # and the world's through the scene's whole disc).
    everything = sum(float(flux @ LUMINANCE)
                     for _, flux, _spec in _photon_lights(scene, meshes=meshes))
    met = float(weight[passed > 0].sum())
    if not total > 0 or not everything > 0 or not met > 0:
        return 0.0, 0.0, 0.0
    return (met / total, min(float((weight * passed).sum() / everything), 1.0),
            float((weight * passed).sum() / met))


def specular_bounds(scene: Scene, surfaces: SceneSurfaces) -> tuple | None:
    """The bounding sphere (center, radius [m]) of the triangles whose material passes light
    on specularly (``MaterialTable.is_transport_specular``), or None when none does. The
    caustic map aims the sun's and the world's photons at it (Jensen's projection maps, 1996,
    in their simplest form): a 0.5 m mirror over a 200 m ground under a sun meets 1 in
    355,000 photons aimed at the whole scene, 45 % of those aimed at its sphere
    (``tests/test_caustic_aim.py``)."""
    mask = surfaces.materials.is_transport_specular[scene.material_ids]
    if not mask.any():
        return None
    points = scene.triangles[mask].reshape(-1, 3).astype(np.float64)
    center = (points.min(axis=0) + points.max(axis=0)) / 2
    radius = float(np.sqrt(((points - center) ** 2).sum(axis=1).max()))
    return center, max(radius * (1 + 1e-6), 1e-9)


def auto_caustic_stored(pixels: int) -> int:
    """Caustic photons to store by default: two per pixel of the frame, within
    [``MIN_CAUSTIC_STORED``, ``MAX_CAUSTIC_STORED``]."""
    return int(np.clip(2 * int(pixels), MIN_CAUSTIC_STORED, MAX_CAUSTIC_STORED))


def caustic_emission_count(stored: int, share: float) -> int:
    """Photons to emit so that about ``stored`` of them first hit a specular surface, for a
    pilot ``share`` (``specular_share``), at most ``MAX_CAUSTIC_EMITTED``."""
    if not share > 0:
        return 0
    return int(min(np.ceil(stored / share), MAX_CAUSTIC_EMITTED))


def build_caustic_map(scene: Scene, accel, emitted_count: int, seed: int = 0,
                      max_bounces: int = 64, k: int = 50, library: str = "pykdtree", pool=None,
                      progress=None, cancelled=None, surfaces: SceneSurfaces | None = None,
                      meshes: list | None = None) -> PhotonMap:
    """The caustic photon map (Jensen 1996): ``emitted_count`` photons from the lights, in
    chunks of ``PHOTON_CHUNK`` emitted and traced one at a time (each chunk an independent,
    stratified emission whose power is divided by the number of chunks), keeping only the
    light -> specular+ -> diffuse paths (``trace_photons(caustic=True)``). ``stats`` add
    ``radius``: the cap on its estimates' radius, 4 x the median k-nearest radius measured
    at up to 4096 of its own photons (so it follows the caustics' own density).
    ``surfaces`` and ``meshes`` (``emissive_meshes``): the scene's, when the caller has them
    (else made once here, not per chunk)."""
    t0 = time.perf_counter()
    surfaces = surfaces or SceneSurfaces(scene)
    if meshes is None:
        meshes = emissive_meshes(scene, surfaces.materials)
    chunks = max(1, int(np.ceil(emitted_count / PHOTON_CHUNK)))
    size = int(np.ceil(emitted_count / chunks))
    target = specular_bounds(scene, surfaces)

    def trace(i):
        rng = sampling.rng_for(seed, sampling.STREAM_CAUSTIC, i + 1)
        emitted = emit_photons(scene, size, rng, accel, target, meshes=meshes)
        emitted.power /= chunks
        return trace_photons(scene, accel, emitted, rng, max_bounces=max_bounces,
                             surfaces=surfaces, caustic=True)

    maps, was_cancelled = [], False
    results = pool.map(trace, range(chunks)) if pool is not None else map(trace, range(chunks))
    for i, part in enumerate(results):
        maps.append(part)
        if progress is not None:
            progress((i + 1) / chunks)
        if cancelled is not None and cancelled():
            was_cancelled = True
            break
    if was_cancelled:
        # Chunks are independent estimates: keep those traced, each worth 1 / len(maps).
        for part in maps:
            part.power *= np.float32(chunks / len(maps))
    cmap = _concatenate(maps)
    cmap.build(library)
    radius = 0.0
    if len(cmap) > k:
        probe = cmap.positions[np.linspace(0, len(cmap) - 1, min(4096, len(cmap))).astype(int)]
        dist, _idx = cmap.query(probe, k)
        radius = float(4.0 * np.median(dist[:, -1]))
    cmap.stats.update({"emitted": int(chunks * size), "chunks": chunks, "stored": int(len(cmap)),
                       "radius": radius, "cancelled": was_cancelled, "k": int(k),
                       "bytes": int(cmap.nbytes), "seconds": time.perf_counter() - t0})
    return cmap
