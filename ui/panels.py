"""Properties-editor panels for the Lanterna engine.

Every Lanterna panel shares :class:`LanternaPanel`: ``COMPAT_ENGINES = {'LANTERNA'}`` and a
poll on ``context.engine``, so they show only while Lanterna is the scene's render engine.

* Render:   ``LANTERNA_RENDER_PT_sampling`` (mode, samples, light samples, bounces, seed,
            threads), ``LANTERNA_RENDER_PT_photons`` (photon count, k, radius, filter, lookups)
            and ``LANTERNA_RENDER_PT_last_render`` (stage timings of the last render and its
            plan: every stage with the reason it ran or was skipped).
* Material: ``LANTERNA_MATERIAL_PT_surface`` (the node tree's Surface input, to edit the
            shader as in Cycles) and ``LANTERNA_MATERIAL_PT_radiometry`` (the seed's rho_d,
            rho_s and M, greyed out while derived from the nodes; a warning when
            rho_d + rho_s > 1 in a channel, which would create energy).
* Light:    ``LANTERNA_LIGHT_PT_light`` (type, colour, power, size; the photon share).
* World:    ``LANTERNA_WORLD_PT_surface`` (the world's Surface input: a constant colour is a
            uniform environment light).

Blender's own engine-independent panels (output format, camera lens, material slots, colour
management, ...) are opened to the engine the way add-on engines do: ``'LANTERNA'`` is added
to the ``COMPAT_ENGINES`` set of every built-in panel that lists ``'BLENDER_RENDER'`` (plus a
few named below) and removed again on unregister.
"""
from __future__ import annotations

import bpy

ENGINE_ID = "LANTERNA"


class LanternaPanel:
    """Mixin of every Lanterna panel."""

    COMPAT_ENGINES = {ENGINE_ID}
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


