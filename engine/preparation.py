"""Everything before the camera: the scene checked, the BVH, the lights, the plan and the
maps (photon map, precomputed irradiance, irradiance cache, shadow photons), each timed.

What it computes
    ``prepare(scene, settings, progress, cancelled, artifacts)`` -> ``Prepared``, in this
    order (DESIGN.md §1):
        1. ``validate``             check the scene, drop untraceable triangles (named)
        2. ``accel_build``          Embree BVH over all triangles (``engine/accel.py``)
        3. ``lights``               exactly evaluated and sampled lights (``engine/lights.py``)
        4. the plan                 which of the stages below this scene needs, each with its
                                    reason, before any work (``engine/plan.py``)
        5a. ``caustics``            the caustic photon map where a pilot of photons finds
                                    lights that see specular or glass surfaces
                                    (``photons.build_caustic_map``, ``indirect.CausticEstimate``;
                                    not kept in baked artifacts: made again each render)
        5. ``photons``              emit, trace, store, kd-tree (``engine/photons.py``)
        6. ``radiance_estimates``   irradiance precomputed at a quarter of the photons
                                    (Christensen 1999, ``engine/gather.py``)
        7. ``irradiance_cache``     records placed in passes (``indirect.place_cache``)
        8. ``shadow_photons``       lit / penumbra / umbra classes (``engine/shadow_photons.py``)
    ``artifacts``: maps made before (``pipeline.bake`` or a loaded file) for this scene and
    these settings, used instead of building them again (the picture is the same).
    ``Prepared.indirect`` is the estimator the camera asks for indirect light
    (``engine/indirect.py``): the photon map at the hit, the final gather, or the cache.
    Automatic counts follow the full frame, not the border window, so tiles of a still agree.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np

from .accel import Accelerator
from .artifacts import Artifacts, scene_fingerprint
from .gather import RadianceEstimates, StrandEstimates
from .indirect import CachedIndirect, CausticEstimate, FinalGather, PhotonEstimate, place_cache
from .lights import LightSet
from .photons import (CAUSTIC_PILOT, MIN_CAUSTIC_FLUX, STRONG_CAUSTIC_PASS, auto_caustic_stored, auto_max_radius, auto_photon_count,
                      build_caustic_map, build_photon_map, caustic_emission_count,
                      emissive_meshes, specular_share)
from .plan import Plan, make_plan
from .report import RenderReport
from .scene import Scene, SceneError
from .settings import CONE_FILTER_K, RenderSettings, auto_lookups
from .shadow_photons import build_shadow_photon_map
from .surfaces import SceneSurfaces

ARTIFACT_STAGES = ("photons", "radiance_estimates", "irradiance_cache", "shadow_photons")


@dataclass
class Prepared:
    """What the stages before the camera made: the shared state of ``render`` and ``bake``."""

    report: RenderReport
    accel: Accelerator
    lights: LightSet
    surfaces: SceneSurfaces
    pool: ThreadPoolExecutor
    plan: Plan | None = None
    photon_map: object = None          # photons.PhotonMap
    indirect: object = None            # the camera's estimator (engine/indirect.py)
    cache: object = None               # irradiance_cache.IrradianceCache
    shadow_map: object = None          # shadow_photons.ShadowPhotonMap
    caustics: object = None            # indirect.CausticEstimate (the caustic map), or None
    radius: float | None = None        # the photon estimate's radius cap [m]
    cone: float | None = None          # the cone filter's k, None without it
    cancelled: bool = False
    fingerprint: str | None = None     # of the artifacts given, checked
    meshes: list | None = None         # photons.emissive_meshes, shared by the photon passes

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.accel.close()

    def artifacts(self, scene: Scene, settings: RenderSettings) -> Artifacts:
        """The maps this render made or used, with their fingerprint and stage entries."""
        fingerprint = self.fingerprint or scene_fingerprint(scene, settings)
        stages = self.report.stages
        return Artifacts(photon_map=self.photon_map, shadow_map=self.shadow_map,
                         cache=self.cache, fingerprint=fingerprint, settings=asdict(settings),
                         report={k: v for k, v in stages.items() if k in ARTIFACT_STAGES})


def prepare(scene: Scene, settings: RenderSettings, progress, cancelled,
            artifacts: Artifacts | None) -> Prepared:
    """Stages 1-8 (module docstring)."""
    report = RenderReport(settings)

    def tell(fraction, text):
        if progress is not None:
            progress(float(fraction), text)

    # 1. validate
    t0 = time.perf_counter()
    scene.validate()
    report.data["warnings"].extend(scene.warnings)
    report.stage("validate", time.perf_counter() - t0, triangles=int(len(scene.triangles)))
    fingerprint = None
    if artifacts is not None:
        fingerprint = scene_fingerprint(scene, settings)
        if fingerprint != artifacts.fingerprint:
            raise SceneError("Baked maps: they were made for another scene or other settings "
                             "(geometry, lights, camera or map settings changed); bake again "
                             "or clear them")
    # 2. accel_build (single-threaded queries: parallelism is across batches)
    tell(0.0, "Building the BVH")
    accel = Accelerator(scene.triangles, threads=1)
    report.stage("accel_build", accel.build_seconds, triangles=int(len(scene.triangles)))

    # 3. lights
    t0 = time.perf_counter()
    lights = LightSet(scene)
    report.stage("lights", time.perf_counter() - t0, **lights.describe())
    surfaces = SceneSurfaces(scene)
    if lights.empty and not surfaces.materials.has_emission:
        if scene.world.seen_by_camera.is_black:
            report.warn("Scene: no lights, no emissive materials and a black world; the image "
                        "is black")
        else:
            report.warn("Scene: no lights, no emissive materials and a world that lights with "
                        "black; only the world the camera sees shows")
    prep = Prepared(report=report, accel=accel, lights=lights, surfaces=surfaces,
                    pool=ThreadPoolExecutor(settings.worker_count), fingerprint=fingerprint)
    try:
        # 4. the plan: which stages this scene needs, and why
        prep.plan = plan = make_plan(scene, settings, lights, surfaces.materials)
        report.data["plan"] = {"mode": settings.mode, "indirect": settings.indirect,
                               "stages": plan.to_report(), "summary": plan.summary()}
        if plan["caustics"]:
            _caustics(prep, scene, settings, tell, cancelled)                # 5a
            report.data["plan"]["stages"] = plan.to_report()
            report.data["plan"]["summary"] = plan.summary()
        if plan["photons"]:
            _photons(prep, scene, settings, tell, cancelled, artifacts)      # 5-7
        prep.cancelled = bool(prep.photon_map is not None
                              and prep.photon_map.stats.get("cancelled"))
        if plan["shadow_photons"] and not prep.cancelled:
            _shadow_photons(prep, scene, settings, tell, artifacts)          # 8
    except BaseException:
        prep.close()
        raise
    return prep


def _emissive_meshes(prep: Prepared, scene) -> list:
    """The scene's emissive meshes as the photon passes read them (``photons.
    emissive_meshes``), made once a render: a textured emission's parts cost 35 ms."""
    if prep.meshes is None:
        prep.meshes = emissive_meshes(scene, prep.surfaces.materials)
    return prep.meshes


