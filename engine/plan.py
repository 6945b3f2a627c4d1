"""The planner: which stages a scene needs, and why, decided before any work (issue 4).

What it computes
    ``make_plan(scene, settings, lights, materials)`` -> ``Plan``: for every stage of the
    pipeline, whether it runs and the reason. The rules simulate only the effects a scene
    calls for:

    ==================  ==========================================================================
    stage               runs when
    ==================  ==========================================================================
    direct              ``full`` mode and some light or emitter exists
    photons             light exists, ``bounces`` > 0 (or ``photon-map`` mode), and some
                        surface reflects (a non-black diffuse or specular material) with a
                        diffuse surface to store photons on
    radiance_estimates  photons run and indirect light is gathered (``indirect`` = gather or
                        cache): irradiance precomputed at photons (Christensen 1999)
    final_gather        as radiance_estimates
    irradiance_cache    ``indirect`` = cache; records live on diffuse surfaces only
    shadow_photons      ``full`` mode, ``shadow_photons`` on, and an area light or emissive mesh
                        with its own ``shadow_photons`` switch on (area lights: the light's
                        flag; emissive meshes always) large enough to cast a visible penumbra
                        (its size above ``MIN_PENUMBRA_SIZE`` x the scene's extent); points,
                        spots and suns cast hard shadows with one ray and need none
    specular            some material has specular reflectance; ``specular_depth`` (camera
                        paths) is the setting, raised to ``TRANSMISSIVE_DEPTH`` where glass is
                        present (rough glass keeps light in by total internal reflection: a
                        GGX 0.3 sphere in a white world lost 3.5 % at 8 bounces, 1.2 % at 16,
                        < 0.1 % at 32); gather rays follow ``gather_specular_depth`` = 4
                        (8 with glass: in and out of an object and a reflection inside)
    glossy              some material has glossy or glass lobes: camera paths sample them
    caustics            ``full`` mode with the final gather, and some light's photons first
                        meet a specular surface (a pilot of photons, ``photons.specular_share``,
                        decides it in the preparation): a caustic photon map (Jensen 1996)
                        estimated at camera hits; gather rays then leave emitters seen through
                        specular surfaces to it. With ``indirect`` = photon the photon map at
                        the hit already holds caustics
    ==================  ==========================================================================

    ``settings.force`` (a comma-separated list of stage names) turns a skipped stage on anyway
    (for checking that the planner's skip changes nothing); a stage that cannot run at all
    (photons without light) stays off and says so.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .scene import SceneError

STAGES = ("direct", "photons", "radiance_estimates", "final_gather", "irradiance_cache",
          "shadow_photons", "specular", "glossy", "caustics")
MIN_PENUMBRA_SIZE = 1e-3
TRANSMISSIVE_DEPTH = 32        # camera specular depth where glass is present
GATHER_SPECULAR_DEPTH = 4      # specular bounces of a gather ray ...
GATHER_TRANSMISSIVE_DEPTH = 8  # ... where glass is present


@dataclass
class Plan:
    runs: dict = field(default_factory=dict)       # stage -> bool
    reasons: dict = field(default_factory=dict)    # stage -> why it runs or is skipped
    specular_depth: int = 0                        # specular bounces of camera paths
    gather_specular_depth: int = GATHER_SPECULAR_DEPTH

    def __getitem__(self, stage: str) -> bool:
        return bool(self.runs.get(stage, False))

    def set(self, stage: str, run: bool, reason: str):
        self.runs[stage] = bool(run)
        self.reasons[stage] = reason if run else f"skipped: {reason}"

    def to_report(self) -> dict:
        return {stage: self.reasons[stage] for stage in STAGES if stage in self.reasons}

    def summary(self) -> str:
        """One line for Blender's stats bar: the stages that run."""
        return "Plan: " + ", ".join(s.replace("_", " ") for s in STAGES if self[s])


def _light_size(light) -> float:
    """A sampled light's size [m] (its largest extent); 0 for suns and the world."""
    tris = getattr(light, "tris", None)
    if tris is not None and len(tris):
        pts = np.asarray(tris, float).reshape(-1, 3)
        return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    if hasattr(light, "du"):                                  # disk / ellipse
        return float(2 * max(np.linalg.norm(light.du), np.linalg.norm(light.dv)))
    return 0.0