def _split(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


# -- Render -----------------------------------------------------------------------------------
class LANTERNA_RENDER_PT_sampling(LanternaPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        layout.prop(settings, "preset")
        layout.prop(settings, "mode")
        col = layout.column(align=True)
        col.active = settings.preset == 'CUSTOM'
        col.prop(settings, "samples")
        sub = col.column(align=True)
        sub.active = settings.mode == 'FULL'
        sub.prop(settings, "light_samples")
        layout.prop(settings, "bounces")
        col = layout.column(align=True)
        col.prop(settings, "seed")
        col.prop(settings, "threads")


class LANTERNA_RENDER_PT_photons(LanternaPanel, bpy.types.Panel):
    bl_label = "Photons"
    bl_context = "render"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        layout.active = settings.mode == 'PHOTON_MAP' or settings.bounces > 0
        layout.prop(settings, "photons", text="Photons (0 = Auto)")
        col = layout.column(align=True)
        col.prop(settings, "photon_k")
        col.prop(settings, "photon_radius", text="Max Radius (0 = Auto)")
        layout.prop(settings, "photon_filter")
        layout.prop(settings, "photon_lookups", text="Lookups per Pixel (0 = Auto)")
        col = layout.column(align=True)
        col.active = settings.mode == 'FULL'
        col.prop(settings, "indirect")
        sub = col.column(align=True)
        sub.active = settings.indirect != 'PHOTON_MAP' and settings.preset == 'CUSTOM'
        sub.prop(settings, "gather_m")
        sub.prop(settings, "gather_n")
        sub.prop(settings, "gather_guided")
        sub.prop(settings, "cache_error")
        col.prop(settings, "shadow_photons")


class LANTERNA_RENDER_PT_last_render(LanternaPanel, bpy.types.Panel):
    bl_label = "Last Render"
    bl_context = "render"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        from ..engine.blender import render_engine

        layout = self.layout
        last = render_engine.LAST_RENDER
        if not last:
            layout.label(text="No render yet")
            return
        if last.get("error"):
            layout.label(text=last["error"], icon='ERROR')
        col = layout.column(align=True)
        for name, seconds in _stage_times(last.get("report") or {}):
            row = col.row()
            row.label(text=name)
            row.label(text=f"{seconds:.3f} s")
        if "total_time" in last:
            layout.label(text=f"Total {last['total_time']:.3f} s")
        plan = (last.get("report") or {}).get("plan", {}).get("stages", {})
        if plan:
            box = layout.box()
            box.label(text="Plan")
            for stage, reason in plan.items():
                row = box.row()
                row.label(text=stage.replace("_", " ").capitalize(),
                          icon='X' if str(reason).startswith("skipped") else 'CHECKMARK')
                row.label(text=str(reason))
        for text in last.get("warnings", ())[:8]:
            layout.label(text=text, icon='INFO')


def _stage_times(report: dict):
    """(name, seconds) pairs from the pipeline report's ``stages`` entry, whatever its shape."""
    stages = report.get("stages") or {}
    items = stages.items() if isinstance(stages, dict) else enumerate(stages)
    for key, value in items:
        if isinstance(value, dict):
            name = str(value.get("name", key))
            seconds = value.get("time", value.get("seconds"))
        else:
            name, seconds = str(key), value
        if isinstance(seconds, (int, float)):
            yield name, float(seconds)


# -- Material ---------------------------------------------------------------------------------
def _draw_node_input(layout, id_data, input_name: str) -> bool:
    """Draw the node tree feeding ``input_name`` of the active output node; False if none."""
    ntree = getattr(id_data, "node_tree", None)
    if ntree is None:
        return False
    node = ntree.get_output_node('ALL')
    if node is None:
        layout.label(text="No output node")
        return True
    socket = node.inputs.get(input_name)
    if socket is None:
        layout.label(text="Incompatible output node")
        return True
    layout.template_node_view(ntree, node, socket)
    return True


class _SurfacePanel(LanternaPanel):
    """The node tree feeding the Surface input of ``context.<bl_context>`` (a material or the
    world), or ``fallback`` (property, label) when it has no node tree."""

    bl_label = "Surface"
    fallback = ("color", None)

    @classmethod
    def poll(cls, context):
        return getattr(context, cls.bl_context, None) is not None and super().poll(context)

    def draw(self, context):
        layout = _split(self.layout)
        owner = getattr(context, self.bl_context)
        if not _draw_node_input(layout, owner, "Surface"):
            prop, label = self.fallback
            if label:
                layout.prop(owner, prop, text=label)
            else:
                layout.prop(owner, prop)


class LANTERNA_MATERIAL_PT_surface(_SurfacePanel, bpy.types.Panel):
    bl_context = "material"
    fallback = ("diffuse_color", "Base Color")


class LANTERNA_MATERIAL_PT_radiometry(LanternaPanel, bpy.types.Panel):
    bl_label = "Radiometry"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        mat = context.material
        return mat is not None and hasattr(mat, "lanterna") and super().poll(context)

    def draw_header(self, context):
        self.layout.label(icon='LIGHT')

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.material.lanterna
        layout.prop(settings, "derive_from_nodes")
        col = layout.column()
        col.active = not settings.derive_from_nodes
        col.prop(settings, "diffuse")
        col.prop(settings, "specular")
        col.prop(settings, "exitance")
        if settings.derive_from_nodes:
            layout.label(text="Values come from the node tree", icon='NODETREE')
            return
        over = overfull_channels(settings.diffuse, settings.specular)
        if over:
            layout.label(text=f"Diffuse + specular > 1 in {', '.join(over)}: creates energy",
                         icon='ERROR')


def overfull_channels(diffuse, specular) -> list[str]:
    """Names of the channels where rho_d + rho_s exceeds 1 (energy would be created)."""
    return [c for c, d, s in zip("RGB", diffuse, specular) if d + s > 1.0 + 1e-6]


# -- Light ------------------------------------------------------------------------------------
class LANTERNA_LIGHT_PT_light(LanternaPanel, bpy.types.Panel):
    bl_label = "Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.light is not None and super().poll(context)

    def draw(self, context):
        layout = self.layout
        light = context.light
        layout.row().prop(light, "type", expand=True)
        _split(layout)
        col = layout.column()
        col.prop(light, "color")
        col.prop(light, "energy")
        col = layout.column()
        if light.type in {'POINT', 'SPOT'}:
            col.prop(light, "shadow_soft_size", text="Radius")
        elif light.type == 'SUN':
            col.prop(light, "angle")
        elif light.type == 'AREA':
            col.prop(light, "shape")
            sub = col.column(align=True)
            if light.shape in {'SQUARE', 'DISK'}:
                sub.prop(light, "size")
            else:
                sub.prop(light, "size", text="Size X")
                sub.prop(light, "size_y", text="Y")
            if hasattr(light, "spread"):
                col.prop(light, "spread")
        if light.type == 'SPOT':
            col = layout.column()
            col.prop(light, "spot_size", text="Spot Size")
            col.prop(light, "spot_blend", text="Blend", slider=True)
            col.prop(light, "show_cone")
        if hasattr(light, "lanterna"):
            layout.prop(light.lanterna, "photon_share")


# -- World ------------------------------------------------------------------------------------
class LANTERNA_WORLD_PT_surface(_SurfacePanel, bpy.types.Panel):
    bl_context = "world"


classes = (
    LANTERNA_RENDER_PT_sampling,
    LANTERNA_RENDER_PT_photons,
    LANTERNA_RENDER_PT_last_render,
    LANTERNA_MATERIAL_PT_surface,
    LANTERNA_MATERIAL_PT_radiometry,
    LANTERNA_LIGHT_PT_light,
    LANTERNA_WORLD_PT_surface,
)


# -- Blender's own panels ---------------------------------------------------------------------
# Engine-independent built-ins that do not list BLENDER_RENDER but are wanted.
_EXTRA_BUILTINS = {"EEVEE_MATERIAL_PT_context_material"}
# BLENDER_RENDER panels that Lanterna replaces with its own or that cannot work for it.
_EXCLUDED_BUILTINS = {"DATA_PT_light", "DATA_PT_preview", "MATERIAL_PT_preview",
                      "WORLD_PT_context_world_preview"}

_opened: list[type] = []  # built-in panels whose COMPAT_ENGINES we extended


def builtin_panels() -> list[type]:
    """Blender's panels to open to Lanterna: own set lists BLENDER_RENDER, or named extras.

    Some panels share one set object (the node editor's copies of the light panels share the
    Properties editor's); a panel whose set is also an excluded panel's set is left alone.
    """
    panels = bpy.types.Panel.__subclasses__()
    excluded_sets = [p.__dict__["COMPAT_ENGINES"] for p in panels
                     if p.__name__ in _EXCLUDED_BUILTINS and "COMPAT_ENGINES" in p.__dict__]
    found = []
    for panel in panels:
        name = panel.__name__
        engines = panel.__dict__.get("COMPAT_ENGINES")  # own set only, never an inherited one
        if not isinstance(engines, set) or name.startswith("LANTERNA_"):
            continue
        if name in _EXCLUDED_BUILTINS or any(engines is s for s in excluded_sets):
            continue
        if "BLENDER_RENDER" in engines or name in _EXTRA_BUILTINS:
            found.append(panel)
    return found


def register():
    from ..engine.blender.registration import register_classes
    register_classes(classes)
    for panel in builtin_panels():
        if ENGINE_ID not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE_ID)
            _opened.append(panel)


def unregister():
    while _opened:
        _opened.pop().COMPAT_ENGINES.discard(ENGINE_ID)
    from ..engine.blender.registration import unregister_classes
    unregister_classes(classes)