def _caustics(prep: Prepared, scene, settings, tell, cancelled):
    """Stage 5a: the caustic photon map where the lights' photons meet specular surfaces
    first: a pilot measures the share that does (``photons.specular_share``), which sets the
    photons emitted for ``auto_caustic_stored`` of them to reach a specular surface; the
    estimate's radius follows the map's own density (``build_caustic_map``)."""
    report, plan = prep.report, prep.plan
    t0 = time.perf_counter()
    share, flux_share, passed = specular_share(scene, prep.accel, settings.seed,
                                               surfaces=prep.surfaces,
                                               meshes=_emissive_meshes(prep, scene))
    if not share > 0:
        plan.set("caustics", False, f"no light's photons meet a specular or glass surface "
                                    f"first (a pilot of {CAUSTIC_PILOT:,})")
        return
    if flux_share < MIN_CAUSTIC_FLUX and passed < STRONG_CAUSTIC_PASS:
        plan.set("caustics", False, f"specular and glass surfaces pass on {flux_share:.2%} of "
                                    f"the lights' flux (under {MIN_CAUSTIC_FLUX:.1%}; a pilot "
                                    f"of {CAUSTIC_PILOT:,}), {passed:.0%} of what reaches "
                                    f"them: gather rays take it")
        return
    full_w, full_h = scene.camera.resolution
    count = caustic_emission_count(auto_caustic_stored(full_w * full_h), share)
    tell(0.0, f"Caustics: tracing {count:,} photons")
    cmap = build_caustic_map(scene, prep.accel, count, seed=settings.seed,
                             max_bounces=settings.bounces, k=settings.photon_k, pool=prep.pool,
                             progress=lambda f: tell(0.0, f"Caustics: {f:.0%} traced"),
                             cancelled=cancelled, surfaces=prep.surfaces,
                             meshes=_emissive_meshes(prep, scene))
    stats = cmap.stats
    report.stage("caustics", time.perf_counter() - t0, specular_share=round(share, 6),
                 flux_share=round(flux_share, 6), passed_share=round(passed, 4),
                 emitted=stats["emitted"], stored=stats["stored"], radius=stats["radius"],
                 bytes=stats["bytes"], cancelled=stats["cancelled"])
    if not stats["radius"] > 0:
        plan.set("caustics", False, f"only {stats['stored']} caustic photons stored (the "
                                    "specular surfaces pass little light to diffuse ones)")
        return
    prep.caustics = CausticEstimate(cmap, settings.photon_k, stats["radius"])
    plan.set("caustics", True, f"{share:.2%} of the lights' photons meet specular or glass "
                               "surfaces first")


