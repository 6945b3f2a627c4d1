"""The pipeline: builds the stages in a fixed order, times each and fills the report.

What it computes
    ``render(scene, settings)`` -> ``RenderResult`` with the Combined image (linear radiance
    [W m^-2 sr^-1], (H, W, 3) float32, row 0 at the top of the render window) and a report.

Stages, in order (DESIGN.md §1)
    1. ``validate``            check the scene, drop untraceable triangles (counted, named)
    2. ``accel_build``         Embree BVH over all triangles
    3. ``lights``              sort lights into exactly evaluated and sampled ones
    4. the plan                ``engine/plan.py``: which of the stages below this scene needs,
                               each with its reason, before any work
    5. ``photons``             emit, trace and store photons, build the kd-tree
                               (``engine/photons.py``)
    6. ``radiance_estimates``  irradiance precomputed at a quarter of the photons
                               (Christensen 1999, ``engine/gather.py``)
    7. ``irradiance_cache``    records placed in passes at pixel strides 32, 16, ..., 1 by the
                               final gather, with Ward & Heckbert gradients, checked against
                               their neighbours after each pass, the gaps refilled coarse to
                               fine by the next (``engine/irradiance_cache.py``,
                               ``_cache_prepass``)
    8. ``camera``              primary rays in batches of whole pixels; at each diffuse hit the
                               emission plus, by ``mode``:
                               ``full``: exact direct light (``engine/direct.py``) + indirect
                               light by ``indirect``: ``cache`` (interpolated records),
                               ``gather`` (a final gather per looked-up sample) or
                               ``photon-map`` (the estimate at the hit, photons that bounced);
                               ``photon-map``: the photon-map estimate of all light (seed 9.5).
                               Perfect specular surfaces reflect the camera ray (up to
                               ``max_specular_depth``).

    Batches are square blocks of the full frame (64 x 64 pixels at 16 spp), each with its own
    random stream from (seed, block number), so they run on a thread pool (embreex and numpy
    release the GIL) and a fixed seed gives the same picture whatever the scheduling or the
    thread count. A render border renders the blocks it meets and keeps its part of them;
    with automatic counts and the cache placed over the full frame, tiles of a still
    reassemble into the full render pixel for pixel (a farm can split a still). Between batches ``progress(fraction, text)`` is called
    and ``cancelled()`` is polled; a batch takes well under a second, so Esc acts quickly.

Settings (``RenderSettings``)
    =====================  ========  ===========================================================
    name                   default   meaning
    =====================  ========  ===========================================================
    mode                   full      ``full`` (direct + photon-map indirect) or ``photon-map``
    samples                16        camera samples per pixel
    light_samples          4         samples per shading point shared by area/mesh/world lights
    bounces                128       most bounces of light; 0 = direct light only. Photon paths
                                     end after this many bounces (counted in the report); 128
                                     keeps a rho = 0.95 enclosure within 0.2 % (0.95^130; 64
                                     left it 3.4 % dark)
    photons                0         photons emitted; 0 = automatic: 2 per pixel, 200k-2M
    photon_k               50        photons per estimate (k nearest, Eq. 9.11)
    photon_radius          0.0       cap on the estimate's radius [m]; 0 = automatic (4x the
                                     radius holding k photons spread evenly over the scene)
    photon_filter          none      ``none`` or ``cone`` (Jensen's cone filter, k = 1.1)
    photon_lookups         0         camera samples per pixel that ask for indirect light
                                     (photon map, gather or cache); their value stands for
                                     the pixel's other samples too. 0 = automatic: about
                                     300k look-ups per image, between 1 and ``samples``
    indirect               cache     ``full`` mode's indirect light: ``cache``, ``gather`` or
                                     ``photon-map`` (see stage 8)
    gather_m, gather_n     8, 32     final gather strata in theta and phi (M x N rays)
    cache_error            0.2       irradiance cache error a: records serve where w > 1/a
    cache_gradients        True      interpolate with the records' gradients (Eq. 10.5)
    cache_refine           True      records that a neighbour's gather contradicts reach
                                     less far (``irradiance_cache.consistent_radii``), so
                                     indirect shadows get records of their own
    gather_guided          1.0       extra gather rays, as a multiple of M x N, steered by the
                                     nearby photons' directions (Jensen 1995); 0 = off
    shadow_photons         True      lit / penumbra / umbra classes from shadow photons
    force                  ""        comma-separated stages to run although the plan skips
                                     them (checks that a skip changes nothing)
    preset                 custom    ``preview`` / ``final`` set samples, light samples,
                                     photons, gather and cache error together
    seed                   0         random seed; same seed, same image
    threads                0         worker threads; 0 = all cores
    filter_width           1.5       Blackman-Harris pixel filter width [px]
    max_specular_depth     8         perfect-mirror reflections followed from the camera
    =====================  ========  ===========================================================
"""
from __future__ import annotations

import os
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from . import sampling
from .accel import Accelerator
from .camera import pixel_rays
from .direct import direct_terms, irradiance_from_terms
from .lights import LightSet
from .memory import peak_memory
from .gather import RadianceEstimates, final_gather
from .photons import auto_max_radius, auto_photon_count, build_photon_map
from .plan import make_plan
from .scene import Scene, SceneError

TARGET_BATCH_SAMPLES = 1 << 16
# What each camera batch counts (rays, seconds of threads, look-ups); summed over batches.
BATCH_COUNTERS = ("camera_rays", "shadow_rays", "specular_rays", "trace_seconds", "queries",
                  "query_seconds", "estimate_seconds", "cache_interpolated", "cache_gathered",
                  "cache_local_records", "cache_local_interpolated", "gather_rays",
                  "gather_points", "shadow_rays_saved", "shadow_lit", "shadow_umbra",
                  "shadow_penumbra")


MODES = ("full", "photon-map")
# Quality presets (issue 4): photons, gather M x N, cache error a, samples. Measured time and
# error on the seed's scenes are in the README.
PRESETS = {
    "preview": dict(samples=4, light_samples=2, photons=200_000, gather_m=6, gather_n=24,
                    cache_error=0.3, indirect="cache"),
    "final": dict(samples=16, light_samples=8, photons=1_000_000, gather_m=12, gather_n=48,
                  cache_error=0.1, indirect="cache"),
}
INDIRECT_METHODS = ("cache", "gather", "photon-map")
PHOTON_FILTERS = ("none", "cone")
CONE_FILTER_K = 1.1
MAX_PHOTONS = 50_000_000


