"""Lanterna's settings as Blender PropertyGroups.

``Scene.lanterna``     render settings (sampling, photons, indirect light: final gather and
                       irradiance cache, shadow photons); the exporter
                       (``engine/blender/export.py``) is the only reader that turns them into
                       ``pipeline.RenderSettings``.
``Material.lanterna``  the seed's three radiometric properties (section 3.2): diffuse
                       reflectance rho_d, specular reflectance rho_s (both per RGB channel, in
                       [0, 1]) and radiant exitance M [W/m^2]; by default derived from the
                       material's node tree instead.
``Light.lanterna``     per-light settings for the photon stages: the light's share of the
                       photon budget and whether shadow photons (seed 7.2, 9.6) leave it.

Every property carries a description, limits and a subtype. Names are part of the contract
with the exporter: a ``Scene.lanterna`` property whose name is a field of
``pipeline.RenderSettings`` reaches the core under that name (``export.export_settings``);
``Light.lanterna`` is read by ``export.export_scene``. Do not rename them.
``use_irradiance_cache`` stores nothing: it reads and writes ``indirect`` (on: ``CACHE``; off:
``GATHER``), so that the Irradiance Cache panel can carry its switch in its header as Cycles'
panels do. Material and light properties tag their data block when they change, so that an
evaluated depsgraph (viewport, scripts) sees the new value; F12 builds a fresh one anyway.
"""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty)

INT_MAX = 2 ** 31 - 1


def _tag_owner(self, _context) -> None:
    """Tag the data block that owns the group, so that an evaluated depsgraph (which the
    exporter reads) sees the new value; Blender does not do it for add-on properties."""
    self.id_data.update_tag()


def _get_use_cache(self) -> bool:
    return self.indirect == 'CACHE'


def _set_use_cache(self, value: bool) -> None:
    if bool(value) != (self.indirect == 'CACHE'):
        self.indirect = 'CACHE' if value else 'GATHER'


class LanternaSceneSettings(bpy.types.PropertyGroup):
    """Render settings of one scene (Properties editor > Render: Sampling, Photons, Indirect
    Light, Shadow Photons)."""

    mode: EnumProperty(
        name="Mode",
        description="How light is computed",
        items=(
            ('FULL', "Full", "Exact direct light plus indirect light from the photon map"),
            ('PHOTON_MAP', "Photon Map",
             "All light from the photon map, seen directly (fast, noisy; seed section 9.5)"),
        ),
        default='FULL',
    )
    samples: IntProperty(
        name="Samples",
        description="Camera samples per pixel",
        default=16, min=1, max=65536, soft_max=4096, subtype='NONE',
    )
    light_samples: IntProperty(
        name="Light Samples",
        description="Samples per area/mesh/world light per camera hit",
        default=4, min=1, max=65536, soft_max=256, subtype='NONE',
    )
    bounces: IntProperty(
        name="Max Bounces",
        description=("Most bounces of light between surfaces (0 = direct light only); photon "
                     "paths end after this many"),
        default=128, min=0, max=255, soft_max=128, subtype='NONE',
    )
    photons: IntProperty(
        name="Photons",
        description="Photons emitted from the lights (0 = automatic: two per pixel, 200k-2M)",
        default=0, min=0, max=50_000_000, soft_max=10_000_000, subtype='NONE',
    )
    photon_k: IntProperty(
        name="Photons per Estimate",
        description="Nearest photons in each radiance estimate (Eq. 9.11)",
        default=50, min=1, max=10_000, soft_max=500, subtype='NONE',
    )
    photon_radius: FloatProperty(
        name="Max Radius",
        description=("Largest radius of a photon estimate (0 = automatic, from the scene's "
                     "area and the photon count)"),
        default=0.0, min=0.0, max=1.0e6, soft_max=10.0, precision=4, subtype='DISTANCE',
    )
    photon_filter: EnumProperty(
        name="Filter",
        description="Weighting of the photons in an estimate",
        items=(
            ('NONE', "None", "Every photon in the disc counts fully"),
            ('CONE', "Cone", "Nearer photons count more (Jensen's cone filter, k = 1.1): "
                             "sharper edges, a little more noise"),
        ),
        default='NONE',
    )
    preset: EnumProperty(
        name="Preset",
        description="Quality preset: sets photons, gather, cache error and samples together",
        items=(
            ('CUSTOM', "Custom", "Use the settings below"),
            ('PREVIEW', "Preview", "Fast: 4 spp, 200k photons, gather 6x24, cache error 0.3"),
            ('FINAL', "Final", "16 spp, 1M photons, gather 12x48, cache error 0.1"),
        ),
        default='CUSTOM',
    )
    indirect: EnumProperty(
        name="Indirect",
        description="How the full mode computes indirect light",
        items=(
            ('CACHE', "Irradiance Cache", "Final gather at cached records, interpolated with "
                                          "gradients (seed chapter 10)"),
            ('GATHER', "Final Gather", "A final gather at every looked-up sample (slow, "
                                        "reference quality)"),
            ('PHOTON_MAP', "Photon Map", "The photon map's estimate at the hit (fast, blotchy)"),
        ),
        default='CACHE',
    )
    gather_m: IntProperty(
        name="Gather Theta",
        description="Final gather: strata in the polar angle (M of M x N rays)",
        default=8, min=1, max=256, soft_max=64, subtype='NONE',
    )
    gather_n: IntProperty(
        name="Gather Phi",
        description="Final gather: strata in the azimuth (N of M x N rays)",
        default=32, min=1, max=1024, soft_max=256, subtype='NONE',
    )
    gather_guided: FloatProperty(
        name="Guided Rays",
        description=("Final gather: extra rays, as a multiple of M x N, steered into the "
                     "directions nearby photons came from (Jensen 1995); 0 = off"),
        default=1.0, min=0.0, max=64.0, soft_max=8.0, precision=2, subtype='NONE',
    )
    cache_error: FloatProperty(
        name="Cache Error",
        description="Irradiance cache: largest error a; records are used where w > 1/a (Eq. 10.3)",
        default=0.2, min=0.01, max=10.0, soft_max=1.0, precision=3, subtype='NONE',
    )
    cache_gradients: BoolProperty(
        name="Gradients",
        description=("Irradiance cache: extrapolate each record with its rotation and "
                     "translation gradients (Ward and Heckbert 1992, Eq. 10.5); off: plain "
                     "weighted average of the records"),
        default=True,
    )
    cache_refine: BoolProperty(
        name="Refine at Contrasts",
        description=("Irradiance cache: records whose extrapolation a neighbouring record's "
                     "gather contradicts reach less far, so indirect shadows and sharp "
                     "changes get records of their own; off: records placed by Ward's "
                     "geometric weight only"),
        default=True,
    )
    use_irradiance_cache: BoolProperty(
        name="Irradiance Cache",
        description=("Interpolate the final gather between cached records (Indirect = "
                     "Irradiance Cache); off: a final gather at every looked-up sample "
                     "(Indirect = Final Gather)"),
        get=_get_use_cache, set=_set_use_cache,
    )
    shadow_photons: BoolProperty(
        name="Shadow Photons",
        description="Classify lit, penumbra and umbra with shadow photons to save shadow rays",
        default=True,
    )
    photon_lookups: IntProperty(
        name="Lookups per Pixel",
        description=("Camera samples per pixel that ask the photon map; their estimate stands "
                     "for the pixel's other samples (0 = automatic: about 300k look-ups per "
                     "image)"),
        default=0, min=0, max=65536, soft_max=64, subtype='NONE',
    )
    seed: IntProperty(
        name="Seed",
        description="Seed of the random sequences; the same seed gives the same image",
        default=0, min=0, max=INT_MAX, subtype='NONE',
    )
    threads: IntProperty(
        name="Threads",
        description="Worker threads (0 = automatic: one per CPU core)",
        default=0, min=0, max=1024, soft_max=64, subtype='NONE',
    )


