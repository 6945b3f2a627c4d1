"""The render report: what each stage did and cost, filled as the stages run (DESIGN.md §1).

What it holds (``RenderReport.data``, a JSON-ready dict; ``lanterna render --report`` writes it)
    ``seed``, ``settings``   the resolved settings (preset applied)
    ``stages``               per stage: ``seconds`` and its counts (``stage``); the photon
                             stage's energy bookkeeping (``photon_entry``), the camera's rays,
                             look-ups and shadow classes (``camera_entry``), the cache's use
                             (``cache_usage``)
    ``plan``                 which stages run and why (``engine/plan.py``)
    ``estimate``             the cost estimate made before any work (``engine/estimate.py``)
    ``warnings``             everything the input or the run gave cause to say
    ``passes``, ``rays``, ``scene``, ``total_seconds``, ``peak_memory_mb`` (``None`` with
                             ``peak_memory_note`` where the platform cannot tell), ``cancelled``
Times are wall-clock seconds; ``*_thread_seconds`` are summed over the worker threads.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import asdict

import numpy as np

from .memory import peak_memory


class RenderReport:
    """The report of one render or bake (module docstring)."""

    def __init__(self, settings):
        self.started = time.perf_counter()
        self.data = {"seed": settings.seed, "settings": asdict(settings), "stages": {},
                     "warnings": []}

    @property
    def stages(self) -> dict:
        return self.data["stages"]

    def stage(self, name: str, seconds: float, **extra) -> None:
        self.stages[name] = {"seconds": round(seconds, 6), **extra}

    @contextlib.contextmanager
    def timed(self, name: str, **extra):
        """A ``with`` block timed as stage ``name``."""
        t0 = time.perf_counter()
        yield
        self.stage(name, time.perf_counter() - t0, **extra)

    def elapsed(self) -> float:
        """Seconds since the report (the render) began."""
        return time.perf_counter() - self.started

    def warn(self, text: str) -> None:
        self.data["warnings"].append(text)

    def photon_entry(self, s: dict, settings, radius, lookups) -> dict:
        """The ``photons`` stage's fields from a photon map's stats (missing keys: 0)."""
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
                    crevice_dropped=g("crevice_dropped", 0),
                    flux_crevice=g("flux_crevice", [0, 0, 0]),
                    crevice_seconds=round(g("crevice_seconds", 0.0), 6),
                    map_bytes=g("bytes", 0), bytes_per_photon=g("bytes_per_photon", 0),
                    kd_tree=g("library"), emit_seconds=round(g("emit_seconds", 0.0), 6),
                    trace_seconds=round(g("trace_seconds", 0.0), 6),
                    build_seconds=round(g("build_seconds", 0.0), 6),
                    k=settings.photon_k, max_radius_m=radius,
                    radius_automatic=not settings.photon_radius, filter=settings.photon_filter,
                    max_bounces=settings.bounces, lookups_per_pixel=lookups)

    def camera_entry(self, camera) -> None:
        """The ``camera`` stage and the ray totals from an ``integrator.CameraImage``."""
        t = camera.totals
        rays = t["camera_rays"] + t["shadow_rays"] + t["specular_rays"]
        seconds = camera.seconds
        self.stage("camera", seconds, batches=camera.batches, batches_done=camera.done,
                   camera_rays=t["camera_rays"], shadow_rays=t["shadow_rays"],
                   specular_rays=t["specular_rays"], glossy_rays=t["glossy_rays"],
                   paths_cut_at_max_depth=t["paths_cut"],
                   trace_thread_seconds=round(t["trace_seconds"], 6),
                   photon_queries=t["queries"],
                   photon_query_thread_seconds=round(t["query_seconds"], 6),
                   photon_estimate_thread_seconds=round(t["estimate_seconds"], 6),
                   indirect_thread_seconds=round(t["estimate_seconds"], 6),
                   gather_points=t["gather_points"], gather_rays=t["gather_rays"],
                   cache_interpolated=t["cache_interpolated"],
                   cache_gathered=t["cache_gathered"],
                   cache_local_records=t["cache_local_records"],
                   cache_local_interpolated=t["cache_local_interpolated"],
                   strand_gathered=t["strand_gathered"],
                   edge_pixels=t["edge_pixels"], edge_rays=t["edge_rays"],
                   adaptive_pixels=t["adaptive_pixels"],
                   adaptive_samples=t["adaptive_samples"],
                   shadow_rays_saved=t["shadow_rays_saved"],
                   shadow_classes={"lit": t["shadow_lit"], "umbra": t["shadow_umbra"],
                                   "penumbra": t["shadow_penumbra"]},
                   thread_seconds=round(t["batch_seconds"], 6),
                   rays_per_second=rays / seconds if seconds > 0 else 0.0)
        self.data["rays"] = {"camera": t["camera_rays"], "shadow": t["shadow_rays"],
                             "specular": t["specular_rays"], "total": rays}

    def cache_usage(self, cache, samples: int) -> None:
        """How many pixels each record served (interpolated samples / samples per pixel)."""
        if cache is None or not len(cache):
            return
        served = cache.usage / samples
        self.stages["irradiance_cache"].update(
            pixels_per_record_mean=round(float(served.mean()), 2),
            pixels_per_record_median=round(float(np.median(served)), 2),
            pixels_per_record_max=round(float(served.max()), 2),
            records_unused=int((served == 0).sum()), bytes=int(cache.stats().get("bytes", 0)))

    def finish(self, scene, lights, passes, cancelled: bool) -> dict:
        """The closing fields: passes, scene, total time, peak memory, cancelled."""
        self.data["passes"] = list(passes)
        self.data["scene"] = {"triangles": int(len(scene.triangles)),
                              "materials": len(scene.materials), "extent_m": scene.extent,
                              "lights": lights.describe(),
                              "resolution": list(scene.camera.resolution),
                              "window": list(scene.camera.border)}
        self.data["total_seconds"] = round(self.elapsed(), 6)
        self.data.update(peak_memory().to_report())
        self.data["cancelled"] = cancelled
        return self.data
