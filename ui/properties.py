"""Lanterna's settings as Blender PropertyGroups.

``Scene.lanterna``     render settings (sampling, photons, indirect light: final gather and
                       irradiance cache, shadow photons); the exporter
                       (``engine/blender/export.py``) is the only reader that turns them into
                       ``settings.RenderSettings``.
``Material.lanterna``  the seed's three radiometric properties (section 3.2): diffuse
                       reflectance rho_d, specular reflectance rho_s (both per RGB channel, in
                       [0, 1]) and radiant exitance M [W/m^2]; by default derived from the
                       material's node tree instead.
``Light.lanterna``     per-light settings for the photon stages: the light's share of the
                       photon budget and whether shadow photons (seed 7.2, 9.6) leave it.

Every property carries a description, limits and a subtype. ``Scene.lanterna`` takes every
label, description, default, minimum and maximum from ``engine/settings.py`` (the one source
the command line and ``RenderSettings.validate`` read too): a property whose name is a field
of ``settings.RenderSettings`` reaches the core under that name (``export.export_settings``);
``Light.lanterna`` is read by ``export.export_scene``. Do not rename them.
``use_irradiance_cache`` stores nothing: it reads and writes ``indirect`` (on: ``CACHE``; off:
``GATHER``), so that the Irradiance Cache panel can carry its switch in its header as Cycles'
panels do. Material and light properties tag their data block when they change, so that an
evaluated depsgraph (viewport, scripts) sees the new value; F12 builds a fresh one anyway.
"""

import dataclasses

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty)

from ..engine.settings import SETTINGS, RenderSettings

RENDER_DEFAULTS = dataclasses.asdict(RenderSettings())


def _tag_owner(self, _context) -> None:
    """Tag the data block that owns the group, so that an evaluated depsgraph (which the
    exporter reads) sees the new value; Blender does not do it for add-on properties."""
    self.id_data.update_tag()


def _get_use_cache(self) -> bool:
    return self.indirect == 'CACHE'


def _set_use_cache(self, value: bool) -> None:
    if bool(value) != (self.indirect == 'CACHE'):
        self.indirect = 'CACHE' if value else 'GATHER'


def _enum_id(core_name: str) -> str:
    """A core choice ('photon-map') as Blender's enum identifier ('PHOTON_MAP')."""
    return core_name.upper().replace("-", "_")


def setting_property(name: str):
    """The Blender property of render setting ``name``, built from its contract in
    ``engine/settings.py`` (label, description, default, limits, unit): the one source."""
    spec = SETTINGS[name]
    default = RENDER_DEFAULTS[name]
    common = dict(name=spec.label, description=spec.description)
    if spec.choices:
        return EnumProperty(items=tuple((_enum_id(c), label, desc) for c, label, desc in spec.choices),
                            default=_enum_id(default), **common)
    if isinstance(default, bool):
        return BoolProperty(default=default, **common)
    limits = dict(min=spec.minimum, max=spec.maximum,
                  soft_max=spec.soft_max if spec.soft_max is not None else spec.maximum)
    if isinstance(default, int):
        return IntProperty(default=default, subtype='NONE', **limits, **common)
    return FloatProperty(default=default, subtype=spec.unit, precision=spec.precision or 3,
                         **limits, **common)


class LanternaSceneSettings(bpy.types.PropertyGroup):
    """Render settings of one scene (Properties editor > Render: Sampling, Photons, Indirect
    Light, Shadow Photons): one property per exposed field of ``settings.RenderSettings``,
    each built from that field's contract (``setting_property``)."""

    __annotations__ = {name: setting_property(name) for name, spec in SETTINGS.items()
                       if spec.exposed}
    __annotations__["use_irradiance_cache"] = BoolProperty(
        name="Irradiance Cache",
        description=("Interpolate the final gather between cached records (Indirect = "
                     "Irradiance Cache); off: a final gather at every looked-up sample "
                     "(Indirect = Final Gather)"),
        get=_get_use_cache, set=_set_use_cache,
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
    from ..engine.blender.classes import register_classes
    register_classes(classes)
    for owner, group, description in _POINTERS:
        owner.lanterna = PointerProperty(type=group, name="Lanterna", description=description)


def unregister():
    for owner, _group, _description in reversed(_POINTERS):
        if hasattr(owner, "lanterna"):
            del owner.lanterna
    from ..engine.blender.classes import unregister_classes
    unregister_classes(classes)
