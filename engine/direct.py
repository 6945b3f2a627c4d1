"""Direct illumination: irradiance from every light at arrays of shading points (seed ch. 7).

What it computes
    ``direct_irradiance(x, n, lights, accel, rng, light_samples)`` returns E (N, 3) [W/m^2]
    on the side of each surface that ``n`` points to, with visibility by shadow rays.
    Outgoing radiance of a Lambertian surface is then rho_d / pi * E.

    * Delta lights (point Eq. 7.1, spot, hard sun, collimated disk Eq. 7.2) cost one shadow
      ray each per point and have no sampling noise.
    * Sampled lights (area, emissive mesh, soft sun, world) share ``light_samples`` samples per
      point. Each sample first picks a light with probability proportional to its estimated
      unoccluded contribution at that point (``LightSet.selection_weights``), then a point /
      direction on it; the selection number and the 2-D light numbers are stratified over the
      point's samples. Estimate: sum_k f_k V_k / (p_select,k K).

Parameters
    ``light_samples`` (int, default 4): samples per point shared by the sampled lights.
    Shadow rays start ``accel.offset_origins`` off the surface and stop short of the light by
    the same relative offset, so lights touching surfaces do not shadow themselves.

All shadow rays of a call go to Embree in one batch.
"""
from __future__ import annotations

import time

import numpy as np

from . import sampling
from .lights import LightSet


def direct_irradiance(x: np.ndarray, n: np.ndarray, lights: LightSet, accel, rng: np.random.Generator,
                      light_samples: int = 4, stats: dict | None = None,
                      offset_normals: np.ndarray | None = None, ray_log: list | None = None) -> np.ndarray:
    """Irradiance (N, 3) at points ``x`` with unit normals ``n`` (facing the viewer).

    ``offset_normals`` (default ``n``) are the geometric normals used to push shadow-ray
    origins off the surface; ``stats`` receives ``shadow_rays`` and ``trace_seconds``.
    """
    terms = direct_terms(x, n, lights, accel, rng, light_samples, stats, offset_normals, ray_log)
    return irradiance_from_terms(terms, len(x))


def irradiance_from_terms(terms, count: int) -> np.ndarray:
    """Sum the ``direct_terms`` of ``count`` points into irradiance (count, 3)."""
    irradiance = np.zeros((count, 3))
    for target, scalar, rgb in terms:
        if target is not None:
            scalar = np.bincount(target, weights=scalar, minlength=count)
        irradiance += scalar[:, None] * np.asarray(rgb, np.float64)[None]
    return irradiance


def direct_terms(x: np.ndarray, n: np.ndarray, lights: LightSet, accel, rng: np.random.Generator,
                 light_samples: int = 4, stats: dict | None = None,
                 offset_normals: np.ndarray | None = None, ray_log: list | None = None) -> list:
    """Irradiance as a list of terms (target, scalar, rgb): term i adds ``scalar * rgb`` to
    points ``target`` (None: every point, in order). Callers that weight the irradiance per
    point (albedo, pixel) can then do so on scalars instead of (N, 3) arrays."""
    count = len(x)
    if count == 0 or lights.empty:
        return []

    # Each entry: (target points, directions, distances, scalar weights, rgb of the light).
    groups = []

    # Delta lights: one ray per light and lit point.
    for w, dist, weight, rgb in lights.delta_rays(x, n):
        live = weight > 0
        if live.all():
            groups.append((None, w, dist, weight, rgb, False))
        elif live.any():
            idx = np.nonzero(live)[0]
            groups.append((idx, w[idx], dist[idx], weight[idx], rgb, False))

    # Sampled lights: K stratified samples per point, light chosen by estimated contribution.
    if lights.sampled and light_samples > 0:
        k = int(light_samples)
        u2 = sampling.stratified_2d(count, k, rng)                     # (N, K, 2)
        u_pick = (np.argsort(rng.random((count, k)), axis=1) + rng.random((count, k))) / k
        probs = lights.selection_weights(x, n)                          # (N, L)
        cdf = np.cumsum(probs, axis=1)
        choice = np.minimum((cdf[:, None, :] < u_pick[..., None]).sum(axis=2), len(lights.sampled) - 1)
        point_of = np.repeat(np.arange(count), k)
        choice = choice.reshape(-1)
        u2 = u2.reshape(-1, 2)
        p_sel = probs[point_of, choice]
        for li, light in enumerate(lights.sampled):
            sel = np.nonzero(choice == li)[0]
            if len(sel) == 0:
                continue
            pts = point_of[sel]
            w, dist, weight = light.sample(x[pts], n[pts], u2[sel])
            weight = weight / (p_sel[sel] * k)
            live = (weight > 0) & np.isfinite(weight)
            if live.any():
                groups.append((pts[live], w[live], dist[live], weight[live], light.rgb,
                               getattr(light, 'in_bvh', False)))

    if not groups:
        return []
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
        org = x[target]
        normals = (n if offset_normals is None else offset_normals)[target]
    eps = accel.offset_distance(org)
    start = accel.offset_origins(org, normals, dirs, eps=eps)
    finite = np.isfinite(dist)
    # Rays to points and to lights that are not geometry: stop an offset short of the light.
    if finite.all():
        far = np.subtract(dist, eps, dtype=np.float32)
    else:
        far = np.full(len(org), 1e37, np.float32)
        if finite.any():
            far[finite] = dist[finite] - eps[finite]
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
    if ray_log is not None:
        ray_log.append(("shadow", start, dirs, far))
    t0 = time.perf_counter()
    blocked = accel.occluded(start, dirs, far)
    traced = time.perf_counter() - t0

    # One term per light group: its weights for the rays that got through.
    visible = ~blocked
    visible &= far > 0
    terms = []
    offset = 0
    for group in groups:
        size = len(group[2])
        terms.append((group[0], group[3] * visible[offset:offset + size], group[4]))
        offset += size
    if stats is not None:
        stats["shadow_rays"] = stats.get("shadow_rays", 0) + len(org)
        stats["trace_seconds"] = stats.get("trace_seconds", 0.0) + traced
    return terms
