"""The camera stage: radiance per pixel, in blocks of the frame on a thread pool.

What it computes
    ``render_camera(context, progress, cancelled)`` -> ``CameraImage``: the Combined image
    (linear radiance [W m^-2 sr^-1], flat (pixels, 3) float32 of the render window, top row
    first), the Emission, Direct and Indirect parts the passes ask for, the Cache usage shares
    and the batches' summed counters; with ``CameraContext.light_passes``, Cycles' light
    passes' sums (``passes.LightSums``: each path's light by its first bounce's kind, the first
    hit's albedos), nothing of which is computed otherwise.
    ``shade_block(context, index, pixels, camera)``  one batch: ``samples`` rays a pixel
        through the Blackman-Harris filter (``engine/camera.py``); at each hit
        * emission (surfaces and the world seen from the camera or in mirrors; camera rays,
          also those gone straight through transparent surfaces, see
          ``World.seen_by_camera``: ``world_along``);
        * at a diffuse hit, ``full`` mode: exact direct light (``engine/direct.py``) times
          rho_d / pi, plus the indirect estimator of ``context.indirect``
          (``engine/indirect.py``: cache, gather or photon map) at the samples that ask;
          ``photon-map`` mode: the photon map's estimate of all light;
        * at a mirror: the reflected ray goes on with throughput rho_s, up to
          ``max_specular_depth`` bounces;
        * at a material with glossy lobes (``bsdf.glossy_material``: Principled metal and
          specular layer, Glossy, Metallic; issue 23): their direct light from light samples
          weighted by f (``direct.direct_terms(with_directions=True)``), ``light_samples`` x
          a factor 1-8 that grows with the lobes' sharpness (``glossy_light_factor``,
          ``GLOSSY_REFERENCE_PEAK``) so that a sharp highlight is not left to a few samples
          that land on it; the diffuse
          below a Principled specular layer scaled by 1 - its albedo (Cycles' layering);
          then one ray by sampling a lobe: where the glossy lobes reflect more than the diffuse
          part the path goes on from it, elsewhere it ends and the ray is an emission probe
          that also reads the diffuse radiance where it lands (the irradiance precomputed at
          photons, ``surface_irradiance`` of the gather or cache estimator): the lobes'
          indirect light, one final-gather ray of the lobe (``_GlossyHits``; with indirect =
          photon, which stores no direct light, the irradiance estimate x albedo / pi as if
          it came evenly). Lights that the lobes' rays meet too (area lights, lights with a
          radius, emissive meshes, the world) reach each non-delta lobe by both strategies,
          weighted by Veach's power heuristic (multiple importance sampling, Veach 1997
          §9.2): light samples by p_light^2 / (p_light^2 + p_lobe^2) (``_GlossyHits.
          radiance``), the lobe's ray where it meets the light by the complement
          (``bsdf_strategy_weights``), p_light = light samples x selection x the light's
          ``solid_angle_pdf`` (``lights.LightSet.sample_density``), p_lobe = the lobe's pick
          probability x its pdf (``bsdf.sample_glossy``); suns and point lights only by light
          samples, delta lobes only by their rays. Photons and gather
          rays see these materials as ``MaterialTable.transport_*`` says: glossy lobes and
          glass sampled, a Principled layer as a specular share over a diffuse reduced by it;
        * glass (``bsdf.GlassLobe``: Glass, Refraction, Principled Transmission) is a lobe
          like the glossy ones that always goes on: eta = IOR entering a front face, 1 / IOR
          leaving by a back face, all its light from its own rays; at the path's first
          ``GLASS_SPLIT_DEPTH`` vertices smooth glass sends one ray each way (weights F and
          1 - F, ``lobes.SmoothGlass.branches``), deeper ones pick one by its Fresnel share;
        * materials whose nodes read Light Path Is Camera Ray see 1 at the camera path's
          hits (also after transparent surfaces), 0 everywhere else (``SurfaceParams(camera=
          ...)``);
        * caustics: at diffuse hits (``full`` mode) the caustic map's irradiance
          (``indirect.CausticEstimate``, ``context.caustics``) x rho_d / pi, in Indirect;
        * after a bounce, area lights and point and spot lights with a radius that the ray
          meets add their radiance (``lights.seen_light_radiance``): in full after a mirror
          or smooth glass (their glints), with the MIS weight after a glossy lobe.
        Materials are read through ``bsdf`` (``SceneSurfaces.params``). Pixels whose filter
        may hold an emitter's edge (``emitter_edges``) take their camera-seen emission from
        ``EDGE_SAMPLES_FACTOR`` x samples of their own (``edge_emission``): at 16 spp such a
        pixel is otherwise decided by how many samples land on an emitter 100x brighter than
        its surroundings.

Adaptive sampling (``noise_threshold`` > 0; ``final`` sets Cycles' default 0.01):
``shade_adaptive`` shades a block's samples in two halves, estimates each pixel's noise from
their difference (Cycles' estimate, taken as an RMS over the pixel's 3 x 3 neighbourhood)
and shades the noisy pixels again with 1, 3, 7 or 15 x the samples more
(``settings.ADAPTIVE_LEVELS``), at most half the block's samples again in all
(``ADAPTIVE_BUDGET``); a pixel's samples are then consecutive points of one scrambled (0,
2)-sequence (``sampling.sobol_02``). On the yard at ``final`` the error falls from 1.7-1.9 %
to 0.75-0.87 % (seeds 1-2) for 0.2-0.4 s more.

Blocks (``settings.camera_blocks``) are square parts of the full frame (64 x 64 pixels at
16 spp), each with its own random stream from (seed, block number): they run on the thread
pool (embreex and numpy release the GIL) and a fixed seed gives the same picture whatever the
scheduling or the thread count. Between batches ``progress(fraction, text)`` is called and
``cancelled()`` polled; a batch takes well under a second, so Esc acts quickly. Each batch
keeps its own counters, summed once it is done (no counter is shared between threads).
"""
from __future__ import annotations

import time
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field, replace

import numpy as np

from . import sampling
from .camera import pixel_rays
from .bsdf import (RoughDiffuseHits, layer_diffuse_factor, lobe_shares, reflection_albedo,
                   sample_glossy)
from .direct import direct_terms, irradiance_from_terms
from .passes import DIFFUSE, GLOSSY, LIGHT_PASS_NAMES, TRANSMISSION, LightSums
from .lights import SunCone, ray_visible, seen_light_radiance, seen_sun_radiance
from .settings import (ADAPTIVE_BUDGET, ADAPTIVE_LEVELS, TARGET_BATCH_SAMPLES,
                       RenderSettings, camera_blocks)
from .textures import STRAIGHT_ON, ray_after_bounce

# What each camera batch counts (rays, seconds of threads, look-ups); summed over batches.
BATCH_COUNTERS = ("camera_rays", "shadow_rays", "specular_rays", "glossy_rays", "paths_cut",
                  "trace_seconds", "queries",
                  "query_seconds", "estimate_seconds", "cache_interpolated", "cache_gathered",
                  "cache_local_records", "cache_local_interpolated", "strand_gathered",
                  "gather_rays",
                  "gather_points", "shadow_rays_saved", "shadow_lit", "shadow_umbra",
                  "shadow_penumbra", "edge_pixels", "edge_rays", "adaptive_pixels",
                  "adaptive_samples")
# Above this many materials the per-(pixel, material) histogram of the diffuse term gets big.
MAX_HISTOGRAM_MATERIALS = 64
EDGE_SAMPLES_FACTOR = 16    # an emitter edge's pixel: this x samples for its emission
# Extra texture look-ups per primary sample on a textured material (``supersample_textures``).
TEXTURE_SUPERSAMPLES = 7
# ``STRAIGHT_ON`` (``textures``): a bounce whose new direction has this cosine or more with
# the old one went on straight (a transparent surface): the ray stays a camera ray
# (``scene.World.camera``) and keeps its Light Path values (``textures.ray_after_bounce``).
# Camera-path vertices below this depth split smooth glass into a reflected and a refracted
# ray (``_GlossyHits.sample``); deeper ones pick one by its Fresnel share, as Cycles does.
GLASS_SPLIT_DEPTH = 2

# How glossy lobes take the light of the lights their own rays meet (area lights, lights with
# a radius, emissive meshes, the world): "mis", both strategies weighted by the power
# heuristic (Veach 1997 §9.2.2); "light", light samples alone; "bsdf", the lobes' rays alone
# (each strategy still takes what the other cannot reach). The last two are for tests.
GLOSSY_LIGHT_STRATEGY = "mis"

# Light samples at glossy hits scale with the lobes' sharpness. A lobe narrower than the light
# it reflects catches a share of area-uniform light samples about equal to its solid angle
# over the light's, so its highlight's noise grows as 1 / that solid angle (~ 1 / the lobe's
# peak density). A glossy hit takes ``light_samples`` x m, m = the power of two nearest its
# lobes' peak density (pick share x pdf towards the mirror direction) times their share of
# what the hit reflects (glossy over glossy + diffuse albedo: a highlight that is a few per
# cent of the pixel adds little noise to it), over the peak of GGX at Blender's default
# Roughness 0.5 (alpha 0.25) seen straight on, 1 / (4 pi alpha^2), and between 1 and
# ``GLOSSY_LIGHT_FACTOR_MAX``: a Principled dielectric keeps the base count, Roughness 0.3
# metal takes 8x. Multiple importance sampling counts the same m on both sides
# (``bsdf_strategy_weights``' ``light_counts``).
GLOSSY_REFERENCE_PEAK = 1.0 / (4.0 * np.pi * 0.25 ** 2)
GLOSSY_LIGHT_FACTOR_MAX = 8


