"""Indirect light at shading points: three estimators with one interface, and the placement
of the irradiance cache's records.

What it computes
    Each estimator answers ``irradiance(x, ns, ng, rng, stats)`` -> E (N, C) [W/m^2]: the
    indirect irradiance at points ``x`` with shading normals ``ns`` (facing the viewer) and
    geometric normals ``ng`` (for ray offsets); ``lookups`` says how many of a pixel's camera
    samples ask it (their value stands for the others). ``channels`` C is 3 (RGB), or 6 where
    the gather counts the smooth sky of an image world with a sun
    (``lights.LightSet.gather_sky``): RGB of the light met at surfaces (indirect), then RGB of
    the sky (direct light, which the light passes file as Diffuse Direct); the cache's records
    hold both, and every decision about them (placement, the neighbour check) reads the sum.

    ``PhotonEstimate``  the photon map's estimate at the hit itself (Eq. 9.11; seed 9.5):
        ``full`` mode asks for the photons that bounced at least once (direct light is exact),
        ``photon-map`` mode for all of them.
    ``FinalGather``  the stratified final gather (seed ch. 8, ``engine/gather.py``) over
        irradiance precomputed at photons (Christensen 1999) at every asking sample.
    ``CachedIndirect``  the irradiance cache (seed ch. 10): interpolation with the gradients
        (Eq. 10.5) wherever a record has w > 1/a; the samples no record covers make records of
        their own, kept to their batch (``local_cache_records``).
    ``place_cache(...)``  the records before the camera stage: Ward's "overture" in passes of
        pixel strides ``CACHE_STRIDES`` = 32, 16, ..., 1, each record a final gather with Ward
        & Heckbert's gradients, R clamped to [``R_MIN_PIXELS``, ``R_MAX_PIXELS``] pixel
        footprints / a, checked against its neighbours' gathers after each pass
        (``irradiance_cache.consistent_radii``), the gaps refilled coarse to fine; a
        record on an edge of its triangle gathers from just inside it
        (``into_own_triangle``).

Parameters
    ==================  ==========  ==========================================================
    name                default     meaning
    ==================  ==========  ==========================================================
    CACHE_STRIDES       32 ... 1    pixel strides of the placement passes
    R_MIN_PIXELS        1.5         the least a record reaches, in pixel footprints / a
    R_MAX_PIXELS        64          the most a record reaches, in pixel footprints / a
    LOCAL_STEPS         (16, 4)     batch-local records: every 16th uncovered sample gathers,
                                    then every 4th of those still uncovered
    STRAND_GATHER_DIVISOR  4        samples on hair (``Scene.strands``) take no record: each
                                    gathers with M/4 x N/4 rays (at least 1 x 4)
    ==================  ==========  ==========================================================
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np

from . import sampling
from .camera import pixel_rays
from .gather import final_gather
from .irradiance_cache import (IrradianceCache, clamp_radius, consistent_radii,
                               frames_from_normals, irradiance_and_gradients,
                               limit_translational_gradient)

CACHE_STRIDES = (32, 16, 8, 4, 2, 1)     # placement passes: every 32nd pixel, then 16th, ...
R_MIN_PIXELS = 1.5                       # a record reaches at least this many pixels ...
R_MAX_PIXELS = 64.0                      # ... and at most this many (R clamped, DESIGN §4)
LOCAL_STEPS = (16, 4)   # batch-local records: every 16th uncovered sample, then every 4th left
STRAND_GATHER_DIVISOR = 4   # hair samples gather with M/4 x N/4 rays each (CachedIndirect)


class PhotonEstimate:
    """Indirect (``full``) or all (``photon-map``) light from the photon map's estimate at the
    hit itself (Eq. 9.11; seed 9.5)."""

    channels = 3

    def __init__(self, photon_map, k, max_radius, min_bounces, cone_filter, lookups):
        self.photon_map, self.k, self.max_radius = photon_map, k, max_radius
        self.min_bounces, self.cone_filter, self.lookups = min_bounces, cone_filter, lookups

    def irradiance(self, x, ns, ng, rng, stats, strands=None):
        return self.photon_map.irradiance(x, ng, k=self.k, max_radius=self.max_radius,
                                          min_bounces=self.min_bounces,
                                          cone_filter=self.cone_filter, stats=stats)


class CausticEstimate:
    """Caustic irradiance at camera hits from the caustic photon map (Jensen 1996): Eq. 9.11
    over the ``k`` nearest caustic photons within ``radius`` [m], with Jensen's cone filter
    (k_c = 1.1: caustics have sharp edges). Only points near caustic photons are looked up:
    the photons mark the cells of a grid of cell size ``radius`` and their 26 neighbours, and
    points in unmarked cells get 0 without a query (a hash of the cell; a collision only costs
    a query)."""

    CONE = 1.1

    def __init__(self, caustic_map, k, radius):
        self.map, self.k, self.radius = caustic_map, int(k), float(radius)
        cells = np.floor(caustic_map.positions.astype(np.float64) / self.radius).astype(np.int64)
        cells = np.unique(cells, axis=0)
        steps = np.array([(i, j, l) for i in (-1, 0, 1) for j in (-1, 0, 1) for l in (-1, 0, 1)])
        self.cells = np.unique(self._key((cells[:, None, :] + steps[None]).reshape(-1, 3)))

    @staticmethod
    def _key(cells):
        return (cells[:, 0] * 73856093) ^ (cells[:, 1] * 19349663) ^ (cells[:, 2] * 83492791)

    def irradiance(self, x, n, stats=None):
        """E (N, 3) [W/m^2] of the caustic photons at points ``x`` on the side ``n`` faces."""
        out = np.zeros((len(x), 3))
        if len(x) == 0 or len(self.map) == 0:
            return out
        cells = np.floor(np.asarray(x, np.float64) / self.radius).astype(np.int64)
        near = np.flatnonzero(np.isin(self._key(cells), self.cells))
        if len(near):
            out[near] = self.map.irradiance(x[near], n[near], k=self.k, max_radius=self.radius,
                                            cone_filter=self.CONE, stats=stats)
        return out


class FinalGather:
    """Indirect light by the stratified final gather at every asking sample (no cache).
    ``guide``: the photon map whose nearby photons steer ``guide_extra`` x M x N extra rays
    (Jensen 1995). ``sky``: the smooth sky its escaping rays count where the world light left
    it to the gather (``lights.LightSet.gather_sky``); the estimate then holds that direct
    light too, in channels of its own (``channels`` 6, module docstring)."""

    def __init__(self, estimates, accel, surfaces, m, n, lookups, guide=None, guide_extra=0.0,
                 max_specular=4, mirrored_emission=True, sky=None):
        self.estimates, self.accel, self.surfaces = estimates, accel, surfaces
        # The world's smooth sky, counted by the rays that leave the scene
        # (``lights.LightSet.gather_sky``; None: the light samples count all the world).
        self.sky = sky
        self.channels = 3 if sky is None else 6
        self.m, self.n, self.lookups = m, n, lookups
        self.guide, self.guide_extra = guide, guide_extra
        # Specular bounces a gather ray follows, and whether it counts the emitters it meets
        # after them (not when the caustic map holds that light).
        self.max_specular, self.mirrored_emission = max_specular, mirrored_emission

    def gather(self, x, ns, ng, rng, stats=None):
        return final_gather(x, ns, ng, self.estimates, self.accel, self.surfaces, rng, self.m,
                            self.n, max_specular=self.max_specular, stats=stats,
                            guide=self.guide if self.guide_extra > 0 else None,
                            guide_extra=self.guide_extra,
                            mirrored_emission=self.mirrored_emission, sky=self.sky,
                            split_sky=self.sky is not None)

    def irradiance(self, x, ns, ng, rng, stats, strands=None):
        return self.gather(x, ns, ng, rng, stats)[0]

    def surface_irradiance(self, x, n):
        """All the light's irradiance (N, 3) [W/m^2] at surface points ``x`` (normals ``n``
        towards the viewer) from the irradiance precomputed at photons: what a gather ray
        reads where it lands."""
        return self.estimates.lookup(x, n).astype(np.float64)


class CachedIndirect:
    """Indirect light from the irradiance cache (seed chapter 10): interpolation with the
    gradients (Eq. 10.5) wherever a record has w > 1/a. Where none does (the part of a pixel
    across an edge from its centre, a curved surface whose normal turns by more than a within
    a pixel, the holes the neighbour check left after the last placement pass, mirror
    reflections) the batch makes records of its own, as Ward's ray tracer does when a look-up
    fails, but kept to the batch (so the picture does not depend on the order batches finish):
    ``local_cache_records``. Without them every one of a pixel's 16 samples gathered: on the
    seed's Scene 2 at 160 x 120 the camera gathered at 5,329 samples (``final``) and 13,722
    (a = 0.4, 19 s of 28 s). Reaching for records with a relaxed error instead was measured 2x
    too bright along a box's contact with the floor.

    ``camera`` (``scene.Camera``) gives a point's pixel footprint (``Camera.footprint`` of its
    distance from the camera's position). ``stats["covered_mask"]`` is left for
    the batch: which asking samples a placed record served (the Cache usage pass)."""

    def __init__(self, cache, a, gather: FinalGather, lookups, use_gradients, camera):
        self.cache, self.a, self.gather, self.lookups = cache, a, gather, lookups
        self.use_gradients = use_gradients
        self.camera = camera
        self.channels = gather.channels
        # Hair samples' own gathers (``_with_strands``): M/4 x N/4 rays.
        self.strand_gather = copy.copy(gather)
        self.strand_gather.m = max(1, gather.m // STRAND_GATHER_DIVISOR)
        self.strand_gather.n = max(4, gather.n // STRAND_GATHER_DIVISOR)

    def surface_irradiance(self, x, n):
        """As ``FinalGather.surface_irradiance``."""
        return self.gather.surface_irradiance(x, n)

    def irradiance(self, x, ns, ng, rng, stats, strands=None):
        if strands is not None and strands.any():
            return self._with_strands(x, ns, ng, rng, stats, strands)
        e, covered, _w, _count = self.cache.interpolate(x, ns, self.a,
                                                        use_gradients=self.use_gradients)
        stats["cache_interpolated"] = stats.get("cache_interpolated", 0) + int(covered.sum())
        rest = np.nonzero(~covered)[0]
        gathered = 0
        if len(rest):
            rest, made = local_cache_records(self, x, ns, ng, rest, e, covered, rng, stats)
            gathered += made
        if len(rest):
            e[rest] = self.gather.irradiance(x[rest], ns[rest], ng[rest], rng, stats)
            gathered += len(rest)
        if gathered:
            stats["cache_gathered"] = stats.get("cache_gathered", 0) + gathered
        stats["covered_mask"] = covered          # taken by the batch for the Cache usage pass
        return e

    def _with_strands(self, x, ns, ng, rng, stats, strands):
        """Samples on hair (``strands``) gather their own indirect light with M x N /
        ``STRAND_GATHER_DIVISOR``^2 rays (a strand's normal turns all the way round within a
        pixel, so a record serves almost none of its neighbours: a fur ball's camera stage
        made a record at nearly every sample); the others as usual."""
        e = np.zeros((len(x), self.channels))
        plain = ~strands
        covered = np.zeros(len(x), bool)
        if plain.any():
            e[plain] = self.irradiance(x[plain], ns[plain], ng[plain], rng, stats)
            covered[plain] = stats.pop("covered_mask")
        e[strands] = self.strand_gather.irradiance(x[strands], ns[strands], ng[strands], rng,
                                                   stats)
        stats["strand_gathered"] = stats.get("strand_gathered", 0) + int(strands.sum())
        stats["covered_mask"] = covered
        return e


def local_cache_records(indirect: CachedIndirect, x, ns, ng, rest, e, covered, rng, stats):
    """``CachedIndirect``'s batch-local records: a final gather at every ``LOCAL_STEPS[0]``-th
    uncovered sample (samples come pixel by pixel, so about one per uncovered pixel) becomes a
    record reaching ``R_MIN_PIXELS`` pixel footprints (the least any record reaches; no
    neighbour check vouches for a longer one), the samples it covers interpolate it, and so on
    with every ``LOCAL_STEPS[1]``-th of the rest. Fills ``e`` at the samples ``rest`` they
    serve (and at their own points), marks those ``covered``, and returns (the samples still
    uncovered, the gathers made)."""
    a = indirect.a
    local = IrradianceCache(channels=indirect.channels)
    made = 0
    for step in LOCAL_STEPS:
        if len(rest) < 2:                     # one sample: its own gather serves no other
            break
        pick = rest[::step]
        camera = indirect.camera
        footprint = camera.footprint(np.linalg.norm(x[pick] - camera.position, axis=1))
        reach = np.maximum(R_MIN_PIXELS * footprint / a, 1e-12)
        e_pick, e_rec, radius, rot, trans, _var = gathered_records(
            indirect.gather, x[pick], ns[pick], ng[pick], rng, reach, reach, stats)
        local.add(x[pick], ns[pick], e_rec, radius, rot, trans)
        e[pick] = e_pick
        made += len(pick)
        keep = np.ones(len(rest), bool)
        keep[::step] = False
        rest = rest[keep]
        if not len(rest):
            break
        e_l, cov_l, _w, _c = local.interpolate(x[rest], ns[rest], a,
                                               use_gradients=indirect.use_gradients,
                                               count_usage=False)
        served = rest[cov_l]
        e[served] = e_l[cov_l]
        covered[served] = True
        stats["cache_local_interpolated"] = (stats.get("cache_local_interpolated", 0)
                                             + len(served))
        rest = rest[~cov_l]
    stats["cache_local_records"] = stats.get("cache_local_records", 0) + made
    return rest, made


def gathered_records(gather: FinalGather, x, ns, ng, rng, r_min, r_max, stats=None):
    """Irradiance-cache records at points ``x`` (normals ``ns``, offset normals ``ng``): a
    final gather at each, Ward's E, R and gradients from it (``irradiance_and_gradients``,
    misses not counted), R clamped to [``r_min``, ``r_max``] [m] and the translational
    gradient limited to the clamped R. Returns (E as the gather gives it, the records' E, R,
    rotational and translational gradients, the gathers' noise variance)."""
    e, radiance, dist = gather.gather(x, ns, ng, rng, stats)
    g = irradiance_and_gradients(radiance, dist, gather.m, gather.n, frames_from_normals(ns),
                                 misses_count=False)
    # (Limiting R further to E / |grad_t E| was tried and dropped: with noisy records it
    # shrinks the ones that caught a bright patch; Scene 2 came out 26 % dark.)
    radius = clamp_radius(g.radius, r_min, r_max)
    trans = limit_translational_gradient(g.trans_grad, g.irradiance, g.radius, radius)
    return e, g.irradiance, radius, g.rot_grad, trans, g.variance


def into_own_triangle(x, triangles, eps):
    """Points x (N, 3) within ``eps`` (N,) [m] of an edge of their own ``triangles``
    (N, 3, 3) moved ``eps`` towards its centroid (the others as they are): where a record's
    gather rays start. A pixel centre of an aligned camera lands exactly (in float32) on an
    edge, in the plane of the neighbouring face; the gather's rays then met that face at
    t = 0 and read its far side (a camera inside a closed box: 2 of 58 records took the lit
    room's light through the box's wall). Moved inside its own triangle, the point is off
    the other face's plane; the record keeps its place."""
    tri = np.asarray(triangles, np.float64)
    out = np.array(x, np.float64)
    near = np.zeros(len(out), bool)
    for k in range(3):
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        edge = b - a
        length = np.maximum(np.linalg.norm(edge, axis=1), 1e-300)
        near |= np.linalg.norm(np.cross(out - a, edge), axis=1) / length <= eps
    if near.any():
        towards = tri[near].mean(axis=1) - out[near]
        length = np.linalg.norm(towards, axis=1, keepdims=True)
        out[near] += towards / np.maximum(length, 1e-300) * np.minimum(eps[near, None], length)
    return out


def place_cache(scene, accel, surfaces, gather: FinalGather, settings, pool, tell, cancelled):
    """Place irradiance-cache records in passes of increasing image resolution (Ward's
    "overture", the seed's cache placement): the first hits of pixel centres on a grid of
    stride 32, 16, ..., 1; at each pass the points no record covers get new records, computed
    in batches by the final gather. R_i (harmonic mean distance) is clamped to
    [R_MIN_PIXELS, R_MAX_PIXELS] pixel footprints divided by a, so a record reaches between
    1.5 and 64 pixels: corners cannot drive R_i to 0, open walls cannot spread one record
    over the image. After each pass (``cache_refine``) every record is checked against the
    gathers of its neighbours (``consistent_radii``): records whose extrapolation a neighbour
    contradicts reach less far, so the next pass puts records between them, and after the
    last pass the camera's batches fill what no record covers (``CachedIndirect``).
    Each pass starts with the coarser strides again, for the points nothing covers: where
    the check shrank records, the disc they leave is refilled coarse to fine, as Ward's
    overture would have placed it had those records been small from the start. Filled at the
    pass's own stride instead, every point of the disc got a record with its full geometric
    R (Scene 2 at 320 x 240, ``preview``: 4,027 records at stride 1, up to 921 covering one
    look-up, 20 s a render; refilled: 941 records in all, 3.8 s).
    Measured on the seed's Scene 2 (160 x 120, ``final``, two seeds) against a gather at every
    pixel: the knot's indirect shadow on the floor came out 17 % bright and the worst 4 x 4
    block +4.3 % with Ward's weight alone, +1.3 % and 0.8 % with the check, for 4,520 records
    instead of 2,625 and 13.9 s instead of 10.3 s.

    Returns (cache, stats): the stats hold the records and, per pass, its stride, the new
    records, those that refilled the check's gaps and the records the check shrank."""
    # Over the full frame, whatever the render border: a tile of a still gets the records the
    # whole frame would (so tiles reassemble into the full render, pixel for pixel).
    cam = replace(scene.camera, border=None)
    width, height = cam.window_size
    rng = sampling.rng_for(settings.seed, sampling.STREAM_GATHER, 1 << 20)
    origins, directions, tmax = pixel_rays(cam, 0, width * height, 1, rng, centres=True)
    t_hit, prim, bu, bv = accel.intersect(origins, directions, tmax)
    hit = prim >= 0
    pixel = np.nonzero(hit)[0]
    t_hit, prim, bu, bv = t_hit[hit], prim[hit], bu[hit], bv[hit]
    d = directions[hit]
    x = origins[hit] + t_hit[:, None] * d
    ng, ns, _front = surfaces.normals(prim, bu, bv, d)
    diffuse = surfaces.params(prim).is_diffuse
    if scene.strands is not None:        # hair gathers per sample (CachedIndirect)
        diffuse &= ~scene.strands[prim]
    pixel, x, ng, ns, t_hit = pixel[diffuse], x[diffuse], ng[diffuse], ns[diffuse], t_hit[diffuse]
    x_gather = into_own_triangle(x, scene.triangles[prim[diffuse]], accel.offset_distance(x))
    footprint = cam.footprint(t_hit)
    a = settings.cache_error
    cache = IrradianceCache(channels=gather.channels)
    row, col = np.divmod(pixel, width)
    stats = {"passes": [], "records": 0}
    record_point, record_variance = [], []       # per record: its pixel's hit, its noise
    chunk = 256

    def record(part, key):
        prng = sampling.rng_for(settings.seed, sampling.STREAM_GATHER, key)
        _e, e_rec, radius, rot, trans, var = gathered_records(
            gather, x_gather[part], ns[part], ng[part], prng,
            R_MIN_PIXELS * footprint[part] / a, R_MAX_PIXELS * footprint[part] / a)
        return part, e_rec, radius, rot, trans, var

    strides = CACHE_STRIDES
    for pass_index, stride in enumerate(strides):
        if cancelled is not None and cancelled():
            break
        made = refilled = 0
        # The overture again from the coarsest stride down to this pass's, each sub-pass
        # placing records only where nothing covers: where the check emptied a disc, it is
        # refilled coarse to fine, as if its records had been small from the start, instead of
        # with a record at every point of this pass's grid (the docstring).
        for sub_index, sub in enumerate(strides[:pass_index + 1]):
            idx = np.nonzero((row % sub == 0) & (col % sub == 0))[0]
            if len(cache) and len(idx):
                _e, covered, _w, _c = cache.interpolate(x[idx], ns[idx], a, count_usage=False,
                                                        pool=pool)
                idx = idx[~covered]
            if not len(idx):
                continue
            parts = [idx[i:i + chunk] for i in range(0, len(idx), chunk)]
            keys = [(pass_index << 40) + (sub_index << 32) + k for k in range(len(parts))]
            for part, e, radius, rot, trans, var in pool.map(record, parts, keys):
                cache.add(x[part], ns[part], e, radius, rot, trans)
                record_point.append(part)
                record_variance.append(var)
                made += len(part)
                refilled += len(part) if sub_index < pass_index else 0
        shrunk = 0
        if made and settings.cache_refine:
            # Records that disagree with a neighbour's gather reach less far; the finer passes
            # then fill the gap (an indirect shadow gets records of its own).
            points = np.concatenate(record_point)
            bound = consistent_radii(cache, a, np.concatenate(record_variance),
                                     r_min=R_MIN_PIXELS * footprint[points] / a, pool=pool)
            shrunk = cache.limit_radius(bound)
        stats["passes"].append({"stride": stride, "new_records": made, "refilled": refilled,
                                "shrunk": shrunk})
        tell((pass_index + 1) / len(strides),
             f"Irradiance cache: pass {pass_index + 1}/{len(strides)}, {len(cache):,} records")
    stats["records"] = len(cache)
    return cache, stats