def _photons(prep: Prepared, scene, settings, tell, cancelled, artifacts):
    """Stages 5-7: the photon map, then the indirect estimator the plan asks for (the map at
    the hit; or the final gather over precomputed irradiance, with the cache's records)."""
    report, plan, pool = prep.report, prep.plan, prep.pool
    full_w, full_h = scene.camera.resolution
    pixel_count = full_w * full_h
    lookups = settings.photon_lookups or auto_lookups(pixel_count, settings.samples)
    reused = artifacts is not None
    if reused and artifacts.photon_map is not None:
        pmap, photon_seconds = artifacts.photon_map, 0.0
    else:
        count = settings.photons or auto_photon_count(pixel_count)
        tell(0.0, f"Photons: tracing {count:,}")
        t0 = time.perf_counter()
        pmap = build_photon_map(
            scene, prep.accel, count, seed=settings.seed, max_bounces=settings.bounces,
            keep="indirect" if settings.mode == "full" and not plan["final_gather"] else "all",
            pool=pool, progress=lambda f: tell(0.0, f"Photons: {f:.0%} of {count:,} traced"),
            cancelled=cancelled, surfaces=prep.surfaces, meshes=_emissive_meshes(prep, scene))
        photon_seconds = time.perf_counter() - t0
    prep.photon_map = pmap
    prep.radius = radius = (settings.photon_radius
                            or auto_max_radius(scene, len(pmap), settings.photon_k))
    s = pmap.stats
    report.stage("photons", photon_seconds, **report.photon_entry(s, settings, radius, lookups),
                 reused=reused)
    prep.cone = CONE_FILTER_K if settings.photon_filter == "cone" else None
    if not plan["final_gather"]:
        prep.indirect = PhotonEstimate(pmap, settings.photon_k, radius,
                                       1 if settings.mode == "full" else 0, prep.cone, lookups)
    else:
        tell(0.0, "Precomputing irradiance at photons")
        estimates = RadianceEstimates.build(pmap, k=settings.photon_k, max_radius=radius,
                                            pool=pool, coverage=prep.accel.disc_coverage)
        strand_stats = {}
        if scene.strands is not None:          # hair: estimates of their own
            estimates.strands = StrandEstimates.build(pmap, prep.accel, scene.triangles,
                                                      scene.strands, seed=settings.seed)
            strand_stats = estimates.strands.stats
        report.stage("radiance_estimates",
                     estimates.stats["seconds"] + strand_stats.get("seconds", 0.0),
                     estimates=estimates.stats["estimates"],
                     bytes=estimates.stats.get("bytes", 0),
                     **{k: v for k, v in strand_stats.items() if k != "seconds"})
        # With direct light computed, the smooth part of an image world with a sun goes to
        # the gather (``lights.EnvironmentLight.gather_sky``): its light samples keep the sun.
        sky = prep.lights.gather_sky() if settings.mode == "full" else None
        gather = FinalGather(estimates, prep.accel, prep.surfaces, settings.gather_m,
                             settings.gather_n, lookups, pmap, settings.gather_guided,
                             max_specular=plan.gather_specular_depth,
                             mirrored_emission=prep.caustics is None, sky=sky)
        prep.indirect = gather
        if plan["irradiance_cache"]:
            _cache(prep, scene, settings, gather, lookups, tell, cancelled, artifacts)
    for light in scene.lights:
        if getattr(light, "photon_share", 1.0) == 0:
            report.warn(f"Light '{light.name}': photon share 0, so it sends no photons and "
                        "adds no indirect light")
    if s.get("capped_paths", 0):
        report.warn(f"Photons: {s['capped_paths']:,} photon paths reached the bounce limit "
                    f"({settings.bounces}); their flux {np.round(s['flux_capped'], 6).tolist()} "
                    "W was dropped (a very bright enclosure?)")


