"""Direct illumination: irradiance from every light at arrays of shading points (seed ch. 7).

What it computes
    ``direct_irradiance(x, n, lights, accel, rng, light_samples)`` returns E (N, 3) [W/m^2]
    on the side of each surface that ``n`` points to, with visibility by shadow rays.
    Outgoing radiance of a Lambertian surface is then rho_d / pi * E.

    * Delta lights (point Eq. 7.1, spot, hard sun, collimated disk Eq. 7.2) cost one shadow
      ray each per point and have no sampling noise.
    * Sampled lights (area, emissive mesh, soft sun, point / spot with a radius, world) share ``light_samples`` samples per
      point. Each sample first picks a light with probability proportional to its estimated
      unoccluded contribution at that point (``LightSet.selection_weights``), then a point /
      direction on it; the selection number and the 2-D light numbers are stratified over the
      point's samples. Estimate: sum_k f_k V_k / (p_select,k K).

Parameters
    ``light_samples`` (int, default 4): samples per point shared by the sampled lights.
    Shadow rays start ``accel.offset_origins`` off the surface and stop short of the light by
    the same relative offset, so lights touching surfaces do not shadow themselves.

Shadow photons (seed 7.2, 9.6; ``engine/shadow_photons.py``)
    With ``shadow_map`` given, each (point, sampled light) pair whose light has shadow
    photons is classified once, and all the point's samples of that light follow its class:
    LIT: visibility 1, no ray (a sample whose direction lies below the geometric surface is
    traced as before); UMBRA: no light, no ray; PENUMBRA: each of the pair's samples is
    replaced by ``shadow_map.penumbra_factor`` = M fresh stratified samples of the same light,
    each weighted f / (p_select K M) and traced. The class depends on the point and the light
    only, never on a sample's numbers, so the penumbra estimate stays unbiased: the M samples
    have the same expectation as the one they replace. ``stats`` then also count
    ``shadow_rays_saved`` (the rays a plain call with the same light samples traces, minus the
    rays traced; negative where penumbrae cost more than they save) and ``shadow_lit``,
    ``shadow_umbra``, ``shadow_penumbra`` (classified pairs). Suns with an angle, sphere
    lights, the world and delta lights keep plain shadow rays. Without a map the code path, the random numbers
    and the results are those of a plain call.

All shadow rays of a call go to Embree in one batch. Lights draw their samples in batches of
``LIGHT_SAMPLE_BATCH`` points (``draw_light_samples``): a light's temporaries over hundreds of
thousands of samples fall out of the CPU's caches into fresh memory pages.
"""
from __future__ import annotations

import time

import numpy as np

from . import sampling
from .lights import LightSet, ray_visible

LIT, UMBRA, PENUMBRA = 0, 1, 2          # shadow-photon classes (engine/shadow_photons.py)
# Light samples drawn at once (``draw_light_samples``). The textured room's panel at 400,000
# samples: its radiance 0.14-0.22 s at once, 0.08 s in batches (the same values).
LIGHT_SAMPLE_BATCH = 1 << 16


def draw_light_samples(light, x, n, points, u, pick=None):
    """A sampled light's samples at points ``x[points]`` with normals ``n[points]`` for
    numbers ``u`` (P, 2) (and ``pick`` (P,), the rest of each sample's choice number, for
    lights with a radiance per sample): directions (P, 3), shadow distances (P,), weights
    (P,) and, for ``per_sample_rgb`` lights, radiances (P, 3) (else None); drawn in batches
    of ``LIGHT_SAMPLE_BATCH``, each batch's points gathered from ``x`` and ``n`` by itself."""
    per_sample = getattr(light, "per_sample_rgb", False)
    parts = []
    for start in range(0, max(len(points), 1), LIGHT_SAMPLE_BATCH):
        at = slice(start, start + LIGHT_SAMPLE_BATCH)
        xs, ns = np.take(x, points[at], axis=0), np.take(n, points[at], axis=0)
        if per_sample:
            parts.append(light.sample_rgb(xs, ns, u[at], None if pick is None else pick[at]))
        else:
            parts.append(tuple(light.sample(xs, ns, u[at])) + (None,))
    if len(parts) == 1:
        return parts[0]
    return tuple(None if part[0] is None else np.concatenate(part)
                 for part in zip(*parts))