class LanternaMaterialSettings(bpy.types.PropertyGroup):
    """The seed's radiometric material: rho_d, rho_s and M (section 3.2)."""

    derive_from_nodes: BoolProperty(
        name="Derive from Nodes",
        description=("Take reflectances and exitance from the material's node tree (Principled, "
                     "Diffuse, Glossy, Emission); off: use the values below"),
        default=True, update=_tag_owner,
    )
    diffuse: FloatVectorProperty(
        name="Diffuse",
        description="Diffuse (Lambertian) reflectance rho_d per channel; BRDF rho_d / pi",
        size=3, default=(0.8, 0.8, 0.8), min=0.0, max=1.0, subtype='COLOR', update=_tag_owner,
    )
    specular: FloatVectorProperty(
        name="Specular",
        description="Perfect-mirror reflectance rho_s per channel",
        size=3, default=(0.0, 0.0, 0.0), min=0.0, max=1.0, subtype='COLOR', update=_tag_owner,
    )
    exitance: FloatVectorProperty(
        name="Exitance",
        description="Radiant exitance M in W/m² per channel (radiance L = M / pi per side)",
        size=3, default=(0.0, 0.0, 0.0), min=0.0, max=1.0e9, soft_max=1000.0,
        precision=3, subtype='NONE', update=_tag_owner,
    )


class LanternaLightSettings(bpy.types.PropertyGroup):
    """Per-light settings for the photon stages."""

    photon_share: FloatProperty(
        name="Photon Share",
        description=("Relative weight of this light when the photon budget is split between "
                     "lights (1 = in proportion to its power)"),
        default=1.0, min=0.0, max=1000.0, soft_max=10.0, subtype='NONE',
        update=_tag_owner,
    )
    shadow_photons: BoolProperty(
        name="Shadow Photons",
        description=("Send shadow photons from this area light to classify points as lit, "
                     "penumbra or umbra (seed 9.6); off: every shadow ray to it is traced. "
                     "Point, spot and sun lights always use one shadow ray"),
        default=True, update=_tag_owner,
    )


classes = (LanternaSceneSettings, LanternaMaterialSettings, LanternaLightSettings)

_POINTERS = (
    (bpy.types.Scene, LanternaSceneSettings, "Lanterna render settings"),
    (bpy.types.Material, LanternaMaterialSettings, "Lanterna material settings"),
    (bpy.types.Light, LanternaLightSettings, "Lanterna light settings"),
)


def register():
    from ..engine.blender.registration import register_classes
    register_classes(classes)
    for owner, group, description in _POINTERS:
        owner.lanterna = PointerProperty(type=group, name="Lanterna", description=description)


def unregister():
    for owner, _group, _description in reversed(_POINTERS):
        if hasattr(owner, "lanterna"):
            del owner.lanterna
    from ..engine.blender.registration import unregister_classes
    unregister_classes(classes)