@dataclass
class RenderSettings:
    mode: str = "full"
    samples: int = 16
    light_samples: int = 4
    bounces: int = 128
    seed: int = 0
    threads: int = 0
    filter_width: float = 1.5
    max_specular_depth: int = 8
    photons: int = 0
    photon_k: int = 50
    photon_radius: float = 0.0
    photon_filter: str = "none"
    photon_lookups: int = 0
    indirect: str = "cache"
    gather_m: int = 8
    gather_n: int = 32
    cache_error: float = 0.2
    cache_gradients: bool = True
    cache_refine: bool = True
    gather_guided: float = 1.0
    shadow_photons: bool = True
    force: str = ""
    preset: str = "custom"

    def resolved(self) -> "RenderSettings":
        """A copy with the preset's values in place of the individual settings (``custom``:
        the settings as they are)."""
        if self.preset not in PRESETS and self.preset != "custom":
            raise SceneError(f"Render settings: preset = {self.preset!r} is not one of "
                             f"{', '.join(('custom',) + tuple(PRESETS))}")
        return replace(self, **PRESETS.get(self.preset, {}))

    def validate(self) -> "RenderSettings":
        checks = [("mode", self.mode in MODES),
                  ("samples", self.samples >= 1), ("light_samples", self.light_samples >= 0),
                  ("bounces", 0 <= self.bounces <= 255), ("threads", self.threads >= 0),
                  ("filter_width", 0 <= self.filter_width <= 10),
                  ("max_specular_depth", self.max_specular_depth >= 0),
                  ("photons", 0 <= self.photons <= MAX_PHOTONS),
                  ("photon_k", 1 <= self.photon_k <= 10_000),
                  ("photon_radius", np.isfinite(self.photon_radius) and self.photon_radius >= 0),
                  ("photon_filter", self.photon_filter in PHOTON_FILTERS),
                  ("photon_lookups", self.photon_lookups >= 0),
                  ("indirect", self.indirect in INDIRECT_METHODS),
                  ("gather_m", 1 <= self.gather_m <= 256), ("gather_n", 1 <= self.gather_n <= 1024),
                  ("cache_error", np.isfinite(self.cache_error) and 0.01 <= self.cache_error <= 10),
                  ("gather_guided", np.isfinite(self.gather_guided) and 0 <= self.gather_guided <= 64)]
        for name, ok in checks:
            if not ok:
                allowed = {"mode": f" (one of {', '.join(MODES)})",
                           "indirect": f" (one of {', '.join(INDIRECT_METHODS)})",
                           "photon_filter": f" (one of {', '.join(PHOTON_FILTERS)})",
                           "photons": f" (0 = automatic, at most {MAX_PHOTONS:,})",
                           "bounces": " (0-255)"}.get(name, "")
                raise SceneError(f"Render settings: {name} = {getattr(self, name)!r} is out of "
                                 f"range{allowed}")
        return self

    @property
    def worker_count(self) -> int:
        return self.threads or os.cpu_count() or 1


@dataclass
class RenderResult:
    image: np.ndarray                      # (H, W, 3) float32 linear radiance, row 0 = top
    passes: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    cancelled: bool = False
    artifacts: object = None               # engine.artifacts.Artifacts: the maps it used


class _SceneArrays:
    """Per-triangle data the shading needs, gathered once."""

    def __init__(self, scene: Scene):
        table = scene.material_table()
        self.diffuse = table["diffuse"].astype(np.float64)
        self.specular = table["specular"].astype(np.float64)
        self.emitted_radiance = table["exitance"].astype(np.float64) / np.pi
        self.both_sides = table["both_sides"]
        self.material_ids = scene.material_ids
        self.geometric_normals = scene.geometric_normals().astype(np.float32)
        self.shading_normals = scene.shading_normals
        # Flat-shaded meshes need no interpolation: drop normals equal to the geometric ones.
        if self.shading_normals is not None:
            agree = np.einsum("tkj,tj->tk", self.shading_normals, self.geometric_normals)
            self.smooth = np.any(np.abs(agree) < 0.99999, axis=1)
            if not self.smooth.any():
                self.shading_normals = None
        self.is_diffuse = np.any(self.diffuse > 0, axis=1)
        self.diffuse_over_pi = self.diffuse / np.pi
        self.is_specular = np.any(self.specular > 0, axis=1)
        self.has_specular = bool(np.any(self.specular > 0))
        self.has_emission = bool(np.any(self.emitted_radiance > 0))
        self.material_count = len(self.diffuse)


def _add_to_pixels(pixels: np.ndarray, pixel_of: np.ndarray | None, values: np.ndarray):
    """pixels[pixel_of[i]] += values[i] (values (n, 3)); pixel_of None: all samples in order."""
    if pixel_of is None:
        pixels += values.reshape(len(pixels), -1, 3).sum(axis=1)
        return
    for c in range(3):
        pixels[:, c] += np.bincount(pixel_of, weights=values[:, c], minlength=len(pixels))


class _CachedIndirect:
    """Indirect light from the irradiance cache (seed chapter 10): interpolation with the
    gradients (Eq. 10.5) wherever a record has w > 1/a. Where none does (the part of a pixel
    across an edge from its centre, a curved surface whose normal turns by more than a within
    a pixel, the holes the neighbour check left after the last placement pass, mirror
    reflections) the batch makes records of its own, as Ward's ray tracer does when a look-up
    fails, but kept to the batch (so the picture does not depend on the order batches finish):
    a final gather at every ``LOCAL_STEPS[0]``-th uncovered sample (samples come pixel by
    pixel, so about one per uncovered pixel) becomes a record reaching ``R_MIN_PIXELS`` pixel
    footprints (the least any record reaches; no neighbour check vouches for a longer one),
    the samples it covers interpolate it, and so on with every ``LOCAL_STEPS[1]``-th of the
    rest; what is still uncovered gets a gather of its own. Without this every one of a
    pixel's 16 samples gathered: on the seed's Scene 2 at 160 x 120 the camera gathered at
    5,329 samples (``final``) and 13,722 (a = 0.4, 19 s of 28 s). Reaching for records with a
    relaxed error instead was measured 2x too bright along a box's contact with the floor.

    ``eye`` [m] and ``pixel_angle`` (2 tan(fov_x / 2) / width) give a point's pixel footprint
    (its distance from the eye times ``pixel_angle``)."""

    def __init__(self, cache, a, gather: _FinalGather, lookups, use_gradients, eye,
                 pixel_angle):
        self.cache, self.a, self.gather, self.lookups = cache, a, gather, lookups
        self.use_gradients = use_gradients
        self.eye = np.asarray(eye, np.float64)
        self.pixel_angle = float(pixel_angle)

    def irradiance(self, x, ns, ng, rng, stats):
        e, covered, _w, _count = self.cache.interpolate(x, ns, self.a,
                                                        use_gradients=self.use_gradients)
        stats["cache_interpolated"] = stats.get("cache_interpolated", 0) + int(covered.sum())
        rest = np.nonzero(~covered)[0]
        gathered = 0
        if len(rest):
            rest, made = _local_cache_records(self, x, ns, ng, rest, e, covered, rng, stats)
            gathered += made
        if len(rest):
            e[rest] = self.gather.irradiance(x[rest], ns[rest], ng[rest], rng, stats)
            gathered += len(rest)
        if gathered:
            stats["cache_gathered"] = stats.get("cache_gathered", 0) + gathered
        stats["covered_mask"] = covered          # taken by the batch for the Cache usage pass
        return e


