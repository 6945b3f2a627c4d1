"""The pipeline: the whole flow of a render in one place, stage after stage.

What it computes
    ``render(scene, settings)`` -> ``RenderResult``: the Combined image (linear radiance
    [W m^-2 sr^-1], (H, W, 3) float32, row 0 at the top of the render window), the passes
    asked for, the report (``engine/report.py``) and the maps it used.
    ``bake(scene, settings)`` -> ``artifacts.Artifacts``: every stage but the camera.

The flow (DESIGN.md §1), each stage in its own module:
    0. the settings resolved and checked (``engine/settings.py``) and the cost estimate made
       before any work; a render that cannot fit in memory is refused (``engine/estimate.py``)
    1-8. ``preparation.prepare``: validate, BVH, lights, the plan, caustic map, photons,
       precomputed irradiance, irradiance cache, shadow photons (``engine/preparation.py``)
    9. the camera: blocks of the frame on a thread pool, direct light plus the indirect
       estimator and the caustic map at each diffuse hit, mirrors, glossy lobes and glass
       followed to the plan's specular depth (``engine/integrator.py``)
    10. the diagnostic passes from the maps (``engine/passes.py``) and the report's last
       fields
``progress(fraction, text)`` is called between batches and ``cancelled()`` polled there
(return True to stop early: the result is then marked cancelled). The settings are
``settings.RenderSettings`` (their table is in that module).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .artifacts import Artifacts
from .estimate import preflight
from .integrator import PART_NAMES, CameraContext, render_camera
from .passes import LIGHT_PASS_NAMES, light_pass_images
from .passes import diagnostic_passes, parse_passes
from .preparation import prepare
from .scene import Scene
from .settings import RenderSettings

__all__ = ["RenderResult", "RenderSettings", "render", "bake"]


@dataclass
class RenderResult:
    image: np.ndarray                      # (H, W, 3) float32 linear radiance, row 0 = top
    passes: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    cancelled: bool = False
    artifacts: Artifacts | None = None     # the maps it used


def render(scene: Scene, settings: RenderSettings | None = None, progress=None, cancelled=None,
           ray_log: list | None = None, passes=(), artifacts: Artifacts | None = None
           ) -> RenderResult:
    """Render ``scene`` (module docstring). ``ray_log``, when a list, receives every traced
    batch of rays (benchmarks re-trace them with raw Embree). ``passes``: pass names or
    ``--passes`` names (``engine/passes.py``). ``artifacts``: maps from ``bake`` (or a saved
    file) for this scene and settings, used instead of building them again."""
    settings = (settings or RenderSettings()).resolved().validate()
    wanted = parse_passes(passes)
    estimate = preflight(scene, settings, wanted, reused=artifacts is not None)      # 0
    maps = prepare(scene, settings, progress, cancelled, artifacts)                   # 1-8
    report = maps.report
    report.data["estimate"] = estimate
    report.data["warnings"].extend(estimate.get("warnings", ()))
    try:
        # The camera follows the plan's specular depth (raised where glass is present).
        camera_settings = replace(settings, max_specular_depth=maps.plan.specular_depth) \
            if maps.plan is not None else settings
        context = CameraContext(scene, maps.surfaces, maps.accel, maps.lights, camera_settings,
                                indirect=maps.indirect, shadow_map=maps.shadow_map,
                                track_usage="CacheUsage" in wanted and maps.cache is not None,
                                ray_log=ray_log, caustics=maps.caustics,
                                light_passes=bool(set(wanted) & set(LIGHT_PASS_NAMES)))
        camera = render_camera(context, wanted, maps.pool, progress, cancelled,     # 9
                               skip=maps.cancelled)
        report.camera_entry(camera)
        report.cache_usage(maps.cache, settings.samples)
        height, width = scene.camera.window_size[::-1]
        images = {name: camera.parts[name].reshape(height, width, 3) for name in camera.parts}
        if camera.light is not None:
            images.update({name: image.reshape(height, width, 3) for name, image in
                           light_pass_images(camera.light, wanted).items()})
        diagnostic = [name for name in wanted
                      if name not in PART_NAMES and name not in LIGHT_PASS_NAMES]
        was_cancelled = maps.cancelled or camera.cancelled
        if diagnostic and not was_cancelled:                                          # 10
            with report.timed("passes", passes=list(wanted)):
                images.update(diagnostic_passes(wanted, scene, settings, maps, camera.usage))
        report.finish(scene, maps.lights, wanted, was_cancelled)
        return RenderResult(image=camera.image.reshape(height, width, 3), passes=images,
                            report=report.data, cancelled=was_cancelled,
                            artifacts=maps.artifacts(scene, settings))
    finally:
        maps.close()


def bake(scene: Scene, settings: RenderSettings | None = None, progress=None,
         cancelled=None) -> Artifacts:
    """Every stage but the camera: the photon map, the shadow photons and the irradiance
    cache of ``scene`` with ``settings``, as ``engine.artifacts.Artifacts`` (for the viewport
    overlays, to save next to the .blend, or to render with later: ``render(...,
    artifacts=...)`` gives the same picture as a render that builds them itself)."""
    settings = (settings or RenderSettings()).resolved().validate()
    estimate = preflight(scene, settings, camera=False)
    maps = prepare(scene, settings, progress, cancelled, None)
    try:
        artifacts = maps.artifacts(scene, settings)
        artifacts.report["estimate"] = estimate
        artifacts.report["total_seconds"] = round(maps.report.elapsed(), 6)
        artifacts.report["plan"] = maps.report.data["plan"]
        artifacts.report["cancelled"] = maps.cancelled
    finally:
        maps.close()
    return artifacts