def direct_irradiance(x: np.ndarray, n: np.ndarray, lights: LightSet, accel, rng: np.random.Generator,
                      light_samples: int = 4, stats: dict | None = None,
                      offset_normals: np.ndarray | None = None, ray_log: list | None = None,
                      shadow_map=None) -> np.ndarray:
    """Irradiance (N, 3) at points ``x`` with unit normals ``n`` (facing the viewer).

    ``offset_normals`` (default ``n``) are the geometric normals used to push shadow-ray
    origins off the surface; ``stats`` receives ``shadow_rays`` and ``trace_seconds``.
    ``shadow_map``: a ``ShadowPhotonMap`` that classifies points (see the module docstring).
    """
    terms = direct_terms(x, n, lights, accel, rng, light_samples, stats, offset_normals, ray_log,
                         shadow_map=shadow_map)
    return irradiance_from_terms(terms, len(x))


def irradiance_from_terms(terms, count: int) -> np.ndarray:
    """Sum the ``direct_terms`` of ``count`` points into irradiance (count, 3)."""
    irradiance = np.zeros((count, 3))
    for target, scalar, rgb in terms:
        rgb = np.asarray(rgb, np.float64)
        if rgb.ndim == 2:                # a radiance per sample (an image world)
            value = scalar[:, None] * rgb
            if target is None:
                irradiance += value
            else:
                for c in range(3):
                    irradiance[:, c] += np.bincount(target, weights=value[:, c], minlength=count)
            continue
        if target is not None:
            scalar = np.bincount(target, weights=scalar, minlength=count)
        irradiance += scalar[:, None] * rgb[None]
    return irradiance