LOCAL_STEPS = (16, 4)   # batch-local records: every 16th uncovered sample, then every 4th left


def _local_cache_records(indirect: _CachedIndirect, x, ns, ng, rest, e, covered, rng, stats):
    """``_CachedIndirect``'s batch-local records (its docstring): fills ``e`` at the samples
    ``rest`` they serve (and at their own points), marks those ``covered`` (interpolated from a
    record), and returns (the samples still uncovered, the gathers made)."""
    from .irradiance_cache import IrradianceCache

    a = indirect.a
    local = IrradianceCache()
    made = 0
    for step in LOCAL_STEPS:
        if len(rest) < 2:                     # one sample: its own gather serves no other
            break
        pick = rest[::step]
        footprint = np.linalg.norm(x[pick] - indirect.eye, axis=1) * indirect.pixel_angle
        reach = np.maximum(R_MIN_PIXELS * footprint / a, 1e-12)
        e_pick, e_rec, radius, rot, trans, _var = _gathered_records(
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


def _gathered_records(gather: _FinalGather, x, ns, ng, rng, r_min, r_max, stats=None):
    """Irradiance-cache records at points ``x`` (normals ``ns``, offset normals ``ng``): a
    final gather at each, Ward's E, R and gradients from it (``irradiance_and_gradients``,
    misses not counted), R clamped to [``r_min``, ``r_max``] [m] and the translational
    gradient limited to the clamped R. Returns (E as the gather gives it, the records' E, R,
    rotational and translational gradients, the gathers' noise variance)."""
    from .irradiance_cache import (clamp_radius, frames_from_normals, irradiance_and_gradients,
                                   limit_translational_gradient)

    e, radiance, dist = gather.gather(x, ns, ng, rng, stats)
    g = irradiance_and_gradients(radiance, dist, gather.m, gather.n, frames_from_normals(ns),
                                 misses_count=False)
    # (Limiting R further to E / |grad_t E| was tried and dropped: with noisy records it
    # shrinks the ones that caught a bright patch; Scene 2 came out 26 % dark.)
    radius = clamp_radius(g.radius, r_min, r_max)
    trans = limit_translational_gradient(g.trans_grad, g.irradiance, g.radius, radius)
    return e, g.irradiance, radius, g.rot_grad, trans, g.variance


CACHE_STRIDES = (32, 16, 8, 4, 2, 1)     # placement passes: every 32nd pixel, then 16th, ...
R_MIN_PIXELS = 1.5                       # a record reaches at least this many pixels ...
R_MAX_PIXELS = 64.0                      # ... and at most this many (R clamped, DESIGN §4)


def _cache_prepass(scene, accel, arrays, gather: _FinalGather, settings, pool, tell, cancelled,
                   strides=CACHE_STRIDES, pixel_mask=None):
    """Place irradiance-cache records in passes of increasing image resolution (Ward's
    "overture", the seed's cache placement): the first hits of pixel centres on a grid of
    stride 32, 16, ..., 1; at each pass the points no record covers get new records, computed
    in batches by the final gather. R_i (harmonic mean distance) is clamped to
    [R_MIN_PIXELS, R_MAX_PIXELS] pixel footprints divided by a, so a record reaches between
    1.5 and 64 pixels: corners cannot drive R_i to 0, open walls cannot spread one record
    over the image. After each pass (``cache_refine``) every record is checked against the
    gathers of its neighbours (``consistent_radii``): records whose extrapolation a neighbour
    contradicts reach less far, so the next pass puts records between them, and after the
    last pass the camera's batches fill what no record covers (``_CachedIndirect``).
    Each pass starts with the coarser strides again, for the points nothing covers: where
    the check shrank records, the disc they leave is refilled coarse to fine, as Ward's
    overture would have placed it had those records been small from the start. Filled at the
    pass's own stride instead, every point of the disc got a record with its full geometric
    R (Scene 2 at 320 x 240, ``preview``: 4,027 records at stride 1, up to 921 covering one
    look-up, 20 s a render; refilled: 941 records in all, 3.8 s; measured in the README).
    Measured on the seed's Scene 2 (160 x 120, ``final``, two seeds) against a gather at every pixel: the knot's
    indirect shadow on the floor came out 17 % bright and the worst 4 x 4 block +4.3 % with
    Ward's weight alone, +1.3 % and 0.8 % with the check, for 4,520 records instead of 2,625
    and 13.9 s instead of 10.3 s.

    ``strides`` (default ``CACHE_STRIDES``) and ``pixel_mask`` (a (height, width) bool array
    of the full frame: only its pixels are placed; default all) let a study place a part of
    the cache (``tools/fit_cache_counts.py --pilots``); renders use the defaults. The stats'
    ``record_pixels`` and ``record_footprint`` give each record's frame pixel and that pixel's
    footprint [m] at the hit."""
    from .irradiance_cache import IrradianceCache, consistent_radii

    # Over the full frame, whatever the render border: a tile of a still gets the records the
    # whole frame would (so tiles reassemble into the full render, pixel for pixel).
    cam = replace(scene.camera, border=None)
    width, height = cam.window_size
    rng = sampling.rng_for(settings.seed, sampling.STREAM_GATHER, 1 << 20)
    origins, directions, tmax = pixel_rays(cam, 0, width * height, 1, rng, centres=True)
    t_hit, prim, bu, bv = accel.intersect(origins, directions, tmax)
    hit = prim >= 0
    if pixel_mask is not None:
        hit &= np.asarray(pixel_mask, bool).reshape(-1)
    pixel = np.nonzero(hit)[0]
    t_hit, prim, bu, bv = t_hit[hit], prim[hit], bu[hit], bv[hit]
    d = directions[hit]
    x = origins[hit] + t_hit[:, None] * d
    ng, ns, _front = _surface_normals(arrays, prim, bu, bv, d)
    diffuse = arrays.is_diffuse[arrays.material_ids[prim]]
    pixel, x, ng, ns, t_hit = pixel[diffuse], x[diffuse], ng[diffuse], ns[diffuse], t_hit[diffuse]
    footprint = t_hit.astype(np.float64) * (2.0 * cam.tan_half_x / cam.resolution[0])
    a = settings.cache_error
    cache = IrradianceCache()
    row, col = np.divmod(pixel, width)
    stats = {"passes": [], "records": 0}
    record_point, record_variance = [], []       # per record: its pixel's hit, its noise
    chunk = 256

    def record(part, key):
        prng = sampling.rng_for(settings.seed, sampling.STREAM_GATHER, key)
        _e, e_rec, radius, rot, trans, var = _gathered_records(
            gather, x[part], ns[part], ng[part], prng,
            R_MIN_PIXELS * footprint[part] / a, R_MAX_PIXELS * footprint[part] / a)
        return part, e_rec, radius, rot, trans, var

    for pass_index, stride in enumerate(strides):
        if cancelled is not None and cancelled():
            break
        made = refilled = 0
        # The overture again from the coarsest stride down to this pass's, each sub-pass
        # placing records only where nothing covers: where the check emptied a disc, it is
        # refilled coarse to fine, as if its records had been small from the start, instead of
        # with a record at every point of this pass's grid (module docstring of the function).
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
    points = np.concatenate(record_point) if record_point else np.zeros(0, np.int64)
    stats["record_pixels"], stats["record_footprint"] = pixel[points], footprint[points]
    return cache, stats


def _surface_normals(arrays: _SceneArrays, prim, bu, bv, d):
    """At hits of rays ``d`` on triangles ``prim`` (barycentrics bu, bv): the geometric normal
    turned towards the viewer, the shading normal (interpolated; the geometric one where the
    mesh is flat or the interpolated one faces away), and whether the front side was hit."""
    ng = np.take(arrays.geometric_normals, prim, axis=0)  # take: faster than ng[prim]
    facing = sampling.dot_rows(ng, d)
    front = facing < 0                                   # the ray meets the wound front side
    if not front.all():                                  # turn ng towards the viewer
        sampling.scale_rows(ng, np.where(front, np.float32(1), np.float32(-1)), out=ng)
    if arrays.shading_normals is None:
        return ng, ng, front
    corner = arrays.shading_normals[prim]
    w = np.stack([1.0 - bu - bv, bu, bv], axis=1)[..., None]
    ns = (corner * w).sum(axis=1)
    ns = np.where(front[:, None], ns, -ns)
    ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
    # A shading normal that points away from the viewer would shade the wrong side.
    ns = np.where((np.einsum("ij,ij->i", ns, d) < 0)[:, None], ns, ng).astype(np.float32)
    return ng, ns, front


# Above this many materials the per-(pixel, material) histogram of the diffuse term gets big.
MAX_HISTOGRAM_MATERIALS = 64


LOOKUP_BUDGET = 300_000      # photon-map look-ups per image when photon_lookups = 0


def auto_lookups(pixels: int, samples: int) -> int:
    """Camera samples per pixel that ask the photon map by default: about ``LOOKUP_BUDGET``
    look-ups per image (a small preview gets every sample looked up, a 640 x 480 render one
    per pixel), between 1 and ``samples``."""
    return int(min(samples, max(1, -(-LOOKUP_BUDGET // max(int(pixels), 1)))))


class _PhotonEstimate:
    """Indirect (``full``) or all (``photon-map``) light from the photon map's estimate at the
    hit itself (Eq. 9.11; seed 9.5)."""

    def __init__(self, photon_map, k, max_radius, min_bounces, cone_filter, lookups):
        self.photon_map, self.k, self.max_radius = photon_map, k, max_radius
        self.min_bounces, self.cone_filter, self.lookups = min_bounces, cone_filter, lookups

    def irradiance(self, x, ns, ng, rng, stats):
        return self.photon_map.irradiance(x, ng, k=self.k, max_radius=self.max_radius,
                                          min_bounces=self.min_bounces,
                                          cone_filter=self.cone_filter, stats=stats)


class _FinalGather:
    """Indirect light by the stratified final gather at every asking sample (no cache)."""

    def __init__(self, estimates, accel, arrays, m, n, lookups, guide=None, guide_extra=0.0):
        self.estimates, self.accel, self.arrays = estimates, accel, arrays
        self.m, self.n, self.lookups = m, n, lookups
        self.guide, self.guide_extra = guide, guide_extra

    def gather(self, x, ns, ng, rng, stats=None):
        return final_gather(x, ns, ng, self.estimates, self.accel, self.arrays, rng, self.m,
                            self.n, stats=stats,
                            guide=self.guide if self.guide_extra > 0 else None,
                            guide_extra=self.guide_extra)

    def irradiance(self, x, ns, ng, rng, stats):
        return self.gather(x, ns, ng, rng, stats)[0]


@dataclass
class CameraBlock:
    """One camera batch: a square block of the full frame (``camera``: the frame's camera
    with its border set to the block). ``index`` numbers the block in the full frame and
    seeds its random stream, so a block's pixels come out the same whatever render border
    (tile) it is rendered for; ``source`` picks the block's pixels inside the window and
    ``target`` says where they go in the window image (flat, row-major, top row first)."""

    index: int
    camera: object
    pixels: int
    source: np.ndarray
    target: np.ndarray


def camera_blocks(camera, samples: int) -> list[CameraBlock]:
    """The full-frame blocks that meet ``camera``'s render window, in window order. A block
    is B x B pixels with B = sqrt(TARGET_BATCH_SAMPLES / samples) rounded down to a multiple
    of 8 (64 at 16 spp), clipped to the frame; blocks are numbered row by row from the
    frame's bottom-left, as Blender counts border coordinates."""
    side = max(8, int(np.sqrt(TARGET_BATCH_SAMPLES / max(1, samples))) // 8 * 8)
    full_w, full_h = camera.resolution
    wx0, wy0, wx1, wy1 = camera.border
    win_w = wx1 - wx0
    columns = -(-full_w // side)
    out = []
    for by in range(wy0 // side, -(-wy1 // side)):
        for bx in range(wx0 // side, -(-wx1 // side)):
            x0, y0 = bx * side, by * side
            x1, y1 = min(x0 + side, full_w), min(y0 + side, full_h)
            bw = x1 - x0
            # the block's pixels inside the window: block rows run top-down from y1 - 1
            ys = np.arange(max(y0, wy0), min(y1, wy1))
            xs = np.arange(max(x0, wx0), min(x1, wx1))
            yy, xx = np.meshgrid(ys, xs, indexing="ij")
            source = ((y1 - 1 - yy) * bw + (xx - x0)).ravel()
            target = ((wy1 - 1 - yy) * win_w + (xx - wx0)).ravel()
            out.append(CameraBlock(index=by * columns + bx,
                                   camera=replace(camera, border=(x0, y0, x1, y1)),
                                   pixels=bw * (y1 - y0), source=source, target=target))
    # window order (top rows first), so progress sweeps down the picture
    out.sort(key=lambda b: (-b.camera.border[1], b.camera.border[0]))
    return out


def _shade_camera_batch(batch: int, pixel_range, scene: Scene, arrays: _SceneArrays,
                        accel: Accelerator, lights: LightSet, settings: RenderSettings,
                        ray_log: list | None, photon=None, shadow_map=None,
                        track_usage: bool = False, camera=None):
    """Radiance for the pixels of one batch, mean over their samples, by kind: (3, pixels, 3)
    for emission (surfaces and the world seen from the camera or in mirrors), direct light
    and indirect light (in ``photon-map`` mode: the whole estimate); their sum is Combined.
    Also the batch's counters and, with ``track_usage``, (pixels, 2) shares of samples
    interpolated from cache records and gathered afresh."""
    stats = dict.fromkeys(BATCH_COUNTERS, 0)
    stats["seconds"] = 0.0
    direct_light = settings.mode == "full"
    started = time.perf_counter()
    rng = sampling.rng_for(settings.seed, sampling.STREAM_CAMERA, batch)
    p0, p1 = pixel_range
    spp = settings.samples
    origins, directions, tmax = pixel_rays(camera or scene.camera, p0, p1, spp, rng,
                                           settings.filter_width)
    count = len(origins)
    # Sums of the samples' radiance per pixel, by kind (the Emission, Direct and Indirect
    # passes; Combined is their sum): every contribution goes straight to its pixel.
    parts = np.zeros((3, p1 - p0, 3))
    emission_sums, direct_sums, indirect_sums = parts
    # Cache usage pass: per pixel, samples interpolated from records and samples gathered.
    usage = np.zeros((p1 - p0, 2)) if track_usage else None
    throughput = np.ones((count, 3), np.float32) if arrays.has_specular else None
    ray_of = np.arange(count)
    world = scene.world.radiance
    if photon is not None and photon.lookups < spp:
        first_lookup = rng.integers(0, spp, p1 - p0)
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
        all_hit = bool(hit.all())
        if not all_hit and not scene.world.is_black:
            missed = np.broadcast_to(world, (int((~hit).sum()), 3)) if throughput is None \
                else throughput[~hit] * world
            _add_to_pixels(emission_sums, ray_of[~hit] // spp, missed)
        if not hit.any():
            break
        if not all_hit:
            prim, bu, bv, t_hit = prim[hit], bu[hit], bv[hit], _t[hit]
            d, o, rays = directions[hit], origins[hit], ray_of[hit]
            thr = None if throughput is None else throughput[hit]
        else:
            t_hit, d, o, rays, thr = _t, directions, origins, ray_of, throughput
        # Samples in order (primary rays, all hit): pixel sums need no index.
        in_order = depth == 0 and all_hit
        pixel_of = None if in_order else rays // spp
        x = sampling.scale_rows(d, t_hit)
        x += o
        ng, ns, front = _surface_normals(arrays, prim, bu, bv, d)
        mat = arrays.material_ids[prim]

        if arrays.has_emission:
            emitted = arrays.emitted_radiance[mat] * (front | arrays.both_sides[mat])[:, None]
            _add_to_pixels(emission_sums, pixel_of, emitted if thr is None else thr * emitted)

        diffuse = arrays.is_diffuse[mat]
        if diffuse.all():
            idx = slice(None)
        elif diffuse.any():
            idx = np.nonzero(diffuse)[0]
        else:
            idx = None
        if idx is not None and photon is not None:
            # Photon-map estimate at the diffuse hits of the samples that ask for it.
            ask = idx if isinstance(idx, np.ndarray) else np.arange(len(mat))
            if photon.lookups < spp:
                # The pixel's strata come in a fixed order: start at a random one per pixel,
                # so the asking samples are a uniform pick over the pixel's filter footprint.
                s = rays[ask]
                ask = ask[(s - first_lookup[s // spp]) % spp < photon.lookups]
            if len(ask):
                t0 = time.perf_counter()
                e = photon.irradiance(x[ask], ns[ask], ng[ask], rng, stats)
                stats["estimate_seconds"] += time.perf_counter() - t0
                covered = stats.pop("covered_mask", None)
                if usage is not None and covered is not None:
                    owner = rays[ask] // spp
                    usage[:, 0] += np.bincount(owner[covered], minlength=len(usage))
                    usage[:, 1] += np.bincount(owner[~covered], minlength=len(usage))
                e *= arrays.diffuse_over_pi[mat[ask]] * (spp / min(photon.lookups, spp))
                if depth > 0:
                    e *= thr[ask]
                _add_to_pixels(indirect_sums, rays[ask] // spp, e)
        if idx is not None and direct_light:
            shadow_stats = {}
            terms = direct_terms(x[idx], ns[idx], lights, accel, rng, settings.light_samples,
                                 stats=shadow_stats, offset_normals=ng[idx], ray_log=ray_log,
                                 shadow_map=shadow_map)
            stats["shadow_rays"] += shadow_stats.get("shadow_rays", 0)
            for key in ("shadow_rays_saved", "shadow_lit", "shadow_umbra", "shadow_penumbra"):
                stats[key] = stats.get(key, 0) + shadow_stats.get(key, 0)
            stats["trace_seconds"] += shadow_stats.get("trace_seconds", 0.0)
            mat_d = mat[idx]
            materials = arrays.material_count
            if depth == 0 and materials <= MAX_HISTOGRAM_MATERIALS:
                # Outgoing radiance rho_d / pi * E, summed per pixel: a (pixel, material)
                # histogram of each term's scalar weights times the materials' rho_d / pi * rgb.
                if pixel_of is None:
                    key = np.repeat(np.arange(len(direct_sums), dtype=np.int32) * materials, spp)[idx]
                else:
                    key = pixel_of[idx] * materials
                key += mat_d
                for target, scalar, rgb in terms:
                    hist = np.bincount(key if target is None else key[target], weights=scalar,
                                       minlength=len(direct_sums) * materials)
                    direct_sums += hist.reshape(-1, materials) @ (arrays.diffuse_over_pi * rgb)
            elif terms:
                e = irradiance_from_terms(terms, len(mat_d))
                e *= arrays.diffuse_over_pi[mat_d]
                if depth > 0:
                    e *= thr[idx]
                in_order_d = pixel_of is None and isinstance(idx, slice)
                _add_to_pixels(direct_sums, None if in_order_d else (rays // spp)[idx], e)

        if not arrays.has_specular or depth == settings.max_specular_depth:
            break
        mirror = arrays.is_specular[mat]
        if not mirror.any():
            break
        rho_s = arrays.specular[mat]
        idx = np.nonzero(mirror)[0]
        dm, nm = d[idx], ns[idx]
        reflected = dm - 2.0 * np.einsum("ij,ij->i", dm, nm)[:, None] * nm
        origins = accel.offset_origins(x[idx], ng[idx], reflected)
        directions = reflected
        tmax = None
        throughput = thr[idx] * rho_s[idx]
        ray_of = rays[idx]

    parts /= spp
    if usage is not None:
        usage /= spp
    stats["seconds"] = time.perf_counter() - started
    return parts, stats, usage


def _photon_stage_entry(s: dict, settings, radius, lookups, seconds_key=True) -> dict:
    """The report's ``photons`` stage entry from a photon map's stats (missing keys: 0)."""
    g = s.get
    return dict(requested=g("requested", 0), emitted=g("emitted", 0), stored=g("stored", 0),
                stored_all=g("stored_all", 0), kept=g("kept", ""),
                photons_per_light=g("photons_per_light", {}), photon_rays=g("rays", 0),
                flux_emitted=g("flux_emitted", [0, 0, 0]),
                flux_absorbed=g("flux_absorbed", [0, 0, 0]),
                flux_escaped=g("flux_escaped", [0, 0, 0]),
                flux_capped=g("flux_capped", [0, 0, 0]), capped_paths=g("capped_paths", 0),
                flux_stored_direct=g("flux_stored_direct", [0, 0, 0]),
                flux_stored_indirect=g("flux_stored_indirect", [0, 0, 0]),
                map_bytes=g("bytes", 0), bytes_per_photon=g("bytes_per_photon", 0),
                kd_tree=g("library"), emit_seconds=round(g("emit_seconds", 0.0), 6),
                trace_seconds=round(g("trace_seconds", 0.0), 6),
                build_seconds=round(g("build_seconds", 0.0), 6),
                k=settings.photon_k, max_radius_m=radius,
                radius_automatic=not settings.photon_radius, filter=settings.photon_filter,
                max_bounces=settings.bounces, lookups_per_pixel=lookups)


class _Prepared:
    """Everything the stages before the camera made: the shared state of ``render`` and
    ``bake``."""

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def close(self):
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.accel.close()


def _prepare(scene: Scene, settings: RenderSettings, progress, cancelled, artifacts) -> _Prepared:
    """Stages 1-7 (validate ... irradiance cache, shadow photons). ``artifacts``: maps made
    before (``bake`` or a loaded file) for this scene and these settings, used instead of
    building them again."""
    total_start = time.perf_counter()
    report = {"seed": settings.seed, "settings": asdict(settings), "stages": {}, "warnings": []}
    stages = report["stages"]

    def stage(name, seconds, **extra):
        stages[name] = {"seconds": round(seconds, 6), **extra}

    def tell(fraction, text):
        if progress is not None:
            progress(float(fraction), text)

    # 1. validate
    t0 = time.perf_counter()
    scene.validate()
    report["warnings"].extend(scene.warnings)
    stage("validate", time.perf_counter() - t0, triangles=int(len(scene.triangles)))
    fingerprint = None
    if artifacts is not None:
        from .artifacts import scene_fingerprint
        fingerprint = scene_fingerprint(scene, settings)
        if fingerprint != artifacts.fingerprint:
            raise SceneError("Baked maps: they were made for another scene or other settings "
                             "(geometry, lights, camera or map settings changed); bake again "
                             "or clear them")
    # 2. accel_build (single-threaded queries: parallelism is across batches)
    tell(0.0, "Building the BVH")
    accel = Accelerator(scene.triangles, threads=1)
    stage("accel_build", accel.build_seconds, triangles=int(len(scene.triangles)))

    # 3. lights
    t0 = time.perf_counter()
    lights = LightSet(scene)
    stage("lights", time.perf_counter() - t0, **lights.describe())
    if lights.empty and not np.any(scene.material_table()["exitance"] > 0):
        report["warnings"].append("Scene: no lights, no emissive materials and a black world; "
                                  "the image is black")

    # Automatic counts follow the full frame, not the border window (tiles agree).
    full_w, full_h = scene.camera.resolution
    pixel_count = full_w * full_h
    arrays = _SceneArrays(scene)
    pool = ThreadPoolExecutor(settings.worker_count)
    prep = _Prepared(report=report, stage=stage, tell=tell, accel=accel, lights=lights,
                     arrays=arrays, pool=pool, pmap=None, photon=None, cache=None,
                     shadow_map=None, radius=None, cone=None, was_cancelled=False,
                     total_start=total_start, fingerprint=fingerprint,
                     reused=artifacts is not None)
    try:
        _prepare_maps(prep, scene, settings, cancelled, artifacts, pixel_count)
    except BaseException:
        prep.close()
        raise
    return prep


def _prepare_maps(prep: _Prepared, scene, settings, cancelled, artifacts, pixel_count):
    """Stages 4-7 of ``_prepare``: the plan, photons, estimates, cache, shadow photons."""
    report, stage, tell = prep.report, prep.stage, prep.tell
    accel, lights, arrays, pool = prep.accel, prep.lights, prep.arrays, prep.pool
    # 4. the plan: which stages this scene needs, and why (engine/plan.py)
    plan = make_plan(scene, settings, lights, arrays)
    prep.plan = plan
    report["plan"] = {"mode": settings.mode, "indirect": settings.indirect,
                      "stages": plan.to_report(), "summary": plan.summary()}
    if plan["photons"]:
        lookups = settings.photon_lookups or auto_lookups(pixel_count, settings.samples)
        if artifacts is not None and artifacts.photon_map is not None:
            pmap, photon_seconds = artifacts.photon_map, 0.0
        else:
            count = settings.photons or auto_photon_count(pixel_count)
            tell(0.0, f"Photons: tracing {count:,}")
            t0 = time.perf_counter()
            pmap = build_photon_map(
                scene, accel, count, seed=settings.seed, max_bounces=settings.bounces,
                keep="indirect" if settings.mode == "full" and not plan["final_gather"] else "all",
                pool=pool,
                progress=lambda f: tell(0.0, f"Photons: {f:.0%} of {count:,} traced"),
                cancelled=cancelled)
            photon_seconds = time.perf_counter() - t0
        prep.pmap = pmap
        radius = settings.photon_radius or auto_max_radius(scene, len(pmap), settings.photon_k)
        prep.radius = radius
        s = pmap.stats
        stage("photons", photon_seconds, **_photon_stage_entry(s, settings, radius, lookups),
              reused=artifacts is not None)
        cone = CONE_FILTER_K if settings.photon_filter == "cone" else None
        prep.cone = cone
        if not plan["final_gather"]:
            prep.photon = _PhotonEstimate(pmap, settings.photon_k, radius,
                                          1 if settings.mode == "full" else 0, cone, lookups)
        else:
            tell(0.0, "Precomputing irradiance at photons")
            estimates = RadianceEstimates.build(pmap, k=settings.photon_k, max_radius=radius,
                                                pool=pool)
            stage("radiance_estimates", estimates.stats["seconds"],
                  estimates=estimates.stats["estimates"], bytes=estimates.stats.get("bytes", 0))
            photon = _FinalGather(estimates, accel, arrays, settings.gather_m, settings.gather_n,
                                  lookups, pmap, settings.gather_guided)
            prep.photon = photon
            if plan["irradiance_cache"]:
                t0 = time.perf_counter()
                if artifacts is not None and artifacts.cache is not None:
                    cache = artifacts.cache
                    cache.usage[:] = 0
                    cache_stats = {"records": len(cache), "passes": []}
                else:
                    cache, cache_stats = _cache_prepass(scene, accel, arrays, photon, settings,
                                                        pool, tell, cancelled)
                # Prebuild the spatial index once, before the batches share the cache.
                cache.interpolate(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]),
                                  settings.cache_error, count_usage=False)
                stage("irradiance_cache", time.perf_counter() - t0, records=cache_stats["records"],
                      passes=cache_stats["passes"], cache_error=settings.cache_error,
                      gather=f"{settings.gather_m}x{settings.gather_n}",
                      reused=artifacts is not None)
                prep.cache = cache
                cam = scene.camera
                prep.photon = _CachedIndirect(
                    cache, settings.cache_error, photon, lookups, settings.cache_gradients,
                    eye=np.asarray(cam.matrix, np.float64)[:3, 3],
                    pixel_angle=2.0 * cam.tan_half_x / cam.resolution[0])
        for light in scene.lights:
            if getattr(light, "photon_share", 1.0) == 0:
                report["warnings"].append(f"Light '{light.name}': photon share 0, so it sends "
                                          "no photons and adds no indirect light")
        if s.get("capped_paths", 0):
            report["warnings"].append(
                f"Photons: {s['capped_paths']:,} photon paths reached the bounce limit "
                f"({settings.bounces}); their flux {np.round(s['flux_capped'], 6).tolist()} W was "
                "dropped (a very bright enclosure?)")

    # shadow photons: lit / umbra / penumbra classes for area and mesh lights (seed 9.6)
    prep.was_cancelled = bool(prep.pmap is not None and prep.pmap.stats.get("cancelled"))
    if plan["shadow_photons"] and not prep.was_cancelled:
        t0 = time.perf_counter()
        if artifacts is not None and artifacts.shadow_map is not None:
            shadow_map = artifacts.shadow_map
        else:
            from .shadow_photons import build_shadow_photon_map
            tell(0.0, "Shadow photons")
            shadow_map = build_shadow_photon_map(scene, accel, lights, seed=settings.seed,
                                                 pool=pool)
        s = shadow_map.stats
        stage("shadow_photons", time.perf_counter() - t0, reused=artifacts is not None,
              **{k: v for k, v in s.items() if isinstance(v, (int, float, str, list, dict))})
        prep.shadow_map = shadow_map


def _artifacts_of(prep: _Prepared, scene, settings):
    from .artifacts import Artifacts, scene_fingerprint

    fingerprint = prep.fingerprint or scene_fingerprint(scene, settings)
    keep = ("photons", "radiance_estimates", "irradiance_cache", "shadow_photons")
    return Artifacts(photon_map=prep.pmap, shadow_map=prep.shadow_map, cache=prep.cache,
                     fingerprint=fingerprint, settings=asdict(settings),
                     report={k: v for k, v in prep.report["stages"].items() if k in keep})


def bake(scene: Scene, settings: RenderSettings | None = None, progress=None,
         cancelled=None):
    """Every stage but the camera: the photon map, the shadow photons and the irradiance
    cache of ``scene`` with ``settings``, as ``engine.artifacts.Artifacts`` (for the viewport
    overlays, to save next to the .blend, or to render with later: ``render(...,
    artifacts=...)`` gives the same picture as a render that builds them itself)."""
    settings = (settings or RenderSettings()).resolved().validate()
    # Issue 6: the cost estimate before any work; refuses what cannot fit in memory.
    from .estimate import preflight
    estimate = preflight(scene, settings, camera=False)
    prep = _prepare(scene, settings, progress, cancelled, None)
    try:
        artifacts = _artifacts_of(prep, scene, settings)
        artifacts.report["estimate"] = estimate
        artifacts.report["total_seconds"] = round(time.perf_counter() - prep.total_start, 6)
        artifacts.report["plan"] = prep.report["plan"]
        artifacts.report["cancelled"] = prep.was_cancelled
    finally:
        prep.close()
    return artifacts


def _centre_hits(scene: Scene, accel, arrays: _SceneArrays):
    """First hits of one ray per window pixel through its centre (the diagnostic passes)."""
    from .passes import CentreHits

    width, height = scene.camera.window_size
    origins, directions, tmax = pixel_rays(scene.camera, 0, width * height, 1,
                                           np.random.default_rng(0), centres=True)
    t_hit, prim, bu, bv = accel.intersect(origins, directions, tmax)
    hit = np.nonzero(prim >= 0)[0]
    t_hit, prim, bu, bv, d = t_hit[hit], prim[hit], bu[hit], bv[hit], directions[hit]
    x = origins[hit] + t_hit[:, None] * d
    ng, ns, _front = _surface_normals(arrays, prim, bu, bv, d)
    mat = arrays.material_ids[prim]
    return CentreHits(pixel=hit, x=x, ns=ns, ng=ng, material=mat,
                      diffuse=arrays.is_diffuse[mat], shape=(height, width))


def _diagnostic_passes(wanted, scene, settings, prep: _Prepared, usage) -> dict:
    from . import passes as P

    shape = scene.camera.window_size[::-1]
    out = {}
    hits = None
    if {"PhotonMap", "ShadowClasses"} & set(wanted):
        hits = _centre_hits(scene, prep.accel, prep.arrays)
    if "PhotonMap" in wanted:
        # All stored photons (in full mode with the photon map at the hit the map keeps only
        # the photons that bounced, so the view shows indirect light there).
        out["PhotonMap"] = P.photon_map_view(hits, prep.pmap, settings.photon_k,
                                             prep.radius or np.inf, 0,
                                             prep.arrays.diffuse_over_pi, prep.cone)
    if "ShadowClasses" in wanted:
        out["ShadowClasses"] = P.shadow_classes_image(hits, prep.shadow_map,
                                                      range(len(prep.lights.sampled)))
    if "Photons" in wanted:
        out["Photons"] = P.photons_image(scene.camera, prep.accel, prep.pmap, shape)
    if "CachePoints" in wanted:
        out["CachePoints"] = P.cache_points_image(scene.camera, prep.accel, prep.cache, shape)
    if "CacheUsage" in wanted:
        out["CacheUsage"] = P.cache_usage_image(usage, shape)
    return out


def render(scene: Scene, settings: RenderSettings | None = None, progress=None, cancelled=None,
           ray_log: list | None = None, passes=(), artifacts=None) -> RenderResult:
    """Render ``scene``. ``progress(fraction, text)`` is called between batches and
    ``cancelled()`` polled there (return True to stop early). ``ray_log``, when a list,
    receives every traced batch of rays (benchmarks re-trace them with raw Embree).
    ``passes``: pass names or ``--passes`` names (``engine/passes.py``) to return in
    ``result.passes`` beside Combined. ``artifacts``: maps from ``bake`` (or a saved file)
    for this scene and settings, used instead of building them again; the picture is the
    same. ``result.artifacts`` holds the maps this render used."""
    from .passes import parse_passes

    settings = (settings or RenderSettings()).resolved().validate()
    wanted = parse_passes(passes)
    # Issue 6: the cost estimate before any work; refuses what cannot fit in memory.
    from .estimate import preflight
    estimate = preflight(scene, settings, wanted, reused=artifacts is not None)
    prep = _prepare(scene, settings, progress, cancelled, artifacts)
    report, stage, tell = prep.report, prep.stage, prep.tell
    report["estimate"] = estimate
    report["warnings"].extend(estimate.get("warnings", ()))
    stages = report["stages"]
    accel, lights, arrays, pool = prep.accel, prep.lights, prep.arrays, prep.pool
    photon, shadow_map, cache = prep.photon, prep.shadow_map, prep.cache
    was_cancelled = prep.was_cancelled
    width, height = scene.camera.window_size
    pixel_count = width * height

    # 5. camera: blocks of the full frame over a thread pool
    track_usage = "CacheUsage" in wanted and isinstance(photon, _CachedIndirect)
    blocks = camera_blocks(scene.camera, settings.samples)
    image = np.zeros((pixel_count, 3), np.float32)
    split = [name for name in ("Emission", "Direct", "Indirect") if name in wanted]
    kinds = {name: np.zeros((pixel_count, 3), np.float32) for name in split}
    usage = np.zeros((pixel_count, 2)) if track_usage else None
    totals = dict.fromkeys(BATCH_COUNTERS, 0)
    totals["batch_seconds"] = 0.0
    t0 = time.perf_counter()
    done = 0
    label = "Rendering" if settings.mode == "full" else "Photon map"
    tell(0.0, f"{label}: 0/{len(blocks)} batches")
    try:
        with pool:
            pending = {}
            queue = [] if was_cancelled else list(blocks)
            queue.reverse()

            def submit():
                while queue and len(pending) < 2 * settings.worker_count:
                    block = queue.pop()
                    fut = pool.submit(_shade_camera_batch, block.index, (0, block.pixels), scene,
                                      arrays, accel, lights, settings, ray_log, photon,
                                      shadow_map, track_usage, block.camera)
                    pending[fut] = block

            submit()
            while pending:
                finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for fut in finished:
                    block = pending.pop(fut)
                    parts, batch_stats, batch_usage = fut.result()
                    src, dst = block.source, block.target
                    image[dst] = (parts[0] + parts[1] + parts[2])[src]
                    for index, name in enumerate(("Emission", "Direct", "Indirect")):
                        if name in kinds:
                            kinds[name][dst] = parts[index][src]
                    if usage is not None:
                        usage[dst] = batch_usage[src]
                    for key in BATCH_COUNTERS:
                        totals[key] += batch_stats[key]
                    totals["batch_seconds"] += batch_stats["seconds"]
                    done += 1
                tell(done / len(blocks), f"{label}: {done}/{len(blocks)} batches")
                if cancelled is not None and cancelled():
                    was_cancelled = True
                    queue.clear()
                submit()
    except BaseException:
        accel.close()
        raise
    camera_seconds = time.perf_counter() - t0
    rays = totals["camera_rays"] + totals["shadow_rays"] + totals["specular_rays"]
    stage("camera", camera_seconds, batches=len(blocks), batches_done=done,
          camera_rays=totals["camera_rays"], shadow_rays=totals["shadow_rays"],
          specular_rays=totals["specular_rays"],
          trace_thread_seconds=round(totals["trace_seconds"], 6),
          photon_queries=totals["queries"],
          photon_query_thread_seconds=round(totals["query_seconds"], 6),
          photon_estimate_thread_seconds=round(totals["estimate_seconds"], 6),
          indirect_thread_seconds=round(totals["estimate_seconds"], 6),
          gather_points=totals["gather_points"], gather_rays=totals["gather_rays"],
          cache_interpolated=totals["cache_interpolated"], cache_gathered=totals["cache_gathered"],
          cache_local_records=totals["cache_local_records"],
          cache_local_interpolated=totals["cache_local_interpolated"],
          shadow_rays_saved=totals["shadow_rays_saved"],
          shadow_classes={"lit": totals["shadow_lit"], "umbra": totals["shadow_umbra"],
                          "penumbra": totals["shadow_penumbra"]},
          thread_seconds=round(totals["batch_seconds"], 6),
          rays_per_second=rays / camera_seconds if camera_seconds > 0 else 0.0)

    if cache is not None and len(cache):
        # How many pixels each record served (interpolated samples / samples per pixel).
        served = cache.usage / settings.samples
        stages["irradiance_cache"].update(
            pixels_per_record_mean=round(float(served.mean()), 2),
            pixels_per_record_median=round(float(np.median(served)), 2),
            pixels_per_record_max=round(float(served.max()), 2),
            records_unused=int((served == 0).sum()), bytes=int(cache.stats().get("bytes", 0)))

    # 6. passes
    result_passes = {name: kinds[name].reshape(height, width, 3) for name in split}
    if set(wanted) - set(split) and not was_cancelled:
        t0 = time.perf_counter()
        try:
            result_passes.update(_diagnostic_passes(wanted, scene, settings, prep, usage))
        except BaseException:
            accel.close()
            raise
        stage("passes", time.perf_counter() - t0, passes=list(wanted))
    report["passes"] = list(wanted)
    report["rays"] = {"camera": totals["camera_rays"], "shadow": totals["shadow_rays"],
                      "specular": totals["specular_rays"], "total": rays}
    report["scene"] = {"triangles": int(len(scene.triangles)), "materials": len(scene.materials),
                       "extent_m": scene.extent, "lights": lights.describe(),
                       "resolution": list(scene.camera.resolution), "window": list(scene.camera.border)}
    report["total_seconds"] = round(time.perf_counter() - prep.total_start, 6)
    report.update(peak_memory().to_report())
    report["cancelled"] = was_cancelled
    artifacts_out = _artifacts_of(prep, scene, settings)
    accel.close()
    result_image = image.reshape(height, width, 3)
    return RenderResult(image=result_image, passes=result_passes, report=report,
                        cancelled=was_cancelled, artifacts=artifacts_out)

