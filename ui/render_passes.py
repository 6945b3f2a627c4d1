"""Lanterna's render passes in Blender: which to make, per view layer, and where to tick them.

``ViewLayer.lanterna_passes`` (:class:`LanternaPassSettings`) holds one checkbox per pass of
``engine/passes.py`` (Direct, Indirect, Emission, PhotonMap, CachePoints, Photons,
ShadowClasses, CacheUsage; all off by default, so a plain render makes only Combined).
Cycles' light passes (``engine/passes.py``: DiffDir, DiffInd, DiffCol, GlossDir,
GlossInd, GlossCol, TransDir, TransInd, TransCol, Emit, Env) follow Blender's own view-layer
flags, as Cycles' do (``ViewLayer.use_pass_diffuse_direct`` ... ``use_pass_environment``,
``LIGHT_PASS_FLAGS``; off by default). The
RenderEngine registers the ticked ones in ``update_render_passes`` (they then appear in the
Image Editor's pass menu, in the compositor's Render Layers node and in multilayer EXRs, as
Cycles' passes do) and fills them after the render. The checkboxes sit in View Layer
properties > Passes (grouped Light / Method, like Cycles' pass panels); changing one
calls ``ViewLayer.update_render_passes()`` so the compositor's sockets follow at once. (The
panel with the checkboxes is ``ui/panels.py``'s ``LANTERNA_VIEW_LAYER_PT_passes``.)
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty

from ..engine.passes import LIGHT_PASS_NAMES
from ..engine.passes import PASS_NAMES, PASSES

# property name -> (pass name, label, description)
PASS_PROPERTIES = {
    "direct": ("Direct", "Direct", "Exact direct light"),
    "indirect": ("Indirect", "Indirect", "Indirect light (irradiance cache, gather or photon map)"),
    "emission": ("Emission", "Emission", "Emitters and the world seen from the camera"),
    "photon_map": ("PhotonMap", "Photon Map", "The photon map seen directly (seed Fig. 12.6)"),
    "cache_points": ("CachePoints", "Cache Points",
                     "Each irradiance-cache record as a white dot (seed Fig. 12.4)"),
    "photons": ("Photons", "Photons", "Each stored photon as a dot of its colour (seed Fig. 12.5)"),
    "shadow_classes": ("ShadowClasses", "Shadow Classes",
                       "Shadow-photon classes: green lit, red penumbra, blue umbra"),
    "cache_usage": ("CacheUsage", "Cache Usage",
                    "Share of look-ups interpolated from records (green) and gathered (red)"),
}
# pass name -> Blender's ViewLayer flag (Cycles' light passes)
LIGHT_PASS_FLAGS = {f"{prefix}{suffix}": f"use_pass_{word}_{part}"
                    for prefix, word in (("Diff", "diffuse"), ("Gloss", "glossy"),
                                         ("Trans", "transmission"))
                    for suffix, part in (("Dir", "direct"), ("Ind", "indirect"),
                                         ("Col", "color"))}
LIGHT_PASS_FLAGS.update({"Emit": "use_pass_emit", "Env": "use_pass_environment"})
assert tuple(LIGHT_PASS_FLAGS) == LIGHT_PASS_NAMES
assert tuple(p[0] for p in PASS_PROPERTIES.values()) + LIGHT_PASS_NAMES == PASS_NAMES
assert set(PASSES.values()) == set(PASS_NAMES)


def _update_passes(self, context):
    # A ViewLayer is not an ID: id_data is its Scene; find the layer these settings are on.
    for layer in getattr(self.id_data, "view_layers", ()):
        if layer.lanterna_passes.as_pointer() == self.as_pointer():
            layer.update_render_passes()


def _annotations():
    return {prop: BoolProperty(name=label, description=desc, default=False, update=_update_passes)
            for prop, (_name, label, desc) in PASS_PROPERTIES.items()}


LanternaPassSettings = type("LanternaPassSettings", (bpy.types.PropertyGroup,),
                            {"__annotations__": _annotations(),
                             "__doc__": "Which Lanterna passes this view layer makes."})


def enabled_passes(view_layer) -> list[str]:
    """Pass names (``engine/passes.py``) ticked on ``view_layer``: Lanterna's checkboxes,
    then Cycles' light passes whose Blender flag is on."""
    settings = getattr(view_layer, "lanterna_passes", None)
    if settings is None:
        return []
    names = [name for prop, (name, _l, _d) in PASS_PROPERTIES.items() if getattr(settings, prop)]
    return names + [name for name, flag in LIGHT_PASS_FLAGS.items()
                    if getattr(view_layer, flag, False)]


def register():
    bpy.utils.register_class(LanternaPassSettings)
    bpy.types.ViewLayer.lanterna_passes = bpy.props.PointerProperty(type=LanternaPassSettings)


def unregister():
    if hasattr(bpy.types.ViewLayer, "lanterna_passes"):
        del bpy.types.ViewLayer.lanterna_passes
    if getattr(LanternaPassSettings, "is_registered", False):
        bpy.utils.unregister_class(LanternaPassSettings)