def direct_terms(x: np.ndarray, n: np.ndarray, lights: LightSet, accel, rng: np.random.Generator,
                 light_samples: int = 4, stats: dict | None = None,
                 offset_normals: np.ndarray | None = None, ray_log: list | None = None,
                 shadow_map=None, with_directions: bool = False,
                 pixel_slots: tuple | None = None) -> list:
    """Irradiance as a list of terms (target, scalar, rgb): term i adds ``scalar * rgb`` to
    points ``target`` (None: every point, in order); ``rgb`` is a light's (3,) or, for an
    image world (``lights.EnvironmentLight``), one radiance per sample (K, 3). Callers that weight the irradiance per
    point (albedo, pixel) can then do so on scalars instead of (N, 3) arrays.
    ``shadow_map``: a ``ShadowPhotonMap``; None traces every shadow ray (module docstring).
    ``pixel_slots``: (primary-ray indices (N,), samples per pixel) at a camera path's first
    hits: the light numbers (the light's choice, a world's strategy and patch, the 2-D
    position) are then stratified over each pixel's samples x ``light_samples``
    (``sampling.pixel_stratified``) rather than over each point's: with one light sample a
    sample, a world's sun and sky strategies still split evenly over the pixel (the yard at
    16 x 1 samples: 16.2 % -> 4.4 % error), and more camera samples with fewer light samples
    each cost no more light noise.
    ``with_directions``: terms are (target, scalar, rgb, directions, hittable, light)
    instead, with each sample's unit direction to the light (rows of ``scalar``), what a ray
    could hit of the light (``_hittable``: ``"mesh"``, ``"world"``, ``"area"`` or ``""``) and
    the light's index in ``lights.sampled`` (-1 for delta lights), for BSDFs other than
    Lambert's: a sample's radiance towards wo is then f(wo, direction) x scalar x rgb (times
    a weight of multiple importance sampling where the BSDF's rays meet the light too)."""
    count = len(x)
    if count == 0 or lights.empty:
        return []

    # Each entry: (target points, directions, distances, scalar weights, rgb of the light).
    groups = []
    unshadowed = []     # terms of LIT samples: no shadow ray (shadow photons)
    tally = None if shadow_map is None else {"plain": 0, "lit": 0, "umbra": 0, "penumbra": 0}

    # Delta lights: one ray per light and lit point.
    for w, dist, weight, rgb in lights.delta_rays(x, n):
        live = weight > 0
        if tally is not None:
            tally["plain"] += int(live.sum())
        if live.all():
            groups.append((None, w, dist, weight, rgb, False, "", -1))
        elif live.any():
            idx = np.nonzero(live)[0]
            groups.append((idx, w[idx], dist[idx], weight[idx], rgb, False, "", -1))

    # Sampled lights: K stratified samples per point, light chosen by estimated contribution.
    if lights.sampled and light_samples > 0:
        k = int(light_samples)
        if pixel_slots is not None:
            # Camera hits: stratified over the pixel's samples x K (module docstring).
            u2, u_pick = sampling.pixel_stratified(pixel_slots[0], pixel_slots[1], k, rng)
        else:
            u2 = sampling.stratified_2d(count, k, rng)                 # (N, K, 2)
            u_pick = (np.argsort(rng.random((count, k)), axis=1) + rng.random((count, k))) / k
        point_of = np.repeat(np.arange(count), k)
        u2 = u2.reshape(-1, 2)
        u_pick = u_pick.reshape(-1)
        if len(lights.sampled) == 1:
            # One sampled light takes every sample, its choice number whole.
            choice = None
            p_sel = np.ones(len(point_of))
            rest = np.clip(u_pick, 0.0, 1.0 - 1e-12)
        else:
            probs = lights.selection_weights(x, n)                      # (N, L)
            cdf = np.cumsum(probs, axis=1)
            choice = np.minimum((cdf[:, None, :] < u_pick.reshape(count, k)[..., None])
                                .sum(axis=2), len(lights.sampled) - 1).reshape(-1)
            p_sel = probs[point_of, choice]
            # What is left of each sample's choice number inside its light's interval,
            # uniform in [0, 1) and stratified over the point's samples of that light: an
            # image world picks its strategy and cell with it (``EnvironmentLight.sample_rgb``).
            below = np.where(choice > 0, cdf[point_of, np.maximum(choice - 1, 0)], 0.0)
            rest = np.clip((u_pick - below) / np.maximum(p_sel, 1e-300), 0.0, 1.0 - 1e-12)
        for li, light in enumerate(lights.sampled):
            sel = slice(None) if choice is None else np.nonzero(choice == li)[0]
            pts = point_of[sel]
            if len(pts) == 0:
                continue
            # An image world or a textured emitter gives each sample its own radiance
            # (lights.EnvironmentLight, lights.TriangleEmitter.sample_rgb), other lights None.
            w, dist, weight, rgb = draw_light_samples(light, x, n, pts, u2[sel], rest[sel])
            weight = weight / (p_sel[sel] * k)
            live = (weight > 0) & np.isfinite(weight)
            if shadow_map is not None and shadow_map.covers(li):
                _classified_samples(groups, unshadowed, tally, shadow_map, li, light, x, n,
                                    offset_normals, accel, rng, k, pts, p_sel[sel],
                                    w, dist, weight, live, rgb)
                continue
            if tally is not None:
                tally["plain"] += int(live.sum())
            if live.any():
                groups.append((pts[live], w[live], dist[live], weight[live],
                               light.rgb if rgb is None else rgb[live],
                               getattr(light, 'in_bvh', False), _hittable(light), li))

    if not groups:
        _count_classes(stats, tally, 0)
        return unshadowed if with_directions else [t[:3] for t in unshadowed]
    single = len(groups) == 1 and groups[0][0] is None
    if single:
        target = None
        dirs, dist, org = groups[0][1].astype(x.dtype, copy=False), groups[0][2], x
        normals = n if offset_normals is None else offset_normals
    else:
        everyone = np.arange(count)
        target = np.concatenate([everyone if g[0] is None else g[0] for g in groups])
        dirs = np.concatenate([g[1] for g in groups]).astype(x.dtype, copy=False)
        dist = np.concatenate([g[2] for g in groups])
        org = np.take(x, target, axis=0)           # (take: row gathers at twice the speed)
        normals = np.take(n if offset_normals is None else offset_normals, target, axis=0)
    eps = accel.offset_distance(org)
    start = accel.offset_origins(org, normals, dirs, eps=eps)
    finite = np.isfinite(dist)
    # Rays to points and to lights that are not geometry: stop an offset short of the light.
    # The start moved up to eps towards the light (straight at it under normal incidence),
    # so the ray stops 2 eps short of ``dist``: a light touching or lying in a surface (a
    # panel flush with the ceiling) is not shadowed by that surface (it was, below it).
    if finite.all():
        far = np.subtract(dist, 2.0 * eps, dtype=np.float32)
    else:
        far = np.full(len(org), 1e37, np.float32)
        if finite.any():
            far[finite] = dist[finite] - 2.0 * eps[finite]
    # Rays to emissive meshes end on geometry of the BVH: aim from the offset origin at the
    # sampled point itself and stop short of it by its own offset, so that neither the
    # receiver nor the emitter shadows the ray.
    if any(g[5] for g in groups):
        aim = np.concatenate([np.full(len(g[2]), g[5]) for g in groups])
        light_point = org[aim] + dist[aim, None].astype(org.dtype) * dirs[aim]
        towards = light_point - start[aim]
        length = np.sqrt(np.einsum("ij,ij->i", towards, towards))
        dirs[aim] = towards / np.maximum(length, 1e-30)[:, None]
        far[aim] = length - 2.0 * accel.offset_distance(light_point)
    # Then eps along the ray as well: a point on a concave edge (the foot of a box on the
    # floor) is pushed along its own normal into the other surface's plane, where Embree
    # reports that surface at t = 0; moving along the ray leaves it (for rays that leave it).
    start += sampling.scale_rows(dirs, eps.astype(dirs.dtype))
    far -= eps.astype(far.dtype)
    if ray_log is not None:
        ray_log.append(("shadow", start, dirs, far))
    t0 = time.perf_counter()
    blocked = accel.occluded(start, dirs, far)
    traced = time.perf_counter() - t0

    # One term per light group: its weights for the rays that got through.
    visible = ~blocked
    # A light nearer than the offsets (an emitting wall met at a corner or an edge, within
    # 2 eps of the point): nothing can lie between the two, so it is visible, not dropped
    # (dropped, a point 1e-7 m from the edge of a glowing box got half its light).
    visible |= far <= 0
    terms = []
    offset = 0
    for group in groups:
        size = len(group[2])
        term = (group[0], group[3] * visible[offset:offset + size], group[4])
        terms.append(term + (group[1], group[6], group[7]) if with_directions else term)
        offset += size
    if stats is not None:
        stats["shadow_rays"] = stats.get("shadow_rays", 0) + len(org)
        stats["trace_seconds"] = stats.get("trace_seconds", 0.0) + traced
    _count_classes(stats, tally, len(org))
    return terms + (unshadowed if with_directions else [t[:3] for t in unshadowed])