def power_heuristic(p_this: np.ndarray, p_other: np.ndarray) -> np.ndarray:
    """Veach's power heuristic (beta = 2): p_this^2 / (p_this^2 + p_other^2) per sample (N,),
    1 where p_this is inf (a delta), 0 where p_this is 0 and p_other is not; densities [1/sr]
    with each strategy's sample count folded in."""
    p_this = np.asarray(p_this, np.float64)
    p_other = np.asarray(p_other, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = p_other / p_this
    out = 1.0 / (1.0 + ratio * ratio)
    out = np.where(np.isinf(p_this), 1.0, out)
    return np.where(np.isnan(out), np.where(p_other > 0, 0.0, 1.0), out)


def light_strategy_weights(p_light, p_bsdf, strategy: str | None = None) -> np.ndarray:
    """(N,) the weight of light samples drawn with densities ``p_light`` where the lobe's
    rays would come with ``p_bsdf`` (``GLOSSY_LIGHT_STRATEGY``). A light sample whose
    density comes out 0 (round-off at a light's edge: it was drawn) keeps weight 1."""
    strategy = strategy or GLOSSY_LIGHT_STRATEGY
    p_light = np.where(np.asarray(p_light) > 0, p_light, np.inf)
    if strategy == "light":
        return np.ones(len(p_light))
    if strategy == "bsdf":
        return (np.asarray(p_bsdf) <= 0).astype(np.float64)
    return power_heuristic(p_light, p_bsdf)


def bsdf_strategy_weights(context, which, pdf, points, normals, directions,
                          strategy: str | None = None, light_counts=None) -> np.ndarray:
    """(N,) the weight of rays drawn by a lobe with densities ``pdf`` (inf: a delta, weight 1;
    None: camera rays, weight 1) from ``points`` with shading ``normals``, that meet light
    ``which`` (N,) of ``context.lights.sampled`` (-1: none, weight 1) along ``directions``:
    the complement of ``light_strategy_weights`` against the density of that vertex's light
    samples (``LightSet.sample_density``; 0 below the normal, where a light sample gives
    nothing). ``light_counts`` (N,): the light samples each vertex took (default
    ``settings.light_samples``; glossy hits take more, ``_GlossyHits.light_counts``)."""
    count = len(which)
    if pdf is None:
        return np.ones(count)
    strategy = strategy or GLOSSY_LIGHT_STRATEGY
    out = np.ones(count)
    ask = np.flatnonzero((which >= 0) & np.isfinite(pdf))
    if len(ask) == 0:
        return out
    x, n = points[ask], normals[ask]
    w = np.asarray(directions[ask], np.float64)
    p_light = np.zeros(len(ask))
    counts = (np.full(len(ask), context.settings.light_samples) if light_counts is None
              else np.asarray(light_counts)[ask])
    for index in np.unique(which[ask]):
        sel = np.flatnonzero(which[ask] == index)
        p_light[sel] = context.lights.sample_density(x[sel], n[sel], w[sel], int(index),
                                                     counts[sel])
    p_light *= sampling.dot_rows(n, w) > 0
    if strategy == "light":
        out[ask] = (p_light <= 0).astype(np.float64)
    elif strategy == "bsdf":
        out[ask] = 1.0
    else:
        out[ask] = power_heuristic(pdf[ask], p_light)
    return out
PART_NAMES = ("Emission", "Direct", "Indirect")


@dataclass
class CameraContext:
    """What every batch of one render shares (read only)."""

    scene: object
    surfaces: object               # surfaces.SceneSurfaces
    accel: object
    lights: object                 # lights.LightSet
    settings: RenderSettings
    indirect: object = None        # an estimator of engine/indirect.py, or None
    shadow_map: object = None      # shadow_photons.ShadowPhotonMap, or None
    track_usage: bool = False      # the Cache usage pass asks for per-pixel shares
    ray_log: list | None = None    # benchmarks: every traced batch of rays
    edges: np.ndarray | None = None   # emitter-edge pixels of the full frame (emitter_edges)
    caustics: object = None        # indirect.CausticEstimate, or None (no caustic map)
    light_passes: bool = False     # sum Cycles' light passes (``engine/passes.py``)


@dataclass
class CameraImage:
    image: np.ndarray                           # (pixels, 3) float32, the window
    parts: dict = field(default_factory=dict)   # "Emission" / "Direct" / "Indirect" asked for
    usage: np.ndarray | None = None             # (pixels, 2): interpolated, gathered shares
    light: np.ndarray | None = None             # (11, pixels, 3): LightSums.stacked, or None
    totals: dict = field(default_factory=dict)  # BATCH_COUNTERS summed, batch_seconds
    batches: int = 0
    done: int = 0
    cancelled: bool = False
    seconds: float = 0.0


def add_to_pixels(pixels: np.ndarray, pixel_of: np.ndarray | None, values: np.ndarray):
    """pixels[pixel_of[i]] += values[i] (values (n, 3)); pixel_of None: all samples in order."""
    if pixel_of is None:
        pixels += values.reshape(len(pixels), -1, 3).sum(axis=1)
        return
    for c in range(3):
        pixels[:, c] += np.bincount(pixel_of, weights=values[:, c], minlength=len(pixels))


def render_camera(context: CameraContext, wanted_parts, pool, progress=None, cancelled=None,
                  skip: bool = False) -> CameraImage:
    """Every block of the render window on ``pool``, at most two per worker in flight;
    ``wanted_parts``: which of ``PART_NAMES`` to keep; ``skip``: render nothing (an earlier
    stage was cancelled)."""
    scene, settings = context.scene, context.settings
    width, height = scene.camera.window_size
    pixel_count = width * height
    blocks = camera_blocks(scene.camera, settings.samples)
    out = CameraImage(image=np.zeros((pixel_count, 3), np.float32), batches=len(blocks),
                      parts={name: np.zeros((pixel_count, 3), np.float32)
                             for name in PART_NAMES if name in wanted_parts},
                      usage=np.zeros((pixel_count, 2)) if context.track_usage else None,
                      light=np.zeros((len(LIGHT_PASS_NAMES), pixel_count, 3))
                      if context.light_passes else None,
                      totals={**dict.fromkeys(BATCH_COUNTERS, 0), "batch_seconds": 0.0})
    label = "Rendering" if settings.mode == "full" else "Photon map"

    def tell(text):
        if progress is not None:
            progress(out.done / max(len(blocks), 1), text)

    t0 = time.perf_counter()
    if not skip:
        context = replace(context, edges=emitter_edges(scene, context.accel, context.surfaces,
                                                       settings.filter_width, context.lights))
    tell(f"{label}: 0/{len(blocks)} batches")
    pending = {}
    queue = [] if skip else list(reversed(blocks))

    def submit():
        while queue and len(pending) < 2 * settings.worker_count:
            block = queue.pop()
            future = pool.submit(shade_adaptive, context, block)
            pending[future] = block

    submit()
    while pending:
        finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
        for future in finished:
            block = pending.pop(future)
            parts, batch_stats, batch_usage, batch_light = future.result()
            src, dst = block.source, block.target
            out.image[dst] = (parts[0] + parts[1] + parts[2])[src]
            for index, name in enumerate(PART_NAMES):
                if name in out.parts:
                    out.parts[name][dst] = parts[index][src]
            if out.usage is not None:
                out.usage[dst] = batch_usage[src]
            if out.light is not None:
                out.light[:, dst] = batch_light[:, src]
            for key in BATCH_COUNTERS:
                out.totals[key] += batch_stats[key]
            out.totals["batch_seconds"] += batch_stats["seconds"]
            out.done += 1
        tell(f"{label}: {out.done}/{len(blocks)} batches")
        if cancelled is not None and cancelled():
            out.cancelled = True
            queue.clear()
        submit()
    out.seconds = time.perf_counter() - t0
    return out


def shade_block(context: CameraContext, batch: int, pixels: int, camera, subset=None,
                sequence=None):
    """Radiance for the ``pixels`` of one block (``camera``: the frame's camera bordered to
    it), mean over their samples, by kind: (3, pixels, 3) for emission, direct light and
    indirect light (in ``photon-map`` mode: the whole estimate); their sum is Combined. Also
    the batch's counters and, with ``track_usage``, (pixels, 2) shares of samples
    interpolated from cache records and gathered afresh. ``subset``: only these of the
    block's pixels (row-major indices; the results have one row each, in their order): the
    extra samples of adaptive sampling (``shade_adaptive``). ``sequence``: (block index,
    first sample): the samples' positions in their pixels are the (0, 2)-sequence's points
    from that index on, scrambled per pixel of that block (``sampling.sobol_02``), instead
    of a jittered set of their own."""
    scene, surfaces, accel = context.scene, context.surfaces, context.accel
    settings, ray_log, photon = context.settings, context.ray_log, context.indirect
    materials = surfaces.materials
    stats = dict.fromkeys(BATCH_COUNTERS, 0)
    stats["seconds"] = 0.0
    direct_light = settings.mode == "full"
    # Glossy lobes where the path ends take their indirect light from their probe rays' hits
    # (``surface_irradiance`` of the estimator: the gather's and the cache's precomputed
    # irradiance); the photon estimate at the hit has no direct light stored, so it keeps the
    # uniform approximation.
    probe_lookup = direct_light and hasattr(photon, "surface_irradiance")
    started = time.perf_counter()
    rng = sampling.rng_for(settings.seed, sampling.STREAM_CAMERA, batch)
    spp = settings.samples
    block_pixels = np.arange(pixels) if subset is None else np.asarray(subset, np.int64)
    positions = None
    if sequence is not None:
        block_index, first = sequence
        scramble = sampling.rng_for(settings.seed, sampling.STREAM_SEQUENCE, block_index) \
            .integers(0, 1 << 32, (pixels, 2), dtype=np.uint32)[block_pixels]
        index = first + np.arange(spp)
        positions = sampling.sobol_02(np.tile(index, len(block_pixels)),
                                      np.repeat(scramble, spp, axis=0))
    if subset is None and positions is None:
        origins, directions, tmax = pixel_rays(camera, 0, pixels, spp, rng,
                                               settings.filter_width)
    else:
        origins, directions, tmax = pixel_rays(camera, 0, 0, spp, rng, settings.filter_width,
                                               pixels=block_pixels, positions=positions)
    pixels = len(block_pixels)
    count = len(origins)
    # Sums of the samples' radiance per pixel, by kind (the Emission, Direct and Indirect
    # passes; Combined is their sum): every contribution goes straight to its pixel.
    parts = np.zeros((3, pixels, 3))
    emission_sums, direct_sums, indirect_sums = parts
    # Cache usage pass: per pixel, samples interpolated from records and samples gathered.
    usage = np.zeros((pixels, 2)) if context.track_usage else None
    # Cycles' light passes: each path's contributions by its first bounce's kind.
    light = LightSums(pixels, spp) if context.light_passes else None
    follows = materials.has_specular or materials.has_glossy
    throughput = np.ones((count, 3), np.float32) if follows else None
    # Per ray after a bounce: the density its lobe drew it with (``bsdf.sample_glossy``: lobe
    # pick x lobe pdf; inf after a delta lobe or a mirror) and the vertex it left (point,
    # shading normal): the lights it meets count with the BSDF's weight of multiple importance
    # sampling (``bsdf_strategy_weights``) against that vertex's light samples (``mis_count``
    # of them: ``_GlossyHits.light_counts``).
    mis_pdf = mis_x = mis_n = mis_count = None
    # Per ray: an emission probe (from a glossy hit where the path ended, ``_GlossyHits``):
    # it counts the world or emitter it meets and is not shaded.
    probes = None
    ray_of = np.arange(count)
    # Rays after a bounce see the lights that are not geometry (area lights, lights with a
    # radius: ``lights.ray_visible``); camera rays those with Visibility > Camera on.
    ray_lights = any(ray_visible(light) for light in context.lights.sampled)
    camera_lights = _lights_in_frame(context.lights)
    # Suns with an angle: their discs, for rays that leave the scene straight from the camera
    # (Visibility > Camera on) or after a delta bounce (``seen_sun_radiance``).
    suns = any(isinstance(light, SunCone) for light in context.lights.sampled)
    # Where the world's or a material's nodes tell camera rays apart (``World.camera``,
    # Light Path Is Camera Ray), each ray after the first hit carries whether it is still a
    # camera ray: it went on straight through transparent surfaces only, which keep Cycles'
    # camera flag.
    track_camera = scene.world.camera is not None or materials.reads_light_path
    camera_rays = cam = None
    # Where a material's nodes read Light Path, each ray after the first hit carries the
    # other outputs' values too (``textures.ray_after_bounce``: Cycles' flags and depths).
    path_ray = path_values = None
    # Per ray after the first bounce, with the light passes: its path's first-bounce kind.
    path_kind = kinds = None
    if photon is not None and photon.lookups < spp:
        first_lookup = rng.integers(0, spp, pixels)
    # Emitter edges: their camera-seen emission is estimated apart (``edge_emission``).
    edge_pixels, own_emission = None, None
    if context.edges is not None:
        x0, y0, x1, y1 = camera.border
        row, col = np.divmod(block_pixels, x1 - x0)
        marked = context.edges[camera.resolution[1] - 1 - (y1 - 1 - row), x0 + col]
        if marked.any():
            edge_pixels = np.flatnonzero(marked)
            own_emission = ~np.repeat(marked, spp)        # per primary ray
    for depth in range(settings.max_specular_depth + 1):
        if len(ray_of) == 0:
            break
        if ray_log is not None:
            ray_log.append(("camera" if depth == 0 else "specular", origins, directions, tmax))
        t0 = time.perf_counter()
        _t, prim, bu, bv = accel.intersect(origins, directions, tmax)
        stats["trace_seconds"] += time.perf_counter() - t0
        stats["camera_rays" if depth == 0 else "specular_rays"] += len(origins)
        hit = prim >= 0
        if depth == 0 and camera_lights:
            # Lights in frame, as Cycles draws them: their radiance adds to the pixel and the
            # ray goes on (a light is not a surface). Nothing else samples them from here.
            glint = seen_light_radiance(context.lights, origins, directions,
                                        np.where(hit, _t, np.inf), camera=True)
            seen = np.flatnonzero(glint.any(axis=1))
            if len(seen):
                value = glint[seen]
                if own_emission is not None:         # edge pixels: ``edge_emission`` has it
                    value = value * own_emission[ray_of[seen]][:, None]
                add_to_pixels(emission_sums, ray_of[seen] // spp, value)
                if light is not None:
                    light.add_seen(ray_of[seen], value, world=False)
        if depth > 0 and ray_lights:
            # Area lights and lights with a radius seen after a bounce: after a mirror or
            # smooth glass their glint (no light sample reaches them through a delta lobe),
            # after a glossy lobe weighted against its light samples.
            t_seen = np.where(hit, _t, np.inf)
            glint, which = seen_light_radiance(context.lights, origins, directions, t_seen,
                                               with_index=True)
            seen = np.flatnonzero(which >= 0)
            if len(seen):
                value = glint[seen] * throughput[seen]
                value *= bsdf_strategy_weights(context, which[seen], mis_pdf[seen],
                                               mis_x[seen], mis_n[seen], directions[seen],
                                               light_counts=mis_count[seen])[:, None]
                add_to_pixels(emission_sums, ray_of[seen] // spp, value)
                if light is not None:
                    light.add(ray_of[seen], value, direct=depth == 1, kind=path_kind[seen])
        all_hit = bool(hit.all())
        seen_world = None
        if not all_hit:
            seen_world = world_along(scene.world, directions[~hit],
                                     depth == 0 or (camera_rays is not None
                                                    and camera_rays[~hit]))
        if seen_world is not None:
            missed = seen_world if throughput is None else throughput[~hit] * seen_world
            if depth == 0 and own_emission is not None:
                missed = missed * own_emission[ray_of[~hit]][:, None]
            if mis_pdf is not None:
                gone = ~hit
                missed = missed * bsdf_strategy_weights(
                    context, np.full(int(gone.sum()), context.lights.world_index),
                    mis_pdf[gone], mis_x[gone], mis_n[gone], directions[gone],
                    light_counts=mis_count[gone])[:, None]

            add_to_pixels(emission_sums, ray_of[~hit] // spp, missed)
            if light is not None:
                if depth == 0:
                    light.add_seen(ray_of[~hit], missed, world=True)
                else:
                    light.add(ray_of[~hit], missed, direct=depth == 1, kind=path_kind[~hit])
        if suns and not all_hit:
            gone = np.flatnonzero(~hit)
            if mis_pdf is not None:              # after a glossy lobe its light samples count
                gone = gone[np.isinf(mis_pdf[gone])]
            disc = seen_sun_radiance(context.lights, directions[gone], camera=depth == 0)
            inside = disc.any(axis=1)
            gone, disc = gone[inside], disc[inside]
            if len(gone):
                value = disc if throughput is None else throughput[gone] * disc
                if depth == 0 and own_emission is not None:
                    value = value * own_emission[ray_of[gone]][:, None]
                add_to_pixels(emission_sums, ray_of[gone] // spp, value)
                if light is not None:
                    if depth == 0:
                        light.add_seen(ray_of[gone], value, world=False)
                    else:
                        light.add(ray_of[gone], value, direct=depth == 1, kind=path_kind[gone])
        if not hit.any():
            break
        if not all_hit:
            prim, bu, bv, t_hit = prim[hit], bu[hit], bv[hit], _t[hit]
            d, o, rays = directions[hit], origins[hit], ray_of[hit]
            thr = None if throughput is None else throughput[hit]
            probing = None if probes is None else probes[hit]
            cam = None if camera_rays is None else camera_rays[hit]
            path_values = None if path_ray is None else {k: v[hit] for k, v in path_ray.items()}
            kinds = None if path_kind is None else path_kind[hit]
            if mis_pdf is not None:
                mis_pdf, mis_x, mis_n = mis_pdf[hit], mis_x[hit], mis_n[hit]
                mis_count = mis_count[hit]
        else:
            t_hit, d, o, rays, thr = _t, directions, origins, ray_of, throughput
            probing = probes
            cam = camera_rays
            path_values = path_ray
            kinds = path_kind
        # Samples in order (primary rays, all hit): pixel sums need no index.
        in_order = depth == 0 and all_hit
        pixel_of = None if in_order else rays // spp
        x = sampling.scale_rows(d, t_hit)
        x += o
        ng, ns, front = surfaces.normals(prim, bu, bv, d)
        strands = getattr(surfaces, "strands", None)
        if strands is not None:
            # Hair: from the round surface the tube stands for, rays leave off its normal.
            on = np.flatnonzero(strands[prim])
            if len(on):
                x[on] = surfaces.strand_points(prim[on], bu[on], bv[on], x[on])
                ns[on] = ng[on] = surfaces.strand_normals(prim[on], bu[on], bv[on], d[on])
        surface = surfaces.params(prim, bu, bv, d, True if depth == 0 else cam,
                                  ray=None if not materials.reads_light_path else
                                  {**(path_values or {}), "Ray Length": t_hit})
        if depth == 0 and not materials.constant_per_material:
            t0 = time.perf_counter()
            supersample_textures(context, camera, batch, surface, prim, rays, spp, stats,
                                 subset)
            stats["trace_seconds"] += time.perf_counter() - t0

        if materials.has_emission:
            emitted = surface.emitted_radiance * (front | surface.both_sides)[:, None]
            if depth == 0 and own_emission is not None:
                emitted *= own_emission[rays][:, None]
            if mis_pdf is not None:
                lit = np.flatnonzero(np.any(emitted > 0, axis=1))
                if len(lit):
                    emitted[lit] *= bsdf_strategy_weights(
                        context, context.lights.emitter_of_triangle[prim[lit]], mis_pdf[lit],
                        mis_x[lit], mis_n[lit], d[lit], light_counts=mis_count[lit])[:, None]
            add_to_pixels(emission_sums, pixel_of, emitted if thr is None else thr * emitted)
            if light is not None:
                if depth == 0:
                    light.add_seen(rays, emitted if thr is None else thr * emitted, world=False)
                else:
                    light.add(rays, thr * emitted, direct=depth == 1, kind=kinds)
        if probing is not None and probing.any() and probe_lookup:
            # Emission probes from glossy hits where the path ended: the radiance of the
            # surface they meet is the glossy lobe's indirect light (one final-gather ray of
            # the lobe, Jensen 1996): the irradiance precomputed at photons there (all light
            # at that point) x rho_d / pi (below a layer x 1 - E_layer at this ray's angle)
            # plus, for its own glossy lobes, x their albedo / pi (as if it came evenly: the
            # second bounce, where that approximation costs least).
            met = np.flatnonzero(probing & surface.is_diffuse)
            if len(met):
                wo_met, n_met = -d[met].astype(np.float64), ng[met].astype(np.float64)
                rho = surface.diffuse_over_pi[met]
                if materials.has_layer:
                    rho = rho * layer_diffuse_factor(materials, surface.material[met], wo_met,
                                                     n_met)
                per_hit = surface.lobe_inputs
                rho = rho + reflection_albedo(materials, surface.material[met], wo_met, n_met,
                                              None if per_hit is None else per_hit[met]) / np.pi
                value = photon.surface_irradiance(x[met], ng[met]) * rho * thr[met]
                if materials.has_translucent:
                    value += (photon.surface_irradiance(x[met], -ng[met]) * thr[met]
                              * surface.translucent[met] / np.pi)
                add_to_pixels(indirect_sums, rays[met] // spp, value)
                if light is not None:
                    light.add(rays[met], value, direct=False, kind=kinds[met])
        if probing is not None and probing.any():
            shaded = np.flatnonzero(~probing)
            if len(shaded) == 0:
                break
            prim, bu, bv, d, o, rays = (a[shaded] for a in (prim, bu, bv, d, o, rays))
            x, ng, ns, front = x[shaded], ng[shaded], ns[shaded], front[shaded]
            thr = thr[shaded]
            surface = surface.subset(shaded)
            pixel_of = rays // spp
            cam = None if cam is None else cam[shaded]
            kinds = None if kinds is None else kinds[shaded]

        # A node-driven Normal (a Normal Map) shades what the camera path computes here:
        # direct light and the glossy and glass lobes; the indirect estimates (cache, gather,
        # photons, caustics) keep the smooth normal ``ns_smooth`` their records were made at.
        ns_smooth = ns
        if materials.has_shading_normals:
            ns = materials.shading_normals(surface.material, prim, bu, bv, x, ns, ng, -d,
                                           front, context.scene.camera.footprint(t_hit))

        glossy = None
        if materials.has_glossy:
            glossy = _GlossyHits(materials, surface, -d, ns, front,
                                 split=light is not None and depth == 0,
                                 light_samples=settings.light_samples)
            if glossy.count == 0:
                glossy = None

        # Oren-Nayar diffuse (Principled Diffuse Roughness, Diffuse BSDF Roughness).
        rough = None
        if materials.has_oren_nayar:
            rough = RoughDiffuseHits(materials, surface, -d, ns)
            if rough.count == 0:
                rough = None

        if light is not None and depth == 0:
            _first_hit_colors(light, rays, surface, glossy)

        # Diffuse reflection (translucent closures, which pass light from the far side, are
        # shaded apart: ``_shade_translucent``).
        diffuse = surface.reflects_diffuse if materials.has_translucent else surface.is_diffuse
        if diffuse.all():
            idx = slice(None)
        elif diffuse.any():
            idx = np.nonzero(diffuse)[0]
        else:
            idx = None
        if idx is not None and photon is not None:
            # The indirect estimate at the diffuse hits of the samples that ask for it.
            ask = idx if isinstance(idx, np.ndarray) else np.arange(len(prim))
            if photon.lookups < spp:
                ask = _asking(ask, rays[ask], spp, first_lookup, photon.lookups)
            if len(ask):
                t0 = time.perf_counter()
                e = photon.irradiance(x[ask], ns_smooth[ask], ng[ask], rng, stats,
                                      strands=None if strands is None else strands[prim[ask]])
                stats["estimate_seconds"] += time.perf_counter() - t0
                covered = stats.pop("covered_mask", None)
                if usage is not None and covered is not None:
                    owner = rays[ask] // spp
                    usage[:, 0] += np.bincount(owner[covered], minlength=len(usage))
                    usage[:, 1] += np.bincount(owner[~covered], minlength=len(usage))
                e *= (spp / min(photon.lookups, spp))
                for part, is_direct in _estimate_parts(e):
                    _add_irradiance(part, ask, surface, glossy, thr, rays, spp, depth,
                                    direct_sums if is_direct else indirect_sums, light,
                                    direct_light and not probe_lookup, rough, kinds,
                                    is_direct=is_direct)
        if idx is not None and direct_light and context.caustics is not None:
            _shade_caustics(context, stats, idx, x, ns_smooth, surface, glossy, thr, rays, spp,
                            depth, indirect_sums, light, probe_lookup, rough, kinds)
        if idx is not None and direct_light:
            layer = None if glossy is None else glossy.diffuse_factor
            lambert = idx
            if rough is not None:
                every = np.arange(len(x)) if isinstance(idx, slice) else idx
                _shade_direct_rough(context, stats, rng, depth, every[rough.row_of[every] >= 0],
                                    x, ns, ng, thr, rays, direct_sums, layer, light, rough,
                                    kinds)
                lambert = every[rough.row_of[every] < 0]
            if isinstance(lambert, slice) or len(lambert):
                _shade_direct(context, stats, rng, depth, lambert, x, ns, ng, surface, thr,
                              rays, pixel_of, direct_sums, layer, light, kinds)
        if glossy is not None:
            _shade_glossy_direct(context, stats, rng, glossy, x, ns, ng, thr, rays, spp,
                                 direct_sums, light, depth, kinds)
        if materials.has_translucent:
            _shade_translucent(context, stats, rng, depth, x, ns, ns_smooth, ng, surface, thr,
                               rays, spp, parts, light,
                               None if photon is None or photon.lookups >= spp
                               else first_lookup, kinds)

        if not follows:
            break
        mirror = surface.is_specular
        if glossy is not None:
            mirror = mirror & ~glossy.mask
        if depth == settings.max_specular_depth:
            stats["paths_cut"] += int(mirror.sum()) + (0 if glossy is None else glossy.count)
            break
        if not mirror.any() and glossy is None:
            break
        idx = np.nonzero(mirror)[0]
        directions, weight, mis_pdf = surface.subset(idx).bsdf().mirror.sample(-d[idx], ns[idx])
        mis_count = np.full(len(idx), settings.light_samples)
        if glossy is not None:
            # Smooth glass seen first splits: one ray reflects, one refracts, each with its
            # Fresnel share, so that a light's glint in the glass (a few percent reflected,
            # picked by a few percent of the samples) is not a scatter of fireflies.
            g_dirs, g_weight, g_keep, g_pdf = glossy.sample(
                rng, split_glass=depth < GLASS_SPLIT_DEPTH)
            glossy_index = np.concatenate([glossy.index, glossy.index[glossy.twin_of]])
            stats["glossy_rays"] += len(glossy_index)
            mirrors = len(idx)
            keep = np.concatenate([np.ones(mirrors, bool), g_keep])
            idx = np.concatenate([idx, glossy_index])[keep]
            directions = np.concatenate([directions, g_dirs.astype(directions.dtype)])[keep]
            weight = np.concatenate([weight, g_weight])[keep]
            mis_pdf = np.concatenate([mis_pdf, g_pdf])[keep]
            mis_count = np.concatenate([mis_count, glossy.light_counts[glossy_index]])[keep]
            probes = np.concatenate([np.zeros(mirrors, bool),
                                     ~glossy.goes_on[glossy_index]])[keep]
        else:
            probes = None
        if len(idx) == 0:
            break
        mis_x, mis_n = x[idx].astype(np.float64), ns[idx].astype(np.float64)
        origins = accel.offset_origins(x[idx], ng[idx], directions)
        tmax = None
        throughput = thr[idx] * weight
        ray_of = rays[idx]
        if track_camera:
            was = np.ones(len(idx), bool) if depth == 0 else cam[idx]
            camera_rays = was & (sampling.dot_rows(directions, d[idx]) > STRAIGHT_ON)
        if materials.reads_light_path:
            path_ray = ray_after_bounce(
                None if path_values is None else {k: v[idx] for k, v in path_values.items()},
                directions, d[idx], ns[idx], np.isinf(mis_pdf))
        if light is not None:
            # Each path's first bounce's kind (the passes its later light goes to): through
            # the surface (glass refracting) Transmission, else (mirror, glossy lobes, glass
            # reflecting) Glossy; kept per ray, as a split sample has one path of each.
            if depth == 0:
                through = sampling.dot_rows(directions, ns[idx]) < 0
                path_kind = np.where(through, TRANSMISSION, GLOSSY).astype(np.int8)
            else:
                path_kind = kinds[idx]

    if edge_pixels is not None:
        seen, traced = edge_emission(context, camera, batch, block_pixels[edge_pixels],
                                     split=light is not None)
        if light is not None:
            seen, seen_world = seen
            light.emit[edge_pixels] += (seen - seen_world) * spp
            light.env[edge_pixels] += seen_world * spp
        emission_sums[edge_pixels] += seen * spp
        stats["edge_pixels"] += len(edge_pixels)
        stats["edge_rays"] += traced
    parts /= spp
    if usage is not None:
        usage /= spp
    stats["seconds"] = time.perf_counter() - started
    return parts, stats, usage, None if light is None else light.stacked()


def shade_adaptive(context: CameraContext, block):
    """``shade_block`` for one block (``settings.CameraBlock``), with adaptive sampling where
    ``noise_threshold`` > 0 (Cycles' adaptive sampling, in one refining step): the block's
    samples in two halves, each pixel's noise estimated from their difference as Cycles
    does (sum over the channels of |I - A| over sqrt(sum of I), I the mean of all samples,
    A of one half), and the pixels above the threshold shaded again with ``ADAPTIVE_LEVELS``
    x samples more, the least level that brings their noise to the threshold if noise falls
    as 1 / sqrt(samples) (the largest where none does); where that would take more than
    ``ADAPTIVE_BUDGET`` x the block's samples, the highest level is lowered until all fit
    and what is left lifts the noisiest a level (many pixels a little better rather than a
    few perfect). A pixel's samples, halves and extra ones, are consecutive points of one
    (0, 2)-sequence scrambled for it (``sampling.sobol_02``), so all of them together are as
    well spread over the pixel as one stratified set: drawn as independent jittered sets
    instead, 16 + 48 samples left the yard's edge pixels 1.3x noisier than 64 in one set.
    Each pixel is the mean of all its samples (as in Cycles, the extra samples go where the
    first ones happened to disagree, a bias that falls with their number). Returns what
    ``shade_block`` returns."""
    settings = context.settings
    spp = settings.samples
    if settings.noise_threshold <= 0 or spp < 2:
        return shade_block(context, block.index, block.pixels, block.camera)
    half = spp // 2
    runs = []
    for part, samples in enumerate((half, spp - half)):
        run = shade_block(replace(context, settings=replace(settings, samples=samples)),
                          block.index + (part << 32), block.pixels, block.camera,
                          sequence=(block.index, part * half))
        runs.append((None, samples, run))
    image_a = runs[0][2][0].sum(axis=0)
    image_b = runs[1][2][0].sum(axis=0)
    mean = (half * image_a + (spp - half) * image_b) / spp
    # Cycles' estimate at each pixel, then its RMS over the pixel's 3 x 3 neighbourhood: a
    # pixel's own samples then have little say in whether it gets more (judged by its own
    # estimate alone, the pixels whose samples happened to come out dark looked noisier
    # and only they were corrected: +0.35 % on the test's box yard, at a budget of 1).
    width = block.camera.border[2] - block.camera.border[0]
    own = np.abs(mean - image_a).sum(axis=1) / (1e-4 + np.sqrt(np.maximum(mean.sum(axis=1),
                                                                           0.0)))
    noise = np.sqrt(_box_3x3((own ** 2).reshape(-1, width)).reshape(-1))
    # Extra samples that bring a pixel's noise to the threshold, in levels of ``spp``.
    need = spp * ((noise / settings.noise_threshold) ** 2 - 1.0)
    levels = np.asarray(ADAPTIVE_LEVELS) * spp
    level = np.minimum(np.searchsorted(levels, need), len(levels) - 1)
    wanted = np.flatnonzero(noise > settings.noise_threshold)
    wanted = wanted[np.argsort(-noise[wanted], kind="stable")]
    budget = ADAPTIVE_BUDGET * spp * block.pixels
    # Over the budget: the highest level lowered until every wanted pixel fits (many pixels
    # a little better, not a few perfect), then the noisiest first.
    for cap in range(len(levels) - 1, -1, -1):
        extra = levels[np.minimum(level[wanted], cap)]
        if extra.sum() <= budget:
            break
    if cap < len(levels) - 1:
        # What the cap leaves of the budget lifts the noisiest a level further.
        lifted = levels[np.minimum(level[wanted], cap + 1)]
        room = np.cumsum(lifted - extra) <= budget - extra.sum()
        extra = np.where(room, lifted, extra)
    keep = np.cumsum(extra) <= budget
    wanted, extra = wanted[keep], extra[keep]
    for step, samples in enumerate(levels):
        chosen = np.sort(wanted[extra == samples])
        chunk = max(1, TARGET_BATCH_SAMPLES // int(samples))
        for start in range(0, len(chosen), chunk):
            subset = chosen[start:start + chunk]
            run = shade_block(replace(context, settings=replace(settings, samples=int(samples))),
                              block.index + ((2 + step) << 32) + (start << 40), block.pixels,
                              block.camera, subset=subset, sequence=(block.index, spp))
            runs.append((subset, int(samples), run))
    # Every pixel's mean over all its samples.
    parts, counts = np.zeros((3, block.pixels, 3)), np.zeros(block.pixels)
    usage = None if runs[0][2][2] is None else np.zeros((block.pixels, 2))
    light = None if runs[0][2][3] is None else np.zeros(runs[0][2][3].shape)
    stats = dict.fromkeys(BATCH_COUNTERS, 0)
    stats["seconds"] = 0.0
    for subset, samples, (r_parts, r_stats, r_usage, r_light) in runs:
        at = slice(None) if subset is None else subset
        parts[:, at] += samples * r_parts
        counts[at] += samples
        if usage is not None:
            usage[at] += samples * r_usage
        if light is not None:
            light[:, at] += samples * r_light
        for key in BATCH_COUNTERS:
            stats[key] += r_stats.get(key, 0)
        stats["seconds"] += r_stats["seconds"]
    stats["adaptive_pixels"] = len(wanted)
    stats["adaptive_samples"] = int(extra.sum())
    parts /= counts[None, :, None]
    if usage is not None:
        usage /= counts[:, None]
    if light is not None:
        light /= counts[None, :, None]
    return parts, stats, usage, light


def _box_3x3(values: np.ndarray) -> np.ndarray:
    """The mean of each (H, W) value's 3 x 3 neighbourhood (edges repeated): scipy's
    ``uniform_filter(size=3, mode="nearest")``, in numpy, as scipy is not bundled with the
    add-on (blender_manifest.toml)."""
    h, w = values.shape
    padded = np.pad(values, 1, mode="edge")
    return sum(padded[i:i + h, j:j + w] for i in range(3) for j in range(3)) / 9.0


def emitter_edges(scene, accel, surfaces, filter_width: float, lights=None):
    """(height, width) bool over the full frame, row 0 at the top: the pixels whose filter
    footprint may hold an edge of an emitter or of a light in frame (``lights``: the scene's
    ``LightSet``) seen by the camera, or None (no emission, no light in frame).

    An emitter is far brighter than what lies beside it (the Cornell box's light quad: 50
    against 0.2-0.5), so the share of a pixel's samples that land on it decides the pixel:
    at 16 samples, in steps of 1/16 of the emitter's radiance. Measured on the original
    Cornell box at ``final`` (24 seeds): the 4 x 4 image region holding the light has a
    relative SD of 1.9-2.1 % a render from its emission alone (unbiased: mean -0.14 and
    -0.30 %, SE 0.4 %), while every other region's whole SD is 0.1-0.9 %. The camera gives
    these pixels ``EDGE_SAMPLES_FACTOR`` x samples for their emission (``edge_emission``):
    the light regions' SD 0.22-0.26 % (12 seeds).

    Which pixels: through every pixel centre one ray (no random numbers, so the choice is
    independent of the samples that estimate the pixel, and the estimate stays unbiased
    whatever it picks); a pixel is chosen where the seen emission differs between the
    centres of the (2r + 1)^2 pixels around it, r = ceil(filter_width) + 1 (the filter
    reaches filter_width pixels out). An emitter thinner than a pixel that no centre meets
    keeps the ordinary samples. Over the full frame, so tiles of a still choose alike."""
    lights = lights if _lights_in_frame(lights) else None
    if not surfaces.materials.has_emission and lights is None:
        return None
    cam = replace(scene.camera, border=None)
    width, height = cam.window_size
    origins, directions, tmax = pixel_rays(cam, 0, width * height, 1, np.random.default_rng(0),
                                           centres=True)
    value = _seen_emission(scene, accel, surfaces, origins, directions, tmax,
                           lights=lights).sum(axis=1)
    img = value.reshape(height, width)
    r = int(np.ceil(filter_width)) + 1
    pad = np.pad(img, r, mode="edge")
    hi, lo = img.copy(), img.copy()
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            window = pad[dy:dy + height, dx:dx + width]
            np.maximum(hi, window, out=hi)
            np.minimum(lo, window, out=lo)
    return hi > lo


def world_along(world, directions: np.ndarray, camera) -> np.ndarray | None:
    """The radiance (M, 3) of ``world`` along the unit ``directions`` (M, 3) of rays that left
    the scene, or None where it is black for all of them. ``camera``: True, False, or (M,) bool,
    which rays are camera rays and see ``world.seen_by_camera`` (``scene.World.camera``)."""
    if world.camera is None or not np.any(camera):
        return None if world.is_black else world.radiance_towards(directions)
    if np.all(camera):
        seen = world.camera
        return None if seen.is_black else seen.radiance_towards(directions)
    out = np.zeros((len(directions), 3))
    for part, rows in ((world, ~camera), (world.camera, camera)):
        if rows.any() and not part.is_black:
            out[rows] = part.radiance_towards(directions[rows])
    return out


def _lights_in_frame(lights) -> bool:
    """Whether camera rays can see any of ``lights`` (a ``LightSet`` or None): lights that
    are not geometry and suns' discs, with Visibility > Camera on."""
    return lights is not None and any(
        (ray_visible(light) or isinstance(light, SunCone)) and light.camera_visible
        for light in lights.sampled)


def _seen_emission(scene, accel, surfaces, origins, directions, tmax, split=False,
                   lights=None):
    """Radiance (N, 3) the camera rays see first: an emitter's (on its emitting side, as a
    camera ray meets it) or the world's where they miss; 0 on other surfaces; plus the
    lights in frame they pass (``lights``: the scene's ``LightSet``, camera-visible lights
    that are not geometry). ``split``: also the world's part alone."""
    _t, prim, bu, bv = accel.intersect(origins, directions, tmax)
    out = np.zeros((len(origins), 3))
    hit = prim >= 0
    world_part = np.zeros((len(origins), 3)) if split else None
    if not hit.all():
        world = world_along(scene.world, directions[~hit], True)
        if world is not None:
            out[~hit] = world
            if split:
                world_part[~hit] = world
    if lights is not None:
        out += seen_light_radiance(lights, origins, directions, np.where(hit, _t, np.inf),
                                   camera=True)
        if not hit.all():
            out[~hit] += seen_sun_radiance(lights, directions[~hit], camera=True)
    if hit.any():
        p = prim[hit]
        front = sampling.dot_rows(np.take(surfaces.geometric_normals, p, axis=0),
                                  directions[hit]) < 0
        surface = surfaces.params(p, bu[hit], bv[hit], directions[hit], camera=True,
                                  ray={"Ray Length": _t[hit]})
        out[hit] = surface.emitted_radiance * (front | surface.both_sides)[:, None]
    if split:
        return out, world_part
    return out


def supersample_textures(context: CameraContext, camera, batch: int, surface, prim, rays,
                         spp: int, stats: dict, subset=None) -> None:
    """At primary hits on textured materials, the diffuse reflectance averaged over the hit's
    own look-up and ``TEXTURE_SUPERSAMPLES`` more: extra rays through the same pixel (drawn
    from the pixel filter, ``STREAM_TEXTURE``) that meet the same material; only their
    texture is read, nothing is shaded. A pixel's texture detail then costs (1 + K) look-ups
    a sample instead of more shaded samples: the anti-aliasing noise of texture edges falls
    as if the pixel had (1 + K) x spp samples. Where the light varies inside the pixel across
    a texture edge this averages the texture over the pixel's part on that material (a
    second-order difference from the pixel filter's exact integral). ``subset``: the block's
    pixels the batch shades (``shade_block``), None for all of them."""
    textured = np.flatnonzero(context.surfaces.materials.textured[surface.material])
    k = TEXTURE_SUPERSAMPLES
    if len(textured) == 0 or k == 0:
        return
    rng = sampling.rng_for(context.settings.seed, sampling.STREAM_TEXTURE, batch)
    pixel = rays[textured] // spp
    # The pixel's spp x K extra positions are one set, stratified over the pixel in two
    # dimensions (``sampling.pixel_stratified``'s jittered set); each sample takes its own K
    # of them. The pixel's texture then averages over a stratified set of (1 + K) x spp
    # positions, not spp sets of K drawn independently (DiffCol's seed-to-seed noise on the
    # textured room's floor: 1.31 % with independent sets).
    positions = sampling.pixel_stratified(rays[textured], spp, k, rng)[0]   # (T, K, 2)
    origins, directions, tmax = pixel_rays(camera, 0, 0, k, rng, context.settings.filter_width,
                                           pixels=pixel if subset is None else subset[pixel],
                                           positions=positions)
    _t, p2, u2, v2 = context.accel.intersect(origins, directions, tmax)
    stats["camera_rays"] += len(origins)
    owner = np.repeat(textured, k)
    materials_of = context.surfaces.material_ids
    same = (p2 >= 0)
    same[same] = materials_of[p2[same]] == surface.material[owner[same]]
    total = np.array(surface.diffuse[textured], np.float64)
    counts = np.ones(len(textured))
    if same.any():
        extra = context.surfaces.params(p2[same], u2[same], v2[same], directions[same],
                                        camera=True, ray={"Ray Length": _t[same]}).diffuse
        slot = np.searchsorted(textured, owner[same])
        np.add.at(total, slot, extra)
        counts += np.bincount(slot, minlength=len(textured))
    surface.replace_diffuse(textured, total / counts[:, None])


def edge_emission(context: CameraContext, camera, batch: int, pixels: np.ndarray,
                  split: bool = False):
    """Mean emission seen (``_seen_emission``) over ``EDGE_SAMPLES_FACTOR`` x samples of the
    block's pixels ``pixels``, with the pixel filter, from the batch's own stream
    (``STREAM_EDGE``): (P, 3) and the rays traced; ``split``: (P, 3) pairs (all, the
    world's part) instead of the (P, 3)."""
    settings = context.settings
    m = EDGE_SAMPLES_FACTOR * settings.samples
    rng = sampling.rng_for(settings.seed, sampling.STREAM_EDGE, batch)
    origins, directions, tmax = pixel_rays(camera, 0, 0, m, rng, settings.filter_width,
                                           pixels=pixels)
    lights = context.lights if _lights_in_frame(context.lights) else None
    seen = _seen_emission(context.scene, context.accel, context.surfaces, origins, directions,
                          tmax, split, lights=lights)
    if split:
        seen, world = (a.reshape(len(pixels), m, 3).mean(axis=1) for a in seen)
        return (seen, world), len(origins)
    return seen.reshape(len(pixels), m, 3).mean(axis=1), len(origins)


def _shade_caustics(context, stats, idx, x, ns, surface, glossy, thr, rays, spp, depth,
                    indirect_sums, light=None, probe_lookup=False, rough=None, kinds=None):
    """Caustics at the diffuse hits ``idx``: the caustic map's irradiance (light that reached
    them through specular surfaces, ``indirect.CausticEstimate``) x rho_d / pi (below a
    Principled layer: x its diffuse share), plus, at glossy hits where the path ends and no
    probe look-up takes their indirect light (``probe_lookup`` False), x their glossy albedo
    / pi (with the look-up, the radiance the probe reads already holds what reaches them
    through specular surfaces); summed into the Indirect part (and ``light``'s passes)."""
    ask = idx if isinstance(idx, np.ndarray) else np.arange(len(x))
    t0 = time.perf_counter()
    e = context.caustics.irradiance(x[ask], ns[ask], stats)
    stats["estimate_seconds"] += time.perf_counter() - t0
    lit = np.flatnonzero(np.any(e > 0, axis=1))
    if len(lit) == 0:
        return
    _add_irradiance(e[lit], ask[lit], surface, glossy, thr, rays, spp, depth, indirect_sums,
                    light, not probe_lookup, rough, kinds)


def _asking(candidates, samples, spp, first_lookup, lookups):
    """The ``candidates`` whose samples (their camera sample indices ``samples``) ask for the
    indirect estimate when only ``lookups`` of a pixel's ``spp`` do. The pixel's strata come
    in a fixed order: start at a random one per pixel (``first_lookup``), so the asking
    samples are a uniform pick over the pixel's filter footprint."""
    return candidates[(samples - first_lookup[samples // spp]) % spp < lookups]


def _shade_translucent(context, stats, rng, depth, x, ns, ns_smooth, ng, surface, thr, rays,
                       spp, parts, light, first_lookup, kinds=None):
    """Translucent closures (Cycles' Translucent BSDF, f = rho_t / pi for light from the far
    side) at a camera-path vertex: rho_t / pi x the irradiance on the far side, the side
    whose normal is -n, estimated as at any diffuse point facing that way: direct light by
    light samples from there (the Direct part), the cache / gather / photon estimate and
    the caustic map with the far side's normal (the Indirect part; in ``photon-map`` mode
    the photon estimate is the whole). ``parts``: the (emission, direct, indirect) pixel
    sums; ``first_lookup``: the pixels' first asking sample when the estimate is asked by
    fewer samples than the pixel has (``shade_block``), else None."""
    on = np.flatnonzero(np.any(surface.translucent > 0, axis=1))
    if len(on) == 0:
        return
    _emission, direct_sums, indirect_sums = parts
    photon = context.indirect
    factor = surface.translucent[on] / np.pi
    if depth > 0:
        factor = factor * thr[on]
    kind = DIFFUSE if depth == 0 or light is None else kinds[on]
    back_x = x[on]
    if context.settings.mode == "full":
        terms = _counted_direct_terms(context, stats, rng, back_x, -ns[on], -ng[on])
        if terms:
            value = irradiance_from_terms(terms, len(on)) * factor
            add_to_pixels(direct_sums, rays[on] // spp, value)
            if light is not None:
                light.add(rays[on], value, direct=depth == 0, kind=kind)
        if context.caustics is not None:
            t0 = time.perf_counter()
            e = context.caustics.irradiance(back_x, -ns_smooth[on], stats)
            stats["estimate_seconds"] += time.perf_counter() - t0
            value = e * factor
            add_to_pixels(indirect_sums, rays[on] // spp, value)
            if light is not None:
                light.add(rays[on], value, direct=False, kind=kind)
    if photon is None:
        return
    ask = np.arange(len(on))
    if first_lookup is not None:
        ask = _asking(ask, rays[on], spp, first_lookup, photon.lookups)
    if len(ask) == 0:
        return
    at = on[ask]
    t0 = time.perf_counter()
    e = photon.irradiance(x[at], -ns_smooth[at], -ng[at], rng, stats)
    stats["estimate_seconds"] += time.perf_counter() - t0
    stats.pop("covered_mask", None)
    scale = (spp / min(photon.lookups, spp)) * factor[ask]
    for part, is_direct in _estimate_parts(e):
        value = part * scale
        add_to_pixels(direct_sums if is_direct else indirect_sums, rays[at] // spp, value)
        if light is not None:
            light.add(rays[at], value, direct=is_direct and depth == 0,
                      kind=kind if depth == 0 else kind[ask])


def _estimate_parts(e):
    """An indirect estimate's irradiance (k, C) as (part (k, 3), is_direct) pairs: C = 3 is
    indirect light alone; C = 6 (``indirect.FinalGather.channels``: a gathered sky) adds the
    sky's direct light, filed in the Direct passes (Cycles' Diffuse Direct)."""
    if e.shape[1] == 3:
        return ((e, False),)
    return ((e[:, :3], False), (e[:, 3:6], True))


def _add_irradiance(e, at, surface, glossy, thr, rays, spp, depth, sums, light,
                    glossy_part, rough=None, kinds=None, is_direct=False):
    """Irradiance ``e`` (k, 3) at the diffuse hits ``at`` into the pixel ``sums`` of the
    Indirect part (with ``is_direct``, a gathered sky's direct light: the Direct part's sums,
    and the light passes' Direct at the first hit): x rho_d / pi
    (below a Principled layer x its diffuse share) and, with ``glossy_part``, plus the glossy
    lobes' albedo / pi at hits where the path ends (their indirect light as if it came
    evenly: where no probe reads it, ``probe_lookup``); x the path's throughput after the
    first hit; the light passes' kinds at the first hit (``passes.LightSums``). ``rough``:
    the vertex's Oren-Nayar hits (``bsdf.RoughDiffuseHits``), whose diffuse takes the light
    as if it came evenly (x its directional albedo over rho)."""
    value = e * surface.diffuse_over_pi[at]
    if rough is not None:
        value *= rough.indirect_factor[at]
    if glossy is not None:
        value *= glossy.diffuse_factor[at]
        if light is not None and depth == 0:
            light.add(rays[at], value, direct=is_direct, kind=DIFFUSE)
        if glossy_part:
            reflected = glossy.ending_albedo[at] * e / np.pi
            if light is not None and depth == 0:
                through = glossy.ending_transmitted[at] * e / np.pi
                light.add(rays[at], reflected - through, direct=is_direct, kind=GLOSSY)
                light.add(rays[at], through, direct=is_direct, kind=TRANSMISSION)
            value += reflected
    elif light is not None and depth == 0:
        light.add(rays[at], value, direct=is_direct, kind=DIFFUSE)
    if depth > 0:
        value *= thr[at]
        if light is not None:
            light.add(rays[at], value, direct=False, kind=kinds[at])
    add_to_pixels(sums, rays[at] // spp, value)


def _counted_direct_terms(context, stats, rng, x, ns, ng, with_directions=False, rays=None):
    """``direct.direct_terms`` at points (x, ns, ng) with the render's lights and light
    samples, its shadow-ray counters added to ``stats``. ``rays``: the points' primary-ray
    indices, at a path's first vertex: their light numbers are then stratified over each
    pixel's samples (``sampling.pixel_stratified``)."""
    settings = context.settings
    shadow_stats = {}
    terms = direct_terms(x, ns, context.lights, context.accel, rng, settings.light_samples,
                         stats=shadow_stats, offset_normals=ng, ray_log=context.ray_log,
                         shadow_map=context.shadow_map, with_directions=with_directions,
                         pixel_slots=None if rays is None else (rays, settings.samples))
    stats["shadow_rays"] += shadow_stats.get("shadow_rays", 0)
    for key in ("shadow_rays_saved", "shadow_lit", "shadow_umbra", "shadow_penumbra"):
        stats[key] = stats.get(key, 0) + shadow_stats.get(key, 0)
    stats["trace_seconds"] += shadow_stats.get("trace_seconds", 0.0)
    return terms


def _shade_direct_rough(context, stats, rng, depth, on, x, ns, ng, thr, rays, direct_sums,
                        diffuse_factor, light, rough, kinds=None):
    """Direct light at the Oren-Nayar hits ``on`` (indices among the vertex's hits): each
    light sample weighted by the lobe's f(wo, wi) (``bsdf.RoughDiffuseHits``) instead of
    rho / pi; below a Principled layer x its diffuse share; summed as ``_shade_direct``
    sums (Diffuse Direct at the first hit)."""
    if len(on) == 0:
        return
    terms = _counted_direct_terms(context, stats, rng, x[on], ns[on], ng[on],
                                  with_directions=True, rays=rays[on] if depth == 0 else None)
    rows = rough.row_of[on]
    lobe, wo, n = rough.lobe.subset(rows), rough.wo[rows], rough.n[rows]
    radiance = np.zeros((len(on), 3))
    for target, scalar, rgb, directions, _hittable, _light in terms:
        at = np.arange(len(on)) if target is None else target
        f = lobe.subset(at).evaluate(wo[at], np.asarray(directions, np.float64), n[at])
        value = f * (scalar[:, None] * np.asarray(rgb, np.float64).reshape(-1, 3))
        for c in range(3):
            radiance[:, c] += np.bincount(at, weights=value[:, c], minlength=len(on))
    if diffuse_factor is not None:
        radiance *= diffuse_factor[on]
    if depth > 0:
        radiance *= thr[on]
    spp = context.settings.samples
    add_to_pixels(direct_sums, rays[on] // spp, radiance)
    if light is not None:
        light.add(rays[on], radiance, direct=depth == 0,
                  kind=DIFFUSE if depth == 0 else kinds[on])


def _shade_direct(context, stats, rng, depth, idx, x, ns, ng, surface, thr, rays, pixel_of,
                  direct_sums, diffuse_factor=None, light=None, kinds=None):
    """Direct light at the diffuse hits ``idx``: rho_d / pi times the irradiance of
    ``direct.direct_terms``, summed into the pixels (and into ``light``'s passes: Diffuse
    Direct at the first hit, the path's kind's Indirect after). Primary hits of a scene whose materials
    are constant per material (no textures) sum each term's scalar weights in a (pixel,
    material) histogram and multiply by the materials' rho_d / pi once, instead of per hit."""
    settings, materials = context.settings, context.surfaces.materials
    spp = settings.samples
    terms = _counted_direct_terms(context, stats, rng, x[idx], ns[idx], ng[idx],
                                  rays=rays[idx] if depth == 0 else None)
    count = materials.count
    if depth == 0 and materials.constant_per_material and count <= MAX_HISTOGRAM_MATERIALS:
        mat_d = surface.material[idx]
        if pixel_of is None:
            key = np.repeat(np.arange(len(direct_sums), dtype=np.int32) * count, spp)[idx]
        else:
            key = pixel_of[idx] * count
        key += mat_d
        factor = None if diffuse_factor is None else diffuse_factor[idx]
        for target, scalar, rgb in terms:
            if factor is not None:
                # The share below the layers is RGB (a tinted coat): per channel.
                part = factor if target is None else factor[target]
            where = key if target is None else key[target]
            rgb = np.asarray(rgb, np.float64)
            if rgb.ndim == 2 or factor is not None:
                # A radiance per sample (an image world) or an RGB layer share: per channel.
                rgb_c = rgb if rgb.ndim == 2 else np.broadcast_to(rgb, (len(scalar), 3))
                weights = scalar[:, None] * rgb_c
                if factor is not None:
                    weights = weights * part
                value = np.stack([np.bincount(where, weights=weights[:, c],
                                              minlength=len(direct_sums) * count)
                                  .reshape(-1, count) @ materials.diffuse_over_pi[:, c]
                                  for c in range(3)], axis=1)
            else:
                hist = np.bincount(where, weights=scalar, minlength=len(direct_sums) * count)
                value = hist.reshape(-1, count) @ (materials.diffuse_over_pi * rgb)
            direct_sums += value
            if light is not None:
                light.light[DIFFUSE, 0] += value
    elif terms:
        e = irradiance_from_terms(terms, len(x[idx]))
        e *= surface.diffuse_over_pi[idx]
        if diffuse_factor is not None:
            e *= diffuse_factor[idx]
        if depth > 0:
            e *= thr[idx]
        in_order = pixel_of is None and isinstance(idx, slice)
        add_to_pixels(direct_sums, None if in_order else (rays // spp)[idx], e)
        if light is not None:
            light.add(rays[idx], e, direct=depth == 0,
                      kind=DIFFUSE if depth == 0 else kinds[idx])


class _GlossyHits:
    """The hits of one camera-path vertex on materials with glossy lobes
    (``bsdf.GlossyMaterial``), grouped by material (a loop over materials, never over hits).

    Where the glossy lobes reflect more than the diffuse part (largest channel of the summed
    albedos: metals, a Mix floor of more glossy than diffuse) the path goes on by sampling
    them (``goes_on``); elsewhere it ends here (diffuse-dominant, as photon mapping
    splits transport: Jensen 1996): their ray still goes one step as an emission probe, for
    the world and the emitters it meets (their direct light) and the diffuse radiance of the
    surface it lands on (their indirect light, from the irradiance precomputed at photons);
    it is not shaded there. Without precomputed irradiance (indirect = photon) the lobes'
    indirect light is the irradiance estimate times their albedo / pi (``ending_albedo``),
    as if it came evenly.

    ``index`` (G,) the glossy hits among the vertex's N hits, ``mask`` (N,), ``goes_on`` (N,)
    the hits where the path goes on, ``group_of`` / ``row_of`` (N,) each hit's material group
    and its row in that group's lobes, ``diffuse_factor`` (N, 3) the share of the diffuse below a Principled
    specular layer (1 elsewhere), ``ending_albedo`` (N, 3) the glossy albedo at ending hits
    (0 elsewhere), ``light_counts`` (N,) the light samples each glossy hit takes
    (``light_samples`` x its lobes' sharpness factor, ``GLOSSY_REFERENCE_PEAK``). With
    ``split`` (the light passes): ``reflected`` / ``transmitted`` (N, 3)
    the lobes' albedo by branch (glass lobes split, ``lobes.SmoothGlass.albedo_split``) and
    ``ending_transmitted`` (N, 3) the transmitted part of ``ending_albedo``."""

    def __init__(self, materials, surface, wo, n, front=None, split: bool = False,
                 light_samples: int = 1):
        count = len(surface)
        self.light_counts = np.full(count, int(light_samples))
        self.front = np.ones(count, bool) if front is None else np.asarray(front, bool)
        self.mask = surface.camera_glossy
        self.index = np.flatnonzero(self.mask)
        self.count = len(self.index)
        self.diffuse_factor = np.ones((count, 3))
        self.ending_albedo = np.zeros((count, 3))
        self.goes_on = np.zeros(count, bool)
        if split:
            self.reflected = np.zeros((count, 3))
            self.transmitted = np.zeros((count, 3))
            self.ending_transmitted = np.zeros((count, 3))
        self.wo, self.n = wo, n
        self.materials = materials
        self.material_ids = surface.material[self.index]
        # After ``sample(split_glass=True)``: the positions in ``index`` of the twin rays.
        self.twin_of = np.zeros(0, np.int64)
        # The lobes' per-hit inputs (``bsdf.LobeInputs``), or None
        self.per_hit = surface.lobe_inputs
        # (hits (k,) into the vertex, [(weight (k, 3), lobe, delta)], lobe shares (k, J))
        self.groups = []
        self.group_of = np.full(count, -1)
        self.row_of = np.zeros(count, np.int64)
        ids = self.material_ids
        for material_id in np.unique(ids):
            hits = self.index[ids == material_id]
            self.group_of[hits] = len(self.groups)
            self.row_of[hits] = np.arange(len(hits))
            spec = materials.glossy[material_id]
            wo_h, n_h = wo[hits].astype(np.float64), n[hits].astype(np.float64)
            lobes = spec.entries(len(hits), wo_h, n_h, self.front[hits],
                                 None if self.per_hit is None else self.per_hit[hits])
            if spec.layered:
                self.diffuse_factor[hits] = spec.diffuse_factor(wo_h, n_h)
            albedo = sum(w * lobe.albedo(wo_h, n_h) for w, lobe, _ in lobes)
            diffuse = surface.diffuse[hits] * self.diffuse_factor[hits]
            goes_on = albedo.max(axis=1) > diffuse.max(axis=1)
            self.goes_on[hits] = goes_on
            self.ending_albedo[hits] = albedo * ~goes_on[:, None]
            shares = lobe_shares([(w, lobe) for w, lobe, _ in lobes], wo_h, n_h)
            self.groups.append((hits, lobes, shares))
            self.light_counts[hits] = light_samples * glossy_light_factor(
                lobes, shares, wo_h, n_h, glossy_energy_share(albedo, diffuse))
            if split:
                for w, lobe, _ in lobes:
                    if hasattr(lobe, "albedo_split"):
                        r, t = lobe.albedo_split(wo_h, n_h)
                    else:
                        r, t = lobe.albedo(wo_h, n_h), 0.0
                    self.reflected[hits] += w * r
                    self.transmitted[hits] += w * t
                self.ending_transmitted[hits] = self.transmitted[hits] * ~goes_on[:, None]

    def sample(self, rng, split_glass: bool = False):
        """One ray per glossy hit, in the order of ``index`` (``bsdf.sample_glossy``):
        returns (directions, weight = w f cos / (pdf P), kept, pdf) where ``pdf`` is P x the
        picked lobe's density (inf for a mirror or smooth glass), the BSDF's side of multiple
        importance sampling for the lights the ray meets. From hits where the path ends the
        ray is an emission probe. ``split_glass``: smooth glass sends a reflected and a
        refracted ray (``sample_glossy``'s twins, appended after the G rays; ``twin_of``
        (M,) then holds their positions in ``index``)."""
        sampled = sample_glossy(self.materials, self.material_ids,
                                self.wo[self.index].astype(np.float64),
                                self.n[self.index].astype(np.float64), rng,
                                self.front[self.index],
                                per_hit=None if self.per_hit is None
                                else self.per_hit[self.index], split_glass=split_glass)
        wi, weight, pdf = sampled[:3]
        self.twin_of = np.zeros(0, np.int64)
        if split_glass:
            self.twin_of, twin_wi, twin_weight = sampled[3]
            wi = np.concatenate([wi, twin_wi])
            weight = np.concatenate([weight, twin_weight])
            pdf = np.concatenate([pdf, np.full(len(self.twin_of), np.inf)])
        return wi, weight, np.any(weight > 0, axis=1) & (pdf > 0), pdf

    def radiance(self, target, directions, p_light=None, meets=None):
        """f summed over the lobes (k, 3) for light samples of the glossy hits ``target``
        (positions in ``index``) arriving from ``directions``. ``p_light`` (k,): the density
        the light samples were drawn with (``lights.LightSet.sample_density``) for a light
        the lobes' own rays also meet (area lights, lights with a radius, emissive meshes,
        the world; None for the others, suns and point lights, which keep weight 1); each
        non-delta lobe j then weighs its f by the power heuristic p_light^2 / (p_light^2 +
        p_j^2), p_j = its pick probability x its pdf (``bsdf.sample_glossy``), whose
        complement its rays take where they meet the light (Veach 1997 §9.2). ``meets``
        (k,): where a ray along the direction would not meet the light (an ellipse's light
        samples on its fan beyond the ellipse), p_j counts as 0. Delta lobes have f = 0 here:
        their rays take all the light they meet. Where the path ends the same holds: its ray
        goes on as an emission probe (counted at the next hit, not shaded)."""
        f = np.zeros((len(target), 3))
        hit_of = self.index[target]
        group = self.group_of[hit_of]
        rows = self.row_of[hit_of]
        for g, (_hits, lobes, shares) in enumerate(self.groups):
            sel = np.flatnonzero(group == g)
            if len(sel) == 0:
                continue
            wo = self.wo[hit_of[sel]].astype(np.float64)
            n = self.n[hit_of[sel]].astype(np.float64)
            wi = directions[sel].astype(np.float64)
            for j, (w, lobe, delta) in enumerate(lobes):
                if delta:
                    continue
                at = lobe.subset(rows[sel])
                value = w[rows[sel]] * at.evaluate(wo, wi, n)
                if p_light is not None:
                    p_bsdf = shares[rows[sel], j] * at.pdf(wo, wi, n)
                    if meets is not None:
                        p_bsdf = p_bsdf * meets[sel]
                    value *= light_strategy_weights(p_light[sel], p_bsdf)[:, None]
                f[sel] += value
        return f


def glossy_energy_share(glossy_albedo, diffuse_albedo) -> np.ndarray:
    """(k,) the glossy lobes' share of what k hits reflect: the glossy albedo's channel sum
    over that of glossy + the diffuse left below them (1 where both are 0)."""
    glossy = np.asarray(glossy_albedo, np.float64).sum(axis=1)
    total = glossy + np.asarray(diffuse_albedo, np.float64).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0.0, glossy / np.where(total > 0.0, total, 1.0), 1.0)


def glossy_light_factor(lobes, shares, wo, n, energy_share=None) -> np.ndarray:
    """(k,) the factor on the light samples of k glossy hits (``GLOSSY_REFERENCE_PEAK``): the
    power of two nearest their non-delta lobes' largest pick share x pdf towards the mirror
    direction of ``wo`` about ``n``, times the glossy lobes' ``energy_share`` (k,) of what
    the hit reflects (``glossy_energy_share``; default 1), over the reference, within
    [1, GLOSSY_LIGHT_FACTOR_MAX]. A highlight that carries a few per cent of a pixel beside
    its diffuse (a Principled dielectric's specular layer) adds little noise to it, so it
    keeps the base count; a metal's or a glossy floor's takes the full factor."""
    mirror = 2.0 * sampling.dot_rows(wo, n)[:, None] * n - wo
    peak = np.zeros(len(wo))
    for j, (_w, lobe, delta) in enumerate(lobes):
        if not delta:
            peak = np.maximum(peak, shares[:, j] * lobe.pdf(wo, mirror, n))
    if energy_share is not None:
        peak = peak * np.asarray(energy_share, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.round(np.log2(peak / GLOSSY_REFERENCE_PEAK))
    top = np.log2(GLOSSY_LIGHT_FACTOR_MAX)
    steps = np.clip(np.nan_to_num(steps, nan=0.0, posinf=top, neginf=0.0), 0, top)
    return (2 ** steps.astype(np.int64)).astype(np.int64)


def _glossy_direct_part(context, stats, rng, glossy, part, x, ns, ng, light_samples):
    """(len(part), 3) the glossy lobes' direct light at the glossy hits ``part`` (positions in
    ``glossy.index``), each from ``light_samples`` light samples weighted by multiple
    importance sampling against the lobes' rays (``_GlossyHits.radiance``)."""
    at_part = glossy.index[part]
    shadow_stats = {}
    terms = direct_terms(x[at_part], ns[at_part], context.lights, context.accel, rng,
                         light_samples, stats=shadow_stats, offset_normals=ng[at_part],
                         ray_log=context.ray_log, shadow_map=context.shadow_map,
                         with_directions=True)
    stats["shadow_rays"] += shadow_stats.get("shadow_rays", 0)
    stats["trace_seconds"] += shadow_stats.get("trace_seconds", 0.0)
    radiance = np.zeros((len(part), 3))
    everyone = np.arange(len(part))
    lights = context.lights
    for target, scalar, rgb, dirs, hittable, index in terms:
        target = everyone if target is None else target
        p_light = meets = None
        at = at_part[target]
        if hittable:
            # A light the lobes' rays meet too: multiple importance sampling.
            p_light = lights.sample_density(x[at], ns[at], dirs, index, light_samples)
            p_light *= sampling.dot_rows(ns[at].astype(np.float64), dirs) > 0
            if hittable == "area":
                meets = lights.sampled[index].intersect(x[at].astype(np.float64), dirs,
                                                        np.inf)[1] > 0
        f = glossy.radiance(part[target], dirs, p_light, meets)
        rgb = np.asarray(rgb, np.float64)
        contribution = f * (scalar[:, None] * (rgb if rgb.ndim == 2 else rgb[None]))
        for c in range(3):
            radiance[:, c] += np.bincount(target, weights=contribution[:, c],
                                          minlength=len(part))
    return radiance


def _shade_glossy_direct(context, stats, rng, glossy, x, ns, ng, thr, rays, spp, direct_sums,
                         light=None, depth=0, kinds=None):
    """Direct light reflected by the glossy lobes: light samples at the glossy hits
    (``direct.direct_terms`` with their directions), each weighted by the lobes' f and, for
    lights the lobes' rays meet as well, by the light's weight of multiple importance sampling
    (``_GlossyHits.radiance``); each hit takes ``_GlossyHits.light_counts`` samples, hits with
    the same count in one batch (``_glossy_direct_part``) (into
    ``light``'s passes: Glossy Direct at the first hit ``depth`` 0, where light samples reach
    only the reflection side; the path's kind's Indirect after)."""
    idx = glossy.index
    radiance = np.zeros((len(idx), 3))
    counts = glossy.light_counts[idx]
    for count in np.unique(counts):
        part = np.flatnonzero(counts == count)
        radiance[part] = _glossy_direct_part(context, stats, rng, glossy, part, x, ns, ng,
                                             int(count))
    if thr is not None:
        radiance *= thr[idx]
    add_to_pixels(direct_sums, rays[idx] // spp, radiance)
    if light is not None:
        light.add(rays[idx], radiance, direct=depth == 0,
                  kind=GLOSSY if depth == 0 else kinds[idx])


def _first_hit_colors(light, rays, surface, glossy):
    """The Color passes' albedos at the first hits (samples ``rays``): Diffuse rho_d (x the
    share under a Principled layer), Glossy the seed's mirror rho_s or the glossy lobes'
    reflected albedo, Transmission the glass lobes' transmitted albedo."""
    diffuse = surface.diffuse
    specular = surface.specular
    if glossy is not None:
        diffuse = diffuse * glossy.diffuse_factor
        specular = np.where(glossy.mask[:, None], glossy.reflected, specular)
        light.add_color(rays, TRANSMISSION, glossy.transmitted)
    if surface.table.has_translucent:
        diffuse = diffuse + surface.translucent       # Cycles' Diffuse passes hold it
    light.add_color(rays, DIFFUSE, diffuse)
    light.add_color(rays, GLOSSY, specular)