def _cache(prep: Prepared, scene, settings, gather, lookups, tell, cancelled, artifacts):
    """Stage 7: the irradiance cache's records, placed or taken from ``artifacts``."""
    t0 = time.perf_counter()
    reused = artifacts is not None and artifacts.cache is not None
    if reused and artifacts.cache.channels != gather.channels:
        # Saved with the sky in the indirect light's channels, or without a gathered sky:
        # its records do not hold what this render's passes need, so they are placed anew.
        prep.report.warn(f"Irradiance cache: the saved records hold {artifacts.cache.channels} "
                         f"channels, this render needs {gather.channels} (the gathered sky "
                         "apart); the records are placed again")
        reused = False
    if reused:
        cache = artifacts.cache
        cache.reset_usage()
        cache_stats = {"records": len(cache), "passes": []}
    else:
        cache, cache_stats = place_cache(scene, prep.accel, prep.surfaces, gather, settings,
                                         prep.pool, tell, cancelled)
    # Prebuild the spatial index once, before the batches share the cache.
    cache.interpolate(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), settings.cache_error,
                      count_usage=False)
    prep.report.stage("irradiance_cache", time.perf_counter() - t0,
                      records=cache_stats["records"], passes=cache_stats["passes"],
                      cache_error=settings.cache_error,
                      gather=f"{settings.gather_m}x{settings.gather_n}",
                      reused=reused)
    prep.cache = cache
    prep.indirect = CachedIndirect(cache, settings.cache_error, gather, lookups,
                                   settings.cache_gradients, scene.camera)


def _shadow_photons(prep: Prepared, scene, settings, tell, artifacts):
    """Stage 8: lit / umbra / penumbra classes for area and mesh lights (seed 9.6)."""
    t0 = time.perf_counter()
    reused = artifacts is not None and artifacts.shadow_map is not None
    if reused:
        shadow_map = artifacts.shadow_map
    else:
        tell(0.0, "Shadow photons")
        shadow_map = build_shadow_photon_map(scene, prep.accel, prep.lights, seed=settings.seed,
                                             pool=prep.pool)
    s = shadow_map.stats
    prep.report.stage("shadow_photons", time.perf_counter() - t0, reused=artifacts is not None,
                      **{k: v for k, v in s.items()
                         if isinstance(v, (int, float, str, list, dict))})
    prep.shadow_map = shadow_map
