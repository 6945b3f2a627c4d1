"""The pipeline: builds the stages in a fixed order, times each and fills the report.

What it computes
    ``render(scene, settings)`` -> ``RenderResult`` with the Combined image (linear radiance
    [W m^-2 sr^-1], (H, W, 3) float32, row 0 at the top of the render window) and a report.

Stages, in order (DESIGN.md §1)
    1. ``validate``     check the scene, drop untraceable triangles (counted, named)
    2. ``accel_build``  Embree BVH over all triangles
    3. ``lights``       sort lights into exactly evaluated and sampled ones
    4. ``camera``       primary rays in batches of whole pixels; at each hit the emission, the
                        direct light (``engine/direct.py``) and, on perfect specular surfaces,
                        the reflected ray (up to ``max_specular_depth``)

    Batches are independent (each has its own random stream from (seed, batch)), so they run
    on a thread pool (embreex and numpy release the GIL) and a fixed seed gives the same
    picture whatever the scheduling. Between batches ``progress(fraction, text)`` is called
    and ``cancelled()`` is polled; a batch takes well under a second, so Esc acts quickly.

Settings (``RenderSettings``)
    =====================  ========  ===========================================================
    name                   default   meaning
    =====================  ========  ===========================================================
    samples                16        camera samples per pixel
    light_samples          4         samples per shading point shared by area/mesh/world lights
    bounces                0         indirect bounces; 0 = direct light only
    seed                   0         random seed; same seed, same image
    threads                0         worker threads; 0 = all cores
    filter_width           1.5       Blackman-Harris pixel filter width [px]
    max_specular_depth     8         perfect-mirror reflections followed from the camera
    =====================  ========  ===========================================================
"""
from __future__ import annotations

import os
import resource
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, field

import numpy as np

from . import sampling
from .accel import Accelerator
from .camera import pixel_rays
from .direct import direct_terms, irradiance_from_terms
from .lights import LightSet
from .scene import Scene, SceneError

TARGET_BATCH_SAMPLES = 1 << 16


@dataclass
class RenderSettings:
    samples: int = 16
    light_samples: int = 4
    bounces: int = 0
    seed: int = 0
    threads: int = 0
    filter_width: float = 1.5
    max_specular_depth: int = 8

    def validate(self) -> "RenderSettings":
        checks = [("samples", self.samples >= 1), ("light_samples", self.light_samples >= 0),
                  ("bounces", self.bounces >= 0), ("threads", self.threads >= 0),
                  ("filter_width", 0 <= self.filter_width <= 10),
                  ("max_specular_depth", self.max_specular_depth >= 0)]
        for name, ok in checks:
            if not ok:
                raise SceneError(f"Render settings: {name} = {getattr(self, name)} is out of range")
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


# Above this many materials the per-(pixel, material) histogram of the diffuse term gets big.
MAX_HISTOGRAM_MATERIALS = 64