def make_plan(scene, settings, lights, materials) -> Plan:
    """The plan for ``scene`` with ``settings``, its ``lights.LightSet`` and its
    ``bsdf.MaterialTable`` (module docstring)."""
    plan = Plan()
    force = {s.strip() for s in str(getattr(settings, "force", "") or "").split(",") if s.strip()}
    unknown = force - set(STAGES)
    if unknown:
        raise SceneError(f"Render settings: force names unknown stages {sorted(unknown)} "
                         f"(known: {', '.join(STAGES)})")
    full = settings.mode == "full"
    emits = (not lights.empty) or materials.has_emission
    reflects = bool(np.any(materials.diffuse > 0) or np.any(materials.specular > 0))

    # direct light
    if not full:
        plan.set("direct", False, "photon-map mode: the photon map holds the direct light")
    elif not emits:
        plan.set("direct", False, "no lights, emitters or world light")
    else:
        plan.set("direct", True, "exact direct light from every light")

    # photons
    if not emits:
        plan.set("photons", False, "nothing emits light")
    elif full and settings.bounces == 0:
        plan.set("photons", False, "bounces = 0 (direct light only)")
    elif not reflects:
        plan.set("photons", False, "all materials are black: no light bounces")
    elif not materials.is_diffuse.any():
        plan.set("photons", False, "no diffuse surface to store photons on")
    elif full:
        plan.set("photons", True, "indirect light")
    else:
        plan.set("photons", True, "all light, seen directly (photon-map mode)")
    if "photons" in force and not plan["photons"]:
        if emits:
            plan.set("photons", True, "forced on (the planner would skip it)")
        else:
            plan.reasons["photons"] += " (forced, but nothing can emit photons)"

    gathered = full and settings.indirect in ("gather", "cache")
    for stage in ("radiance_estimates", "final_gather"):
        if not plan["photons"]:
            plan.set(stage, False, "no photon map")
        elif not gathered:
            plan.set(stage, False, f"indirect = {settings.indirect if full else 'photon map'}: "
                                   "the photon map is looked up at the hit itself")
        else:
            plan.set(stage, True, "indirect light by the final gather over precomputed "
                                  "irradiance (Christensen 1999)")
    if not plan["final_gather"]:
        plan.set("irradiance_cache", False, "no final gather")
    elif settings.indirect != "cache":
        plan.set("irradiance_cache", False, "indirect = gather: a gather at every sample")
    else:
        diffuse_materials = int(materials.is_diffuse.sum())
        plan.set("irradiance_cache", True,
                 f"records on diffuse surfaces ({diffuse_materials} of "
                 f"{materials.count} materials)")

    # shadow photons
    positioned = [light for light in lights.sampled if getattr(light, "kind", "") in ("mesh", "area")]
    enabled = [light for light in positioned if getattr(light, "shadow_photons", True)]
    large = [light for light in enabled
             if _light_size(light) > MIN_PENUMBRA_SIZE * max(scene.extent, 1e-30)]
    if not full:
        plan.set("shadow_photons", False, "photon-map mode traces no shadow rays")
    elif not getattr(settings, "shadow_photons", True):
        plan.set("shadow_photons", False, "switched off")
    elif not positioned:
        plan.set("shadow_photons", False, "no area light or emissive mesh (points, spots and "
                                          "suns need one shadow ray each)")
    elif not enabled:
        plan.set("shadow_photons", False, "every eligible light has shadow photons off")
    elif not large:
        plan.set("shadow_photons", False, "area lights too small to cast a visible penumbra")
    else:
        off = len(positioned) - len(enabled)
        plan.set("shadow_photons", True, f"{len(large)} area/mesh light(s) with penumbrae"
                 + (f"; {off} with shadow photons off" if off else ""))
    if "shadow_photons" in force and not plan["shadow_photons"]:
        plan.set("shadow_photons", True, "forced on (the planner would skip it)")

    # specular paths
    transmissive = getattr(materials, "has_transmission", False)
    plan.specular_depth = int(settings.max_specular_depth)
    if transmissive and plan.specular_depth < TRANSMISSIVE_DEPTH:
        plan.specular_depth = TRANSMISSIVE_DEPTH
        depth_note = (f"; depth {TRANSMISSIVE_DEPTH} (glass present; Mirror Depth "
                      f"{settings.max_specular_depth} raised)")
    else:
        depth_note = f"; depth {plan.specular_depth}"
    plan.gather_specular_depth = GATHER_TRANSMISSIVE_DEPTH if transmissive \
        else GATHER_SPECULAR_DEPTH
    if materials.has_specular:
        plan.set("specular", True, "specular materials reflect camera and gather rays"
                 + depth_note)
    else:
        plan.set("specular", False, "no specular materials")
    if getattr(materials, "has_glossy", False):
        kinds = "glass and glossy" if transmissive else "glossy"
        plan.set("glossy", True, f"{kinds} lobes: camera paths sample them")
    else:
        plan.set("glossy", False, "no glossy or glass lobes")
    if not full:
        plan.set("caustics", False, "photon-map mode: the photon map holds the caustics")
    elif not plan["photons"]:
        plan.set("caustics", False, "no photons")
    elif not plan["final_gather"]:
        plan.set("caustics", False, "indirect = photon: the photon map at the hit holds the "
                                    "caustics")
    elif not getattr(materials, "has_transport_specular", materials.has_specular):
        plan.set("caustics", False, "no specular or glass surface")
    else:
        plan.set("caustics", True, "specular or glass surfaces (checked by a pilot of photons)")
    for stage in force - {"photons", "shadow_photons"}:
        if not plan[stage] and stage != "direct":
            plan.reasons[stage] += " (cannot be forced)"
    return plan