def _hittable(light) -> str:
    """What of the light rays can hit: "mesh" (an emissive mesh, in the BVH), "world", "area"
    (not geometry, but rays after a delta bounce meet it: area lights and point / spot lights
    with a radius, ``lights.ray_visible``), or "" (suns, collimated and point lights: only
    light samples reach them)."""
    if getattr(light, "in_bvh", False):
        return "mesh"
    if getattr(light, "kind", "") == "world":
        return "world"
    return "area" if ray_visible(light) else ""


def _count_classes(stats, tally, traced):
    """Shadow-photon counters: rays saved against a plain call, classified pairs."""
    if stats is None or tally is None:
        return
    stats.setdefault("shadow_rays", 0)
    stats["shadow_rays_saved"] = stats.get("shadow_rays_saved", 0) + tally["plain"] - traced
    for name in ("lit", "umbra", "penumbra"):
        stats["shadow_" + name] = stats.get("shadow_" + name, 0) + tally[name]


def _classified_samples(groups, unshadowed, tally, shadow_map, li, light, x, n, offset_normals,
                        accel, rng, k, pts, p_sel, w, dist, weight, live, rgb=None):
    """The samples of sampled light ``li`` at points ``pts`` (sorted), by their pair's class:
    LIT terms go to ``unshadowed``, PENUMBRA samples (M per original) to ``groups``.
    ``rgb`` (len(pts), 3): each sample's radiance where the light has one per sample
    (``per_sample_rgb``; None: ``light.rgb``)."""

    def colour(rows):
        return light.rgb if rgb is None else rgb[rows]

    in_bvh = getattr(light, "in_bvh", False)
    hittable = _hittable(light)
    tally["plain"] += int(live.sum())
    # One class per (point, light): pts is sorted, so its distinct values are runs.
    first = np.empty(len(pts), bool)
    first[0] = True
    np.not_equal(pts[1:], pts[:-1], out=first[1:])
    points = pts[first]
    geo = n if offset_normals is None else offset_normals
    pair = shadow_map.classify(x[points], geo[points], li)
    cls = pair[np.cumsum(first) - 1]
    for name, c in zip(("lit", "umbra", "penumbra"), (LIT, UMBRA, PENUMBRA)):
        tally[name] += int(np.count_nonzero(pair == c))

    # LIT: visibility 1 without a ray, unless the direction leaves below the geometric surface
    # (shading normals): such a sample is traced as a plain call would.
    lit = np.flatnonzero(live & (cls == LIT))
    if len(lit):
        p = pts[lit]
        below = sampling.dot_rows(np.ascontiguousarray(geo[p], np.float64), w[lit]) <= 0
        # As the traced rays: a light closer than the ray offsets is not seen.
        near = dist[lit] <= 2.0 * accel.offset_distance(x[p])
        trace = below & ~near
        keep = ~below & ~near
        if keep.any():
            unshadowed.append((p[keep], weight[lit[keep]], colour(lit[keep]), w[lit[keep]],
                               hittable, li))
        if trace.any():
            t = lit[trace]
            groups.append((pts[t], w[t], dist[t], weight[t], colour(t), in_bvh, hittable, li))
    # UMBRA: no light, no ray. PENUMBRA: every sample of the pair (live or not: the class
    # must not depend on the sample's numbers) becomes M fresh stratified samples.
    pen = np.flatnonzero(cls == PENUMBRA)
    if len(pen) == 0:
        return
    m = int(max(1, shadow_map.penumbra_factor))
    if m == 1:
        t = pen[live[pen]]
        if len(t):
            groups.append((pts[t], w[t], dist[t], weight[t], colour(t), in_bvh, hittable, li))
        return
    p = np.repeat(pts[pen], m)
    u = sampling.stratified_2d(len(pen), m, rng).reshape(-1, 2)
    w_m, dist_m, weight_m, rgb_m = draw_light_samples(light, x, n, p, u)
    if rgb is None:
        rgb_m = light.rgb
    weight_m = weight_m / (np.repeat(p_sel[pen], m) * (k * m))
    ok = (weight_m > 0) & np.isfinite(weight_m)
    if ok.any():
        groups.append((p[ok], w_m[ok], dist_m[ok], weight_m[ok],
                       rgb_m if rgb is None else rgb_m[ok], in_bvh, hittable, li))