def _shade_camera_batch(batch: int, pixel_range, scene: Scene, arrays: _SceneArrays,
                        accel: Accelerator, lights: LightSet, settings: RenderSettings,
                        ray_log: list | None):
    """Radiance for the pixels of one batch: (pixels, 3) mean over their samples."""
    stats = {"camera_rays": 0, "shadow_rays": 0, "specular_rays": 0,
             "trace_seconds": 0.0, "seconds": 0.0}
    started = time.perf_counter()
    rng = sampling.rng_for(settings.seed, sampling.STREAM_CAMERA, batch)
    p0, p1 = pixel_range
    spp = settings.samples
    origins, directions, tmax = pixel_rays(scene.camera, p0, p1, spp, rng, settings.filter_width)
    count = len(origins)
    # Sums of the samples' radiance per pixel: every contribution goes straight to its pixel.
    pixel_sums = np.zeros((p1 - p0, 3))
    throughput = np.ones((count, 3), np.float32) if arrays.has_specular else None
    ray_of = np.arange(count)
    world = scene.world.radiance
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
            _add_to_pixels(pixel_sums, ray_of[~hit] // spp, missed)
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
        ng = np.take(arrays.geometric_normals, prim, axis=0)  # take: faster than ng[prim]
        facing = sampling.dot_rows(ng, d)
        front = facing < 0                                   # the ray meets the wound front side
        if not front.all():                                  # turn ng towards the viewer
            sampling.scale_rows(ng, np.where(front, np.float32(1), np.float32(-1)), out=ng)
        if arrays.shading_normals is not None:
            corner = arrays.shading_normals[prim]
            w = np.stack([1.0 - bu - bv, bu, bv], axis=1)[..., None]
            ns = (corner * w).sum(axis=1)
            ns = np.where(front[:, None], ns, -ns)
            ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
            # A shading normal that points away from the viewer would shade the wrong side.
            ns = np.where((np.einsum("ij,ij->i", ns, d) < 0)[:, None], ns, ng).astype(np.float32)
        else:
            ns = ng
        mat = arrays.material_ids[prim]

        if arrays.has_emission:
            emitted = arrays.emitted_radiance[mat] * (front | arrays.both_sides[mat])[:, None]
            _add_to_pixels(pixel_sums, pixel_of, emitted if thr is None else thr * emitted)

        diffuse = arrays.is_diffuse[mat]
        if diffuse.all():
            idx = slice(None)
        elif diffuse.any():
            idx = np.nonzero(diffuse)[0]
        else:
            idx = None
        if idx is not None:
            shadow_stats = {}
            terms = direct_terms(x[idx], ns[idx], lights, accel, rng, settings.light_samples,
                                 stats=shadow_stats, offset_normals=ng[idx], ray_log=ray_log)
            stats["shadow_rays"] += shadow_stats.get("shadow_rays", 0)
            stats["trace_seconds"] += shadow_stats.get("trace_seconds", 0.0)
            mat_d = mat[idx]
            materials = arrays.material_count
            if depth == 0 and materials <= MAX_HISTOGRAM_MATERIALS:
                # Outgoing radiance rho_d / pi * E, summed per pixel: a (pixel, material)
                # histogram of each term's scalar weights times the materials' rho_d / pi * rgb.
                if pixel_of is None:
                    key = np.repeat(np.arange(len(pixel_sums), dtype=np.int32) * materials, spp)[idx]
                else:
                    key = pixel_of[idx] * materials
                key += mat_d
                for target, scalar, rgb in terms:
                    hist = np.bincount(key if target is None else key[target], weights=scalar,
                                       minlength=len(pixel_sums) * materials)
                    pixel_sums += hist.reshape(-1, materials) @ (arrays.diffuse_over_pi * rgb)
            elif terms:
                e = irradiance_from_terms(terms, len(mat_d))
                e *= arrays.diffuse_over_pi[mat_d]
                if depth > 0:
                    e *= thr[idx]
                in_order_d = pixel_of is None and isinstance(idx, slice)
                _add_to_pixels(pixel_sums, None if in_order_d else (rays // spp)[idx], e)

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

    pixels = pixel_sums / spp
    stats["seconds"] = time.perf_counter() - started
    return pixels, stats


def render(scene: Scene, settings: RenderSettings | None = None, progress=None, cancelled=None,
           ray_log: list | None = None) -> RenderResult:
    """Render ``scene``. ``progress(fraction, text)`` is called between batches and
    ``cancelled()`` polled there (return True to stop early). ``ray_log``, when a list,
    receives every traced batch of rays (benchmarks re-trace them with raw Embree)."""
    settings = (settings or RenderSettings()).validate()
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
    if settings.bounces > 0:
        report["warnings"].append(
            f"Render settings: bounces = {settings.bounces}, but indirect light is not "
            "implemented yet; rendering direct light only")

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

    # 4. camera: batches of whole pixels over a thread pool
    width, height = scene.camera.window_size
    pixel_count = width * height
    batch_pixels = max(1, TARGET_BATCH_SAMPLES // settings.samples)
    ranges = [(p, min(p + batch_pixels, pixel_count)) for p in range(0, pixel_count, batch_pixels)]
    arrays = _SceneArrays(scene)
    image = np.zeros((pixel_count, 3), np.float32)
    totals = {"camera_rays": 0, "shadow_rays": 0, "specular_rays": 0, "trace_seconds": 0.0,
              "batch_seconds": 0.0}
    t0 = time.perf_counter()
    was_cancelled = False
    done = 0
    tell(0.0, f"Direct light: 0/{len(ranges)} batches")
    with ThreadPoolExecutor(settings.worker_count) as pool:
        pending = {}
        queue = list(enumerate(ranges))
        queue.reverse()

        def submit():
            while queue and len(pending) < 2 * settings.worker_count:
                batch, rng_ = queue.pop()
                fut = pool.submit(_shade_camera_batch, batch, rng_, scene, arrays, accel, lights,
                                  settings, ray_log)
                pending[fut] = rng_

        submit()
        while pending:
            finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for fut in finished:
                a, b = pending.pop(fut)
                pixels, batch_stats = fut.result()
                image[a:b] = pixels
                for key in ("camera_rays", "shadow_rays", "specular_rays", "trace_seconds"):
                    totals[key] += batch_stats[key]
                totals["batch_seconds"] += batch_stats["seconds"]
                done += 1
            tell(done / len(ranges), f"Direct light: {done}/{len(ranges)} batches")
            if cancelled is not None and cancelled():
                was_cancelled = True
                queue.clear()
            submit()
    camera_seconds = time.perf_counter() - t0
    rays = totals["camera_rays"] + totals["shadow_rays"] + totals["specular_rays"]
    stage("camera", camera_seconds, batches=len(ranges), batches_done=done,
          camera_rays=totals["camera_rays"], shadow_rays=totals["shadow_rays"],
          specular_rays=totals["specular_rays"],
          trace_thread_seconds=round(totals["trace_seconds"], 6),
          thread_seconds=round(totals["batch_seconds"], 6),
          rays_per_second=rays / camera_seconds if camera_seconds > 0 else 0.0)

    report["rays"] = {"camera": totals["camera_rays"], "shadow": totals["shadow_rays"],
                      "specular": totals["specular_rays"], "total": rays}
    report["scene"] = {"triangles": int(len(scene.triangles)), "materials": len(scene.materials),
                       "extent_m": scene.extent, "lights": lights.describe(),
                       "resolution": list(scene.camera.resolution), "window": list(scene.camera.border)}
    report["total_seconds"] = round(time.perf_counter() - total_start, 6)
    report["peak_memory_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)
    report["cancelled"] = was_cancelled
    accel.close()
    result_image = image.reshape(height, width, 3)
    return RenderResult(image=result_image, report=report, cancelled=was_cancelled)
